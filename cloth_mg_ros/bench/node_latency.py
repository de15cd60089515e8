"""`cloth-mg bench node`: cloth_node live, over DDS, from pose received to marker received.

    cloth-mg bench node --bag walk --json out/bench_node.json --png doc/bench_node.png
    cloth-mg bench node --bag walk --particles 1200 --rate 0.3 --json out/bench_node_0.3.json

Two processes on one machine: cloth_node (`python -m cloth_mg_ros.ros.node`, the scene's
params file, and `particles:=N` when asked for; by default the scene's own count) and this
benchmark, which replays the bag into it (`replay_bag` in a thread, paced by the bag's stamps
times `rate`) and subscribes raw (the CDR bytes, no message objects) to both
`/avatar/body_poses`, the replayed input, `/cloth/marker`, the node's output, and
`/cloth/stats`. Both processes use one ROS domain of their own
(`cloth_mg_ros.ros.processes.open_ros_side`) and localhost discovery.

The node advances the cloth each tick to the newest pose it received, through every pose that
arrived since its last tick (ros.session): a marker stands for the pose whose stamp it
carries and for every pose before it that its tick coalesced. So the latency of a pose is the
time this process received the first marker stamped at or after the pose's stamp minus the
time this process received the pose, both `time.monotonic()` in this process (one clock). The
benchmark's pose subscription shares the replay's DDS participant, so it receives a pose within
a fraction of a millisecond of its publication; the figure is thus the pose's transport to the
node, the wait for the tick in progress, the tick that simulates to it and the marker's
transport back. The pose the node dresses the garment on is reported on its own
(`dress_latency_ms`). (Not from a third process: its new DDS participant is sometimes
discovered by one of the two subscribers a few hundred ms to seconds later than by the other,
and a replay starts once one subscriber has matched, so one side would lose the first
messages. In this process the replay's writer matches the node's reader, already discovered,
at once.)

Reported, beside the latency's p50 / p95 / max: `service_ms` (a marker's receipt minus the
later of its own pose's receipt and the previous marker's: the tick and the transport),
`queue_ms` (a pose's latency less its marker's service time: how long it waited for a tick to
start), the latency's p95 over the first and the last third of the clip (`latency_thirds`;
growth means the node falls behind), and the node's own counters from its last status:
`poses_used`, `poses_coalesced`, `dropped` (poses received that no counter holds; 0), the lag
(newest pose received minus simulated time) and its step times. `lost` = pose messages sent
minus poses the node received (DDS). `keeps_up`: nothing lost or dropped and the last third's
p95 at most 1.2 times the first third's. `--png` charts the latency of every pose and the
node's tick times over the clip.
"""

from __future__ import annotations

import os
import platform
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from cloth_mg_ros.bench.node_figures import (
    GROWTH_LIMIT,
    latency_figures,
    lod_figures,
    median,
    pass_figures,
    percentiles,
    stats_values,
)
from cloth_mg_ros.bench.results import recorded_path
from cloth_mg_ros.config.scenes import scene_path
from cloth_mg_ros.config.schema import check
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import absolute_topic, resolve_bag
from cloth_mg_ros.ros.demo import IDLE_TIMEOUT_S, check_rate, check_run_args, locked_log
from cloth_mg_ros.ros.demo_recording import first_messages_bag, header_stamp_ns
from cloth_mg_ros.ros.processes import (
    MARKER_TOPIC,
    NODE_NAME,
    START_TIMEOUT_S,
    STATS_TOPIC,
    NodeError,
    NodeProcess,
    check_domain_id,
    child_env,
    open_ros_side,
    wait_for_node,
)
from cloth_mg_ros.ros.replay import bag_topics, reliable_qos, replay_bag
from cloth_mg_ros.solvers.threads import resolve_threads

__all__ = ["NodeBenchOptions", "bench_node", "run_node_bench"]

SETTLE_S = 0.5  # after the node's topics appeared, before the replay starts, s
REPLAY_TIMEOUT_S = 600.0  # the replay of one bag at the slowest sensible rate, s
























