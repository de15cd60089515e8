"""The live session at run time, without DDS (ros.session, ros.body_scene, ros.sheet_scene):
what a reset or a new time line does to poses held back, a tick that fails, the requests
that cross from the executor's thread, the timer's span after a pause."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("diagnostic_msgs")

from log_lines import LogLines
from test_live_scene import Outputs, clock, sheet_session

from cloth_mg_ros.budget.cost_model import CostModel
from cloth_mg_ros.ros import body_scene
from cloth_mg_ros.ros.body_scene import AUTO_RATE_KEYS
from cloth_mg_ros.ros.parameters import check_parameters
from cloth_mg_ros.ros.session import MAX_FAILED_TICKS, LiveSession
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
    assert out[-1].values["poses_pending"] == "0" and scene.dropped(counts) == 0


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
    assert counts.used == AUTO_RATE_KEYS and scene.dropped(counts) == 0


def _wait_for(condition, timeout_s: float = 120.0) -> None:
    """Spin until condition() holds (the simulation thread works meanwhile)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def _statuses(outputs: Outputs) -> list[dict]:
    return [c[1] for c in list(outputs.calls) if c[0] == "status"]


def test_a_sheet_tick_that_fails_is_logged_skipped_and_the_node_goes_on():
    """The tick loop survives a tick that raises: logged with its traceback, counted
    (ticks_failed in the status), the next ticks step (old code: the thread and the node
    stopped with status 1)."""
    session, outputs, finished = sheet_session()
    scene, tick = session.scene, session.scene.tick
    failures = [ValueError("boom")]

    def failing_tick(inputs, period_s):
        if failures:
            raise failures.pop()
        return tick(inputs, period_s)

    scene.tick = failing_tick
    try:
        session.start()
        _wait_for(lambda: any(s["ticks_failed"] == "1" and int(s["step"]) >= 2
                              for s in _statuses(outputs)))
        assert finished == [] and session.ticks_failed == 1
        assert sum("Traceback" in line and "boom" in line
                   for line in session.logger.lines) == 1
    finally:
        session.close()


def test_ticks_that_keep_failing_stop_the_node_with_one_traceback_per_kind():
    session, outputs, finished = sheet_session()

    def failing_tick(inputs, period_s):
        raise ValueError("always")

    session.scene.tick = failing_tick
    try:
        session.start()
        _wait_for(lambda: finished)
        assert finished == [1] and session.ticks_failed == MAX_FAILED_TICKS
        lines = session.logger.lines
        assert sum("Traceback" in line for line in lines) == 1
        assert any(f"{MAX_FAILED_TICKS} ticks in a row failed" in line for line in lines)
    finally:
        session.close()


