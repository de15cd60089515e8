"""bench saw_teeth: saw teeth by the vertices' mean curvature, and both measures on known shapes."""

from __future__ import annotations

import numpy as np
import pytest
from fold_shapes import checkerboard, cylinder, grid
from scipy.spatial.transform import Rotation

from cloth_mg_ros.bench.fold_calibration import calibration, calibration_shapes
from cloth_mg_ros.bench.hinge_zigzag import hinge_angles
from cloth_mg_ros.bench.saw_teeth import (
    classify_vertices,
    rest_operator,
    saw_teeth_figures,
    vertex_mean_curvature,
)
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.topology import MeshLevel


def test_a_cylinder_has_its_mean_curvature_at_every_interior_vertex():
    mesh = grid(15, 9, 0.02)
    radius = 0.15
    c = classify_vertices(cylinder(mesh, radius), mesh, 3.0)
    # the grid's valences alternate 4 and 8: the Voronoi areas keep H the same at both; the
    # chord's sagitta makes it 0.1 % low
    assert c["H"][c["interior"]] == pytest.approx(-1.0 / (2.0 * radius), rel=2e-3)
    # the hinge measure's sign: the cylinder curls towards the normals, its hinges negative
    assert np.all(hinge_angles(cylinder(mesh, radius), mesh) < 1e-12)
    assert not c["interior"][mesh.boundary_vertices].any()


def sheared_lattice(nx: int, ny: int, h: float, angle: float) -> MeshLevel:
    """A flat lattice of nx x ny vertices, h m apart along its rows, each row shifted h / 2
    from the one below and each cell cut along its long diagonal, so that every triangle has
    a 116.6 deg corner; turned by `angle` rad in the xy plane. Every interior vertex has the
    same six triangles around it (two of them obtuse at it)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    flat = np.stack([h * (i.ravel() + 0.5 * j.ravel()), h * j.ravel()], axis=1)
    c, s = np.cos(angle), np.sin(angle)
    rest = np.column_stack([flat @ np.array([[c, s], [-s, c]]), np.zeros(i.size)])
    ci, cj = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    v00 = (ci * ny + cj).ravel()
    v10, v01, v11 = v00 + ny, v00 + 1, v00 + ny + 1
    return MeshLevel(rest, np.concatenate([np.stack([v00, v10, v11], 1),
                                           np.stack([v00, v11, v01], 1)]))


def rest_angles_deg(mesh: MeshLevel) -> np.ndarray:
    """(t, 3) deg: each face's rest angle at each of its corners."""
    p = mesh.rest[mesh.faces]
    u, v = np.roll(p, -1, axis=1) - p, np.roll(p, -2, axis=1) - p
    return np.degrees(np.arccos(np.einsum("tka,tka->tk", u, v)
                                / (np.linalg.norm(u, axis=2) * np.linalg.norm(v, axis=2))))


def reference_mixed_areas(mesh: MeshLevel) -> np.ndarray:
    """(n,) m^2 of a planar mesh, by Meyer et al. 2003's Fig. 4 from the geometry: a corner of
    a non-obtuse face gets the quadrilateral between it, its two edges' midpoints and the
    face's circumcentre; an obtuse face gives its obtuse corner half its area, the others a
    quarter each."""
    area = np.zeros(mesh.n_vertices)
    for face, angles in zip(mesh.faces, rest_angles_deg(mesh), strict=True):
        p = mesh.rest[face, :2]
        u, v = p[1] - p[0], p[2] - p[0]
        d = 2.0 * (u[0] * v[1] - u[1] * v[0])
        sq = np.sum(p ** 2, axis=1)
        centre = np.array([sq @ (p[[1, 2, 0], 1] - p[[2, 0, 1], 1]),
                           sq @ (p[[2, 0, 1], 0] - p[[1, 2, 0], 0])]) / d
        whole = 0.5 * abs(d) / 2.0
        for k in range(3):
            if angles.max() > 90.0:
                area[face[k]] += (0.5 if angles[k] > 90.0 else 0.25) * whole
                continue
            quad = np.array([p[k], 0.5 * (p[k] + p[(k + 1) % 3]), centre,
                             0.5 * (p[k] + p[(k + 2) % 3])])
            area[face[k]] += 0.5 * abs(np.sum(quad[:, 0] * np.roll(quad[:, 1], -1)
                                              - np.roll(quad[:, 0], -1) * quad[:, 1]))
    return area


@pytest.mark.parametrize("angle", [0.0, 0.3, 1.0])
def test_a_cylinder_of_obtuse_triangles_has_its_mean_curvature(angle):
    """The mixed areas' obtuse branch (a half or a quarter of the face): on a lattice whose
    every triangle is obtuse the vertices' areas are the lattice's area per vertex, and H is
    exact; swapping the half and the quarter makes the areas 25 % too large, H 20 % low."""
    mesh = sheared_lattice(15, 11, 0.02, angle)
    angles = rest_angles_deg(mesh)
    assert np.all(angles.max(axis=1) == pytest.approx(116.565, abs=1e-3))  # every face obtuse
    interior = ~mesh.boundary_vertices
    area = rest_operator(mesh)[3]
    # planar: the shares of each face sum to its area (0.5 + 0.25 + 0.25)
    assert area.sum() == pytest.approx(mesh.face_areas.sum(), rel=1e-12)
    # an interior vertex is the obtuse corner of two of its six triangles: 2 / 2 + 4 / 4
    assert area[interior] == pytest.approx(2.0 * mesh.face_areas[0], rel=1e-12)
    radius = 0.15
    c = classify_vertices(cylinder(mesh, radius), mesh, 3.0)
    # the same chord's sagitta as the right-angled grid's: 0.1 % low at most
    assert c["H"][interior] == pytest.approx(-1.0 / (2.0 * radius), rel=1.5e-3)
    assert not c["saw"].any()


