"""`cloth-mg bench faults`: the figures from synthetic streams (fast), the pose bytes, the CLI,
the CPU hogs, and one end-to-end run of a few faults against cloth_node (marked bench).

The end-to-end run uses a ROS domain of its own (231 + pid % 2: test_node.py uses 1..100,
test_replay.py 101..200, test_demo.py 201..230) with localhost discovery.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cloth_mg_ros.bench.faults import add_cli
from cloth_mg_ros.bench.faults.figures import (
    Clear,
    Marks,
    Sent,
    Tick,
    check_row,
    classify_clears,
    counter_delta,
    describe_row,
    expected_restarts,
    format_table,
    percentiles,
    pose_latencies,
    rung_figures,
    stream_row,
)
from cloth_mg_ros.bench.faults.injection import FAULTS, parse_faults
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.processes import claim_domain_id

REPO = Path(__file__).resolve().parents[1]
DOMAIN_ID = claim_domain_id(231, 2)  # no other run on the machine holds it
START_TIMEOUT_S = 600.0  # s: a node's start, as the node tests' harness waits for it
MS = 1_000_000  # ns per ms


def _sent(t: float, stamp_ms: int, kind: str = "valid", epoch: int = 0) -> Sent:
    return Sent(t, stamp_ms * MS, epoch, kind)


def _tick(t: float, stamp_ms: int, message: str = "ok", **values) -> Tick:
    base = {"substeps": "1", "level": "0", "particles": "1200"}
    base.update({k: str(v) for k, v in values.items()})
    return Tick(t, stamp_ms * MS, message, base)


# ------------------------------------------------------------------------------------------
# Figures


def test_percentiles_of_nothing_and_of_values():
    assert percentiles([]) == {"p50": None, "p95": None, "n": 0}
    p = percentiles([10.0, 20.0, 30.0])
    assert p["p50"] == 20.0 and p["n"] == 3 and 20.0 < p["p95"] <= 30.0


def test_a_pose_is_timed_to_the_first_marker_stamped_at_or_after_it():
    sent = [_sent(1.00, 100), _sent(1.03, 133), _sent(1.06, 166, "stale"), _sent(1.09, 200)]
    # The first marker (stamp 100) covers pose 100 only; the second (200) covers 133 and 200.
    markers = [(1.01, 100 * MS), (1.15, 200 * MS)]
    lat, uncovered = pose_latencies(sent, markers, 0.0, 2.0)
    assert np.allclose(lat, [10.0, 120.0, 60.0]) and uncovered == 0
    # Only the poses published in the window; a marker received before a pose covers nothing.
    lat, uncovered = pose_latencies(sent, [(0.5, 300 * MS)], 1.0, 1.05)
    assert lat == [] and uncovered == 2


def test_a_marker_of_an_older_time_line_covers_nothing_of_a_new_one():
    # Time line 0 reached stamp 900; time line 1 starts over at 100. A marker stamped 900 that
    # arrives after the new line's first pose was published is the old line's.
    sent = [_sent(1.0, 900, epoch=0), _sent(2.0, 100, epoch=1), _sent(2.1, 133, epoch=1)]
    markers = [(2.05, 900 * MS), (2.2, 133 * MS)]
    lat, uncovered = pose_latencies(sent, markers, 1.5, 3.0)
    assert np.allclose(lat, [200.0, 100.0]) and uncovered == 0


def test_expected_restarts_count_time_lines_that_go_back():
    sent = [_sent(1.0, 100), _sent(1.1, 200), _sent(2.0, 50, epoch=1), _sent(2.1, 80, epoch=1),
            _sent(3.0, 1000, epoch=2)]  # epoch 2 moves on: no restart
    assert expected_restarts(sent, 0.0, 5.0) == 1
    assert expected_restarts(sent, 2.5, 5.0) == 0
    # A stale pose on the same time line is no new one.
    assert expected_restarts([_sent(1.0, 500), _sent(1.1, 100, "stale"), _sent(1.2, 533)],
                             0.0, 5.0) == 0


def test_counter_delta_reads_absent_skip_counters_as_zero():
    assert counter_delta({}, {"skipped_stale": "2"}, "skipped_stale") == 2
    assert counter_delta({"skipped_nan": "1"}, {"skipped_nan": "1"}, "skipped_empty") == 0
    assert counter_delta({"poses_used": "10"}, {"poses_used": "25"}, "poses_used") == 15
    assert counter_delta({}, {}, "stream_restarts") is None  # a node that does not report it


def test_rung_figures_find_the_step_down_and_the_way_back():
    ticks = [_tick(t, int(t * 1000), level=lv, particles=n) for t, lv, n in [
        (0.5, 0, 1200), (1.0, 0, 1200), (2.5, 1, 600), (9.0, 1, 600), (13.0, 0, 1200),
        (14.0, 0, 1200)]]
    lod = rung_figures(ticks, 1.0, 11.0)  # the load from 1 s to 11 s
    assert lod["lowest"] == 1 and lod["fewest_particles"] == 600
    assert lod["step_down_s"] == pytest.approx(1.5)
    assert lod["level_at_load_end"] == 1 and lod["recovery_s"] == pytest.approx(2.0)
    assert lod["final_level"] == 0
    assert lod["held_s"] == pytest.approx(1.0)  # back at 13 s, last tick at 14 s
    assert [lv for _, lv, _ in lod["levels"]] == [0, 1, 0]
    # every tick's cost with its level, in the load's time (the way back's evidence)
    assert [row[:3] for row in lod["ticks"]] == [[-0.5, 0, 1200], [0.0, 0, 1200], [1.5, 1, 600],
                                                 [8.0, 1, 600], [12.0, 0, 1200], [13.0, 0, 1200]]
    flat = rung_figures(ticks[:2], 1.0, 11.0)
    assert flat["lowest"] == 0 and flat["recovery_s"] == 0.0 and flat["step_down_s"] is None
    stuck = rung_figures(ticks[:4], 1.0, 5.0)
    assert stuck["recovery_s"] is None and stuck["final_level"] == 1


def test_clears_are_told_apart_by_their_stamps():
    ticks = [_tick(1.0, 100, "dressed a dress"), _tick(1.1, 133), _tick(1.2, 166, level=1),
             _tick(1.3, 200, level=1)]
    clears = [Clear(1.0, 100 * MS, "marker"), Clear(1.0, 100 * MS, "markers"),
              Clear(1.2, 166 * MS, "marker"), Clear(1.3, 200 * MS, "marker")]
    c = classify_clears(clears, ticks)
    assert c["marker"] == {"dress": 1, "lod": 1, "other": 1}
    assert c["markers"] == {"dress": 1, "lod": 0, "other": 0}


def _stale_row(redress: bool) -> dict:
    """A synthetic stale row: 90 live poses over 3 s, one stale pose at 1 s."""
    sent = [_sent(0.0 + k / 30, 1000 + 33 * k) for k in range(90)]
    sent.insert(31, _sent(1.01, 1000 + 33 * 30 - 5000, "stale"))
    markers = [(s.t + 0.015, s.stamp_ns) for s in sent if s.kind == "valid"]
    ticks = [_tick(t + 0.016, st // MS) for t, st in markers]
    clears = []
    used = 90
    if redress:  # what a node that takes the stale pose for a new time line does
        stamp = sent[31].stamp_ns // MS
        ticks.insert(31, _tick(1.02, stamp, "dressed a dress of 1200 particles"))
        clears = [Clear(1.02, stamp * MS, "marker"), Clear(1.02, stamp * MS, "markers")]
        used += 1
    before = {"poses_received": "10", "poses_used": "10", "dropped": "0",
              "stream_restarts": "0"}
    after = {"poses_received": "101", "poses_used": str(10 + used), "dropped": "0",
             "stream_restarts": "1" if redress else "0",
             "skipped_stale": "0" if redress else "1"}
    row = stream_row("stale", FAULTS["stale"], sent, markers, clears, ticks,
                     Marks(0.0, 1.0, 1.01, 3.0, 3.5), before, after)
    row["why"] = check_row(row)
    row["ok"] = not row["why"]
    row["did"] = describe_row(row)
    return row


def test_a_stale_pose_skipped_with_the_cloth_kept_is_ok():
    row = _stale_row(redress=False)
    assert row["ok"], row["why"]
    assert row["kept"] and row["lost"] == 0 and row["stale"] == 1 and row["not_received"] == 0
    assert row["latency_fault_ms"]["p50"] == pytest.approx(15.0)
    # The lead-in second is in neither window: [1, 2) s is the fault's, [2, 3) s after it.
    assert row["latency_fault_ms"]["n"] == 30 and row["latency_after_ms"]["n"] == 30
    assert row["did"] == "cloth kept; skipped 1 stale"


def test_a_stale_pose_that_re_dresses_the_garment_is_not_ok():
    row = _stale_row(redress=True)
    assert not row["ok"] and not row["kept"] and row["dressed"] == 1
    why = " | ".join(row["why"])
    assert "cloth not kept" in why and "stream_restarts +1" in why
    assert "0 skipped as stale, expected 1" in why and "the node reports no" not in why
    assert row["did"].startswith("re-dressed once")


def test_a_load_row_that_comes_back_late_is_not_ok():
    sent = [_sent(k / 30, 1000 + 33 * k) for k in range(600)]
    markers = [(s.t + 0.02, s.stamp_ns) for s in sent]
    levels = [1 if 2.0 <= t < 18.5 else 0 for t, _ in markers]
    ticks = [_tick(t + 0.021, st // MS, level=lv, particles=600 if lv else 1200)
             for (t, st), lv in zip(markers, levels, strict=True)]
    before = {"poses_received": "0", "poses_used": "0", "dropped": "0", "lod_switches": "0"}
    after = {"poses_received": "600", "poses_used": "600", "dropped": "0", "lod_switches": "2"}
    row = stream_row("hog1", FAULTS["hog1"], sent, markers, [], ticks,
                     Marks(0.0, 1.0, 11.0, 20.0, 20.5), before, after)
    assert row["lod"]["recovery_s"] == pytest.approx(7.5, abs=0.05)
    row["why"], row["did"] = check_row(row), describe_row(row)
    row["ok"] = not row["why"]
    assert row["why"] == ["back to level 0 7.5 s after the load (target 6 s)"]
    assert "stepped down to level 1 (600 particles) 1.0 s into the fault" in row["did"]
    assert "back up 7.5 s after it" in row["did"]
    text = format_table([row])
    assert "hog1" in text and "2 / 7.5 s" in text and "NOT OK: back to level 0" in text
    assert "0 of 1 rows ok; not ok: hog1" in text


def test_a_signal_row_needs_exit_zero_and_both_deleteall():
    from cloth_mg_ros.bench.faults.figures import signal_row

    sent = [_sent(k / 30, 1000 + 33 * k) for k in range(90)]
    markers = [(s.t + 0.02, s.stamp_ns) for s in sent]
    ticks = [_tick(t + 0.021, st // MS) for t, st in markers[:-1]]  # the last tick cut short
    row = signal_row("sigint", "SIGINT", sent, markers, [Clear(3.5, 5 * MS, "marker")], ticks,
                     3.0, sent[-1], 0, 0.4,
                     "[WARN] [1.5] [cloth_node]: shutdown: DELETEALL on /cloth/marker and "
                     "/cloth/markers not acknowledged by every reliable reader within 1 s")
    why = check_row(row)
    assert why == ["no DELETEALL on /cloth/markers after SIGINT"]
    assert row["mid_tick"] and row["latency_fault_ms"]["n"] == 90
    row.update(why=why, ok=False, did=describe_row(row))
    assert row["deleteall_s"] == {"marker": 0.5, "markers": None}
    assert row["shutdown_acked"] is False
    assert row["did"] == ("exit 0 0.40 s after it; DELETEALL on /cloth/marker (received 0.50 s "
                          "after it); its log says not acknowledged")
    assert "0 / marker" in format_table([row])


def test_parse_faults_keeps_the_run_order_and_names_unknown_ones():
    assert parse_faults("all") == list(FAULTS)
    assert parse_faults("sigint, stale,burst") == ["burst", "stale", "sigint"]
    with pytest.raises(ClothInputError, match="'nope'"):
        parse_faults("stale,nope")


def test_add_cli_registers_the_faults_sub_command():
    parser = argparse.ArgumentParser()
    add_cli(parser.add_subparsers(dest="bench"))
    args = parser.parse_args(["faults"])
    assert (args.particles, args.faults, args.hog_s, args.json, args.domain_id,
            args.load_particles) == (1200, "all", 10.0, "out/bench_faults.json", None, 2400)
    assert callable(args.bench_func)
    args = parser.parse_args(["faults", "--faults", "stale", "--hog-s", "2", "--domain-id", "7"])
    assert (args.faults, args.hog_s, args.domain_id) == ("stale", 2.0, 7)


# ------------------------------------------------------------------------------------------
# Bytes, poses and hogs


def test_pose_array_bytes_decode_as_the_node_and_rclpy_read_them():
    pytest.importorskip("geometry_msgs")
    from geometry_msgs.msg import PoseArray

    from cloth_mg_ros.bench.faults.stream import pose_array_cdr
    from cloth_mg_ros.ros.ingest import pose_array_from_cdr
    from cloth_mg_ros.ros.message_reference import deserialize

    rng = np.random.default_rng(3)
    for n in (0, 1, 15, 16):
        poses = rng.normal(size=(n, 7))
        if n:
            poses[0, 2] = np.nan
        data = pose_array_cdr(1_700_000_000_123_456_789, poses)
        sec, nanosec, frame, got = pose_array_from_cdr(data)
        assert (sec, nanosec, frame) == (1_700_000_000, 123_456_789, "world")
        assert np.array_equal(got, poses, equal_nan=True)
        msg = deserialize(data, PoseArray)
        assert len(msg.poses) == n and msg.header.stamp.nanosec == 123_456_789


def test_a_marker_array_clear_is_told_from_a_drawn_array():
    from cloth_mg_ros.bench.faults.stream import marker_array_clear_stamp
    from cloth_mg_ros.ros.marker_array import delete_all_bytes, marker_array_bytes

    _, array = delete_all_bytes(12, 345, "world")
    assert marker_array_clear_stamp(array) == 12_000_000_345
    drawn = marker_array_bytes(None, None, 12, 345, "world",
                               caption=((0.0, 0.0, 1.0), "1200 particles"))
    assert marker_array_clear_stamp(drawn) is None


def test_the_pose_source_goes_forward_and_back_without_a_jump():
    from cloth_mg_ros.bench.faults.stream import PoseSource

    frames = [np.full((16, 7), float(i)) for i in range(5)]
    src = PoseSource(frames, start_ns=10 * 10**9, rate_hz=30.0)
    got = [src.next() for _ in range(12)]
    assert [int(p[0, 0]) for _, p in got] == [0, 1, 2, 3, 4, 3, 2, 1, 0, 1, 2, 3]
    assert np.all(np.diff([st for st, _ in got]) == src.period_ns)
    src.new_time_line(5 * 10**9)
    assert src.epoch == 1 and src.next()[0] == 5 * 10**9
    src.continue_from(7 * 10**9, frame_index=4, epoch=3)  # after the bag's last frame
    stamp, poses = src.next()
    assert src.epoch == 3 and stamp == 7 * 10**9 + src.period_ns and poses[0, 0] == 3.0
    # a slower tracker: the same poses in turn, stamped 1/15 s apart
    slow = PoseSource(frames, start_ns=0, rate_hz=15.0)
    got = [slow.next() for _ in range(3)]
    assert [st for st, _ in got] == [0, 66_666_667, 133_333_334]
    assert [int(p[0, 0]) for _, p in got] == [0, 1, 2]


@pytest.mark.parametrize("rate", [0.5, 500.0, float("nan")])
def test_a_stream_rate_out_of_range_is_refused_before_any_work(rate):
    from cloth_mg_ros.bench.faults import bench_faults

    with pytest.raises(ClothInputError, match="--rate-hz must be from 1 to 120 Hz"):
        bench_faults(["hog2"], rate_hz=rate)


def test_cpu_hogs_are_gone_when_the_block_ends():
    from cloth_mg_ros.bench.faults.stream import cpu_hogs

    with cpu_hogs(2, 60.0) as procs:
        assert len(procs) == 2 and all(p.poll() is None for p in procs)
    assert all(p.poll() is not None for p in procs)
    with pytest.raises(RuntimeError), cpu_hogs(1, 60.0) as procs:
        raise RuntimeError("a failing row")
    assert procs[0].poll() is not None


# ------------------------------------------------------------------------------------------
# End to end


@pytest.mark.bench
def test_bench_faults_stale_burst_and_sigint(tmp_path, walking_one_thread):
    """A stale pose and a burst in the live stream of one node, SIGINT to another (~400
    particles). Asserts what the node does, never how fast: every wait in the benchmark
    spins until its condition holds, with generous timeouts (a node's start too: 10 minutes,
    as the node tests' harness waits; a loaded machine took 81 s and more than 120 s). The
    walking scene on one thread: its nodes find the run's calibration (walking_one_thread)."""
    pytest.importorskip("rclpy")
    out = tmp_path / "faults.json"
    env = dict(os.environ, PYTHONUNBUFFERED="1", OPENBLAS_NUM_THREADS="1")
    t0 = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "cloth_mg_ros.cli.main", "bench", "faults",
                          "--faults", "stale,burst,sigint", "--particles", "400",
                          "--scene", str(walking_one_thread), "--json",
                          str(out), "--domain-id", str(DOMAIN_ID), "--start-timeout",
                          str(START_TIMEOUT_S)], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=4 * START_TIMEOUT_S,
                         check=False)
    text = run.stdout + run.stderr
    assert run.returncode == 0, text
    assert "Traceback" not in text, text
    result = json.loads(out.read_text())
    rows = {r["name"]: r for r in result["rows"]}
    assert list(rows) == ["burst", "stale", "sigint"], text
    for name, r in rows.items():
        assert r["ok"], f"{name}: {r['why']}\n{text}"
        assert name in run.stdout and r["did"] in run.stdout

    burst = rows["burst"]
    assert burst["kinds"] == {"valid": burst["sent"]} and burst["lost"] == 0
    assert burst["not_received"] == 0 and burst["dropped"] == 0 and burst["kept"]
    assert burst["latency_fault_ms"]["n"] >= 10 and burst["latency_after_ms"]["n"] > 0

    stale = rows["stale"]
    assert stale["kinds"]["stale"] == 1 and stale["deltas"]["skipped_stale"] == 1
    assert stale["lost"] == 0 and stale["kept"] and stale["dressed"] == 0
    assert stale["deltas"].get("stream_restarts") == 0

    sigint = rows["sigint"]
    assert sigint["exit_code"] == 0 and sigint["deleteall"] == {"marker": True,
                                                                "markers": True}
    assert not sigint["traceback"] and sigint["ticks"] > 0
    assert result["particles"] == 400 and result["faults"] == ["burst", "stale", "sigint"]
    assert result["wall_s"] <= time.monotonic() - t0
    logs = tmp_path / "faults.node_logs"
    assert (logs / "stream.node.log").is_file() and (logs / "sigint.node.log").is_file()
    assert "3 of 3 rows ok" in run.stdout
