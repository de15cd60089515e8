"""cloth_node as a separate process, over real Fast DDS on loopback.

Each test run gets its own ROS_DOMAIN_ID and loopback discovery (node_harness.py, fixtures in
conftest.py). Names, frames, /diagnostics, geometry out and bag loops: test_node_interfaces.py;
coalescing, QoS, a fast publisher and lock-step determinism: test_node_ingestion.py.

Body scenes: the walking scene at ~400 particles, fed the first 40 messages of the bundled
walk bag by `cloth-mg replay` (a subprocess) or by `replay_bag` (in a thread of the test).
They keep the scene's settings that its cost model is calibrated on (tolerance auto, self
contact, the threads) unless a test is about one of them: every such node then starts from
the one calibration in the run's cache (conftest.cost_model_cache; 30-45 s each otherwise).
The relations checked: every valid pose message is used (simulated to, or coalesced into a
tick that reached a newer one: how many are coalesced depends on the machine's load, so the
tests never count on it), none is dropped; the node publishes one cloth marker (and one
marker array and one status) per tick, stamped with the newest pose of the tick, so the
marker stamps are increasing pose stamps and the last is the last pose's; skipped frames
(empty, wrong count, NaN, stamps not advancing) are never used.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("visualization_msgs")
pytest.importorskip("diagnostic_msgs")
pytest.importorskip("std_srvs")

from diagnostic_msgs.msg import DiagnosticStatus
from node_harness import (
    BODY_PARTICLES,
    MESSAGES,
    PARTICLES,
    RELIABLE_INPUT,
    REPO,
    START_TIMEOUT_S,
    Listener,
    array_stamp_ns,
    check_marker,
    domain_id,
    kill_node,
    node_command,
    pose_array_cdr,
    replay_in_thread,
    stamps_ns,
    start_node,
    stats_stamp_ns,
    status_values,
    stop_node,
)
from rclpy.context import Context
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.io.bags import POSE_ARRAY, jazzy_typestore, write_pose_bag
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.ros.marker_array import ARROW_NS
from cloth_mg_ros.ros.message_reference import deserialize
from cloth_mg_ros.sim.sheets import DRAPE_SHEET_HEIGHT, build_scene

# ------------------------------------------------------------------------------------------
# In-process checks (no DDS traffic)


def test_hand_written_layouts_match_rclpy():
    from cloth_mg_ros.ros.ingest import pose_array_from_cdr, verify_pose_array_layout
    from cloth_mg_ros.ros.marker_array import (
        marker_array_bytes,
        marker_array_message,
        strain_colours,
        verify_marker_array_layout,
    )

    verify_pose_array_layout()
    verify_marker_array_layout()
    with pytest.raises(ValueError):
        pose_array_from_cdr(b"\x00\x01\x00\x00\x01")
    # Strain colours: the rest shape is the plain cloth colour, a stretched one turns red.
    model = build_scene("hang", 100, get_material("cotton")).model
    rest = model.mesh.rest
    plain = strain_colours(rest, model.mesh.edges, model.edge_rest)
    assert plain.shape == (model.n, 4) and plain.dtype == np.float32
    assert np.allclose(plain, plain[0]) and plain[0, 0] == pytest.approx(0.85)
    red = strain_colours(rest * 1.2, model.mesh.edges, model.edge_rest)
    assert np.allclose(red[:, :3], [0.9, 0.05, 0.05], atol=1e-6)
    data = marker_array_bytes(rest, model.mesh.faces, 1, 2, "world", per_vertex_colours=red)
    (cloth,) = deserialize(data, MarkerArray).markers
    assert len(cloth.colors) == len(cloth.points) == 3 * len(model.mesh.faces)
    ref = marker_array_message(rest, model.mesh.faces, 1, 2, "world")
    assert ref.markers[0].points == cloth.points


@pytest.mark.parametrize("scene", ["walking", "brisk_walking", "running", "jumping"])
def test_every_key_of_the_scene_files_is_declared(ros_env, scene):
    import yaml
    from rclpy.parameter import Parameter

    from cloth_mg_ros.ros.node import ClothNode

    params = yaml.safe_load((REPO / "config" / f"{scene}.yaml").read_text())
    params = params["/**"]["ros__parameters"] | {"particles": 100}
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id())
    try:
        node = ClothNode(context=ctx, parameter_overrides=[Parameter(k, value=v)
                                                           for k, v in params.items()])
        try:
            for key, value in params.items():
                assert node.get_parameter(key).value == value, key
            assert node.body and node.session.settings.values.tick_mode == "message"
            desc = node.describe_parameter("tolerance")
            assert not desc.read_only and desc.floating_point_range[0].to_value == 0.5
            assert node.describe_parameter("garment").read_only
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


# ------------------------------------------------------------------------------------------
# Sheet scenes (timer mode)


def test_node_publishes_markers_and_stats_and_stops_on_sigint(ros_env, listener, tmp_path):
    model = build_scene("drape", PARTICLES, get_material("cotton")).model
    faces = model.mesh.faces
    log_path = tmp_path / "node.log"
    proc = start_node(node_command(f"particles:={PARTICLES}", "scene:=drape", "rate_hz:=50.0",
                                   "max_steps:=0"), ros_env, log_path)
    lis = listener
    try:
        ok = lis.spin_until(lambda: len(lis.markers) >= 10 and len(lis.stats) >= 10
                            and len(lis.arrays) >= 1, START_TIMEOUT_S, proc, log_path)
        assert ok, (f"{len(lis.markers)} markers, {len(lis.stats)} stats in "
                    f"{START_TIMEOUT_S} s:\n{log_path.read_text()}")

        first = None
        for data in lis.markers:
            msg = deserialize(data, Marker)
            assert msg.type == Marker.TRIANGLE_LIST and msg.action == Marker.ADD
            assert msg.header.frame_id == "world" and msg.ns == "cloth"
            assert len(msg.points) == 3 * len(faces)
            pts = np.array([[p.x, p.y, p.z] for p in msg.points])
            assert np.isfinite(pts).all()
            first = pts if first is None else first
        assert not np.array_equal(first, pts), "the cloth did not move"
        # The marker array: the drape scene's sphere and the caption (the cloth is drawn
        # once, on the marker topic).
        arr = deserialize(lis.arrays[-1], MarkerArray)
        assert [m.ns for m in arr.markers] == ["collider", "caption"]
        assert arr.markers[0].type == Marker.SPHERE
        assert arr.markers[0].scale.x == pytest.approx(0.5)
        assert arr.markers[1].type == Marker.TEXT_VIEW_FACING
        assert f"{model.n} particles" in arr.markers[1].text, arr.markers[1].text

        for arr in lis.stats:
            status, values = status_values(arr)
            assert status.name == "cloth_node: solver"
            assert status.level == DiagnosticStatus.OK, f"{status.message} {values}"
            for key in ("step", "solve_ms", "step_ms", "iterations", "rel_residual",
                        "max_penetration_m", "contacts", "particles"):
                assert key in values
            assert int(values["particles"]) == model.n
            assert float(values["rel_residual"]) <= 1e-4
        steps = [int(status_values(a)[1]["step"]) for a in lis.stats]
        assert steps == sorted(steps) and steps[0] >= 1

        # The reset service restarts the sheet: the step count goes on, the cloth starts over.
        # Once it has landed (its mean height 8 cm below the start), the ticks are slowed to
        # 5 Hz, so that the restarted sheet's first ticks, near its start height, are seen
        # whatever this process's pace; a marker after the reset must come back near it.
        def mean_z(data: bytes) -> float:
            return float(marker_arrays_from_bytes(data).points[:, 2].mean())

        assert lis.spin_until(lambda: mean_z(lis.markers[-1]) < DRAPE_SHEET_HEIGHT - 0.08,
                              60.0, proc, log_path), log_path.read_text()
        assert lis.set_parameter("rate_hz", 5.0).successful
        n_before = len(lis.markers)
        step_before = int(status_values(lis.stats[-1])[1]["step"])
        assert lis.call(lis.reset, Trigger.Request()).success
        assert lis.spin_until(lambda: any(mean_z(d) > DRAPE_SHEET_HEIGHT - 0.04
                                          for d in lis.markers[n_before:]), 30.0, proc,
                              log_path), log_path.read_text()
        assert lis.spin_until(lambda: int(status_values(lis.stats[-1])[1]["step"])
                              > step_before, 30.0, proc, log_path)
        stop_node(proc, log_path)
    finally:
        kill_node(proc)


@pytest.mark.parametrize(("param", "named"), [
    ("material:=velvet", "velvet"),
    ("scene:=tablecloth", "tablecloth"),
    ("particles:=5", "particles"),
    ("garment:=gown", "gown"),
    ("tick_mode:=sometimes", "tick_mode"),
])
def test_bad_parameter_exits_nonzero_naming_it(ros_env, param, named):
    run = subprocess.run(node_command(param), env=ros_env, cwd=REPO, capture_output=True,
                         text=True, timeout=60, check=False)
    assert run.returncode != 0
    assert named in run.stderr, run.stderr
    assert "Traceback" not in run.stderr, run.stderr


def test_max_steps_exits_zero(ros_env):
    run = subprocess.run(node_command("scene:=drape", "particles:=100", "max_steps:=3",
                                      "rate_hz:=100.0"),
                         env=ros_env, cwd=REPO, capture_output=True, text=True, timeout=60,
                         check=False)
    assert run.returncode == 0, run.stderr
    assert "max_steps 3 reached" in run.stderr


# ------------------------------------------------------------------------------------------
# Body scenes


def _walking_node(ros_env, tmp_path, *params: str):
    """cloth_node on the walking scene at BODY_PARTICLES (and `params`): (process, log). The
    level of detail off: on a loaded machine it stepped the dress down mid-test, and the
    re-dress's DELETEALL and smaller cloth are not what these tests check. Its input reliable
    (RELIABLE_INPUT): these tests assert that every pose is used."""
    log_path = tmp_path / "node.log"
    proc = start_node(node_command(f"particles:={BODY_PARTICLES}", "lod:=false",
                                   RELIABLE_INPUT, *params,
                                   params_file=str(REPO / "config" / "walking.yaml")),
                      ros_env, log_path)
    return proc, log_path


def _play(lis: Listener, proc, log_path: Path, bag: Path, expected: list[int]) -> None:
    """Replay `bag` from the listener's process and spin until the node's marker of its last
    pose (stamps `expected`, ns) and a status for every marker arrived."""
    before = len(lis.markers)
    thread = replay_in_thread(bag, lis.ctx)
    ok = lis.spin_until(lambda: not thread.is_alive() and len(lis.markers) > before
                        and lis.has_tick(expected[-1]), 60.0, proc, log_path)
    assert not thread.errors, thread.errors
    assert ok, (f"{len(lis.markers)} markers ({before} before), stamps "
                f"{stamps_ns(lis.markers[before:])[-3:]} (last pose {expected[-1]}), "
                f"{len(lis.stats)} statuses:\n{log_path.read_text()}")


def test_body_scene_one_marker_per_pose_message(ros_env, listener, tmp_path, short_bag,
                                                walk_frames):
    proc, log_path = _walking_node(ros_env, tmp_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        t0 = time.monotonic()
        replay = subprocess.Popen([sys.executable, "-m", "cloth_mg_ros.cli.main", "replay",
                                   str(short_bag), "--wait", "30", "--settle", "0.3"],
                                  env=ros_env, cwd=REPO, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        expected = [round(s * 1e9) for s, _ in walk_frames]

        def all_used() -> bool:
            # the last tick's status says every pose was used: the statuses come in order,
            # so every tick's has arrived (its count alone may include a status with no
            # marker and pass while the last tick's is still on its way)
            return bool(lis.stats) and status_values(lis.stats[-1])[1].get(
                "poses_used") == str(MESSAGES)

        try:
            ok = lis.spin_until(lambda: replay.poll() is not None
                                and lis.has_tick(expected[-1]) and all_used(), 60.0, proc,
                                log_path)
        finally:
            kill_node(replay)
        out = replay.stdout.read()
        assert replay.returncode == 0, out
        assert f"published {MESSAGES} messages" in out, out
        assert ok, (f"{len(lis.markers)} markers, {len(lis.stats)} stats for {MESSAGES} "
                    f"messages:\n{log_path.read_text()}")
        wall = time.monotonic() - t0

        # One marker per tick, stamped with the tick's newest pose: increasing pose stamps,
        # the dressing pose first and the last pose last. (More ticks cannot come: every
        # pose is used, and each tick uses at least one.)
        ticks = len(lis.markers)
        assert ticks <= MESSAGES
        got = stamps_ns(lis.markers)
        assert got[0] == expected[0] and got[-1] == expected[-1]
        # each topic's stamps: the ticks' poses, in order, once each (the statuses and the
        # arrays come on writers of their own, so they are compared by stamp, not by count)
        for stamps in (got, [stats_stamp_ns(a) for a in lis.stats],
                       [array_stamp_ns(a) for a in lis.arrays]):
            assert set(stamps) <= set(expected) and stamps == sorted(set(stamps))
            assert stamps[-1] == expected[-1]
        n_faces = None
        for data in lis.markers:
            m = marker_arrays_from_bytes(data)
            n_faces = len(m.points) // 3
            check_marker(data, 3 * n_faces)
        msg = deserialize(lis.markers[-1], Marker)  # rclpy's decoder agrees
        assert len(msg.points) == 3 * n_faces and msg.type == Marker.TRIANGLE_LIST
        assert msg.lifetime.sec == msg.lifetime.nanosec == 0  # marker_lifetime 0: forever
        first, last = check_marker(lis.markers[0], 3 * n_faces), check_marker(
            lis.markers[-1], 3 * n_faces)
        assert np.linalg.norm(last.mean(0) - first.mean(0)) > 0.1, "the dress did not walk"

        # The marker array: 16 capsules (cylinders), their end caps, the caption, and an
        # arrow per segment the dress pushes on (if any); the cloth is drawn once, on the
        # marker topic.
        arr = deserialize(lis.arrays[-1], MarkerArray)
        kinds = [(m.ns, m.type) for m in arr.markers if m.ns != "contact_forces"]
        assert all(m.type == Marker.ARROW for m in arr.markers if m.ns == "contact_forces")
        assert kinds == ([("avatar", Marker.CYLINDER)] * 16
                         + [("avatar_caps", Marker.SPHERE_LIST)] * 16
                         + [("caption", Marker.TEXT_VIEW_FACING)])
        for m in arr.markers[:16]:
            assert m.scale.x > 0.02 and m.scale.z > 0.0 and m.header.frame_id == "world"
        assert "particles" in arr.markers[-1].text and "ms/tick" in arr.markers[-1].text
        assert not lis.cleared, lis.cleared

        # Stats: one per tick; the first reports the dressing; solver figures present; every
        # pose received and used, the ticks' key poses adding up to all of them; no kernel
        # compiled after the warm-up.
        statuses = [status_values(a) for a in lis.stats]
        # The dressing's status (step 0), and it alone, says "dressed" (a listener behind on a
        # loaded machine can miss a status of the keep-last-5 topic, the dressing's too: the
        # node's log below has it whatever the timing)
        assert all(s.message.startswith("dressed") == (v["step"] == "0") for s, v in statuses)
        for status, values in statuses:
            assert status.level in (DiagnosticStatus.OK, DiagnosticStatus.WARN), status.message
            for key in ("step_ms", "solve_ms", "iterations", "rel_residual",
                        "max_penetration_m", "contacts", "particles", "poses_received",
                        "poses_used", "poses_coalesced", "dropped", "lag_ms", "tick_poses"):
                assert key in values
        status, values = statuses[-1]
        assert int(values["iterations"]) > 0 and float(values["solve_ms"]) > 0
        assert int(values["poses_received"]) == int(values["poses_used"]) == MESSAGES
        assert int(values["dropped"]) == 0 and int(values["poses_pending"]) == 0
        # Each tick's key poses are the ones it used: between consecutive ticks' statuses
        # poses_used grows by the later tick's tick_poses. (Only consecutive ones: the status
        # topic keeps the last 5 messages, and a listener that falls behind on a loaded
        # machine can miss one; the last status's counters above hold the total.)
        steps = [(int(v["step"]), int(v["poses_used"]), int(v["tick_poses"]))
                 for _, v in statuses]
        pairs = [(a, b) for a, b in zip(steps, steps[1:], strict=False) if b[0] == a[0] + 1]
        assert pairs and all(b[1] - a[1] == b[2] for a, b in pairs), steps
        assert 1 + sum(int(v["tick_poses"]) for _, v in statuses) <= MESSAGES
        # every tick took one pose and coalesced the rest of its run (the dressing took one)
        assert int(values["poses_coalesced"]) == MESSAGES - 1 - int(values["step"])
        assert values["kernels_compiled"] == "0", log_path.read_text()
        assert values["solver"] == "mpcg"
        assert abs(int(values["particles"]) - BODY_PARTICLES) < BODY_PARTICLES // 4
        text = stop_node(proc, log_path)
        assert f"pose frames: {MESSAGES} received, {MESSAGES} used" in text, text
        assert text.count("dressed a dress of") == 1, text
        print(f"body scene: {MESSAGES} messages in, {ticks} markers out in {wall:.1f} s")
    finally:
        kill_node(proc)


def test_run_time_parameters_are_checked_and_a_reset_re_dresses(ros_env, listener, tmp_path,
                                                                 short_bag, walk_frames):
    proc, log_path = _walking_node(ros_env, tmp_path)
    lis = listener
    expected = [round(s * 1e9) for s, _ in walk_frames]
    try:
        lis.wait_matched(proc, log_path)
        _play(lis, proc, log_path, short_bag, expected)
        ticks = len(lis.markers)
        n_points = len(marker_arrays_from_bytes(lis.markers[-1]).points)

        # Run-time parameters: invalid values rejected with the reason, valid ones applied.
        result = lis.set_parameter("tolerance", -1.0)
        assert not result.successful and "tolerance" in result.reason, result.reason
        result = lis.set_parameter("solver", "magic")
        assert not result.successful and "magic" in result.reason, result.reason
        result = lis.set_parameter("garment", "cape")
        assert not result.successful and "read-only" in result.reason, result.reason
        assert lis.set_parameter("solver", "bscg").successful
        assert lis.set_parameter("tolerance", 1e-5).successful

        # Reset: the display is cleared (DELETEALL on both marker topics), the garment is
        # re-dressed on the next pose; the same bag played again is used in full again.
        response = lis.call(lis.reset, Trigger.Request())
        assert response.success and "re-dressed" in response.message
        assert lis.spin_until(lambda: len(lis.cleared) >= 2, 20.0, proc, log_path)
        assert sorted(topic for topic, _ in lis.cleared) == ["marker", "markers"]
        _play(lis, proc, log_path, short_bag, expected)
        again = stamps_ns(lis.markers[ticks:])
        assert again[0] == expected[0] and again[-1] == expected[-1]
        for data in lis.markers[ticks:]:
            check_marker(data, n_points)
        # the statuses after the reset (one may be missed by a listener behind: keep-last-5)
        statuses = [(s, v) for s, v in map(status_values, lis.stats) if v["resets"] == "1"]
        assert sum(s.message.startswith("dressed") for s, _ in statuses) <= 1
        assert {v["solver"] for _, v in statuses} == {"bscg"}
        assert statuses[-1][1]["tolerance"] == "1.000e-05"
        assert int(statuses[-1][1]["resets"]) == 1
        assert int(statuses[-1][1]["poses_used"]) == 2 * MESSAGES
        assert int(statuses[-1][1]["dropped"]) == 0
        assert int(statuses[-1][1]["stream_restarts"]) == 0
        assert len(lis.cleared) == 2, lis.cleared  # once per reset, not again on re-dressing
        text = stop_node(proc, log_path)
        assert f"pose frames: {2 * MESSAGES} received, {2 * MESSAGES} used" in text, text
        assert "solver is now bscg" in text
        assert text.count("dressed a dress of") == 2, text  # at start and after the reset
    finally:
        kill_node(proc)


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "max_steps"])
def test_shutdown_clears_both_marker_topics_and_exits_zero(ros_env, listener, tmp_path,
                                                           short_bag, how):
    """The shutdown contract: DELETEALL on both marker topics, acknowledged by this reliable
    reader before the node exits (status 0); markers carry marker_lifetime. The bag loops
    (stamps moving on) until the node is gone, so max_steps is reached however the ticks
    coalesce."""
    import threading

    from cloth_mg_ros.ros.replay import replay_bag

    params = ["marker_lifetime:=2.5"] + (["max_steps:=5"] if how == "max_steps" else [])
    proc, log_path = _walking_node(ros_env, tmp_path, *params)
    lis = listener
    stop = threading.Event()
    thread = threading.Thread(target=lambda: replay_bag(
        short_bag, loop=True, stop=stop, context=lis.ctx, wait_s=30.0, settle_s=0.3,
        node_name="test_replay", log=lambda line: None), daemon=True)
    try:
        lis.wait_matched(proc, log_path)
        thread.start()
        if how == "max_steps":
            assert lis.spin_until(lambda: proc.poll() is not None, 120.0), log_path.read_text()
        else:
            assert lis.spin_until(lambda: len(lis.markers) >= 3, 60.0, proc, log_path)
            proc.send_signal(getattr(signal, how))  # mid-clip: a tick is likely running
        code = proc.wait(timeout=120.0)
        text = log_path.read_text()
        assert code == 0 and "Traceback" not in text, text
        assert re.search(r"shutdown: DELETEALL on \S+ and \S+ acknowledged by every "
                         r"reliable reader in \d+ ms", text), text
        # Acknowledged means this process's reader has both samples: they arrive on spinning.
        assert lis.spin_until(lambda: len(lis.cleared) >= 2, 10.0)
        assert sorted(topic for topic, _ in lis.cleared) == ["marker", "markers"]
        msg = deserialize(lis.markers[-1], Marker)
        assert (msg.lifetime.sec, msg.lifetime.nanosec) == (2, 500_000_000)
        # Every marker drawn carries the lifetime; a DELETE (of a contact arrow whose segment
        # the cloth no longer touches, in whichever tick came last) draws nothing and has none.
        arr = deserialize(lis.arrays[-1], MarkerArray)
        drawn = [m for m in arr.markers if m.action == Marker.ADD]
        assert drawn and {(m.lifetime.sec, m.lifetime.nanosec) for m in drawn} == {
            (2, 500_000_000)}
        assert all(m.action == Marker.DELETE and m.ns == ARROW_NS
                   for m in arr.markers if m.action != Marker.ADD)
    finally:
        stop.set()
        kill_node(proc)
        if thread.is_alive():
            thread.join(timeout=60.0)


def write_bad_bag(path: Path, frames: list[tuple[float, np.ndarray]]) -> tuple[int, dict]:
    """A pose bag of `frames` with bad ones mixed in. Returns (messages, {kind: count}).

    The bag's receive times advance steadily (so the replay paces it); the header stamps are
    what the node checks."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    msgs: list[tuple[int, np.ndarray]] = []
    kinds: dict[str, int] = {}
    shift = np.zeros(7)
    for k, (stamp, poses) in enumerate(frames):
        ns = round(stamp * 1e9)
        if k in (4, 9, 14):  # NaN, then an infinity, then a zero quaternion
            bad = poses.copy()
            if k == 14:
                bad[3, 3:7] = 0.0
            else:
                bad[3, k % 3] = np.nan if k == 4 else np.inf
            msgs.append((ns - 1, bad))
            kinds["non_finite"] = kinds.get("non_finite", 0) + 1
        if k == 6:
            msgs.append((ns - 1, poses[:15]))
            kinds["wrong_count"] = 1
        if k == 8:
            msgs.append((ns - 1, np.zeros((0, 7))))
            kinds["empty"] = 1
        if k == 11:
            msgs.append((round(frames[2][0] * 1e9), poses))  # a stamp from the past
            kinds["stale"] = 1
        if k == 20:  # from here on the body stands 5 m further along x: one teleport
            shift[0] = 5.0
            kinds["teleport"] = 1
        msgs.append((ns, poses + shift))
    ts = jazzy_typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/avatar/body_poses", POSE_ARRAY, typestore=ts)
        for i, (ns, poses) in enumerate(msgs):
            writer.write(conn, i * 33_333_333, pose_array_cdr(ns, poses))
    return len(msgs), kinds


