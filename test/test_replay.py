"""`cloth-mg replay` and `cloth-mg record` over real Fast DDS on loopback (see test_node.py
for the environment: own ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("geometry_msgs")
pytest.importorskip("visualization_msgs")

from geometry_msgs.msg import PoseArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from visualization_msgs.msg import Marker

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.io.bags import bag_info, bundled_bag, jazzy_typestore, read_pose_frames
from cloth_mg_ros.io.bags import write_pose_bag as write_bag
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.ros.ingest import pose_array_from_cdr
from cloth_mg_ros.ros.processes import claim_domain_id
from cloth_mg_ros.ros.replay import replay_bag

REPO = Path(__file__).resolve().parents[1]
# not test_node.py's domains, test_domain_claims' (180-182) or another run's
DOMAIN_ID = claim_domain_id(101, 79)
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                 depth=100)
TOPIC = "/avatar/body_poses"


@pytest.fixture
def ros(ros_env):
    """(context, node, executor) of the test's own side."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    node = rclpy.create_node("replay_test", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    yield ctx, node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


@pytest.fixture(scope="module")
def frames() -> list[tuple[float, np.ndarray]]:
    return read_pose_frames(bundled_bag("walk"))[:40]


def short_bag(path: Path, frames) -> Path:
    return write_bag(path, np.array([s for s, _ in frames]), np.stack([p for _, p in frames]))


def spin_until(executor, done, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not done():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.02)
    return True


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "cloth_mg_ros.cli.main", *args]


def test_replay_publishes_every_message_unchanged_paced_by_stamps(ros, ros_env, tmp_path,
                                                                  frames):
    _, node, executor = ros
    # 80 messages (the 40 frames twice, the second pass 40 intervals later): long enough that
    # a stall of the replay process, after which it catches up with its schedule, touches few
    # of them
    step = frames[1][0] - frames[0][0]
    shift = len(frames) * step
    messages = list(frames) + [(t + shift, p) for t, p in frames]
    bag = short_bag(tmp_path / "walk80", messages)
    got: list[tuple[float, bytes]] = []
    # each message with the time its publisher wrote it (DDS source timestamp, ns): the
    # pacing is the replay's, whenever this loaded process got round to taking it
    node.create_subscription(
        PoseArray, TOPIC, lambda d, info: got.append((1e-9 * info["source_timestamp"], d)),
        QOS, raw=True)
    proc = subprocess.Popen(cli("replay", str(bag), "--rate", "2", "--settle", "0.3"),
                            env=ros_env, cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert spin_until(executor, lambda: proc.poll() is not None and len(got) >= 80, 60)
    finally:
        if proc.poll() is None:
            proc.kill()
        out = proc.communicate()[0]
    assert proc.returncode == 0, out
    spin_until(executor, lambda: False, 0.3)
    assert len(got) == len(messages), out
    for (_, data), (stamp, poses) in zip(got, messages, strict=True):
        sec, nanosec, frame_id, decoded = pose_array_from_cdr(data)
        assert sec * 1_000_000_000 + nanosec == round(stamp * 1e9)
        assert frame_id == "world"
        assert np.array_equal(decoded, poses)
    # Paced at rate 2 by the stamps: 1/60 s between messages, 79 intervals about 1.32 s, by
    # the times the replay published them. The replay keeps to its schedule, so after a
    # stall it publishes the messages that came due at once and is back on time: the median
    # interval and half the span hold whatever a stall shorter than about 0.6 s does (the
    # span alone lost 0.13 s to one on a loaded machine); a replay that ignored the stamps,
    # or ran faster than the rate, fails both.
    published = np.array([t for t, _ in got])
    interval = step / 2.0
    assert np.median(np.diff(published)) > 0.8 * interval, np.diff(published)
    span = published[-1] - published[0]
    expected = (messages[-1][0] - messages[0][0]) / 2.0
    assert span > 0.5 * expected, (span, expected)


def test_replay_loop_moves_header_stamps_on(ros, tmp_path, frames):
    ctx, node, executor = ros
    bag = short_bag(tmp_path / "walk10", frames[:10])
    got: list[bytes] = []
    node.create_subscription(PoseArray, TOPIC, got.append, QOS, raw=True)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(stats=replay_bag(
        bag, rate=4.0, loop=True, max_loops=3, context=ctx, settle_s=0.2, wait_s=20,
        log=lambda line: None)), daemon=True)
    thread.start()
    assert spin_until(executor, lambda: not thread.is_alive() and len(got) >= 30, 30)
    stats = result["stats"]
    assert stats.messages == 30 and stats.loops == 3
    stamps = [s + 1e-9 * n for s, n, _, _ in map(pose_array_from_cdr, got)]
    assert len(got) == 30 and np.all(np.diff(stamps) > 0), stamps
    period = frames[1][0] - frames[0][0]
    assert stamps[10] == pytest.approx(stamps[9] + period, abs=1e-6)
    assert stamps[20] == pytest.approx(stamps[0] + 2 * 10 * period, abs=1e-6)


