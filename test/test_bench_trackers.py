"""bench trackers: a live run's figures pooled over repeats; bad options refused first; the true
penetration (marker_depths): each marker's deepest corner in the true body's colliding capsules."""

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
    from cloth_mg_ros.bench.node_figures import percentiles
    from cloth_mg_ros.bench.trackers import verdicts

    assert percentiles(np.zeros(0)) == {"p50": None, "p95": None, "max": None}
    live = pooled([_run(3, [], [], {})])
    assert live["true_penetration_m"] == {"markers": 0, "p50": None, "p95": None, "max": None}
    assert live["penetration_m"]["p95"] is None
    rows = _rows([0.0, 0.001], [0.0, 0.001], 2)
    assert verdicts(rows) and all(r["holds"] for r in rows.values())
    # no marker matched: nothing measured, so nothing holds (an empty sample read as 0 did)
    rows = _rows([], [], 0)
    assert not verdicts(rows)
    assert not rows["segments"]["holds"] and not rows["kinect32"]["penetration_within"]
    # fewer matched than received: the unmatched ones are unchecked
    rows = _rows([0.0, 0.001], [0.0, 0.001], 3)
    assert not verdicts(rows) and not rows["kinect32"]["markers_matched"]


def test_marker_depths_are_each_markers_deepest_corner_in_the_true_colliding_capsules():
    from cloth_mg_ros.bench.trackers import marker_depths
    from cloth_mg_ros.io.messages.markers import marker_triangle_list_bytes
    from cloth_mg_ros.motion.joint_body import packaged_avatar, zero_pose

    avatar = packaged_avatar()
    rest = zero_pose(avatar)[0]  # (16, 7): the T-pose, pelvis at the origin
    moved = rest.copy()
    moved[:, 0] += 1.0  # the body 1 m along x at the second stamp
    truth = {12_345_000_000: rest, 12_378_000_000: moved}  # stamp ns -> segment poses
    p0, p1, r = avatar.capsules(rest)
    head, hand = avatar.names.index("head"), avatar.names.index("hand_l")
    up = (p1[head] - p0[head]) / np.linalg.norm(p1[head] - p0[head])
    inside = p1[head] + (r[head] - 0.005) * up  # 5 mm under the top of the head
    outside = p1[head] + (r[head] + 0.2) * up  # 0.2 m above it, clear of every capsule
    in_3mm = p1[head] + (r[head] - 0.003) * up + [1.0, 0.0, 0.0]  # in the moved head

    def marker(sec: int, nanosec: int, *corners) -> bytes:
        pts = np.array(corners, dtype=float).reshape(-1, 3)
        return marker_triangle_list_bytes(pts, np.arange(len(pts)).reshape(-1, 3), sec,
                                          nanosec)

    markers = [
        marker(12, 345_000_000, outside, inside, outside),  # its deepest corner: 5 mm
        marker(12, 345_000_000, outside, outside, outside),  # outside the body: 0
        marker(12, 378_000_000, in_3mm, in_3mm, in_3mm),  # against its own stamp's body
        # inside the left hand, whose capsule the default garment (a dress) leaves out
        marker(12, 345_000_000, *[(p0[hand] + p1[hand]) / 2] * 3),
        marker(12, 345_000_001, inside, inside, inside),  # a stamp the truth lacks: left out
        marker(12, 345_000_000),  # no points: left out
    ]
    depths = marker_depths(markers, truth)
    assert depths == pytest.approx([0.005, 0.0, 0.003, 0.0], abs=1e-9)
