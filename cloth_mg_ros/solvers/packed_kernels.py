"""The numba kernels of MG-preconditioned CG on packed levels (solvers.packed_levels).

Every vector here is in packed row order: level l's rows are voff[l] .. voff[l+1], in that
level's sweep order (solvers.dissection), and ``bounds[l]`` (parts + 2,) are the absolute rows
where its parts start, then its separator's start and end. Per row: the packed full diagonal
block ``diag6`` (upper triangle of A_ii = B_i - sum_j G_ij) and its inverse ``dinv6``, the
filter ``free`` (0 on pinned particles); its pair blocks in two slot sets
(solvers.packed_levels): full ones, row i's slots ``fstart[i]..fstop[i]``, those of its
earlier neighbours first (up to ``fmid[i]``), ``fnbr`` the row at the other end, ``frows``
the upper triangles; scalar ones (w I), ``sstart``, ``smid``, ``sstop``, ``snbr``, ``swts``
the weights. A fine row's ``parents`` are rows of the next level;
``chunks[l]`` (parts + 1,) split level l's rows evenly. The kernels take the ten slot
arrays as one tuple, ``slots`` (PackedLevels.slots).

Threads: the parts of a level are swept at once (``prange``), then its separator on one
thread; rows of a product or an update are independent and go in even chunks, one per
part, and every sum is formed per chunk and the partial sums added in chunk order. So the iterates
depend on the ordering only: the same system and ordering give bit-identical results on any
number of threads. Every kernel releases the GIL (``nogil``), so a node's subscription thread
keeps receiving poses while the solver runs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


# -- row kernels on one range of rows ---------------------------------------------------------
@njit(cache=True, nogil=True, inline="always")
def _gather(i, slots, x, below):
    """sum_j A_ij x_j over row i's pair slots (with `below`, only neighbours j < i)."""
    fstart, fmid, fstop, fnbr, frows, sstart, smid, sstop, snbr, swts = slots
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for k in range(fstart[i], fmid[i] if below else fstop[i]):
        j = fnbr[k]
        y0 = x[j, 0]
        y1 = x[j, 1]
        y2 = x[j, 2]
        g1 = frows[k, 1]
        g2 = frows[k, 2]
        g4 = frows[k, 4]
        s0 += frows[k, 0] * y0 + g1 * y1 + g2 * y2
        s1 += g1 * y0 + frows[k, 3] * y1 + g4 * y2
        s2 += g2 * y0 + g4 * y1 + frows[k, 5] * y2
    for k in range(sstart[i], smid[i] if below else sstop[i]):
        j = snbr[k]
        w = swts[k]
        s0 += w * x[j, 0]
        s1 += w * x[j, 1]
        s2 += w * x[j, 2]
    return s0, s1, s2


@njit(cache=True, nogil=True)
def _gauss_seidel(lo, hi, slots, dinv6, free, b, x, forward):
    """One block Gauss-Seidel sweep over rows lo..hi (forward or backward)."""
    for ii in range(hi - lo):
        i = lo + ii if forward else hi - 1 - ii
        if free[i] == 0.0:
            continue
        a0, a1, a2 = _gather(i, slots, x, False)
        s0 = b[i, 0] - a0
        s1 = b[i, 1] - a1
        s2 = b[i, 2] - a2
        x[i, 0] = dinv6[i, 0] * s0 + dinv6[i, 1] * s1 + dinv6[i, 2] * s2
        x[i, 1] = dinv6[i, 1] * s0 + dinv6[i, 3] * s1 + dinv6[i, 4] * s2
        x[i, 2] = dinv6[i, 2] * s0 + dinv6[i, 4] * s1 + dinv6[i, 5] * s2


