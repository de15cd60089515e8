"""`cloth-mg bench trackers`: cloth_node driven by a body tracker's joints, against the segment
input, on one clip, over DDS.

    cloth-mg bench trackers --bvh CLIP.bvh --json out/bench_trackers.json
    cloth-mg bench trackers --bvh CLIP.bvh --particles 1200 --jitter-mm 2 --occlusion 0.05

The clip becomes four bags (`bag_from_bvh`, 30 Hz, 1 s settle): the avatar's segment poses in
the z-up world, and the same motion as a tracker sends it (motion.tracker_view): kinect32 and
mediapipe33 joint positions (PoseArray) and the Azure Kinect driver's MarkerArray, each in a
camera's frame (x right, y down, z forward; 3 m in front of the subject, 1 m up), jittered
(`--jitter-mm`, Gaussian per axis), limb joints hidden in spans of 0.1-0.8 s (`--occlusion`,
the share of their samples). Then:

1. **Capsules.** Each tracker bag through the node's own conversion (ros.body_input.BodyInput,
   the node's defaults: hold 0.15 s, 1 Euro filter; input_transform the camera's pose): every
   capsule end point placed against the segment input's at the same frame (p50, p95, max, m),
   and the segment samples dropped (lost joints). Then once more with the camera's height
   unknown (its z 0) and floor_height auto, as a user who knows the camera's tilt but not its
   height sets them: `floor_found_m` is where that puts the floor in the clip's world (the
   floor is z = 0 there; the avatar's convention, its lowest point over the first second at
   its ground clearance, is what is found).
2. **Live.** cloth_node over DDS for each input (the scene's params file, `--particles`), the
   bag replayed at `--rate`: pose messages sent, received, used, skipped (by kind), dropped
   (must be 0), statuses with a non-finite cloth (must be 0), the deepest penetration per tick
   into the body the node simulates (its `max_penetration_m`), and into the true body: each
   cloth marker's triangle corners against the segment input's colliding capsules at the
   marker's stamp (`true_penetration_m`: per marker the deepest, then p50, p95, max).
   `--repeats N` runs each input N times and pools the ticks and markers (a clip gives about
   100 markers a run, few for a p95); `runs` keeps each run's figures.
   `holds`: every pose used, nothing non-finite, every cloth marker received matched to a
   true body pose (and at least one), the capsules within CAPSULE_LIMIT_M (p95) and the true
   penetration's p95 within the segment input's plus PENETRATION_MARGIN_M (issue 43's
   figures). An empty sample's percentiles are None, never 0.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.node_figures import percentiles
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError

__all__ = ["CAPSULE_LIMIT_M", "INPUTS", "PENETRATION_MARGIN_M", "add_cli", "bench_trackers",
           "marker_depths", "verdicts"]

CAPSULE_LIMIT_M = 0.01  # capsules from joints within this of the segment input's (issue 43)
PENETRATION_MARGIN_M = 0.002  # penetration within the segment input's plus this (issue 43)
#: input name -> (bag_from_bvh body_input, skeleton); the node's body_input and skeleton
INPUTS = {
    "segments": ("segments", None),
    "kinect32": ("joints", "kinect32"),
    "mediapipe33": ("joints", "mediapipe33"),
    "kinect_markers": ("kinect_markers", None),
}
# The conversion's own log (the avatar sized from the stream): quiet, the live runs log it
_LOG = logging.getLogger(__name__)
_LOG.addHandler(logging.NullHandler())
_LOG.propagate = False
IDLE_S = 60.0  # s without a new status after the replay: the node is done (or stuck)


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench trackers`."""
    t = bsub.add_parser("trackers", help="cloth_node driven by a tracker's joints (kinect32, "
                        "mediapipe33, the Azure Kinect MarkerArray) in a camera frame with "
                        "jitter and occlusion, against the segment input, over DDS")
    t.add_argument("--bvh", required=True, help="the clip (a CMU-style BVH)")
    t.add_argument("--scene", default="walking", help="body scene (default walking)")
    t.add_argument("--particles", type=int, default=1200, help="cloth particles (1200)")
    t.add_argument("--rate", type=float, default=1.0, help="replay speed factor (1)")
    t.add_argument("--jitter-mm", type=float, default=2.0, help="joint jitter, mm (2)")
    t.add_argument("--occlusion", type=float, default=0.05,
                   help="share of the limb joints' samples hidden (0.05)")
    t.add_argument("--seed", type=int, default=0, help="the jitter's and occlusion's seed")
    t.add_argument("--repeats", type=int, default=1,
                   help="live runs per input, their ticks and markers pooled (1)")
    t.add_argument("--inputs", default=",".join(INPUTS),
                   help=f"comma list of {', '.join(INPUTS)} (default all)")
    t.add_argument("--json", default="out/bench_trackers.json", help="JSON output file")
    t.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run it, print the table, write the JSON; 0 when every figure holds, 1 otherwise."""
    inputs = [s.strip() for s in args.inputs.split(",") if s.strip()]
    result = bench_trackers(args.bvh, scene=args.scene, particles=args.particles,
                            rate=args.rate, jitter_m=1e-3 * args.jitter_mm,
                            occlusion=args.occlusion, seed=args.seed, inputs=inputs,
                            repeats=args.repeats)
    print(format_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}")
    return 0 if result["holds"] else 1


def bench_trackers(bvh: str | Path, *, scene: str = "walking", particles: int = 1200,
                   rate: float = 1.0, jitter_m: float = 0.002, occlusion: float = 0.05,
                   seed: int = 0, inputs: list[str] | None = None, repeats: int = 1,
                   log: Callable[[str], None] = print) -> dict:
    """The module docstring's runs; returns {"clip", "view", "inputs": {name: {...}},
    "holds"}. ClothInputError for a bad argument, before any work."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.io.bags import read_pose_frames
    from cloth_mg_ros.motion.tracker_view import TrackerView

    inputs = list(INPUTS) if inputs is None else inputs
    unknown = [n for n in inputs if n not in INPUTS]
    if unknown or "segments" not in inputs:
        raise ClothInputError(f"--inputs must name segments and any of "
                              f"{', '.join(INPUTS)}, got {', '.join(inputs)}")
    if not Path(bvh).is_file():
        raise ClothInputError(f"{bvh}: BVH file not found")
    if not (isinstance(repeats, int) and repeats >= 1):
        raise ClothInputError(f"--repeats must be a positive integer, got {repeats!r}")
    _check_options(scene, particles, rate, jitter_m, occlusion)
    view = TrackerView(None, jitter_m, occlusion, seed)
    out: dict = {"clip": Path(bvh).name, "scene": scene, "particles": particles,
                 "rate": rate, "repeats": repeats,
                 "view": {"jitter_mm": 1e3 * jitter_m, "occlusion": occlusion, "seed": seed},
                 "inputs": {}}
    with tempfile.TemporaryDirectory(prefix="cloth_bench_trackers_") as tmp:
        bags = _write_bags(Path(bvh), Path(tmp), inputs, view)
        truth = {round(t * 1e9): p for t, p in read_pose_frames(bags["segments"])}
        for name in inputs:
            row = out["inputs"][name] = {}
            if name != "segments":
                row["capsules"] = capsule_errors(bags["segments"], bags[name], name)
                log(f"bench trackers: {name}: capsules p95 "
                    f"{1e3 * row['capsules']['p95_m']:.1f} mm")
            row["live"] = pooled([live_run(bags[name], name, scene, particles, rate,
                                           Path(tmp) / f"{name}_{k}.log", truth, log)
                                  for k in range(repeats)])
    out["holds"] = verdicts(out["inputs"])
    return out


