"""Benchmarks refuse bad options before any work: no dressing, no calibration, no node."""

from __future__ import annotations

import pytest

from cloth_mg_ros.errors import ClothInputError


def _no_work(*args, **kwargs):
    raise AssertionError("work started before the options were checked")


@pytest.mark.parametrize("kwargs, match", [
    ({"threads": -1}, "threads"),
    ({"tol": "auto"}, "--tol"),  # make_solver takes no 'auto' in each run's process
])
def test_scaling_checks_up_front(monkeypatch, kwargs, match):
    from cloth_mg_ros.bench import scaling

    monkeypatch.setattr(scaling, "dask_client", _no_work)
    args = {"sizes": [300], "solvers": ["mpcg"], "steps": 3} | kwargs
    with pytest.raises(ClothInputError, match=match):
        scaling.bench_scaling(**args, log=lambda line: None)


def test_profile_checks_threads_before_any_work(monkeypatch):
    from cloth_mg_ros.bench import profile_tick

    monkeypatch.setattr(profile_tick, "load_scene", _no_work)
    with pytest.raises(ClothInputError, match="threads"):
        profile_tick.profile_ticks(particles=300, threads=-1)


@pytest.mark.parametrize("kwargs, match", [
    ({"rate": []}, "--rate"),
    ({"threads": -3}, "threads"),
    ({"contact_friction": "after"}, "--contact-friction"),
])
def test_node_bench_checks_before_a_node_starts(monkeypatch, kwargs, match):
    from cloth_mg_ros.bench import node_latency

    monkeypatch.setattr(node_latency, "_record_run", _no_work)
    with pytest.raises(ClothInputError, match=match):
        node_latency.bench_node("walk", 300, **kwargs)


def test_node_bench_passes_the_contact_friction_to_the_node():
    from cloth_mg_ros.bench import node_latency

    opts = node_latency.NodeBenchOptions("walk", 300, contact_friction="solve")
    extra = node_latency._node_overrides(node_latency._plan(opts))
    assert "contact_friction:=solve" in extra
    plain = node_latency._node_overrides(node_latency._plan(node_latency.NodeBenchOptions()))
    assert not any(e.startswith("contact_friction") for e in plain)


@pytest.mark.parametrize("kwargs, match", [
    ({"particles": 3}, "--particles"),
    ({"rate": 0.0}, "--rate"),
    ({"jitter_m": -0.001}, "--jitter-mm"),
    ({"occlusion": 1.0}, "--occlusion"),
    ({"occlusion": -0.1}, "--occlusion"),
    ({"scene": "nowhere"}, "--scene"),
])
def test_trackers_checks_before_bags_or_nodes(monkeypatch, tmp_path, kwargs, match):
    from cloth_mg_ros.bench import trackers

    monkeypatch.setattr(trackers, "_write_bags", _no_work)
    monkeypatch.setattr(trackers, "live_run", _no_work)
    bvh = tmp_path / "clip.bvh"
    bvh.write_text("HIERARCHY\n")
    with pytest.raises(ClothInputError, match=match):
        trackers.bench_trackers(bvh, **kwargs, log=lambda line: None)


def test_a_bag_inside_the_repository_is_recorded_relative(tmp_path):
    from cloth_mg_ros.bench.results import recorded_path
    from cloth_mg_ros.io.bags import resolve_bag

    assert recorded_path(resolve_bag("walk")) == "bags/walk"  # not /home/.../bags/walk
    outside = tmp_path / "my_bag"
    assert recorded_path(outside) == str(outside.resolve())
