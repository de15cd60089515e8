"""bench cost: every option checked before the cost model's calibration (minutes of work)."""

from __future__ import annotations

import pytest

from cloth_mg_ros.bench import cost
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError


@pytest.fixture
def no_calibration(monkeypatch):
    """Fail the test if the calibration starts."""
    def calibrate(*args, **kwargs):
        raise AssertionError("calibration started before the options were checked")

    monkeypatch.setattr(cost, "load_or_calibrate", calibrate)


@pytest.mark.parametrize("sizes, ticks, match", [
    ([1200], 5, "--ticks"),  # passed the old check (>= 1), failed after the calibration
    ([1200], cost.MIN_TIMED_TICKS - 1, "--ticks"),
    ([10], 60, "--particles"),
    ([1200, 10**7], 60, "--particles"),
    ([], 60, "--particles"),
    ([1200.5], 60, "--particles"),
])
def test_bad_options_refused_before_calibration(no_calibration, sizes, ticks, match):
    with pytest.raises(ClothInputError, match=match):
        cost.bench_cost("walking", sizes, ticks, log=lambda line: None)


def test_cli_refuses_few_ticks_before_calibration(no_calibration, capsys):
    assert main(["bench", "cost", "--particles", "1200", "--ticks", "3"]) == 2
    assert "--ticks" in capsys.readouterr().err


def test_good_options_reach_the_calibration(no_calibration):
    with pytest.raises(AssertionError, match="calibration started"):
        cost.bench_cost("walking", [1200], cost.MIN_TIMED_TICKS, log=lambda line: None)


def test_contact_friction_is_checked_before_calibration_and_reaches_it(no_calibration,
                                                                       monkeypatch):
    with pytest.raises(ClothInputError, match="contact"):
        cost.bench_cost("walking", [1200], cost.MIN_TIMED_TICKS, log=lambda line: None,
                        contact_friction="sideways")
    seen = {}

    def calibrate(options, material, log=None, refresh=False, bag="walk"):
        seen["contact_friction"] = options.contact_friction
        raise AssertionError("calibration started")

    monkeypatch.setattr(cost, "load_or_calibrate", calibrate)
    with pytest.raises(AssertionError, match="calibration started"):
        cost.bench_cost("walking", [1200], cost.MIN_TIMED_TICKS, log=lambda line: None,
                        contact_friction="solve")
    assert seen == {"contact_friction": "solve"}  # the calibration's garment takes it
