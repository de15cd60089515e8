"""visualization_msgs/Marker TRIANGLE_LIST written from numpy straight into CDR bytes.

`marker_triangle_list_bytes` gathers the triangle corners of a mesh, (t, 3) faces into (n, 3)
positions, and writes them with the message's other members into the bytes that rclpy 7.1.6
publishes with `publisher.publish(data)` (a publisher created with the Marker type), with no
`Point` object built (doc/architecture.md compares the costs).

Layout of visualization_msgs/Marker (Jazzy, 5.3.6) in plain little-endian CDR, offsets counted
after the 4-byte encapsulation header; every member is aligned to its own size:

    header.stamp (int32 sec, uint32 nanosec), header.frame_id (string)
    ns (string), id, type, action (int32)
    pose (7 float64), scale (3 float64)            <- 8-byte aligned: padding depends on strings
    color (4 float32), lifetime (int32, uint32), frame_locked (bool)
    points: uint32 count, count x 3 float64       <- 4 bytes padding before the first point
                                                     when the count ends off an 8-byte boundary
    colors: uint32 count, count x 4 float32
    texture_resource (string), texture (sensor_msgs/CompressedImage: header, format, uint8[]),
    uv_coordinates (sequence of 2 float32), text, mesh_resource (strings),
    mesh_file (filename string, uint8[]), mesh_use_embedded_materials (bool)

Everything after `colors` is written empty. ros.message_reference's `verify_layout()` checks
this layout against the installed message definition and rclpy's serialiser (same length,
same decoded message), so a changed definition fails loudly instead of publishing garbage;
the node calls it at start-up.

Nothing here imports rclpy or message packages, so recorders and viewers can build marker
bytes without ROS.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.io.messages.cdr import CdrReader, CdrWriter

__all__ = [
    "ADD",
    "TRIANGLE_LIST",
    "MarkerArrays",
    "marker_arrays_from_bytes",
    "marker_triangle_list_bytes",
    "triangle_corners",
]

TRIANGLE_LIST = 11  # visualization_msgs/Marker.TRIANGLE_LIST
ADD = 0  # visualization_msgs/Marker.ADD

DEFAULT_COLOUR = (0.85, 0.35, 0.25, 1.0)  # RGBA in 0..1: a terracotta cloth


def triangle_corners(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle corners as a TRIANGLE_LIST wants them: (3 t, 3) float64, m.

    positions: (n, 3) vertex positions, m; faces: (t, 3) vertex indices. Corner 3 f + c is
    positions[faces[f, c]].
    """
    pos = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(faces)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"positions must have shape (n, 3), got {pos.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3 or not np.issubdtype(tri.dtype, np.integer):
        raise ValueError(f"faces must be integers of shape (t, 3), got {tri.dtype} {tri.shape}")
    idx = tri.reshape(-1)
    if idx.size and (idx.min() < 0 or idx.max() >= len(pos)):
        raise ValueError(f"faces index vertices {idx.min()}..{idx.max()}, but there are "
                         f"{len(pos)} positions")
    # np.take with a flat index is one gather into a fresh C-contiguous array.
    return np.take(pos, idx, axis=0)


def write_fixed(w: CdrWriter, stamp_sec: int, stamp_nanosec: int, frame_id: str, ns: str,
                 marker_id: int, marker_type: int, action: int, position: Sequence[float],
                 orientation: Sequence[float], scale: Sequence[float],
                 colour: Sequence[float], lifetime_s: float = 0.0) -> None:
    """Members from header to frame_locked (see the module docstring); lifetime_s: the
    marker expires this long after its stamp on a display (0: never)."""
    w.pack("iI", int(stamp_sec), int(stamp_nanosec), align=4)
    w.string(frame_id)
    w.string(ns)
    w.pack("iii", int(marker_id), int(marker_type), int(action), align=4)
    # pose (position xyz, orientation xyzw) and scale: 10 float64, one 8-byte aligned run.
    w.pack("10d", *position, *orientation, *scale, align=8)
    w.pack("4f", *colour, align=4)
    sec, nanosec = divmod(round(float(lifetime_s) * 1e9), 1_000_000_000)
    w.pack("iI", int(sec), int(nanosec), align=4)  # lifetime (0: the marker never expires)
    w.boolean(False)  # frame_locked


