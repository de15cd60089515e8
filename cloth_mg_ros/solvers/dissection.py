"""Orderings of a level's vertices that let Gauss-Seidel sweep on several threads and stay a
plain Gauss-Seidel sweep: `parts` independent parts, then a separator.

The vertices are split into `parts` slabs along the longest axis of the level's rest shape
(equal counts); every pair whose two ends fall in different slabs puts one end (the one in the
later slab) into the separator. Then no pair joins two parts, so a sweep over the parts can
run them at once, each in its own order, and the separator follows on one thread. That is a
sequential Gauss-Seidel sweep in the order part 0, part 1, ..., separator, whichever thread
swept which part: the result depends on the ordering (on `parts`), never on the threads or
their timing. With one part the order is the natural one (no separator).

Why not colours: a multicolour sweep needs one parallel region per colour (8-16 on these
meshes with their bending pairs) and visits memory in a scattered order; two to a few large
parts keep each thread's sweep sequential and cache-friendly, and the separator (a ring or two
of vertices across the cut, 4-6 % of a garment per cut) is all that runs alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_PART_VERTICES", "Ordering", "slabs", "split_ordering"]

MIN_PART_VERTICES = 256  # a level with fewer vertices per part is not split (no gain)


def slabs(rest: np.ndarray, parts: int) -> np.ndarray:
    """(n,) the slab (0..parts-1) of each vertex: equal counts along the principal axis of the
    rest positions rest (n, 3), m. A level too small for `parts` slabs of MIN_PART_VERTICES
    gets fewer (the others stay empty)."""
    n = len(rest)
    parts = max(1, min(parts, n // MIN_PART_VERTICES))
    if parts == 1:
        return np.zeros(n, dtype=np.int64)
    centred = rest - rest.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    along = centred @ vecs[:, -1]
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(along, kind="stable")] = np.arange(n)
    return rank * parts // n


@dataclass(frozen=True)
class Ordering:
    """order (n,): original vertex indices in sweep order; pos (n,): the inverse (a vertex's
    position); bounds (parts + 2,): positions where each part starts, then where the separator
    starts and ends (= n)."""

    order: np.ndarray
    pos: np.ndarray
    bounds: np.ndarray

    @property
    def parts(self) -> int:
        return len(self.bounds) - 2

    @property
    def separator(self) -> int:
        """Vertices in the separator."""
        return int(self.bounds[-1] - self.bounds[-2])

    def separator_mask(self) -> np.ndarray:
        """(n,) bool: the vertices in the separator."""
        mask = np.zeros(len(self.order), dtype=bool)
        mask[self.order[self.bounds[-2]:]] = True
        return mask


def split_ordering(slab: np.ndarray, pairs: np.ndarray, parts: int,
                   separator: np.ndarray | None = None) -> Ordering:
    """The parts-then-separator ordering of vertices in slabs `slab` (n,) for the pairs
    (m, 2) that couple them (see the module docstring); within a part and within the
    separator the natural order is kept. separator: (n,) bool vertices already in the
    separator (those of other pairs: the ordering of both sets of pairs together)."""
    n = len(slab)
    sep = np.zeros(n, dtype=bool) if separator is None else separator.copy()
    if parts > 1 and len(pairs):
        a, b = slab[pairs[:, 0]], slab[pairs[:, 1]]
        cross = a != b
        later = np.where(a[cross] > b[cross], pairs[cross, 0], pairs[cross, 1])
        sep[later] = True
    key = np.where(sep, parts, slab)
    order = np.argsort(key, kind="stable").astype(np.int64)
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    counts = np.bincount(key, minlength=parts + 1)
    bounds = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return Ordering(order, pos, bounds)
