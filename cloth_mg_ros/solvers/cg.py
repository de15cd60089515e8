"""Preconditioned conjugate gradients on the block-symmetric system, in numba.

Pinned particles are Baraff-Witkin filtered constraints: their unknowns are fixed at the
values given in x0, and the filter S (zero on pinned particles, identity elsewhere) is
applied to the residual and to every search direction, so CG works in the free subspace.
Stopping: ||S(b - A x)||_2 <= tol max(||S b||_2, floor), or the iteration cap. The floor (0
unless the caller gives one) is the scale below which b is no measure of the step: the
simulator gives the step's weight impulse (sim.integrator.StepSystem.weight_impulse), so a
sheet at rest, whose b is the vanishing imbalance of its weight and its membrane, is solved to
a fraction tol of its weight rather than of that imbalance.

`cg_iterations` is the one CG loop of the preconditioned solvers (multigrid's packed and
unpacked paths, PyAMG's baseline): each gives it its own direction, update and
preconditioner steps over its own storage. The Jacobi baseline keeps its whole loop in one
numba kernel (`pcg_kernel`): its thousands of cheap iterations would pay a Python call per
step otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from cloth_mg_ros.physics.system import BlockSystem, bs_full_matvec, bs_matvec

MATVEC_ALGORITHM1 = 0
MATVEC_STANDARD = 1


@dataclass
class SolveResult:
    """x (n, 3) the solution; iterations; rel_residual ||S r|| / ||S b||; converged."""

    x: np.ndarray
    iterations: int
    rel_residual: float
    converged: bool


@njit(cache=True, nogil=True)
def block_jacobi_inverse(full_diag, free, out):
    """out (n, 3, 3): inverse of each diagonal block on free particles, zero on pinned."""
    for i in range(full_diag.shape[0]):
        if free[i] == 0.0:
            out[i] = 0.0
        else:
            out[i] = np.linalg.inv(full_diag[i])


@njit(cache=True, nogil=True)
def _apply_block(pinv, r, z):
    for i in range(r.shape[0]):
        for a in range(3):
            z[i, a] = pinv[i, a, 0] * r[i, 0] + pinv[i, a, 1] * r[i, 1] + pinv[i, a, 2] * r[i, 2]


@njit(cache=True, nogil=True)
def _dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@njit(cache=True, nogil=True)
def _filter(v, free):
    for i in range(v.shape[0]):
        if free[i] == 0.0:
            v[i, 0] = 0.0
            v[i, 1] = 0.0
            v[i, 2] = 0.0


@njit(cache=True, nogil=True)
def cg_step(x, r, p, q, alpha):
    """x += alpha p, r -= alpha q; returns ||r||^2. Arrays (n, 3)."""
    s = 0.0
    for i in range(x.shape[0]):
        for a in range(3):
            x[i, a] += alpha * p[i, a]
            r[i, a] -= alpha * q[i, a]
            s += r[i, a] * r[i, a]
    return s


@njit(cache=True, nogil=True)
def cg_direction(p, z, beta):
    """p = z + beta p, (n, 3)."""
    for i in range(p.shape[0]):
        for a in range(3):
            p[i, a] = z[i, a] + beta * p[i, a]


@njit(cache=True, nogil=True)
def filtered_dot(a, b, free):
    """sum over free particles of a_i . b_i; zeroes a and b on pinned ones first."""
    s = 0.0
    for i in range(a.shape[0]):
        if free[i] == 0.0:
            for c in range(3):
                a[i, c] = 0.0
                b[i, c] = 0.0
        else:
            s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@njit(cache=True, nogil=True)
def _matvec(algo, diag, full_diag, pairs, offd, d, out):
    if algo == 0:
        bs_matvec(diag, pairs, offd, d, out)
    else:
        bs_full_matvec(full_diag, pairs, offd, d, out)


@njit(cache=True, nogil=True)
def pcg_kernel(diag, full_diag, pairs, offd, pinv, b, x, free, tol, floor, maxiter, algo):
    """Filtered block-Jacobi PCG, x (n, 3) updated in place; the residual is measured against
    max(||S b||, floor) (module docstring). Returns (iterations, rel_res):
    iterations counts the updates of x. A non-finite right-hand side or first residual
    returns (0, nan) at once, a residual turning non-finite stops with rel_res nan, and a
    breakdown (p . q <= 0 or not finite) stops before its update, so it is not counted."""
    n = b.shape[0]
    r = np.empty((n, 3))
    q = np.empty((n, 3))
    z = np.empty((n, 3))
    _matvec(algo, diag, full_diag, pairs, offd, x, q)
    for i in range(n):
        for a in range(3):
            r[i, a] = (b[i, a] - q[i, a]) * free[i]
    sb = b.copy()
    _filter(sb, free)
    bnorm = max(np.sqrt(_dot(sb, sb)), floor)
    if bnorm == 0.0:
        bnorm = 1.0
    rnorm = np.sqrt(_dot(r, r))
    # NaN or inf in b, x0 or A: every iteration would only carry it along
    if not (np.isfinite(bnorm) and np.isfinite(rnorm)):
        return 0, np.nan
    if rnorm <= tol * bnorm:
        return 0, rnorm / bnorm
    _apply_block(pinv, r, z)
    p = z.copy()
    rz = _dot(r, z)
    for it in range(maxiter):
        _matvec(algo, diag, full_diag, pairs, offd, p, q)
        _filter(q, free)
        pq = _dot(p, q)
        if not pq > 0.0:  # breakdown (or NaN): x is not updated this iteration
            return it, rnorm / bnorm
        alpha = rz / pq
        for i in range(n):
            for a in range(3):
                x[i, a] += alpha * p[i, a]
                r[i, a] -= alpha * q[i, a]
        rnorm = np.sqrt(_dot(r, r))
        if not np.isfinite(rnorm):
            return it + 1, np.nan
        if rnorm <= tol * bnorm:
            return it + 1, rnorm / bnorm
        _apply_block(pinv, r, z)
        rz_new = _dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            for a in range(3):
                p[i, a] = z[i, a] + beta * p[i, a]
    return maxiter, rnorm / bnorm


def cg_iterations(direction: Callable[[float, bool], float], update: Callable[[float], float],
                  precondition: Callable[[], float], rz: float, rel: float, bnorm: float,
                  tol: float, maxiter: int) -> tuple[int, float]:
    """Preconditioned CG from a first preconditioned residual: returns (iterations, relative
    residual ||r|| / bnorm).

    direction(beta, first): p = z + beta p (first: p = z) and q = A p; returns p . q.
    update(alpha): x += alpha p, r -= alpha q; returns r . r. precondition(): z = M r;
    returns r . z. rz: r . z of the first z; rel: the relative residual before the first
    iteration (returned if maxiter is 0). Stops at rel <= tol, a non-finite residual, a
    direction with p . q <= 0 (breakdown: not SPD on the free subspace, or r = 0), or
    maxiter iterations.
    """
    beta = 0.0
    its = 0
    while its < maxiter:
        pq = direction(beta, its == 0)
        if pq <= 0.0:
            break
        rr = update(rz / pq)
        its += 1
        rel = math.sqrt(rr) / bnorm
        if rel <= tol or not math.isfinite(rel):
            break
        rz_new = precondition()
        beta = rz_new / rz
        rz = rz_new
    return its, rel


class PCGSolver:
    """Jacobi-preconditioned CG on the block-symmetric system.

    tol: relative residual to reach; maxiter: iteration cap; preconditioner: 'block' (the
    inverse 3x3 diagonal blocks) or 'scalar' (the inverse diagonal entries, textbook Jacobi);
    matvec: 'algorithm1' (the paper's block-symmetric product) or 'standard' (one block
    product per stored block and per direction, the paper's Algorithm 2).
    """

    def __init__(self, tol: float = 1e-4, maxiter: int = 20000, preconditioner: str = "block",
                 matvec: str = "algorithm1", name: str = "bscg"):
        if preconditioner not in ("block", "scalar"):
            raise ValueError(f"preconditioner must be 'block' or 'scalar', got {preconditioner!r}")
        if matvec not in ("algorithm1", "standard"):
            raise ValueError(f"matvec must be 'algorithm1' or 'standard', got {matvec!r}")
        self.tol = float(tol)
        self.maxiter = int(maxiter)
        self.preconditioner = preconditioner
        self.algo = MATVEC_ALGORITHM1 if matvec == "algorithm1" else MATVEC_STANDARD
        self.name = name

    def solve(self, system: BlockSystem, b: np.ndarray, x0: np.ndarray | None = None,
              fixed: np.ndarray | None = None, floor: float = 0.0) -> SolveResult:
        """Solve A x = b; b (n, 3); fixed (n,) bool marks pinned particles whose x0 is kept;
        floor: the residual's scale where ||S b|| is below it (module docstring), b's units."""
        n = system.n
        x = np.zeros((n, 3)) if x0 is None else np.array(x0, dtype=np.float64).reshape(n, 3)
        free = np.ones(n) if fixed is None else (~np.asarray(fixed, dtype=bool)).astype(np.float64)
        full_diag = system.full_diagonal()
        pinv = np.empty_like(full_diag)
        if self.preconditioner == "block":
            block_jacobi_inverse(full_diag, free, pinv)
        else:
            pinv[:] = 0.0
            entries = np.diagonal(full_diag, axis1=1, axis2=2)  # (n, 3)
            for a in range(3):
                pinv[:, a, a] = free / entries[:, a]
        b3 = np.ascontiguousarray(b, dtype=np.float64).reshape(n, 3)
        its, rel = pcg_kernel(system.diag, full_diag, system.pairs, system.offd, pinv, b3, x,
                              free, self.tol, float(floor), self.maxiter, self.algo)
        return SolveResult(x, int(its), float(rel), bool(rel <= self.tol))
