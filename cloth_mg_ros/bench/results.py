"""Writing a benchmark's figures: JSON files that keep what it printed."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["write_json"]


def write_json(path: str | Path, result: dict) -> Path:
    """Write a benchmark's figures to ``path`` (folders made as needed); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    return path
