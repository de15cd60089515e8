"""The body scene's input subscription: a PoseArray (segments or joints, raw CDR bytes straight
into the ingest) or the Azure Kinect ROS driver's MarkerArray (body_input kinect_markers).

The driver publishes one visualization_msgs/MarkerArray per body tracking frame on
`body_tracking_data`: a SPHERE per joint of every body seen, id = body id x 100 + joint index
(k4abt_joint_id_t), positions in m in the depth camera's frame (io.kinect_markers has the
sources). `KinectMarkerInput` picks one body's 32 joints out of it (the chosen `body_id`, or
the body whose pelvis is nearest the camera) and offers them to the ingest as a joint frame
(kinect32), NaN for a joint the message lacks (the ingest holds it; a message with none of
the body is skipped, counted). The stamp is the first marker's header stamp, the frame its
frame_id. rclpy deserialises the message here (32 markers: well under a millisecond).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseArray
from visualization_msgs.msg import MarkerArray

from cloth_mg_ros.io.kinect_markers import DELETEALL, K4ABT_JOINT_COUNT, kinect_joints
from cloth_mg_ros.ros.ingest import PoseIngest

__all__ = ["KinectMarkerInput", "body_subscription"]



class KinectMarkerInput:
    """The MarkerArray callback: one body's joints into `ingest` (module docstring).

    body_id: the body to follow (>= 0), or -1: the nearest the camera in each message."""

    def __init__(self, ingest: PoseIngest, body_id: int = -1) -> None:
        self.ingest = ingest
        self.body_id = None if body_id < 0 else int(body_id)

    def __call__(self, msg: MarkerArray) -> None:
        markers = [m for m in msg.markers if m.action != DELETEALL]
        if not markers:
            self.ingest.offer_frame(0, 0, "", np.empty((0, 7)))  # counted as 'empty'
            return
        ids = np.array([m.id for m in markers], dtype=np.int64)
        positions = np.array([(m.pose.position.x, m.pose.position.y, m.pose.position.z)
                              for m in markers])
        _, joints = kinect_joints(ids, positions, self.body_id, K4ABT_JOINT_COUNT)
        header = markers[0].header
        poses = np.zeros((K4ABT_JOINT_COUNT, 7))
        poses[:, :3], poses[:, 6] = joints, 1.0
        self.ingest.offer_frame(header.stamp.sec, header.stamp.nanosec, header.frame_id,
                                poses)


def body_subscription(node, topic: str, body_input: str, body_id: int, ingest: PoseIngest,
                      qos):
    """The body scene's subscription on `topic` with `qos` (rclpy Node `node`)."""
    if body_input == "kinect_markers":
        return node.create_subscription(MarkerArray, topic, KinectMarkerInput(ingest, body_id),
                                        qos)
    return node.create_subscription(PoseArray, topic, ingest.offer, qos, raw=True)
