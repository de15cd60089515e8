"""The implicit system A dv = b held in block-symmetric form (paper Sec. 4.1).

    (A d)_i = B_i d_i + sum_j G_ij (d_j - d_i)

B (n, 3, 3): one block per particle, mass plus external Jacobians (contact penalties, drag).
G (m, 3, 3): one block per vertex pair (i < j) from ``pairs`` (m, 2), the internal-force part
of A, with G_ij = G_ji and the zero row sums of translation invariance built in. The paper's
Algorithm 1 computes c = G_ij (d_j - d_i) once per pair, adds it to i and subtracts it from j.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit, prange


@njit(cache=True, nogil=True)
def bs_matvec(diag, pairs, offd, d, out):
    """Algorithm 1: out = A d for the block-symmetric A; d, out (n, 3)."""
    n = diag.shape[0]
    for i in range(n):
        d0 = d[i, 0]
        d1 = d[i, 1]
        d2 = d[i, 2]
        for a in range(3):
            out[i, a] = diag[i, a, 0] * d0 + diag[i, a, 1] * d1 + diag[i, a, 2] * d2
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        e0 = d[j, 0] - d[i, 0]
        e1 = d[j, 1] - d[i, 1]
        e2 = d[j, 2] - d[i, 2]
        for a in range(3):
            c = offd[p, a, 0] * e0 + offd[p, a, 1] * e1 + offd[p, a, 2] * e2
            out[i, a] += c
            out[j, a] -= c


@njit(cache=True, nogil=True)
def bs_full_matvec(full_diag, pairs, offd, d, out):
    """The standard block product (the paper's Algorithm 2) on the same storage.

    full_diag holds A_ii = B_i - sum_j G_ij; each pair contributes G_ij d_j to row i and
    G_ij d_i to row j, two block products per pair where Algorithm 1 needs one.
    """
    n = full_diag.shape[0]
    for i in range(n):
        for a in range(3):
            out[i, a] = (full_diag[i, a, 0] * d[i, 0] + full_diag[i, a, 1] * d[i, 1]
                         + full_diag[i, a, 2] * d[i, 2])
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        for a in range(3):
            out[i, a] += offd[p, a, 0] * d[j, 0] + offd[p, a, 1] * d[j, 1] + offd[p, a, 2] * d[j, 2]
            out[j, a] += offd[p, a, 0] * d[i, 0] + offd[p, a, 1] * d[i, 1] + offd[p, a, 2] * d[i, 2]


@njit(cache=True, nogil=True)
def bs_full_diagonal(diag, pairs, offd, out):
    """out (n, 3, 3) = the diagonal blocks of A: A_ii = B_i - sum_j G_ij."""
    out[:] = diag
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        for a in range(3):
            for b in range(3):
                out[i, a, b] -= offd[p, a, b]
                out[j, a, b] -= offd[p, a, b]


@njit(cache=True, nogil=True)
def pair_difference_product(pairs, weights, y, out):
    """out_i += sum_j H_ij (y_j - y_i) for pair blocks H (m, 3, 3): the product with a
    zero-row-sum matrix held by its pair blocks only (used for K v and bending forces)."""
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        for a in range(3):
            c = (weights[p, a, 0] * (y[j, 0] - y[i, 0]) + weights[p, a, 1] * (y[j, 1] - y[i, 1])
                 + weights[p, a, 2] * (y[j, 2] - y[i, 2]))
            out[i, a] += c
            out[j, a] -= c


@njit(cache=True, nogil=True, parallel=True)
def pair_scalar_product_rows(vp_ptr, vp_pair, vp_other, weights, y, out):
    """out_i = sum_j w_ij (y_j - y_i) over the pairs at vertex i (physics.incidence tables)
    for scalar pair blocks weights (m,) (w_ij I: bending), a vertex per thread:
    pair_difference_product's result for those blocks (out overwritten), gathered."""
    for i in prange(y.shape[0]):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(vp_ptr[i], vp_ptr[i + 1]):
            w = weights[vp_pair[k]]
            j = vp_other[k]
            s0 += w * (y[j, 0] - y[i, 0])
            s1 += w * (y[j, 1] - y[i, 1])
            s2 += w * (y[j, 2] - y[i, 2])
        out[i, 0] = s0
        out[i, 1] = s1
        out[i, 2] = s2


@dataclass
class RotationTerms:
    """What A's product with a rotation of the particles needs beyond A's blocks: positions
    (n, 3) m, where the elastic Hessian H was taken, and the elastic forces (n, 3) N there.

    The elastic energy does not change when the cloth turns, so H takes a rotation field
    theta x x to theta x (its gradient) = -theta x forces, and for a system built as B +
    hess_scale H (plus cloth-cloth springs, whose linearised blocks take it to zero) A's
    product is B_i (theta x x_i) - hess_scale theta x forces_i. That is exact where H is the
    energy's own Hessian; where the stretch Hessian's compression clamp drops a measure's
    share (a compressed face), it is an approximation. solvers.first_guess uses it."""

    positions: np.ndarray
    forces: np.ndarray


@dataclass
class BlockSystem:
    """A dv = b in block-symmetric form; see the module docstring.

    diag: (n, 3, 3) B blocks, kg. pairs: (m, 2) int64, i < j. offd: (m, 3, 3) G blocks, kg.
    hess_scale: where offd = hess_scale * (pair blocks of the elastic Hessian), the factor
    (h'^2 + h' damping, s^2); None for systems not built that way (coarse Galerkin levels).
    rotation: the positions and elastic forces a step's system was built at, for the
    products of rotations (RotationTerms); None where not known.
    """

    diag: np.ndarray
    pairs: np.ndarray
    offd: np.ndarray
    hess_scale: float | None = None
    rotation: RotationTerms | None = None

    @property
    def n(self) -> int:
        return self.diag.shape[0]

    def matvec(self, d: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """A d with Algorithm 1; d (n, 3) or (3n,), returns the same shape."""
        d3 = np.ascontiguousarray(d, dtype=np.float64).reshape(-1, 3)
        res = np.empty_like(d3) if out is None else out.reshape(-1, 3)
        bs_matvec(self.diag, self.pairs, self.offd, d3, res)
        return res.reshape(np.shape(d)) if out is None else out

    def full_diagonal(self) -> np.ndarray:
        """The 3x3 diagonal blocks A_ii, (n, 3, 3)."""
        out = np.empty_like(self.diag)
        bs_full_diagonal(self.diag, self.pairs, self.offd, out)
        return out

    def to_bsr(self) -> sp.bsr_matrix:
        """A as a scipy BSR matrix with 3x3 blocks, (3n, 3n)."""
        n = self.n
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        rows = np.concatenate([np.arange(n), i, j])
        cols = np.concatenate([np.arange(n), j, i])
        blocks = np.concatenate([self.full_diagonal(), self.offd,
                                 np.transpose(self.offd, (0, 2, 1))])
        order = np.lexsort((cols, rows))
        rows, cols, blocks = rows[order], cols[order], blocks[order]
        indptr = np.searchsorted(rows, np.arange(n + 1))
        return sp.bsr_matrix((blocks, cols, indptr), shape=(3 * n, 3 * n))

    def to_csr(self) -> sp.csr_matrix:
        """A as a scipy CSR matrix, (3n, 3n)."""
        return self.to_bsr().tocsr()

    def copy(self) -> BlockSystem:
        return BlockSystem(self.diag.copy(), self.pairs, self.offd.copy(), self.hess_scale,
                           self.rotation)
