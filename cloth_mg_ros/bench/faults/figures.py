"""The figures of `cloth-mg bench faults`, computed from what the benchmark sent and received.

Pure functions over plain lists (no ROS): the unit tests feed them synthetic streams.

- `Sent`, `Tick`, `Clear`, `Marks`: one published message, one /cloth/stats status, one
  DELETEALL, the times that bound a row (all times `time.monotonic()` of this process, s;
  stamps ns);
- `pose_latencies`: each valid pose's publication to the first marker (or status) stamped at
  or after it, ms;
- `expected_restarts`, `rung_figures`, `classify_clears`, `counter_delta`: what the node did;
- `stream_row`, `signal_row`: a row's figures; `check_row`: why it is not what the node should
  do (empty: ok); `describe_row`: what the node did, in words; `format_table`: the report.
"""

from __future__ import annotations

import bisect
from collections import Counter
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.io.text_table import text_table

__all__ = [
    "BAD_KINDS",
    "LOAD_ROWS",
    "RESTART_ROWS",
    "SIGNAL_ROWS",
    "VALID_KINDS",
    "Clear",
    "Marks",
    "Sent",
    "Tick",
    "check_row",
    "classify_clears",
    "counter_delta",
    "describe_row",
    "expected_restarts",
    "format_table",
    "rung_figures",
    "percentiles",
    "pose_latencies",
    "signal_row",
    "stream_row",
]

#: Kinds of sent message that carry a valid body pose the node should use (a reordered one:
#: valid, used when it still lies ahead of the simulated time, else skipped as stale).
VALID_KINDS = ("valid", "reordered")
#: Deliberately bad frames and the node's skip counter each must land in.
BAD_KINDS = {"nan": "non_finite", "empty": "empty", "wrong_count": "wrong_count",
             "stale": "stale", "duplicate": "stale"}
LOAD_ROWS = ("hog1", "hog2")
RESTART_ROWS = ("new_stream", "loop")
SIGNAL_ROWS = ("sigint", "sigterm")
MIN_FAULT_WINDOW_S = 1.0  # an instant fault (one stale pose, a burst) is judged over this, s
COVER_HORIZON_S = 10.0  # a pose's marker is looked for this long after its publication, s
RECOVERY_TARGET_S = 6.0  # back to level 0 within this after the load ends, s
MAX_SWITCHES = 4  # level switches a load row may make (down and up: 2)


class Sent(NamedTuple):
    """One message published on the pose topic: when (s, monotonic), its header stamp (ns),
    its time line (epoch: stamps within one only move on) and kind (VALID_KINDS or
    BAD_KINDS)."""

    t: float
    stamp_ns: int
    epoch: int
    kind: str


class Tick(NamedTuple):
    """One /cloth/stats status: received at t (s, monotonic), header stamp (ns), its message
    and key/value figures."""

    t: float
    stamp_ns: int
    message: str
    values: dict


class Clear(NamedTuple):
    """A DELETEALL received at t (s) on `topic` ('marker' or 'markers'), stamped (ns)."""

    t: float
    stamp_ns: int
    topic: str


class Marks(NamedTuple):
    """A row's times (s, monotonic): it began, its fault began and ended, its last pose was
    sent, and the node had simulated everything sent (`done`)."""

    row: float
    fault: float
    fault_end: float
    end: float
    done: float


def percentiles(values_ms: Sequence[float]) -> dict:
    """{"p50", "p95" (ms, None when empty), "n"} of `values_ms`."""
    if not len(values_ms):
        return {"p50": None, "p95": None, "n": 0}
    a = np.asarray(values_ms, dtype=float)
    return {"p50": float(np.percentile(a, 50)), "p95": float(np.percentile(a, 95)),
            "n": int(a.size)}


