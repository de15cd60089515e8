"""`cloth-mg bench folds`: folds, not saw teeth.

A real fabric folds smoothly; a membrane that buckles at the mesh's own scale makes saw teeth
instead, the surface turning up and down from one vertex to the next (light and dark
triangles side by side in a shaded picture). This benchmark measures how much of a garment's
bending sits in saw teeth, by two measures: the hinge measure the issue named
(`bench.hinge_zigzag`: triangles whose hinges bend past a threshold both ways) and the
vertex measure (`bench.saw_teeth`: vertices whose mean curvature has the opposite sign of
their neighbours'), and shows what each reads on known shapes (`bench.fold_calibration`): on
the project's lattices the hinge measure counts smooth folds as zig-zag and misses an
accordion pleated at every row; the vertex measure does neither.

The runner measures the walking dress (`cloth-mg run --scene walking --particles N`, the
positions after N pose messages, by the library's GarmentSim as `apps.runner.run_body_scene`
steps it) and the drape over the sphere (`cloth-mg run --scene drape --particles N --material
cotton --solver mpcg --steps 120`), at several resolutions.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.fold_calibration import calibration
from cloth_mg_ros.bench.fold_charts import closeup_picture, plot_folds
from cloth_mg_ros.bench.hinge_zigzag import DEFAULT_THRESHOLD_DEG, checked_threshold, fold_figures
from cloth_mg_ros.bench.results import git_output, write_json
from cloth_mg_ros.bench.saw_teeth import saw_teeth_figures
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

DEFAULT_JSON = "doc/results/bench_folds.json"
DEFAULT_PNG = "doc/bench_folds.png"
DEFAULT_PICTURE = "doc/images/folds_dress.png"
DEFAULT_PARTICLES = "2400,10000"
DEFAULT_DRAPE_PARTICLES = "2400,10000"
DEFAULT_MESSAGES = 100
# The drape as the command-line page runs it: cotton, mpcg, 120 steps of 1/60 s (2 s: the
# sheet lands on the sphere 10 cm below at 0.14 s and has settled), tolerance 1e-4, bdf2,
# friction 0.5 (the schema's default for sheet scenes).
DRAPE_MATERIAL = "cotton"
DRAPE_SOLVER = "mpcg"
DRAPE_STEPS = 120
DRAPE_DT = 1.0 / 60.0
DRAPE_TOL = 1e-4
DRAPE_FRICTION = 0.5
MIN_PARTICLES = 100


# ----------------------------------------------------------------------------------------
# The scenes
def walking_case(particles: int, messages: int = DEFAULT_MESSAGES, scene: str = "walking",
                 log=None, compression: str = "elastic", contact_friction: str = "projection"
                 ) -> tuple[np.ndarray, object, dict]:
    """The body scene's garment after ``messages`` pose messages, stepped as `cloth-mg run
    --scene SCENE --particles N --steps MESSAGES` steps it (apps.runner.run_body_scene: one
    tick per message, the scene file's solver, tolerance and threads; tolerance auto from the
    cost model's calibration). Returns (positions (n, 3) m, the garment's MeshLevel, {"scene",
    "particles", "messages", "time_s" (since the first pose), "tolerance"}). compression,
    contact_friction: sim.model.build_model's."""
    # imported here: the simulation (numba kernels) loads when the bench runs
    from cloth_mg_ros.budget.cost_model import scene_cost_model
    from cloth_mg_ros.config.scenes import AUTO, gripper_scripts, is_body_scene, load_scene
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.motion.frames import FrameStatus, check_frame
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim

    if not is_body_scene(scene):
        raise ClothInputError(f"--scene must be a body scene (walking, running, ...), got "
                              f"{scene!r}")
    params = load_scene(scene).replace(particles=particles, contact_friction=contact_friction)
    material = get_material(params.material)
    tolerances: tuple = ()
    if params.tolerance == AUTO:
        model, _ = scene_cost_model(params, material, log)
        tolerances = tuple(model.tolerances)
    options = BodySimOptions.from_scene(params, tolerances=tolerances)
    options.compression = compression
    frames = read_pose_frames(resolve_bag(params.bag), params.topic)[: messages + 1]
    avatar = Avatar.load()
    first = next((k for k, (st, p) in enumerate(frames)
                  if check_frame(None, st, p, avatar.num_segments) == FrameStatus.OK), None)
    if first is None:
        raise ClothInputError(f"scene {scene}: no valid body pose in the first {messages + 1} "
                              f"messages of bag {params.bag}")
    garment_sim = GarmentSim.dress(avatar, frames[first][0], frames[first][1], material,
                                   options)
    garment_sim.scripts = list(gripper_scripts(scene, params))
    for k, (stamp, poses) in enumerate(frames[first + 1:], start=first + 1):
        garment_sim.push(stamp, poses)
        if not np.all(np.isfinite(garment_sim.positions)):
            raise FloatingPointError(f"{scene} at {particles} particles, message {k}: cloth "
                                     "positions became non-finite")
    model = garment_sim.sim.model
    info = {"scene": params.scene, "particles": int(model.n),
            "requested_particles": int(particles), "messages": int(len(frames) - 1),
            "time_s": float(frames[-1][0] - frames[first][0]),
            "tolerance": garment_sim.solve_tolerance(), "material": material.name,
            "solver": params.solver, "compression": compression,
            "contact_friction": contact_friction, **stored_stretch(model, garment_sim.positions)}
    return garment_sim.positions.copy(), model.mesh, info


def drape_case(particles: int, steps: int = DRAPE_STEPS, compression: str = "elastic",
               contact_friction: str = "projection") -> tuple[np.ndarray, object, dict]:
    """The sheet draped over the sphere after ``steps`` steps of 1/60 s, as `cloth-mg run
    --scene drape --particles N --material cotton --solver mpcg --steps STEPS` runs it
    (apps.runner.run_scene: bdf2, tolerance 1e-4, friction 0.5). Returns (positions (n, 3) m,
    the sheet's MeshLevel, {"scene", "particles", "steps", "time_s", ...})."""
    # imported here: the simulation (numba kernels) loads when the bench runs
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.sheets import build_scene
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import make_solver

    scene = build_scene("drape", particles, get_material(DRAPE_MATERIAL),
                        friction=DRAPE_FRICTION, compression=compression,
                        contact_friction=contact_friction)
    solver = make_solver(DRAPE_SOLVER, tol=DRAPE_TOL, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    sim = Simulator(scene.model, scene.state, solver, dt=DRAPE_DT, scheme="bdf2")
    for k in range(1, steps + 1):
        sim.step()
        if not np.all(np.isfinite(sim.state.x)):
            raise FloatingPointError(f"drape at {particles} particles, step {k}: cloth "
                                     "positions became non-finite")
    info = {"scene": "drape", "particles": int(scene.model.n),
            "requested_particles": int(particles), "steps": int(steps),
            "time_s": float(steps * DRAPE_DT), "tolerance": DRAPE_TOL,
            "material": DRAPE_MATERIAL, "solver": DRAPE_SOLVER, "compression": compression,
            "contact_friction": contact_friction, **stored_stretch(scene.model, sim.state.x)}
    return sim.state.x.copy(), scene.model.mesh, info


def stored_stretch(model, x: np.ndarray) -> dict:
    """{"stretch_energy_j": the membrane's stretch and shear energy at positions x (n, 3) m,
    J; "mass_kg": the cloth's mass}: what the folds' picture cannot show, the strain the
    cloth holds (a draped sheet's is its weight's share, far under a joule; the contact
    corrections' leak shows as tens of joules, doc/benchmarks/folds.md)."""
    from cloth_mg_ros.sim.forces import internal_forces  # with the simulation, as above

    return {"stretch_energy_j": float(internal_forces(model, x).stretch_energy),
            "mass_kg": float(np.sum(model.mass))}


def bench_folds(particles: list[int], messages: int = DEFAULT_MESSAGES,
                scene: str = "walking", drape_particles: list[int] = (),
                drape_steps: int = DRAPE_STEPS, threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                picture: str | Path | None = None, log=print,
                compression: str = "elastic", contact_friction: str = "projection") -> dict:
    """Measure the garment of ``scene`` at each particle count and the drape at each of
    ``drape_particles``: {"meta" (with "calibration": both measures on known shapes),
    "walking": [{**case info, **fold_figures, **saw_teeth_figures, "rest": both measures on
    the mesh's rest shape}], "drape": [...]}; with
    ``picture``, one PNG of the garment close up at every particle count
    (`fold_charts.closeup_picture`)."""
    checked_threshold(threshold_deg)
    for n in [*particles, *drape_particles]:
        if n < MIN_PARTICLES:
            raise ClothInputError(f"--particles and --drape-particles must be at least "
                                  f"{MIN_PARTICLES}, got {n}")
    if messages < 1:
        raise ClothInputError(f"--messages must be a positive integer, got {messages}")
    if drape_steps < 1:
        raise ClothInputError(f"--drape-steps must be a positive integer, got {drape_steps}")
    t0 = time.perf_counter()
    walking, drape, shots = [], [], []
    for n in particles:
        x, mesh, info = walking_case(n, messages, scene, log, compression, contact_friction)
        walking.append({**info, **_figures(x, mesh, threshold_deg)})
        log(_case_line(walking[-1]))
        if picture is not None:
            title = f"{info['scene']}, {info['particles']} particles, {info['time_s']:.2f} s"
            shots.append((title, x, mesh))
    for n in drape_particles:
        x, mesh, info = drape_case(n, drape_steps, compression, contact_friction)
        drape.append({**info, **_figures(x, mesh, threshold_deg)})
        log(_case_line(drape[-1]))
    pictures = [str(closeup_picture(shots, picture, threshold_deg))] if shots else []
    meta = {"machine": platform.node(), "cpus": os.cpu_count(),
            "platform": platform.platform(), "commit": git_output("rev-parse", "--short", "HEAD"),
            "stretch_commit": git_output("log", "-1", "--format=%h", "--",
                                         "cloth_mg_ros/physics/stretch.py"),
            "changed_files": git_output("status", "--porcelain", "-uno"),
            "threads": {k: os.environ.get(k, "unset")
                        for k in ("OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")},
            "threshold_deg": float(threshold_deg), "pictures": pictures,
            "bending": "l0^2 theta^2 / (A0 + A1) per hinge (rest length, rest areas), half "
                       "to each of its two faces",
            "vertex_bending": "A H^2 per interior vertex (rest area, signed mean curvature)",
            "calibration": calibration(threshold_deg),
            "wall_s": time.perf_counter() - t0}
    return {"meta": meta, "walking": walking, "drape": drape}


def _figures(x: np.ndarray, mesh, threshold_deg: float) -> dict:
    """Both measures' figures for one garment at x, and under "rest" at its rest shape: what
    the measures read before the cloth moves (a tube cut in rows reads as zig-zag by the
    hinges, its axis crossing the rows; a flat sheet as nothing)."""
    def both(y: np.ndarray) -> dict:
        return {**fold_figures(y, mesh, threshold_deg), **saw_teeth_figures(y, mesh,
                                                                              threshold_deg)}
    return {**both(x), "rest": both(np.asarray(mesh.rest, dtype=np.float64))}


def _case_line(row: dict) -> str:
    return (f"{row['scene']} {row['particles']} particles: {100 * row['zigzag_share']:.0f} % of "
            f"the bent triangles zig-zag, holding {100 * row['bending_share']:.0f} % of the "
            f"bending; {100 * row['vertex_saw_share']:.0f} % of the bent vertices are saw "
            f"teeth, holding {100 * row['vertex_bending_share']:.0f} %; "
            f"{row['stretch_energy_j']:.3g} J of stretch in {row['mass_kg']:.3g} kg")


def format_report(result: dict) -> str:
    """One row per case: triangles, bent ones, both measures' shares, the hinges' angles;
    then the measures on the calibration shapes."""
    rows = []
    for row in [*result["walking"], *result["drape"]]:
        rows.append([row["scene"], str(row["particles"]), str(row["triangles"]),
                     str(row["bent_triangles"]), str(row["zigzag_triangles"]),
                     f"{100 * row['zigzag_share']:.1f}", f"{100 * row['bending_share']:.1f}",
                     f"{100 * row['rest']['bending_share']:.1f}",
                     f"{100 * row['bending_share_hinges']:.1f}",
                     f"{100 * row['vertex_saw_share']:.1f}",
                     f"{100 * row['vertex_bending_share']:.1f}",
                     f"{row['theta_rms_deg']:.2f}", f"{row['theta_max_deg']:.1f}",
                     f"{row['stretch_energy_j']:.3g}"])
    head = ["scene", "particles", "triangles", "bent", "zig-zag", "zig-zag %",
            "bending %", "at rest %", "hinges' %", "saw vertices %", "their bending %", "rms deg",
            "max deg", "stretch J"]
    cal = [[c["shape"], "yes" if c["saw_teeth"] else "no",
            f"{100 * c['zigzag_share']:.1f}", f"{100 * c['bending_share']:.1f}",
            f"{100 * c['vertex_saw_share']:.1f}", f"{100 * c['vertex_bending_share']:.1f}"]
           for c in result["meta"].get("calibration", [])]
    out = (f"hinges past {result['meta']['threshold_deg']:g} degrees; bending % : the "
           f"zig-zag triangles' share of all bending (at rest %: the same of the rest "
           f"shape; hinges' %: of the hinges touching one); saw vertices %: bent vertices "
           f"whose mean curvature has the opposite sign of their neighbours', their "
           f"bending %: their share of sum A H^2\n"
           + text_table(head, rows))
    if cal:
        out += ("\nthe measures on known shapes (a 1 m sheet, 2.5 cm edges)\n"
                + text_table(["shape", "saw teeth", "zig-zag %", "bending %",
                              "saw vertices %", "their bending %"], cal))
    return out


# ----------------------------------------------------------------------------------------
# Command line
def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench folds` on the bench sub-parsers."""
    p = bsub.add_parser("folds", help="folds, not saw teeth: the share of triangles whose "
                        "hinges bend past a few degrees both ways and of vertices whose "
                        "curvature flips against their neighbours', and of the bending they "
                        "hold, on the walking dress and the drape per resolution")
    p.add_argument("--particles", default=DEFAULT_PARTICLES,
                   help=f"the garment's particle counts, comma-separated (default "
                        f"{DEFAULT_PARTICLES})")
    p.add_argument("--messages", type=int, default=DEFAULT_MESSAGES,
                   help=f"pose messages replayed before measuring (default {DEFAULT_MESSAGES})")
    p.add_argument("--scene", default="walking", help="body scene (default walking)")
    p.add_argument("--drape-particles", default=DEFAULT_DRAPE_PARTICLES,
                   help=f"the drape's particle counts, comma-separated, or 'none' (default "
                        f"{DEFAULT_DRAPE_PARTICLES})")
    p.add_argument("--drape-steps", type=int, default=DRAPE_STEPS,
                   help=f"the drape's steps of 1/60 s (default {DRAPE_STEPS})")
    p.add_argument("--threshold", type=float, default=DEFAULT_THRESHOLD_DEG,
                   help=f"a hinge is bent past this angle, and a vertex whose curvature "
                        f"bends a hinge across it so far, degrees (default "
                        f"{DEFAULT_THRESHOLD_DEG:g})")
    p.add_argument("--compression", default="elastic", choices=("elastic", "buckle"),
                   help="the membrane under compression: elastic (resisted as in tension, "
                        "the default) or buckle (faces wrinkle, physics.wrinkles)")
    p.add_argument("--contact-friction", default="projection",
                   choices=("projection", "solve"),
                   help="where friction against the colliders acts: projection (after the "
                        "solve, the default) or solve (inside it, sim.contact_friction)")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.add_argument("--png", default=DEFAULT_PNG, help=f"chart output (default {DEFAULT_PNG})")
    p.add_argument("--before", default=None,
                   help="an earlier run's JSON, drawn dashed on the chart")
    p.add_argument("--picture", nargs="?", const=DEFAULT_PICTURE, default=None,
                   help=f"also draw the garment close up, a row per particle count, to "
                        f"this PNG (default {DEFAULT_PICTURE})")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the bench from parsed options; exit 0."""
    import json

    from cloth_mg_ros.bench.solvers import parse_list

    particles = parse_list(args.particles, "particles", int)
    drape = [] if args.drape_particles.strip().lower() in ("none", "0", "") else \
        parse_list(args.drape_particles, "drape-particles", int)
    before = None
    if args.before is not None:
        try:
            before = json.loads(Path(args.before).read_text())
        except (OSError, ValueError) as exc:
            raise ClothInputError(f"--before {args.before}: not a readable JSON file "
                                  f"({exc})") from None
    result = bench_folds(particles, args.messages, args.scene, drape, args.drape_steps,
                         args.threshold, args.picture, compression=args.compression,
                         contact_friction=args.contact_friction)
    print(format_report(result))
    write_json(args.json, result)
    png = plot_folds(result, args.png, before)
    print(f"wrote {args.json} and {png}" + "".join(f", {p}" for p in result["meta"]["pictures"]))
    return 0
