"""The tolerance that the step allows, per level of detail: the fifth part of `cloth-mg bench
pareto`.

A solve's error buys nothing below the error of the time step that uses it. Per level the
garment may be simulated at (bench.pareto_rungs) and per pose interval (every `every`-th
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
over the intervals is a tenth of the averaged step error (`tolerance: auto`'s rule:
budget.tolerance_rule), with the ms per tick it saves against the reference tolerance (the
paper's 1e-4). The measurement of one interval is budget.tolerance_rule.interval_tolerance.

With the (particles, tolerance) points `tolerance: auto` calibrated for the run's garment,
fabric, bag and threads (the cost model's), each level is also measured at the tolerance auto
gives it, and the report checks the rule there (`auto_check`): the ratio of the mean solver
error to the mean step error over the measured messages (every message with ``every`` 1),
and the per-message ratios' spread.
"""

from __future__ import annotations

import copy

import numpy as np

from cloth_mg_ros.bench.pareto_runs import REF_SUBSTEP_FACTOR, REFERENCE_SOLVER
from cloth_mg_ros.budget.tolerance_rule import REFERENCE_TOL, SOLVER_SHARE, interval_tolerance
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.sim.solve_tolerance import tolerance_at

DEFAULT_TOLS = (1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 1e-5, 1e-6)


def tolerance_axis(base, frames: list, solver: str = "mpcg",
                   tols: tuple[float, ...] = DEFAULT_TOLS, every: int = 1,
                   small_factor: int | None = None, log=print,
                   auto_points: tuple | None = None) -> dict:
    """Part 5 of bench pareto (module docstring) from a settled garment `base` (a GarmentSim
    at level 0) over `frames`; with `auto_points` (tolerance auto's calibrated (particles,
    tolerance) points) each level also at the tolerance auto gives it, and the rule checked.
    Returns {"levels": [{"level", "particles", "step_rms_mm", "solver_rms_mm": {tol: mean mm},
    "ratio": {tol: mean solver / mean step}, "ms_per_tick": {tol: median ms}, "tolerance_all",
    "tolerance_median", "tolerance_mean", "intervals", "messages": [{"stamp", "step_mm",
    "solver_mm": {tol: mm}}], "auto": auto_check's or None}], "tols", "solver", "share",
    "reference_tol", "small_step_factor", "auto_points", "messages"}."""
    factor = REF_SUBSTEP_FACTOR if small_factor is None else small_factor
    garment_sim = copy.deepcopy(base)
    garment_sim.set_solver(REFERENCE_SOLVER, REFERENCE_TOL)
    garment_sim.prepare_rungs()
    auto = {level: tolerance_at(auto_points, garment_sim.rung_particles(level), level)
            for level in garment_sim.rung_indices()} if auto_points else {}
    # the reference always, and each level's auto tolerance (measured at every level)
    tols = sorted(set(tols) | {REFERENCE_TOL} | set(auto.values()), reverse=True)
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
        row = _rung_row(garment_sim, level, per, [frames[k][0] for k in picked], tols)
        row["auto"] = auto_check(row, auto[level]) if auto else None
        rows.append(row)
        ref_ms = row["ms_per_tick"][f"{REFERENCE_TOL:g}"]
        at = row["ms_per_tick"][f"{row['tolerance_all']:g}"]
        log(f"  level {level} ({row['particles']} particles, {len(picked)} intervals): step "
            f"error {row['step_rms_mm']:.2f} mm RMS per interval; solver error <= "
            f"{SOLVER_SHARE:g} of it on every interval from tol {row['tolerance_all']:g} "
            f"(median interval {row['tolerance_median']:g}, on average over the intervals "
            f"{row['tolerance_mean']:g}): {at:.1f} ms/tick against {ref_ms:.1f} at "
            f"{REFERENCE_TOL:g}")
        if row["auto"]:
            log(_auto_line(row))
    garment_sim.set_rung(0)
    return {"levels": rows, "tols": tols, "solver": solver, "share": SOLVER_SHARE,
            "reference_tol": REFERENCE_TOL, "small_step_factor": factor,
            "auto_points": [list(p) for p in auto_points] if auto_points else None,
            "messages": len(frames), "every": every}


