"""Pictures of cloth frames (matplotlib, headless): a strip of shaded 3-D views."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def _face_colours(x: np.ndarray, faces: np.ndarray, base: tuple) -> np.ndarray:
    """Two-sided Lambert shading per face, (t, 4) RGBA."""
    n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
    shade = 0.35 + 0.65 * np.abs(n @ LIGHT)
    rgba = np.empty((len(faces), 4))
    rgba[:, :3] = shade[:, None] * np.asarray(base)[None, :]
    rgba[:, 3] = 1.0
    return rgba


def _sphere_mesh(centre: np.ndarray, radius: float, res: int = 20):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, res), np.linspace(0, np.pi, res // 2))
    return (centre[0] + radius * np.cos(u) * np.sin(v), centre[1] + radius * np.sin(u) * np.sin(v),
            centre[2] + radius * np.cos(v))


def render_frames(
    path: str | Path,
    frames: list[tuple[float, np.ndarray]],
    faces: np.ndarray,
    spheres: list[tuple[np.ndarray, float]] = (),
    title: str = "",
    capsules_per_frame: list | None = None,
) -> Path:
    """Write a PNG strip with one shaded 3-D view per frame.

    frames: [(time s, positions (n, 3) m)]; faces (t, 3); spheres: [(centre (3,), radius)]
    drawn as wireframes; capsules_per_frame: optional per-frame list of segments
    [(p0 (3,), p1 (3,), radius)] drawn as thick lines (a body).
    """
    path = Path(path)
    k = max(1, len(frames))
    fig = plt.figure(figsize=(3.2 * k, 3.6), dpi=110)
    # One scale for every frame, each frame centred on its own content (a walking body
    # leaves the first frame's box).
    boxes = []
    for idx, (_, x) in enumerate(frames):
        pts = [x]
        if capsules_per_frame is not None:
            pts += [np.stack([p0, p1]) for p0, p1, _ in capsules_per_frame[idx]]
        pts += [np.stack([np.asarray(c) - r, np.asarray(c) + r]) for c, r in spheres]
        allp = np.concatenate(pts)
        boxes.append((allp.min(axis=0), allp.max(axis=0)))
    span = max(float(np.max(hi - lo)) for lo, hi in boxes) / 2 * 1.05 + 1e-9 if boxes else 1.0
    for idx, (t, x) in enumerate(frames):
        centre = 0.5 * (boxes[idx][0] + boxes[idx][1])
        ax = fig.add_subplot(1, k, idx + 1, projection="3d")
        poly = Poly3DCollection(x[faces], facecolors=_face_colours(x, faces, (0.30, 0.55, 0.85)),
                                edgecolors="none", linewidths=0.0,
                                antialiased=False)
        ax.add_collection3d(poly)
        for c, r in spheres:
            ax.plot_wireframe(*_sphere_mesh(np.asarray(c), r), color="0.6", linewidth=0.4)
        if capsules_per_frame is not None:
            for p0, p1, r in capsules_per_frame[idx]:
                ax.plot(*np.stack([p0, p1]).T, color="0.35", linewidth=max(1.0, 60 * r),
                        solid_capstyle="round")
        ax.set_xlim(centre[0] - span, centre[0] + span)
        ax.set_ylim(centre[1] - span, centre[1] + span)
        ax.set_zlim(centre[2] - span, centre[2] + span)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=22, azim=-60)
        ax.set_axis_off()
        ax.set_title(f"t = {t:.2f} s", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
