"""`cloth-mg bench solvers`: every linear solver on the same recorded step systems.

For each (particles, material) the drape scene is recorded once (`bench.step_systems`: the sheet
falls onto the sphere with an accurate reference solver; the ``systems`` consecutive step
systems after the first contact are kept). Every solver then solves every recorded system,
starting from the simulator's initial guess, with the same relative tolerance.

Per run (one solver, one size, one material) the figures are:

* ms_per_solve: median over the systems of the wall time of ``solver.solve`` (perf_counter;
  with ``repeat`` > 1 each system's median over its repeats; ``ms_all`` holds those per
  system, ``ms_fastest_all`` each system's fastest repeat). Everything a solver does
  per matrix (Jacobi inverses, coarsening, AMG set-up, factorisation) is inside ``solve``;
  the assembly of A and b is not. ``setup_ms``: the median of the solver's own
  ``last_setup_ms`` where it has one (already included in ms_per_solve).
* iterations: median CG iterations, or V-cycles for the stand-alone multigrid solvers.
* rel_residual: the worst over the systems of ||S (b - A x)|| / ||S b||, recomputed here from
  the returned x with Algorithm 1 (S zeroes the pinned rows); solver_rel_residual is the
  solver's own claim. converged: every solve said so and its recomputed residual is within
  CONVERGED_SLACK x tol.
* rel_error_ref: the worst ||x - x_ref|| / ||x_ref|| against the recording's reference solution
  (the direct solver when available, else block-symmetric CG at 1e-8); rel_error_direct: the
  same against this benchmark's 'direct' run, when 'direct' is among the solvers.
* skipped: the first solve took longer than ``max_seconds``; the run holds that one time.
  A solver whose module is missing (solvers/baselines.py for 'amg' and 'direct') is
  recorded as skipped with the import error as the reason.

Every solver is first run once on a small recording (~300 particles) so that numba's
compilation and cache loading stay out of the timings, and once, untimed, on the first system
of every size (``warmup_ms``), for the kernels only large meshes use (the split coarsening from
SPLIT_VERTICES particles on). Every solver runs on ``threads`` kernel
threads (default 1) and every loaded OpenBLAS on one thread (bench.blas_threads);
meta.threads and meta.blas_threads record the counts in effect.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np
import scipy

from cloth_mg_ros.bench.blas_threads import blas_thread_count, blas_threads, one_blas_thread
from cloth_mg_ros.bench.paper_tables import (
    PAPER_SIZE_MATCH,
    PAPER_TABLE3,
    PAPER_TABLE4,
)
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.bench.solvers_charts import plot_solvers
from cloth_mg_ros.bench.step_systems import Recording, filtered_rel_residual, record_systems
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.mesh.generators import MAX_PARTICLES, MIN_PARTICLES
from cloth_mg_ros.physics.materials import MATERIALS
from cloth_mg_ros.sim.sheets import SCENES
from cloth_mg_ros.solvers import SOLVERS, make_solver
from cloth_mg_ros.solvers.threads import resolve_threads, threads_for_block

MULTIGRID_SOLVERS = ("galerkin", "mg", "mpcg")
BASELINE_SOLVERS = ("pcg", "amg", "direct")
CONVERGED_SLACK = 1.5
WARMUP_PARTICLES = 300

# -- options ------------------------------------------------------------------------------
def parse_list(text: str | list, what: str, cast=str) -> list:
    """'a,b,c' -> [cast(a), cast(b), cast(c)]; ClothInputError naming ``what`` on failure."""
    items = text if isinstance(text, (list, tuple)) else str(text).split(",")
    out = []
    for item in items:
        item = item.strip() if isinstance(item, str) else item
        if item == "":
            continue
        try:
            out.append(cast(item))
        except (TypeError, ValueError):
            raise ClothInputError(f"--{what}: {item!r} is not a valid value") from None
    if not out:
        raise ClothInputError(f"--{what} must list at least one value")
    return out


def particle_problems(particles, flag: str = "--particles") -> list[str]:
    """What is wrong with each of a benchmark's particle counts (not integers in
    MIN_PARTICLES..MAX_PARTICLES), one line each, naming `flag`."""
    return [f"{flag} must be integers in {MIN_PARTICLES}..{MAX_PARTICLES}, got {p!r}"
            for p in particles if isinstance(p, bool) or not isinstance(p, (int, np.integer))
            or not MIN_PARTICLES <= p <= MAX_PARTICLES]


def validate_bench_args(scene: str, particles: list, materials: list, solvers: list, tol: float,
                        systems: int, levels: int | None, repeat: int,
                        max_seconds: float | None) -> None:
    """Check every option before any work; one ClothInputError lists all the problems."""
    problems = []
    if scene not in SCENES:
        problems.append(f"unknown scene {scene!r} (choose one of {', '.join(SCENES)})")
    problems += particle_problems(particles)
    bad = [m for m in materials if str(m).strip().lower() not in MATERIALS]
    if bad:
        problems.append(f"unknown material(s) {', '.join(map(repr, bad))} "
                        f"(choose from {', '.join(MATERIALS)})")
    bad = [s for s in solvers if s not in SOLVERS]
    if bad:
        problems.append(f"unknown solver(s) {', '.join(map(repr, bad))} "
                        f"(choose from {', '.join(SOLVERS)})")
    if len(set(solvers)) != len(solvers):
        problems.append(f"--solvers lists a solver twice: {','.join(solvers)}")
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and 0.0 < tol < 1.0):
        problems.append(f"--tol must be in (0, 1), got {tol!r}")
    if isinstance(systems, bool) or not isinstance(systems, int) or systems < 1:
        problems.append(f"--systems must be a positive integer, got {systems!r}")
    if levels is not None and (isinstance(levels, bool) or not isinstance(levels, int)
                               or not 1 <= levels <= 7):
        problems.append(f"--levels must be an integer between 1 and 7, got {levels!r}")
    if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
        problems.append(f"--repeat must be a positive integer, got {repeat!r}")
    if max_seconds is not None and not (isinstance(max_seconds, (int, float))
                                        and max_seconds > 0.0):
        problems.append(f"--max-seconds must be positive, got {max_seconds!r}")
    if problems:
        raise ClothInputError("bench solvers: " + "; ".join(problems))


# -- running ------------------------------------------------------------------------------
def _rel_error(x: np.ndarray, ref: np.ndarray) -> float:
    ref = np.asarray(ref).reshape(-1)
    return float(np.linalg.norm(np.asarray(x).reshape(-1) - ref) / (np.linalg.norm(ref) or 1.0))


def _make(name: str, rec: Recording, tol: float, levels: int | None, threads: int = 1):
    return make_solver(name, tol=tol, hierarchy=rec.scene.hierarchy,
                       bending=rec.scene.model.bending, levels=levels, threads=threads)


_WARM: set = set()
_WARM_REC: dict = {}


def warm_up(names: list[str], tol: float, threads: int = 1) -> dict[str, str]:
    """Solve a small system once with each solver (numba compilation and cache loading).
    Returns {name: error message} for solvers that could not be made (missing module)."""
    failed = {}
    todo = [n for n in names if n not in _WARM]
    if not todo:
        return failed
    if "rec" not in _WARM_REC:
        _WARM_REC["rec"] = record_systems("drape", WARMUP_PARTICLES, "cotton", 1, levels=None)
    rec = _WARM_REC["rec"]
    step = rec.systems[0]
    for name in todo:
        try:
            solver = _make(name, rec, tol, len(rec.scene.hierarchy.levels), threads)
        except (ImportError, ClothInputError) as exc:  # require_extra raises the latter
            failed[name] = f"{type(exc).__name__}: {exc}"
            continue
        solver.solve(step.system, step.rhs, step.x0.copy(), step.fixed)
        _WARM.add(name)
    return failed


def solve_recording(rec: Recording, name: str, tol: float, levels: int | None = None,
                    repeat: int = 1, max_seconds: float | None = None,
                    direct: list[np.ndarray] | None = None,
                    threads: int = 1) -> tuple[dict, list[np.ndarray]]:
    """Run solver ``name`` on every system of ``rec``. Returns (run dict, solutions).

    threads: mpcg's parts per level (make_solver); the kernels' thread count is the calling
    thread's (`bench_solvers` sets it)."""
    run: dict = {"particles": rec.particles, "material": rec.material, "solver": name,
                 "tol": tol, "systems": len(rec.systems), "skipped": False}
    try:
        solver = _make(name, rec, tol, levels, threads)
    except (ImportError, ClothInputError) as exc:  # require_extra raises the latter
        run.update(skipped=True, skip_reason=f"unavailable: {type(exc).__name__}: {exc}",
                   ms_per_solve=None, iterations=None, rel_residual=None, converged=False)
        return run, []
    # One untimed solve at this size first: kernels used only on large meshes (the split
    # coarsening from SPLIT_VERTICES on) compile or load from the cache here, not in the first
    # timed solve, which also decides --max-seconds.
    first = rec.systems[0]
    t0 = time.perf_counter()
    solver.solve(first.system, first.rhs, first.x0.copy(), first.fixed)
    run["warmup_ms"] = 1e3 * (time.perf_counter() - t0)
    times, fastest, its, rels, claimed, flags, setups, sols = [], [], [], [], [], [], [], []
    for k, step in enumerate(rec.systems):
        res, reps = _time_system(solver, step, repeat, max_seconds if k == 0 else None)
        best = min(reps)
        x = np.asarray(res.x, dtype=np.float64).reshape(-1, 3)
        times.append(1e3 * float(np.median(reps)))
        fastest.append(1e3 * best)
        its.append(int(res.iterations))
        rels.append(filtered_rel_residual(step, x))
        claimed.append(float(res.rel_residual))
        flags.append(bool(res.converged))
        if hasattr(solver, "last_setup_ms"):
            setups.append(float(solver.last_setup_ms))
        sols.append(x)
        if max_seconds is not None and k == 0 and best > max_seconds:
            run.update(skipped=True, skip_reason=f"first solve took {best:.1f} s > "
                       f"--max-seconds {max_seconds:g}")
            break
    worst = max(rels)
    run.update(
        ms_per_solve=float(np.median(times)),
        ms_min=float(np.min(times)), ms_max=float(np.max(times)),
        ms_all=[round(t, 3) for t in times], ms_fastest_all=[round(t, 3) for t in fastest],
        iterations=float(np.median(its)), iterations_all=its,
        rel_residual=worst, solver_rel_residual=max(claimed),
        converged=bool(all(flags) and worst <= CONVERGED_SLACK * tol),
        solver_converged=bool(all(flags)),
        rel_error_ref=max(_rel_error(x, r)
                          for x, r in zip(sols, rec.reference[:len(sols)], strict=True)),
        contacts=rec.contacts[:len(sols)],
    )
    if setups:
        run["setup_ms"] = float(np.median(setups))
    if direct:
        run["rel_error_direct"] = max(_rel_error(x, r)
                                      for x, r in zip(sols, direct[:len(sols)], strict=True))
    return run, sols


