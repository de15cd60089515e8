"""`cloth-mg bench node`: cloth_node's latency over DDS, from pose received to marker received.

    cloth-mg bench node --bag walk --particles 1200 --json out/bench_node.json
    cloth-mg bench node --bag walk --particles 1200 --rate 0.3 --json out/bench_node_0.3.json

Two processes on one machine: cloth_node (`python -m cloth_mg_ros.ros.node`, the scene's
params file and `particles:=N`, a subprocess) and this benchmark, which replays the bag into it
(`replay_bag` in a thread, paced by the bag's stamps times `rate`) and subscribes raw (the CDR
bytes, no message objects) to both `/avatar/body_poses`, the replayed input, and
`/cloth/marker`, the node's output. Both processes use one ROS domain of their own
(`cloth_mg_ros.ros.demo.open_ros_side`) and localhost discovery.

Latency of a pose message = the time this process received the node's marker for it minus the
time this process received the pose, both `time.monotonic()` in this process (one clock).
The node stamps each marker with its pose message's header stamp, which matches the two. The
benchmark's pose subscription shares the replay's DDS participant, so it receives a pose
within a fraction of a millisecond of its publication; the figure is thus the pose's transport
to the node, the node's tick (or its wait in the queue) and the marker's transport back (a
1200-particle marker holds ~7000 points, ~170 KB). Only simulation ticks count in the
percentiles; the first message, on which the node dresses the garment, is reported on its own
(`dress_latency_ms`). (Replaying from a third process was tried: its new DDS participant was
sometimes discovered by one of the two subscribers a few hundred ms to seconds later than by
the other, and a replay starts once one subscriber has matched, so one side lost the first
messages. In this process the replay's writer matches the node's reader, already discovered,
at once.)

Queueing: the replay sends at the bag's rate times `rate` (30 Hz for the bundled bags at rate
1). When a tick costs more than that interval, pose messages wait in the node's subscription
queue and the latency grows along the run: it then measures the backlog, not the node. The
report gives `service_ms` too: marker received minus the later of its pose received and the
previous marker received, i.e. the latency with the wait in the queue (`queue_ms`) taken out,
and says whether the node kept up (`keeps_up`: 95 % of the ticks waited less than one message
interval). Heavy ticks (many solver iterations) can exceed the interval even when the median
step does not, and then a backlog builds up. Use `--rate` to replay slower, at a pace the node
keeps up with, to see the latency without queueing; report both.

`lost` = pose messages sent minus markers received for them (0 when nothing was dropped: the
topics are reliable, keep-last 100, so a node more than 100 messages behind would drop the
oldest). The node's own figures come from its `/cloth/stats` (medians over the ticks).
"""

from __future__ import annotations

import os
import platform
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.demo import (
    IDLE_TIMEOUT_S,
    MARKER_TOPIC,
    NODE_NAME,
    START_TIMEOUT_S,
    STATS_TOPIC,
    NodeError,
    NodeProcess,
    check_domain_id,
    check_run_args,
    child_env,
    first_messages_bag,
    header_stamp_ns,
    locked_log,
    open_ros_side,
    wait_for_node,
)

__all__ = ["bench_node", "format_node_report", "latency_figures"]

SETTLE_S = 0.5  # after the node's topics appeared, before the replay starts, s
REPLAY_TIMEOUT_S = 600.0  # the replay of one bag at the slowest sensible rate, s


def _percentiles(values: list[float]) -> dict[str, float | None]:
    """{"p50", "p95", "max"} of `values` (ms), None when empty."""
    if not values:
        return {"p50": None, "p95": None, "max": None}
    a = np.asarray(values, dtype=float)
    return {"p50": float(np.percentile(a, 50)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max())}


