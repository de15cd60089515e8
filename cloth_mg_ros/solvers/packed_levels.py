"""Every level of one multigrid solve in flat arrays, and the numba kernels of the
MG-preconditioned CG iteration over them.

The levels' unknowns are concatenated, finest first: level l holds the global rows
voff[l] .. voff[l+1]. Per row (vertex) the arrays hold its packed full diagonal block
(``diag6``, the upper triangle of A_ii = B_i - sum_j G_ij), its packed inverse (``dinv6``) and
its filter (``free``, 0 on pinned particles of the finest level); per adjacency slot (row i's
slots are ``start[i]..stop[i]``, ``nbr`` the global row at the other end) the packed pair block
G_ij (``rows``). A coarse row's
``parents`` are global rows of the next level (the finest levels' rows only).

Why flat arrays and a handful of kernels: at the sizes a live node runs (1-5K particles) a
Python-level V-cycle spent a large part of each CG iteration calling small kernels one level
at a time and allocating scratch arrays. Here one CG iteration is four kernel calls and the
coarsest level's Cholesky solve, and every kernel releases the GIL (``nogil``), so a node's
subscription thread keeps receiving poses while the solver runs.

Determinism: every kernel runs its loops in a fixed order on one thread, so the same system
gives bit-identical iterates on every run and machine with the same numba and LLVM.
"""

from __future__ import annotations

import numpy as np
from numba import njit


# -- set-up ---------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def adjacency_csr(pairs, n, ptr, nbr, slot):
    """Per vertex the pairs that touch it, by a counting sort (stable: a vertex's slots are in
    pair order). pairs (m, 2); writes ptr (n + 1,), nbr (2m,) the other ends, slot (2m,) the
    pair indices."""
    m = pairs.shape[0]
    for i in range(n + 1):
        ptr[i] = 0
    for p in range(m):
        ptr[pairs[p, 0] + 1] += 1
        ptr[pairs[p, 1] + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:n].copy()
    for p in range(m):
        i = pairs[p, 0]
        j = pairs[p, 1]
        nbr[fill[i]] = j
        slot[fill[i]] = p
        fill[i] += 1
        nbr[fill[j]] = i
        slot[fill[j]] = p
        fill[j] += 1


@njit(cache=True, nogil=True)
def _inverse6(a, b, c, d, e, f, out, i):
    """out[i] = the packed inverse of the symmetric block [[a b c] [b d e] [c e f]]
    (cofactors over the determinant)."""
    c0 = d * f - e * e
    c1 = c * e - b * f
    c2 = b * e - c * d
    det = a * c0 + b * c1 + c * c2
    inv = 1.0 / det
    out[i, 0] = c0 * inv
    out[i, 1] = c1 * inv
    out[i, 2] = c2 * inv
    out[i, 3] = (a * f - c * c) * inv
    out[i, 4] = (b * c - a * e) * inv
    out[i, 5] = (a * d - b * b) * inv


@njit(cache=True, nogil=True)
def _sub6(offd, p, out, g):
    """out[g] -= the packed upper triangle of offd[p]."""
    out[g, 0] -= offd[p, 0, 0]
    out[g, 1] -= offd[p, 0, 1]
    out[g, 2] -= offd[p, 0, 2]
    out[g, 3] -= offd[p, 1, 1]
    out[g, 4] -= offd[p, 1, 2]
    out[g, 5] -= offd[p, 2, 2]


@njit(cache=True, nogil=True)
def pack_level(diag, pairs, offd, free, ptr, slot, voff, aoff, diag6, dinv6, rows):
    """Pack one level (diag (n, 3, 3), pairs (m, 2), offd (m, 3, 3) symmetric blocks) into
    the global arrays at rows voff.. and adjacency slots aoff.. : diag6 / dinv6 (N, 6) the full
    diagonal blocks and their inverses (zero where free == 0), rows (M, 6) the pair blocks in
    adjacency order. ptr, slot: the level's own adjacency (adjacency_csr)."""
    n = diag.shape[0]
    for i in range(n):
        g = voff + i
        diag6[g, 0] = diag[i, 0, 0]
        diag6[g, 1] = diag[i, 0, 1]
        diag6[g, 2] = diag[i, 0, 2]
        diag6[g, 3] = diag[i, 1, 1]
        diag6[g, 4] = diag[i, 1, 2]
        diag6[g, 5] = diag[i, 2, 2]
    for p in range(pairs.shape[0]):
        gi = voff + pairs[p, 0]
        gj = voff + pairs[p, 1]
        _sub6(offd, p, diag6, gi)
        _sub6(offd, p, diag6, gj)
    for i in range(n):
        g = voff + i
        if free[g] == 0.0:
            for a in range(6):
                dinv6[g, a] = 0.0
        else:
            _inverse6(diag6[g, 0], diag6[g, 1], diag6[g, 2], diag6[g, 3], diag6[g, 4],
                      diag6[g, 5], dinv6, g)
    for k in range(ptr[n]):
        p = slot[k]
        out = aoff + k
        rows[out, 0] = offd[p, 0, 0]
        rows[out, 1] = offd[p, 0, 1]
        rows[out, 2] = offd[p, 0, 2]
        rows[out, 3] = offd[p, 1, 1]
        rows[out, 4] = offd[p, 1, 2]
        rows[out, 5] = offd[p, 2, 2]


