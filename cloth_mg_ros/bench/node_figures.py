"""The figures of `cloth-mg bench node` (bench/node_latency.py runs it): from what the
benchmark received (poses, markers, the node's stats) to the latency figures, the report and
the chart. The module docstring of bench/node_latency.py defines each figure."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.ros.message_reference import deserialize

__all__ = ["GROWTH_LIMIT", "LATENCY_TARGET_MS", "format_node_report", "latency_figures",
           "lod_figures", "median", "pass_figures", "percentiles", "plot_node", "stats_values"]

GROWTH_LIMIT = 1.2  # keeps_up: the last third's latency p95 at most this times the first's
LATENCY_TARGET_MS = 100.0  # the live target, drawn on the chart


def percentiles(values: Sequence[float] | np.ndarray) -> dict[str, float | None]:
    """{"p50", "p95", "max"} of `values` (a sequence or an array, in its own unit), None each
    when empty (no figure, not a zero that would pass for a good one)."""
    a = np.asarray(values, dtype=float)
    if not a.size:
        return {"p50": None, "p95": None, "max": None}
    return {"p50": float(np.percentile(a, 50)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max())}


def _p95(values: list[float]) -> float | None:
    return float(np.percentile(values, 95)) if values else None


def latency_figures(poses: list[tuple[float, int]], markers: list[tuple[float, int]],
                    not_ticks: set[int] = frozenset()) -> dict:
    """Match every pose to the marker that first covered it, and time them.

    Args:
        poses: [(receive time s, stamp ns)] of the pose messages, in arrival order.
        markers: [(receive time s, stamp ns)] of the markers, in arrival order (their stamps
            increase: each is the newest pose of its tick).
        not_ticks: stamps (ns) of markers that were no simulation tick (the dressing, a
            re-anchoring): the first one's pose latency is `dress_latency_ms`; those poses
            are left out of the percentiles.

    Returns:
        {"latency_ms": {"p50", "p95", "max"} over the poses simulated in ticks,
        "service_ms": {...} over the markers (receipt minus the later of their own pose's
        receipt and the previous marker's), "queue_ms": {...} (a pose's latency less its
        marker's service), "dress_latency_ms", "per_pose": [[s since the first pose,
        latency ms]], "latency_thirds": {"first", "last", "growth"} (p95 of the first and
        last third of the poses, and last / first), "covered": poses with a marker,
        "uncovered": poses no marker covered, "matched": markers whose stamp is a pose's,
        "unmatched": markers of no received pose}.
    """
    received: dict[int, float] = {}
    for t, stamp in poses:
        received.setdefault(stamp, t)
    service_of, service, matched = _marker_service(received, markers, not_ticks)
    m_stamps = np.array([st for _, st in markers], dtype=np.int64)
    m_times = np.array([t for t, _ in markers], dtype=float)
    order = np.argsort(m_stamps, kind="stable")
    by_stamp = _ByStamp(m_stamps[order], m_times[order])
    dressed_at = min((t for t, st in markers if st in not_ticks), default=-np.inf)
    c = _cover_poses(received, by_stamp, service_of, not_ticks, dressed_at,
                     poses[0][0] if poses else 0.0)
    latency = c.latency
    return {"latency_second_half_p95": _p95(latency[len(latency) // 2:]),
            "last_pose_latency_ms": _last_pose_ms(received, by_stamp),
            "latency_stamps": c.stamps, "latency": latency,
            "latency_ms": percentiles(latency), "service_ms": percentiles(service),
            "queue_ms": percentiles(c.queue), "dress_latency_ms": c.dress,
            "during_dressing": len(c.waiting), "dressing_latency_ms": percentiles(c.waiting),
            "per_pose": c.per_pose, "latency_thirds": _thirds(latency),
            "covered": c.covered, "uncovered": len(received) - c.covered,
            "matched": matched, "unmatched": len(markers) - matched}


class _ByStamp(NamedTuple):
    """The markers' stamps (ns, int64) in increasing order and their receive times (s)."""

    stamps: np.ndarray
    times: np.ndarray


