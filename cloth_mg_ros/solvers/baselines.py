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
from cloth_mg_ros.solvers.cg import SolveResult
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
           fixed: np.ndarray | None):
    """(n, x (3n,) from x0, b (3n,), pinned dof indices (k,), ||S b|| or 1 when zero)."""
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
    bnorm = float(np.linalg.norm(sb))
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

    Measured on real systems (cotton, h = 1/60 s, BDF2 step after 12 steps: the drape with 505
    sphere contacts, the hang with its 2 pins; tol 1e-4, one core, OPENBLAS_NUM_THREADS=1, a
    shared 2-core machine so +-15% noise, best of 3). ms as setup + CG = total, then CG
    iterations; setup includes assembling the filtered BSR matrix (~10-25 ms at 20K):

    ======================================  =====================  =====================
    variant (20K particles)                 drape                  hang
    ======================================  =====================  =====================
    PyAMG defaults (block GS, improve B)    491 + 837 = 1328, 24   470 + 1397 = 1868, 40
    defaults, ``aspreconditioner`` in CG    583 + 864 = 1448, 24   517 + 1494 = 2011, 40
    no improve_candidates                   321 + 788 = 1109, 24   213 + 1502 = 1715, 40
    + 'local' Jacobi weighting              113 + 757 =  870, 23   153 + 1665 = 1819, 41
    + 'block' weighting instead             320 + 639 =  959, 19   232 + 1453 = 1685, 39
    + energy-min. smoothing instead         249 + 637 =  886, 18   265 +  905 = 1170, 26
    unsmoothed aggregation                   96 + 984 = 1080, 31    47 + 2487 = 2535, 78
    CSR input (aggregation per unknown)     484 + 604 = 1089, 41   298 +  604 =  902, 40
    local + CSR scalar sym. GS, theta 0     111 + 528 =  639, 41   114 +  530 =  644, 41
    same, theta 0.08                        118 + 546 =  664, 41   148 +  393 =  542, 32
    same, max_coarse 500 + splu (chosen)    105 + 504 =  610, 41   108 +  371 =  479, 26
    chosen, 2 sweeps each side              183 + 872 = 1056, 29   125 +  696 =  821, 28
    chosen, forward / backward GS           137 + 547 =  684, 58   134 +  377 =  511, 36
    chosen, PyAMG block GS fwd / bwd        127 + 575 =  702, 27   134 +  850 =  984, 38
    chosen, energy-min. smoothing           186 + 474 =  661, 40   201 +  277 =  480, 21
    chosen, 'evolution' strength            610 + 531 = 1142, 41   373 +  422 =  798, 28
    chosen, theta 0.25                       84 + 2268 = 2352, 188  98 + 4899 = 4999, 323
    block-Jacobi PCG (reference)            607 ms, 517 it          619 ms, 811 it
    ======================================  =====================  =====================

    At 4.5K the chosen options took 26 + 87 = 114 ms, 24 it (drape, 2 levels) and 23 + 57 =
    80 ms, 19 it (hang), against PyAMG's defaults 57 + 127 = 183 ms, 20 it and 78 + 245 =
    323 ms, 31 it (block-Jacobi PCG: 66 ms, 295 it and 67 ms, 368 it). theta 0.04-0.15 and
    omega 1.0-1.6 were within the noise; scalar Jacobi, block Jacobi and Chebyshev smoothers
    took 2-5x the iterations. The V-cycles (about 12 ms per CG iteration at 20K) now dominate;
    rigid rotations in B would need the positions, which a BlockSystem does not carry.

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
              fixed: np.ndarray | None = None) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool marks pinned particles whose x0 is kept."""
        t0 = time.perf_counter()
        n, x, b, pin, bnorm = _setup(system, b, x0, fixed)
        ml = self.build(system, fixed)
        prec = self._preconditioner(ml)
        t1 = time.perf_counter()
        goal = self.tol * bnorm
        its = 0
        rnorm = np.inf
        for _ in range(4):  # a restart when the recurrence residual has drifted
            r = _filtered_residual(system, b, x, pin)
            rnorm = float(np.linalg.norm(r))
            if rnorm <= goal or its >= self.maxiter:
                break
            its_before = its
            z = prec(r)
            z[pin] = 0.0
            p = z.copy()
            rz = float(r @ z)
            while its < self.maxiter:
                q = system.matvec(p)
                q[pin] = 0.0
                pq = float(p @ q)
                its += 1
                if not pq > 0.0:  # breakdown (not SPD on the free subspace, or r = 0)
                    break
                alpha = rz / pq
                x += alpha * p
                r -= alpha * q
                if np.linalg.norm(r) <= goal:
                    break
                z = prec(r)
                z[pin] = 0.0
                rz_new = float(r @ z)
                p *= rz_new / rz
                p += z
                rz = rz_new
            if its == its_before + 1 and not pq > 0.0:
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

    Measured (ms: build + factor + solve, best of 3, one core, shared 2-core machine; the
    filtered matrix of a cotton drape on the sphere and of the two-pin hang, tol irrelevant):

    ===================================  ========  ========  ==========  =========
    solver                               drape 4.5K hang 4.5K drape 20K  hang 20K
    ===================================  ========  ========  ==========  =========
    cvxopt CHOLMOD supernodal (chosen)         97        70        715        667
    cvxopt CHOLMOD simplicial                 396       580      12309       9425
    sksparse-minimal (CHOLMOD, ref. BLAS)     193       270       2949       1493
    cholespy (CHOLMOD, ref. BLAS)             468       250       4933       4269
    splu MMD_AT_PLUS_A, SPD options           219       238       2721       2895
    splu MMD_AT_PLUS_A, partial pivoting    25079       314          -          -
    splu COLAMD                               464       448       7918       6241
    spsolve (SuperLU, use_umfpack=False)      515       444       7626       6116
    qdldl (LDL^T, AMD)                        325       541       7827       7433
    pypardiso mtype 2 (SPD), 1 MKL thread     183       179       1047       1243
    pypardiso mtype 11 (default)              279       260       2039       2035
    ===================================  ========  ========  ==========  =========

    Through this class (assembly from the blocks included, best of 5) 'auto' took 59, 96, 644
    and 593 ms, 'splu' 213, 288, 2798 and 2461 ms. The supernodal factorisation needs an
    optimised BLAS: sksparse-minimal and cholespy bundle CHOLMOD with the reference BLAS and
    are 2-7x slower. pypardiso needs the ``mkl`` wheel (221 MB download, about 900 MB
    installed with its dependencies) and was still slower. scikit-sparse has no wheel (it
    needs SuiteSparse from the system), nor has scikit-umfpack.
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
              fixed: np.ndarray | None = None) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool marks pinned particles whose x0 is kept."""
        t0 = time.perf_counter()
        n, x, b, pin, bnorm = _setup(system, b, x0, fixed)
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