def latency_figures(poses: list[tuple[float, int]], markers: list[tuple[float, int]],
                    not_ticks: set[int] = frozenset()) -> dict:
    """Match markers to pose messages by header stamp and time them.

    Args:
        poses: [(receive time s, stamp ns)] of the pose messages, in arrival order.
        markers: [(receive time s, stamp ns)] of the markers, in arrival order.
        not_ticks: stamps (ns) of messages that were no simulation tick (the dressing, a
            re-anchoring): left out of the percentiles.

    Returns:
        {"latency_ms": {"p50", "p95", "max"} over the ticks, "service_ms": {"p50", "p95",
        "max"} (latency less the wait behind the previous marker), "queue_ms": {...} (that
        wait: latency - service), "dress_latency_ms" (the first non-tick message's latency,
        or None), "matched": markers matched to a pose, "unmatched": markers without a pose
        of their stamp}.
    """
    received: dict[int, float] = {}
    for t, stamp in poses:
        received.setdefault(stamp, t)
    latency, service, queue = [], [], []
    dress = None
    matched = unmatched = 0
    prev_marker = -np.inf
    for t, stamp in markers:
        if stamp not in received:
            unmatched += 1
            prev_marker = t
            continue
        matched += 1
        lat = 1e3 * (t - received[stamp])
        if stamp in not_ticks:
            if dress is None:
                dress = lat
        else:
            latency.append(lat)
            service.append(1e3 * (t - max(received[stamp], prev_marker)))
            queue.append(lat - service[-1])
        prev_marker = t
    return {"latency_ms": _percentiles(latency), "service_ms": _percentiles(service),
            "queue_ms": _percentiles(queue), "dress_latency_ms": dress, "matched": matched,
            "unmatched": unmatched}


