"""`cloth-mg bench folds`: folds, not saw teeth.

A real fabric folds smoothly: across a triangle of the mesh its curvature keeps its sign. A
membrane that resists compression as it resists stretch buckles instead at the mesh's own
scale, the hinges of one triangle bending in opposite directions, a zig-zag one triangle wide
(light and dark triangles in a shaded picture). This benchmark measures how much of a garment's
bending sits in such saw teeth.

Definitions (``hinge_angles``, ``fold_figures``):

* hinge: an interior edge (a, b) with its two faces (a, b, c) and (b, a, d), consistently
  oriented (`mesh.topology.MeshLevel.wings`). Its signed angle theta in (-pi, pi] is the angle
  between the two faces' normals n0 = e x (x_c - x_a) and n1 = (x_d - x_a) x e (e = x_b - x_a),
  signed by (n0 x n1) . e: 0 flat, positive where the surface bends away from the side its
  normals point to (convex seen from that side), negative where it bends towards it. The sign
  of every hinge flips with the mesh's orientation; which triangles are zig-zag does not.
* bending of a hinge: l0^2 theta^2 / (A0 + A1), l0 the edge's rest length and A0, A1 its two
  faces' rest areas (dimensionless). Times (3/8) B (B the flexural rigidity, N m) it is the
  hinge energy of discrete shells (Grinspun et al. 2003; the project's hinge stencil,
  physics.bending, for small angles), so it weights a hinge as the fabric's bending energy
  does, independent of the resolution. A triangle's bending is half of each of its hinges'
  (each hinge's bending split equally between its two faces), so the triangles' bending adds
  up to the garment's: "the share of all bending held by zig-zag triangles" is the zig-zag
  triangles' sum over the total. (Giving each triangle all of its hinges' bending instead
  doubles both sums: the same share.) ``bending_share_hinges`` is a second reading: the share
  of the bending on hinges that touch a zig-zag triangle, each such hinge counted whole.
* a triangle is bent when one of its hinges bends past the threshold (|theta| > threshold),
  and zig-zag when two of its hinges past the threshold bend in opposite directions.
  ``zigzag_share`` is the zig-zag triangles over the bent ones (0 when none is bent);
  ``bending_share`` the zig-zag triangles' bending over all the garment's (0 when it is flat).

A smooth fold (a cylinder) bends all hinges one way: no zig-zag. The angle is measured from
flat, not from the rest shape: the walking dress's rest shape is a tube whose hinges bend
one way by a few degrees, which a smooth fold keeps. What the measure cannot tell from saw
teeth: a saddle, whose hinges across its two principal directions bend opposite ways, by
about kappa h (h the mesh spacing): it counts where both curvature radii are under about
h / 0.052 at 3 degrees (0.5 m at 2.5 cm spacing, 0.25 m at 1.25 cm), so a finer mesh counts
fewer of a garment's saddles.

The runner measures the walking dress (`cloth-mg run --scene walking --particles N`, the
positions after N pose messages, by the library's GarmentSim as `apps.runner.run_body_scene`
steps it) and the drape over the sphere (`cloth-mg run --scene drape --particles N --material
cotton --solver mpcg --steps 120`), at several resolutions.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

DEFAULT_JSON = "doc/results/bench_folds.json"
DEFAULT_PNG = "doc/bench_folds.png"
DEFAULT_PICTURE = "doc/images/folds_dress.png"
DEFAULT_THRESHOLD_DEG = 3.0
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
CLOSEUP_RADIUS = 0.15  # m: the half-width of the picture's patch of the garment
VIEW_ELEV, VIEW_AZIM = 15.0, -60.0  # degrees: the picture's camera, io.render's azimuth
MIN_PARTICLES = 100


# ----------------------------------------------------------------------------------------
# The measure
def _checked_positions(x: np.ndarray, mesh) -> np.ndarray:
    """x as (n, 3) float64; ClothInputError naming the shape or the bad value."""
    x = np.asarray(x, dtype=np.float64)
    n = len(mesh.rest)
    if x.shape != (n, 3):
        raise ClothInputError(f"positions must have shape ({n}, 3) for this mesh, got "
                              f"{x.shape}")
    if not np.all(np.isfinite(x)):
        raise ClothInputError(f"positions hold non-finite values (first at row "
                              f"{int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])})")
    return x


def hinge_angles(x: np.ndarray, mesh) -> np.ndarray:
    """Signed angle of every interior edge (hinge), radians, (w,) in the order of
    ``mesh.wings`` (a, b, c, d): 0 flat, positive where the surface bends away from its
    normals' side (module docstring).

    x: (n, 3) positions, m; mesh: a `mesh.topology.MeshLevel` (consistently oriented faces).
    A mesh without interior edges gives an empty array.
    """
    x = _checked_positions(x, mesh)
    wings = np.asarray(mesh.wings, dtype=np.int64).reshape(-1, 4)
    if len(wings) == 0:
        return np.zeros(0)
    xa, xb, xc, xd = (x[wings[:, k]] for k in range(4))
    e = xb - xa
    n0 = np.cross(e, xc - xa)
    n1 = np.cross(xd - xa, e)
    # atan2 of (|n0| |n1| |e| sin, |n0| |n1| |e| cos): no normalisation needed, exact near 0
    # and near pi, where arccos of a dot product loses its digits.
    sin = np.einsum("ij,ij->i", np.cross(n0, n1), e)
    cos = np.einsum("ij,ij->i", n0, n1) * np.linalg.norm(e, axis=1)
    return np.arctan2(sin, cos)


def hinge_bending(mesh, theta: np.ndarray) -> np.ndarray:
    """Each hinge's bending l0^2 theta^2 / (A0 + A1) (module docstring), (w,), dimensionless:
    l0 the rest edge length, A0 and A1 its faces' rest areas; theta (w,) radians."""
    wings = np.asarray(mesh.wings, dtype=np.int64).reshape(-1, 4)
    rest = np.asarray(mesh.rest, dtype=np.float64)
    l0_sq = np.sum((rest[wings[:, 1]] - rest[wings[:, 0]]) ** 2, axis=1)
    areas = np.asarray(mesh.face_areas, dtype=np.float64)
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    return l0_sq * theta ** 2 / (areas[pair[:, 0]] + areas[pair[:, 1]])


