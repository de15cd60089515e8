"""Baseline solvers on the same matrices and stopping rule: PyAMG smoothed aggregation as a CG
preconditioner, and a sparse direct solve (the accuracy reference).

Both solve the Baraff-Witkin filtered system. S zeroes pinned particles; with x = x0 + y,

    (S A S + (I - S)) y = S (b - A x0),

so pinned unknowns keep their x0 values and the residual reported is ||S(b - A x)|| / ||S b||,
as for every other solver in this package.
"""

from __future__ import annotations

import time
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cloth_mg_ros.physics.system import BlockSystem
from cloth_mg_ros.solvers.cg import SolveResult, cg_iterations
from cloth_mg_ros.solvers.cholesky import SparseCholesky, cholmod_available

__all__ = [
    "AMGSolver",
    "DirectSolver",
    "filtered_bsr",
    "rigid_translations",
]

_EYE3 = np.eye(3)


class _BlockPattern:
    """The sorted BSR structure of A for one ``pairs`` array (fixed for a model), so that
    assembling A each step is one gather instead of a sort.

    ``order`` sorts the blocks [diagonal (n), G_ij at (i, j) (m), G_ij^T at (j, i) (m)] by
    (row, column); ``diag_slot`` says where each diagonal block lands.
    """

    def __init__(self, n: int, pairs: np.ndarray):
        self.n = n
        self.pairs = np.array(pairs, dtype=np.int64, copy=True)
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        rows = np.concatenate([np.arange(n), i, j])
        cols = np.concatenate([np.arange(n), j, i])
        order = np.lexsort((cols, rows))
        self.order = order
        self.rows = rows[order]
        self.indices = cols[order]
        self.indptr = np.searchsorted(self.rows, np.arange(n + 1))
        slot = np.empty_like(order)
        slot[order] = np.arange(len(order))
        self.diag_slot = slot[:n]  # where particle i's diagonal block lands

    def matches(self, n: int, pairs: np.ndarray) -> bool:
        return (n == self.n and pairs.shape == self.pairs.shape
                and np.array_equal(pairs, self.pairs))


def _pattern_for(cache: list, system: BlockSystem) -> _BlockPattern:
    """The cached pattern for ``system.pairs`` (rebuilt when the pairs change)."""
    if not cache or not cache[0].matches(system.n, system.pairs):
        cache[:] = [_BlockPattern(system.n, system.pairs)]
    return cache[0]


def filtered_bsr(system: BlockSystem, fixed: np.ndarray | None = None,
                 pattern: _BlockPattern | None = None) -> sp.bsr_matrix:
    """S A S + (I - S) as a (3n, 3n) BSR matrix with 3x3 blocks (A itself when nothing is
    pinned): rows and columns of pinned particles are zero except an identity diagonal block.
    """
    n = system.n
    pat = pattern if pattern is not None else _BlockPattern(n, system.pairs)
    offd = system.offd
    blocks = np.concatenate([system.full_diagonal(), offd, np.transpose(offd, (0, 2, 1))])
    blocks = np.take(blocks, pat.order, axis=0)
    if fixed is not None and np.any(fixed):
        fixed = np.asarray(fixed, dtype=bool)
        blocks[np.flatnonzero(fixed[pat.rows] | fixed[pat.indices])] = 0.0
        blocks[pat.diag_slot[fixed]] = _EYE3
    return sp.bsr_matrix((blocks, pat.indices, pat.indptr), shape=(3 * n, 3 * n))


def rigid_translations(n: int) -> np.ndarray:
    """The near-nullspace of the elastic part of A for PyAMG: the three rigid translations,
    (3n, 3), unknowns interleaved x, y, z per particle."""
    B = np.zeros((3 * n, 3))
    for a in range(3):
        B[a::3, a] = 1.0
    return B


def _setup(system: BlockSystem, b: np.ndarray, x0: np.ndarray | None,
           fixed: np.ndarray | None, floor: float = 0.0):
    """(n, x (3n,) from x0, b (3n,), pinned dof indices (k,), max(||S b||, floor) or 1 when
    zero: what the residual is measured against, solvers.cg's docstring)."""
    n = system.n
    x = np.zeros(3 * n) if x0 is None else np.array(x0, dtype=np.float64).reshape(3 * n)
    b = np.ascontiguousarray(b, dtype=np.float64).reshape(3 * n)
    if fixed is None:
        pin = np.zeros(0, dtype=np.int64)
    else:
        fixed = np.asarray(fixed, dtype=bool).reshape(n)
        pin = (3 * np.flatnonzero(fixed)[:, None] + np.arange(3)[None, :]).ravel()
    sb = b.copy()
    sb[pin] = 0.0
    bnorm = max(float(np.linalg.norm(sb)), float(floor))
    return n, x, b, pin, (bnorm if bnorm > 0.0 else 1.0)


