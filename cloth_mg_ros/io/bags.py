"""rosbag2 bags of avatar body poses, written and read with `rosbags` (no rclpy needed).

A pose bag holds one topic (default `/avatar/body_poses`) of geometry_msgs/msg/PoseArray, one
message per frame: header.stamp is the motion time (s, the first frame at 0, the same value is
the bag's receive timestamp), header.frame_id the world frame (default 'world', ROS REP 103:
z up, x forward, metres), and poses[s] the pose of avatar segment s (Avatar.names order):
position = the segment origin, orientation = its unit quaternion (x, y, z, w). Bags written by
`write_pose_bag` record the segment names and the source in the bag's metadata.yaml custom_data
(`bag_info(...)['custom_data']`).

A joint bag (`write_joint_bag`, read by `read_joint_frames`) is the same message type with poses[j]
the j-th joint of a tracker's layout (motion.skeletons), orientation the identity; bags from
`cloth-mg bag from-bvh` name the kind and the layout in custom_data (`BODY_INPUT_KEY`,
`SKELETON_KEY`). The Azure Kinect driver's MarkerArray: `io.kinect_markers`.

Storage: MCAP (the ROS 2 Jazzy default, `ros2 bag play` reads it) or sqlite3; both read back.
Serialisation uses the ROS 2 Jazzy type store (rosbags.typesys.Stores.ROS2_JAZZY).

The checks of one incoming frame (FrameStatus, check_frame) are in cloth_mg_ros.motion.frames.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import numpy as np
import yaml
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import StoragePlugin

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.messages.markers import marker_triangle_list_bytes
from cloth_mg_ros.io.share import share_path

__all__ = [
    'BODY_INPUT_KEY',
    'DEFAULT_TOPIC',
    'POSE_ARRAY',
    'SKELETON_KEY',
    'absolute_topic',
    'bag_info',
    'bundled_bag',
    'iter_pose_frames',
    'read_joint_frames',
    'read_pose_frames',
    'write_joint_bag',
    'write_message_bag',
    'write_pose_bag',
]

DEFAULT_TOPIC = '/avatar/body_poses'
#: custom_data keys of bags from `cloth-mg bag from-bvh`: the input kind (segments, joints,
#: kinect_markers) and, for joints, the layout
BODY_INPUT_KEY = 'cloth_mg_ros.body_input'
SKELETON_KEY = 'cloth_mg_ros.skeleton'


def absolute_topic(name: str) -> str:
    """A topic name as a bag records it: a relative name ('avatar/body_poses', as the node's
    parameters have it, resolved in the root namespace) gets its leading slash."""
    return name if name.startswith('/') else '/' + name
POSE_ARRAY = 'geometry_msgs/msg/PoseArray'
STORAGES = ('mcap', 'sqlite3')

_TYPESTORE = None


def jazzy_typestore():
    global _TYPESTORE
    if _TYPESTORE is None:
        # imported here: the typestore is built once, on first use (it parses every message
        # definition)
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def resolve_bag(bag: str | os.PathLike) -> Path:
    """A bag folder or file path, or the name of a bundled bag (walk, brisk_walk, run, jump).

    Raises ClothInputError when it is neither."""
    path = Path(bag)
    if path.exists():
        return path
    if os.sep not in str(bag) and bundled_bag(str(bag)).exists():
        return bundled_bag(str(bag))
    raise ClothInputError(f"bag {str(bag)!r}: no such bag folder or file, and no bundled bag of "
                          f"that name (bundled: walk, brisk_walk, run, jump)")


def bundled_bag(name: str) -> Path:
    """Path of a bag shipped in bags/ (walk, brisk_walk, run, jump), in the source tree or in the
    installed share/cloth_mg_ros/io/bags."""
    return share_path('bags', name)


# --------------------------------------------------------------------------------------------
# Writing


def _to_ns(seconds: float) -> int:
    return round(float(seconds) * 1e9)


def write_pose_bag(out_dir: str | os.PathLike, stamps: np.ndarray, poses: np.ndarray, *,
                   topic: str = DEFAULT_TOPIC, frame_id: str = 'world', storage: str = 'mcap',
                   custom_data: Mapping[str, str] | None = None,
                   missing_ok: bool = False) -> Path:
    """Write a bag of PoseArray messages, one per frame.

    Args:
        out_dir: the bag directory to create (must not exist).
        stamps: (F,) motion time of each frame in seconds (>= 0, non-decreasing); written as
            header.stamp and as the bag's receive timestamp.
        poses: (F, S, 7) float [x, y, z, qx, qy, qz, qw] per segment, metres.
        topic: topic name.
        frame_id: header.frame_id.
        storage: 'mcap' (default, ROS 2 Jazzy's) or 'sqlite3'.
        custom_data: extra string key/values stored in metadata.yaml custom_data.
        missing_ok: NaN positions are written (a tracker's hidden joints).

    Returns:
        the bag directory.

    Raises:
        ClothInputError: bad shapes, non-finite values, negative or decreasing stamps, an
            existing output path, an unknown storage.
    """
    out = Path(out_dir)
    stamps = np.asarray(stamps, dtype=float).reshape(-1)
    poses = np.asarray(poses, dtype=float)
    _check_pose_frames(out, stamps, poses, topic, storage, missing_ok)
    ts = jazzy_typestore()
    return write_message_bag(out, topic, POSE_ARRAY, stamps,
                             lambda k, ns: _pose_array(ts, ns, poses[k], frame_id),
                             storage=storage, custom_data=custom_data)


def write_message_bag(out: Path, topic: str, msgtype: str, stamps: np.ndarray,
                      message: Callable[[int, int], object], *, storage: str = 'mcap',
                      custom_data: Mapping[str, str] | None = None) -> Path:
    """Write one topic of `msgtype`, message k = message(k, stamp_ns) (a rosbags message of the
    Jazzy type store) received at stamps[k] (s). The caller has checked its arguments.

    Raises:
        ClothInputError: the bag cannot be written (naming `out`).
    """
    ts = jazzy_typestore()
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    try:
        with Writer(out, version=9, storage_plugin=plugin) as writer:
            for key, value in (custom_data or {}).items():
                writer.set_custom_data(str(key), str(value))
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for k, stamp in enumerate(stamps):
                ns = _to_ns(stamp)
                writer.write(conn, ns, ts.serialize_cdr(message(k, ns), msgtype))
    except OSError as exc:
        raise ClothInputError(f'{out}: cannot write bag: {exc}') from None
    return out


def _check_pose_frames(out: Path, stamps: np.ndarray, poses: np.ndarray, topic: str,
                       storage: str, missing_ok: bool = False) -> None:
    """ClothInputError naming `out` for what write_pose_bag cannot write."""
    if storage not in STORAGES:
        raise ClothInputError(f'{out}: storage must be one of {", ".join(STORAGES)}, '
                              f'got {storage!r}')
    if poses.ndim != 3 or poses.shape[2] != 7:
        raise ClothInputError(f'{out}: poses must have shape (F, S, 7), got {poses.shape}')
    if poses.shape[0] != stamps.shape[0]:
        raise ClothInputError(f'{out}: {stamps.shape[0]} stamps for {poses.shape[0]} frames')
    if poses.shape[0] == 0:
        raise ClothInputError(f'{out}: no frames to write')
    bad = ~np.isfinite(poses)
    if missing_ok:  # a hidden joint: its position NaN
        bad[..., :3] &= ~np.isnan(poses[..., :3])
    if bad.any():
        f = int(np.argwhere(bad)[0][0])
        raise ClothInputError(f'{out}: poses of frame {f} are not finite')
    if not np.all(np.isfinite(stamps)) or np.any(stamps < 0):
        raise ClothInputError(f'{out}: stamps must be finite and >= 0 s, got min '
                              f'{np.nanmin(stamps)}')
    if np.any(np.diff(stamps) < 0):
        f = int(np.flatnonzero(np.diff(stamps) < 0)[0]) + 1
        raise ClothInputError(f'{out}: stamps go backwards at frame {f} '
                              f'({stamps[f - 1]} -> {stamps[f]} s)')
    if not topic.startswith('/'):
        raise ClothInputError(f'{out}: topic must be an absolute name, got {topic!r}')
    if out.exists():
        raise ClothInputError(f'{out}: output exists already')


def _pose_array(ts, ns: int, frame: np.ndarray, frame_id: str):
    """The rosbags PoseArray of one frame (S, 7) stamped ns."""
    T = ts.types
    Header, Time = T['std_msgs/msg/Header'], T['builtin_interfaces/msg/Time']
    Pose, Point, Quat = (T['geometry_msgs/msg/Pose'], T['geometry_msgs/msg/Point'],
                         T['geometry_msgs/msg/Quaternion'])
    return T[POSE_ARRAY](
        header=Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000),
                      frame_id=frame_id),
        poses=[Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    orientation=Quat(x=float(p[3]), y=float(p[4]), z=float(p[5]),
                                     w=float(p[6])))
               for p in frame])


def write_joint_bag(out_dir: str | os.PathLike, stamps: np.ndarray, joints: np.ndarray, *,
                    topic: str = DEFAULT_TOPIC, frame_id: str = 'world', storage: str = 'mcap',
                    custom_data: Mapping[str, str] | None = None) -> Path:
    """Write a bag of joint positions: one PoseArray per frame whose poses are the layout's
    joints in its order, position the joint (m; NaN: hidden), orientation the identity
    (0, 0, 0, 1) (the joint input reads positions only). Arguments and errors as
    `write_pose_bag`, with joints (F, J, 3) float, m, in place of the poses."""
    joints = np.asarray(joints, dtype=float)
    if joints.ndim != 3 or joints.shape[2] != 3:
        raise ClothInputError(f'{out_dir}: joints must have shape (F, J, 3), got {joints.shape}')
    identity = np.broadcast_to([0.0, 0.0, 0.0, 1.0], joints.shape[:2] + (4,))
    return write_pose_bag(out_dir, stamps, np.concatenate([joints, identity], axis=-1),
                          topic=topic, frame_id=frame_id, storage=storage,
                          custom_data=custom_data, missing_ok=True)


MARKER = 'visualization_msgs/msg/Marker'


def write_marker_bag(out_dir: str | os.PathLike, stamps: np.ndarray, positions: np.ndarray,
                     faces: np.ndarray, *, topic: str = '/cloth/marker',
                     frame_id: str = 'world') -> Path:
    """Write a bag (MCAP) of the garment as visualization_msgs/Marker TRIANGLE_LISTs (ns
    'cloth', id 0), one per tick, as cloth_node publishes them: stamps (k,) s, positions
    (k, n, 3) m, faces (t, 3). Foxglove and RViz (through `ros2 bag play`) show it.

    Raises ClothInputError for mismatched shapes or an existing output path."""

    out = Path(out_dir)
    stamps = np.asarray(stamps, dtype=float).reshape(-1)
    positions = np.asarray(positions)
    if positions.ndim != 3 or positions.shape[2] != 3 or len(positions) != len(stamps):
        raise ClothInputError(f'{out}: positions must have shape ({len(stamps)}, n, 3), got '
                              f'{positions.shape}')
    if out.exists():
        raise ClothInputError(f'{out}: output exists already')
    ts = jazzy_typestore()
    try:
        with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conn = writer.add_connection(absolute_topic(topic), MARKER, typestore=ts)
            for stamp, x in zip(stamps, positions, strict=True):
                ns = _to_ns(stamp)
                writer.write(conn, ns, marker_triangle_list_bytes(
                    np.asarray(x, dtype=np.float64), faces, ns // 1_000_000_000,
                    ns % 1_000_000_000, frame_id))
    except OSError as exc:
        raise ClothInputError(f'{out}: cannot write bag: {exc}') from None
    return out


# --------------------------------------------------------------------------------------------
# Reading


def open_reader(bag_dir: str | os.PathLike):
    """An opened rosbags Reader, or ClothInputError naming the bag and the problem."""
    path = Path(bag_dir)
    if not path.exists():
        raise ClothInputError(f'{path}: bag not found')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        raise ClothInputError(f'{path}: not a rosbag2 bag (no metadata.yaml)')
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types for bad bags
        raise ClothInputError(f'{path}: cannot read bag: {exc}') from None
    return reader


def _topic_list(reader) -> str:
    topics = reader.topics
    if not topics:
        return 'none'
    return ', '.join(f'{name} [{info.msgtype}]' for name, info in sorted(topics.items()))


def iter_pose_frames(bag_dir: str | os.PathLike, topic: str = DEFAULT_TOPIC
                     ) -> Iterator[tuple[float, np.ndarray]]:
    """Iterate over the PoseArray messages of a bag, in bag order.

    The bag and the topic are checked before this returns (errors are not deferred to the first
    iteration).

    Yields:
        (stamp_s, poses): header stamp in seconds, poses (k, 7) float64
        [x, y, z, qx, qy, qz, qw].

    Raises:
        ClothInputError: the bag is missing or unreadable, lacks the topic (the message lists the
            topics it has), or the topic is not geometry_msgs/msg/PoseArray.
    """
    topic = absolute_topic(topic)
    reader = open_reader(bag_dir)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise ClothInputError(f'{bag_dir}: no topic {topic!r} in the bag (topics: '
                                  f'{_topic_list(reader)})')
        wrong = [c.msgtype for c in conns if c.msgtype != POSE_ARRAY]
        if wrong:
            raise ClothInputError(f'{bag_dir}: topic {topic!r} has type {wrong[0]}, expected '
                                  f'{POSE_ARRAY}')
    except BaseException:
        reader.close()
        raise
    return _frames(reader, conns, bag_dir)


def _frames(reader, conns, bag_dir) -> Iterator[tuple[float, np.ndarray]]:
    ts = jazzy_typestore()
    try:
        for conn, _, raw in reader.messages(connections=conns):
            try:
                msg = ts.deserialize_cdr(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001
                raise ClothInputError(f'{bag_dir}: cannot decode a {conn.msgtype} message on '
                                      f'{conn.topic}: {exc}') from None
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            poses = np.array([[p.position.x, p.position.y, p.position.z, p.orientation.x,
                               p.orientation.y, p.orientation.z, p.orientation.w]
                              for p in msg.poses], dtype=np.float64).reshape(-1, 7)
            yield stamp, poses
    finally:
        reader.close()


def read_pose_frames(bag_dir: str | os.PathLike, topic: str = DEFAULT_TOPIC
                     ) -> list[tuple[float, np.ndarray]]:
    """All frames of a pose bag as a list of (stamp_s, poses (k, 7) float64); see
    `iter_pose_frames`. Works for MCAP and sqlite3 bags."""
    return list(iter_pose_frames(bag_dir, topic))


def read_joint_frames(bag_dir: str | os.PathLike, topic: str = DEFAULT_TOPIC,
                      num_joints: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The joint positions of a joint bag (`write_joint_bag`, `cloth-mg bag from-bvh
    --body-input joints`): the PoseArrays' positions; orientations are not read.

    Returns:
        stamps (F,) s and joints (F, J, 3) float64, m, in the poses' order.

    Raises:
        ClothInputError: as `iter_pose_frames`; an empty topic; messages whose pose counts
            differ from one another or from `num_joints` (naming the first such message).
    """
    stamps, joints = [], []
    for k, (stamp, poses) in enumerate(iter_pose_frames(bag_dir, topic)):
        want = num_joints if num_joints is not None else (len(joints[0]) if joints else None)
        if want is not None and len(poses) != want:
            raise ClothInputError(f'{bag_dir}: message {k} on {absolute_topic(topic)} has '
                                  f'{len(poses)} poses, expected {want} joints')
        stamps.append(stamp)
        joints.append(poses[:, :3])
    if not joints:
        raise ClothInputError(f'{bag_dir}: no messages on {absolute_topic(topic)}')
    return np.array(stamps), np.stack(joints)


def bag_info(bag_dir: str | os.PathLike) -> dict:
    """Summary of a bag.

    Returns:
        dict with 'path', 'storage' ('mcap' or 'sqlite3'), 'topics' ({name: {'type', 'count',
        'rate_hz'}}), 'message_count', 'start_s' and 'end_s' (receive timestamps of the first and
        last message, s), 'duration_s' (end_s - start_s), 'rate_hz' (of the topic with the most
        messages: (count - 1) / its time span; 0 for fewer than two messages) and 'custom_data'
        (the metadata.yaml custom_data mapping, {} if none).

    Raises:
        ClothInputError: missing or unreadable bag.
    """
    reader = open_reader(bag_dir)
    path = Path(bag_dir)
    try:
        topics = {}
        for name, info in sorted(reader.topics.items()):
            topics[name] = {'type': info.msgtype, 'count': int(info.msgcount), 'rate_hz': 0.0}
        spans: dict[str, list[int]] = {}
        for conn, t, _ in reader.messages():
            span = spans.setdefault(conn.topic, [t, t])
            span[0] = min(span[0], t)
            span[1] = max(span[1], t)
        for name, (t0, t1) in spans.items():
            n = topics[name]['count']
            if n > 1 and t1 > t0:
                topics[name]['rate_hz'] = (n - 1) / ((t1 - t0) * 1e-9)
        starts = [s[0] for s in spans.values()]
        ends = [s[1] for s in spans.values()]
        start = min(starts) * 1e-9 if starts else 0.0
        end = max(ends) * 1e-9 if ends else 0.0
        main = max(topics.values(), key=lambda x: x['count'], default=None)
        count = int(sum(t['count'] for t in topics.values()))
    finally:
        reader.close()
    storage, custom = _metadata(path)
    return {
        'path': str(path),
        'storage': storage,
        'topics': topics,
        'message_count': count,
        'start_s': start,
        'end_s': end,
        'duration_s': end - start,
        'rate_hz': main['rate_hz'] if main else 0.0,
        'custom_data': custom,
    }


def _metadata(path: Path) -> tuple[str, dict]:
    if not path.is_dir():
        return {'.mcap': 'mcap', '.db3': 'sqlite3'}.get(path.suffix, path.suffix), {}
    try:
        meta = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    except (OSError, KeyError, TypeError, yaml.YAMLError) as exc:
        raise ClothInputError(f'{path}: cannot read metadata.yaml: {exc}') from None
    return str(meta.get('storage_identifier', '')), dict(meta.get('custom_data') or {})
