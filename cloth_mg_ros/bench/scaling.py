"""`cloth-mg bench scaling`: ms per tick and peak memory against particle count.

The scene is the walking benchmark's (`bench walking`: the dress of config/walking.yaml on
a bag, replayed from the end of its still lead-in) from 1.2K to 80K particles. Every (size,
solver) run is a Dask task (cloth_mg_ros.apps.cluster: an embedded one-worker LocalCluster, or a
running cluster with ``--scheduler``) that starts a fresh Python process for the run, so that
its memory is its own; the runs go one at a time, so that each has the machine to itself:

1. it warms the solver up on a ~500-particle garment (numba compilation and cache loading
   stay out of the figures), then reads its resident set size (``baseline_rss_mb``);
2. it dresses the garment at the size and replays ``steps`` pose messages;
3. it reads its peak resident set size while stepping (``peak_rss_mb``, the kernel's
   high-water mark, reset after the dressing), and ``memory_mb`` = peak - baseline is what
   the scene and the solver hold at that size (mesh, hierarchy, model, solver set-up, the
   largest step's temporaries). The dressing's own transient peak (building the garment
   around the body) is reported apart, as ``dress_peak_mb`` over the baseline.

ms_per_tick / ms_per_solve / iterations are medians over the replayed messages, as in
`bench walking`. A run whose first tick takes longer than ``max_seconds`` stops after it and
the solver is skipped at the larger sizes. The log-log slope of each solver (least squares of
log ms per tick and of log memory against log particles over its completed sizes) is the
exponent p of time ~ n^p. Every run's OpenBLAS libraries use one thread (bench.blas_threads;
each run's ``blas_threads`` and meta.blas_threads record the count in effect).
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from cloth_mg_ros.apps.cluster import dask_client
from cloth_mg_ros.bench.blas_threads import blas_thread_count, one_blas_thread
from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.bench.solvers import parse_list
from cloth_mg_ros.bench.walking import (
    DEFAULT_START,
    dress_garment,
    garment_options,
    replay,
    skip_lead_in,
    validate_walking_args,
    walking_meta,
    warm_up,
    with_solver,
)
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.environment import ONE_BLAS_THREAD
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.solvers.threads import resolve_threads

DEFAULT_SIZES = (1200, 2400, 4500, 10000, 20000, 40000, 80000)
DEFAULT_SOLVERS = ("pcg", "mg", "mpcg", "amg", "direct")
DEFAULT_STEPS = 10
DEFAULT_MAX_SECONDS = 30.0


def _rss_mb(field: str) -> float:
    """VmRSS (now) or VmHWM (peak) of this process in MB, from /proc; getrusage's peak
    where /proc is missing."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_peak() -> None:
    """Hand freed heap back to the system and start the kernel's high-water mark (VmHWM)
    afresh, so that what came before is not counted (Linux >= 4.0; elsewhere the peak
    includes it). Without the trim, memory freed but kept by malloc would make RSS readings
    before and after disagree by more than a small scene holds."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass


def measure_run(bag: str, garment: str, particles: int, solver: str, material: str,
                steps: int, tol: float, max_seconds: float | None, threads: int = 0) -> dict:
    """One (size, solver) run in this process; see the module docstring. Meant to run in a
    fresh process (`bench_scaling` starts one per run). threads: the solver's and the
    kernels' threads (0: every core)."""
    params = load_scene("walking")
    frames = read_pose_frames(resolve_bag(bag), params.topic)
    mat = get_material(material)
    failed = warm_up([solver], frames, params, garment, mat, tol)
    if failed:
        return {"skipped": True, "skip_reason": f"unavailable: {failed[solver]}"}
    _reset_peak()
    baseline = _rss_mb("VmRSS")
    t0 = time.perf_counter()
    frames = skip_lead_in(frames, DEFAULT_START)
    base, first = dress_garment(Avatar.load(), frames, mat,
                         garment_options(params, garment, particles, solver, tol, threads))
    dress_s = time.perf_counter() - t0
    dress_peak = _rss_mb("VmHWM")  # the dressing's own peak, before the copy below adds one
    garment_sim = with_solver(base, solver, tol)
    del base
    _reset_peak()  # the dressing's transient peak is not the stepping's
    run = replay(garment_sim, frames[first + 1: first + 1 + steps], max_seconds, per_tick=False)
    peak = _rss_mb("VmHWM")
    run.update(particles=int(garment_sim.sim.model.n),
               levels=len(garment_sim.garment.hierarchy.levels),
               dress_s=dress_s, baseline_rss_mb=baseline, peak_rss_mb=peak,
               memory_mb=peak - baseline, dress_peak_mb=dress_peak - baseline,
               pid=os.getpid())
    return run


