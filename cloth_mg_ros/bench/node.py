"""`cloth-mg bench node`: the command line of the live node benchmark (bench.node_latency
runs it, bench.node_figures reports it). Kept apart so that building cloth-mg's parser does
not load rclpy."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.config.scenes import particles_option
from cloth_mg_ros.errors import ClothInputError

__all__ = ["add_cli", "rates_option", "run_cli"]


def rates_option(text: str) -> list[float]:
    """--rate of the node benchmark: one factor or a comma list (one per pass)."""
    try:
        return [float(part) for part in text.split(",")]
    except ValueError:
        raise ClothInputError(f"--rate must be a number or a comma list of numbers, got "
                              f"{text!r}") from None


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench node` on the bench sub-parsers."""
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
    n.add_argument("--contact-friction", default=None,
                   help="where the body's friction acts: projection or solve (the node's "
                        "contact_friction parameter; default: the scene's)")
    n.add_argument("--json", default="out/bench_node.json", help="JSON output file")
    n.add_argument("--png", default=None, help="also chart the latency over the clip here")
    n.add_argument("--threads", type=int, default=None,
                   help="the node's solver threads (default: the scene's, 0: every core)")
    n.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the node benchmark, print its report, write the JSON (and the chart with --png).
    Returns 0, 1 when the node could not start, 130 on Ctrl-C."""
    # imported here: rclpy and the node's processes load when the benchmark runs
    from cloth_mg_ros.bench.node_figures import format_node_report, plot_node
    from cloth_mg_ros.bench.node_latency import bench_node
    from cloth_mg_ros.ros.processes import run_node_job

    result, code = run_node_job(lambda: bench_node(
        args.bag, particles_option(args.particles), args.scene, rates_option(args.rate),
        args.messages, args.domain_id, Path(args.json).with_suffix(".node.log"),
        log=lambda line: print(line, flush=True), threads=args.threads, loops=args.loops,
        lod=None if args.lod is None else args.lod == "true", tick_budget=args.tick_budget,
        contact_friction=args.contact_friction))
    if code:
        return code
    print(format_node_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json}")
    if args.png:
        print(f"wrote {plot_node(result, args.png)}")
    return 0
