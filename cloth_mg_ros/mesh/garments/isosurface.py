"""The top's first surface: marching tetrahedra on an implicit function sampled on a grid,
and the clean-up of the cut, open mesh (largest piece, no dangling triangles)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                  [0, 4, 6, 7]])
_TET_EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def _mt_table() -> dict[int, list[list[int]]]:
    def e(p: int, q: int) -> int:
        return _TET_EDGES.index((min(p, q), max(p, q)))

    table = {}
    for mask in range(1, 15):
        inside = [k for k in range(4) if mask >> k & 1]
        outside = [k for k in range(4) if not mask >> k & 1]
        if len(inside) == 1:
            tris = [[e(inside[0], o) for o in outside]]
        elif len(inside) == 3:
            tris = [[e(outside[0], i) for i in inside]]
        else:
            (i, j), (k, m) = inside, outside
            tris = [[e(i, k), e(i, m), e(j, m)], [e(i, k), e(j, m), e(j, k)]]
        table[mask] = tris
    return table


_MT_TABLE = _mt_table()


def marching_tets(func: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, step: float,
                   shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Zero surface of func (negative inside) on a grid: (vertices (n, 3), faces (t, 3)),
    faces oriented with normals towards increasing func (outward). A manifold surface: each
    cube is split into 6 tetrahedra along its main diagonal, consistently across cubes.

    Not scikit-image's marching cubes: measured in its place, it is faster, but the remeshed
    coarse meshes are no better and the different mesh changes outcomes for the worse
    (doc/scenes.md has the figures); not worth a new dependency (scikit-image and four
    packages under it) for ~50 lines.
    """
    nx, ny, nz = shape
    axes = [lo[k] + step * np.arange(shape[k]) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing='ij'), axis=-1).reshape(-1, 3)
    vals = func(grid)
    vals = np.where(np.abs(vals) < 1e-9, 1e-9, vals)
    ci, cj, ck = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), np.arange(nz - 1),
                             indexing='ij')
    base = ((ci * ny + cj) * nz + ck).ravel()
    off = np.array([(c & 1) * ny * nz + (c >> 1 & 1) * nz + (c >> 2 & 1) for c in range(8)])
    tets = (base[:, None, None] + off[_TETS][None]).reshape(-1, 4)
    mask = ((vals[tets] < 0.0) * np.array([1, 2, 4, 8])).sum(axis=1)
    edges = np.array(_TET_EDGES)
    ends_p, ends_q = [], []
    for m, tris in _MT_TABLE.items():
        sel = tets[mask == m]
        if len(sel) == 0:
            continue
        for tri in tris:
            e = edges[tri]
            ends_p.append(sel[:, e[:, 0]])
            ends_q.append(sel[:, e[:, 1]])
    if not ends_p:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    p, q = np.concatenate(ends_p), np.concatenate(ends_q)
    n_grid = len(grid)
    keys = np.minimum(p, q) * n_grid + np.maximum(p, q)
    uniq, inv = np.unique(keys.ravel(), return_inverse=True)
    a, b = uniq // n_grid, uniq % n_grid
    t = vals[a] / (vals[a] - vals[b])
    verts = grid[a] + t[:, None] * (grid[b] - grid[a])
    faces = inv.reshape(-1, 3).astype(np.int64)
    p0, q0 = p[:, 0], q[:, 0]
    outward = np.where((vals[p0] < 0.0)[:, None], grid[q0] - grid[p0], grid[p0] - grid[q0])
    normal = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]],
                      verts[faces[:, 2]] - verts[faces[:, 0]])
    flip = np.einsum('ij,ij->i', normal, outward) < 0.0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return verts, faces


def edge_table(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per face side (t, 3) edge ids and per-edge face counts."""
    a, b = faces, np.roll(faces, -1, axis=1)
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, inv, counts = np.unique(key.ravel(), return_inverse=True, return_counts=True)
    return inv.reshape(-1, 3), counts


def clean_open_mesh(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the largest edge-connected piece of a cut mesh, without dangling triangles
    (two or more boundary sides) or vertices where two boundary fans touch."""
    n = len(verts)
    for _ in range(50):
        if len(faces) == 0:
            break
        side_edge, counts = edge_table(faces, n)
        border = counts[side_edge] == 1
        ears = border.sum(axis=1) >= 2
        per_vertex = np.bincount(faces[border].ravel() if border.any() else np.zeros(0, int),
                                 minlength=n)
        pinch = per_vertex > 2
        bad = ears | pinch[faces].any(axis=1)
        # Largest component by shared edges.
        e_ids = side_edge.ravel()
        f_ids = np.repeat(np.arange(len(faces)), 3)
        inc = sp.csr_matrix((np.ones(len(e_ids)), (f_ids, e_ids)))
        _, label = connected_components(inc @ inc.T, directed=False)
        main = label == np.argmax(np.bincount(label))
        keep = main & ~bad
        if keep.all():
            break
        faces = faces[keep]
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]
