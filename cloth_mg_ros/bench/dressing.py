"""`cloth-mg bench dressing`: a robot pulls a gown's sleeve onto an arm (apps.dressing).

The cases: the published rig's two speeds (0.10 and 0.15 m/s over 0.85 m, Kapusta et al.
2016) on the arm held still and on the arm moving as in a mocap clip, and a bad pull whose
line is off the arm's axis, so that the hand inside the sleeve runs into its wall. Each case
prints the outcome, the dressed length and ratios, the peak force on the robot and on each
arm segment against 10 N (the rig's emergency stop) and 15 N (a snag), the slip of the held
cloth and how deep any cloth edge cut into the arm; writes them to JSON with the force
traces, a chart (forces against the gripper's travel) and a picture strip.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

# The simulation's modules (numba kernels) load when the benchmark runs, not when cloth-mg
# builds its parser (cli.main's PLUGIN_BENCHES).
E_STOP_N, SNAG_N, SPEEDS = 10.0, 15.0, (0.10, 0.15)  # N, N, m/s: apps.dressing's (a test
# checks that they agree)
SEGMENTS = ("hand", "forearm", "upper_arm")

DEFAULT_JSON = "doc/results/bench_dressing.json"
DEFAULT_PNG = "doc/bench_dressing.png"
DEFAULT_STRIP = "doc/bench_dressing_strip.png"
BAD_ANGLE_DEG = 15.0  # the bad pull's line against the arm's axis
PARTICLES, QUICK_PARTICLES = 2000, 1200


def cases(bag: str = "walk", quick: bool = False, particles: int | None = None) -> list:
    """The benchmark's runs: both speeds on the still arm and on the arm moving as in
    ``bag``, and the bad pull (still arm, 0.10 m/s, the line BAD_ANGLE_DEG off the arm);
    quick: 0.15 m/s only, fewer particles. Returns [apps.dressing.DressingSpec]."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing import DressingSpec

    n = particles or (QUICK_PARTICLES if quick else PARTICLES)
    speeds = SPEEDS[-1:] if quick else SPEEDS
    out = [DressingSpec(motion=m, speed=v, particles=n,
                        label=f"{'still' if m == 'still' else 'moving'}, {v:.2f} m/s")
           for m in ("still", bag) for v in speeds]
    out.append(DressingSpec(motion="still", speed=SPEEDS[0], angle_deg=BAD_ANGLE_DEG,
                            particles=n, label=f"bad pull, {BAD_ANGLE_DEG:g} deg off"))
    return out


def trace(run, every: int = 2) -> dict:
    """The run's forces against the gripper's travel, every ``every``-th step: travel m,
    force N (on the grippers together, averaged as in the summary), body N (the largest of
    the segments'), dressed m. run: an apps.dressing.DressingRun."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing import windowed

    steps = run.steps
    force = windowed(np.array([r["force_n"] for r in steps]), run.spec.dt)
    body = windowed(np.array([r["body_n"] for r in steps]), run.spec.dt).max(axis=1)
    keep = slice(None, None, every)
    return {"travel_m": [round(r["travel"], 5) for r in steps][keep],
            "force_n": np.round(force, 4)[keep].tolist(),
            "body_n": np.round(body, 4)[keep].tolist(),
            "dressed_m": [round(r["dressed"], 4) for r in steps][keep]}


def table(rows: list[dict]) -> str:
    """The printed table of the runs' summaries."""
    header = ["case", "outcome", "dressed m", "upper arm", "whole arm", "peak F N",
              "at m", "10 N at m", "hand N", "forearm N", "upper arm N", "slip m",
              "edge in arm mm", "ms/step"]
    body = []
    for r in rows:
        def at(v):
            return "-" if v is None else f"{v:.2f}"
        body.append([r["name"], r["outcome"], f"{r['dressed_m']:.2f}",
                     f"{r['upper_arm_ratio']:.2f}", f"{r['whole_arm_ratio']:.2f}",
                     f"{r['peak_force_n']:.2f}", at(r["peak_force_travel_m"]),
                     at(r["e_stop_travel_m"])]
                    + [f"{r['peak_body_n'][s]:.2f}" for s in SEGMENTS]
                    + [f"{r['slip_m']:.0e}" if r["slip_m"] else "0",
                       f"{1e3 * r['edge_depth_m']:.1f}",
                       f"{1e3 * r['wall_s'] / max(r['steps'], 1):.0f}"])
    return text_table(header, body)


