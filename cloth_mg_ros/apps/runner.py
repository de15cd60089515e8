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

from cloth_mg_ros.budget.cost_model import auto_particles, scene_cost_model, stream_rate
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.extras import extra_of, missing_extra_message
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.frames import FrameStatus, check_frame
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.grippers import GripperScript, GripperSet, step_held
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES
from cloth_mg_ros.sim.sheets import Scene, build_scene
from cloth_mg_ros.sim.simulator import Simulator
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
    solver_name: str = "mpcg",
    dt: float = 1.0 / 60.0,
    out: str | Path = "out/run",
    mesh_path: str | None = None,
    scheme: str = "bdf2",
    tol: float = 1e-4,
    levels: int | None = None,
    n_frames: int = 4,
    progress: bool = True,
    obstacle: str | None = None,
    spectral_radius: float = DEFAULT_SPECTRAL_RADIUS,
    friction: float | None = None,
    compression: str = "elastic",
    newton_iterations: int = 1,
    linearise_at: str = "start",
    contact_friction: str = "projection",
) -> dict:
    """Run a scene headless and write out/summary.json and out/frames.png; returns the
    summary ({"steps": [{"solve_ms", "iterations", ...}], "scene", ...}). friction: the
    cloth's Coulomb coefficient against the scene's colliders (None: their own, sim.sheets;
    the hang's summary names None); compression, contact_friction: build_model's."""
    validate_run_args(steps, dt, tol, scheme)
    validate_solver_name(solver_name)
    scene: Scene = build_scene(scene_name, particles, material, mesh_path, levels, obstacle,
                               friction, compression, contact_friction)
    solver = make_solver(solver_name, tol=tol, hierarchy=scene.hierarchy,
                         bending=scene.model.bending, levels=levels)
    (out := Path(out)).mkdir(parents=True, exist_ok=True)
    stepping = {"scheme": scheme, "newton_iterations": newton_iterations,
                "linearise_at": linearise_at}
    sim = Simulator(scene.model, scene.state, solver, dt=dt, spectral_radius=spectral_radius,
                    **stepping)
    t_start = time.perf_counter()
    records, frames = _step_sheet(sim, steps, n_frames, progress,
                                  f"{scene_name} {scene.model.n} particles", scene.grippers)
    wall = time.perf_counter() - t_start
    solve = np.array([r["solve_ms"] for r in records])
    summary = {
        "scene": scene_name, "particles": int(scene.model.n), "material": material.name,
        "mass_kg": float(scene.model.mass.sum()), "faces": len(scene.model.mesh.faces),
        "levels": len(scene.hierarchy.levels), "solver": solver_name, **stepping,
        "spectral_radius": spectral_radius if scheme == "genalpha" else None,
        "friction": friction, "compression": compression, "contact_friction": contact_friction,
        "dt": dt, "tol": tol, "mesh": mesh_path, "obstacle": obstacle, "wall_s": wall,
        "median_solve_ms": float(np.median(solve)),
        "median_iterations": float(np.median([r["iterations"] for r in records])),
        "all_converged": bool(all(r["converged"] for r in records)),
        "grippers": None if scene.grippers is None else scene.grippers.names,
        "steps": records,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    title = (f"{scene_name}: {scene.model.n} particles, {material.name}, {solver_name}, "
             f"dt={dt:.4g} s")
    _picture(out / "frames.png", frames, scene.model.mesh.faces, scene.spheres, title)
    return summary


def _step_sheet(sim: Simulator, steps: int, n_frames: int, progress: bool, label: str,
                grippers: GripperSet | None = None
                ) -> tuple[list[dict], list[tuple[float, np.ndarray]]]:
    """`steps` steps of a sheet's simulator, held by its grippers if it has some: (each
    step's StepStats as a dict, with "gripper_wrenches" {name: {"force", "torque"}} (N, N m,
    on each gripper) where there are grippers, and about `n_frames` (t s, positions (n, 3) m)
    evenly spread from the start, for the picture)."""
    keep = set(np.linspace(0, steps, max(2, n_frames)).round().astype(int).tolist())
    frames = [(0.0, sim.state.x.copy())]
    records = []
    bar = tqdm(range(1, steps + 1), desc=label, unit="step", disable=not progress,
               file=sys.stderr, mininterval=0.1 if sys.stderr.isatty() else 5.0)
    for k in bar:
        stats, _ = step_held(sim, grippers)
        if not np.all(np.isfinite(sim.state.x)):
            raise FloatingPointError(f"step {k}: cloth positions became non-finite")
        records.append(asdict(stats))
        if grippers is not None:
            records[-1]["gripper_wrenches"] = grippers.wrenches()
        bar.set_postfix(it=stats.iterations, ms=f"{stats.solve_ms:.1f}", refresh=False)
        if k in keep:
            frames.append((sim.state.t, sim.state.x.copy()))
    return records, frames


def _check_segment_poses(bag: Path, frames: list, segments: int) -> None:
    """ClothInputError, before the calibration and dressing, when no message of the bag has
    one pose per avatar segment (a bag of a tracker's joints)."""
    counts = {len(p) for _, p in frames}
    if frames and segments not in counts:
        raise ClothInputError(
            f"bag {bag}: {'/'.join(map(str, sorted(counts)))} poses per message, where the "
            f"avatar has {segments} segments: `cloth-mg run` takes segment poses (a bag of a "
            f"tracker's joints drives the node: body_input:=joints)")


def run_body_scene(params, out: str | Path = "out/run", steps: int | None = None,
                   n_frames: int = 5, progress: bool = True, material: Material | None = None,
                   rate_hz: float | None = None, log=None,
                   scripts: list[GripperScript] | None = None) -> dict:
    """Replay a body scene's bag through a garment simulation without ROS.

    params: a scene's parameters (`config.scenes.load_scene`, possibly `replace`d); steps: at
    most this many pose messages (None: the whole bag). Writes out/summary.json,
    {"ticks": [{"total_ms", "solve_ms", "iterations", "max_penetration", "contacts", ...}],
    "options": the BodySimOptions used, ...}, out/positions.npz (the garment after every
    tick: "stamps" (k,) s, "positions" (k, n, 3) float32 m, "final" (n, 3) float64 m exactly,
    "faces" (t, 3)) and out/frames.png (a strip of frames, avatar and garment). Returns the
    summary.

    Each pose message is one tick (`GarmentSim.push`), so the same bag, scene, solver and
    numba thread count give bit-identical positions on every run. With particles 'auto' the
    count is chosen for the stream's rate (rate_hz, or measured from the bag's first stamps)
    by the cost model (`cost_model.auto_particles`); the summary records the choice
    ("particles", "budget_ms", "predicted_ms", "rate_hz"), and a run given that count
    repeats the cloth exactly. With tolerance 'auto' each level solves to the tolerance the
    cost model's calibration measured for its size (budget.tolerance_rule); the summary records
    the finest level's ("solve_tolerance") and the measured points ("tolerances"), and a run
    given that tolerance repeats the cloth exactly.

    Every tick records "body_forces" ({segment: [fx, fy, fz] N} on each segment the garment
    collides with), "self_contact_dropped" (cloth-cloth pairs the self-contact search left
    out past its cap; the summary's is the sum over the ticks) and, with grippers,
    "gripper_wrenches" (TickStats); scripts: the scene's scripted grippers
    (config.scenes.gripper_scripts), for its ``grippers``. The summary states the garment's
    "mass_kg".
    """
    mat = material if material is not None else get_material(params.material)
    validate_solver_name(params.solver)
    bag = resolve_bag(params.bag)
    frames = read_pose_frames(bag, params.topic)
    if steps is not None:
        frames = frames[: steps + 1]
    avatar = Avatar.load()
    _check_segment_poses(bag, frames, avatar.num_segments)
    run_params, options, auto = _body_options(params, mat, frames, rate_hz, log)
    t0 = time.perf_counter()
    first = next((k for k, (st, p) in enumerate(frames)
                  if check_frame(None, st, p, avatar.num_segments) == FrameStatus.OK), None)
    if first is None:
        raise ClothInputError(f"bag {bag}: no valid body pose to dress the garment on")
    garment_sim = GarmentSim.dress(avatar, frames[first][0], frames[first][1], mat, options)
    garment_sim.scripts = list(scripts or [])
    dress_s = time.perf_counter() - t0
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    run = _replay(garment_sim, frames, first, n_frames, progress,
                  f"{params.scene} {params.garment}")
    summary = _body_summary(params, str(bag), mat, garment_sim, run_params, options, auto,
                            dress_s, run)
    _write_body_run(out, summary, garment_sim, run, f"{params.scene}: {params.garment}, "
                    f"{garment_sim.sim.model.n} particles, {mat.name}, {params.solver}")
    return summary


def _body_summary(params, bag: str, mat: Material, garment_sim: GarmentSim, run_params,
                  options, auto, dress_s: float, run: dict) -> dict:
    """run_body_scene's summary (see there) of a finished replay `run` (_replay's)."""
    ticks = run["ticks"]
    return {
        "scene": params.scene, "bag": str(bag), "garment": params.garment,
        "particles": int(garment_sim.sim.model.n),
        "mass_kg": garment_sim.mass_kg,
        "levels": len(garment_sim.garment.hierarchy.levels),
        "material": mat.name, "solver": params.solver, "tolerance": params.tolerance,
        "solve_tolerance": garment_sim.solve_tolerance(),
        "tolerances": [list(t) for t in options.tolerances] or None,
        "dress_s": dress_s, **_tick_figures(ticks),
        "requested_particles": run_params.particles if auto is None else AUTO,
        "budget_ms": None if auto is None else auto.budget_ms,
        "predicted_ms": None if auto is None else auto.predicted_ms,
        "rate_hz": None if auto is None else 1.0 / auto.period_s,
        "p95_total_ms": float(np.percentile([t["total_ms"] for t in ticks], 95))
        if ticks else None,
        "skipped_frames": run["skipped"], "rejected": dict(garment_sim.rejected),
        "options": asdict(options), "ticks": ticks,
    }


def _write_body_run(out: Path, summary: dict, garment_sim: GarmentSim, run: dict,
                    title: str) -> None:
    """out/summary.json, out/positions.npz and out/frames.png (run_body_scene)."""
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    np.savez_compressed(out / "positions.npz", stamps=np.array(run["stamps"]),
                        positions=np.array(run["trajectory"], dtype=np.float32).reshape(
                            len(run["trajectory"]), garment_sim.sim.model.n, 3),
                        final=garment_sim.positions, faces=garment_sim.faces)
    shots = run["shots"]
    _picture(out / "frames.png", [(t, x) for t, x, _ in shots], garment_sim.faces, title=title,
             capsules_per_frame=[c for _, _, c in shots])


def _body_options(params, material: Material, frames: list, rate_hz: float | None, log):
    """(the parameters run, with particles auto's choice, the BodySimOptions, the
    AutoChoice or None) of a body scene: particles and tolerance 'auto' ask the cost model."""
    auto = model = None
    if AUTO in (params.particles, params.tolerance):
        model, _ = scene_cost_model(params, material, log)
    if params.particles == AUTO:
        rate = rate_hz if rate_hz is not None else stream_rate([st for st, _ in frames[:16]])
        auto = auto_particles(params, rate, material, log, model)
        params = params.replace(particles=auto.particles)
    tolerances = tuple(model.tolerances) if params.tolerance == AUTO else ()
    return params, BodySimOptions.from_scene(params, tolerances=tolerances), auto


def _replay(garment_sim: GarmentSim, frames: list, first: int, n_frames: int, progress: bool,
            label: str) -> dict:
    """Push every frame after `first` through `garment_sim`: {"ticks": TickStats dicts, "skipped":
    frames refused, "stamps" and "trajectory" of the ticks, "shots": (s, positions, capsules)
    of `n_frames` frames for the picture}."""
    keep = set(np.linspace(first + 1, len(frames) - 1, max(2, n_frames)).round().astype(int))
    run = {"ticks": [], "skipped": [], "stamps": [], "trajectory": [],
           "shots": [(0.0, garment_sim.positions.copy(), _capsule_list(garment_sim))]}
    bar = tqdm(frames[first + 1:], desc=f"{label} {garment_sim.sim.model.n} particles", unit="tick",
               disable=not progress, file=sys.stderr,
               mininterval=0.1 if sys.stderr.isatty() else 5.0)
    for k, (stamp, poses) in enumerate(bar, start=first + 1):
        result = garment_sim.push(stamp, poses)
        if isinstance(result, FrameStatus):
            run["skipped"].append({"index": k, "stamp": stamp, "status": result.value})
            continue
        if not np.all(np.isfinite(garment_sim.positions)):
            raise FloatingPointError(f"tick {k}: cloth positions became non-finite")
        run["ticks"].append(asdict(result))
        run["stamps"].append(stamp)
        run["trajectory"].append(garment_sim.positions.astype(np.float32))
        bar.set_postfix(it=result.iterations, ms=f"{result.total_ms:.0f}", refresh=False)
        if k in keep:
            run["shots"].append((stamp - frames[first][0], garment_sim.positions.copy(),
                                 _capsule_list(garment_sim)))
    return run


def _picture(path: Path, *args, **kwargs) -> None:
    """io.render.render_frames into `path`, or a note where matplotlib (the 'bench' extra) is
    not installed: the run's figures and positions are written either way."""
    try:
        # imported here: matplotlib is in the 'bench' extra, not in the node's install
        from cloth_mg_ros.io.render import render_frames
    except ModuleNotFoundError as exc:
        if extra_of(exc.name) is None:
            raise
        print(f"{path.name} not drawn: {missing_extra_message(exc.name, 'the picture')}",
              file=sys.stderr)
        return
    render_frames(path, *args, **kwargs)


def _tick_figures(ticks: list[dict]) -> dict:
    """The summary's medians and extremes over the ticks (None where there is no tick)."""
    return {"median_total_ms": float(np.median([t["total_ms"] for t in ticks]))
            if ticks else None,
            "median_solve_ms": float(np.median([t["solve_ms"] for t in ticks]))
            if ticks else None,
            "max_penetration": float(max((t["max_penetration"] for t in ticks), default=0.0)),
            "all_converged": bool(all(t["converged"] for t in ticks)),
            # cloth-cloth pairs the self-contact search left out past its cap, all ticks
            "self_contact_dropped": int(sum(t["self_contact_dropped"] for t in ticks)),
            # what the penalties pulled the cloth onto the colliders with (TickStats)
            "contact_pull_p95_n": float(np.percentile([t["contact_pull_n"] for t in ticks], 95))
            if ticks else None,
            "contact_pull_max_n": float(max((t["contact_pull_n"] for t in ticks), default=0.0))}


def _capsule_list(garment_sim: GarmentSim) -> list:
    p0, p1, r = garment_sim.capsules()
    return list(zip(p0, p1, r, strict=True))
