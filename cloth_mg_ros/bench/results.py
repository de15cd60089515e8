"""Writing a benchmark's figures: JSON files that keep what it printed."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["recorded_path", "write_json"]

REPO_ROOT = Path(__file__).resolve().parents[2]  # the checkout holding cloth_mg_ros/


def recorded_path(path: str | Path) -> str:
    """How a benchmark's JSON records a file it read (a bag): relative to the repository when
    it lies inside it (bags/walk, the same on every machine and checkout), else absolute."""
    path = Path(path).resolve()
    try:
        return path.relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return str(path)


def write_json(path: str | Path, result: dict) -> Path:
    """Write a benchmark's figures to ``path`` (folders made as needed); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    return path
