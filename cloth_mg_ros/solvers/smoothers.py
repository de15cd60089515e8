"""Smoothers on block-symmetric levels: block Gauss-Seidel, block Jacobi, and residuals.

Gauss-Seidel needs each vertex's neighbours; ``Adjacency`` lists, per vertex, the pairs that
touch it (fixed by the mesh, built once per level). (A x)_i = D_i x_i + sum_j G_ij x_j with
D_i = B_i - sum_j G_ij the full diagonal block.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Adjacency:
    """ptr (n + 1,), pair (2m,), nbr (2m,): vertex i touches pairs pair[ptr[i]:ptr[i+1]],
    whose other ends are nbr[ptr[i]:ptr[i+1]]."""

    ptr: np.ndarray
    pair: np.ndarray
    nbr: np.ndarray

    @classmethod
    def from_pairs(cls, pairs: np.ndarray, n: int) -> Adjacency:
        m = len(pairs)
        owner = np.concatenate([pairs[:, 0], pairs[:, 1]])
        other = np.concatenate([pairs[:, 1], pairs[:, 0]])
        pid = np.concatenate([np.arange(m), np.arange(m)])
        order = np.argsort(owner, kind="stable")
        ptr = np.zeros(n + 1, dtype=np.int64)
        np.add.at(ptr, owner + 1, 1)
        return cls(np.cumsum(ptr), pid[order].astype(np.int64), other[order].astype(np.int64))


@njit(cache=True, nogil=True)
def residual(diag, pairs, offd, b, x, free, r):
    """r = S (b - A x) with Algorithm 1."""
    n = b.shape[0]
    for i in range(n):
        for a in range(3):
            r[i, a] = b[i, a] - (diag[i, a, 0] * x[i, 0] + diag[i, a, 1] * x[i, 1]
                                 + diag[i, a, 2] * x[i, 2])
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        e0 = x[j, 0] - x[i, 0]
        e1 = x[j, 1] - x[i, 1]
        e2 = x[j, 2] - x[i, 2]
        for a in range(3):
            c = offd[p, a, 0] * e0 + offd[p, a, 1] * e1 + offd[p, a, 2] * e2
            r[i, a] -= c
            r[j, a] += c
    for i in range(n):
        if free[i] == 0.0:
            r[i, 0] = 0.0
            r[i, 1] = 0.0
            r[i, 2] = 0.0


@njit(cache=True, nogil=True)
def block_jacobi_sweep(dinv, diag, pairs, offd, b, x, free, omega, r):
    """x += omega D^-1 S (b - A x): one damped block Jacobi sweep; r is scratch (n, 3)."""
    residual(diag, pairs, offd, b, x, free, r)
    for i in range(b.shape[0]):
        for a in range(3):
            x[i, a] += omega * (dinv[i, a, 0] * r[i, 0] + dinv[i, a, 1] * r[i, 1]
                                + dinv[i, a, 2] * r[i, 2])


# Packed row storage for the smoothers. Every pair block G_ij is a symmetric 3x3 matrix, so
# six numbers hold it; the smoothers keep them in float32, in adjacency (row) order, so that a
# sweep streams through them once per row instead of gathering 9 doubles per pair from both
# ends. Smoothing only shapes a preconditioner, so single precision costs nothing in the
# outer iteration's accuracy, and it halves the memory traffic that bounds these sweeps.
@njit(cache=True, nogil=True)
def pack_rows(pair, offd, out):
    """out (2m, 6) float32: the upper triangle of offd[pair[k]] for each adjacency slot k."""
    for k in range(pair.shape[0]):
        p = pair[k]
        out[k, 0] = offd[p, 0, 0]
        out[k, 1] = offd[p, 0, 1]
        out[k, 2] = offd[p, 0, 2]
        out[k, 3] = offd[p, 1, 1]
        out[k, 4] = offd[p, 1, 2]
        out[k, 5] = offd[p, 2, 2]


@njit(cache=True, nogil=True)
def pack_symmetric(blocks, out):
    """out (n, 6): the upper triangle of each symmetric 3x3 block of blocks (n, 3, 3)."""
    for i in range(blocks.shape[0]):
        out[i, 0] = blocks[i, 0, 0]
        out[i, 1] = blocks[i, 0, 1]
        out[i, 2] = blocks[i, 0, 2]
        out[i, 3] = blocks[i, 1, 1]
        out[i, 4] = blocks[i, 1, 2]
        out[i, 5] = blocks[i, 2, 2]


@njit(cache=True, nogil=True)
def packed_gauss_seidel(dinv6, ptr, nbr, rows, b, x, free, forward):
    """One block Gauss-Seidel sweep on packed rows; dinv6 (n, 6) packed inverse diagonal
    blocks, rows (2m, 6) from pack_rows. Pinned particles (free == 0) keep their value."""
    n = b.shape[0]
    for ii in range(n):
        i = ii if forward else n - 1 - ii
        if free[i] == 0.0:
            continue
        s0 = b[i, 0]
        s1 = b[i, 1]
        s2 = b[i, 2]
        for k in range(ptr[i], ptr[i + 1]):
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
def packed_residual(diag6, ptr, nbr, rows, b, x, free, r):
    """r = S (b - A x) row by row from packed storage; diag6 (n, 6) the full diagonal blocks."""
    for i in range(b.shape[0]):
        if free[i] == 0.0:
            r[i, 0] = 0.0
            r[i, 1] = 0.0
            r[i, 2] = 0.0
            continue
        x0 = x[i, 0]
        x1 = x[i, 1]
        x2 = x[i, 2]
        s0 = b[i, 0] - (diag6[i, 0] * x0 + diag6[i, 1] * x1 + diag6[i, 2] * x2)
        s1 = b[i, 1] - (diag6[i, 1] * x0 + diag6[i, 3] * x1 + diag6[i, 4] * x2)
        s2 = b[i, 2] - (diag6[i, 2] * x0 + diag6[i, 4] * x1 + diag6[i, 5] * x2)
        for k in range(ptr[i], ptr[i + 1]):
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
        r[i, 0] = s0
        r[i, 1] = s1
        r[i, 2] = s2