def classify_faces(x: np.ndarray, mesh, threshold_deg: float = DEFAULT_THRESHOLD_DEG
                   ) -> dict[str, np.ndarray]:
    """Per-hinge and per-face arrays of the measure: {"theta" (w,) rad, "hinge_bending" (w,),
    "face_bending" (t,) (half of each hinge to each of its faces), "bent" (t,) bool (a hinge
    past the threshold), "zigzag" (t,) bool (hinges past it bending both ways)}."""
    threshold_deg = _checked_threshold(threshold_deg)
    theta = hinge_angles(x, mesh)
    t = len(mesh.faces)
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    bend = hinge_bending(mesh, theta)
    face_bending = np.bincount(pair.ravel(), weights=np.repeat(0.5 * bend, 2), minlength=t)
    limit = np.radians(threshold_deg)
    up = np.bincount(pair.ravel(), weights=np.repeat(theta > limit, 2).astype(float),
                     minlength=t) > 0
    down = np.bincount(pair.ravel(), weights=np.repeat(theta < -limit, 2).astype(float),
                       minlength=t) > 0
    return {"theta": theta, "hinge_bending": bend, "face_bending": face_bending,
            "bent": up | down, "zigzag": up & down}


def _checked_threshold(threshold_deg: float) -> float:
    if not (isinstance(threshold_deg, (int, float)) and np.isfinite(threshold_deg)
            and 0.0 <= threshold_deg < 180.0):
        raise ClothInputError(f"--threshold must be in [0, 180) degrees, got {threshold_deg!r}")
    return float(threshold_deg)


