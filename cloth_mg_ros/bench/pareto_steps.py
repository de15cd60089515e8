"""The step rule's own accuracy: the third part of `cloth-mg bench pareto`, the step (substep
count) as an axis of speed against accuracy.

Rules compared, each on the same settled garment and pose messages (`RULES`):

* ``scene``: the scene's own rule (its substeps, max_substep_motion and max_step; the
  walking scene: one step per pose message unless a limb near the cloth moves further than
  25 cm in it);
* ``5cm``: max_substep_motion 5 cm, a finer motion rule than the scene's (2-4 steps per
  message at walking speed);
* ``1x`` .. ``8x``: that many steps per pose message, no motion rule.

The reference is ``REF_STEPS`` fixed steps per message, every system solved exactly (direct).
Three figures per rule, all with exact solves so that only the step differs:

* ``clip``: the RMS / max vertex distance from the reference over the whole clip (every
  message, every vertex). Over a second this is dominated by chaos, not by the step: a fold
  forms or does not (../shared/DESIGN.md, "How far one trajectory can be trusted"), so
* ``interval``: from the reference's own state after each message, one message's interval
  with the rule, against the reference's next state: the error the rule makes per pose
  interval, which nothing amplifies (mean RMS over the intervals, and the worst interval's);
* ``floor``: beside them, how far any change grows over the clip: the scene rule's clip
  with its start displaced by 1 um against itself undisplaced (`PERTURBATION_M`).

Speed: each rule's clip again with the default solver (mpcg at 1e-4): ms per tick and steps
per tick, and that run's clip error (solver and step together). Successive halvings of the
fixed rules (1x against 2x, 2x against 4x, ...) come from their interval states.
"""

from __future__ import annotations

import copy
import itertools
import math
from dataclasses import replace

import numpy as np

from cloth_mg_ros.bench.walking import replay
from cloth_mg_ros.budget.tolerance_rule import rms_max_mm as _rms_max
from cloth_mg_ros.io.text_table import text_table

REF_STEPS = 16
RULES = ("scene", "5cm", "1x", "2x", "4x", "8x")
PERTURBATION_M = 1e-6
MOTION_OFF = 1e9  # m: a max_substep_motion that never adds steps
OLD_MOTION_M = 0.05


def rule_options(options, rule: str):
    """The BodySimOptions of a step rule (module docstring) from the scene's."""
    if rule == "scene":
        return replace(options)
    if rule == "5cm":
        return replace(options, max_substep_motion=OLD_MOTION_M)
    steps = int(rule.rstrip("x"))
    return replace(options, substeps=steps, max_substep_motion=MOTION_OFF, max_step=0.25)


def _with_rule(base, rule: str, solver: str, tol: float):
    """A copy of the settled garment `base` stepping with `rule` and `solver`."""
    garment_sim = copy.deepcopy(base)
    garment_sim.options = rule_options(garment_sim.options, rule)
    garment_sim.set_solver(solver, tol)
    return garment_sim


def _clip(garment_sim, frames) -> tuple[np.ndarray, dict, list]:
    """Run garment_sim over frames: (positions after every message (T, n, 3), the run's figures,
    snapshots before every message)."""
    snaps = [garment_sim.snapshot()]
    out: list[np.ndarray] = []

    def keep(g, _):
        out.append(g.positions.copy())
        snaps.append(g.snapshot())

    run = replay(garment_sim, frames, on_tick=keep, per_tick=False)
    return np.array(out), run, snaps[:-1]


def _intervals(garment_sim, frames, snaps) -> np.ndarray:
    """(T, n, 3): from each reference snapshot, one message with garment_sim's rule."""
    out = []
    for snap, (stamp, poses) in zip(snaps, frames, strict=True):
        garment_sim.restore(snap)
        garment_sim.push(stamp, poses)
        out.append(garment_sim.positions.copy())
    return np.array(out)