def _rung_row(garment_sim, level: int, per: list, stamps: list[float], tols: list) -> dict:
    """Part 5's row of one level from its measured intervals `per` (IntervalTolerance, one per
    pose message at `stamps`, s) over the tolerances `tols`."""
    chosen = [r.chosen if r.chosen is not None else min(tols) for r in per]
    step = float(np.mean([r.step_mm for r in per]))
    solver_err = {t: float(np.mean([r.solver_mm[t] for r in per])) for t in tols}
    # tolerance auto's criterion (budget.tolerance_rule.measure_tolerances): the mean errors
    mean_ok = [t for t in tols if solver_err[t] <= SOLVER_SHARE * step]
    return {"level": level, "particles": garment_sim.rung_particles(level),
            "intervals": len(per), "step_rms_mm": step,
            "solver_rms_mm": {f"{t:g}": v for t, v in solver_err.items()},
            "ratio": {f"{t:g}": v / step if step > 0.0 else float("inf")
                      for t, v in solver_err.items()},
            "ms_per_tick": {f"{t:g}": float(np.median([r.ms[t] for r in per])) for t in tols},
            "tolerance_all": float(min(chosen)),
            # a ladder value: the lower middle of an even count, not the mean of the two
            "tolerance_median": float(sorted(chosen)[(len(chosen) - 1) // 2]),
            "tolerance_mean": float(max(mean_ok)) if mean_ok else float(min(tols)),
            "per_interval": [float(c) for c in chosen],
            "messages": [{"stamp": float(st), "step_mm": r.step_mm,
                          "solver_mm": {f"{t:g}": v for t, v in r.solver_mm.items()}}
                         for st, r in zip(stamps, per, strict=True)]}


def calibrated_points(bag: str, garment: str, material: str, threads: int, log) -> tuple:
    """tolerance auto's (particles, tolerance) points for the walking scene's settings with
    this garment, material name, bag and threads: the cost model's, calibrated once per
    machine and cached, as the node's are (bench.walking.auto_tolerances)."""
    from cloth_mg_ros.bench.walking import auto_tolerances  # the cost model loads only here
    from cloth_mg_ros.physics.materials import get_material

    return auto_tolerances(load_scene("walking"), garment, get_material(material), bag,
                           threads, log)


def auto_check(row: dict, tol: float, share: float = SOLVER_SHARE) -> dict:
    """tolerance auto's rule at one level (a row of tolerance_axis, measured at `tol`): the
    rule's ratio (the solver error per message averaged over the measured messages, over the
    step error per message averaged over the same), whether it is within `share`, and the
    per-message ratios (solver / step error of each message): median, 90th percentile, largest
    and the share of messages within `share`."""
    key = f"{tol:g}"
    step = np.array([m["step_mm"] for m in row["messages"]])
    solver = np.array([m["solver_mm"][key] for m in row["messages"]])
    ratio = float(solver.mean() / step.mean()) if step.mean() > 0.0 else float("inf")
    each = solver / np.maximum(step, 1e-300)
    return {"tolerance": float(tol), "messages": len(step), "step_mm": float(step.mean()),
            "solver_mm": float(solver.mean()), "ratio": ratio, "holds": bool(ratio <= share),
            "message_ratio_median": float(np.median(each)),
            "message_ratio_p90": float(np.percentile(each, 90)),
            "message_ratio_max": float(each.max()),
            "messages_within": float(np.mean(each <= share))}


def _auto_line(row: dict) -> str:
    a = row["auto"]
    return (f"  level {row['level']} at tolerance auto's {a['tolerance']:g}: solver error "
            f"{a['solver_mm']:.3f} mm against a step error of {a['step_mm']:.2f} mm per message "
            f"(mean over {a['messages']} messages): ratio {a['ratio']:.3f} "
            f"({'within' if a['holds'] else 'ABOVE'} {SOLVER_SHARE:g}); per message median "
            f"{a['message_ratio_median']:.3f}, 90th percentile {a['message_ratio_p90']:.3f}, "
            f"largest {a['message_ratio_max']:.3f}, {100 * a['messages_within']:.0f} % of "
            f"messages within {SOLVER_SHARE:g}")


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
            _ladder_table(part)] + format_auto_check(part)


def format_auto_check(part: dict) -> list[str]:
    """Report lines: tolerance auto's rule checked per level (none without auto's points)."""
    rows = [[str(r["level"]), str(r["particles"]), f"{a['tolerance']:g}", str(a["messages"]),
             f"{a['step_mm']:.2f}", f"{a['solver_mm']:.3f}", f"{a['ratio']:.3f}",
             "yes" if a["holds"] else "NO", f"{a['message_ratio_median']:.3f}",
             f"{a['message_ratio_p90']:.3f}", f"{a['message_ratio_max']:.3f}",
             f"{100 * a['messages_within']:.0f} %"]
            for r in part["levels"] if (a := r.get("auto"))]
    if not rows:
        return []
    every = part.get("every", 1)
    which = "every pose message" if every == 1 else f"one pose message in {every}"
    points = ", ".join(f"{t:g} at {n} particles" for n, t in part["auto_points"])
    share = f"{part['share']:g}"
    return ["", (f"tolerance auto's rule over {which} of the clip ({points}): mean solver error "
                 f"per message / mean step error per message <= {share}"),
            text_table(["level", "particles", "auto's tol", "messages", "step error",
                        "solver error", "ratio", "holds", "per message: median", "90th pct",
                        "largest", f"within {share}"], rows)]


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
