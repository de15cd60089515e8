"""The one OS thread that runs every numba kernel of cloth_node: the calibration and the
warm-up at start as well as every tick.

Why one thread: numba's parallel kernels (its OpenMP layer) keep a team of helper threads per
OS thread that calls them; a second calling thread doubles the teams, oversubscribes the cores,
and OpenMP stops spinning at its barriers and sleeps in the kernel instead: every parallel
region then pays a sleep and a wake (doc/architecture.md, "The threading model", has the
measurements).

Why a thread of its own at all: with the step in a callback of the executor that also serves
the pose subscription, poses wait in a FIFO backlog behind each step; with the step on this
thread and kernels that release the GIL, the subscription's callback runs within a
millisecond (the same page).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

__all__ = ["SimThread"]


class SimThread:
    """`call` runs a function on the simulation thread and returns its result (or raises its
    exception) to the caller; `submit` starts one without waiting (the tick loop)."""

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cloth_sim")

    def call(self, fn: Callable, *args, **kwargs):
        return self._pool.submit(fn, *args, **kwargs).result()

    def submit(self, fn: Callable) -> Future:
        return self._pool.submit(fn)

    def shutdown(self) -> None:
        """No more work: the thread ends once the function it runs returns."""
        self._pool.shutdown(wait=False)
