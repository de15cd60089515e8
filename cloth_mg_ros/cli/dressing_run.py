"""`cloth-mg run --scene dressing`: a robot pulls a gown's sleeve onto an arm, headless
(apps.dressing_scene); writes summary.json (every step's gripper wrenches and forces on the arm
segments) and frames.png, and prints the run's figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError

DRESSING_SCENE = "dressing"


def add_dressing_run_args(p: argparse.ArgumentParser) -> None:
    """Options of `cloth-mg run` that only the dressing scene takes (with --particles,
    --material, --solver, --bag: the moving arm's clip)."""
    p.add_argument("--speed", type=float, default=None,
                   help="dressing: the pull's speed along the arm, m/s (default 0.10)")
    p.add_argument("--travel", type=float, default=None,
                   help="dressing: how far the grippers pull, m (default 0.85)")
    p.add_argument("--angle", type=float, default=None,
                   help="dressing: the pull line's angle to the arm, degrees (default 0; 15: "
                        "the hand runs into the sleeve's wall); incline: the slope, degrees")


def run_dressing_scene(args: argparse.Namespace) -> int:
    """`cloth-mg run --scene dressing [--steps N]`: the still arm, or the arm moving as in
    --bag; --steps caps the steps."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from dataclasses import replace

    from cloth_mg_ros.apps.dressing_scene import DressingSpec, run_dressing
    from cloth_mg_ros.io.render import render_frames

    for flag, value in (("--garment", args.garment), ("--obstacle", args.obstacle),
                        ("--mesh", args.mesh), ("--tick-budget", args.tick_budget)):
        if value is not None:
            raise ClothInputError(f"{flag} is not an option of the dressing scene")
    if args.steps is not None and args.steps < 1:
        raise ClothInputError(f"--steps must be a positive integer, got {args.steps}")
    given = {"motion": args.bag, "speed": args.speed, "travel": args.travel,
             "angle_deg": args.angle, "material": args.material, "solver": args.solver,
             "compression": args.compression,
             "particles": None if args.particles is None else _particles(args.particles)}
    spec = DressingSpec(**{k: v for k, v in given.items() if v is not None})
    if args.steps is not None:  # fewer steps: the same pull, cut short
        spec = replace(spec, travel=min(spec.travel, spec.speed * max(
            args.steps * spec.dt - spec.settle_s, spec.dt)))
    run = run_dressing(spec, progress=not args.no_progress, shots=max(args.frames, 2))
    if args.steps is not None:
        run.steps = run.steps[:args.steps]
    summary = run.summary()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps({**summary, "step_records": run.steps},
                                                 indent=1))
    render_frames(out / "frames.png", [(t, x) for t, x, _ in run.frames], run.faces,
                  title=f"dressing: {spec.name}, {run.particles} particles",
                  capsules_per_frame=[c for _, _, c in run.frames])
    print(f"dressing ({spec.name}): sleeve of {run.particles} particles, "
          f"{1e3 * run.mass_kg:.0f} g of {spec.material}; {summary['steps']} steps, "
          f"{summary['final_travel_m']:.2f} m pulled in {run.wall_s:.1f} s")
    print(f"  {summary['outcome']}: dressed {summary['dressed_m']:.2f} m (upper arm "
          f"{summary['upper_arm_ratio']:.2f}, whole arm {summary['whole_arm_ratio']:.2f}); "
          f"peak force on the grippers {summary['peak_force_n']:.2f} N; on the arm "
          + ", ".join(f"{k} {v:.2f} N" for k, v in summary["peak_body_n"].items()))
    print(f"  slip of the held cloth {summary['slip_m']:.1e} m; deepest cloth edge in the arm "
          f"{1e3 * summary['edge_depth_m']:.1f} mm")
    print(f"  wrote {out / 'summary.json'} and {out / 'frames.png'}")
    return 0


def _particles(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ClothInputError(f"--particles must be an integer, got {text!r}") from None
