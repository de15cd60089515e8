"""Pictures of the textile tests: cantilever profiles over the exact elastica, DC against
bending length (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cloth_mg_ros.fidelity.cantilever import centre_profile
from cloth_mg_ros.fidelity.elastica import elastica


def chart_pyplot():
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib.pyplot as plt

    return plt


def save_chart_png(plt: object, fig: object, path: str | Path) -> Path:
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def cantilever_picture(path: str | Path, items: list) -> Path:
    """Side view of settled strips over their exact elastica curves, in units of l.

    items: [(CantileverScene, settled ClothState, measure() block), ...].
    """
    profiles = [{"gamma": block["gamma"],
                 "label": f"G {block['gamma']:.3g}, {block['mesh']} "
                          f"{block['orientation_deg']:g} deg: tip off by "
                          f"{block['tip_error_pct_of_overhang']:.2f} % of l",
                 "profile": centre_profile(scene, state) / scene.spec.overhang}
                for scene, state, block in items]
    return cantilever_profiles_chart(path, profiles)


def cantilever_profiles_chart(path: str | Path, profiles: list[dict]) -> Path:
    """The same picture from stored profiles: [{"gamma", "label", "profile": [[x, z], ...]
    (units of l)}, ...] (what `bench fidelity` keeps in its JSON)."""
    plt = chart_pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 5.0))
    for k, item in enumerate(profiles):
        exact = elastica(item["gamma"])
        colour = f"C{k % 10}"
        ax.plot(exact.x, -exact.z, "-", color=colour, lw=1.0, alpha=0.6)
        prof = np.asarray(item["profile"])
        ax.plot(prof[:, 0], -prof[:, 1], "o", ms=2.5, color=colour, label=item["label"])
    ax.plot([-0.15, 0.0], [0.0, 0.0], color="k", lw=3)
    ax.set_aspect("equal")
    ax.set_xlabel("reach / l")
    ax.set_ylabel("height / l")
    ax.set_title("cantilever: simulated strips (dots) over the exact heavy elastica (lines)")
    ax.legend(fontsize=6, loc="lower left")
    return save_chart_png(plt, fig, path)


def drape_chart(path: str | Path, rows: list[dict]) -> Path:
    """DC (mean and spread over the perturbed starts) against bending length, one point per
    fabric: rows [{"material", "bending_length_cm", "dc_mean", "dc_min", "dc_max"}, ...]."""
    plt = chart_pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    c = np.array([r["bending_length_cm"] for r in rows])
    mean = np.array([r["dc_mean"] for r in rows])
    lo = mean - np.array([r["dc_min"] for r in rows])
    hi = np.array([r["dc_max"] for r in rows]) - mean
    ax.errorbar(c, mean, yerr=[lo, hi], fmt="o", capsize=3)
    for r in rows:
        ax.annotate(r["material"], (r["bending_length_cm"], r["dc_mean"]), fontsize=7,
                    xytext=(4, 3), textcoords="offset points")
    ax.set_xlabel("bending length (B / (rho g))^(1/3), cm")
    ax.set_ylabel("drape coefficient DC")
    ax.set_title("Cusick drape (30 cm on 18 cm): mean and range over perturbed starts")
    return save_chart_png(plt, fig, path)
