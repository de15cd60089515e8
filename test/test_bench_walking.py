"""`cloth-mg bench walking` at ~300 particles: JSON, PNG, table, option validation."""

from __future__ import annotations

import json

import pytest
from matplotlib import pyplot as plt

from cloth_mg_ros.bench.walking import (
    PAPER_WALKING,
    format_walking_report,
    validate_walking_args,
)
from cloth_mg_ros.budget.tolerance_rule import LADDER
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.solve_tolerance import tolerance_at

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench

KEYS = ("particles", "solver", "ms_per_solve", "ms_per_tick", "iterations", "converged")


def test_bench_walking_cli_writes_json_and_png(tmp_path, capsys):
    out_json, out_png = tmp_path / "walk.json", tmp_path / "walk.png"
    rc = main(["bench", "walking", "--bag", "walk", "--garment", "dress", "--particles", "300",
               "--steps", "10", "--solvers", "bscg,mpcg", "--json", str(out_json),
               "--png", str(out_png)])
    assert rc == 0
    result = json.loads(out_json.read_text())
    assert set(result) >= {"runs", "meta"}
    assert [r["solver"] for r in result["runs"]] == ["bscg", "mpcg"]
    for run in result["runs"]:
        assert all(k in run for k in KEYS)
        assert 250 <= run["particles"] <= 350
        assert run["ticks"] == 10 and not run["skipped"]
        assert run["ms_per_solve"] > 0 and run["ms_per_tick"] >= run["ms_per_solve"]
        assert run["iterations"] >= 1
        assert run["converged"] is True  # one-level mpcg too (symmetric smoothing)
        assert run["warmup_ms"] > 0  # an untimed tick at this size came first
    meta = result["meta"]
    assert meta["tol"] == 1e-4 and meta["steps"] == 10 and meta["garment"] == "dress"
    assert meta["bag"] == "bags/walk"  # the bundled bag, relative to the repository
    assert meta["self_contact"] is True  # as in config/walking.yaml
    img = plt.imread(out_png)
    assert img.shape[0] > 100 and img.shape[1] > 100
    text = capsys.readouterr().out
    assert "ms per linear solve" in text and "ms per tick" in text and "bscg" in text
    report = format_walking_report(result)
    assert "mpcg" in report


def test_bench_walking_max_seconds_skips(tmp_path):
    out_json = tmp_path / "walk.json"
    rc = main(["bench", "walking", "--particles", "300", "--steps", "3", "--solvers", "bscg",
               "--max-seconds", "1e-9", "--json", str(out_json),
               "--png", str(tmp_path / "walk.png")])
    assert rc == 0
    (run,) = json.loads(out_json.read_text())["runs"]
    assert run["skipped"] and run["ticks"] == 1 and "max-seconds" in run["skip_reason"]


def test_bench_walking_tol_auto_takes_the_cost_models_tolerance_per_size(tmp_path, capsys,
                                                                          cost_model_cache,
                                                                          walking_calibration):
    # the walking scene's fabric on one thread: walking_calibration's cost model (the run's
    # cache), not a calibration of its own
    out_json = tmp_path / "walk.json"
    before = {p.name: p.stat().st_mtime_ns for p in cost_model_cache.glob("cost-*.json")}
    assert before  # walking_calibration's model, in the run's cache
    rc = main(["bench", "walking", "--particles", "300,1200", "--steps", "4", "--solvers",
               "mpcg", "--tol", "auto", "--material", "white-dots-on-blk", "--threads", "1",
               "--json", str(out_json),
               "--png", str(tmp_path / "walk.png")])
    assert rc == 0
    result = json.loads(out_json.read_text())
    meta = result["meta"]
    points = [tuple(p) for p in meta["tolerances"]]
    assert meta["tol"] == "auto" and len(points) == 2 and all(t in LADDER for _, t in points)
    # the cached model taken as it is, not calibrated again: its tolerances are the bench's
    assert {p.name: p.stat().st_mtime_ns for p in cost_model_cache.glob("cost-*.json")} == before
    assert points == [tuple(p) for p in walking_calibration.model.tolerances]
    assert len(result["runs"]) == len(result["sizes"]) == 2
    for run, size in zip(result["runs"], result["sizes"], strict=True):
        assert run["tol"] == size["tol"] == tolerance_at(points, run["particles"])
        assert run["ticks"] == 4 and run["converged"]
    text = capsys.readouterr().out
    assert "tol auto (" in text and "tolerance auto per size: " in text


def test_paper_table():
    assert len(PAPER_WALKING["particles"]) == len(PAPER_WALKING["pcg"]) == 5
    assert PAPER_WALKING["mg"][-1] == 458.9


def test_validation_lists_every_problem():
    with pytest.raises(ClothInputError) as err:
        validate_walking_args("no_such_bag", "hat", [5], ["nope", "pcg", "pcg"], "paper", 0,
                              2.0, -1.0)
    msg = str(err.value)
    for part in ("no_such_bag", "hat", "--particles", "nope", "twice", "paper", "--steps",
                 "--tol", "--max-seconds"):
        assert part in msg, part


def test_cli_rejects_bad_options(capsys):
    rc = main(["bench", "walking", "--solvers", "pcg,bogus", "--steps", "0", "--tol", "tight"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "bogus" in err and "--steps" in err and "'tight'" in err and "'auto'" in err
