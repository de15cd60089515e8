"""bench saw_teeth: saw teeth by the vertices' mean curvature, and both measures on known shapes."""

from __future__ import annotations

import numpy as np
import pytest
from fold_shapes import checkerboard, cylinder, grid
from scipy.spatial.transform import Rotation

from cloth_mg_ros.bench.fold_calibration import calibration, calibration_shapes
from cloth_mg_ros.bench.hinge_zigzag import hinge_angles
from cloth_mg_ros.bench.saw_teeth import classify_vertices, saw_teeth_figures, vertex_mean_curvature
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
