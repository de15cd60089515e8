"""The reference side of the hand-written message bytes (io.messages): rclpy's own decoder,
the triangle-list Marker built the slow way from Point objects, and the start-up check that
the hand-written Marker layout matches the installed definition. ROS side: they need rclpy
and the message packages, which the core never imports.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from cloth_mg_ros.io.messages.markers import DEFAULT_COLOUR, marker_triangle_list_bytes

__all__ = ["deserialize", "marker_message", "verify_layout"]


def deserialize(data: bytes, msg_type: type) -> Any:
    """Decode serialised bytes into a message of `msg_type` with rclpy (the reference decoder).

    Used by tests to check the bytes built here; raises whatever rclpy raises on bad data.
    """
    return deserialize_message(data, msg_type)



def marker_message(positions: np.ndarray, faces: np.ndarray, stamp_sec: int = 0,
                   stamp_nanosec: int = 0, frame_id: str = "world", ns: str = "cloth",
                   marker_id: int = 0, colour: Sequence[float] = DEFAULT_COLOUR,
                   per_vertex_colours: np.ndarray | None = None) -> Any:
    """The same marker built the slow way, as a visualization_msgs/Marker of Point objects.

    The reference for tests and for small meshes; needs the ROS message packages. Arguments
    as in `marker_triangle_list_bytes`.
    """
    # imported here: the message packages load only where the slow reference is built
    from geometry_msgs.msg import Point
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker

    msg = Marker()
    msg.header.stamp.sec = int(stamp_sec)
    msg.header.stamp.nanosec = int(stamp_nanosec)
    msg.header.frame_id = frame_id
    msg.ns = ns
    msg.id = int(marker_id)
    msg.type = Marker.TRIANGLE_LIST
    msg.action = Marker.ADD
    msg.pose.orientation.w = 1.0
    msg.scale.x = msg.scale.y = msg.scale.z = 1.0
    # float32 on the wire: round here so the message equals its own decoded copy.
    r, g, b, a = (float(c) for c in np.asarray(colour, dtype=np.float32))
    msg.color = ColorRGBA(r=r, g=g, b=b, a=a)
    pos = np.asarray(positions, dtype=np.float64)
    for face in np.asarray(faces):
        for v in face:
            x, y, z = pos[v]
            msg.points.append(Point(x=float(x), y=float(y), z=float(z)))
    if per_vertex_colours is not None:
        rgba = np.asarray(per_vertex_colours, dtype=np.float32)
        for face in np.asarray(faces):
            for v in face:
                r, g, b, a = (float(c) for c in rgba[v])
                msg.colors.append(ColorRGBA(r=r, g=g, b=b, a=a))
    return msg



def verify_layout() -> None:
    """Check the hand-written layout against the installed Marker and rclpy's serialiser.

    For frame ids and namespaces of every length mod 8 and with 0, 1 and 2 triangles, the bytes
    written here must have the length of `serialize_message`'s and decode to an equal message.
    Raises RuntimeError naming the first case that differs. Needs rclpy and the message
    packages; takes a few milliseconds.
    """
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5], [1.0, 1.0, -0.25]])
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    rgba = np.linspace(0.0, 1.0, 16, dtype=np.float32).reshape(4, 4)
    for k in range(8):
        for t in (0, 1, 2):
            for colours in (None, rgba):
                args = {"stamp_sec": 12, "stamp_nanosec": 345, "frame_id": "f" * k,
                        "ns": "n" * ((k + 3) % 8), "marker_id": k,
                        "per_vertex_colours": colours}
                ours = marker_triangle_list_bytes(pos, tri[:t], **args)
                ref = marker_message(pos, tri[:t], **args)
                theirs = serialize_message(ref)
                if len(ours) != len(theirs) or deserialize(ours, type(ref)) != ref:
                    raise RuntimeError(
                        f"visualization_msgs/Marker layout differs from the hand-written one "
                        f"(frame_id length {k}, {t} triangles, colours {colours is not None}): "
                        f"{len(ours)} bytes written, serialize_message gives {len(theirs)}")
