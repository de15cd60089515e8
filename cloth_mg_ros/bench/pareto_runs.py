"""What every cell of `bench pareto` shares: a settled garment, a trajectory from it, the
errors of one trajectory against another, and a cell's record. `bench.pareto` (the sweep and
its report) and its axes (`pareto_tasks`, `pareto_tolerance`, ...) import from here, so the
sweep's modules do not import each other in a circle."""

from __future__ import annotations

import copy
import math
import time

import numpy as np

from cloth_mg_ros.bench.walking import dress_garment, garment_options, replay
from cloth_mg_ros.collision.mesh_kernels import surface_distances
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.motion.avatar import Avatar

DEFAULT_SOLVER = "mpcg"  # the scenes' default solver and tolerance (config/walking.yaml)
DEFAULT_TOL = 1e-4
REF_SUBSTEP_FACTOR = 8
REFERENCE_SOLVER = "direct"


def settled_garment(bag: str, garment: str, particles: int, material, settle: float,
                    steps: int, threads: int = 0):
    """Dress the garment on the bag's first pose and settle it through the first ``settle``
    seconds of messages with exact solves, ``threads`` simulation threads (0: every core).
    Returns (GarmentSim, the next ``steps`` frames, info dict)."""
    params = load_scene("walking")
    frames = read_pose_frames(resolve_bag(bag), params.topic)
    t0 = time.perf_counter()
    garment_sim, first = dress_garment(Avatar.load(), frames, material,
                       garment_options(params, garment, particles, REFERENCE_SOLVER, DEFAULT_TOL,
                                threads))
    start = frames[first][0]
    rest = frames[first + 1:]
    k = next((i for i, (st, _) in enumerate(rest) if st - start > settle + 1e-9), len(rest))
    if k:
        replay(garment_sim, rest[:k])
    todo = rest[k:k + steps]
    if len(todo) < steps:
        raise ClothInputError(f"bench pareto: the bag has {len(todo)} pose messages after the "
                              f"{settle:g} s settle, fewer than --steps {steps}")
    info = {"particles": int(garment_sim.sim.model.n),
            "levels": len(garment_sim.garment.hierarchy.levels),
            "settle_messages": k, "prepare_s": time.perf_counter() - t0}
    return garment_sim, todo, info


def trajectory(base, frames: list, solver: str, tol: float = DEFAULT_TOL,
               levels: int | None = None, substep_factor: int = 1) -> tuple[np.ndarray, dict]:
    """Run a copy of ``base`` (a settled GarmentSim) over ``frames`` with ``solver``.

    Returns (positions after every message (T, n, 3) float64 m, the run's figures from
    bench.walking.replay)."""
    garment_sim = copy.deepcopy(base)
    garment_sim.options.substeps *= substep_factor
    garment_sim.options.max_substep_motion /= substep_factor
    garment_sim.options.levels = levels
    garment_sim.set_solver(solver, tol)
    out: list[np.ndarray] = []
    run = replay(garment_sim, frames, on_tick=lambda g, _: out.append(g.positions.copy()),
                 per_tick=False)
    return np.array(out), run


def vertex_errors(traj: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(RMS, max) in mm of the vertex distances between two trajectories (T, n, 3) m."""
    if traj.shape != ref.shape:
        return math.inf, math.inf  # a run that stopped early (skipped ticks)
    d = np.linalg.norm(traj - ref, axis=2)
    return 1e3 * float(np.sqrt(np.mean(d * d))), 1e3 * float(d.max())


def surface_errors(traj: np.ndarray, faces: np.ndarray, ref: np.ndarray,
                   ref_faces: np.ndarray) -> tuple[float, float]:
    """(RMS, max) in mm of the symmetric surface distance between two cloth trajectories of
    different meshes (T, n, 3) / (T, m, 3) m with faces (f, 3) / (g, 3): every vertex of
    each to the nearest point on the other's triangles, after every message."""
    sq, worst, count = 0.0, 0.0, 0
    for x, y in zip(traj, ref, strict=True):
        d = np.concatenate([surface_distances(x, y[ref_faces]),
                            surface_distances(y, x[faces])])
        sq += float(np.sum(d * d))
        worst = max(worst, float(d.max()))
        count += len(d)
    return 1e3 * math.sqrt(sq / max(count, 1)), 1e3 * worst


def run_record(solver, tol, levels, n, run, err) -> dict:
    return {"solver": solver, "tol": tol, "levels": levels, "particles": n,
            "ms_per_tick": run["ms_per_tick"], "ms_per_solve": run["ms_per_solve"],
            "iterations": run["iterations"], "converged": run["converged"],
            "rms_mm": err[0], "max_mm": err[1], "ticks": run["ticks"],
            "solver_failures": run["solver_failures"], "available": True}
