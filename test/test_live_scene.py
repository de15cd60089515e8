"""The live scene protocol without DDS: a scene's tick returns values (Frame, Clear) that own
their arrays, and the session publishes exactly what they hold (ros.live_scene, ros.session).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("diagnostic_msgs")

from log_lines import LogLines

from cloth_mg_ros.ros.body_scene import BodyScene
from cloth_mg_ros.ros.ingest import KeyPose
from cloth_mg_ros.ros.live_scene import Clear, Frame, LiveScene
from cloth_mg_ros.ros.parameters import check_parameters
from cloth_mg_ros.ros.session import LiveSession
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.ros.sheet_scene import SheetScene


class Outputs:
    """ClothOutputs' calls, recorded."""

    frame_id = "world"
    wrenches = None

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def frame(self, frame_id: str) -> str:
        return frame_id or self.frame_id

    def cloth(self, model, x, sec, nanosec, frame_id="", v=None, **kw) -> float:
        self.calls.append(("cloth", x.copy(), sec, nanosec))
        return 1.0

    def cloth_messages(self, *a, **kw):
        return None

    def status(self, stats, total_ms, finite, sec, nanosec, values, *a) -> None:
        self.calls.append(("status", dict(values), finite))

    def clear(self, sec, nanosec, frame_id="") -> bool:
        self.calls.append(("clear", sec, nanosec, frame_id))
        return True


def clock() -> tuple[int, int]:
    return 7, 500


def sheet_session(max_steps: int = 0) -> tuple[LiveSession, Outputs, list[int]]:
    values = check_parameters({"scene": "hang", "particles": 120, "max_steps": max_steps,
                               "tick_mode": "timer", "threads": 1})
    outputs, finished = Outputs(), []
    session = LiveSession(SessionSettings.from_values(values, body=False), outputs, LogLines(),
                          clock, finished.append)
    session.prepare()
    return session, outputs, finished


def body_session(**extra) -> LiveSession:
    """A walking scene's session at 300 particles, one thread, no level of detail and no
    self-contact, with `extra` parameters (not prepared)."""
    values = check_parameters({"scene": "walking", "particles": 300, "lod": False,
                               "threads": 1, "self_contact": False, **extra})
    return LiveSession(SessionSettings.from_values(values, body=True), Outputs(), LogLines(),
                       clock, lambda status: None)


def test_both_scenes_implement_the_protocol():
    methods = [m for m in vars(LiveScene) if not m.startswith("_")]
    assert "tick" in methods and "prepare" in methods
    for kind in (BodyScene, SheetScene):
        missing = [m for m in methods if not callable(getattr(kind, m, None))]
        assert not missing, (kind.__name__, missing)


def test_the_hang_says_at_start_that_it_has_no_use_for_friction():
    """The node passes its friction parameter (default 0.5) to every sheet scene; the hang
    has no collider, so the start-up line says the parameter is unused there (before: it was
    taken silently) and the drape's says nothing of it."""
    values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                               "threads": 1, "friction": 0.8})
    session = LiveSession(SessionSettings.from_values(values, body=False), Outputs(),
                          LogLines(), clock, lambda status: None)
    try:
        described = session.prepare()
    finally:
        session.close()
    assert "friction 0.8 unused" in described and "no collider" in described
    values = check_parameters({"scene": "drape", "particles": 120, "tick_mode": "timer",
                               "threads": 1})
    session = LiveSession(SessionSettings.from_values(values, body=False), Outputs(),
                          LogLines(), clock, lambda status: None)
    try:
        assert "friction" not in session.prepare()
    finally:
        session.close()


def test_a_sheets_tick_returns_a_frame_that_owns_its_arrays_and_reset_restarts_it():
    session, _, _ = sheet_session()
    try:
        scene = session.scene
        x0 = scene.sim.state.x.copy()
        (frame,) = scene.tick(scene.take(0.0), 0.02)
        assert isinstance(frame, Frame) and frame.stepped and frame.step == 1
        assert frame.finite and frame.model is scene.scene.model
        assert set(frame.values) >= {"solver", "tolerance", "particles", "mass_kg"}
        assert set(frame.gripper_wrenches) == {"left", "right"}  # the hang's own grippers
        held = frame.positions.copy()
        scene.tick(None, 0.02)  # the next step must not move what the frame holds
        assert np.array_equal(frame.positions, held)
        assert not np.array_equal(scene.sim.state.x, held)
        scene.reset()
        assert np.array_equal(scene.sim.state.x, x0)
    finally:
        session.close()


