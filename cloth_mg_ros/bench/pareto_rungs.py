"""The level of detail (its rungs, sim.detail) as an axis of speed against accuracy: the fourth
part of `cloth-mg bench pareto`.

The settled garment (bench.pareto.settled_garment) runs the clip at every level it may be
simulated at live (sim.detail.rung_indices: the finest and each coarser level of its
hierarchy with at least MIN_RUNG_PARTICLES), all with the scenes' solver and tolerance, so
that only the resolution differs. A coarser level's cloth is compared with the finest's as a
user sees it: its surface carried to the finest mesh with the hierarchy's prolongations (the
coarse vertices as they are, every finer vertex on the coarse triangles), vertex by vertex.

Per level:

* ``interval``: from the finest's own state before each pose message, restricted to the
  level (what a live step down does), one message at that level against the finest's next
  state: what a tick at that level gives up, which nothing amplifies (mean RMS over the
  intervals, the worst interval's RMS and the largest distance); beside it ``shape``: the
  finest's states against their own restriction, displayed, before any step: the part of the
  interval's figure that is the coarser mesh's missing detail, not its motion;
* ``clip``: the whole clip at that level from the settled state against the finest's clip;
  beside it ``floor``: the finest's clip from a start displaced by 1 um against itself (over
  a second any change grows to tens of mm: ../shared/DESIGN.md, "How far one trajectory can
  be trusted"), so a clip error near the floor says the level changes no more than chaos does;
* what a user sees, over the clip: the deepest penetration of the displayed surface into the
  body or floor (the prolongated vertices, which include points on the coarse triangles
  between the coarse vertices), the worst stretch of the level's own edges (length over rest
  length, minus one), and the drape's silhouette: the garment's outline seen from the side
  (x-z) and the front (y-z), rasterised at SILHOUETTE_PX, as the intersection over the union
  with the finest's (1: the same outline);
* speed: ms per tick (median over the clip) and steps per tick.
"""

from __future__ import annotations

import copy

import numpy as np

from cloth_mg_ros.bench.pareto_steps import PERTURBATION_M, plot_interval_and_clip
from cloth_mg_ros.budget.tolerance_rule import one_message
from cloth_mg_ros.budget.tolerance_rule import rms_max_mm as _rms_max
from cloth_mg_ros.collision.colliders import penetration
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.sim.tick_stats import TickStats

SILHOUETTE_PX = 0.004  # m per pixel of the outline's raster


def prolongate_positions(hierarchy, x: np.ndarray, level: int) -> np.ndarray:
    """Positions (n_level, 3) at hierarchy ``level`` carried to the finest level (n_0, 3)
    with the hierarchy's prolongations: the displayed coarse surface at the fine vertices."""
    for k in range(level - 1, -1, -1):
        x = hierarchy.transfers[k].prolongation() @ x
    return x


def silhouette_iou(a: np.ndarray, b: np.ndarray, faces: np.ndarray,
                   px: float = SILHOUETTE_PX) -> float:
    """Intersection over union of two cloth outlines of the same mesh (positions (n, 3) m,
    faces (f, 3)), seen from the side (x-z) and from the front (y-z): both views' pixels
    summed."""
    # imported here: pillow is the 'bench' extra's, and cloth-mg's parser imports this module
    from PIL import Image, ImageDraw

    inter = union = 0
    for axis in (0, 1):
        lo = np.minimum(a.min(axis=0), b.min(axis=0)) - 2 * px
        hi = np.maximum(a.max(axis=0), b.max(axis=0)) + 2 * px
        size = np.ceil((hi - lo) / px).astype(int) + 1
        masks = []
        for x in (a, b):
            img = Image.new("1", (int(size[axis]), int(size[2])), 0)
            draw = ImageDraw.Draw(img)
            uv = np.stack([(x[:, axis] - lo[axis]) / px, (hi[2] - x[:, 2]) / px], axis=1)
            for tri in uv[faces]:
                draw.polygon([tuple(p) for p in tri], fill=1)
            masks.append(np.asarray(img, dtype=bool))
        inter += int(np.count_nonzero(masks[0] & masks[1]))
        union += int(np.count_nonzero(masks[0] | masks[1]))
    return inter / union if union else 1.0


def _with_solver(base, solver: str, tol: float):
    """A copy of the settled garment `base` solving with `solver` at `tol` on every level,
    every level's simulation built."""
    garment_sim = copy.deepcopy(base)
    garment_sim.set_solver(solver, tol)
    garment_sim.prepare_rungs()
    return garment_sim


