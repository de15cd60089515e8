"""`cloth-mg`: the command line of cloth_mg_ros (headless runs, benchmarks, the demo)."""

from __future__ import annotations

import argparse
import importlib
import math
import sys
import time
from pathlib import Path

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.cli.bag import add_bag_parser, run_bag_command
from cloth_mg_ros.cli.batch import add_batch_parser, run_batch_command
from cloth_mg_ros.cli.fidelity import (
    FIDELITY_SCENES,
    add_fidelity_run_args,
    add_materials_parser,
    run_fidelity_scene,
    run_materials_command,
)
from cloth_mg_ros.errors import ClothInputError

# Benchmarks whose module adds its own sub-command: ``add_cli(bsub)`` registers the parser and
# sets ``bench_func`` (a callable taking the parsed args, returning the exit code). Their
# modules import only light dependencies at the top, so building the parser stays quick.
PLUGIN_BENCHES = ("pareto", "scaling", "stability", "peers", "profile_tick", "cost",
                  "faults", "fidelity")


# `cloth-mg run`'s options that set a shared parameter (config.schema): their help is the
# schema's and body scenes check their values with it.
RUN_SCENE_OPTIONS = {"--particles": "particles", "--tick-budget": "tick_budget",
                     "--material": "material", "--solver": "solver", "--tol": "tolerance",
                     "--levels": "levels", "--bag": "bag", "--garment": "garment",
                     "--substeps": "substeps"}


def _add_run(sub: argparse._SubParsersAction) -> None:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.schema import BODY_SCENES, option_help

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.sim.sheets import SCENES

    def scene_option(flag: str, **kwargs) -> None:
        p.add_argument(flag, default=None, help=option_help(RUN_SCENE_OPTIONS[flag]), **kwargs)

    p = sub.add_parser("run", help="simulate a scene headless; writes summary.json, frames.png")
    p.add_argument("--scene", default="drape",
                   help=f"{', '.join(SCENES)} (a sheet), a textile test: "
                        f"{', '.join(FIDELITY_SCENES)}, or a body scene: "
                        f"{', '.join(BODY_SCENES)} (walk, run, ... also work), or a params .yaml")
    scene_option("--particles")
    p.add_argument("--rate-hz", type=float, default=None,
                   help="body scenes with --particles auto: the pose stream's rate, Hz "
                        "(default: measured from the bag's stamps)")
    scene_option("--tick-budget", type=float)
    scene_option("--material")
    p.add_argument("--steps", type=int, default=None,
                   help="time steps (sheets, default 120) or pose messages (body scenes, "
                        "default: the whole bag)")
    scene_option("--solver")
    p.add_argument("--dt", type=float, default=1.0 / 60.0, help="time step of a sheet scene, s")
    p.add_argument("--scheme", default="bdf2", help="implicit integrator: bdf2 or euler")
    scene_option("--tol")
    scene_option("--levels", type=int)
    p.add_argument("--mesh", default=None,
                   help="coarse triangle mesh file replacing the sheet; cantilever and tensile: "
                        "the strip's mesh kind, lattice (default) or garment")
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


