"""`cloth-mg bench cost`: the cost model's prediction against measured ticks.

The scene's cost model (calibrated afresh, or the cached one with --cached) predicts the
median tick at each size; the scene's garments of those sizes then run through the scene's
bag side by side, each taking every pose message in turn, one per tick as the headless
runner does, and the median and 95th percentile of the ticks of the motion are measured (the
bag's opening hold, at least WARMUP_TICKS, settles the garments untimed: a still body costs
less than a moving one, and a live node must keep up with the motion). The error of the
prediction (%) tells a user how far `particles: auto` can be trusted on this machine; the
shape error, both taken relative to the 2400-particle row, how far the model's growth with
the particles can, whatever the machine's speed did since the calibration.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING

import numpy as np

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.budget.cost_model import load_or_calibrate, motion_start, stream_rate
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.config.schema import MAX_PARTICLES, check
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.mesh.garments.design import MIN_PARTICLES as GARMENT_MIN_PARTICLES
from cloth_mg_ros.mesh.generators import MIN_PARTICLES as GENERATOR_MIN_PARTICLES
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.tick_stats import TickStats

if TYPE_CHECKING:
    from cloth_mg_ros.config.schema import SceneParams

DEFAULT_SIZES = (1200, 2400, 4500, 10000)
WARMUP_TICKS = 20  # at least: the cloth settles first (a dressed cloth solves fast)
MIN_TIMED_TICKS = 10


def validate_cost_args(params: SceneParams, sizes: list, ticks: int) -> None:
    """Check the sizes (integers a garment of the scene accepts) and `ticks` (at least
    MIN_TIMED_TICKS, which every size must time) before any work: the calibration alone takes
    minutes. One ClothInputError lists every problem."""
    problems = []
    low = GARMENT_MIN_PARTICLES.get(params.garment, GENERATOR_MIN_PARTICLES)
    if not sizes:
        problems.append("--particles must list at least one size")
    for n in sizes:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not (
                low <= n <= MAX_PARTICLES):
            problems.append(f"--particles: {n!r} is not an integer in [{low}, {MAX_PARTICLES}] "
                            f"(a {params.garment})")
    if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < MIN_TIMED_TICKS:
        problems.append(f"--ticks must be an integer >= {MIN_TIMED_TICKS} (the fewest timed "
                        f"ticks a size's median and p95 are read from), got {ticks!r}")
    if problems:
        raise ClothInputError("bench cost: " + "; ".join(problems))


def timed_window(params: SceneParams, frames: list, ticks: int) -> tuple[int, int]:
    """(first, end): the indices of `frames` whose ticks are timed (after the bag's opening
    hold and at least WARMUP_TICKS, at most `ticks` of them); ClothInputError when the bag
    leaves fewer than MIN_TIMED_TICKS."""
    first = min(max(WARMUP_TICKS + 1, motion_start(frames)), len(frames))
    end = min(first + ticks, len(frames))
    if end - first < MIN_TIMED_TICKS:
        raise ClothInputError(f"bag {params.bag}: {len(frames)} poses leave "
                              f"{end - first} ticks of motion to time, {MIN_TIMED_TICKS} "
                              f"needed")
    return first, end


def measure_ticks(params: SceneParams, frames: list, sizes: list[int], ticks: int, material,
                  tolerances=()) -> list[dict]:
    """Median and p95 of up to `ticks` timed ticks of the motion (after the bag's opening
    hold and at least WARMUP_TICKS) of the scene's garment at each of `sizes` (about so many
    particles) on its bag's `frames` [(stamp s, poses (S, 7))], the garments taking each
    message in turn (so that a machine whose speed wanders over minutes slows every size
    alike, and the sizes' ratios hold: measured one after another, the walking dress's 9964
    against 2394 particles read 2.4-5.0 over five runs): per size {"particles", "median_ms",
    "p95_ms", "steps", "ticks", "first_tick", "tolerance"} (the relative residual its finest
    level solved to). tolerances: the cost model's, for a scene with tolerance auto."""
    first, end = timed_window(params, frames, ticks)
    garments = [GarmentSim.dress(Avatar.load(), frames[0][0], frames[0][1], material,
                                 BodySimOptions.from_scene(params, particles=int(n),
                                                           tolerances=tuple(tolerances)))
                for n in sizes]
    times: list[list[float]] = [[] for _ in sizes]
    steps: list[list[int]] = [[] for _ in sizes]
    for k in range(1, end):
        for i, garment_sim in enumerate(garments):
            stats = garment_sim.push(*frames[k])
            if isinstance(stats, TickStats) and k >= first:
                times[i].append(stats.total_ms)
                steps[i].append(stats.substeps)
    return [{"particles": int(g.positions.shape[0]), "median_ms": float(np.median(t)),
             "p95_ms": float(np.percentile(t, 95)), "steps": float(np.mean(st)),
             "ticks": len(t), "first_tick": first, "tolerance": float(g.sim.solver.tol)}
            for g, t, st in zip(garments, times, steps, strict=True)]


