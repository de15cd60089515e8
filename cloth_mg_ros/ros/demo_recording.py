"""A recorded cloth bag read back, tabulated and drawn; pose bags cut to their first messages.

- `read_cloth_bag`: the `/cloth/marker` and `/cloth/stats` messages that `cloth-mg demo`
  recorded from cloth_node, as a `ClothRecording` (triangle corners and status values);
- `stats_rows` and `format_table`: one row of figures per status, printed as a text table;
- `render_recording`: frames.png, a strip of recorded cloth frames with the avatar's capsules;
- `header_stamp_ns`: the header stamp of a serialised message, without deserialising it;
- `first_messages_bag`: a pose bag of the first N PoseArrays of another.

Used by `cloth_mg_ros.ros.demo` and `cloth_mg_ros.bench.node_latency`.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import (
    jazzy_typestore,
    open_reader,
    read_pose_frames,
    resolve_bag,
    write_pose_bag,
)
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.ros.processes import MARKER_TOPIC, POSE_TOPIC, STATS_TOPIC

__all__ = [
    "ClothRecording",
    "first_messages_bag",
    "format_table",
    "header_stamp_ns",
    "read_cloth_bag",
    "render_recording",
    "stats_rows",
]

LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


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
    store = jazzy_typestore()
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
    # imported here: matplotlib (charts), loaded only when needed
    from cloth_mg_ros.io.render import render_frames

    if not rec.markers:
        raise ValueError("no markers to draw")
    picks = sorted(set(np.linspace(0, len(rec.markers) - 1, max(1, n_frames))
                       .round().astype(int).tolist()))
    t0 = rec.markers[0][0]
    frames, capsules = [], []
    avatar = None
    if poses:

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

