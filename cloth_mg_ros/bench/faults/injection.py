"""The faults of `cloth-mg bench faults`, one function each, and the run of them all.

The stream faults share one cloth_node process (the CPU hogs one of their own, with a garment
of LOAD_PARTICLES), in the order of FAULTS, each a row: a second of the live stream, the
fault, the stream after it (for the load rows, until the node is back at full detail), then
a drain (`FaultStream.drain`: nothing sent until the node has simulated all of it) whose
status closes the row's counters and opens the next row's. The shutdown faults each need a
process of their own.
"""

from __future__ import annotations

import os
import platform
import signal
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.faults.figures import (
    LOAD_ROWS,
    MIN_FAULT_WINDOW_S,
    SIGNAL_ROWS,
    Marks,
    check_row,
    describe_row,
    pose_latencies,
    signal_row,
    stream_row,
)
from cloth_mg_ros.bench.faults.stream import (
    RATE_HZ,
    FaultStream,
    PoseSource,
    cpu_hogs,
    pose_array_cdr,
)
from cloth_mg_ros.bench.results import recorded_path
from cloth_mg_ros.config.scenes import load_scene, scene_path
from cloth_mg_ros.config.schema import PARAMETERS
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.ros.processes import (
    NODE_NAME,
    POSE_TOPIC,
    START_TIMEOUT_S,
    NodeError,
    NodeProcess,
    child_env,
    open_ros_side,
)

__all__ = ["FAULTS", "LOAD_PARTICLES", "STREAM_FAULTS", "bench_faults", "parse_faults"]

#: Row name -> what the fault is, in the order they run.
FAULTS = {
    "hog1": "a CPU hog on one core",
    "hog2": "a CPU hog on both cores",
    "burst": "10 poses published at once",
    "reorder": "neighbouring stamps swapped, each pair sent back to back",
    "duplicate": "every pose sent twice",
    "stale": "one pose stamped 5 s in the past",
    "new_stream": "the publisher stops 2 s, restarts on an earlier time line",
    "loop": "the bag looped (ros2 bag play --loop): stamps jump back each pass",
    "bad_frames": "NaN, empty and wrong-count frames mixed in",
    "sub_gone": "the /cloth/marker subscriber goes away, then comes back",
    "sigint": "SIGINT",
    "sigterm": "SIGTERM",
}
STREAM_FAULTS = tuple(n for n in FAULTS if n not in SIGNAL_ROWS)

LEAD_S = 1.0  # live stream at the start of each row, s
# before a CPU hog: the node at full detail long enough to have measured its steps there
# (the level of detail's live anchor, 2 s), as a load comes to a node that has run a while
# (issue 40's trial: a load from 6 s to 14 s of the clip)
HOG_LEAD_S = 5.0
AFTER_S = 3.0  # live stream after a fault, s
START_LIVE_S = 3.0  # live stream after the dressing, before the first row, s
LEVEL0_TIMEOUT_S = 20.0  # wait this long for full detail before the rows, s
RECOVERY_TIMEOUT_S = 15.0  # after a load, stream this long at most for the way back up, s
# Once back at full detail, stream this much longer: a node that steps straight down again
# (its full size mispredicted) shows it as a final level > 0 or a fifth switch.
HOLD_S = 6.0
RESUBSCRIBE_TIMEOUT_S = 60.0  # a new subscriber's discovery and first marker, at most, s
DRESS_TIMEOUT_S = 120.0  # the first pose's dressing, at most (a cold start), s
BURST = 10  # poses published at once
MIXED_S = 3.0  # reordered, duplicated or bad frames are sent this long, s
STALE_BACK_S = 5.0  # the stale pose's age, s
PAUSE_S = 2.0  # the publisher's silence before its new time line, s
LOOP_PASSES = 2  # passes of the bag in the loop row
UNSUBSCRIBED_S = 3.0  # the marker subscriber stays away this long, s
SIGNAL_LIVE_S = 3.0  # live ticks before a signal, s
EXIT_TIMEOUT_S = 90.0  # the node exits within this after a signal (a slow tick), s
BAD_CYCLE = ("nan", "empty", "wrong_count")
# The hog rows' garment: the walking dress's smallest size with a coarser level of detail (615
# particles) under it; at 1200 it has none, and the node cannot step down.
LOAD_PARTICLES = 2400


