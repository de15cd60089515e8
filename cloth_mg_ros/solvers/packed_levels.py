"""Every level of one multigrid solve in flat arrays, refilled for each solve, for the kernels
of solvers.packed_kernels.

The levels' unknowns are concatenated, finest first: level l holds the rows voff[l] ..
voff[l+1], in that level's sweep order (solvers.dissection: its parts, then its separator),
and ``bounds[l]`` holds the absolute rows where each part starts, then the separator's start
and end. Per row: the packed full diagonal block and its inverse, the filter; per adjacency
slot: the packed pair block, in double precision (on this machine's large caches the float32
rows' conversions cost more than their halved memory traffic saved: a Gauss-Seidel sweep at
2.4K particles 115 -> 81 us, a 20K iteration 5.4 -> 4.8 ms).

Why flat arrays and a handful of kernels: at the sizes a live node runs (1-5K particles) a
Python-level V-cycle spent a large part of each CG iteration calling small kernels one level
at a time and allocating scratch arrays. Here one CG iteration is four kernel calls and the
coarsest level's Cholesky solve.

What stays fixed and what is rebuilt: the coarse levels' pairs are the mesh's, so their
orderings and adjacency are made once; the finest level's pairs change whenever cloth-cloth
contact springs come or go, and then its ordering (a spring across a cut puts an end into the
separator), its adjacency and the parents maps that point into it are rebuilt.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cloth_mg_ros.solvers.dissection import Ordering, slabs, split_ordering

__all__ = ["PackedLevels", "adjacency_csr", "pack_level"]


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
def pack_level(diag, pairs, offd, order, pos, free, ptr, slot, voff, aoff, diag6, dinv6,
               rows):
    """Pack one level (diag (n, 3, 3), pairs (m, 2) in vertex indices, offd (m, 3, 3)
    symmetric blocks) into rows voff.. in sweep order (order: vertex of each position, pos:
    its inverse) and adjacency slots aoff..: diag6 / dinv6 (N, 6) the full diagonal blocks and
    their inverses (zero where free == 0), rows (M, 6) the pair blocks in adjacency order.
    ptr, slot: the level's adjacency over positions (adjacency_csr)."""
    n = diag.shape[0]
    for q in range(n):
        i = order[q]
        g = voff + q
        diag6[g, 0] = diag[i, 0, 0]
        diag6[g, 1] = diag[i, 0, 1]
        diag6[g, 2] = diag[i, 0, 2]
        diag6[g, 3] = diag[i, 1, 1]
        diag6[g, 4] = diag[i, 1, 2]
        diag6[g, 5] = diag[i, 2, 2]
    for p in range(pairs.shape[0]):
        _sub6(offd, p, diag6, voff + pos[pairs[p, 0]])
        _sub6(offd, p, diag6, voff + pos[pairs[p, 1]])
    for q in range(n):
        g = voff + q
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