def _check_options(scene: str, particles: int, rate: float, jitter_m: float,
                   occlusion: float) -> None:
    """The scene (a body scene), particles and rate (what cloth_node accepts), the jitter (m)
    and the occlusion (a share in [0, 1), at most TrackerView's limit), before any bag is
    written or node started; ClothInputError naming the option."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import is_body_scene
    from cloth_mg_ros.ros.demo import check_particles, check_rate

    if not is_body_scene(scene):
        raise ClothInputError(f"--scene: {scene!r} is not a body scene")
    try:
        check_particles(particles)
    except ClothInputError as exc:
        raise ClothInputError(f"--particles: {exc}") from None
    check_rate(rate)
    if isinstance(jitter_m, bool) or not isinstance(jitter_m, (int, float)) or not (
            0.0 <= jitter_m <= 0.1):
        raise ClothInputError(f"--jitter-mm must be in [0, 100], got {jitter_m!r} m")
    if isinstance(occlusion, bool) or not isinstance(occlusion, (int, float)) or not (
            0.0 <= occlusion < 1.0):
        raise ClothInputError(f"--occlusion must be a share in [0, 1), got {occlusion!r}")


def _write_bags(bvh: Path, root: Path, inputs: list[str], view) -> dict[str, Path]:
    """One bag per input (module docstring); the tracker bags carry the camera's pose."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.motion.pose_bags import bag_from_bvh

    bags = {}
    for name in inputs:
        body_input, skeleton = INPUTS[name]
        bags[name] = root / name
        bag_from_bvh(bvh, bags[name], body_input=body_input, skeleton=skeleton,
                     view=None if name == "segments" else view)
    return bags


