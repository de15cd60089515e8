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
every interval measured, the median interval's, and the loosest whose solver error averaged
over the intervals is a tenth of the averaged step error (what `tolerance: auto` takes:
budget.tolerance), with the ms per tick it saves against the reference tolerance (the
paper's 1e-4). The measurement of one interval is budget.tolerance.interval_tolerance.
"""

from __future__ import annotations

import copy

import numpy as np

from cloth_mg_ros.bench.pareto_runs import REF_SUBSTEP_FACTOR, REFERENCE_SOLVER
from cloth_mg_ros.budget.tolerance import REFERENCE_TOL, SOLVER_SHARE, interval_tolerance
from cloth_mg_ros.io.text_table import text_table

DEFAULT_TOLS = (1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 1e-5, 1e-6)


def tolerance_axis(base, frames: list, solver: str = "mpcg",
                   tols: tuple[float, ...] = DEFAULT_TOLS, every: int = 3,
                   small_factor: int | None = None, log=print) -> dict:
    """Part 5 of bench pareto (module docstring) from a settled garment `base` (a GarmentSim
    at level 0) over `frames`. Returns {"levels": [{"level", "particles", "step_rms_mm",
    "solver_rms_mm": {tol: mean mm}, "ms_per_tick": {tol: median ms}, "tolerance_all",
    "tolerance_median", "tolerance_mean", "intervals"}], "tols", "solver", "share",
    "reference_tol"}."""
    factor = REF_SUBSTEP_FACTOR if small_factor is None else small_factor
    tols = sorted(set(tols) | {REFERENCE_TOL}, reverse=True)  # the reference always
    garment_sim = copy.deepcopy(base)
    garment_sim.set_solver(REFERENCE_SOLVER, REFERENCE_TOL)
    garment_sim.prepare_rungs()
    snaps = []
    for frame in frames:  # the finest's exact clip: the states every interval starts from
        snaps.append(garment_sim.snapshot())
        garment_sim.push(*frame)
    picked = list(range(0, len(frames), max(1, every)))
    rows = []
    for level in garment_sim.rung_indices():
        per = [interval_tolerance(garment_sim, snaps[k], level, frames[k], solver, tuple(tols),
                                  factor)
               for k in picked]
        chosen = [r.chosen if r.chosen is not None else min(tols) for r in per]
        step = float(np.mean([r.step_mm for r in per]))
        solver_err = {t: float(np.mean([r.solver_mm[t] for r in per])) for t in tols}
        # tolerance auto's criterion (budget.tolerance.measure_tolerances): the mean errors
        mean_ok = [t for t in tols if solver_err[t] <= SOLVER_SHARE * step]
        row = {"level": level, "particles": garment_sim.rung_particles(level),
               "intervals": len(picked), "step_rms_mm": step,
               "solver_rms_mm": {f"{t:g}": v for t, v in solver_err.items()},
               "ms_per_tick": {f"{t:g}": float(np.median([r.ms[t] for r in per]))
                               for t in tols},
               "tolerance_all": float(min(chosen)),
               "tolerance_median": float(np.median(chosen)),
               "tolerance_mean": float(max(mean_ok)) if mean_ok else float(min(tols)),
               "per_interval": [float(c) for c in chosen]}
        rows.append(row)
        ref_ms = row["ms_per_tick"][f"{REFERENCE_TOL:g}"]
        at = row["ms_per_tick"][f"{row['tolerance_all']:g}"]
        log(f"  level {level} ({row['particles']} particles, {len(picked)} intervals): step "
            f"error {row['step_rms_mm']:.2f} mm RMS per interval; solver error <= "
            f"{SOLVER_SHARE:g} of it on every interval from tol {row['tolerance_all']:g} "
            f"(median interval {row['tolerance_median']:g}, on average over the intervals "
            f"{row['tolerance_mean']:g}): {at:.1f} ms/tick against {ref_ms:.1f} at "
            f"{REFERENCE_TOL:g}")
    garment_sim.set_rung(0)
    return {"levels": rows, "tols": tols, "solver": solver, "share": SOLVER_SHARE,
            "reference_tol": REFERENCE_TOL, "small_step_factor": factor}


def format_tolerance_axis(part: dict) -> list[str]:
    """Report lines for part 5."""
    ref = f"{part['reference_tol']:g}"
    rows = []
    for r in part["levels"]:
        tol = f"{r['tolerance_all']:g}"
        mean = f"{r['tolerance_mean']:g}" if "tolerance_mean" in r else None
        rows.append([str(r["level"]), str(r["particles"]), f"{r['step_rms_mm']:.2f}",
                     f"{r['solver_rms_mm'][ref]:.3f}", tol,
                     f"{r['tolerance_median']:g}", f"{r['solver_rms_mm'][tol]:.3f}",
                     f"{r['ms_per_tick'][tol]:.1f}", mean or "-",
                     f"{r['ms_per_tick'][mean]:.1f}" if mean else "-",
                     f"{r['ms_per_tick'][ref]:.1f}"])
    return ["", (f"the tolerance the step allows ({part['solver']}; solver error at most "
                 f"{part['share']:g} of the step's, against {part['small_step_factor']}x steps; "
                 f"RMS mm per pose interval)"),
            text_table(["level", "particles", "step error", f"solver error at {ref}",
                        "tolerance (every interval)", "(median interval)",
                        "its solver error", "its ms/tick", "on average (auto's)",
                        "its ms/tick", f"ms/tick at {ref}"], rows),
            "", "solver error at each tolerance (mm RMS per pose interval, mean over intervals)",
            _ladder_table(part)]


def _ladder_table(part: dict) -> str:
    """The ladder's solver errors, a row per level, loosest tolerance first."""
    tols = [f"{t:g}" for t in sorted(part["tols"], reverse=True)]
    rows = [[str(r["level"]), str(r["particles"])]
            + [f"{r['solver_rms_mm'][t]:.3f}" for t in tols] for r in part["levels"]]
    return text_table(["level", "particles"] + tols, rows)


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