class PackedLevels:
    """The flat arrays of a hierarchy's first ``len(sizes)`` levels (module docstring).

    sizes: vertices per level, finest first; parents: per level but the coarsest, the (n_l, 2)
    parents map onto the next level (vertex indices); rest: per level, its rest positions
    (n_l, 3), m, which place the parts; parts: parts per level (1: the natural order, no
    separator).
    """

    def __init__(self, sizes: list[int], parents: list[np.ndarray], rest: list[np.ndarray],
                 parts: int = 1):
        self.n_levels = len(sizes)
        self.parts = max(1, int(parts))
        self.voff = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.voff[-1])
        self._parents_local = [np.ascontiguousarray(p, dtype=np.int64) for p in parents]
        # The coarsest level of several is solved directly, never swept: it keeps the natural
        # order its Cholesky factor was made in.
        self._slabs = [slabs(np.asarray(r, dtype=np.float64),
                             1 if lvl == self.n_levels - 1 > 0 else self.parts)
                       for lvl, r in enumerate(rest)]
        self.orderings: list[Ordering | None] = [None] * self.n_levels
        self.bounds = np.zeros((self.n_levels, self.parts + 2), dtype=np.int64)
        # Even chunks of each level's rows, one per part, for the row-independent kernels
        # (products, updates, interpolation): balanced on `parts` threads, and the sums
        # formed per chunk, so the result does not depend on the threads.
        self.chunks = np.array([np.linspace(self.voff[lvl], self.voff[lvl + 1],
                                            self.parts + 1).round()
                                for lvl in range(self.n_levels)], dtype=np.int64)
        self.parents = np.zeros((total, 2), dtype=np.int64)
        self.diag6 = np.zeros((total, 6))
        self.dinv6 = np.zeros((total, 6))
        self.free = np.ones(total)
        self.b = np.zeros((total, 3))
        self.x = np.zeros((total, 3))
        self.r = np.zeros((total, 3))
        self.start = np.zeros(total, dtype=np.int64)
        self.stop = np.zeros(total, dtype=np.int64)
        self._local: list = [None] * self.n_levels  # (pairs, ptr, slot, nbr) per level
        self._slot_off = [0] * self.n_levels
        self._coarse_nbr: np.ndarray | None = None
        self.nbr = np.zeros(0, dtype=np.int64)
        self.rows = np.zeros((0, 6))

    # -- layout -------------------------------------------------------------------------------
    def _relayout(self, lvl: int, pairs: np.ndarray) -> bool:
        """Level lvl's ordering and adjacency for these pairs (kept while they stay equal);
        True when rebuilt."""
        cached = self._local[lvl]
        if cached is not None and (cached[0] is pairs or (
                cached[0].shape == pairs.shape and np.array_equal(cached[0], pairs))):
            return False
        pairs = np.ascontiguousarray(pairs, dtype=np.int64)
        ordering = split_ordering(self._slabs[lvl], pairs, self.parts)
        self.orderings[lvl] = ordering
        self.bounds[lvl] = self.voff[lvl] + ordering.bounds
        n = len(ordering.order)
        ptr = np.empty(n + 1, dtype=np.int64)
        nbr = np.empty(2 * len(pairs), dtype=np.int64)
        slot = np.empty(2 * len(pairs), dtype=np.int64)
        adjacency_csr(ordering.pos[pairs], n, ptr, nbr, slot)
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

    def _link_parents(self) -> None:
        """Each fine row's parents as rows of the next level (both in sweep order)."""
        for lvl in range(self.n_levels - 1):
            fine, coarse = self.orderings[lvl], self.orderings[lvl + 1]
            local = self._parents_local[lvl][fine.order]
            lo, hi = int(self.voff[lvl]), int(self.voff[lvl + 1])
            self.parents[lo:hi] = self.voff[lvl + 1] + coarse.pos[local]

    def fill(self, systems: list, fixed: np.ndarray | None) -> None:
        """Pack one solve's systems (finest first, a BlockSystem each); fixed (n_0,) bool
        marks the finest level's pinned particles (filtered: free = 0)."""
        rebuilt = [self._relayout(lvl, s.pairs) for lvl, s in enumerate(systems)]
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
            self.rows = np.empty((len(self.nbr), 6))
            self._link_parents()
        n0 = int(self.voff[1])
        self.free[:n0] = 1.0
        if fixed is not None:
            self.free[self.orderings[0].pos[np.asarray(fixed, dtype=bool)]] = 0.0
        for lvl, s in enumerate(systems):
            pairs, ptr, slot, _ = self._local[lvl]
            o = self.orderings[lvl]
            pack_level(s.diag, pairs, s.offd, o.order, o.pos, self.free, ptr, slot,
                       self.voff[lvl], self._slot_off[lvl], self.diag6, self.dinv6, self.rows)

    # -- the finest level's vectors in and out ------------------------------------------------
    def to_rows(self, v: np.ndarray) -> np.ndarray:
        """A finest-level vector (n_0, 3) in vertex order, in sweep order (a copy)."""
        return np.ascontiguousarray(v[self.orderings[0].order])

    def from_rows(self, v: np.ndarray) -> np.ndarray:
        """A finest-level vector (n_0, 3) in sweep order, back in vertex order (a copy)."""
        return np.ascontiguousarray(v[self.orderings[0].pos])

    @property
    def fine_chunks(self) -> np.ndarray:
        """(parts + 1,) even chunks of the finest level's rows."""
        return self.chunks[0]
