"""cloth_node: a garment draped over a moving avatar (or a sheet scene), published for RViz.

Run it (in a ROS 2 workspace, or in the project's virtualenv):

    cloth_node --ros-args --params-file config/walking.yaml      # a body scene
    cloth_node --ros-args -p scene:=running -p particles:=1200   # the scene file's defaults
    cloth_node --ros-args -p scene:=hang -p particles:=5000 -p rate_hz:=30.0   # a sheet
    python -m cloth_mg_ros.ros.node                              # the walking scene

and, in another shell, play body poses into it: `cloth-mg replay bags/walk`.

Two kinds of scene (parameter `scene`, default 'walking'):

- Body scenes (walking, brisk_walking, running, jumping, their aliases walk, ..., any
  config/<scene>.yaml, or a path to a params .yaml): the parameters not given on the command
  line take their defaults from the scene's file (scene_config.load_scene). The node subscribes
  to `topic` (geometry_msgs/PoseArray, one pose per avatar segment in Avatar.names order,
  [x, y, z] m and a unit quaternion; reliable, keep-last 100), dresses the garment on the first
  valid message (GarmentSim.dress) and then, in tick mode 'message' (the default), advances
  the cloth to every further message's body pose over the interval between the header stamps
  (GarmentSim.push). In tick mode 'timer' it steps 1/rate_hz s of simulated time every
  1/rate_hz s of wall time towards the latest body pose received. Messages are read from their
  CDR bytes straight into an (S, 7) numpy array (raw subscription, no Pose objects).
- Sheet scenes (drape, hang): always timer mode, one step of `dt` per tick (as before).

Per pose message used (the one dressed on, each one that advanced the cloth, each teleport
the garment was carried along with) or per timer tick, the node publishes, stamped with the
pose message's header stamp in message mode and the node's clock otherwise:

- `marker_topic` (visualization_msgs/Marker, default /cloth/marker): the cloth as one
  TRIANGLE_LIST in `frame_id` (ns 'cloth', id 0), m, z up, serialised straight from numpy
  (`cloth_mg_ros.ros.markers`; 20K particles: about 1 ms). With strain_colours, per-vertex
  colours show the stretch (the cloth colour at rest length, red at 10 % and more);
- `markers_topic` (visualization_msgs/MarkerArray, default /cloth/markers): the same cloth
  marker, then per avatar capsule a CYLINDER (ns 'avatar', id = segment index) and a
  SPHERE_LIST of its two end caps (ns 'avatar_caps'); sheet scenes add their sphere collider
  (ns 'collider'). Written by hand into CDR (`marker_array_bytes`) and checked at start-up
  against rclpy's serialiser;
- `stats_topic` (diagnostic_msgs/DiagnosticArray, default /cloth/stats): one status
  'cloth_node: solver' with step_ms, solve_ms, iterations, rel_residual, max_penetration_m,
  contacts, substeps, particles, marker_ms and frame counts. Level OK; WARN when the solve
  stopped short of `tolerance`, when pose frames were skipped since the previous status, or
  after a re-anchoring; ERROR when a simulation step failed (its result was dropped, the
  cloth held) or positions became non-finite (then no marker is published).

Bad pose input never reaches the cloth: empty messages, a wrong number of poses, NaN or
infinite values, stamps that do not advance and undecodable bytes are skipped; a jump of more
than a metre re-anchors the garment (carried rigidly with the body). Each kind is logged once
as a warning when first seen, then counted: a summary is logged every 10 s while the counts
change, and at shutdown ('pose frames: 40 received, 36 used; skipped 4: non_finite 2 ...').

Services and run-time parameters:

- `~/reset` (std_srvs/Trigger): body scenes re-dress the garment on the next valid pose
  (stamps start afresh, so a bag can be replayed again); sheet scenes restart at once.
- `solver` and `tolerance` may be set while running (`ros2 param set`); an unknown solver or a
  tolerance out of (0, 0.5] is rejected with the reason; a valid change rebuilds the solver
  (make_solver with the garment's hierarchy and bending Hessians) before the next step.
  `rate_hz` may be changed too (timer modes). Every other parameter is read-only (needs a
  restart).

Both publishers and the subscription are reliable, keep-last 100. With max_steps > 0 the node
exits (status 0) after that many simulation ticks. Ctrl-C exits with status 0. Start-up
failures (an unknown scene, garment, material or solver, a parameter out of its declared range
or of the wrong type, a bad topic name) are logged as one error line naming the value and the
node exits with status 1 before any topic appears.

rclpy notes: a publisher created with the Marker type accepts either a Marker or `bytes`
(exactly `bytes`: a bytearray raises TypeError); subscribers cannot tell the difference.
Parameter on-set callbacks also run for declarations, so they are added after declaring.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidTopicNameException, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.integrator import Simulator
from cloth_mg_ros.physics.materials import MATERIALS, get_material
from cloth_mg_ros.ros.cdr import CdrReader, CdrWriter, deserialize
from cloth_mg_ros.ros.markers import (
    ADD,
    TRIANGLE_LIST,
    _write_fixed,
    _write_tail,
    marker_triangle_list_bytes,
    triangle_corners,
    verify_layout,
)
from cloth_mg_ros.scene_config import BODY_SCENES, SCENE_KEYS, check_value, load_scene
from cloth_mg_ros.scenes import SCENES, build_scene
from cloth_mg_ros.solvers import SOLVERS, make_solver, validate_solver_name

__all__ = [
    "ClothNode",
    "main",
    "marker_array_bytes",
    "pose_array_from_cdr",
    "verify_marker_array_layout",
    "verify_pose_array_layout",
]

NODE_NAME = "cloth_node"
STATUS_NAME = "cloth_node: solver"
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                 depth=100)
CLOTH_RGBA = (0.85, 0.35, 0.25, 1.0)
AVATAR_RGBA = (0.55, 0.62, 0.72, 1.0)
STRAIN_RGBA = (0.9, 0.05, 0.05, 1.0)  # colour of a 10 % (or more) stretched region
STRAIN_FULL = 0.1  # relative stretch shown in full STRAIN_RGBA
TICK_MODES = ("message", "timer")
SUMMARY_PERIOD_S = 10.0  # s between summaries of skipped pose frames (while they change)
MAX_TOLERANCE = 0.5
CYLINDER, SPHERE, SPHERE_LIST = 3, 2, 7  # visualization_msgs/Marker types

#: What each kind of skipped (or repaired) pose frame means, for the log.
FRAME_KINDS = {
    "empty": "no poses",
    "wrong_count": "not one pose per avatar segment",
    "non_finite": "NaN or infinite values, or a zero quaternion",
    "stamp_backwards": "a header stamp not after the previous frame's",
    "malformed": "bytes that do not decode as a PoseArray",
    "dress_failed": "the garment could not be dressed on this pose",
    "teleport": "a jump of more than a metre: the garment was carried along (re-anchored)",
}


# ------------------------------------------------------------------------------------------
# Parameters


@dataclass(frozen=True)
class _Param:
    """One declared parameter: default, description, whether it needs a restart, range."""

    default: object
    description: str
    read_only: bool = True
    int_range: tuple[int, int] | None = None
    float_range: tuple[float, float] | None = None
    constraints: str = ""


def scene_defaults(scene: str, overridden: Sequence[str] = ()) -> tuple[bool, dict]:
    """(is a body scene, the defaults of every scene key) for a scene name.

    Sheet scenes (SCENES) get the sheet defaults. A body scene name, alias, config/<name>.yaml
    or .yaml path gets its file's values (scene_config.load_scene). A name without a file is
    still a body scene when the parameters `overridden` (from --params-file or -p) include
    'garment' (a params file that holds the scene itself); otherwise ClothInputError.
    """
    defaults = {k: default for k, (_, default) in SCENE_KEYS.items()}
    if scene in SCENES:
        defaults.update(scene=scene, solver="pcg")
        return False, defaults
    try:
        return True, load_scene(scene)
    except ClothInputError as exc:
        if "garment" in overridden and "no file" in str(exc):
            defaults["scene"] = scene
            return True, defaults
        raise ClothInputError(
            f"unknown scene {scene!r}: sheet scenes are {', '.join(SCENES)}; body scenes "
            f"{', '.join(BODY_SCENES)}, a config/<scene>.yaml or a params .yaml ({exc})"
        ) from None


def parameter_table(body: bool, d: dict) -> dict[str, _Param]:
    """Every parameter the node declares, with defaults `d` (scene_defaults) for the scene
    keys. Body keys are declared for sheet scenes too (so any params file is accepted)."""
    sheets, bodies = ", ".join(SCENES), ", ".join(BODY_SCENES)
    return {
        "scene": _Param(d["scene"], f"scene: a sheet ({sheets}) or a body scene ({bodies}, "
                        f"config/<scene>.yaml or a params .yaml path)"),
        "bag": _Param(d["bag"], "the scene's bag of body poses (for reference: the node "
                      "listens on `topic`; play the bag with `cloth-mg replay`)"),
        "topic": _Param(d["topic"], "geometry_msgs/PoseArray input topic: the avatar's body "
                        "poses (body scenes)"),
        "garment": _Param(d["garment"], "garment of a body scene",
                          constraints="skirt, dress, cape or top"),
        "particles": _Param(d["particles"], "approximate number of cloth particles",
                            int_range=(16, 200_000)),
        "material": _Param(d["material"], "cloth material (paper Table 2 stiffness ratios)",
                           constraints=f"one of {', '.join(MATERIALS)}"),
        "solver": _Param(d["solver"], "linear solver of each implicit step (may be changed "
                         "while running: rebuilds the solver)", read_only=False,
                         constraints=f"one of {', '.join(SOLVERS)}"),
        "tolerance": _Param(float(d["tolerance"]), "relative residual the linear solve must "
                            "reach (may be changed while running)", read_only=False,
                            float_range=(1e-10, MAX_TOLERANCE)),
        "levels": _Param(d["levels"], "multigrid hierarchy levels (0: as many as the mesh "
                         "size calls for)", int_range=(0, 7)),
        "substeps": _Param(d["substeps"], "body scenes: at least this many steps per pose "
                           "interval", int_range=(1, 64)),
        "max_substep_motion": _Param(float(d["max_substep_motion"]), "body scenes: more "
                                     "substeps while a capsule end moves further than this per "
                                     "substep, m", float_range=(1e-3, 1.0)),
        "floor": _Param(bool(d["floor"]), "body scenes: a ground plane at z = 0"),
        "self_contact": _Param(bool(d["self_contact"]), "body scenes: cloth-cloth repulsion"),
        "tick_mode": _Param("message" if body else "timer", "message: one tick per pose "
                            "message (body scenes); timer: one tick every 1/rate_hz s",
                            constraints="message or timer"),
        "rate_hz": _Param(30.0, "timer rate: ticks per second of wall time, Hz (may be "
                          "changed while running)", read_only=False, float_range=(0.1, 1000.0)),
        "dt": _Param(1.0 / 60.0, "sheet scenes: simulation time step, s",
                     float_range=(1e-5, 0.1)),
        "frame_id": _Param("world", "frame of the published markers (z up, metres)",
                           constraints="non-empty"),
        "marker_topic": _Param("/cloth/marker", "visualization_msgs/Marker output: the cloth"),
        "markers_topic": _Param("/cloth/markers", "visualization_msgs/MarkerArray output: "
                                "the cloth and the avatar's capsules"),
        "stats_topic": _Param("/cloth/stats", "diagnostic_msgs/DiagnosticArray output"),
        "strain_colours": _Param(False, "colour the cloth by stretch (per-vertex colours)"),
        "max_steps": _Param(0, "exit after this many ticks (0: run until shut down)",
                            int_range=(0, 2**31 - 1)),
    }


def _descriptor(name: str, spec: _Param) -> ParameterDescriptor:
    """The ParameterDescriptor of one parameter_table entry."""
    kinds = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
             float: ParameterType.PARAMETER_DOUBLE, bool: ParameterType.PARAMETER_BOOL}
    desc = ParameterDescriptor(name=name, type=kinds[type(spec.default)],
                               description=spec.description, read_only=spec.read_only,
                               additional_constraints=spec.constraints)
    if spec.int_range is not None:
        desc.integer_range = [IntegerRange(from_value=spec.int_range[0],
                                           to_value=spec.int_range[1], step=1)]
    if spec.float_range is not None:
        desc.floating_point_range = [FloatingPointRange(from_value=spec.float_range[0],
                                                        to_value=spec.float_range[1], step=0.0)]
    return desc


# ------------------------------------------------------------------------------------------
# Messages in and out as CDR bytes


def pose_array_from_cdr(data: bytes | bytearray | memoryview
                        ) -> tuple[int, int, str, np.ndarray]:
    """Decode a serialised geometry_msgs/PoseArray without building Pose objects.

    Layout (plain little-endian CDR after the 4-byte encapsulation header): header.stamp
    (int32 sec, uint32 nanosec), header.frame_id (string), then a uint32 count and count
    poses of 7 float64 (position x, y, z, orientation x, y, z, w), 8-byte aligned.

    Returns (stamp sec, stamp nanosec, frame_id, poses (count, 7) float64, a fresh array).
    Raises ValueError for bytes that are not such a message.
    """
    r = CdrReader(data)
    sec, nanosec = r.unpack("iI", 4)
    frame_id = r.string()
    count = r.uint32()
    if count > r.remaining // 56 + 1:
        raise ValueError(f"PoseArray claims {count} poses in {r.remaining} bytes")
    poses = np.array(r.array(np.float64, 7 * count, 8), dtype=np.float64).reshape(count, 7)
    return sec, nanosec, frame_id, poses


def verify_pose_array_layout() -> None:
    """Check `pose_array_from_cdr` against rclpy's serialiser (frame ids of every length mod
    8, 0 to 2 poses); raises RuntimeError naming the first case that differs."""
    from geometry_msgs.msg import Pose
    from rclpy.serialization import serialize_message

    for k in range(8):
        for n in range(3):
            msg = PoseArray()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 7 + k, 123 * n
            msg.header.frame_id = "f" * k
            vals = np.arange(7 * n, dtype=np.float64).reshape(n, 7) + 0.5
            for v in vals:
                p = Pose()
                p.position.x, p.position.y, p.position.z = (float(c) for c in v[:3])
                (p.orientation.x, p.orientation.y, p.orientation.z,
                 p.orientation.w) = (float(c) for c in v[3:])
                msg.poses.append(p)
            sec, nsec, frame, poses = pose_array_from_cdr(serialize_message(msg))
            if (sec, nsec, frame) != (7 + k, 123 * n, "f" * k) or not np.array_equal(poses,
                                                                                     vals):
                raise RuntimeError(f"geometry_msgs/PoseArray layout differs from the "
                                   f"hand-written one (frame_id length {k}, {n} poses)")


def _write_marker(w: CdrWriter, sec: int, nanosec: int, frame_id: str, ns: str, marker_id: int,
                  marker_type: int, position: Sequence[float], orientation: Sequence[float],
                  scale: Sequence[float], colour: Sequence[float],
                  points: np.ndarray | None = None, colours: np.ndarray | None = None) -> None:
    """One visualization_msgs/Marker (ADD) appended to `w` (see cloth_mg_ros.ros.markers for
    the layout). points: (k, 3) float64 m; colours: (k, 4) float32 RGBA."""
    _write_fixed(w, sec, nanosec, frame_id, ns, marker_id, marker_type, ADD, position,
                 orientation, scale, colour)
    for arr, dtype, align in ((points, np.float64, 8), (colours, np.float32, 4)):
        if arr is None:
            w.uint32(0)
        else:
            arr = np.asarray(arr, dtype=dtype)
            w.uint32(len(arr))
            w.array(arr, align=align)
    _write_tail(w)


def _z_to_axis_quaternions(axis: np.ndarray) -> np.ndarray:
    """Unit quaternions (k, 4) [x, y, z, w] turning +z onto each row of `axis` (k, 3)."""
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    d = np.divide(axis, length, out=np.tile([0.0, 0.0, 1.0], (len(axis), 1)),
                  where=length > 1e-12)
    q = np.stack([-d[:, 1], d[:, 0], np.zeros(len(d)), 1.0 + d[:, 2]], axis=1)
    flipped = q[:, 3] < 1e-9  # axis along -z: half a turn about x
    q[flipped] = [1.0, 0.0, 0.0, 0.0]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def marker_array_bytes(positions: np.ndarray, faces: np.ndarray, sec: int, nanosec: int,
                       frame_id: str, capsules: tuple[np.ndarray, np.ndarray, np.ndarray]
                       | None = None, spheres: Sequence[tuple[np.ndarray, float]] = (),
                       cloth_rgba: Sequence[float] = CLOTH_RGBA,
                       body_rgba: Sequence[float] = AVATAR_RGBA,
                       per_vertex_colours: np.ndarray | None = None) -> bytes:
    """Serialised visualization_msgs/MarkerArray: the cloth, the capsules, the spheres.

    positions: (n, 3) cloth vertices, m; faces: (t, 3) vertex indices: marker 0 is the cloth
    TRIANGLE_LIST (ns 'cloth', id 0), as on the marker topic. per_vertex_colours: optional
    (n, 4) RGBA in 0..1. capsules: (p0 (S, 3), p1 (S, 3), radius (S,)) in m: for each
    capsule s a CYLINDER (ns 'avatar', id s; pose at the axis midpoint, z along p1 - p0,
    scale (2 r, 2 r, |p1 - p0|)), then for each a SPHERE_LIST of its two end caps
    (ns 'avatar_caps', id s, scale 2 r). spheres: (centre (3,), radius) pairs, m, as SPHERE
    markers (ns 'collider'). sec, nanosec: the header stamp of every marker.

    Returns bytes for `publisher.publish(data)` on a MarkerArray publisher.
    """
    w = CdrWriter()
    n_caps = 0 if capsules is None else len(capsules[2])
    w.uint32(1 + 2 * n_caps + len(spheres))
    colours = None
    if per_vertex_colours is not None:
        colours = np.take(np.asarray(per_vertex_colours, np.float32), np.asarray(faces).ravel(),
                          axis=0)
    _write_marker(w, sec, nanosec, frame_id, "cloth", 0, TRIANGLE_LIST, (0.0, 0.0, 0.0),
                  (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0), cloth_rgba,
                  triangle_corners(positions, faces), colours)
    if capsules is not None:
        p0, p1, radius = (np.asarray(a, dtype=np.float64) for a in capsules)
        mid = 0.5 * (p0 + p1)
        length = np.linalg.norm(p1 - p0, axis=1)
        quats = _z_to_axis_quaternions(p1 - p0)
        for s in range(n_caps):  # one marker per body segment (16), not per particle
            d = 2.0 * float(radius[s])
            _write_marker(w, sec, nanosec, frame_id, "avatar", s, CYLINDER, mid[s], quats[s],
                          (d, d, float(length[s])), body_rgba)
        for s in range(n_caps):
            d = 2.0 * float(radius[s])
            _write_marker(w, sec, nanosec, frame_id, "avatar_caps", s, SPHERE_LIST,
                          (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (d, d, d), body_rgba,
                          np.stack([p0[s], p1[s]]))
    for k, (centre, r) in enumerate(spheres):
        d = 2.0 * float(r)
        _write_marker(w, sec, nanosec, frame_id, "collider", k, SPHERE,
                      np.asarray(centre, dtype=np.float64), (0.0, 0.0, 0.0, 1.0), (d, d, d),
                      body_rgba)
    return w.getvalue()


def marker_array_message(positions: np.ndarray, faces: np.ndarray, sec: int, nanosec: int,
                         frame_id: str, capsules=None, spheres=(), cloth_rgba=CLOTH_RGBA,
                         body_rgba=AVATAR_RGBA) -> MarkerArray:
    """The same MarkerArray built from message objects (the reference of the tests and of
    `verify_marker_array_layout`; slow for a large cloth)."""
    from geometry_msgs.msg import Point

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

    cloth = base("cloth", 0, Marker.TRIANGLE_LIST, cloth_rgba)
    cloth.scale.x = cloth.scale.y = cloth.scale.z = 1.0
    cloth.points = [point(p) for p in triangle_corners(positions, faces)]
    out = MarkerArray(markers=[cloth])
    if capsules is not None:
        p0, p1, radius = capsules
        quats = _z_to_axis_quaternions(p1 - p0)
        caps = []
        for s in range(len(radius)):
            m = base("avatar", s, Marker.CYLINDER, body_rgba)
            m.pose.position = point(0.5 * (p0[s] + p1[s]))
            (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
             m.pose.orientation.w) = (float(c) for c in quats[s])
            m.scale.x = m.scale.y = 2.0 * float(radius[s])
            m.scale.z = float(np.linalg.norm(p1[s] - p0[s]))
            out.markers.append(m)
            c = base("avatar_caps", s, Marker.SPHERE_LIST, body_rgba)
            c.scale.x = c.scale.y = c.scale.z = 2.0 * float(radius[s])
            c.points = [point(p0[s]), point(p1[s])]
            caps.append(c)
        out.markers.extend(caps)
    for k, (centre, r) in enumerate(spheres):
        m = base("collider", k, Marker.SPHERE, body_rgba)
        m.pose.position = point(centre)
        m.scale.x = m.scale.y = m.scale.z = 2.0 * float(r)
        out.markers.append(m)
    return out


def verify_marker_array_layout() -> None:
    """Check `marker_array_bytes` against the installed MarkerArray and rclpy's serialiser
    (frame ids of every length mod 8; capsules and spheres); raises RuntimeError naming the
    first case that differs."""
    from rclpy.serialization import serialize_message

    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5], [1.0, 1.0, -0.25]])
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    p0 = np.array([[0.0, 0.0, 1.0], [0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])
    p1 = np.array([[0.0, 0.0, 1.5], [0.4, 0.2, 0.1], [0.0, 0.0, -1.0]])
    caps = (p0, p1, np.array([0.1, 0.05, 0.2]))
    for k in range(8):
        for t, c, sph in ((2, caps, [(np.array([0.0, 0.0, 0.5]), 0.25)]), (1, None, ())):
            ours = marker_array_bytes(pos, tri[:t], 3, 4, "f" * k, c, sph)
            ref = marker_array_message(pos, tri[:t], 3, 4, "f" * k, c, sph)
            if len(ours) != len(serialize_message(ref)) or deserialize(ours, MarkerArray) != ref:
                raise RuntimeError(f"visualization_msgs/MarkerArray layout differs from the "
                                   f"hand-written one (frame_id length {k}, {t} triangles)")


# ------------------------------------------------------------------------------------------
# Bookkeeping of skipped pose frames


class FrameLog:
    """Counts the pose frames received, used and skipped by kind (FRAME_KINDS); warns once
    per kind, then summarises."""

    def __init__(self, logger, segments: int) -> None:
        self.logger = logger
        self.segments = segments
        self.received = 0
        self.used = 0
        self.counts: Counter = Counter()
        self.since_status: Counter = Counter()
        self._summarised: Counter = Counter()

    def note(self, kind: str, stamp: float) -> None:
        """Count one skipped (or re-anchored, kind 'teleport') frame with header stamp (s)."""
        if not self.counts[kind]:
            what = FRAME_KINDS.get(kind, kind)
            if kind == "wrong_count":
                what = f"not {self.segments} poses (one per avatar segment)"
            verb = "re-anchored the garment at" if kind == "teleport" else "skipped"
            self.logger.warning(
                f"{verb} a body pose frame (stamp {stamp:.3f} s): {kind}: {what}; further "
                f"{kind} frames are counted and summarised every {SUMMARY_PERIOD_S:g} s and "
                f"at shutdown")
        self.counts[kind] += 1
        self.since_status[kind] += 1

    @property
    def skipped(self) -> int:
        """Frames skipped (re-anchorings not counted: those frames were used)."""
        return sum(n for k, n in self.counts.items() if k != "teleport")

    def summary(self) -> str:
        """One line: 'pose frames: R received, U used (...); skipped S: kind n (meaning), ...'."""
        line = f"pose frames: {self.received} received, {self.used} used"
        if self.counts["teleport"]:
            line += f" ({self.counts['teleport']} re-anchored after a teleport)"
        skipped = {k: n for k, n in sorted(self.counts.items()) if k != "teleport" and n}
        if skipped:
            parts = [f"skipped {n} frame{'s' if n > 1 else ''} with {k} "
                     f"({FRAME_KINDS.get(k, k)})" for k, n in skipped.items()]
            line += "; " + ", ".join(parts)
        return line

    def periodic(self) -> None:
        """Log the summary if anything was skipped or re-anchored since the last one."""
        if self.counts != self._summarised:
            self._summarised = self.counts.copy()
            self.logger.warning(self.summary())


# ------------------------------------------------------------------------------------------
# The node


class ClothNode(Node):
    """Declares the parameters, builds the scene, steps and publishes it (module docstring).

    Raises ClothInputError (or rclpy's ParameterException) from the constructor when a
    parameter is unusable; the node is destroyed before the exception leaves.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        #: Completed with the exit status when the node should stop (max_steps or a failure).
        self.finished = Future()
        self.steps = 0  # simulation ticks done (sheet steps, or pose intervals advanced)
        self.gs = None  # the GarmentSim of a body scene, once dressed
        self.resets = 0
        try:
            self._declare()
            self._setup()
        except Exception:
            self.destroy_node()
            raise

    # -- set-up --------------------------------------------------------------------------
    def _param(self, name: str):
        return self.get_parameter(name).value

    def _declare(self) -> None:
        """Declare `scene` first, then every other parameter with the scene's defaults."""
        overrides = tuple(getattr(self, "_parameter_overrides", {}))
        spec = _Param("walking", "scene: a sheet or a body scene (see the node's docs)")
        self.declare_parameter("scene", "walking", _descriptor("scene", spec))
        scene = str(self._param("scene"))
        self.body, defaults = scene_defaults(scene, overrides)
        self.table = parameter_table(self.body, defaults)
        for name, spec in self.table.items():
            if name != "scene":
                self.declare_parameter(name, spec.default, _descriptor(name, spec))

    def _setup(self) -> None:
        """Validate every parameter, build the scene or wait for poses, create topics."""
        self.frame_id = str(self._param("frame_id"))
        if not self.frame_id.strip():
            raise ClothInputError("parameter frame_id must not be empty")
        for key in SCENE_KEYS:
            check_value(key, self._param(key), "parameter")
        self.max_steps = int(self._param("max_steps"))
        self.material = get_material(self._param("material"))
        validate_solver_name(self._param("solver"))
        self.tick_mode = str(self._param("tick_mode"))
        if self.tick_mode not in TICK_MODES:
            raise ClothInputError(f"parameter tick_mode must be one of {', '.join(TICK_MODES)}, "
                                  f"got {self.tick_mode!r}")
        if not self.body and self.tick_mode != "timer":
            raise ClothInputError(f"tick_mode {self.tick_mode!r} needs a body scene; sheet "
                                  f"scene {self._param('scene')!r} runs on the timer")
        self.strain_colours = bool(self._param("strain_colours"))
        verify_layout()  # the hand-written layouts must match the installed definitions
        verify_marker_array_layout()
        pubs = {}
        for key, msg_type in (("marker_topic", Marker), ("markers_topic", MarkerArray),
                              ("stats_topic", DiagnosticArray)):
            pubs[key] = self._topic(key, lambda t, m=msg_type: self.create_publisher(m, t, QOS))
        self.marker_pub = pubs["marker_topic"]
        self.markers_pub = pubs["markers_topic"]
        self.stats_pub = pubs["stats_topic"]
        self.timer = None
        if self.body:
            self._setup_body()
        else:
            self._setup_sheet()
        self.reset_srv = self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def _topic(self, key: str, create):
        """create(topic name of parameter `key`), a bad name turned into ClothInputError."""
        topic = str(self._param(key))
        try:
            return create(topic)
        except InvalidTopicNameException as exc:
            raise ClothInputError(f"parameter {key}: invalid topic name {topic!r} "
                                  f"({exc})") from exc

    def _levels(self) -> int | None:
        return int(self._param("levels")) or None

    def _setup_sheet(self) -> None:
        t0 = time.perf_counter()
        self.scene = build_scene(self._param("scene"), int(self._param("particles")),
                                 self.material, levels=self._levels())
        self.initial_state = self.scene.state.copy()
        self.sim = Simulator(self.scene.model, self.scene.state, self._make_solver(),
                             dt=float(self._param("dt")), scheme="bdf2")
        self.faces = np.ascontiguousarray(self.scene.model.mesh.faces)
        build_ms = 1e3 * (time.perf_counter() - t0)
        self.timer = self.create_timer(1.0 / float(self._param("rate_hz")), self._tick_sheet)
        self.get_logger().info(
            f"scene {self.scene.name!r}: {self.scene.model.n} particles, "
            f"{len(self.faces)} triangles, {self.material.name}, solver {self._param('solver')} "
            f"(tol {self._param('tolerance'):g}), dt {self.sim.dt:.4g} s, "
            f"{self._param('rate_hz'):g} Hz, built in {build_ms:.0f} ms; publishing "
            f"{self.marker_pub.topic_name}, {self.markers_pub.topic_name} and "
            f"{self.stats_pub.topic_name} in {self.frame_id!r}")

    def _setup_body(self) -> None:
        from cloth_mg_ros.body_sim import BodySimOptions
        from cloth_mg_ros.mesh.garments import GARMENTS
        from cloth_mg_ros.motion.avatar import Avatar

        if self._param("garment") not in GARMENTS:
            raise ClothInputError(f"parameter garment: unknown garment "
                                  f"{self._param('garment')!r}; choose one of "
                                  f"{', '.join(GARMENTS)}")
        self.avatar = Avatar.load()
        self.options = BodySimOptions(
            garment=self._param("garment"), particles=int(self._param("particles")),
            solver=self._param("solver"), tolerance=float(self._param("tolerance")),
            levels=self._levels(), substeps=int(self._param("substeps")),
            max_substep_motion=float(self._param("max_substep_motion")),
            floor=bool(self._param("floor")), self_contact=bool(self._param("self_contact")))
        self.frames = FrameLog(self.get_logger(), self.avatar.num_segments)
        self.redress = False
        self.prev_rx: float | None = None  # stamp (s) of the last pose accepted on receipt
        self.latest: tuple[int, int, np.ndarray] | None = None  # timer mode: newest pose
        self.sim_stamp = 0.0  # timer mode: simulated time, s
        verify_pose_array_layout()
        warm_ms = self._warm_up()
        self.pose_sub = self._topic("topic", lambda t: self.create_subscription(
            PoseArray, t, self._on_pose, QOS, raw=True))
        if self.tick_mode == "timer":
            self.timer = self.create_timer(1.0 / float(self._param("rate_hz")),
                                           self._tick_body_timer)
        self.summary_timer = self.create_timer(SUMMARY_PERIOD_S, self.frames.periodic)
        o = self.options
        self.get_logger().info(
            f"scene {self._param('scene')!r}: a {o.garment} of about {o.particles} particles, "
            f"{self.material.name}, solver {o.solver} (tol {o.tolerance:g}, levels "
            f"{o.levels or 'auto'}), substeps >= {o.substeps}, floor {o.floor}, self-contact "
            f"{o.self_contact}; warmed up in {warm_ms:.0f} ms; tick mode {self.tick_mode}; "
            f"waiting for body poses on {self.pose_sub.topic_name}; publishing "
            f"{self.marker_pub.topic_name}, {self.markers_pub.topic_name} and "
            f"{self.stats_pub.topic_name} in {self.frame_id!r}")

    def _warm_up(self) -> float:
        """Dress a small garment of the same kind on the standing avatar and step it once, so
        that the compiled kernels are loaded before the first pose arrives. Returns ms."""
        from dataclasses import replace

        from cloth_mg_ros.body_sim import GarmentSim

        t0 = time.perf_counter()
        rest = self.avatar.rest_poses()
        gs = GarmentSim.dress(self.avatar, 0.0, rest, self.material,
                              replace(self.options, particles=min(self.options.particles, 300)))
        gs.push(1.0 / 30.0, rest)
        return 1e3 * (time.perf_counter() - t0)

    def _make_solver(self, name: str | None = None, tol: float | None = None):
        """A solver for the current garment or sheet (make_solver with its hierarchy and
        bending Hessians), from the parameters unless name/tol are given."""
        name = self._param("solver") if name is None else name
        tol = float(self._param("tolerance")) if tol is None else tol
        if self.body:
            return make_solver(name, tol=tol, hierarchy=self.gs.garment.hierarchy,
                               wing_hess=self.gs.sim.model.wing_hess, levels=self._levels())
        return make_solver(name, tol=tol, hierarchy=self.scene.hierarchy,
                           wing_hess=self.scene.model.wing_hess, levels=self._levels())

    # -- parameters and services ---------------------------------------------------------
    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Reject an unknown solver or a tolerance out of (0, MAX_TOLERANCE] with the reason
        (ranges and types were already checked against the descriptors)."""
        for p in params:
            if p.name == "solver" and p.value not in SOLVERS:
                return SetParametersResult(successful=False, reason=(
                    f"unknown solver {p.value!r}; choose one of {', '.join(SOLVERS)}"))
            if p.name == "tolerance" and not (isinstance(p.value, float)
                                              and math.isfinite(p.value)
                                              and 0.0 < p.value <= MAX_TOLERANCE):
                return SetParametersResult(successful=False, reason=(
                    f"tolerance must be a relative residual in (0, {MAX_TOLERANCE:g}], got "
                    f"{p.value!r}"))
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, params: list[Parameter]) -> None:
        """Apply a new rate_hz, solver or tolerance (after `_validate_parameters`)."""
        names = {p.name for p in params}
        if "rate_hz" in names and self.timer is not None:
            self.timer.timer_period_ns = round(1e9 / float(self._param("rate_hz")))
            self.timer.reset()
            self.get_logger().info(f"rate_hz is now {self._param('rate_hz'):g}")
        if names & {"solver", "tolerance"}:
            if self.body:
                self.options.solver = self._param("solver")
                self.options.tolerance = float(self._param("tolerance"))
            sim = (None if self.gs is None else self.gs.sim) if self.body else self.sim
            if sim is not None:
                sim.solver = self._make_solver()
            self.get_logger().info(f"solver is now {self._param('solver')} (tol "
                                   f"{self._param('tolerance'):g})")

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        """~/reset: re-dress on the next valid pose (body scenes) or restart the sheet."""
        self.resets += 1
        if self.body:
            self.redress = True
            self.prev_rx = None
            self.latest = None
            response.message = "the garment is re-dressed on the next valid body pose"
        else:
            self.sim = Simulator(self.scene.model, self.initial_state.copy(), self.sim.solver,
                                 dt=self.sim.dt, scheme=self.sim.scheme)
            response.message = "the sheet restarted from its initial state"
        response.success = True
        self.get_logger().info(f"reset: {response.message}")
        return response

    # -- sheet scenes --------------------------------------------------------------------
    def _tick_sheet(self) -> None:
        """One simulation step, then the markers and the diagnostics."""
        if self.finished.done():
            return
        stats = self.sim.step()
        self.steps += 1
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        finite = bool(np.isfinite(self.sim.state.x).all())
        marker_ms = self._publish_cloth(self.sim.state.x, sec, nanosec,
                                        spheres=self.scene.spheres) if finite else 0.0
        values = {"particles": str(self.scene.model.n)}
        self.stats_pub.publish(self._diagnostics(stats, finite, sec, nanosec, marker_ms,
                                                 values))
        self._after_tick(finite)

    def _after_tick(self, finite: bool) -> None:
        if not finite:
            self.get_logger().error(
                f"cloth positions became non-finite at step {self.steps}; try a smaller dt "
                f"or tolerance")
            self._finish(1)
        elif self.max_steps and self.steps >= self.max_steps:
            self.get_logger().info(f"max_steps {self.max_steps} reached")
            self._finish(0)

    # -- body scenes ---------------------------------------------------------------------
    def _on_pose(self, data: bytes) -> None:
        """A PoseArray arrived (raw bytes): decode, then tick (message mode) or keep it."""
        if self.finished.done():
            return
        self.frames.received += 1
        try:
            sec, nanosec, _, poses = pose_array_from_cdr(data)
        except ValueError:
            self.frames.note("malformed", math.nan)
            return
        stamp = sec + 1e-9 * nanosec
        if self.tick_mode == "timer":
            from cloth_mg_ros.ros.bags import FrameStatus, check_frame

            status = check_frame(self.prev_rx, stamp, poses, self.avatar.num_segments)
            if status != FrameStatus.OK:
                self.frames.note(status.value, stamp)
                return
            self.prev_rx = stamp
            self.latest = (sec, nanosec, poses)
            self.frames.used += 1
            return
        self._use_pose(sec, nanosec, stamp, poses)

    def _tick_body_timer(self) -> None:
        """Timer mode: step 1/rate_hz s of simulated time towards the latest pose."""
        if self.finished.done() or self.latest is None:
            return
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        if self.gs is not None and not self.redress:
            self.sim_stamp += 1.0 / float(self._param("rate_hz"))
        self._use_pose(sec, nanosec, self.sim_stamp, self.latest[2], count=False)

    def _use_pose(self, sec: int, nanosec: int, stamp: float, poses: np.ndarray,
                  count: bool = True) -> None:
        """Dress on, or advance the garment to, the body pose `poses` (S, 7) at `stamp` (s);
        publish when the pose was used. `count`: a received message (not a timer tick)."""
        from cloth_mg_ros.body_sim import GarmentSim, TickStats
        from cloth_mg_ros.ros.bags import FrameStatus, check_frame

        if self.gs is None or self.redress:
            status = check_frame(None, stamp, poses, self.avatar.num_segments)
            if status != FrameStatus.OK:
                self.frames.note(status.value, stamp)
                return
            t0 = time.perf_counter()
            try:
                gs = GarmentSim.dress(self.avatar, stamp, poses, self.material, self.options)
            except ClothInputError as exc:
                if not self.frames.counts["dress_failed"]:
                    self.get_logger().error(f"cannot dress the garment: {exc}")
                self.frames.note("dress_failed", stamp)
                return
            self.gs, self.redress = gs, False
            self.sim_stamp = stamp
            dress_ms = 1e3 * (time.perf_counter() - t0)
            self.frames.used += count
            self.get_logger().info(
                f"dressed a {self.options.garment} of {gs.sim.model.n} particles "
                f"({len(gs.garment.hierarchy.levels)} levels) on the body pose at stamp "
                f"{stamp:.3f} s in {dress_ms:.0f} ms")
            self._publish_body(sec, nanosec, None, dress_ms, "dressed")
            return
        failures = self.gs.failures
        result = self.gs.push(stamp, poses)
        if isinstance(result, FrameStatus):
            self.frames.note(result.value, stamp)
            if result != FrameStatus.TELEPORT:
                return
            self.frames.used += count
            self._publish_body(sec, nanosec, None, 0.0, "re-anchored after a teleport")
            return
        assert isinstance(result, TickStats)
        self.steps += 1
        self.frames.used += count
        failed = self.gs.failures - failures
        self._publish_body(sec, nanosec, result, result.total_ms,
                           f"{failed} simulation step(s) failed" if failed else "")

    def _publish_body(self, sec: int, nanosec: int, tick, step_ms: float, event: str) -> None:
        """Markers and diagnostics of the garment now; tick: the TickStats or None."""
        x = self.gs.positions
        finite = bool(np.isfinite(x).all())
        marker_ms = 0.0
        if finite:
            marker_ms = self._publish_cloth(x, sec, nanosec, capsules=self.gs.capsules())
        values = {
            "stamp_s": f"{sec + 1e-9 * nanosec:.6f}",
            "particles": str(self.gs.sim.model.n),
            "substeps": str(tick.substeps if tick else 0),
            "kinetic_energy_j": f"{tick.kinetic_energy:.4e}" if tick else "0",
            "frames_received": str(self.frames.received),
            "frames_used": str(self.frames.used),
            "frames_skipped": str(self.frames.skipped),
            "resets": str(self.resets),
        }
        since = self.frames.since_status
        notes = [event] if event else []
        skipped_now = {k: n for k, n in since.items() if k != "teleport" and n}
        if skipped_now:
            notes.append("skipped since the last status: " + ", ".join(
                f"{k} {n}" for k, n in sorted(skipped_now.items())))
        for kind, n in self.frames.counts.items():
            values[f"skipped_{kind}"] = str(n)
        stats = _Stats.from_tick(tick, step_ms)
        failed = "failed" in event
        level_hint = DiagnosticStatus.ERROR if failed else (
            DiagnosticStatus.WARN if skipped_now or "re-anchored" in event else
            DiagnosticStatus.OK)
        self.stats_pub.publish(self._diagnostics(stats, finite, sec, nanosec, marker_ms, values,
                                                 level_hint, "; ".join(notes)))
        since.clear()
        if tick is not None:
            self._after_tick(finite)

    # -- publishing ----------------------------------------------------------------------
    def _publish_cloth(self, x: np.ndarray, sec: int, nanosec: int, capsules=None,
                       spheres=()) -> float:
        """Publish the cloth marker and the marker array of positions x (n, 3), m, stamped
        (sec, nanosec); capsules and spheres as in marker_array_bytes. Returns ms."""
        t0 = time.perf_counter()
        model = self.gs.sim.model if self.body else self.scene.model
        faces = model.mesh.faces
        colours = strain_colours(x, model.mesh.edges, model.edge_rest) if (
            self.strain_colours and model.edge_rest is not None) else None
        self.marker_pub.publish(marker_triangle_list_bytes(
            x, faces, sec, nanosec, self.frame_id, "cloth", 0, CLOTH_RGBA, colours))
        self.markers_pub.publish(marker_array_bytes(
            x, faces, sec, nanosec, self.frame_id, capsules, spheres,
            per_vertex_colours=colours))
        return 1e3 * (time.perf_counter() - t0)

    def _finish(self, status: int) -> None:
        if self.timer is not None:
            self.timer.cancel()
        if not self.finished.done():
            self.finished.set_result(status)

    def _diagnostics(self, stats, finite: bool, sec: int, nanosec: int, marker_ms: float,
                     extra: dict[str, str], level: bytes = DiagnosticStatus.OK,
                     note: str = "") -> DiagnosticArray:
        """DiagnosticArray with one status: level, message and the tick's figures."""
        notes = [note] if note else []
        if not finite:
            level, notes = DiagnosticStatus.ERROR, ["cloth positions became non-finite"]
        elif not stats.converged:
            level = max(level, DiagnosticStatus.WARN)
            notes.append(f"solve stopped at relative residual {stats.rel_residual:.3g} after "
                         f"{stats.iterations} iterations")
        values = {
            "step": str(self.steps),
            "solve_ms": f"{stats.solve_ms:.3f}",
            "step_ms": f"{stats.total_ms:.3f}",
            "iterations": str(stats.iterations),
            "rel_residual": f"{stats.rel_residual:.3e}",
            "max_penetration_m": f"{stats.max_penetration:.3e}",
            "contacts": str(stats.contacts),
            "marker_ms": f"{marker_ms:.3f}",
            "solver": str(self._param("solver")),
            "tolerance": f"{self._param('tolerance'):.3e}",
            **extra,
        }
        status = DiagnosticStatus(level=level, name=STATUS_NAME, message="; ".join(notes) or "ok",
                                  hardware_id=NODE_NAME,
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        out = DiagnosticArray(status=[status])
        out.header.stamp.sec, out.header.stamp.nanosec = sec, nanosec
        out.header.frame_id = self.frame_id
        return out

    def log_summary(self) -> None:
        """Log the pose-frame summary (body scenes; called at shutdown)."""
        if self.body:
            self.get_logger().info(f"{self.frames.summary()}; {self.steps} ticks, "
                                   f"{self.resets} resets")


@dataclass
class _Stats:
    """The figures a status reports, from a TickStats or zero (dressing, re-anchoring)."""

    total_ms: float = 0.0
    solve_ms: float = 0.0
    iterations: int = 0
    rel_residual: float = 0.0
    converged: bool = True
    max_penetration: float = 0.0
    contacts: int = 0

    @classmethod
    def from_tick(cls, tick, step_ms: float) -> _Stats:
        if tick is None:
            return cls(total_ms=step_ms)
        return cls(tick.total_ms, tick.solve_ms, tick.iterations, tick.rel_residual,
                   tick.converged, tick.max_penetration, tick.contacts)


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


def _interrupt(signum: int, frame) -> None:
    """SIGTERM handler: stop like Ctrl-C."""
    raise KeyboardInterrupt


def spin_until_done(node: Node, future: Future, period_s: float = 0.1) -> None:
    """Spin `node` until `future` is done, waking every `period_s` s so that Ctrl-C (a
    KeyboardInterrupt, with rclpy's own signal handlers off) is seen promptly."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while not future.done() and node.context.ok():
            executor.spin_once(timeout_sec=period_s)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.0)


def main(args: list[str] | None = None) -> int:
    """Entry point of `cloth_node`: returns the exit status (0 normal or Ctrl-C, 1 failure).

    rclpy's signal handlers are off: Ctrl-C and SIGTERM raise KeyboardInterrupt here, so the
    context is still valid while the node logs its final summary and is destroyed.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    # A process started in the background of a non-interactive shell inherits SIGINT ignored.
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    node = None
    status = 0
    try:
        node = ClothNode()
        spin_until_done(node, node.finished)
        if node.finished.done():
            status = int(node.finished.result())
    except (ClothInputError, ParameterException) as exc:
        rclpy.logging.get_logger(NODE_NAME).error(f"cannot start: {exc}")
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl-C or an external shutdown is a normal way to stop
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        if node is not None:
            node.log_summary()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
