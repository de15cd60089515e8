"""Linear solvers for the implicit cloth system A dv = b, by name.

pcg       Jacobi PCG: inverse diagonal entries, the standard block product (the paper's
          baseline)
bjpcg     block-Jacobi PCG: inverse 3x3 diagonal blocks, the standard block product
bscg      block-Jacobi PCG with the paper's Algorithm 1 (block-symmetric product)
galerkin  standard geometric multigrid: Galerkin coarse systems R A P, Gauss-Seidel smoothing,
          V-cycles to the tolerance
mg        the paper's multigrid: faithful (energy-conserving) coarsening, CG smoothing until the
          residual drops by 0.4, V-cycles to the tolerance
mpcg      CG preconditioned by one faithful V-cycle (symmetric block Gauss-Seidel)
amg       PyAMG smoothed aggregation as a CG preconditioner, set up anew for every matrix
direct    sparse direct factorisation (the accuracy reference)
"""

from __future__ import annotations

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.extras import require_extra
from cloth_mg_ros.solvers import baselines
from cloth_mg_ros.solvers.cg import PCGSolver, SolveResult
from cloth_mg_ros.solvers.multigrid import MultigridSolver
from cloth_mg_ros.solvers.threads import resolve_threads

__all__ = [
    "HIERARCHY_SOLVERS",
    "SOLVERS",
    "PCGSolver",
    "SolveResult",
    "check_solver_installed",
    "make_solver",
    "validate_solver_name",
]

SOLVERS = ("pcg", "bjpcg", "bscg", "galerkin", "mg", "mpcg", "amg", "direct")
HIERARCHY_SOLVERS = ("galerkin", "mg", "mpcg")


def validate_solver_name(name: str) -> str:
    """Reject an unknown solver name before anything is built."""
    if name not in SOLVERS:
        raise ClothInputError(f"unknown solver {name!r}; choose one of {', '.join(SOLVERS)}")
    return name


def make_solver(name: str, tol: float = 1e-4, maxiter: int | None = None, hierarchy=None,
                bending=None, levels: int | None = None,
                threads: int = 1):
    """A solver by name (see the module docstring) with relative tolerance ``tol``.

    threads: mpcg sweeps each level in this many parts at once (0: one per core); its
    iterates depend on this number, not on the threads that run them (solvers.dissection).

    The multigrid solvers need the mesh ``hierarchy`` (levels[0] the simulated mesh) and, for
    the faithful coarsening, the model's ``bending`` stencils; ``levels`` is how many
    hierarchy levels they use (at most: a hierarchy with fewer uses all of its own). The
    default is all of them: the hierarchy is built as deep as the mesh size calls for
    (coarsest level at least 6 cells across, about 50-350 particles), which is 3 levels at
    the paper's 1.2K-2.4K sizes and up to 6 at 80K. A fixed 3 levels would leave 10K
    particles on the coarsest level at 40K, whose direct factorisation then costs seconds
    per step.
    """
    validate_solver_name(name)
    if not (0.0 < tol < 1.0):
        raise ClothInputError(f"solver tolerance must be in (0, 1), got {tol!r}")
    if name in ("pcg", "bjpcg", "bscg"):
        prec = "scalar" if name == "pcg" else "block"
        matvec = "algorithm1" if name == "bscg" else "standard"
        return PCGSolver(tol, maxiter or 20000, prec, matvec, name)
    if name in HIERARCHY_SOLVERS:
        if hierarchy is None:
            raise ClothInputError(f"solver {name!r} needs the mesh hierarchy")
        lv = len(hierarchy.levels) if levels is None else levels
        if name == "galerkin":
            return MultigridSolver(hierarchy, None, lv, "galerkin", "vcycle", "gs", tol=tol,
                                   maxiter=maxiter or 500, name=name)
        if name == "mg":
            return MultigridSolver(hierarchy, bending, lv, "faithful", "vcycle", "cg",
                                   tol=tol, maxiter=maxiter or 500, name=name)
        return MultigridSolver(hierarchy, bending, lv, "faithful", "pcg", "gs", tol=tol,
                               maxiter=maxiter or 500, name=name,
                               parts=resolve_threads(threads))

    if name == "amg":
        check_solver_installed(name)
        return baselines.AMGSolver(tol=tol, maxiter=maxiter or 500)
    return baselines.DirectSolver()


def check_solver_installed(name: str) -> None:
    """ClothInputError naming the extra that solver `name` needs and this install lacks
    (amg: pyamg, the bench extra); the others need nothing beyond the package."""
    if name == "amg":
        require_extra("pyamg", "solver 'amg'")
