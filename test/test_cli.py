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
        (["--particles", "5"], "--particles must be at least"),
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