def pose_latencies(sent: Sequence[Sent], covers: Sequence[tuple[float, int]], t0: float,
                   t1: float) -> tuple[list[float], int]:
    """Latency (ms) of each valid pose published in [t0, t1): the first cover (a marker or a
    status: (receive time s, stamp ns), in arrival order) received after the pose's
    publication whose stamp lies at or after the pose's and within the pose's time line (at
    most the newest stamp sent on it: a marker of an older, later-stamped time line covers
    nothing of a new one). Returns (latencies, poses no cover reached within
    COVER_HORIZON_S)."""
    limit: dict[int, int] = {}
    for s in sent:
        limit[s.epoch] = max(limit.get(s.epoch, s.stamp_ns), s.stamp_ns)
    times = [t for t, _ in covers]
    out, uncovered = [], 0
    for s in sent:
        if s.kind not in VALID_KINDS or not t0 <= s.t < t1:
            continue
        k = bisect.bisect_left(times, s.t)
        while k < len(covers) and covers[k][0] - s.t <= COVER_HORIZON_S:
            if s.stamp_ns <= covers[k][1] <= limit[s.epoch]:
                out.append(1e3 * (covers[k][0] - s.t))
                break
            k += 1
        else:
            uncovered += 1
    return out, uncovered


def expected_restarts(sent: Sequence[Sent], t0: float, t1: float) -> int:
    """New time lines begun in [t0, t1) whose first stamp lies before the newest valid stamp
    sent so far: each should re-dress the garment once."""
    newest: int | None = None
    epoch: int | None = None
    count = 0
    for s in sent:
        if s.kind not in VALID_KINDS:
            continue
        if epoch is not None and s.epoch != epoch and t0 <= s.t < t1 and (
                newest is not None and s.stamp_ns < newest):
            count += 1
        epoch = s.epoch
        newest = s.stamp_ns if newest is None else max(newest, s.stamp_ns)
    return count


def counter_delta(before: dict, after: dict, key: str) -> int | None:
    """How much the node's counter `key` grew between two statuses' values. A `skipped_*`
    counter absent is 0 (the node lists a kind once it has counted one); any other absent
    key gives None (the node does not report it)."""
    if key.startswith("skipped_"):
        return int(after.get(key, 0)) - int(before.get(key, 0))
    if key not in after:
        return None
    return int(after[key]) - int(before.get(key, 0))


def rung_figures(ticks: Sequence[Tick], load0: float, load1: float) -> dict:
    """The level of detail around a load from load0 to load1 (s), over `ticks` (the row's):
    {"levels": [[s since load0, level, particles]] at the first tick and each change,
    "lowest" (the coarsest level seen), "fewest_particles", "step_down_s" (into the load, of
    the first step down; None: none), "level_at_load_end", "recovery_s" (after the load's
    end, of the first tick back at level 0 when the load ended at a coarser level; 0.0 when it
    did not; None: never back), "final_level", "held_s" (how long the last level had held
    at the last tick, s), "ticks": [[s since load0, level, particles,
    step_ms, substeps, contacts, threads, wait_share]] of every tick that stepped (what a
    level costs before, in and after the load; threads 0, wait_share -1: not reported)}."""
    levels: list[list] = []
    for x in ticks:
        lv, n = int(x.values.get("level", 0)), int(x.values.get("particles", 0))
        if not levels or levels[-1][1] != lv:
            levels.append([round(x.t - load0, 3), lv, n])
    down = next((t for t, lv, _ in levels if lv > 0 and t >= 0.0), None)
    at_end = 0
    for x in ticks:
        if x.t <= load1:
            at_end = int(x.values.get("level", 0))
    recovery: float | None = 0.0
    if at_end > 0:
        recovery = next((x.t - load1 for x in ticks
                         if x.t > load1 and int(x.values.get("level", 0)) == 0), None)
    return {"levels": levels, "lowest": max((lv for _, lv, _ in levels), default=0),
            "fewest_particles": min((n for *_, n in levels), default=None),
            "step_down_s": down, "level_at_load_end": at_end, "recovery_s": recovery,
            "final_level": levels[-1][1] if levels else None,
            "held_s": round(ticks[-1].t - load0 - levels[-1][0], 3) if levels else None,
            "ticks": [[round(x.t - load0, 3), int(x.values.get("level", 0)),
                       int(x.values.get("particles", 0)), float(x.values.get("step_ms", 0.0)),
                       int(x.values.get("substeps", 0)), int(x.values.get("contacts", 0)),
                       int(x.values.get("threads", 0)), float(x.values.get("wait_share", -1))]
                      for x in ticks if int(x.values.get("substeps", 0)) > 0]}


