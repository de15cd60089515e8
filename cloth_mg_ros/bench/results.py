"""Writing a benchmark's figures: JSON files that keep what it printed."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

__all__ = ["git_output", "recorded_path", "write_json"]

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


def git_output(*args: str) -> str | None:
    """A git command's output in this checkout (None outside one): what a benchmark's JSON
    records of the code it measured (the commit, files changed since)."""
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), *args], capture_output=True,
                             text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()
