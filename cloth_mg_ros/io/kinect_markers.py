"""The Azure Kinect ROS driver's body tracking output, visualization_msgs/MarkerArray, written to
and read from rosbag2 bags with `rosbags` (no rclpy).

What the driver publishes on `body_tracking_data` (microsoft/Azure_Kinect_ROS_Driver: docs/usage.md,
"Topics"; src/k4a_ros_device.cpp, K4AROSDevice::bodyPublisherThread and ::getBodyMarker, the
ROS 2 branches; include/azure_kinect_ros_driver/k4a_ros_types.h, BODY_COLOR_PALETTE): one
MarkerArray per body tracking frame holding, body by body, one Marker per joint in the order of
the Body Tracking SDK's k4abt_joint_id_t (32 joints), each with

- header: frame_id `depth_camera_link` (the driver's tf_prefix, empty by default, + its depth
  camera frame), stamp the capture's time;
- id = body_id x 100 + joint index (subscribers recover them as id // 100 and id % 100);
- type SPHERE, action ADD (not set, the default), ns empty;
- pose.position the joint's position in metres (the SDK's millimetres / 1000), pose.orientation
  the joint's orientation from the SDK;
- scale 0.05 m on each axis, colour BODY_COLOR_PALETTE[body_id % 8], lifetime 0.25 s ("to
  prevent flickering for even 5fps configurations").

`write_kinect_marker_bag` writes exactly those members, with two differences a bag made from a
posed avatar cannot avoid: orientations are the identity (the joint input ignores them; the
SDK's joint frames are not derived here), and positions are in the frame they are given in (the
avatar's z-up world for `cloth-mg bag from-bvh`), where the driver's are in the depth camera's
(x right, y down, z forward); the header still names `depth_camera_link` unless told otherwise.
`kinect_joints` picks one body's joints out of a MarkerArray's ids and positions (the chosen
body id, or the body nearest the frame's origin, the camera); `read_kinect_marker_frames` reads a
bag through it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import (
    DEFAULT_TOPIC,
    STORAGES,
    absolute_topic,
    jazzy_typestore,
    open_reader,
    write_message_bag,
)

__all__ = [
    'BODY_COLOR_PALETTE',
    'BODY_TRACKING_TOPIC',
    'DELETEALL',
    'DEPTH_CAMERA_FRAME',
    'K4ABT_JOINT_COUNT',
    'MARKER_ARRAY',
    'kinect_joints',
    'read_kinect_marker_frames',
    'write_kinect_marker_bag',
]

MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'
DELETEALL = 3  # visualization_msgs/Marker.DELETEALL: a driver frame with no body
BODY_TRACKING_TOPIC = '/body_tracking_data'  # the driver's topic, in its node's namespace
DEPTH_CAMERA_FRAME = 'depth_camera_link'
K4ABT_JOINT_COUNT = 32  # k4abt_joint_id_t: K4ABT_JOINT_COUNT
MARKER_LIFETIME_S = 0.25
MARKER_SCALE_M = 0.05
SPHERE, ADD = 2, 0  # visualization_msgs/msg/Marker constants
#: RGBA per body_id % 8 (the driver's k4a_ros_types.h)
BODY_COLOR_PALETTE = ((1.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0, 1.0), (0.0, 0.0, 1.0, 1.0),
                      (1.0, 1.0, 0.0, 1.0), (1.0, 0.0, 1.0, 1.0), (0.0, 1.0, 1.0, 1.0),
                      (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0, 1.0))


# --------------------------------------------------------------------------------------------
# Writing


def write_kinect_marker_bag(out_dir: str | os.PathLike, stamps: np.ndarray, joints: np.ndarray,
                            *, body_id: int = 1, topic: str = DEFAULT_TOPIC,
                            frame_id: str = DEPTH_CAMERA_FRAME, storage: str = 'mcap',
                            custom_data: dict[str, str] | None = None) -> Path:
    """Write one MarkerArray per frame as the Azure Kinect driver publishes one body (module
    docstring).

    Args:
        out_dir: the bag directory to create (must not exist).
        stamps: (F,) s, >= 0, non-decreasing: header stamps and receive times.
        joints: (F, 32, 3) positions, m, in k4abt_joint_id_t order (motion.skeletons kinect32);
            NaN: a hidden joint, whose marker the message leaves out.
        body_id: the tracker's body id (>= 0): marker ids body_id * 100 + joint.
        topic, frame_id, storage, custom_data: as `io.bags.write_pose_bag`.

    Raises:
        ClothInputError: bad shapes, infinite positions, bad stamps, a negative body id, an
            unknown storage, a relative topic, an existing output path.
    """
    out = Path(out_dir)
    stamps = np.asarray(stamps, dtype=float).reshape(-1)
    joints = np.asarray(joints, dtype=float)
    _check(out, stamps, joints, body_id, topic, storage)
    ts = jazzy_typestore()
    T = ts.types
    Marker, Header, Time = (T['visualization_msgs/msg/Marker'], T['std_msgs/msg/Header'],
                            T['builtin_interfaces/msg/Time'])
    Pose, Point, Quat = (T['geometry_msgs/msg/Pose'], T['geometry_msgs/msg/Point'],
                         T['geometry_msgs/msg/Quaternion'])
    scale = T['geometry_msgs/msg/Vector3'](x=MARKER_SCALE_M, y=MARKER_SCALE_M, z=MARKER_SCALE_M)
    r, g, b, a = BODY_COLOR_PALETTE[body_id % len(BODY_COLOR_PALETTE)]
    colour = T['std_msgs/msg/ColorRGBA'](r=r, g=g, b=b, a=a)
    lifetime = T['builtin_interfaces/msg/Duration'](sec=0, nanosec=round(MARKER_LIFETIME_S * 1e9))
    texture = T['sensor_msgs/msg/CompressedImage'](
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id=''), format='',
        data=np.zeros(0, np.uint8))
    mesh = T['visualization_msgs/msg/MeshFile'](filename='', data=np.zeros(0, np.uint8))

    def message(k: int, ns: int):
        header = Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000),
                        frame_id=frame_id)
        return T[MARKER_ARRAY](markers=[
            Marker(header=header, ns='', id=body_id * 100 + j, type=SPHERE, action=ADD,
                   pose=Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                             orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0)),
                   scale=scale, color=colour, lifetime=lifetime, frame_locked=False, points=[],
                   colors=[], texture_resource='', texture=texture, uv_coordinates=[], text='',
                   mesh_resource='', mesh_file=mesh, mesh_use_embedded_materials=False)
            for j, p in enumerate(joints[k]) if not np.isnan(p).any()])  # hidden: left out

    return write_message_bag(out, topic, MARKER_ARRAY, stamps, message, storage=storage,
                             custom_data=custom_data)


def _check(out: Path, stamps: np.ndarray, joints: np.ndarray, body_id: int, topic: str,
           storage: str) -> None:
    if storage not in STORAGES:
        raise ClothInputError(f'{out}: storage must be one of {", ".join(STORAGES)}, '
                              f'got {storage!r}')
    if joints.ndim != 3 or joints.shape[1:] != (K4ABT_JOINT_COUNT, 3):
        raise ClothInputError(f'{out}: Azure Kinect joints must have shape (F, '
                              f'{K4ABT_JOINT_COUNT}, 3), got {joints.shape}')
    if len(joints) != len(stamps) or len(joints) == 0:
        raise ClothInputError(f'{out}: {len(stamps)} stamps for {len(joints)} frames')
    bad = ~np.isfinite(joints) & ~np.isnan(joints)  # NaN: a hidden joint, left out
    if bad.any():
        raise ClothInputError(f'{out}: joints of frame {int(np.argwhere(bad)[0][0])} are '
                              f'infinite')
    if not np.all(np.isfinite(stamps)) or np.any(stamps < 0) or np.any(np.diff(stamps) < 0):
        raise ClothInputError(f'{out}: stamps must be finite, >= 0 s and non-decreasing')
    if not (isinstance(body_id, (int, np.integer)) and body_id >= 0):
        raise ClothInputError(f'{out}: body id must be an integer >= 0, got {body_id!r}')
    if not topic.startswith('/'):
        raise ClothInputError(f'{out}: topic must be an absolute name, got {topic!r}')
    if out.exists():
        raise ClothInputError(f'{out}: output exists already')


# --------------------------------------------------------------------------------------------
# Reading


def kinect_joints(ids: np.ndarray, positions: np.ndarray, body_id: int | None = None,
                  num_joints: int = K4ABT_JOINT_COUNT) -> tuple[int | None, np.ndarray]:
    """One body's joints from a body tracking MarkerArray.

    Args:
        ids: (M,) the markers' ids (body_id * 100 + joint).
        positions: (M, 3) their pose positions, m.
        body_id: the body to take; None: the body whose pelvis (joint 0; else the mean of its
            joints) is nearest the frame's origin (the camera).
        num_joints: joints per body (32); markers with a larger joint index are ignored.

    Returns:
        (body id, or None when the message holds no such body), (num_joints, 3) positions, NaN
        for joints the message lacks.
    """
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    bodies, joint = ids // 100, ids % 100
    keep = (joint < num_joints) & (ids >= 0)
    out = np.full((num_joints, 3), np.nan)
    if body_id is None:
        candidates = np.unique(bodies[keep])
        if len(candidates) == 0:
            return None, out
        body_id = int(min(candidates, key=lambda b: _distance(bodies, joint, positions, keep, b)))
    mine = keep & (bodies == body_id)
    if not mine.any():
        return None, out
    out[joint[mine]] = positions[mine]
    return int(body_id), out


def _distance(bodies, joint, positions, keep, b) -> float:
    mine = keep & (bodies == b)
    pelvis = mine & (joint == 0)
    p = positions[pelvis][0] if pelvis.any() else np.nanmean(positions[mine], axis=0)
    return float(np.linalg.norm(p)) if np.all(np.isfinite(p)) else np.inf


def read_kinect_marker_frames(bag_dir: str | os.PathLike, topic: str = DEFAULT_TOPIC,
                              body_id: int | None = None
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every MarkerArray of a body tracking bag as one body's joints (`kinect_joints`).

    Returns:
        stamps (F,) s (the first marker's header stamp, NaN for an empty array), joints
        (F, 32, 3) m (NaN where missing), body ids (F,) int (-1 where the body is absent).

    Raises:
        ClothInputError: the bag is missing or unreadable, lacks the topic or has it with
            another type, or holds no messages on it.
    """
    topic = absolute_topic(topic)
    reader = open_reader(bag_dir)
    ts = jazzy_typestore()
    stamps, joints, chosen = [], [], []
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns or any(c.msgtype != MARKER_ARRAY for c in conns):
            have = ', '.join(f'{c.topic} [{c.msgtype}]' for c in reader.connections) or 'none'
            raise ClothInputError(f'{bag_dir}: no {MARKER_ARRAY} topic {topic!r} (topics: '
                                  f'{have})')
        for conn, t_ns, raw in reader.messages(connections=conns):
            # as the live input: a DELETEALL marker is a driver frame with no body in it
            markers = [m for m in ts.deserialize_cdr(raw, conn.msgtype).markers
                       if m.action != DELETEALL]
            ids = np.array([m.id for m in markers], dtype=np.int64)
            pos = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                            for m in markers], dtype=float).reshape(-1, 3)
            b, x = kinect_joints(ids, pos, body_id)
            head = markers[0].header.stamp if markers else None
            # an empty array (no body in view) has no header: the time the bag received it
            stamps.append(head.sec + 1e-9 * head.nanosec if head else 1e-9 * t_ns)
            joints.append(x)
            chosen.append(-1 if b is None else b)
    finally:
        reader.close()
    if not joints:
        raise ClothInputError(f'{bag_dir}: no messages on {topic}')
    return np.array(stamps), np.stack(joints), np.array(chosen)
