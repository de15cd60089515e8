"""`cloth-mg demo` and `cloth-mg bench node`: cloth_node in its own process over Fast DDS.

Both commands run as subprocesses, as a user runs them, on a ROS domain of this test run's own
(201 + pid % 30: test_node.py uses 1..100, test_replay.py 101..200) with localhost discovery:
the demo on the first 40 messages of the walk bag at ~300 particles, the benchmark on 30.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("visualization_msgs")
pytest.importorskip("diagnostic_msgs")

from cloth_mg_ros.bench.node_figures import format_node_report, latency_figures
from cloth_mg_ros.ros.demo import run_demo
from cloth_mg_ros.ros.demo_recording import (
    format_table,
    header_stamp_ns,
    read_cloth_bag,
    stats_rows,
)
from cloth_mg_ros.ros.processes import NodeError, claim_domain_id

REPO = Path(__file__).resolve().parents[1]
DOMAIN_ID = claim_domain_id(201, 30)  # no other run on the machine holds it
PARTICLES = 300
MESSAGES = 40


def cli(*args: str, timeout: float = 1200.0) -> subprocess.CompletedProcess:
    """`python -m cloth_mg_ros.cli.main ARGS` with this run's domain; stdout and stderr as text.
    The timeout is a deadline for a hung command, beyond the node's own start deadline
    (ros.processes.START_TIMEOUT_S, which covers a cost-model calibration on a loaded
    machine)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "cloth_mg_ros.cli.main", *args,
                           "--domain-id", str(DOMAIN_ID)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout, check=False)


def test_demo_records_draws_and_tabulates(tmp_path):
    out = tmp_path / "demo"
    run = cli("demo", "--particles", str(PARTICLES), "--steps", str(MESSAGES), "--out",
              str(out))
    text = run.stdout + run.stderr
    assert run.returncode == 0, text
    assert "Traceback" not in text, text

    # The recorded bag: one marker and one status per tick, stamped alike, the last with the
    # last pose's stamp; every pose used (some coalesced, as the machine's load has it).
    rec = read_cloth_bag(out / "cloth_bag")
    assert 2 <= len(rec.markers) == len(rec.stats) <= MESSAGES, text
    assert [s for s, _ in rec.markers] == [s for s, *_ in rec.stats]
    assert np.all(np.diff([s for s, _ in rec.markers]) > 0)
    last = rec.stats[-1][3]
    assert int(last["poses_used"]) == MESSAGES and int(last["dropped"]) == 0
    points = rec.markers[-1][1]
    assert points.ndim == 2 and points.shape[1] == 3 and len(points) % 3 == 0
    assert len(points) > 3 * PARTICLES and np.isfinite(points).all()
    assert np.linalg.norm(points.mean(0) - rec.markers[0][1].mean(0)) > 0.05  # it walked
    assert rec.stats[0][2].startswith("dressed")
    assert {level for _, level, *_ in rec.stats} <= {0, 1}
    assert (out / "cloth_bag" / "metadata.yaml").is_file()

    # frames.png: a strip of shaded frames, not an empty canvas.
    import matplotlib.image

    png = out / "frames.png"
    assert png.is_file() and png.stat().st_size > 20_000
    img = matplotlib.image.imread(png)
    # five frames side by side, less those of another size: the scene's level of detail
    # (on, as `make demo` runs it) re-dresses a smaller garment when the machine is loaded,
    # and the strip draws only the first garment's size
    picks = sorted(set(np.linspace(0, len(rec.markers) - 1, 5).round().astype(int).tolist()))
    drawn = sum(len(rec.markers[k][1]) == len(rec.markers[0][1]) for k in picks)
    assert drawn >= 1 and img.shape[1] > 0.6 * drawn * img.shape[0], (drawn, img.shape)
    assert img[..., :3].std() > 0.02

    # The table: the dressing, every 10th status, the last, then the medians.
    rows = re.findall(r"^\s*(dress|\d+)\s+\d+\.\d\d\s+\d+\.\d", run.stdout, re.MULTILINE)
    assert rows[0] == "dress" and len(rows) == 1 + (len(rec.stats) - 1) // 10 + (
        (len(rec.stats) - 1) % 10 != 0), run.stdout
    assert re.search(r"^\s*med\.\s+\d+\.\d", run.stdout, re.MULTILINE), run.stdout
    assert (f"{MESSAGES} pose messages in ({MESSAGES} used, {MESSAGES - len(rec.markers)} "
            f"coalesced into a later tick, 0 dropped), {len(rec.markers)} cloth markers"
            in run.stdout), run.stdout
    for path in ("cloth_bag", "frames.png", "node.log"):
        assert str(out / path) in run.stdout
    log = (out / "node.log").read_text()
    assert f"pose frames: {MESSAGES} received, {MESSAGES} used" in log, log