def test_a_body_tick_that_fails_skips_its_poses_and_redresses_on_the_next(monkeypatch):
    """A garment step that raises: the tick's pose is counted as skipped (tick_failed), the
    garment is re-dressed on the next valid pose and steps on; nothing is lost."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag

    monkeypatch.setattr(body_scene, "warm_up_body", lambda scene, outputs: "(skipped)")
    values = check_parameters({"scene": "walking", "particles": 300, "lod": False,
                               "tolerance": 1e-3, "threads": 1, "self_contact": False})
    outputs, finished = Outputs(), []
    session = LiveSession(SessionSettings.from_values(values, body=True), outputs,
                          LogLines(), clock, finished.append)
    frames = read_pose_frames(resolve_bag("walk"))
    try:
        session.prepare()
        scene = session.scene
        session.start()
        _offer(scene, frames[:2])
        _wait_for(lambda: scene.ingest.counts().used == 2)
        dressed = scene.garment_sim

        def failing_advance(keys, dropped=None):
            raise RuntimeError("solver exploded")

        dressed.advance = failing_advance
        _offer(scene, frames[2:3])
        _wait_for(lambda: session.ticks_failed == 1)
        _offer(scene, frames[3:5])
        _wait_for(lambda: scene.ingest.counts().used == 4)
        assert scene.garment_sim is not dressed  # re-dressed on frame 3, stepped to 4
        counts = scene.ingest.counts()
        assert counts.skipped == 1 and scene.frames.count("tick_failed") == 1
        assert counts.pending == 0 and counts.discarded == 0
        # the simulation thread counts a tick's keys used, then lets go of them: wait for both
        _wait_for(lambda: scene.dropped(scene.ingest.counts()) == 0)
        _wait_for(lambda: any(s["ticks_failed"] == "1" and s["poses_used"] == "4"
                              for s in _statuses(outputs)))
        last = _statuses(outputs)[-1]
        assert last["skipped_tick_failed"] == "1" and finished == []
    finally:
        session.close()


def test_a_rate_change_is_queued_for_the_simulation_thread():
    """set_rate_hz (the executor's thread) leaves `config` to the simulation thread, which
    alone replaces it; the new rate counts at once."""
    session, _, _ = sheet_session()
    try:
        config = session.config
        session.set_rate_hz(12.5)
        assert session.rate_hz == 12.5 and session.config is config
        session._apply_requests()  # the simulation thread, before its next tick
        assert session.config.rate_hz == 12.5 and session.rate_hz == 12.5
        assert session.config.solver == config.solver
    finally:
        session.close()


def test_a_sheet_steps_on_the_threads_parameter():
    """threads 1 holds for every kernel of a sheet's tick (numba's count is the calling
    thread's own): before, only the mpcg solver read it."""
    import numba

    from cloth_mg_ros.solvers.threads import available_threads

    if available_threads() < 2:
        pytest.skip("one core: every thread count is 1")
    session, _, _ = sheet_session()  # threads 1, solver mpcg
    asked: list[int] = []
    set_threads = numba.set_num_threads

    def recorded(count: int) -> None:  # a count set and put back within the tick shows here
        asked.append(int(count))
        set_threads(count)

    try:
        def tick_threads() -> int:
            numba.set_num_threads = recorded
            try:
                session.scene.tick(None, 0.02)
            finally:
                numba.set_num_threads = set_threads
            return numba.get_num_threads()

        assert session.sim_thread.call(tick_threads) == 1
        assert set(asked) <= {1}, asked
    finally:
        numba.set_num_threads = set_threads
        session.close()


WARM_SHEET = """
import json
from log_lines import LogLines
from test_live_scene import Outputs, clock
from cloth_mg_ros.apps.warmup import kernel_signatures
from cloth_mg_ros.ros.parameters import check_parameters
from cloth_mg_ros.ros.session import LiveSession
from cloth_mg_ros.ros.session_settings import SessionSettings

values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                           "threads": 1, "scheme": "genalpha", "spectral_radius": 0.5,
                           "compression": "buckle", "friction": 0.2})
session = LiveSession(SessionSettings.from_values(values, body=False), Outputs(), LogLines(),
                      clock, lambda status: None)
session.prepare()
before = kernel_signatures()
session.sim_thread.call(session.scene.tick, None, 0.02)
session.sim_thread.call(session.scene.tick, None, 0.02)
print(json.dumps({"compiled": sorted(session.compiles.compiled),
                  "after": kernel_signatures() - before}))
session.close()
"""


def test_a_sheets_warm_up_leaves_its_integrator_and_membrane_no_kernel():
    """In a fresh process (kernels loaded in this one would hide a gap): a sheet on genalpha
    with a buckling membrane compiles or loads no kernel in its ticks after the warm-up
    (before, the warm-up stepped bdf2 on an elastic membrane)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    here = Path(__file__).resolve().parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(here.parent), str(here), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", WARM_SHEET], capture_output=True, text=True,
                         cwd=here.parent, env=env, timeout=600, check=False)
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result["compiled"] == [] and result["after"] == 0, result


def test_a_resumed_sheets_first_tick_spans_one_period_not_the_pause():
    """A managed node deactivated and activated again: the timer's first tick after the
    resume spans one period of the node's clock (its grippers' stamped poses are used over
    it), not the whole time it was inactive (old code: from the last tick before the stop)."""
    now = [(7, 0)]
    values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                               "threads": 1, "rate_hz": 50.0})
    session = LiveSession(SessionSettings.from_values(values, body=False), Outputs(),
                          LogLines(), lambda: now[0], lambda status: None)
    try:
        session.prepare()
        scene, spans = session.scene, []
        place = scene.desk.place_stamped

        def record(grippers, t0, t1, frame_id):
            spans.append((t0, t1))
            return place(grippers, t0, t1, frame_id)

        scene.desk.place_stamped = record
        session.sim_thread.call(scene.tick, None, 0.02)
        assert spans == [(6.98, 7.0)]
        session.stop()  # deactivated (the loop never ran: nothing to wait for)
        now[0] = (100, 0)  # ... for 93 s
        session.resume()
        _wait_for(lambda: len(spans) >= 2)
        session.stop()
        assert spans[1] == pytest.approx((99.98, 100.0))
    finally:
        session.close()


STUCK = """
import threading
from cloth_mg_ros.ros.sim_thread import SimThread
thread = SimThread()
thread.submit(threading.Event().wait)  # a tick that never ends
print("main done", flush=True)
"""


def test_a_stuck_simulation_thread_does_not_keep_the_process_from_exiting():
    """A stop that timed out leaves the simulation thread in its tick: the process still
    exits (old code: a ThreadPoolExecutor worker, joined at exit, hung it)."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", STUCK], capture_output=True, text=True,
                         timeout=60, check=False)
    assert run.returncode == 0 and "main done" in run.stdout, run.stderr
