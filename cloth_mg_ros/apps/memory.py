"""Keeping freed memory in the process (glibc), so that a step's large temporaries are not
paged in afresh every step.

Each implicit step allocates and frees arrays of megabytes (a 20K-particle cloth: pair blocks,
face Hessians, coarse systems, about 8 MB each). glibc serves such sizes with mmap, or returns
a heap top that large to the system when it is freed, so the next step's array comes back as
fresh pages that the kernel faults in and zeroes on first touch. On a large cloth that
paging, not the kernels, took most of the internal forces' time (doc/design-measurements.md,
'Memory', has the figures). `keep_freed_memory` raises glibc's mmap and trim thresholds for
this process (mallopt); it changes the whole process's allocator, so the entry points
(cloth_node, cloth-mg) call it, not the library on import.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["keep_freed_memory"]

M_TRIM_THRESHOLD = -1  # glibc malloc.h
M_MMAP_THRESHOLD = -3
THRESHOLD_BYTES = 1 << 30  # 1 GiB: every array a cloth step makes stays below


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process; True when they were set
    (False off glibc, where nothing is changed)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(M_MMAP_THRESHOLD, THRESHOLD_BYTES)
                and mallopt(M_TRIM_THRESHOLD, THRESHOLD_BYTES))
