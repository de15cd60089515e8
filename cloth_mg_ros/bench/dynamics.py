"""`cloth-mg bench dynamics`: the integrators' accuracy in motion against their cost.

Two parts, one run:

* the swing (`fidelity.swing`): for each scheme (implicit Euler, BDF2, generalised-alpha at
  its default spectral radius 0, at 0.5 and at 1.0) and each step from 1/30 s to 1/480 s, the first
  mode's frequency error against the exact heavy chain and its damping ratio (the exact
  chain's is 0), with the fabric's stiffness-proportional damping and without it (what is
  left is the integrator's own), the energy left, and the cost: the median step's wall time
  per simulated second (s/s) on this machine, one run;
* the walking dress (the body scene ``walking`` on the bundled bag ``walk``, one step per
  pose message as the node steps): its kinetic energy over the clip per scheme, at a modest
  particle count and a fixed solver tolerance (how lively each scheme leaves a garment).

A cell whose swing gains energy (`max_energy_ratio` above ``STABLE_ENERGY_RATIO``) or whose
positions become non-finite is reported unstable, its figures kept but not charted.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.budget.cost_model import machine_id
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.text_table import text_table

DEFAULT_JSON = "doc/results/bench_dynamics.json"
DEFAULT_PNG = "doc/bench_dynamics.png"
STEPS_PER_S = (30, 60, 120, 240, 480)
QUICK_STEPS_PER_S = (30, 60)
QUICK_SWING_PARTICLES = 48
QUICK_PERIODS = 2.5  # the fit needs two
WALK_PARTICLES = 600
QUICK_WALK_PARTICLES = 300
QUICK_WALK_MESSAGES = 8
WALK_TOLERANCE = 1e-4  # fixed: tolerance auto would first calibrate the cost model
WALK_LEAD_IN_S = 1.0  # the bundled bags' still lead-in before the stride
# a free swing never gains energy; the first steps' transients stay well under this
STABLE_ENERGY_RATIO = 1.05


def variants() -> list[tuple[str, float | None]]:
    """(scheme, spectral radius or None) of each column: Euler, BDF2, genalpha at its
    default spectral radius (0), at 0.5 and at 1.0 (no numerical damping of the fastest
    modes)."""
    # imported here: the integrator (numba kernels) loads when the bench runs
    from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS

    radii = sorted({DEFAULT_SPECTRAL_RADIUS, 0.5, 1.0})
    return [("euler", None), ("bdf2", None)] + [("genalpha", r) for r in radii]


def variant_label(scheme: str, radius: float | None) -> str:
    return scheme if radius is None else f"{scheme} rho {radius:g}"


def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench dynamics` on the bench sub-parsers."""
    p = bsub.add_parser("dynamics", help="each integrator's swing against the exact heavy "
                        "chain (frequency error, damping ratio) and cost, 1/30-1/480 s; the "
                        "walking dress's kinetic energy per scheme")
    p.add_argument("--quick", action="store_true",
                   help=f"steps 1/30 and 1/60 s, a {QUICK_SWING_PARTICLES}-particle strip for "
                        f"{QUICK_PERIODS:g} periods, the dress at {QUICK_WALK_PARTICLES} "
                        f"particles for {QUICK_WALK_MESSAGES} pose messages: a smoke run")
    p.add_argument("--material", default=None,
                   help="the swing's fabric (default: the swing scene's, white-dots-on-blk)")
    p.add_argument("--length", type=float, default=None,
                   help="the swing's strip length, m (default 0.5)")
    p.add_argument("--walk-particles", type=int, default=None,
                   help=f"the walking dress's particles (default {WALK_PARTICLES})")
    p.add_argument("--json", default=DEFAULT_JSON, help=f"JSON output (default {DEFAULT_JSON})")
    p.add_argument("--png", default=DEFAULT_PNG, help=f"chart output (default {DEFAULT_PNG})")
    p.set_defaults(bench_func=run_cli)