def _filtered_residual(system: BlockSystem, b: np.ndarray, x: np.ndarray,
                       pin: np.ndarray) -> np.ndarray:
    r = b - system.matvec(x)
    r[pin] = 0.0
    return r


class AMGSolver:
    """PyAMG smoothed aggregation (SA) as the preconditioner of CG, set up anew every solve.

    The matrix changes every step, so the AMG setup is part of each solve's cost: it is timed
    in ``last_setup_ms`` (assembling the filtered matrix S A S + (I - S), the SA hierarchy, the
    smoother set-up); ``last_solve_ms`` times the CG loop, ``last_levels`` and
    ``last_operator_complexity`` describe the hierarchy. CG runs on the free unknowns (the
    filter S on every residual and preconditioned residual, pinned values kept from x0) and
    stops on ||S(b - A x)|| <= tol ||S b||, the rule of every solver here; ``iterations``
    counts CG iterations (one V-cycle each). The recurrence residual stops the loop; the true
    residual is then recomputed, reported, and CG restarted from x if it is still above tol.

    Chosen options (``DEFAULT_OPTIONS``):

    - input as BSR with 3x3 blocks and near-nullspace B = the 3 rigid translations, so strength
      and aggregation are per particle (the three unknowns of a particle stay together);
    - strength ('symmetric', theta=0.08); no candidate improvement (the translations are exact
      for the elastic part already); prolongation smoothing: one Jacobi step, omega 4/3, with
      the 'local' (Gershgorin-type) spectral weighting, which avoids the Arnoldi estimates of
      rho(D^-1 A) that dominate PyAMG's default setup;
    - max_coarse 500 with a SuperLU coarse solve (2-3 levels from 4.5K to 20K particles);
    - V(1,1) cycle, smoothing by one symmetric pointwise Gauss-Seidel sweep before and after,
      on CSR copies of the level matrices: PyAMG's 3x3 block Gauss-Seidel kernel costs about
      three scalar sweeps, and its fewer iterations do not pay for that;
    - the V-cycle is called directly (PyAMG's ``aspreconditioner`` wraps ``ml.solve``, which
      adds two fine-level residual products per application); ``aspreconditioner`` is the
      fallback should that private method go away.

    Why these options: each variant was timed, setup and CG together, on recorded drape and
    hang systems at 4.5K and 20K particles, and these were among the fastest on both. Nearby
    theta and omega made no difference beyond the noise; theta 0.25, and pointwise Jacobi,
    block Jacobi or Chebyshev smoothers, needed several times the iterations. The V-cycles
    now dominate a solve; rigid rotations in B would need the positions, which a BlockSystem
    does not carry. doc/design-measurements.md ('Solvers and baselines') has the figures.

    ``sa_options`` overrides entries of ``DEFAULT_OPTIONS``; ``csr_smoothing=False`` keeps
    PyAMG's smoothers on the BSR levels as set up by ``sa_options``.
    """

    DEFAULT_OPTIONS: ClassVar[dict] = {
        "symmetry": "hermitian",
        "strength": ("symmetric", {"theta": 0.08}),
        "aggregate": "standard",
        "smooth": ("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}),
        "improve_candidates": None,
        "max_coarse": 500,
        "coarse_solver": "splu",
        "keep": False,
    }
    SMOOTHER: ClassVar[tuple] = ("gauss_seidel", {"sweep": "symmetric", "iterations": 1})

    def __init__(self, tol: float = 1e-4, maxiter: int = 500, name: str = "amg",
                 sa_options: dict | None = None, csr_smoothing: bool = True):
        self.tol = float(tol)
        self.maxiter = int(maxiter)
        self.name = name
        self.options = {**self.DEFAULT_OPTIONS, **(sa_options or {})}
        self.csr_smoothing = bool(csr_smoothing)
        self.last_setup_ms = 0.0
        self.last_solve_ms = 0.0
        self.last_levels = 0
        self.last_operator_complexity = 0.0
        self._pattern: list = []

    def build(self, system: BlockSystem, fixed: np.ndarray | None = None):
        """The PyAMG multilevel solver for the filtered matrix of ``system``."""
        # imported here: pyamg (a baseline), loaded only when needed
        import pyamg
        from pyamg.relaxation.smoothing import change_smoothers

        A = filtered_bsr(system, fixed, _pattern_for(self._pattern, system))
        ml = pyamg.smoothed_aggregation_solver(A, B=rigid_translations(system.n),
                                               **self.options)
        if self.csr_smoothing:
            for level in ml.levels:
                level.A = level.A.tocsr()
            change_smoothers(ml, self.SMOOTHER, self.SMOOTHER)
        return ml

    @staticmethod
    def _preconditioner(ml):
        """r -> one V-cycle from zero on ml (the exact coarse solve for a one-level ml)."""
        if len(ml.levels) == 1:
            A0 = ml.levels[0].A
            return lambda r: np.asarray(ml.coarse_solver(A0, r)).reshape(-1)
        cycle = getattr(ml, "_MultilevelSolver__solve", None)
        if cycle is None:  # a PyAMG without the private cycle: its public wrapper
            return ml.aspreconditioner(cycle="V").matvec

        def apply(r):
            z = np.zeros_like(r)
            cycle(0, z, r, "V")
            return z
        return apply

    def solve(self, system: BlockSystem, b: np.ndarray, x0: np.ndarray | None = None,
              fixed: np.ndarray | None = None, floor: float = 0.0) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool marks pinned particles whose x0 is kept;
        floor: the residual's scale where ||S b|| is below it (solvers.cg's docstring)."""
        t0 = time.perf_counter()
        n, x, b, pin, bnorm = _setup(system, b, x0, fixed, floor)
        ml = self.build(system, fixed)
        prec = self._preconditioner(ml)
        t1 = time.perf_counter()
        its = 0
        rnorm = np.inf
        for _ in range(4):  # a restart when the recurrence residual has drifted
            r = _filtered_residual(system, b, x, pin)
            rnorm = float(np.linalg.norm(r))
            if rnorm <= self.tol * bnorm or its >= self.maxiter:
                break
            done, broke = _amg_cg(system, prec, pin, x, r, rnorm / bnorm, bnorm, self.tol,
                                  self.maxiter - its)
            its += done
            if broke and done == 0:  # no direction at all: restarting will not help
                break
        else:
            rnorm = float(np.linalg.norm(_filtered_residual(system, b, x, pin)))
        t2 = time.perf_counter()
        self.last_setup_ms = 1e3 * (t1 - t0)
        self.last_solve_ms = 1e3 * (t2 - t1)
        self.last_levels = len(ml.levels)
        self.last_operator_complexity = float(ml.operator_complexity())
        rel = rnorm / bnorm
        return SolveResult(x.reshape(n, 3), int(its), float(rel), bool(rel <= self.tol))


def _amg_cg(system: BlockSystem, prec, pin: np.ndarray, x: np.ndarray, r: np.ndarray,
            rel: float, bnorm: float, tol: float, maxiter: int) -> tuple[int, bool]:
    """One run of the shared CG loop (solvers.cg.cg_iterations) from x and its filtered
    residual r (flat, updated in place), preconditioned by ``prec``; pin: the pinned
    unknowns. Returns (iterations, whether it stopped on a breakdown)."""
    z = np.zeros_like(r)
    p = np.zeros_like(r)
    q = np.zeros_like(r)
    broke = [False]

    def precondition() -> float:
        z[:] = prec(r)
        z[pin] = 0.0
        return float(r @ z)

    def direction(beta: float, first: bool) -> float:
        if first:
            p[:] = z
        else:  # p = beta p + z, in place
            np.multiply(p, beta, out=p)
            np.add(p, z, out=p)
        q[:] = system.matvec(p)
        q[pin] = 0.0
        pq = float(p @ q)
        broke[0] = not pq > 0.0  # not SPD on the free subspace, or r = 0
        return pq if pq > 0.0 else 0.0

    def update(alpha: float) -> float:
        x[:] += alpha * p
        r[:] -= alpha * q
        return float(r @ r)

    its, _ = cg_iterations(direction, update, precondition, precondition(), rel, bnorm, tol,
                           maxiter)
    return its, broke[0]


class DirectSolver:
    """Sparse direct solve of the filtered system, the accuracy reference.

    x = x0 + y with (S A S + (I - S)) y = S (b - A x0); ``rel_residual`` ||S(b - A x)|| /
    ||S b|| is computed after the fact; ``iterations`` is 0; ``converged`` is True when the
    residual is finite. ``last_backend`` names what solved it, ``last_factor_ms`` the time of
    the assembly and factorisation.

    Backends, the fastest available first (``backend='auto'``):

    1. 'cholmod': CHOLMOD supernodal Cholesky (AMD ordering) through cvxopt (the ``cvxopt``
       wheel bundles SuiteSparse and OpenBLAS, about 65 MB installed); falls through when
       cvxopt is missing or the matrix is not positive definite.
    2. 'splu': SciPy's SuperLU tuned for SPD matrices (MMD on A^T + A, diagonal pivots,
       symmetric mode); on failure SuperLU with COLAMD and partial pivoting.

    Why this order: timed on the filtered matrices of a cotton drape and of the two-pin hang
    at 4.5K and 20K particles, cvxopt's supernodal CHOLMOD was the fastest of the backends
    tried (CHOLMOD simplicial, CHOLMOD through sksparse-minimal and cholespy, SuperLU with
    several orderings and options, qdldl, pypardiso), and SuperLU with the SPD options the
    fastest of SciPy's own. doc/design-measurements.md ('Solvers and baselines') has the
    figures. The supernodal factorisation needs an optimised BLAS: sksparse-minimal and
    cholespy bundle CHOLMOD with the reference BLAS and are up to several times slower.
    pypardiso needs the ``mkl`` wheel (221 MB download, about 900 MB installed with its
    dependencies) and was still slower. scikit-sparse has no wheel (it needs SuiteSparse from
    the system), nor has scikit-umfpack.
    The residual reached is 1e-14-1e-15 on the drape and 1e-11 on the hang, whose right-hand
    side is small next to the terms that cancel in it.
    """

    BACKENDS = ("auto", "cholmod", "splu")

    def __init__(self, name: str = "direct", backend: str = "auto"):
        if backend not in self.BACKENDS:
            raise ValueError(f"backend must be one of {self.BACKENDS}, got {backend!r}")
        if backend == "cholmod" and not cholmod_available():
            raise ImportError("backend 'cholmod' needs cvxopt (pip install cvxopt)")
        self.name = name
        self.backend = backend
        self.last_backend = ""
        self.last_factor_ms = 0.0
        self._pattern: list = []

    def _solve_cholmod(self, system, fixed, rhs):
        factor = SparseCholesky(system, fixed)
        t = time.perf_counter()
        return factor.solve(rhs), t

    def _solve_splu(self, system, fixed, rhs):
        A = filtered_bsr(system, fixed, _pattern_for(self._pattern, system)).tocsc()
        try:
            lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
            self.last_backend = "splu"
        except RuntimeError:  # a zero pivot: let SuperLU pivot
            lu = spla.splu(A, permc_spec="COLAMD")
            self.last_backend = "splu-colamd"
        t = time.perf_counter()
        return lu.solve(rhs), t

    def solve(self, system: BlockSystem, b: np.ndarray, x0: np.ndarray | None = None,
              fixed: np.ndarray | None = None, floor: float = 0.0) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool marks pinned particles whose x0 is kept;
        floor: the residual's scale where ||S b|| is below it (the reported residual's)."""
        t0 = time.perf_counter()
        n, x, b, pin, bnorm = _setup(system, b, x0, fixed, floor)
        rhs = _filtered_residual(system, b, x, pin)
        y = None
        if self.backend in ("auto", "cholmod") and cholmod_available():
            try:
                y, t1 = self._solve_cholmod(system, fixed, rhs)
                self.last_backend = "cholmod"
            except ArithmeticError:  # not positive definite
                if self.backend == "cholmod":
                    raise
        if y is None:
            y, t1 = self._solve_splu(system, fixed, rhs)
        self.last_factor_ms = 1e3 * (t1 - t0)
        y[pin] = 0.0
        x += y
        rel = float(np.linalg.norm(_filtered_residual(system, b, x, pin))) / bnorm
        return SolveResult(x.reshape(n, 3), 0, rel, bool(np.isfinite(rel)))
