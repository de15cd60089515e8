"""cloth_node's force outputs: each gripper's wrench (`gripper/<name>/wrench`), the cloth's
force on each body segment it collides with (`cloth/contact/<segment>`), both
geometry_msgs/WrenchStamped, and the contact forces as arrows for the marker array.

One WrenchStamped per topic is made at start and refilled every tick (a handful of fields:
no message is built per tick), published from the simulation thread in the tick's stamp. A
gripper's wrench is the force the cloth exerts on it (N) and the torque (N m) it exerts about
its grasp point; a segment's is the cloth's force on it and the torque about the segment's
origin (its pose's position), the mean over the tick's steps (sim.tick_stats.TickStats),
taken about the segment's pose at the tick's end.

Each message names the frame whose origin its torque is taken about and whose axes it is
expressed in (`wrench_frame`, WRENCH_FRAMES), so that tf2 re-expresses it right (rotation, and
the torque shifted by the translation cross the force):

- `world` (the default): the poses' frame (header.frame_id as the cloth's): force and torque in
  its axes, the torque about its origin (torque about the grasp point + p x F, p the grasp
  point; a segment's likewise with its origin);
- `local`: each gripper's own frame (named by `gripper_frame`, default 'gripper/{name}':
  its grasp point and orientation, as last commanded) and each segment's (`segment_frame`,
  default '{name}': the segment's pose), force and torque in its axes, the torque about its
  origin.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from geometry_msgs.msg import WrenchStamped

from cloth_mg_ros.config.schema import WRENCH_FRAMES
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.rotations import quat_to_matrix

__all__ = ["ARROW_MAX_M", "ARROW_MIN_N", "ARROW_M_PER_N", "WRENCH_FRAMES", "WrenchOutputs",
           "contact_arrows", "express"]

ARROW_M_PER_N = 0.02  # m of arrow per N of contact force
ARROW_MAX_M = 0.5  # m: the longest arrow (a larger force is drawn this long)
ARROW_MIN_N = 0.01  # N: a smaller force draws no arrow
_ZERO = (0.0, 0.0, 0.0)
_ORIGIN = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))


def express(mode: str, force, torque, position, orientation) -> tuple[np.ndarray, np.ndarray]:
    """(force (3,) N, torque (3,) N m) of a wrench given in world axes with its torque about
    `position` (3,) m, the origin of a frame of `orientation` (4,) xyzw: in mode 'world', in
    world axes about the world's origin (torque + position x force); in mode 'local', in that
    frame's axes about its origin (both rotated by R^T)."""
    f = np.asarray(force, dtype=np.float64)
    t = np.asarray(torque, dtype=np.float64)
    if mode == "world":
        return f, t + np.cross(np.asarray(position, dtype=np.float64), f)
    rot = quat_to_matrix(np.asarray(orientation, dtype=np.float64)[None])[0]
    return f @ rot, t @ rot


