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

This module holds the driver (`run_demo`, `DemoResult`) and the option checks it shares with
`cloth_mg_ros.bench.node_latency` (`check_run_args`, `check_particles`, `locked_log`). The ROS
domain, the environment and cloth_node's process (`open_ros_side`, `child_env`, `NodeProcess`,
`RosSide`, `wait_for_node`, `NodeError`) are in `cloth_mg_ros.ros.processes`; reading the
recorded bag back, the table and frames.png (`read_cloth_bag`, `stats_rows`, `format_table`,
`render_recording`, `header_stamp_ns`, `first_messages_bag`) in
`cloth_mg_ros.ros.demo_recording`.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cloth_mg_ros.config.scenes import is_body_scene, load_scene, scene_path
from cloth_mg_ros.config.schema import PARAMETERS
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import absolute_topic, read_pose_frames, resolve_bag
from cloth_mg_ros.ros.demo_recording import (
    first_messages_bag,
    header_stamp_ns,
    read_cloth_bag,
    render_recording,
    stats_rows,
)
from cloth_mg_ros.ros.processes import (
    MARKER_TOPIC,
    START_TIMEOUT_S,
    STATS_TOPIC,
    NodeError,
    NodeProcess,
    RosSide,
    check_domain_id,
    child_env,
    open_ros_side,
    wait_for_node,
)
from cloth_mg_ros.ros.record import record_topics
from cloth_mg_ros.ros.replay import reliable_qos, replay_bag

__all__ = [
    "DEFAULT_PARTICLES",
    "DemoResult",
    "check_particles",
    "check_run_args",
    "locked_log",
    "run_demo",
]

DEFAULT_PARTICLES = 1200  # a short run (its tick time: doc/getting-started.md)
IDLE_TIMEOUT_S = 20.0  # after the replay: give up when no status arrived for this long, s
SETTLE_S = 0.5  # after the node's subscription appeared, before the first pose, s
RECORD_TIMEOUT_S = 30.0  # after the last status: the most the recorder may take to hold it, s
PROGRESS_PERIOD_S = 5.0  # between progress lines while the node steps, s


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
    check_particles(particles)
    check_rate(rate)
    if messages is not None and messages < 2:
        raise ClothInputError(f"{messages_flag} must be at least 2 pose messages, got "
                              f"{messages}")
    if not is_body_scene(scene):
        raise ClothInputError(f"{who} needs a body scene, not {scene!r}")
    return load_scene(scene)


def check_rate(rate: float) -> float:
    """A replay speed factor cloth_node runs accept ((0, 100]), else ClothInputError."""
    if isinstance(rate, bool) or not (isinstance(rate, (int, float)) and 0.0 < rate <= 100.0):
        raise ClothInputError(f"--rate must be in (0, 100], got {rate!r}")
    return float(rate)


def check_particles(particles: int) -> int:
    """`particles` if cloth_node accepts it (an integer in the schema's range of
    `particles`), else ClothInputError."""
    if isinstance(particles, str):  # 'auto' is for scene files, not the demo
        raise ClothInputError(f"--particles must be an integer, got {particles!r}")
    return PARAMETERS["particles"].check(particles, "--particles")


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
    t_start = time.monotonic()
    log = locked_log(log)
    params = check_run_args(particles, rate, messages, scene, "--steps", "the demo")
    params_file = scene_path(scene)
    bag_path = resolve_bag(bag if bag is not None else params["bag"])
    if domain_id is not None:
        check_domain_id(domain_id)
    result = _new_result(Path(out))
    topic = absolute_topic(params["topic"])

    with tempfile.TemporaryDirectory(prefix="cloth_demo_") as tmp:
        play = (bag_path if messages is None
                else first_messages_bag(bag_path, messages, tmp, topic))
        frames_in = read_pose_frames(play, topic)
        side = open_ros_side(domain_id, "cloth_demo", log)
        try:
            node = _start_node(side, params_file, params, particles, result, log)
            last_ns = round(frames_in[-1][0] * 1e9) if frames_in else 0
            _drive(side, node, result, _Feed(play, len(frames_in), last_ns, topic, rate),
                   start_timeout_s, log)
        finally:
            side.close()

    _read_back(result, frames_in, params, n_frames)
    result.wall_s = time.monotonic() - t_start
    if result.node_exit != 0:
        raise NodeError(f"cloth_node did not exit cleanly after SIGINT (status "
                        f"{result.node_exit}; the outputs in {result.out} were written); the last "
                        f"lines of its log ({node.log_path}):\n{node.tail()}")
    return result