def parse_faults(text: str) -> list[str]:
    """--faults: 'all' or a comma list of FAULTS' names; ClothInputError naming an unknown
    one. Returned in the order they run."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if names in ([], ["all"]):
        return list(FAULTS)
    unknown = [n for n in names if n not in FAULTS]
    if unknown:
        raise ClothInputError(f"--faults: unknown fault {', '.join(map(repr, unknown))}; "
                              f"choose from {', '.join(FAULTS)} (or all)")
    return [n for n in FAULTS if n in names]


# ------------------------------------------------------------------------------------------
# Stream faults: each returns the row's Marks but `done` (the drain sets it) and extra figures


def _hog(cores: int, hog_s: float) -> Callable:
    def run(s: FaultStream) -> tuple:
        t_row = time.monotonic()
        s.run(HOG_LEAD_S)
        t0 = time.monotonic()
        with cpu_hogs(cores, hog_s):
            s.run(hog_s)
        t1 = time.monotonic()

        def recovered() -> bool:  # a status at full detail received since the load ended
            return any(x.t > t1 and int(x.values.get("level", 0)) == 0
                       for x in s.rec.ticks[-5:])

        s.run(AFTER_S, until=recovered, max_s=RECOVERY_TIMEOUT_S)
        if recovered():
            s.run(HOLD_S)
        return (t_row, t0, t1, time.monotonic()), {"hog_s": hog_s, "hog_cores": cores}
    return run


def _burst(s: FaultStream) -> tuple:
    t_row = time.monotonic()
    s.run(LEAD_S)
    t0 = time.monotonic()
    for _ in range(BURST):  # the publisher stalled for 10 periods, then flushes them
        s.send_valid()
    s.reset_pacing()
    t1 = time.monotonic()
    s.run(AFTER_S)
    return (t_row, t0, t1, time.monotonic()), {}


def _mixed(slot: Callable[[FaultStream, int], None]) -> Callable:
    """A fault of MIXED_S s whose k-th slot is slot(stream, k)."""
    def run(s: FaultStream) -> tuple:
        t_row = time.monotonic()
        s.run(LEAD_S)
        t0 = time.monotonic()
        count = [0]

        def one(stream: FaultStream) -> None:
            slot(stream, count[0])
            count[0] += 1

        s.run(MIXED_S, one)
        t1 = time.monotonic()
        s.run(AFTER_S)
        return (t_row, t0, t1, time.monotonic()), {}
    return run


def _reorder_slot(s: FaultStream, k: int) -> None:
    # Two slots' poses in one, the later stamp first: a transport that delivers a pair
    # swapped. The earlier one is used when it is still ahead of the simulated time.
    if k % 2:
        return
    stamp_a, poses_a = s.source.next()
    stamp_b, poses_b = s.source.next()
    s.publish(pose_array_cdr(stamp_b, poses_b), stamp_b, "valid")
    s.publish(pose_array_cdr(stamp_a, poses_a), stamp_a, "reordered")


def _duplicate_slot(s: FaultStream, k: int) -> None:
    stamp, poses = s.source.next()
    data = pose_array_cdr(stamp, poses)
    s.publish(data, stamp, "valid")
    s.publish(data, stamp, "duplicate")


def _bad_slot(s: FaultStream, k: int) -> None:
    stamp, poses = s.source.next()
    if k % 3 != 1:
        s.publish(pose_array_cdr(stamp, poses), stamp, "valid")
        return
    kind = BAD_CYCLE[(k // 3) % len(BAD_CYCLE)]
    bad = poses.copy()
    if kind == "nan":
        bad[len(bad) // 2, 0] = np.nan
    elif kind == "empty":
        bad = bad[:0]
    else:
        bad = bad[:-1]
    s.publish(pose_array_cdr(stamp, bad), stamp, kind)


def _stale(s: FaultStream) -> tuple:
    t_row = time.monotonic()
    s.run(LEAD_S)
    t0 = time.monotonic()
    # A message delayed 5 s arrives between two live ones: its stamp and the body then.
    src = s.source
    back = round(STALE_BACK_S / s.period)
    stamp = src.last_stamp_ns - back * src.period_ns
    s.publish(pose_array_cdr(stamp, src.frame(src.cursor - 1 - back)), stamp, "stale")
    t1 = time.monotonic()
    s.run(AFTER_S)
    return (t_row, t0, t1, time.monotonic()), {}


def _new_stream(s: FaultStream) -> tuple:
    t_row = time.monotonic()
    s.run(LEAD_S)
    t0 = time.monotonic()
    s.wait(lambda: False, PAUSE_S)  # the publisher is gone
    # It comes back replaying from its start: its first stamp and frame again.
    s.source.new_time_line(s.source.first_start_ns, cursor=0)
    s.reset_pacing()
    s.run(MIN_FAULT_WINDOW_S)
    t1 = time.monotonic()
    s.run(AFTER_S)
    return (t_row, t0, t1, time.monotonic()), {"pause_s": PAUSE_S}


def _loop(frames: list[tuple[float, np.ndarray]]) -> Callable:
    def run(s: FaultStream) -> tuple:
        t_row = time.monotonic()
        s.run(LEAD_S)
        t0 = time.monotonic()
        for _ in range(LOOP_PASSES):  # the bag's own stamps, pass after pass
            s.source.new_time_line(0)
            epoch = s.source.epoch
            queue = list(frames)

            def slot(stream: FaultStream, queue=queue, epoch=epoch) -> None:
                stamp_s, poses = queue.pop(0)
                stamp = round(stamp_s * 1e9)
                stream.publish(pose_array_cdr(stamp, poses), stamp, "valid", epoch)

            s.run(0.0, slot, until=lambda q=queue: not q, max_s=600.0)
        t1 = time.monotonic()
        last = s.last_valid()
        s.source.continue_from(last.stamp_ns, len(frames) - 1, last.epoch)
        s.run(AFTER_S)
        return (t_row, t0, t1, time.monotonic()), {"passes": LOOP_PASSES}
    return run


def _sub_gone(s: FaultStream) -> tuple:
    t_row = time.monotonic()
    s.run(LEAD_S)
    t0 = time.monotonic()
    s.rec.unsubscribe_marker()
    s.run(UNSUBSCRIBED_S)
    t1 = time.monotonic()
    s.rec.subscribe_marker()
    n_before = len(s.rec.markers)
    s.run(AFTER_S, until=lambda: len(s.rec.markers) > n_before, max_s=RESUBSCRIBE_TIMEOUT_S)
    gone = [x for x in s.rec.ticks if t0 <= x.t <= t1]
    covers = [(x.t, x.stamp_ns) for x in s.rec.ticks]
    _, uncovered = pose_latencies(s.sent, covers, t0, t1)
    return (t_row, t0, t1, time.monotonic()), {
        "ticks_while_gone": sum(int(x.values.get("substeps", 0)) > 0 for x in gone),
        "uncovered_while_gone": uncovered,
        "markers_after_resubscribe": len(s.rec.markers) - n_before}


def _stream_faults(frames, hog_s: float) -> dict[str, Callable]:
    return {"hog1": _hog(1, hog_s), "hog2": _hog(2, hog_s), "burst": _burst,
            "reorder": _mixed(_reorder_slot), "duplicate": _mixed(_duplicate_slot),
            "stale": _stale, "new_stream": _new_stream, "loop": _loop(frames),
            "bad_frames": _mixed(_bad_slot), "sub_gone": _sub_gone}


# ------------------------------------------------------------------------------------------
# Sessions: one cloth_node process each


class _Session:
    """A cloth_node process fed by the stream on the benchmark's RosSide."""

    def __init__(self, stream: FaultStream, scene: str, particles: int, log_path: Path,
                 start_timeout_s: float, log: Callable[[str], None]) -> None:
        side = stream.side
        # The last session's node must have left the graph, or its endpoints would pass for
        # the new one's.
        stream.wait(lambda: not side.has_endpoint(POSE_TOPIC, NODE_NAME, True), 30.0)
        self.stream = stream
        self.node = NodeProcess(scene_path(scene), [f"particles:={particles}"],
                                child_env(side.domain_id), log_path)
        stream.node = self.node
        t0 = time.monotonic()
        ok = stream.wait(lambda: stream.pub.get_subscription_count() > 0
                         and stream.rec.matched(), start_timeout_s)
        if not ok:

            self.node.kill()
            raise NodeError(f"cloth_node did not match the benchmark's topics within "
                            f"{start_timeout_s:g} s; its log ({log_path}):\n{self.node.tail()}")
        stream.wait(lambda: False, 0.5)  # the other side of discovery
        log(f"bench faults: cloth_node up after {time.monotonic() - t0:.1f} s ({log_path})")

    def live_until_dressed(self) -> None:
        """Stream until the garment is dressed, then START_LIVE_S more."""
        s = self.stream
        n = len(s.rec.ticks)
        s.run(0.0, until=lambda: any(x.message.startswith("dressed")
                                     for x in s.rec.ticks[n:]), max_s=DRESS_TIMEOUT_S)
        s.run(START_LIVE_S)

    def stop(self) -> int:
        code = self.node.stop()
        self.stream.node = None
        return code


