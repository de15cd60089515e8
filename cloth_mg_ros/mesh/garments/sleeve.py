"""A gown's sleeve on its own: a straight open tube, meshed in rings and subdivided 1-to-4.

The sleeve is a cylinder of a given radius and length around an axis. Its coarse mesh is
rings of ``m`` vertices, the rings about sqrt(3)/2 of the vertex spacing apart and every
other ring turned by half a spacing, zipped into near-equilateral triangles (the tubes of
`rows` on a straight axis, without a body to fit); 1-to-4 subdivision then makes the
hierarchy the multigrid solves on. Ring 0 is the opening a robot holds (the cuff, near the
hand), the last ring the far end (towards the shoulder). Vertex 0 of every even coarse ring
lies in the direction ``up`` from the axis, so a gripper placed at the top (or, with an even
ring, at the bottom) of the cuff sits on a vertex.

Rest shape: the coarse rings are regular polygons; the finer levels lie on their facets
(flat subdivision), so the finest ring sags inside the circle by r (1 - cos(pi / m)), at
most 2.6 mm for the 7.5 cm sleeve with the 12-vertex coarse rings the size policy keeps.
Units: metres.
"""

from __future__ import annotations

import math

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import MeshLevel

MIN_RING = 12  # coarse vertices around: fewer would make a polygon more than 2.6 mm off a
# 7.5 cm circle (r (1 - cos(pi / m)))
MAX_SLEEVE_DEPTH = 3
_ROW_RATIO = math.sqrt(3.0) / 2.0


def sleeve_counts(ring: int, rings: int, depth: int) -> tuple[int, int]:
    """(vertices around, vertices) of the finest level of a coarse sleeve of ``rings`` rings of
    ``ring`` vertices after ``depth`` subdivisions (a subdivided ring doubles, and so do the
    gaps between rings)."""
    around = ring * 2 ** depth
    return around, around * ((rings - 1) * 2 ** depth + 1)


def sleeve_plan(n_particles: int, length: float, radius: float,
                depth: int | None = None) -> tuple[int, int, int]:
    """(coarse vertices per ring, rings, depth) of a sleeve of about ``n_particles`` vertices:
    the finest spacing s from the area (n s^2 sqrt(3)/2 = 2 pi r L), and the deepest depth
    (at most MAX_SLEEVE_DEPTH) whose coarse ring keeps MIN_RING vertices."""
    if isinstance(n_particles, bool) or not isinstance(n_particles, (int, np.integer)) \
            or n_particles < 2 * MIN_RING:
        raise ClothInputError(f"sleeve: particles must be an integer >= {2 * MIN_RING}, got "
                              f"{n_particles!r}")
    for name, value in (("length", length), ("radius", radius)):
        if not (math.isfinite(value) and value > 0.0):
            raise ClothInputError(f"sleeve: {name} must be positive, got {value!r} m")
    spacing = math.sqrt(2.0 * math.pi * radius * length / (_ROW_RATIO * n_particles))
    around = 2.0 * math.pi * radius / spacing
    if depth is None:
        depth = next((d for d in range(MAX_SLEEVE_DEPTH, -1, -1)
                      if around / 2 ** d >= MIN_RING), 0)
    elif isinstance(depth, bool) or not isinstance(depth, int) or \
            not 0 <= depth <= MAX_SLEEVE_DEPTH:
        raise ClothInputError(f"sleeve: depth must be an integer in [0, {MAX_SLEEVE_DEPTH}], "
                              f"got {depth!r}")
    ring = max(MIN_RING if depth else 3, 2 * round(around / 2 ** depth / 2))  # even: a bottom
    # The gaps between rings that land nearest n_particles, the rows kept within 20 % of
    # the equilateral spacing.
    equilateral = length / (_ROW_RATIO * 2.0 * math.pi * radius / ring)
    wanted = (n_particles / (ring * 2 ** depth) - 1) / 2 ** depth
    gaps = max(1, round(min(max(wanted, equilateral / 1.2), equilateral * 1.2)))
    return ring, gaps + 1, depth


