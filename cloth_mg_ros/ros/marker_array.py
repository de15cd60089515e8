"""visualization_msgs/MarkerArray of the cloth and the avatar's capsules, written from numpy
straight into CDR bytes, and per-vertex strain colours.

`marker_array_bytes` writes the cloth's TRIANGLE_LIST (as `markers.marker_triangle_list_bytes`
does for a single Marker), then one CYLINDER and one SPHERE_LIST of end caps per body capsule,
a SPHERE per sphere collider, an ARROW per contact force (ns 'contact_forces': the cloth's
force on a body segment, with a DELETE for an arrow that went since the last array) and a
TEXT_VIEW_FACING caption (the node's figures, for RViz).
`marker_array_message` builds the same message from message objects (the reference of the
tests; slow for a large cloth), and
`verify_marker_array_layout` checks the hand-written bytes against rclpy's serialiser at
start-up, so a changed message definition fails loudly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.io.messages.cdr import CdrWriter
from cloth_mg_ros.io.messages.markers import (
    ADD,
    TRIANGLE_LIST,
    triangle_corners,
    write_fixed,
    write_tail,
)
from cloth_mg_ros.ros.message_reference import deserialize

__all__ = [
    "ARROW_NS",
    "AVATAR_RGBA",
    "CLOTH_RGBA",
    "delete_all_bytes",
    "marker_array_bytes",
    "marker_array_message",
    "strain_colours",
    "verify_marker_array_layout",
]

CLOTH_RGBA = (0.85, 0.35, 0.25, 1.0)
AVATAR_RGBA = (0.55, 0.62, 0.72, 1.0)
STRAIN_RGBA = (0.9, 0.05, 0.05, 1.0)  # colour of a 10 % (or more) stretched region
STRAIN_FULL = 0.1  # relative stretch shown in full STRAIN_RGBA
CYLINDER, SPHERE, SPHERE_LIST, TEXT_VIEW_FACING = 3, 2, 7, 9  # visualization_msgs/Marker types
CAPTION_RGBA = (0.95, 0.95, 0.95, 1.0)
CAPTION_HEIGHT = 0.06  # m: height of a capital letter of the caption
DELETE, DELETEALL = 2, 3  # visualization_msgs/Marker actions
ARROW = 0  # visualization_msgs/Marker type
ARROW_NS = "contact_forces"
ARROW_RGBA = (1.0, 0.8, 0.1, 1.0)
ARROW_SCALE = (0.01, 0.02, 0.03)  # m: shaft diameter, head diameter, head length


def _write_marker(w: CdrWriter, sec: int, nanosec: int, frame_id: str, ns: str, marker_id: int,
                  marker_type: int, position: Sequence[float], orientation: Sequence[float],
                  scale: Sequence[float], colour: Sequence[float],
                  points: np.ndarray | None = None, colours: np.ndarray | None = None,
                  text: str = "", lifetime_s: float = 0.0, action: int = ADD) -> None:
    """One visualization_msgs/Marker (ADD, or `action`) appended to `w` (see
    cloth_mg_ros.io.messages.markers for the layout). points: (k, 3) float64 m; colours: (k, 4)
    float32 RGBA; lifetime_s: s (0: never expires)."""
    write_fixed(w, sec, nanosec, frame_id, ns, marker_id, marker_type, action, position,
                 orientation, scale, colour, lifetime_s)
    for arr, dtype, align in ((points, np.float64, 8), (colours, np.float32, 4)):
        if arr is None:
            w.uint32(0)
        else:
            arr = np.asarray(arr, dtype=dtype)
            w.uint32(len(arr))
            w.array(arr, align=align)
    write_tail(w, text)


def _z_to_axis_quaternions(axis: np.ndarray) -> np.ndarray:
    """Unit quaternions (k, 4) [x, y, z, w] turning +z onto each row of `axis` (k, 3)."""
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    d = np.divide(axis, length, out=np.tile([0.0, 0.0, 1.0], (len(axis), 1)),
                  where=length > 1e-12)
    q = np.stack([-d[:, 1], d[:, 0], np.zeros(len(d)), 1.0 + d[:, 2]], axis=1)
    flipped = q[:, 3] < 1e-9  # axis along -z: half a turn about x
    q[flipped] = [1.0, 0.0, 0.0, 0.0]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def marker_array_bytes(positions: np.ndarray | None, faces: np.ndarray | None, sec: int,
                       nanosec: int,
                       frame_id: str, capsules: tuple[np.ndarray, np.ndarray, np.ndarray]
                       | None = None, spheres: Sequence[tuple[np.ndarray, float]] = (),
                       cloth_rgba: Sequence[float] = CLOTH_RGBA,
                       body_rgba: Sequence[float] = AVATAR_RGBA,
                       per_vertex_colours: np.ndarray | None = None,
                       caption: tuple[Sequence[float], str] | None = None,
                       lifetime_s: float = 0.0,
                       arrows: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None,
                       deleted_arrows: Sequence[int] = ()) -> bytes:
    """Serialised visualization_msgs/MarkerArray: the cloth, the capsules, the spheres, the
    contact arrows, a caption.

    positions: (n, 3) cloth vertices, m; faces: (t, 3) vertex indices: marker 0 is the cloth
    TRIANGLE_LIST (ns 'cloth', id 0), as on the marker topic; None: no cloth marker (the node's
    array holds the body only, so that a display of both topics draws the cloth once).
    per_vertex_colours: optional
    (n, 4) RGBA in 0..1. capsules: (p0 (S, 3), p1 (S, 3), radius (S,)) in m: for each
    capsule s a CYLINDER (ns 'avatar', id s; pose at the axis midpoint, z along p1 - p0,
    scale (2 r, 2 r, |p1 - p0|)), then for each a SPHERE_LIST of its two end caps
    (ns 'avatar_caps', id s, scale 2 r). spheres: (centre (3,), radius) pairs, m, as SPHERE
    markers (ns 'collider'). arrows: {id: (start (3,), end (3,)) m}: an ARROW each (ns
    ARROW_NS, points start and end); deleted_arrows: ids of ARROW_NS to DELETE (arrows drawn
    before that are gone). caption: (position (3,) m, text): a TEXT_VIEW_FACING marker
    (ns 'caption', id 0, CAPTION_HEIGHT high) there. sec, nanosec: the header stamp of every
    marker. lifetime_s: every marker expires this long (s) after its stamp (0: never).

    Returns bytes for `publisher.publish(data)` on a MarkerArray publisher.
    """
    w = CdrWriter()
    n_caps = 0 if capsules is None else len(capsules[2])
    cloth = positions is not None
    arrows = arrows or {}
    w.uint32(int(cloth) + 2 * n_caps + len(spheres) + len(arrows) + len(deleted_arrows)
             + int(caption is not None))
    head = _Head(sec, nanosec, frame_id, lifetime_s)
    if cloth:
        _write_cloth(w, head, positions, faces, cloth_rgba, per_vertex_colours)
    if capsules is not None:
        _write_capsules(w, head, capsules, body_rgba)
    for k, (centre, r) in enumerate(spheres):
        d = 2.0 * float(r)
        _write_marker(w, sec, nanosec, frame_id, "collider", k, SPHERE,
                      np.asarray(centre, dtype=np.float64), (0.0, 0.0, 0.0, 1.0), (d, d, d),
                      body_rgba, lifetime_s=lifetime_s)
    for k, (start, end) in arrows.items():  # a few: one per body segment at most
        _write_marker(w, sec, nanosec, frame_id, ARROW_NS, k, ARROW, (0.0, 0.0, 0.0),
                      (0.0, 0.0, 0.0, 1.0), ARROW_SCALE, ARROW_RGBA, np.stack([start, end]),
                      lifetime_s=lifetime_s)
    for k in deleted_arrows:
        _write_marker(w, sec, nanosec, frame_id, ARROW_NS, k, ARROW, (0.0, 0.0, 0.0),
                      (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0), ARROW_RGBA, action=DELETE)
    if caption is not None:
        _write_marker(w, sec, nanosec, frame_id, "caption", 0, TEXT_VIEW_FACING,
                      np.asarray(caption[0], dtype=np.float64), (0.0, 0.0, 0.0, 1.0),
                      (0.0, 0.0, CAPTION_HEIGHT), CAPTION_RGBA, text=caption[1],
                      lifetime_s=lifetime_s)
    return w.getvalue()


class _Head(NamedTuple):
    """What every marker of an array shares: the stamp (sec, nanosec), the frame and the
    lifetime (s; 0: never expires)."""

    sec: int
    nanosec: int
    frame_id: str
    lifetime_s: float


def _write_cloth(w: CdrWriter, head: _Head, positions: np.ndarray, faces: np.ndarray,
                 cloth_rgba: Sequence[float], per_vertex_colours: np.ndarray | None) -> None:
    """The cloth's TRIANGLE_LIST (ns 'cloth', id 0), coloured per vertex when given."""
    colours = None
    if per_vertex_colours is not None:
        colours = np.take(np.asarray(per_vertex_colours, np.float32),
                          np.asarray(faces).ravel(), axis=0)
    _write_marker(w, head.sec, head.nanosec, head.frame_id, "cloth", 0, TRIANGLE_LIST,
                  (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0), cloth_rgba,
                  triangle_corners(positions, faces), colours, lifetime_s=head.lifetime_s)


