"""`cloth-mg demo`: cloth_node in its own process, driven by a bag over DDS, recorded and drawn.

    cloth-mg demo                                   # the walking scene, ~1200 particles
    cloth-mg demo --particles 2400 --out out/demo2  # a finer dress (slower than real time)
    cloth-mg demo --steps 40 --particles 300        # only the first 40 pose messages

What it does, as a ROS 2 user would by hand with three terminals:

1. starts `cloth_node` as a subprocess (`python -m cloth_mg_ros.ros.node --ros-args
   --params-file config/walking.yaml -p particles:=N`), its output in `<out>/node.log`;
2. records `/cloth/marker` and `/cloth/stats` into `<out>/cloth_bag` (MCAP) with
   `record_topics` (a thread of this process) as soon as the node's topics appear;
3. once the node subscribes to `/avatar/body_poses`, replays the bag (default the bundled
   `bags/walk`, 109 PoseArrays at 30 Hz) into it with `replay_bag` (a thread of this process),
   paced by its stamps (`rate` 1 = real time);
4. waits until the node has published the status of its tick that reached the last pose
   message (or stops publishing), stops the recorder and shuts the node down with SIGINT (it
   logs its frame summary and exits 0);
5. reads `<out>/cloth_bag` back with rosbags: `<out>/frames.png` is a strip of ~5 frames, the
   cloth decoded from the recorded TRIANGLE_LIST markers (3 corners per triangle, m) and the
   avatar's capsules from the replayed poses of the same stamps; `DemoResult.rows` holds one
   row of figures per recorded status (`format_table` prints every 10th and the medians).

Isolation: every process of the demo uses one ROS domain, by default ``1 + pid % 100`` of the
demo's process (`default_domain_id`; when other nodes show up there within a second, the
next free one, `open_ros_side`), and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, so it neither
hears nor disturbs other ROS graphs on the machine or the network (both are set for the child
process and, while its rclpy context starts, for this process; the previous values come back).

Failures are reported as `NodeError` with the last lines of the node's log: the node exits
during start-up (a bad parameter, a missing package), its topics do not appear within
`start_timeout_s`, or it dies while stepping. The first run after installation compiles the
numba kernels (the node does it while warming up, before it subscribes): up to a minute.

Latency: each tick of the node advances the cloth to the newest pose message it received,
through every one that arrived since its last tick, so when a tick costs more than the interval
between two pose messages (33 ms at 30 Hz, divided by `rate`) the next tick coalesces the
poses that came meanwhile: a marker per tick, stamped with its newest pose's header stamp, and
no pose waits in a queue or is lost. `cloth-mg bench node` measures that latency.

The helpers here (`open_ros_side`, `child_env`, `NodeProcess`, `RosSide`, `wait_for_node`,
`header_stamp_ns`, `first_messages_bag`) are shared with `cloth_mg_ros.bench.node_latency`.
"""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cloth_mg_ros.bags import absolute_topic
from cloth_mg_ros.errors import ClothInputError

__all__ = [
    "DEFAULT_PARTICLES",
    "DemoResult",
    "NodeError",
    "NodeProcess",
    "RosSide",
    "child_env",
    "default_domain_id",
    "first_messages_bag",
    "format_table",
    "header_stamp_ns",
    "interrupt_signals",
    "locked_log",
    "open_ros_side",
    "read_cloth_bag",
    "ros_environment",
    "run_demo",
]