def _body_params(args: argparse.Namespace):
    """The body scene's parameters (config.scenes.load_scene) with the options given, each
    checked by the schema (ClothInputError naming the flag)."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import load_scene

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.schema import check

    given = {flag: getattr(args, flag[2:].replace("-", "_")) for flag in RUN_SCENE_OPTIONS}
    given["--particles"] = _particles_arg(args.particles)
    given["--tol"] = _tol_arg(args.tol)
    changes = {RUN_SCENE_OPTIONS[flag]: check(RUN_SCENE_OPTIONS[flag], value, flag)
               for flag, value in given.items() if value is not None}
    return load_scene(args.scene).replace(**changes)


def _cmd_run(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.runner import run_body_scene, run_scene

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import is_body_scene

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.schema import PARAMETERS

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.physics.materials import get_material

    if args.scene in FIDELITY_SCENES:
        return run_fidelity_scene(args)
    overrides = {"stretch": args.stretch, "shear": args.shear, "bend": args.bend,
                 "density": args.density}
    if is_body_scene(args.scene):
        if args.obstacle is not None:
            raise ClothInputError("--obstacle is for the drape scene")
        params = _body_params(args)
        if args.steps is not None and args.steps < 1:
            raise ClothInputError(f"--steps must be a positive integer, got {args.steps}")
        material = get_material(params.material, **overrides)
        if args.rate_hz is not None and not (math.isfinite(args.rate_hz) and args.rate_hz > 0):
            raise ClothInputError(f"--rate-hz must be a positive number, got {args.rate_hz}")
        summary = run_body_scene(params, args.out, args.steps, args.frames,
                                 not args.no_progress, material, args.rate_hz, log=print)
        _print_body_summary(summary, Path(args.out))
        return 0
    for flag, value in (("--bag", args.bag), ("--garment", args.garment),
                        ("--substeps", args.substeps), ("--rate-hz", args.rate_hz),
                        ("--tick-budget", args.tick_budget)):
        if value is not None:
            raise ClothInputError(f"{flag} is for body scenes; scene {args.scene!r} is a sheet")
    sheet = {name: PARAMETERS[name].default_for(body=False)
             for name in ("particles", "material", "solver", "tolerance")}
    material = get_material(args.material or sheet["material"], **overrides)
    particles, tol = _particles_arg(args.particles), _tol_arg(args.tol)
    if "auto" in (particles, tol):
        raise ClothInputError("--particles auto and --tol auto are for body scenes (a garment "
                              "on a pose stream); give a sheet a number")
    summary = run_scene(args.scene, sheet["particles"] if particles is None else particles,
                        material, 120 if args.steps is None else args.steps,
                        args.solver or sheet["solver"], args.dt, args.out, args.mesh,
                        args.scheme, sheet["tolerance"] if tol is None else tol, args.levels,
                        args.frames, progress=not args.no_progress, obstacle=args.obstacle)
    _print_run_summary(summary, Path(args.out))
    return 0


def _particles_arg(text: str | None) -> int | str | None:
    """--particles: an integer, 'auto', or None; ClothInputError naming anything else."""
    if text is None or text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise ClothInputError(f"--particles must be an integer or 'auto', got {text!r}") from None


def _tol_arg(text: str | None) -> float | str | None:
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


def _rates_arg(text: str) -> list[float]:
    """--rate of the node benchmark: one factor or a comma list (one per pass)."""
    try:
        return [float(part) for part in text.split(",")]
    except ValueError:
        raise ClothInputError(f"--rate must be a number or a comma list of numbers, got "
                              f"{text!r}") from None


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
    if summary.get("budget_ms") is not None:
        print(f"  particles auto at {summary['rate_hz']:.1f} Hz: budget "
              f"{summary['budget_ms']:.1f} ms, predicted {summary['predicted_ms']:.1f} ms, "
              f"tick p95 {summary['p95_total_ms']:.1f} ms")
    if summary.get("tolerances"):
        print(f"  tolerance auto: {summary['solve_tolerance']:.3g} at the garment's size "
              f"(measured: " + ", ".join(f"{t:g} at {n} particles"
                                         for n, t in summary["tolerances"]) + ")")
    print(f"  wrote {out / 'summary.json'} and {out / 'frames.png'}")


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
    print(f"  wrote {out / 'summary.json'} and {out / 'frames.png'}")


def _add_bench(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks that print and save figures")
    bsub = p.add_subparsers(dest="bench", required=True)
    m = bsub.add_parser("matvec", help="Algorithm 1 against scipy CSR and BSR products")
    m.add_argument("--particles", type=int, default=20000)
    m.add_argument("--material", default="cotton")
    m.add_argument("--repeat", type=int, default=200, help="timed products per method")
    m.add_argument("--json", default=None, help="write the figures to this JSON file")
    _add_bench_solvers(bsub)
    _add_bench_node(bsub)
    _add_bench_walking(bsub)
    for name in PLUGIN_BENCHES:
        importlib.import_module(f"cloth_mg_ros.bench.{name}").add_cli(bsub)


def _add_bench_walking(bsub: argparse._SubParsersAction) -> None:
    w = bsub.add_parser("walking", help="every solver on the walking scene, timed per tick "
                        "(the paper's Table 3, walking half)")
    w.add_argument("--bag", default="walk", help="pose bag to replay (default walk)")
    w.add_argument("--garment", default="dress", help="garment (default dress)")
    w.add_argument("--particles", default="1200,2400,4500,10000,20000",
                   help="comma-separated particle counts")
    w.add_argument("--solvers", default="pcg,mg,mpcg,amg,direct",
                   help="comma-separated solvers (default pcg,mg,mpcg,amg,direct)")
    w.add_argument("--material", default="cotton", help="material (default cotton)")
    w.add_argument("--steps", type=int, default=None,
                   help="replay at most this many pose messages (default: all)")
    w.add_argument("--tol", type=float, default=1e-4, help="relative residual of every solve")
    w.add_argument("--max-seconds", type=float, default=None,
                   help="skip a solver whose first tick takes longer than this (and at the "
                        "larger sizes)")
    w.add_argument("--start", type=float, default=1.0,
                   help="seconds of the bag skipped before dressing (default 1: the bundled "
                        "bags' still lead-in)")
    w.add_argument("--threads", type=int, default=0,
                   help="solver and kernel threads (default 0: every core)")
    w.add_argument("--json", default="out/bench_walking.json", help="JSON output file")
    w.add_argument("--png", default="out/bench_walking.png", help="chart output file")


def _cmd_bench_walking(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.bench.solvers import parse_list

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.bench.walking import (
        bench_walking,
        format_walking_report,
        plot_walking,
        validate_walking_args,
    )

    particles = parse_list(args.particles, "particles", int)
    solvers = parse_list(args.solvers, "solvers")
    material = args.material.strip().lower()
    validate_walking_args(args.bag, args.garment, particles, solvers, material, args.steps,
                          args.tol, args.max_seconds)
    result = bench_walking(args.bag, particles, solvers, args.garment, material, args.steps,
                           args.tol, args.max_seconds, args.start, threads=args.threads)
    print(format_walking_report(result))
    write_json(args.json, result)
    png = plot_walking(result, args.png)
    print(f"wrote {args.json} and {png}")
    return 0


def _add_bench_node(bsub: argparse._SubParsersAction) -> None:
    n = bsub.add_parser("node", help="cloth_node live over DDS: latency from pose received "
                        "to marker received (p50, p95, over time), poses used, coalesced, "
                        "dropped")
    n.add_argument("--bag", default="walk", help="pose bag to replay (default walk)")
    n.add_argument("--particles", default=None,
                   help="about how many cloth particles, or auto (default: the scene's own)")
    n.add_argument("--scene", default="walking", help="body scene (default walking)")
    n.add_argument("--rate", default="1",
                   help="replay speed factor (default 1: the bag's own pace); a comma list "
                        "gives one per pass of the bag (1,1,1,0.3: a stream that slows)")
    n.add_argument("--loops", type=int, default=None,
                   help="replay the bag this many times in a row, stamps moving on (a long "
                        "clip; default: one pass per --rate factor)")
    n.add_argument("--lod", choices=["true", "false"], default=None,
                   help="the node's live level of detail (default: the scene's)")
    n.add_argument("--tick-budget", type=float, default=None,
                   help="the node's tick budget, a fraction of the pose period (default: the "
                        "scene's)")
    n.add_argument("--messages", type=int, default=None,
                   help="replay only the first N pose messages (default: all)")
    n.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain of the benchmark's processes (default: the first free one "
                        "from 1 + pid %% 100 on)")
    n.add_argument("--json", default="out/bench_node.json", help="JSON output file")
    n.add_argument("--png", default=None, help="also chart the latency over the clip here")
    n.add_argument("--threads", type=int, default=None,
                   help="the node's solver threads (default: the scene's, 0: every core)")


def _cmd_bench_node(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.bench.node_latency import bench_node, format_node_report, plot_node

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.processes import NodeError, interrupt_signals

    try:
        with interrupt_signals():
            result = bench_node(args.bag, _particles_arg(args.particles), args.scene,
                                _rates_arg(args.rate),
                                args.messages, args.domain_id,
                                Path(args.json).with_suffix(".node.log"),
                                log=lambda line: print(line, flush=True),
                                threads=args.threads, loops=args.loops,
                                lod=None if args.lod is None else args.lod == "true",
                                tick_budget=args.tick_budget)
    except NodeError as exc:
        print(f"cloth-mg: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted (cloth_node stopped)", file=sys.stderr)
        return 130
    print(format_node_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}")
    if args.png:
        print(f"wrote {plot_node(result, args.png)}")
    return 0


def _add_bench_solvers(bsub: argparse._SubParsersAction) -> None:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.solvers import SOLVERS

    s = bsub.add_parser("solvers", help="every solver on the same recorded step systems "
                        "(the paper's Tables 3 and 4)")
    s.add_argument("--scene", default="drape", help="scene to record (default drape)")
    s.add_argument("--particles", default="1200,2400,4500,10000,20000",
                   help="comma-separated particle counts")
    s.add_argument("--materials", default="cotton", help="comma-separated materials")
    s.add_argument("--tol", type=float, default=1e-4, help="relative residual of every solve")
    s.add_argument("--solvers", default=",".join(SOLVERS),
                   help="comma-separated solvers (default: all)")
    s.add_argument("--systems", type=int, default=5,
                   help="consecutive step systems recorded")
    s.add_argument("--delay", type=int, default=20,
                   help="steps after the first contact before recording (default 20: the "
                        "sheet folding over the sphere; 0: the still-flat first touch)")
    s.add_argument("--levels", type=int, default=None,
                   help="hierarchy levels (default: as many as the mesh size calls for)")
    s.add_argument("--repeat", type=int, default=1, help="timed solves per system (fastest kept)")
    s.add_argument("--max-seconds", type=float, default=None,
                   help="skip a solver whose first solve takes longer than this")
    s.add_argument("--json", default="out/bench_solvers.json", help="JSON output file")
    s.add_argument("--png", default="out/bench_solvers.png", help="chart output file")


def _cmd_bench_solvers(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.bench.solvers import (
        bench_solvers,
        format_report,
        parse_list,
        plot_solvers,
        validate_bench_args,
    )

    particles = parse_list(args.particles, "particles", int)
    materials = [m.lower() for m in parse_list(args.materials, "materials")]
    solvers = parse_list(args.solvers, "solvers")
    validate_bench_args(args.scene, particles, materials, solvers, args.tol, args.systems,
                        args.levels, args.repeat, args.max_seconds)
    result = bench_solvers(particles, materials, solvers, args.tol, args.systems, args.levels,
                           args.repeat, args.max_seconds, args.scene, delay=args.delay)
    print(format_report(result))
    write_json(args.json, result)
    pngs = plot_solvers(result, args.png)
    print(f"wrote {args.json} and {', '.join(map(str, pngs))}")
    return 0


def _add_export(sub: argparse._SubParsersAction) -> None:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.physics.materials import MATERIALS

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.sim.sheets import SCENES

    e = sub.add_parser("export-system", help="write one step's linear system (A, b, direct "
                       "solution, prolongations) to an .npz for other solvers")
    e.add_argument("--scene", default="drape", help=f"one of {', '.join(SCENES)}")
    e.add_argument("--particles", type=int, default=2400, help="about how many particles")
    e.add_argument("--material", default="cotton", help=f"one of {', '.join(MATERIALS)}")
    e.add_argument("--step", type=int, default=0, help="step index, 0 = the first system")
    e.add_argument("--levels", type=int, default=None, help="hierarchy levels (default: auto)")
    e.add_argument("--dt", type=float, default=1.0 / 60.0, help="time step, s")
    e.add_argument("--scheme", default="bdf2", help="implicit integrator: bdf2 or euler")
    e.add_argument("--out", default="out/system.npz", help="output .npz file")


def _cmd_export(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.bench.export import export_system

    info = export_system(args.scene, args.particles, args.material, args.step, args.out,
                         args.levels, args.dt, args.scheme)
    print(f"{info['scene']} step {info['step']}: {info['particles']} particles "
          f"({info['dofs']} unknowns, nnz {info['nnz']}), {info['levels']} levels, "
          f"{info['material']}, {info['contacts']} contacts, {info['pinned']} pinned; "
          f"x by {info['direct_solver']} (rel. residual {info['rel_residual']:.1e}); "
          f"{info['seconds']:.1f} s")
    print(f"wrote {info['path']} ({info['bytes'] / 1e6:.1f} MB); read it with "
          f"cloth_mg_ros.bench.export.load_exported")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    if args.bench == "matvec":
        # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
        from cloth_mg_ros.bench.matvec import bench_matvec, print_matvec

        result = bench_matvec(args.particles, args.material, args.repeat)
        print_matvec(result)
        if args.json:
            write_json(args.json, result)
            print(f"wrote {args.json}")
        return 0
    if args.bench == "solvers":
        return _cmd_bench_solvers(args)
    if args.bench == "node":
        return _cmd_bench_node(args)
    if args.bench == "walking":
        return _cmd_bench_walking(args)
    if getattr(args, "bench_func", None) is not None:
        return args.bench_func(args)
    raise ClothInputError(f"unknown benchmark {args.bench!r}")


def _cmd_demo(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.demo import run_demo

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.demo_recording import format_table

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.processes import NodeError, interrupt_signals

    print(f"cloth_mg_ros demo: cloth_node drapes a dress on an avatar walking as CMU subject 7 "
          f"walked ({args.bag or 'bags/walk'}, replayed over DDS), implicit BDF2, faithful "
          f"multigrid; recording /cloth/marker and /cloth/stats", flush=True)
    try:
        with interrupt_signals():
            r = run_demo(args.out, args.particles, args.steps, args.bag, rate=args.rate,
                         domain_id=args.domain_id, log=lambda line: print(line, flush=True))
    except NodeError as exc:
        print(f"cloth-mg: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted (cloth_node stopped)", file=sys.stderr)
        return 130
    print(f"\n{r.messages} pose messages in ({r.poses_used} used, {r.poses_coalesced} "
          f"coalesced into a later tick, {r.dropped} dropped), {r.markers} cloth markers and "
          f"{r.statuses} statuses recorded; a dress of {r.particles} particles; node up in "
          f"{r.start_s:.1f} s, replay {r.replay_s:.1f} s, last status "
          f"{r.finish_s:.1f} s after the replay began\n")
    print(format_table(r.rows))
    print(f"\nwrote {r.cloth_bag} (MCAP: cloth-mg bag info {r.cloth_bag}), {r.frames_png} "
          f"and {r.node_log}; demo took {r.wall_s:.1f} s")
    return 0


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="publish a bag's messages on their topics, paced by "
                       "their timestamps (like ros2 bag play)")
    p.add_argument("bag", help="a rosbag2 bag folder or file, or a bundled bag name (walk, "
                   "brisk_walk, run, jump)")
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    p.add_argument("--loop", action="store_true",
                   help="play again and again until Ctrl-C (header stamps move on each pass)")
    p.add_argument("--topic", action="append", default=None, metavar="T",
                   help="only this topic (repeat for more; default: every topic of the bag)")
    p.add_argument("--wait", type=float, default=30.0, metavar="S",
                   help="wait at most S seconds for a first subscriber (0: do not wait)")
    p.add_argument("--settle", type=float, default=0.5, metavar="S",
                   help="pause S seconds after the first subscriber matched")
    p.add_argument("--clock", action="store_true",
                   help="also publish the bag's time on /clock, for nodes with use_sim_time")
    p.add_argument("--namespace", default="", metavar="NS",
                   help="publish every topic under namespace NS (/alice: "
                        "/alice/avatar/body_poses), for a node started in NS")


def _cmd_replay(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.replay import replay_bag

    return _with_ros(lambda: replay_bag(args.bag, rate=args.rate, loop=args.loop,
                                        topics=args.topic, wait_s=args.wait,
                                        settle_s=args.settle, clock=args.clock,
                                        namespace=args.namespace,
                                        log=lambda line: print(line, flush=True)))


def _add_record(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record topics into a rosbag2 bag (MCAP) until Ctrl-C or "
                       "for --duration seconds")
    p.add_argument("out", help="the bag folder to create")
    p.add_argument("--topics", nargs="+", required=True, metavar="T",
                   help="topics to record, e.g. /cloth/marker /cloth/stats")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: at Ctrl-C)")
    p.add_argument("--storage", default="mcap", help="mcap (default) or sqlite3")


def _cmd_record(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.record import record_topics

    return _with_ros(lambda: record_topics(args.out, args.topics, duration=args.duration,
                                           storage=args.storage,
                                           log=lambda line: print(line, flush=True)))


def _with_ros(run) -> int:
    """Run `run()` inside rclpy.init/shutdown with Ctrl-C and SIGTERM as KeyboardInterrupt
    (rclpy's own signal handlers off, so the context stays valid while closing). 0 on success
    or Ctrl-C; ClothInputError propagates (exit 2)."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    import signal

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    import rclpy

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from rclpy.signals import SignalHandlerOptions

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    previous = signal.signal(signal.SIGTERM, interrupt)
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        run()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        rclpy.try_shutdown()
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cloth-mg", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    _add_run(sub)
    _add_bench(sub)
    add_bag_parser(sub)
    _add_export(sub)
    _add_replay(sub)
    _add_record(sub)
    add_batch_parser(sub)
    add_materials_parser(sub)
    d = sub.add_parser("demo", help="the newcomer's first run: cloth_node in its own process, "
                       "the walking bag replayed into it, its output recorded and drawn")
    d.add_argument("--particles", type=int, default=1200,
                   help="about how many cloth particles (default 1200)")
    d.add_argument("--steps", type=int, default=None,
                   help="replay only the first N pose messages (default: all)")
    d.add_argument("--out", default="out/demo",
                   help="output folder: cloth_bag/, frames.png, node.log")
    d.add_argument("--bag", default=None,
                   help="pose bag to replay (default: the scene's, bags/walk)")
    d.add_argument("--rate", type=float, default=1.0,
                   help="replay speed factor (default 1: real time)")
    d.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain of the demo's processes (default: the first free one from "
                        "1 + pid %% 100 on)")
    w = sub.add_parser("warmup", help="compile every kernel the scenes' ticks use into numba's "
                       "cache (make runs it after installing; run it after an upgrade)")
    w.add_argument("--scenes", default=None,
                   help="comma list of scenes (default: every bundled body and sheet scene)")
    w.add_argument("--threads", type=int, default=0, help="kernel threads (0: every core)")
    return parser