def classify_clears(clears: Sequence[Clear], ticks: Sequence[Tick]) -> dict:
    """{topic: {"dress", "lod", "other"}}: each DELETEALL by cause, told by its stamp: that of
    a status that dressed the garment ("dressed ..."), that of a tick whose level differs
    from the previous one's (the cloth's size changed: the node clears before drawing it),
    or neither."""
    dressed = {x.stamp_ns for x in ticks if x.message.startswith("dressed")}
    resized, prev = set(), None
    for x in ticks:
        lv = x.values.get("level")
        if prev is not None and lv != prev:
            resized.add(x.stamp_ns)
        prev = lv
    out = {topic: {"dress": 0, "lod": 0, "other": 0} for topic in ("marker", "markers")}
    for c in clears:
        cause = "dress" if c.stamp_ns in dressed else "lod" if c.stamp_ns in resized else "other"
        out.setdefault(c.topic, {"dress": 0, "lod": 0, "other": 0})[cause] += 1
    return out


def _within(items, t0: float, t1: float) -> list:
    return [x for x in items if t0 <= x.t <= t1]


def stream_row(name: str, fault: str, sent: Sequence[Sent], markers: Sequence[tuple[float, int]],
               clears: Sequence[Clear], ticks: Sequence[Tick], marks: Marks, before: dict,
               after: dict, latency_from_stats: bool = False, extra: dict | None = None) -> dict:
    """One row of a fault in the live stream.

    Args:
        name, fault: the row's name and what was done.
        sent, markers, clears, ticks: everything the benchmark sent and received (markers:
            (receive s, stamp ns) of the cloth markers drawn).
        marks: the row's times; the fault window is [fault, fault_end], at least
            MIN_FAULT_WINDOW_S long, the window after it runs to `end`.
        before, after: the node's status values when the previous row was done and when this
            one was (its counters: poses_received, poses_used, skipped_<kind>, ...).
        latency_from_stats: time the fault window's poses to /cloth/stats instead of the
            marker (nobody subscribed to the marker then).
        extra: more figures of the row (kept as they are).

    Returns the row's figures (a JSON-ready dict; latencies ms, times s).
    """
    f_end = max(marks.fault_end, marks.fault + MIN_FAULT_WINDOW_S)
    row_sent = [s for s in sent if marks.row <= s.t < marks.end + 1e-9]
    kinds = Counter(s.kind for s in row_sent)
    stat_covers = [(x.t, x.stamp_ns) for x in ticks if int(x.values.get("substeps", 0)) > 0
                   or x.message.startswith("dressed")]
    lat_f, unc_f = pose_latencies(sent, stat_covers if latency_from_stats else markers,
                                  marks.fault, f_end)
    lat_a, unc_a = pose_latencies(sent, markers, f_end, marks.end + 1e-9)
    row_ticks = _within(ticks, marks.row, marks.done)
    row = {
        "name": name, "fault": fault, "sent": len(row_sent), "kinds": dict(kinds),
        **_pose_counts(len(row_sent), kinds, _counter_deltas(before, after)),
        "latency_fault_ms": percentiles(lat_f), "latency_after_ms": percentiles(lat_a),
        "latency_fault_source": "stats" if latency_from_stats else "marker",
        "uncovered": unc_f + unc_a,
        "dressed": sum(x.message.startswith("dressed") for x in row_ticks),
        "expected_restarts": expected_restarts(sent, marks.row, marks.end + 1e-9),
        "clears": classify_clears(_within(clears, marks.row, marks.done), row_ticks),
        "ticks": sum(int(x.values.get("substeps", 0)) > 0 for x in row_ticks),
        "lod": rung_figures(row_ticks, marks.fault, marks.fault_end),
        "windows_s": {"fault": [0.0, round(f_end - marks.fault, 3)],
                      "after": [round(f_end - marks.fault, 3),
                                round(marks.end - marks.fault, 3)]},
    }
    row["kept"] = bool(row["dressed"] == 0 and all(
        c["dress"] == 0 and c["other"] == 0 for c in row["clears"].values()))
    row.update(extra or {})
    return row


