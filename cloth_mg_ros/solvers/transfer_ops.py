"""Grid transfers on a midpoint-subdivision hierarchy, in numba.

Each fine vertex m has coarse parents (p0, p1): p0 == p1 for a copy of a coarse vertex, the
ends of its coarse edge for a midpoint. Prolongation P is linear interpolation; restriction
R = P^T is full weighting (a coarse vertex gets its own residual plus half of each adjacent
midpoint's). The same weights move diagonal blocks (mass, contact penalties) down a level,
which is the paper's Voronoi-overlap mass coarsening for one-third lumping (W = P^T).
"""

from __future__ import annotations

from numba import njit, prange


@njit(cache=True, nogil=True)
def restrict(parents, r_f, r_c):
    """r_c (n_c, 3) = R r_f, r_f (n_f, 3)."""
    r_c[:] = 0.0
    for m in range(parents.shape[0]):
        p0 = parents[m, 0]
        p1 = parents[m, 1]
        if p0 == p1:
            for a in range(3):
                r_c[p0, a] += r_f[m, a]
        else:
            for a in range(3):
                h = 0.5 * r_f[m, a]
                r_c[p0, a] += h
                r_c[p1, a] += h


@njit(cache=True, nogil=True)
def prolong_add(parents, e_c, x_f, free):
    """x_f (n_f, 3) += P e_c, e_c (n_c, 3), except where free == 0 (pinned particles)."""
    for m in range(parents.shape[0]):
        if free[m] == 0.0:
            continue
        p0 = parents[m, 0]
        p1 = parents[m, 1]
        if p0 == p1:
            for a in range(3):
                x_f[m, a] += e_c[p0, a]
        else:
            for a in range(3):
                x_f[m, a] += 0.5 * (e_c[p0, a] + e_c[p1, a])


@njit(cache=True, nogil=True)
def _restrict_blocks_range(parents, blocks_f, blocks_c, lo, hi):
    """`restrict_blocks` onto the coarse blocks lo..hi only (the fine ones in order)."""
    for i in range(lo, hi):
        for a in range(3):
            for b in range(3):
                blocks_c[i, a, b] = 0.0
    for m in range(parents.shape[0]):
        p0 = parents[m, 0]
        p1 = parents[m, 1]
        in0 = lo <= p0 < hi
        in1 = p0 != p1 and lo <= p1 < hi
        if not (in0 or in1):
            continue
        w = 1.0 if p0 == p1 else 0.5
        for a in range(3):
            for b in range(3):
                v = w * blocks_f[m, a, b]
                if in0:
                    blocks_c[p0, a, b] += v
                if in1:
                    blocks_c[p1, a, b] += v


@njit(cache=True, nogil=True)
def restrict_blocks(parents, blocks_f, blocks_c):
    """blocks_c (n_c, 3, 3) = W blocks_f: diagonal blocks moved by area overlap."""
    _restrict_blocks_range(parents, blocks_f, blocks_c, 0, blocks_c.shape[0])


@njit(cache=True, nogil=True, parallel=True)
def restrict_blocks_split(parents, blocks_f, blocks_c, parts):
    """`restrict_blocks` on `parts` threads, each taking the coarse blocks of its own range
    and the fine ones in order: every coarse block gets its terms in the same order on any
    number of threads."""
    n_c = blocks_c.shape[0]
    for part in prange(parts):
        _restrict_blocks_range(parents, blocks_f, blocks_c, part * n_c // parts,
                               (part + 1) * n_c // parts)
