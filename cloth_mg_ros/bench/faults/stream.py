"""The live side of `cloth-mg bench faults`: poses published from this process, paced in wall
time, and raw subscriptions to what cloth_node sends back; CPU hogs.

- `pose_array_cdr`: a PoseArray's CDR bytes for any values (NaN, no poses, any count);
- `marker_array_clear_stamp`: the stamp of a MarkerArray that is one DELETEALL (else None),
  read from the bytes without decoding the whole array;
- `PoseSource`: body poses without end: the walk bag's frames played forward and back
  (a loop that wraps would jump the body from the clip's end to its start: a teleport in
  every pass), stamped `start + k / rate` on a time line that can start over;
- `FaultStream`: a publisher of raw PoseArray bytes on this process's RosSide, the record of
  every message sent (`figures.Sent`), and a `Recorder` of /cloth/marker, /cloth/markers and
  /cloth/stats; `run` publishes at the pose rate while it spins, `drain` waits until the
  node has simulated everything sent;
- `cpu_hogs`: busy-loop processes, each bounded in time by itself and killed on leaving.
"""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from cloth_mg_ros.bench.faults.figures import VALID_KINDS, Clear, Sent, Tick
from cloth_mg_ros.io.messages.cdr import CdrReader, CdrWriter
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.ros.message_reference import deserialize
from cloth_mg_ros.ros.processes import MARKER_TOPIC, STATS_TOPIC
from cloth_mg_ros.ros.replay import reliable_qos

__all__ = [
    "DELETEALL",
    "FaultStream",
    "PoseSource",
    "Recorder",
    "cpu_hogs",
    "marker_array_clear_stamp",
    "pose_array_cdr",
]

DELETEALL = 3  # visualization_msgs/Marker action
RATE_HZ = 30.0  # the pose stream's rate (the walk bag's), Hz
DRAIN_TIMEOUT_S = 60.0  # the node simulates what was sent within this (a slow machine), s
MARKERS_TOPIC = "/cloth/markers"
# A hog stops by itself at its deadline, even were the benchmark killed before its cleanup.
HOG_CODE = "import time\nend = time.monotonic() + {s!r}\nwhile time.monotonic() < end:\n    pass\n"


