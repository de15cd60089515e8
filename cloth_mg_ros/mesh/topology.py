"""One level of the mesh hierarchy: a validated triangle mesh and its connectivity tables.

`MeshLevel(rest, faces, source='...')` checks the input and derives, with vectorised numpy
(no Python loop over vertices or faces), everything the physics and the multigrid operators
index into: edges, bending wings, the vertex pairs that carry a Jacobian block, rest areas
and the lumped vertex areas.

Conventions (shared with the physics and solvers):

- Lengths in metres, areas in square metres. Indices are int64.
- Face side k of face f joins faces[f, k] and faces[f, (k + 1) % 3].
- A wing is an interior edge (a, b), a < b, with the vertices c and d opposite it. c is the
  tip of the face in which the edge runs a -> b (so that face is (a, b, c) up to rotation),
  d the tip of the face in which it runs b -> a.
- A "pair" is an unordered vertex pair (i < j) that receives a 3x3 Jacobian block G_ij in the
  block-symmetric system: every edge, plus the tip pair (c, d) of every wing (bending).
- Lumped vertex area: one third of each adjacent face's rest area (barycentric lumping). It is
  exactly what the energy-conserving mass coarsening of the paper (Sec. 5.1) needs on a
  midpoint-subdivided hierarchy: with it, the area overlap weights are exactly the transpose of
  linear interpolation (see `LevelTransfer.vertex_area_overlap`), and for the equilateral
  meshes the paper asks for it coincides with the Voronoi area.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.frozen_arrays import FrozenArrays, frozen

__all__ = ['DEGENERATE_AREA_RATIO', 'MIN_REST_ANGLE_DEG', 'WING_PAIR_LOCAL', 'MeshLevel']

# A triangle whose rest area is below this fraction of the mean face area is degenerate: its
# shape matrix would be (near) singular and its stretch coefficients blow up.
DEGENERATE_AREA_RATIO = 1e-12
# A triangle with a rest angle below this (degrees) is a sliver, whatever its area: the
# stretch model's inverse rest matrix (physics.stretch: Dm^-1, the measures' coefficients)
# grows as 1 / sin(angle), and the triangle's stiffest mode with it, without bound towards 0
# (and 180: the other two angles then go to 0). Every bundled mesh passes with a margin of 5
# or more: the smallest rest angle over the sheets (16-20000 particles), the four garments on
# the standing body and on the first pose of each bundled bag (100-20000 particles, the
# clearance rebuilds included), the textile tests' strips and disc and the dressing sleeve is
# 5.45 degrees (the top on the walk at 10000 particles; the dress 11.8, the cape 23.3, the
# skirt 34.9, the rest 17.8 or more; measured at 227d9c6).
MIN_REST_ANGLE_DEG = 1.0

# The six vertex pairs of a wing [a, b, c, d], as local indices, in the fixed order
# (a,b), (a,c), (a,d), (b,c), (b,d), (c,d) used by `wing_pairs` and the transfer maps.
WING_PAIR_LOCAL = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


def _where(source: str) -> str:
    return f' in {source}' if source else ''


def _sorted_unique(keys: np.ndarray) -> np.ndarray:
    """Sorted unique values of a 1-D int array (sort + mask: faster than np.unique here)."""
    k = np.sort(keys)
    keep = np.ones(len(k), dtype=bool)
    keep[1:] = k[1:] != k[:-1]
    return k[keep]


def _checked_rest(rest: np.ndarray, source: str) -> np.ndarray:
    try:
        arr = np.array(rest, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ClothInputError(f'rest positions{_where(source)} are not numeric: {exc}') from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ClothInputError(
            f'rest positions{_where(source)} must have shape (n, 3), got {arr.shape}')
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ClothInputError(
            f'vertex {i}{_where(source)} has a non-finite coordinate {arr[i].tolist()} '
            f'({int(bad.sum())} such vertices)')
    return arr


def _checked_faces(faces: np.ndarray, n: int, source: str) -> np.ndarray:
    raw = np.asarray(faces)
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise ClothInputError(
            f'faces{_where(source)} must have shape (t, 3) (triangles), got {raw.shape}')
    # Accept float arrays holding whole numbers (some loaders give those), nothing else.
    whole_floats = (raw.dtype.kind == 'f' and bool(np.isfinite(raw).all())
                    and bool((raw == np.round(raw)).all()))
    if raw.dtype.kind not in 'iu' and not whole_floats:
        raise ClothInputError(
            f'faces{_where(source)} must hold integer vertex indices, got dtype {raw.dtype}')
    arr = raw.astype(np.int64)
    if len(arr) < 2:
        raise ClothInputError(
            f'mesh{_where(source)} needs at least 2 faces, got {len(arr)}')
    out = (arr < 0) | (arr >= n)
    if out.any():
        f, k = (int(x) for x in np.argwhere(out)[0])
        raise ClothInputError(
            f'face {f}{_where(source)} has vertex index {int(arr[f, k])} out of range '
            f'[0, {n})')
    rep = (arr[:, 0] == arr[:, 1]) | (arr[:, 1] == arr[:, 2]) | (arr[:, 2] == arr[:, 0])
    if rep.any():
        f = int(np.flatnonzero(rep)[0])
        raise ClothInputError(
            f'face {f}{_where(source)} repeats a vertex: {arr[f].tolist()}')
    used = np.zeros(n, dtype=bool)
    used[arr.ravel()] = True
    if not used.all():
        i = int(np.flatnonzero(~used)[0])
        raise ClothInputError(
            f'vertex {i}{_where(source)} is not used by any face (it would have no mass; '
            f'{int((~used).sum())} unused vertices)')
    return arr


def _face_areas(rest: np.ndarray, faces: np.ndarray, source: str) -> np.ndarray:
    p0, p1, p2 = rest[faces[:, 0]], rest[faces[:, 1]], rest[faces[:, 2]]
    areas = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    mean = float(areas.mean())
    bad = areas <= DEGENERATE_AREA_RATIO * mean
    if not mean > 0.0 or bad.any():
        f = int(np.flatnonzero(bad)[0]) if bad.any() else 0
        raise ClothInputError(
            f'face {f}{_where(source)} is degenerate: rest area {areas[f]:.3g} m^2 '
            f'(mean face area {mean:.3g} m^2, vertices {faces[f].tolist()}; '
            f'{int(bad.sum())} degenerate faces)')
    return areas


def _check_angles(rest: np.ndarray, faces: np.ndarray, areas: np.ndarray, source: str) -> None:
    """ClothInputError naming the first face with a rest angle below MIN_REST_ANGLE_DEG (a
    sliver: see there), its smallest angle and where, its area and the threshold."""
    p = rest[faces]  # (t, 3, 3): each face's corners
    u = np.roll(p, -1, axis=1) - p  # from each corner to the next
    v = np.roll(p, -2, axis=1) - p  # ... and to the one after
    # atan2(|u x v|, u . v): accurate near 0 and 180 degrees, where arccos is not
    angles = np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=2),
                                   np.einsum('tka,tka->tk', u, v)))
    smallest = angles.min(axis=1)
    bad = smallest < MIN_REST_ANGLE_DEG
    if bad.any():
        f = int(np.flatnonzero(bad)[0])
        corner = int(np.argmin(angles[f]))
        raise ClothInputError(
            f'face {f}{_where(source)} is a sliver: smallest rest angle {smallest[f]:.3g} deg '
            f'at vertex {int(faces[f, corner])} (threshold {MIN_REST_ANGLE_DEG:g} deg; rest '
            f'area {areas[f]:.3g} m^2, vertices {faces[f].tolist()}; {int(bad.sum())} such '
            f'faces): its stretch terms would be near singular')


class _Edges(NamedTuple):
    """The edge tables of a mesh (`_edge_tables`): the half-edges h = 3 f + k (from, to and
    the opposite vertex of each), the sorted edge keys i * n + j (i < j), each half-edge's
    edge, the faces on each edge, the edges (e, 2) and each face side's edge (t, 3)."""

    h_from: np.ndarray
    h_to: np.ndarray
    h_tip: np.ndarray
    keys: np.ndarray
    h_edge: np.ndarray
    counts: np.ndarray
    edges: np.ndarray
    face_edges: np.ndarray


