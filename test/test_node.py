"""cloth_node as a separate process, over real Fast DDS on loopback.

Each test run gets its own ROS_DOMAIN_ID (from the pid) and ROS_AUTOMATIC_DISCOVERY_RANGE=
LOCALHOST, so parallel runs on one machine do not hear each other.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("visualization_msgs")
pytest.importorskip("diagnostic_msgs")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import Marker

from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.ros.cdr import deserialize
from cloth_mg_ros.scenes import build_scene

REPO = Path(__file__).resolve().parents[1]
DOMAIN_ID = 1 + os.getpid() % 100
PARTICLES = 300
START_TIMEOUT_S = 60.0  # discovery plus a possible numba compile on the first step
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                 depth=100)


@pytest.fixture
def ros_env(monkeypatch) -> dict[str, str]:
    """Environment for both ends: loopback discovery on this run's own domain."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN_ID))
    return dict(os.environ, PYTHONUNBUFFERED="1")


def node_command(*params: str) -> list[str]:
    """`python -m cloth_mg_ros.ros.node --ros-args -p ...` with the given name:=value pairs."""
    cmd = [sys.executable, "-m", "cloth_mg_ros.ros.node", "--ros-args"]
    for p in params:
        cmd += ["-p", p]
    return cmd


def test_node_publishes_markers_and_stats_and_stops_on_sigint(ros_env, tmp_path):
    model = build_scene("drape", PARTICLES, get_material("cotton")).model
    faces = model.mesh.faces
    log_path = tmp_path / "node.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            node_command(f"particles:={PARTICLES}", "scene:=drape", "rate_hz:=50.0",
                         "max_steps:=0"),
            env=ros_env, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    node = rclpy.create_node("cloth_node_test", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    markers: list[bytes] = []
    stats: list[DiagnosticArray] = []
    try:
        node.create_subscription(Marker, "/cloth/marker", markers.append, QOS, raw=True)
        node.create_subscription(DiagnosticArray, "/cloth/stats", stats.append, QOS)
        deadline = time.monotonic() + START_TIMEOUT_S
        while (len(markers) < 10 or len(stats) < 10) and time.monotonic() < deadline:
            assert proc.poll() is None, f"node exited early:\n{log_path.read_text()}"
            executor.spin_once(timeout_sec=0.1)
        assert len(markers) >= 10 and len(stats) >= 10, (
            f"{len(markers)} markers, {len(stats)} stats in {START_TIMEOUT_S} s:\n"
            f"{log_path.read_text()}")

        first = None
        for data in markers:
            assert isinstance(data, bytes)
            msg = deserialize(data, Marker)
            assert msg.type == Marker.TRIANGLE_LIST and msg.action == Marker.ADD
            assert msg.header.frame_id == "world" and msg.ns == "cloth"
            assert len(msg.points) == 3 * len(faces)
            pts = np.array([[p.x, p.y, p.z] for p in msg.points])
            assert np.isfinite(pts).all()
            first = pts if first is None else first
        assert not np.array_equal(first, pts), "the cloth did not move"

        for arr in stats:
            (status,) = arr.status
            values = {kv.key: kv.value for kv in status.values}
            assert status.name == "cloth_node: solver"
            assert status.level == DiagnosticStatus.OK, f"{status.message} {values}"
            for key in ("step", "solve_ms", "step_ms", "iterations", "rel_residual",
                        "max_penetration_m", "contacts", "particles"):
                assert key in values
            assert int(values["particles"]) == model.n
            assert float(values["rel_residual"]) <= 1e-4
        steps = [int({kv.key: kv.value for kv in a.status[0].values}["step"]) for a in stats]
        assert steps == sorted(steps) and steps[0] >= 1

        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0, log_path.read_text()
        assert "Traceback" not in log_path.read_text(), log_path.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize(("param", "named"), [
    ("material:=velvet", "velvet"),
    ("scene:=tablecloth", "tablecloth"),
    ("particles:=5", "particles"),
])
def test_bad_parameter_exits_nonzero_naming_it(ros_env, param, named):
    run = subprocess.run(node_command(param), env=ros_env, cwd=REPO, capture_output=True,
                         text=True, timeout=60, check=False)
    assert run.returncode != 0
    assert named in run.stderr, run.stderr
    assert "Traceback" not in run.stderr, run.stderr


def test_max_steps_exits_zero(ros_env):
    run = subprocess.run(node_command("particles:=100", "max_steps:=3", "rate_hz:=100.0"),
                         env=ros_env, cwd=REPO, capture_output=True, text=True, timeout=60,
                         check=False)
    assert run.returncode == 0, run.stderr
    assert "max_steps 3 reached" in run.stderr
