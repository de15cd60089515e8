"""Headless runs: step a scene, record per-step figures, write summary.json and frames.png."""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.integrator import SCHEMES, Simulator
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.render import render_frames
from cloth_mg_ros.scenes import Scene, build_scene
from cloth_mg_ros.solvers import make_solver, validate_solver_name


def validate_run_args(steps: int, dt: float, tol: float, scheme: str) -> None:
    """Reject nonsense run parameters before anything is built, naming the value."""
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ClothInputError(f"--steps must be a positive integer, got {steps!r}")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0.0):
        raise ClothInputError(f"--dt must be a positive number of seconds, got {dt!r}")
    if dt > 0.1:
        raise ClothInputError(f"--dt {dt} s is too large for cloth (at most 0.1 s)")
    if not (math.isfinite(tol) and 0.0 < tol < 1.0):
        raise ClothInputError(f"--tol must be in (0, 1), got {tol!r}")
    if scheme not in SCHEMES:
        raise ClothInputError(f"--scheme must be one of {', '.join(SCHEMES)}, got {scheme!r}")


def run_scene(
    scene_name: str,
    particles: int,
    material: Material,
    steps: int,
    solver_name: str = "pcg",
    dt: float = 1.0 / 60.0,
    out: str | Path = "out/run",
    mesh_path: str | None = None,
    scheme: str = "bdf2",
    tol: float = 1e-4,
    levels: int | None = None,
    n_frames: int = 4,
    progress: bool = True,
) -> dict:
    """Run a scene headless and write out/summary.json and out/frames.png.

    Returns the summary dict: {"steps": [{"solve_ms", "iterations", "rel_residual",
    "kinetic_energy", "potential_energy", ...}], "scene", "particles", ...}.
    """
    validate_run_args(steps, dt, tol, scheme)
    validate_solver_name(solver_name)
    scene: Scene = build_scene(scene_name, particles, material, mesh_path, levels)
    solver = make_solver(solver_name, tol=tol, hierarchy=scene.hierarchy,
                         wing_hess=scene.model.wing_hess, levels=levels)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sim = Simulator(scene.model, scene.state, solver, dt=dt, scheme=scheme)
    keep = set(np.linspace(0, steps, max(2, n_frames)).round().astype(int).tolist())
    frames = [(0.0, sim.state.x.copy())]
    records = []
    t_start = time.perf_counter()
    bar = tqdm(range(1, steps + 1), desc=f"{scene_name} {scene.model.n} particles",
               unit="step", disable=not progress, file=sys.stderr,
               mininterval=0.1 if sys.stderr.isatty() else 5.0)
    for k in bar:
        stats = sim.step()
        if not np.all(np.isfinite(sim.state.x)):
            raise FloatingPointError(f"step {k}: cloth positions became non-finite")
        records.append(asdict(stats))
        bar.set_postfix(it=stats.iterations, ms=f"{stats.solve_ms:.1f}")
        if k in keep:
            frames.append((sim.state.t, sim.state.x.copy()))
    wall = time.perf_counter() - t_start
    solve = np.array([r["solve_ms"] for r in records])
    summary = {
        "scene": scene_name,
        "particles": int(scene.model.n),
        "faces": len(scene.model.mesh.faces),
        "levels": len(scene.hierarchy.levels),
        "material": material.name,
        "solver": solver_name,
        "scheme": scheme,
        "dt": dt,
        "tol": tol,
        "mesh": mesh_path,
        "wall_s": wall,
        "median_solve_ms": float(np.median(solve)),
        "median_iterations": float(np.median([r["iterations"] for r in records])),
        "all_converged": bool(all(r["converged"] for r in records)),
        "steps": records,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    title = (f"{scene_name}: {scene.model.n} particles, {material.name}, {solver_name}, "
             f"dt={dt:.4g} s")
    render_frames(out / "frames.png", frames, scene.model.mesh.faces, scene.spheres, title)
    return summary