def _edge_tables(faces: np.ndarray, n: int, src: str) -> _Edges:
    """The edges of a mesh of n vertices, found through its half-edges; ClothInputError for
    an edge of more than two faces."""
    t = len(faces)
    # Half-edge h = 3 f + k runs faces[f, k] -> faces[f, (k+1) % 3].
    h_from = faces.ravel()
    h_to = faces[:, [1, 2, 0]].ravel()
    h_tip = faces[:, [2, 0, 1]].ravel()
    lo, hi = np.minimum(h_from, h_to), np.maximum(h_from, h_to)
    edge_keys, h_edge, counts = np.unique(lo * n + hi, return_inverse=True,
                                          return_counts=True)
    if (counts > 2).any():
        ei = int(np.flatnonzero(counts > 2)[0])
        fs = (np.flatnonzero(h_edge == ei) // 3).tolist()
        a, b = divmod(int(edge_keys[ei]), n)
        raise ClothInputError(
            f'non-manifold edge ({a}, {b}){_where(src)}: shared by {int(counts[ei])} '
            f'faces {fs} (at most 2 allowed)')
    edges = np.stack(np.divmod(edge_keys, n), axis=1).astype(np.int64)
    face_edges = h_edge.reshape(t, 3).astype(np.int64)
    return _Edges(h_from, h_to, h_tip, edge_keys, h_edge, counts, edges, face_edges)


class _Wings(NamedTuple):
    """The wing tables (`_wing_tables`): [a, b, c, d] per interior edge, the faces holding c
    and d, each wing's edge and each edge's wing (-1 on the boundary)."""

    wings: np.ndarray
    wing_faces: np.ndarray
    wing_edge: np.ndarray
    edge_wing: np.ndarray


def _wing_tables(faces: np.ndarray, e: _Edges, src: str) -> _Wings:
    """The bending wings of the interior edges; ClothInputError for neighbouring faces of
    inconsistent orientation and for duplicate faces."""
    h_from, h_to = e.h_from, e.h_to
    # Wings: the two half-edges of each interior edge, adjacent after a stable sort.
    order = np.argsort(e.h_edge, kind='stable')
    starts = np.cumsum(e.counts) - e.counts
    wing_edge = np.flatnonzero(e.counts == 2).astype(np.int64)
    h0, h1 = order[starts[wing_edge]], order[starts[wing_edge] + 1]
    # Consistent orientation: the two faces of an interior edge run it in opposite
    # directions, so its two half-edges start at different vertices.
    same = h_from[h0] == h_from[h1]
    if same.any():
        i = int(np.flatnonzero(same)[0])
        a, b = int(h_from[h0[i]]), int(h_to[h0[i]])
        raise ClothInputError(
            f'inconsistent orientation{_where(src)}: faces {[int(h0[i] // 3), int(h1[i] // 3)]}'
            f' both run edge ({a}, {b}) in the same direction (flip one of them)')
    # c's half-edge runs a -> b with a < b.
    swap = h_from[h0] > h_to[h0]
    hc, hd = np.where(swap, h1, h0), np.where(swap, h0, h1)
    wings = np.stack([e.edges[wing_edge, 0], e.edges[wing_edge, 1], e.h_tip[hc], e.h_tip[hd]],
                     axis=1)
    wing_faces = np.stack([hc // 3, hd // 3], axis=1).astype(np.int64)
    # Two faces on the same three vertices (opposite orientation, else caught above) give
    # wings whose tips coincide.
    dup = wings[:, 2] == wings[:, 3]
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        raise ClothInputError(
            f'faces {wing_faces[i].tolist()}{_where(src)} are duplicates (same vertices '
            f'{sorted(faces[wing_faces[i, 0]].tolist())})')
    edge_wing = np.full(len(e.edges), -1, dtype=np.int64)
    edge_wing[wing_edge] = np.arange(len(wing_edge))
    return _Wings(wings, wing_faces, wing_edge, edge_wing)


def _pair_tables(edge_keys: np.ndarray, wings: np.ndarray,
                 n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the sorted pair keys i * n + j: the edges and the wing tips (c, d), each edge's pair,
    each wing's six pairs in `WING_PAIR_LOCAL` order (flat))."""
    c, d = wings[:, 2], wings[:, 3]
    tip_keys = np.minimum(c, d) * n + np.maximum(c, d)
    pair_keys = _sorted_unique(np.concatenate([edge_keys, tip_keys]))
    edge_pairs = np.searchsorted(pair_keys, edge_keys).astype(np.int64)
    wa, wb = wings[:, WING_PAIR_LOCAL[:, 0]], wings[:, WING_PAIR_LOCAL[:, 1]]
    wing_pairs = np.searchsorted(
        pair_keys, np.minimum(wa, wb) * n + np.maximum(wa, wb)).astype(np.int64)
    return pair_keys, edge_pairs, wing_pairs


@dataclass(eq=False)
class MeshLevel(FrozenArrays):
    """A validated triangle mesh (one hierarchy level) with its connectivity tables.

    Constructor arguments:
        rest: (n, 3) float64 rest (material-space) positions, metres.
        faces: (t, 3) int64 vertex indices, consistently oriented.
        source: optional name of where the mesh came from (a path); used in error messages.

    Raises ClothInputError for: non-finite positions, malformed or out-of-range faces, a face
    repeating a vertex, unused vertices, duplicate faces, degenerate faces (area <=
    1e-12 x mean area), slivers (a rest angle below MIN_REST_ANGLE_DEG), non-manifold edges
    (more than two faces), inconsistent orientation of neighbouring faces, fewer than two
    faces.

    Derived attributes (all read-only arrays):
        edges: (e, 2) int64, unique vertex pairs i < j, sorted lexicographically.
        face_edges: (t, 3) int64, edge index of face side k (faces[:, k] - faces[:, (k+1) % 3]).
        edge_face_count: (e,) int64, 1 for a boundary edge, 2 for an interior edge.
        edge_wing: (e,) int64, wing index of each edge, -1 for boundary edges.
        wings: (w, 4) int64, [a, b, c, d] per interior edge (a < b the edge, c and d the
            opposite vertices; c's face runs a -> b), in edge order.
        wing_faces: (w, 2) int64, the faces holding c and d.
        wing_edge: (w,) int64, edge index of each wing.
        pairs: (m, 2) int64, sorted unique i < j: the union of edges and wing-tip pairs (c, d).
        edge_pairs: (e,) int64, pair index of each edge.
        face_pairs: (t, 3) int64, pair index of each face side.
        wing_pairs: (w, 6) int64, pair index of the wing pairs (a,b),(a,c),(a,d),(b,c),(b,d),
            (c,d) (local order `WING_PAIR_LOCAL`).
        face_areas: (t,) float64 rest areas, m^2.
        vertex_areas: (n,) float64 lumped rest areas, m^2: one third of each adjacent face.
        boundary_vertices: (n,) bool, True on vertices of boundary edges.
    """

    rest: np.ndarray
    faces: np.ndarray
    source: str = ''
    edges: np.ndarray = field(init=False, repr=False)
    face_edges: np.ndarray = field(init=False, repr=False)
    edge_face_count: np.ndarray = field(init=False, repr=False)
    edge_wing: np.ndarray = field(init=False, repr=False)
    wings: np.ndarray = field(init=False, repr=False)
    wing_faces: np.ndarray = field(init=False, repr=False)
    wing_edge: np.ndarray = field(init=False, repr=False)
    pairs: np.ndarray = field(init=False, repr=False)
    edge_pairs: np.ndarray = field(init=False, repr=False)
    face_pairs: np.ndarray = field(init=False, repr=False)
    wing_pairs: np.ndarray = field(init=False, repr=False)
    face_areas: np.ndarray = field(init=False, repr=False)
    vertex_areas: np.ndarray = field(init=False, repr=False)
    boundary_vertices: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        src = self.source
        rest = _checked_rest(self.rest, src)
        faces = _checked_faces(self.faces, len(rest), src)
        n = len(rest)
        areas = _face_areas(rest, faces, src)
        _check_angles(rest, faces, areas, src)
        e = _edge_tables(faces, n, src)
        w = _wing_tables(faces, e, src)
        pair_keys, edge_pairs, wing_pairs = _pair_tables(e.keys, w.wings, n)

        boundary = np.zeros(n, dtype=bool)
        boundary[e.edges[e.counts == 1].ravel()] = True

        # Read-only: the transfer maps and every kernel index into these tables.
        self.rest = frozen(rest)
        self.faces = frozen(faces)
        self.edges = frozen(e.edges)
        self.face_edges = frozen(e.face_edges)
        self.edge_face_count = frozen(e.counts.astype(np.int64))
        self.edge_wing = frozen(w.edge_wing)
        self.wings = frozen(w.wings.astype(np.int64))
        self.wing_faces = frozen(w.wing_faces)
        self.wing_edge = frozen(w.wing_edge)
        self.pairs = frozen(np.stack(np.divmod(pair_keys, n), axis=1).astype(np.int64))
        self.edge_pairs = frozen(edge_pairs)
        self.face_pairs = frozen(edge_pairs[e.face_edges])
        self.wing_pairs = frozen(wing_pairs.reshape(-1, 6))
        self.face_areas = frozen(areas)
        # One third of each face's area to each of its corners (see module docstring).
        self.vertex_areas = frozen(np.bincount(faces.ravel(), weights=np.repeat(areas / 3.0, 3),
                                               minlength=n))
        self.boundary_vertices = frozen(boundary)

    @property
    def n_vertices(self) -> int:
        """Number of vertices (particles)."""
        return len(self.rest)

    @property
    def n_faces(self) -> int:
        """Number of triangles."""
        return len(self.faces)

    @property
    def n_edges(self) -> int:
        """Number of edges."""
        return len(self.edges)

    @property
    def n_wings(self) -> int:
        """Number of bending wings (interior edges)."""
        return len(self.wings)

    @property
    def n_pairs(self) -> int:
        """Number of vertex pairs carrying a Jacobian block."""
        return len(self.pairs)

    def pair_index(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Pair index of vertex pairs (i, j), in either order; -1 where (i, j) is not a pair.

        i, j: integer arrays of the same shape. Returns an int64 array of that shape.
        """
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        n = self.n_vertices
        keys = self.pairs[:, 0] * n + self.pairs[:, 1]
        query = np.minimum(i, j) * n + np.maximum(i, j)
        idx = np.minimum(np.searchsorted(keys, query), len(keys) - 1)
        return np.where(keys[idx] == query, idx, -1).astype(np.int64)
