"""One BLAS thread for the benchmarks that time BLAS-backed baselines.

The direct solver (CHOLMOD through cvxopt, SuperLU through scipy), the AMG baseline (PyAMG on
scipy) and numpy all call a BLAS of their own wheel, each with as many threads as cores unless
told otherwise; our kernels run on the thread count the bench sets. Setting
OPENBLAS_NUM_THREADS after numpy's import is too late for the libraries already loaded, so
`one_blas_thread` limits every loaded BLAS through threadpoolctl (which finds each one and
calls its own thread setter) and sets the environment variables for the libraries loaded
later (cvxopt's, when 'direct' first runs), which read them when they load. `blas_threads`
reads back the counts in effect.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from cloth_mg_ros.environment import ONE_BLAS_THREAD, environ_set
from cloth_mg_ros.extras import require_extra

__all__ = ["blas_thread_count", "blas_threads", "one_blas_thread"]



def _threadpoolctl():
    # imported here: threadpoolctl comes with the 'bench' extra
    require_extra("threadpoolctl", "a benchmark's BLAS thread limit")
    import threadpoolctl

    return threadpoolctl


def blas_threads() -> dict[str, int]:
    """{library file name: its thread count now} for every BLAS this process has loaded."""
    info = _threadpoolctl().threadpool_info()
    return {Path(i["filepath"]).name: int(i["num_threads"]) for i in info
            if i.get("user_api") == "blas"}


def blas_thread_count() -> int | None:
    """The most threads any loaded BLAS uses now (None: none loaded)."""
    return max(blas_threads().values(), default=None)


@contextmanager
def one_blas_thread() -> Iterator[dict[str, int]]:
    """Within the block every loaded BLAS uses one thread, and so will those loaded inside it
    (the environment says 1). Yields blas_threads() as set; restores the counts and the
    environment on exit (a library first loaded inside keeps its one thread)."""
    with environ_set(ONE_BLAS_THREAD), \
            _threadpoolctl().threadpool_limits(limits=1, user_api="blas"):
        yield blas_threads()