@dataclass(frozen=True)
class NodeBenchOptions:
    """What one `bench_node` run does: its arguments but `log` (see there)."""

    bag: str | os.PathLike = "walk"
    particles: int | str | None = None
    scene: str = "walking"
    rate: float | Sequence[float] = 1.0
    messages: int | None = None
    domain_id: int | None = None
    node_log: str | os.PathLike | None = None
    start_timeout_s: float = START_TIMEOUT_S
    threads: int | None = None
    loops: int | None = None
    lod: bool | None = None
    tick_budget: float | None = None
    contact_friction: str | None = None


@dataclass(frozen=True)
class _Plan:
    """NodeBenchOptions checked: the scene's parameters, one rate per pass given, the number
    of passes, the particles asked for (the scene's when None), the pose topic, the bag."""

    opts: NodeBenchOptions
    params: object  # config.scenes.load_scene's SceneParams
    rates: list
    passes: int
    particles: int | str
    topic: str
    bag_path: Path


@dataclass
class _Recorded:
    """What a run received, each message with its receive time (`time.monotonic()`, s):
    poses and markers with their stamps (ns), the statuses' CDR bytes; the pose messages
    sent, the node's exit status, the ROS domain, and the played bag's message count and
    first and last stamps (ns)."""

    poses: list[tuple[float, int]] = field(default_factory=list)
    markers: list[tuple[float, int]] = field(default_factory=list)
    stats_raw: list[tuple[float, bytes]] = field(default_factory=list)
    sent: int = 0
    node_exit: int = -1
    domain_id: int = -1
    per_pass: int = 0
    t_first: int = 0
    t_last: int = 0


def bench_node(bag: str | os.PathLike = "walk", particles: int | str | None = None,
               scene: str = "walking", rate: float | Sequence[float] = 1.0,
               messages: int | None = None,
               domain_id: int | None = None, node_log: str | os.PathLike | None = None,
               start_timeout_s: float = START_TIMEOUT_S,
               log: Callable[[str], None] = print, threads: int | None = None,
               loops: int | None = None, lod: bool | None = None,
               tick_budget: float | None = None, contact_friction: str | None = None) -> dict:
    """Run cloth_node, replay `bag` into it and time each pose against the marker that
    covered it (module docstring). `run_node_bench` takes the same options as one
    NodeBenchOptions.

    Args:
        bag: a pose bag folder or a bundled bag name.
        particles: about this many cloth particles, or "auto" (None: the scene's own).
        scene: a body scene (config/<scene>.yaml or a params .yaml).
        rate: replay speed factor (1: the bag's own pace), or one factor per pass of the bag
            (a stream that slows down: [1, 1, 1, 0.3]).
        loops: replay the bag this many times in a row, stamps moving on with each pass (a
            long clip; the body walks back to its start between passes, which the node
            takes as a teleport); None: one pass per rate given.
        lod: the node's `lod` parameter (None: the scene's).
        tick_budget: the node's `tick_budget` parameter (None: the scene's).
        contact_friction: the node's `contact_friction` parameter (None: the scene's).
        messages: replay only the first this many pose messages (None: all).
        domain_id: the ROS domain of both processes (None: a free one, `open_ros_side`).
        node_log: where the node's output goes (None: a temporary file).
        start_timeout_s: wait at most this long for the node to subscribe, s.
        log: where progress lines go.
        threads: the node's solver threads (None: the scene's, by default every core).

    Returns:
        {"particles" (asked for, or the scene's), "garment_particles", "scene", "bag", "rate",
        "messages" (pose messages sent), "poses_received" (by this process), "markers"
        (received), "lost", "latency_ms": {"p50", "p95", "max"}, "service_ms", "queue_ms",
        "dress_latency_ms", "latency_thirds", "per_pose", "step_ms_p50", "step_ms_p95",
        "solve_ms_p50", "marker_ms_p50", "ticks", "ticks_series": [[s, step ms, poses,
        particles]],
        "node_poses_received", "poses_used", "poses_coalesced", "dropped", "pending",
        "lag_ms": {...}, "pose_interval_ms", "keeps_up", "node_exit", "domain_id", "host",
        "passes": [{"pass", "rate", "poses", "latency_ms", "level", "particles", "step_ms_p50",
        "budget_ms"}], "lod": {"switches", "levels": [[s, level, particles]] at each change,
        "final_level", "lowest_level"}, "latency_second_half_p95", "last_pose_latency_ms"};
        times in ms. ClothInputError for bad arguments or a failed replay, NodeError when the
        node fails.
    """
    return run_node_bench(NodeBenchOptions(bag, particles, scene, rate, messages, domain_id,
                                           node_log, start_timeout_s, threads, loops, lod,
                                           tick_budget, contact_friction), log)