def test_replay_paces_each_pass_at_its_own_rate(ros, tmp_path, frames):
    """rate=[4, 1]: the first pass at 4x, the second at the bag's own pace (a stream that
    slows down); stamps move on as with one rate."""
    ctx, node, executor = ros
    bag = short_bag(tmp_path / "walk10", frames[:10])
    got: list[tuple[float, bytes]] = []
    # each message with the time its publisher wrote it (DDS source timestamp, ns), not the
    # time this process got round to taking it
    node.create_subscription(
        PoseArray, TOPIC, lambda d, info: got.append((1e-9 * info["source_timestamp"], d)),
        QOS, raw=True)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(stats=replay_bag(
        bag, rate=[4.0, 1.0], loop=True, max_loops=2, context=ctx, settle_s=0.2, wait_s=20,
        log=lambda line: None)), daemon=True)
    thread.start()
    assert spin_until(executor, lambda: not thread.is_alive() and len(got) >= 20, 30)
    assert result["stats"].messages == 20 and result["stats"].loops == 2
    period = frames[1][0] - frames[0][0]
    # Never faster than asked (a slow machine may take longer; a stall only delays): the
    # replay publishes each message at or after its time on a schedule that starts when the
    # first is due, so the 20th comes at least the first pass's 9 intervals at rate 4 and
    # the second's 9 at rate 1 after that, and the first went out at most the replay's
    # measured lateness after it (opening the bag delays it: once 4 ms on a loaded machine,
    # which a bound from the first's own time failed by 0.3 ms); and the second pass, on a
    # schedule of its own from its first message, takes rate 1's 9 intervals (a median of
    # its intervals would not hold: after a stall the replay catches up back to back).
    published = np.array([t for t, _ in got])
    late = result["stats"].max_late_s
    assert published[19] - published[0] >= 0.99 * 9 * period * (1.0 + 1.0 / 4.0) - late, \
        (published, late)
    assert published[19] - published[10] >= 0.99 * 9 * period - late, (published, late)
    stamps = [s + 1e-9 * n for s, n, _, _ in (pose_array_from_cdr(d) for _, d in got)]
    assert np.all(np.diff(stamps) > 0)


def test_topic_out_publishes_the_bag_on_the_nodes_topic(ros, tmp_path, frames):
    """A relative --topic-out goes under --namespace (as the node's relative topic does); the
    bag's own topic gets nothing."""
    ctx, node, executor = ros
    bag = short_bag(tmp_path / "walk5", frames[:5])
    moved: list[bytes] = []
    own: list[bytes] = []
    node.create_subscription(PoseArray, "/alice/mocap/poses", moved.append, QOS, raw=True)
    node.create_subscription(PoseArray, "/alice/avatar/body_poses", own.append, QOS, raw=True)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(stats=replay_bag(
        bag, context=ctx, settle_s=0.2, wait_s=20, namespace="alice",
        topic_out="mocap/poses", log=lambda line: None)), daemon=True)
    thread.start()
    assert spin_until(executor, lambda: not thread.is_alive() and len(moved) >= 5, 30)
    # an absence: what the replay sent to the other topic would have come with the rest
    spin_until(executor, lambda: False, 0.2)
    assert result["stats"].messages == 5 and not own


@pytest.mark.parametrize("topic", ["1poses", "a b", "mocap//poses"])
def test_a_bad_topic_out_is_named(ros_env, capsys, topic):
    assert main(["replay", "walk", "--topic-out", topic, "--wait", "0"]) == 2
    assert "--topic-out" in capsys.readouterr().err


def test_replay_namespace_and_clock(ros, tmp_path, frames):
    """--namespace moves every topic under it (as `-r __ns:=` moves the node's); --clock
    publishes the bag's time on the global /clock before each message, loops included."""
    from rosgraph_msgs.msg import Clock

    ctx, node, executor = ros
    bag = short_bag(tmp_path / "walk5", frames[:5])
    got: list[bytes] = []
    clock: list[int] = []
    global_poses: list[bytes] = []
    node.create_subscription(PoseArray, "/alice" + TOPIC, got.append, QOS, raw=True)
    node.create_subscription(PoseArray, TOPIC, global_poses.append, QOS, raw=True)
    node.create_subscription(Clock, "/clock", lambda m: clock.append(
        m.clock.sec * 1_000_000_000 + m.clock.nanosec), QOS)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(stats=replay_bag(
        bag, rate=4.0, loop=True, max_loops=2, context=ctx, settle_s=0.2, wait_s=20,
        clock=True, namespace="alice/", log=lambda line: None)), daemon=True)
    thread.start()
    assert spin_until(executor, lambda: not thread.is_alive() and len(got) >= 10
                      and len(clock) >= 10, 30)
    spin_until(executor, lambda: False, 0.2)
    assert result["stats"].messages == 10 and not global_poses
    stamps = [s * 1_000_000_000 + n for s, n, _, _ in map(pose_array_from_cdr, got)]
    assert clock == stamps  # each message's own time, just before it; on across the loop
    assert np.all(np.diff(clock) > 0)