def fold_figures(x: np.ndarray, mesh, threshold_deg: float = DEFAULT_THRESHOLD_DEG) -> dict:
    """The saw-teeth figures of positions x (n, 3) m on mesh (`MeshLevel`), hinges counted
    bent past threshold_deg degrees (module docstring):

    {"triangles", "hinges", "hinges_past_threshold", "bent_triangles" (a hinge past the
    threshold), "zigzag_triangles", "zigzag_share" (zig-zag over bent triangles),
    "bending_share" (the zig-zag triangles' share of all bending, each hinge's bending split
    between its faces), "bending_share_hinges" (the share on hinges touching a zig-zag
    triangle), "bending_total" (the sum of l0^2 theta^2 / (A0 + A1)), "theta_rms_deg",
    "theta_p95_deg", "theta_max_deg", "threshold_deg"}. Shares are fractions in [0, 1].
    """
    c = classify_faces(x, mesh, threshold_deg)
    theta, bend, zig = c["theta"], c["hinge_bending"], c["zigzag"]
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    total = float(bend.sum())
    bent = int(c["bent"].sum())
    on_zig = zig[pair].any(axis=1) if len(pair) else np.zeros(0, dtype=bool)
    deg = np.degrees(np.abs(theta))
    return {
        "threshold_deg": float(threshold_deg),
        "triangles": len(mesh.faces),
        "hinges": len(theta),
        "hinges_past_threshold": int((deg > threshold_deg).sum()),
        "bent_triangles": bent,
        "zigzag_triangles": int(zig.sum()),
        "zigzag_share": float(zig.sum() / bent) if bent else 0.0,
        "bending_share": float(c["face_bending"][zig].sum() / total) if total > 0 else 0.0,
        "bending_share_hinges": float(bend[on_zig].sum() / total) if total > 0 else 0.0,
        "bending_total": total,
        "theta_rms_deg": float(np.sqrt(np.mean(deg ** 2))) if len(deg) else 0.0,
        "theta_p95_deg": float(np.percentile(deg, 95)) if len(deg) else 0.0,
        "theta_max_deg": float(deg.max()) if len(deg) else 0.0,
    }


# ----------------------------------------------------------------------------------------
# The scenes
def walking_case(particles: int, messages: int = DEFAULT_MESSAGES, scene: str = "walking",
                 log=None, compression: str = "elastic") -> tuple[np.ndarray, object, dict]:
    """The body scene's garment after ``messages`` pose messages, stepped as `cloth-mg run
    --scene SCENE --particles N --steps MESSAGES` steps it (apps.runner.run_body_scene: one
    tick per message, the scene file's solver, tolerance and threads; tolerance auto from the
    cost model's calibration). Returns (positions (n, 3) m, the garment's MeshLevel, {"scene",
    "particles", "messages", "time_s" (since the first pose), "tolerance"}). compression: the
    membrane's (sim.model.build_model)."""
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
    params = load_scene(scene).replace(particles=particles)
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
    info = {"scene": params.scene, "particles": int(garment_sim.sim.model.n),
            "requested_particles": int(particles), "messages": int(len(frames) - 1),
            "time_s": float(frames[-1][0] - frames[first][0]),
            "tolerance": garment_sim.solve_tolerance(), "material": material.name,
            "solver": params.solver, "compression": compression}
    return garment_sim.positions.copy(), garment_sim.sim.model.mesh, info


def drape_case(particles: int, steps: int = DRAPE_STEPS, compression: str = "elastic"
               ) -> tuple[np.ndarray, object, dict]:
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
                        friction=DRAPE_FRICTION, compression=compression)
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
            "material": DRAPE_MATERIAL, "solver": DRAPE_SOLVER, "compression": compression}
    return sim.state.x.copy(), scene.model.mesh, info


