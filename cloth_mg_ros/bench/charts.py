"""Writing the benchmarks' charts."""

from __future__ import annotations

from pathlib import Path


def save_chart(fig, png: str | Path) -> Path:
    """Save the matplotlib figure ``fig`` to ``png`` (folders made as needed, 110 dpi), close
    it, and return the written path."""
    # imported here: matplotlib (charts), loaded only when needed
    from matplotlib import pyplot as plt

    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def log_log_solver_axes(ax, ylabel: str) -> None:
    """The solver charts' shared frame: legend entries for a run that did not converge (red
    x) and one skipped over --max-seconds (open square), log-log axes, particles on x."""
    ax.plot([], [], marker="x", color="red", mew=2.5, linestyle="none", label="not converged")
    ax.plot([], [], marker="s", mfc="none", mec="grey", linestyle="none",
            label="skipped (over --max-seconds)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles")
    ax.set_ylabel(ylabel)
