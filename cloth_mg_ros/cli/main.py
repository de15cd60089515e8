"""`cloth-mg`: the command line of cloth_mg_ros (headless runs, benchmarks, the demo)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time

from cloth_mg_ros.cli.bag import add_bag_parser, run_bag_command
from cloth_mg_ros.cli.batch import add_batch_parser, run_batch_command
from cloth_mg_ros.cli.fidelity import (
    add_materials_parser,
    run_materials_command,
)
from cloth_mg_ros.cli.run import add_run_parser, run_command
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.extras import extra_of, missing_extra_message, require_extras

# Every benchmark's module adds its own sub-command: ``add_cli(bsub)`` registers the parser
# and sets ``bench_func`` (a callable taking the parsed args, returning the exit code). Their
# modules import no optional ('bench' extra) module at the top, so the parser builds without.
BENCHES = ("matvec", "solvers", "walking", "node", "pareto", "scaling", "stability", "peers",
           "profile_tick", "cost", "faults", "fidelity", "dressing", "dynamics", "folds",
           "trackers", "capstan")


def _add_bench(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks that print and save figures")
    bsub = p.add_subparsers(dest="bench", required=True)
    for name in BENCHES:
        importlib.import_module(f"cloth_mg_ros.bench.{name}").add_cli(bsub)


def _add_export(sub: argparse._SubParsersAction) -> None:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.physics.materials import MATERIALS
    from cloth_mg_ros.sim.sheets import SCENES

    e = sub.add_parser("export-system", help="write one step's linear system (A, b, direct "
                       "solution, prolongations) to an .npz for other solvers")
    e.add_argument("--scene", default="drape", help=f"one of {', '.join(SCENES)}")
    e.add_argument("--particles", type=int, default=2400, help="about how many particles")
    e.add_argument("--material", default="cotton", help=f"one of {', '.join(MATERIALS)}")
    e.add_argument("--step", type=int, default=0, help="step index, 0 = the first system")
    e.add_argument("--levels", type=int, default=None, help="hierarchy levels (default: auto)")
    e.add_argument("--dt", type=float, default=1.0 / 60.0, help="time step, s")
    e.add_argument("--scheme", default="bdf2",
                   help="implicit integrator: euler, bdf2 or genalpha (default bdf2)")
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
    # before any work: a benchmark's charts, baselines and sweeps are the 'bench' extra's
    require_extras("bench", f"cloth-mg bench {args.bench}")
    return args.bench_func(args)


def _cmd_demo(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.demo import run_demo
    from cloth_mg_ros.ros.demo_recording import format_table
    from cloth_mg_ros.ros.processes import run_node_job

    print(f"cloth_mg_ros demo: cloth_node drapes a dress on an avatar walking as CMU subject 7 "
          f"walked ({args.bag or 'bags/walk'}, replayed over DDS), implicit BDF2, faithful "
          f"multigrid; recording /cloth/marker and /cloth/stats", flush=True)
    r, code = run_node_job(lambda: run_demo(
        args.out, args.particles, args.steps, args.bag, rate=args.rate,
        domain_id=args.domain_id, log=lambda line: print(line, flush=True)))
    if code:
        return code
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
    p.add_argument("--topic-out", default=None, metavar="T",
                   help="publish the one topic played (the bag's only one, or one --topic) "
                        "on T instead, for a node whose input topic is T (relative: under "
                        "--namespace)")


def _cmd_replay(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.ros.replay import replay_bag

    return _with_ros(lambda: replay_bag(args.bag, rate=args.rate, loop=args.loop,
                                        topics=args.topic, wait_s=args.wait,
                                        settle_s=args.settle, clock=args.clock,
                                        namespace=args.namespace,
                                        topic_out=args.topic_out,
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

    import rclpy
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
    add_run_parser(sub)
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
    w.add_argument("--peers", action="store_true",
                   help="only the peers of `bench peers` (the .[peers] extra): a few steps of "
                        "each, so that Warp compiles their kernels into its cache (make test "
                        "runs it; ~85 s the first time)")
    return parser


def _cmd_warmup(args: argparse.Namespace) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.warmup import warm_up_scenes
    from cloth_mg_ros.config.scenes import BODY_SCENES
    from cloth_mg_ros.sim.sheets import SCENES

    if args.peers:
        from cloth_mg_ros.bench.peers.run import warm_up_peers

        t0 = time.perf_counter()
        warm_up_peers()
        print(f"peers' warm-up done in {time.perf_counter() - t0:.1f} s")
        return 0
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


# Each command's output paths (attribute, flag): folders, then files. bag from-bvh and record
# write a new bag folder and check it themselves.
_OUTPUT_DIRS = {"run": "out", "demo": "out", "batch": "out"}
_OUTPUT_FILES = (("json", "--json"), ("png", "--png"), ("strip", "--strip"),
                 ("picture", "--picture"))


def _check_outputs(args: argparse.Namespace) -> None:
    """ClothInputError naming the flag of an output path that cannot be written."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.io.outputs import check_output_dir, check_output_file

    folder = _OUTPUT_DIRS.get(args.command)
    if folder and getattr(args, folder, None):
        check_output_dir(getattr(args, folder), f"--{folder}")
    if args.command == "export-system" and args.out:
        check_output_file(args.out, "--out")
    for attr, flag in _OUTPUT_FILES:
        value = getattr(args, attr, None)
        if isinstance(value, (str, os.PathLike)) and value:
            check_output_file(value, flag)


def main(argv: list[str] | None = None) -> int:
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.memory import keep_freed_memory

    args = build_parser().parse_args(argv)
    keep_freed_memory()  # a step's large temporaries are not paged in afresh every step
    handlers = {"run": run_command, "bench": _cmd_bench, "demo": _cmd_demo, "bag": run_bag_command,
                "export-system": _cmd_export, "replay": _cmd_replay, "record": _cmd_record,
                "batch": run_batch_command, "warmup": _cmd_warmup,
                "materials": run_materials_command}
    try:
        _check_outputs(args)  # before any work: results written at the end must fit there
        return handlers[args.command](args)
    except ClothInputError as exc:
        print(f"cloth-mg: error: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        if extra_of(exc.name) is None:
            raise
        print(f"cloth-mg: error: {missing_extra_message(exc.name, f'cloth-mg {args.command}')}",
              file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