def node_values(name: str, bag: Path, floor_auto: bool = False) -> dict:
    """The node's parameter values for input `name` of tracker bag `bag`: body_input,
    skeleton, input_transform the camera's pose from the bag ([x, y, z, qx, qy, qz, qw]);
    floor_auto: its height left out (z 0), floor_height auto."""
    body_input, skeleton = INPUTS[name]
    values: dict = {"body_input": body_input} if name != "segments" else {}
    if skeleton is not None:
        values["skeleton"] = skeleton
    if name == "segments":
        return values
    camera = _camera(bag)
    if floor_auto:
        camera[2] = 0.0  # the camera's height is not known: the floor is found instead
        values["floor_height"] = "auto"
    values["input_transform"] = camera
    return values


def node_parameters(name: str, bag: Path, floor_auto: bool = False) -> list[str]:
    """node_values as the node's command-line arguments (`name:=value`)."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.motion.tracker_view import transform_text

    return [f"{k}:={transform_text(np.array(v)) if k == 'input_transform' else v}"
            for k, v in node_values(name, bag, floor_auto).items()]


def capsule_errors(segment_bag: Path, tracker_bag: Path, name: str) -> dict:
    """The node's conversion of `tracker_bag` (its defaults and node_parameters) against the
    segment bag's capsules, frame by frame: end-point error over placed segments; and the
    floor found with floor_height auto (module docstring)."""
    out = _conversion_errors(segment_bag, tracker_bag, name, False)
    camera = _camera(tracker_bag)
    found = _conversion_errors(segment_bag, tracker_bag, name, True)["floor_m"]
    out["floor_found_m"] = found + camera[2]
    return out


def _camera(bag: Path) -> list[float]:
    """The camera's pose [x, y, z, qx, qy, qz, qw] a tracker bag records."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.io.bags import bag_info

    return [float(v) for v in bag_info(bag)["custom_data"][
        "cloth_mg_ros.input_transform"].strip("[]").split(",")]


