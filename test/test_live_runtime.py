"""The live session at run time, without DDS (ros.session, ros.body_scene, ros.sheet_scene):
what a reset or a new time line does to poses held back, a tick that fails, the requests
that cross from the executor's thread, the timer's span after a pause."""

from __future__ import annotations

import pytest

pytest.importorskip("diagnostic_msgs")

from log_lines import LogLines
from test_live_scene import Outputs, clock

from cloth_mg_ros.budget.cost_model import CostModel
from cloth_mg_ros.ros import body_scene
from cloth_mg_ros.ros.body_scene import AUTO_RATE_KEYS
from cloth_mg_ros.ros.parameters import check_parameters
from cloth_mg_ros.ros.session import LiveSession
from cloth_mg_ros.ros.session_settings import SessionSettings


def _cost_model() -> CostModel:
    """A made-up cost model: any garment up to max_particles fits a 30 Hz stream's budget."""
    a, b = 1.0, 1e-4
    return CostModel(a, b, [(600, a + 600 * b), (2400, a + 2400 * b)], 0.0,
                     {"substeps": 1, "max_step": 0.1}, "m", "v", 0.5)


@pytest.fixture()
def auto_session(monkeypatch):
    """A walking session with particles auto (at most 300: the smallest dress), its cost model
    made up and its warm-up left out (the tests below time nothing and compile what they
    use): (session, walk bag frames [(stamp s, poses (S, 7))])."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag

    monkeypatch.setattr(body_scene, "load_or_calibrate",
                        lambda *a, **kw: (_cost_model(), True))
    monkeypatch.setattr(body_scene, "warm_up_body", lambda scene, outputs: "(skipped)")
    values = check_parameters({"scene": "walking", "particles": "auto", "max_particles": 300,
                               "lod": False, "tolerance": 1e-3, "threads": 1,
                               "self_contact": False})
    session = LiveSession(SessionSettings.from_values(values, body=True), Outputs(),
                          LogLines(), clock, lambda status: None)
    session.prepare()
    try:
        yield session, read_pose_frames(resolve_bag("walk"))
    finally:
        session.close()


def _offer(scene, frames, shift_s: float = 0.0) -> None:
    from node_harness import pose_array_cdr

    for stamp, poses in frames:
        scene.ingest.offer(pose_array_cdr(round((stamp + shift_s) * 1e9), poses))


def _tick(scene) -> list:
    return scene.tick(scene.take(0.0), None)


def test_particles_auto_forgets_the_poses_it_held_when_a_reset_starts_a_new_stream(
        auto_session):
    """Fewer than AUTO_RATE_KEYS poses held for particles auto's rate, then ~/reset and a
    stream whose stamps start over: the held poses are discarded (counted), the garment is
    dressed on the new stream's first pose and steps on (old code: the old poses were mixed
    in, stamps went back and advance raised)."""
    session, frames = auto_session
    scene = session.scene
    old = frames[20:20 + AUTO_RATE_KEYS - 2]
    _offer(scene, old)
    assert _tick(scene) == []  # held: the rate is not known yet
    assert scene.pending(scene.ingest.counts()) == len(old)
    session.reset()
    session._apply_requests()  # as the loop does before its next tick
    _offer(scene, frames[:AUTO_RATE_KEYS])
    out = _tick(scene)
    assert out and out[0].stats is None  # dressed ...
    assert out[0].values["stamp_s"] == f"{frames[0][0]:.6f}"  # ... on the new stream's first
    assert out[-1].stepped and out[-1].finite
    counts = scene.ingest.counts()
    assert counts.discarded == len(old) and counts.used == AUTO_RATE_KEYS
    assert out[-1].values["poses_pending"] == "0" and counts.dropped == 0


def test_particles_auto_forgets_the_poses_it_held_when_the_stream_restarts(auto_session):
    """The same with a new time line (stamps that went back: a looped bag) instead of a
    reset: the old stream's held poses are discarded, the new one dresses and steps."""
    session, frames = auto_session
    scene = session.scene
    old = frames[20:22]
    _offer(scene, old, shift_s=100.0)
    assert _tick(scene) == [] and scene.pending(scene.ingest.counts()) == 2
    _offer(scene, frames[:AUTO_RATE_KEYS])  # stamps back by 100 s: a new stream
    out = _tick(scene)
    assert out and out[0].stats is None and out[-1].stepped and out[-1].finite
    assert out[0].values["stamp_s"] == f"{frames[0][0]:.6f}"
    counts = scene.ingest.counts()
    assert counts.restarts == 1 and counts.discarded == 2
    assert counts.used == AUTO_RATE_KEYS and counts.dropped == 0
