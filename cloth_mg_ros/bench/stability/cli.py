"""`cloth-mg bench stability`: the sub-command's parser (`add_cli`) and its run
(`cmd_stability`: validate, run the map, print the report, write the JSON and the heatmap)."""

from __future__ import annotations

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.bench.stability.options import (
    DEFAULT_DTS,
    DEFAULT_JOBS,
    DEFAULT_MATERIALS,
    DEFAULT_PARTICLES,
    DEFAULT_SCHEMES,
    DEFAULT_SECONDS,
    DEFAULT_SOLVERS,
    MAX_SPEED_UP,
    MIN_LEVELS,
    MOTIONS,
    SETTLE_SCHEME,
    validate_stability_args,
)
from cloth_mg_ros.bench.stability.report import format_stability_report, plot_stability
from cloth_mg_ros.bench.stability.sweep import bench_stability
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS


# -- command line -------------------------------------------------------------------------
def add_cli(bsub) -> None:
    """Add ``stability`` to the bench sub-parsers ``bsub``."""
    p = bsub.add_parser("stability", help="materials x step sizes x motions x solvers: ok, "
                        "not converged, NaN, blew up or tunnelled (heatmap and JSON)")
    p.add_argument("--materials", default=",".join(DEFAULT_MATERIALS),
                   help=f"comma-separated materials (default {','.join(DEFAULT_MATERIALS)})")
    p.add_argument("--dts", default=",".join(DEFAULT_DTS),
                   help=f"comma-separated steps in s, dividing 1/30 s or spanning 2-7 pose "
                        f"messages (default {','.join(DEFAULT_DTS)})")
    p.add_argument("--motions", default=",".join(MOTIONS),
                   help=f"comma-separated motions (default {','.join(MOTIONS)})")
    p.add_argument("--solvers", default=",".join(DEFAULT_SOLVERS),
                   help=f"comma-separated solvers, 'explicit' for symplectic Euler (default "
                        f"{','.join(DEFAULT_SOLVERS)})")
    p.add_argument("--schemes", default=",".join(DEFAULT_SCHEMES),
                   help=f"comma-separated implicit schemes, an axis (default "
                        f"{','.join(DEFAULT_SCHEMES)}); every cell settles with "
                        f"{SETTLE_SCHEME} first; the explicit solver is run once")
    p.add_argument("--spectral-radius", default=None,
                   help=f"genalpha's spectral radius rho_inf in 0..1 (default "
                        f"{DEFAULT_SPECTRAL_RADIUS:g}, the scene parameter's)")
    p.add_argument("--linearise", default="start",
                   help="where euler's and bdf2's steps linearise the forces: start (the "
                        "default) or prediction (sim.newton.predicted_step)")
    p.add_argument("--contact-friction", default="projection",
                   help="where the body's and the floor's friction acts: projection (after "
                        "the solve, the default) or solve (inside it; sim.contact_friction)")
    p.add_argument("--particles", default=str(DEFAULT_PARTICLES),
                   help=f"comma-separated garment particle counts, the resolution axis "
                        f"(default {DEFAULT_PARTICLES}; at least {MIN_LEVELS} hierarchy "
                        f"levels each)")
    p.add_argument("--speeds", default="1",
                   help=f"comma-separated motion speed-ups, an axis (default 1; at most "
                        f"{MAX_SPEED_UP}): every speed-th pose message, still one per 1/30 s")
    p.add_argument("--seconds", default=str(DEFAULT_SECONDS),
                   help=f"seconds of motion per cell after the still lead-in (default "
                        f"{DEFAULT_SECONDS:g})")
    p.add_argument("--workers", "--jobs", dest="workers", default=str(DEFAULT_JOBS),
                   help=f"Dask workers of the embedded cluster (default {DEFAULT_JOBS}; 1: "
                        f"in this process)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the cells on this running Dask scheduler instead")
    p.add_argument("--json", default="out/bench_stability.json", help="JSON output file")
    p.add_argument("--png", default="out/bench_stability.png", help="heatmap PNG file")
    p.set_defaults(bench_func=cmd_stability)


def cmd_stability(args) -> int:
    """Run the map from parsed CLI args; exit 0, or 1 when mg is not ok in every cell (of
    every scheme)."""
    cfg = validate_stability_args(args.materials, args.dts, args.motions, args.solvers,
                                  args.particles, args.seconds, args.workers,
                                  json_path=args.json, png_path=args.png, speeds=args.speeds,
                                  scheduler=args.scheduler, schemes=args.schemes,
                                  spectral_radius=args.spectral_radius,
                                  linearise=args.linearise,
                                  contact_friction=args.contact_friction)
    result = bench_stability(cfg)
    print(format_stability_report(result))
    write_json(args.json, result)
    plot_stability(result, args.png)
    print(f"wrote {args.json} and {args.png}")
    return 1 if result["summary"]["mg_ok_everywhere"] is False else 0