def run_node_bench(opts: NodeBenchOptions, log: Callable[[str], None] = print) -> dict:
    """`bench_node` with its options in one object: check them, run the node and the replay,
    and work out the figures."""
    log = locked_log(log)
    plan = _plan(opts)
    with tempfile.TemporaryDirectory(prefix="cloth_bench_node_") as tmp:
        rec = _record_run(plan, tmp, log)
    return _node_figures(plan, rec)


def _plan(opts: NodeBenchOptions) -> _Plan:
    """Check the options before anything starts; ClothInputError names the bad one."""
    rate, particles, loops = opts.rate, opts.particles, opts.loops
    rates = list(rate) if isinstance(rate, Sequence) else [rate]
    if not rates:
        raise ClothInputError("--rate must list at least one replay speed factor")
    for r in rates[1:]:
        check_rate(r)
    if opts.threads is not None:
        resolve_threads(opts.threads)  # before a node starts with a count it would refuse
    params = check_run_args(particles if isinstance(particles, int) else 100,
                            rates[0] if rates else None, opts.messages, opts.scene,
                            "--messages", "bench node")
    if particles is not None and not isinstance(particles, int) and particles != "auto":
        raise ClothInputError(f"--particles must be an integer or 'auto', got {particles!r}")
    passes = len(rates) if loops is None else loops
    if isinstance(passes, bool) or not isinstance(passes, int) or not 1 <= passes <= 100:
        raise ClothInputError(f"--loops must be an integer in 1..100, got {loops!r}")
    if opts.tick_budget is not None:
        check("tick_budget", opts.tick_budget, "--tick-budget")
    if opts.contact_friction is not None:
        check("contact_friction", opts.contact_friction, "--contact-friction")
    if particles is None:  # the scene's own: a number, or 'auto' (the node chooses)
        particles = params.particles
    topic = absolute_topic(params.topic)
    bag_path = resolve_bag(opts.bag)
    if opts.domain_id is not None:
        check_domain_id(opts.domain_id)
    return _Plan(opts, params, rates, passes, particles, topic, bag_path)


def _record_run(plan: _Plan, tmp: str, log: Callable[[str], None]) -> _Recorded:
    """Start cloth_node, replay the bag into it from a thread and record what comes back
    until a marker covers the newest pose (or nothing comes for IDLE_TIMEOUT_S); stop the
    replay and the node (also on errors). NodeError when the node does not exit cleanly."""
    opts, topic = plan.opts, plan.topic
    play = (plan.bag_path if opts.messages is None
            else first_messages_bag(plan.bag_path, opts.messages, tmp, topic))
    types, per_pass, t_first, t_last = bag_topics(play)
    if topic not in types:
        raise ClothInputError(f"{play}: no topic {topic!r} in the bag")
    log_path = Path(opts.node_log) if opts.node_log is not None else Path(tmp) / "node.log"
    rec = _Recorded(per_pass=per_pass, t_first=t_first, t_last=t_last)
    side = open_ros_side(opts.domain_id, "cloth_bench_node", log)
    rec.domain_id = side.domain_id
    replay: _ReplayThread | None = None
    node = None
    try:
        log(f"bench node: cloth_node, scene {plan.params.scene} (~{plan.particles} "
            f"particles, solver {plan.params.solver}), {per_pass * plan.passes} messages "
            f"of {play} ({plan.passes} pass{'es' if plan.passes > 1 else ''}) at rate "
            f"{','.join(f'{r:g}' for r in plan.rates)}, ROS domain {rec.domain_id}")
        _subscribe(side, topic, rec)
        node = NodeProcess(scene_path(opts.scene), _node_overrides(plan),
                           child_env(rec.domain_id), log_path)
        start_s = wait_for_node(side, node, topic, opts.start_timeout_s, also=lambda: (
            side.has_endpoint(MARKER_TOPIC, NODE_NAME, False)))
        side.spin_until(lambda: False, SETTLE_S)
        log(f"bench node: cloth_node up after {start_s:.1f} s; replaying")
        replay = _ReplayThread(play, plan, side, log)
        side.spin_until(_covered_or_idle(replay, rec), float("inf"), node, "while simulating")
        side.spin_until(lambda: len(rec.stats_raw) >= len(rec.markers), 2.0)
    finally:
        if replay is not None:
            replay.stop.set()
            replay.thread.join(timeout=15.0)
        rec.node_exit = node.stop() if node is not None else -1
        side.close()
    if rec.node_exit != 0:
        raise NodeError(f"cloth_node did not exit cleanly after SIGINT (status "
                        f"{rec.node_exit}); the last lines of its log ({log_path}):\n"
                        f"{node.tail()}")
    rec.sent = replay.stats[0].messages
    return rec


