"""`bench stability`'s report: the printed map (one block per motion, rows material x dt,
columns scheme x solver, the explicit solver once), the counts per scheme and solver and the
verdict on mg, and the heatmap PNG (the schemes side by side within each motion)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.stability.cells import (
    MAX_PENETRATION,
    MAX_SPECIFIC_KINETIC,
    MAX_SPEED,
    OUTCOMES,
)
from cloth_mg_ros.bench.stability.options import (
    EXPLICIT,
    SETTLE_SCHEME,
    cell_scheme,
    dt_label,
    map_columns,
)
from cloth_mg_ros.io.text_table import text_table

# -- reporting ----------------------------------------------------------------------------
CODES = {"ok": ".", "not_converged": "NC", "tunnelled": "T", "blew_up": "B", "nan": "N"}
COLOURS = {"ok": "#4caf50", "not_converged": "#ffd54f", "tunnelled": "#ff9800",
           "blew_up": "#e53935", "nan": "#4a148c"}


def _sizes(meta: dict) -> list[int]:
    """The particle counts requested (one int in JSON written before the resolution axis)."""
    req = meta["particles_requested"]
    return list(req) if isinstance(req, (list, tuple)) else [int(req)]


def _schemes(meta: dict) -> list[str]:
    """The implicit schemes of the map (one, `scheme`, in JSON written before the axis)."""
    return list(meta.get("schemes") or [meta.get("scheme") or SETTLE_SCHEME])


def _key(c: dict, sizes: list[int], default_scheme: str = SETTLE_SCHEME) -> tuple:
    """(particles requested, speed, material, dt, motion, (scheme, solver)) of a cell."""
    return (c.get("particles_requested", sizes[0]), c.get("speed", 1), c["material"], c["dt"],
            c["motion"], (cell_scheme(c, default_scheme), c["solver"]))


def _label(column: tuple[str, str], schemes: list[str]) -> str:
    """A column's heading: the solver, after its scheme where the map has several."""
    scheme, solver = column
    return solver if solver == EXPLICIT or len(schemes) == 1 else f"{scheme} {solver}"


def _scheme_text(meta: dict) -> str:
    """'schemes euler, bdf2, genalpha (rho_inf 0.5)' for the headings."""
    schemes = _schemes(meta)
    rho = meta.get("spectral_radius")
    return (f"scheme{'s' if len(schemes) > 1 else ''} {', '.join(schemes)}"
            + (f" (rho_inf {rho:g})" if "genalpha" in schemes and rho is not None else ""))


def format_stability_report(result: dict) -> str:
    """The printed map (one block per motion: rows material x dt, columns scheme x solver;
    '.' ok, NC not converged, T tunnelled, B blew up, N NaN), the counts per scheme and
    solver and the verdict on mg (per scheme where there are several)."""
    cells, meta, summary = result["cells"], result["meta"], result["summary"]
    schemes = _schemes(meta)
    columns = map_columns(meta["solvers"], schemes)
    sizes = _sizes(meta)
    speeds = meta.get("speeds", [1])
    find = {_key(c, sizes, schemes[0]): c for c in cells}
    head = (f"bench stability: {', '.join(map(str, sizes))} particles requested, motion "
            f"speed {', '.join(f'x{v}' for v in speeds)}, {_scheme_text(meta)}, "
            f"{meta['seconds']:g} s of motion after a {meta['settle_s']:g} s settle, tol "
            f"{meta['tol']:g}, OPENBLAS_NUM_THREADS={meta['OPENBLAS_NUM_THREADS']}, "
            f"{meta['machine']}")
    key = (f"cells: . ok, NC not converged, T tunnelled (penetration > "
           f"{MAX_PENETRATION * 100:g} cm), B blew up (speed > {MAX_SPEED:g} m/s or "
           f"kinetic energy > {MAX_SPECIFIC_KINETIC:g} J/kg; at speed xk, k times and k^2 "
           f"times those), N NaN; a step longer than the 1/30 s pose interval goes through 2 "
           f"or more pose messages")
    lines = [head, key]
    for n in sizes:
        for v in speeds:
            for motion in meta["motions"]:
                some = next((c for c in cells if c["motion"] == motion
                             and _key(c, sizes)[:2] == (n, v)), None)
                if some is None:
                    continue
                title = (f"{motion} x{v} ({some['garment']}, {some['particles']} particles, "
                         f"{some['levels']} levels, {some['simulated_s']:g} s)")
                lines += ["", title]
                rows = []
                for mat in meta["materials"]:
                    for dt in meta["dts"]:
                        rows.append([f"{mat} {dt_label(dt)}"] + [
                            CODES[find[(n, v, mat, dt, motion, col)]["outcome"]]
                            if (n, v, mat, dt, motion, col) in find else "-"
                            for col in columns])
                lines.append(text_table(["material dt"] + [_label(c, schemes)
                                                           for c in columns], rows))
    lines += ["", "outcomes per scheme and solver" if len(schemes) > 1 else
              "outcomes per solver"]
    by_scheme = summary.get("by_scheme") or {schemes[0]: summary["counts"]}
    rows = [[_label(col, schemes)] + [str(by_scheme[col[0]][col[1]][o]) for o in OUTCOMES]
            for col in columns if col[0] in by_scheme and col[1] in by_scheme[col[0]]]
    lines.append(text_table(["solver", *OUTCOMES], rows))
    lines += _mg_verdicts(cells, schemes)
    skipped = [c for c in cells if c.get("skipped_messages")]
    if skipped:
        lines.append(f"NOT SIMULATED: {sum(c['skipped_messages'] for c in skipped)} pose "
                     f"messages (teleports or bad frames) in {len(skipped)} cells")
    where = f"on {meta['scheduler']}" if meta.get("scheduler") else (
        f"with {meta['jobs']} worker(s)")
    lines.append(f"wall time {meta['wall_s']:.0f} s {where}")
    return "\n".join(lines)


