"""Grid transfers on a midpoint-subdivision hierarchy, in numba.

Each fine vertex m has coarse parents (p0, p1): p0 == p1 for a copy of a coarse vertex, the
ends of its coarse edge for a midpoint. Prolongation P is linear interpolation; restriction
R = P^T is full weighting (a coarse vertex gets its own residual plus half of each adjacent
midpoint's). The same weights move diagonal blocks (mass, contact penalties) down a level,
which is the paper's Voronoi-overlap mass coarsening for one-third lumping (W = P^T).
"""

from __future__ import annotations

import numpy as np
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


def children_csr(parents: np.ndarray, n_coarse: int) -> tuple[np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """Per coarse vertex, the fine vertices of parents (n_f, 2) that restrict onto it, in
    fine order, and their weights (1 for a copy, 1/2 for a midpoint): ptr (n_c + 1,),
    child (k,), weight (k,) for `restrict_blocks`."""
    parents = np.asarray(parents, dtype=np.int64)
    m = np.arange(len(parents))
    own = parents[:, 0] == parents[:, 1]
    mid = np.flatnonzero(~own)
    coarse = np.concatenate([parents[:, 0], parents[mid, 1]])
    child = np.concatenate([m, mid])
    weight = np.concatenate([np.where(own, 1.0, 0.5), np.full(len(mid), 0.5)])
    # stable by coarse vertex, then fine vertex: a coarse vertex's terms in fine order
    order = np.lexsort((child, coarse))
    ptr = np.zeros(n_coarse + 1, dtype=np.int64)
    np.cumsum(np.bincount(coarse, minlength=n_coarse), out=ptr[1:])
    return ptr, child[order], weight[order]


@njit(cache=True, nogil=True, parallel=True)
def restrict_blocks(ptr, child, weight, blocks_f, blocks_c):
    """blocks_c (n_c, 3, 3) = W blocks_f: diagonal blocks moved by area overlap, a coarse
    vertex per thread gathering its children in fine order (`children_csr`; the sums a
    scatter in fine order made, bit for bit, on any number of threads)."""
    for c in prange(blocks_c.shape[0]):
        s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
        for k in range(ptr[c], ptr[c + 1]):
            m = child[k]
            w = weight[k]
            s00 += w * blocks_f[m, 0, 0]
            s01 += w * blocks_f[m, 0, 1]
            s02 += w * blocks_f[m, 0, 2]
            s10 += w * blocks_f[m, 1, 0]
            s11 += w * blocks_f[m, 1, 1]
            s12 += w * blocks_f[m, 1, 2]
            s20 += w * blocks_f[m, 2, 0]
            s21 += w * blocks_f[m, 2, 1]
            s22 += w * blocks_f[m, 2, 2]
        blocks_c[c, 0, 0] = s00
        blocks_c[c, 0, 1] = s01
        blocks_c[c, 0, 2] = s02
        blocks_c[c, 1, 0] = s10
        blocks_c[c, 1, 1] = s11
        blocks_c[c, 1, 2] = s12
        blocks_c[c, 2, 0] = s20
        blocks_c[c, 2, 1] = s21
        blocks_c[c, 2, 2] = s22