def run_cli(args: argparse.Namespace) -> int:
    """Run the bench from parsed options; exit 0."""
    # imported here: the scene modules (numba kernels) load when the bench runs
    from cloth_mg_ros.fidelity.swing import (
        DEFAULT_LENGTH,
        DEFAULT_MATERIAL,
        DEFAULT_PARTICLES,
        SwingSpec,
    )

    walk_particles = args.walk_particles if args.walk_particles is not None else \
        (QUICK_WALK_PARTICLES if args.quick else WALK_PARTICLES)
    if walk_particles < 100:
        raise ClothInputError(f"--walk-particles must be at least 100, got {walk_particles}")
    base = SwingSpec(material=args.material or DEFAULT_MATERIAL,
                     length=DEFAULT_LENGTH if args.length is None else args.length,
                     particles=QUICK_SWING_PARTICLES if args.quick else DEFAULT_PARTICLES)
    if args.quick:
        base = replace(base, duration=QUICK_PERIODS / base.exact_frequency)
    result = bench_dynamics(base, QUICK_STEPS_PER_S if args.quick else STEPS_PER_S,
                            walk_particles, QUICK_WALK_MESSAGES if args.quick else None)
    result["meta"]["quick"] = bool(args.quick)
    print(format_report(result))
    write_json(args.json, result)
    png = plot_dynamics(result, args.png)
    print(f"wrote {args.json} and {png}")
    return 0


def _swing_cell(spec) -> dict:
    """One swing run's block, or its failure: {"stable": False, "error": ...}."""
    # imported here: the scene modules (numba kernels) load when the bench runs
    from cloth_mg_ros.fidelity.swing import run_swing

    try:
        block, _, _ = run_swing(spec, fabric_split=False)
    except (FloatingPointError, RuntimeError, np.linalg.LinAlgError) as err:
        return {"stable": False, "error": str(err)}
    block.pop("fit_curve", None)
    ok = math.isfinite(block["max_energy_ratio"]) and \
        block["max_energy_ratio"] <= STABLE_ENERGY_RATIO
    return {**block, "stable": bool(ok)}


def swing_rows(base, steps_per_s: tuple[int, ...]) -> list[dict]:
    """One row per (variant, step): the swing with the fabric's damping ("with_fabric") and
    without it ("integrator_only"), the frequency error in %, damping ratios, cost."""
    rows = []
    for scheme, radius in variants():
        for rate in steps_per_s:
            spec = replace(base, scheme=scheme, dt=1.0 / rate, spectral_radius=radius)
            fabric = _swing_cell(spec)
            bare = _swing_cell(replace(spec, fabric_damping=False))
            row = {"scheme": scheme, "spectral_radius": radius,
                   "label": variant_label(scheme, radius), "steps_per_s": rate,
                   "dt_s": 1.0 / rate, "with_fabric": fabric, "integrator_only": bare,
                   "stable": fabric["stable"] and bare["stable"]}
            rows.append(row)
            print(f"  swing {row['label']:>16} 1/{rate:<3d} s: " + _cell_text(row), flush=True)
    return rows


def _cell_text(row: dict) -> str:
    f, b = row["with_fabric"], row["integrator_only"]

    def unstable(c: dict) -> str:
        return "unstable (" + (c.get("error") or f"energy x{c['max_energy_ratio']:.3g}") + ")"

    bare = f"{b['damping_ratio']:.5f}" if b["stable"] else unstable(b)
    if not f["stable"]:
        return f"{unstable(f)}; integrator only {bare}"
    return (f"f {f['frequency_error_pct']:+.3f} %, zeta {f['damping_ratio']:.5f} (integrator "
            f"only {bare}), energy left {f['energy_left']:.3f}, "
            f"{f['cost_s_per_simulated_s']:.3f} s/s (CPU {f['cpu_s_per_simulated_s']:.3f})")