def test_the_session_publishes_what_the_frames_hold_and_stops_at_max_steps():
    session, outputs, finished = sheet_session(max_steps=2)
    try:
        session.tick(None, 0.02)
        session.tick(None, 0.02)
        cloth = [c for c in outputs.calls if c[0] == "cloth"]
        status = [c[1] for c in outputs.calls if c[0] == "status"]
        assert [c[2:] for c in cloth] == [(7, 500), (7, 500)]  # stamped by the node's clock
        assert np.array_equal(cloth[-1][1], session.scene.sim.state.x)
        assert [s["step"] for s in status] == ["1", "2"]
        assert status[-1]["marker_ms"] == "1.000" and status[-1]["resets"] == "0"
        assert "kernels_compiled" in status[-1]
        assert finished == [0]  # max_steps 2 reached
    finally:
        session.close()


def test_a_body_scene_clears_the_display_and_redresses_on_a_newer_stream():
    """A key of a newer stream than the garment's (after ~/reset) yields a Clear before the
    new dressing's Frame; keys of the stream a reset discarded are dropped, counted."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag

    session = body_session()
    try:
        session.prepare()
        scene = session.scene
        frames = read_pose_frames(resolve_bag("walk"))[:3]

        def key(k: int, generation: int) -> KeyPose:
            stamp, poses = frames[k]
            sec = int(stamp)
            return KeyPose(sec, round((stamp - sec) * 1e9), stamp, "map", poses,
                           generation=generation)

        first = scene.tick([key(0, 0), key(1, 0)], None)
        assert [f.stats is None for f in first] == [True, False]  # dressed, then a tick
        assert first[0].values["substeps"] == "0" and first[1].stepped
        scene.request_reset()  # a new stream: generation 1
        out = scene.tick([key(1, 0), key(2, 1)], None)
        assert isinstance(out[0], Clear) and out[0].frame_id == "map"
        assert isinstance(out[1], Frame) and out[1].stats is None  # re-dressed on key 2
        assert scene.ingest.counts().discarded == 1
    finally:
        session.close()


def test_a_body_scenes_timer_tick_times_itself():
    """tick_mode timer: the tick's step_ms is the time it took (a clock span once replaced
    the timer's start and gave a huge negative figure, which the budget then followed)."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag

    session = body_session(tick_mode="timer")
    try:
        session.prepare()
        scene = session.scene
        frames = read_pose_frames(resolve_bag("walk"))[:3]
        keys = [KeyPose(int(t), round((t - int(t)) * 1e9), t, "", p) for t, p in frames]
        timed = []  # (step_ms, the wall time of the call that made it)
        for part in (keys[:1], keys[1:]):
            t0 = time.perf_counter()
            out = scene.tick(part, 1.0 / 30.0)
            wall_ms = 1e3 * (time.perf_counter() - t0)
            timed += [(f.step_ms, wall_ms) for f in out if isinstance(f, Frame) and f.stepped]
        # within the call that made it: never negative, never longer than the call
        assert timed and all(0.0 <= ms <= wall for ms, wall in timed), timed
    finally:
        session.close()


def test_a_body_scene_driven_by_joints_places_the_body_as_the_segments_do():
    """body_input joints (kinect32, no filter): joint positions made from the walk's segment
    poses, any orientation sent (zero quaternions here), drive the body to within a
    millimetre of the segment input's capsules; a joint missing (NaN) is held; an untracked
    body (every joint at the origin) is skipped and counted, not lost."""
    from node_harness import pose_array_cdr

    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.joint_body import joints_from_poses
    from cloth_mg_ros.motion.skeletons import get_skeleton

    session = body_session(body_input="joints", skeleton="kinect32", joint_filter_hz=0.0)
    try:
        session.prepare()
        scene, skeleton = session.scene, get_skeleton("kinect32")
        frames = read_pose_frames(resolve_bag("walk"))[:4]
        hand = skeleton.joint_index("hand_left")
        for k, (stamp, poses) in enumerate(frames[:3]):
            joints = joints_from_poses(scene.avatar, poses, skeleton)
            sent = np.column_stack([joints, np.zeros((skeleton.num_joints, 4))])
            if k == 1:
                sent[hand, :3] = np.nan  # occluded for a frame: held where it was
            assert scene.ingest.offer(pose_array_cdr(round(stamp * 1e9), sent)) == "ok"
        keys = scene.take(0.0)
        assert [k.poses.shape for k in keys] == [(16, 7)] * 3
        (dressed, ticked) = scene.tick(keys, None)
        assert dressed.stats is None and ticked.stepped and ticked.finite
        got = scene.avatar.capsules(scene.garment_sim.poses)
        want = scene.avatar.capsules(frames[2][1])
        assert max(np.abs(got[0] - want[0]).max(), np.abs(got[1] - want[1]).max()) < 1e-3
        untracked = np.zeros((skeleton.num_joints, 7))
        scene.ingest.offer(pose_array_cdr(round(frames[3][0] * 1e9), untracked))
        assert scene.take(0.0) == []
        counts = scene.ingest.counts()
        assert counts.skipped == 1 and scene.frames.counts["no_body"] == 1
        assert counts.used == 3 and scene.dropped(counts) == 0 and counts.pending == 0
        assert scene.input.track.counts.held == 1
    finally:
        session.close()