def _counter_deltas(before: dict, after: dict) -> dict[str, int | None]:
    """How the node's pose, skip, restart and level counters grew over a row."""
    return {k: counter_delta(before, after, k) for k in sorted(set(after) | set(before))
            if k.startswith("skipped_") or k in (
                "poses_received", "poses_used", "poses_coalesced", "poses_discarded",
                "dropped", "stream_restarts", "lod_switches", "resets")}


def _pose_counts(n_sent: int, kinds: Counter, deltas: dict[str, int | None]) -> dict:
    """A row's "valid_sent", "not_received", "used", "unused", "lost", "stale", "deltas" and
    "dropped", from the kinds of message sent and the node's counters' growth (None where the
    node reports no such counter)."""
    valid = sum(kinds[k] for k in VALID_KINDS)
    used = deltas.get("poses_used")
    received = deltas.get("poses_received")
    stale = (deltas.get("skipped_stale") or 0) + (deltas.get("skipped_stamp_backwards") or 0)
    return {
        "valid_sent": valid,
        "not_received": None if received is None else n_sent - received,
        "used": used, "unused": None if used is None else valid - used,
        # Valid poses neither used nor accounted for (skipped as stale: a reordered pose that
        # arrived behind the simulated time, or discarded by a reset): lost.
        "lost": None if used is None else (
            valid - used - (deltas.get("poses_discarded") or 0)
            - max(stale - sum(n for k, n in kinds.items() if BAD_KINDS.get(k) == "stale"), 0)),
        "stale": stale, "deltas": deltas,
        "dropped": deltas.get("dropped"),
    }


def signal_row(name: str, signal_name: str, sent: Sequence[Sent],
               markers: Sequence[tuple[float, int]], clears: Sequence[Clear],
               ticks: Sequence[Tick], t_signal: float, pose: Sent | None, exit_code: int,
               exit_s: float | None, log_text: str, extra: dict | None = None) -> dict:
    """One row of a shutdown by `signal_name` sent at t_signal (s), `pose` the last one
    published before it: the exit status (-9: killed after the wait), the seconds to exit,
    DELETEALLs received after the signal on each topic, whether the tick of `pose` was still
    running when the signal went (its status arrived after it, or never), what the node's
    log says of the DELETEALL's acknowledgement ("shutdown_acked"), and the
    live stream's latency before the signal (ms); "deleteall_s": when each topic's DELETEALL
    arrived, s after the signal."""
    lat, _ = pose_latencies(sent, markers, t_signal - 3.0, t_signal)
    after = [c for c in clears if c.t >= t_signal]
    pose_tick = next((x for x in ticks if pose is not None and x.stamp_ns == pose.stamp_ns),
                     None)
    first = {topic: min((c.t for c in after if c.topic == topic), default=None)
             for topic in ("marker", "markers")}
    row = {
        "name": name, "fault": f"{signal_name} while ticking", "signal": signal_name,
        "exit_code": exit_code, "exit_s": exit_s,
        "deleteall": {topic: t is not None for topic, t in first.items()},
        "deleteall_s": {topic: None if t is None else t - t_signal
                        for topic, t in first.items()},
        "mid_tick": pose_tick is None or pose_tick.t > t_signal,
        "traceback": "Traceback" in log_text,
        "shutdown_acked": _shutdown_acked(log_text),
        "latency_fault_ms": percentiles(lat), "latency_after_ms": percentiles([]),
        "ticks": sum(int(x.values.get("substeps", 0)) > 0 for x in ticks if x.t <= t_signal),
    }
    row.update(extra or {})
    return row