def _clip(garment_sim, frames: list, level: int, exclude: np.ndarray) -> dict:
    """Run garment_sim at `level` over frames: {"x": displayed positions at the finest
    vertices after every message (T, n_0, 3), "snaps": snapshots before every message (at
    level 0 only), "ms", "steps", "penetration_mm", "stretch"}."""
    garment_sim.set_rung(level)
    mesh = garment_sim.sim.model.mesh
    edges = np.asarray(mesh.edges)
    rest = np.linalg.norm(mesh.rest[edges[:, 1]] - mesh.rest[edges[:, 0]], axis=1)
    out, snaps, ms, steps = [], [], [], []
    deepest = stretch = 0.0
    for stamp, poses in frames:
        if level == 0:
            snaps.append(garment_sim.snapshot())
        stats = garment_sim.push(stamp, poses)
        if not isinstance(stats, TickStats) or not np.all(np.isfinite(garment_sim.positions)):
            raise FloatingPointError(f"level {level}: the tick at {stamp:.3f} s failed")
        x = garment_sim.positions
        shown = prolongate_positions(garment_sim.garment.hierarchy, x, level)
        out.append(shown)
        ms.append(stats.total_ms)
        steps.append(stats.substeps)
        deepest = max(deepest, penetration(garment_sim.sim.state.colliders(garment_sim.sim.model),
                                             shown, exclude))
        length = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1)
        stretch = max(stretch, float(np.max(length / rest)) - 1.0)
    return {"x": np.array(out), "snaps": snaps, "ms": float(np.median(ms)),
            "steps": float(np.mean(steps)), "penetration_mm": 1e3 * deepest,
            "stretch": stretch}


def _intervals(garment_sim, frames: list, snaps: list, level: int) -> tuple[np.ndarray, float]:
    """From each of the finest's snapshots, restricted to `level`, one message at that
    level: (the results displayed at the finest vertices (T, n_0, 3), the mean RMS in mm of
    the finest's states against their own restriction displayed: what the level's mesh
    cannot show before it takes any step)."""
    out, shape = [], []
    hier = garment_sim.garment.hierarchy
    n = garment_sim.rung_particles(level)
    for snap, frame in zip(snaps, frames, strict=True):
        x = snap.state.x
        shape.append(_rms_max(prolongate_positions(hier, x[:n], level), x)[0])
        out.append(prolongate_positions(hier, one_message(garment_sim, snap, level, frame)[0],
                                        level))
    garment_sim.set_rung(0)
    return np.array(out), float(np.mean(shape))