def test_a_lost_joints_segments_leave_the_collider_for_the_tick():
    """body_input joints with joint_hold 0: a frame without the right elbow still steps the
    cloth, with the segments that need the elbow out of the collider (GarmentSim.dropped,
    the status's dropped_now); the elbow back, every segment collides again."""
    from node_harness import pose_array_cdr

    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.joint_body import joints_from_poses
    from cloth_mg_ros.motion.skeletons import get_skeleton

    session = body_session(body_input="joints", skeleton="kinect32", joint_filter_hz=0.0,
                           joint_hold=0.0)
    try:
        session.prepare()
        scene, skeleton = session.scene, get_skeleton("kinect32")
        elbow = skeleton.joint_index("elbow_right")
        for k, (stamp, poses) in enumerate(read_pose_frames(resolve_bag("walk"))[:4]):
            sent = np.column_stack([joints_from_poses(scene.avatar, poses, skeleton),
                                    np.zeros((skeleton.num_joints, 4))])
            if k == 2:
                sent[elbow, :3] = np.nan
            assert scene.ingest.offer(pose_array_cdr(round(stamp * 1e9), sent)) == "ok"
            frames = scene.tick(scene.take(0.0), None)
            assert frames and frames[-1].finite
            dropped = scene.garment_sim.dropped
            if k == 2:
                names = {scene.avatar.names[s] for s in np.flatnonzero(dropped)}
                assert names and names <= {"upper_arm_r", "lower_arm_r", "hand_r"}
                assert frames[-1].values["dropped_now"] == ",".join(sorted(
                    names, key=scene.avatar.names.index))
            else:
                assert dropped is None
        assert scene.ingest.counts().used == 4
    finally:
        session.close()


@pytest.mark.parametrize("tick_mode", ["message", "timer"])
def test_a_lost_joints_segments_come_back_with_the_first_key_that_has_it(tick_mode):
    """body_input joints, joint_hold 0, three key poses per tick: the left knee hidden in the
    first key only, the steps toward the second and third have every segment colliding and
    the tick ends with none dropped; hidden in the third only, the segments are out only for
    the steps toward it, and dropped_now names them at the tick's end. Before, the union of
    the tick's masks left them out for every step of both ticks."""
    from node_harness import pose_array_cdr

    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.joint_body import joints_from_poses
    from cloth_mg_ros.motion.skeletons import get_skeleton
    from cloth_mg_ros.sim.body_poses import key_interval
    from cloth_mg_ros.sim.tick_stats import BODY_COLLIDER

    session = body_session(body_input="joints", skeleton="kinect32", joint_filter_hz=0.0,
                           joint_hold=0.0, tick_mode=tick_mode, substeps=6)
    try:
        session.prepare()
        scene, skeleton = session.scene, get_skeleton("kinect32")
        knee = skeleton.joint_index("knee_left")
        frames = read_pose_frames(resolve_bag("walk"))[:7]

        def offer(k: int, hidden: bool) -> None:
            stamp, poses = frames[k]
            sent = np.column_stack([joints_from_poses(scene.avatar, poses, skeleton),
                                    np.zeros((skeleton.num_joints, 4))])
            if hidden:
                sent[knee, :3] = np.nan
            assert scene.ingest.offer(pose_array_cdr(round(stamp * 1e9), sent)) == "ok"

        offer(0, False)
        scene.tick(scene.take(0.0), 0.1)  # dressed
        g = scene.garment_sim
        sim, colliding = g.sim, []
        step = sim.step

        def recording_step():
            ends = sim.control.collider_poses[BODY_COLLIDER]
            colliding.append(len(ends) == 2 or bool(np.all(ends[2])))
            return step()

        sim.step = recording_step
        for first, lost_in in ((1, 0), (4, 2)):
            for i in range(3):
                offer(first + i, i == lost_in)
            keys = scene.take(0.0)
            assert len(keys) == 3 and (keys[lost_in].dropped is not None)
            names = [scene.avatar.names[s] for s in np.flatnonzero(keys[lost_in].dropped)]
            assert set(names) & {scene.avatar.names[s] for s in g.segments}  # they collide
            before, colliding[:] = g.stamp, []
            (frame,) = scene.tick(keys, 0.1)
            n = frame.stats.substeps
            spread = [before + 0.1 * (i + 1) / 3 for i in range(3)]  # BodyScene._timer_path's
            stamps = np.array([before] + ([k.stamp for k in keys] if tick_mode == "message"
                                          else spread))
            toward = [key_interval(stamps, k / n) for k in range(1, n + 1)]
            assert len(colliding) == n and set(toward) == {1, 2, 3}
            assert colliding == [t != lost_in + 1 for t in toward]
            assert frame.values["dropped_now"] == (",".join(names) if lost_in == 2 else "")
    finally:
        session.close()