def walking_rows(particles: int, messages: int | None) -> list[dict]:
    """The walking dress per variant: its kinetic energy per pose message (J), the mean and
    peak over the stride (after the lead-in), and the median tick (ms)."""
    # imported here: the runner loads the garment machinery when the bench runs
    from cloth_mg_ros.apps.runner import run_body_scene
    from cloth_mg_ros.config.scenes import load_scene

    rows = []
    scene = load_scene("walking")
    for scheme, radius in variants():
        params = scene.replace(particles=particles, tolerance=WALK_TOLERANCE, scheme=scheme,
                               threads=1, **({} if radius is None else
                                             {"spectral_radius": radius}))
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            try:
                summary = run_body_scene(params, out, messages, n_frames=2, progress=False)
            except FloatingPointError as err:
                rows.append({"scheme": scheme, "spectral_radius": radius,
                             "label": variant_label(scheme, radius), "stable": False,
                             "error": str(err)})
                print(f"  walking {variant_label(scheme, radius):>16}: {err}", flush=True)
                continue
            wall = time.perf_counter() - t0
        ticks = summary["ticks"]
        stamps = np.array([t["stamp"] for t in ticks])
        t_rel = stamps - stamps[0] if len(stamps) else stamps
        ke = np.array([t["kinetic_energy"] for t in ticks])
        stride = ke[t_rel >= WALK_LEAD_IN_S] if np.any(t_rel >= WALK_LEAD_IN_S) else ke
        row = {"scheme": scheme, "spectral_radius": radius,
               "label": variant_label(scheme, radius), "stable": True,
               "particles": summary["particles"], "mass_kg": summary["mass_kg"],
               "messages": len(ticks), "time_s": t_rel.tolist(), "kinetic_j": ke.tolist(),
               "mean_kinetic_j": float(np.mean(stride)), "peak_kinetic_j": float(np.max(stride)),
               "mean_specific_kinetic_j_per_kg": float(np.mean(stride)) / summary["mass_kg"],
               "median_tick_ms": summary["median_total_ms"],
               "all_converged": summary["all_converged"], "wall_s": wall}
        rows.append(row)
        print(f"  walking {row['label']:>16}: mean KE over the stride "
              f"{1e3 * row['mean_kinetic_j']:.2f} mJ, peak {1e3 * row['peak_kinetic_j']:.2f} "
              f"mJ, median tick {row['median_tick_ms']:.1f} ms", flush=True)
    return rows


def bench_dynamics(base, steps_per_s: tuple[int, ...], walk_particles: int,
                   walk_messages: int | None) -> dict:
    """The whole bench: {"meta", "swing": rows, "walking": rows}."""
    t0 = time.perf_counter()
    print(f"swing: {base.material}, L {base.length:g} m x {base.width:g} m, amplitude "
          f"{1e3 * base.start_amplitude:.1f} mm, {base.particles} particles, "
          f"{base.run_duration:.2f} s; exact chain {base.exact_frequency:.4f} Hz", flush=True)
    swing = swing_rows(base, tuple(steps_per_s))
    print(f"walking: dress at {walk_particles} particles, tolerance {WALK_TOLERANCE:g}, one "
          f"step per pose message", flush=True)
    walking = walking_rows(walk_particles, walk_messages)
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    meta = {"machine": machine_id(), "commit": _commit(), "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "load_average": load,
            "threads": {k: os.environ.get(k, "unset")
                        for k in ("OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")},
            "swing": {"material": base.material, "length_m": base.length,
                      "width_m": base.width, "amplitude_m": base.start_amplitude,
                      "particles": base.particles, "duration_s": base.run_duration,
                      "exact_frequency_hz": base.exact_frequency, "solver": "direct"},
            "walking": {"scene": "walking", "bag": "walk", "particles": walk_particles,
                        "tolerance": WALK_TOLERANCE, "messages": walk_messages,
                        "solver_threads": 1},
            "stable_energy_ratio": STABLE_ENERGY_RATIO,
            "wall_s": time.perf_counter() - t0}
    return {"meta": meta, "swing": swing, "walking": walking}


def _commit() -> str | None:
    """The checkout's commit (and '+' when it has changes), or None outside a git checkout."""
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10, check=True)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "-uno"],
                               capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+" if dirty.stdout.strip() else "")


def format_report(result: dict) -> str:
    """The swing's table (one row per variant and step) and the walking table."""
    swing = result["swing"]
    rows = []
    for r in swing:
        f, b = r["with_fabric"], r["integrator_only"]
        head = [r["label"], f"1/{r['steps_per_s']}"]
        bare = f"{b['damping_ratio']:.5f}" if b["stable"] else "unstable"
        if not f["stable"]:
            rows.append(head + ["unstable", "", "", bare, "", "", ""])
            continue
        rows.append(head + [f"{f['frequency_hz']:.4f}", f"{f['frequency_error_pct']:+.3f}",
                            f"{f['damping_ratio']:.5f}", bare, f"{f['energy_left']:.3f}",
                            f"{f['cost_s_per_simulated_s']:.3f}",
                            f"{f['cpu_s_per_simulated_s']:.3f}"])
    exact = result["meta"]["swing"]["exact_frequency_hz"]
    text = [f"swing against the exact chain ({exact:.4f} Hz, damping ratio 0)",
            text_table(["scheme", "dt s", "f Hz", "f err %", "zeta", "zeta integrator",
                        "energy left", "cost s/s", "CPU s/s"], rows)]
    walk = [[w["label"], str(w.get("particles", "")),
             f"{1e3 * w['mean_kinetic_j']:.2f}" if w["stable"] else "unstable",
             f"{1e3 * w['peak_kinetic_j']:.2f}" if w["stable"] else "",
             f"{w['median_tick_ms']:.1f}" if w["stable"] else ""] for w in result["walking"]]
    text += ["\nwalking dress: kinetic energy over the stride (after the lead-in)",
             text_table(["scheme", "particles", "mean KE mJ", "peak KE mJ", "tick ms"], walk)]
    return "\n".join(text)