def _write_capsules(w: CdrWriter, head: _Head,
                    capsules: tuple[np.ndarray, np.ndarray, np.ndarray],
                    body_rgba: Sequence[float]) -> None:
    """A CYLINDER per capsule (ns 'avatar'), then a SPHERE_LIST of its two end caps per
    capsule (ns 'avatar_caps')."""
    sec, nanosec, frame_id, lifetime_s = head
    p0, p1, radius = (np.asarray(a, dtype=np.float64) for a in capsules)
    mid = 0.5 * (p0 + p1)
    length = np.linalg.norm(p1 - p0, axis=1)
    quats = _z_to_axis_quaternions(p1 - p0)
    n_caps = len(capsules[2])
    for s in range(n_caps):  # one marker per body segment (16), not per particle
        d = 2.0 * float(radius[s])
        _write_marker(w, sec, nanosec, frame_id, "avatar", s, CYLINDER, mid[s], quats[s],
                      (d, d, float(length[s])), body_rgba, lifetime_s=lifetime_s)
    for s in range(n_caps):
        d = 2.0 * float(radius[s])
        _write_marker(w, sec, nanosec, frame_id, "avatar_caps", s, SPHERE_LIST,
                      (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (d, d, d), body_rgba,
                      np.stack([p0[s], p1[s]]), lifetime_s=lifetime_s)


def marker_array_message(positions: np.ndarray, faces: np.ndarray, sec: int, nanosec: int,
                         frame_id: str, capsules=None, spheres=(), cloth_rgba=CLOTH_RGBA,
                         body_rgba=AVATAR_RGBA, caption=None, arrows=None, deleted_arrows=()):
    """The same visualization_msgs/MarkerArray built from message objects (the reference of
    the tests and of `verify_marker_array_layout`; slow for a large cloth)."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker, MarkerArray

    def base(ns: str, mid: int, kind: int, rgba) -> Marker:
        m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD)
        m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
        m.header.frame_id = frame_id
        m.pose.orientation.w = 1.0
        r, g, b, a = (float(c) for c in np.asarray(rgba, dtype=np.float32))
        m.color.r, m.color.g, m.color.b, m.color.a = r, g, b, a
        return m

    def point(p) -> Point:
        return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))

    out = MarkerArray()
    if positions is not None:
        cloth = base("cloth", 0, Marker.TRIANGLE_LIST, cloth_rgba)
        cloth.scale.x = cloth.scale.y = cloth.scale.z = 1.0
        cloth.points = [point(p) for p in triangle_corners(positions, faces)]
        out.markers.append(cloth)
    if capsules is not None:
        out.markers.extend(_capsule_markers(capsules, base, point, body_rgba))
    for k, (centre, r) in enumerate(spheres):
        m = base("collider", k, Marker.SPHERE, body_rgba)
        m.pose.position = point(centre)
        m.scale.x = m.scale.y = m.scale.z = 2.0 * float(r)
        out.markers.append(m)
    for k, (start, end) in (arrows or {}).items():
        m = base(ARROW_NS, k, Marker.ARROW, ARROW_RGBA)
        m.scale.x, m.scale.y, m.scale.z = ARROW_SCALE
        m.points = [point(start), point(end)]
        out.markers.append(m)
    for k in deleted_arrows:
        m = base(ARROW_NS, k, Marker.ARROW, ARROW_RGBA)
        m.action = Marker.DELETE
        m.scale.x = m.scale.y = m.scale.z = 1.0
        out.markers.append(m)
    if caption is not None:
        m = base("caption", 0, Marker.TEXT_VIEW_FACING, CAPTION_RGBA)
        m.pose.position = point(caption[0])
        m.scale.z = CAPTION_HEIGHT
        m.text = caption[1]
        out.markers.append(m)
    return out


def _capsule_markers(capsules, base, point, body_rgba) -> list:
    """The avatar's markers, objects: a CYLINDER per capsule, then a SPHERE_LIST of each
    capsule's two end caps; capsules (p0, p1, radius); base, point: marker_array_message's
    makers of a Marker and a Point."""
    from visualization_msgs.msg import Marker

    p0, p1, radius = capsules
    quats = _z_to_axis_quaternions(p1 - p0)
    bodies, caps = [], []
    for s in range(len(radius)):
        m = base("avatar", s, Marker.CYLINDER, body_rgba)
        m.pose.position = point(0.5 * (p0[s] + p1[s]))
        (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
         m.pose.orientation.w) = (float(c) for c in quats[s])
        m.scale.x = m.scale.y = 2.0 * float(radius[s])
        m.scale.z = float(np.linalg.norm(p1[s] - p0[s]))
        bodies.append(m)
        c = base("avatar_caps", s, Marker.SPHERE_LIST, body_rgba)
        c.scale.x = c.scale.y = c.scale.z = 2.0 * float(radius[s])
        c.points = [point(p0[s]), point(p1[s])]
        caps.append(c)
    return bodies + caps


def verify_marker_array_layout() -> None:
    """Check `marker_array_bytes` against the installed MarkerArray and rclpy's serialiser
    (frame ids of every length mod 8; capsules and spheres); raises RuntimeError naming the
    first case that differs."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.serialization import serialize_message

    # imported here: ROS messages (the ROS side), loaded only when needed
    from visualization_msgs.msg import MarkerArray

    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5], [1.0, 1.0, -0.25]])
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    p0 = np.array([[0.0, 0.0, 1.0], [0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])
    p1 = np.array([[0.0, 0.0, 1.5], [0.4, 0.2, 0.1], [0.0, 0.0, -1.0]])
    caps = (p0, p1, np.array([0.1, 0.05, 0.2]))
    arrows = {2: (p0[1], p1[1]), 0: (p0[0], p1[2])}
    for k in range(8):
        for t, c, sph, cap, arr, gone in (
                (2, caps, [(np.array([0.0, 0.0, 0.5]), 0.25)], None, None, ()),
                (1, None, (), ((0.0, 0.5, 2.0), "t" * k), arrows, (1, 5)),
                (0, caps, (), None, arrows, ())):
            cloth = (pos, tri[:t]) if t else (None, None)
            ours = marker_array_bytes(*cloth, 3, 4, "f" * k, c, sph, caption=cap, arrows=arr,
                                      deleted_arrows=gone)
            ref = marker_array_message(*cloth, 3, 4, "f" * k, c, sph, caption=cap,
                                       arrows=arr, deleted_arrows=gone)
            if len(ours) != len(serialize_message(ref)) or deserialize(ours, MarkerArray) != ref:
                raise RuntimeError(f"visualization_msgs/MarkerArray layout differs from the "
                                   f"hand-written one (frame_id length {k}, {t} triangles)")


def strain_colours(x: np.ndarray, edges: np.ndarray, rest: np.ndarray,
                   base: Sequence[float] = CLOTH_RGBA) -> np.ndarray:
    """Per-vertex RGBA (n, 4) float32 from the stretch of the edges around each vertex.

    x: (n, 3) positions, m; edges: (e, 2) vertex indices; rest: (e,) rest lengths, m. The
    vertex strain is the mean of max(|x_i - x_j| / rest - 1, 0) over its edges; 0 gives
    `base`, STRAIN_FULL (10 %) or more STRAIN_RGBA, linear in between.
    """
    e = np.asarray(edges)
    strain = np.maximum(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1) / rest - 1.0, 0.0)
    n = len(x)
    total = np.bincount(e.ravel(), weights=np.repeat(strain, 2), minlength=n)
    count = np.maximum(np.bincount(e.ravel(), minlength=n), 1)
    s = np.clip(total / count / STRAIN_FULL, 0.0, 1.0)[:, None]
    out = (1.0 - s) * np.asarray(base) + s * np.asarray(STRAIN_RGBA)
    return out.astype(np.float32)


def delete_all_bytes(sec: int, nanosec: int, frame_id: str) -> tuple[bytes, bytes]:
    """(Marker, MarkerArray) serialised, each one DELETEALL marker: a display clears every
    marker it holds from this publisher (on a reset, at shutdown, when the cloth changes
    size)."""
    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.serialization import serialize_message

    # imported here: ROS messages (the ROS side), loaded only when needed
    from visualization_msgs.msg import Marker, MarkerArray

    m = Marker(action=DELETEALL)
    m.header.stamp.sec, m.header.stamp.nanosec = int(sec), int(nanosec)
    m.header.frame_id = frame_id
    m.pose.orientation.w = 1.0
    return bytes(serialize_message(m)), bytes(serialize_message(MarkerArray(markers=[m])))