def _start_node(side: RosSide, params_file: Path, params, particles: int,
                result: DemoResult, log: Callable[[str], None]) -> NodeProcess:
    """cloth_node started on the side's ROS domain (kept in the result), its output into
    result.node_log."""
    result.domain_id = side.domain_id
    log(f"cloth_node: scene {params['scene']} ({params['garment']}, ~{particles} "
        f"particles, {params['material']}, solver {params['solver']}) on ROS domain "
        f"{side.domain_id} (localhost only); log: {result.node_log}")
    return NodeProcess(params_file, [f"particles:={particles}"], child_env(side.domain_id),
                       result.node_log)


def _new_result(out: Path) -> DemoResult:
    """The output folder made, an earlier demo's cloth bag removed; the run's result to
    fill (domain -1 until the ROS side is open)."""
    out.mkdir(parents=True, exist_ok=True)
    cloth_bag = out / "cloth_bag"
    _clear_old_bag(cloth_bag)
    return DemoResult(out, cloth_bag, out / "frames.png", out / "node.log", -1)


def _read_back(result: DemoResult, frames_in: list, params: dict, n_frames: int) -> None:
    """Read the recorded bag back into `result` (the rows, the node's last counters) and draw
    frames.png from its markers and the replayed poses (`frames_in`: (stamp s, poses))."""
    rec = read_cloth_bag(result.cloth_bag)
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


@dataclass(frozen=True)
class _Feed:
    """What the node is fed: the bag played, its pose messages, the last one's stamp (ns),
    the pose topic and the replay's rate."""

    play: Path
    n_messages: int
    last_stamp_ns: int
    topic: str
    rate: float


def _drive(side: RosSide, node: NodeProcess, result: DemoResult, feed: _Feed,
           start_timeout_s: float, log: Callable[[str], None]) -> None:
    """Record, wait for the node, replay, wait for its last status, stop the recorder, the
    replay and the node (also on errors and Ctrl-C)."""
    run = _DemoRun(side, node, result, feed, log)
    try:
        run.start_recorder()
        run.wait_for_node(start_timeout_s)
        run.replay()
    finally:
        run.stop()
    if "record" in run.errors:
        raise run.errors["record"]


def _in_thread(name: str, work: Callable[[], None], key: str,
               errors: dict[str, BaseException]) -> threading.Thread:
    """A daemon thread `name` that runs work(); what it raises goes to errors[key], for the
    main thread to raise."""
    def target() -> None:
        try:
            work()
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors[key] = exc

    return threading.Thread(target=target, name=name, daemon=True)


