"""`cloth-mg run`: a scene headless (a sheet, a body scene on a bag, or a textile test), its
summary printed and written."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from cloth_mg_ros.cli.dressing_run import (
    DRESSING_OPTIONS,
    DRESSING_SCENE,
    add_dressing_run_args,
    run_dressing_scene,
)
from cloth_mg_ros.cli.fidelity import (
    FIDELITY_SCENES,
    TEXTILE_OPTIONS,
    add_fidelity_run_args,
    reject_options,
    run_fidelity_scene,
)
from cloth_mg_ros.config.scenes import particles_option
from cloth_mg_ros.errors import ClothInputError

# `cloth-mg run`'s options that set a shared parameter (config.schema): their help is the
# schema's and body scenes check their values with it.
RUN_SCENE_OPTIONS = {"--particles": "particles", "--tick-budget": "tick_budget",
                     "--material": "material", "--solver": "solver", "--tol": "tolerance",
                     "--levels": "levels", "--bag": "bag", "--garment": "garment",
                     "--substeps": "substeps", "--scheme": "scheme",
                     "--spectral-radius": "spectral_radius", "--friction": "friction",
                     "--compression": "compression", "--newton": "newton_iterations",
                     "--linearise": "linearise_at", "--contact-friction": "contact_friction"}


def add_run_parser(sub: argparse._SubParsersAction) -> None:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.schema import BODY_SCENES, option_help
    from cloth_mg_ros.sim.sheets import SCENES

    def scene_option(flag: str, **kwargs) -> None:
        p.add_argument(flag, default=None, help=option_help(RUN_SCENE_OPTIONS[flag]), **kwargs)

    p = sub.add_parser("run", help="simulate a scene headless; writes summary.json, frames.png",
                       description="Simulate a scene headless. The defaults shown are the body "
                       "scenes' (and the sheets'); a textile test and the dressing scene have "
                       "their own (doc/scenes.md), and every scene refuses by name an option it "
                       "has no use for.")
    p.add_argument("--scene", default="drape",
                   help=f"{', '.join(SCENES)} (a sheet), a textile test: "
                        f"{', '.join(FIDELITY_SCENES)}, the robot dressing an arm: "
                        f"{DRESSING_SCENE}, or a body scene: "
                        f"{', '.join(BODY_SCENES)} (walk, run, ... also work), or a params .yaml")
    scene_option("--particles")
    p.add_argument("--rate-hz", type=float, default=None,
                   help="body scenes with particles auto: the pose stream's rate, Hz "
                        "(default: measured from the bag's stamps)")
    scene_option("--tick-budget", type=float)
    scene_option("--material")
    p.add_argument("--steps", type=int, default=None,
                   help="time steps (sheets, default 120) or pose messages (body scenes, "
                        "default: the whole bag)")
    scene_option("--solver")
    p.add_argument("--dt", type=float, default=None,
                   help="time step of a sheet scene (default 1/60), of the swing, incline or "
                        "capstan test or of the dressing scene, s (the other textile tests "
                        "settle by their own rules)")
    scene_option("--scheme")
    scene_option("--spectral-radius", type=float)
    scene_option("--friction", type=float)
    scene_option("--compression")
    scene_option("--newton", type=int)
    scene_option("--linearise")
    scene_option("--contact-friction")
    scene_option("--tol")
    scene_option("--levels", type=int)
    p.add_argument("--mesh", default=None,
                   help="coarse triangle mesh file replacing the sheet; cantilever, tensile and "
                        "buckle: the strip's mesh kind, lattice (default) or garment")
    p.add_argument("--obstacle", default=None,
                   help="drape: a closed triangle mesh (m) replacing the sphere (mesh collider)")
    scene_option("--bag")
    scene_option("--garment")
    scene_option("--substeps", type=int)
    p.add_argument("--stretch", type=float, default=None, help="override stretch stiffness, N/m")
    p.add_argument("--shear", type=float, default=None, help="override shear stiffness, N/m")
    p.add_argument("--bend", type=float, default=None, help="override bending stiffness, N m")
    p.add_argument("--density", type=float, default=None, help="override density, kg/m^2")
    p.add_argument("--frames", type=int, default=4, help="frames drawn in frames.png")
    p.add_argument("--out", default="out/run", help="output directory")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_fidelity_run_args(p)
    add_dressing_run_args(p)


def _body_params(args: argparse.Namespace):
    """The body scene's parameters (config.scenes.load_scene) with the options given, each
    checked by the schema (ClothInputError naming the flag)."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import check_garment_size, load_scene
    from cloth_mg_ros.config.schema import check

    given = {flag: getattr(args, flag[2:].replace("-", "_")) for flag in RUN_SCENE_OPTIONS}
    given["--particles"] = particles_option(args.particles)
    given["--tol"] = tol_arg(args.tol)
    changes = {RUN_SCENE_OPTIONS[flag]: check(RUN_SCENE_OPTIONS[flag], value, flag)
               for flag, value in given.items() if value is not None}
    return check_garment_size(load_scene(args.scene).replace(**changes),
                              f"scene {args.scene} with --particles, --garment")