def _run_stream_session(stream: FaultStream, names: Sequence[str], frames, hog_s: float,
                        scene: str, particles: int, log_path: Path, start_timeout_s: float,
                        log: Callable[[str], None]) -> list[dict]:
    rows: list[dict] = []
    faults = _stream_faults(frames, hog_s)
    session = None
    pending = list(names)
    try:
        session = _Session(stream, scene, particles, log_path, start_timeout_s, log)
        session.live_until_dressed()
        stream.run(0.0, until=lambda: stream.latest_values().get("level") == "0",
                   max_s=LEVEL0_TIMEOUT_S)
        before, _ = stream.drain()
        while pending:
            name = pending[0]
            log(f"bench faults: {name}: {FAULTS[name]}")
            (t_row, t0, t1, t_end), extra = faults[name](stream)
            after, drained = stream.drain()
            if not drained:
                extra["drain_timed_out"] = True
            r = stream.rec
            rows.append(stream_row(
                name, FAULTS[name], stream.sent, r.markers, r.clears, r.ticks,
                Marks(t_row, t0, t1, t_end, time.monotonic()), before, after,
                latency_from_stats=name == "sub_gone", extra=extra))
            before = after
            pending.pop(0)
    except NodeError as exc:
        for name in pending:
            rows.append({"name": name, "fault": FAULTS[name],
                         "error": f"cloth_node failed: {str(exc).splitlines()[0]}"})
        log(str(exc))
    finally:
        if session is not None:
            code = session.stop()
            log(f"bench faults: cloth_node exited with status {code}")
    return rows