class _Covers(NamedTuple):
    """The poses as their markers covered them (`_cover_poses`): the latency (ms), the
    stamp, the wait for a tick (ms) and [s since the first pose, latency ms] of each pose
    simulated in a tick; the latencies of the poses that arrived while the garment was being
    dressed; the dressing pose's latency (ms); how many poses a marker covered."""

    latency: list[float]
    stamps: list[int]
    queue: list[float]
    per_pose: list[list[float]]
    waiting: list[float]
    dress: float | None
    covered: int


def _marker_service(received: dict[int, float], markers: list[tuple[float, int]],
                    not_ticks: set[int]) -> tuple[dict[int, float], list[float], int]:
    """({stamp: service ms} of the markers of received poses, the service times of the
    ticks among them, how many markers were of a received pose). A marker's service is its
    receipt minus the later of its pose's receipt and the previous marker's."""
    service_of: dict[int, float] = {}
    service = []
    matched = 0
    prev_marker = -np.inf
    for t, stamp in markers:
        if stamp in received:
            matched += 1
            svc = 1e3 * (t - max(received[stamp], prev_marker))
            service_of[stamp] = svc
            if stamp not in not_ticks:
                service.append(svc)
        prev_marker = t
    return service_of, service, matched


def _cover_poses(received: dict[int, float], by_stamp: _ByStamp, service_of: dict[int, float],
                 not_ticks: set[int], dressed_at: float, t_first: float) -> _Covers:
    """Each received pose (by stamp) against the first marker stamped at or after it; poses
    that arrived before the dressing's marker (received at `dressed_at`) are counted apart."""
    latency, queue, per_pose, waiting, stamps = [], [], [], [], []
    dress = None
    covered = 0
    for stamp, t in sorted(received.items()):
        k = int(np.searchsorted(by_stamp.stamps, stamp, side="left"))
        if k == len(by_stamp.stamps):
            continue
        covered += 1
        lat = 1e3 * (by_stamp.times[k] - t)
        cover = int(by_stamp.stamps[k])
        if cover in not_ticks:
            if dress is None:
                dress = lat
            continue
        if t < dressed_at:  # arrived while the garment was being dressed
            waiting.append(lat)
            continue
        latency.append(lat)
        stamps.append(stamp)
        per_pose.append([round(t - t_first, 4), round(lat, 3)])
        if cover in service_of:
            queue.append(max(lat - service_of[cover], 0.0))
    return _Covers(latency, stamps, queue, per_pose, waiting, dress, covered)


def _thirds(latency: list[float]) -> dict:
    """{"first", "last": the p95 of the first and the last third of `latency`, "growth":
    last / first} (None where there are fewer than three)."""
    third = len(latency) // 3
    first_p95 = _p95(latency[:third]) if third else None
    last_p95 = _p95(latency[-third:]) if third else None
    growth = (last_p95 / first_p95 if first_p95 and last_p95 is not None else None)
    return {"first": first_p95, "last": last_p95, "growth": growth}


def _last_pose_ms(received: dict[int, float], by_stamp: _ByStamp) -> float | None:
    """The newest pose's latency to the marker that covered it, ms (None: none did)."""
    newest = max(received, default=None)
    last_covered = (newest is not None and by_stamp.stamps.size
                    and newest <= by_stamp.stamps[-1])
    return (1e3 * (by_stamp.times[int(np.searchsorted(by_stamp.stamps, newest))]
                   - received[newest]) if last_covered else None)


