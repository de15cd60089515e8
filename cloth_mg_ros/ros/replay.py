"""Play a rosbag2 bag on its topics, paced by its timestamps (what `ros2 bag play` does).

    cloth-mg replay bags/walk                  # a bag folder (or a bundled bag name: walk)
    cloth-mg replay walk --rate 0.5 --loop     # half speed, over and over until Ctrl-C
    cloth-mg replay my_bag --topic /avatar/body_poses --wait 60

Every message of the selected topics (default: all the bag holds, whatever their type, as long
as the message package is importable here) is published as the bag stores it: rosbags reads
the serialised CDR bytes and rclpy publishes them unchanged (`publisher.publish(bytes)`), so
no message is ever converted. Publishers are reliable, keep-last 100, volatile.

Pacing: message k goes out at start + (t_k - t_0) / rate seconds of wall time, t the bag's
receive timestamps (for the project's pose bags equal to the header stamps). Before the first
message the player waits until at least one subscriber has matched one of its publishers
(`wait_s`, default 30 s; then ClothInputError), and then `settle_s` more (default 0.5 s) so
the subscriber's side of the discovery completes too: a reliable, volatile reader can miss
samples written before it has matched the writer. At the end it waits (up to 10 s) until every
subscriber has acknowledged every message, so nothing is lost when the process exits.

Looping: unlike `ros2 bag play --loop`, each further pass is shifted in time: receive times
and the header.stamp of every message type that starts with a std_msgs/Header advance by the
bag's span plus one mean message interval per pass, so a consumer that checks that stamps
advance (cloth_node does) keeps going; the body walks back to its start, which cloth_node
treats as a teleport (the garment is carried along).
"""

from __future__ import annotations

import importlib
import os
import struct
import threading
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import absolute_topic, jazzy_typestore, open_reader, resolve_bag
from cloth_mg_ros.io.topic_names import is_absolute_topic

__all__ = ["ReplayStats", "bag_topics", "message_class", "reliable_qos", "replay_bag"]

WAIT_S = 30.0  # default wait for a first matched subscriber, s
SETTLE_S = 0.5  # default pause after the first match, s
LINGER_S = 0.5  # s after the last message while best-effort subscribers take it
ACK_TIMEOUT_S = 10.0  # wait at most this long for subscribers to acknowledge the last messages
HEADER = "std_msgs/msg/Header"


@dataclass
class ReplayStats:
    """What a replay published: messages per topic, passes, wall time (s), lateness (s)."""

    messages: int = 0
    per_topic: Counter = field(default_factory=Counter)
    loops: int = 0
    wall_s: float = 0.0
    max_late_s: float = 0.0
    skipped_topics: dict[str, str] = field(default_factory=dict)


def reliable_qos(depth: int = 100):
    """Reliable, keep-last `depth`, volatile: the QoS of cloth_node's topics."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=depth)


def message_class(msgtype: str) -> type:
    """The Python class of a ROS message type name 'pkg/msg/Name' (imports pkg.msg).

    Raises ClothInputError when the package is not installed here."""
    parts = msgtype.split("/")
    if len(parts) != 3:
        raise ClothInputError(f"message type {msgtype!r} is not of the form pkg/msg/Name")
    try:
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError):
        raise ClothInputError(f"message type {msgtype}: its Python package {parts[0]} is not "
                              f"installed here") from None


def _has_header(msgtype: str) -> bool:
    """Whether a message type's first field is a std_msgs/Header (ROS 2 Jazzy typestore)."""
    try:
        fields = jazzy_typestore().fielddefs[msgtype][1]
    except KeyError:
        return False
    return bool(fields) and fields[0][1][1] == HEADER