def bench_folds(particles: list[int], messages: int = DEFAULT_MESSAGES,
                scene: str = "walking", drape_particles: list[int] = (),
                drape_steps: int = DRAPE_STEPS, threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                picture: str | Path | None = None, log=print,
                compression: str = "elastic") -> dict:
    """Measure the garment of ``scene`` at each particle count and the drape at each of
    ``drape_particles``: {"meta", "walking": [{**case info, **fold_figures}], "drape": [...]};
    with ``picture``, one PNG of the garment close up at every particle count
    (`closeup_picture`)."""
    _checked_threshold(threshold_deg)
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
        x, mesh, info = walking_case(n, messages, scene, log, compression)
        walking.append({**info, **fold_figures(x, mesh, threshold_deg)})
        log(_case_line(walking[-1]))
        if picture is not None:
            title = f"{info['scene']}, {info['particles']} particles, {info['time_s']:.2f} s"
            shots.append((title, x, mesh))
    for n in drape_particles:
        x, mesh, info = drape_case(n, drape_steps, compression)
        drape.append({**info, **fold_figures(x, mesh, threshold_deg)})
        log(_case_line(drape[-1]))
    pictures = [str(closeup_picture(shots, picture, threshold_deg))] if shots else []
    meta = {"machine": platform.node(), "cpus": os.cpu_count(),
            "platform": platform.platform(), "commit": _git("rev-parse", "--short", "HEAD"),
            "stretch_commit": _git("log", "-1", "--format=%h", "--",
                                   "cloth_mg_ros/physics/stretch.py"),
            "changed_files": _git("status", "--porcelain", "-uno"),
            "threads": {k: os.environ.get(k, "unset")
                        for k in ("OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")},
            "threshold_deg": float(threshold_deg), "pictures": pictures,
            "bending": "l0^2 theta^2 / (A0 + A1) per hinge (rest length, rest areas), half "
                       "to each of its two faces",
            "wall_s": time.perf_counter() - t0}
    return {"meta": meta, "walking": walking, "drape": drape}


def _git(*args: str) -> str | None:
    """A git command's output in this checkout (None outside one)."""
    root = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                             timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


def _case_line(row: dict) -> str:
    return (f"{row['scene']} {row['particles']} particles: {100 * row['zigzag_share']:.0f} % of "
            f"the bent triangles zig-zag, holding {100 * row['bending_share']:.0f} % of the "
            f"bending")


def format_report(result: dict) -> str:
    """One row per case: triangles, bent ones, the zig-zag shares, the hinges' angles."""
    rows = []
    for row in [*result["walking"], *result["drape"]]:
        rows.append([row["scene"], str(row["particles"]), str(row["triangles"]),
                     str(row["bent_triangles"]), str(row["zigzag_triangles"]),
                     f"{100 * row['zigzag_share']:.1f}", f"{100 * row['bending_share']:.1f}",
                     f"{100 * row['bending_share_hinges']:.1f}",
                     f"{row['theta_rms_deg']:.2f}", f"{row['theta_max_deg']:.1f}"])
    head = ["scene", "particles", "triangles", "bent", "zig-zag", "zig-zag %",
            "bending %", "hinges' %", "rms deg", "max deg"]
    return (f"hinges past {result['meta']['threshold_deg']:g} degrees; bending % : the "
            f"zig-zag triangles' share of all bending (hinges' %: of the hinges touching "
            f"one)\n" + text_table(head, rows))


# ----------------------------------------------------------------------------------------
# Chart and picture
def plot_folds(result: dict, png: str | Path, before: dict | None = None) -> Path:
    """Shares against particles (log axis), the garment and the drape, each labelled with its
    run's commit; ``before``: an earlier run's JSON drawn dashed."""
    # imported here: matplotlib loads only when a chart is drawn
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.8), sharey=True)
    for ax, key, title in ((axes[0], "zigzag_share", "bent triangles that zig-zag"),
                           (axes[1], "bending_share", "share of all bending they hold")):
        for runs, style in ((result, "-"), (before, "--")):
            if runs is None:
                continue
            commit = runs.get("meta", {}).get("commit")
            tag = f" ({commit})" if commit else ""
            for case, colour in (("walking", "C3"), ("drape", "C0")):
                rows = runs.get(case) or []
                if rows:
                    ax.plot([r["particles"] for r in rows], [100 * r[key] for r in rows],
                            style, marker="o", color=colour,
                            label=f"{rows[0]['scene']}{tag}")
        ax.set_xscale("log")
        ax.set_xlabel("particles")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.set_ylim(0, 100)
    axes[0].set_ylabel("%")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"one-triangle zig-zags: hinges past {result['meta']['threshold_deg']:g} "
                 f"degrees bending both ways", fontsize=10)
    fig.tight_layout()
    return save_chart(fig, png)


