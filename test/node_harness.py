"""What the cloth_node tests share: a listener on the node's outputs, starting and stopping
the node as a subprocess, and readers of its messages (the fixtures are in conftest.py).

Each test gets a ROS_DOMAIN_ID of its own (`next_domain_id`: from the pid, then the next one
for each test, within 1..100, each claimed by a file lock so that no other run on the machine
has it: `processes.claim_domain_id`) and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, so parallel
runs on one machine do not hear each other and a test never hears a node of the test before
it.
"""

from __future__ import annotations

import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.io.bags import POSE_ARRAY, jazzy_typestore
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.ros import processes
from cloth_mg_ros.ros.message_reference import deserialize

REPO = Path(__file__).resolve().parents[1]
DOMAIN_ID = processes.claim_domain_id(1, 100)  # in-process tests that start no node
KEEP_DOMAINS = 20  # the tests' domains this run holds at once (a node 20 tests back is gone)
_HELD: list[int] = []


def next_domain_id() -> int:
    """A domain in 1..100 that no other run on the machine holds and that none of the last
    KEEP_DOMAINS tests of this run used, starting after the last one."""
    domain = processes.claim_domain_id(1, 100, (_HELD or [DOMAIN_ID])[-1] + 1)
    _HELD.append(domain)
    if len(_HELD) > KEEP_DOMAINS:
        processes.release_domain_id(_HELD.pop(0))
    return domain


def domain_id() -> int:
    """This test's domain: ROS_DOMAIN_ID (set by the ros_env fixture), else DOMAIN_ID."""
    return int(os.environ.get("ROS_DOMAIN_ID", DOMAIN_ID))
PARTICLES = 300
BODY_PARTICLES = 400
MESSAGES = 40  # pose messages replayed from the walk bag
# discovery, a possible numba compile on the first step and, for a scene with particles or
# tolerance auto and an empty cost-model cache, the calibration (40-50 s on a quiet 2-core
# machine, 121 s with two other jobs on its cores): a deadline for the node's topics to
# appear, waited for by spinning, not a sleep, so a generous one costs a passing test nothing
START_TIMEOUT_S = 600.0
# Keep-all: a reliable writer then never overwrites a sample its reader has not acknowledged
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL)
# The node's input made reliable, for the tests that assert every pose is used: its default
# best-effort reader drops a sample that arrives before the reader's side of discovery has
# matched the writer, and a replay can only wait for the writer's side (a reliable writer
# sends the sample again once the reader asks). test_node's best-effort test covers the
# default subscription.
RELIABLE_INPUT = "input_reliability:=reliable"


def node_command(*params: str, params_file: str | None = None) -> list[str]:
    """`python -m cloth_mg_ros.ros.node --ros-args [--params-file F] -p ...` (the package's
    own `ros.processes.node_command`)."""
    return processes.node_command(params, params_file)


class Listener:
    """The test's side: an rclpy context with raw subscriptions to the node's outputs, a
    reset client and a set-parameters client, all under namespace `ns` ('' or '/alice').
    Spin with `spin_until`."""

    def __init__(self, ns: str = "") -> None:
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain_id())
        self.node = rclpy.create_node("cloth_node_test", context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.markers: list[bytes] = []  # cloth markers (ADD)
        self.arrays: list[bytes] = []  # body marker arrays (ADD)
        self.cleared: list[tuple[str, int]] = []  # (topic, stamp ns) of each DELETEALL
        self.stats: list[DiagnosticArray] = []
        self.subs = [
            self.node.create_subscription(Marker, f"{ns}/cloth/marker", self._on_marker, QOS,
                                          raw=True),
            self.node.create_subscription(MarkerArray, f"{ns}/cloth/markers", self._on_array,
                                          QOS, raw=True),
            self.node.create_subscription(DiagnosticArray, f"{ns}/cloth/stats",
                                          self.stats.append, QOS),
        ]
        self.reset = self.node.create_client(Trigger, f"{ns}/cloth_node/reset")
        self.set_params = self.node.create_client(SetParameters,
                                                  f"{ns}/cloth_node/set_parameters")

    def _on_marker(self, data: bytes) -> None:
        m = marker_arrays_from_bytes(data)
        if m.action == Marker.DELETEALL:
            self.cleared.append(("marker", m.stamp_sec * 1_000_000_000 + m.stamp_nanosec))
        else:
            self.markers.append(data)

    def _on_array(self, data: bytes) -> None:
        arr = deserialize(data, MarkerArray)
        if [m.action for m in arr.markers] == [Marker.DELETEALL]:
            stamp = arr.markers[0].header.stamp
            self.cleared.append(("markers", stamp.sec * 1_000_000_000 + stamp.nanosec))
        else:
            self.arrays.append(data)

    def spin_until(self, done, timeout: float, proc: subprocess.Popen | None = None,
                   log: Path | None = None) -> bool:
        """Spin until done() or timeout (s); fail if `proc` (the node) exits meanwhile."""
        deadline = time.monotonic() + timeout
        while not done():
            if proc is not None and proc.poll() is not None:
                pytest.fail(f"node exited early ({proc.returncode}):\n"
                            f"{log.read_text() if log else ''}")
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def has_tick(self, stamp_ns: int) -> bool:
        """Whether the newest marker, status and marker array are all the tick's of stamp
        `stamp_ns`: the three topics have writers of their own, with no order between them,
        and each keeps its last 5 messages, so a listener that fell behind may have missed
        one; a wait on the last tick's own messages holds whatever the timing, where a wait
        on their counts may never hold."""
        return bool(self.markers and self.stats and self.arrays) \
            and stamps_ns(self.markers[-1:]) == [stamp_ns] \
            and stats_stamp_ns(self.stats[-1]) == stamp_ns \
            and array_stamp_ns(self.arrays[-1]) == stamp_ns

    def wait_matched(self, proc, log, timeout: float = START_TIMEOUT_S) -> None:
        """Until every subscription and both services see the node."""
        ok = self.spin_until(lambda: all(s.get_publisher_count() for s in self.subs)
                             and self.reset.service_is_ready()
                             and self.set_params.service_is_ready(), timeout, proc, log)
        assert ok, f"the node's topics and services did not appear:\n{log.read_text()}"

    def publish_until_seen(self, pub, data: bytes, proc, log: Path,
                           timeout: float = START_TIMEOUT_S, seen=None) -> None:
        """Publish `data` (a pose) every 0.5 s until seen() (default: the node has published
        a status, so it dressed on it): a sample written before the node's reader has matched
        the writer is not delivered, on a loaded machine discovery's second half can take
        seconds, and best effort may drop any sample. A repeat of a stamp is skipped by the
        node as stale (counted)."""
        seen = seen or (lambda: bool(self.stats))
        deadline = time.monotonic() + timeout
        while not seen():
            assert time.monotonic() < deadline, f"not seen after {timeout:g} s:\n" \
                f"{log.read_text()}"
            pub.publish(data)
            self.spin_until(seen, 0.5, proc, log)

    def call(self, client, request, timeout: float = 20.0):
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout), "no service response"
        return future.result()

    def set_parameter(self, name: str, value) -> object:
        """SetParameters with one parameter; returns its SetParametersResult."""
        kind, field = {float: (ParameterType.PARAMETER_DOUBLE, "double_value"),
                       str: (ParameterType.PARAMETER_STRING, "string_value")}[type(value)]
        pv = ParameterValue(type=kind, **{field: value})
        req = SetParameters.Request(parameters=[ParameterMsg(name=name, value=pv)])
        (result,) = self.call(self.set_params, req).results
        return result

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


