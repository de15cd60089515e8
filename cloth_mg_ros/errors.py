"""The project's error type for bad input (meshes, files, parameters).

Every check on user-supplied data raises `ClothInputError`, so callers (the ROS node, the
command-line tools, tests) can catch one type and show its message. Messages name what is
wrong and where: the file or source, the field, the offending index and value.
"""

from __future__ import annotations

__all__ = ['ClothInputError']


class ClothInputError(ValueError):
    """Bad input: a malformed mesh file, an invalid mesh, or an out-of-range parameter.

    Subclasses ValueError so that generic `except ValueError` handlers still catch it.
    """
