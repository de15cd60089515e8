"""`cloth-mg bench dressing`: a robot pulls a gown's sleeve onto an arm (apps.dressing_scene), each
case from N starts a micrometre apart, reported as distributions.

The cases: the published rig's two speeds (0.10 and 0.15 m/s over 0.85 m, Kapusta et al.
2016) on the arm held still and on the arm moving as in a mocap clip, and a bad pull whose
line is off the arm's axis, so that the hand inside the sleeve runs into its wall.

The contact of a sleeve sliding over a hand is chaotic (a change of gravity by one part in
10^12 turns a good pull into a catch), so one run of a case is one sample. Each case runs
from ``starts`` starts: start k moves every sleeve particle's start NUDGE_M (1 micrometre)
in a direction drawn from numpy's default_rng([seed, k]) (apps.dressing_scene.nudge_positions),
a difference no rig could make or measure; the same seed and k give the same run, bit for
bit, on one machine. Per case it prints the share of each outcome (missed, caught, good)
with its 95 % interval (Wilson's score interval, bench.dressing_stats) and the median and
10th-90th percentiles of the dressed length, the peak force on the robot and on each arm
segment (against 10 N, the rig's emergency stop, and 15 N, a snag) and where the force
passed 10 N; writes every start's figures and force trace to JSON, a chart (every start's
forces against the gripper's travel) and a picture strip of start 0.

The starts are independent runs: Dask tasks on the project's embedded cluster
(apps.cluster), one single-threaded worker per core by default, or in this process with
``--workers 1``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.dressing_stats import (
    OUTCOMES,
    distribution,
    share_text,
    spread_text,
)
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

# The simulation's modules (numba kernels) load when the benchmark runs, not when cloth-mg
# builds its parser (cli.main's BENCHES).
E_STOP_N, SNAG_N, SPEEDS = 10.0, 15.0, (0.10, 0.15)  # N, N, m/s: apps.dressing_scene's (a test
# checks that they agree)
SEGMENTS = ("hand", "forearm", "upper_arm")

DEFAULT_JSON = "doc/results/bench_dressing.json"
DEFAULT_PNG = "doc/bench_dressing.png"
DEFAULT_STRIP = "doc/bench_dressing_strip.png"
BAD_ANGLE_DEG = 15.0  # the bad pull's line against the arm's axis
PARTICLES, QUICK_PARTICLES = 2000, 1200
STARTS = 10  # starts per case
NUDGE_M = 1e-6  # m: how far each sleeve particle's start is moved (module docstring)
TRACE_EVERY = 6  # steps between a start's trace points: one per 0.1 s force window at 1/60 s


def cases(bag: str = "walk", quick: bool = False, particles: int | None = None,
          travel: float | None = None, scheme: str = "bdf2",
          friction: float | None = None, spectral_radius: float | None = None,
          compression: str = "elastic") -> list:
    """The benchmark's cases, each at its nominal start: both speeds on the still arm and on
    the arm moving as in ``bag``, and the bad pull (still arm, 0.10 m/s, the line
    BAD_ANGLE_DEG off the arm); quick: 0.15 m/s only, fewer particles. travel m (None: the
    rig's 0.85 m), scheme: the integrator (spectral_radius: genalpha's rho_inf, None: the
    integrator's default), friction: the arm's Coulomb coefficient (None: the scene's),
    compression: the membrane's ('elastic' or 'buckle', sim.model.build_model). Returns
    [apps.dressing_scene.DressingSpec]; a bad value raises ClothInputError (the spec's check)."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing_scene import TRAVEL_M, DressingSpec

    n = particles or (QUICK_PARTICLES if quick else PARTICLES)
    speeds = SPEEDS[-1:] if quick else SPEEDS
    common = {"particles": n, "travel": travel or TRAVEL_M, "scheme": scheme,
              "compression": compression}
    if friction is not None:
        common["friction"] = friction
    if spectral_radius is not None:
        common["spectral_radius"] = spectral_radius
    out = [DressingSpec(motion=m, speed=v, label=f"{'still' if m == 'still' else 'moving'}, "
                        f"{v:.2f} m/s", **common)
           for m in ("still", bag) for v in speeds]
    out.append(DressingSpec(motion="still", speed=SPEEDS[0], angle_deg=BAD_ANGLE_DEG,
                            label=f"bad pull, {BAD_ANGLE_DEG:g} deg off", **common))
    return out


def case_key(spec) -> str:
    """A case's short name for --cases: still-0.10, still-0.15, moving-0.10, moving-0.15,
    bad."""
    if spec.angle_deg:
        return "bad"
    return f"{'still' if spec.motion == 'still' else 'moving'}-{spec.speed:.2f}"


def pick_cases(specs: list, keys: str | None) -> list:
    """The specs named in ``keys`` (comma-separated `case_key`s; None: all), in the
    benchmark's order; ClothInputError for a name that is not a case."""
    if not keys:
        return specs
    wanted = [k.strip() for k in keys.split(",") if k.strip()]
    known = [case_key(s) for s in specs]
    unknown = [k for k in wanted if k not in known]
    if unknown or not wanted:
        raise ClothInputError(f"--cases {keys!r}: choose from {', '.join(known)}")
    return [s for s in specs if case_key(s) in wanted]


def starts_of(spec, starts: int = STARTS, seed: int = 0, nudge: float = NUDGE_M) -> list:
    """The ``starts`` perturbed starts of a case: ``spec`` with start_nudge ``nudge`` m, the
    seed, and start 0 .. starts-1."""
    return [replace(spec, start_nudge=nudge, seed=seed, start=k) for k in range(starts)]


def trace(run, every: int = TRACE_EVERY) -> dict:
    """The run's forces against the gripper's travel, every ``every``-th step and the last:
    travel m, force N (on the grippers together, averaged as in the summary), body N (the
    largest of the segments'), dressed m. run: an apps.dressing_scene.DressingRun."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing_scene import windowed

    steps = run.steps
    force = windowed(np.array([r["force_n"] for r in steps]), run.spec.dt)
    body = windowed(np.array([r["body_n"] for r in steps]), run.spec.dt).max(axis=1)
    # every ``every``-th step and the last: a caught run's trace ends at its stop
    keep = np.unique(np.append(np.arange(0, len(steps), every), len(steps) - 1)) \
        if steps else np.zeros(0, dtype=np.int64)
    return {"travel_m": [round(steps[k]["travel"], 5) for k in keep],
            "force_n": np.round(force, 3)[keep].tolist(),
            "body_n": np.round(body, 3)[keep].tolist(),
            "dressed_m": [round(steps[k]["dressed"], 4) for k in keep]}


def run_start(spec) -> dict:
    """Run one start (an apps.dressing_scene.DressingSpec): {"summary": its figures without the
    spec, "trace": `trace`, "frames" and "faces": start 0's pictures (None for the others)}.
    A module-level function: the Dask tasks ship it to their workers."""
    # imported here: the simulation's modules (see the note above)
    from cloth_mg_ros.apps.dressing_scene import run_dressing

    run = run_dressing(spec, progress=False, shots=4 if spec.start == 0 else 0)
    summary = run.summary()
    summary.pop("spec")
    summary.update(seed=spec.seed, start=spec.start, start_nudge_m=spec.start_nudge)
    pictures = spec.start == 0
    return {"summary": summary, "trace": trace(run),
            "frames": run.frames if pictures else None,
            "faces": run.faces if pictures else None}


def run_starts(specs: list, workers: int = 1, progress: bool = True, log=print,
               finished=None) -> list[dict]:
    """`run_start` of every spec (the starts of every case), in ``workers`` processes (1: in
    this one; more: Dask's embedded cluster, apps.cluster), under a progress bar; the
    results in the order of ``specs``. finished: called with {position in specs: result}
    after each start finishes (a checkpoint). The first start that raised is raised again,
    after every other has finished."""
    t0 = time.perf_counter()
    results: dict[int, dict] = {}
    errors = []

    def done(k: int, result: dict | None, error: BaseException | None) -> None:
        spec = specs[k]
        if error is not None:
            errors.append((spec, error))
            log(f"  {spec.name}, start {spec.start}: failed ({error})")
            return
        results[k] = result
        if finished is not None:
            finished(results)
        s = result["summary"]
        log(f"  {spec.name}, start {spec.start}: {s['outcome']}, dressed {s['dressed_m']:.2f}"
            f" m, peak force {s['peak_force_n']:.2f} N ({s['wall_s']:.0f} s; "
            f"{time.perf_counter() - t0:.0f} s in all)")

    if workers == 1:
        bar = tqdm(list(enumerate(specs)), desc="starts", unit="run", disable=not progress,
                   file=sys.stderr, mininterval=0.5 if sys.stderr.isatty() else 10.0)
        for k, spec in bar:
            try:
                result, error = run_start(spec), None
            except ArithmeticError as exc:  # a run that went non-finite
                result, error = None, exc
            done(k, result, error)
    else:
        # imported here: dask.distributed (the cluster), loaded only when needed
        from cloth_mg_ros.apps.cluster import dask_client, run_tasks

        with dask_client(None, workers, log) as client:
            for (k, _), result, error in run_tasks(client, _IndexedStart(),
                                                   list(enumerate(specs)), desc="starts",
                                                   progress=progress):
                done(k, result, error)
    if errors:
        spec, error = errors[0]
        raise RuntimeError(f"bench dressing: {spec.name}, start {spec.start} failed: "
                           f"{error}") from error
    return [results[k] for k in range(len(specs))]


class _IndexedStart:
    """run_start of the spec of a (position, spec) pair (picklable, for the Dask tasks)."""

    def __call__(self, pair: tuple[int, object]) -> dict:
        return run_start(pair[1])


def bench_dressing(specs: list, starts: int = STARTS, seed: int = 0, nudge: float = NUDGE_M,
                   workers: int = 1, progress: bool = True, log=print,
                   checkpoint=None, previous: dict | None = None) -> list[dict]:
    """Every case (apps.dressing_scene.DressingSpec at its nominal start) from ``starts`` starts
    (`starts_of`): per case {"name", "spec" (with start 0's nudge and seed), "distribution"
    (bench.dressing_stats.distribution), "starts": [{"summary", "trace"}, one per start],
    "frames", "faces" (start 0's pictures)}. The runs go start by start (start 0 of every
    case, then start 1, ...), and checkpoint, if given, is called with the cases' results
    over the starts finished so far after each one: a run stopped early leaves every case
    with about as many starts. previous: {(case's index in specs, start): {"summary",
    "trace"}} of starts already run (`resumable`), not run again."""
    per_case = [starts_of(spec, starts, seed, nudge) for spec in specs]
    every = [per_case[c][k] for k in range(starts) for c in range(len(specs))]

    def collect(done: dict[int, dict]) -> list[dict]:
        out = []
        for c, spec in enumerate(specs):
            runs = [done[k * len(specs) + c] for k in range(starts)
                    if k * len(specs) + c in done]
            if not runs:
                continue
            first = runs[0] if runs[0]["summary"]["start"] == 0 else {}
            out.append({"name": spec.name, "spec": asdict(every[c]),
                        "distribution": distribution([r["summary"] for r in runs]),
                        "starts": [{"summary": r["summary"], "trace": r["trace"]}
                                   for r in runs],
                        "frames": first.get("frames"), "faces": first.get("faces")})
        return out

    prev = {k * len(specs) + c: r for (c, k), r in (previous or {}).items() if k < starts}
    todo = [i for i in range(len(every)) if i not in prev]

    def merged(done: dict[int, dict]) -> dict[int, dict]:
        return {**prev, **{todo[j]: r for j, r in done.items()}}

    if prev:
        log(f"  {len(prev)} starts from the earlier run, {len(todo)} to run")
    finished = None if checkpoint is None else (lambda done: checkpoint(collect(merged(done))))
    done = run_starts([every[i] for i in todo], workers, progress, log, finished) if todo else []
    return collect(merged(dict(enumerate(done))))


def resumable(path: str | Path, specs: list, seed: int, nudge: float) -> dict:
    """The starts of a saved run (``path``, bench dressing's JSON, a checkpoint too) that
    `bench_dressing` can reuse for ``specs``: {(case index, start): {"summary", "trace"}} of
    the cases whose spec, seed and nudge are the same (the same code runs them bit for bit
    the same on one machine). {} when there is no file."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        raise ClothInputError(f"--resume: {path} is not a bench dressing JSON ({exc})") from None
    stored = {json.dumps(case["spec"], sort_keys=True): case for case in data.get("cases", [])}
    out = {}
    for c, spec in enumerate(specs):
        case = stored.get(json.dumps(asdict(starts_of(spec, 1, seed, nudge)[0]),
                                     sort_keys=True))
        for start in case["starts"] if case else []:
            out[(c, start["summary"]["start"])] = start
    return out


HEADER = ["case", "starts"] + list(OUTCOMES) + [
    "dressed m", "peak F N", "10 N at m", "hand N", "forearm N", "upper arm N", "slip m",
    "edge mm", "s/run"]


def table(results: list[dict], markdown: bool = False) -> str:
    """The printed table (markdown: the docs' table): per case, each outcome's share [95 %
    interval] and the figures' median (10th-90th percentile) over the starts."""
    body = []
    for r in results:
        d = r["distribution"]
        f = d["figures"]
        reached = f["e_stop_travel_m"]
        body.append([r["name"], str(d["starts"])]
                    + [share_text(d["outcomes"][o]) for o in OUTCOMES]
                    + [spread_text(f["dressed_m"]), spread_text(f["peak_force_n"]),
                       (spread_text(reached) + (f" ({reached['n']} of {d['starts']})"
                                                if 0 < reached["n"] < d["starts"] else "")),
                       spread_text(f["hand_n"]), spread_text(f["forearm_n"]),
                       spread_text(f["upper_arm_n"]),
                       f"{f['slip_m']['max']:.0e}" if f["slip_m"]["max"] else "0",
                       f"{1e3 * f['edge_depth_m']['max']:.1f}",
                       f"{f['wall_s']['median']:.0f}"])
    if markdown:
        return "\n".join("| " + " | ".join(row) + " |"
                         for row in [HEADER, ["---"] * len(HEADER)] + body)
    return text_table(HEADER, body)


def chart(results: list[dict], png: str | Path) -> Path:
    """Gripper force and the largest arm-segment force against the gripper's travel, every
    start of every case (one colour a case), with the 10 N and 15 N lines."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for k, r in enumerate(results):
        for i, start in enumerate(r["starts"]):
            tr = start["trace"]
            style = {"color": f"C{k}", "lw": 0.8, "alpha": 0.6,
                     "label": f"{r['name']} ({len(r['starts'])} starts)" if i == 0 else None}
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


def strip(shown: list[dict], png: str | Path, per_run: int = 3) -> Path:
    """A picture strip: ``per_run`` frames of each case's start 0 (sleeve and arm), each view
    centred between the sleeve and the arm, one scale for all. shown: `bench_dressing`'s
    results."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    shots = [(r, frame) for r in shown
             for frame in [r["frames"][i] for i in
                           np.linspace(0, len(r["frames"]) - 1, per_run).round().astype(int)]]
    fig = plt.figure(figsize=(2.6 * len(shots), 3.0))
    for k, (r, (t, x, capsules)) in enumerate(shots):
        ax = fig.add_subplot(1, len(shots), k + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(x[r["faces"]], facecolors=(0.30, 0.55, 0.85, 0.55),
                                             edgecolors=(0.1, 0.2, 0.4, 0.15),
                                             linewidths=0.2))
        for p0, p1, radius in capsules:
            ax.plot(*np.stack([p0, p1]).T, color="0.3", lw=150 * radius,
                    solid_capstyle="round")
        centre = 0.5 * (x.mean(axis=0) + np.mean([c[0] for c in capsules], axis=0))
        span = 0.3
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
            setter(c - span, c + span)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=18, azim=-35)
        ax.set_axis_off()
        ax.set_title(f"{r['name']}, start 0\nt = {t:.1f} s", fontsize=7)
    fig.tight_layout()
    return save_chart(fig, png)


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench dressing` on the bench sub-parsers."""
    p = bsub.add_parser("dressing", help="a robot pulls a gown's sleeve onto an arm, each case "
                        "from N perturbed starts: outcome shares with 95 %% intervals, forces' "
                        "and dressed length's spread; JSON, chart, strip")
    p.add_argument("--quick", action="store_true",
                   help=f"0.15 m/s and the bad pull only, {QUICK_PARTICLES} particles")
    p.add_argument("--starts", type=int, default=STARTS,
                   help=f"starts per case (default {STARTS}): each sleeve particle's start "
                        f"moved {NUDGE_M:g} m in a random direction")
    p.add_argument("--seed", type=int, default=0,
                   help="the starts' random seed (default 0): the same seed, the same runs")
    p.add_argument("--nudge", type=float, default=NUDGE_M,
                   help=f"how far each particle's start is moved, m (default {NUDGE_M:g}; 0: "
                        "every start the nominal one)")
    p.add_argument("--workers", type=int, default=0,
                   help="processes running starts at once (default 0: one per core; 1: in "
                        "this process); never more than the cores")
    p.add_argument("--cases", default=None,
                   help="comma-separated cases to run (default all): still-0.10, still-0.15, "
                        "moving-0.10, moving-0.15, bad (--quick: the 0.15 m/s ones and bad)")
    p.add_argument("--from-json", default=None, metavar="PATH",
                   help="run nothing: print the table and draw the chart of a saved run (one "
                        "stopped early too: its JSON is written after every start)")
    p.add_argument("--resume", action="store_true",
                   help="reuse the starts already in --json (a run stopped early, or other "
                        "cases) whose case, seed and nudge match; run the rest")
    p.add_argument("--particles", type=int, default=None,
                   help=f"the sleeve's particles (default {PARTICLES}, quick "
                        f"{QUICK_PARTICLES})")
    p.add_argument("--travel", type=float, default=None,
                   help="how far the grippers pull, m (default the rig's 0.85; less: a "
                        "shorter, test-sized pull)")
    p.add_argument("--scheme", default="bdf2",
                   help="the implicit integrator (sim.schemes.SCHEMES; default bdf2)")
    p.add_argument("--spectral-radius", type=float, default=None,
                   help="genalpha's rho_inf, 0..1 (default the integrator's)")
    p.add_argument("--friction", type=float, default=None,
                   help="the cloth's Coulomb friction against the arm (default the scene's, "
                        "0.5)")
    p.add_argument("--compression", default="elastic",
                   help="the membrane under compression: elastic (the default, the paper's) "
                        "or buckle (wrinkles finer than the mesh)")
    p.add_argument("--bag", default="walk", help="the clip the moving arm follows")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.add_argument("--png", default=DEFAULT_PNG, help=f"chart (default {DEFAULT_PNG})")
    p.add_argument("--strip", default=DEFAULT_STRIP,
                   help=f"picture strip (default {DEFAULT_STRIP})")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(bench_func=run_cli)


def check_args(args: argparse.Namespace) -> int:
    """Refuse bad options before any work (ClothInputError naming the flag and the value);
    returns the worker count: --workers (0: one per core), at most the cores."""
    # imported here: the simulation's modules (see the note above); apps.cluster imports
    # dask only when a cluster starts
    from cloth_mg_ros.apps.cluster import local_workers
    from cloth_mg_ros.sim.model import COMPRESSION_MODELS
    from cloth_mg_ros.sim.schemes import SCHEMES

    if args.particles is not None and args.particles < 200:
        raise ClothInputError(f"--particles must be at least 200, got {args.particles}")
    if not 1 <= args.starts <= 10000:
        raise ClothInputError(f"--starts must be in [1, 10000], got {args.starts}")
    if args.seed < 0:
        raise ClothInputError(f"--seed must be a non-negative integer, got {args.seed}")
    if not 0.0 <= args.nudge <= 1e-3:
        raise ClothInputError(f"--nudge must be in [0, 1e-3] m, got {args.nudge}")
    if args.travel is not None and not 0.0 < args.travel <= 2.0:
        raise ClothInputError(f"--travel must be in (0, 2] m, got {args.travel}")
    if args.scheme not in SCHEMES:
        raise ClothInputError(f"--scheme must be one of {', '.join(SCHEMES)}, got "
                              f"{args.scheme!r}")
    if args.spectral_radius is not None and not 0.0 <= args.spectral_radius <= 1.0:
        raise ClothInputError(f"--spectral-radius must be in [0, 1], got "
                              f"{args.spectral_radius}")
    if args.friction is not None and not 0.0 <= args.friction <= 10.0:
        raise ClothInputError(f"--friction must be in [0, 10], got {args.friction}")
    if args.compression not in COMPRESSION_MODELS:
        raise ClothInputError(f"--compression must be one of {', '.join(COMPRESSION_MODELS)}, "
                              f"got {args.compression!r}")
    if args.workers < 0:
        raise ClothInputError(f"--workers must be 0 (one per core) or more, got "
                              f"{args.workers}")
    return min(local_workers(args.workers or None), local_workers())


def payload(results: list[dict], args: argparse.Namespace, workers: int, wall: float,
            complete: bool) -> dict:
    """The JSON: every case's distribution and every start's figures and trace; complete:
    False while starts are still running (a checkpoint)."""
    return {"cases": [{k: v for k, v in r.items() if k not in ("frames", "faces")}
                      for r in results],
            "starts": args.starts, "seed": args.seed, "start_nudge_m": args.nudge,
            "compression": args.compression,
            "workers": workers, "wall_s": wall, "quick": bool(args.quick),
            "complete": complete,
            "finished_starts": sum(len(r["starts"]) for r in results)}


def _write_atomic(path: str | Path, data: dict) -> None:
    """write_json through a temporary file, so that a run stopped mid-write leaves the last
    whole checkpoint."""
    path = Path(path)
    tmp = write_json(path.with_name(path.name + ".part"), data)
    tmp.replace(path)


NOTE = ("outcome: share of the starts [95 % Wilson score interval]; figures: median "
        "(10th-90th percentile) over the starts; 10 N at m: the travel where the robot's "
        "force passed 10 N, over the starts that passed it; dressed: the arm's length inside "
        "the sleeve's held opening at the end (fingertip to shoulder); forces: peaks of 0.1 s "
        "means; slip, edge: the largest over the starts")


def report(path: str | Path, png: str | Path) -> int:
    """`--from-json`: the table and the chart of a saved run."""
    try:
        data = json.loads(Path(path).read_text())
        results = data["cases"]
    except (OSError, ValueError, KeyError) as exc:
        raise ClothInputError(f"--from-json {path}: not a bench dressing JSON ({exc})") from None
    state = "complete" if data.get("complete", True) else "stopped early"
    print(f"bench dressing, from {path} ({state}): {data.get('finished_starts')} runs, seed "
          f"{data.get('seed')}, starts moved {data.get('start_nudge_m')} m")
    print(table(results))
    print(NOTE)
    print(table(results, markdown=True))
    print(f"wrote {chart(results, png)}")
    return 0


def run_cli(args: argparse.Namespace) -> int:
    if args.from_json:
        return report(args.from_json, args.png)
    workers = check_args(args)
    specs = pick_cases(cases(args.bag, args.quick, args.particles, args.travel, args.scheme,
                             args.friction, args.spectral_radius, args.compression),
                       args.cases)
    workers = min(workers, len(specs) * args.starts)
    t0 = time.perf_counter()
    print(f"bench dressing: {len(specs)} cases x {args.starts} starts (each sleeve particle's "
          f"start moved {args.nudge:g} m, seed {args.seed}), sleeve of about "
          f"{specs[0].particles} particles ({specs[0].material}), arm: still and {args.bag}, "
          f"{args.scheme}"
          + (f" rho_inf {specs[0].spectral_radius:g}" if args.scheme == "genalpha" else "")
          + f", friction {specs[0].friction:g}, compression {args.compression}, "
          f"{workers} worker(s)")

    def checkpoint(partial: list[dict]) -> None:
        _write_atomic(args.json, payload(partial, args, workers, time.perf_counter() - t0,
                                         complete=False))

    previous = resumable(args.json, specs, args.seed, args.nudge) if args.resume else None
    results = bench_dressing(specs, args.starts, args.seed, args.nudge, workers,
                             not args.no_progress, checkpoint=checkpoint, previous=previous)
    wall = time.perf_counter() - t0
    print(table(results))
    print(NOTE)
    ran = len(specs) * args.starts - len(previous or {})
    print(f"{ran} runs in {wall:.0f} s with {workers} worker(s)"
          + (f" ({len(previous)} reused from {args.json})" if previous else ""))
    _write_atomic(args.json, payload(results, args, workers, wall, complete=True))
    shown = [r for r in {id(r): r for r in (results[0], results[-1])}.values() if r["frames"]]
    pictures = strip(shown, args.strip) if shown else "no strip (start 0 was reused)"
    print(f"wrote {args.json}, {chart(results, args.png)}, {pictures}")
    return 0
