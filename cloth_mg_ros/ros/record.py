"""Record topics into a rosbag2 bag (MCAP by default) with rosbags, as received.

    cloth-mg record out/run1 --topics /cloth/marker /cloth/stats --duration 10
    cloth-mg record out/run2 --topics /cloth/marker          # until Ctrl-C

Each topic is subscribed to as soon as it appears in the ROS graph (its type is taken from
there), with a raw subscription: the serialised CDR bytes are written to the bag unchanged,
stamped with the time of receipt (ns since the epoch, the node's clock), as `ros2 bag record`
does. The QoS follows the publishers: reliable when every publisher of the topic is reliable,
best effort otherwise (a reliable reader does not match a best-effort writer); keep-last 100,
volatile. Recording stops after `duration` seconds, when `stop` is set, or on Ctrl-C (the
command line turns SIGINT and SIGTERM into that); the bag is then closed, which writes
metadata.yaml, so `ros2 bag info` and rosbags read it.

Message types must be known to the ROS 2 Jazzy type store of rosbags (all the standard
message packages are) and importable here; a topic whose type is not is skipped with a
warning. Topics that never appeared are reported in the result.
"""

from __future__ import annotations

import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import jazzy_typestore
from cloth_mg_ros.io.topic_names import is_absolute_topic
from cloth_mg_ros.ros.replay import message_class, reliable_qos

__all__ = ["RecordStats", "record_topics"]

STORAGES = ("mcap", "sqlite3")
DISCOVERY_PERIOD_S = 0.2  # s between looks at the ROS graph for topics not yet subscribed


@dataclass
class RecordStats:
    """What a recording holds: the bag path, messages per topic, the recording time (s),
    topics never seen and topics skipped (with the reason)."""

    path: Path
    per_topic: Counter = field(default_factory=Counter)
    duration_s: float = 0.0
    missing: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

    @property
    def messages(self) -> int:
        return sum(self.per_topic.values())


