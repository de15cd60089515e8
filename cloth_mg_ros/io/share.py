"""Packaged resources: where config/ and bags/ live, in the source tree or in an installed
share/cloth_mg_ros/ (ament index, AMENT_PREFIX_PATH, sys.prefix).

`share_path('bags', 'walk')` / `config_path('avatar.yaml')` return the first place that has the
file, and raise ClothInputError naming every place tried when none has it.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError

__all__ = ['PACKAGE', 'config_path', 'share_path']

PACKAGE = 'cloth_mg_ros'


def _share_dirs() -> Iterator[Path]:
    """Candidate roots holding config/ and bags/: the source tree, then installed share dirs
    (ament index, AMENT_PREFIX_PATH, sys.prefix). Lazy: the ament index is only asked when the
    source tree does not have the resource."""
    yield Path(__file__).resolve().parents[2]
    share = None
    # not installed, no ament index, AMENT_PREFIX_PATH unset: each raises something else
    with contextlib.suppress(Exception):
        # imported here: the ament index is optional (a ROS installation), asked only when the
        # source tree lacks the file
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory(PACKAGE))
    if share is not None:
        yield share
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            yield Path(prefix) / 'share' / PACKAGE
    yield Path(sys.prefix) / 'share' / PACKAGE


def share_path(*parts: str) -> Path:
    """Path of a packaged resource, e.g. share_path('bags', 'walk') or ('config', 'avatar.yaml').

    Looks in the source tree first (the repository's config/ and bags/), then in the installed
    share/cloth_mg_ros/ (ament index, AMENT_PREFIX_PATH, sys.prefix). ClothInputError lists the
    places tried if none has it.
    """
    tried: list[str] = []
    for root in _share_dirs():
        candidate = root.joinpath(*parts)
        if candidate.exists():
            return candidate
        if str(candidate) not in tried:
            tried.append(str(candidate))
    raise ClothInputError(f'{"/".join(parts)}: not found (looked in {", ".join(tried)})')


def config_path(name: str) -> Path:
    """Path of config/<name> in the source tree or in the installed share/cloth_mg_ros/config."""
    return share_path('config', name)