def _cmd_warmup(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.warmup import warm_up_scenes

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.config.scenes import BODY_SCENES

    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.sim.sheets import SCENES

    known = (*BODY_SCENES, *SCENES)
    scenes = known if args.scenes is None else [s.strip() for s in args.scenes.split(",")]
    unknown = [s for s in scenes if s not in known]
    if unknown:
        raise ClothInputError(f"--scenes: unknown scene(s) {', '.join(unknown)}; choose from "
                              f"{', '.join(known)}")
    t0 = time.perf_counter()
    results = warm_up_scenes(scenes, threads=args.threads)
    compiled = sum(r.compiled for r in results.values())
    print(f"warm-up done in {time.perf_counter() - t0:.1f} s: {compiled} kernels compiled into "
          f"numba's cache, the rest were there already")
    return 0


def main(argv: list[str] | None = None) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.memory import keep_freed_memory

    args = build_parser().parse_args(argv)
    keep_freed_memory()  # a step's large temporaries are not paged in afresh every step
    handlers = {"run": _cmd_run, "bench": _cmd_bench, "demo": _cmd_demo, "bag": run_bag_command,
                "export-system": _cmd_export, "replay": _cmd_replay, "record": _cmd_record,
                "batch": run_batch_command, "warmup": _cmd_warmup,
                "materials": run_materials_command}
    try:
        return handlers[args.command](args)
    except ClothInputError as exc:
        print(f"cloth-mg: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
