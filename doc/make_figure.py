"""The README's picture: the walking dress on the capsule avatar, three moments of the walk.

Runs the walking scene headless through the package's library (the bundled bag `walk`, its
garment and material, a fixed particle count and tolerance so that the picture is the same on
every machine), keeps the cloth and the body's capsules at three poses, and draws them with a
small painter's-algorithm renderer: every capsule as a shaded cylinder with hemispherical
caps of its own radius, the cloth as shaded triangles (its inside darker), a soft shadow on
the floor. Writes doc/images/hero.png:

    .venv/bin/python doc/make_figure.py [--particles 2400] [--out doc/images/hero.png]

Takes about a minute on 2 cores (numba's cache warm: `make warm`).
"""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PolyCollection
from PIL import Image

HERE = Path(__file__).resolve().parent
# Bag message indices drawn (30 Hz; the walk starts at message 30 after a 1 s still lead-in).
SHOTS = (40, 52, 70, 76)
# The camera: looking from the front-left, a little from above (degrees).
AZIMUTH, ELEVATION = -62.0, 12.0
LIGHT = np.array([-0.45, -0.62, 0.64])  # towards the key light (world, z up): camera's left
SUN = np.array([0.08, -0.12, 1.0])  # towards the light that casts the floor shadows
BODY_RGB = np.array([0.88, 0.85, 0.80])
CLOTH_RGB = np.array([0.70, 0.16, 0.20])
CLOTH_INSIDE_RGB = np.array([0.42, 0.10, 0.12])
SHADOW_RGB = np.array([0.86, 0.86, 0.86])


def simulate(particles: int) -> list[tuple[float, np.ndarray, np.ndarray, tuple]]:
    """(time since the walk began, cloth positions, faces, capsules) at each of SHOTS."""
    from cloth_mg_ros.config.scenes import load_scene
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim

    params = load_scene("walking")
    options = BodySimOptions.from_scene(params, particles=particles, tolerance=1e-4, threads=0)
    frames = read_pose_frames(resolve_bag(params.bag), params.topic)
    avatar = Avatar.load()
    garment_sim = GarmentSim.dress(avatar, frames[0][0], frames[0][1],
                          get_material(params.material), options)
    shots = []
    for k in range(1, max(SHOTS) + 1):
        stamp, poses = frames[k]
        garment_sim.push(stamp, poses)
        if k in SHOTS:
            shots.append((stamp - frames[30][0], garment_sim.positions.copy(),
                          garment_sim.faces.copy(),
                          tuple(a.copy() for a in garment_sim.capsules())))
    print(f"{garment_sim.sim.model.n} particles, {len(garment_sim.faces)} triangles")
    return shots


def camera() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, towards the viewer) of an orthographic camera at AZIMUTH, ELEVATION."""
    az, el = np.radians(AZIMUTH), np.radians(ELEVATION)
    view = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross([0.0, 0.0, 1.0], view)
    right /= np.linalg.norm(right)
    return right, np.cross(view, right), view


def capsule_quads(p0: np.ndarray, p1: np.ndarray, r: float, around: int = 40,
                  rings: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Quads (q, 4, 3) and their outward normals (q, 3) of the capsule p0-p1 of radius r:
    a hemisphere at p0, the cylinder, a hemisphere at p1, as one strip of rings."""
    axis = p1 - p0
    length = np.linalg.norm(axis)
    a = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    theta = np.linspace(0.0, 2 * np.pi, around + 1)
    ring_dir = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    pts, nrm = [], []
    for centre, phis in ((p0, np.linspace(-np.pi / 2, 0.0, rings + 1)),
                         (p1, np.linspace(0.0, np.pi / 2, rings + 1))):
        for phi in phis:
            n = np.cos(phi) * ring_dir + np.sin(phi) * a
            pts.append(centre + r * n)
            nrm.append(n)
    pts, nrm = np.array(pts), np.array(nrm)  # (R, around + 1, 3)
    quads = np.stack([pts[:-1, :-1], pts[:-1, 1:], pts[1:, 1:], pts[1:, :-1]], axis=2)
    normals = nrm[:-1, :-1] + nrm[:-1, 1:] + nrm[1:, 1:] + nrm[1:, :-1]
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return quads.reshape(-1, 4, 3), normals.reshape(-1, 3)


def shade(rgb: np.ndarray, normals: np.ndarray, view: np.ndarray,
          shininess: float = 24.0, spec: float = 0.25) -> np.ndarray:
    """Per-face colours: ambient, Lambert from LIGHT, a soft fill light and a highlight."""
    light = LIGHT / np.linalg.norm(LIGHT)
    diffuse = np.clip(normals @ light, 0.0, None)
    fill = 0.5 * np.clip(normals @ np.array([0.6, 0.3, 0.2]), 0.0, None)
    half = (light + view) / np.linalg.norm(light + view)
    highlight = spec * np.clip(normals @ half, 0.0, None) ** shininess
    c = rgb * (0.24 + 0.72 * diffuse + 0.16 * fill)[:, None] + highlight[:, None]
    return np.clip(c, 0.0, 1.0)


