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