@njit(cache=True, nogil=True)
def _first_sweep(lo, hi, slots, dinv6, free, b, x, r):
    """A forward Gauss-Seidel sweep from x = 0 over rows lo..hi and, in the same pass, the
    residual r = S (b - A x) it leaves.

    From a zero guess row i sees only its earlier neighbours: x_i = D_i^-1 (b_i - sum_{j<i}
    A_ij x_j), so r_i = -sum_{j>i} A_ij x_j, which row i's update scatters to its earlier
    neighbours as soon as x_i is known (A_ji = A_ij: symmetric blocks). Each earlier slot is
    read twice and no later slot at all: half the memory traffic of a sweep and a residual.
    Rows lo..hi are zeroed first; a separator's rows scatter into its parts' rows, which were
    swept before.
    """
    fstart, fmid, _, fnbr, frows, sstart, smid, _, snbr, swts = slots
    for i in range(lo, hi):
        for a in range(3):
            x[i, a] = 0.0
            r[i, a] = 0.0
    for i in range(lo, hi):
        if free[i] == 0.0:
            continue
        a0, a1, a2 = _gather(i, slots, x, True)
        s0 = b[i, 0] - a0
        s1 = b[i, 1] - a1
        s2 = b[i, 2] - a2
        x0 = dinv6[i, 0] * s0 + dinv6[i, 1] * s1 + dinv6[i, 2] * s2
        x1 = dinv6[i, 1] * s0 + dinv6[i, 3] * s1 + dinv6[i, 4] * s2
        x2 = dinv6[i, 2] * s0 + dinv6[i, 4] * s1 + dinv6[i, 5] * s2
        x[i, 0] = x0
        x[i, 1] = x1
        x[i, 2] = x2
        for k in range(fstart[i], fmid[i]):
            j = fnbr[k]
            if free[j] == 0.0:
                continue
            g1 = frows[k, 1]
            g2 = frows[k, 2]
            g4 = frows[k, 4]
            r[j, 0] -= frows[k, 0] * x0 + g1 * x1 + g2 * x2
            r[j, 1] -= g1 * x0 + frows[k, 3] * x1 + g4 * x2
            r[j, 2] -= g2 * x0 + g4 * x1 + frows[k, 5] * x2
        for k in range(sstart[i], smid[i]):
            j = snbr[k]
            if free[j] == 0.0:
                continue
            w = swts[k]
            r[j, 0] -= w * x0
            r[j, 1] -= w * x1
            r[j, 2] -= w * x2


@njit(cache=True, nogil=True)
def _direction(lo, hi, z, beta, p):
    """p = z + beta p over rows lo..hi (every range's p is complete before `_apply` reads
    its neighbours')."""
    for i in range(lo, hi):
        for a in range(3):
            p[i, a] = z[i, a] + beta * p[i, a]


@njit(cache=True, nogil=True)
def _apply(lo, hi, slots, diag6, free, p, q):
    """q = S A p over rows lo..hi (the full diagonal blocks and the pair blocks, row by row);
    returns the sum of p . q over the free rows."""
    s = 0.0
    for i in range(lo, hi):
        if free[i] == 0.0:
            q[i, 0] = 0.0
            q[i, 1] = 0.0
            q[i, 2] = 0.0
            continue
        y0 = p[i, 0]
        y1 = p[i, 1]
        y2 = p[i, 2]
        a0, a1, a2 = _gather(i, slots, p, False)
        s0 = diag6[i, 0] * y0 + diag6[i, 1] * y1 + diag6[i, 2] * y2 + a0
        s1 = diag6[i, 1] * y0 + diag6[i, 3] * y1 + diag6[i, 4] * y2 + a1
        s2 = diag6[i, 2] * y0 + diag6[i, 4] * y1 + diag6[i, 5] * y2 + a2
        q[i, 0] = s0
        q[i, 1] = s1
        q[i, 2] = s2
        s += y0 * s0 + y1 * s1 + y2 * s2
    return s


# -- one level, its parts at once ---------------------------------------------------------------
@njit(cache=True, nogil=True, parallel=True)
def _first_sweep_level(bounds, slots, dinv6, free, b, x, r):
    parts = bounds.shape[0] - 2
    for p in prange(parts):
        _first_sweep(bounds[p], bounds[p + 1], slots, dinv6, free, b, x, r)
    _first_sweep(bounds[parts], bounds[parts + 1], slots, dinv6, free, b, x, r)


@njit(cache=True, nogil=True, parallel=True)
def _sweep_level(bounds, slots, dinv6, free, b, x, forward):
    parts = bounds.shape[0] - 2
    if not forward:  # the mirror image: the separator first, then the parts backwards
        _gauss_seidel(bounds[parts], bounds[parts + 1], slots, dinv6, free, b, x, False)
    for p in prange(parts):
        _gauss_seidel(bounds[p], bounds[p + 1], slots, dinv6, free, b, x, forward)
    if forward:
        _gauss_seidel(bounds[parts], bounds[parts + 1], slots, dinv6, free, b, x, True)


@njit(cache=True, nogil=True, parallel=True)
def _prolong_level(chunks, parents, free, x):
    """x_fine += P x_coarse over the level's rows (linear interpolation; pinned rows keep
    theirs)."""
    ranges = chunks.shape[0] - 1
    for k in prange(ranges):
        for m in range(chunks[k], chunks[k + 1]):
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


@njit(cache=True, nogil=True)
def _restrict_level(lo, hi, top, parents, r, b):
    """b over the next level's rows hi..top = R r over rows lo..hi (full weighting)."""
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


