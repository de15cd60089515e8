"""Smoothers on block-symmetric levels: block Gauss-Seidel, block Jacobi, CG to a ratio.

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


@njit(cache=True)
def block_gauss_seidel(dinv, ptr, pair, nbr, offd, b, x, free, forward):
    """One block Gauss-Seidel sweep in place on x (n, 3); dinv (n, 3, 3) inverse diagonal
    blocks; pinned particles (free == 0) keep their value."""
    n = b.shape[0]
    s = np.empty(3)
    for ii in range(n):
        i = ii if forward else n - 1 - ii
        if free[i] == 0.0:
            continue
        s[0] = b[i, 0]
        s[1] = b[i, 1]
        s[2] = b[i, 2]
        for k in range(ptr[i], ptr[i + 1]):
            p = pair[k]
            j = nbr[k]
            for a in range(3):
                s[a] -= offd[p, a, 0] * x[j, 0] + offd[p, a, 1] * x[j, 1] + offd[p, a, 2] * x[j, 2]
        for a in range(3):
            x[i, a] = dinv[i, a, 0] * s[0] + dinv[i, a, 1] * s[1] + dinv[i, a, 2] * s[2]


@njit(cache=True)
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


@njit(cache=True)
def block_jacobi_sweep(dinv, diag, pairs, offd, b, x, free, omega, r):
    """x += omega D^-1 S (b - A x): one damped block Jacobi sweep; r is scratch (n, 3)."""
    residual(diag, pairs, offd, b, x, free, r)
    for i in range(b.shape[0]):
        for a in range(3):
            x[i, a] += omega * (dinv[i, a, 0] * r[i, 0] + dinv[i, a, 1] * r[i, 1]
                                + dinv[i, a, 2] * r[i, 2])
