"""How many threads the solver's kernels use.

numba's thread count is per calling thread (`numba.set_num_threads`), so whoever steps a
simulation sets it in the thread that steps (`use_threads`). The multigrid's threaded sweeps
split each level into as many parts as threads (solvers.dissection): the ordering, and so the
arithmetic, follows the thread count asked for, never how the threads are scheduled.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numba

from cloth_mg_ros.errors import ClothInputError

__all__ = ["available_threads", "resolve_threads", "threads_for_block", "use_threads"]


def available_threads() -> int:
    """The threads numba may use on this machine (its NUMBA_NUM_THREADS: the cores)."""
    return int(numba.config.NUMBA_NUM_THREADS)


def resolve_threads(threads: int) -> int:
    """`threads` (0: every core) as a count in 1..available_threads(); ClothInputError for a
    negative or non-integer value."""
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 0:
        raise ClothInputError(f"threads must be a non-negative integer (0: every core), got "
                              f"{threads!r}")
    return min(threads, available_threads()) if threads else available_threads()


def use_threads(threads: int) -> int:
    """Let the calling thread's kernels use `threads` threads (0: every core); returns the
    count."""
    count = resolve_threads(threads)
    if numba.get_num_threads() != count:
        numba.set_num_threads(count)
    return count


@contextmanager
def threads_for_block(threads: int) -> Iterator[int]:
    """`use_threads(threads)` until the block ends, then the calling thread's count before it
    again (a benchmark's setting does not outlive it); yields the count."""
    before = numba.get_num_threads()
    try:
        yield use_threads(threads)
    finally:
        numba.set_num_threads(before)
