"""The cells of `cloth-mg bench pareto` as Dask tasks (cloth_mg_ros.apps.cluster).

Every cell starts from the same settled garment and compares with the same exact-solve
reference. A worker prepares both once per set-up (`prepared`, `exact_reference`: cached in
the worker process) and keeps them for the cells that follow, so a cell costs its own run
only. The settled garment is deterministic (one set-up, one thread count: the same bits in
every process), so cells on different workers start from the same state.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.bench.blas_threads import blas_thread_count, one_blas_thread
from cloth_mg_ros.bench.pareto_rungs import rung_axis
from cloth_mg_ros.bench.pareto_runs import (
    DEFAULT_SOLVER,
    DEFAULT_TOL,
    REF_SUBSTEP_FACTOR,
    REFERENCE_SOLVER,
    run_record,
    settled_garment,
    surface_errors,
    trajectory,
    vertex_errors,
)
from cloth_mg_ros.bench.pareto_steps import step_rules
from cloth_mg_ros.bench.pareto_tolerance import DEFAULT_TOLS, tolerance_axis
from cloth_mg_ros.bench.walking import warm_up
from cloth_mg_ros.budget.tolerance_rule import LADDER
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.physics.materials import get_material

__all__ = ["Setup", "finest_cell", "lod_cell", "reference_cell", "rules_cell", "size_cell",
           "solver_cell", "warm_worker"]


@dataclass(frozen=True)
class Setup:
    """What a settled garment depends on: the bag, garment, particles, material name, the
    settle (s), the pose messages replayed after it, and the simulation threads."""

    bag: str
    garment: str
    particles: int
    material: str
    settle: float
    steps: int
    threads: int


@functools.lru_cache(maxsize=3)
def prepared(setup: Setup):
    """(settled GarmentSim, the frames after the settle, info) of a set-up, once per
    process."""
    return settled_garment(setup.bag, setup.garment, setup.particles,
                           get_material(setup.material), setup.settle, setup.steps,
                           threads=setup.threads)


@functools.lru_cache(maxsize=3)
def exact_reference(setup: Setup):
    """(trajectory (T, n, 3) m, run figures) of the set-up with exact solves, once per
    process."""
    base, frames, _ = prepared(setup)
    return trajectory(base, frames, REFERENCE_SOLVER)


def warm_worker(names: list[str], bag: str, garment: str, material: str, tol: float) -> dict:
    """Compile or load every solver's kernels in this worker (runs on each worker before the
    cells, so that no cell's time includes it); returns {solver: why it is unavailable}."""
    params = load_scene("walking")
    return warm_up(names, read_pose_frames(resolve_bag(bag), params.topic), params, garment,
                   get_material(material), tol)


def reference_cell(setup: Setup) -> dict:
    """The exact-solve reference's figures and the time step's own error (exact solves with
    REF_SUBSTEP_FACTOR times the steps against the scene's step)."""
    with one_blas_thread():  # the timed direct reference: one BLAS thread, as in solver_cell
        base, frames, info = prepared(setup)
        exact, ref_run = exact_reference(setup)
    small, small_run = trajectory(base, frames, REFERENCE_SOLVER,
                                  substep_factor=REF_SUBSTEP_FACTOR)
    time_err = vertex_errors(exact, small)
    return {"particles": info["particles"], "levels": info["levels"],
            "settle_messages": info["settle_messages"], "messages": len(frames),
            "ms_per_tick": ref_run["ms_per_tick"], "ms_per_solve": ref_run["ms_per_solve"],
            "substeps": ref_run["substeps"], "small_step_substeps": small_run["substeps"],
            "small_step_ms_per_tick": small_run["ms_per_tick"],
            "time_rms_mm": time_err[0], "time_max_mm": time_err[1]}


def solver_cell(cell: tuple[Setup, str, float, int | None]) -> dict:
    """One solver at one tolerance and level count against the exact reference."""
    setup, solver, tol, levels = cell
    base, frames, info = prepared(setup)
    exact, _ = exact_reference(setup)
    with one_blas_thread():  # the direct and AMG baselines' BLAS: one thread, on any worker
        traj, run = trajectory(base, frames, solver, tol, levels)
        blas = blas_thread_count()
    record = run_record(solver, tol, levels, info["particles"], run,
                        vertex_errors(traj, exact))
    record["blas_threads"] = blas
    return record


def rules_cell(cell: tuple[Setup, tuple[str, ...], str, float]) -> tuple[dict, list[str]]:
    """Part 3 (bench.pareto_steps.step_rules) on the set-up; returns (its result, its log
    lines)."""
    setup, rules, solver, tol = cell
    base, frames, _ = prepared(setup)
    lines: list[str] = []
    return step_rules(base, frames, rules, solver, tol, lines.append), lines


def lod_cell(cell: tuple[Setup, str, float, tuple[float, ...] | None, int, tuple | None]
             ) -> tuple[dict, dict, list[str]]:
    """Parts 4 and 5 (bench.pareto_rungs.rung_axis, bench.pareto_tolerance.tolerance_axis)
    on the set-up, part 5 over its own ladder and those of the run's tolerances `tols` that
    lie within the ladder's range (tols None: only the tolerances auto gives), on every `every`-th
    pose message, with tolerance auto's (particles, tolerance) points `auto_points` (None: no
    check); returns (part 4, part 5, their log lines)."""
    setup, solver, tol, tols, every, auto_points = cell
    base, frames, _ = prepared(setup)
    lines: list[str] = []
    levels = rung_axis(base, frames, solver, tol, lines.append)
    if tols is None:  # tolerance auto's own (tolerance_axis adds them and the reference)
        ladder: tuple[float, ...] = ()
    else:
        inside = {float(t) for t in tols if min(DEFAULT_TOLS) <= t <= max(DEFAULT_TOLS)}
        auto = {t for t in LADDER if t >= 1e-3}  # the rungs auto picks from in practice
        ladder = tuple(sorted(set(DEFAULT_TOLS) | auto | inside, reverse=True))
    return levels, tolerance_axis(base, frames, solver, ladder, every, log=lines.append,
                                  auto_points=auto_points), lines


def finest_cell(setup: Setup) -> tuple[np.ndarray, np.ndarray]:
    """(the exact trajectory, the faces) of the resolution reference."""
    base, _, _ = prepared(setup)
    traj, _ = exact_reference(setup)
    return traj, base.faces


def size_cell(setup: Setup, finest: tuple[np.ndarray, np.ndarray] | None) -> dict:
    """Part 2's row of one size: the solver's, the time step's and (with `finest`, from
    finest_cell) the resolution's error."""
    with one_blas_thread():  # the timed direct reference: one BLAS thread, as in solver_cell
        base, frames, info = prepared(setup)
        exact, ref_run = exact_reference(setup)
        small, _ = trajectory(base, frames, REFERENCE_SOLVER,
                              substep_factor=REF_SUBSTEP_FACTOR)
        traj, run = trajectory(base, frames, DEFAULT_SOLVER, DEFAULT_TOL)
    row = {"particles": info["particles"], "levels": info["levels"], "solver": DEFAULT_SOLVER,
           "tol": DEFAULT_TOL, "ms_per_tick": run["ms_per_tick"],
           "direct_ms_per_tick": ref_run["ms_per_tick"], "converged": run["converged"]}
    row["solver_rms_mm"], row["solver_max_mm"] = vertex_errors(traj, exact)
    row["time_rms_mm"], row["time_max_mm"] = vertex_errors(exact, small)
    if finest is not None:
        row["resolution_rms_mm"], row["resolution_max_mm"] = surface_errors(
            exact, base.faces, *finest)
    return row