def bench_cost(scene: str, sizes=DEFAULT_SIZES, ticks: int = 60, cached: bool = False,
               log=print, contact_friction: str | None = None) -> dict:
    """Calibrate (or load) the scene's cost model and compare it with measured ticks.

    sizes: garment particle counts; ticks: timed ticks per size, at most (>= MIN_TIMED_TICKS);
    contact_friction: the scene's parameter instead of the file's (None: the file's).
    Returns {"scene", "rate_hz", "contact_friction", "model", "from_cache",
    "calibration_wall_s", "rows", "max_abs_error_pct"}; ClothInputError for a bad option or a
    too short bag, before the calibration."""
    params = load_scene(scene)
    if contact_friction is not None:
        params = params.replace(contact_friction=check("contact_friction", contact_friction,
                                                       "--contact-friction"))
    sizes = list(sizes)
    validate_cost_args(params, sizes, ticks)
    frames = read_pose_frames(resolve_bag(params.bag), params.topic)
    timed_window(params, frames, ticks)
    material = get_material(params.material)
    options = BodySimOptions.from_scene(params, particles=2400)
    t0 = time.perf_counter()
    model, from_cache = load_or_calibrate(options, material, log, refresh=not cached,
                                          bag=params.bag)
    calibration_s = time.perf_counter() - t0
    rate = stream_rate([st for st, _ in frames[:16]])
    rows = measure_ticks(params, frames, [int(n) for n in sizes], ticks, material,
                         model.tolerances)
    for m in rows:
        pred = model.tick_ms(m["particles"], 1.0 / rate)
        m.update(predicted_ms=pred, error_pct=100.0 * (pred / m["median_ms"] - 1.0))
        log(f"  {m['particles']:>6} particles: predicted {pred:6.1f} ms, measured median "
            f"{m['median_ms']:6.1f} ms (p95 {m['p95_ms']:.1f}), error {m['error_pct']:+.0f} %")
    shape_errors(rows)
    return {"scene": params.scene, "rate_hz": rate,
            "contact_friction": params.contact_friction, "model": model.to_json(),
            "from_cache": from_cache, "calibration_wall_s": calibration_s, "rows": rows,
            "max_abs_error_pct": float(max(abs(r["error_pct"]) for r in rows))}


def shape_errors(rows: list[dict]) -> None:
    """Add to each row `shape_error_pct`: the prediction's error once both are taken relative
    to the row nearest the calibration's 2400 particles. A cached calibration meets a machine
    whose speed has moved since (on the 2-core VM by up to 1.6x within minutes), which shifts
    every row alike; the shape is what the model itself gets right or wrong."""
    ref = min(rows, key=lambda r: abs(r["particles"] - 2400))
    for r in rows:
        r["shape_error_pct"] = 100.0 * ((r["predicted_ms"] / ref["predicted_ms"])
                                        / (r["median_ms"] / ref["median_ms"]) - 1.0)


def format_cost_report(result: dict) -> str:
    """The header (the model: ms per tick = a + b per 1000 particles per step, steps per tick,
    tail factor) and a table per size of predicted, median and p95 ms per tick and the
    prediction's error (%), from `bench_cost`'s result."""
    m = result["model"]
    steps = f"{m['motion_steps']:.2f}" if m["motion_steps"] else "the rule's"
    head = (f"bench cost: scene {result['scene']} (contact friction "
            f"{result.get('contact_friction', 'projection')}) at {result['rate_hz']:.1f} Hz; model "
            f"{m['a_ms']:.2f} ms + {1e3 * m['b_ms']:.2f} ms per 1000 particles per step, "
            f"{steps} steps per tick, tail x{m['tail']:.2f}; calibrated "
            f"in {m['calibration_s']:.2f} s from {m['points']}")
    rows = [[str(r["particles"]), f"{r['predicted_ms']:.1f}", f"{r['median_ms']:.1f}",
             f"{r['p95_ms']:.1f}", f"{r['error_pct']:+.0f}", f"{r['shape_error_pct']:+.0f}"]
            for r in result["rows"]]
    body = text_table(["particles", "predicted ms", "median ms", "p95 ms", "error %",
                       "shape error %"], rows)
    return f"{head}\n{body}\nlargest error {result['max_abs_error_pct']:.0f} %"


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench cost`."""
    p = bsub.add_parser("cost", help="the tick cost model against measured ticks")
    p.add_argument("--scene", default="walking")
    p.add_argument("--particles", default=",".join(map(str, DEFAULT_SIZES)),
                   help="comma-separated sizes to measure")
    p.add_argument("--ticks", type=int, default=60,
                   help="timed ticks per size, at most (the bag's motion may be shorter)")
    p.add_argument("--cached", action="store_true",
                   help="use the cached cost model instead of calibrating afresh")
    p.add_argument("--contact-friction", default=None,
                   help="projection or solve: where friction against the body acts (the "
                        "scene's contact_friction parameter; default: the scene's)")
    p.add_argument("--json", default="out/bench_cost.json")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run `bench_cost`, print its report, write the JSON; 0 on success."""
    try:
        sizes = [int(s) for s in args.particles.split(",") if s.strip()]
    except ValueError:
        raise ClothInputError(f"--particles must be comma-separated integers, got "
                              f"{args.particles!r}") from None
    result = bench_cost(args.scene, sizes, args.ticks, args.cached,
                        contact_friction=args.contact_friction)
    print(format_cost_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}", file=sys.stderr)
    return 0