def _time_system(solver, step, repeat: int, max_seconds: float | None) -> tuple:
    """(the last result, the wall times in s of `repeat` solves of one recorded system from its
    initial guess); stops after a solve over max_seconds (None: never)."""
    reps = []
    for _ in range(repeat):
        x0 = step.x0.copy()
        t0 = time.perf_counter()
        res = solver.solve(step.system, step.rhs, x0, step.fixed)
        reps.append(time.perf_counter() - t0)
        if max_seconds is not None and reps[-1] > max_seconds:
            break
    return res, reps


def machine_meta() -> str:
    """The CPU's model name (/proc/cpuinfo's first "model name"), else platform's processor
    or machine name: the JSON's meta.machine."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def solvers_meta(scene: str, tol: float | str, systems: int | None, levels: int | None,
                 repeat: int, max_seconds: float | None, dt: float | None,
                 scheme: str) -> dict:
    """The JSON's "meta" of a benchmark run: the machine (CPU model, cpus, platform), the
    versions of python, numpy, scipy and numba, the UTC date, the thread variables, the load
    averages at the start (1, 5, 15 min; None where unknown) and CONVERGED_SLACK, with the
    run's settings as given: scene name, tol (relative residual, or 'auto'), systems per
    size, levels (None: automatic), repeat, max_seconds (s, None: no limit), dt (s) and the
    integration scheme (bench.walking passes None for what it does not use)."""
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {
        "machine": machine_meta(), "cpus": os.cpu_count(), "platform": platform.platform(),
        "python": sys.version.split()[0], "numpy": np.__version__, "scipy": scipy.__version__,
        "numba": numba.__version__,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "scene": scene, "tol": tol, "systems": systems, "levels": levels, "repeat": repeat,
        "max_seconds": max_seconds, "dt": dt, "scheme": scheme,
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS", "unset"),
        "loadavg_start": load, "converged_slack": CONVERGED_SLACK,
    }


def bench_solvers(particles: list[int], materials: list[str], solvers: list[str],
                  tol: float = 1e-4, systems: int = 5, levels: int | None = None,
                  repeat: int = 1, max_seconds: float | None = None, scene: str = "drape",
                  dt: float = 1.0 / 60.0, scheme: str = "bdf2", log=None,
                  delay: int = 20, threads: int = 1) -> dict:
    """Run the benchmark; returns {"runs": [...], "recordings": [...], "meta": {...}}.

    log: a callable taking one line of progress (default: print to stderr); threads: the
    kernels' threads for every solver alike (0: every core; default 1). The faithful
    coarsening splits its work over threads from SPLIT_VERTICES particles on while the CG
    baselines run on one, so a thread count left to numba's default would compare several
    cores against one. meta["threads"] is the count used."""
    materials = [str(m).strip().lower() for m in materials]
    if isinstance(delay, bool) or not isinstance(delay, int) or delay < 0:
        raise ClothInputError(f"--delay must be a non-negative integer, got {delay!r}")
    count = resolve_threads(threads)
    validate_bench_args(scene, particles, materials, solvers, tol, systems, levels, repeat,
                        max_seconds)
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    meta = solvers_meta(scene, tol, systems, levels, repeat, max_seconds, dt, scheme)
    meta["delay_steps_after_contact"] = delay
    # the direct and AMG baselines' BLAS on one thread too, as ours
    with threads_for_block(count) as meta["threads"], one_blas_thread():
        result = _bench_all(particles, materials, solvers, meta, log, count)
        meta.update(blas_threads=blas_thread_count(), blas_libraries=blas_threads())
    return result


def _bench_all(particles: list[int], materials: list[str], solvers: list[str], meta: dict,
               log, threads: int) -> dict:
    """`bench_solvers`' runs: every size and material recorded, every solver on it."""
    tol, systems, levels, repeat = meta["tol"], meta["systems"], meta["levels"], meta["repeat"]
    scene, dt, scheme = meta["scene"], meta["dt"], meta["scheme"]
    max_seconds, delay = meta["max_seconds"], meta["delay_steps_after_contact"]
    t_start = time.perf_counter()
    unavailable = warm_up(solvers, tol, threads)
    for name, why in unavailable.items():
        log(f"solver {name!r} unavailable ({why}); recorded as skipped")
    # 'direct' first, so the others can be compared with its solutions.
    order = sorted(solvers, key=lambda s: s != "direct")
    runs, recordings = [], []
    for n in particles:
        for mat in materials:
            t0 = time.perf_counter()
            rec = record_systems(scene, n, mat, systems, dt, scheme, levels, delay=delay)
            info = {"particles_requested": n, "particles": rec.particles, "material": mat,
                    "levels": len(rec.scene.hierarchy.levels), "start_step": rec.start_step,
                    "systems": len(rec.systems), "contacts": rec.contacts,
                    "reference_solver": rec.reference_solver,
                    "reference_rel_residual": rec.reference_rel_residual,
                    "record_s": rec.record_s,
                    "mbytes": rec.nbytes() / 1e6, "truncated": rec.truncated,
                    "solver_s": {}}
            log(f"{rec.particles} particles, {mat}: recorded {len(rec.systems)} systems from "
                f"step {rec.start_step} (contacts {rec.contacts}) in {rec.record_s:.1f} s")
            direct, by_name = None, {}
            for name in order:
                ts = time.perf_counter()
                run, sols = solve_recording(rec, name, tol, levels, repeat, max_seconds, direct,
                                            threads)
                info["solver_s"][name] = time.perf_counter() - ts
                run["particles_requested"] = n
                if name == "direct" and not run["skipped"]:
                    direct = sols
                by_name[name] = run
                log(_progress_line(run))
            runs.extend(by_name[name] for name in solvers)
            info["bench_s"] = time.perf_counter() - t0
            recordings.append(info)
            del rec
    meta["wall_s"] = time.perf_counter() - t_start
    meta["unavailable"] = unavailable
    return {"runs": runs, "recordings": recordings, "meta": meta}