def _run_signal_session(stream: FaultStream, name: str, scene: str, particles: int,
                        log_path: Path, start_timeout_s: float,
                        log: Callable[[str], None]) -> dict:
    sig = signal.SIGINT if name == "sigint" else signal.SIGTERM
    log(f"bench faults: {name}: {FAULTS[name]} while the node ticks")
    session = None
    try:
        r = stream.rec
        first = len(r.markers), len(r.clears), len(r.ticks)  # this node's are after these
        session = _Session(stream, scene, particles, log_path, start_timeout_s, log)
        session.live_until_dressed()
        stream.run(SIGNAL_LIVE_S)
        ticks = [float(x.values["step_ms"]) for x in stream.rec.ticks[-30:]
                 if int(x.values.get("substeps", 0)) > 0]
        half_tick_s = 0.5e-3 * float(np.median(ticks)) if ticks else 0.005
        pose = stream.send_valid()
        # Half a median tick after a pose: its tick is most likely running.
        stream.wait(lambda: False, half_tick_s)
        t_signal = time.monotonic()
        session.node.proc.send_signal(sig)
        stream.node = None  # its exit is what is awaited now
        proc = session.node.proc
        stream.run(0.0, until=lambda: proc.poll() is not None, max_s=EXIT_TIMEOUT_S)
        exit_s = time.monotonic() - t_signal if proc.poll() is not None else None
        session.node.kill()  # after the wait: still running means it hung
        # DELETEALLs sent before the exit may still be on their way: wait a little for them.
        stream.wait(lambda: {c.topic for c in stream.rec.clears if c.t >= t_signal}
                    >= {"marker", "markers"}, 3.0)
        return signal_row(
            name, sig.name, stream.sent, r.markers[first[0]:], r.clears[first[1]:],
            r.ticks[first[2]:], t_signal, pose,
            int(proc.returncode), exit_s, log_path.read_text(errors="replace"),
            extra={"half_tick_s": half_tick_s})
    except NodeError as exc:
        return {"name": name, "fault": FAULTS[name],
                "error": f"cloth_node failed: {str(exc).splitlines()[0]}"}
    finally:
        if session is not None:
            session.node.kill()
            stream.node = None


