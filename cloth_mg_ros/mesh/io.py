"""Loading a coarse cloth mesh from a file (obj, ply, stl, off, ... through trimesh).

Choices:
- trimesh loads with process=False, so the file's vertex order is kept (a user's pin indices
  stay valid) and nothing is silently repaired.
- Vertices at exactly the same position are then merged, keeping the first occurrence's index
  and the file's order otherwise. This is needed for STL (a triangle soup) and for OBJ files
  split along texture seams; for a cloth, two coincident vertices would be a zero-width cut
  that falls apart. A clean indexed mesh is unchanged by it. Pass merge_duplicates=False to
  keep coincident vertices apart.
- Vertices used by no face are dropped (they would have no mass); the others keep their order.
- Positions are taken to be metres; `scale` multiplies them (0.01 for a file in centimetres).
Every problem raises ClothInputError naming the path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy, subdivided_counts
from cloth_mg_ros.mesh.topology import MeshLevel

__all__ = ['MAX_FILE_DEPTH', 'choose_file_depth', 'hierarchy_from_file', 'load_coarse_mesh']

# Up to 4^6 = 4096 times the file's face count.
MAX_FILE_DEPTH = 6


def _merge_coincident(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exactly coincident vertices, keeping first-occurrence order."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(vertices):
        return vertices, faces
    order = np.argsort(first)            # unique rows in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return vertices[first[order]], rank[inverse.ravel()][faces]


def _drop_unused(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return vertices, faces
    new_index = np.cumsum(used) - 1
    return vertices[used], new_index[faces]


def load_coarse_mesh(path: str | Path, merge_duplicates: bool = True,
                     scale: float = 1.0) -> MeshLevel:
    """Read a triangle mesh file into a validated MeshLevel (positions in metres x scale).

    Raises ClothInputError (message names the path) for: a missing file, a file trimesh cannot
    read, a file with no triangles, non-finite vertex coordinates, and every MeshLevel check
    (non-manifold edge, degenerate triangle, inconsistent orientation, ...).
    """
    p = Path(path)
    if not p.exists():
        raise ClothInputError(f'mesh file not found: {p}')
    if not p.is_file():
        raise ClothInputError(f'mesh path is not a file: {p}')
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ClothInputError(f'scale for {p} must be a positive number, got {scale!r}')
    try:
        mesh = trimesh.load(str(p), force='mesh', process=False)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many unrelated types on bad input
        raise ClothInputError(
            f'cannot read mesh file {p}: {type(exc).__name__}: {exc}') from None
    vertices = np.asarray(getattr(mesh, 'vertices', np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, 'faces', np.zeros((0, 3))), dtype=np.int64)
    if len(vertices) == 0 or len(faces) == 0:
        raise ClothInputError(
            f'mesh file {p} contains no triangles ({len(vertices)} vertices, {len(faces)} '
            f'faces): empty, garbled or not a surface mesh')
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ClothInputError(
            f'vertex {i} (0-based) in {p} has a non-finite coordinate {vertices[i].tolist()}')
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
        raise ClothInputError(f'mesh file {p} has invalid face indices')
    if merge_duplicates:
        vertices, faces = _merge_coincident(vertices, faces)
    vertices, faces = _drop_unused(vertices, faces)
    return MeshLevel(vertices * float(scale), faces, source=str(p))


def choose_file_depth(coarse: MeshLevel, n_particles: int) -> int:
    """Number of subdivisions (0..MAX_FILE_DEPTH) whose finest vertex count is nearest
    n_particles on a log scale (n_f is about 4^depth x n_c).

    Raises ClothInputError when the mesh alone has more than twice n_particles vertices: the
    caller asked for a much coarser cloth than the file, and silently simulating the file would
    be much slower than asked. Depth is capped at MAX_FILE_DEPTH even if still short of the
    target.
    """
    if isinstance(n_particles, bool) or not isinstance(n_particles, (int, np.integer)) \
            or n_particles < 1:
        raise ClothInputError(f'n_particles must be a positive integer, got {n_particles!r}')
    n_c = coarse.n_vertices
    if n_c > 2 * n_particles:
        raise ClothInputError(
            f'mesh {coarse.source or "(unnamed)"} already has {n_c} vertices, more than twice '
            f'n_particles={n_particles}; use a coarser mesh or a larger n_particles')
    counts = [subdivided_counts(n_c, coarse.n_edges, coarse.n_faces, d)[0]
              for d in range(MAX_FILE_DEPTH + 1)]
    errors = [abs(math.log(c / n_particles)) for c in counts]
    return int(np.argmin(errors))


def hierarchy_from_file(path: str | Path, n_particles: int | None = None,
                        depth: int | None = None, merge_duplicates: bool = True,
                        scale: float = 1.0) -> MeshHierarchy:
    """Load a coarse mesh and subdivide it into a hierarchy (levels[0] finest).

    depth given: that many subdivisions (n_particles, if also given, is ignored).
    depth None: chosen by `choose_file_depth` so the finest level lands nearest n_particles.
    """
    if depth is None and n_particles is None:
        raise ClothInputError(f'hierarchy_from_file({path}): give n_particles or depth')
    coarse = load_coarse_mesh(path, merge_duplicates=merge_duplicates, scale=scale)
    if depth is None:
        depth = choose_file_depth(coarse, n_particles)
    return MeshHierarchy.from_coarse(coarse, depth)
