"""`bench dressing` over perturbed starts: the starts are a micrometre apart and reproducible,
N starts give N outcomes, the outcome shares sum to 1 and their 95 % intervals are Wilson's
score intervals, and the CLI writes every start's figures.

The runs here are test-sized (a few hundred particles, a short pull): behaviour, not the
benchmark's figures."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from cloth_mg_ros.apps.dressing_scene import DressingSpec, build_dressing, nudge_positions
from cloth_mg_ros.bench import dressing as bench
from cloth_mg_ros.bench.dressing_stats import (
    OUTCOMES,
    distribution,
    outcome_shares,
    proportion_interval,
    spread,
)
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError

Z95 = 1.959963984540054  # the normal distribution's 97.5th percentile


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson's score interval written out (Wilson 1927): the check on scipy's."""
    p, z2 = k / n, Z95 ** 2
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = Z95 / (1 + z2 / n) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return centre - half, centre + half


@pytest.mark.parametrize("k, n, expected", [(0, 10, (0.0, 0.2775)), (5, 10, (0.2366, 0.7634)),
                                            (10, 10, (0.7225, 1.0)), (3, 7, None),
                                            (1, 50, None)])
def test_the_interval_is_wilsons_score_interval(k, n, expected):
    low, high = proportion_interval(k, n)
    assert (low, high) == pytest.approx(wilson(k, n), abs=1e-9)
    if expected is not None:
        assert (low, high) == pytest.approx(expected, abs=5e-5)
    assert low <= k / n <= high and 0.0 <= low and high <= 1.0
    # a wider confidence, a wider interval
    wide = proportion_interval(k, n, 0.99)
    assert wide[0] <= low and wide[1] >= high and wide[1] - wide[0] > high - low
    with pytest.raises(ValueError):
        proportion_interval(n + 1, n)


def test_shares_sum_to_one_and_every_interval_holds_its_share():
    outcomes = ["good"] * 6 + ["caught"] * 3 + ["missed"]
    shares = outcome_shares(outcomes)
    assert set(shares) == set(OUTCOMES)
    assert sum(e["share"] for e in shares.values()) == pytest.approx(1.0)
    assert sum(e["count"] for e in shares.values()) == len(outcomes)
    assert shares["good"]["share"] == 0.6 and shares["missed"]["count"] == 1
    for e in shares.values():
        assert e["low"] <= e["share"] <= e["high"]


def test_spread_leaves_out_levels_never_reached():
    s = spread([None, 1.0, 2.0, 3.0, None, 4.0, 5.0])
    assert s["n"] == 5 and s["median"] == 3.0 and s["min"] == 1.0 and s["max"] == 5.0
    assert s["p10"] == pytest.approx(1.4) and s["p90"] == pytest.approx(4.6)
    assert spread([None, None])["median"] is None


def test_the_nudge_moves_every_point_by_its_size_reproducibly():
    x = np.random.default_rng(7).uniform(-0.3, 0.3, (500, 3))
    a = nudge_positions(x, 1e-6, seed=3, start=0)
    assert np.linalg.norm(a - x, axis=1) == pytest.approx(np.full(500, 1e-6), rel=1e-6)
    assert np.array_equal(a, nudge_positions(x, 1e-6, seed=3, start=0))  # same seed, same start
    b, c = nudge_positions(x, 1e-6, 3, 1), nudge_positions(x, 1e-6, 4, 0)
    for other in (b, c):  # another start or seed: another draw, a micrometre's size apart
        gap = np.linalg.norm(other - a, axis=1)
        assert np.all(gap <= 2e-6 + 1e-12) and np.median(gap) > 0.5e-6
    assert np.array_equal(nudge_positions(x, 0.0), x)


def test_starts_begin_a_micrometre_apart_in_the_scene():
    spec = DressingSpec(particles=300, travel=0.1)
    nominal = build_dressing(spec).sim.state.x
    starts = [build_dressing(s).sim.state.x for s in bench.starts_of(spec, 2, seed=5)]
    for x in starts:
        assert np.linalg.norm(x - nominal, axis=1) == pytest.approx(
            np.full(len(x), bench.NUDGE_M), rel=1e-6)
    assert 0.0 < np.abs(starts[0] - starts[1]).max() <= 2 * bench.NUDGE_M


# the bad pull, test-sized: a short settle and the cuff just past the fingertip
SMALL = DressingSpec(speed=0.15, angle_deg=15.0, particles=300, travel=0.15, settle_s=0.1,
                     label="small bad pull")


@pytest.fixture(scope="module")
def small():
    return bench.bench_dressing([SMALL], starts=3, seed=11, workers=1, progress=False,
                                log=lambda line: None)[0]


def test_n_starts_give_n_outcomes_whose_shares_sum_to_one(small):
    assert len(small["starts"]) == 3
    summaries = [s["summary"] for s in small["starts"]]
    assert [s["start"] for s in summaries] == [0, 1, 2]
    assert all(s["seed"] == 11 and s["start_nudge_m"] == bench.NUDGE_M for s in summaries)
    d = small["distribution"]
    assert d["starts"] == 3
    assert sum(e["count"] for e in d["outcomes"].values()) == 3
    assert sum(e["share"] for e in d["outcomes"].values()) == pytest.approx(1.0)
    for name, e in d["outcomes"].items():
        assert e["count"] == sum(s["outcome"] == name for s in summaries)
        assert e["low"] <= e["share"] <= e["high"]
    peaks = [s["peak_force_n"] for s in summaries]
    f = d["figures"]["peak_force_n"]
    assert f["min"] <= f["p10"] <= f["median"] <= f["p90"] <= f["max"]
    assert f["median"] == pytest.approx(np.median(peaks))
    assert small["frames"] and small["faces"] is not None  # start 0's pictures
    for start in small["starts"]:  # a trace runs to the run's last step
        assert start["trace"]["travel_m"][-1] == round(start["summary"]["final_travel_m"], 5)
    assert distribution(summaries) == d