def stats_values(raw: list[tuple[float, bytes]]) -> list[tuple[float, int, dict[str, str]]]:
    """(receive time s, stamp ns, {key: value}) of each recorded /cloth/stats status."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from diagnostic_msgs.msg import DiagnosticArray


    out = []
    for t, data in raw:
        msg = deserialize(data, DiagnosticArray)
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        for st in msg.status:
            out.append((t, stamp, {kv.key: kv.value for kv in st.values}))
    return out


def median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def lod_figures(ticks: list[tuple[float, int, dict[str, str]]], t_start: float) -> dict:
    """{"lod": {"switches", "levels": [[s since the first pose, level, particles]] at the
    first tick and at every change, "final_level", "lowest_level", "time_at_level_s":
    {level: s}, "recoveries": [[s of a step down, level before, level after, s until the
    level was back (None: never)]]}} from the ticks' stats."""
    changes: list[list] = []
    for t, _, v in ticks:
        level, n = int(v.get("level", "0")), int(v.get("particles", "0"))
        if not changes or changes[-1][1] != level:
            changes.append([round(t - t_start, 3), level, n])
    last = ticks[-1][2] if ticks else {}
    t_end = round(ticks[-1][0] - t_start, 3) if ticks else 0.0
    time_at: dict[str, float] = {}
    for (t, level, _), nxt in zip(changes, [*changes[1:], [t_end]], strict=True):
        time_at[str(level)] = round(time_at.get(str(level), 0.0) + nxt[0] - t, 3)
    # After each step down: how long until the level was back where it was before it.
    recoveries = []
    for k in range(1, len(changes)):
        t_down, level, _ = changes[k]
        before = changes[k - 1][1]
        if level > before:
            back = next((c[0] for c in changes[k + 1:] if c[1] <= before), None)
            recoveries.append([t_down, before, level,
                               None if back is None else round(back - t_down, 3)])
    return {"lod": {"switches": int(last.get("lod_switches", "0")), "levels": changes,
                    "final_level": changes[-1][1] if changes else None,
                    "lowest_level": max((c[1] for c in changes), default=None),
                    "time_at_level_s": time_at, "recoveries": recoveries}}


