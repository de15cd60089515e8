"""The garment as geometry other programs can read: sensor_msgs/PointCloud2 of the particles
and shape_msgs/Mesh of the triangles, written from numpy straight into CDR bytes (as the
markers are: a 20K-particle cloth would cost hundreds of ms as message objects).

Layouts (plain little-endian CDR after the 4-byte encapsulation header, every member aligned
to its own size):

    sensor_msgs/PointCloud2: header (stamp int32 + uint32, frame_id string), height, width
        (uint32), fields (uint32 count; per PointField: name string, offset uint32, datatype
        uint8, count uint32), is_bigendian (bool), point_step, row_step (uint32), data (uint32
        length + bytes), is_dense (bool)
    shape_msgs/Mesh: triangles (uint32 count; per triangle uint32[3]), vertices (uint32 count;
        per geometry_msgs/Point three float64, 8-byte aligned)

The point cloud is one row (height 1) of float32 x, y, z (m) and, on request, vx, vy, vz (m/s);
the mesh's vertex i is particle i. `verify_geometry_layouts` checks both layouts against the
installed definitions and rclpy's serialiser at start-up.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.io.messages.cdr import CdrWriter
from cloth_mg_ros.ros.message_reference import deserialize

__all__ = ["mesh_bytes", "pointcloud2_bytes", "verify_geometry_layouts"]

FLOAT32 = 7  # sensor_msgs/PointField.FLOAT32
XYZ = ("x", "y", "z")
VELOCITY = ("vx", "vy", "vz")


def pointcloud2_bytes(positions: np.ndarray, sec: int, nanosec: int, frame_id: str,
                      velocities: np.ndarray | None = None) -> bytes:
    """Serialised sensor_msgs/PointCloud2 of positions (n, 3) m, optionally with velocities
    (n, 3) m/s, stamped (sec, nanosec) in frame_id: one row of float32 points."""
    pos = np.asarray(positions, dtype=np.float32)
    names = XYZ if velocities is None else XYZ + VELOCITY
    cols = pos if velocities is None else np.hstack(
        [pos, np.asarray(velocities, dtype=np.float32)])
    cols = np.ascontiguousarray(cols, dtype="<f4")
    step = 4 * len(names)
    w = CdrWriter()
    w.pack("iI", int(sec), int(nanosec), align=4)
    w.string(frame_id)
    w.pack("II", 1, len(pos), align=4)  # height, width
    w.uint32(len(names))
    for k, name in enumerate(names):
        w.string(name)
        w.uint32(4 * k)  # offset
        w.pack("B", FLOAT32, align=1)
        w.uint32(1)  # count
    w.boolean(False)  # is_bigendian
    w.pack("II", step, step * len(pos), align=4)  # point_step, row_step
    w.uint32(cols.nbytes)
    w.array(cols.reshape(-1).view(np.uint8), align=1)
    w.boolean(bool(np.isfinite(cols).all()))  # is_dense
    return w.getvalue()


def mesh_bytes(positions: np.ndarray, faces: np.ndarray) -> bytes:
    """Serialised shape_msgs/Mesh: triangles faces (t, 3) over vertices positions (n, 3) m."""
    tri = np.ascontiguousarray(faces, dtype="<u4")
    pts = np.ascontiguousarray(positions, dtype="<f8")
    w = CdrWriter()
    w.uint32(len(tri))
    w.array(tri.reshape(-1), align=4)
    w.uint32(len(pts))
    w.array(pts.reshape(-1), align=8)
    return w.getvalue()


def verify_geometry_layouts() -> None:
    """Check both layouts against rclpy's serialiser (frame ids of every length mod 4, with and
    without velocities); raises RuntimeError naming the first case that differs."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from geometry_msgs.msg import Point

    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.serialization import serialize_message

    # imported here: ROS messages (the ROS side), loaded only when needed
    from sensor_msgs.msg import PointCloud2, PointField
    from shape_msgs.msg import Mesh, MeshTriangle

    pos = np.array([[0.0, 1.0, 2.0], [0.5, -1.0, 0.25], [3.0, 0.0, -2.0]])
    vel = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -3.0]])
    for k in range(4):
        for v in (None, vel):
            names = XYZ if v is None else XYZ + VELOCITY
            ref = PointCloud2(height=1, width=3, is_bigendian=False, point_step=4 * len(names),
                              row_step=12 * len(names), is_dense=True)
            ref.header.stamp.sec, ref.header.stamp.nanosec = 5, 6
            ref.header.frame_id = "f" * k
            ref.fields = [PointField(name=n, offset=4 * i, datatype=FLOAT32, count=1)
                          for i, n in enumerate(names)]
            cols = pos if v is None else np.hstack([pos, v])
            ref.data = cols.astype("<f4").tobytes()
            ours = pointcloud2_bytes(pos, 5, 6, "f" * k, v)
            if len(ours) != len(serialize_message(ref)) or deserialize(ours, PointCloud2) != ref:
                raise RuntimeError(f"sensor_msgs/PointCloud2 layout differs from the "
                                   f"hand-written one (frame_id length {k})")
    faces = np.array([[0, 1, 2], [2, 1, 0]])
    ref = Mesh(triangles=[MeshTriangle(vertex_indices=[int(i) for i in f]) for f in faces],
               vertices=[Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in pos])
    ours = mesh_bytes(pos, faces)
    if len(ours) != len(serialize_message(ref)) or deserialize(ours, Mesh) != ref:
        raise RuntimeError("shape_msgs/Mesh layout differs from the hand-written one")
