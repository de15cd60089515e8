"""Grids of independent runs on Dask distributed: `cloth-mg batch` and the benchmark sweeps.

    with dask_client() as client:                          # an embedded LocalCluster
        for item, result, error in run_tasks(client, fn, items, desc="runs"):
            ...
    with dask_client("tcp://10.0.0.5:8786") as client:     # a running cluster
        ...

The embedded cluster has one single-threaded worker process per core (``workers``), each
with OPENBLAS_NUM_THREADS=1 (a BLAS with threads of its own oversubscribes the cores), and
NUMBA_CACHE_DIR left as it is, so every worker of a machine loads the same on-disk numba
caches (compiled once, by whichever worker gets there first). A running cluster is one that
Dask's own commands started (`dask scheduler`, then `dask worker tcp://HOST:8786
--nthreads 1` on each machine, with this package installed); its workers' environment is
theirs to set.

Tasks are submitted with Dask's retries: a task whose worker died (killed, out of memory, a
lost machine) runs again on another worker, up to ``retries`` times. A task that raises is
not retried (a bad input fails the same way everywhere): `run_tasks` hands its exception
back beside the item, so the caller records it and the grid goes on.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from tqdm import tqdm

from cloth_mg_ros.environment import ONE_BLAS_THREAD
from cloth_mg_ros.errors import ClothInputError

__all__ = ["RETRIES", "dask_client", "gather_all", "local_workers", "run_tasks"]

RETRIES = 2  # resubmissions of a task whose worker was lost
CONNECT_TIMEOUT_S = 10.0  # wait this long for a --scheduler to answer
WORKER_ENV = ONE_BLAS_THREAD  # single-threaded workers: one BLAS thread each too


def local_workers(workers: int | None = None) -> int:
    """The embedded cluster's worker count: `workers`, or one per core this process may use.

    Raises ClothInputError for a count below 1."""
    if workers is None or workers == 0:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                   else os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ClothInputError(f"--workers must be a positive integer, got {workers!r}")
    return workers


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None,
                log: Callable[[str], None] | None = None) -> Iterator[Any]:
    """A distributed.Client: on the running cluster at `scheduler` ('tcp://HOST:PORT'), or
    on an embedded LocalCluster of `workers` single-threaded worker processes (None or 0: one
    per core). Both are closed on exit.

    Raises ClothInputError when the scheduler cannot be reached (naming it)."""
    # imported here: dask.distributed (the cluster), loaded only when needed
    from distributed import Client, LocalCluster

    say = log or (lambda line: print(line, file=sys.stderr, flush=True))
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            raise ClothInputError(f"--scheduler {scheduler}: no Dask scheduler answered "
                                  f"within {CONNECT_TIMEOUT_S:g} s ({exc})") from None
        n = len(client.scheduler_info().get("workers", {}))
        say(f"dask: scheduler {scheduler}, {n} worker(s)")
        try:
            yield client
        finally:
            client.close()
        return
    n = local_workers(workers)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=":0", env=dict(WORKER_ENV),
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    say(f"dask: embedded LocalCluster, {n} single-threaded worker(s)")
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def run_tasks(client, fn: Callable, items: Sequence, *, retries: int = RETRIES,
              desc: str = "tasks", progress: bool = True,
              ) -> Iterator[tuple[Any, Any, BaseException | None]]:
    """Run fn(item) for every item as a Dask task; yield (item, result, None) or (item, None,
    exception) as each finishes, in completion order, under a progress bar (stderr).

    A task whose worker is lost is retried up to `retries` times by Dask; an exception raised
    by fn is returned, never raised, so one failing item does not stop the others."""
    # imported here: dask.distributed (the cluster), loaded only when needed
    from distributed import as_completed

    futures = {client.submit(fn, item, retries=retries, pure=False): item for item in items}
    bar = tqdm(total=len(futures), desc=desc, unit="task", disable=not progress,
               file=sys.stderr, mininterval=0.5 if sys.stderr.isatty() else 10.0)
    try:
        for future in as_completed(futures):
            item = futures[future]
            try:
                result, error = future.result(), None
            except Exception as exc:  # noqa: BLE001 - handed back to the caller
                result, error = None, exc
            finally:
                future.release()
            bar.update(1)
            yield item, result, error
    finally:
        bar.close()
        for future in futures:
            future.cancel()


def gather_all(client, fn: Callable, items: Iterable, **kwargs) -> list:
    """fn(item) for every item through `run_tasks`, in the order of `items`; the first
    exception is raised (for sweeps whose cells must all succeed)."""
    items = list(items)
    results: dict[int, Any] = {}
    for (k, _), result, error in run_tasks(client, _Indexed(fn), list(enumerate(items)),
                                           **kwargs):
        if error is not None:
            raise error
        results[k] = result
    return [results[k] for k in range(len(items))]


class _Indexed:
    """fn applied to the item of a (position, item) pair (picklable, unlike a lambda)."""

    def __init__(self, fn: Callable) -> None:
        self.fn = fn

    def __call__(self, pair: tuple[int, Any]) -> Any:
        return self.fn(pair[1])