def _stats_values(raw: list[bytes]) -> list[tuple[int, dict[str, str]]]:
    """(stamp ns, {key: value}) of each recorded /cloth/stats status."""
    from diagnostic_msgs.msg import DiagnosticArray

    from cloth_mg_ros.ros.cdr import deserialize

    out = []
    for data in raw:
        msg = deserialize(data, DiagnosticArray)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        for st in msg.status:
            out.append((stamp, {kv.key: kv.value for kv in st.values}))
    return out


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def bench_node(bag: str | os.PathLike = "walk", particles: int = 1200,
               scene: str = "walking", rate: float = 1.0, messages: int | None = None,
               domain_id: int | None = None, node_log: str | os.PathLike | None = None,
               start_timeout_s: float = START_TIMEOUT_S,
               log: Callable[[str], None] = print) -> dict:
    """Run cloth_node, replay `bag` into it and time each marker against its pose (module
    docstring).

    Args:
        bag: a pose bag folder or a bundled bag name.
        particles: about this many cloth particles.
        scene: a body scene (config/<scene>.yaml or a params .yaml).
        rate: replay speed factor (1: the bag's own pace).
        messages: replay only the first this many pose messages (None: all).
        domain_id: the ROS domain of both processes (None: a free one, `open_ros_side`).
        node_log: where the node's output goes (None: a temporary file).
        start_timeout_s: wait at most this long for the node to subscribe, s.
        log: where progress lines go.

    Returns:
        {"particles" (asked for), "garment_particles", "scene", "bag", "rate", "messages"
        (pose messages sent), "poses_received", "markers" (received for those), "lost",
        "latency_ms": {"p50", "p95", "max"}, "service_ms": {...}, "dress_latency_ms",
        "queue_ms": {...}, "step_ms_p50", "step_ms_p95", "solve_ms_p50", "marker_ms_p50" (the
        node's, ms), "pose_interval_ms", "keeps_up", "node_exit", "domain_id", "host"}; times in ms.
        ClothInputError for bad arguments or a failed replay, NodeError when the node fails.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseArray
    from visualization_msgs.msg import Marker

    from cloth_mg_ros.ros.replay import bag_topics, reliable_qos, replay_bag, resolve_bag
    from cloth_mg_ros.scene_config import scene_path

    log = locked_log(log)
    params = check_run_args(particles, rate, messages, scene, "--messages", "bench node")
    topic = params["topic"]
    bag_path = resolve_bag(bag)
    if domain_id is not None:
        check_domain_id(domain_id)

    with tempfile.TemporaryDirectory(prefix="cloth_bench_node_") as tmp:
        play = bag_path if messages is None else first_messages_bag(bag_path, messages, tmp,
                                                                    topic)
        types, expected, t_first, t_last = bag_topics(play)
        if topic not in types:
            raise ClothInputError(f"{play}: no topic {topic!r} in the bag")
        log_path = Path(node_log) if node_log is not None else Path(tmp) / "node.log"
        poses: list[tuple[float, int]] = []
        markers: list[tuple[float, int]] = []
        stats_raw: list[bytes] = []
        side = open_ros_side(domain_id, "cloth_bench_node", log)
        domain = side.domain_id
        replay: threading.Thread | None = None
        stop_replay = threading.Event()
        replayed: list = []
        errors: list[BaseException] = []
        node = None
        try:
            log(f"bench node: cloth_node, scene {params['scene']} (~{particles} particles, "
                f"solver {params['solver']}), {expected} messages of {play} at rate {rate:g}, "
                f"ROS domain {domain}")
            qos = reliable_qos()
            side.node.create_subscription(
                PoseArray, topic, lambda d: poses.append((time.monotonic(),
                                                          header_stamp_ns(d))),
                qos, raw=True)
            side.node.create_subscription(
                Marker, MARKER_TOPIC, lambda d: markers.append((time.monotonic(),
                                                                header_stamp_ns(d))),
                qos, raw=True)
            side.node.create_subscription(DiagnosticArray, STATS_TOPIC, stats_raw.append,
                                          qos, raw=True)
            node = NodeProcess(scene_path(scene), [f"particles:={particles}"],
                               child_env(domain), log_path)
            start_s = wait_for_node(side, node, topic, start_timeout_s, also=lambda: (
                side.has_endpoint(MARKER_TOPIC, NODE_NAME, False)))
            side.spin_until(lambda: False, SETTLE_S)
            log(f"bench node: cloth_node up after {start_s:.1f} s; replaying")

            def run_replay() -> None:
                try:
                    replayed.append(replay_bag(play, rate=rate, topics=[topic],
                                               context=side.ctx, wait_s=30.0,
                                               settle_s=SETTLE_S, stop=stop_replay,
                                               node_name="cloth_bench_replay", log=log))
                except BaseException as exc:  # noqa: BLE001 - reported below
                    errors.append(exc)

            replay = threading.Thread(target=run_replay, name="cloth_bench_replay",
                                      daemon=True)
            replay.start()
            t0 = time.monotonic()
            last = [time.monotonic(), 0]

            def done() -> bool:
                now = time.monotonic()
                if len(markers) != last[1]:
                    last[:] = [now, len(markers)]
                if replay.is_alive():
                    if now - t0 > REPLAY_TIMEOUT_S:
                        raise ClothInputError(f"the replay took over {REPLAY_TIMEOUT_S:g} s")
                    return False
                if errors:
                    raise errors[0]
                return (len(markers) >= replayed[0].messages
                        or now - last[0] > IDLE_TIMEOUT_S)

            side.spin_until(done, float("inf"), node, "while simulating")
            side.spin_until(lambda: len(stats_raw) >= len(markers), 2.0)
        finally:
            stop_replay.set()
            if replay is not None:
                replay.join(timeout=15.0)
            node_exit = node.stop() if node is not None else -1
            side.close()
        if node_exit != 0:
            raise NodeError(f"cloth_node did not exit cleanly after SIGINT (status "
                            f"{node_exit}); the last lines of its log ({log_path}):\n"
                            f"{node.tail()}")

    sent = replayed[0].messages
    values = _stats_values(stats_raw)
    ticks = [v for _, v in values if int(v.get("substeps", "0")) > 0]
    not_ticks = {stamp for stamp, v in values if int(v.get("substeps", "0")) == 0}
    figures = latency_figures(poses, markers, not_ticks)
    steps = _percentiles([float(v["step_ms"]) for v in ticks])
    interval_ms = 1e3 * (t_last - t_first) * 1e-9 / max(expected - 1, 1) / rate
    result = {
        "particles": particles,
        "garment_particles": int(values[-1][1].get("particles", 0)) if values else 0,
        "scene": params["scene"], "bag": str(bag_path), "rate": float(rate),
        "messages": sent, "poses_received": len(poses), "markers": figures["matched"],
        "lost": max(sent - figures["matched"], 0),
        "latency_ms": figures["latency_ms"], "service_ms": figures["service_ms"],
        "queue_ms": figures["queue_ms"], "dress_latency_ms": figures["dress_latency_ms"],
        "step_ms_p50": steps["p50"], "step_ms_p95": steps["p95"],
        "solve_ms_p50": _median([float(v["solve_ms"]) for v in ticks]),
        "marker_ms_p50": _median([float(v["marker_ms"]) for v in ticks]),
        "ticks": len(ticks), "pose_interval_ms": interval_ms,
        "keeps_up": bool(figures["queue_ms"]["p95"] is not None
                         and figures["queue_ms"]["p95"] < interval_ms),
        "node_exit": node_exit, "domain_id": domain,
        "host": {"machine": platform.machine(), "cpus": os.cpu_count(),
                 "python": platform.python_version()},
    }
    return result


def format_node_report(r: dict) -> str:
    """The benchmark's figures as a few lines of text."""
    def ms(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f}"

    lat, svc = r["latency_ms"], r["service_ms"]
    lines = [
        (f"cloth_node, scene {r['scene']}: {r['garment_particles']} particles (asked "
         f"{r['particles']}), {r['messages']} pose messages from {r['bag']} at rate "
         f"{r['rate']:g} (one every {r['pose_interval_ms']:.1f} ms)"),
        (f"  markers received {r['markers']} of {r['messages']} (lost {r['lost']}); this "
         f"process received {r['poses_received']} poses"),
        (f"  latency pose received -> marker received, over {r['ticks']} ticks: p50 "
         f"{ms(lat['p50'])} ms, p95 {ms(lat['p95'])} ms, max {ms(lat['max'])} ms "
         f"(dressing message: {ms(r['dress_latency_ms'])} ms)"),
        (f"  without the wait in the queue (service): p50 {ms(svc['p50'])} ms, p95 "
         f"{ms(svc['p95'])} ms"),
        (f"  wait in the node's queue: p50 {ms(r['queue_ms']['p50'])} ms, p95 "
         f"{ms(r['queue_ms']['p95'])} ms"),
        (f"  node's own step: p50 {ms(r['step_ms_p50'])} ms, p95 {ms(r['step_ms_p95'])} ms "
         f"(median solve {ms(r['solve_ms_p50'])} ms, marker {ms(r['marker_ms_p50'])} ms)"),
    ]
    if r["keeps_up"]:
        lines.append("  the node kept up with the replay (95 % of the ticks waited less than "
                     "one message interval in its queue)")
    else:
        lines.append(f"  the node did not keep up with the replay (one message every "
                     f"{r['pose_interval_ms']:.1f} ms, its steps take up to "
                     f"{ms(r['step_ms_p95'])} ms at p95): the latency includes the wait in its "
                     f"queue; try --rate {_keep_up_rate(r):.2g} to measure it without")
    return "\n".join(lines)


def _keep_up_rate(r: dict) -> float:
    """A replay rate the node keeps up with: 80 % of the rate at which the interval between
    messages equals the p95 step."""
    step = r["step_ms_p95"] or r["step_ms_p50"] or 1.0
    return 0.8 * r["rate"] * r["pose_interval_ms"] / step
