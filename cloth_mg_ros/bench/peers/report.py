"""`cloth-mg bench peers` output: the progress line of a run, the table the command prints
and the chart (ms per step against particles)."""

from __future__ import annotations

from pathlib import Path

from cloth_mg_ros.bench.charts import save_chart
from cloth_mg_ros.io.text_table import text_table


def peer_progress_line(row: dict) -> str:
    if row["skipped"]:
        return f"{row['label']:15s} skipped: {row['skip_reason']}"
    if not row["finite"]:
        return (f"{row['label']:15s} {row['ms_per_step']:9.1f} ms/step  NaN at step "
                f"{row['nan_at_step']}")
    return (f"{row['label']:15s} {row['ms_per_step']:9.1f} ms/step  sag {row['sag_m']:.3f} m  "
            f"hang {row['hang_m']:.3f} m  penetration {1e3 * row['max_penetration_m']:.2f} mm  "
            f"stretch {100 * (row['max_stretch'] - 1):.2f} % (peak "
            f"{100 * (row['peak_stretch'] - 1):.2f} %)")


def _cores(row: dict) -> str:
    return "-" if row.get("cpu_per_wall") is None else f"{row['cpu_per_wall']:.2f}"


def format_peers_report(result: dict) -> str:
    """The table printed by the CLI: ms per step per run and size, then every run's sanity
    figures, then the notes on the mapping."""
    runs, meta = result["runs"], result["meta"]
    head = (f"bench peers: drape ({meta['material']}), {meta['steps']} steps of "
            f"{meta['dt']:.4g} s, our kernel threads {meta.get('threads', '?')}, "
            f"BLAS threads {meta.get('blas_threads', '?')}, {meta['machine']}")
    lines = [head, ("ms per step of dt (median; substeps included); * = did not drape "
             f"(final mean height less than {meta['draped_sag_m']:g} m below the sphere's top), "
             "NaN = blew up, skip = not run")]
    lines += ["", _speed_table(runs), "", (
        "per run: cpu ms = the process's CPU time per step (median), cores = CPU over wall time, "
        "first ms = the first step, setup s = building the model (MuJoCo: compiling, once per "
        f"size for both its solvers); sphere top at {meta['sphere_top_m']:.2f} m: sag = how far "
        "the final mean height is below it, hang = the lowest particle; pen. = deepest inside "
        "the sphere or below the floor (any step / at the end); stretch = longest edge over its "
        "rest length at the end, and its peak with the step it happened")]
    lines.append(_runs_table(runs))
    skipped = {r["label"]: r["skip_reason"] for r in runs if r["skipped"]}
    for label, why in skipped.items():
        lines.append(f"skipped {label}: {why}")
    if meta.get("warmup_s"):
        lines.append("warm-up (JIT compile or cache load, not timed): " + ", ".join(
            f"{k} {v:.1f} s" for k, v in meta["warmup_s"].items()))
    lines += ["", "notes:"] + [f"- {n}" for n in meta["notes"]]
    return "\n".join(lines)


def _speed_table(runs: list[dict]) -> str:
    """ms per step: a row per engine:solver, a column per size."""
    labels = list(dict.fromkeys(r["label"] for r in runs))
    sizes = sorted({r["particles"] for r in runs if r["particles"] is not None})
    find = {(r["particles"], r["label"]): r for r in runs}

    def cell(r):
        if r is None:
            return "-"
        if r["skipped"]:
            return "skip"
        txt = f"{r['ms_per_step']:.1f}"
        if not r["finite"]:
            return txt + " NaN"
        return txt if r["draped"] else txt + " *"

    header = ["engine:solver (substeps)"] + [str(n) for n in sizes]
    rows = []
    for label in labels:
        some = next((r for r in runs if r["label"] == label and not r["skipped"]), None)
        sub = f" (x{some['substeps']})" if some and some.get("substeps", 1) > 1 else ""
        rows.append([label + sub] + [cell(find.get((n, label))) for n in sizes])
    return text_table(header, rows)


def _runs_table(runs: list[dict]) -> str:
    """Every run's timing and sanity figures, a row each."""
    header = ["run", "particles", "ms/step", "cpu ms", "cores", "first ms", "setup s",
              "mean z m", "sag m", "hang m", "pen. max/end mm", "stretch %", "peak % @step",
              "mass kg"]
    rows = []
    for r in runs:
        if r["skipped"]:
            rows.append([r["label"], str(r["particles"]), "skip"] + [""] * 11)
            continue
        timing = [f"{r['ms_per_step']:.1f}", f"{r['cpu_ms_per_step']:.1f}", _cores(r),
                  f"{r['first_step_ms']:.0f}", f"{r['setup_s']:.1f}"]
        if not r["finite"]:
            rows.append([r["label"], str(r["particles"])] + timing
                        + [f"NaN@{r['nan_at_step']}"] + [""] * 5 + [f"{r['mass_kg']:.4f}"])
            continue
        rows.append([r["label"], str(r["particles"])] + timing + [
            f"{r['mean_height_m']:.3f}", f"{r['sag_m']:.3f}", f"{r['hang_m']:.3f}",
            f"{1e3 * r['max_penetration_m']:.1f}/{1e3 * r['final_penetration_m']:.1f}",
            f"{100 * (r['max_stretch'] - 1):.2f}",
            f"{100 * (r['peak_stretch'] - 1):.1f} @{r['peak_stretch_step']}",
            f"{r['mass_kg']:.4f}"])
    return text_table(header, rows)


def plot_peers(result: dict, png: str | Path) -> Path:
    """ms per step against particles, log-log, one line per engine:solver (open markers: did
    not drape; crosses: NaN). Returns the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt


    meta = result["meta"]
    runs = [r for r in result["runs"] if not r["skipped"]]
    labels = list(dict.fromkeys(r["label"] for r in result["runs"]))
    fig, ax = plt.subplots(figsize=(10, 5.5))
    for i, label in enumerate(labels):
        rs = sorted((r for r in runs if r["label"] == label), key=lambda r: r["particles"])
        if not rs:
            continue
        colour = plt.cm.tab10(i % 10)
        style = "-" if label.startswith("ours") else "--"
        sub = rs[0].get("substeps", 1)
        name = label + (f" (x{sub} substeps)" if sub > 1 else "")
        ax.plot([r["particles"] for r in rs], [r["ms_per_step"] for r in rs], style,
                color=colour, marker="o", label=name)
        for r in rs:
            if not r["finite"]:
                ax.plot(r["particles"], r["ms_per_step"], "x", color="red", ms=12, mew=2.5)
            elif not r["draped"]:
                ax.plot(r["particles"], r["ms_per_step"], "o", ms=13, mfc="none", mec="grey",
                        mew=1.5)
    ax.plot([], [], "o", ms=13, mfc="none", mec="grey", linestyle="none",
            label=f"did not drape (sag < {meta['draped_sag_m']:g} m)")
    ax.plot([], [], "x", color="red", mew=2.5, linestyle="none", label="NaN")
    ax.set_xscale("log")
    ax.set_yscale("log")
    sizes = sorted({r["particles"] for r in runs})
    if sizes:
        ax.set_xticks(sizes, [str(n) for n in sizes])
        ax.minorticks_off()
    ax.set_xlabel("particles")
    ax.set_ylabel(f"ms per step of {meta['dt']:.4g} s (median)")
    ax.set_title(f"drape, {meta['material']}, {meta['steps']} steps: this solver vs Newton (CPU) "
                 f"and MuJoCo flex", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return save_chart(fig, png)