def rung_axis(base, frames: list, solver: str = "mpcg", tol: float = 1e-4,
              log=print) -> dict:
    """Part 4 of bench pareto (module docstring) from a settled garment `base` (a GarmentSim
    at level 0) over `frames`. Returns {"levels": [{"level", "particles", "ms_per_tick",
    "steps_per_tick", "interval_rms_mm", "interval_worst_rms_mm", "interval_max_mm",
    "shape_rms_mm",
    "clip_rms_mm", "clip_max_mm", "penetration_mm", "stretch", "silhouette_iou",
    "silhouette_iou_interval"}], "floor_mm": {"rms", "max", "perturbation_m"},
    "floor_silhouette_iou", "solver", "tol"}; lengths in mm, times in ms."""
    garment_sim = _with_solver(base, solver, tol)
    levels = garment_sim.rung_indices()
    faces = np.asarray(garment_sim.rungs[0].model.mesh.faces)
    exclude = garment_sim.rungs[0].model.fixed_mask()
    start = garment_sim.snapshot()
    fine = _clip(garment_sim, frames, 0, exclude)
    moved = _with_solver(base, solver, tol)
    moved.sim.state.x = moved.sim.state.x + np.random.default_rng(0).normal(
        0.0, PERTURBATION_M, moved.sim.state.x.shape)
    bumped = _clip(moved, frames, 0, exclude)
    floor = _rms_max(bumped["x"], fine["x"])
    floor_iou = float(np.mean([silhouette_iou(a, b, faces)
                               for a, b in zip(bumped["x"], fine["x"], strict=True)]))
    rows = []
    for level in levels:
        garment_sim.set_rung(0)
        garment_sim.restore(start)
        run = fine if level == 0 else _clip(garment_sim, frames, level, exclude)
        row = {"level": level, "particles": garment_sim.rung_particles(level),
               "ms_per_tick": run["ms"], "steps_per_tick": run["steps"],
               "penetration_mm": run["penetration_mm"], "stretch": run["stretch"]}
        if level == 0:
            row.update(interval_rms_mm=0.0, interval_worst_rms_mm=0.0, interval_max_mm=0.0,
                       shape_rms_mm=0.0, clip_rms_mm=0.0, clip_max_mm=0.0, silhouette_iou=1.0,
                       silhouette_iou_interval=1.0)
        else:
            ends, shape = _intervals(garment_sim, frames, fine["snaps"], level)
            ref_next = fine["x"]
            per = [_rms_max(e, r) for e, r in zip(ends, ref_next, strict=True)]
            clip = _rms_max(run["x"], fine["x"])
            row.update(
                interval_rms_mm=float(np.mean([p[0] for p in per])),
                interval_worst_rms_mm=float(max(p[0] for p in per)),
                interval_max_mm=float(max(p[1] for p in per)), shape_rms_mm=shape,
                clip_rms_mm=clip[0], clip_max_mm=clip[1],
                silhouette_iou=float(np.mean([silhouette_iou(a, b, faces) for a, b in
                                              zip(run["x"], fine["x"], strict=True)])),
                silhouette_iou_interval=float(np.mean([silhouette_iou(a, b, faces) for a, b
                                                       in zip(ends, ref_next, strict=True)])))
        rows.append(row)
        log(f"  level {level} ({row['particles']} particles): {row['ms_per_tick']:.1f} ms/tick;"
            f" per interval {row['interval_rms_mm']:.2f} mm RMS (worst "
            f"{row['interval_worst_rms_mm']:.2f}), clip {row['clip_rms_mm']:.1f} mm RMS; "
            f"penetration {row['penetration_mm']:.1f} mm, stretch {100 * row['stretch']:.1f} %,"
            f" silhouette IoU {row['silhouette_iou']:.3f}")
    log(f"  floor: a {1e6 * PERTURBATION_M:g} um start perturbation of the finest grows to "
        f"{floor[0]:.1f} mm RMS over the clip (silhouette IoU {floor_iou:.3f})")
    return {"levels": rows, "solver": solver, "tol": tol,
            "floor_mm": {"rms": floor[0], "max": floor[1], "perturbation_m": PERTURBATION_M},
            "floor_silhouette_iou": floor_iou}


def format_rung_axis(part: dict) -> list[str]:
    """Report lines for part 4."""
    rows = [[str(r["level"]), str(r["particles"]), f"{r['ms_per_tick']:.1f}",
             f"{r['shape_rms_mm']:.2f}", f"{r['interval_rms_mm']:.2f}",
             f"{r['interval_worst_rms_mm']:.2f}", f"{r['clip_rms_mm']:.1f}",
             f"{r['penetration_mm']:.1f}",
             f"{100 * r['stretch']:.1f}", f"{r['silhouette_iou_interval']:.3f}",
             f"{r['silhouette_iou']:.3f}"] for r in part["levels"]]
    floor = part["floor_mm"]
    return ["", (f"levels of detail against the finest ({part['solver']} at tol "
                 f"{part['tol']:g}; mm): per pose interval from the finest's states, and over "
                 f"the clip; what a user sees over the clip"),
            text_table(["level", "particles", "ms/tick", "shape RMS", "interval RMS",
                        "worst interval",
                        "clip RMS", "penetration", "stretch %", "outline IoU (interval)",
                        "outline IoU (clip)"], rows),
            (f"floor: a {1e6 * floor['perturbation_m']:g} um perturbation of the finest's start "
             f"grows to {floor['rms']:.1f} mm RMS ({floor['max']:.0f} max) over the clip, "
             f"outline IoU {part['floor_silhouette_iou']:.3f}")]


def plot_rung_axis(ax, part: dict) -> None:
    """ms per tick against the deviation from the finest, a point per level (per interval
    and over the clip), the perturbation floor as a line."""
    rows = part["levels"][1:]
    plot_interval_and_clip(ax, rows, [f"level {r['level']}: {r['particles']} p, IoU "
                                      f"{r['silhouette_iou']:.2f}" for r in rows],
                           part["floor_mm"], "per pose interval (from the finest's states)",
                           "over the clip", "-")
    fine = part["levels"][0]
    ax.axvline(fine["ms_per_tick"], color="grey", linestyle="-.",
               label=f"finest ({fine['particles']} p) ms/tick")
    ax.set_xlabel(f"ms per tick ({part['solver']} {part['tol']:g})")
    ax.set_ylabel("RMS distance from the finest level (mm)")
    ax.set_title("what a step down gives up", fontsize=10)
    ax.legend(fontsize=7)
