"""cloth_node's live ingestion, over real Fast DDS on loopback (test_node.py has the node's
start, scenes, parameters and shutdown): several poses at once make one tick through all of
them, a best-effort publisher reaches the node, a publisher far faster than the node builds no
backlog and loses nothing, and the node in lock-step gives the headless runner's cloth bit
for bit. Each test run gets its own ROS_DOMAIN_ID and loopback discovery (node_harness.py,
fixtures in conftest.py).
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("visualization_msgs")
pytest.importorskip("diagnostic_msgs")
pytest.importorskip("std_srvs")

from node_harness import (
    QOS,
    RELIABLE_INPUT,
    REPO,
    Listener,
    check_marker,
    domain_id,
    kill_node,
    node_command,
    pose_array_cdr,
    stamps_ns,
    start_node,
    stats_stamp_ns,
    status_values,
    stop_node,
)
from rclpy.context import Context
from rclpy.qos import QoSProfile

from cloth_mg_ros.io.bags import read_pose_frames
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes


def test_three_poses_at_once_make_one_tick_through_all_three(walk_frames):
    """In-process: with the simulation thread held, the node receives a pose (it dresses on
    it) and then three at once; one tick advances the cloth to the newest, through all three
    as key poses, and its status says so."""
    from rclpy.parameter import Parameter

    from cloth_mg_ros.ros.node import ClothNode

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id())
    try:
        node = ClothNode(context=ctx, parameter_overrides=[Parameter("particles", value=200)])
        try:
            node.session.stop()  # hold the thread: the test drives its ticks
            published = []
            node.outputs.status = lambda fig, ms, finite, sec, nsec, values, *a: published.append(
                (sec * 10**9 + nsec, dict(values), fig))
            node.outputs.cloth = lambda *a, **k: 0.0
            frames = walk_frames[30:34]
            for k, (stamp, poses) in enumerate(frames):
                node.session.scene.ingest.offer(pose_array_cdr(round(stamp * 1e9), poses))
                if k == 0:
                    node.session.tick(node.session.scene.ingest.take())  # dress on the first
            keys = node.session.scene.ingest.take()
            assert len(keys) == 3
            node.session.tick(keys)
            (_, dressed, _), (stamp_ns, values, fig) = published
            assert dressed["substeps"] == "0"
            assert stamp_ns == round(frames[-1][0] * 1e9)
            assert node.session.scene.garment_sim.stamp == pytest.approx(frames[-1][0])
            garment_sim = node.session.scene.garment_sim
            assert np.array_equal(garment_sim.poses, frames[-1][1])
            assert values["tick_poses"] == "3" and int(values["substeps"]) >= 1
            assert float(values["simulated_ms"]) == pytest.approx(
                1e3 * (frames[-1][0] - frames[0][0]), abs=1e-3)
            assert (values["poses_received"], values["poses_used"], values["poses_coalesced"],
                    values["dropped"], values["poses_pending"]) == ("4", "4", "2", "0", "0")
            assert np.all(np.isfinite(garment_sim.positions)) and fig.iterations > 0
            assert garment_sim.max_penetration() < 0.005
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def _publisher(lis: Listener, qos: QoSProfile):
    from geometry_msgs.msg import PoseArray

    return lis.node.create_publisher(PoseArray, "/avatar/body_poses", qos)


def test_a_best_effort_publisher_reaches_the_node(ros_env, listener, tmp_path, walk_frames):
    """A sensor-data (best-effort) publisher is matched by the node's default best-effort
    subscription and drives the cloth; a node asked for a reliable subscription would not
    match it at all (the reason best_effort is the default)."""
    from rclpy.qos import qos_profile_sensor_data

    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=walking", "particles:=200"), ros_env, log_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        pub = _publisher(lis, qos_profile_sensor_data)
        assert lis.spin_until(lambda: pub.get_subscription_count() >= 1, 30.0, proc, log_path)
        frames = walk_frames[:10]
        lis.publish_until_seen(pub, pose_array_cdr(round(frames[0][0] * 1e9), frames[0][1]),
                               proc, log_path)
        for stamp, poses in frames[1:-1]:
            pub.publish(pose_array_cdr(round(stamp * 1e9), poses))
            lis.spin_until(lambda: False, 1.0 / 30.0)
        last = round(frames[-1][0] * 1e9)
        # best effort may drop any sample: the last is sent again until its tick is out (a
        # repeat is skipped as a stale frame, which the counts below allow for)
        lis.publish_until_seen(pub, pose_array_cdr(last, frames[-1][1]), proc, log_path, 30.0,
                               seen=lambda: lis.has_tick(last))
        _, values = status_values(lis.stats[-1])
        used, skipped = int(values["poses_used"]), int(values["frames_skipped"])
        # every pose received is used or skipped as a repeat, but for a repeat sent while the
        # last tick ran: received, not yet taken when its status was written (a fresh-clone
        # run read 10 used + 1 skipped of 12 received)
        pending = int(values["poses_pending"])
        assert used >= 2 and used + skipped + pending == int(values["poses_received"])
        assert int(values["dropped"]) == 0
        stop_node(proc, log_path)
    finally:
        kill_node(proc)
    # A reliable subscription does not match a best-effort publisher.
    log_path = tmp_path / "node_reliable.log"
    proc = start_node(node_command("scene:=walking", "particles:=200",
                                   "input_reliability:=reliable"), ros_env, log_path)
    try:
        lis.wait_matched(proc, log_path)
        # a best-effort publisher made now hears of the node's reliable subscription as an
        # incompatible QoS (the middleware's own verdict, not a match that is slow to come)
        from geometry_msgs.msg import PoseArray
        from rclpy.event_handler import PublisherEventCallbacks

        refused = []
        late = lis.node.create_publisher(
            PoseArray, "/avatar/body_poses", qos_profile_sensor_data,
            event_callbacks=PublisherEventCallbacks(incompatible_qos=refused.append))
        assert lis.spin_until(lambda: refused, 30.0, proc, log_path)
        assert late.get_subscription_count() == 0
        stop_node(proc, log_path)
    finally:
        kill_node(proc)


def _fast_frames(walk_frames: list, per_interval: int) -> list[tuple[float, np.ndarray]]:
    """The walk's poses at `per_interval` times its rate (blended between its frames)."""
    from cloth_mg_ros.sim.body_poses import blend_poses

    out = []
    for (s0, p0), (s1, p1) in itertools.pairwise(walk_frames):
        for k in range(per_interval):
            u = k / per_interval
            out.append((s0 + u * (s1 - s0), blend_poses(p0, p1, u)))
    return out