def test_a_seed_and_start_reproduce_their_run_and_another_start_differs(small):
    again = bench.run_start(replace(SMALL, start_nudge=bench.NUDGE_M, seed=11, start=1))

    def figures(summary):
        return {k: v for k, v in summary.items() if k not in ("wall_s", "median_solve_ms")}

    assert figures(again["summary"]) == figures(small["starts"][1]["summary"])
    assert again["trace"] == small["starts"][1]["trace"]
    # the starts differ: the micrometre reaches the robot's force (not the same run)
    peaks = [s["summary"]["peak_step_force_n"] for s in small["starts"]]
    assert len(set(peaks)) == 3
    assert max(peaks) - min(peaks) < 0.01 * max(peaks)  # and so short a pull stays tame


def test_cli_writes_every_starts_figures(tmp_path, capsys):
    out = tmp_path / "dressing.json"
    assert main(["bench", "dressing", "--quick", "--starts", "1", "--particles", "300",
                 "--travel", "0.02", "--workers", "1", "--seed", "3", "--no-progress",
                 "--json", str(out), "--png", str(tmp_path / "c.png"),
                 "--strip", str(tmp_path / "s.png")]) == 0
    data = json.loads(out.read_text())
    assert data["starts"] == 1 and data["seed"] == 3 and data["start_nudge_m"] == 1e-6
    assert data["compression"] == "elastic"
    assert len(data["cases"]) == 3
    for case in data["cases"]:
        assert len(case["starts"]) == 1 and case["starts"][0]["summary"]["seed"] == 3
        assert case["spec"]["start_nudge"] == 1e-6 and case["spec"]["seed"] == 3
        assert sum(e["share"] for e in case["distribution"]["outcomes"].values()) == \
            pytest.approx(1.0)
        assert all(s["trace"]["force_n"] for s in case["starts"])
    assert (tmp_path / "c.png").stat().st_size > 0 and (tmp_path / "s.png").stat().st_size > 0
    assert data["complete"] and data["finished_starts"] == 3
    printed = capsys.readouterr().out
    assert "95 % Wilson score interval" in printed
    # the saved run's table again, without running
    assert main(["bench", "dressing", "--from-json", str(out), "--png",
                 str(tmp_path / "again.png")]) == 0
    table = printed[printed.index("\ncase"):printed.index("outcome:")]
    assert table in capsys.readouterr().out
    # resumed with the same cases, seed and nudge: every start is reused, none runs again
    before = data["cases"]
    assert main(["bench", "dressing", "--quick", "--starts", "1", "--particles", "300",
                 "--travel", "0.02", "--workers", "1", "--seed", "3", "--no-progress",
                 "--resume", "--json", str(out), "--png", str(tmp_path / "c.png"),
                 "--strip", str(tmp_path / "s.png")]) == 0
    assert "0 runs in" in capsys.readouterr().out
    assert json.loads(out.read_text())["cases"] == before


def test_cases_are_picked_by_name():
    specs = bench.cases(quick=False, particles=300)
    assert [bench.case_key(s) for s in specs] == ["still-0.10", "still-0.15", "moving-0.10",
                                                  "moving-0.15", "bad"]
    picked = bench.pick_cases(specs, "bad, still-0.15")
    assert [bench.case_key(s) for s in picked] == ["still-0.15", "bad"]
    assert {s.compression for s in specs} == {"elastic"}
    assert {s.compression for s in bench.cases(quick=True, compression="buckle")} == {"buckle"}
    with pytest.raises(ClothInputError, match="still-0.10"):
        bench.pick_cases(bench.cases(quick=True), "still-0.10")


@pytest.mark.parametrize("flags, named", [(["--starts", "0"], "--starts"),
                                          (["--seed", "-1"], "--seed"),
                                          (["--nudge", "0.1"], "--nudge"),
                                          (["--scheme", "leapfrog"], "--scheme"),
                                          (["--spectral-radius", "2"], "--spectral-radius"),
                                          (["--friction", "-1"], "--friction"),
                                          (["--compression", "soft"], "--compression"),
                                          (["--workers", "-2"], "--workers"),
                                          (["--travel", "0"], "--travel"),
                                          (["--cases", "fast"], "--cases"),
                                          (["--from-json", "/no/such.json"], "--from-json")])
def test_bad_options_are_refused_before_work(flags, named, capsys):
    assert main(["bench", "dressing", "--no-progress", *flags]) != 0
    assert named in capsys.readouterr().err


def test_bad_spec_fields_are_refused():
    for bad in ({"start_nudge": -1e-6}, {"seed": -1}, {"start": 1.5}, {"scheme": "rk4"},
                {"friction": float("nan")}, {"spectral_radius": 1.5}):
        with pytest.raises(ClothInputError):
            DressingSpec(**bad)
