"""1-to-4 midpoint subdivision of a MeshLevel and the fine-to-coarse maps it implies.

`subdivide(coarse)` returns the fine MeshLevel and the LevelTransfer linking the two. All of
it is vectorised over faces, edges and wings; the only loops are over the six wing pairs.

Fine vertex numbering: vertices 0..n_c-1 are the coarse vertices (same index, same rest
position), then one midpoint per coarse edge, in coarse edge order: midpoint of coarse edge e
is fine vertex n_c + e. Rest positions of midpoints are the exact midpoints (flat, not
smoothed), so every child triangle has exactly a quarter of its parent's rest area.

Children of coarse face T = (v0, v1, v2) with side midpoints m0 (v0-v1), m1 (v1-v2),
m2 (v2-v0) are the fine faces 4T + c, in this order and with the parent's orientation:

    c = 0: (v0, m0, m2)   corner at v0     maps to (v0, v1, v2)
    c = 1: (v1, m1, m0)   corner at v1     maps to (v1, v2, v0)
    c = 2: (v2, m2, m1)   corner at v2     maps to (v2, v0, v1)
    c = 3: (m0, m1, m2)   centre           maps to (v2, v0, v1)

"maps to" is the paper's correspondence (Sec. 5.2, Fig. 3a): a corner child's midpoints go to
the far ends of their coarse edges, the centre child's midpoints to the coarse vertex opposite
their edge. Each mapping is an orientation-preserving rotation of the parent, so every child is
a half-size copy of its parent (the centre one turned by 180 degrees) with the same
deformation gradient under a uniform deformation.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.mesh.topology import WING_PAIR_LOCAL, MeshLevel
from cloth_mg_ros.mesh.transfer import LevelTransfer

__all__ = ['CHILD_CORNER_ROTATION', 'subdivide']

# Child c's local vertex k maps to the parent's local vertex (k + CHILD_CORNER_ROTATION[c]) % 3.
CHILD_CORNER_ROTATION = np.array([0, 1, 2, 2], dtype=np.int64)
_CENTRE = 3


def _local_index(faces: np.ndarray, f: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Position k (0..2) of vertex v[i] within face f[i]. faces: (t, 3); f, v: (w,)."""
    return np.argmax(faces[f] == v[:, None], axis=1)