def test_a_publisher_far_faster_than_the_node_builds_no_backlog_and_loses_nothing(
        ros_env, listener, tmp_path, walk_frames):
    """Poses at 450 Hz (the walk blended 15 times finer) into a small garment, sent as a
    burst of 15 every 1/30 s: the node coalesces whatever arrived during a tick into the
    next, uses every pose, drops none, and its last tick reaches the last pose. (Bursts, not
    a pose every 2.2 ms: a machine that ticks this garment in under 2.2 ms would coalesce
    nothing, and the test would measure the machine.)"""
    frames = _fast_frames(walk_frames[:21], 15)  # 300 poses
    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=walking", "particles:=150",
                                   "input_reliability:=reliable"), ros_env, log_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        pub = _publisher(lis, QOS)
        assert lis.spin_until(lambda: pub.get_subscription_count() >= 1, 30.0, proc, log_path)
        t0 = time.monotonic()
        for k, (stamp, poses) in enumerate(frames):
            pub.publish(pose_array_cdr(round(stamp * 1e9), poses))
            if k % 15 == 14:  # pacing the publisher, not waiting for a condition
                delay = t0 + (k + 1) / 450.0 - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                lis.executor.spin_once(timeout_sec=0.0)
        last = round(frames[-1][0] * 1e9)
        ok = lis.spin_until(lambda: lis.markers and stamps_ns(lis.markers[-1:]) == [last]
                            and lis.stats and stats_stamp_ns(lis.stats[-1]) == last, 60.0,
                            proc, log_path)
        statuses = [status_values(a)[1] for a in lis.stats]
        assert ok, (f"{len(lis.markers)} markers, last status {statuses[-1:]}:\n"
                    f"{log_path.read_text()}")
        values = statuses[-1]
        assert int(values["poses_received"]) == int(values["poses_used"]) == len(frames)
        assert int(values["dropped"]) == 0 and int(values["poses_pending"]) == 0
        # Each tick used its newest pose and coalesced the others that had arrived: far
        # fewer ticks than poses, none queued. (The node's own counters: this test's
        # subscriptions may miss statuses while it is busy publishing.)
        ticks = int(values["step"])
        assert int(values["poses_used"]) == 1 + ticks + int(values["poses_coalesced"])
        # A burst's 15 poses arrive within about a millisecond, less than any tick takes, so
        # some tick took several: a node that ticked once per pose would coalesce none.
        assert int(values["poses_coalesced"]) > 0 and ticks < len(frames) - 1, values
        for data in lis.markers:
            check_marker(data, len(marker_arrays_from_bytes(lis.markers[0]).points))
        stop_node(proc, log_path)
    finally:
        kill_node(proc)