DEFAULT_PARTICLES = 1200  # ~80 ms per tick on one core of a 2-core EPYC: the run stays short
POSE_TOPIC = "/avatar/body_poses"
MARKER_TOPIC = "/cloth/marker"
STATS_TOPIC = "/cloth/stats"
NODE_NAME = "cloth_node"
START_TIMEOUT_S = 120.0  # node start: imports, warm-up, the first run's numba compile
IDLE_TIMEOUT_S = 20.0  # after the replay: give up when no status arrived for this long, s
STOP_TIMEOUT_S = 15.0  # SIGINT to exit, s
PROBE_S = 1.0  # look this long for other nodes on a ROS domain before using it, s
DOMAIN_TRIES = 10  # domains tried before using a busy one
SETTLE_S = 0.5  # after the node's subscription appeared, before the first pose, s
PROGRESS_PERIOD_S = 5.0  # between progress lines while the node steps, s
TAIL_LINES = 25  # lines of the node's log shown when it fails
LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
MIN_PARTICLES, MAX_PARTICLES = 16, 200_000  # cloth_node's declared range of `particles`


class NodeError(RuntimeError):
    """cloth_node failed: did not start, died, or did not exit cleanly (message: the log's
    last lines)."""


# ------------------------------------------------------------------------------------------
# Processes and the ROS environment


@contextmanager
def interrupt_signals() -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM raise KeyboardInterrupt in the main thread while the block
    runs, also when the process started with SIGINT ignored (in the background of a
    non-interactive shell); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame) -> None:
        raise KeyboardInterrupt

    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous_int)
        signal.signal(signal.SIGTERM, previous_term)


def default_domain_id(pid: int | None = None) -> int:
    """A ROS domain id for this run: 1 + pid % 100 (1..100, clear of the default 0)."""
    return 1 + (os.getpid() if pid is None else pid) % 100


def check_domain_id(domain_id: int) -> int:
    """`domain_id` if it is a usable ROS domain id (0..232 with Fast DDS); else
    ClothInputError."""
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not (
            0 <= domain_id <= 232):
        raise ClothInputError(f"--domain-id must be an integer in 0..232, got {domain_id!r}")
    return domain_id


@contextmanager
def ros_environment(domain_id: int) -> Iterator[dict[str, str]]:
    """Set ROS_DOMAIN_ID=domain_id and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST in this
    process until the block ends (the previous values come back); yields the environment for
    child processes (`child_env`)."""
    keys = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    saved = {k: os.environ.get(k) for k in keys}
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    try:
        yield child_env(domain_id)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def child_env(domain_id: int) -> dict[str, str]:
    """Environment of a child process: ours with ROS_DOMAIN_ID=domain_id,
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and PYTHONUNBUFFERED=1 (its log arrives whole)."""
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
                ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")


class NodeProcess:
    """cloth_node as a subprocess: stdout and stderr into `log_path`.

    Args:
        params_file: a cloth_node params file (config/<scene>.yaml).
        params: further `name:=value` parameters (`-p`), after the file (they win).
        env: the child's environment (`child_env`).
        log_path: where its output goes (created or truncated).
    """

    def __init__(self, params_file: str | os.PathLike, params: Sequence[str],
                 env: dict[str, str], log_path: str | os.PathLike) -> None:
        self.log_path = Path(log_path)
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self.command = [sys.executable, "-m", "cloth_mg_ros.ros.node", "--ros-args",
                        "--params-file", str(params_file)]
        for p in params:
            self.command += ["-p", p]
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen(self.command, env=env, stdin=subprocess.DEVNULL,
                                         stdout=log, stderr=subprocess.STDOUT)

    def tail(self, lines: int = TAIL_LINES) -> str:
        """The last `lines` lines of the node's log, indented."""
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return "    (no log)"
        kept = text.rstrip().splitlines()[-lines:]
        return "\n".join(f"    {line}" for line in kept) or "    (the log is empty)"

    def check_alive(self, doing: str) -> None:
        """NodeError with the log's tail if the node has exited (`doing`: what was awaited)."""
        code = self.proc.poll()
        if code is not None:
            how = " (stopped by Ctrl-C or a signal?)" if code in (0, -2, -15) else ""
            raise NodeError(f"cloth_node exited with status {code} {doing}{how}; the last "
                            f"lines of its log ({self.log_path}):\n{self.tail()}")

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """SIGINT (Ctrl-C), then wait up to `timeout_s` s; killed after that (status -9).
        Returns the exit status (0: a clean shutdown)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)

    def kill(self) -> None:
        """Kill the node if it still runs (cleanup after an error)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


