"""`cloth-mg replay --topic-out`: the bag's poses on the topic a node listens to (what
`ros2 launch cloth_mg_ros cloth.launch.py topic:=X bag:=...` needs), over real Fast DDS on
loopback (test_node.py describes the environment)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.io.bags import write_pose_bag as write_bag
from cloth_mg_ros.ros.processes import claim_domain_id
from cloth_mg_ros.ros.replay import replay_bag

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("geometry_msgs")
DOMAIN_ID = claim_domain_id(101, 100)  # held by this process alone (ros_env takes it)


def _spin_until(executor, done, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not done():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.02)
    return True


def test_topic_out_publishes_the_bag_on_the_nodes_topic(ros_env, tmp_path):
    """A relative --topic-out goes under --namespace (as the node's relative topic does); the
    bag's own topic gets nothing."""
    from geometry_msgs.msg import PoseArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                     depth=100)
    frames = read_pose_frames(bundled_bag("walk"))[:5]
    bag = write_bag(tmp_path / "walk5", np.array([s for s, _ in frames]),
                    np.stack([p for _, p in frames]))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    node = rclpy.create_node("topic_out_test", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        moved: list[bytes] = []
        own: list[bytes] = []
        node.create_subscription(PoseArray, "/alice/mocap/poses", moved.append, qos, raw=True)
        node.create_subscription(PoseArray, "/alice/avatar/body_poses", own.append, qos,
                                 raw=True)
        result: dict = {}
        thread = threading.Thread(target=lambda: result.update(stats=replay_bag(
            bag, context=ctx, settle_s=0.2, wait_s=20, namespace="alice",
            topic_out="mocap/poses", log=lambda line: None)), daemon=True)
        thread.start()
        assert _spin_until(executor, lambda: not thread.is_alive() and len(moved) >= 5, 30)
        _spin_until(executor, lambda: False, 0.2)
        assert result["stats"].messages == 5 and not own
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize("topic", ["1poses", "a b", "mocap//poses"])
def test_a_bad_topic_out_is_named(ros_env, capsys, topic):
    assert main(["replay", "walk", "--topic-out", topic, "--wait", "0"]) == 2
    assert "--topic-out" in capsys.readouterr().err