STOP_TIMEOUT_S = 60.0


def start_node(cmd: list[str], env: dict, log_path: Path) -> subprocess.Popen:
    """The node command as a child process in the repository, its output in `log_path`."""
    return processes.start_process(cmd, env, log_path, cwd=REPO)


def stop_node(proc: subprocess.Popen, log_path: Path) -> str:
    """SIGINT, expect exit 0 and no traceback; returns the log.

    The wait is a guard against a hang, not a speed check: with cold numba caches on a loaded
    CI machine the step in progress when the signal arrives can take well over 15 s (seen
    once in a fresh-clone run), and the node only exits after it."""
    code = processes.stop_process(proc, STOP_TIMEOUT_S)
    text = log_path.read_text()
    assert code == 0, text
    assert "Traceback" not in text, text
    return text


kill_node = processes.kill_process


def status_values(arr: DiagnosticArray) -> tuple[DiagnosticStatus, dict[str, str]]:
    (status,) = arr.status
    return status, {kv.key: kv.value for kv in status.values}


def check_marker(data: bytes, n_points: int, frame_id: str = "world") -> np.ndarray:
    """A valid cloth TRIANGLE_LIST in frame_id with n_points finite points; returns them
    (k, 3)."""
    assert isinstance(data, bytes)
    m = marker_arrays_from_bytes(data)
    assert (m.marker_type, m.action, m.ns, m.marker_id) == (Marker.TRIANGLE_LIST, Marker.ADD,
                                                            "cloth", 0)
    assert m.frame_id == frame_id
    assert m.points.shape == (n_points, 3)
    assert np.isfinite(m.points).all()
    return m.points


def stats_stamp_ns(arr: DiagnosticArray) -> int:
    return arr.header.stamp.sec * 1_000_000_000 + arr.header.stamp.nanosec


def array_stamp_ns(data: bytes) -> int:
    """The stamp (ns) of a serialised MarkerArray: its first marker's."""
    stamp = deserialize(data, MarkerArray).markers[0].header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def stamps_ns(markers: list[bytes]) -> list[int]:
    out = []
    for data in markers:
        m = marker_arrays_from_bytes(data)
        out.append(m.stamp_sec * 1_000_000_000 + m.stamp_nanosec)
    return out


def replay_in_thread(bag: Path, ctx: Context) -> threading.Thread:
    from cloth_mg_ros.ros.replay import replay_bag

    errors: list[BaseException] = []

    def run() -> None:
        try:
            replay_bag(bag, context=ctx, wait_s=30.0, settle_s=0.3, node_name="test_replay",
                       log=lambda line: None)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.errors = errors
    thread.start()
    return thread


def pose_array_cdr(stamp_ns: int, poses: np.ndarray, frame_id: str = "world") -> bytes:
    """A PoseArray's CDR bytes, any values (NaN too), via the rosbags type store."""
    ts = jazzy_typestore()
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Pose, Point, Quat = (T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/Point"],
                         T["geometry_msgs/msg/Quaternion"])
    msg = T[POSE_ARRAY](
        header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                      frame_id=frame_id),
        poses=[Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    orientation=Quat(x=float(p[3]), y=float(p[4]), z=float(p[5]),
                                     w=float(p[6]))) for p in poses])
    return bytes(ts.serialize_cdr(msg, POSE_ARRAY))
