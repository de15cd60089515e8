"""Every level of one multigrid solve in flat arrays, refilled for each solve, for the kernels
of solvers.packed_kernels.

The levels' unknowns are concatenated, finest first: level l holds the rows voff[l] ..
voff[l+1], in that level's sweep order (solvers.dissection: its parts, then its separator),
and ``bounds[l]`` holds the absolute rows where each part starts, then the separator's start
and end. Per row: the packed full diagonal block and its inverse, the filter. Per adjacency
slot, in two sets: the pairs that are no mesh edge (the wing tips of bending, on every level)
carry a scalar block w I, one number (``swts``); the others (edges, cloth-cloth springs) the
upper triangle of a full block (``frows``). A sweep then spends three multiply-adds instead of
nine on half its slots, and reads an eighth of the bytes there. Double precision throughout:
on a machine with large caches float32 rows' conversions cost more than their halved memory
traffic saves (doc/design-measurements.md, 'Packed levels', has the figures).

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

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from cloth_mg_ros.solvers.dissection import Ordering, slabs, split_ordering

__all__ = ["PackedLevel", "PackedLevels", "adjacency_csr", "pack_level"]


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
def split_rows(ptr, nbr, slot, mid):
    """Reorder each row's slots in place, the neighbours before the row (nbr < row) first,
    each group in its old order, and write where the later ones start, mid (n,): a forward
    sweep from zero reads only the earlier ones, and then loops over them without a test
    per slot (a branch on the neighbour's side mispredicted about every other slot)."""
    n = ptr.shape[0] - 1
    width = 0
    for i in range(n):
        width = max(width, ptr[i + 1] - ptr[i])
    tmp_n = np.empty(width, dtype=nbr.dtype)
    tmp_s = np.empty(width, dtype=slot.dtype)
    for i in range(n):
        lo = ptr[i]
        hi = ptr[i + 1]
        k = lo
        later = 0
        for q in range(lo, hi):
            if nbr[q] < i:
                nbr[k] = nbr[q]
                slot[k] = slot[q]
                k += 1
            else:
                tmp_n[later] = nbr[q]
                tmp_s[later] = slot[q]
                later += 1
        mid[i] = k
        for q in range(later):
            nbr[k + q] = tmp_n[q]
            slot[k + q] = tmp_s[q]


@njit(cache=True, nogil=True)
def add_to_rows(ptr, nbr, slot, mid, extra, extra_ids, out_ptr, out_nbr, out_slot, out_mid):
    """A level's adjacency (ptr, nbr, slot, mid: split_rows' layout) with the pairs extra
    (k, 2) (positions; their pair indices extra_ids (k,)) added after each row's own earlier
    and later neighbours, in pair order: the layout adjacency_csr and split_rows give the two
    sets of pairs together, without redoing the first set."""
    n = ptr.shape[0] - 1
    k = extra.shape[0]
    lo = np.zeros(n, dtype=np.int64)
    hi = np.zeros(n, dtype=np.int64)
    for e in range(k):
        a = extra[e, 0]
        b = extra[e, 1]
        if b < a:
            lo[a] += 1
            hi[b] += 1
        else:
            hi[a] += 1
            lo[b] += 1
    out_ptr[0] = 0
    for i in range(n):
        out_ptr[i + 1] = out_ptr[i] + (ptr[i + 1] - ptr[i]) + lo[i] + hi[i]
    fill_lo = np.empty(n, dtype=np.int64)
    fill_hi = np.empty(n, dtype=np.int64)
    for i in range(n):
        q = out_ptr[i]
        for s in range(ptr[i], mid[i]):
            out_nbr[q] = nbr[s]
            out_slot[q] = slot[s]
            q += 1
        fill_lo[i] = q
        q += lo[i]
        out_mid[i] = q
        for s in range(mid[i], ptr[i + 1]):
            out_nbr[q] = nbr[s]
            out_slot[q] = slot[s]
            q += 1
        fill_hi[i] = q
    for e in range(k):
        a = extra[e, 0]
        b = extra[e, 1]
        for row, other in ((a, b), (b, a)):
            if other < row:
                q = fill_lo[row]
                fill_lo[row] += 1
            else:
                q = fill_hi[row]
                fill_hi[row] += 1
            out_nbr[q] = other
            out_slot[q] = extra_ids[e]


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


@njit(cache=True, nogil=True, parallel=True)
def pack_level(diag, offd, order, free, fptr, fslot, sptr, sslot, voff, foff, soff, diag6,
               dinv6, bdiag6, frows, swts):
    """Pack one level (diag (n, 3, 3), offd (m, 3, 3) symmetric pair blocks) into rows
    voff.. in sweep order (order: the vertex of each position): diag6 / dinv6 (N, 6) the full
    diagonal blocks A_ii = B_i - sum_j G_ij and their inverses (zero where free == 0), bdiag6
    (N, 6) the blocks B_i themselves; the
    full pair blocks' upper triangles into frows (slots foff..), the scalar pair blocks'
    weights into swts (slots soff..). fptr, fslot / sptr, sslot: the level's two adjacencies
    over positions (slot -> pair index). A row per thread, each gathering its own pair blocks:
    the same numbers on any number of threads."""
    n = diag.shape[0]
    for q in prange(n):
        i = order[q]
        g = voff + q
        d0, d1, d2, d3, d4, d5 = _upper6(diag, i)
        _store6(bdiag6, g, d0, d1, d2, d3, d4, d5)
        for k in range(fptr[q], fptr[q + 1]):
            g0, g1, g2, g3, g4, g5 = _upper6(offd, fslot[k])
            _store6(frows, foff + k, g0, g1, g2, g3, g4, g5)
            d0, d1, d2 = d0 - g0, d1 - g1, d2 - g2
            d3, d4, d5 = d3 - g3, d4 - g4, d5 - g5
        for k in range(sptr[q], sptr[q + 1]):
            w = offd[sslot[k], 0, 0]
            swts[soff + k] = w
            d0, d3, d5 = d0 - w, d3 - w, d5 - w
        _store6(diag6, g, d0, d1, d2, d3, d4, d5)
        if free[g] == 0.0:
            for a in range(6):
                dinv6[g, a] = 0.0
        else:
            _inverse6(d0, d1, d2, d3, d4, d5, dinv6, g)


@njit(cache=True, nogil=True, inline="always")
def _upper6(blocks, p):
    """The upper triangle (xx, xy, xz, yy, yz, zz) of 3x3 block p of blocks (m, 3, 3)."""
    return (blocks[p, 0, 0], blocks[p, 0, 1], blocks[p, 0, 2], blocks[p, 1, 1],
            blocks[p, 1, 2], blocks[p, 2, 2])


@njit(cache=True, nogil=True, inline="always")
def _store6(out, row, v0, v1, v2, v3, v4, v5):
    """Write six numbers into out[row, :6]."""
    out[row, 0] = v0
    out[row, 1] = v1
    out[row, 2] = v2
    out[row, 3] = v3
    out[row, 4] = v4
    out[row, 5] = v5


@njit(cache=True, nogil=True, parallel=True)
def take_rows(v, idx, out):
    """out[k] = v[idx[k]] for rows of 3 (numpy's take on axis 0 ran on one thread: 0.1-0.15
    ms a call at 20K particles, three calls a solve)."""
    for k in prange(idx.shape[0]):
        i = idx[k]
        out[k, 0] = v[i, 0]
        out[k, 1] = v[i, 1]
        out[k, 2] = v[i, 2]


def _children(parents: np.ndarray, total: int) -> tuple:
    """(ptr (total + 1,), rows, weights): for every row, the rows whose parents (k, 2) name
    it, ascending, with the restriction's weight (1 where both parents are that row, 1/2
    where it is one of two)."""
    fine = np.arange(len(parents), dtype=np.int64)
    p0, p1 = parents[:, 0].astype(np.int64), parents[:, 1].astype(np.int64)
    two = p0 != p1
    coarse = np.concatenate([p0, p1[two]])
    rows = np.concatenate([fine, fine[two]])
    weights = np.concatenate([np.where(two, 0.5, 1.0), np.full(int(two.sum()), 0.5)])
    order = np.lexsort((rows, coarse))
    ptr = np.zeros(total + 1, dtype=np.int64)
    np.add.at(ptr, coarse + 1, 1)
    return (np.cumsum(ptr), rows[order].astype(np.int32),
            np.ascontiguousarray(weights[order]))


def scalar_pairs(level) -> np.ndarray:
    """(m,) bool over a mesh level's pairs: True where the pair is no edge (a wing tip pair,
    whose block holds only bending, w I, on every level of the faithful hierarchy)."""
    scalar = np.ones(level.n_pairs, dtype=bool)
    scalar[level.edge_pairs] = False
    return scalar


class _Slots:
    """One set of adjacency slots (full blocks or scalar ones) over every level's rows: per
    row start..stop, the earlier neighbours' slots start..mid and the later ones' mid..stop
    (`split_rows`), nbr the row at the other end, and the blocks' numbers (filled by
    pack_level). The coarse levels' slots come first and are laid out once; the finest
    level's after them, rebuilt when its pairs change."""

    def __init__(self, total: int, n_levels: int, width: int):
        # 32-bit row numbers: a sweep streams them with the blocks, and they are a sixth of
        # its bytes at 64 bits
        self.start = np.zeros(total, dtype=np.int32)
        self.mid = np.zeros(total, dtype=np.int32)
        self.stop = np.zeros(total, dtype=np.int32)
        self.nbr = np.zeros(0, dtype=np.int32)
        self.width = width
        self.values = np.zeros((0, width)) if width > 1 else np.zeros(0)
        self._store = self.values
        self.local: list = [None] * n_levels  # (ptr, slot, nbr, mid) over positions, per level
        self.base: list = [None] * n_levels  # the same of the last set_level
        self.off = [0] * n_levels
        self._coarse_nbr: np.ndarray | None = None

    def set_level(self, lvl: int, n: int, pos_pairs: np.ndarray, ids: np.ndarray) -> None:
        """Level lvl's adjacency: pairs pos_pairs (k, 2) over positions, their pair indices
        ids (k,) in the level's system. It is also kept as the level's base for
        `add_pairs`."""
        ptr = np.empty(n + 1, dtype=np.int64)
        nbr = np.empty(2 * len(pos_pairs), dtype=np.int64)
        slot = np.empty(2 * len(pos_pairs), dtype=np.int64)
        adjacency_csr(np.ascontiguousarray(pos_pairs), n, ptr, nbr, slot)
        mid = np.empty(n, dtype=np.int64)
        split_rows(ptr, nbr, slot, mid)
        self.local[lvl] = self.base[lvl] = (ptr, ids[slot], nbr, mid)

    def add_pairs(self, lvl: int, pos_pairs: np.ndarray, ids: np.ndarray) -> None:
        """Level lvl's adjacency: its base (the last `set_level`) and the pairs pos_pairs
        (k, 2) over positions, pair indices ids (k,), after them (`add_to_rows`)."""
        ptr, slot, nbr, mid = self.base[lvl]
        if not len(pos_pairs):
            self.local[lvl] = self.base[lvl]
            return
        n = len(ptr) - 1
        size = len(nbr) + 2 * len(pos_pairs)
        out = (np.empty(n + 1, dtype=np.int64), np.empty(size, dtype=np.int64),
               np.empty(size, dtype=np.int64), np.empty(n, dtype=np.int64))
        add_to_rows(ptr, nbr, slot, mid, np.ascontiguousarray(pos_pairs, dtype=np.int64),
                    np.ascontiguousarray(ids, dtype=np.int64), out[0], out[2], out[1], out[3])
        self.local[lvl] = out

    def _place(self, voff: np.ndarray, lvl: int, off: int) -> np.ndarray:
        ptr, _, nbr, mid = self.local[lvl]
        lo, hi = int(voff[lvl]), int(voff[lvl + 1])
        self.start[lo:hi] = off + ptr[:-1]
        self.mid[lo:hi] = off + mid
        self.stop[lo:hi] = off + ptr[1:]
        self.off[lvl] = off
        return nbr + lo

    def layout(self, voff: np.ndarray, coarse_changed: bool) -> None:
        """Place the slots (the coarse levels' again only when they changed)."""
        if self._coarse_nbr is None or coarse_changed:
            parts, off = [], 0
            for lvl in range(1, len(self.local)):
                parts.append(self._place(voff, lvl, off))
                off += len(self.local[lvl][1])
            self._coarse_nbr = (np.concatenate(parts) if parts
                                else np.zeros(0, dtype=np.int64))
        fine = self._place(voff, 0, len(self._coarse_nbr))
        self.nbr = np.concatenate([self._coarse_nbr, fine]).astype(np.int32)
        # The blocks' numbers: the first rows of an array kept with room to spare, so that
        # springs coming and going do not cost fresh pages (megabytes) every step.
        k = len(self.nbr)
        if len(self._store) < k:
            room = k + k // 16 + 64
            self._store = np.empty((room, self.width) if self.width > 1 else room)
        self.values = self._store[:k]


@dataclass(frozen=True)
class PackedLevel:
    """One level of a `PackedLevels`, as data: views into the flat arrays, in the level's
    sweep order (PyAMG's ``ml.levels[k]`` is the model).

    index: 0 the finest; rows: its slice of the flat rows; particles (its unknowns are 3x
    that); full_blocks, scalar_blocks: the off-diagonal 3 x 3 blocks it stores (each pair
    once per end: full ones as upper triangles, scalar ones as one weight); diag6, dinv6
    (particles, 6): the full diagonal blocks A_ii and their inverses (upper triangles);
    free (particles,): the filter (0 on pinned particles); parents (particles, 2): each
    row's two parents as rows of the next level (None on the coarsest); order: the vertex of
    each row (None before the first fill).
    """

    index: int
    rows: slice
    particles: int
    full_blocks: int
    scalar_blocks: int
    diag6: np.ndarray
    dinv6: np.ndarray
    free: np.ndarray
    parents: np.ndarray | None
    order: np.ndarray | None

    @property
    def nonzero_blocks(self) -> int:
        """Nonzero 3 x 3 blocks of the level's operator: diagonal and both triangles."""
        return self.particles + self.full_blocks + self.scalar_blocks


class PackedLevels:
    """The flat arrays of a hierarchy's first ``len(sizes)`` levels (module docstring).

    sizes: vertices per level, finest first; parents: per level but the coarsest, the (n_l, 2)
    parents map onto the next level (vertex indices); rest: per level, its rest positions
    (n_l, 3), m, which place the parts; scalar: per level, which of its mesh pairs carry a
    scalar block (`scalar_pairs`; pairs beyond them, cloth-cloth springs, are full); parts:
    parts per level (1: the natural order, no separator).
    """

    def __init__(self, sizes: list[int], parents: list[np.ndarray], rest: list[np.ndarray],
                 scalar: list[np.ndarray], parts: int = 1):
        self.n_levels = len(sizes)
        self.parts = max(1, int(parts))
        self.voff = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.voff[-1])
        self._parents_local = [np.ascontiguousarray(p, dtype=np.int64) for p in parents]
        self._scalar = [np.asarray(m, dtype=bool) for m in scalar]
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
        self.parents = np.zeros((total, 2), dtype=np.int32)
        # each coarse row's fine rows and weights, for the restriction's gather
        self.kids = (np.zeros(total + 1, dtype=np.int64), np.zeros(0, dtype=np.int32),
                     np.zeros(0))
        self.diag6 = np.zeros((total, 6))
        self.dinv6 = np.zeros((total, 6))
        self.bdiag6 = np.zeros((total, 6))  # the systems' B_i (mass, contacts), packed
        self.free = np.ones(total)
        self.b = np.zeros((total, 3))
        self.x = np.zeros((total, 3))
        self.r = np.zeros((total, 3))
        # the outer CG's finest-level vectors (x, b, p, q, w), kept: no fresh pages per solve
        self.outer = np.zeros((5, int(self.voff[1]), 3))
        self.touched = np.zeros(int(self.voff[1]), dtype=np.uint8)  # packed_kernels.touched_rows
        # the finest rows' positions less their mean and the scaled elastic gradient, for the
        # rotations of the first guess (solvers.first_guess.rigid_guess)
        self.rigid_rows = np.zeros((2, int(self.voff[1]), 3))
        self.last_guess: str | None = None  # the last solve's first guess: rigid, translation
        self.full = _Slots(total, self.n_levels, 6)
        self.scal = _Slots(total, self.n_levels, 1)
        self._pairs: list = [None] * self.n_levels
        self._mesh_cut: list = [None] * self.n_levels  # (mesh pairs, their separator)

    @property
    def slots(self) -> tuple:
        """The adjacency arrays the kernels take: full starts, mids, stops, neighbours,
        blocks, then the scalar ones."""
        f, s = self.full, self.scal
        return (f.start, f.mid, f.stop, f.nbr, f.values, s.start, s.mid, s.stop, s.nbr,
                s.values)

    # -- layout -------------------------------------------------------------------------------
    def _relayout(self, lvl: int, pairs: np.ndarray) -> tuple[bool, bool]:
        """Level lvl's ordering and adjacencies for these pairs (kept while they stay equal).
        Returns (rebuilt, reordered): whether the full blocks' slots were rebuilt, and
        whether the ordering (hence the scalar slots too) changed.

        Cloth-cloth springs come and go every step on a folding garment; they only add full
        blocks after the mesh's pairs. While they put no new vertex into the separator, the
        ordering and the scalar slots stay, and only the full blocks' slots are rebuilt (a
        whole relayout cost 3-4 ms a step at 20K particles)."""
        cached = self._pairs[lvl]
        if cached is not None and (cached is pairs or (
                cached.shape == pairs.shape and np.array_equal(cached, pairs))):
            return False, False
        pairs = np.ascontiguousarray(pairs, dtype=np.int64)
        n_mesh = len(self._scalar[lvl])
        slab = self._slabs[lvl]
        same_mesh = False
        if len(pairs) >= n_mesh:
            # the mesh's separator, made once; the springs' crossings added to it give the
            # same ordering as all pairs at once (split_ordering is a function of the set)
            mesh = self._mesh_cut[lvl]
            same_mesh = mesh is not None and np.array_equal(mesh[0], pairs[:n_mesh])
            if not same_mesh:
                mesh = (pairs[:n_mesh].copy(),
                        split_ordering(slab, pairs[:n_mesh], self.parts).separator_mask())
                self._mesh_cut[lvl] = mesh
            ordering = split_ordering(slab, pairs[n_mesh:], self.parts, mesh[1])
        else:
            ordering = split_ordering(slab, pairs, self.parts)
        old = self.orderings[lvl]
        keep_order = (same_mesh and old is not None
                      and np.array_equal(old.order, ordering.order))
        if keep_order:
            ordering = old
        else:
            self.orderings[lvl] = ordering
            self.bounds[lvl] = self.voff[lvl] + ordering.bounds
        # The mesh's slots are made again only with a new ordering; the springs (pairs beyond
        # the mesh's, full blocks) are added to the full ones.
        n_ordered = len(ordering.order)
        if not keep_order:
            scalar = self._scalar[lvl][: len(pairs)]
            for kind, keep in ((self.full, ~scalar), (self.scal, scalar)):
                ids = np.flatnonzero(keep).astype(np.int64)
                kind.set_level(lvl, n_ordered, ordering.pos[pairs[ids]], ids)
        n_own = min(n_mesh, len(pairs))
        self.full.add_pairs(lvl, ordering.pos[pairs[n_own:]],
                            np.arange(n_own, len(pairs), dtype=np.int64))
        self._pairs[lvl] = pairs
        return True, not keep_order

    def _link_parents(self) -> None:
        """Each fine row's parents as rows of the next level (both in sweep order)."""
        for lvl in range(self.n_levels - 1):
            fine, coarse = self.orderings[lvl], self.orderings[lvl + 1]
            local = self._parents_local[lvl][fine.order]
            lo, hi = int(self.voff[lvl]), int(self.voff[lvl + 1])
            self.parents[lo:hi] = self.voff[lvl + 1] + coarse.pos[local]
        self.kids = _children(self.parents[: int(self.voff[-2])], int(self.voff[-1]))

    def fill(self, systems: list, fixed: np.ndarray | None) -> None:
        """Pack one solve's systems (finest first, a BlockSystem each); fixed (n_0,) bool
        marks the finest level's pinned particles (filtered: free = 0)."""
        done = [self._relayout(lvl, s.pairs) for lvl, s in enumerate(systems)]
        rebuilt = [r for r, _ in done]
        reordered = [o for _, o in done]
        first = self.full.values.shape[0] == 0 and self.scal.values.shape[0] == 0
        if first or any(reordered):
            for kind in (self.full, self.scal):
                kind.layout(self.voff, first or any(rebuilt[1:]))
            self._link_parents()
        elif any(rebuilt):  # only the full blocks' slots changed
            self.full.layout(self.voff, any(rebuilt[1:]))
        n0 = int(self.voff[1])
        self.free[:n0] = 1.0
        if fixed is not None:
            self.free[self.orderings[0].pos[np.asarray(fixed, dtype=bool)]] = 0.0
        for lvl, s in enumerate(systems):
            fptr, fslot = self.full.local[lvl][:2]
            sptr, sslot = self.scal.local[lvl][:2]
            pack_level(s.diag, s.offd, self.orderings[lvl].order, self.free, fptr, fslot,
                       sptr, sslot, self.voff[lvl], self.full.off[lvl], self.scal.off[lvl],
                       self.diag6, self.dinv6, self.bdiag6, self.full.values,
                       self.scal.values)

    # -- the finest level's vectors in and out ------------------------------------------------
    def to_rows(self, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """A finest-level vector (n_0, 3) in vertex order, in sweep order (a copy, into
        ``out`` (n_0, 3) when given)."""
        order = self.orderings[0].order
        if out is None:
            out = np.empty((len(order), 3))
        take_rows(np.ascontiguousarray(v, dtype=np.float64), order, out)
        return out

    def from_rows(self, v: np.ndarray) -> np.ndarray:
        """A finest-level vector (n_0, 3) in sweep order, back in vertex order (a copy)."""
        pos = self.orderings[0].pos
        out = np.empty((len(pos), 3))
        take_rows(v, pos, out)
        return out

    @property
    def levels(self) -> list[PackedLevel]:
        """The levels, finest first, as `PackedLevel` views (valid until the next fill)."""
        out = []
        for lvl in range(self.n_levels):
            lo, hi = int(self.voff[lvl]), int(self.voff[lvl + 1])
            rows = slice(lo, hi)
            ordering = self.orderings[lvl]
            out.append(PackedLevel(
                lvl, rows, hi - lo, _slot_count(self.full, rows), _slot_count(self.scal, rows),
                self.diag6[rows], self.dinv6[rows], self.free[rows],
                self.parents[rows] if lvl < self.n_levels - 1 else None,
                None if ordering is None else ordering.order))
        return out

    def __str__(self) -> str:
        """The levels as PyAMG prints a multilevel solver: per level its particles, unknowns
        and nonzero blocks, and the operator and grid complexities."""
        levels = self.levels
        nnz = [lv.nonzero_blocks for lv in levels]
        lines = [f"PackedLevels: {self.n_levels} levels, {self.parts} parts per level; "
                 f"operator complexity {sum(nnz) / nnz[0]:.3f}, grid complexity "
                 f"{sum(lv.particles for lv in levels) / levels[0].particles:.3f}",
                 "  level  particles  unknowns  nonzero blocks  [%]"]
        lines += [f"  {lv.index:5d}  {lv.particles:9d}  {3 * lv.particles:8d}  {z:14d}  "
                  f"{100 * z / sum(nnz):5.2f}" for lv, z in zip(levels, nnz, strict=True)]
        return "\n".join(lines)

    @property
    def fine_chunks(self) -> np.ndarray:
        """(parts + 1,) even chunks of the finest level's rows."""
        return self.chunks[0]


def _slot_count(slots: _Slots, rows: slice) -> int:
    """The slots (off-diagonal blocks) of rows ``rows`` in one slot set."""
    return int(np.sum(slots.stop[rows].astype(np.int64) - slots.start[rows]))