# The shared options a scene that is not a body scene takes with the schema's default when
# none is given, and of those the ones each textile test uses (the rest it refuses by name,
# before the defaults are filled in: the cantilever, tensile, Cusick and buckle tests settle
# by their own rules, and the capstan's spec has no spectral radius)
FILLED_OPTIONS = ("--scheme", "--spectral-radius", "--friction", "--compression")
TEST_FILLED_OPTIONS = {"swing": ("--scheme", "--spectral-radius"),
                       "incline": ("--scheme", "--spectral-radius", "--friction"),
                       "capstan": ("--scheme", "--friction")}


def run_command(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import is_body_scene
    from cloth_mg_ros.config.schema import PARAMETERS

    check_scene_name(args.scene)
    if args.scene == DRESSING_SCENE:  # its own defaults (apps.dressing_scene.DressingSpec)
        return run_dressing_scene(args)
    if not is_body_scene(args.scene):
        # a body scene's file sets these unless an option does; other scenes take the
        # schema's defaults, but for one they have no use for (refused by name: the hang
        # has no collider, so no friction; its summary then names none)
        unused = _unused_sheet_options(args.scene)
        reject_options(args, args.scene, unused)
        for flag in FILLED_OPTIONS:
            if flag in unused:
                continue
            name = RUN_SCENE_OPTIONS[flag]
            value = getattr(args, flag[2:].replace("-", "_"))
            setattr(args, flag[2:].replace("-", "_"), PARAMETERS[name].default
                    if value is None else PARAMETERS[name].check(value, flag))
    if args.scene in FIDELITY_SCENES:
        return run_fidelity_scene(args)
    if is_body_scene(args.scene):
        return _run_body_scene(args)
    return _run_sheet_scene(args)


def check_scene_name(scene: str) -> None:
    """ClothInputError naming every scene `run` knows when `scene` is none of them (a body
    scene, its alias, a sheet, a textile test, the dressing scene, or a params .yaml)."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import ALIASES, is_body_scene
    from cloth_mg_ros.config.schema import BODY_SCENES
    from cloth_mg_ros.sim.sheets import SCENES

    if is_body_scene(scene) or scene in (*SCENES, *FIDELITY_SCENES, DRESSING_SCENE):
        return
    raise ClothInputError(
        f"unknown scene {scene!r}; choose one of {', '.join(SCENES)} (sheets), "
        f"{', '.join(FIDELITY_SCENES)} (textile tests), {DRESSING_SCENE}, "
        f"{', '.join(BODY_SCENES)} (body scenes; also {', '.join(ALIASES)}), or a params "
        f".yaml file")


def _unused_sheet_options(scene: str) -> tuple[str, ...]:
    """The shared options scene `scene` (not a body scene) has no use for: --friction and
    --contact-friction for a sheet without a collider (sim.sheets.FRICTION_SCENES); for a
    textile test, those of FILLED_OPTIONS it does not take (TEST_FILLED_OPTIONS)."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.sim.sheets import FRICTION_SCENES, SCENES

    if scene in FIDELITY_SCENES:
        takes = TEST_FILLED_OPTIONS.get(scene, ())
        return tuple(flag for flag in FILLED_OPTIONS if flag not in takes)
    return (("--friction", "--contact-friction") if scene in SCENES
            and scene not in FRICTION_SCENES else ())


def _overrides(args: argparse.Namespace) -> dict:
    return {"stretch": args.stretch, "shear": args.shear, "bend": args.bend,
            "density": args.density}


def _run_body_scene(args: argparse.Namespace) -> int:
    """A body scene on its bag; every option it has no use for is refused first."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.runner import run_body_scene
    from cloth_mg_ros.config.scenes import AUTO, gripper_scripts
    from cloth_mg_ros.physics.materials import get_material

    if args.obstacle is not None:
        raise ClothInputError("--obstacle is for the drape scene")
    # the step comes from the pose stream's stamps, the garment from --garment
    reject_options(args, args.scene, ("--mesh", "--dt", "--seed", *DRESSING_OPTIONS,
                                      *TEXTILE_OPTIONS))
    params = _body_params(args)
    if args.steps is not None and args.steps < 1:
        raise ClothInputError(f"--steps must be a positive integer, got {args.steps}")
    if args.rate_hz is not None and params.particles != AUTO:
        raise ClothInputError(f"--rate-hz is for --particles auto (the rate it sizes the "
                              f"garment for); scene {args.scene!r} runs {params.particles} "
                              f"particles")
    material = get_material(params.material, **_overrides(args))
    if args.rate_hz is not None and not (math.isfinite(args.rate_hz) and args.rate_hz > 0):
        raise ClothInputError(f"--rate-hz must be a positive number, got {args.rate_hz}")
    summary = run_body_scene(params, args.out, args.steps, args.frames,
                             not args.no_progress, material, args.rate_hz, log=print,
                             scripts=gripper_scripts(args.scene, params))
    _print_body_summary(summary, Path(args.out))
    return 0


def _run_sheet_scene(args: argparse.Namespace) -> int:
    """A sheet scene (sim.sheets); every option it has no use for is refused first."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.runner import run_scene
    from cloth_mg_ros.config.schema import PARAMETERS, check
    from cloth_mg_ros.physics.materials import get_material

    for flag, value in (("--bag", args.bag), ("--garment", args.garment),
                        ("--substeps", args.substeps), ("--rate-hz", args.rate_hz),
                        ("--tick-budget", args.tick_budget)):
        if value is not None:
            raise ClothInputError(f"{flag} is for body scenes; scene {args.scene!r} is a sheet")
    reject_options(args, args.scene, ("--seed", *DRESSING_OPTIONS, *TEXTILE_OPTIONS))
    sheet = {name: PARAMETERS[name].default_for(body=False)
             for name in ("particles", "material", "solver", "tolerance", "dt")}
    material = get_material(args.material or sheet["material"], **_overrides(args))
    particles, tol = particles_option(args.particles), tol_arg(args.tol)
    if "auto" in (particles, tol):
        raise ClothInputError("--particles auto and --tol auto are for body scenes (a garment "
                              "on a pose stream); give a sheet a number")
    # --levels 0 (the schema's default): as many as the mesh calls for, build_scene's None
    levels = None if args.levels is None else check("levels", args.levels, "--levels") or None
    summary = run_scene(args.scene, sheet["particles"] if particles is None else particles,
                        material, 120 if args.steps is None else args.steps,
                        args.solver or sheet["solver"],
                        sheet["dt"] if args.dt is None else args.dt, args.out, args.mesh,
                        args.scheme, sheet["tolerance"] if tol is None else tol, levels,
                        args.frames, progress=not args.no_progress, obstacle=args.obstacle,
                        spectral_radius=args.spectral_radius, friction=args.friction,
                        compression=args.compression,
                        newton_iterations=1 if args.newton is None else check(
                            "newton_iterations", args.newton, "--newton"),
                        linearise_at="start" if args.linearise is None else check(
                            "linearise_at", args.linearise, "--linearise"),
                        contact_friction="projection" if args.contact_friction is None else
                        check("contact_friction", args.contact_friction, "--contact-friction"))
    _print_run_summary(summary, Path(args.out))
    return 0


def tol_arg(text: str | None) -> float | str | None:
    """--tol: a relative residual, 'auto', or None; ClothInputError naming anything else."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.schema import check

    if text is None:
        return None
    try:
        value: object = text if text == "auto" else float(text)
    except ValueError:
        value = text  # the schema's check names what --tol takes
    return check("tolerance", value, "--tol")


def _print_body_summary(summary: dict, out: Path) -> None:
    ticks = summary["ticks"]
    print(f"{summary['scene']}: {summary['garment']} of {summary['particles']} particles "
          f"({summary['levels']} levels, {summary['material']}), solver {summary['solver']}, "
          f"{len(ticks)} ticks from {summary['bag']}")
    if ticks:
        print(f"  median tick {summary['median_total_ms']:.1f} ms (solve "
              f"{summary['median_solve_ms']:.1f} ms), deepest penetration after a step "
              f"{1e3 * summary['max_penetration']:.1f} mm, all converged: "
              f"{summary['all_converged']}")
    if summary["rejected"]:
        print(f"  frames skipped or repaired: {summary['rejected']}")
    if summary["self_contact_dropped"]:
        print(f"  self-contact pairs dropped past the search's cap: "
              f"{summary['self_contact_dropped']} over the run (the cloth may pass through "
              f"itself there)")
    if ticks:
        peak = max(ticks, key=lambda t: t["contact_peak_n"])
        print(f"  garment {1e3 * summary['mass_kg']:.0f} g; largest force on the body "
              f"{peak['contact_peak_n']:.2f} N ({peak['contact_peak_segment'] or 'none'}, "
              f"tick at {peak['stamp']:.2f} s); penalties pulling the cloth onto the colliders "
              f"p95 {summary['contact_pull_p95_n']:.3f} N, "
              f"max {summary['contact_pull_max_n']:.3f} N")
        _print_wrenches(ticks[-1].get("gripper_wrenches") or {}, summary["mass_kg"])
    if summary.get("budget_ms") is not None:
        print(f"  particles auto at {summary['rate_hz']:.1f} Hz: budget "
              f"{summary['budget_ms']:.1f} ms, predicted {summary['predicted_ms']:.1f} ms, "
              f"tick p95 {summary['p95_total_ms']:.1f} ms")
    if summary.get("tolerances"):
        print(f"  tolerance auto: {summary['solve_tolerance']:.3g} at the garment's size "
              f"(measured: " + ", ".join(f"{t:g} at {n} particles"
                                         for n, t in summary["tolerances"]) + ")")
    print(f"  wrote {out / 'summary.json'} and {out / 'frames.png'}")


def _print_wrenches(wrenches: dict, mass_kg: float) -> None:
    """The last step's gripper forces and their sum against the cloth's weight."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.sim.model import GRAVITY

    if not wrenches:
        return
    forces = {name: w["force"] for name, w in wrenches.items()}
    total = [sum(f[k] for f in forces.values()) for k in range(3)]
    weight = -float(GRAVITY[2]) * mass_kg
    parts = ", ".join(f"{name} ({f[0]:.3f}, {f[1]:.3f}, {f[2]:.3f}) N"
                      for name, f in forces.items())
    print(f"  grippers at the last step: {parts}; together {math.hypot(*total):.4f} N "
          f"against the cloth's weight {weight:.4f} N ({1e3 * mass_kg:.1f} g)")


def _print_run_summary(summary: dict, out: Path) -> None:
    steps = summary["steps"]
    print(f"{summary['scene']}: {summary['particles']} particles, {summary['levels']} levels, "
          f"{summary['material']}, solver {summary['solver']}, {len(steps)} steps in "
          f"{summary['wall_s']:.1f} s")
    print(f"  median solve {summary['median_solve_ms']:.1f} ms, median iterations "
          f"{summary['median_iterations']:.0f}, all converged: {summary['all_converged']}")
    last = steps[-1]
    print(f"  final kinetic energy {last['kinetic_energy']:.3e} J, potential "
          f"{last['potential_energy']:.3e} J")
    _print_wrenches(last.get("gripper_wrenches") or {}, summary["mass_kg"])
    print(f"  wrote {out / 'summary.json'} and {out / 'frames.png'}")