def sleeve_coarse(ring: int, rings: int, length: float, radius: float) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """(rest (ring * rings, 3) m, faces (t, 3)) of the coarse sleeve in its own frame: axis
    +z from the opening (z = 0) to z = length, vertex 0 of ring 0 on +x, outward faces."""
    j, i = np.meshgrid(np.arange(rings), np.arange(ring), indexing="ij")
    theta = 2.0 * math.pi * (i + 0.5 * (j % 2)) / ring
    z = length * j / (rings - 1)
    rest = np.stack([radius * np.cos(theta), radius * np.sin(theta), z], axis=-1).reshape(-1, 3)
    a = np.arange(ring)
    nxt = (a + 1) % ring
    faces = []
    for k in range(rings - 1):
        lo, hi = k * ring, (k + 1) * ring
        if k % 2 == 0:  # the upper ring is turned by +half a spacing
            faces += [np.stack([lo + a, lo + nxt, hi + a], 1),
                      np.stack([lo + nxt, hi + nxt, hi + a], 1)]
        else:  # the lower ring is turned
            faces += [np.stack([lo + a, hi + nxt, hi + a], 1),
                      np.stack([lo + a, lo + nxt, hi + nxt], 1)]
    faces = np.concatenate(faces).astype(np.int64)
    e1 = rest[faces[:, 1]] - rest[faces[:, 0]]
    e2 = rest[faces[:, 2]] - rest[faces[:, 0]]
    centre = rest[faces].mean(axis=1)
    if np.einsum("ij,ij->", np.cross(e1, e2), centre * [1.0, 1.0, 0.0]) < 0.0:
        faces = faces[:, ::-1].copy()
    return rest, faces


def sleeve_frame(axis, up) -> np.ndarray:
    """(3, 3) rotation whose columns are the sleeve's x (``up`` made perpendicular to the
    axis), y and z (the unit ``axis``): local coordinates to world."""
    z = np.asarray(axis, dtype=np.float64).reshape(3)
    x = np.asarray(up, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(x))):
        raise ClothInputError(f"sleeve: axis and up must be finite, got {z} and {x}")
    z = z / max(np.linalg.norm(z), 1e-300)
    x = x - np.dot(x, z) * z
    if np.linalg.norm(x) < 1e-9:
        raise ClothInputError("sleeve: 'up' must not be parallel to the axis")
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def sleeve_hierarchy(n_particles: int, length: float, radius: float, start, axis, up,
                     depth: int | None = None) -> tuple[MeshHierarchy, np.ndarray, np.ndarray]:
    """A sleeve of about ``n_particles`` vertices (finest level), ``length`` x ``radius`` m,
    its opening's centre at ``start`` (3,) m, running along ``axis`` (3,) with vertex 0 of the
    opening in the direction ``up`` (3,) from the axis.

    Returns (hierarchy, opening (k,), far_end (k,)): the finest vertices of the cuff ring and
    of the far ring, each in order around the axis (k = vertices around)."""
    ring, rings, depth = sleeve_plan(n_particles, length, radius, depth)
    rest, faces = sleeve_coarse(ring, rings, length, radius)
    rot = sleeve_frame(axis, up)
    start = np.asarray(start, dtype=np.float64).reshape(3)
    coarse = MeshLevel(rest @ rot.T + start, faces, source="sleeve (coarse)")
    hierarchy = MeshHierarchy.from_coarse(coarse, depth)
    local = (np.asarray(hierarchy.finest.rest) - start) @ rot
    tol = 1e-6 * length
    theta = np.arctan2(local[:, 1], local[:, 0]) % (2.0 * math.pi)
    rims = []
    for z in (0.0, length):
        on = np.flatnonzero(np.abs(local[:, 2] - z) < tol)
        rims.append(on[np.argsort(theta[on], kind="stable")])
    return hierarchy, rims[0], rims[1]