LOCK_STEP_THREADS = 2  # the node's and the runner's (the cloth depends on it, bit for bit)


def _lock_step_run(lis: Listener, ros_env, log_path: Path, frames) -> np.ndarray:
    """Start the walking node (300 particles), feed it `frames` one at a time (each marker
    awaited before the next pose), stop it; returns the last marker's points (3 t, 3)."""
    # the level of detail off: the runner has none, and a loaded machine may step the node down
    proc = start_node(node_command("particles:=300", "tolerance:=1e-4", "lod:=false",
                                   f"threads:={LOCK_STEP_THREADS}", RELIABLE_INPUT,
                                   params_file=str(REPO / "config" / "walking.yaml")),
                      ros_env, log_path)
    try:
        lis.wait_matched(proc, log_path)
        pub = _publisher(lis, QOS)
        assert lis.spin_until(lambda: pub.get_subscription_count() >= 1, 30.0, proc, log_path)
        lis.markers.clear()
        for stamp, poses in frames:
            ns = round(stamp * 1e9)
            pub.publish(pose_array_cdr(ns, poses))
            assert lis.spin_until(lambda ns=ns: lis.markers and stamps_ns(lis.markers[-1:])
                                  == [ns], 60.0, proc, log_path), log_path.read_text()
        assert len(lis.markers) == len(frames)  # one tick per pose: nothing coalesced
        points = marker_arrays_from_bytes(lis.markers[-1]).points.copy()
        stop_node(proc, log_path)
        lis.node.destroy_publisher(pub)
        return points
    finally:
        kill_node(proc)


def test_node_in_lock_step_gives_bit_identical_cloth_to_the_headless_runner(
        ros_env, listener, tmp_path, short_bag):
    """Fed one pose at a time, the node computes exactly what the headless runner computes on
    the same bag, scene, solver and thread count, run after run (float64 positions, bit for
    bit)."""
    from cloth_mg_ros.apps.runner import run_body_scene
    from cloth_mg_ros.config.scenes import load_scene
    from cloth_mg_ros.io.messages.markers import triangle_corners

    frames = read_pose_frames(short_bag)[:16]
    params = load_scene("walking").replace(particles=300, bag=str(short_bag),
                                           threads=LOCK_STEP_THREADS, tolerance=1e-4)
    run_body_scene(params, tmp_path / "run", steps=len(frames) - 1, progress=False)
    saved = np.load(tmp_path / "run" / "positions.npz")
    reference = triangle_corners(saved["final"], saved["faces"])
    first = _lock_step_run(listener, ros_env, tmp_path / "node1.log", frames)
    second = _lock_step_run(listener, ros_env, tmp_path / "node2.log", frames)
    assert np.array_equal(first, second)
    assert np.array_equal(first, reference)
