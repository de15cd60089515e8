"""The tolerance that the step allows, per level of detail: the fifth part of `cloth-mg bench
pareto`.

A solve's error buys nothing below the error of the time step that uses it. Per level the
garment may be simulated at (bench.pareto_levels) and per pose interval (every `every`-th
message of the clip), from the finest's exact-solve state before the message restricted to
the level, one message is taken

* with exact (direct) solves at the scene's step rule: ``x_exact``;
* with exact solves and REF_SUBSTEP_FACTOR times the steps: the step's own error is
  ``|x_exact - x_small|`` (RMS over the vertices, mm);
* with the scenes' solver at each tolerance of ``tols`` (and REFERENCE_TOL): the solver's
  error is
  ``|x_tol - x_exact|``, and the tick's ms.

The interval's tolerance is the loosest one whose solver error is at most a tenth of the
step's (SOLVER_SHARE); per level the report gives the loosest tolerance that meets this on
every interval measured (and the median interval's), with the ms per tick it saves against
the reference tolerance (the paper's 1e-4, which stays the scenes' default).
"""

from __future__ import annotations

import copy

import numpy as np

from cloth_mg_ros.bench.pareto_levels import one_message
from cloth_mg_ros.bench.pareto_steps import _rms_max

DEFAULT_TOLS = (1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 1e-5, 1e-6)
SOLVER_SHARE = 0.1  # the solver's error may be this fraction of the step's
REFERENCE_TOL = 1e-4  # the paper's, the scenes' default


def tolerance_axis(base, frames: list, solver: str = "mpcg",
                   tols: tuple[float, ...] = DEFAULT_TOLS, every: int = 3,
                   small_factor: int | None = None, log=print) -> dict:
    """Part 5 of bench pareto (module docstring) from a settled garment `base` (a GarmentSim
    at level 0) over `frames`. Returns {"levels": [{"level", "particles", "step_rms_mm",
    "solver_rms_mm": {tol: mean mm}, "ms_per_tick": {tol: median ms}, "tolerance_all",
    "tolerance_median", "intervals"}], "tols", "solver", "share", "reference_tol"}."""
    from cloth_mg_ros.bench.pareto import REF_SUBSTEP_FACTOR, REFERENCE_SOLVER

    factor = REF_SUBSTEP_FACTOR if small_factor is None else small_factor
    tols = sorted(set(tols) | {REFERENCE_TOL}, reverse=True)  # the reference always
    gs = copy.deepcopy(base)
    gs.set_solver(REFERENCE_SOLVER, REFERENCE_TOL)
    gs.prepare_levels()
    snaps = []
    for frame in frames:  # the finest's exact clip: the states every interval starts from
        snaps.append(gs.snapshot())
        gs.push(*frame)
    picked = list(range(0, len(frames), max(1, every)))
    opts = gs.options
    rows = []
    for level in gs.lod_levels():
        step_err, solver_err, ms, chosen = [], {t: [] for t in tols}, {t: [] for t in tols}, []
        for k in picked:
            gs.set_solver(REFERENCE_SOLVER, REFERENCE_TOL)
            exact, _ = one_message(gs, snaps[k], level, frames[k])
            substeps, motion = opts.substeps, opts.max_substep_motion
            opts.substeps, opts.max_substep_motion = substeps * factor, motion / factor
            try:
                small, _ = one_message(gs, snaps[k], level, frames[k])
            finally:
                opts.substeps, opts.max_substep_motion = substeps, motion
            step = _rms_max(exact, small)[0]
            step_err.append(step)
            best = None
            for tol in tols:
                gs.set_solver(solver, tol)
                x, tick_ms = one_message(gs, snaps[k], level, frames[k])
                err = _rms_max(x, exact)[0]
                solver_err[tol].append(err)
                ms[tol].append(tick_ms)
                if best is None and err <= SOLVER_SHARE * step:
                    best = tol
            chosen.append(best if best is not None else min(tols))
        row = {"level": level, "particles": gs.level_particles(level),
               "intervals": len(picked), "step_rms_mm": float(np.mean(step_err)),
               "solver_rms_mm": {f"{t:g}": float(np.mean(v)) for t, v in solver_err.items()},
               "ms_per_tick": {f"{t:g}": float(np.median(v)) for t, v in ms.items()},
               "tolerance_all": float(min(chosen)),
               "tolerance_median": float(np.median(chosen)),
               "per_interval": [float(c) for c in chosen]}
        rows.append(row)
        ref_ms = row["ms_per_tick"][f"{REFERENCE_TOL:g}"]
        at = row["ms_per_tick"][f"{row['tolerance_all']:g}"]
        log(f"  level {level} ({row['particles']} particles): step error "
            f"{row['step_rms_mm']:.2f} mm RMS per interval; solver error <= "
            f"{SOLVER_SHARE:g} of it on every interval from tol {row['tolerance_all']:g} "
            f"(median interval {row['tolerance_median']:g}): {at:.1f} ms/tick against "
            f"{ref_ms:.1f} at {REFERENCE_TOL:g}")
    gs.set_level(0)
    return {"levels": rows, "tols": tols, "solver": solver, "share": SOLVER_SHARE,
            "reference_tol": REFERENCE_TOL, "small_step_factor": factor}


def format_tolerance_axis(part: dict) -> list[str]:
    """Report lines for part 5."""
    from cloth_mg_ros.text_table import text_table

    ref = f"{part['reference_tol']:g}"
    rows = []
    for r in part["levels"]:
        tol = f"{r['tolerance_all']:g}"
        rows.append([str(r["level"]), str(r["particles"]), f"{r['step_rms_mm']:.2f}",
                     f"{r['solver_rms_mm'][ref]:.3f}", tol,
                     f"{r['tolerance_median']:g}", f"{r['solver_rms_mm'][tol]:.3f}",
                     f"{r['ms_per_tick'][tol]:.1f}", f"{r['ms_per_tick'][ref]:.1f}"])
    return ["", (f"the tolerance the step allows ({part['solver']}; solver error at most "
                 f"{part['share']:g} of the step's, against {part['small_step_factor']}x steps; "
                 f"RMS mm per pose interval)"),
            text_table(["level", "particles", "step error", f"solver error at {ref}",
                        "tolerance (every interval)", "(median interval)",
                        "its solver error", "its ms/tick", f"ms/tick at {ref}"], rows)]


def plot_tolerance_axis(ax, part: dict) -> None:
    """The solver's error against the tolerance, a line per level, and a tenth of each
    level's step error as a dashed line of the same colour."""
    for i, r in enumerate(part["levels"]):
        colour = f"C{i}"
        tols = [float(t) for t in r["solver_rms_mm"]]
        ax.plot(tols, list(r["solver_rms_mm"].values()), "o-", color=colour,
                label=f"level {r['level']} ({r['particles']} p): solver error")
        ax.axhline(part["share"] * r["step_rms_mm"], color=colour, linestyle="--",
                   label=f"level {r['level']}: {part['share']:g} x step error")
        ax.axvline(r["tolerance_all"], color=colour, linestyle=":", alpha=0.6)
    ax.axvline(part["reference_tol"], color="grey", linestyle="-.", label="paper's 1e-4")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.invert_xaxis()
    ax.set_xlabel(f"relative tolerance ({part['solver']})")
    ax.set_ylabel("RMS error per pose interval (mm)")
    ax.set_title("the tolerance the step allows, per level", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