@pytest.mark.bench
def test_bench_node_writes_latency_json(tmp_path):
    out = tmp_path / "bench_node.json"
    run = cli("bench", "node", "--bag", "walk", "--particles", str(PARTICLES), "--messages",
              "30", "--rate", "1,2", "--json", str(out))
    assert run.returncode == 0, run.stdout + run.stderr
    result = json.loads(out.read_text())
    for key in ("particles", "scene", "bag", "latency_ms", "step_ms_p50", "messages",
                "markers", "lost", "dropped", "poses_used", "poses_coalesced",
                "latency_thirds", "per_pose", "keeps_up"):
        assert key in result, key
    assert result["particles"] == PARTICLES and result["scene"] == "walking"
    # Two passes of the first 30 messages, the second at twice the pace.
    assert result["loops"] == 2 and result["rates"] == [1.0, 2.0]
    assert result["messages"] == result["poses_received"] == 60
    assert result["node_poses_received"] == result["poses_used"] == 60
    assert result["lost"] == result["dropped"] == result["uncovered"] == 0
    assert 2 <= result["markers"] <= 60
    assert result["poses_coalesced"] == 60 - result["markers"]
    passes = result["passes"]
    assert [p["rate"] for p in passes] == [1.0, 2.0]
    assert sum(p["poses"] for p in passes) == len(result["per_pose"])
    assert passes[1]["poses"] == 30 and passes[1]["particles"] == result["garment_particles"]
    assert result["lod"]["switches"] == 0 and result["lod"]["final_level"] == 0
    assert 0.0 < result["last_pose_latency_ms"]
    lat = result["latency_ms"]
    assert 0.0 < lat["p50"] <= lat["p95"] <= lat["max"]
    assert len(result["per_pose"]) >= 29 - result["during_dressing"]
    assert result["step_ms_p50"] > 0.0 and result["node_exit"] == 0
    svc = result["service_ms"]
    assert 0.0 < svc["p50"] and result["queue_ms"]["p50"] >= 0.0
    assert "latency pose received -> marker received" in run.stdout


def test_a_node_that_cannot_start_is_reported_with_its_log(tmp_path):
    scene = tmp_path / "bad.yaml"
    text = (REPO / "config" / "walking.yaml").read_text()
    # A file the scene loader takes (every value in its range) but the node refuses: no dress
    # is that small (a check across parameters, made by the node at start).
    scene.write_text(re.sub(r"max_particles: \S+", "max_particles: 20", text))
    assert "max_particles: 20" in scene.read_text()
    keys = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    before = {k: os.environ.get(k) for k in keys}
    with pytest.raises(NodeError) as err:
        run_demo(tmp_path / "out", particles=100, messages=5, scene=str(scene),
                 domain_id=DOMAIN_ID, start_timeout_s=60.0, log=lambda line: None)
    message = str(err.value)
    assert "exited with status 1 during start-up" in message
    assert "max_particles 20" in message  # the node's own error line, from its log
    assert {k: os.environ.get(k) for k in keys} == before  # the environment came back