def _check_particles(value: int, flag: str) -> int:
    """A particle count the node takes (the schema's range of `particles`), not 'auto'."""
    if isinstance(value, str):
        raise ClothInputError(f"{flag} must be an integer, got {value!r}")
    return PARAMETERS["particles"].check(value, flag)


def bench_faults(faults: Sequence[str] | None = None, particles: int = 1200,
                 hog_s: float = 10.0, scene: str = "walking", domain_id: int | None = None,
                 log_dir: str | os.PathLike | None = None,
                 start_timeout_s: float | None = None,
                 log: Callable[[str], None] = print,
                 load_particles: int | None = LOAD_PARTICLES,
                 bag: str | os.PathLike | None = None, rate_hz: float = RATE_HZ) -> dict:
    """Run cloth_node under each fault and judge what it did (module docstring of
    `cloth_mg_ros.bench.faults`).

    Args:
        faults: row names (FAULTS; None: all), run in FAULTS' order.
        particles: the garment's size (about), passed as `particles:=N`.
        hog_s: how long each CPU hog runs, s.
        scene: the body scene (config/<scene>.yaml, or a params .yaml).
        domain_id: the ROS domain (None: a free one, `open_ros_side`).
        log_dir: where the nodes' logs go (None: a temporary folder, removed).
        start_timeout_s: wait this long for a node to start, s (None: the default).
        log: where progress lines go.
        load_particles: the garment's size in the CPU-hog rows, which then run on a node of
            their own (None or `particles`: on the node of the other stream rows). It needs
            a coarser level of detail to step down to: the walking dress has none at 1200
            particles (two hierarchy levels, the coarse one of about 300 particles is the
            multigrid's) and one of 615 particles at 2400.
        bag: the bag whose poses are streamed (a path or a bundled bag's name; None: the
            scene's). The node keeps the scene's: its calibration never sees this motion.
        rate_hz: the stream's rate, Hz: each of the bag's poses in turn, stamped 1/rate_hz
            s apart and sent as often (below the bag's 30 Hz the body moves in slow motion):
            a slower tracker, whose longer pose period gives every tick a larger budget.

    Returns:
        {"rows": [a row's figures (stream_row / signal_row) with "did", "why",
        "ok"], "ok" (every row), "particles", "load_particles", "scene", "hog_s", "faults",
        "domain_id", "wall_s", "host"}. ClothInputError for bad arguments.
    """
    names, load_particles = _checked(faults, particles, load_particles, hog_s, rate_hz)
    params = load_scene(scene)
    bag_path = resolve_bag(params.bag if bag is None else bag)
    frames = read_pose_frames(bag_path, POSE_TOPIC)
    start_timeout_s = START_TIMEOUT_S if start_timeout_s is None else start_timeout_s
    run = _FaultsRun(names, particles, load_particles, hog_s, scene, params.scene, frames,
                     start_timeout_s, float(rate_hz))
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="cloth_bench_faults_") as tmp:
        logs = Path(log_dir) if log_dir is not None else Path(tmp)
        logs.mkdir(parents=True, exist_ok=True)
        side = open_ros_side(domain_id, "cloth_bench_faults", log)
        try:
            rows = _run_rows(run, side, logs, log)
        finally:
            side.close()
    _judge(rows)
    return {"rows": rows, "ok": all(r["ok"] for r in rows), "particles": particles,
            "load_particles": load_particles, "scene": params.scene, "bag": recorded_path(bag_path),
            "hog_s": hog_s, "rate_hz": float(rate_hz),
            "faults": names, "domain_id": side.domain_id,
            "wall_s": time.monotonic() - t_start,
            "node_logs": str(log_dir) if log_dir is not None else None,
            "host": {"machine": platform.machine(), "cpus": os.cpu_count(),
                     "python": platform.python_version()}}