class WrenchOutputs:
    """The wrench publishers: grippers {name: publisher} and contacts {segment: publisher}
    (rclpy publishers of geometry_msgs/WrenchStamped); mode: 'world' or 'local' (module
    docstring); gripper_frame, segment_frame: the local frames' names, '{name}' replaced by
    the gripper's or the segment's name."""

    def __init__(self, grippers: Mapping[str, object], contacts: Mapping[str, object],
                 mode: str = "world", gripper_frame: str = "gripper/{name}",
                 segment_frame: str = "{name}") -> None:
        if mode not in WRENCH_FRAMES:
            raise ValueError(f"wrench frame {mode!r}: one of {', '.join(WRENCH_FRAMES)}")
        self.grippers = dict(grippers)
        self.contacts = dict(contacts)
        self.mode = mode
        for key, pattern, count in (("gripper_frame", gripper_frame, len(self.grippers)),
                                    ("segment_frame", segment_frame, len(self.contacts))):
            if mode == "local" and count > 1 and "{name}" not in pattern:
                raise ClothInputError(f"parameter {key}: {pattern!r} names one frame for "
                                      f"{count} wrenches; put {{name}} in it")
        self.frame_names = {("gripper", n): gripper_frame.replace("{name}", n)
                            for n in self.grippers}
        self.frame_names.update({("contact", s): segment_frame.replace("{name}", s)
                                 for s in self.contacts})
        self._msgs = {key: WrenchStamped() for key in
                      [("gripper", n) for n in self.grippers]
                      + [("contact", s) for s in self.contacts]}

    def publish(self, wrenches: Mapping[str, Mapping[str, Sequence[float]]], sec: int,
                nanosec: int, frame_id: str,
                forces: Mapping[str, Sequence[float]] | None = None,
                torques: Mapping[str, Sequence[float]] | None = None,
                gripper_poses: Mapping[str, tuple] | None = None,
                segment_poses: Mapping[str, tuple] | None = None) -> None:
        """A tick's wrenches: every gripper's (wrenches, gripper_poses as in
        publish_grippers) and every colliding segment's (forces, torques, segment_poses as in
        publish_contacts; none given: zero), stamped (sec, nanosec); frame_id: the poses'."""
        self.publish_grippers(wrenches, sec, nanosec, frame_id, gripper_poses)
        if self.contacts:
            self.publish_contacts(forces or {}, torques or {}, sec, nanosec, frame_id,
                                  segment_poses)

    def publish_grippers(self, wrenches: Mapping[str, Mapping[str, Sequence[float]]], sec: int,
                         nanosec: int, frame_id: str,
                         poses: Mapping[str, tuple] | None = None) -> None:
        """Every gripper's wrench: wrenches {name: {"force": (3,) N, "torque": (3,) N m}}
        (GripperSet.wrenches, world axes, torque about the grasp point; a gripper missing
        from it, or holding nothing, publishes zero), poses {name: (grasp point (3,) m,
        orientation (4,) xyzw)} (GripperSet.frames; missing: origin, identity), stamped
        (sec, nanosec), in the mode's frame (frame_id: the poses' frame)."""
        for name, pub in self.grippers.items():
            w = wrenches.get(name)
            force, torque = (w["force"], w["torque"]) if w else (_ZERO, _ZERO)
            pose = (poses or {}).get(name, _ORIGIN)
            pub.publish(self._fill(("gripper", name), force, torque, pose, sec, nanosec,
                                   frame_id))

    def publish_contacts(self, forces: Mapping[str, Sequence[float]],
                         torques: Mapping[str, Sequence[float]], sec: int, nanosec: int,
                         frame_id: str, poses: Mapping[str, tuple] | None = None) -> None:
        """Each colliding segment's wrench: forces {segment: (3,) N}, torques {segment: (3,)
        N m} about its origin (TickStats.body_forces, body_torques; a segment missing
        publishes zero), poses {segment: (origin (3,) m, orientation (4,) xyzw)} at the
        tick's end (missing: origin, identity), in the mode's frame."""
        for segment, pub in self.contacts.items():
            msg = self._fill(("contact", segment), forces.get(segment, _ZERO),
                             torques.get(segment, _ZERO), (poses or {}).get(segment, _ORIGIN),
                             sec, nanosec, frame_id)
            pub.publish(msg)

    def _fill(self, key: tuple[str, str], force: Sequence[float], torque: Sequence[float],
              pose: tuple, sec: int, nanosec: int, frame_id: str) -> WrenchStamped:
        msg = self._msgs[key]
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(sec), int(nanosec)
        msg.header.frame_id = frame_id if self.mode == "world" else self.frame_names[key]
        force, torque = express(self.mode, force, torque, *pose)
        f, t = msg.wrench.force, msg.wrench.torque
        f.x, f.y, f.z = (float(c) for c in force)
        t.x, t.y, t.z = (float(c) for c in torque)
        return msg


def contact_arrows(forces: Mapping[str, Sequence[float]], names: Sequence[str],
                   capsules: tuple[np.ndarray, np.ndarray, np.ndarray]
                   ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{segment index: (start (3,), end (3,)) m}: an arrow per segment whose force (forces
    {segment: (3,) N}) is at least ARROW_MIN_N, from the middle of its capsule (capsules: p0,
    p1 (S, 3) m, radius (S,) of every segment, in `names` order) along the force,
    ARROW_M_PER_N m per N, at most ARROW_MAX_M long."""
    p0, p1, _ = capsules
    out = {}
    for segment, force in forces.items():
        f = np.asarray(force, dtype=np.float64)
        size = float(np.linalg.norm(f))
        if not size >= ARROW_MIN_N:
            continue
        k = names.index(segment)
        start = 0.5 * (p0[k] + p1[k])
        out[k] = (start, start + f / size * min(ARROW_M_PER_N * size, ARROW_MAX_M))
    return out