class RosSide:
    """This process's side of the graph: an rclpy context on `domain_id` with localhost
    discovery (`ros_environment` while it initialises; no signal handlers: Ctrl-C stays a
    KeyboardInterrupt), one node and an executor spun by `spin_until`."""

    def __init__(self, domain_id: int, node_name: str) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.domain_id = domain_id
        self.ctx = Context()
        with ros_environment(domain_id):
            rclpy.init(context=self.ctx, domain_id=domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
            self.node = rclpy.create_node(node_name, context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)

    def other_nodes(self) -> list[str]:
        """Names of the nodes in the graph that are not this process's (call it before
        adding nodes): 'a node' for each other /rosout publisher not yet known by name."""
        names = sorted(name for name, _ in self.node.get_node_names_and_namespaces()
                       if name != self.node.get_name())
        unnamed = self.node.count_publishers("/rosout") - 1 - len(names)
        return names + ["a node"] * max(unnamed, 0)

    def spin_until(self, done: Callable[[], bool], timeout_s: float,
                   node: NodeProcess | None = None, doing: str = "") -> bool:
        """Spin until done() (True) or `timeout_s` s (False); NodeError if `node` exits."""
        deadline = time.monotonic() + timeout_s
        while not done():
            if node is not None:
                node.check_alive(doing)
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def has_endpoint(self, topic: str, node_name: str, subscription: bool) -> bool:
        """Whether node `node_name` has a subscription (or publisher) on `topic` in the
        graph."""
        get = (self.node.get_subscriptions_info_by_topic if subscription
               else self.node.get_publishers_info_by_topic)
        return any(i.node_name == node_name for i in get(topic))

    def close(self) -> None:
        import rclpy

        self.executor.shutdown(timeout_sec=0.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def open_ros_side(domain_id: int | None, node_name: str, log: Callable[[str], None] = print,
                  probe_s: float = PROBE_S, tries: int = DOMAIN_TRIES) -> RosSide:
    """A RosSide on a ROS domain nobody else uses, before the node is started on it.

    domain_id None: `default_domain_id()`, or, when other nodes show up there within
    `probe_s` seconds, the next of 1..100 (up to `tries` domains; then the last one, with a
    warning). An explicit domain_id is used as given (a warning if it is busy)."""
    base = default_domain_id() if domain_id is None else check_domain_id(domain_id)
    tries = 1 if domain_id is not None else max(1, tries)
    for k in range(tries):
        domain = base if domain_id is not None else 1 + (base - 1 + k) % 100
        side = RosSide(domain, node_name)
        side.spin_until(lambda s=side: bool(s.other_nodes()), probe_s)
        others = side.other_nodes()
        if not others:
            return side
        if k < tries - 1:
            side.close()
            log(f"ROS domain {domain} is in use ({', '.join(others)}); trying the next")
            continue
        log(f"warning: ROS domain {domain} is in use ({', '.join(others)}); their messages "
            f"may mix with ours (choose a free one with --domain-id)")
        return side
    raise AssertionError("unreachable")


def wait_for_node(side: RosSide, node: NodeProcess, topic: str = POSE_TOPIC,
                  timeout_s: float = START_TIMEOUT_S,
                  also: Callable[[], bool] = lambda: True) -> float:
    """Spin until cloth_node subscribes to `topic` (it does after its warm-up, the last
    step of its start-up) and also() holds; returns the seconds waited. NodeError if the node
    exits or `timeout_s` passes."""
    t0 = time.monotonic()
    ok = side.spin_until(lambda: side.has_endpoint(topic, NODE_NAME, True) and also(),
                         timeout_s, node, "during start-up")
    if not ok:
        raise NodeError(f"cloth_node did not subscribe to {topic} within {timeout_s:g} s; the "
                        f"last lines of its log ({node.log_path}):\n{node.tail()}")
    return time.monotonic() - t0


# ------------------------------------------------------------------------------------------
# Bags


def header_stamp_ns(data: bytes | memoryview) -> int:
    """header.stamp (ns) of a serialised message that starts with a std_msgs/Header
    (PoseArray, Marker, DiagnosticArray): int32 sec and uint32 nanosec right after the 4-byte
    encapsulation header, little- or big-endian as it says."""
    endian = "<" if bytes(data[1:2]) == b"\x01" else ">"
    sec, nanosec = struct.unpack_from(endian + "iI", data, 4)
    return sec * 1_000_000_000 + nanosec


def first_messages_bag(bag: str | os.PathLike, messages: int, out_dir: str | os.PathLike,
                       topic: str = POSE_TOPIC) -> Path:
    """A pose bag of the first `messages` PoseArrays of `bag` (stamps kept), written to
    out_dir/first_<messages> (MCAP). ClothInputError for fewer than 2 or a bad bag."""
    from cloth_mg_ros.bags import read_pose_frames, write_pose_bag
    from cloth_mg_ros.ros.replay import resolve_bag

    if messages < 2:
        raise ClothInputError(f"replay at least 2 pose messages, got {messages}")
    frames = read_pose_frames(resolve_bag(bag), topic)[:messages]
    return write_pose_bag(Path(out_dir) / f"first_{messages}", np.array([s for s, _ in frames]),
                          np.stack([p for _, p in frames]), topic=topic)


@dataclass
class ClothRecording:
    """What a recorded cloth bag holds.

    markers: [(stamp ns, triangle corners (3 t, 3) float64 m)], in recording order;
    stats: [(stamp ns, level 0..3, message, {key: value})], in recording order.
    """

    markers: list[tuple[int, np.ndarray]] = field(default_factory=list)
    stats: list[tuple[int, int, str, dict[str, str]]] = field(default_factory=list)


def read_cloth_bag(path: str | os.PathLike, marker_topic: str = MARKER_TOPIC,
                   stats_topic: str = STATS_TOPIC) -> ClothRecording:
    """Read a bag recorded from cloth_node with rosbags: the markers decoded straight from
    their CDR bytes (`marker_arrays_from_bytes`), the statuses with the ROS 2 Jazzy type
    store."""
    from cloth_mg_ros.bags import _typestore, open_reader
    from cloth_mg_ros.messages.markers import marker_arrays_from_bytes

    store = _typestore()
    out = ClothRecording()
    reader = open_reader(path)
    try:
        conns = [c for c in reader.connections if c.topic in (marker_topic, stats_topic)]
        for conn, _, raw in reader.messages(connections=conns):
            if conn.topic == marker_topic:
                m = marker_arrays_from_bytes(raw)
                out.markers.append((m.stamp_sec * 1_000_000_000 + m.stamp_nanosec,
                                    np.array(m.points)))
            else:
                msg = store.deserialize_cdr(raw, conn.msgtype)
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                for st in msg.status:
                    out.stats.append((stamp, int(st.level), str(st.message),
                                      {kv.key: kv.value for kv in st.values}))
    finally:
        reader.close()
    return out


# ------------------------------------------------------------------------------------------
# Figures


def stats_rows(stats: Sequence[tuple[int, int, str, dict[str, str]]],
               t0_ns: int | None = None) -> list[dict]:
    """One row per status: tick (0: dressing or re-anchoring), t (s since the first stamp, or
    `t0_ns`), step_ms, solve_ms, iterations, residual, penetration_mm, level ('OK', ...),
    message, and `is_tick` (a simulation step: substeps > 0)."""
    rows = []
    if t0_ns is None and stats:
        t0_ns = stats[0][0]
    for stamp, level, message, v in stats:
        def num(key: str, v=v) -> float:
            try:
                return float(v.get(key, "nan"))
            except ValueError:
                return float("nan")

        rows.append({
            "tick": int(num("step")) if np.isfinite(num("step")) else -1,
            "t": 1e-9 * (stamp - (t0_ns or 0)),
            "step_ms": num("step_ms"), "solve_ms": num("solve_ms"),
            "iterations": int(num("iterations")) if np.isfinite(num("iterations")) else 0,
            "residual": num("rel_residual"),
            "penetration_mm": 1e3 * num("max_penetration_m"),
            "level": LEVELS.get(level, str(level)), "message": message,
            "is_tick": num("substeps") > 0,
        })
    return rows


def format_table(rows: Sequence[dict], every: int = 10) -> str:
    """A text table of `rows` (`stats_rows`): the first, every `every`-th and the last
    status, then the medians over the simulation ticks (dressing and re-anchoring left out,
    their step ms is the dressing time) and the count of statuses per level."""
    head = (f"{'tick':>5} {'t s':>6} {'step ms':>8} {'solve ms':>9} {'iters':>6} "
            f"{'residual':>9} {'pen. mm':>8}  status")
    lines = [head, "-" * len(head)]

    def line(label: str, r: dict) -> str:
        status = r["level"] if r["message"] in ("ok", "") else f"{r['level']} {r['message']}"
        if len(status) > 48:
            status = status[:45] + "..."
        return (f"{label:>5} {r['t']:6.2f} {r['step_ms']:8.1f} {r['solve_ms']:9.1f} "
                f"{r['iterations']:6d} {r['residual']:9.2e} {r['penetration_mm']:8.2f}  {status}")

    for k, r in enumerate(rows):
        if k % every == 0 or k == len(rows) - 1:
            label = (str(r["tick"]) if r["is_tick"]
                     else "dress" if r["message"].startswith("dressed") else "-")
            lines.append(line(label, r))
    ticks = [r for r in rows if r["is_tick"]]
    if ticks:
        def med(key: str) -> float:
            return float(np.median([r[key] for r in ticks]))

        counts = {}
        for r in rows:
            counts[r["level"]] = counts.get(r["level"], 0) + 1
        lines.append("-" * len(head))
        lines.append(f"{'med.':>5} {'':>6} {med('step_ms'):8.1f} {med('solve_ms'):9.1f} "
                     f"{med('iterations'):6.0f} {med('residual'):9.2e} "
                     f"{med('penetration_mm'):8.2f}  "
                     + ", ".join(f"{n} {lvl}" for lvl, n in counts.items())
                     + f" (median of {len(ticks)} ticks)")
    return "\n".join(lines)


def render_recording(path: str | os.PathLike, rec: ClothRecording,
                     poses: dict[int, np.ndarray] | None = None, n_frames: int = 5,
                     title: str = "") -> Path:
    """frames.png: `n_frames` recorded markers evenly spread over the recording, the cloth
    drawn from its triangle corners (positions = the marker's points (3 t, 3) m, faces
    arange(3 t) in threes) and, where `poses` ({stamp ns: (S, 7)}) holds the marker's stamp,
    the avatar's capsules. Returns the path."""
    from cloth_mg_ros.render import render_frames

    if not rec.markers:
        raise ValueError("no markers to draw")
    picks = sorted(set(np.linspace(0, len(rec.markers) - 1, max(1, n_frames))
                       .round().astype(int).tolist()))
    t0 = rec.markers[0][0]
    frames, capsules = [], []
    avatar = None
    if poses:
        from cloth_mg_ros.motion.avatar import Avatar

        avatar = Avatar.load()
    for k in picks:
        stamp, points = rec.markers[k]
        frames.append((1e-9 * (stamp - t0), points))
        body = poses.get(stamp) if poses else None
        if avatar is not None and body is not None and body.shape == (avatar.num_segments, 7):
            p0, p1, radius = avatar.capsules(body)
            capsules.append(list(zip(p0, p1, radius, strict=True)))
        else:
            capsules.append([])
    faces = np.arange(len(frames[0][1])).reshape(-1, 3)
    same = all(len(x) == len(frames[0][1]) for _, x in frames)
    if not same:  # a re-dressed garment of another size: draw only the first one's size
        frames = [(t, x) for t, x in frames if len(x) == len(frames[0][1])]
    return render_frames(path, frames, faces, title=title,
                         capsules_per_frame=capsules[:len(frames)] if poses else None)


# ------------------------------------------------------------------------------------------
# The demo


@dataclass
class DemoResult:
    """What a demo run produced.

    out: the output folder; cloth_bag, frames_png, node_log: the files in it; domain_id: the
    ROS domain used; messages: pose messages replayed; markers, statuses: recorded;
    poses_used, poses_coalesced, dropped: the node's counters in its last status;
    rows: `stats_rows` of the recorded statuses; particles: the garment's particle count;
    node_exit: the node's exit status after SIGINT (0: clean); start_s: the node's start-up
    (launch to subscribed), s; replay_s: the replay's wall time, s; finish_s: from the first
    pose to the last status recorded, s; wall_s: the whole demo, s.
    """

    out: Path
    cloth_bag: Path
    frames_png: Path
    node_log: Path
    domain_id: int
    messages: int = 0
    markers: int = 0
    statuses: int = 0
    rows: list[dict] = field(default_factory=list)
    particles: int = 0
    poses_used: int = 0
    poses_coalesced: int = 0
    dropped: int = 0
    node_exit: int = 0
    start_s: float = 0.0
    replay_s: float = 0.0
    finish_s: float = 0.0
    wall_s: float = 0.0


def _clear_old_bag(path: Path) -> None:
    """Remove a previous demo's cloth bag (a folder of metadata.yaml and .mcap/.db3 files)
    at `path`; ClothInputError if `path` holds anything else."""
    import shutil

    if not path.exists():
        return
    if not path.is_dir() or any(p.suffix not in (".yaml", ".mcap", ".db3", ".db3-shm",
                                                 ".db3-wal") for p in path.iterdir()):
        raise ClothInputError(f"{path} exists and is not a bag of an earlier demo; move it "
                              f"away or choose another --out")
    shutil.rmtree(path)


def locked_log(log: Callable[[str], None]) -> Callable[[str], None]:
    """`log` behind a lock: the replay and the recorder log from their threads."""
    lock = threading.Lock()

    def locked(line: str) -> None:
        with lock:
            log(line)

    return locked


def check_run_args(particles: int, rate: float, messages: int | None, scene: str,
                   messages_flag: str, who: str) -> dict:
    """Check the options of a node run fed by a bag (the demo, the node benchmark) before
    anything starts; returns the body scene's parameters. ClothInputError names the option."""
    from cloth_mg_ros.scene_config import is_body_scene, load_scene

    check_particles(particles)
    if not (isinstance(rate, (int, float)) and 0.0 < rate <= 100.0):
        raise ClothInputError(f"--rate must be in (0, 100], got {rate!r}")
    if messages is not None and messages < 2:
        raise ClothInputError(f"{messages_flag} must be at least 2 pose messages, got "
                              f"{messages}")
    if not is_body_scene(scene):
        raise ClothInputError(f"{who} needs a body scene, not {scene!r}")
    return load_scene(scene)


def check_particles(particles: int) -> int:
    """`particles` if cloth_node accepts it (MIN_PARTICLES..MAX_PARTICLES), else
    ClothInputError."""
    if isinstance(particles, bool) or not isinstance(particles, int) or not (
            MIN_PARTICLES <= particles <= MAX_PARTICLES):
        raise ClothInputError(f"--particles must be an integer in {MIN_PARTICLES}.."
                              f"{MAX_PARTICLES}, got {particles!r}")
    return particles


def run_demo(out: str | os.PathLike = "out/demo", particles: int = DEFAULT_PARTICLES,
             messages: int | None = None, bag: str | os.PathLike | None = None,
             scene: str = "walking", rate: float = 1.0, domain_id: int | None = None,
             n_frames: int = 5, start_timeout_s: float = START_TIMEOUT_S,
             log: Callable[[str], None] = print) -> DemoResult:
    """Run cloth_node on a bag over DDS, record its output, draw and tabulate it (module
    docstring).

    Args:
        out: output folder (created): cloth_bag/, frames.png, node.log.
        particles: about this many cloth particles.
        messages: replay only the first this many pose messages (None: the whole bag).
        bag: the pose bag (a folder or a bundled name; None: the scene's bag).
        scene: a body scene (config/<scene>.yaml or a params .yaml).
        rate: replay speed factor (1: real time).
        domain_id: the ROS domain of every process (None: a free one, `open_ros_side`).
        n_frames: frames drawn in frames.png.
        start_timeout_s: wait at most this long for the node to subscribe, s.
        log: where progress lines go.

    Returns:
        DemoResult. Raises ClothInputError for bad arguments and NodeError when the node
        fails (with its log's tail); KeyboardInterrupt stops everything (the node too).
    """
    from cloth_mg_ros.ros.record import record_topics
    from cloth_mg_ros.ros.replay import replay_bag, resolve_bag
    from cloth_mg_ros.scene_config import scene_path

    t_start = time.monotonic()
    log = locked_log(log)
    params = check_run_args(particles, rate, messages, scene, "--steps", "the demo")
    params_file = scene_path(scene)
    bag_path = resolve_bag(bag if bag is not None else params["bag"])
    if domain_id is not None:
        check_domain_id(domain_id)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cloth_bag = out / "cloth_bag"
    _clear_old_bag(cloth_bag)
    result = DemoResult(out, cloth_bag, out / "frames.png", out / "node.log", -1)
    topic = absolute_topic(params["topic"])

    with tempfile.TemporaryDirectory(prefix="cloth_demo_") as tmp:
        play = (bag_path if messages is None
                else first_messages_bag(bag_path, messages, tmp, topic))
        from cloth_mg_ros.bags import read_pose_frames

        frames_in = read_pose_frames(play, topic)
        side = open_ros_side(domain_id, "cloth_demo", log)
        try:
            result.domain_id = side.domain_id
            log(f"cloth_node: scene {params['scene']} ({params['garment']}, ~{particles} "
                f"particles, {params['material']}, solver {params['solver']}) on ROS domain "
                f"{side.domain_id} (localhost only); log: {result.node_log}")
            node = NodeProcess(params_file, [f"particles:={particles}"],
                               child_env(side.domain_id), result.node_log)
            last_ns = round(frames_in[-1][0] * 1e9) if frames_in else 0
            _drive(side, node, result, play, len(frames_in), last_ns, topic, rate,
                   start_timeout_s, log, replay_bag, record_topics)
        finally:
            side.close()

    rec = read_cloth_bag(cloth_bag)
    result.markers, result.statuses = len(rec.markers), len(rec.stats)
    result.rows = stats_rows(rec.stats)
    if rec.stats:
        last = rec.stats[-1][3]
        result.particles = int(last.get("particles", 0))
        result.poses_used = int(last.get("poses_used", 0))
        result.poses_coalesced = int(last.get("poses_coalesced", 0))
        result.dropped = int(last.get("dropped", 0))
    if rec.markers:
        poses = {round(s * 1e9): p for s, p in frames_in}
        render_recording(result.frames_png, rec, poses, n_frames,
                         f"{params['scene']}: {params['garment']}, {result.particles} "
                         f"particles, from {result.markers} recorded /cloth/marker messages")
    result.wall_s = time.monotonic() - t_start
    if result.node_exit != 0:
        raise NodeError(f"cloth_node did not exit cleanly after SIGINT (status "
                        f"{result.node_exit}; the outputs in {out} were written); the last "
                        f"lines of its log ({node.log_path}):\n{node.tail()}")
    return result


def _drive(side: RosSide, node: NodeProcess, result: DemoResult, play: Path,
           n_messages: int, last_stamp_ns: int, topic: str, rate: float,
           start_timeout_s: float, log: Callable[[str], None], replay_bag,
           record_topics) -> None:
    """Record, wait for the node, replay, wait for its last status, stop the recorder, the
    replay and the node (also on errors and Ctrl-C)."""
    stop_record = threading.Event()
    stop_replay = threading.Event()
    recorder: threading.Thread | None = None
    replayer: threading.Thread | None = None
    errors: dict[str, BaseException] = {}
    replay_stats: list = []
    statuses = [0]
    newest_status = [-1]  # stamp (ns) of the newest status: the tick that reached it
    last_status = [time.monotonic()]
    try:
        from diagnostic_msgs.msg import DiagnosticArray

        from cloth_mg_ros.ros.replay import reliable_qos

        def on_status(data: bytes) -> None:
            statuses[0] += 1
            newest_status[0] = max(newest_status[0], header_stamp_ns(data))
            last_status[0] = time.monotonic()

        side.node.create_subscription(DiagnosticArray, STATS_TOPIC, on_status, reliable_qos(),
                                      raw=True)

        def record() -> None:
            try:
                record_topics(result.cloth_bag, [MARKER_TOPIC, STATS_TOPIC],
                              context=side.ctx, stop=stop_record,
                              node_name="cloth_demo_record", log=log)
            except BaseException as exc:  # noqa: BLE001 - reported by the main thread
                errors["record"] = exc

        recorder = threading.Thread(target=record, name="cloth_demo_record", daemon=True)
        recorder.start()
        log("waiting for cloth_node (start-up and warm-up; the first run after installation "
            "compiles its kernels, up to a minute) ...")
        t0 = time.monotonic()

        def recording() -> bool:
            if "record" in errors:
                raise errors["record"]
            return all(side.has_endpoint(t, "cloth_demo_record", True)
                       for t in (MARKER_TOPIC, STATS_TOPIC))

        wait_for_node(side, node, topic, start_timeout_s, also=recording)
        result.start_s = time.monotonic() - t0
        log(f"cloth_node is up after {result.start_s:.1f} s")

        def replay() -> None:
            try:
                replay_stats.append(replay_bag(play, rate=rate, topics=[topic],
                                               context=side.ctx, wait_s=30.0,
                                               settle_s=SETTLE_S, stop=stop_replay,
                                               node_name="cloth_demo_replay", log=log))
            except BaseException as exc:  # noqa: BLE001 - reported by the main thread
                errors["replay"] = exc

        t_play = time.monotonic()
        replayer = threading.Thread(target=replay, name="cloth_demo_replay", daemon=True)
        replayer.start()
        next_progress = [t_play + PROGRESS_PERIOD_S]

        def progressed() -> bool:
            now = time.monotonic()
            if now >= next_progress[0]:
                next_progress[0] = now + PROGRESS_PERIOD_S
                log(f"  cloth_node: {statuses[0]} ticks for {n_messages} pose messages")
            if replayer.is_alive():
                return False
            if "replay" in errors:
                raise errors["replay"]
            return (newest_status[0] >= last_stamp_ns
                    or now - last_status[0] > IDLE_TIMEOUT_S)

        side.spin_until(progressed, float("inf"), node, "while simulating")
        result.replay_s = replay_stats[0].wall_s
        result.messages = replay_stats[0].messages
        result.finish_s = last_status[0] - t_play
        if newest_status[0] < last_stamp_ns:
            log(f"warning: no status reached the last pose message (none for "
                f"{IDLE_TIMEOUT_S:g} s): its frame was skipped or the node stalled; see "
                f"{result.node_log}")
        side.spin_until(lambda: False, 0.3)  # the recorder's copies of the last messages
    finally:
        stop_record.set()
        stop_replay.set()
        if recorder is not None:
            recorder.join(timeout=15.0)
        if replayer is not None:
            replayer.join(timeout=15.0)
        result.node_exit = node.stop()
    if "record" in errors:
        raise errors["record"]