def _progress_line(run: dict) -> str:
    if run["ms_per_solve"] is None:
        return f"  {run['solver']:9s} skipped: unavailable"
    flag = "" if run["converged"] else "  NOT CONVERGED"
    if run["skipped"]:
        flag += f"  skipped ({run['skip_reason']})"
    return (f"  {run['solver']:9s} {run['ms_per_solve']:10.1f} ms/solve  "
            f"{run['iterations']:6.0f} it  res {run['rel_residual']:.1e}  "
            f"err {run['rel_error_ref']:.1e}{flag}")


# -- reporting ----------------------------------------------------------------------------
def paper_match(n: int, paper_sizes: list[int] | None = None) -> int | None:
    """Index into ``paper_sizes`` (default: PAPER_TABLE3's) of the paper size within
    PAPER_SIZE_MATCH of n, or None."""
    sizes = PAPER_TABLE3["particles"] if paper_sizes is None else paper_sizes
    for k, p in enumerate(sizes):
        if abs(n / p - 1.0) <= PAPER_SIZE_MATCH:
            return k
    return None


def _cell(run: dict | None) -> str:
    if run is None:
        return "-"
    if run["ms_per_solve"] is None:
        return "n/a"
    txt = f"{run['ms_per_solve']:.1f} ({run['iterations']:.0f})"
    if run["skipped"]:
        return f">{run['ms_per_solve']:.0f} skip"
    return txt if run["converged"] else txt + " NC"