def test_the_mixed_areas_of_an_irregular_mesh_with_obtuse_triangles():
    """Per vertex against the geometric construction, on a grid whose vertices moved at random:
    about half its faces obtuse, whose circumcentres lie outside them (their circumcentric
    shares are not the mixed ones). H on a cylinder is not exact on such a mesh with any vertex
    area: the rest cotangent Laplacian of a quadratic is not, where the lattice is irregular."""
    base = grid(13, 11, 0.02)
    rng = np.random.default_rng(7)
    rest = base.rest.copy()
    rest[:, :2] += rng.uniform(-0.007, 0.007, (base.n_vertices, 2))
    mesh = MeshLevel(rest, base.faces)
    obtuse = rest_angles_deg(mesh).max(axis=1) > 90.0
    assert 0.3 < obtuse.mean() < 0.7
    area = rest_operator(mesh)[3]
    assert area == pytest.approx(reference_mixed_areas(mesh), rel=1e-9)
    assert area.sum() == pytest.approx(mesh.face_areas.sum(), rel=1e-12)
    assert area.min() > 0.0


def test_smooth_folds_have_no_saw_teeth_and_saw_teeth_are_all_saw_teeth():
    mesh = grid(15, 9, 0.02)
    fold = saw_teeth_figures(cylinder(mesh, 0.1), mesh, 3.0)
    assert fold["vertices_bent"] == fold["vertices_interior"] > 0
    assert fold["vertex_saw_share"] == 0.0 and fold["vertex_bending_share"] == 0.0
    teeth = saw_teeth_figures(checkerboard(mesh, 0.004), mesh, 3.0)
    assert teeth["vertex_saw_share"] == 1.0
    assert teeth["vertex_bending_share"] == pytest.approx(1.0)


def test_teeth_on_part_of_a_fold_hold_their_share():
    mesh = grid(21, 9, 0.02)
    x = cylinder(mesh, 0.15)
    left = mesh.rest[:, 0] < 0.1
    x[left, 2] += checkerboard(mesh, 0.004)[left, 2]
    figures = saw_teeth_figures(x, mesh, 3.0)
    assert 0.2 < figures["vertex_saw_share"] < 0.8
    assert figures["vertex_bending_share"] > figures["vertex_saw_share"]


def test_the_figures_do_not_change_under_a_rigid_motion_a_scale_or_a_flip():
    mesh = grid(11, 7, 0.02)
    rng = np.random.default_rng(3)
    x = cylinder(mesh, 0.12) + rng.normal(0.0, 0.002, (mesh.n_vertices, 3))
    base = saw_teeth_figures(x, mesh, 3.0)
    assert 0 < base["vertices_saw"] < base["vertices_bent"]  # the noise makes some
    rotation = Rotation.from_rotvec([0.7, -1.9, 2.4]).as_matrix()
    moved = x @ rotation.T + np.array([3.0, -1.0, 0.5])
    assert saw_teeth_figures(moved, mesh, 3.0) == pytest.approx(base, rel=1e-9)
    # twice the size, rest and positions: H halves, the angles and shares stay
    big = MeshLevel(2.0 * mesh.rest, mesh.faces)
    assert vertex_mean_curvature(2.0 * x, big) == pytest.approx(
        0.5 * vertex_mean_curvature(x, mesh), rel=1e-9, abs=1e-12)
    assert saw_teeth_figures(2.0 * x, big, 3.0) == pytest.approx(base, rel=1e-9)
    # the other orientation turns every H, not which vertices are saw teeth
    flipped = MeshLevel(mesh.rest, mesh.faces[:, ::-1].copy())
    assert vertex_mean_curvature(x, flipped) == pytest.approx(-vertex_mean_curvature(x, mesh),
                                                              rel=1e-9, abs=1e-12)
    assert saw_teeth_figures(x, flipped, 3.0) == pytest.approx(base, rel=1e-9)


def test_a_mesh_without_interior_vertices_and_bad_positions():
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    mesh = MeshLevel(rest, np.array([[0, 1, 2], [1, 3, 2]]))
    figures = saw_teeth_figures(rest, mesh, 3.0)
    assert figures["vertices_interior"] == 0 and figures["vertex_saw_share"] == 0.0
    with pytest.raises(ClothInputError, match="shape"):
        vertex_mean_curvature(rest[:3], mesh)
    bad = rest.copy()
    bad[1, 2] = np.inf
    with pytest.raises(ClothInputError, match="non-finite"):
        vertex_mean_curvature(bad, mesh)
    with pytest.raises(ClothInputError, match="--threshold"):
        saw_teeth_figures(rest, mesh, -1.0)


def test_the_calibration_shapes_read_as_what_they_are():
    rows = calibration(3.0)
    assert len(rows) == len(calibration_shapes()[1])
    for row in rows:
        if row["saw_teeth"]:
            assert row["vertex_saw_share"] > 0.7, row
        elif "3 edges" in row["shape"]:
            assert row["vertex_saw_share"] < 0.1, row  # a wave three edges long: borderline
        else:
            assert row["vertex_saw_share"] == 0.0, row
    by_name = {row["shape"]: row for row in rows}
    # the hinge measure on the same lattice (bench.hinge_zigzag's docstring): a cylinder across
    # the rows reads as zig-zag, the accordion pleated at every row as none
    assert by_name["cylinder r 10 cm, axis across the rows"]["zigzag_share"] > 0.9
    assert by_name["accordion pleated at every row"]["zigzag_share"] == 0.0