def _conversion_errors(segment_bag: Path, tracker_bag: Path, name: str,
                       floor_auto: bool) -> dict:
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.io.bags import read_pose_frames
    from cloth_mg_ros.io.kinect_markers import read_kinect_marker_frames
    from cloth_mg_ros.ros.body_input import BodyInput
    from cloth_mg_ros.ros.ingest import KeyPose
    from cloth_mg_ros.ros.parameters import check_parameters

    conv = BodyInput(check_parameters({"scene": "walking", **node_values(name, tracker_bag,
                                                                        floor_auto)}), _LOG)
    if name == "kinect_markers":
        stamps, joints, _ = read_kinect_marker_frames(tracker_bag)
        frames = [(t, np.column_stack([j, np.zeros((len(j), 3)), np.ones(len(j))]))
                  for t, j in zip(stamps, joints, strict=True)]
    else:
        frames = read_pose_frames(tracker_bag)
    keys = [KeyPose(int(t), round((t % 1) * 1e9), float(t), "camera", p) for t, p in frames]
    skipped: list = []
    got = {k.stamp: k for k in conv.convert(keys, lambda *a: skipped.append(a))}
    want = {float(t): p for t, p in read_pose_frames(segment_bag)}
    errors = []
    for stamp, key in got.items():
        a0, a1, _ = conv.avatar.capsules(key.poses)
        b0, b1, _ = conv.avatar.capsules(want[stamp])
        err = np.maximum(np.linalg.norm(a0 - b0, axis=1), np.linalg.norm(a1 - b1, axis=1))
        errors.append(err if key.dropped is None else err[~key.dropped])
    e = np.concatenate(errors) if errors else np.zeros(0)
    return {"frames": len(keys), "placed": len(got), "skipped": len(skipped),
            "segments_dropped": conv.dropped_samples, "floor_m": conv.frame.floor or 0.0,
            "p50_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95)),
            "max_m": float(e.max())}


def live_run(bag: Path, name: str, scene: str, particles: int, rate: float, log_path: Path,
             truth: dict[int, np.ndarray], log: Callable[[str], None]) -> dict:
    """cloth_node on input `name`, `bag` replayed into it; the figures of its statuses and
    its cloth against the true body (truth: stamp ns -> segment poses)."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from diagnostic_msgs.msg import DiagnosticArray
    from visualization_msgs.msg import Marker

    from cloth_mg_ros.config.scenes import scene_path
    from cloth_mg_ros.ros.processes import (
        MARKER_TOPIC,
        STATS_TOPIC,
        NodeError,
        NodeProcess,
        child_env,
        open_ros_side,
        wait_for_node,
    )
    from cloth_mg_ros.ros.replay import reliable_qos, replay_bag

    side = open_ros_side(None, "cloth_bench_trackers", log)
    raw: list[bytes] = []
    markers: list[bytes] = []
    side.node.create_subscription(DiagnosticArray, STATS_TOPIC, raw.append, reliable_qos(),
                                  raw=True)
    side.node.create_subscription(Marker, MARKER_TOPIC, markers.append, reliable_qos(),
                                  raw=True)
    node, stop, sent = None, threading.Event(), []
    try:
        node = NodeProcess(scene_path(scene), [f"particles:={particles}", "threads:=1",
                                               *node_parameters(name, bag)],
                           child_env(side.domain_id), log_path)
        wait_for_node(side, node)
        log(f"bench trackers: {name}: cloth_node up; replaying {bag.name}")
        thread = threading.Thread(target=lambda: sent.append(replay_bag(
            bag, rate=rate, context=side.ctx, wait_s=30.0, settle_s=0.5, stop=stop,
            node_name="cloth_bench_trackers_replay", log=lambda line: None)), daemon=True)
        thread.start()
        side.spin_until(_done(thread, raw, sent), float("inf"), node, "while simulating")
    finally:
        stop.set()
        code = node.stop() if node is not None else -1
        side.close()
    if code != 0:
        raise NodeError(f"cloth_node did not exit cleanly (status {code}): {node.tail()}")
    figures = _live_figures(raw, sent[0].messages if sent else 0)
    figures["marker_depths_m"] = marker_depths(markers, truth)
    figures["markers_received"] = len(markers)
    return figures


# counts a live run reports that add up over repeats
_COUNTS = ("sent", "poses_received", "poses_used", "dropped", "poses_pending",
           "segments_dropped", "joints_held", "joints_lost", "ticks", "non_finite")


def pooled(runs: list[dict]) -> dict:
    """One input's live figures over its runs (`live_run`'s, with their per-tick penetrations
    and per-marker depths): the counts summed, the penetrations' p50, p95 and max over every
    tick and every marker of all runs; "runs" keeps each run's counts and percentiles."""
    skipped: dict[str, int] = {}
    for r in runs:
        for k, n in r["skipped"].items():
            skipped[k] = skipped.get(k, 0) + n
    merged = {**{k: sum(r[k] for r in runs) for k in _COUNTS}, "skipped": skipped,
              "tick_penetration_m": np.concatenate([r["tick_penetration_m"] for r in runs]),
              "marker_depths_m": np.concatenate([r["marker_depths_m"] for r in runs]),
              "markers_received": sum(_received(r) for r in runs)}
    return {**_summary(merged), "runs": [_summary(r) for r in runs]}