def _hang_session() -> LiveSession:
    values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                               "threads": 1})
    return LiveSession(SessionSettings.from_values(values, body=False), Outputs(), LogLines(),
                       clock, lambda status: None)


def test_a_solver_this_install_cannot_build_is_refused_and_the_old_one_kept(monkeypatch):
    """`ros2 param set /cloth_node solver amg` without pyamg: the parameter is refused with
    the extra to install; and a change that fails to build anyway (the check passed it)
    leaves the solver before, logged, instead of stopping the simulation thread."""
    from cloth_mg_ros import extras
    from cloth_mg_ros.ros.parameters import check_runtime_change

    monkeypatch.setattr(extras, "_importable", lambda module: module != "pyamg")
    assert "pyamg" in check_runtime_change("solver", "amg")
    assert check_runtime_change("solver", "pcg") is None
    session = _hang_session()
    try:
        session.prepare()
        before = session.solver
        session.request_solver_change("amg", 1e-4)
        session._apply_requests()  # as the simulation thread does before a tick
        assert session.solver == before
        assert any("solver amg refused" in line and "pyamg" in line
                   for line in session.logger.lines)
        session.tick(session.scene.take(0.0), 1.0 / 30.0)  # and it still ticks
    finally:
        session.close()


def test_a_closed_session_is_freed():
    """`ready` freezes what the warm-up left (gc.freeze), the session among it; `close`
    gives it back to the collector, so a managed node's cleanup and configure do not keep
    every earlier session's garment."""
    import gc
    import weakref

    session = _hang_session()
    session.prepare()
    refs = [weakref.ref(session), weakref.ref(session.scene)]
    session.close()
    del session
    gc.collect()
    assert [r() for r in refs] == [None, None]


def test_keys_taken_as_the_loop_stops_are_counted_not_lost():
    """A stop (shutdown, deactivate) wakes the take, which may return keys: the loop does
    not tick them, and the scene counts them as discarded, so received = used + skipped +
    discarded + pending still holds."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag

    session = body_session()
    try:
        session.prepare()
        ingest = session.scene.ingest
        for t, poses in read_pose_frames(resolve_bag("walk"))[:2]:
            ingest.offer_frame(int(t), round((t - int(t)) * 1e9), "world", poses)
        keys = session.scene.take(0.0)
        session.scene.not_ticked(keys)
        c = ingest.counts()
        assert len(keys) == 2 and c.received == c.discarded == 2 and c.pending == c.used == 0
    finally:
        session.close()


def test_a_sheet_on_two_threads_runs_on_one_while_the_cores_are_busy_and_stays_the_same():
    """The thread governor drives a sheet's steps as a body scene's: with the process's
    threads waiting 90 % of their time for a core the hang drops to one thread (logged,
    `threads` on the status), and the cloth is the same bit for bit as on two threads."""
    from cloth_mg_ros.solvers.threads import available_threads

    if available_threads() < 2:
        pytest.skip("one core: every thread count is 1")

    def run(share: float) -> tuple[np.ndarray, list[str], list[str]]:
        values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                                   "threads": 2})
        log = LogLines()
        session = LiveSession(SessionSettings.from_values(values, body=False), Outputs(), log,
                              clock, lambda status: None)
        session.prepare()
        scene = session.scene
        scene.contention.share = lambda: share  # the machine as the scheduler shows it

        def ticks() -> tuple[np.ndarray, list[str]]:
            used = []
            for _ in range(8):
                (frame,) = scene.tick(None, 0.02)
                scene.published(frame, 0.0)
                used.append(frame.values["threads"])
            return frame.positions, used

        try:
            x, used = session.sim_thread.call(ticks)
        finally:
            session.close()
        return x, used, log.lines

    busy, busy_threads, busy_log = run(0.9)
    idle, idle_threads, idle_log = run(0.0)
    assert idle_threads == ["2"] * 8 and not any("solver threads" in s for s in idle_log)
    assert busy_threads[0] == "2" and busy_threads[-1] == "1", busy_threads
    assert any(s.startswith("solver threads: 1 of 2 (the threads waited 90 %") for s in busy_log)
    assert np.array_equal(busy, idle)
