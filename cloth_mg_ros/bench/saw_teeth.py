"""Saw teeth by the vertices' curvature: a measure that tells a fold from a zig-zag on any lattice.

The hinge measure of `bench.hinge_zigzag` (a triangle whose hinges bend past a threshold in opposite
directions) reads the mesh's own facets as well as the cloth's shape. A triangle mesh laid on
a smooth fold whose axis crosses the lattice's rows bends its edges along the fold's curvature
both ways: the two triangles on either side of such an edge have their apices at different
points of the curve, so the edge carries a small ridge or valley whose sign follows the
triangles' orientation (on a cylinder of radius 10 cm at 2.5 cm spacing, up to 4.1 degrees
against the 8.3 of the edges across the curvature). On the sheet scenes' lattice that cylinder
reads 95 % zig-zag triangles by it, a smooth fold 16 edges long 78 %; and an accordion pleated
at every row (ridges and valleys one triangle apart, the saw tooth the measure is meant to
find) reads 0 %, each triangle touching one of the bent rows only (`bench.fold_calibration`).
So it cannot say whether a cloth is folded or crumpled.

This module measures at the vertices instead. Each interior vertex's signed mean curvature
H (1/m) comes from the cotangent Laplacian (Meyer et al. 2003, "Discrete differential-geometry
operators for triangulated 2-manifolds"): L x_i = sum_j w_ij (x_j - x_i), w_ij = (cot alpha_ij +
cot beta_ij) / 2 with the rest triangles' angles (the cloth barely stretches, and rest weights
do not blow up on a crushed triangle), H_i = -(L x)_i . n_i / (2 A_i), A_i the vertex's rest
mixed Voronoi area and n_i its current normal (the area-weighted face normals):
positive where the surface bends away from its normals' side, the hinge angles' convention.
On a smooth surface sampled by the mesh H varies smoothly, whatever the lattice; on saw teeth
it flips sign from a vertex to its neighbours. So:

* a vertex is **bent** when 2 |H| l / sqrt(3) passes the threshold (l its mean rest edge
  length): the angle a hinge across a cylinder of curvature 2 |H| bends on an equilateral
  lattice, so 3 degrees means here what it means to the hinge measure;
* a bent vertex is a **saw tooth** when its H and the mean of its interior neighbours' H
  (weighted by the Laplacian's weights) have opposite signs: a wave one or two edges long
  (on the sheet lattice a smooth fold three edges long reads 5 %, four or more 0 %, the
  accordion 96 %, random heights 78 %);
* the **bending** of a vertex is A_i H_i^2 (its share of the bending energy 2 B integral H^2
  of a surface bent without stretching), and the saw teeth's share of it is the second figure.

Boundary vertices (their Laplacian is not a curvature) count in neither.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.bench.hinge_zigzag import checked_positions, checked_threshold


def rest_operator(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, w, area): the cotangent Laplacian's off-diagonal entries with the rest
    angles, one per directed half-edge of every face (a pair appears once per face it is in),
    and each vertex's mixed Voronoi area (n,) m^2 (Meyer et al. 2003: its Voronoi cell within
    each non-obtuse face, half or a quarter of an obtuse one), which keeps H exact on a
    cylinder over a regular lattice in any orientation, obtuse or not (the sheets', and the
    garments' within each coarse face: 1-to-4 subdivision copies it). Where irregular
    triangles meet it is not: on a grid whose vertices were moved at random by up to 0.35 of
    an edge, vertices' H on a cylinder erred by 10-160 % whichever area was used (measured
    once; the mixed area is chosen because it stays positive, not for accuracy there)."""
    rest = np.asarray(mesh.rest, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n = len(rest)
    corner = [faces[:, k] for k in range(3)]
    cots, length_sq = [], []
    for k in range(3):
        a, b, c = corner[k], corner[(k + 1) % 3], corner[(k + 2) % 3]
        u, v = rest[b] - rest[a], rest[c] - rest[a]
        cots.append(np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1))
        length_sq.append(np.sum((rest[c] - rest[b]) ** 2, axis=1))  # the edge opposite a
    face_area = np.asarray(mesh.face_areas, dtype=np.float64)
    obtuse = np.stack(cots, axis=1) < 0.0
    rows, cols, weights = [], [], []
    area = np.zeros(n)
    for k in range(3):
        # the corner at vertex k weighs the edge opposite it, between the other two corners
        b, c = corner[(k + 1) % 3], corner[(k + 2) % 3]
        rows += [b, c]
        cols += [c, b]
        weights += [0.5 * cots[k]] * 2
        # Voronoi share of corner k: the two edges at it, each times the opposite corner's cot
        voronoi = (length_sq[(k + 1) % 3] * cots[(k + 1) % 3]
                   + length_sq[(k + 2) % 3] * cots[(k + 2) % 3]) / 8.0
        share = np.where(obtuse.any(axis=1),
                         np.where(obtuse[:, k], 0.5, 0.25) * face_area, voronoi)
        area += np.bincount(corner[k], weights=share, minlength=n)
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(weights), area