# -- one V-cycle ------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _gauss_seidel(lo, hi, start, stop, nbr, rows, dinv6, free, b, x, forward):
    """One block Gauss-Seidel sweep over rows lo..hi (forward or backward)."""
    for ii in range(hi - lo):
        i = lo + ii if forward else hi - 1 - ii
        if free[i] == 0.0:
            continue
        s0 = b[i, 0]
        s1 = b[i, 1]
        s2 = b[i, 2]
        for k in range(start[i], stop[i]):
            j = nbr[k]
            y0 = x[j, 0]
            y1 = x[j, 1]
            y2 = x[j, 2]
            g1 = rows[k, 1]
            g2 = rows[k, 2]
            g4 = rows[k, 4]
            s0 -= rows[k, 0] * y0 + g1 * y1 + g2 * y2
            s1 -= g1 * y0 + rows[k, 3] * y1 + g4 * y2
            s2 -= g2 * y0 + g4 * y1 + rows[k, 5] * y2
        x[i, 0] = dinv6[i, 0] * s0 + dinv6[i, 1] * s1 + dinv6[i, 2] * s2
        x[i, 1] = dinv6[i, 1] * s0 + dinv6[i, 3] * s1 + dinv6[i, 4] * s2
        x[i, 2] = dinv6[i, 2] * s0 + dinv6[i, 4] * s1 + dinv6[i, 5] * s2


@njit(cache=True, nogil=True)
def _first_sweep(lo, hi, start, stop, nbr, rows, dinv6, free, b, x, r):
    """A forward Gauss-Seidel sweep from x = 0 over rows lo..hi and, in the same pass, the
    residual r = S (b - A x) it leaves.

    From a zero guess row i sees only its lower neighbours: x_i = D_i^-1 (b_i - sum_{j<i}
    A_ij x_j), so r_i = -sum_{j>i} A_ij x_j, which row i's update scatters to its lower
    neighbours as soon as x_i is known (A_ji = A_ij: symmetric blocks). Each lower slot is read
    twice and no upper slot at all: half the memory traffic of a sweep and a residual.
    """
    for i in range(lo, hi):
        for a in range(3):
            x[i, a] = 0.0
            r[i, a] = 0.0
    for i in range(lo, hi):
        if free[i] == 0.0:
            continue
        s0 = b[i, 0]
        s1 = b[i, 1]
        s2 = b[i, 2]
        for k in range(start[i], stop[i]):
            j = nbr[k]
            if j > i:
                continue
            y0 = x[j, 0]
            y1 = x[j, 1]
            y2 = x[j, 2]
            g1 = rows[k, 1]
            g2 = rows[k, 2]
            g4 = rows[k, 4]
            s0 -= rows[k, 0] * y0 + g1 * y1 + g2 * y2
            s1 -= g1 * y0 + rows[k, 3] * y1 + g4 * y2
            s2 -= g2 * y0 + g4 * y1 + rows[k, 5] * y2
        x0 = dinv6[i, 0] * s0 + dinv6[i, 1] * s1 + dinv6[i, 2] * s2
        x1 = dinv6[i, 1] * s0 + dinv6[i, 3] * s1 + dinv6[i, 4] * s2
        x2 = dinv6[i, 2] * s0 + dinv6[i, 4] * s1 + dinv6[i, 5] * s2
        x[i, 0] = x0
        x[i, 1] = x1
        x[i, 2] = x2
        for k in range(start[i], stop[i]):
            j = nbr[k]
            if j > i or free[j] == 0.0:
                continue
            g1 = rows[k, 1]
            g2 = rows[k, 2]
            g4 = rows[k, 4]
            r[j, 0] -= rows[k, 0] * x0 + g1 * x1 + g2 * x2
            r[j, 1] -= g1 * x0 + rows[k, 3] * x1 + g4 * x2
            r[j, 2] -= g2 * x0 + g4 * x1 + rows[k, 5] * x2