def _received(run: dict) -> int:
    """The cloth markers a run received (those matched, where the run does not say)."""
    return int(run.get("markers_received", len(run["marker_depths_m"])))


def _summary(run: dict) -> dict:
    """A run's (or the pooled runs') counts and penetration percentiles, m."""
    return {**{k: run[k] for k in _COUNTS}, "skipped": run["skipped"],
            "markers_received": _received(run),
            "penetration_m": percentiles(run["tick_penetration_m"]),
            "true_penetration_m": {"markers": len(run["marker_depths_m"]),
                                   **percentiles(run["marker_depths_m"])}}


def marker_depths(markers: list[bytes], truth: dict[int, np.ndarray]) -> np.ndarray:
    """Per cloth marker (raw Marker bytes) the deepest corner inside the true body's colliding
    capsules at the marker's stamp (truth: stamp ns -> segment poses (S, 7)), m, 0 outside
    (markers of a stamp the truth lacks: left out)."""
    # imported here: a bench's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.collision.capsules import point_segment_distances
    from cloth_mg_ros.config.schema import body_options
    from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
    from cloth_mg_ros.motion.joint_body import packaged_avatar

    avatar = packaged_avatar()
    seg = body_options().colliding_segments(tuple(avatar.names))
    depths = []
    for data in markers:
        m = marker_arrays_from_bytes(data)
        poses = truth.get(m.stamp_sec * 1_000_000_000 + m.stamp_nanosec)
        if poses is None or not len(m.points):
            continue
        p0, p1, r = (a[seg] for a in avatar.capsules(poses))
        inside = r[None, :] - point_segment_distances(m.points, p0, p1)
        depths.append(float(np.max(inside, initial=0.0)))
    return np.maximum(np.array(depths), 0.0)


def _done(thread: threading.Thread, raw: list[bytes], sent: list) -> Callable[[], bool]:
    """done() for spin_until: the replay ended and the node's last status has every pose
    received and none pending, or no status came for IDLE_S."""
    last = [time.monotonic(), 0]

    def done() -> bool:
        if len(raw) != last[1]:
            last[:] = [time.monotonic(), len(raw)]
        if thread.is_alive() or not sent:
            return False
        values = _statuses(raw[-1:])[0][0] if raw else {}
        settled = (int(values.get("poses_received", -1)) >= sent[0].messages
                   and values.get("poses_pending") == "0")
        return settled or time.monotonic() - last[0] > IDLE_S

    return done


