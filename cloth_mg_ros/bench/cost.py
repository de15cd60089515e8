"""`cloth-mg bench cost`: the cost model's prediction against measured ticks.

The scene's cost model (calibrated afresh, or the cached one with --cached) predicts the
median tick at each size; the scene's garment of that size then runs through the scene's
bag, one pose message per tick as the headless runner does, and the median and 95th
percentile of the ticks of the motion are measured (the bag's opening hold, at least
WARMUP_TICKS, settles the garment untimed: a still body costs less than a moving one, and a
live node must keep up with the motion). The error of the prediction (%) tells
a user how far `particles: auto` can be trusted on this machine.
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
from cloth_mg_ros.config.schema import MAX_PARTICLES
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


def measure_ticks(params: SceneParams, frames: list, particles: int, ticks: int, material,
                  tolerances=()) -> dict:
    """Median and p95 of up to `ticks` timed ticks of the motion (after the bag's opening
    hold and at least WARMUP_TICKS) of the scene's garment of about `particles` on its bag's
    `frames` [(stamp s, poses (S, 7))]: {"particles", "median_ms", "p95_ms", "steps",
    "ticks", "first_tick"}. tolerances: the cost model's, for a scene with tolerance auto."""
    first, end = timed_window(params, frames, ticks)
    options = BodySimOptions.from_scene(params, particles=particles,
                                        tolerances=tuple(tolerances))
    garment_sim = GarmentSim.dress(Avatar.load(), frames[0][0], frames[0][1], material, options)
    times, steps = [], []
    for k in range(1, end):
        stats = garment_sim.push(*frames[k])
        if isinstance(stats, TickStats) and k >= first:
            times.append(stats.total_ms)
            steps.append(stats.substeps)
    return {"particles": int(garment_sim.positions.shape[0]), "median_ms": float(np.median(times)),
            "p95_ms": float(np.percentile(times, 95)), "steps": float(np.mean(steps)),
            "ticks": len(times), "first_tick": first}


def bench_cost(scene: str, sizes=DEFAULT_SIZES, ticks: int = 60, cached: bool = False,
               log=print) -> dict:
    """Calibrate (or load) the scene's cost model and compare it with measured ticks.

    sizes: garment particle counts; ticks: timed ticks per size, at most (>= MIN_TIMED_TICKS).
    Returns {"scene", "rate_hz", "model", "from_cache", "calibration_wall_s", "rows",
    "max_abs_error_pct"}; ClothInputError for a bad option or a too short bag, before the
    calibration."""
    params = load_scene(scene)
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
    rows = []
    for n in sizes:
        m = measure_ticks(params, frames, int(n), ticks, material, model.tolerances)
        pred = model.tick_ms(m["particles"], 1.0 / rate)
        m.update(predicted_ms=pred, error_pct=100.0 * (pred / m["median_ms"] - 1.0))
        rows.append(m)
        log(f"  {m['particles']:>6} particles: predicted {pred:6.1f} ms, measured median "
            f"{m['median_ms']:6.1f} ms (p95 {m['p95_ms']:.1f}), error {m['error_pct']:+.0f} %")
    return {"scene": params.scene, "rate_hz": rate, "model": model.to_json(),
            "from_cache": from_cache, "calibration_wall_s": calibration_s, "rows": rows,
            "max_abs_error_pct": float(max(abs(r["error_pct"]) for r in rows))}


def format_cost_report(result: dict) -> str:
    """The header (the model: ms per tick = a + b per 1000 particles per step, steps per tick,
    tail factor) and a table per size of predicted, median and p95 ms per tick and the
    prediction's error (%), from `bench_cost`'s result."""
    m = result["model"]
    steps = f"{m['motion_steps']:.2f}" if m["motion_steps"] else "the rule's"
    head = (f"bench cost: scene {result['scene']} at {result['rate_hz']:.1f} Hz; model "
            f"{m['a_ms']:.2f} ms + {1e3 * m['b_ms']:.2f} ms per 1000 particles per step, "
            f"{steps} steps per tick, tail x{m['tail']:.2f}; calibrated "
            f"in {m['calibration_s']:.2f} s from {m['points']}")
    rows = [[str(r["particles"]), f"{r['predicted_ms']:.1f}", f"{r['median_ms']:.1f}",
             f"{r['p95_ms']:.1f}", f"{r['error_pct']:+.0f}"] for r in result["rows"]]
    body = text_table(["particles", "predicted ms", "median ms", "p95 ms", "error %"], rows)
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
    p.add_argument("--json", default="out/bench_cost.json")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run `bench_cost`, print its report, write the JSON; 0 on success."""
    try:
        sizes = [int(s) for s in args.particles.split(",") if s.strip()]
    except ValueError:
        raise ClothInputError(f"--particles must be comma-separated integers, got "
                              f"{args.particles!r}") from None
    result = bench_cost(args.scene, sizes, args.ticks, args.cached)
    print(format_cost_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}", file=sys.stderr)
    return 0