@njit(cache=True, nogil=True)
def vcycle_down(n_levels, voff, start, stop, nbr, rows, dinv6, free, parents, r0, b, x, r):
    """The descending half of one V-cycle applied to r0 (n_0, 3) with a zero first guess:
    on each level but the coarsest, a forward Gauss-Seidel sweep with the residual it leaves
    (one pass, `_first_sweep`), the residual's restriction (full weighting) as the next level's right-hand side. The caller solves the
    coarsest level (b -> x at rows voff[L-1]..) and then calls vcycle_up. A one-level
    hierarchy only smooths (forward here, backward in vcycle_up)."""
    n0 = voff[1]
    for i in range(n0):
        for a in range(3):
            b[i, a] = r0[i, a]
    for lvl in range(max(n_levels - 1, 1)):
        lo = voff[lvl]
        hi = voff[lvl + 1]
        _first_sweep(lo, hi, start, stop, nbr, rows, dinv6, free, b, x, r)
        if n_levels == 1:
            return
        top = voff[lvl + 2]
        for i in range(hi, top):
            for a in range(3):
                b[i, a] = 0.0
        for m in range(lo, hi):
            p0 = parents[m, 0]
            p1 = parents[m, 1]
            if p0 == p1:
                for a in range(3):
                    b[p0, a] += r[m, a]
            else:
                for a in range(3):
                    h = 0.5 * r[m, a]
                    b[p0, a] += h
                    b[p1, a] += h


@njit(cache=True, nogil=True)
def vcycle_up(n_levels, voff, start, stop, nbr, rows, dinv6, free, parents, b, x, r0, z):
    """The ascending half: on each level from the second coarsest up, the coarse correction
    (linear interpolation; pinned rows keep theirs) and a backward Gauss-Seidel sweep. Writes
    z (n_0, 3) = the preconditioned r0 and returns z . r0 over free rows."""
    for lvl in range(n_levels - 2, -1, -1):
        lo = voff[lvl]
        hi = voff[lvl + 1]
        for m in range(lo, hi):
            if free[m] == 0.0:
                continue
            p0 = parents[m, 0]
            p1 = parents[m, 1]
            if p0 == p1:
                for a in range(3):
                    x[m, a] += x[p0, a]
            else:
                for a in range(3):
                    x[m, a] += 0.5 * (x[p0, a] + x[p1, a])
        _gauss_seidel(lo, hi, start, stop, nbr, rows, dinv6, free, b, x, False)
    if n_levels == 1:
        _gauss_seidel(0, voff[1], start, stop, nbr, rows, dinv6, free, b, x, False)
    s = 0.0
    for i in range(voff[1]):
        if free[i] == 0.0:
            for a in range(3):
                z[i, a] = 0.0
        else:
            for a in range(3):
                z[i, a] = x[i, a]
            s += z[i, 0] * r0[i, 0] + z[i, 1] * r0[i, 1] + z[i, 2] * r0[i, 2]
    return s


# -- the CG iteration on the finest level -----------------------------------------------------
@njit(cache=True, nogil=True)
def direction_matvec(diag, pairs, offd, z, beta, p, q, free):
    """p = z + beta p, q = S A p (Algorithm 1, the paper's block-symmetric product); returns
    p . q over free rows. Arrays (n, 3); pinned rows of q are zero."""
    n = diag.shape[0]
    for i in range(n):
        for a in range(3):
            p[i, a] = z[i, a] + beta * p[i, a]
    for i in range(n):
        d0 = p[i, 0]
        d1 = p[i, 1]
        d2 = p[i, 2]
        for a in range(3):
            q[i, a] = diag[i, a, 0] * d0 + diag[i, a, 1] * d1 + diag[i, a, 2] * d2
    for k in range(pairs.shape[0]):
        i = pairs[k, 0]
        j = pairs[k, 1]
        e0 = p[j, 0] - p[i, 0]
        e1 = p[j, 1] - p[i, 1]
        e2 = p[j, 2] - p[i, 2]
        for a in range(3):
            c = offd[k, a, 0] * e0 + offd[k, a, 1] * e1 + offd[k, a, 2] * e2
            q[i, a] += c
            q[j, a] -= c
    s = 0.0
    for i in range(n):
        if free[i] == 0.0:
            q[i, 0] = 0.0
            q[i, 1] = 0.0
            q[i, 2] = 0.0
        else:
            s += p[i, 0] * q[i, 0] + p[i, 1] * q[i, 1] + p[i, 2] * q[i, 2]
    return s


@njit(cache=True, nogil=True)
def parents_global(parents, lo, hi_coarse_off, out):
    """out[lo + m] = hi_coarse_off + parents[m] for a level's (n_f, 2) parents map."""
    for m in range(parents.shape[0]):
        out[lo + m, 0] = hi_coarse_off + parents[m, 0]
        out[lo + m, 1] = hi_coarse_off + parents[m, 1]