def _shift_stamp(data: bytes, shift_ns: int) -> bytes:
    """CDR bytes of a message that starts with a Header, its header.stamp moved by shift_ns.

    The stamp is the first member: int32 sec at byte 4, uint32 nanosec at byte 8 (after the
    encapsulation header); only little-endian plain CDR (what Fast DDS writes) is patched.
    """
    if len(data) < 12 or data[:2] != b"\x00\x01":
        return data
    sec, nanosec = struct.unpack_from("<iI", data, 4)
    total = sec * 1_000_000_000 + nanosec + shift_ns
    out = bytearray(data)
    struct.pack_into("<iI", out, 4, total // 1_000_000_000, total % 1_000_000_000)
    return bytes(out)


def _messages(bag: Path, topics: set[str]) -> Iterator[tuple[str, int, bytes]]:
    """(topic, receive time ns, CDR bytes) of the selected topics, in bag order."""
    reader = open_reader(bag)
    try:
        conns = [c for c in reader.connections if c.topic in topics]
        for conn, t, raw in reader.messages(connections=conns):
            yield conn.topic, int(t), raw if isinstance(raw, bytes) else bytes(raw)
    finally:
        reader.close()


def bag_topics(bag: Path) -> tuple[dict[str, str], int, int, int]:
    """({topic: type}, message count, first and last receive time in ns) of a bag."""
    reader = open_reader(bag)
    try:
        types = {name: info.msgtype for name, info in reader.topics.items()}
        count = int(reader.message_count)
        return types, count, int(reader.start_time), int(reader.end_time)
    finally:
        reader.close()


def replay_bag(bag: str | os.PathLike, *, rate: float | Sequence[float] = 1.0,
               loop: bool = False, topics: Sequence[str] | None = None, wait_s: float = WAIT_S,
               settle_s: float = SETTLE_S, context=None, max_loops: int | None = None,
               stop: threading.Event | None = None, node_name: str = "cloth_replay",
               log=print, clock: bool = False, namespace: str = "",
               topic_out: str | None = None) -> ReplayStats:
    """Publish a bag's messages on their topics, paced by their timestamps; see the module
    docstring.

    Args:
        bag: a bag folder or file, or a bundled bag name.
        rate: playback speed factor (> 0; 2 = twice as fast), or one factor per pass (a
            stream that slows down or speeds up; passes beyond the list keep its last).
        loop: play again and again (until `stop`, Ctrl-C or `max_loops` passes).
        topics: only these topics (default: every topic whose message type is importable).
        wait_s: wait at most this long (s) for a first matched subscriber; 0: do not wait.
        settle_s: pause after the first match, s.
        context: the rclpy Context to use (initialised); None: the default context (must be
            initialised by the caller).
        max_loops: with loop, stop after this many passes.
        stop: set it to stop early (checked between messages).
        node_name: name of the player's node.
        log: where progress lines go (a callable taking one str).
        clock: also publish the bag's time on /clock (rosgraph_msgs/Clock) before each
            message, as `ros2 bag play --clock` does, for nodes with use_sim_time.
        namespace: publish each topic under this namespace ('/alice': /avatar/body_poses goes
            out on /alice/avatar/body_poses), for a node started in that namespace; /clock
            stays global, as nodes look for it there.
        topic_out: publish the one topic played (the bag's only one, or one of `topics`) on
            this name instead, for a node listening there (relative: under `namespace`).

    Returns:
        ReplayStats. Raises ClothInputError for a missing or unreadable bag, an unknown topic,
        a bad rate, or no subscriber within `wait_s`.
    """
    # imported here: rclpy (the ROS side), loaded only when needed
    import rclpy

    stats = ReplayStats()
    plan = _replay_plan(bag, rate, topics, wait_s, settle_s, stats, log)
    out_name = _played_names(plan, _namespaced(namespace, topic_out, plan))
    node = rclpy.create_node(node_name, context=context)
    try:
        pubs, clock_pub = _publishers(node, plan, out_name, clock)
        if wait_s > 0:
            _wait_for_subscriber(pubs, wait_s, stop)
            time.sleep(settle_s)
        log(f"replay: {plan.path} ({plan.count} messages, {plan.span_ns * 1e-9:.2f} s) on "
            f"{', '.join(sorted(out_name(t) for t in pubs))} at rate "
            f"{','.join(f'{r:g}' for r in plan.rates)}{', looping' if loop else ''}")
        start = time.monotonic()
        _Player(plan, pubs, clock_pub, stop, stats).play(start, loop, max_loops)
        _let_readers_catch_up(node, pubs)
        stats.wall_s = time.monotonic() - start
        log(f"replay: published {stats.messages} messages in {stats.wall_s:.2f} s "
            f"({stats.loops} pass{'es' if stats.loops != 1 else ''}; "
            + ", ".join(f"{t}: {n}" for t, n in sorted(stats.per_topic.items())) + ")")
        return stats
    finally:
        node.destroy_node()


@dataclass(frozen=True)
class _ReplayPlan:
    """What a replay plays: the bag, the rate of each pass, its message count, the first
    receive time and the span (ns), the mean message interval (ns), the class of each topic
    to publish and the topics whose messages start with a Header."""

    path: Path
    rates: list
    count: int
    t_first: int
    span_ns: int
    gap_ns: int
    classes: dict[str, type]
    headers: set[str]


def _replay_plan(bag: str | os.PathLike, rate: float | Sequence[float],
                 topics: Sequence[str] | None, wait_s: float, settle_s: float,
                 stats: ReplayStats, log) -> _ReplayPlan:
    """Check replay_bag's options and the bag's topics (ClothInputError); topics whose
    message package is not installed here are skipped, in `stats` and the log."""
    rates = list(rate) if isinstance(rate, Sequence) else [rate]
    if not rates or not all(isinstance(r, (int, float)) and 0.0 < r < 1e6 for r in rates):
        raise ClothInputError(f"--rate must be a positive number, got {rate!r}")
    if wait_s < 0 or settle_s < 0:
        raise ClothInputError("--wait and --settle must not be negative")
    path = resolve_bag(bag)
    types, count, t_first, t_last = bag_topics(path)
    wanted = [absolute_topic(t) for t in topics] if topics else sorted(types)
    unknown = [t for t in wanted if t not in types]
    if unknown:
        listing = ", ".join(f"{n} [{m}]" for n, m in sorted(types.items())) or "none"
        raise ClothInputError(f"{path}: no topic {unknown[0]!r} in the bag (topics: {listing})")
    classes = {}
    for topic in wanted:
        try:
            classes[topic] = message_class(types[topic])
        except ClothInputError as exc:
            stats.skipped_topics[topic] = str(exc)
            log(f"replay: skipping {topic}: {exc}")
    if not classes:
        raise ClothInputError(f"{path}: none of the topics can be published here")
    headers = {t for t in classes if _has_header(types[t])}
    span_ns = max(t_last - t_first, 0)
    gap_ns = span_ns // max(count - 1, 1) if count > 1 else 1_000_000_000
    return _ReplayPlan(path, rates, count, t_first, span_ns, gap_ns, classes, headers)


@dataclass
class _Player:
    """Publishes a plan's messages on `pubs` (and the bag's time on `clock_pub`), pass after
    pass, into `stats`; `stop` ends it between messages."""

    plan: _ReplayPlan
    pubs: dict
    clock_pub: object | None
    stop: threading.Event | None
    stats: ReplayStats

    def stopped(self) -> bool:
        return self.stop is not None and self.stop.is_set()

    def play(self, start: float, loop: bool, max_loops: int | None) -> None:
        """Every pass from wall time `start` (s, monotonic): once, or with loop until
        `max_loops` passes (None: until stopped). Each pass is shifted by the bag's span
        plus one mean interval, in time and in the stamps."""
        plan = self.plan
        passes = 0
        origin = start  # wall time of the pass's first message, s
        while not self.stopped():
            pass_rate = plan.rates[min(passes, len(plan.rates) - 1)]
            self.play_pass(origin, passes * (plan.span_ns + plan.gap_ns), pass_rate)
            origin += (plan.span_ns + plan.gap_ns) * 1e-9 / pass_rate
            passes += 1
            self.stats.loops = passes
            if not loop or (max_loops is not None and passes >= max_loops):
                break

    def play_pass(self, origin: float, shift: int, rate: float) -> None:
        """One pass: each message at origin + (t - t_first) / rate (s), its receive time and
        header stamp moved by `shift` ns."""
        stats = self.stats
        for topic, t, data in _messages(self.plan.path, set(self.pubs)):
            if self.stopped():
                break
            due = origin + (t - self.plan.t_first) * 1e-9 / rate
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                stats.max_late_s = max(stats.max_late_s, -delay)
            if shift and topic in self.plan.headers:
                data = _shift_stamp(data, shift)
            if self.clock_pub is not None:
                _publish_clock(self.clock_pub, t + shift)
            self.pubs[topic].publish(data)
            stats.messages += 1
            stats.per_topic[topic] += 1


def _let_readers_catch_up(node, pubs: dict) -> None:
    """Wait (up to ACK_TIMEOUT_S) until every reliable reader has acknowledged every message,
    and LINGER_S more when a reader is best-effort."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.duration import Duration

    for pub in pubs.values():
        pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
    if _best_effort_readers(node, pubs):
        # Best-effort readers acknowledge nothing, and a Fast DDS reader that shares the
        # writer's memory loses the samples it has not taken yet when the writer goes:
        # stay a moment so that the last messages reach them.
        time.sleep(LINGER_S)


def _publishers(node, plan: _ReplayPlan, out_name, clock: bool) -> tuple[dict, object]:
    """({bag topic: publisher on out_name(topic)}, the /clock publisher or None)."""
    pubs = {t: node.create_publisher(cls, out_name(t), reliable_qos())
            for t, cls in plan.classes.items()}
    return pubs, _clock_publisher(node) if clock else None


def _played_names(plan: _ReplayPlan, out_name):
    """`out_name` (a bag topic's published name), once every topic of `plan` maps to a name
    ROS takes (ClothInputError naming the bag's topic: rclpy would raise as the publisher is
    made, with no word of the bag)."""
    bad = [t for t in plan.classes if not is_absolute_topic(out_name(t))]
    if bad:
        raise ClothInputError(f"{plan.path}: topic {bad[0]!r} is no valid ROS topic name; "
                              f"play it on another with --topic-out")
    return out_name


def _namespaced(namespace: str, topic_out: str | None = None,
                plan: _ReplayPlan | None = None):
    """A function mapping a bag's absolute topic into `namespace` ('' or '/': unchanged), or
    the one topic of `plan` to `topic_out` (relative: under `namespace`).

    Raises ClothInputError for a namespace or topic that is not a valid ROS name, or a
    topic_out with several topics to play."""
    ns = "/" + namespace.strip().strip("/") if namespace.strip().strip("/") else ""
    if ns and not is_absolute_topic(ns):
        raise ClothInputError(f"--namespace {namespace!r} is not a valid ROS namespace "
                              f"(letters, digits and _ in /-separated parts)")
    if topic_out is None:
        return lambda topic: ns + topic
    if plan is not None and len(plan.classes) != 1:
        raise ClothInputError(f"--topic-out needs one topic to play; {plan.path} has "
                              f"{', '.join(sorted(plan.classes))}: choose one with --topic")
    if not is_absolute_topic(topic_out if topic_out.startswith("/") else "/" + topic_out):
        raise ClothInputError(f"--topic-out {topic_out!r} is not a valid ROS topic name "
                              f"(letters, digits and _ in /-separated parts)")
    out = topic_out if topic_out.startswith("/") else f"{ns}/{topic_out}"
    return lambda topic: out


def _clock_publisher(node):
    """A rosgraph_msgs/Clock publisher on the global /clock."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from rosgraph_msgs.msg import Clock

    return node.create_publisher(Clock, "/clock", reliable_qos())


def _publish_clock(pub, stamp_ns: int) -> None:
    """One rosgraph_msgs/Clock at stamp_ns (bag time, ns)."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from rosgraph_msgs.msg import Clock

    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    pub.publish(msg)


def _best_effort_readers(node, pubs: dict) -> bool:
    """Whether any subscription on the topics of `pubs` is best-effort."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.qos import ReliabilityPolicy

    return any(info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
               for pub in pubs.values()
               for info in node.get_subscriptions_info_by_topic(pub.topic_name))


def _wait_for_subscriber(pubs: dict, wait_s: float, stop: threading.Event | None) -> None:
    """Return once a publisher in `pubs` has a matched subscriber; ClothInputError after
    `wait_s` seconds."""
    deadline = time.monotonic() + wait_s
    while not any(p.get_subscription_count() for p in pubs.values()):
        if stop is not None and stop.is_set():
            return
        if time.monotonic() > deadline:
            names = ", ".join(sorted(p.topic_name for p in pubs.values()))
            raise ClothInputError(f"no subscriber matched on {names} within "
                                  f"{wait_s:g} s (is the node running, on the same "
                                  f"ROS_DOMAIN_ID?); use --wait to wait longer, 0 not to wait")
        time.sleep(0.02)