def _shutdown_acked(log_text: str) -> bool | None:
    """What the node's log says of its shutdown DELETEALL: acknowledged by every reliable
    reader (True), not (False), or nothing (None)."""
    line = next((ln for ln in log_text.splitlines() if "shutdown:" in ln and "DELETEALL" in ln),
                None)
    if line is None or "acknowledged" not in line:
        return None
    return "not acknowledged" not in line


def check_row(row: dict) -> list[str]:
    """Why the row's outcome is not what the node should do (empty: ok). The expectations
    are the node's documented behaviour (the benchmark's module docstring)."""
    if row.get("error"):
        return [row["error"]]
    if row["name"] in SIGNAL_ROWS:
        return _signal_why(row)
    why = _poses_why(row) + _cloth_why(row) + _skips_why(row)
    d = row["deltas"]
    if row["name"] not in RESTART_ROWS and d.get("stream_restarts"):
        why.append(f"stream_restarts +{d['stream_restarts']}, expected +0")
    return why + _load_why(row) + _sub_gone_why(row)


def _signal_why(row: dict) -> list[str]:
    """A shutdown row: exit 0, a DELETEALL on both marker topics, no traceback."""
    why = []
    if row["exit_code"] != 0:
        why.append(f"exit status {row['exit_code']}, not 0")
    for topic, got in row["deleteall"].items():
        if not got:
            why.append(f"no DELETEALL on /cloth/{topic} after {row['signal']}")
    if row["traceback"]:
        why.append("a traceback in the node's log")
    return why


def _poses_why(row: dict) -> list[str]:
    """Every pose sent simulated, none dropped or lost, no bad one used."""
    why = []
    if row.get("drain_timed_out"):
        why.append("the node had not simulated every pose sent a minute after the row")
    if row["dropped"]:
        why.append(f"dropped {row['dropped']} (must stay 0)")
    lost, unused = row["lost"], row["unused"]
    if lost is None:
        why.append("no poses_used counter")
    elif lost > 0:
        why.append(f"{lost} valid poses lost: {unused} not used, {row['stale']} of them "
                   f"counted stale")
    if unused is not None and unused < 0:
        why.append(f"{-unused} more poses used than valid ones sent (a bad pose was used)")
    return why


def _cloth_why(row: dict) -> list[str]:
    """A restart row re-dresses (with a DELETEALL) once per new time line; any other keeps
    the cloth."""
    why = []
    restarts, d = row["expected_restarts"], row["deltas"]
    if row["name"] in RESTART_ROWS:
        if row["dressed"] != restarts:
            why.append(f"re-dressed {row['dressed']} times, expected {restarts}")
        for topic, c in row["clears"].items():
            if c["dress"] < restarts:
                why.append(f"{c['dress']} DELETEALL on /cloth/{topic} at a re-dress, expected "
                           f"{restarts}")
        got = d.get("stream_restarts")
        if got is None:
            why.append("the node reports no stream_restarts")
        elif got != restarts:
            why.append(f"stream_restarts +{got}, expected +{restarts}")
    elif not row["kept"]:
        why.append(f"cloth not kept (re-dressed {row['dressed']}, DELETEALL "
                   + ", ".join(f"{t} {c['dress'] + c['other']}" for t, c in
                               row["clears"].items()) + ")")
    return why