def _statuses(raw: list[bytes]) -> list[tuple[dict[str, str], str]]:
    """(values, message) of each status in the raw DiagnosticArray messages."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    out = []
    for data in raw:
        for st in deserialize_message(data, DiagnosticArray).status:
            out.append(({kv.key: kv.value for kv in st.values}, st.message))
    return out


def _live_figures(raw: list[bytes], sent: int) -> dict:
    statuses = _statuses(raw)
    ticks = [v for v, _ in statuses if int(v.get("substeps", "0")) > 0]
    pen = np.array([float(v["max_penetration_m"]) for v in ticks]) if ticks else np.zeros(0)
    last = statuses[-1][0] if statuses else {}
    skipped = {k[len("skipped_"):]: int(n) for k, n in last.items()
               if k.startswith("skipped_") and int(n)}
    num = {k: int(last.get(k, "-1")) for k in ("poses_received", "poses_used", "dropped",
                                               "poses_pending", "segments_dropped",
                                               "joints_held", "joints_lost")}
    return {"sent": sent, **num, "skipped": skipped, "ticks": len(ticks),
            "non_finite": sum("non-finite" in m for _, m in statuses),
            "tick_penetration_m": pen}


def verdicts(rows: dict) -> bool:
    """Mark each row's `holds` (module docstring); True when every row holds. A row whose
    cloth markers were none, or not all matched to a true body pose, does not hold: its true
    penetration is unmeasured, not zero."""
    base = rows["segments"]["live"]["true_penetration_m"]["p95"]
    ok = True
    for name, row in rows.items():
        live = row["live"]
        row["every_pose_used"] = (live["sent"] == live["poses_received"] == live["poses_used"]
                                  and live["dropped"] == 0)
        matched = live["true_penetration_m"]["markers"]
        row["markers_matched"] = matched > 0 and matched >= live.get("markers_received", matched)
        holds = row["every_pose_used"] and live["non_finite"] == 0 and row["markers_matched"]
        if name != "segments":
            p95 = live["true_penetration_m"]["p95"]
            row["penetration_within"] = (p95 is not None and base is not None
                                         and p95 <= base + PENETRATION_MARGIN_M)
            row["capsules_within"] = row["capsules"]["p95_m"] <= CAPSULE_LIMIT_M
            holds = holds and row["penetration_within"] and row["capsules_within"]
        row["holds"] = holds
        ok = ok and holds
    return ok


def _mm(metres: float | None) -> str:
    """A length in m as mm with two decimals; '-' for no figure."""
    return "-" if metres is None else f"{1e3 * metres:.2f}"


def format_report(r: dict) -> str:
    """The table `cloth-mg bench trackers` prints."""
    v = r["view"]
    lines = [f"bench trackers: {r['clip']}, scene {r['scene']} ~{r['particles']} particles, "
             f"rate {r['rate']:g}, {r.get('repeats', 1)} live run(s) per input pooled; "
             f"tracker view: camera frame, jitter {v['jitter_mm']:g} mm, "
             f"occlusion {v['occlusion']:g} (seed {v['seed']})",
             f"{'input':<15}{'sent':>6}{'used':>6}{'skip':>6}{'drop':>6}{'NaN':>5}"
             f"{'pen p95 mm':>12}{'true p95 mm':>12}{'true max mm':>12}"
             f"{'caps p95 mm':>13}{'caps max mm':>13}"
             f"{'seg dropped':>13}{'floor mm':>10}  holds"]
    for name, row in r["inputs"].items():
        live, caps = row["live"], row.get("capsules")
        lines.append(
            f"{name:<15}{live['sent']:>6}{live['poses_used']:>6}"
            f"{sum(live['skipped'].values()):>6}{live['dropped']:>6}{live['non_finite']:>5}"
            f"{_mm(live['penetration_m']['p95']):>12}"
            f"{_mm(live['true_penetration_m']['p95']):>12}"
            f"{_mm(live['true_penetration_m']['max']):>12}"
            + (f"{1e3 * caps['p95_m']:>13.2f}{1e3 * caps['max_m']:>13.2f}"
               f"{caps['segments_dropped']:>13}{1e3 * caps['floor_found_m']:>10.1f}"
               if caps else f"{'':>49}")
            + f"  {row['holds']}")
    lines.append(f"every figure holds: {r['holds']}")
    return "\n".join(lines)
