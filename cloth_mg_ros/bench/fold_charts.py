"""`cloth-mg bench folds`' chart and close-up picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.hinge_zigzag import DEFAULT_THRESHOLD_DEG, checked_positions, classify_faces
from cloth_mg_ros.bench.saw_teeth import classify_vertices

CLOSEUP_RADIUS = 0.15  # m: the half-width of the picture's patch of the garment
VIEW_ELEV, VIEW_AZIM = 15.0, -60.0  # degrees: the picture's camera, io.render's azimuth


def plot_folds(result: dict, png: str | Path, before: dict | None = None) -> Path:
    """Shares against particles (log axis), the garment and the drape, each labelled with its
    run's commit: the hinge measure above, the vertex measure below; ``before``: an earlier
    run's JSON drawn dashed (where it has the figure)."""
    # imported here: matplotlib loads only when a chart is drawn
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    panels = (("zigzag_share", "hinges: bent triangles that zig-zag"),
              ("bending_share", "hinges: share of all bending they hold"),
              ("vertex_saw_share", "vertices: bent vertices that are saw teeth"),
              ("vertex_bending_share", "vertices: share of all bending they hold"))
    fig, axes = plt.subplots(2, 2, figsize=(9.5, 7.2), sharey=True, sharex=True)
    for ax, (key, title) in zip(axes.ravel(), panels, strict=True):
        for runs, style in ((result, "-"), (before, "--")):
            if runs is None:
                continue
            commit = runs.get("meta", {}).get("commit")
            tag = f" ({commit})" if commit else ""
            for case, colour in (("walking", "C3"), ("drape", "C0")):
                rows = [r for r in runs.get(case) or [] if key in r]
                if rows:
                    ax.plot([r["particles"] for r in rows], [100 * r[key] for r in rows],
                            style, marker="o", color=colour,
                            label=f"{rows[0]['scene']}{tag}")
        ax.set_xscale("log")
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.set_ylim(0, 100)
    for ax in axes[1]:
        ax.set_xlabel("particles")
    for ax in axes[:, 0]:
        ax.set_ylabel("%")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"saw teeth past {result['meta']['threshold_deg']:g} degrees: triangles "
                 f"whose hinges bend both ways (above),\nvertices whose curvature flips "
                 f"against their neighbours' (below)", fontsize=10)
    fig.tight_layout()
    return save_chart(fig, png)


def closeup_picture(shots: list[tuple[str, np.ndarray, object]], png: str | Path,
                    threshold_deg: float = DEFAULT_THRESHOLD_DEG,
                    radius: float = CLOSEUP_RADIUS) -> Path:
    """The garment close up, one row per shot (title, positions (n, 3) m, MeshLevel): left,
    each triangle shaded as io.render shades cloth (two-sided Lambert, the same light), where
    saw teeth show as light and dark triangles side by side; middle, the same triangles
    coloured by the hinge measure (zig-zag red, bent one way grey, not bent past the threshold
    white); right, by the vertex measure (a triangle with a saw-tooth vertex red, with a bent
    one grey, else white). The patch: the triangles within ``radius`` m of the point of the
    garment's middle height band nearest to the camera, a rule that does not look at the
    folds, so that runs before and after a change show the same place."""
    # imported here: matplotlib loads only when a picture is drawn
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from cloth_mg_ros.io.render import LIGHT

    camera = np.array([np.cos(np.radians(VIEW_ELEV)) * np.cos(np.radians(VIEW_AZIM)),
                       np.cos(np.radians(VIEW_ELEV)) * np.sin(np.radians(VIEW_AZIM)),
                       np.sin(np.radians(VIEW_ELEV))])
    fig = plt.figure(figsize=(11.5, 0.4 + 3.8 * len(shots)))
    for row, (title, x, mesh) in enumerate(shots):
        x = checked_positions(x, mesh)
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
        v = classify_vertices(x, mesh, threshold_deg)
        saw = v["saw"][faces[keep]].any(axis=1)
        titles = (title, f"hinges: zig-zag {int(zig.sum())} of {int(keep.sum())} (red)",
                  f"vertices: {int(saw.sum())} touch a saw tooth (red)")
        for col, colours in enumerate((shade[:, None] * np.array([0.30, 0.55, 0.85]),
                                       _classes(zig, bent),
                                       _classes(saw, v["bent"][faces[keep]].any(axis=1)))):
            ax = fig.add_subplot(len(shots), 3, 3 * row + col + 1, projection="3d")
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colours,
                                                 edgecolors="k" if col else "none",
                                                 linewidths=0.15 if col else 0.0))
            ax.set_xlim(centre[0] - radius, centre[0] + radius)
            ax.set_ylim(centre[1] - radius, centre[1] + radius)
            ax.set_zlim(centre[2] - radius, centre[2] + radius)
            ax.set_box_aspect((1, 1, 1), zoom=1.5)
            ax.view_init(elev=VIEW_ELEV, azim=VIEW_AZIM)
            ax.set_axis_off()
            ax.set_title(titles[col], fontsize=9)
    fig.suptitle(f"{2 * radius * 100:.0f} cm of the garment: shaded; the triangles whose "
                 f"hinges bend past {threshold_deg:g} degrees both ways; the vertices whose "
                 f"curvature flips against their neighbours'", fontsize=10)
    fig.tight_layout()
    return save_chart(fig, png)


def _classes(saw: np.ndarray, bent: np.ndarray) -> np.ndarray:
    """(t, 3) colours: saw teeth red, bent grey, the rest white."""
    return np.where(saw[:, None], [0.85, 0.15, 0.15],
                    np.where(bent[:, None], [0.6, 0.6, 0.65], [0.97, 0.97, 0.97]))