def _skips_why(row: dict) -> list[str]:
    """Each bad frame skipped under its own counter, as many stale as sent stale."""
    why = []
    name, stale, d = row["name"], row["stale"], row["deltas"]
    expected_skips: Counter = Counter()
    for kind, n in row["kinds"].items():
        if kind in BAD_KINDS:
            expected_skips[BAD_KINDS[kind]] += n
    for kind in ("empty", "wrong_count", "non_finite", "malformed", "teleport"):
        got = d.get(f"skipped_{kind}") or 0
        if got != expected_skips.get(kind, 0):
            why.append(f"skipped_{kind} +{got}, expected +{expected_skips.get(kind, 0)}")
    if name not in ("reorder", *RESTART_ROWS) and stale != expected_skips.get("stale", 0):
        why.append(f"{stale} skipped as stale, expected {expected_skips.get('stale', 0)}")
    if name in ("stale", "duplicate") and "skipped_stale" not in row["deltas"]:
        why.append("the node reports no skipped_stale")
    return why


def _load_why(row: dict) -> list[str]:
    """A load row: back at level 0 within RECOVERY_TARGET_S, at most MAX_SWITCHES."""
    if row["name"] not in LOAD_ROWS:
        return []
    why = []
    lod = row["lod"]
    if lod["final_level"]:
        why.append(f"still at level {lod['final_level']} at the row's end")
    rec = lod["recovery_s"]
    if rec is None:
        why.append("never back to level 0 after the load")
    elif rec > RECOVERY_TARGET_S:
        why.append(f"back to level 0 {rec:.1f} s after the load (target "
                   f"{RECOVERY_TARGET_S:g} s)")
    switches = row["deltas"].get("lod_switches") or 0
    if switches > MAX_SWITCHES:
        why.append(f"{switches} level switches (at most {MAX_SWITCHES})")
    return why


def _sub_gone_why(row: dict) -> list[str]:
    """The sub_gone row: ticks and statuses while the marker had no subscriber, markers for
    the new one."""
    if row["name"] != "sub_gone":
        return []
    why = []
    if not row.get("ticks_while_gone"):
        why.append("no tick while the marker's subscriber was gone")
    if row.get("uncovered_while_gone"):
        why.append(f"{row['uncovered_while_gone']} poses sent while it was gone never "
                   f"reached a status")
    if not row.get("markers_after_resubscribe"):
        why.append("no marker reached the new subscriber")
    return why


def _times(n: int) -> str:
    return {1: "once", 2: "twice"}.get(n, f"{n} times")


def describe_row(row: dict) -> str:
    """What the node did in the row, in a few words."""
    if row.get("error"):
        return row["error"]
    if row["name"] in SIGNAL_ROWS:
        got = [t for t, ok in row["deleteall"].items() if ok]
        exit_s = "" if row["exit_s"] is None else f" {row['exit_s']:.2f} s after it"
        arrived = [s for s in row.get("deleteall_s", {}).values() if s is not None]
        when = f" (received {max(arrived):.2f} s after it)" if arrived else ""
        return (f"exit {row['exit_code']}{exit_s}; DELETEALL on "
                f"{' and '.join('/cloth/' + t for t in got) or 'no marker topic'}{when}"
                f"{'' if row['mid_tick'] else '; the signal fell between ticks'}"
                f"{'; its log says not acknowledged' if row['shutdown_acked'] is False else ''}"
                f"{'; a traceback in its log' if row['traceback'] else ''}")
    parts = []
    if row["dressed"]:
        parts.append(f"re-dressed {_times(row['dressed'])}")
    elif row["kept"]:
        parts.append("cloth kept")
    else:
        parts.append("cloth cleared (DELETEALL) without a re-dress")
    skipped = {k[len("skipped_"):]: n for k, n in row["deltas"].items()
               if k.startswith("skipped_") and n}
    if skipped:
        parts.append("skipped " + ", ".join(f"{n} {k}" for k, n in sorted(skipped.items())))
    if row["deltas"].get("stream_restarts"):
        parts.append(f"stream_restarts +{row['deltas']['stream_restarts']}")
    lod = row["lod"]
    if row["name"] in LOAD_ROWS or row["deltas"].get("lod_switches"):
        if lod["lowest"] == 0:
            parts.append(f"stayed at level 0 ({lod['fewest_particles']} particles)")
        else:
            text = (f"stepped down to level {lod['lowest']} ({lod['fewest_particles']} "
                    f"particles)")
            if lod["step_down_s"] is not None:
                text += f" {lod['step_down_s']:.1f} s into the fault"
            rec = lod["recovery_s"]
            if lod["level_at_load_end"] == 0:
                text += ", back at level 0 before it ended"
            elif rec is None:
                text += f", still at level {lod['final_level']} at the end"
            else:
                text += f", back up {rec:.1f} s after it"
                if not lod["final_level"] and lod.get("held_s") is not None:
                    text += f" and held there {lod['held_s']:.1f} s"
            parts.append(text)
        lod_clears = sum(c["lod"] for c in row["clears"].values())
        if lod_clears:
            parts.append(f"{lod_clears} DELETEALL at level switches")
    lost, unused = row.get("lost") or 0, row.get("unused") or 0
    if lost > 0:
        parts.append(f"{lost} valid poses lost")
    if unused < 0:
        parts.append(f"used {-unused} poses it should have skipped")
    if row.get("not_received"):
        parts.append(f"{row['not_received']} messages never received")
    if row["name"] == "sub_gone":
        parts.append(f"{row.get('ticks_while_gone', 0)} ticks while unsubscribed")
    return "; ".join(parts)


