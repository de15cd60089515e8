"""`cloth-mg bench faults`: cloth_node live under faults and load, each judged against what
the node should do.

    cloth-mg bench faults                 # every fault, ~1200 particles (the hogs ~2400)
    cloth-mg bench faults --faults stale,burst,sigint --particles 400 --json out/f.json

cloth_node runs as a subprocess (`ros.processes.NodeProcess`, the scene's params file and
`particles:=N`) on a ROS domain of its own; this process publishes body poses into it as raw
PoseArray bytes (reliable, keep-last 100; the node's best-effort subscription matches),
paced at 30 Hz of wall time: the scene bag's frames (or --bag's) forward and back, stamped `start +
k/30 s`, so a run lasts as long as its faults need. It subscribes raw to /cloth/marker (the cloth,
and DELETEALL: the display cleared), /cloth/markers (the body; a DELETEALL there is one marker)
and /cloth/stats (one status per tick: the pose counters, `level`, `lod_switches`,
`stream_restarts`, `skipped_<kind>`; the message starts with "dressed" on a dressing).

Rows (FAULTS, in this order; the stream faults share one node process, a drain between them
settles its counters; each shutdown fault has a process of its own):

- hog1, hog2: a busy loop on one, then both cores for --hog-s s, on a node of their own with
  a garment of --load-particles (2400: at 1200 the walking dress has no coarser level to step
  down to). The node may step down its level of detail; it must be back at level 0 within
  6 s of the load's end, with at most 4 switches, and lose no pose (a slow tick coalesces, it
  does not drop).
- burst: 10 poses at once: coalesced, none lost.
- reorder: neighbouring stamps swapped (each pair back to back): a pose still ahead of the
  simulated time is used, one at or before it is skipped as stale and counted; nothing
  else is lost.
- duplicate: every pose twice: each copy skipped as stale.
- stale: one pose stamped 5 s back: skipped and counted (`skipped_stale`), the cloth kept
  (no DELETEALL, no re-dress).
- new_stream: the publisher stops 2 s and restarts from its first stamp: the node re-dresses
  once (DELETEALL on both marker topics, a "dressed" status, `stream_restarts` +1) once the
  new time line has advanced for 5 poses; at most 6 valid poses are not used.
- loop: the bag twice with its own stamps (`ros2 bag play --loop`): a re-dress per jump back.
- bad_frames: NaN, empty and wrong-count frames among the valid ones: each skipped and
  counted by kind, the cloth kept.
- sub_gone: this process's /cloth/marker subscription is destroyed for 3 s: the node goes on
  ticking (its statuses cover every pose), and a new subscriber gets markers again.
- sigint, sigterm: the signal half a tick after a pose: exit status 0, DELETEALL received on
  /cloth/marker and /cloth/markers, no traceback.

Figures per row: what the node did, the latency from a pose's publication to the first marker
stamped at or after it (p50 / p95, ms) in the fault window (at least 1 s) and in the window
after it, poses lost (valid poses sent but not counted used by the node: its counters'
growth over the row against this process's count), whether the cloth was kept, the level
switches and the time back to level 0 (load rows), the exit status and DELETEALLs (signal
rows), and `ok`. A node's `skipped_stamp_backwards` (the name a node without
`skipped_stale` gives that counter) counts as stale in the figures; the checks on
`skipped_stale` and `stream_restarts` need a node that reports them.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from cloth_mg_ros.bench.faults.figures import format_table
from cloth_mg_ros.bench.faults.injection import bench_faults as run
from cloth_mg_ros.bench.faults.injection import parse_faults
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.processes import check_domain_id, run_node_job

__all__ = ["add_cli", "bench_faults", "main", "run_cli"]

DEFAULT_JSON = "out/bench_faults.json"


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench faults` on the bench sub-parsers."""
    p = bsub.add_parser("faults", help="cloth_node live under faults (CPU hogs, bursts, stale "
                        "and reordered stamps, a restarted or looped stream, bad frames, a "
                        "vanished subscriber, SIGINT/SIGTERM): what it did, latency, poses "
                        "lost, ok")
    p.add_argument("--particles", type=int, default=1200,
                   help="about how many cloth particles (default 1200)")
    p.add_argument("--faults", default="all",
                   help="comma list of rows to run (default all): hog1, hog2, burst, reorder, "
                        "duplicate, stale, new_stream, loop, bad_frames, sub_gone, sigint, "
                        "sigterm")
    p.add_argument("--hog-s", type=float, default=10.0,
                   help="how long each CPU hog runs, s (default 10)")
    p.add_argument("--load-particles", type=int, default=2400,
                   help="the garment's size in the CPU-hog rows, on a node of their own "
                        "(default 2400: at 1200 the walking dress has no coarser level of "
                        "detail to step down to); 0: --particles, on the shared node")
    p.add_argument("--scene", default="walking", help="body scene (default walking)")
    p.add_argument("--bag", default=None,
                   help="bag whose body poses are streamed (default: the scene's); the node "
                        "keeps the scene's for its calibration, so this motion is new to it")
    p.add_argument("--rate-hz", type=float, default=30.0,
                   help="the pose stream's rate (default 30, the bag's): each pose of the bag "
                        "in turn, stamped 1/rate s apart (below 30 Hz the body moves in slow "
                        "motion, as from a slower tracker, and every tick has a longer budget)")
    p.add_argument("--start-timeout", type=float, default=None,
                   help="how long to wait for each cloth_node to start, s (default "
                        "ros.processes.START_TIMEOUT_S; a loaded machine may need more)")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain of the benchmark's processes (default: the first free one "
                        "from 1 + pid %% 100 on)")
    p.add_argument("--check", action="store_true",
                   help="exit with status 1 when a row is not ok")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the rows, print the table, write the JSON (and the nodes' logs beside it:
    <json stem>.<session>.node.log). Returns 0 (with --check: 1 when a row is not ok), 1 when
    a node could not start, 130 on Ctrl-C."""

    names = parse_faults(args.faults)
    if args.start_timeout is not None and not (math.isfinite(args.start_timeout)
                                                and args.start_timeout > 0.0):
        raise ClothInputError(f"bench faults: --start-timeout must be a positive number of "
                              f"seconds, got {args.start_timeout!r}")
    if args.domain_id is not None:
        check_domain_id(args.domain_id)
    out = Path(args.json)
    log_dir = out.parent / f"{out.stem}.node_logs"
    result, code = run_node_job(
        lambda: bench_faults(names, args.particles, args.hog_s, args.scene, args.domain_id,
                             log_dir, start_timeout_s=args.start_timeout,
                             log=lambda line: print(line, flush=True),
                             load_particles=args.load_particles, bag=args.bag,
                             rate_hz=args.rate_hz),
        "cloth_node and the hogs stopped")
    if code:
        return code
    print(format_table(result["rows"]))
    write_json(out, result)
    print(f"wrote {out} (the nodes' logs in {log_dir})")
    return 1 if args.check and not result["ok"] else 0


def bench_faults(*args, **kwargs) -> dict:
    """`cloth_mg_ros.bench.faults.injection.bench_faults` (imported when called: the CLI's
    parser stays quick to build)."""
    return run(*args, **kwargs)
