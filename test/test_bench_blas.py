"""One BLAS thread for the timed comparisons with BLAS-backed baselines (bench.blas_threads),
whatever the environment set before numpy loaded its OpenBLAS; bench matvec's options."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg  # noqa: F401 - scipy's own OpenBLAS, loaded as the benches load it

from cloth_mg_ros.bench.blas_threads import blas_threads, one_blas_thread
from cloth_mg_ros.bench.matvec import bench_matvec
from cloth_mg_ros.errors import ClothInputError

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench


@pytest.fixture
def two_blas_threads():
    """Every loaded BLAS on two threads (as without OPENBLAS_NUM_THREADS on a 2-core
    machine), put back afterwards."""
    from threadpoolctl import threadpool_limits

    if not blas_threads():
        pytest.skip("no BLAS found in this process")
    with threadpool_limits(limits=2, user_api="blas"):
        if max(blas_threads().values()) < 2:
            pytest.skip("this BLAS was built for one thread")
        yield


def test_one_blas_thread_sets_and_restores(two_blas_threads):
    assert max(blas_threads().values()) == 2
    with one_blas_thread() as inside:
        assert inside and set(inside.values()) == {1}
        np.dot(np.ones((64, 64)), np.ones((64, 64)))
        assert set(blas_threads().values()) == {1}
    assert max(blas_threads().values()) == 2


def test_matvec_json_records_one_blas_thread(two_blas_threads):
    result = bench_matvec(300, "cotton", repeat=10)
    assert result["blas_threads"] == 1
    # every timed product is the product: each method against SciPy's CSR, to rounding
    errors = result["rel_error_vs_csr"]
    assert errors and max(errors.values()) < 1e-12, errors
    assert max(blas_threads().values()) == 2  # the caller's setting is back


@pytest.mark.parametrize("kwargs, match", [
    ({"repeat": 3}, "--repeat"),  # below one batch: used to time 5 products silently
    ({"repeat": 0}, "--repeat"),
    ({"particles": 5}, "--particles"),
    ({"particles": 10**9}, "--particles"),
    ({"material": "paper"}, "--material"),
])
def test_matvec_options_checked_before_any_work(monkeypatch, kwargs, match):
    from cloth_mg_ros.bench import matvec

    def no_work(*args, **kw):
        raise AssertionError("work started before the options were checked")

    monkeypatch.setattr(matvec, "bench_system", no_work)
    args = {"particles": 300, "material": "cotton", "repeat": 10} | kwargs
    with pytest.raises(ClothInputError, match=match):
        matvec.bench_matvec(**args)