# -- the arrays, refilled for every solve -----------------------------------------------------
class PackedLevels:
    """The flat arrays of a hierarchy's first ``len(sizes)`` levels (see the module docstring).

    sizes: vertices per level, finest first; parents: per level but the coarsest, the (n_l, 2)
    parents map onto the next level; rows_dtype: the smoothers' pair blocks (float32 halves
    their memory traffic, which bounds the sweeps on large meshes; the outer CG stays exact).

    Row i's adjacency slots are start[i]..stop[i]. The coarse levels' adjacency never changes
    (the mesh's pairs), so it is laid out once, first; the finest level's comes after it and is
    rebuilt only when its pairs change (cloth-cloth contact springs come and go every step).
    """

    def __init__(self, sizes: list[int], parents: list[np.ndarray], rows_dtype=np.float32):
        self.n_levels = len(sizes)
        self.voff = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.voff[-1])
        self.parents = np.zeros((total, 2), dtype=np.int64)
        for lvl in range(self.n_levels - 1):
            parents_global(np.ascontiguousarray(parents[lvl], dtype=np.int64),
                           self.voff[lvl], self.voff[lvl + 1], self.parents)
        self.rows_dtype = rows_dtype
        self.diag6 = np.zeros((total, 6))
        self.dinv6 = np.zeros((total, 6))
        self.free = np.ones(total)
        self.b = np.zeros((total, 3))
        self.x = np.zeros((total, 3))
        self.r = np.zeros((total, 3))
        self.start = np.zeros(total, dtype=np.int64)
        self.stop = np.zeros(total, dtype=np.int64)
        self._local: list = [None] * self.n_levels  # (pairs, ptr, slot, nbr) per level
        self._slot_off = [0] * self.n_levels  # where each level's slots start
        self._coarse_nbr: np.ndarray | None = None
        self.nbr = np.zeros(0, dtype=np.int64)
        self.rows = np.zeros((0, 6), dtype=rows_dtype)

    def _adjacency(self, lvl: int, pairs: np.ndarray) -> bool:
        """Level lvl's local adjacency (cached while its pairs stay equal); True if rebuilt."""
        cached = self._local[lvl]
        if cached is not None and (cached[0] is pairs or (
                cached[0].shape == pairs.shape and np.array_equal(cached[0], pairs))):
            return False
        n = int(self.voff[lvl + 1] - self.voff[lvl])
        ptr = np.empty(n + 1, dtype=np.int64)
        nbr = np.empty(2 * len(pairs), dtype=np.int64)
        slot = np.empty(2 * len(pairs), dtype=np.int64)
        adjacency_csr(np.ascontiguousarray(pairs, dtype=np.int64), n, ptr, nbr, slot)
        self._local[lvl] = (pairs, ptr, slot, nbr)
        return True

    def _place(self, lvl: int, off: int) -> np.ndarray:
        """Set level lvl's start/stop from slot offset off; returns its global neighbours."""
        _, ptr, _, nbr = self._local[lvl]
        lo, hi = int(self.voff[lvl]), int(self.voff[lvl + 1])
        self.start[lo:hi] = off + ptr[:-1]
        self.stop[lo:hi] = off + ptr[1:]
        self._slot_off[lvl] = off
        return nbr + lo

    def fill(self, systems: list, fixed: np.ndarray | None) -> None:
        """Pack one solve's systems (finest first, a BlockSystem each); fixed (n_0,) bool
        marks the finest level's pinned particles (filtered: free = 0)."""
        rebuilt = [self._adjacency(lvl, s.pairs) for lvl, s in enumerate(systems)]
        if self._coarse_nbr is None or any(rebuilt[1:]):
            parts, off = [], 0
            for lvl in range(1, self.n_levels):
                parts.append(self._place(lvl, off))
                off += len(self._local[lvl][2])
            self._coarse_nbr = (np.concatenate(parts) if parts
                                else np.zeros(0, dtype=np.int64))
            rebuilt[0] = True
        if rebuilt[0]:
            fine = self._place(0, len(self._coarse_nbr))
            self.nbr = np.concatenate([self._coarse_nbr, fine])
            self.rows = np.empty((len(self.nbr), 6), dtype=self.rows_dtype)
        n0 = int(self.voff[1])
        self.free[:n0] = 1.0
        if fixed is not None:
            self.free[:n0][np.asarray(fixed, dtype=bool)] = 0.0
        for lvl, s in enumerate(systems):
            _, ptr, slot, _ = self._local[lvl]
            pack_level(s.diag, s.pairs, s.offd, self.free, ptr, slot, self.voff[lvl],
                       self._slot_off[lvl], self.diag6, self.dinv6, self.rows)