def chart(results: list[dict], png: str | Path) -> Path:
    """Gripper force and the largest arm-segment force against the gripper's travel, every
    case, with the 10 N and 15 N lines."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for k, r in enumerate(results):
        tr = r["trace"]
        style = {"color": f"C{k}", "lw": 1.2, "label": r["summary"]["name"]}
        axes[0].plot(tr["travel_m"], tr["force_n"], **style)
        axes[1].plot(tr["travel_m"], tr["body_n"], **style)
    for ax, title in zip(axes, ("on the robot (grippers together)",
                                "on the arm (largest segment)"), strict=True):
        for level, what in ((E_STOP_N, "10 N: the rig's e-stop"), (SNAG_N, "15 N: a snag")):
            ax.axhline(level, color="0.4", ls="--" if level == E_STOP_N else ":", lw=0.9)
            ax.text(0.01, level + 0.3, what, fontsize=7, color="0.3")
        ax.set_xlabel("gripper travel along the arm, m")
        ax.set_title(f"force {title}", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("force, N (0.1 s mean)")
    axes[0].legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, 0.9))
    fig.tight_layout()
    return save_chart(fig, png)


def strip(runs: list, png: str | Path, per_run: int = 3) -> Path:
    """A picture strip: ``per_run`` frames of each run (sleeve and arm), each view centred
    between the sleeve and the arm, one scale for all."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    shots = [(run, frame) for run in runs
             for frame in [run.frames[i] for i in
                           np.linspace(0, len(run.frames) - 1, per_run).round().astype(int)]]
    fig = plt.figure(figsize=(2.6 * len(shots), 3.0))
    for k, (run, (t, x, capsules)) in enumerate(shots):
        ax = fig.add_subplot(1, len(shots), k + 1, projection="3d")
        faces = run.faces
        ax.add_collection3d(Poly3DCollection(x[faces], facecolors=(0.30, 0.55, 0.85, 0.55),
                                             edgecolors=(0.1, 0.2, 0.4, 0.15),
                                             linewidths=0.2))
        for p0, p1, r in capsules:
            ax.plot(*np.stack([p0, p1]).T, color="0.3", lw=150 * r, solid_capstyle="round")
        centre = 0.5 * (x.mean(axis=0) + np.mean([c[0] for c in capsules], axis=0))
        span = 0.3
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
            setter(c - span, c + span)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=18, azim=-35)
        ax.set_axis_off()
        ax.set_title(f"{run.spec.name}\nt = {t:.1f} s", fontsize=7)
    fig.tight_layout()
    return save_chart(fig, png)


def bench_dressing(specs: list, progress: bool = True, log=print) -> tuple[list[dict], list]:
    """Run every spec (apps.dressing.DressingSpec): ([{"summary": its figures, "trace": its
    forces}], the DressingRuns)."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing import run_dressing

    results, runs = [], []
    for spec in specs:
        run = run_dressing(spec, progress=progress, shots=4)
        summary = run.summary()
        log(f"  {summary['name']}: {summary['outcome']}, dressed {summary['dressed_m']:.2f} m, "
            f"peak force {summary['peak_force_n']:.2f} N ({run.wall_s:.0f} s)")
        results.append({"summary": summary, "trace": trace(run)})
        runs.append(run)
    return results, runs


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench dressing` on the bench sub-parsers."""
    p = bsub.add_parser("dressing", help="a robot pulls a gown's sleeve onto an arm: dressed "
                        "length, forces on the robot and the arm, slip; JSON, chart, strip")
    p.add_argument("--quick", action="store_true",
                   help=f"0.15 m/s and the bad pull only, {QUICK_PARTICLES} particles")
    p.add_argument("--particles", type=int, default=None,
                   help=f"the sleeve's particles (default {PARTICLES}, quick "
                        f"{QUICK_PARTICLES})")
    p.add_argument("--bag", default="walk", help="the clip the moving arm follows")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.add_argument("--png", default=DEFAULT_PNG, help=f"chart (default {DEFAULT_PNG})")
    p.add_argument("--strip", default=DEFAULT_STRIP,
                   help=f"picture strip (default {DEFAULT_STRIP})")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    if args.particles is not None and args.particles < 200:
        raise ClothInputError(f"--particles must be at least 200, got {args.particles}")
    specs = cases(args.bag, args.quick, args.particles)
    t0 = time.perf_counter()
    print(f"bench dressing: {len(specs)} runs, sleeve of about {specs[0].particles} particles "
          f"({specs[0].material}), arm: still and {args.bag}")
    results, runs = bench_dressing(specs, not args.no_progress)
    rows = [r["summary"] for r in results]
    print(table(rows))
    print("dressed: the arm's length inside the sleeve's held opening at the end (fingertip to "
          "shoulder); forces: 0.1 s means; slip: held cloth's distance from its gripper's "
          "frame; edge in arm: deepest cloth edge inside a capsule")
    write_json(args.json, {"cases": results, "wall_s": time.perf_counter() - t0,
                           "quick": bool(args.quick)})
    keep = [runs[0], runs[-1]]
    print(f"wrote {args.json}, {chart(results, args.png)}, {strip(keep, args.strip)}")
    return 0