def speedups(result: dict) -> list[dict]:
    """Per (particles, material): the fastest converged multigrid run and its speed-up over
    pcg, amg and direct (converged, not skipped runs only)."""
    out = []
    keys = list(dict.fromkeys((r["particles"], r["material"]) for r in result["runs"]))
    for n, mat in keys:
        runs = {r["solver"]: r for r in result["runs"]
                if r["particles"] == n and r["material"] == mat}
        ok = {k: r for k, r in runs.items() if r["ms_per_solve"] is not None
              and not r["skipped"] and r["converged"]}
        mg = [ok[k] for k in MULTIGRID_SOLVERS if k in ok]
        if not mg:
            continue
        best = min(mg, key=lambda r: r["ms_per_solve"])
        entry = {"particles": n, "material": mat, "fastest_multigrid": best["solver"],
                 "ms_per_solve": best["ms_per_solve"]}
        for base in BASELINE_SOLVERS:
            if base in ok:
                entry[f"speedup_vs_{base}"] = ok[base]["ms_per_solve"] / best["ms_per_solve"]
        out.append(entry)
    return out


def _report_header(meta: dict) -> str:
    """The report's first line: the run's settings, the thread counts, the machine."""
    return (f"bench solvers: {meta['scene']}, tol {meta['tol']:g}, {meta['systems']} "
            f"systems after first contact, levels {meta['levels']}, kernel threads "
            f"{meta.get('threads', '?')}, BLAS threads {meta.get('blas_threads', '?')}, "
            f"{meta['machine']}")