def test_bad_frames_are_skipped_logged_once_and_never_reach_the_cloth(
        ros_env, listener, tmp_path, walk_frames):
    frames = walk_frames[:30]
    bag = tmp_path / "bad"
    total, kinds = write_bad_bag(bag, frames)
    skipped = sum(n for k, n in kinds.items() if k != "teleport")
    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=walking", f"particles:={BODY_PARTICLES}",
                                   RELIABLE_INPUT), ros_env, log_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        thread = replay_in_thread(bag, lis.ctx)
        last = round(frames[-1][0] * 1e9)
        ok = lis.spin_until(lambda: not thread.is_alive() and lis.has_tick(last), 60.0, proc,
                            log_path)
        assert not thread.errors, thread.errors
        assert ok, f"{len(lis.markers)} markers:\n{log_path.read_text()}"
        # Every good frame used (the re-anchoring teleport frame too), the bad ones never.
        assert len(lis.markers) <= total - skipped == len(frames)
        _, values = status_values(lis.stats[-1])
        assert int(values["poses_used"]) == len(frames) and int(values["dropped"]) == 0
        assert int(values["poses_received"]) == total
        assert int(values["frames_skipped"]) == skipped
        # The stale stamp among them never re-dressed the garment nor cleared the display.
        assert values["stream_restarts"] == "0" and values["skipped_stale"] == "1"
        assert not lis.cleared, lis.cleared
        n_points = len(marker_arrays_from_bytes(lis.markers[0]).points)
        positions = [check_marker(data, n_points) for data in lis.markers]  # never NaN
        # After the teleport the garment is carried 5 m along with the body.
        assert positions[-1][:, 0].mean() - positions[0][:, 0].mean() > 4.0
        levels = [a.status[0].level for a in lis.stats]
        assert DiagnosticStatus.ERROR not in levels
        messages = " | ".join(a.status[0].message for a in lis.stats)
        assert re.search(r"skipped since the last status: .*non_finite \d", messages), messages
        assert "re-anchored after a teleport" in messages, messages

        text = stop_node(proc, log_path)
        for kind in kinds:  # each kind is warned about exactly once ...
            first = [line for line in text.splitlines()
                     if "body pose frame" in line and f": {kind}:" in line]
            assert len(first) == 1, (kind, text)
        # ... and counted in the summary at shutdown.
        assert (f"pose frames: {total} received, {total - skipped} used (1 re-anchored after "
                f"a teleport)") in text, text
        assert "skipped 3 frames with non_finite" in text, text
        for kind in ("wrong_count", "empty", "stale"):
            assert f"skipped 1 frame with {kind}" in text, text
    finally:
        kill_node(proc)


