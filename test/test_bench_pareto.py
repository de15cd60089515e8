"""`cloth-mg bench pareto`: error measures, Pareto fronts, a small run, option checks."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from matplotlib import pyplot as plt

from cloth_mg_ros.bench.pareto import validate_pareto_args
from cloth_mg_ros.bench.pareto_report import format_pareto_report, pareto_front
from cloth_mg_ros.bench.pareto_rungs import prolongate_positions, rung_axis, silhouette_iou
from cloth_mg_ros.bench.pareto_runs import surface_errors, vertex_errors
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import sheet_hierarchy
from cloth_mg_ros.sim.solve_tolerance import tolerance_at

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench


def test_pareto_front_keeps_the_undominated_points():
    pts = [(10.0, 1.0), (5.0, 2.0), (20.0, 0.5), (12.0, 3.0), (30.0, 0.5), (7.0, 2.5)]
    assert pareto_front(pts) == [1, 0, 2]


def test_vertex_errors_in_mm():
    ref = np.zeros((2, 4, 3))
    traj = ref.copy()
    traj[1, 0, 2] = 0.004  # one vertex 4 mm off after the second message
    rms, worst = vertex_errors(traj, ref)
    assert worst == pytest.approx(4.0)
    assert rms == pytest.approx(math.sqrt(16.0 / 8))
    assert vertex_errors(traj[:1], ref) == (math.inf, math.inf)


def test_surface_errors_compare_different_meshes():
    fine = sheet_hierarchy(300).levels[0]
    coarse = sheet_hierarchy(100).levels[0]
    x = np.asarray(fine.rest)[None]
    y = np.asarray(coarse.rest)[None]
    # Two resolutions of the same flat sheet lie on the same surface: no error.
    rms, worst = surface_errors(y, coarse.faces, x, fine.faces)
    assert rms < 1e-9 and worst < 1e-9
    # Lifted by 3 mm: every point is 3 mm from the other surface.
    rms, worst = surface_errors(y + [0.0, 0.003, 0.0], coarse.faces, x, fine.faces)
    assert rms == pytest.approx(3.0) and worst == pytest.approx(3.0)


def test_bench_pareto_small_run(tmp_path, capsys, monkeypatch):
    # tolerance auto's points as a calibration would give them (the calibration itself is
    # test_tolerance_auto's); part 5 measures each level at the tolerance they give it
    points = ((150, 5e-3), (600, 2e-2))
    monkeypatch.setattr("cloth_mg_ros.bench.pareto.calibrated_points",
                        lambda bag, garment, material, threads, log: points)
    out_json, out_png = tmp_path / "p.json", tmp_path / "p.png"
    rc = main(["bench", "pareto", "--particles", "600", "--solvers", "mpcg,bscg",
               "--tols", "5e-2,1e-7", "--levels", "2,3", "--sizes", "300",
               "--finest", "600", "--steps", "6", "--settle", "0.2",
               "--rules", "scene,1x,2x", "--every", "2", "--json", str(out_json),
               "--png", str(out_png)])
    assert rc == 0
    result = json.loads(out_json.read_text())
    runs = [r for r in result["runs"] if r["available"]]
    assert {(r["solver"], r["levels"]) for r in runs} == {("mpcg", 2), ("bscg", None)}
    (missing,) = [r for r in result["runs"] if not r["available"]]
    assert missing["levels"] == 3 and "2 levels" in missing["why"]
    for solver in ("mpcg", "bscg"):
        loose, tight = sorted((r for r in runs if r["solver"] == solver),
                              key=lambda r: -r["tol"])
        # A tighter tolerance lands closer to the exact-solve trajectory.
        assert tight["rms_mm"] < loose["rms_mm"]
        assert tight["rms_mm"] < 0.05 and tight["max_mm"] >= tight["rms_mm"]
        assert tight["converged"] and tight["ticks"] == 6
    ref = result["reference"]
    assert ref["small_step_substeps"] >= 8 * ref["substeps"]
    assert ref["time_rms_mm"] > 0.0 and math.isfinite(ref["time_rms_mm"])
    (size,) = result["sizes"]
    assert size["particles"] < 400 and size["resolution_rms_mm"] > 0.0
    assert size["solver_rms_mm"] < size["time_rms_mm"]
    # Part 3: the step rules against 16 steps per message, from the same settled garment.
    part = result["steps"]
    assert part["reference"]["steps"] == 16
    rules = {r["rule"]: r for r in part["rules"]}
    assert set(rules) == {"scene", "1x", "2x"}
    assert rules["1x"]["steps_per_tick"] == 1 and rules["2x"]["steps_per_tick"] == 2
    for r in rules.values():
        assert 0.0 < r["interval_rms_mm"] <= r["interval_worst_rms_mm"] <= r["interval_max_mm"]
        assert math.isfinite(r["clip_rms_mm"]) and r["ms_per_tick"] > 0.0 and r["converged"]
    (halving,) = part["halvings"]
    assert (halving["from"], halving["to"]) == ("1x", "2x") and halving["interval_rms_mm"] > 0
    assert part["floor_mm"]["rms"] > 0.0
    # Parts 4 and 5: a 600-particle dress has one live level (no coarser one of 300+).
    assert [r["level"] for r in result["lod_levels"]["levels"]] == [0]
    assert [r["level"] for r in result["lod_tolerance"]["levels"]] == [0]
    # --every 2: part 5 measures pose messages 0, 2 and 4 of the six
    assert result["lod_tolerance"]["levels"][0]["intervals"] == 3
    assert result["meta"]["every"] == 2
    # Part 5's ladder takes the run's tolerances that lie within its range (5e-2, not 1e-7).
    ladder = result["lod_tolerance"]["tols"]
    assert 5e-2 in ladder and 1e-7 not in ladder and 1e-1 in ladder and 1e-6 in ladder
    assert set(result["lod_tolerance"]["levels"][0]["solver_rms_mm"]) == {f"{t:g}" for t in ladder}
    # tolerance auto's rule at the tolerance the points give the level, over the measured
    # messages: the mean solver error over the mean step error, and each message's ratio
    (row,) = result["lod_tolerance"]["levels"]
    auto = row["auto"]
    assert auto["tolerance"] == pytest.approx(tolerance_at(points, row["particles"],
                                                           row["level"]))
    assert auto["tolerance"] in ladder and len(row["messages"]) == auto["messages"] == 3
    step = np.array([m["step_mm"] for m in row["messages"]])
    solver = np.array([m["solver_mm"][f"{auto['tolerance']:g}"] for m in row["messages"]])
    assert auto["ratio"] == pytest.approx(solver.mean() / step.mean())
    assert auto["holds"] == (auto["ratio"] <= 0.1)
    assert auto["message_ratio_max"] == pytest.approx(np.max(solver / step))
    assert auto["messages_within"] == pytest.approx(np.mean(solver / step <= 0.1))
    assert row["ratio"][f"{auto['tolerance']:g}"] == pytest.approx(auto["ratio"])
    assert result["lod_tolerance"]["auto_points"] == [list(p) for p in points]
    height, width = plt.imread(out_png).shape[:2]
    assert 1.5 * height < width < 2 * height  # five panels in two rows of three
    text = capsys.readouterr().out
    assert "step rules against 16 steps per message" in text
    assert "Pareto fronts" in text and "error against particles" in text
    assert "solver error at each tolerance" in text
    assert "tolerance auto's rule over one pose message in 2 " in text
    assert "mpcg" in format_pareto_report(result)


def test_prolongated_positions_and_outlines():
    h = sheet_hierarchy(300)
    fine, coarse = h.levels[0], h.levels[1]
    shown = prolongate_positions(h, np.asarray(coarse.rest), 1)
    assert shown.shape == (fine.n_vertices, 3)
    # The coarse vertices stay as they are; on a flat sheet the finer ones lie on it too.
    assert np.array_equal(shown[:coarse.n_vertices], np.asarray(coarse.rest))
    assert np.allclose(shown[:, 1], np.asarray(fine.rest)[:, 1])
    x = np.asarray(fine.rest)
    faces = np.asarray(fine.faces)
    assert silhouette_iou(x, x, faces) == 1.0
    lower = x - [0.0, 0.0, 0.05]  # lowered 5 cm: the outlines overlap in part
    assert 0.2 < silhouette_iou(x, lower, faces) < 0.999


def test_levels_of_detail_and_the_tolerance_per_level():
    """Parts 4 and 5 on a 2400-particle dress (two live levels: 2394 and 615 particles)."""
    from cloth_mg_ros.bench.pareto_runs import settled_garment
    from cloth_mg_ros.bench.pareto_tolerance import tolerance_axis
    from cloth_mg_ros.physics.materials import get_material

    base, frames, _ = settled_garment("walk", "dress", 2400, get_material("cotton"), 0.2, 4)
    part = rung_axis(base, frames, log=lambda line: None)
    fine, coarse = part["levels"]
    assert (fine["level"], fine["interval_rms_mm"], fine["silhouette_iou"]) == (0, 0.0, 1.0)
    assert coarse["particles"] < fine["particles"] / 3
    # The coarse mesh misses detail before it steps; one interval adds its own motion.
    assert 0.0 < coarse["shape_rms_mm"]
    assert 0.0 < coarse["interval_rms_mm"] <= coarse["interval_worst_rms_mm"] \
        <= coarse["interval_max_mm"]
    assert 0.5 < coarse["silhouette_iou"] < 1.0 and coarse["silhouette_iou_interval"] < 1.0
    for row in part["levels"]:
        assert 0.0 <= row["penetration_mm"] < 5.0 and 0.0 <= row["stretch"] < 1.0
        assert row["ms_per_tick"] > 0.0
    assert part["floor_mm"]["rms"] > 0.0
    tols = tolerance_axis(base, frames, tols=(1e-1, 1e-3, 1e-6), every=2, small_factor=4,
                          log=lambda line: None)
    assert [r["level"] for r in tols["levels"]] == [0, coarse["level"]]
    for r in tols["levels"]:
        err = r["solver_rms_mm"]
        assert r["intervals"] == 2 and r["step_rms_mm"] > 0.0
        assert err["1e-06"] < err["0.1"]  # a tighter tolerance lands closer to exact
        assert r["tolerance_all"] <= r["tolerance_median"]
        if r["tolerance_all"] > 1e-6:  # met on every interval, so on their mean too
            assert err[f"{r['tolerance_all']:g}"] <= tols["share"] * r["step_rms_mm"]
            assert r["tolerance_mean"] >= r["tolerance_all"]
        # auto's criterion: the loosest whose mean error is within the share of the mean step
        # (the tightest tried when none is)
        met = [t for t in tols["tols"] if err[f"{t:g}"] <= tols["share"] * r["step_rms_mm"]]
        assert r["tolerance_mean"] == (max(met) if met else min(tols["tols"]))
    # --ladder auto: no ladder, only the tolerance auto gives each level and the reference
    points = ((150, 5e-3), (600, 2e-2))
    alone = tolerance_axis(base, frames[:1], tols=(), small_factor=2, log=lambda line: None,
                           auto_points=points)
    given = {tolerance_at(points, r["particles"], r["level"]) for r in alone["levels"]}
    assert alone["tols"] == sorted(given | {1e-4}, reverse=True)
    for r in alone["levels"]:
        assert set(r["solver_rms_mm"]) == {f"{t:g}" for t in alone["tols"]}
        assert r["auto"]["tolerance"] == pytest.approx(
            tolerance_at(points, r["particles"], r["level"]))


def test_cells_on_two_workers_give_the_errors_of_one(dask_local):
    """The cells of part 1 on two Dask workers (each preparing the settled garment and the
    exact reference itself) against one worker doing them all: the same errors, bit for bit
    (one thread each, the same inputs)."""
    from cloth_mg_ros.bench.pareto import bench_pareto

    kw = {"particles": 600, "solvers": ["mpcg", "pcg"], "tols": [1e-2, 1e-5], "levels": [2],
          "sizes": [], "finest": None, "steps": 4, "settle": 0.2, "rules": (),
          "log": lambda line: None, "threads": 1, "auto": False}
    one = bench_pareto(workers=1, **kw)
    two = bench_pareto(client=dask_local, workers=2, **kw)
    key = ("solver", "levels", "tol", "rms_mm", "max_mm", "iterations", "ticks")
    assert [{k: r[k] for k in key} for r in one["runs"]] == [
        {k: r[k] for k in key} for r in two["runs"]]
    assert one["reference"]["time_rms_mm"] == two["reference"]["time_rms_mm"]
    assert len(one["runs"]) == 4 and two["meta"]["workers"] == 2


def test_bad_options_are_named():
    with pytest.raises(ClothInputError) as exc:
        validate_pareto_args("walk", "dress", 600, ["mpcg", "direct", "nope"], [0.0, 1e-4],
                             [0], [300], 200, "cotton", 5, -1.0, 0)
    msg = str(exc.value)
    for part in ("'direct' is the reference", "nope", "--tols", "--levels", "--finest",
                 "--settle", "--every"):
        assert part in msg
    with pytest.raises(ClothInputError, match="--ladder must be one of full, auto"):
        validate_pareto_args("walk", "dress", 600, ["mpcg"], [1e-4], [2], [], None, "cotton",
                             5, 1.0, 1, "some")
    with pytest.raises(ClothInputError, match=r"--ladder auto .* \(leave out --no-auto\)"):
        validate_pareto_args("walk", "dress", 600, ["mpcg"], [1e-4], [2], [], None, "cotton",
                             5, 1.0, 1, "auto", False)
    assert main(["bench", "pareto", "--tols", "abc"]) == 2
    assert main(["bench", "pareto", "--rules", "fast"]) == 2