def _plot_variant(ax_f, ax_z, ax_c, rows: list[dict], label: str, c) -> None:
    """One variant's swing rows on the frequency, damping and cost panels (colour c)."""
    fab = [r for r in rows if r["with_fabric"]["stable"]]
    bare = [r for r in rows if r["integrator_only"]["stable"]]
    dt = [r["dt_s"] for r in fab]
    ax_f.plot(dt, [r["with_fabric"]["frequency_error_pct"] for r in fab], "o-", color=c,
              label=label)
    ax_z.plot(dt, [r["with_fabric"]["damping_ratio"] for r in fab], "o-", color=c,
              label=f"{label}, with the fabric's damping")
    ax_z.plot([r["dt_s"] for r in bare], [r["integrator_only"]["damping_ratio"]
                                          for r in bare], "s--", color=c, mfc="none",
              label=f"{label}, integrator only")
    ax_c.plot(dt, [r["with_fabric"]["cost_s_per_simulated_s"] for r in fab], "o-",
              color=c, label=f"{label}, wall clock")
    ax_c.plot(dt, [r["with_fabric"]["cpu_s_per_simulated_s"] for r in fab], "s--",
              color=c, mfc="none", label=f"{label}, CPU of the stepping thread")
    for r in rows:
        for part, marker in (("with_fabric", "x"), ("integrator_only", "+")):
            if not r[part]["stable"]:
                ax_z.plot([r["dt_s"]], [1e-5], marker, color=c, ms=10, mew=2)


def plot_dynamics(result: dict, png: str | Path) -> Path:
    """Four panels: frequency error and damping ratio against dt per variant (the exact
    chain's lines: 0 % and 0), cost per simulated second, the walking dress's kinetic
    energy over the clip."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11.0, 8.0))
    ax_f, ax_z, ax_c, ax_w = axes.ravel()
    labels = list(dict.fromkeys(r["label"] for r in result["swing"]))
    colours = dict(zip(labels, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for label in labels:
        _plot_variant(ax_f, ax_z, ax_c, [r for r in result["swing"] if r["label"] == label],
                      label, colours[label])
    meta = result["meta"]["swing"]
    ax_f.axhline(0.0, color="k", lw=1.0, label="exact chain")
    ax_f.axhspan(-2.0, 2.0, color="0.9", zorder=0, label="within 2 %")
    ax_z.axhline(0.0, color="k", lw=1.0, label="exact chain (0)")
    rates = sorted({r["steps_per_s"] for r in result["swing"]})
    for ax in (ax_f, ax_z, ax_c):
        ax.set_xscale("log")
        ax.set_xticks([1.0 / n for n in rates], [f"1/{n}" for n in rates])
        ax.minorticks_off()
        ax.set_xlabel("step dt, s")
    ax_f.set_ylabel("first-mode frequency error, %")
    ax_f.set_title(f"swing: {meta['material']}, L {meta['length_m']:g} m "
                   f"(chain {meta['exact_frequency_hz']:.4f} Hz)")
    ax_z.set_yscale("symlog", linthresh=1e-5)
    ax_z.set_ylim(bottom=0.0)
    ax_z.set_ylabel("damping ratio (x, +: unstable with, without the fabric's)")
    ax_z.set_title("damping ratio (the exact chain's is 0)")
    ax_c.set_yscale("log")
    ax_c.set_ylabel("s per simulated s (median step)")
    ax_c.set_title(f"cost, {meta['particles']} particles, direct solver")
    for w in result["walking"]:
        if w["stable"]:
            ax_w.plot(w["time_s"], 1e3 * np.array(w["kinetic_j"]), "-",
                      color=colours.get(w["label"]), label=w["label"])
    walk = result["meta"]["walking"]
    ax_w.set_xlabel("time in the clip, s")
    ax_w.set_ylabel("kinetic energy, mJ")
    ax_w.set_title(f"walking dress, {walk['particles']} particles, one step per pose message")
    for ax in (ax_f, ax_w):
        ax.legend(fontsize=7)
    ax_c.legend(fontsize=6)
    ax_z.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    return save_chart(fig, png)
