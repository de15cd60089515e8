"""bench folds: signed hinge angles and the share of one-triangle zig-zags (saw teeth)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fold_shapes import checkerboard, cylinder, grid
from scipy.spatial.transform import Rotation

from cloth_mg_ros.bench.hinge_zigzag import fold_figures, hinge_angles, hinge_bending
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.topology import MeshLevel


def _hinge(fold: float) -> tuple[np.ndarray, MeshLevel]:
    """Two unit-edge triangles on the x axis, face (0, 1, 2) with normal +z; the second face's
    tip 3 turned about the edge by ``fold`` rad (positive: up, towards the first face's
    normal)."""
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]])
    mesh = MeshLevel(rest, np.array([[0, 1, 2], [1, 0, 3]]))
    x = rest.copy()
    x[3] = [0.5, -np.cos(fold), np.sin(fold)]
    return x, mesh


@pytest.mark.parametrize("degrees", [5.0, 30.0, 90.0, 150.0])
def test_signed_angle_of_a_hinge_folded_either_way(degrees):
    fold = np.radians(degrees)
    up, mesh = _hinge(fold)
    down, _ = _hinge(-fold)
    # folded towards the normals' side: negative; away from it: positive; the size exact
    assert hinge_angles(up, mesh) == pytest.approx([-fold], abs=1e-12)
    assert hinge_angles(down, mesh) == pytest.approx([fold], abs=1e-12)
    flat, _ = _hinge(0.0)
    assert hinge_angles(flat, mesh) == pytest.approx([0.0], abs=1e-15)


def test_the_sign_follows_the_orientation_of_the_faces():
    x, mesh = _hinge(np.radians(40.0))
    flipped = MeshLevel(mesh.rest, mesh.faces[:, ::-1].copy())
    assert hinge_angles(x, flipped) == pytest.approx(-hinge_angles(x, mesh), abs=1e-12)


def test_hinge_bending_is_rest_length_squared_theta_squared_over_the_areas():
    x, mesh = _hinge(np.radians(20.0))
    theta = hinge_angles(x, mesh)
    # edge 1 m, faces 0.5 m^2 each
    assert hinge_bending(mesh, theta) == pytest.approx(theta ** 2 / 1.0)
    # l^2 / (A0 + A1) is scale-free: a mesh twice the size weighs its hinges the same
    big = MeshLevel(2.0 * mesh.rest, mesh.faces)
    assert hinge_bending(big, theta) == pytest.approx(hinge_bending(mesh, theta))


def test_a_smooth_cylinder_fold_has_no_zigzag():
    mesh = grid(15, 9, 0.02)
    x = cylinder(mesh, 0.15)  # about 7.6 degrees across each cell
    theta = np.degrees(hinge_angles(x, mesh))
    # the grid's normals point up (+z), the cylinder curls up: every hinge bends towards them
    assert theta.max() < 1e-9 and theta.min() < -3.0
    figures = fold_figures(x, mesh, 3.0)
    assert figures["bent_triangles"] > 0.8 * figures["triangles"]
    assert figures["zigzag_triangles"] == 0
    assert figures["zigzag_share"] == 0.0
    assert figures["bending_share"] == 0.0
    assert figures["bending_total"] > 0.0


def test_one_triangle_saw_teeth_are_all_zigzag():
    mesh = grid(15, 9, 0.02)
    x = checkerboard(mesh, 0.004)
    figures = fold_figures(x, mesh, 3.0)
    assert figures["bent_triangles"] == figures["triangles"]
    assert figures["zigzag_share"] > 0.95
    assert figures["bending_share"] > 0.95


def test_saw_teeth_on_part_of_a_fold_hold_their_share():
    mesh = grid(21, 9, 0.02)
    x = cylinder(mesh, 0.15)
    teeth = checkerboard(mesh, 0.004)
    left = mesh.rest[:, 0] < 0.1
    x[left, 2] += teeth[left, 2]
    figures = fold_figures(x, mesh, 3.0)
    assert 0.2 < figures["zigzag_share"] < 0.8
    # the teeth bend far more than the fold: they hold most of the bending
    assert figures["bending_share"] > figures["zigzag_share"]
    assert figures["bending_share_hinges"] >= figures["bending_share"]


def test_figures_do_not_change_under_a_rigid_motion():
    mesh = grid(11, 7, 0.02)
    rng = np.random.default_rng(3)
    x = cylinder(mesh, 0.12) + rng.normal(0.0, 0.002, (mesh.n_vertices, 3))
    rotation = Rotation.from_rotvec([0.7, -1.9, 2.4]).as_matrix()
    moved = x @ rotation.T + np.array([3.0, -1.0, 0.5])
    assert hinge_angles(moved, mesh) == pytest.approx(hinge_angles(x, mesh), abs=1e-9)
    a, b = fold_figures(x, mesh), fold_figures(moved, mesh)
    assert a["zigzag_triangles"] > 0  # the noise makes some: the comparison means something
    assert b == pytest.approx(a, rel=1e-9)


def test_a_mesh_without_interior_hinges():
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0], [2, 1, 0]])
    mesh = MeshLevel(rest, np.array([[0, 1, 2], [3, 4, 5]]))
    assert hinge_angles(rest, mesh).shape == (0,)
    figures = fold_figures(rest, mesh)
    assert figures["hinges"] == 0 and figures["triangles"] == 2
    assert figures["zigzag_share"] == 0.0 and figures["bending_share"] == 0.0
    assert json.loads(json.dumps(figures)) == figures


def test_bad_positions_and_threshold_are_refused():
    x, mesh = _hinge(0.3)
    with pytest.raises(ClothInputError, match="shape"):
        hinge_angles(x[:3], mesh)
    x[2, 0] = np.nan
    with pytest.raises(ClothInputError, match="non-finite"):
        fold_figures(x, mesh)
    with pytest.raises(ClothInputError, match="--threshold"):
        fold_figures(_hinge(0.3)[0], mesh, -1.0)


def test_stored_stretch_is_none_in_free_fall_and_some_once_the_sheet_lands():
    """The drape's sheet falls as one until it meets the sphere (0.14 s): no strain; once it
    has landed it holds some (its weight's, and what the contact leaves)."""
    from cloth_mg_ros.bench.folds import drape_case

    _, _, falling = drape_case(150, steps=3)
    _, _, landed = drape_case(150, steps=30)
    assert falling["stretch_energy_j"] < 1e-9
    assert landed["stretch_energy_j"] > 1e-6
    assert falling["mass_kg"] == landed["mass_kg"] == pytest.approx(0.2, rel=1e-6)


@pytest.mark.bench
def test_the_bench_measures_the_dress_and_the_drape(tmp_path, capsys, walking_one_thread):
    from cloth_mg_ros.cli.main import main

    out, png, picture = tmp_path / "folds.json", tmp_path / "folds.png", tmp_path / "dress.png"
    assert main(["bench", "folds", "--particles", "300", "--messages", "4",
                 "--scene", str(walking_one_thread),
                 "--drape-particles", "150", "--drape-steps", "30", "--json", str(out),
                 "--png", str(png), "--picture", str(picture)]) == 0
    printed = capsys.readouterr().out
    assert "zig-zag %" in printed and "saw vertices %" in printed and "at rest %" in printed
    assert "accordion pleated at every row" in printed  # the calibration table
    result = json.loads(out.read_text())
    assert png.stat().st_size > 0 and picture.stat().st_size > 0
    (walk,), (drape,) = result["walking"], result["drape"]
    assert walk["scene"] == "walking" and walk["messages"] == 4
    assert drape["scene"] == "drape" and drape["steps"] == 30
    for row in (walk, drape):
        assert row["triangles"] > 100 and row["hinges"] > row["triangles"]
        assert 0.0 <= row["zigzag_share"] <= 1.0 and 0.0 <= row["bending_share"] <= 1.0
        assert 0 < row["vertices_interior"] < row["triangles"]
        assert 0.0 <= row["vertex_saw_share"] <= 1.0
        assert 0.0 <= row["vertex_bending_share"] <= 1.0
        # the shares are the counts' ratios (the figures the page quotes come from them)
        assert row["zigzag_share"] == pytest.approx(
            row["zigzag_triangles"] / row["bent_triangles"] if row["bent_triangles"] else 0.0)
        assert row["vertex_saw_share"] == pytest.approx(
            row["vertices_saw"] / row["vertices_bent"] if row["vertices_bent"] else 0.0)
        assert row["zigzag_triangles"] <= row["bent_triangles"] <= row["triangles"]
    assert {c["shape"] for c in result["meta"]["calibration"]} >= {
        "accordion pleated at every row", "cylinder r 10 cm, axis across the rows"}
    # the sheet has landed on the sphere in 0.5 s: bent
    assert drape["bent_triangles"] > 0
    # the strain each holds, with its mass: the drape's sheet is the 1 m square of cotton
    assert "stretch J" in printed and "J of stretch in" in printed
    assert drape["mass_kg"] == pytest.approx(0.2, rel=1e-6)
    assert walk["mass_kg"] > 0.0
    assert np.isfinite(walk["stretch_energy_j"]) and walk["stretch_energy_j"] > 0.0
    assert np.isfinite(drape["stretch_energy_j"]) and drape["stretch_energy_j"] > 0.0
    # both measures on the rest shapes too: the flat sheet reads nothing, the dress's tube
    # (rows crossing its axis) reads as zig-zag by the hinges and as smooth by the vertices
    assert drape["rest"]["bent_triangles"] == 0 and drape["rest"]["bending_share"] == 0.0
    assert drape["rest"]["vertices_bent"] == 0
    assert walk["rest"]["zigzag_triangles"] > 0 and walk["rest"]["vertex_bending_share"] < 0.05


def test_the_bench_refuses_bad_options_before_any_work(tmp_path, capsys):
    from cloth_mg_ros.cli.main import main

    for bad, named in ((["--particles", "50"], "--particles"), (["--messages", "0"], "--messages"),
                       (["--threshold", "-2"], "--threshold"),
                       (["--drape-steps", "0"], "--drape-steps"),
                       (["--particles", "x"], "--particles")):
        assert main(["bench", "folds", *bad, "--json", str(tmp_path / "f.json")]) == 2
        assert named in capsys.readouterr().err
    assert not (tmp_path / "f.json").exists()