def vertex_mean_curvature(x: np.ndarray, mesh) -> np.ndarray:
    """Signed mean curvature H of every vertex, 1/m, (n,) (module docstring); boundary
    vertices' values are not curvatures (`saw_teeth_figures` leaves them out).

    x: (n, 3) positions, m; mesh: a `mesh.topology.MeshLevel` (consistently oriented faces).
    """
    return _mean_curvature(checked_positions(x, mesh), mesh, rest_operator(mesh))


def _mean_curvature(x: np.ndarray, mesh, operator: tuple) -> np.ndarray:
    """H (n,) 1/m of checked positions x with the mesh's `rest_operator`."""
    n = len(x)
    rows, cols, w, areas = operator
    d = (x[cols] - x[rows]) * w[:, None]
    faces = np.asarray(mesh.faces, dtype=np.int64)
    face_normal = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    lap = np.empty((n, 3))
    normal = np.empty((n, 3))
    for c in range(3):
        lap[:, c] = np.bincount(rows, weights=d[:, c], minlength=n)
        normal[:, c] = np.bincount(faces.ravel(), weights=np.repeat(face_normal[:, c], 3),
                                   minlength=n)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    return -np.einsum("ij,ij->i", lap, normal) / (2.0 * areas)


def classify_vertices(x: np.ndarray, mesh, threshold_deg: float) -> dict[str, np.ndarray]:
    """Per-vertex arrays: {"H" (n,) 1/m, "angle" (n,) rad (2 |H| l / sqrt 3), "interior",
    "bent", "saw" (n,) bool, "bending" (n,) A H^2 (0 on the boundary)}."""
    threshold_deg = checked_threshold(threshold_deg)
    operator = rest_operator(mesh)
    h = _mean_curvature(checked_positions(x, mesh), mesh, operator)
    n = len(h)
    interior = ~np.asarray(mesh.boundary_vertices, dtype=bool)
    rows, cols, w, area = operator
    rest = np.asarray(mesh.rest, dtype=np.float64)
    length = np.linalg.norm(rest[cols] - rest[rows], axis=1)
    mean_edge = (np.bincount(rows, weights=length, minlength=n)
                 / np.maximum(np.bincount(rows, minlength=n), 1))
    # the neighbours' mean weighted as the Laplacian weighs them: a grid's diagonal, whose
    # opposite angles are right angles, is no neighbour in the metric's sense
    weight = np.where(interior[cols], np.maximum(w, 0.0), 0.0)
    around = np.bincount(rows, weights=weight * h[cols], minlength=n)
    angle = 2.0 * np.abs(h) * mean_edge / np.sqrt(3.0)
    bent = interior & (angle > np.radians(threshold_deg))
    bending = np.where(interior, area * h ** 2, 0.0)
    return {"H": h, "angle": angle, "interior": interior, "bent": bent,
            "saw": bent & (h * around < 0.0), "bending": bending}


def saw_teeth_figures(x: np.ndarray, mesh, threshold_deg: float) -> dict:
    """The vertex measure's figures (module docstring): {"vertices_interior", "vertices_bent",
    "vertices_saw", "vertex_saw_share" (saw teeth over bent vertices), "vertex_bending_share"
    (the saw teeth's share of sum A H^2), "vertex_angle_rms_deg"}; shares in [0, 1]."""
    c = classify_vertices(x, mesh, threshold_deg)
    bent, saw = int(c["bent"].sum()), int(c["saw"].sum())
    total = float(c["bending"].sum())
    angle = np.degrees(c["angle"][c["interior"]])
    return {
        "vertices_interior": int(c["interior"].sum()),
        "vertices_bent": bent,
        "vertices_saw": saw,
        "vertex_saw_share": saw / bent if bent else 0.0,
        "vertex_bending_share": float(c["bending"][c["saw"]].sum() / total) if total > 0 else 0.0,
        "vertex_angle_rms_deg": float(np.sqrt(np.mean(angle ** 2))) if len(angle) else 0.0,
    }