def test_timer_mode_keeps_stepping_on_the_latest_pose(ros_env, listener, tmp_path,
                                                       walk_frames):
    frames = walk_frames[:8]
    bag = write_pose_bag(tmp_path / "walk8", np.array([s for s, _ in frames]),
                         np.stack([p for _, p in frames]))
    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=walk", "particles:=200", "tick_mode:=timer",
                                   "rate_hz:=40.0", "strain_colours:=true", RELIABLE_INPUT),
                      ros_env, log_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        thread = replay_in_thread(bag, lis.ctx)
        ok = lis.spin_until(lambda: not thread.is_alive(), 30.0, proc, log_path)
        assert ok and not thread.errors, thread.errors
        count = len(lis.markers)
        assert lis.spin_until(lambda: lis.stats, 20.0, proc, log_path)
        step = int(status_values(lis.stats[-1])[1]["step"])
        # With no more poses coming, the cloth still steps (and publishes) on the timer: the
        # step count goes on rising and the cloth goes on moving (it swings and settles).
        assert lis.spin_until(
            lambda: len(lis.markers) >= count + 10
            and int(status_values(lis.stats[-1])[1]["step"]) >= step + 10, 20.0, proc, log_path)
        assert not np.array_equal(marker_arrays_from_bytes(lis.markers[count]).points,
                                  marker_arrays_from_bytes(lis.markers[-1]).points)
        n_points = len(marker_arrays_from_bytes(lis.markers[0]).points)
        for data in lis.markers:
            check_marker(data, n_points)
            colours = marker_arrays_from_bytes(data).colors  # strain_colours: one per point
            assert colours.shape == (n_points, 4) and np.all((colours >= 0) & (colours <= 1))
        _, values = status_values(lis.stats[-1])
        assert int(values["poses_used"]) == len(frames) and int(values["dropped"]) == 0
        text = stop_node(proc, log_path)
        assert re.search(r"pose frames: 8 received, 8 used", text), text
    finally:
        kill_node(proc)