def _subscribe(side, topic: str, rec: _Recorded) -> None:
    """Raw subscriptions (the CDR bytes, no message objects) to the poses on `topic`, the
    markers and the statuses, each message kept in `rec` with its receive time."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray
    from visualization_msgs.msg import Marker


    qos = reliable_qos()
    side.node.create_subscription(
        PoseArray, topic, lambda d: rec.poses.append((time.monotonic(), header_stamp_ns(d))),
        qos, raw=True)
    side.node.create_subscription(
        Marker, MARKER_TOPIC, lambda d: rec.markers.append((time.monotonic(),
                                                            header_stamp_ns(d))),
        qos, raw=True)
    side.node.create_subscription(
        DiagnosticArray, STATS_TOPIC,
        lambda d: rec.stats_raw.append((time.monotonic(), d)), qos, raw=True)


def _node_overrides(plan: _Plan) -> list[str]:
    """The node's `name:=value` parameters beyond the scene's params file."""
    opts = plan.opts
    extra = [] if plan.particles == "auto" else [f"particles:={plan.particles}"]
    if opts.threads is not None:
        extra.append(f"threads:={opts.threads}")
    if opts.lod is not None:
        extra.append(f"lod:={'true' if opts.lod else 'false'}")
    if opts.tick_budget is not None:
        extra.append(f"tick_budget:={float(opts.tick_budget)!r}")
    if opts.contact_friction is not None:
        extra.append(f"contact_friction:={opts.contact_friction}")
    return extra


class _ReplayThread:
    """`replay_bag` of the run's bag, every pass at its rate, in a thread of this process on
    the benchmark's context (module docstring); `stats` gets its ReplayStats, `errors` what
    it raised, for the main thread. Set `stop` to end it early."""

    def __init__(self, play: Path, plan: _Plan, side, log: Callable[[str], None]) -> None:
        self.stop = threading.Event()
        self.stats: list = []
        self.errors: list[BaseException] = []

        def run() -> None:
            try:
                self.stats.append(replay_bag(play, rate=plan.rates, topics=[plan.topic],
                                             loop=plan.passes > 1, max_loops=plan.passes,
                                             context=side.ctx, wait_s=30.0,
                                             settle_s=SETTLE_S, stop=self.stop,
                                             node_name="cloth_bench_replay", log=log))
            except BaseException as exc:  # noqa: BLE001 - reported below
                self.errors.append(exc)

        self.thread = threading.Thread(target=run, name="cloth_bench_replay", daemon=True)
        self.thread.start()


def _covered_or_idle(replay: _ReplayThread, rec: _Recorded) -> Callable[[], bool]:
    """done() for `spin_until`: the replay has ended and the newest marker covers the newest
    pose, or no marker came for IDLE_TIMEOUT_S. Raises the replay's error, or
    ClothInputError when it runs over REPLAY_TIMEOUT_S."""
    t0 = time.monotonic()
    last = [time.monotonic(), 0]

    def done() -> bool:
        now = time.monotonic()
        if len(rec.markers) != last[1]:
            last[:] = [now, len(rec.markers)]
        if replay.thread.is_alive():
            if now - t0 > REPLAY_TIMEOUT_S:
                raise ClothInputError(f"the replay took over {REPLAY_TIMEOUT_S:g} s")
            return False
        if replay.errors:
            raise replay.errors[0]
        newest = max((st for _, st in rec.poses), default=None)
        return ((newest is not None and rec.markers and rec.markers[-1][1] >= newest)
                or now - last[0] > IDLE_TIMEOUT_S)

    return done


def _node_figures(plan: _Plan, rec: _Recorded) -> dict:
    """bench_node's result (see there) from what the run recorded."""
    rates, passes, poses, markers = plan.rates, plan.passes, rec.poses, rec.markers
    sent = rec.sent
    values = stats_values(rec.stats_raw)
    ticks_stamped = [(t, st, v) for t, st, v in values if int(v.get("substeps", "0")) > 0]
    ticks = [(t, v) for t, _, v in ticks_stamped]
    not_ticks = {stamp for _, stamp, v in values if int(v.get("substeps", "0")) == 0}
    figures = latency_figures(poses, markers, not_ticks)
    steps = percentiles([float(v["step_ms"]) for _, v in ticks])
    last_values = values[-1][2] if values else {}

    def counter(key: str) -> int:
        return int(last_values.get(key, "0"))

    interval_ms = (1e3 * (rec.t_last - rec.t_first) * 1e-9 / max(rec.per_pass - 1, 1)
                   / rates[0])
    t_start = poses[0][0] if poses else 0.0
    thirds = figures["latency_thirds"]
    result = {
        "particles": plan.particles, "loops": passes, "rates": [float(r) for r in rates],
        "garment_particles": int(last_values.get("particles", 0)),
        "scene": plan.params.scene, "bag": recorded_path(plan.bag_path), "rate": float(rates[0]),
        "messages": sent, "poses_received": len(poses), "markers": len(markers),
        "lost": max(sent - counter("poses_received"), 0),
        "latency_ms": figures["latency_ms"], "service_ms": figures["service_ms"],
        "queue_ms": figures["queue_ms"], "dress_latency_ms": figures["dress_latency_ms"],
        "latency_thirds": thirds, "per_pose": figures["per_pose"],
        "during_dressing": figures["during_dressing"],
        "dressing_latency_ms": figures["dressing_latency_ms"],
        "uncovered": figures["uncovered"],
        "step_ms_p50": steps["p50"], "step_ms_p95": steps["p95"],
        "solve_ms_p50": median([float(v["solve_ms"]) for _, v in ticks]),
        "marker_ms_p50": median([float(v["marker_ms"]) for _, v in ticks]),
        "ticks": len(ticks),
        "ticks_series": [[round(t - t_start, 4), float(v["step_ms"]),
                          int(v.get("tick_poses", "1")), int(v.get("particles", "0"))]
                         for t, v in ticks],
        "node_poses_received": counter("poses_received"),
        "poses_used": counter("poses_used"), "poses_coalesced": counter("poses_coalesced"),
        "dropped": counter("dropped"), "pending": counter("poses_pending"),
        "lag_ms": percentiles([float(v.get("lag_ms", "nan")) for _, v in ticks]),
        "threads": plan.opts.threads, "pose_interval_ms": interval_ms,
        "contact_friction": plan.opts.contact_friction or plan.params.contact_friction,
        "node_exit": rec.node_exit, "domain_id": rec.domain_id,
        "host": {"machine": platform.machine(), "cpus": os.cpu_count(),
                 "python": platform.python_version()},
    }
    result.update(lod_figures(ticks_stamped, t_start))
    result["passes"] = pass_figures(figures, ticks_stamped, rates, passes, rec.t_first,
                                     rec.t_last, rec.per_pass)
    result["latency_second_half_p95"] = figures["latency_second_half_p95"]
    result["last_pose_latency_ms"] = figures["last_pose_latency_ms"]
    result["keeps_up"] = bool(
        result["lost"] == 0 and result["dropped"] == 0 and figures["uncovered"] == 0
        and thirds["growth"] is not None and thirds["growth"] <= GROWTH_LIMIT)
    return result








