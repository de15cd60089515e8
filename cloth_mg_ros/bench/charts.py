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