def format_report(result: dict) -> str:
    """The tables printed by the CLI: ms per solve (median iterations) per solver and size,
    the paper's figures beside ours where the sizes match, and the multigrid speed-ups."""
    runs = result["runs"]
    meta = result["meta"]
    lines = []
    solvers = list(dict.fromkeys(r["solver"] for r in runs))
    materials = list(dict.fromkeys(r["material"] for r in runs))
    sizes = sorted({r["particles"] for r in runs})
    lines.append(_report_header(meta))
    lines.append("cells: median ms per solve (median iterations or V-cycles); NC = not "
                 "converged, skip = first solve over --max-seconds")
    find = {(r["particles"], r["material"], r["solver"]): r for r in runs}
    for mat in materials:
        if len(sizes) == 1 and len(materials) > 1:
            break  # the per-material table below says it all
        header = ["solver"] + [str(n) for n in sizes]
        rows = [[s] + [_cell(find.get((n, mat, s))) for n in sizes] for s in solvers]
        matched = [paper_match(n) for n in sizes]
        # Table 3 is the paper's default fabric; show it beside cotton (or a lone material).
        if any(m is not None for m in matched) and (mat == "cotton" or len(materials) == 1):
            for key, label in (("pcg", "paper PCG"), ("mg", "paper MG")):
                rows.append([f"{label} (falling, 2008)"] + [
                    "-" if m is None else
                    f"{PAPER_TABLE3[key][m]:.1f} @{PAPER_TABLE3['particles'][m]}"
                    for m in matched])
        lines.append("")
        lines.append(f"material {mat}: ms per solve against particles")
        lines.append(text_table(header, rows))
    if len(materials) > 1:
        for n in sizes:
            header = ["solver"] + materials
            rows = [[s] + [_cell(find.get((n, m, s))) for m in materials] for s in solvers]
            if abs(n / PAPER_TABLE4["particles"] - 1.0) <= PAPER_SIZE_MATCH:
                for key, label in (("pcg", "paper PCG"), ("mg", "paper MG")):
                    rows.append([f"{label} (Table 4)"] + [
                        f"{PAPER_TABLE4[key][m]:.1f}" if m in PAPER_TABLE4[key] else "-"
                        for m in materials])
            lines.append("")
            lines.append(f"{n} particles: ms per solve against material")
            lines.append(text_table(header, rows))
    sp = speedups(result)
    if sp:
        lines.append("")
        lines.append("speed-up of the fastest converged multigrid path:")
        for e in sp:
            parts = [f"{e[f'speedup_vs_{b}']:.1f}x over {b}" for b in BASELINE_SOLVERS
                     if f"speedup_vs_{b}" in e]
            lines.append(f"  {e['particles']:6d} {e['material']:8s} {e['fastest_multigrid']:8s} "
                         f"{e['ms_per_solve']:8.1f} ms: " + (", ".join(parts) or "no baseline"))
    bad = [r for r in runs if r["ms_per_solve"] is not None and not r["converged"]]
    for r in bad:
        lines.append(f"note: {r['solver']} at {r['particles']} {r['material']} did not converge "
                     f"(worst recomputed residual {r['rel_residual']:.2e})")
    for rec in result.get("recordings", []):
        lines.append(f"time: {rec['particles']} particles {rec['material']}: recording "
                     f"{rec['record_s']:.1f} s, whole size {rec['bench_s']:.1f} s")
    return "\n".join(lines)


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench solvers` on the bench sub-parsers."""
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
    s.add_argument("--repeat", type=int, default=1,
                   help="timed solves per system (their median kept)")
    s.add_argument("--max-seconds", type=float, default=None,
                   help="skip a solver whose first solve takes longer than this")
    s.add_argument("--threads", type=int, default=1,
                   help="kernel threads of every solver alike (default 1; 0: every core)")
    s.add_argument("--json", default="out/bench_solvers.json", help="JSON output file")
    s.add_argument("--png", default="out/bench_solvers.png", help="chart output file")
    s.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the benchmark, print its report, write the JSON and the charts."""
    particles = parse_list(args.particles, "particles", int)
    materials = [m.lower() for m in parse_list(args.materials, "materials")]
    solvers = parse_list(args.solvers, "solvers")
    validate_bench_args(args.scene, particles, materials, solvers, args.tol, args.systems,
                        args.levels, args.repeat, args.max_seconds)
    result = bench_solvers(particles, materials, solvers, args.tol, args.systems, args.levels,
                           args.repeat, args.max_seconds, args.scene, delay=args.delay,
                           threads=args.threads)
    print(format_report(result))
    write_json(args.json, result)
    pngs = plot_solvers(result, args.png)
    print(f"wrote {args.json} and {', '.join(map(str, pngs))}")
    return 0
