"""Output paths checked before any work: a run, a benchmark or an export that can only write
its results at the end must not find out then that its folder cannot be made (a file in the
way, no permission), with minutes of work lost and a traceback instead of an error that names
the flag."""

from __future__ import annotations

import os
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError

__all__ = ["check_output_dir", "check_output_file"]


def check_output_dir(path: str | os.PathLike, flag: str) -> Path:
    """`path` as a folder to write into (made later where missing); ClothInputError naming
    `flag` when it is a file or cannot be made."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ClothInputError(f"{flag} {path}: exists and is not a folder")
    _creatable(p, flag, path)
    return p


def check_output_file(path: str | os.PathLike, flag: str) -> Path:
    """`path` as a file to write (its folder made later where missing); ClothInputError
    naming `flag` when it is a folder or its folder cannot be made."""
    p = Path(path)
    if p.is_dir():
        raise ClothInputError(f"{flag} {path}: is a folder, not a file")
    _creatable(p.parent, flag, path)
    return p


def _creatable(folder: Path, flag: str, shown: object) -> None:
    """ClothInputError unless `folder` exists as a writable folder or can be made: its
    nearest existing ancestor a folder this process may write in."""
    nearest = folder if str(folder) else Path(".")
    while not nearest.exists():
        nearest = nearest.parent
    if not nearest.is_dir():
        raise ClothInputError(f"{flag} {shown}: {nearest} is a file, so the folder cannot be "
                              f"made")
    if not os.access(nearest, os.W_OK | os.X_OK):
        raise ClothInputError(f"{flag} {shown}: no permission to write in {nearest}")
