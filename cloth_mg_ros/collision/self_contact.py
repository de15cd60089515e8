"""Cloth-cloth contact: particle-particle repulsion springs found with a spatial hash.

As in the paper (Sec. 7.1): particles of the cloth closer than a contact distance ``d0`` (m)
that are not near each other on the cloth itself (rest distance above ``2 d0``) get a stiff
repulsive spring E = k/2 (d0 - |x_j - x_i|)^2 while closer than d0. The pairs are found with
a uniform voxel grid of cell size d0 (hashed, counting-sorted; 27 cells per query), and the
springs enter the implicit system as extra pair blocks: block-symmetric (one 3x3 block per
pair, G_ij = G_ji, zero row sums), so Algorithm 1 and the smoothers take them as they are.
The multigrid's coarse levels do not carry them: they are local, stiff and change every step,
which is what the fine-level smoothing handles; the outer CG iteration sees them exactly.

Scenes that cannot fold onto themselves leave this off and pay nothing for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.frozen_arrays import FrozenArrays, frozen

PAIR_CHUNKS = 64  # particle chunks of the pair search, shared out among the threads
# Pairs a chunk of the search may keep, per particle in it: the output is allocated up front
# (16 n pairs) so the threads write without a count pass; a chunk's pairs past it are dropped
# (counted: close_pairs' second result, SelfContact.dropped) and wait for a later step.
PAIRS_PER_PARTICLE = 16
# Hash table slots per particle (rounded up to a power of two): most of a particle's 14
# probes land on empty cells, and a sparser table finds fewer other cells' particles there
# (at 20K particles 4 against 2 with 32-bit starts: 1.75 -> 1.50 ms; 8 and 16 were slower,
# the table no longer in the core's cache).
TABLE_LOAD = 4


# Cell hashes: the classic three primes, masked to a power-of-two table. (A modulo by an odd
# table size was an integer division per cell and query, 28 per particle: at 20K particles
# it was most of the search.)
_PX, _PY, _PZ = 73856093, 19349663, 83492791


_CELL_BITS = 21  # bits of each cell coordinate in a packed cell key
_CELL_MASK = (1 << _CELL_BITS) - 1


@njit(cache=True, nogil=True, inline="always")
def _cell_key(ix, iy, iz):
    """The cell (ix, iy, iz) packed into one integer, each coordinate modulo 2^21: cells that
    differ by at most 1 in each coordinate never share a key (a neighbour is then told from
    a hash collision by one comparison)."""
    return ((ix & _CELL_MASK) << 42) | ((iy & _CELL_MASK) << 21) | (iz & _CELL_MASK)


@njit(cache=True, nogil=True, inline="always")
def _hash(ix, iy, iz, mask):
    return ((ix * _PX) ^ (iy * _PY) ^ (iz * _PZ)) & mask


@njit(cache=True, nogil=True)
def _bucket(x, inv, mask):
    """Counting sort of the particles by cell hash: start (mask + 2,) int32 (half the bytes
    of a table the probes read at random), and in that sorted order each particle's index
    (n,), position (n, 3) and packed cell key (n,), so that a bucket's particles are read
    side by side."""
    n = x.shape[0]
    key = np.empty(n, dtype=np.int64)
    cells = np.empty(n, dtype=np.int64)
    for i in range(n):
        ix = np.int64(np.floor(x[i, 0] * inv))
        iy = np.int64(np.floor(x[i, 1] * inv))
        iz = np.int64(np.floor(x[i, 2] * inv))
        cells[i] = _cell_key(ix, iy, iz)
        key[i] = _hash(ix, iy, iz, mask)
    start = np.zeros(mask + 2, dtype=np.int32)
    for i in range(n):
        start[key[i] + 1] += 1
    for c in range(mask + 1):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    xs = np.empty((n, 3))
    cs = np.empty(n, dtype=np.int64)
    for i in range(n):
        s = fill[key[i]]
        order[s] = i
        xs[s, 0] = x[i, 0]
        xs[s, 1] = x[i, 1]
        xs[s, 2] = x[i, 2]
        cs[s] = cells[i]
        fill[key[i]] += 1
    return start, order, xs, cs


@njit(cache=True, nogil=True)
def _near(q, xs, cs, order, rest, inv, d2, r2, mask, start, out, k, cap):
    """The partners of the particle at sorted place q (close now, far apart at rest): those
    after it in its own cell and those in the 13 cells of the half of its neighbourhood
    after it, into out[k:cap] as (min, max); returns the new k and how many partners found
    no room (k at cap). Every pair of neighbouring
    cells is searched from one side only, so each pair is found once, half the work of
    searching all 27 cells. A bucket can hold particles of other cells (hash collisions):
    only those of the searched cell count."""
    i = order[q]
    x0 = xs[q, 0]
    x1 = xs[q, 1]
    x2 = xs[q, 2]
    ix = np.int64(np.floor(x0 * inv))
    iy = np.int64(np.floor(x1 * inv))
    iz = np.int64(np.floor(x2 * inv))
    dropped = 0
    for dx in range(2):
        for dy in range(-1 if dx == 1 else 0, 2):
            for dz in range(-1 if dx == 1 or dy == 1 else 0, 2):
                cx = ix + dx
                cy = iy + dy
                cz = iz + dz
                own = dx == 0 and dy == 0 and dz == 0
                want = _cell_key(cx, cy, cz)
                c = _hash(cx, cy, cz, mask)
                for s in range(q + 1 if own else start[c], start[c + 1]):
                    if cs[s] != want:
                        continue
                    e0 = xs[s, 0] - x0
                    e1 = xs[s, 1] - x1
                    e2 = xs[s, 2] - x2
                    if e0 * e0 + e1 * e1 + e2 * e2 >= d2:
                        continue
                    j = order[s]
                    h0 = rest[j, 0] - rest[i, 0]
                    h1 = rest[j, 1] - rest[i, 1]
                    h2 = rest[j, 2] - rest[i, 2]
                    if h0 * h0 + h1 * h1 + h2 * h2 < r2:
                        continue
                    if k == cap:
                        dropped += 1
                        continue
                    out[k, 0] = min(i, j)
                    out[k, 1] = max(i, j)
                    k += 1
    return k, dropped


@njit(cache=True, nogil=True, parallel=True)
def close_pairs(x, rest, d0, min_rest):
    """(pairs, dropped): pairs (k, 2) i < j with |x_j - x_i| < d0 and |rest_j - rest_i| >=
    min_rest, sorted by i, then j, and how many such pairs were left out. The particles go in
    their sorted (bucket) order in fixed chunks on the threads, each chunk writing into its
    own stretch of the output (at most PAIRS_PER_PARTICLE pairs per particle of the chunk:
    the chunk's later ones are dropped, counted in `dropped`, and wait for a later step),
    then the chunks are joined and sorted: the same pairs
    in the same order on any number of threads, each once. A bucket's particles are read
    side by side from the sorted copies, and a cell is told from a hash collision by one
    key (each particle's three coordinates read through its index: 2.1 against 1.75 ms at
    20K particles)."""
    n = x.shape[0]
    inv = 1.0 / d0
    mask = 1
    while mask < TABLE_LOAD * n:
        mask *= 2
    mask -= 1
    start, order, xs, cs = _bucket(x, inv, mask)
    d2 = d0 * d0
    r2 = min_rest * min_rest
    per = PAIRS_PER_PARTICLE
    chunks = min(PAIR_CHUNKS, max(n, 1))
    out = np.empty((per * n, 2), dtype=np.int64)
    found = np.zeros(chunks, dtype=np.int64)
    lost = np.zeros(chunks, dtype=np.int64)
    for ch in prange(chunks):
        lo = ch * n // chunks
        hi = (ch + 1) * n // chunks
        k = per * lo
        for q in range(lo, hi):
            k, d = _near(q, xs, cs, order, rest, inv, d2, r2, mask, start, out, k, per * hi)
            lost[ch] += d
        found[ch] = k - per * lo
    dropped = 0
    for ch in range(chunks):
        dropped += lost[ch]
    total = 0
    for ch in range(chunks):
        total += found[ch]
    keys = np.empty(total, dtype=np.int64)
    k = 0
    for ch in range(chunks):
        lo = per * (ch * n // chunks)
        for q in range(found[ch]):
            keys[k] = out[lo + q, 0] * n + out[lo + q, 1]
            k += 1
    keys.sort()
    pairs = np.empty((total, 2), dtype=np.int64)
    for q in range(total):
        pairs[q, 0] = keys[q] // n
        pairs[q, 1] = keys[q] - pairs[q, 0] * n
    return pairs, dropped


@njit(cache=True, nogil=True)
def spring_forces_hessians(x, pairs, d0, k_spring, forces, hess):
    """Contact springs linearised at x: add forces (n, 3), write pair Hessians hess
    (k, 3, 3); returns the energy, J (of the pairs closer than d0). Compression-clamped like
    the stretch terms (only the d d^T part). A pair found at its predicted positions can be
    further than d0 now: its linearised force is then attractive, and together with the
    implicit step's K v term it pushes exactly by how far the pair would come inside d0."""
    energy = 0.0
    for p in range(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        d = x[j] - x[i]
        dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        for a in range(3):
            for b in range(3):
                hess[p, a, b] = 0.0
        if dn < 1e-12:
            continue
        gap = d0 - dn
        if gap > 0.0:
            energy += 0.5 * k_spring * gap * gap
        for a in range(3):
            f = k_spring * gap * d[a] / dn
            forces[i, a] -= f
            forces[j, a] += f
        # Hessian block between i and j (c_i c_j = -1): -k d d^T / |d|^2.
        for a in range(3):
            for b in range(3):
                hess[p, a, b] = -k_spring * d[a] * d[b] / (dn * dn)
    return energy


@dataclass
class SelfContact(FrozenArrays):
    """Cloth-cloth contact of one mesh: rest (n, 3) rest positions, m; distance d0 (m);
    stiffness as a multiple of m / h^2 (dimensionless, like the body contacts), finite and
    positive. dropped: the close pairs the last `pairs` call left out (more than
    PAIRS_PER_PARTICLE per particle of a search chunk): each step reports it
    (sim.integrator.StepStats.self_contact_dropped, on to cloth/stats and summary.json)."""

    rest: np.ndarray
    distance: float
    stiffness: float = 10.0
    dropped: int = field(default=0, init=False, compare=False)

    def __post_init__(self) -> None:
        if not self.distance > 0.0:
            raise ClothInputError(f"self contact distance must be positive, got {self.distance}")
        if not (np.isfinite(self.stiffness) and self.stiffness > 0.0):
            raise ClothInputError(f"self contact stiffness must be finite and positive, got "
                                  f"{self.stiffness!r}")
        self.rest = frozen(np.array(self.rest, dtype=np.float64))

    @classmethod
    def for_mesh(cls, rest: np.ndarray, edges: np.ndarray, fraction: float = 0.8) -> SelfContact:
        """Contact distance ``fraction`` of the mean rest edge length. Point-point springs
        only stop a particle crossing a triangle's middle when the distance reaches the
        triangle's circumradius (edge / sqrt 3 = 0.58 edge): 0.8 leaves a margin."""
        lengths = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1)
        return cls(rest, fraction * float(lengths.mean()))

    def pairs(self, x: np.ndarray) -> np.ndarray:
        """Particle pairs (k, 2) closer than the contact distance at positions x (n, 3) (the
        integrator passes the positions predicted at the end of the step); those left out
        are counted in `dropped`. Read-only, as the mesh's pairs: the kernels that take
        either are compiled for one kind."""
        pairs, dropped = close_pairs(np.ascontiguousarray(x), self.rest, self.distance,
                                     2.0 * self.distance)
        self.dropped = int(dropped)
        return frozen(pairs)