def test_table_and_latency_figures_from_plain_values():
    def status(step: int, level: int = 0, message: str = "ok") -> tuple:
        values = {"step": str(step), "step_ms": f"{10 + step}", "solve_ms": f"{8 + step}",
                  "iterations": "20", "rel_residual": "9.0e-05",
                  "max_penetration_m": "1.0e-03", "substeps": "1" if step else "0"}
        return (step * 33_333_333, level, message, values)

    stats = [status(0, message="dressed")] + [status(k) for k in range(1, 25)]
    stats[12] = status(12, 1, "solve stopped at relative residual 0.002 after 500 iterations")
    table = format_table(stats_rows(stats))
    lines = table.splitlines()
    assert [line.split()[0] for line in lines[2:-2]] == ["dress", "10", "20", "24"]
    assert lines[-1].split()[:3] == ["med.", "22.5", "20.5"]  # medians of ticks 1..24
    assert "24 OK, 1 WARN" in lines[-1]

    # Poses every 0.1 s; the dressing marker (stamp 0) comes at 0.25 s, the next tick
    # coalesces poses 1 and 2 (its marker, stamped 2, at 0.45 s), then one each.
    poses = [(k * 0.1, k) for k in range(7)]
    markers = [(0.25, 0), (0.45, 2), (0.52, 3), (0.61, 4), (0.68, 5), (0.75, 6), (0.8, 99)]
    fig = latency_figures(poses, markers, not_ticks={0})
    assert fig["matched"] == 6 and fig["unmatched"] == 1 and fig["uncovered"] == 0
    assert fig["dress_latency_ms"] == pytest.approx(250.0)
    # Poses 1 and 2 arrived while the garment was being dressed: reported apart.
    assert fig["during_dressing"] == 2
    assert fig["dressing_latency_ms"]["max"] == pytest.approx(350.0)  # pose 1: 0.1 -> 0.45
    assert [p for p, _ in fig["per_pose"]] == pytest.approx([0.3, 0.4, 0.5, 0.6])
    assert fig["latency_ms"]["max"] == pytest.approx(220.0)  # pose 3: 0.52 - 0.30 s
    # Service: after the later of the pose and the previous marker: 200, 70, 90, 70, 70 ms.
    assert fig["service_ms"]["p50"] == pytest.approx(70.0)
    assert fig["queue_ms"]["max"] == pytest.approx(150.0)  # pose 3: 220 - 70 ms
    assert fig["latency_thirds"]["first"] is not None
    assert header_stamp_ns(b"\x00\x01\x00\x00" + (3).to_bytes(4, "little")
                           + (5).to_bytes(4, "little")) == 3_000_000_005
    report = format_node_report({
        "scene": "walking", "garment_particles": 290, "particles": 300, "messages": 7,
        "bag": "walk", "rate": 1.0, "pose_interval_ms": 100.0, "markers": 7, "lost": 0,
        "poses_received": 7, "node_poses_received": 7, "poses_used": 7, "poses_coalesced": 1,
        "dropped": 0, "pending": 0, "ticks": 5, "latency_ms": fig["latency_ms"],
        "service_ms": fig["service_ms"], "queue_ms": fig["queue_ms"],
        "latency_thirds": {"first": 250.0, "last": 90.0, "growth": 0.36},
        "during_dressing": 2, "dressing_latency_ms": {"p50": 300.0, "p95": 345.0,
                                                      "max": 350.0},
        "lag_ms": {"p50": 1.0, "p95": 2.0, "max": 3.0},
        "dress_latency_ms": 350.0, "step_ms_p50": 50.0, "step_ms_p95": 100.0,
        "solve_ms_p50": 45.0, "marker_ms_p50": 1.0, "keeps_up": True})
    assert "7 used, 1 of them coalesced" in report and "kept up" in report
