"""Environment variables set for the length of a block (the ROS domain of a demo, one BLAS
thread for a benchmark), with the previous values put back."""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

__all__ = ["BLAS_ENV", "ONE_BLAS_THREAD", "environ_set"]

# The variables a BLAS (OpenBLAS, MKL) and OpenMP read their thread counts from at load.
BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
ONE_BLAS_THREAD = {k: "1" for k in BLAS_ENV}


@contextmanager
def environ_set(values: Mapping[str, str]) -> Iterator[None]:
    """Set os.environ[k] = v for every item until the block ends; then each variable has its
    previous value again, or is unset if it had none."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
