"""bench trackers: a live run's figures pooled over repeats; bad options refused first."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.bench.trackers import bench_trackers, pooled
from cloth_mg_ros.errors import ClothInputError


def _run(sent: int, ticks: list[float], depths: list[float], skipped: dict) -> dict:
    return {"sent": sent, "poses_received": sent, "poses_used": sent - sum(skipped.values()),
            "dropped": 0, "poses_pending": 0, "segments_dropped": 1, "joints_held": 2,
            "joints_lost": 0, "ticks": len(ticks), "non_finite": 0, "skipped": skipped,
            "tick_penetration_m": np.array(ticks), "marker_depths_m": np.array(depths)}


def test_runs_pool_their_counts_ticks_and_markers():
    a = _run(10, [0.001, 0.002], [0.0, 0.0, 0.004], {"stale": 1})
    b = _run(12, [0.003], [0.0, 0.010], {"stale": 2, "bad": 1})
    live = pooled([a, b])
    assert (live["sent"], live["poses_used"], live["ticks"], live["segments_dropped"]) == (
        22, 18, 3, 2)
    assert live["skipped"] == {"stale": 3, "bad": 1}
    depths = [0.0, 0.0, 0.004, 0.0, 0.010]
    assert live["true_penetration_m"] == {"markers": 5, "p50": 0.0,
                                          "p95": pytest.approx(np.percentile(depths, 95)),
                                          "max": 0.010}
    assert live["penetration_m"]["max"] == 0.003
    assert live["penetration_m"]["p50"] == pytest.approx(0.002)
    # each run's own figures are kept
    assert [r["true_penetration_m"]["markers"] for r in live["runs"]] == [3, 2]
    assert live["runs"][1]["true_penetration_m"]["max"] == 0.010
    # a run with no ticks and no markers adds nothing
    empty = _run(0, [], [], {})
    assert pooled([a, empty])["true_penetration_m"] == pooled([a])["true_penetration_m"]


def test_repeats_must_be_a_positive_integer(tmp_path):
    bvh = tmp_path / "clip.bvh"
    bvh.write_text("HIERARCHY\n")
    with pytest.raises(ClothInputError, match="--repeats"):
        bench_trackers(bvh, repeats=0)


def _rows(segment_depths: list[float], kinect_depths: list[float], received: int) -> dict:
    caps = {"p95_m": 0.001, "max_m": 0.002, "segments_dropped": 0, "floor_found_m": 0.0}
    rows = {}
    for name, depths in (("segments", segment_depths), ("kinect32", kinect_depths)):
        run = _run(5, [0.001], depths, {})
        run["markers_received"] = received
        rows[name] = {"live": pooled([run])}
    rows["kinect32"]["capsules"] = caps
    return rows


def test_no_matched_markers_gives_no_figure_and_fails_the_verdict():
    from cloth_mg_ros.bench.trackers import _percentiles, _verdicts

    assert _percentiles(np.zeros(0)) == {"p50": None, "p95": None, "max": None}
    live = pooled([_run(3, [], [], {})])
    assert live["true_penetration_m"] == {"markers": 0, "p50": None, "p95": None, "max": None}
    assert live["penetration_m"]["p95"] is None
    rows = _rows([0.0, 0.001], [0.0, 0.001], 2)
    assert _verdicts(rows) and all(r["holds"] for r in rows.values())
    # no marker matched: nothing measured, so nothing holds (an empty sample read as 0 did)
    rows = _rows([], [], 0)
    assert not _verdicts(rows)
    assert not rows["segments"]["holds"] and not rows["kinect32"]["penetration_within"]
    # fewer matched than received: the unmatched ones are unchecked
    rows = _rows([0.0, 0.001], [0.0, 0.001], 3)
    assert not _verdicts(rows) and not rows["kinect32"]["markers_matched"]