@pytest.mark.parametrize("namespace", ["1abc", "a b", "/x//y"])
def test_replay_rejects_a_bad_namespace(ros_env, capsys, namespace):
    assert main(["replay", "walk", "--namespace", namespace, "--wait", "0"]) == 2
    assert "--namespace" in capsys.readouterr().err


def test_replay_gives_up_without_a_subscriber(ros_env, capsys):
    code = main(["replay", "walk", "--wait", "1"])
    assert code == 2
    assert "no subscriber matched" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "message"), [
    (["no/such/bag"], "no such bag"),
    (["walk", "--topic", "/nothing"], "/avatar/body_poses [geometry_msgs/msg/PoseArray]"),
    (["walk", "--rate", "0"], "--rate"),
])
def test_replay_bad_input_names_the_problem(ros_env, capsys, args, message):
    assert main(["replay", *args]) == 2
    assert message in capsys.readouterr().err


def test_record_captures_markers_into_an_mcap_bag(ros, ros_env, tmp_path):
    _, node, executor = ros
    log_path = tmp_path / "node.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "cloth_mg_ros.ros.node", "--ros-args", "-p", "scene:=drape",
             "-p", "particles:=100", "-p", "rate_hz:=30.0"],
            env=ros_env, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
    recorders = []
    try:
        seen: list[bytes] = []
        node.create_subscription(Marker, "/cloth/marker", seen.append, QOS, raw=True)
        assert spin_until(executor, lambda: len(seen) >= 3, 60), log_path.read_text()
        timed, stopped = tmp_path / "timed", tmp_path / "stopped"
        recorders = [
            subprocess.Popen(cli("record", str(timed), "--topics", "/cloth/marker",
                                 "/cloth/stats", "--duration", "6"),
                             env=ros_env, cwd=REPO, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True),
            subprocess.Popen(cli("record", str(stopped), "--topics", "/cloth/marker",
                                 "/not/published"),
                             env=ros_env, cwd=REPO, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True),
        ]
        outs = [r.communicate(timeout=30)[0] if i == 0 else "" for i, r in
                enumerate(recorders)]
        assert recorders[0].returncode == 0, outs[0]
        recorders[1].send_signal(signal.SIGINT)  # the other one stops on Ctrl-C
        outs[1] = recorders[1].communicate(timeout=15)[0]
        assert recorders[1].returncode == 0, outs[1]
        assert "never seen: /not/published" in outs[1], outs[1]
    finally:
        for r in recorders:
            if r.poll() is None:
                r.kill()
                r.wait()
        proc.send_signal(signal.SIGINT)
        # as long as node_harness allows a node to stop: the tick in progress ends first,
        # and with a cold numba cache a step takes well over 15 s
        proc.wait(timeout=60)

    info = bag_info(timed)  # metadata.yaml written, rosbags reads it back
    assert info["storage"] == "mcap"
    assert info["topics"]["/cloth/marker"]["type"] == "visualization_msgs/msg/Marker"
    n_markers = info["topics"]["/cloth/marker"]["count"]
    # How many arrive in the 6 s window (30 Hz less the command's start-up and discovery)
    # depends on the machine's load; both topics must be there, the markers at least twice
    # (the node was publishing before the recorder started) so that their order and rate
    # are checked. The recorder stamps on receipt, so its reported rate depends on delivery
    # timing: only check it is a rate.
    assert n_markers >= 2 and info["topics"]["/cloth/stats"]["count"] >= 1, info
    assert info["topics"]["/cloth/marker"]["rate_hz"] > 0.0, info
    ts = jazzy_typestore()
    with Reader(timed) as reader:
        times, stamps = [], []
        for conn, t, raw in reader.messages():
            if conn.topic == "/cloth/marker":
                m = marker_arrays_from_bytes(raw)
                assert m.marker_type == Marker.TRIANGLE_LIST and np.isfinite(m.points).all()
                assert len(m.points) > 0
                times.append(t)
                stamps.append(m.stamp_sec + 1e-9 * m.stamp_nanosec)
            else:
                msg = ts.deserialize_cdr(raw, conn.msgtype)
                assert msg.status[0].name == "cloth_node: solver"
    assert len(times) == n_markers and times == sorted(times) and np.all(np.diff(stamps) > 0)
    assert bag_info(stopped)["topics"]["/cloth/marker"]["count"] > 0
