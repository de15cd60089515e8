"""The `cloth-mg bench peers` sub-command: its options and what it runs and writes.

`cloth_mg_ros.cli.main` imports this package whenever it builds its parser, so matplotlib and the
engines' packages are imported inside the functions that need them, never at the top."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cloth_mg_ros.bench.peers.options import (
    DEFAULT_DT,
    DEFAULT_PARTICLES,
    DEFAULT_STEPS,
    WARMUP_STEPS,
    parse_engines,
    parse_settings,
    validate_peers_args,
)
from cloth_mg_ros.bench.peers.report import format_peers_report, plot_peers
from cloth_mg_ros.bench.peers.run import bench_peers
from cloth_mg_ros.bench.solvers import parse_list


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench peers` on the bench sub-parsers."""
    p = bsub.add_parser("peers", help="the drape scene in this solver, Newton (Style3D, VBD; "
                        "CPU) and MuJoCo flex, timed side by side (needs the peers extra)")
    p.add_argument("--particles", default=",".join(map(str, DEFAULT_PARTICLES)),
                   help="comma-separated particle counts (default 1200,2400,4500)")
    p.add_argument("--engines", default="all",
                   help="comma-separated engines or engine:solver: ours (mpcg, mg), newton "
                        "(style3d, vbd), mujoco (newton, cg); default all")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                   help=f"steps per run (default {DEFAULT_STEPS}; the first {WARMUP_STEPS} "
                        "are not timed)")
    p.add_argument("--dt", type=float, default=DEFAULT_DT, help="step, s (default 1/60)")
    p.add_argument("--material", default="cotton", help="material (default cotton)")
    p.add_argument("--set", action="append", default=None, metavar="RUN.KEY=VALUE",
                   help="override a run's setting, e.g. newton:vbd.iterations=20 "
                        "(repeatable; keys: substeps, iterations, linear_iterations, "
                        "contact_ke, contact_kd, tolerance, tol)")
    p.add_argument("--threads", type=int, default=1,
                   help="our engine's kernel threads (default 1, as the peers' CPU paths; 0: "
                        "every core)")
    p.add_argument("--json", default="out/bench_peers.json", help="JSON output file")
    p.add_argument("--png", default="out/bench_peers.png", help="chart output file")
    p.set_defaults(bench_func=cmd_bench_peers)


def cmd_bench_peers(args: argparse.Namespace) -> int:
    """`cloth-mg bench peers`: run, print the table, write the JSON and the PNG."""

    particles = parse_list(args.particles, "particles", int)
    labels = parse_engines(args.engines)
    settings = parse_settings(args.set)
    validate_peers_args(particles, labels, args.steps, args.dt, args.material)
    result = bench_peers(particles, labels, args.steps, args.dt, args.material, settings,
                         threads=args.threads)
    print(format_peers_report(result))
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(result, indent=1))
    png = plot_peers(result, args.png)
    print(f"wrote {args.json} and {png}")
    return 0
