"""cloth_node over DDS driven by the Azure Kinect ROS driver's MarkerArray as a tracker sends
it: the running clip's kinect32 joints in a camera's frame with jitter and hidden joints,
input_transform the camera's pose; every message used, none dropped, the cloth finite and
published in the world's frame (frame_id, not the camera's), hanging about the true body
(its centre within 0.3 m of the segment input's pelvis across the floor)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

from node_harness import (
    check_marker,
    kill_node,
    node_command,
    replay_in_thread,
    start_node,
    status_values,
    stop_node,
)

from cloth_mg_ros.bench.trackers import node_parameters
from cloth_mg_ros.io.bags import bag_info, read_pose_frames
from cloth_mg_ros.io.kinect_markers import read_kinect_marker_frames
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.motion.pose_bags import bag_from_bvh
from cloth_mg_ros.motion.tracker_view import TrackerView

RUN = Path(__file__).parent / "data" / "mocap" / "09_01.bvh"  # 1.2 s of running (+1 s settle)


def test_the_kinect_marker_array_in_a_camera_frame_drives_the_node(ros_env, listener, tmp_path):
    bag = tmp_path / "markers"
    bag_from_bvh(RUN, bag, body_input="kinect_markers", view=TrackerView(None, 0.002, 0.05, 0))
    segments = tmp_path / "segments"
    bag_from_bvh(RUN, segments)
    sent = bag_info(bag)["message_count"]
    missing = np.isnan(read_kinect_marker_frames(bag)[1]).any(axis=2)  # (F, 32) hidden
    # the stream hides joints after they were seen: within joint_hold each is held
    assert (~missing[:-1] & missing[1:]).any()
    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=walking", "particles:=200", "lod:=false",
                                   "threads:=1", "input_reliability:=reliable",
                                   *node_parameters("kinect_markers", bag)), ros_env, log_path)
    lis = listener
    try:
        lis.wait_matched(proc, log_path)
        replay = replay_in_thread(bag, lis.ctx)

        def settled() -> bool:
            if replay.is_alive() or not lis.stats:
                return False
            _, values = status_values(lis.stats[-1])
            return int(values["poses_received"]) == sent and values["poses_pending"] == "0"

        assert lis.spin_until(settled, 300.0, proc, log_path), log_path.read_text()
        assert not replay.errors, replay.errors
        _, values = status_values(lis.stats[-1])
        assert int(values["poses_used"]) == sent and int(values["dropped"]) == 0
        # every hidden joint sample counted once, held (some: seen 1/30 s before) or lost
        assert int(values["joints_held"]) > 0, values
        assert int(values["joints_held"]) + int(values["joints_lost"]) == missing.sum(), values
        assert "segments_dropped" in values
        points = check_marker(lis.markers[-1], _points(lis.markers[-1]), frame_id="world")
        truth = read_pose_frames(segments)[-1][1]
        # the cloth hangs about the true body: its centre within 0.3 m of the pelvis's
        assert np.linalg.norm(points.mean(axis=0)[:2] - truth[0, :2]) < 0.3
        text = stop_node(proc, log_path)
        assert "body input kinect_markers" in text and "input_transform" in text
    finally:
        kill_node(proc)


def _points(data: bytes) -> int:
    return len(marker_arrays_from_bytes(data).points)
