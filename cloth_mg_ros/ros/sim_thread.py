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

Why a daemon thread: should a tick never end (a stop that timed out: ros.session logs it),
the process must still exit; a ThreadPoolExecutor's worker would be joined at the
interpreter's exit and hang it. A daemon thread is simply abandoned at exit, after everything
else (the DELETEALL, the summary) has run; os._exit would skip that too, so it is not used.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future

__all__ = ["SimThread"]


class SimThread:
    """`call` runs a function on the simulation thread and returns its result (or raises its
    exception) to the caller; `submit` starts one without waiting (the tick loop); functions
    run one at a time, in the order given."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        # check-and-put under one lock with close-and-sentinel: a job submitted while the
        # thread shuts down is either queued before the sentinel or refused, never lost
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="cloth_sim", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            future, fn, args, kwargs = job
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn(*args, **kwargs)
            except BaseException as exc:  # handed to the caller, as an executor does
                future.set_exception(exc)
            else:
                future.set_result(result)
            del job, future, fn, args, kwargs  # nothing held between jobs

    def call(self, fn: Callable, *args, **kwargs):
        return self.submit(fn, *args, **kwargs).result()

    def submit(self, fn: Callable, *args, **kwargs) -> Future:
        future: Future = Future()
        with self._lock:
            if self._closed:
                raise RuntimeError("the simulation thread was shut down")
            self._jobs.put((future, fn, args, kwargs))
        return future

    @property
    def alive(self) -> bool:
        """Whether the thread still runs (a function, or waits for one)."""
        return self._thread.is_alive()

    def shutdown(self) -> None:
        """No more work: the thread ends once the function it runs returns."""
        with self._lock:
            self._closed = True
            self._jobs.put(None)