def pose_array_cdr(stamp_ns: int, poses: np.ndarray, frame_id: str = "world") -> bytes:
    """A geometry_msgs/PoseArray's CDR bytes (little-endian, what rclpy publishes raw):
    header.stamp from `stamp_ns` (ns), frame_id, then poses (k, 7) [x, y, z, qx, qy, qz, qw]
    (m, unit quaternion) as they are, NaN or empty included."""
    w = CdrWriter()
    w.pack("iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000, align=4)
    w.string(frame_id)
    arr = np.asarray(poses, dtype="<f8").reshape(-1, 7)
    w.uint32(len(arr))
    w.array(arr, align=8)
    return w.getvalue()


def marker_array_clear_stamp(data: bytes | memoryview) -> int | None:
    """The header stamp (ns) of a serialised MarkerArray that is one DELETEALL marker, else
    None. Reads the count and the first marker's header, ns, id, type and action only (a
    drawn array holds a capsule per body segment: decoding each would cost more)."""
    r = CdrReader(data)
    if r.uint32() != 1:
        return None
    sec, nanosec = r.unpack("iI", 4)
    r.string()  # frame_id
    r.string()  # ns
    _, _, action = r.unpack("iii", 4)
    return sec * 1_000_000_000 + nanosec if action == DELETEALL else None


class PoseSource:
    """Body poses for as long as wanted: `frames` (each (S, 7)) forward, then back, and so
    on, so that the body never jumps; stamps `start_ns + k / rate_hz` on the current time line
    (`epoch`), k counting its poses."""

    def __init__(self, frames: list[np.ndarray], start_ns: int, rate_hz: float = RATE_HZ
                 ) -> None:
        self.frames = frames
        self.period_ns = round(1e9 / rate_hz)
        self.first_start_ns = start_ns
        self.epoch = 0
        self.start_ns = start_ns
        self.k = 0  # poses on this time line so far
        self.cursor = 0  # index into the forward-and-back sequence of frames

    def frame(self, cursor: int) -> np.ndarray:
        """The frame at `cursor` of the forward-and-back sequence."""
        n = len(self.frames)
        i = cursor % (2 * n - 2) if n > 1 else 0
        return self.frames[i if i < n else 2 * n - 2 - i]

    def next(self) -> tuple[int, np.ndarray]:
        """The next (stamp ns, poses) on the time line."""
        out = self.start_ns + self.k * self.period_ns, self.frame(self.cursor)
        self.k += 1
        self.cursor += 1
        return out

    @property
    def last_stamp_ns(self) -> int:
        """The stamp of the latest pose given (ns)."""
        return self.start_ns + (self.k - 1) * self.period_ns

    def new_time_line(self, start_ns: int, cursor: int = 0) -> None:
        """Start a new time line at start_ns (ns), from frame position `cursor`."""
        self.epoch += 1
        self.start_ns, self.k, self.cursor = start_ns, 0, cursor

    def continue_from(self, stamp_ns: int, frame_index: int, epoch: int) -> None:
        """Go on after a pose of `epoch` stamped stamp_ns (ns) showing frame `frame_index`,
        the body walking back from there (its stamps move on: the same time line)."""
        self.epoch = epoch
        self.start_ns, self.k = stamp_ns + self.period_ns, 0
        self.cursor = 2 * len(self.frames) - 2 - frame_index + 1 if frame_index else 1


class Recorder:
    """Raw subscriptions (reliable, what the node publishes) to /cloth/marker, /cloth/markers
    and /cloth/stats: the cloth markers drawn (receive time s, stamp ns), the DELETEALLs
    (`Clear`) and the statuses (`Tick`), all received times `time.monotonic()`."""

    def __init__(self, node) -> None:
        self.node = node
        self.qos = reliable_qos()
        self.marker_topic, self.stats_topic = MARKER_TOPIC, STATS_TOPIC
        self.markers: list[tuple[float, int]] = []
        self.clears: list[Clear] = []
        self.ticks: list[Tick] = []
        self.marker_sub = None
        self.subscribe_marker()
        # imported here: ROS messages (the ROS side), loaded only when needed
        from diagnostic_msgs.msg import DiagnosticArray
        from visualization_msgs.msg import MarkerArray

        self.array_sub = node.create_subscription(MarkerArray, MARKERS_TOPIC, self._on_array,
                                                  self.qos, raw=True)
        self.stats_sub = node.create_subscription(DiagnosticArray, STATS_TOPIC,
                                                  self._on_stats, self.qos, raw=True)

    def subscribe_marker(self) -> None:
        """(Re)create the /cloth/marker subscription."""
        # imported here: ROS messages (the ROS side), loaded only when needed
        from visualization_msgs.msg import Marker

        self.marker_sub = self.node.create_subscription(Marker, self.marker_topic,
                                                        self._on_marker, self.qos, raw=True)

    def unsubscribe_marker(self) -> None:
        """Destroy the /cloth/marker subscription (a display that goes away)."""
        if self.marker_sub is not None:
            self.node.destroy_subscription(self.marker_sub)
            self.marker_sub = None

    def matched(self) -> bool:
        """Whether every subscription has matched the node's publisher."""
        subs = [s for s in (self.marker_sub, self.array_sub, self.stats_sub) if s is not None]
        return all(s.get_publisher_count() > 0 for s in subs)

    def _on_marker(self, data: bytes) -> None:
        t = time.monotonic()
        m = marker_arrays_from_bytes(data)
        stamp = m.stamp_sec * 1_000_000_000 + m.stamp_nanosec
        if m.action == DELETEALL:
            self.clears.append(Clear(t, stamp, "marker"))
        else:
            self.markers.append((t, stamp))

    def _on_array(self, data: bytes) -> None:
        t = time.monotonic()
        stamp = marker_array_clear_stamp(data)
        if stamp is not None:
            self.clears.append(Clear(t, stamp, "markers"))

    def _on_stats(self, data: bytes) -> None:
        # imported here: ROS messages (the ROS side), loaded only when needed
        from diagnostic_msgs.msg import DiagnosticArray


        t = time.monotonic()
        msg = deserialize(data, DiagnosticArray)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        for st in msg.status:
            self.ticks.append(Tick(t, stamp, st.message,
                                   {kv.key: kv.value for kv in st.values}))


class FaultStream:
    """Publishes body poses into cloth_node from this process's RosSide and records it all.

    side: the RosSide (its executor is spun here, in this thread only); source: the poses;
    topic: the node's pose topic. `node` (a NodeProcess) is checked while spinning: NodeError
    when it has exited.
    """

    def __init__(self, side, source: PoseSource, topic: str, rate_hz: float = RATE_HZ) -> None:
        # imported here: ROS messages (the ROS side), loaded only when needed
        from geometry_msgs.msg import PoseArray


        self.side = side
        self.source = source
        self.period = 1.0 / rate_hz
        self.pub = side.node.create_publisher(PoseArray, topic, reliable_qos())
        self.rec = Recorder(side.node)
        self.sent: list[Sent] = []
        self.node = None  # the NodeProcess being fed
        self._due: float | None = None

    # -- publishing ------------------------------------------------------------------------
    def publish(self, data: bytes, stamp_ns: int, kind: str, epoch: int | None = None) -> Sent:
        """Publish one message now and note it (kind: figures.VALID_KINDS or BAD_KINDS)."""
        self.pub.publish(data)
        s = Sent(time.monotonic(), stamp_ns, self.source.epoch if epoch is None else epoch,
                 kind)
        self.sent.append(s)
        return s

    def send_valid(self, kind: str = "valid") -> Sent:
        """Publish the source's next pose."""
        stamp, poses = self.source.next()
        return self.publish(pose_array_cdr(stamp, poses), stamp, kind)

    def last_valid(self) -> Sent | None:
        """The latest valid pose sent."""
        return next((s for s in reversed(self.sent) if s.kind in VALID_KINDS), None)

    def reset_pacing(self) -> None:
        """The next slot is one period from now (after a pause or a burst)."""
        self._due = time.monotonic() + self.period

    def run(self, seconds: float, slot: Callable[[FaultStream], None] | None = None,
            until: Callable[[], bool] | None = None, max_s: float | None = None) -> None:
        """Publish a slot every pose period for `seconds` s (then on until `until()`, if
        given, for at most `max_s` s in all), spinning between slots. slot(stream) publishes
        the slot's messages (default: the next valid pose). A late slot is not made up for
        (no burst to catch up)."""
        slot = slot or (lambda s: s.send_valid())
        t0 = time.monotonic()
        if self._due is None:
            self._due = t0
        limit = t0 + max(seconds, max_s or 0.0)
        while True:
            now = time.monotonic()
            if now - t0 >= seconds and (until is None or until() or now >= limit):
                return
            if now >= self._due:
                slot(self)
                self._due = max(self._due + self.period, now)
            self.spin(min(max(self._due - time.monotonic(), 0.0), 0.05))

    # -- spinning --------------------------------------------------------------------------
    def spin(self, timeout_s: float) -> None:
        """Handle one callback (or wait up to timeout_s s); NodeError if the node exited."""
        if self.node is not None:
            self.node.check_alive("while the benchmark streamed poses")
        self.side.executor.spin_once(timeout_sec=timeout_s)

    def wait(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """Spin without publishing until done() (True) or timeout_s s (False)."""
        deadline = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > deadline:
                return False
            self.spin(0.02)
        return True

    def latest_values(self) -> dict:
        """The newest status's values ({} before any)."""
        return dict(self.rec.ticks[-1].values) if self.rec.ticks else {}

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> tuple[dict, bool]:
        """Stop publishing until the node has simulated the latest valid pose sent (its
        status, stamped with it, says nothing is pending) and, with a marker subscriber, its
        marker arrived. Returns (that status's values, True), or (the newest values, False)
        after timeout_s s. The next slot is one period after it."""
        last = self.last_valid()

        def done() -> bool:
            if last is None:
                return True
            tick = next((x for x in reversed(self.rec.ticks) if x.t >= last.t
                         and x.stamp_ns == last.stamp_ns), None)
            if tick is None or int(tick.values.get("poses_pending", 0)):
                return False
            return self.rec.marker_sub is None or any(
                t >= last.t and st >= last.stamp_ns for t, st in self.rec.markers[-20:])

        ok = self.wait(done, timeout_s)
        values = self.latest_values()
        if ok and last is not None:
            values = next(dict(x.values) for x in reversed(self.rec.ticks)
                          if x.stamp_ns == last.stamp_ns)
        self.reset_pacing()
        return values, ok


@contextmanager
def cpu_hogs(count: int, seconds: float) -> Iterator[list[subprocess.Popen]]:
    """`count` processes that each keep a core busy for `seconds` s (a Python busy loop
    that stops by itself); every one still running is killed when the block ends."""
    procs: list[subprocess.Popen] = []
    try:
        for _ in range(count):
            procs.append(subprocess.Popen([sys.executable, "-c", HOG_CODE.format(s=seconds)],
                                          stdin=subprocess.DEVNULL))
        yield procs
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()
