"""The headless runner through the `cloth-mg` command line: outputs and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from matplotlib import pyplot as plt

from cloth_mg_ros.cli.main import main


def _run(tmp_path, *extra):
    out = tmp_path / "out"
    code = main(["run", "--steps", "6", "--particles", "300", "--no-progress", "--frames", "2",
                 "--out", str(out), *extra])
    return code, out


@pytest.mark.parametrize("scene", ["drape", "hang"])
def test_run_writes_summary_and_frames(tmp_path, scene, capsys):
    code, out = _run(tmp_path, "--scene", scene, "--material", "denim")
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"] == scene and summary["material"] == "denim"
    # the hang has no collider: its summary claims no friction (before: the default 0.5)
    assert summary["friction"] == (0.5 if scene == "drape" else None)
    assert len(summary["steps"]) == 6
    for step in summary["steps"]:
        for key in ("solve_ms", "iterations", "rel_residual", "kinetic_energy",
                    "potential_energy"):
            assert np.isfinite(step[key])
        assert step["rel_residual"] <= 1e-4
    img = plt.imread(out / "frames.png")
    blue = (img[..., 2] > img[..., 0] + 0.15) & (img[..., 3] > 0.5)
    assert blue.mean() > 0.005  # the shaded cloth is in the picture
    assert "wrote" in capsys.readouterr().out


def test_run_with_mesh_file(tmp_path):
    # A coarse disc-like patch from trimesh, written as OBJ: the file replaces the sheet.
    patch = trimesh.creation.annulus(r_min=0.1, r_max=0.4, height=0.01, sections=16)
    top = patch.vertices[:, 2] > 0
    faces = patch.faces[np.all(top[patch.faces], axis=1)]
    mesh = trimesh.Trimesh(patch.vertices, faces, process=False)
    mesh.remove_unreferenced_vertices()
    path = tmp_path / "patch.obj"
    mesh.export(path)
    code, out = _run(tmp_path, "--scene", "drape", "--mesh", str(path))
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mesh"] == str(path)
    assert summary["particles"] >= len(mesh.vertices)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--material", "velvet"], "unknown material 'velvet'"),
        (["--stretch", "-3"], "stretch must not be negative"),
        (["--dt", "0"], "--dt must be a positive"),
        (["--dt", "-0.01"], "--dt must be a positive"),
        (["--steps", "0"], "--steps must be a positive"),
        (["--particles", "5"], "--particles must be in 16..200000"),
        (["--scene", "tornado"], "unknown scene 'tornado'"),
        (["--solver", "magic"], "unknown solver 'magic'"),
        (["--tol", "2"], "--tol must be a relative residual"),
        (["--tol", "fast"], "--tol must be a relative residual in 1e-10..0.5 or 'auto'"),
        (["--mesh", "/nonexistent/shirt.obj"], "/nonexistent/shirt.obj"),
    ],
)
def test_bad_input_is_one_clear_error_before_anything_runs(tmp_path, capsys, args, message):
    code, out = _run(tmp_path, *args)
    err = capsys.readouterr().err
    assert code == 2
    assert message in err
    assert err.count("error:") == 1
    assert not out.exists()  # nothing ran, nothing written


def test_degenerate_mesh_file_is_rejected(tmp_path, capsys):
    path = tmp_path / "flat.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n")
    code, out = _run(tmp_path, "--mesh", str(path))
    err = capsys.readouterr().err
    assert code == 2 and "degenerate" in err and str(path) in err
    assert not out.exists()


# Every option a scene kind has no use for is refused, named, before anything runs (before,
# a body scene ran with --mesh, --dt or --seed ignored, a sheet with the dressing's or the
# textile tests' options ignored, the dressing with --levels, --stretch ... ignored).
@pytest.mark.parametrize(
    "args, message",
    [
        (["--scene", "walking", "--mesh", "shirt.obj"], "--mesh is not an option of the walking"),
        (["--scene", "walking", "--dt", "0.01"], "--dt is not an option of the walking"),
        (["--scene", "running", "--seed", "3"], "--seed is not an option of the running"),
        (["--scene", "walking", "--speed", "0.1"], "--speed is not an option"),
        (["--scene", "walking", "--angle", "5"], "--angle is not an option"),
        (["--scene", "walking", "--overhang", "0.1"], "--overhang is not an option"),
        (["--scene", "walking", "--particles", "600", "--rate-hz", "30"],
         "--rate-hz is for --particles auto"),
        (["--scene", "drape", "--travel", "0.5"], "--travel is not an option of the drape"),
        (["--scene", "hang", "--seed", "1"], "--seed is not an option of the hang"),
        (["--scene", "hang", "--friction", "0.8"], "--friction is not an option of the hang"),
        (["--scene", "drape", "--width", "0.1"], "--width is not an option of the drape"),
        (["--scene", "dressing", "--levels", "2"], "--levels is not an option of the dressing"),
        (["--scene", "dressing", "--substeps", "2"], "--substeps is not an option"),
        (["--scene", "dressing", "--rate-hz", "30"], "--rate-hz is not an option"),
        (["--scene", "dressing", "--bend", "1e-6"], "--bend is not an option"),
        (["--scene", "dressing", "--duration", "1"], "--duration is not an option"),
        (["--scene", "dressing", "--tol", "auto"], "--tol auto is for body scenes"),
        (["--scene", "dressing", "--tol", "2"], "--tol must be a relative residual"),
        (["--scene", "dressing", "--angle", "50"], "dressing: --angle must be within"),
        (["--scene", "dressing", "--dt", "0.07"], "dressing: --dt 0.07 s is too long"),
        (["--scene", "dressing", "--scheme", "rk4"], "--scheme: unknown scheme 'rk4'"),
        (["--scene", "dressing", "--friction", "-1"], "--friction must be"),
        (["--scene", "dressing", "--seed", "-1"], "dressing: --seed must be a non-negative"),
        (["--scene", "cantilever", "--overhang", "0.1", "--speed", "1"],
         "--speed is not an option of the cantilever"),
        (["--scene", "cusick", "--dt", "0.01"], "--dt is not an option of the cusick"),
    ],
)
def test_an_option_the_scene_does_not_use_is_refused_by_name(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    code = main(["run", "--no-progress", "--out", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("error:") == 1, err
    assert not out.exists()


def test_the_dressing_scene_takes_the_options_its_spec_has(tmp_path, monkeypatch):
    """--tol, --dt, --scheme, --spectral-radius, --friction and --seed reach DressingSpec
    (before, they were dropped and the run took the spec's defaults); no option: the spec's
    defaults, as before."""
    from cloth_mg_ros.apps import dressing_scene

    specs = []

    def stop(spec, **kwargs):
        specs.append(spec)
        raise KeyboardInterrupt  # the spec is what is looked at; nothing runs

    monkeypatch.setattr(dressing_scene, "run_dressing", stop)
    with pytest.raises(KeyboardInterrupt):
        main(["run", "--scene", "dressing", "--no-progress", "--out", str(tmp_path / "a"),
              "--tol", "1e-6", "--dt", "0.01", "--scheme", "genalpha", "--spectral-radius",
              "0.3", "--friction", "0.2", "--seed", "7", "--angle", "10", "--speed", "0.15",
              "--compression", "buckle"])
    with pytest.raises(KeyboardInterrupt):
        main(["run", "--scene", "dressing", "--no-progress", "--out", str(tmp_path / "b")])
    given, default = specs
    assert (given.tolerance, given.dt, given.scheme, given.spectral_radius, given.friction,
            given.seed, given.angle_deg, given.speed, given.compression) == (
        1e-6, 0.01, "genalpha", 0.3, 0.2, 7, 10.0, 0.15, "buckle")
    assert default == dressing_scene.DressingSpec()


def test_levels_zero_is_automatic_on_a_sheet(tmp_path):
    """--levels 0 is the schema's 'as many as the mesh calls for' (before: refused as out of
    1..7): the same run as no --levels."""
    code, out = _run(tmp_path, "--scene", "drape", "--levels", "0", "--steps", "2")
    assert code == 0
    zero = json.loads((out / "summary.json").read_text())
    code, out = _run(tmp_path, "--scene", "drape", "--steps", "2")
    assert code == 0
    auto = json.loads((out / "summary.json").read_text())
    assert zero["levels"] == auto["levels"] > 1
    assert [s["kinetic_energy"] for s in zero["steps"]] == \
        [s["kinetic_energy"] for s in auto["steps"]]
