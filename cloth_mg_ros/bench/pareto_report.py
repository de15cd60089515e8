"""`cloth-mg bench pareto`'s report: the printed tables and the chart of a result
(bench.pareto's JSON-ready dict)."""

from __future__ import annotations

import math
from pathlib import Path

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.pareto_rungs import format_rung_axis, plot_rung_axis
from cloth_mg_ros.bench.pareto_runs import DEFAULT_SOLVER, DEFAULT_TOL
from cloth_mg_ros.bench.pareto_steps import format_step_rules, plot_step_rules
from cloth_mg_ros.bench.pareto_tolerance import format_tolerance_axis, plot_tolerance_axis
from cloth_mg_ros.io.text_table import text_table

ERROR_BUDGET_MM = 1.0  # the target: RMS error below 1 mm at the default tolerance


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (ms, error) that no other point beats in both (lower is
    better), ordered by ms."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


# -- the benchmark ------------------------------------------------------------------------


def fronts(result: dict) -> dict[str, list[dict]]:
    """Each solver's Pareto front (runs ordered by ms per tick)."""
    out = {}
    for solver in dict.fromkeys(r["solver"] for r in result["runs"]):
        rs = [r for r in result["runs"] if r["solver"] == solver and r["available"]
              and math.isfinite(r["rms_mm"])]
        out[solver] = [rs[i] for i in pareto_front([(r["ms_per_tick"], r["rms_mm"])
                                                    for r in rs])]
    return out


def _label(r: dict) -> str:
    return f"{r['solver']}" + (f" L{r['levels']}" if r["levels"] else "") + f" {r['tol']:.0e}"


def format_pareto_report(result: dict) -> str:
    """The printed tables: per solver its Pareto front; the fastest run within the error
    budget; error against particles."""
    meta, ref = result["meta"], result["reference"]
    lines = [(f"bench pareto: {meta['garment']} on {Path(meta['bag']).name}, {meta['material']}, "
             f"{ref['particles']} particles ({ref['levels']} levels), {meta['steps']} pose "
             f"messages after a {meta['settle_s']:g} s settle, BLAS threads "
             f"{meta.get('blas_threads', '?')}, {meta['machine']}"),
             (f"reference: exact (direct) solves at the scene's step, {ref['ms_per_tick']:.1f} "
             f"ms/tick; the step's own error (against {meta['ref_substep_factor']}x substeps): "
             f"{ref['time_rms_mm']:.3f} mm RMS, {ref['time_max_mm']:.2f} mm max"), ""]
    rows = []
    for solver, front in fronts(result).items():
        for r in front:
            rows.append([solver, str(r["levels"] or "-"), f"{r['tol']:.0e}",
                         f"{r['ms_per_tick']:.1f}", f"{r['iterations']:.1f}",
                         f"{r['rms_mm']:.4f}", f"{r['max_mm']:.3f}",
                         "yes" if r["converged"] else "NO"])
    lines += ["Pareto fronts (ms per tick against RMS error vs exact solves)",
              text_table(["solver", "levels", "tol", "ms/tick", "it/solve", "RMS mm", "max mm",
                      "converged"], rows), ""]
    ok = [r for r in result["runs"] if r["available"] and r["rms_mm"] < ERROR_BUDGET_MM]
    if ok:
        best = min(ok, key=lambda r: r["ms_per_tick"])
        lines.append(f"fastest within {ERROR_BUDGET_MM:g} mm RMS: {_label(best)} "
                     f"({best['ms_per_tick']:.1f} ms/tick, {best['rms_mm']:.4f} mm)")
    at_default = [r for r in result["runs"] if r["available"] and r["solver"] == DEFAULT_SOLVER
                  and r["tol"] == DEFAULT_TOL]
    for r in at_default:
        lines.append(f"default ({_label(r)}): {r['rms_mm']:.4f} mm RMS, {r['max_mm']:.3f} mm "
                     f"max: {'within' if r['rms_mm'] < ERROR_BUDGET_MM else 'ABOVE'} the "
                     f"{ERROR_BUDGET_MM:g} mm target")
    if result.get("steps"):
        lines += format_step_rules(result["steps"])
    if result.get("lod_levels"):
        lines += format_rung_axis(result["lod_levels"])
        lines += format_tolerance_axis(result["lod_tolerance"])
    if result["sizes"]:
        rows = [[str(s["particles"]), str(s["levels"]), f"{s['ms_per_tick']:.1f}",
                 f"{s['solver_rms_mm']:.4f}", f"{s['time_rms_mm']:.3f}",
                 f"{s['resolution_rms_mm']:.2f}" if "resolution_rms_mm" in s else "-"]
                for s in result["sizes"]]
        lines += ["", (f"error against particles (RMS mm; {meta['default_solver']} at tol "
                  f"{meta['default_tol']:g}; resolution against {meta['finest']} particles)"),
                  text_table(["particles", "levels", "ms/tick", "solver", "time step",
                          "resolution"], rows)]
    return "\n".join(lines)


