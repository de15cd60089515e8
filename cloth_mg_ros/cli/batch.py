"""`cloth-mg batch` on the command line (the grid and its runs: cloth_mg_ros.apps.batch; the Dask
cluster: cloth_mg_ros.apps.cluster)."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from cloth_mg_ros.errors import ClothInputError

__all__ = ["add_batch_parser", "add_cluster_arguments", "run_batch_command", "split_list"]


def split_list(text: str, name: str, kind=str) -> list:
    """'a,b,c' -> [a, b, c] converted by `kind`; ClothInputError naming `name` otherwise."""
    items = [t.strip() for t in str(text).split(",") if t.strip()]
    try:
        return [kind(t) for t in items]
    except ValueError:
        raise ClothInputError(f"--{name}: {text!r} is not a comma-separated list of "
                              f"{kind.__name__} values") from None


def add_cluster_arguments(p: argparse.ArgumentParser, workers_help: str) -> None:
    """--scheduler and --workers, shared by `batch` and the benchmark sweeps."""
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the tasks on this running Dask scheduler (started with `dask "
                        "scheduler`, its workers with `dask worker tcp://HOST:PORT --nthreads "
                        "1`); default: an embedded LocalCluster")
    p.add_argument("--workers", type=int, default=None, metavar="N", help=workers_help)


def add_batch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help="a grid of headless garment runs (bags x garments x "
                       "materials x particles x solvers) as Dask tasks, resumable")
    p.add_argument("--bags", default=None,
                   help="comma-separated bundled bags (walk, brisk_walk, run, jump) or bag "
                        "paths (default walk, or none with --bvh)")
    p.add_argument("--bvh", default=None, metavar="DIR",
                   help="also convert every DIR/*.bvh into OUT/bags/<name> (as tasks) and run "
                        "the grid on those bags")
    p.add_argument("--garments", default="dress", help="comma-separated (default dress)")
    p.add_argument("--materials", default="white-dots-on-blk",
                   help="comma-separated (default white-dots-on-blk, a measured fabric)")
    p.add_argument("--particles", default="1200", help="comma-separated (default 1200)")
    p.add_argument("--solvers", default="mpcg", help="comma-separated (default mpcg)")
    p.add_argument("--seconds", type=float, default=None,
                   help="seconds of motion after the lead-in (default: the whole bag)")
    p.add_argument("--scene", default="walking",
                   help="base scene for everything else (default walking)")
    p.add_argument("--mcap", action="store_true",
                   help="also write each run's markers as an MCAP bag (markers/)")
    p.add_argument("--out", default="out/batch", help="output folder (default out/batch)")
    add_cluster_arguments(p, "embedded cluster: this many single-threaded worker processes "
                             "(default: one per core)")


def run_batch_command(args: argparse.Namespace) -> int:
    """Exit status 0 when every run of the grid is ok, 1 when some failed."""
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.apps.batch import BatchGrid, format_batch_report, run_batch, validate_grid
    from cloth_mg_ros.apps.cluster import dask_client

    bags = args.bags if args.bags is not None else ("" if args.bvh else "walk")
    grid = BatchGrid(bags=split_list(bags, "bags"),
                     garments=split_list(args.garments, "garments"),
                     materials=[m.lower() for m in split_list(args.materials, "materials")],
                     particles=split_list(args.particles, "particles", int),
                     solvers=split_list(args.solvers, "solvers"), seconds=args.seconds,
                     scene=args.scene, mcap=args.mcap)
    # every value before a cluster starts; with --bvh the converted clips' bags come later,
    # so the grid's other values are checked against a bundled bag in their place
    validate_grid(grid if not args.bvh or grid.bags
                  else dataclasses.replace(grid, bags=["walk"]))
    with dask_client(args.scheduler, args.workers) as client:
        result = run_batch(grid, args.out, client, bvh_dir=args.bvh,
                           log=lambda line: print(line, file=sys.stderr, flush=True))
    print(format_batch_report(result))
    print(f"manifest: {args.out}/manifest.csv")
    return 1 if any(r["status"] != "ok" for r in result["rows"]) else 0
