"""`cloth-mg run --scene dressing`: a robot pulls a gown's sleeve onto an arm, headless
(apps.dressing_scene); writes summary.json (every step's gripper wrenches and forces on the arm
segments) and frames.png, and prints the run's figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cloth_mg_ros.cli.fidelity import TEXTILE_OPTIONS, reject_options
from cloth_mg_ros.errors import ClothInputError

DRESSING_SCENE = "dressing"
DRESSING_OPTIONS = ("--speed", "--travel", "--angle")  # `cloth-mg run` options of this scene
# alone (--angle: the incline's too)
# the options of `cloth-mg run` the dressing scene takes, by DressingSpec field (its messages
# name the flag)
SPEC_FLAGS = {"motion": "--bag", "speed": "--speed", "travel": "--travel",
              "angle_deg": "--angle", "material": "--material", "solver": "--solver",
              "compression": "--compression", "particles": "--particles", "dt": "--dt",
              "tolerance": "--tol", "scheme": "--scheme", "spectral_radius": "--spectral-radius",
              "friction": "--friction", "seed": "--seed"}
# the options the dressing scene has no use for: refused, not ignored
UNUSED_OPTIONS = ("--garment", "--obstacle", "--mesh", "--tick-budget", "--levels",
                  "--substeps", "--rate-hz", "--stretch", "--shear", "--bend", "--density",
                  "--newton", "--linearise", "--contact-friction", *TEXTILE_OPTIONS)


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

    from cloth_mg_ros.apps.dressing_scene import run_dressing
    from cloth_mg_ros.io.render import render_frames

    spec = dressing_spec(args)
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


def dressing_spec(args: argparse.Namespace):
    """The DressingSpec of `cloth-mg run --scene dressing`: its defaults with the options given
    (SPEC_FLAGS); ClothInputError naming the flag for a bad value or an option the scene has
    no use for (UNUSED_OPTIONS), before any work."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.dressing_scene import DressingSpec
    from cloth_mg_ros.config.schema import check

    reject_options(args, DRESSING_SCENE, UNUSED_OPTIONS)
    if args.steps is not None and args.steps < 1:
        raise ClothInputError(f"--steps must be a positive integer, got {args.steps}")
    given = {field: getattr(args, flag[2:].replace("-", "_"))
             for field, flag in SPEC_FLAGS.items()}
    for field in ("scheme", "spectral_radius", "friction", "compression", "dt"):
        if given[field] is not None:  # the schema's check, as for the other scenes
            given[field] = check(field, given[field], SPEC_FLAGS[field])
    if args.tol is not None:
        if args.tol == "auto":
            raise ClothInputError("--tol auto is for body scenes; give the dressing scene a "
                                  "number")
        given["tolerance"] = check("tolerance", _number(args.tol), "--tol")
    if args.particles is not None:
        given["particles"] = _particles(args.particles)
    try:
        return DressingSpec(**{k: v for k, v in given.items() if v is not None})
    except ClothInputError as exc:
        raise ClothInputError(_flag_named(str(exc))) from None


def _flag_named(message: str) -> str:
    """DressingSpec's 'dressing: angle_deg must be ...' as 'dressing: --angle must be ...'."""
    head = "dressing: "
    name = message[len(head):].split(" ", 1)[0] if message.startswith(head) else ""
    if name not in SPEC_FLAGS:
        return message
    return head + SPEC_FLAGS[name] + message[len(head) + len(name):]


def _number(text: str) -> float | str:
    try:
        return float(text)
    except ValueError:
        return text  # the schema's check names what the option takes


def _particles(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ClothInputError(f"--particles must be an integer, got {text!r}") from None