def closeup_picture(shots: list[tuple[str, np.ndarray, object]], png: str | Path,
                    threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                    radius: float = CLOSEUP_RADIUS) -> Path:
    """The garment close up, one row per shot (title, positions (n, 3) m, MeshLevel): left,
    each triangle shaded as io.render shades cloth (two-sided Lambert, the same light), where
    saw teeth show as light and dark triangles side by side; right, the same triangles
    coloured by the measure (zig-zag red, bent one way grey, not bent past the threshold
    white). The patch: the triangles within ``radius`` m of the point of the garment's middle
    height band nearest to the camera, a rule that does not look at the folds, so that runs
    before and after a change show the same place."""
    # imported here: matplotlib loads only when a picture is drawn
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from cloth_mg_ros.io.render import LIGHT

    camera = np.array([np.cos(np.radians(VIEW_ELEV)) * np.cos(np.radians(VIEW_AZIM)),
                       np.cos(np.radians(VIEW_ELEV)) * np.sin(np.radians(VIEW_AZIM)),
                       np.sin(np.radians(VIEW_ELEV))])
    fig = plt.figure(figsize=(8.0, 0.4 + 3.8 * len(shots)))
    for row, (title, x, mesh) in enumerate(shots):
        x = _checked_positions(x, mesh)
        faces = np.asarray(mesh.faces)
        z = x[:, 2]
        band = np.flatnonzero(np.abs(z - 0.5 * (z.min() + z.max())) <= 0.1 * np.ptp(z))
        centre = x[band[np.argmax((x[band] - x.mean(axis=0)) @ camera)]]
        keep = np.all(np.linalg.norm(x[faces] - centre, axis=2) < radius, axis=1)
        tri = x[faces[keep]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-15)
        shade = 0.35 + 0.65 * np.abs(normal @ LIGHT)
        c = classify_faces(x, mesh, threshold_deg)
        zig, bent = c["zigzag"][keep], c["bent"][keep]
        classes = np.where(zig[:, None], [0.85, 0.15, 0.15],
                           np.where(bent[:, None], [0.6, 0.6, 0.65], [0.97, 0.97, 0.97]))
        for col, colours in enumerate((shade[:, None] * np.array([0.30, 0.55, 0.85]),
                                       classes)):
            ax = fig.add_subplot(len(shots), 2, 2 * row + col + 1, projection="3d")
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colours,
                                                 edgecolors="k" if col else "none",
                                                 linewidths=0.15 if col else 0.0))
            ax.set_xlim(centre[0] - radius, centre[0] + radius)
            ax.set_ylim(centre[1] - radius, centre[1] + radius)
            ax.set_zlim(centre[2] - radius, centre[2] + radius)
            ax.set_box_aspect((1, 1, 1), zoom=1.5)
            ax.view_init(elev=VIEW_ELEV, azim=VIEW_AZIM)
            ax.set_axis_off()
            ax.set_title(title if col == 0 else
                         f"zig-zag {int(zig.sum())} of {int(keep.sum())} (red)", fontsize=9)
    fig.suptitle(f"{2 * radius * 100:.0f} cm of the garment: shaded, and the triangles whose "
                 f"hinges bend past {threshold_deg:g} degrees both ways", fontsize=10)
    fig.tight_layout()
    return save_chart(fig, png)


# ----------------------------------------------------------------------------------------
# Command line
def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench folds` on the bench sub-parsers."""
    p = bsub.add_parser("folds", help="folds, not saw teeth: the share of triangles whose "
                        "hinges bend past a few degrees both ways, and of the bending they "
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
                   help=f"a hinge is bent past this angle, degrees (default "
                        f"{DEFAULT_THRESHOLD_DEG:g})")
    p.add_argument("--compression", default="elastic", choices=("elastic", "buckle"),
                   help="the membrane under compression: elastic (resisted as in tension, "
                        "the default) or buckle (faces wrinkle, physics.wrinkles)")
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
                         args.threshold, args.picture, compression=args.compression)
    print(format_report(result))
    write_json(args.json, result)
    png = plot_folds(result, args.png, before)
    print(f"wrote {args.json} and {png}" + "".join(f", {p}" for p in result["meta"]["pictures"]))
    return 0