def _keys(level: MeshLevel, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    n = level.n_vertices
    return np.minimum(i, j) * n + np.maximum(i, j)


def _pair_lookup(level: MeshLevel, i: np.ndarray, j: np.ndarray, what: str) -> np.ndarray:
    """Pair index of (i, j) in `level`; the maps must only ever land on existing pairs."""
    idx = level.pair_index(i, j)
    if (idx < 0).any():
        raise AssertionError(f'{what}: a mapped vertex pair is not a coarse pair')
    return idx


def _fine_mesh(coarse: MeshLevel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fine rest positions (n_f, 3), fine faces (4 t_c, 3), child_vertex_map (t_c, 4, 3)."""
    n_c = coarse.n_vertices
    ends = coarse.edges
    rest = np.concatenate([coarse.rest, 0.5 * (coarse.rest[ends[:, 0]] + coarse.rest[ends[:, 1]])])
    v0, v1, v2 = coarse.faces.T
    m0, m1, m2 = (n_c + coarse.face_edges).T
    children = np.stack([
        np.stack([v0, m0, m2], axis=1),
        np.stack([v1, m1, m0], axis=1),
        np.stack([v2, m2, m1], axis=1),
        np.stack([m0, m1, m2], axis=1),
    ], axis=1)
    local = (np.arange(3)[None, :] + CHILD_CORNER_ROTATION[:, None]) % 3  # (4, 3)
    child_vertex_map = np.ascontiguousarray(coarse.faces[:, local])  # (t_c, 4, 3)
    return rest, children.reshape(-1, 3), child_vertex_map


def _wing_maps(coarse: MeshLevel, fine: MeshLevel, child_vertex_map: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """wing_map (w_f,) and wing_vertex_map (w_f, 4) of the paper's Fig. 3b correspondence.

    A fine interior edge is either (a) half of a coarse interior edge (p, q): both its faces are
    corner children at p, whose maps send p -> p, m_pq -> q and the tips m_pr -> r, m_ps -> s;
    or (b) an interior edge (m_pr, m_qr) of coarse face (p, q, r), parallel to (p, q): its faces
    are the corner child at r and the centre child. The corner child's map gives m_pr -> p,
    m_qr -> q, r -> r; the centre child's tip m_pq goes to s, the tip of the coarse wing of
    (p, q) on the other side, and the fine wing maps to nothing (-1) if (p, q) is a boundary
    edge.
    """
    cvm = child_vertex_map.reshape(-1, 3)  # indexed by fine face
    w = fine.wings
    f_c, f_d = fine.wing_faces[:, 0], fine.wing_faces[:, 1]
    c_is_centre = f_c % 4 == _CENTRE
    d_is_centre = f_d % 4 == _CENTRE
    # The corner-child face of each fine wing (for type (a) either face; take c's).
    f_corner = np.where(c_is_centre, f_d, f_c)

    def mapped(f: np.ndarray, v: np.ndarray) -> np.ndarray:
        return cvm[f, _local_index(fine.faces, f, v)]

    a_map = mapped(f_corner, w[:, 0])
    b_map = mapped(f_corner, w[:, 1])
    c_map = mapped(f_c, w[:, 2])
    d_map = mapped(f_d, w[:, 3])

    coarse_edge = np.searchsorted(
        coarse.edges[:, 0] * coarse.n_vertices + coarse.edges[:, 1], _keys(coarse, a_map, b_map))
    wing_map = coarse.edge_wing[coarse_edge].copy()

    # Type (b): replace the centre child's tip by the far tip s of the coarse wing.
    centre_tip = c_is_centre | d_is_centre
    has = centre_tip & (wing_map >= 0)
    cw = wing_map[has]
    parent = f_corner[has] // 4
    far_tip = np.where(coarse.wing_faces[cw, 0] == parent, coarse.wings[cw, 3], coarse.wings[cw, 2])
    c_map[has & c_is_centre] = far_tip[c_is_centre[has]]
    d_map[has & d_is_centre] = far_tip[d_is_centre[has]]

    wing_vertex_map = np.stack([a_map, b_map, c_map, d_map], axis=1)
    wing_vertex_map[wing_map < 0] = -1
    return wing_map.astype(np.int64), wing_vertex_map.astype(np.int64)


def subdivide(coarse: MeshLevel) -> tuple[MeshLevel, LevelTransfer]:
    """One 1-to-4 midpoint subdivision. Returns (fine level, transfer fine -> coarse)."""
    rest, faces, child_vertex_map = _fine_mesh(coarse)
    base = coarse.source.removesuffix(' (subdivided)')
    fine = MeshLevel(rest, faces, source=f'{base} (subdivided)' if base else '')
    n_c, t_c = coarse.n_vertices, coarse.n_faces

    parents = np.concatenate([np.repeat(np.arange(n_c, dtype=np.int64)[:, None], 2, axis=1),
                              coarse.edges])
    children = np.arange(4 * t_c, dtype=np.int64).reshape(t_c, 4)

    # Side k of child c joins its local vertices k, k+1, which map to the parent's local
    # vertices k + rot, k + 1 + rot (mod 3): the parent's side (k + rot) % 3. This is the pair
    # of (child_vertex_map[k], child_vertex_map[k+1]) without a search.
    side = (np.arange(3)[None, :] + CHILD_CORNER_ROTATION[:, None]) % 3  # (4, 3)
    face_pair_map = coarse.face_pairs[:, side].reshape(-1, 3)

    wing_map, wing_vertex_map = _wing_maps(coarse, fine, child_vertex_map)
    wing_pair_map = np.full((fine.n_wings, 6), -1, dtype=np.int64)
    ok = wing_map >= 0
    wv = wing_vertex_map[ok]
    wing_pair_map[ok] = _pair_lookup(coarse, wv[:, WING_PAIR_LOCAL[:, 0]],
                                     wv[:, WING_PAIR_LOCAL[:, 1]], 'wing_pair_map')

    # Per fine pair: wing-tip pairs via their wing first, then edges via the faces, so the edge
    # mapping wins where a pair is both (see LevelTransfer.pair_map).
    pair_map = np.full(fine.n_pairs, -1, dtype=np.int64)
    pair_map[fine.wing_pairs[ok, 5]] = wing_pair_map[ok, 5]
    pair_map[fine.face_pairs.ravel()] = face_pair_map.ravel()

    face_area_ratio = fine.face_areas / coarse.face_areas[np.arange(4 * t_c) // 4]
    wing_area_ratio = np.zeros(fine.n_wings)
    fine_wing_area = fine.face_areas[fine.wing_faces].sum(axis=1)
    coarse_wing_area = coarse.face_areas[coarse.wing_faces].sum(axis=1)
    wing_area_ratio[ok] = fine_wing_area[ok] / coarse_wing_area[wing_map[ok]]

    transfer = LevelTransfer(
        n_fine=fine.n_vertices, n_coarse=n_c, parents=parents, children=children,
        child_vertex_map=child_vertex_map, face_pair_map=face_pair_map, wing_map=wing_map,
        wing_vertex_map=wing_vertex_map, wing_pair_map=wing_pair_map, pair_map=pair_map,
        face_area_ratio=face_area_ratio, wing_area_ratio=wing_area_ratio)
    return fine, transfer