def measure_in_fresh_process(cell: dict) -> dict:
    """measure_run(**cell) in a new Python process (`python -m cloth_mg_ros.bench.scaling
    --cell JSON`), so that its peak memory is the run's own; returns its figures. Raises
    RuntimeError with the end of the process's output when it fails."""
    # one BLAS thread from the start: the process's libraries read it when they load
    env = dict(os.environ, **ONE_BLAS_THREAD)
    proc = subprocess.run([sys.executable, "-m", "cloth_mg_ros.bench.scaling", "--cell",
                           json.dumps(cell)], capture_output=True, text=True, check=False,
                          env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"scaling run {cell['particles']} {cell['solver']} failed "
                           f"(exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def loglog_slope(n: list[float], y: list[float]) -> float | None:
    """Least-squares slope of log y against log n (None with fewer than two points)."""
    pts = [(a, b) for a, b in zip(n, y, strict=True) if b is not None and b > 0.0]
    if len(pts) < 2:
        return None
    x = np.log([a for a, _ in pts])
    v = np.log([b for _, b in pts])
    return float(np.polyfit(x, v, 1)[0])


def validate_scaling_args(bag: str, garment: str, sizes: list[int], solvers: list[str],
                          material: str, steps: int, tol: float, max_seconds: float | None,
                          threads: int = 0) -> None:
    """Every option checked before any work (the walking benchmark's checks, a numeric tol:
    each run's make_solver takes no 'auto'; and the thread count)."""
    validate_walking_args(bag, garment, sizes, solvers, material, steps, tol, max_seconds,
                          command="bench scaling")
    if isinstance(tol, str):
        raise ClothInputError(f"bench scaling: --tol must be a number in (0, 1), got {tol!r} "
                              f"(tolerance auto is bench walking's)")
    resolve_threads(threads)


def bench_scaling(bag: str = "walk", garment: str = "dress", sizes: list[int] | None = None,
                  solvers: list[str] | None = None, material: str = "cotton",
                  steps: int = DEFAULT_STEPS, tol: float = 1e-4,
                  max_seconds: float | None = DEFAULT_MAX_SECONDS, log=None,
                  threads: int = 0, scheduler: str | None = None, client=None) -> dict:
    """Run every (size, solver) in its own process with `threads` threads (0: every core), as
    Dask tasks on `client`, or on the running `scheduler`, or on an embedded one-worker
    cluster; returns {"runs", "slopes", "meta"}."""
    sizes = list(DEFAULT_SIZES if sizes is None else sizes)
    solvers = list(DEFAULT_SOLVERS if solvers is None else solvers)
    material = str(material).strip().lower()
    validate_scaling_args(bag, garment, sizes, solvers, material, steps, tol, max_seconds,
                          threads)
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    if client is None:
        with dask_client(scheduler, 1, log) as c:
            return bench_scaling(bag, garment, sizes, solvers, material, steps, tol,
                                 max_seconds, log, threads, scheduler, client=c)
    t_start = time.perf_counter()
    cell = {"bag": bag, "garment": garment, "material": material, "steps": steps, "tol": tol,
            "max_seconds": max_seconds, "threads": threads}
    runs = scaling_runs(client, cell, sizes, solvers, log)
    slopes = _slopes(runs, solvers)
    params = load_scene("walking")
    meta = walking_meta(resolve_bag(bag), garment, material, tol, steps, max_seconds, params)
    meta.update(wall_s=time.perf_counter() - t_start, sizes=sizes, solvers=solvers,
                threads=resolve_threads(threads),
                blas_threads=max((r["blas_threads"] for r in runs if "blas_threads" in r),
                                 default=None))
    return {"runs": runs, "slopes": slopes, "meta": meta}


def scaling_runs(client, cell: dict, sizes: list[int], solvers: list[str],
                  log) -> list[dict]:
    """Every (size, solver) in a fresh process, one at a time (the next size depends on this
    one's time), `cell` holding the options they share; a solver whose first tick ran over
    max_seconds is skipped at the larger sizes."""
    runs, dropped = [], {}  # solver -> why it is skipped at the larger sizes
    for n in sizes:
        for solver in solvers:
            rec = {"particles_requested": n, "solver": solver, "tol": cell["tol"]}
            if solver in dropped:
                rec.update(particles=None, skipped=True, ms_per_tick=None, ms_per_solve=None,
                           iterations=None, converged=False, peak_rss_mb=None,
                           memory_mb=None, skip_reason=dropped[solver])
            else:
                ts = time.perf_counter()
                # retries=0: a run that kills its worker (out of memory) is a failure to
                # report.
                rec.update(client.submit(measure_in_fresh_process, _cell(cell, n, solver),
                                         pure=False, retries=0).result())
                rec["wall_s"] = time.perf_counter() - ts
                if rec.get("skipped"):
                    dropped[solver] = _skip_reason(rec, n)
            runs.append(rec)
            log(_progress(rec))
    return runs


def _skip_reason(rec: dict, n: int) -> str:
    """Why a solver skipped at `rec`'s size is skipped at the larger ones: unavailable (its
    own reason), or its first tick over --max-seconds at this size."""
    if str(rec.get("skip_reason", "")).startswith("unavailable"):
        return rec["skip_reason"]
    return f"first tick over --max-seconds at {rec.get('particles') or n} particles"


def _cell(cell: dict, n: int, solver: str) -> dict:
    """The options of one run, as `measure_in_fresh_process` takes them."""
    return {"bag": cell["bag"], "garment": cell["garment"], "particles": n, "solver": solver,
            "material": cell["material"], "steps": cell["steps"], "tol": cell["tol"],
            "max_seconds": cell["max_seconds"], "threads": cell["threads"]}


def _slopes(runs: list[dict], solvers: list[str]) -> dict:
    """Per solver: the log-log slopes of time and memory against particles over its runs
    that ran, and their sizes."""
    slopes = {}
    for solver in solvers:
        done = [r for r in runs if r["solver"] == solver and not r.get("skipped")
                and r.get("ms_per_tick") is not None]
        ns = [r["particles"] for r in done]
        slopes[solver] = {"time": loglog_slope(ns, [r["ms_per_tick"] for r in done]),
                          "memory": loglog_slope(ns, [r["memory_mb"] for r in done]),
                          "sizes": ns}
    return slopes


def _progress(r: dict) -> str:
    if r.get("ms_per_tick") is None:
        return f"  {r['particles_requested']:6d} {r['solver']:7s} skipped: {r['skip_reason']}"
    flag = "" if r["converged"] else "  NOT CONVERGED"
    if r.get("skipped"):
        flag += f"  ({r['skip_reason']})"
    return (f"  {r['particles']:6d} {r['solver']:7s} {r['ms_per_tick']:10.1f} ms/tick "
            f"{r['ms_per_solve']:9.1f} ms/solve {r['iterations']:7.1f} it  peak "
            f"{r['peak_rss_mb']:7.0f} MB (+{r['memory_mb']:.0f}){flag}")


def format_scaling_report(result: dict) -> str:
    """Tables of ms per tick and memory against particles, and the slopes."""
    runs, meta = result["runs"], result["meta"]
    solvers = list(dict.fromkeys(r["solver"] for r in runs))
    sizes = list(dict.fromkeys(r["particles_requested"] for r in runs))
    find = {(r["particles_requested"], r["solver"]): r for r in runs}
    actual = {r["particles_requested"]: r["particles"] for r in runs if r.get("particles")}

    def cell(r, key, fmt):
        if r is None or r.get(key) is None:
            return "skip"
        txt = fmt.format(r[key])
        if r.get("skipped"):
            return ">" + txt + " skip"
        return txt if r["converged"] or key != "ms_per_tick" else txt + " NC"

    lines = [(f"bench scaling: {meta['garment']} on {Path(meta['bag']).name}, {meta['material']}, "
             f"tol {meta['tol']:g}, {meta['steps']} pose messages per run, BLAS threads "
             f"{meta.get('blas_threads', '?')}, {meta['machine']}")]
    header = ["solver"] + [str(actual.get(n, n)) for n in sizes] + ["slope"]
    for key, what, fmt in (("ms_per_tick", "ms per tick (median)", "{:.1f}"),
                           ("memory_mb", ("memory over the process's baseline (MB, peak RSS - "
                            "RSS before the scene)"), "{:.0f}")):
        rows = []
        for s in solvers:
            slope = result["slopes"][s]["time" if key == "ms_per_tick" else "memory"]
            rows.append([s] + [cell(find.get((n, s)), key, fmt) for n in sizes]
                        + ["-" if slope is None else f"n^{slope:.2f}"])
        lines += ["", what, text_table(header, rows)]
    return "\n".join(lines)


def plot_scaling(result: dict, png: str | Path) -> Path:
    """Log-log panels of ms per tick and memory against particles, one line per solver with
    its slope in the legend, n^1 dotted for reference."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    meta = result["meta"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    solvers = list(dict.fromkeys(r["solver"] for r in result["runs"]))
    for ax, key, label, skey in ((axes[0], "ms_per_tick", "ms per tick (median)", "time"),
                                 (axes[1], "memory_mb", "memory (MB, peak RSS over baseline)",
                                  "memory")):
        for i, s in enumerate(solvers):
            rs = [r for r in result["runs"] if r["solver"] == s and r.get(key) is not None
                  and r[key] > 0]
            if not rs:
                continue
            slope = result["slopes"][s][skey]
            ax.plot([r["particles"] for r in rs], [r[key] for r in rs], marker="o",
                    color=plt.cm.tab10(i % 10),
                    label=s + ("" if slope is None else f"  (n^{slope:.2f})"))
            for r in rs:
                if r.get("skipped"):
                    ax.plot(r["particles"], r[key], marker="s", ms=11, mfc="none", mec="grey",
                            linestyle="none")
        done = [r for r in result["runs"] if r.get(key) and not r.get("skipped")]
        if done:
            n0 = min(r["particles"] for r in done)
            y0 = min(r[key] for r in done if r["particles"] == n0)
            ns = np.array([n0, max(r["particles"] for r in done)], dtype=float)
            ax.plot(ns, y0 * ns / n0, linestyle=":", color="black", alpha=0.5, label="n^1")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("particles")
        ax.set_ylabel(label)
        ax.set_title(f"scaling: walking {meta['garment']}, tol {meta['tol']:g} (squares: first "
                     f"tick over {meta.get('max_seconds')} s, then skipped)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return save_chart(fig, png)


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench scaling` on the bench sub-parsers (``bsub``: the `cloth-mg
    bench` parser's add_subparsers()); its handler is run_cli."""
    p = bsub.add_parser("scaling", help="ms per tick and peak memory from 1.2K to 80K "
                        "particles, one process per run; log-log slopes")
    p.add_argument("--bag", default="walk")
    p.add_argument("--garment", default="dress")
    p.add_argument("--particles", default=",".join(map(str, DEFAULT_SIZES)),
                   help="comma-separated particle counts (default 1.2K..80K)")
    p.add_argument("--solvers", default=",".join(DEFAULT_SOLVERS),
                   help=f"comma-separated (default {','.join(DEFAULT_SOLVERS)})")
    p.add_argument("--material", default="cotton")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                   help=f"pose messages per run (default {DEFAULT_STEPS})")
    p.add_argument("--tol", type=float, default=1e-4)
    p.add_argument("--max-seconds", type=float, default=DEFAULT_MAX_SECONDS,
                   help="skip a solver at larger sizes once its first tick takes longer")
    p.add_argument("--threads", type=int, default=0,
                   help="solver and kernel threads (default 0: every core)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on this running Dask scheduler (default: an embedded one-worker "
                        "LocalCluster)")
    p.add_argument("--json", default="out/bench_scaling.json")
    p.add_argument("--png", default="out/bench_scaling.png")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run `cloth-mg bench scaling` with add_cli's ``args``: check them (ClothInputError
    before any work), run every size and solver (bench_scaling), print the report, write
    the JSON (--json) and the log-log chart (--png). Returns the exit status, 0."""
    sizes = parse_list(args.particles, "particles", int)
    solvers = parse_list(args.solvers, "solvers")
    material = args.material.strip().lower()
    validate_scaling_args(args.bag, args.garment, sizes, solvers, material, args.steps,
                          args.tol, args.max_seconds, args.threads)
    result = bench_scaling(args.bag, args.garment, sizes, solvers, material, args.steps,
                           args.tol, args.max_seconds, threads=args.threads,
                           scheduler=args.scheduler)
    print(format_scaling_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json} and {plot_scaling(result, args.png)}")
    return 0


if __name__ == "__main__" and sys.argv[1:2] == ["--cell"]:
    import json

    with one_blas_thread():  # also where the environment did not say so
        _figures = measure_run(**json.loads(sys.argv[2]))
        _figures["blas_threads"] = blas_thread_count()
    print(json.dumps(_figures))
