"""Geometric multigrid on the subdivision hierarchy: V-cycles and multigrid-preconditioned CG.

Modelled on PyAMG's multilevel solver: a list of levels, each holding its system A, the
transfer to the next level (parents, giving P and R = P^T) and its smoother; the coarsest
level is solved exactly. Two ways to use it:

* ``cycle='vcycle'``: the paper's stand-alone V-cycles until the relative residual reaches
  ``tol`` (with ``smoother='cg'``, CG on every level until its residual drops by
  ``smooth_ratio``, 0.4 in the paper);
* ``cycle='pcg'``: CG preconditioned by one symmetric V-cycle (forward Gauss-Seidel before,
  backward after), which needs a fixed linear preconditioner, so no CG smoothing there.

Pinned particles: the outer iteration filters them exactly (Baraff-Witkin); inside the
hierarchy they become stiff penalties on their diagonal blocks, which coarsen like mass.
Contacts already are diagonal penalties, so every level sees them consistently.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla
from numba import njit

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.bending import BendingTerms
from cloth_mg_ros.physics.system import BlockSystem, bs_matvec
from cloth_mg_ros.solvers.cg import (
    SolveResult,
    block_jacobi_inverse,
    cg_direction,
    cg_iterations,
    cg_step,
    filtered_dot,
    pcg_kernel,
)
from cloth_mg_ros.solvers.cholesky import SparseCholesky, cholmod_available
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening, GalerkinCoarsening
from cloth_mg_ros.solvers.first_guess import (
    rigid_guess,
    rigid_shift,
    translate_rows,
    translation_guess,
)
from cloth_mg_ros.solvers.packed_kernels import (
    cg_update,
    direction_update,
    full_residual,
    residual_rows,
    touched_rows,
    vcycle_down,
    vcycle_up,
)
from cloth_mg_ros.solvers.packed_levels import PackedLevel, PackedLevels, scalar_pairs
from cloth_mg_ros.solvers.smoothers import (
    Adjacency,
    block_jacobi_sweep,
    pack_rows,
    pack_symmetric,
    packed_gauss_seidel,
    packed_residual,
    residual,
)
from cloth_mg_ros.solvers.transfer_ops import prolong_add, restrict

PIN_PENALTY = 1e4  # pinned diagonal blocks inside the hierarchy, times their own size
DENSE_COARSE_DOFS = 900  # factor the coarsest level densely up to this many unknowns
SMOOTHERS = ("gs", "jacobi", "cg")
CYCLES = ("vcycle", "pcg")
# Iterations one CG smoothing pass may take to drop its residual by smooth_ratio: a bound,
# not a working figure. A pass to the paper's 0.4 takes 7-8 on average on the 1.2K drape and
# hang sheets ('mg', 20 steps), 92 at the most; 200 stays clear of that and keeps a pass on a
# level that has lost positive definiteness from running on.
CG_SMOOTH_MAXITER = 200


def _check_settings(tol, maxiter, sweeps, smooth_ratio, parts) -> None:
    """ClothInputError naming the first impossible setting: tol and smooth_ratio must lie in
    (0, 1), maxiter, sweeps and parts be integers >= 1."""
    for name, value in (("tol", tol), ("smooth_ratio", smooth_ratio)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
                or not 0.0 < value < 1.0:
            raise ClothInputError(f"multigrid {name} must be a number in (0, 1), got {value!r}")
    for name, value in (("maxiter", maxiter), ("sweeps", sweeps), ("parts", parts)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ClothInputError(f"multigrid {name} must be an integer >= 1, got {value!r}")


@dataclass
class Level:
    """One level of a solve: its system, inverse diagonal blocks (n, 3, 3), filter (n,),
    adjacency, the pair blocks packed by rows for the smoothers (2m, 6) float32, the packed
    diagonal blocks and their inverses (n, 6), and the parents map down to the next level
    (None on the coarsest)."""

    system: BlockSystem
    full: np.ndarray
    dinv: np.ndarray
    free: np.ndarray
    adj: Adjacency
    rows: np.ndarray
    diag6: np.ndarray
    dinv6: np.ndarray
    parents: np.ndarray | None
    work: np.ndarray  # (n, 3) scratch for residuals


@njit(cache=True, nogil=True)
def _pinned_traces(diag, pairs, offd, fixed, out):
    """out (n,): trace(A_ii) = trace(B_i) - sum_j trace(G_ij) where fixed (n,) is set
    (elsewhere untouched): the pair blocks subtracted in pair order, first where i is a
    pair's first end, then where it is its second (the order of the sums as they were made
    with numpy; a pinned row's size scales its penalty, and a last bit of it can change
    which way a dressing run goes)."""
    for i in range(diag.shape[0]):
        if fixed[i]:
            out[i] = diag[i, 0, 0] + diag[i, 1, 1] + diag[i, 2, 2]
    for end in range(2):
        for p in range(pairs.shape[0]):
            i = pairs[p, end]
            if fixed[i]:
                out[i] -= offd[p, 0, 0] + offd[p, 1, 1] + offd[p, 2, 2]


@njit(cache=True, nogil=True)
def _pinned_traces_at(diag, pairs, offd, rows, ends, n_mesh, out):
    """`_pinned_traces` for the rows `rows` (k,), their mesh pairs looked up in `ends`
    (`pair_ends` of the system's first n_mesh pairs) and the pairs beyond those (cloth-cloth
    springs) scanned: per row and end the same pairs in the same order."""
    for q in range(rows.shape[0]):
        i = rows[q]
        out[i] = diag[i, 0, 0] + diag[i, 1, 1] + diag[i, 2, 2]
    for end in range(2):
        ptr = ends[2 * end]
        idx = ends[2 * end + 1]
        for q in range(rows.shape[0]):
            i = rows[q]
            for k in range(ptr[i], ptr[i + 1]):
                p = idx[k]
                out[i] -= offd[p, 0, 0] + offd[p, 1, 1] + offd[p, 2, 2]
        for p in range(n_mesh, pairs.shape[0]):
            i = pairs[p, end]
            for q in range(rows.shape[0]):
                if rows[q] == i:
                    out[i] -= offd[p, 0, 0] + offd[p, 1, 1] + offd[p, 2, 2]


def pair_ends(pairs: np.ndarray, n: int) -> tuple:
    """(ptr_first (n + 1,), pairs_first, ptr_second, pairs_second): for every vertex the pairs
    (m, 2) whose first (second) end it is, in ascending order."""
    out = []
    for end in range(2):
        who = np.asarray(pairs[:, end], dtype=np.int64)
        order = np.argsort(who, kind="stable").astype(np.int64)
        ptr = np.zeros(n + 1, dtype=np.int64)
        np.add.at(ptr, who + 1, 1)
        out += [np.cumsum(ptr), order]
    return tuple(out)


def pinned_diagonal_size(system: BlockSystem, fixed: np.ndarray, ends: tuple | None = None,
                         n_mesh: int = 0) -> np.ndarray:
    """|trace(A_ii)| / 3 of the full diagonal block of each pinned particle (fixed (n,) bool),
    from the pairs that touch one (a few hundred of a garment's 100K). ends: `pair_ends` of
    the system's first n_mesh pairs (the mesh's, which come first), to look them up instead
    of passing over every pair (0.14 ms at 20K particles)."""
    fixed = np.asarray(fixed, dtype=bool)
    full = np.zeros(system.n)
    if ends is not None and len(system.pairs) >= n_mesh:
        _pinned_traces_at(system.diag, system.pairs, system.offd, np.flatnonzero(fixed), ends,
                          n_mesh, full)
    else:
        _pinned_traces(system.diag, system.pairs, system.offd, fixed, full)
    return np.abs(full[fixed]) / 3.0


class CoarseSolver:
    """Exact solve on the coarsest level: CHOLMOD's sparse Cholesky (several times faster to
    factor a garment's coarsest level than a dense Cholesky or SuperLU;
    doc/design-measurements.md, 'The coarsest solve', has the figures); without cvxopt, dense
    Cholesky when small, sparse LU otherwise."""

    def __init__(self, system: BlockSystem, symbolic=None, pattern=None):
        self.n = system.n
        self.dense = self.lu = self.chol = None
        # CHOLMOD's analysis and matrix, for the next factorisation of this pattern
        self.symbolic = self.pattern = None
        if cholmod_available():
            try:
                self.chol = SparseCholesky(system, symbolic=symbolic, pattern=pattern)
                self.symbolic, self.pattern = self.chol.symbolic, self.chol.pattern
                return
            except ArithmeticError:  # not positive definite: let LU try
                pass
        A = system.to_csr()
        if A.shape[0] <= DENSE_COARSE_DOFS:
            self.dense = sla.cho_factor(A.toarray(), check_finite=False)
        else:
            self.lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")

    def solve(self, b: np.ndarray) -> np.ndarray:
        flat = b.reshape(-1)
        if self.chol is not None:
            x = self.chol.solve(flat)
        elif self.dense is not None:
            x = sla.cho_solve(self.dense, flat, check_finite=False)
        else:
            x = self.lu.solve(flat)
        return x.reshape(-1, 3)


class MultigridSolver:
    """Multigrid for the cloth system on a mesh hierarchy.

    hierarchy: the mesh hierarchy (levels[0] is the simulated mesh); bending: the model's
    bending stencils, ``model.bending`` (faithful coarsening needs them); levels: how many levels to
    use, at most: a number above the hierarchy's depth takes all its levels (on purpose: a
    garment's coarser rungs, sim.detail, run on the part of its hierarchy below them with the
    options' one ``levels``); coarsening: 'faithful' or 'galerkin'; cycle: 'vcycle' or 'pcg';
    smoother: 'gs', 'jacobi' or 'cg'; sweeps: smoothing sweeps before and after the coarse
    correction (with 'cg': CG passes, each until its residual drops by smooth_ratio, in
    (0, 1)); tol: relative residual, in (0, 1); maxiter: cycles or CG iterations; parts: with
    cycle 'pcg' and smoother 'gs', sweep each level in this many parts at once (threads),
    then a separator (solvers.dissection; 1: the natural order). Impossible values raise
    ClothInputError.

    Two storages, one hierarchy. The default (cycle 'pcg', smoother 'gs': ``mpcg``) packs
    every level into flat arrays (solvers.packed_levels) that a few kernels sweep; `levels`
    gives them as PackedLevel views after a solve, and ``print(solver.packed)`` prints them
    as PyAMG prints ``ml``. The unpacked path (`setup`, a list of Level objects, and
    `vcycle`) serves the paper's stand-alone V-cycles (``mg``), the Jacobi and CG smoothers,
    `aspreconditioner` and the tests that check the hierarchy level by level.
    """

    def __init__(self, hierarchy: MeshHierarchy, bending: BendingTerms | None = None,
                 levels: int = 3, coarsening: str = "faithful", cycle: str = "pcg",
                 smoother: str = "gs", sweeps: int = 1, smooth_ratio: float = 0.4,
                 tol: float = 1e-4, maxiter: int = 500, name: str = "mpcg",
                 parts: int = 1):
        if cycle not in CYCLES:
            raise ClothInputError(f"multigrid cycle must be one of {CYCLES}, got {cycle!r}")
        if smoother not in SMOOTHERS:
            raise ClothInputError(f"smoother must be one of {SMOOTHERS}, got {smoother!r}")
        if cycle == "pcg" and smoother == "cg":
            raise ClothInputError("CG smoothing is not a fixed linear preconditioner; "
                                  "use smoother 'gs' or 'jacobi' with cycle 'pcg'")
        _check_settings(tol, maxiter, sweeps, smooth_ratio, parts)
        if coarsening == "faithful":
            if bending is None:
                raise ClothInputError("faithful coarsening needs the model's bending stencils")
            self.coarsening = FaithfulCoarsening(hierarchy, bending, levels)
        elif coarsening == "galerkin":
            self.coarsening = GalerkinCoarsening(hierarchy, levels)
        else:
            raise ClothInputError(f"coarsening must be 'faithful' or 'galerkin', got "
                                  f"{coarsening!r}")
        self.hierarchy = hierarchy
        self.n_levels = self.coarsening.levels
        self.cycle, self.smoother, self.sweeps = cycle, smoother, int(sweeps)
        self.smooth_ratio, self.tol, self.maxiter = float(smooth_ratio), float(tol), int(maxiter)
        self.name = name
        # MG-preconditioned CG sweeps each level in `parts` parts at once, then a separator
        # (solvers.dissection): the iterates depend on `parts`, never on the threads.
        self.parts = int(parts)
        self._parents = [np.ascontiguousarray(t.parents) for t in hierarchy.transfers]
        self._adj_cache: dict[int, tuple[np.ndarray, Adjacency]] = {}
        # Single-precision smoother blocks halve the memory traffic; fine for a preconditioner
        # (the outer CG is exact), but stand-alone cycles would converge to the rounded
        # matrix's solution, so they keep double precision.
        self._rows_dtype = np.float32 if cycle == "pcg" else np.float64
        self.last_setup_ms = 0.0
        # MG-preconditioned CG with Gauss-Seidel runs on flat arrays, a few kernels per
        # iteration (solvers.packed_levels); the other variants keep the level list.
        self._packed: PackedLevels | None = None
        # (coarsest pairs, CHOLMOD analysis, CHOLMOD matrix)
        self._coarse_key: tuple | None = None
        self._pair_ends: tuple | None = None  # the finest mesh's pairs by vertex and end

    # -- set-up of one solve ------------------------------------------------------------
    def _adjacency(self, lvl: int, system: BlockSystem) -> Adjacency:
        cached = self._adj_cache.get(lvl)
        if cached is not None and cached[0] is system.pairs:
            return cached[1]
        if cached is not None and np.array_equal(cached[0], system.pairs):
            return cached[1]
        adj = Adjacency.from_pairs(system.pairs, system.n)
        self._adj_cache[lvl] = (system.pairs, adj)
        return adj

    def setup(self, system: BlockSystem, fixed: np.ndarray | None) -> list[Level]:
        """Coarsen one step's system and prepare every level's smoother and the coarse solve."""
        work = system
        if fixed is not None and np.any(fixed):
            work = system.copy()
            # pinned_diagonal_size gives these sizes up to rounding (its traces are summed in
            # another order: last-bit differences on the drape and hang sheets); kept so that
            # 'mg' and 'galerkin' stay bit for bit what they were.
            full = system.full_diagonal()
            size = np.abs(np.trace(full, axis1=1, axis2=2))[fixed] / 3.0
            work.diag[fixed] += (PIN_PENALTY * size)[:, None, None] * np.eye(3)[None]
        systems = self.coarsening.coarsen(work)
        levels = []
        for lvl, sysl in enumerate(systems):
            free = np.ones(sysl.n)
            if lvl == 0 and fixed is not None:
                free[np.asarray(fixed, dtype=bool)] = 0.0
            full = sysl.full_diagonal()
            dinv = np.empty_like(full)
            block_jacobi_inverse(full, free, dinv)
            adj = self._adjacency(lvl, sysl)
            rows = np.empty((len(adj.pair), 6), dtype=self._rows_dtype)
            pack_rows(adj.pair, sysl.offd, rows)
            diag6 = np.empty((sysl.n, 6))
            pack_symmetric(full, diag6)
            dinv6 = np.empty((sysl.n, 6))
            pack_symmetric(dinv, dinv6)
            parents = self._parents[lvl] if lvl < len(systems) - 1 else None
            levels.append(Level(sysl, full, dinv, free, adj, rows, diag6, dinv6, parents,
                                np.empty((sysl.n, 3))))
        self._coarse = CoarseSolver(systems[-1]) if len(systems) > 1 else None
        return levels

    # -- the cycle ------------------------------------------------------------------------
    def _smooth(self, lv: Level, b: np.ndarray, x: np.ndarray, pre: bool) -> None:
        s = lv.system
        if self.smoother == "gs":
            for _ in range(self.sweeps):
                packed_gauss_seidel(lv.dinv6, lv.adj.ptr, lv.adj.nbr, lv.rows, b, x, lv.free, pre)
        elif self.smoother == "jacobi":
            for _ in range(self.sweeps):
                block_jacobi_sweep(lv.dinv, s.diag, s.pairs, s.offd, b, x, lv.free, 2.0 / 3.0,
                                   lv.work)
        else:  # `sweeps` passes of CG on the error equation, each to a smooth_ratio drop
            r = lv.work
            for _ in range(self.sweeps):
                residual(s.diag, s.pairs, s.offd, b, x, lv.free, r)
                e = np.zeros_like(x)
                pcg_kernel(s.diag, lv.full, s.pairs, s.offd, lv.dinv, r, e, lv.free,
                           self.smooth_ratio, 0.0, CG_SMOOTH_MAXITER, 0)
                x += e

    def vcycle(self, levels: list[Level], lvl: int, b: np.ndarray, x: np.ndarray) -> None:
        """Improve x (n_lvl, 3) in place towards A_lvl^-1 b by one V-cycle."""
        lv = levels[lvl]
        if lvl == len(levels) - 1:
            if self._coarse is not None:
                x[:] = self._coarse.solve(b)
            else:  # a one-level "hierarchy": symmetric smoothing only (a valid CG preconditioner)
                self._smooth(lv, b, x, True)
                self._smooth(lv, b, x, False)
            return
        self._smooth(lv, b, x, True)
        r = lv.work
        packed_residual(lv.diag6, lv.adj.ptr, lv.adj.nbr, lv.rows, b, x, lv.free, r)
        nxt = levels[lvl + 1]
        rc = np.empty((nxt.system.n, 3))
        restrict(lv.parents, r, rc)
        ec = np.zeros_like(rc)
        self.vcycle(levels, lvl + 1, rc, ec)
        # the coarse correction must not move pinned particles (free == 0)
        prolong_add(lv.parents, ec, x, lv.free)
        self._smooth(lv, b, x, False)

    # -- the hierarchy as data (PyAMG's print(ml) and ml.aspreconditioner()) -------------
    @property
    def packed(self) -> PackedLevels | None:
        """The packed levels of the last packed solve (None before one)."""
        return self._packed

    @property
    def levels(self) -> list[PackedLevel]:
        """The packed levels of the last solve, finest first, as PackedLevel views ([]
        before the first packed solve)."""
        return [] if self._packed is None else self._packed.levels

    def summary(self, system: BlockSystem) -> str:
        """The levels this solver builds for one step's `system`: per level its particles,
        unknowns and nonzero 3 x 3 blocks (diagonal and both triangles), the operator and
        grid complexities (the levels' nonzeros and unknowns over the finest's) and the
        coarsest level's solve, as PyAMG prints a multilevel solver."""
        systems = self.coarsening.coarsen(system)
        nnz = [s.n + 2 * len(s.pairs) for s in systems]
        coarse = "smoothing only" if len(systems) == 1 else (
            "CHOLMOD sparse Cholesky" if cholmod_available() else
            "dense Cholesky" if 3 * systems[-1].n <= DENSE_COARSE_DOFS else "sparse LU")
        cycle = {"pcg": "CG preconditioned by one V-cycle", "vcycle": "V-cycles"}[self.cycle]
        lines = [f"MultigridSolver {self.name!r}: {type(self.coarsening).__name__}, {cycle}, "
                 f"smoother {self.smoother} x{self.sweeps}, tol {self.tol:g}",
                 f"levels: {len(systems)}; operator complexity "
                 f"{sum(nnz) / nnz[0]:.3f}; grid complexity "
                 f"{sum(s.n for s in systems) / systems[0].n:.3f}; coarsest solve: {coarse}",
                 "  level  particles  unknowns  nonzero blocks  [%]"]
        lines += [f"  {k:5d}  {s.n:9d}  {3 * s.n:8d}  {z:14d}  {100 * z / sum(nnz):5.2f}"
                  for k, (s, z) in enumerate(zip(systems, nnz, strict=True))]
        return "\n".join(lines)

    def aspreconditioner(self, system: BlockSystem, fixed: np.ndarray | None = None):
        """One V-cycle from a zero guess on `system` (pinned particles `fixed` (n,) bool held
        at zero) as a scipy LinearOperator on flat (3n,) vectors: a fixed, symmetric
        preconditioner for any Krylov method (scipy.sparse.linalg.cg(A, b, M=...))."""
        levels = self.setup(system, fixed)
        n = system.n

        def apply(r: np.ndarray) -> np.ndarray:
            x = np.zeros((n, 3))
            self.vcycle(levels, 0, np.ascontiguousarray(r, dtype=np.float64).reshape(n, 3), x)
            return x.reshape(-1)

        return spla.LinearOperator((3 * n, 3 * n), matvec=apply, dtype=np.float64)

    # -- the solve ------------------------------------------------------------------------
    def solve(self, system: BlockSystem, b: np.ndarray, x0: np.ndarray | None = None,
              fixed: np.ndarray | None = None, floor: float = 0.0) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool pinned particles keep their x0 values; the
        residual measured against max(||S b||, floor) (solvers.cg's docstring)."""
        n = system.n
        if n != self.hierarchy.levels[0].n_vertices:
            raise ClothInputError(f"system has {n} particles but the hierarchy's finest level "
                                  f"{self.hierarchy.levels[0].n_vertices}")
        t0 = time.perf_counter()
        fixed_mask = None if fixed is None else np.asarray(fixed, dtype=bool)
        if self.cycle == "pcg" and self.smoother == "gs":
            return self._solve_packed(system, b, x0, fixed_mask, t0, floor)
        levels = self.setup(system, fixed_mask)
        self.last_setup_ms = 1e3 * (time.perf_counter() - t0)
        x = np.zeros((n, 3)) if x0 is None else np.array(x0, dtype=np.float64).reshape(n, 3)
        b3 = np.ascontiguousarray(b, dtype=np.float64).reshape(n, 3)
        free = levels[0].free
        sb = b3 * free[:, None]
        bnorm = max(float(np.linalg.norm(sb)), float(floor)) or 1.0
        if self.cycle == "vcycle":
            return self._solve_cycles(levels, system, b3, x, free, bnorm)
        return self._solve_pcg(levels, system, b3, x, free, bnorm)

    def _solve_cycles(self, levels, system, b, x, free, bnorm) -> SolveResult:
        r = np.empty_like(x)
        pinned = free == 0.0
        keep = x[pinned].copy()
        residual(system.diag, system.pairs, system.offd, b, x, free, r)
        rel = float(np.linalg.norm(r)) / bnorm
        its = 0
        while rel > self.tol and its < self.maxiter:
            self.vcycle(levels, 0, b, x)
            x[pinned] = keep
            residual(system.diag, system.pairs, system.offd, b, x, free, r)
            rel = float(np.linalg.norm(r)) / bnorm
            its += 1
            if not np.isfinite(rel):
                break
        return SolveResult(x, its, rel, bool(rel <= self.tol))

    def _solve_pcg(self, levels, system, b, x, free, bnorm) -> SolveResult:
        r = np.empty_like(x)
        residual(system.diag, system.pairs, system.offd, b, x, free, r)
        rel = float(np.linalg.norm(r)) / bnorm
        if rel <= self.tol:
            return SolveResult(x, 0, rel, True)
        z = np.zeros_like(x)
        p = np.empty_like(x)
        q = np.empty_like(x)

        def direction(beta: float, first: bool) -> float:
            if first:
                p[:] = z
            else:
                cg_direction(p, z, beta)
            bs_matvec(system.diag, system.pairs, system.offd, p, q)
            return filtered_dot(q, p, free)

        def precondition() -> float:
            z[:] = 0.0
            self.vcycle(levels, 0, r, z)
            return filtered_dot(z, r, free)

        its, rel = cg_iterations(direction, lambda alpha: cg_step(x, r, p, q, alpha),
                                 precondition, precondition(), rel, bnorm, self.tol,
                                 self.maxiter)
        return SolveResult(x, its, rel, bool(rel <= self.tol))

    # -- MG-preconditioned CG on packed levels ----------------------------------------------
    def _coarse_systems(self, system: BlockSystem, fixed: np.ndarray | None) -> list:
        """The step's systems on every level, pinned particles as stiff penalties inside the
        hierarchy (only the diagonal blocks are copied)."""
        work = system
        if fixed is not None and np.any(fixed):
            mesh = self.hierarchy.levels[0]
            if self._pair_ends is None:
                self._pair_ends = pair_ends(mesh.pairs, mesh.n_vertices)
            size = pinned_diagonal_size(system, fixed, self._pair_ends, len(mesh.pairs))
            diag = system.diag.copy()
            diag[fixed] += (PIN_PENALTY * size)[:, None, None] * np.eye(3)[None]
            work = BlockSystem(diag, system.pairs, system.offd, system.hess_scale)
        return self.coarsening.coarsen(work)

    def _coarse_solver(self, coarsest: BlockSystem) -> CoarseSolver:
        """Factor the coarsest level, reusing CHOLMOD's analysis while its pattern holds."""
        key = self._coarse_key
        same = key is not None and key[0] is coarsest.pairs
        solver = CoarseSolver(coarsest, key[1] if same else None, key[2] if same else None)
        self._coarse_key = ((coarsest.pairs, solver.symbolic, solver.pattern)
                            if solver.symbolic else None)
        return solver

    def _fill_packed(self, system: BlockSystem, fixed: np.ndarray | None):
        """The packed levels (made on first use) filled with this system's coarse systems,
        and the coarsest level's direct solver (None for a single level)."""
        systems = self._coarse_systems(system, fixed)
        if self._packed is None:
            sizes = [s.n for s in systems]
            meshes = self.hierarchy.levels[: len(sizes)]
            self._packed = PackedLevels(sizes, self._parents[: len(sizes) - 1],
                                        [lv.rest for lv in meshes],
                                        [scalar_pairs(lv) for lv in meshes], self.parts)
        self._packed.fill(systems, fixed)
        coarse = self._coarse_solver(systems[-1]) if len(systems) > 1 else None
        return self._packed, coarse

    def _solve_packed(self, system: BlockSystem, b: np.ndarray, x0: np.ndarray | None,
                      fixed: np.ndarray | None, t0: float, floor: float = 0.0) -> SolveResult:
        """MG-preconditioned CG on packed levels (solvers.packed_kernels), in sweep order."""
        n = system.n
        pk, coarse = self._fill_packed(system, fixed)
        lo_c = int(pk.voff[-2])
        self.last_setup_ms = 1e3 * (time.perf_counter() - t0)

        fine = pk.fine_chunks
        free = pk.free[:n]
        x, b3, p, q, w = pk.outer
        if x0 is None:
            x.fill(0.0)
        else:
            pk.to_rows(np.asarray(x0, dtype=np.float64).reshape(n, 3), x)
        pk.to_rows(np.asarray(b, dtype=np.float64).reshape(n, 3), b3)
        bnorm = max(float(np.linalg.norm(b3 * free[:, None])), float(floor)) or 1.0
        # The residual lives in the finest level's right-hand side rows and the preconditioned
        # residual in its solution rows: the V-cycle reads and writes them there, no copies.
        r = pk.b[:n]
        slots = pk.slots
        touched = pk.touched
        touched_rows(n, slots, free, x, touched)
        rr = residual_rows(fine, slots, pk.diag6, pk.free, b3, x, r, touched)
        rr = _first_guess(pk, system, b3, x, r, rr)
        rel = float(np.sqrt(rr)) / bnorm
        if rel <= self.tol:
            return SolveResult(pk.from_rows(x), 0, rel, True)
        z = pk.x[:n]
        # w = S A z, formed by the V-cycle's last sweep; q = S A p by the recurrence
        # q = w + beta q. p and q start at zero (beta 0 on the first step must not meet a
        # non-finite value left by an earlier solve).
        p.fill(0.0)
        q.fill(0.0)
        levels = pk.n_levels

        def precondition() -> float:
            vcycle_down(levels, pk.voff, pk.bounds, pk.chunks, slots, pk.dinv6, pk.free,
                        pk.kids, r, pk.b, pk.x, pk.r)
            if coarse is not None:
                pk.x[lo_c:] = coarse.solve(pk.b[lo_c:])
            return vcycle_up(levels, pk.voff, pk.bounds, pk.chunks, slots, pk.dinv6, pk.diag6,
                             pk.free, pk.parents, pk.b, pk.x, r, z, w)

        its, rel = cg_iterations(
            lambda beta, first: direction_update(fine, z, w, beta, p, q),
            lambda alpha: cg_update(fine, x, r, p, q, alpha), precondition, precondition(),
            rel, bnorm, self.tol, self.maxiter)
        return SolveResult(pk.from_rows(x), its, rel, bool(rel <= self.tol))


def _first_guess(pk: PackedLevels, system: BlockSystem, b3: np.ndarray, x: np.ndarray,
                 r: np.ndarray, rr: float) -> float:
    """Move x (packed rows) by the first guess and return the new squared residual (rr if
    there is none): the rigid motion of the free particles nearest to the solution
    (solvers.first_guess), then the exact residual; the translations alone where the system
    carries no elastic forces for the rotations' products. Records which in pk.last_guess."""
    fine, slots, touched = pk.fine_chunks, pk.slots, pk.touched
    motion = None
    if system.rotation is not None and system.hess_scale is not None:
        motion = rigid_guess(pk, touched, r, system.rotation, system.hess_scale)
    pk.last_guess = None
    if motion is not None:
        rigid_shift(fine, pk.free, pk.rigid_rows[0], motion, x)
        pk.last_guess = "rigid"
        return full_residual(fine, slots, pk.diag6, pk.free, b3, x, r)
    shift = translation_guess(pk, touched, r)
    if shift is not None:
        pk.last_guess = "translation"
        return translate_rows(fine, slots, pk.bdiag6, pk.free, touched, shift, x, r)
    return rr