def step_rules(base, frames: list, rules: tuple[str, ...] = RULES, solver: str = "mpcg",
               tol: float = 1e-4, log=print) -> dict:
    """Part 3 of bench pareto (module docstring) from a settled garment `base` (a
    GarmentSim) over `frames`. Returns {"reference": {...}, "rules": [...], "floor_mm":
    {...}, "halvings": [...]}; lengths in mm, times in ms."""
    ref_gs = _with_rule(base, f"{REF_STEPS}x", "direct", tol)
    ref, ref_run, ref_snaps = _clip(ref_gs, frames)
    log(f"  step rules: reference {REF_STEPS} steps per message, exact solves, "
        f"{ref_run['ms_per_tick']:.0f} ms/tick")
    rows, ends = [], {}
    for rule in rules:
        exact, exact_run, _ = _clip(_with_rule(base, rule, "direct", tol), frames)
        ends[rule] = _intervals(_with_rule(base, rule, "direct", tol), frames, ref_snaps)
        per = [_rms_max(e, r) for e, r in zip(ends[rule], ref, strict=True)]
        fast, fast_run, _ = _clip(_with_rule(base, rule, solver, tol), frames)
        row = {"rule": rule, "steps_per_tick": exact_run["substeps"],
               "clip_rms_mm": _rms_max(exact, ref)[0], "clip_max_mm": _rms_max(exact, ref)[1],
               "interval_rms_mm": float(np.mean([p[0] for p in per])),
               "interval_worst_rms_mm": float(max(p[0] for p in per)),
               "interval_max_mm": float(max(p[1] for p in per)),
               "solver": solver, "tol": tol, "ms_per_tick": fast_run["ms_per_tick"],
               "solver_steps_per_tick": fast_run["substeps"],
               "solver_clip_rms_mm": _rms_max(fast, ref)[0],
               "converged": fast_run["converged"]}
        rows.append(row)
        log(f"  rule {rule:6s}: {row['steps_per_tick']:.1f} steps/tick, interval "
            f"{row['interval_rms_mm']:.2f} mm RMS (worst {row['interval_worst_rms_mm']:.2f}), "
            f"clip {row['clip_rms_mm']:.1f} mm RMS; {solver} {row['ms_per_tick']:.1f} ms/tick")
    fixed = [r for r in rules if r.endswith("x")]
    halvings = []
    for a, b in itertools.pairwise(fixed):
        d = [_rms_max(x, y)[0] for x, y in zip(ends[a], ends[b], strict=True)]
        halvings.append({"from": a, "to": b, "interval_rms_mm": float(np.mean(d))})
    scene, _, _ = _clip(_with_rule(base, "scene", "direct", tol), frames)
    moved = copy.deepcopy(base)
    rng = np.random.default_rng(0)
    moved.sim.state.x = moved.sim.state.x + rng.normal(0.0, PERTURBATION_M,
                                                       moved.sim.state.x.shape)
    bumped, _, _ = _clip(_with_rule(moved, "scene", "direct", tol), frames)
    floor = _rms_max(bumped, scene)
    log(f"  floor: a {1e6 * PERTURBATION_M:g} um start perturbation grows to {floor[0]:.1f} mm "
        f"RMS over the clip; successive halvings per interval: "
        + ", ".join(f"{h['from']}/{h['to']} {h['interval_rms_mm']:.2f} mm" for h in halvings))
    return {"reference": {"steps": REF_STEPS, "ms_per_tick": ref_run["ms_per_tick"]},
            "rules": rows, "halvings": halvings,
            "floor_mm": {"rms": floor[0], "max": floor[1], "perturbation_m": PERTURBATION_M}}


def format_step_rules(part: dict) -> list[str]:
    """Report lines for part 3."""
    rows = [[r["rule"], f"{r['steps_per_tick']:.1f}", f"{r['interval_rms_mm']:.2f}",
             f"{r['interval_worst_rms_mm']:.2f}", f"{r['clip_rms_mm']:.1f}",
             f"{r['clip_max_mm']:.0f}", f"{r['ms_per_tick']:.1f}",
             f"{r['solver_clip_rms_mm']:.1f}"] for r in part["rules"]]
    floor = part["floor_mm"]
    return ["", (f"step rules against {part['reference']['steps']} steps per message (exact "
                 f"solves; mm): per pose interval from the reference's states, and over the "
                 f"clip; ms/tick with the default solver"),
            text_table(["rule", "steps/tick", "interval RMS", "worst interval", "clip RMS",
                    "clip max", "ms/tick", "clip RMS (solver)"], rows),
            (f"floor: a {1e6 * floor['perturbation_m']:g} um perturbation of the start grows "
             f"to {floor['rms']:.1f} mm RMS ({floor['max']:.0f} max) over the clip; "
             f"successive halvings per interval: "
             + ", ".join(f"{h['from']}/{h['to']} {h['interval_rms_mm']:.2f} mm"
                         for h in part["halvings"]))]


def plot_interval_and_clip(ax, rows: list[dict], labels: list[str], floor_mm: dict,
                           interval_label: str, clip_label: str, style: str = "") -> None:
    """ms per tick against each row's per-interval and clip RMS error (mm), annotated with
    `labels`, the perturbation floor `floor_mm` ({"rms", "perturbation_m"}) as a dotted line;
    log axes."""
    ms = [r["ms_per_tick"] for r in rows]
    ax.plot(ms, [r["interval_rms_mm"] for r in rows], "o" + style, color="tab:blue",
            label=interval_label)
    ax.plot(ms, [r["clip_rms_mm"] for r in rows], "s" + style, color="tab:orange",
            alpha=0.6, label=clip_label)
    for r, label in zip(rows, labels, strict=True):
        ax.annotate(label, (r["ms_per_tick"], r["interval_rms_mm"]), fontsize=7,
                    xytext=(3, 3), textcoords="offset points")
    ax.axhline(floor_mm["rms"], color="black", linestyle=":",
               label=f"clip floor: {1e6 * floor_mm['perturbation_m']:g} um perturbation")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)


def plot_step_rules(ax, part: dict) -> None:
    """ms per tick against the per-interval error, a point per rule; the clip errors and the
    perturbation floor as reference lines."""
    rules = part["rules"]
    plot_interval_and_clip(ax, rules, [f"{r['rule']} ({r['steps_per_tick']:.1f}/tick)"
                                       for r in rules], part["floor_mm"],
                           "per pose interval (from the reference's states)",
                           "over the clip (chaotic, see floor)")
    ax.set_xlabel("ms per tick (default solver)")
    ax.set_ylabel(f"RMS vertex error vs {part['reference']['steps']} steps/message (mm)")
    ax.set_title("the step rule's own error (exact solves)", fontsize=10)
    ax.legend(fontsize=7)
    if not math.isfinite(ax.get_ylim()[0]):
        ax.set_ylim(1e-3, None)