def _checked(faults: Sequence[str] | None, particles: int, load_particles: int | None,
             hog_s: float, rate_hz: float) -> tuple[list[str], int]:
    """(the rows in run order, the hog rows' garment size), once the options are checked
    (ClothInputError)."""
    names = list(FAULTS) if faults is None else parse_faults(",".join(faults))
    _check_particles(particles, "--particles")
    load_particles = particles if load_particles in (None, 0) else _check_particles(
        load_particles, "--load-particles")
    if not (hog_s > 0.0 and np.isfinite(hog_s)):
        raise ClothInputError(f"--hog-s must be a positive number of seconds, got {hog_s!r}")
    if not (isinstance(rate_hz, (int, float)) and np.isfinite(rate_hz)
            and 1.0 <= rate_hz <= 120.0):
        raise ClothInputError(f"--rate-hz must be from 1 to 120 Hz, got {rate_hz!r}")
    return names, load_particles


def _judge(rows: list[dict]) -> None:
    """Each row's verdict, in place: "why" (what failed, '' if nothing), "ok", "did"."""
    for r in rows:
        r["why"] = check_row(r)
        r["ok"] = not r["why"]
        r["did"] = describe_row(r)


@dataclass(frozen=True)
class _FaultsRun:
    """The checked options of a `bench_faults` run: the rows, the garment's size (and the
    hog rows'), the hogs' length (s), the scene (as given, and its name), its bag's frames,
    the node's start-up limit (s)."""

    names: list[str]
    particles: int
    load_particles: int
    hog_s: float
    scene: str
    scene_name: str
    frames: list
    start_timeout_s: float
    rate_hz: float = RATE_HZ


def _sessions(run: _FaultsRun) -> list[tuple[str, list[str], int]]:
    """(session, its stream rows, particles): one node for every stream row, or the hog
    rows on a node of their own when their garment's size differs."""
    stream_names = [n for n in run.names if n in STREAM_FAULTS]
    if run.load_particles == run.particles:
        return [("stream", stream_names, run.particles)]
    return [("load", [n for n in stream_names if n in LOAD_ROWS], run.load_particles),
            ("stream", [n for n in stream_names if n not in LOAD_ROWS], run.particles)]


def _run_rows(run: _FaultsRun, side, logs: Path, log: Callable[[str], None]) -> list[dict]:
    """Every row's figures: the stream sessions, then a node of its own per signal row, all
    fed by one stream on `side`; the nodes' logs go into `logs`."""
    source = PoseSource([p for _, p in run.frames], time.time_ns(), run.rate_hz)
    stream = FaultStream(side, source, POSE_TOPIC, run.rate_hz)
    rows: list[dict] = []
    for session, session_names, n in _sessions(run):
        if not session_names:
            continue
        log(f"bench faults: scene {run.scene_name}, ~{n} particles, ROS domain "
            f"{side.domain_id}: {', '.join(session_names)}")
        rows += _run_stream_session(stream, session_names, run.frames, run.hog_s, run.scene,
                                    n, logs / f"{session}.node.log", run.start_timeout_s, log)
    for name in (n for n in run.names if n in SIGNAL_ROWS):
        rows.append(_run_signal_session(stream, name, run.scene, run.particles,
                                        logs / f"{name}.node.log", run.start_timeout_s, log))
    return rows