class _DemoRun:
    """One demo's recorder and replay threads beside the node, and the statuses seen: their
    count, the newest stamp (ns: the tick that reached it) and when the last came."""

    def __init__(self, side: RosSide, node: NodeProcess, result: DemoResult, feed: _Feed,
                 log: Callable[[str], None]) -> None:
        self.side, self.node, self.result, self.feed, self.log = side, node, result, feed, log
        self.stop_record = threading.Event()
        self.stop_replay = threading.Event()
        self.recorder: threading.Thread | None = None
        self.replayer: threading.Thread | None = None
        self.errors: dict[str, BaseException] = {}
        self.replay_stats: list = []
        self.statuses = 0
        self.newest_status = -1
        self.last_status = time.monotonic()
        # the newest stamp (ns) the recorder has written per topic (its own thread sets it)
        self.recorded = {MARKER_TOPIC: -1, STATS_TOPIC: -1}

    def on_status(self, data: bytes) -> None:
        self.statuses += 1
        self.newest_status = max(self.newest_status, header_stamp_ns(data))
        self.last_status = time.monotonic()

    def on_recorded(self, topic: str, data: bytes) -> None:
        self.recorded[topic] = max(self.recorded[topic], header_stamp_ns(data))

    def start_recorder(self) -> None:
        """Watch the statuses and record the markers and statuses into result.cloth_bag."""
        # imported here: ROS messages (the ROS side), loaded only when needed
        from diagnostic_msgs.msg import DiagnosticArray


        self.side.node.create_subscription(DiagnosticArray, STATS_TOPIC, self.on_status,
                                           reliable_qos(), raw=True)
        self.recorder = _in_thread("cloth_demo_record", lambda: record_topics(
            self.result.cloth_bag, [MARKER_TOPIC, STATS_TOPIC], context=self.side.ctx,
            stop=self.stop_record, node_name="cloth_demo_record", log=self.log,
            on_message=self.on_recorded),
            "record", self.errors)
        self.recorder.start()

    def wait_for_node(self, start_timeout_s: float) -> None:
        """Until the node subscribes to the poses and the recorder to its topics."""
        side = self.side
        self.log("waiting for cloth_node (start-up and warm-up; the first run after "
                 "installation compiles its kernels, up to a minute) ...")
        t0 = time.monotonic()

        def recording() -> bool:
            if "record" in self.errors:
                raise self.errors["record"]
            return all(side.has_endpoint(t, "cloth_demo_record", True)
                       for t in (MARKER_TOPIC, STATS_TOPIC))

        wait_for_node(side, self.node, self.feed.topic, start_timeout_s, also=recording)
        self.result.start_s = time.monotonic() - t0
        self.log(f"cloth_node is up after {self.result.start_s:.1f} s")

    def replay(self) -> None:
        """Replay the bag and wait for the status of the last pose (or IDLE_TIMEOUT_S without
        one), logging progress every PROGRESS_PERIOD_S."""
        feed, result = self.feed, self.result
        t_play = time.monotonic()
        self.replayer = _in_thread("cloth_demo_replay", lambda: self.replay_stats.append(
            replay_bag(feed.play, rate=feed.rate, topics=[feed.topic], context=self.side.ctx,
                       wait_s=30.0, settle_s=SETTLE_S, stop=self.stop_replay,
                       node_name="cloth_demo_replay", log=self.log)), "replay", self.errors)
        self.replayer.start()
        self.side.spin_until(self._progressed(t_play), float("inf"), self.node,
                             "while simulating")
        result.replay_s = self.replay_stats[0].wall_s
        result.messages = self.replay_stats[0].messages
        result.finish_s = self.last_status - t_play
        if self.newest_status < feed.last_stamp_ns:
            self.log(f"warning: no status reached the last pose message (none for "
                     f"{IDLE_TIMEOUT_S:g} s): its frame was skipped or the node stalled; see "
                     f"{result.node_log}")
        # the recorder runs in its own thread with its own subscriptions: the last tick's
        # marker and status are in the bag only once it has written them
        if not self.side.spin_until(lambda: min(self.recorded.values()) >= self.newest_status,
                                    RECORD_TIMEOUT_S):
            self.log(f"warning: the recorder had not written the last tick's marker and "
                     f"status after {RECORD_TIMEOUT_S:g} s (newest recorded stamps "
                     f"{self.recorded}, last status {self.newest_status})")

    def _progressed(self, t_play: float) -> Callable[[], bool]:
        """done() for spin_until: the replay has ended and a status reached the last pose, or
        none came for IDLE_TIMEOUT_S; raises the replay's error."""
        next_progress = [t_play + PROGRESS_PERIOD_S]

        def progressed() -> bool:
            now = time.monotonic()
            if now >= next_progress[0]:
                next_progress[0] = now + PROGRESS_PERIOD_S
                self.log(f"  cloth_node: {self.statuses} ticks for {self.feed.n_messages} pose "
                         f"messages")
            if self.replayer.is_alive():
                return False
            if "replay" in self.errors:
                raise self.errors["replay"]
            return (self.newest_status >= self.feed.last_stamp_ns
                    or now - self.last_status > IDLE_TIMEOUT_S)

        return progressed

    def stop(self) -> None:
        """Stop the recorder and the replay, then the node (its exit status in the result)."""
        self.stop_record.set()
        self.stop_replay.set()
        if self.recorder is not None:
            self.recorder.join(timeout=15.0)
        if self.replayer is not None:
            self.replayer.join(timeout=15.0)
        self.result.node_exit = self.node.stop()