def pass_figures(figures: dict, ticks: list[tuple[float, int, dict[str, str]]],
                  rates: list[float], passes: int, t_first: int, t_last: int,
                  per_pass: int) -> list[dict]:
    """Per pass of the bag (stamps shifted by the bag's span plus one interval per pass, as
    `replay_bag` does): its rate, latency percentiles over its poses, and its last tick's
    level, particles and budget, its median tick."""
    span = max(t_last - t_first, 0)
    pass_ns = span + (span // max(per_pass - 1, 1) if per_pass > 1 else 1_000_000_000)

    def index(stamp: int) -> int:
        return min(max((stamp - t_first) // pass_ns, 0), passes - 1)

    lat_of = [[] for _ in range(passes)]
    for stamp, lat in zip(figures["latency_stamps"], figures["latency"], strict=True):
        lat_of[index(stamp)].append(lat)
    ticks_of = [[] for _ in range(passes)]
    for _, stamp, v in ticks:
        ticks_of[index(stamp)].append(v)
    out = []
    for k in range(passes):
        last = ticks_of[k][-1] if ticks_of[k] else {}
        out.append({
            "pass": k + 1, "rate": float(rates[min(k, len(rates) - 1)]),
            "poses": len(lat_of[k]), "latency_ms": percentiles(lat_of[k]),
            "level": int(last["level"]) if "level" in last else None,
            "particles": int(last["particles"]) if "particles" in last else None,
            "budget_ms": float(last["budget_ms"]) if "budget_ms" in last else None,
            "step_ms_p50": median([float(v["step_ms"]) for v in ticks_of[k]])})
    return out


def format_node_report(r: dict) -> str:
    """The benchmark's figures as a few lines of text."""
    def ms(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f}"

    lat, svc, thirds = r["latency_ms"], r["service_ms"], r["latency_thirds"]
    growth = "-" if thirds["growth"] is None else f"{thirds['growth']:.2f}x"
    lines = [
        (f"cloth_node, scene {r['scene']}: {r['garment_particles']} particles (asked "
         f"{r['particles']}), {r['messages']} pose messages from {r['bag']} at rate "
         f"{r['rate']:g} (one every {r['pose_interval_ms']:.1f} ms)"),
        (f"  poses: {r['node_poses_received']} received by the node (lost {r['lost']}), "
         f"{r['poses_used']} used, {r['poses_coalesced']} of them coalesced into a later "
         f"tick, dropped {r['dropped']}, pending {r['pending']}; {r['ticks']} ticks, "
         f"{r['markers']} markers"),
        (f"  latency pose received -> marker received: p50 {ms(lat['p50'])} ms, p95 "
         f"{ms(lat['p95'])} ms, max {ms(lat['max'])} ms"),
        (f"  start-up: the dressing pose {ms(r['dress_latency_ms'])} ms; "
         f"{r['during_dressing']} poses arrived while it was dressed (up to "
         f"{ms(r['dressing_latency_ms']['max'])} ms, not in the figures above)"),
        (f"  p95 over the first third {ms(thirds['first'])} ms, the last third "
         f"{ms(thirds['last'])} ms (growth {growth})"),
        (f"  marker service (tick + transport): p50 {ms(svc['p50'])} ms, p95 "
         f"{ms(svc['p95'])} ms; wait for a tick: p50 {ms(r['queue_ms']['p50'])} ms, p95 "
         f"{ms(r['queue_ms']['p95'])} ms; lag p95 {ms(r['lag_ms']['p95'])} ms"),
        (f"  node's own tick: p50 {ms(r['step_ms_p50'])} ms, p95 {ms(r['step_ms_p95'])} ms "
         f"(median solve {ms(r['solve_ms_p50'])} ms, marker {ms(r['marker_ms_p50'])} ms)"),
    ]
    if r.get("loops", 1) > 1 or r.get("lod", {}).get("switches"):
        lines.append(f"  second half: latency p95 {ms(r['latency_second_half_p95'])} ms; the "
                     f"newest pose's marker after {ms(r['last_pose_latency_ms'])} ms")
        lod = r["lod"]
        steps = ", ".join(f"{n} particles (level {lv}) at {t:.1f} s"
                          for t, lv, n in lod["levels"])
        lines.append(f"  level of detail: {lod['switches']} switches: {steps}")
        at = ", ".join(f"level {lv} {t:.1f} s" for lv, t in lod.get("time_at_level_s", {}).items())
        lines.append(f"  time at each level: {at}")
        for t, before, after, back in lod.get("recoveries", []):
            lines.append(f"  stepped down {before} -> {after} at {t:.1f} s: "
                         + ("never back" if back is None else f"back after {back:.1f} s"))
        for p in r["passes"]:
            lat = p["latency_ms"]
            lines.append(f"    pass {p['pass']} at rate {p['rate']:g}: {p['poses']} poses, "
                         f"latency p50 {ms(lat['p50'])} / p95 {ms(lat['p95'])} ms, tick p50 "
                         f"{ms(p['step_ms_p50'])} ms of a {ms(p['budget_ms'])} ms budget, "
                         f"ends at level {p['level']} ({p['particles']} particles)")
    if r["keeps_up"]:
        lines.append("  the node kept up: nothing lost or dropped, no latency growth over the "
                     "clip")
    else:
        lines.append(f"  the node did not keep up (lost {r['lost']}, dropped {r['dropped']}, "
                     f"latency growth {growth}, limit {GROWTH_LIMIT:g}x)")
    return "\n".join(lines)


def plot_node(result: dict, png: str | Path) -> Path:
    """The latency of every pose (dots) and the node's tick times (line) over the clip, the
    100 ms target and one pose interval dashed. Returns the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    fig, ax = plt.subplots(figsize=(10, 4.5))
    per = np.asarray(result["per_pose"], dtype=float).reshape(-1, 2)
    ticks = np.asarray(result["ticks_series"], dtype=float).reshape(-1, 4)
    ax.plot(per[:, 0], per[:, 1], ".", ms=4, label="pose -> marker latency")
    if len(ticks):
        ax.plot(ticks[:, 0], ticks[:, 1], "-", lw=1, alpha=0.7, label="node tick (step_ms)")
    if len(ticks) and np.ptp(ticks[:, 3]) > 0:  # the level of detail changed: show it
        twin = ax.twinx()
        twin.step(ticks[:, 0], ticks[:, 3], where="post", color="green", lw=1.2)
        twin.set_ylabel("particles (level of detail)", color="green")
        twin.set_ylim(0, 1.1 * ticks[:, 3].max())
    ax.axhline(LATENCY_TARGET_MS, color="red", ls="--", lw=1, label="100 ms")
    ax.axhline(result["pose_interval_ms"], color="grey", ls=":", lw=1, label="pose interval")
    ax.set_xlabel("s since the first pose")
    ax.set_ylabel("ms")
    lat = result["latency_ms"]
    rates = ",".join(f"{r:g}" for r in result.get("rates", [result["rate"]]))
    ax.set_title(f"cloth_node live: {Path(result['bag']).name}, {result['garment_particles']} "
                 f"particles, rate {rates}: latency p50 {lat['p50'] or 0:.0f} / "
                 f"p95 {lat['p95'] or 0:.0f} ms, dropped {result['dropped']}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_chart(fig, png)