def scene_polygons(cloth: np.ndarray, faces: np.ndarray, capsules: tuple, offset: np.ndarray
                   ) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, np.ndarray]:
    """Polygons (3D, shifted by offset), their colours and depths, and the floor shadows."""
    view = camera()[2]
    polys, colours, depths = [], [], []
    shadows = []
    sun = SUN / np.linalg.norm(SUN)

    def add(quads: np.ndarray, cols: np.ndarray) -> None:
        polys.extend(quads)
        colours.extend(cols)
        depths.extend(quads.mean(axis=1) @ view)

    def drop(quads: np.ndarray) -> None:  # shadow on z = 0 along the light
        t = quads[..., 2:3] / sun[2]
        shadows.extend(quads - t * sun)

    p0, p1, radius = capsules
    for a, b, r in zip(p0 + offset, p1 + offset, radius, strict=True):
        quads, normals = capsule_quads(a, b, float(r))
        drop(quads[::2])
        front = normals @ view > -0.05  # closed surfaces: the back faces are hidden anyway
        add(quads[front], shade(BODY_RGB, normals[front], view))

    tri = (cloth + offset)[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # twice the area, outward?
    # The garment's outward side: its normals point away from the body's axis, on average.
    centre = np.array([*(cloth.mean(axis=0) + offset)[:2], 0.0])
    radial = tri.mean(axis=1) - centre
    radial[:, 2] = 0.0
    if np.mean(np.sum(n * radial, axis=1)) < 0.0:
        n = -n
    # Smooth shading: area-weighted vertex normals, each face the mean of its corners' shades.
    vn = np.zeros_like(cloth)
    for corner in range(3):
        np.add.at(vn, faces[:, corner], n)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-15)
    facing = n @ view >= 0.0
    outside = shade(CLOTH_RGB, vn, view, spec=0.12)[faces].mean(axis=1)
    inside = shade(CLOTH_INSIDE_RGB, -vn, view, spec=0.0)[faces].mean(axis=1)
    cols = np.where(facing[:, None], outside, inside)
    add(tri, cols)
    drop(tri)
    return polys, colours, np.array(depths), shadows


def render(shots: list, out: Path) -> None:
    """Draw the shots side by side (each where its body stands, moved sideways on the page)
    and write a small PNG."""
    right, up, _ = camera()
    fig, ax = plt.subplots(figsize=(9.0, 4.6), dpi=150)
    ax.set_axis_off()
    ax.set_aspect("equal")
    xs, ys = [], []
    for i, (t, cloth, faces, capsules) in enumerate(shots):
        root = capsules[0][0]
        offset = -np.array([root[0], root[1], 0.0])
        polys, colours, depths, shadows = scene_polygons(cloth, faces, capsules, offset)
        shift = np.array([i * 0.95, 0.0])

        def project(p: np.ndarray, shift: np.ndarray = shift) -> np.ndarray:
            return np.stack([p @ right, p @ up], axis=-1) + shift

        flat_shadows = [project(s) for s in shadows]
        ax.add_collection(PolyCollection(flat_shadows, facecolors=SHADOW_RGB,
                                         edgecolors=SHADOW_RGB, linewidths=0.3, zorder=1))
        order = np.argsort(depths)
        flat = [project(polys[j]) for j in order]
        cols = np.array(colours)[order]
        ax.add_collection(PolyCollection(flat, facecolors=cols, edgecolors=cols,
                                         linewidths=0.25, zorder=2))
        pts = np.concatenate(flat)
        everything = np.concatenate([pts, *flat_shadows])
        xs += [everything[:, 0].min(), everything[:, 0].max()]
        ys += [everything[:, 1].min(), everything[:, 1].max()]
        ax.text(np.mean(pts[:, 0]), everything[:, 1].min() - 0.04, f"t = {t:.2f} s", ha="center",
                va="top", fontsize=8, color="0.35")
    ax.set_xlim(min(xs) - 0.1, max(xs) + 0.1)
    ax.set_ylim(min(ys) - 0.16, max(ys) + 0.04)
    fig.text(0.5, 0.02, "walking dress (CMU 07_01 walk), 16 capsules with their radii; "
             "implicit steps solved by the faithful multigrid", ha="center", fontsize=7.5,
             color="0.35")
    fig.subplots_adjust(0, 0.04, 1, 1)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150, facecolor="white")
    plt.close(fig)
    # A palette of 256 colours keeps the PNG small (the shading has few distinct tones).
    with Image.open(out) as im:
        small = im.convert("RGB").quantize(256, dither=Image.Dither.NONE)
    small.save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size // 1024} KB)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=2400)
    ap.add_argument("--out", type=Path, default=HERE / "images" / "hero.png")
    ap.add_argument("--cache", type=Path, default=None,
                    help="keep the simulated shots in this pickle and reuse them (restyling)")
    args = ap.parse_args()
    if args.cache is not None and args.cache.exists():
        shots = pickle.loads(args.cache.read_bytes())
    else:
        shots = simulate(args.particles)
        if args.cache is not None:
            args.cache.write_bytes(pickle.dumps(shots))
    render(shots, args.out)


if __name__ == "__main__":
    main()
