"""tolerance: auto (issue 15, item 4; issue 40, part 5): each level of detail solves to the
tolerance its time step allows, measured by the cost model's calibration on messages spread
over the bag's whole motion. Behaviour only: which tolerance is chosen is checked against the
errors the same measurement gives, never against a speed."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cloth_mg_ros.budget.cost_model import (
    TOLERANCE_INTERVALS,
    TOLERANCE_SPAN_S,
    cache_path,
    calibration_frames,
    load_or_calibrate,
    tolerance_frames,
)
from cloth_mg_ros.budget.tolerance_rule import (
    CALIBRATION_SHARE,
    LADDER,
    SOLVER_SHARE,
    interval_tolerance,
    measure_tolerances,
)
from cloth_mg_ros.config import schema
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.config.schema import check
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import GarmentSim
from cloth_mg_ros.sim.solve_tolerance import tolerance_at

POINTS = ((600, 3e-3), (2400, 1e-2))


@pytest.fixture(scope="module")
def walk():
    return read_pose_frames(bundled_bag("walk"))


def _dressed(walk, particles=1200, **kw) -> GarmentSim:
    options = schema.body_options(garment="dress", particles=particles, threads=1,
                             max_substep_motion=0.25, **kw)
    return GarmentSim.dress(Avatar.load(), walk[0][0], walk[0][1], get_material("cotton"),
                            options)


def test_tolerance_at_holds_below_the_points_and_tightens_above_them():
    # POINTS: the calibration's finest level (2400, 1e-2) and the one below it (600, 3e-3)
    assert tolerance_at(POINTS, 2400) == 1e-2 and tolerance_at(POINTS, 100) == 1e-2
    assert tolerance_at(POINTS, 1200) == 1e-2  # nothing looser than measured below it
    assert tolerance_at(POINTS, 9600) == pytest.approx(1e-2 * 0.5)  # (2400 / 9600) ** 0.5
    sizes = [300, 2400, 5000, 20000, 80000]
    assert np.all(np.diff([tolerance_at(POINTS, n) for n in sizes]) <= 0)
    with pytest.raises(ClothInputError, match="no measured tolerances"):
        tolerance_at((), 1000)


def test_a_coarser_level_of_detail_takes_the_calibrations_coarse_tolerance():
    for n in (300, 600):
        assert tolerance_at(POINTS, n, rung=1) == 3e-3
        assert tolerance_at(POINTS, n, rung=2) == 3e-3
    assert tolerance_at(POINTS, 2400, rung=1) == pytest.approx(3e-3 * 0.5)
    assert tolerance_at(POINTS, 5000, rung=1) < tolerance_at(POINTS, 5000, rung=0)
    assert tolerance_at(((2400, 1e-2),), 2400, rung=1) == 1e-2  # nothing coarser measured


def test_bad_tolerances_are_clear_errors():
    assert check("tolerance", "auto") == "auto" and check("tolerance", 1e-4) == 1e-4
    assert check("tolerance", "auto", "scene: tolerance") == "auto"
    for bad in ("fast", 0.0, -1e-4, 0.9, float("nan"), True):
        with pytest.raises(ClothInputError, match="tolerance must be a relative residual"):
            check("tolerance", bad, "scene: tolerance")


def test_each_level_solves_to_its_own_tolerance_and_a_fixed_one_replaces_them(walk):
    garment_sim = _dressed(walk, 2400, tolerance="auto", tolerances=POINTS)
    garment_sim.prepare_rungs()
    assert len(garment_sim.rung_indices()) >= 2
    for level in garment_sim.rung_indices():
        expected = tolerance_at(POINTS, garment_sim.rung_particles(level), level)
        assert garment_sim.rungs[level].solver.tol == pytest.approx(expected)
    garment_sim.set_rung(1)
    assert garment_sim.solve_tolerance() == pytest.approx(
        tolerance_at(POINTS, garment_sim.rung_particles(1), 1))
    garment_sim.set_solver("mpcg", 1e-4)  # a number: every level
    assert {sim.solver.tol for sim in garment_sim.rungs.values()} == {1e-4}
    garment_sim.set_solver("mpcg", "auto")
    assert garment_sim.rungs[0].solver.tol == pytest.approx(tolerance_at(POINTS,
                                                                garment_sim.rung_particles(0)))
    with pytest.raises(ClothInputError, match="no measured tolerances"):
        _dressed(walk, 600, tolerance="auto")


def test_the_chosen_tolerance_is_the_loosest_whose_clip_mean_is_a_tenth_of_the_steps(walk):
    garment_sim = _dressed(walk, 1200, self_contact=True)
    for frame in walk[1:16]:  # the opening hold: the garment settles
        garment_sim.push(*frame)
    solver, tol = garment_sim.options.solver, garment_sim.options.tolerance
    motion = walk[31:40]
    levels = measure_tolerances(garment_sim, motion, intervals=3)
    assert [lv.particles for lv in levels] == [garment_sim.rung_particles(k) for k in
    garment_sim.rung_indices()]
    for lv in levels:
        assert lv.tolerance in LADDER and lv.step_mm > 0.0
        # the sampled messages are spread from the motion's first message to its last
        assert [m[0] for m in lv.messages] == [motion[k][0] for k in (0, 4, 8)]
        # the rule is the clip's: the mean solver error per message over the mean step error
        assert lv.step_mm == pytest.approx(np.mean([m[1] for m in lv.messages]))
        assert lv.solver_mm == pytest.approx(np.mean([m[2] for m in lv.messages]))
        assert lv.ratio == pytest.approx(lv.solver_mm / lv.step_mm)
        assert list(lv.tried) == [t for t in sorted(LADDER, reverse=True) if t >= lv.tolerance]
        if lv.tolerance != min(LADDER):
            assert lv.solver_mm <= SOLVER_SHARE * lv.step_mm
        for looser in list(lv.tried)[:-1]:
            assert lv.tried[looser] > SOLVER_SHARE * lv.step_mm
    # The garment stepped on through the motion at its finest level, its solver as before.
    assert garment_sim.rung == 0 and garment_sim.stamp == pytest.approx(motion[-1][0])
    assert (garment_sim.options.solver, garment_sim.options.tolerance) == (solver, tol)
    assert np.all(np.isfinite(garment_sim.positions))
    # One interval measured in full (the chart's way): tighter solves err less.
    snap = garment_sim.snapshot()
    r = interval_tolerance(garment_sim, snap, 0, walk[40], solver, tols=(1e-2, 1e-4, 1e-6))
    assert r.solver_mm[1e-6] < r.solver_mm[1e-4] < r.solver_mm[1e-2]
    assert r.solver_mm[1e-6] < 0.01 * r.step_mm


def test_calibration_samples_the_bags_whole_motion_not_its_start(walk):
    frames, warmup = calibration_frames(walk)
    first = frames[1 + warmup][0]  # the first message after the calibration's settling
    motion = tolerance_frames(walk, first)
    assert motion[0][0] == first and motion[-1][0] == walk[-1][0]  # the stride to the end
    assert walk[-1][0] - first > 2.0  # the walk bag: 2.6 s of motion, strides included
    # a long bag: up to TOLERANCE_SPAN_S of it
    long = [(0.1 * k, walk[0][1]) for k in range(int(3 * TOLERANCE_SPAN_S / 0.1))]
    span = tolerance_frames(long, 1.0)
    assert span[0][0] == pytest.approx(1.0)
    assert span[-1][0] == pytest.approx(1.0 + TOLERANCE_SPAN_S)


def test_calibration_measures_and_caches_the_tolerances_and_times_with_them(
        walking_calibration, monkeypatch, walk):
    cal = walking_calibration  # the walking scene (tolerance auto), calibrated in conftest
    options, material, model = cal.options, cal.material, cal.model
    monkeypatch.setenv("CLOTH_MG_CACHE", str(cal.cache))
    assert options.tolerance == "auto"
    assert not cal.cached and len(model.tolerances) == 2
    (n0, t0), (n1, t1) = model.tolerances
    assert n0 > n1 == model.points[0][0] and t0 in LADDER and t1 in LADDER
    # each rung's rule on messages spread over the whole walk, its clip mean within the
    # calibration's share (the ladder's tightest is the fallback)
    assert [(r["particles"], r["tolerance"]) for r in model.tolerance_rule] == model.tolerances
    for r in model.tolerance_rule:
        # TOLERANCE_INTERVALS messages spread over the walk's whole motion, its end included
        motion = [st for st, _ in walk[31:]]
        assert len(r["stamps"]) == TOLERANCE_INTERVALS and set(r["stamps"]) <= set(motion)
        assert (r["stamps"][0], r["stamps"][-1]) == (motion[0], motion[-1])
        assert np.max(np.diff(r["stamps"])) < 2.5 * (motion[1] - motion[0])
        assert r["ratio"] == pytest.approx(r["solver_mm"] / r["step_mm"])
        # each sampled message's tick at the rung's tolerance: the margin for slow ticks
        assert len(r["tick_ms"]) == TOLERANCE_INTERVALS and min(r["tick_ms"]) > 0.0
        assert r["ratio"] <= CALIBRATION_SHARE or r["tolerance"] == min(LADDER)
    # the probe garment, about four times the finest rung, timed at its finest level
    n_probe, ms_probe = model.probe
    assert 3.5 * n0 < n_probe < 4.5 * n0 and ms_probe > 0.0
    # never below the line: its second piece is never cheaper per particle, and where the
    # probe came out cheaper it is the line itself, summed another way (a fresh-clone run
    # read it 1 ulp under a + b n: 1e-9 ms allows for the rounding, nothing else)
    assert model.upper_ms()[2] >= model.b_ms
    assert model.step_ms(n_probe) >= model.a_ms + model.b_ms * n_probe - 1e-9
    again, cached = load_or_calibrate(options, material)
    assert cached and again.tolerances == model.tolerances and again.probe == model.probe
    fixed, cached = load_or_calibrate(replace(options, tolerance=1e-4), material)
    assert not cached and fixed.tolerances == []  # a fixed tolerance is another model
    # refresh (bench cost's default) measures again, even with the model cached
    fixed, cached = load_or_calibrate(replace(options, tolerance=1e-4), material, refresh=True)
    assert not cached and fixed.tolerances == []
    assert cache_path(options, "walk", material).is_file()
    assert cache_path(replace(options, tolerance=1e-4), "walk", material).is_file()
    # another fabric is another model: its iterations and the step's error are its own
    assert cache_path(options, "walk", material) != cache_path(options, "walk",
                                                               get_material("silk"))
    assert cache_path(options, "walk", material) == cache_path(options, "walk",
                                                               get_material(material.name))


def test_a_run_with_tolerance_auto_records_what_repeats_it_exactly(tmp_path,
                                                                   walking_calibration):
    from cloth_mg_ros.apps.runner import run_body_scene

    # walking_calibration's settings: its cost model, not a calibration
    params = load_scene("walking").replace(particles=600, tolerance="auto", threads=1)
    first = run_body_scene(params, tmp_path / "auto", steps=40, progress=False)
    assert first["tolerance"] == "auto" and len(first["tolerances"]) == 2
    chosen = first["solve_tolerance"]
    assert chosen == pytest.approx(tolerance_at(first["tolerances"], first["particles"]))
    again = run_body_scene(params.replace(tolerance=chosen), tmp_path / "fixed", steps=40,
                           progress=False)
    assert again["tolerances"] is None and again["solve_tolerance"] == chosen
    a = np.load(tmp_path / "auto" / "positions.npz")["final"]
    b = np.load(tmp_path / "fixed" / "positions.npz")["final"]
    assert np.array_equal(a, b)


def test_the_node_takes_tolerance_auto_at_start_only(walk, walking_calibration):
    import rclpy
    from node_harness import DOMAIN_ID
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from cloth_mg_ros.ros.node import ClothNode

    def node_with(ctx, tolerance):
        # walking_calibration's settings: its cost model, not a calibration
        overrides = {"scene": "walking", "particles": 300,
                     "lod": False, "threads": 1, "tolerance": tolerance}
        return ClothNode(context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])

    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    try:
        node = node_with(ctx, "auto")
        try:
            options = node.session.scene.options
            assert len(options.tolerances) == 2 and options.tolerance == "auto"
            for value in (1e-4, "auto"):
                (result,) = node.set_parameters([Parameter("tolerance", value=value)])
                assert result.successful, result.reason
            (result,) = node.set_parameters([Parameter("tolerance", value="fast")])
            assert not result.successful and "tolerance" in result.reason
        finally:
            node.destroy_node()
        node = node_with(ctx, 1e-4)
        try:
            (result,) = node.set_parameters([Parameter("tolerance", value="auto")])
            assert not result.successful and "at start" in result.reason, result.reason
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_bench_cost_times_a_scene_with_tolerance_auto_at_its_measured_tolerances():
    from cloth_mg_ros.bench.cost import bench_cost

    # cached: the scene's cost model from the run's cache where a node test or bench faults
    # calibrated it, else calibrated here (refresh, the CLI's default, measures again: checked
    # in test_calibration_measures_and_caches_the_tolerances_and_times_with_them)
    result = bench_cost("walking", sizes=(600,), ticks=10, cached=True, log=lambda line: None)
    assert load_scene("walking").tolerance == "auto"
    assert len(result["model"]["tolerances"]) == 2
    (row,) = result["rows"]
    assert row["ticks"] == 10 and row["median_ms"] > 0.0 and math.isfinite(row["error_pct"])
    # the garment solved to the tolerance the model measured for its size
    points = [tuple(p) for p in result["model"]["tolerances"]]
    assert row["tolerance"] == tolerance_at(points, row["particles"], 0)
