"""`cloth-mg bench walking`: every solver on the walking scene (the paper's Table 3, walking).

For each particle count the garment is dressed once on the bag's first valid body pose
``start`` seconds in (default 1 s: the bundled bags' still lead-in is skipped, so the motion
is what is timed) (`GarmentSim.dress`,
                   the scene's options from ``load_scene('walking')``: substeps, floor,
self-contact, ...), then each solver replays the same pose messages (at most ``steps``)
from a copy of that dressed garment, with the solver swapped in. Every tick is timed.

Per run (one solver, one size) the figures are:

* ms_per_solve: median over the ticks of TickStats.solve_ms / TickStats.substeps (a tick's
  solve time is summed over its substeps, one linear solve each);
* ms_per_tick: median of TickStats.total_ms (the whole tick: body motion, collisions,
  assembly, every substep's solve);
* iterations: median over the ticks of iterations per solve (TickStats.iterations /
  substeps);
* converged: every tick's every solve converged;
* skipped: the first tick took longer than ``max_seconds`` (the run holds that one tick),
  and then the solver is skipped at the larger sizes too. A solver that cannot be made
  (missing module) is recorded as skipped with the reason.

Every solver is first run for a few ticks at ~500 particles (two levels) so that numba's
compilation and cache loading stay out of the timings, and for one untimed tick at every size
(``warmup_ms``), for the kernels only large meshes use (the split coarsening from
SPLIT_VERTICES particles on). Every loaded OpenBLAS runs on one thread
(bench.blas_threads; meta.blas_threads records the count in effect).

``tol='auto'``: each size solves to the tolerance `tolerance: auto` gives a garment of its
particle count (sim.solve_tolerance.tolerance_at) from the cost model's measured points for the
walking scene's settings with this bench's garment, fabric, bag and threads and the scene's
solver (budget.cost_model.load_or_calibrate: calibrated once per machine and cached, as the
node's is); every solver of the run takes that tolerance.
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cloth_mg_ros.bench.blas_threads import blas_thread_count, blas_threads, one_blas_thread
from cloth_mg_ros.bench.charts import log_log_solver_axes, save_chart
from cloth_mg_ros.bench.results import recorded_path, write_json
from cloth_mg_ros.bench.solvers import paper_match, parse_list, particle_problems
from cloth_mg_ros.bench.solvers import solvers_meta as solver_meta
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.mesh.garments import GARMENTS
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.frames import FrameStatus, check_frame
from cloth_mg_ros.physics.materials import MATERIALS, get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.solve_tolerance import AUTO, describe, tolerance_at
from cloth_mg_ros.sim.tick_stats import TickStats
from cloth_mg_ros.solvers import SOLVERS, make_solver
from cloth_mg_ros.solvers.threads import use_threads

if TYPE_CHECKING:
    from cloth_mg_ros.config.schema import SceneParams
    from cloth_mg_ros.physics.materials import Material

WARMUP_PARTICLES = 500  # two levels, so the multigrid paths compile too
WARMUP_TICKS = 3
DEFAULT_TOL = 1e-4
DEFAULT_START = 1.0  # s: the bundled bags' still lead-in, skipped so that the motion is timed

# The paper's Table 3, walking half (ms, 2008 CPU).
PAPER_WALKING = {
    "particles": (1189, 2397, 4491, 9919, 19014),
    "pcg": (12.7, 42.62, 117.6, 471.0, 1687.3),
    "mg": (6.3, 18.7, 44.1, 152.9, 458.9),
}


# -- options ------------------------------------------------------------------------------
def validate_walking_args(bag: str, garment: str, particles: list, solvers: list,
                          material: str, steps: int | None, tol: float,
                          max_seconds: float | None, command: str = "bench walking",
                          steps_flag: str = "--steps") -> None:
    """Check every option before any work; one ClothInputError lists all the problems,
    prefixed by `command` (the benchmark that took them; steps_flag: its flag for `steps`)."""
    problems = []
    try:
        resolve_bag(bag)
    except ClothInputError as exc:
        problems.append(str(exc))
    if garment not in GARMENTS:
        problems.append(f"unknown garment {garment!r} (choose from {', '.join(GARMENTS)})")
    problems += particle_problems(particles)
    bad = [s for s in solvers if s not in SOLVERS]
    if bad:
        problems.append(f"unknown solver(s) {', '.join(map(repr, bad))} "
                        f"(choose from {', '.join(SOLVERS)})")
    if len(set(solvers)) != len(solvers):
        problems.append(f"--solvers lists a solver twice: {','.join(solvers)}")
    if not solvers:
        problems.append("--solvers must list at least one solver")
    if str(material).strip().lower() not in MATERIALS:
        problems.append(f"unknown material {material!r} (choose from {', '.join(MATERIALS)})")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int)
                              or steps < 1):
        problems.append(f"{steps_flag} must be a positive integer, got {steps!r}")
    if tol != AUTO and not (isinstance(tol, (int, float)) and not isinstance(tol, bool)
                            and math.isfinite(tol) and 0.0 < tol < 1.0):
        problems.append(f"--tol must be in (0, 1) or 'auto', got {tol!r}")
    if max_seconds is not None and not (isinstance(max_seconds, (int, float))
                                        and not isinstance(max_seconds, bool)
                                        and math.isfinite(max_seconds) and max_seconds > 0.0):
        problems.append(f"--max-seconds must be positive, got {max_seconds!r}")
    if problems:
        raise ClothInputError(f"{command}: " + "; ".join(problems))


def tol_option(text: str) -> float | str:
    """A --tol option of the walking benches: 'auto' or a number (anything else is passed on
    for validate_walking_args to name with the other problems)."""
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        return float(text)
    except ValueError:
        return text


# -- running ------------------------------------------------------------------------------
def skip_lead_in(frames: list, start: float) -> list:
    """The frames (stamp s, poses) from ``start`` seconds after the first one on. The bundled
    bags open with a still lead-in (1 s); starting at its end times the motion itself (the
    body is still until then, so dressing on the pose there is dressing on the first)."""
    if not frames or start <= 0.0:
        return frames
    t0 = frames[0][0]
    k = next((i for i, (st, _) in enumerate(frames) if st - t0 >= start - 1e-9), len(frames))
    return frames[k:]


def garment_options(params: SceneParams, garment: str, particles: int, solver: str,
                    tol: float | str, threads: int = 0) -> BodySimOptions:
    """The options a benchmark dresses with: the scene ``params``' (substeps, floor,
    self-contact, ...) with the garment's name, its particle count (the target; the mesh
    holds about that many), the solver's name, the relative residual ``tol`` of every solve
    (or 'auto': sim.solve_tolerance) and ``threads`` (0: every core)."""
    return BodySimOptions.from_scene(params, garment=garment, particles=particles,
                                     solver=solver, tolerance=tol, threads=threads)


def dress_garment(avatar: Avatar, frames: list[tuple[float, np.ndarray]],
                  material: Material, options: BodySimOptions) -> tuple[GarmentSim, int]:
    """The garment dressed (GarmentSim.dress) on the first valid pose of ``frames``, a bag's
    (stamp s, poses (S, 7): x, y, z in m and qx, qy, qz, qw per body segment) in order, and that
    frame's index; the replay goes on from the next one. Raises ClothInputError when no
    frame holds a valid pose."""
    first = next((k for k, (st, p) in enumerate(frames)
                  if check_frame(None, st, p, avatar.num_segments) == FrameStatus.OK), None)
    if first is None:
        raise ClothInputError("bench walking: the bag holds no valid body pose to dress on")
    return GarmentSim.dress(avatar, frames[first][0], frames[first][1], material, options), first


def with_solver(base: GarmentSim, name: str, tol: float) -> GarmentSim:
    """A copy of the dressed garment ``base`` stepping with solver ``name``."""
    garment_sim = copy.deepcopy(base)
    garment_sim.options.solver = name
    garment_sim.sim.solver = make_solver(name, tol=tol, hierarchy=garment_sim.garment.hierarchy,
                                bending=garment_sim.sim.model.bending,
                                levels=garment_sim.options.levels,
                                threads=garment_sim.options.threads)
    return garment_sim


def replay(garment_sim: GarmentSim, frames: list, max_seconds: float | None = None,
           on_tick=None, per_tick: bool = True) -> dict:
    """Push every frame through ``garment_sim``; the run's medians and, with ``per_tick``, every
    tick's ms per solve and per tick (``ms_per_solve_all``, ``ms_per_tick_all``).

    on_tick: called as ``on_tick(garment_sim, stats)`` after every stepped frame (e.g. to keep the
    cloth's positions for an accuracy comparison); its time is not in the tick's."""
    ticks: list[TickStats] = []
    skipped_frames = 0
    over = None
    for stamp, poses in frames:
        res = garment_sim.push(stamp, poses)
        if isinstance(res, FrameStatus):
            skipped_frames += 1
            continue
        if not np.all(np.isfinite(garment_sim.positions)):
            raise FloatingPointError("cloth positions became non-finite")
        ticks.append(res)
        if on_tick is not None:
            on_tick(garment_sim, res)
        if max_seconds is not None and len(ticks) == 1 and res.total_ms > 1e3 * max_seconds:
            over = res.total_ms / 1e3
            break
    per_solve = [t.solve_ms / max(1, t.substeps) for t in ticks]
    its = [t.iterations / max(1, t.substeps) for t in ticks]
    run = {
        "ms_per_solve": float(np.median(per_solve)) if ticks else None,
        "ms_per_tick": float(np.median([t.total_ms for t in ticks])) if ticks else None,
        "iterations": float(np.median(its)) if ticks else None,
        "converged": bool(ticks) and all(t.converged for t in ticks),
        "ticks": len(ticks), "frames_skipped": skipped_frames,
        "substeps": float(np.median([t.substeps for t in ticks])) if ticks else None,
        "solves": int(sum(t.substeps for t in ticks)),
        "worst_rel_residual": float(max((t.rel_residual for t in ticks), default=0.0)),
        "max_penetration": float(max((t.max_penetration for t in ticks), default=0.0)),
        "skipped": over is not None,
        "solver_failures": int(garment_sim.failures),
    }
    if per_tick:
        run["ms_per_solve_all"] = [round(v, 3) for v in per_solve]
        run["ms_per_tick_all"] = [round(t.total_ms, 3) for t in ticks]
    if over is not None:
        run["skip_reason"] = f"first tick took {over:.1f} s > --max-seconds {max_seconds:g}"
    return run


_WARM: set = set()


def warm_up(names: list[str], bag_frames: list, params: SceneParams, garment: str, material,
            tol: float) -> dict[str, str]:
    """A few ticks (WARMUP_TICKS) at ~WARMUP_PARTICLES (500) particles with each solver not
    yet warmed up in this process (numba compilation, cache loading); the garment is dressed
    on the first valid pose of ``bag_frames`` ((stamp s, poses (S, 7)) as dress_garment's).
    Returns {name: error message} for solvers that could not be made."""
    failed: dict[str, str] = {}
    todo = [n for n in names if n not in _WARM]
    if not todo:
        return failed
    avatar = Avatar.load()
    frames = bag_frames[: WARMUP_TICKS + 8]
    base, first = dress_garment(avatar, frames, material,
                         garment_options(params, garment, WARMUP_PARTICLES, "bscg", tol))
    for name in todo:
        try:
            garment_sim = with_solver(base, name, tol)
        except (ImportError, ClothInputError) as exc:  # require_extra raises the latter
            failed[name] = f"{type(exc).__name__}: {exc}"
            continue
        replay(garment_sim, frames[first + 1: first + 1 + WARMUP_TICKS])
        _WARM.add(name)
    return failed


def walking_meta(bag: str | Path, garment: str, material: str, tol: float | str,
                 steps: int | None, max_seconds: float | None, params: SceneParams) -> dict:
    """The JSON's "meta" of a walking run: bench.solvers' solvers_meta (machine, versions,
    date, threads variables; scene 'walking', tol: relative residual or 'auto', levels from
    the scene, max_seconds s or None) less what a walk does not use (systems, repeat, dt),
    with the bag (recorded_path), garment, material, steps (None: the whole bag) and the
    scene's substeps, max_substep_motion (m), max_step (s), floor and self_contact."""
    meta = solver_meta("walking", tol, None, params.levels or None, 1, max_seconds,
                       None, "bdf2")
    for key in ("systems", "repeat", "dt"):
        meta.pop(key, None)
    meta.update(bag=recorded_path(bag), garment=garment, material=material, steps=steps,
                substeps=params.substeps, max_substep_motion=params.max_substep_motion,
                max_step=params.max_step, floor=params.floor,
                self_contact=params.self_contact)
    return meta


def bench_walking(bag: str, particles: list[int], solvers: list[str], garment: str = "dress",
                  material: str = "cotton", steps: int | None = None,
                  tol: float | str = DEFAULT_TOL, max_seconds: float | None = None,
                  start: float = DEFAULT_START, log=None, threads: int = 0) -> dict:
    """Run the benchmark; returns {"runs": [...], "sizes": [...], "meta": {...}}.

    tol: every solve's relative residual, or 'auto' (the module docstring); start: seconds
    of the bag skipped before dressing (see `skip_lead_in`); log: a callable taking one line
    of progress (default: print to stderr); threads: the solver's and the kernels' threads
    (0: every core)."""
    material = str(material).strip().lower()
    validate_walking_args(bag, garment, particles, solvers, material, steps, tol, max_seconds)
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    params = load_scene("walking")
    path = resolve_bag(bag)
    all_frames = read_pose_frames(path, params.topic)
    frames = skip_lead_in(all_frames, start)
    if len(frames) < 2:
        raise ClothInputError(f"bench walking: the bag {path} has no pose messages "
                              f"{start:g} s after its first (--start)")
    mat = get_material(material)
    meta = walking_meta(path, garment, material, tol, steps, max_seconds, params)
    meta["start_s"] = start
    meta["threads"] = use_threads(threads)
    t_start = time.perf_counter()
    tolerances: tuple = ()
    if tol == AUTO:
        tolerances = auto_tolerances(params, garment, mat, str(path), threads, log)
        meta["tolerances"] = [list(p) for p in tolerances]
        meta["calibration_s"] = time.perf_counter() - t_start
    warm_tol = DEFAULT_TOL if tol == AUTO else tol
    with one_blas_thread():  # the direct and AMG baselines' BLAS: one thread
        unavailable = warm_up(solvers, all_frames, params, garment, mat, warm_tol)
        meta["warmup_s"] = time.perf_counter() - t_start
        for name, why in unavailable.items():
            log(f"solver {name!r} unavailable ({why}); recorded as skipped")
        walk = _Walk(Avatar.load(), frames, mat, params, garment, solvers, tol, steps,
                     max_seconds, threads, unavailable, tolerances)
        runs, sizes = [], []
        too_slow: dict[str, int] = {}
        for n in particles:
            info, size_runs = _bench_size(walk, n, too_slow, log)
            runs += size_runs
            sizes.append(info)
        meta.update(blas_threads=blas_thread_count(), blas_libraries=blas_threads())
    meta["wall_s"] = time.perf_counter() - t_start
    meta["unavailable"] = unavailable
    return {"runs": runs, "sizes": sizes, "meta": meta}


def auto_tolerances(params: SceneParams, garment: str, material, bag: str, threads: int,
                    log) -> tuple:
    """`tolerance: auto`'s measured (particles, tolerance) points for the walking scene's
    settings with this garment, material (physics.materials.Material), bag and threads and
    the scene's solver: the cost model's, calibrated once per machine and cached."""
    # imported here: the cost model (and its calibration) only loads for --tol auto
    from cloth_mg_ros.budget.cost_model import CALIBRATION_PARTICLES, load_or_calibrate

    options = garment_options(params, garment, CALIBRATION_PARTICLES, params.solver, AUTO,
                              threads)
    model, _ = load_or_calibrate(options, material, log, bag=bag)
    return tuple(model.tolerances)


def size_tolerance(tol: float | str, tolerances, particles: int) -> float:
    """The relative residual of a garment of `particles`: tol itself, or with 'auto' the
    tolerance the measured (particles, tolerance) points give it
    (sim.solve_tolerance.tolerance_at)."""
    return tolerance_at(tolerances, particles) if tol == AUTO else float(tol)


@dataclass(frozen=True)
class _Walk:
    """What every size of a `bench_walking` run shares: the avatar, the pose messages from
    the start on, the material, the scene's parameters, the options, and the solvers that
    could not be made (with why)."""

    avatar: object  # motion.avatar.Avatar
    frames: list
    material: object
    params: Mapping
    garment: str
    solvers: list[str]
    tol: float | str  # a relative residual, or 'auto' (then `tolerances` holds the points)
    steps: int | None
    max_seconds: float | None
    threads: int
    unavailable: dict[str, str]
    tolerances: tuple = ()

    def tol_at(self, particles: int) -> float:
        """The relative residual of every solve of a garment of `particles`."""
        return size_tolerance(self.tol, self.tolerances, particles)


def _bench_size(w: _Walk, n: int, too_slow: dict[str, int], log) -> tuple[dict, list[dict]]:
    """(the size's figures, a run per solver) at about n particles: the garment dressed once,
    then each solver replays the messages from a copy of it. A solver whose first tick ran
    over max_seconds goes into `too_slow` (solver: particles) and is skipped from then on."""
    t0 = time.perf_counter()
    # dressed at the tolerance auto gives the size asked for; the dressed garment's own
    # particle count (a little off n) sets the replays' tolerance
    base, first = dress_garment(w.avatar, w.frames, w.material,
                                garment_options(w.params, w.garment, n, w.solvers[0],
                                                w.tol_at(n), w.threads))
    tol = w.tol_at(int(base.sim.model.n))
    todo = w.frames[first + 1:]
    if w.steps is not None:
        todo = todo[:w.steps]
    dress_s = time.perf_counter() - t0
    info = {"particles_requested": n, "particles": int(base.sim.model.n),
            "levels": len(base.garment.hierarchy.levels), "frames": len(todo),
            "dress_s": dress_s, "solver_s": {}, "tol": tol}
    log(f"{info['particles']} particles ({info['levels']} levels): dressed in "
        f"{dress_s:.1f} s, {len(todo)} pose messages")
    runs = []
    for name in w.solvers:
        run = {"particles": info["particles"], "particles_requested": n, "solver": name,
               "tol": tol}
        if name in w.unavailable:
            run.update(skipped=True, skip_reason=f"unavailable: {w.unavailable[name]}",
                       ms_per_solve=None, ms_per_tick=None, iterations=None,
                       converged=False)
        elif name in too_slow:
            run.update(skipped=True, skip_reason=f"first tick over --max-seconds at "
                       f"{too_slow[name]} particles", ms_per_solve=None,
                       ms_per_tick=None, iterations=None, converged=False)
        else:
            ts = time.perf_counter()
            # one untimed tick on a copy at this size first: kernels only large meshes use
            # (the split coarsening) load here, not in the first timed tick (--max-seconds)
            replay(with_solver(base, name, tol), todo[:1], per_tick=False)
            run["warmup_ms"] = 1e3 * (time.perf_counter() - ts)
            run.update(replay(with_solver(base, name, tol), todo, w.max_seconds))
            info["solver_s"][name] = time.perf_counter() - ts
            if run["skipped"]:
                too_slow[name] = info["particles"]
        runs.append(run)
        log(_progress_line(run))
    info["bench_s"] = time.perf_counter() - t0
    return info, runs


def _progress_line(run: dict) -> str:
    if run["ms_per_solve"] is None:
        return f"  {run['solver']:9s} skipped: {run.get('skip_reason', '')}"
    flag = "" if run["converged"] else "  NOT CONVERGED"
    if run["skipped"]:
        flag += f"  skipped ({run['skip_reason']})"
    return (f"  {run['solver']:9s} {run['ms_per_solve']:9.1f} ms/solve "
            f"{run['ms_per_tick']:9.1f} ms/tick {run['iterations']:6.1f} it/solve "
            f"({run['ticks']} ticks, {run['solves']} solves){flag}")


# -- reporting ----------------------------------------------------------------------------
def _cell(run: dict | None, key: str) -> str:
    if run is None:
        return "-"
    if run[key] is None:
        return "skip" if run.get("skipped") else "n/a"
    txt = f"{run[key]:.1f}"
    if key == "ms_per_solve":
        txt += f" ({run['iterations']:.0f})"
    if run["skipped"]:
        return f">{run[key]:.0f} skip"
    return txt if run["converged"] else txt + " NC"


def format_walking_report(result: dict) -> str:
    """The table printed by the CLI: per solver and size, ms per solve (iterations per
    solve) and ms per tick, the paper's walking figures beside ours where sizes match."""
    runs, meta = result["runs"], result["meta"]
    solvers = list(dict.fromkeys(r["solver"] for r in runs))
    sizes = sorted({r["particles"] for r in runs})
    find = {(r["particles"], r["solver"]): r for r in runs}
    matched = [paper_match(n, PAPER_WALKING["particles"]) for n in sizes]
    head = (f"bench walking: {meta['garment']} on {Path(meta['bag']).name}, {meta['material']}, "
            f"tol {_tol_text(meta)}, steps {meta['steps'] or 'all'}, substeps >= "
            f"{meta['substeps']}, self-contact {meta['self_contact']}, BLAS threads "
            f"{meta.get('blas_threads', '?')}, {meta['machine']}")
    lines = [head, "cells: median over ticks; NC = not converged, skip = over --max-seconds"]
    for key, what in (("ms_per_solve", "ms per linear solve (iterations per solve)"),
                      ("ms_per_tick", "ms per tick (pose message)")):
        header = ["solver"] + [str(n) for n in sizes]
        rows = [[s] + [_cell(find.get((n, s)), key) for n in sizes] for s in solvers]
        if any(m is not None for m in matched):
            for pk, label in (("pcg", "paper PCG"), ("mg", "paper MG")):
                rows.append([f"{label} (walking, 2008)"] + [
                    "-" if m is None else
                    f"{PAPER_WALKING[pk][m]:.1f} @{PAPER_WALKING['particles'][m]}"
                    for m in matched])
        lines += ["", f"{what} against particles", text_table(header, rows)]
    for r in runs:
        if r["ms_per_solve"] is not None and not r["converged"]:
            lines.append(f"note: {r['solver']} at {r['particles']} did not converge on every "
                         f"solve (worst rel. residual {r['worst_rel_residual']:.2e})")
    if meta["tol"] == AUTO:
        lines.append("tolerance auto per size: " + ", ".join(
            f"{s['tol']:g} at {s['particles']} particles" for s in result.get("sizes", [])))
    for s in result.get("sizes", []):
        lines.append(f"time: {s['particles']} particles: dressing {s['dress_s']:.1f} s, whole "
                     f"size {s['bench_s']:.1f} s")
    return "\n".join(lines)


def _tol_text(meta: dict) -> str:
    """'0.0001', or 'auto (0.01 at 2394 particles, ...)' with the measured points."""
    return describe(meta["tol"], [tuple(p) for p in meta.get("tolerances", [])])


def plot_walking(result: dict, png: str | Path) -> Path:
    """Two log-log panels against particles, one line per solver: ms per solve and ms per
    tick; the paper's walking figures dashed in both (red crosses: not converged; open
    squares: skipped). Returns the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    meta = result["meta"]
    runs = [r for r in result["runs"] if r["ms_per_solve"] is not None]
    solvers = list(dict.fromkeys(r["solver"] for r in result["runs"]))
    colours = {s: plt.cm.tab10(i % 10) for i, s in enumerate(solvers)}
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    for ax, key, label in ((axes[0], "ms_per_solve", "ms per linear solve (median)"),
                           (axes[1], "ms_per_tick", "ms per tick (median)")):
        for s in solvers:
            rs = sorted((r for r in runs if r["solver"] == s), key=lambda r: r["particles"])
            if not rs:
                continue
            ax.plot([r["particles"] for r in rs], [r[key] for r in rs], marker="o",
                    color=colours[s], label=s)
            for r in rs:
                if r["skipped"]:
                    ax.plot(r["particles"], r[key], marker="s", ms=11, mfc="none", mec="grey",
                            mew=1.5, linestyle="none")
                elif not r["converged"]:
                    ax.plot(r["particles"], r[key], marker="x", ms=12, color="red", mew=2.5,
                            linestyle="none")
        for pk, plabel in (("pcg", "paper PCG (walking, 2008 CPU)"),
                           ("mg", "paper MG (walking, 2008 CPU)")):
            ax.plot(PAPER_WALKING["particles"], PAPER_WALKING[pk], linestyle="--",
                    color="black" if pk == "mg" else "grey", alpha=0.5, marker=".",
                    label=plabel)
        log_log_solver_axes(ax, label)
        ax.set_title(f"walking, {meta['garment']}, {meta['material']}: tol {_tol_text(meta)}, "
                     f"{meta['steps'] or 'all'} pose messages", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return save_chart(fig, png)


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench walking` on the bench sub-parsers."""
    w = bsub.add_parser("walking", help="every solver on the walking scene, timed per tick "
                        "(the paper's Table 3, walking half)")
    w.add_argument("--bag", default="walk", help="pose bag to replay (default walk)")
    w.add_argument("--garment", default="dress", help="garment (default dress)")
    w.add_argument("--particles", default="1200,2400,4500,10000,20000",
                   help="comma-separated particle counts")
    w.add_argument("--solvers", default="pcg,mg,mpcg,amg,direct",
                   help="comma-separated solvers (default pcg,mg,mpcg,amg,direct)")
    w.add_argument("--material", default="cotton", help="material (default cotton)")
    w.add_argument("--steps", type=int, default=None,
                   help="replay at most this many pose messages (default: all)")
    w.add_argument("--tol", default="1e-4",
                   help="relative residual of every solve, or 'auto': at each size the "
                        "tolerance `tolerance: auto` gives it (the cost model's measured "
                        "points, calibrated once per machine)")
    w.add_argument("--max-seconds", type=float, default=None,
                   help="skip a solver whose first tick takes longer than this (and at the "
                        "larger sizes)")
    w.add_argument("--start", type=float, default=1.0,
                   help="seconds of the bag skipped before dressing (default 1: the bundled "
                        "bags' still lead-in)")
    w.add_argument("--threads", type=int, default=0,
                   help="solver and kernel threads (default 0: every core)")
    w.add_argument("--json", default="out/bench_walking.json", help="JSON output file")
    w.add_argument("--png", default="out/bench_walking.png", help="chart output file")
    w.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the benchmark, print its report, write the JSON and the chart."""
    particles = parse_list(args.particles, "particles", int)
    solvers = parse_list(args.solvers, "solvers")
    material = args.material.strip().lower()
    tol = tol_option(args.tol)
    validate_walking_args(args.bag, args.garment, particles, solvers, material, args.steps,
                          tol, args.max_seconds)
    result = bench_walking(args.bag, particles, solvers, args.garment, material, args.steps,
                           tol, args.max_seconds, args.start, threads=args.threads)
    print(format_walking_report(result))
    write_json(args.json, result)
    png = plot_walking(result, args.png)
    print(f"wrote {args.json} and {png}")
    return 0