def _qos_for(node, topic: str):
    """Reliable keep-last 100 unless a publisher of `topic` offers only best effort."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.qos import ReliabilityPolicy


    qos = reliable_qos()
    infos = node.get_publishers_info_by_topic(topic)
    if any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos):
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    return qos


def record_topics(out: str | os.PathLike, topics: Sequence[str], *,
                  duration: float | None = None, context=None,
                  stop: threading.Event | None = None, storage: str = "mcap",
                  node_name: str = "cloth_record", log=print,
                  on_message: Callable[[str, bytes], None] | None = None) -> RecordStats:
    """Record `topics` into a new bag at `out`; see the module docstring.

    Args:
        out: the bag folder to create (must not exist; its parent is created).
        topics: absolute topic names.
        duration: stop after this many seconds (None: until `stop` or Ctrl-C).
        context: the rclpy Context to use (initialised); None: the default context.
        stop: set it to stop early.
        storage: 'mcap' (the Jazzy default) or 'sqlite3'.
        node_name: name of the recorder's node.
        log: where progress lines go (a callable taking one str).
        on_message: called with (topic, serialised bytes) in the recorder's thread once each
            message is written (a caller waits on it for the messages it needs in the bag).

    Returns:
        RecordStats. Raises ClothInputError for an existing output, no or relative topic
        names, a bad duration or storage.
    """
    # imported here: rclpy (the ROS side), loaded only when needed
    import rclpy

    from cloth_mg_ros.ros.executor import single_threaded_executor

    path = _checked_output(out, topics, duration, storage)
    path.parent.mkdir(parents=True, exist_ok=True)
    stats = RecordStats(path)
    store = jazzy_typestore()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    node = rclpy.create_node(node_name, context=context)
    executor = single_threaded_executor(node.context)
    executor.add_node(node)
    writer = Writer(path, version=9, storage_plugin=plugin)
    writer.open()
    rec = _Subscriber(node, writer, store, stats, list(dict.fromkeys(topics)), log,
                      on_message)
    start = time.monotonic()
    try:
        log(f"record: {', '.join(rec.pending)} into {path}"
            + (f" for {duration:g} s" if duration else " until Ctrl-C"))
        _spin(executor, rec, start, duration, stop)
    except KeyboardInterrupt:
        pass  # Ctrl-C (or SIGTERM, from the command line) is the normal way to stop
    finally:
        stats.duration_s = time.monotonic() - start
        stats.missing = rec.pending
        writer.close()  # writes metadata.yaml
        executor.shutdown(timeout_sec=0.0)
        node.destroy_node()
    log(f"record: wrote {stats.messages} messages in {stats.duration_s:.1f} s to {path} ("
        + ", ".join(f"{t}: {n}" for t, n in sorted(stats.per_topic.items()))
        + (f"; never seen: {', '.join(stats.missing)}" if stats.missing else "") + ")")
    return stats


def _checked_output(out: str | os.PathLike, topics: Sequence[str], duration: float | None,
                    storage: str) -> Path:
    """The bag's path, once record_topics' options are checked (ClothInputError)."""
    path = Path(out)
    if not topics:
        raise ClothInputError("record: name at least one topic (--topics /cloth/marker ...)")
    bad = [t for t in topics if not is_absolute_topic(t)]
    if bad:
        raise ClothInputError(f"record: {bad[0]!r} is not an absolute ROS topic name ('/', then "
                              f"/-separated parts of letters, digits and _; several topics "
                              f"are separate arguments: --topics /a /b)")
    if duration is not None and not (duration > 0):
        raise ClothInputError(f"record: --duration must be positive seconds, got {duration!r}")
    if storage not in STORAGES:
        raise ClothInputError(f"record: storage must be one of {', '.join(STORAGES)}, got "
                              f"{storage!r}")
    if path.exists():
        raise ClothInputError(f"record: {path} exists already")
    return path


class _Subscriber:
    """Subscribes the recorder's node to each `pending` topic once it appears in the graph,
    every message written to the bag (`writer`, types from the rosbags type `store`) as
    received."""

    def __init__(self, node, writer, store, stats: RecordStats, pending: list[str],
                 log, on_message: Callable[[str, bytes], None] | None = None) -> None:
        self.node, self.writer, self.store = node, writer, store
        self.stats, self.pending, self.log = stats, pending, log
        self.on_message = on_message
        self.clock = node.get_clock()

    def look(self) -> None:
        """Subscribe to the pending topics that are in the graph now (a topic whose type
        rosbags or this Python does not know is skipped)."""
        graph = dict(self.node.get_topic_names_and_types())
        for topic in [t for t in self.pending if t in graph]:
            self.pending.remove(topic)
            msgtype = graph[topic][0]
            try:
                if msgtype not in self.store.types:
                    raise ClothInputError(f"type {msgtype} is not in the rosbags "
                                          f"ROS 2 Jazzy type store")
                cls = message_class(msgtype)
            except ClothInputError as exc:
                self.stats.skipped[topic] = str(exc)
                self.log(f"record: skipping {topic}: {exc}")
                continue
            self._subscribe(topic, msgtype, cls)

    def _subscribe(self, topic: str, msgtype: str, cls: type) -> None:
        conn = self.writer.add_connection(topic, msgtype, typestore=self.store)
        writer, clock, stats, on_message = self.writer, self.clock, self.stats, self.on_message

        def write(data: bytes, conn=conn, topic=topic) -> None:
            writer.write(conn, clock.now().nanoseconds, data)
            stats.per_topic[topic] += 1
            if on_message is not None:
                on_message(topic, data)

        self.node.create_subscription(cls, topic, write, _qos_for(self.node, topic), raw=True)
        self.log(f"record: subscribed to {topic} [{msgtype}]")


def _spin(executor, rec: _Subscriber, start: float, duration: float | None,
          stop: threading.Event | None) -> None:
    """Spin the recorder's node from `start` (s, monotonic) until `duration`, `stop` or the
    context's end, looking for the pending topics every DISCOVERY_PERIOD_S."""
    next_look = start
    while not (stop is not None and stop.is_set()) and rec.node.context.ok():
        now = time.monotonic()
        if duration is not None and now - start >= duration:
            break
        if rec.pending and now >= next_look:
            next_look = now + DISCOVERY_PERIOD_S
            rec.look()
        wait = 0.05 if duration is None else min(0.05, max(duration - (now - start), 0.0))
        executor.spin_once(timeout_sec=wait)