def _ms(p: dict) -> str:
    if p["p50"] is None:
        return "-"
    return f"{p['p50']:.0f}/{p['p95']:.0f}"


def format_table(rows: Sequence[dict]) -> str:
    """The report: one line of figures per row (latency ms p50/p95 in the fault window and
    after it, poses skipped as stale, valid poses lost, cloth kept, level switches and recovery,
    exit status and DELETEALLs), then what the node did and why a row is not ok."""
    header = ["fault", "lat fault ms", "lat after ms", "stale", "lost", "kept",
              "lod sw/recov", "exit/DELETEALL", "ok"]
    lines = []
    body = []
    for r in rows:
        if r.get("error"):
            body.append([r["name"], "-", "-", "-", "-", "-", "-", "-", "no"])
        elif r["name"] in SIGNAL_ROWS:
            got = "+".join(t for t, ok in r["deleteall"].items() if ok) or "none"
            body.append([r["name"], _ms(r["latency_fault_ms"]), "-", "-", "-", "-", "-",
                         f"{r['exit_code']} / {got}", "yes" if r["ok"] else "NO"])
        else:
            lat_f = _ms(r["latency_fault_ms"]) + ("*" if r["latency_fault_source"] == "stats"
                                                  else "")
            lod = "-"
            if r["name"] in LOAD_ROWS:
                rec, lowest = r["lod"]["recovery_s"], r["lod"]["lowest"]
                recov = ("-" if not lowest else "never" if rec is None else f"{rec:.1f} s")
                lod = f"{r['deltas'].get('lod_switches') or 0} / {recov}"
            lost = "?" if r["lost"] is None else str(r["lost"])
            body.append([r["name"], lat_f, _ms(r["latency_after_ms"]), str(r["stale"]), lost,
                         "yes" if r["kept"] else "no", lod, "-", "yes" if r["ok"] else "NO"])
    lines.append(text_table(header, body))
    if any(r.get("latency_fault_source") == "stats" for r in rows):
        lines.append("* to /cloth/stats: nobody subscribed to /cloth/marker then")
    lines.append("")
    width = max((len(r["name"]) for r in rows), default=4)
    for r in rows:
        lines.append(f"{r['name']:<{width}}  {r['fault']}: {r['did']}")
        for reason in r["why"]:
            lines.append(f"{'':<{width}}    NOT OK: {reason}")
    bad = [r["name"] for r in rows if not r["ok"]]
    lines.append("")
    lines.append(f"{len(rows) - len(bad)} of {len(rows)} rows ok"
                 + (f"; not ok: {', '.join(bad)}" if bad else ""))
    return "\n".join(lines)
