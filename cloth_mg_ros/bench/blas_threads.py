"""One BLAS thread for the benchmarks that time BLAS-backed baselines.

The direct solver (CHOLMOD through cvxopt, SuperLU through scipy), the AMG baseline (PyAMG on
scipy) and numpy all call an OpenBLAS of their own wheel, each with as many threads as cores
unless told otherwise; our kernels run on the thread count the bench sets. Setting
OPENBLAS_NUM_THREADS after numpy's import is too late for the libraries already loaded, so
`one_blas_thread` does what threadpoolctl does without the dependency: it calls each loaded
OpenBLAS's own ``set_num_threads`` (found through /proc/self/maps and ctypes), and sets the
environment variables for the libraries loaded later (cvxopt's, when 'direct' first runs),
which read them when they load. `blas_threads` reads back the counts in effect.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["BLAS_ENV", "blas_thread_count", "blas_threads", "loaded_openblas",
           "one_blas_thread"]

BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

# (get, set) symbol names: plain OpenBLAS, and the scipy-openblas builds numpy and scipy ship
# (the 64-bit-integer one has a "64_" suffix).
_SYMBOLS = (("openblas_get_num_threads", "openblas_set_num_threads"),
            ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
            ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"))


def loaded_openblas() -> dict[str, tuple]:
    """{library path: (get_num_threads, set_num_threads)} for every OpenBLAS this process has
    loaded (Linux: read from /proc/self/maps; elsewhere: none found)."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return {}
    paths = sorted({line.split()[-1] for line in maps.splitlines()
                    if "openblas" in line.rsplit("/", 1)[-1].lower() and "/" in line})
    found = {}
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get_name, set_name in _SYMBOLS:
            if hasattr(lib, get_name) and hasattr(lib, set_name):
                found[path] = (getattr(lib, get_name), getattr(lib, set_name))
                break
    return found


def blas_threads() -> dict[str, int]:
    """{library file name: its thread count now} for every loaded OpenBLAS."""
    return {Path(p).name: int(get()) for p, (get, _set) in loaded_openblas().items()}


def blas_thread_count() -> int | None:
    """The most threads any loaded OpenBLAS uses now (None: none loaded, or not Linux)."""
    return max(blas_threads().values(), default=None)


@contextmanager
def one_blas_thread() -> Iterator[dict[str, int]]:
    """Within the block every loaded OpenBLAS uses one thread, and so will those loaded inside
    it (the environment says 1). Yields blas_threads() as set; restores the counts and the
    environment on exit (a library first loaded inside keeps its one thread)."""
    libs = loaded_openblas()
    before = {p: int(get()) for p, (get, _set) in libs.items()}
    env = {k: os.environ.get(k) for k in BLAS_ENV}
    os.environ.update({k: "1" for k in BLAS_ENV})
    for _get, setter in libs.values():
        setter(1)
    try:
        yield blas_threads()
    finally:
        for path, count in before.items():
            libs[path][1](count)
        for k, v in env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