def plot_pareto(result: dict, png: str | Path) -> Path:
    """Two panels: ms per tick against RMS error, every run a dot and each solver's front a
    line (the time-step error and the 1 mm budget as lines); and error against particles
    (solver, time step, resolution; only when sizes were run); then one panel per further
    part. Returns the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    # (plot, its data) per panel; `--sizes ''` runs no size: no empty panel for them
    drawn = [(_plot_fronts, result)] + ([(_plot_sizes, result)] if result.get("sizes") else [])
    drawn += [(plot, result[key]) for key, plot in (("steps", plot_step_rules),
                                                   ("lod_levels", plot_rung_axis),
                                                   ("lod_tolerance", plot_tolerance_axis))
              if result.get(key)]
    panels = len(drawn)
    cols = min(panels, 3)
    rows = (panels + cols - 1) // cols
    fig, grid = plt.subplots(rows, cols, figsize=(7 * cols, 6 * rows), squeeze=False)
    axes = list(grid.ravel())
    for ax in axes[panels:]:
        ax.set_axis_off()
    for ax, (plot, data) in zip(axes, drawn, strict=False):
        plot(ax, data)
    fig.tight_layout()
    return save_chart(fig, png)


_LOG_FLOOR = 1e-6  # errors below this (mm) are drawn at it, on the log axes


def _plot_fronts(ax, result: dict) -> None:
    """The Pareto panel: every run a dot, each solver's front a line, the time-step error,
    the 1 mm budget and the direct solves' time as lines."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt

    meta, ref = result["meta"], result["reference"]
    solvers = list(dict.fromkeys(r["solver"] for r in result["runs"]))
    colours = {s: plt.cm.tab10(i % 10) for i, s in enumerate(solvers)}
    floor = _LOG_FLOOR
    for solver, front in fronts(result).items():
        rs = [r for r in result["runs"] if r["solver"] == solver and r["available"]
              and math.isfinite(r["rms_mm"])]
        ax.scatter([r["ms_per_tick"] for r in rs], [max(r["rms_mm"], floor) for r in rs],
                   s=14, color=colours[solver], alpha=0.45)
        ax.plot([r["ms_per_tick"] for r in front], [max(r["rms_mm"], floor) for r in front],
                marker="o", color=colours[solver], label=f"{solver} front")
        for r in front:
            ax.annotate(f"{r['tol']:.0e}" + (f" L{r['levels']}" if r["levels"] else ""),
                        (r["ms_per_tick"], max(r["rms_mm"], floor)), fontsize=6,
                        xytext=(3, 3), textcoords="offset points", color=colours[solver])
    ax.axhline(max(ref["time_rms_mm"], floor), color="black", linestyle=":",
               label=f"time-step error ({meta['ref_substep_factor']}x substeps)")
    ax.axhline(ERROR_BUDGET_MM, color="red", linestyle="--", alpha=0.6, label="1 mm target")
    ax.axvline(ref["ms_per_tick"], color="grey", linestyle="-.", alpha=0.6,
               label="direct (exact) ms/tick")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("ms per tick (median)")
    ax.set_ylabel("RMS vertex error vs exact solves (mm)")
    ax.set_title(f"walking {meta['garment']}, {ref['particles']} particles: tolerances "
                 f"{min(meta['tols']):.0e}..{max(meta['tols']):.0e}, levels "
                 f"{','.join(map(str, meta['levels']))}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def _plot_sizes(ax, result: dict) -> None:
    """The error against particles panel (solver, time step, resolution; each size labelled
    with its ms per tick), or nothing without sizes."""
    meta, sizes, floor = result["meta"], result["sizes"], _LOG_FLOOR
    if not sizes:
        ax.set_axis_off()
        return
    ns = [s["particles"] for s in sizes]
    for key, label, style in (("solver_rms_mm", (f"solver ({meta['default_solver']} tol "
                               f"{meta['default_tol']:g}) vs exact"), "o-"),
                              ("time_rms_mm", (f"time step vs {meta['ref_substep_factor']}x "
                               "substeps"), "s-"),
                              ("resolution_rms_mm", (f"resolution vs {meta['finest']} "
                               "particles"), "^-")):
        if all(key in s for s in sizes):
            ax.plot(ns, [max(s[key], floor) for s in sizes], style, label=label)
    for s in sizes:
        ax.annotate(f"{s['ms_per_tick']:.0f} ms", (s["particles"],
                                                   max(s.get("resolution_rms_mm",
                                                             s["time_rms_mm"]), floor)),
                    fontsize=7, xytext=(3, 5), textcoords="offset points")
    ax.axhline(ERROR_BUDGET_MM, color="red", linestyle="--", alpha=0.6, label="1 mm")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles")
    ax.set_ylabel("RMS error (mm)")
    ax.set_title("error against resolution (labels: ms per tick at the default solver)",
                 fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


# -- command line -------------------------------------------------------------------------
