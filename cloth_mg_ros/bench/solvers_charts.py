"""The chart of `cloth-mg bench solvers`: ms per solve against particles, and per material."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import log_log_solver_axes, save_chart
from cloth_mg_ros.bench.paper_tables import PAPER_SIZE_MATCH, PAPER_TABLE3, PAPER_TABLE4


def plot_solvers(result: dict, png: str | Path) -> list[Path]:
    """Write the chart(s): ms per solve against particles (log-log, one line per solver and
    material; crosses for runs that did not converge, open squares for skipped ones, the
    paper's Table 3 dashed); with several materials a second panel of bars per material
    and solver at the largest size (the paper's Table 4). Returns the written paths."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    runs = [r for r in result["runs"] if r["ms_per_solve"] is not None]
    solvers = list(dict.fromkeys(r["solver"] for r in result["runs"]))
    materials = list(dict.fromkeys(r["material"] for r in result["runs"]))
    colours = {s: plt.cm.tab10(i % 10) for i, s in enumerate(solvers)}
    two = len(materials) > 1
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(13 if two else 7.5, 5.5),
                             squeeze=False)
    _plot_solve_times(axes[0, 0], runs, solvers, materials, colours, result["meta"])
    if two:
        _plot_per_material(axes[0, 1], runs, solvers, materials, colours, result["meta"])
    fig.tight_layout()
    return [save_chart(fig, png)]


_MATERIAL_STYLES = ["-", "--", ":", "-.", (0, (5, 1))]  # line style of each material


def _plot_solve_times(ax, runs: list[dict], solvers: list[str], materials: list[str],
                      colours: dict, meta: dict) -> None:
    """ms per solve against particles: a line per solver and material, the paper's Table
    3 dashed, the runs that did not converge crossed, the skipped ones in open squares."""
    styles = _MATERIAL_STYLES
    for mi, mat in enumerate(materials):
        for s in solvers:
            rs = sorted((r for r in runs if r["solver"] == s and r["material"] == mat),
                        key=lambda r: r["particles"])
            if not rs:
                continue
            n = [r["particles"] for r in rs]
            ms = [r["ms_per_solve"] for r in rs]
            ax.plot(n, ms, linestyle=styles[mi % len(styles)], marker="o", color=colours[s],
                    label=s if mi == 0 else None)
            for r in rs:
                if r["skipped"]:
                    ax.plot(r["particles"], r["ms_per_solve"], marker="s", ms=11,
                            mfc="none", mec="grey", mew=1.5, linestyle="none")
                elif not r["converged"]:
                    ax.plot(r["particles"], r["ms_per_solve"], marker="x", ms=12, color="red",
                            mew=2.5, linestyle="none")
    if len(materials) > 1:
        for mi, mat in enumerate(materials):
            ax.plot([], [], linestyle=styles[mi % len(styles)], color="black", label=mat)
    paper_n = PAPER_TABLE3["particles"]
    for key, label in (("pcg", "paper PCG (2008 CPU)"), ("mg", "paper MG (2008 CPU)")):
        ax.plot(paper_n, PAPER_TABLE3[key], linestyle="--", color="black" if key == "mg"
                else "grey", alpha=0.5, marker=".", label=label)
    log_log_solver_axes(ax, "ms per solve (median, setup included)")
    ax.set_title(f"{meta['scene']}, {', '.join(materials)}: tol {meta['tol']:g}, "
                 f"{meta['systems']} systems after contact", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)


def _plot_per_material(ax2, runs: list[dict], solvers: list[str], materials: list[str],
                       colours: dict, meta: dict) -> None:
    """Bars per material and solver at the largest size (hatched: not converged or
    skipped), the paper's Table 4 beside them when the size matches it."""
    size = max(r["particles"] for r in runs) if runs else 0
    width = 0.8 / max(1, len(solvers))
    x = np.arange(len(materials))
    for si, s in enumerate(solvers):
        vals, bad = [], []
        for mat in materials:
            r = next((r for r in runs if r["solver"] == s and r["material"] == mat
                      and r["particles"] == size), None)
            vals.append(np.nan if r is None else r["ms_per_solve"])
            bad.append(r is not None and (not r["converged"] or r["skipped"]))
        if all(np.isnan(vals)):
            continue
        bars = ax2.bar(x + (si - (len(solvers) - 1) / 2) * width, vals, width,
                       color=colours[s], label=s)
        for b, flag in zip(bars, bad, strict=True):
            if flag:
                b.set_hatch("xx")
                b.set_edgecolor("red")
    if abs(size / PAPER_TABLE4["particles"] - 1.0) <= PAPER_SIZE_MATCH:
        for key, mk in (("pcg", "v"), ("mg", "^")):
            ax2.plot(x, [PAPER_TABLE4[key].get(m, np.nan) for m in materials], mk,
                     color="black", linestyle="none", label=f"paper {key.upper()} (Table 4)")
    ax2.set_xticks(x, materials)
    ax2.set_yscale("log")
    ax2.set_ylabel("ms per solve")
    ax2.set_title(f"{size} particles, tol {meta['tol']:g}: per material "
                  "(hatched: not converged or skipped)", fontsize=10)
    ax2.grid(True, axis="y", which="both", alpha=0.3)
    ax2.legend(fontsize=7, ncol=2)