# -- the V-cycle ---------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def vcycle_down(n_levels, voff, bounds, slots, dinv6, free, parents, r0, b, x, r):
    """The descending half of one V-cycle applied to r0 (the finest level's rows) with a zero
    first guess: on each level but the coarsest, a forward Gauss-Seidel sweep with the
    residual it leaves (one pass), the residual's restriction (full weighting) as the next
    level's right-hand side. The caller solves the coarsest level (b -> x at rows
    voff[L-1]..) and then calls vcycle_up. A one-level hierarchy only smooths (forward here,
    backward in vcycle_up). r0 may be b's first rows themselves (no copy then: the solver
    keeps its residual there)."""
    if r0.ctypes.data != b.ctypes.data:
        for i in range(voff[1]):
            for a in range(3):
                b[i, a] = r0[i, a]
    for lvl in range(max(n_levels - 1, 1)):
        _first_sweep_level(bounds[lvl], slots, dinv6, free, b, x, r)
        if n_levels == 1:
            return
        _restrict_level(voff[lvl], voff[lvl + 1], voff[lvl + 2], parents, r, b)


@njit(cache=True, nogil=True)
def vcycle_up(n_levels, voff, bounds, chunks, slots, dinv6, free, parents, b, x, r0, z):
    """The ascending half: on each level from the second coarsest up, the coarse correction
    and a backward Gauss-Seidel sweep. Writes z = the preconditioned r0 (finest rows) and
    returns z . r0 over free rows (summed per range, in range order). z may be x's first rows
    themselves (no copy then: pinned rows' x is zero, as z's must be)."""
    for lvl in range(n_levels - 2, -1, -1):
        _prolong_level(chunks[lvl], parents, free, x)
        _sweep_level(bounds[lvl], slots, dinv6, free, b, x, False)
    if n_levels == 1:
        _sweep_level(bounds[0], slots, dinv6, free, b, x, False)
    return _take(chunks[0], free, x, r0, z)


@njit(cache=True, nogil=True, parallel=True)
def _take(fine, free, x, r0, z):
    """z = S x over the finest level's rows (fine: its chunks; z may be x's rows, then only
    the product is formed); returns z . r0."""
    ranges = fine.shape[0] - 1
    partial = np.zeros(ranges)
    copy = z.ctypes.data != x.ctypes.data
    for k in prange(ranges):
        s = 0.0
        for i in range(fine[k], fine[k + 1]):
            if free[i] == 0.0:
                if copy:
                    for a in range(3):
                        z[i, a] = 0.0
            else:
                if copy:
                    for a in range(3):
                        z[i, a] = x[i, a]
                s += x[i, 0] * r0[i, 0] + x[i, 1] * r0[i, 1] + x[i, 2] * r0[i, 2]
        partial[k] = s
    return _ordered_sum(partial)


# -- the outer CG on the finest level -------------------------------------------------------------
@njit(cache=True, nogil=True)
def _ordered_sum(partial):
    s = 0.0
    for k in range(partial.shape[0]):
        s += partial[k]
    return s


@njit(cache=True, nogil=True, parallel=True)
def direction_product(fine, slots, diag6, free, z, beta, p, q):
    """p = z + beta p, q = S A p over the finest level's rows (`fine`: its chunks); returns
    p . q over free rows."""
    ranges = fine.shape[0] - 1
    for k in prange(ranges):
        _direction(fine[k], fine[k + 1], z, beta, p)
    partial = np.zeros(ranges)
    for k in prange(ranges):
        partial[k] = _apply(fine[k], fine[k + 1], slots, diag6, free, p, q)
    return _ordered_sum(partial)


@njit(cache=True, nogil=True, parallel=True)
def residual_rows(fine, slots, diag6, free, b, x, r):
    """r = S (b - A x) over the finest level's rows; returns |r|^2."""
    ranges = fine.shape[0] - 1
    for k in prange(ranges):
        _apply(fine[k], fine[k + 1], slots, diag6, free, x, r)
    partial = np.zeros(ranges)
    for k in prange(ranges):
        s = 0.0
        for i in range(fine[k], fine[k + 1]):
            for a in range(3):
                r[i, a] = (b[i, a] - r[i, a]) * free[i]
                s += r[i, a] * r[i, a]
        partial[k] = s
    return _ordered_sum(partial)


@njit(cache=True, nogil=True, parallel=True)
def cg_update(fine, x, r, p, q, alpha):
    """x += alpha p, r -= alpha q over the finest level's rows; returns |r|^2."""
    ranges = fine.shape[0] - 1
    partial = np.zeros(ranges)
    for k in prange(ranges):
        s = 0.0
        for i in range(fine[k], fine[k + 1]):
            for a in range(3):
                x[i, a] += alpha * p[i, a]
                r[i, a] -= alpha * q[i, a]
                s += r[i, a] * r[i, a]
        partial[k] = s
    return _ordered_sum(partial)