def write_tail(w: CdrWriter, text: str = "") -> None:
    """Members after `colors`: texture, uv_coordinates, text, mesh fields (all empty but
    `text`)."""
    w.string("")  # texture_resource
    w.pack("iI", 0, 0, align=4)  # texture.header.stamp
    w.string("")  # texture.header.frame_id
    w.string("")  # texture.format
    w.uint32(0)  # texture.data (uint8[])
    w.uint32(0)  # uv_coordinates
    w.string(text)
    w.string("")  # mesh_resource
    w.string("")  # mesh_file.filename
    w.uint32(0)  # mesh_file.data (uint8[])
    w.boolean(False)  # mesh_use_embedded_materials


def marker_triangle_list_bytes(
    positions: np.ndarray,
    faces: np.ndarray,
    stamp_sec: int = 0,
    stamp_nanosec: int = 0,
    frame_id: str = "world",
    ns: str = "cloth",
    marker_id: int = 0,
    colour: Sequence[float] = DEFAULT_COLOUR,
    per_vertex_colours: np.ndarray | None = None,
    scale: Sequence[float] = (1.0, 1.0, 1.0),
    position: Sequence[float] = (0.0, 0.0, 0.0),
    orientation: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
    lifetime_s: float = 0.0,
) -> bytes:
    """Serialised visualization_msgs/Marker (TRIANGLE_LIST, ADD) of a triangle mesh.

    positions: (n, 3) vertex positions in m, in `frame_id`; faces: (t, 3) vertex indices.
    The marker's `points` are the 3 t triangle corners, positions[faces].reshape(-1, 3).
    stamp_sec, stamp_nanosec: header stamp (s, ns). colour: RGBA in 0..1 for the whole
    marker. per_vertex_colours: optional (n, 4) RGBA in 0..1 per vertex, written as one
    `colors` entry per corner (3 t entries); RViz then ignores `colour`.
    scale, position, orientation (x, y, z, w quaternion): the marker's scale and pose.
    lifetime_s: a display drops the marker this long (s) after its stamp (0: never).

    Returns bytes (CDR encapsulation header included) for `publisher.publish(data)`. Positions
    are not checked for NaN: RViz drops a marker holding one, so the caller checks first.
    """
    points = triangle_corners(positions, faces)
    if len(colour) != 4 or len(scale) != 3 or len(position) != 3 or len(orientation) != 4:
        raise ValueError("colour and orientation need 4 numbers, scale and position 3")
    colours = None
    if per_vertex_colours is not None:
        rgba = np.asarray(per_vertex_colours, dtype=np.float32)
        n = len(np.asarray(positions))
        if rgba.shape != (n, 4):
            raise ValueError(f"per_vertex_colours must have shape ({n}, 4), got {rgba.shape}")
        colours = np.take(rgba, np.asarray(faces).reshape(-1), axis=0)

    w = CdrWriter()
    write_fixed(w, stamp_sec, stamp_nanosec, frame_id, ns, marker_id, TRIANGLE_LIST, ADD,
                 position, orientation, scale, colour, lifetime_s)
    w.uint32(len(points))
    w.array(points, align=8)
    if colours is None:
        w.uint32(0)
    else:
        w.uint32(len(colours))
        w.array(colours, align=4)
    write_tail(w)
    return w.getvalue()


@dataclass
class MarkerArrays:
    """A Marker's header, identity and arrays read from CDR bytes without building a message.

    points: (k, 3) float64 m; colors: (k2, 4) float32 RGBA; both read-only views into the
    bytes (copy them to keep or change them).
    """

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    ns: str
    marker_id: int
    marker_type: int
    action: int
    pose: tuple[float, ...]
    scale: tuple[float, ...]
    colour: tuple[float, ...]
    points: np.ndarray
    colors: np.ndarray


def marker_arrays_from_bytes(data: bytes | bytearray | memoryview) -> MarkerArrays:
    """Read a serialised Marker's header, pose, colour, points and colors (no rclpy needed).

    For raw subscriptions (`create_subscription(Marker, ..., raw=True)`): decoding 120K points
    this way builds no `Point` objects (doc/architecture.md has the cost of each way).
    """
    r = CdrReader(data)
    sec, nsec = r.unpack("iI", 4)
    frame_id = r.string()
    ns = r.string()
    marker_id, marker_type, action = r.unpack("iii", 4)
    pose_scale = r.unpack("10d", 8)
    colour = r.unpack("4f", 4)
    r.unpack("iI?", 4)  # lifetime, frame_locked
    points = r.array(np.float64, 3 * r.uint32(), 8).reshape(-1, 3)
    colors = r.array(np.float32, 4 * r.uint32(), 4).reshape(-1, 4)
    return MarkerArrays(sec, nsec, frame_id, ns, marker_id, marker_type, action,
                        pose_scale[:7], pose_scale[7:], colour, points, colors)
