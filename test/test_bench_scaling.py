"""`cloth-mg bench scaling`: slopes, a two-size run in fresh processes, option checks."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from matplotlib import pyplot as plt

from cloth_mg_ros.bench.scaling import format_scaling_report, loglog_slope
from cloth_mg_ros.cli.main import main

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench


def test_loglog_slope():
    n = [1e3, 2e3, 4e3, 8e3]
    assert loglog_slope(n, [3.0 * x ** 1.5 for x in n]) == pytest.approx(1.5)
    assert loglog_slope(n[:1], [1.0]) is None
    assert loglog_slope(n, [None, 0.0, 2.0, 4.0]) == pytest.approx(1.0)


def test_bench_scaling_runs_each_size_in_its_own_process(tmp_path):
    out_json, out_png = tmp_path / "s.json", tmp_path / "s.png"
    rc = main(["bench", "scaling", "--particles", "300,1200", "--solvers", "mpcg",
               "--steps", "3", "--json", str(out_json), "--png", str(out_png)])
    assert rc == 0
    result = json.loads(out_json.read_text())
    small, big = result["runs"]
    for r in (small, big):
        assert r["solver"] == "mpcg" and not r["skipped"] and r["ticks"] == 3
        assert r["converged"] and r["ms_per_tick"] > 0.0
        assert r["peak_rss_mb"] >= r["baseline_rss_mb"] > 0.0
        assert r["memory_mb"] == pytest.approx(r["peak_rss_mb"] - r["baseline_rss_mb"])
    assert big["particles"] > 3 * small["particles"]
    assert len({small["pid"], big["pid"], os.getpid()}) == 3  # each run a process of its own
    assert big["levels"] > small["levels"]
    slope = result["slopes"]["mpcg"]
    assert slope["sizes"] == [small["particles"], big["particles"]]
    assert np.isfinite(slope["time"])
    assert plt.imread(out_png).shape[0] > 100
    assert "ms per tick" in format_scaling_report(result)


def test_bench_scaling_rejects_bad_options(capsys):
    assert main(["bench", "scaling", "--particles", "8,abc"]) == 2
    assert main(["bench", "scaling", "--particles", "1200", "--solvers", "nope",
                 "--steps", "0"]) == 2
    err = capsys.readouterr().err
    assert "bench scaling" in err and "nope" in err and "--steps" in err


class _Done:
    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


class _FakeClient:
    """Answers each run at once: 'amg' unavailable, 'mg' over --max-seconds at 300."""

    def submit(self, fn, cell, **kwargs):
        if cell["solver"] == "amg":
            return _Done({"skipped": True, "skip_reason": "unavailable: needs pyamg"})
        return _Done({"particles": cell["particles"], "skipped": True,
                      "skip_reason": "first tick took 9 s > --max-seconds 1"})


def test_a_solver_skipped_as_unavailable_keeps_its_reason_at_larger_sizes():
    from cloth_mg_ros.bench.scaling import scaling_runs

    cell = {"bag": "walk", "garment": "dress", "material": "cotton", "steps": 3,
            "tol": 1e-4, "max_seconds": 1.0, "threads": 1}
    runs = scaling_runs(_FakeClient(), cell, [300, 1200], ["amg", "mg"], lambda line: None)
    later = {r["solver"]: r for r in runs if r["particles_requested"] == 1200}
    assert later["amg"]["skip_reason"] == "unavailable: needs pyamg"  # not "over --max-seconds"
    assert later["mg"]["skip_reason"] == "first tick over --max-seconds at 300 particles"