def _mg_verdicts(cells: list[dict], schemes: list) -> list[str]:
    """Whether mg ran ok in every cell, a line per scheme (none without mg cells)."""
    mg = [c for c in cells if c["solver"] == "mg"]
    lines = []
    for scheme in schemes if mg else []:
        bad = [c for c in mg if cell_scheme(c, schemes[0]) == scheme and c["outcome"] != "ok"]
        lines.append("mg" + (f" ({scheme})" if len(schemes) > 1 else "")
                     + " ok in every cell: " + ("yes" if not bad else
                     f"NO ({len(bad)} cells: " + ", ".join(
                         f"{c['material']} {c['dt_label']} {c['motion']} {c['outcome']}"
                         for c in bad[:10]) + ")"))
    return lines


def _outcome_grid(cells: list[dict], rows: list, cols: list, sizes: list, schemes: list
                  ) -> np.ndarray:
    """(rows, cols) the index in OUTCOMES of each cell's outcome, nan where none ran."""
    grid = np.full((len(rows), len(cols)), np.nan)
    find = {_key(c, sizes, schemes[0]): c["outcome"] for c in cells}
    for i, (n, v, m, d) in enumerate(rows):
        for j, (mo, s) in enumerate(cols):
            if (n, v, m, d, mo, s) in find:
                grid[i, j] = OUTCOMES.index(find[(n, v, m, d, mo, s)])
    return grid


def plot_stability(result: dict, png: str | Path) -> Path:
    """Heatmap: rows material x dt, columns motion x scheme x solver (the schemes side by
    side within each motion, the explicit solver once), one colour per outcome (and its
    code in the cell), a legend. Returns the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    meta, cells = result["meta"], result["cells"]
    mats, dts, motions = meta["materials"], meta["dts"], meta["motions"]
    schemes = _schemes(meta)
    columns = map_columns(meta["solvers"], schemes)
    sizes = _sizes(meta)
    speeds = meta.get("speeds", [1])
    rows = [(n, v, m, d) for n in sizes for v in speeds for m in mats for d in dts]
    cols = [(mo, col) for mo in motions for col in columns]
    grid = _outcome_grid(cells, rows, cols, sizes, schemes)
    cmap = ListedColormap([COLOURS[o] for o in OUTCOMES]).with_extremes(bad="#dddddd")
    fig, ax = plt.subplots(figsize=(max(7.0, 3.0 + 0.42 * len(cols)), 2.0 + 0.32 * len(rows)),
                           layout="constrained")
    ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-0.5, vmax=len(OUTCOMES) - 0.5,
              aspect="auto", interpolation="nearest")
    for i, j in zip(*np.nonzero(np.nan_to_num(grid) > 0), strict=True):
        ax.text(j, i, CODES[OUTCOMES[int(grid[i, j])]], ha="center", va="center", fontsize=6,
                color="white" if grid[i, j] >= 3 else "black")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([(f"{n} " if len(sizes) > 1 else "")
                        + (f"x{v} " if len(speeds) > 1 else "") + f"{m} {dt_label(d)}"
                        for n, v, m, d in rows], fontsize=7)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels([_label(col, schemes) for _, col in cols], rotation=90, fontsize=7)
    for k in range(1, len(mats) * len(sizes) * len(speeds)):
        ax.axhline(k * len(dts) - 0.5, color="white" if k % len(mats) else "black", lw=2.5)
    width = len(columns)
    for k in range(1, len(motions)):
        ax.axvline(k * width - 0.5, color="black", lw=2.5)
    # the schemes' groups within a motion
    edges = [j for j in range(1, width) if columns[j][0] != columns[j - 1][0]]
    for k in range(len(motions)):
        for j in edges:
            ax.axvline(k * width + j - 0.5, color="white", lw=2.5)
    top = ax.secondary_xaxis("top")
    top.set_xticks([(k + 0.5) * width - 0.5 for k in range(len(motions))],
                   labels=motions, fontsize=9, fontweight="bold")
    top.tick_params(length=0)
    fig.suptitle(f"stability: {', '.join(map(str, sizes))} particles, motion "
                 f"{', '.join(f'x{v}' for v in speeds)}, {meta['seconds']:g} s "
                 f"of motion per cell, tol {meta['tol']:g}, {_scheme_text(meta)}\nrows: "
                 + ("particles, " if len(sizes) > 1 else "")
                 + ("speed, " if len(speeds) > 1 else "")
                 + "material and step (s); columns: motion, "
                 + ("scheme and solver" if len(schemes) > 1 else "solver"), fontsize=9)
    ax.legend(handles=[Patch(color=COLOURS[o], label=o.replace("_", " ")) for o in OUTCOMES],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    return save_chart(fig, png)
