"""cloth_node's force outputs: each gripper's wrench (`gripper/<name>/wrench`), the cloth's
force on each body segment it collides with (`cloth/contact/<segment>`), both
geometry_msgs/WrenchStamped, and the contact forces as arrows for the marker array.

One WrenchStamped per topic is made at start and refilled every tick (a handful of fields:
no message is built per tick), published from the simulation thread in the tick's stamp and
the poses' frame. A gripper's wrench is the force the cloth exerts on it (N) and the torque
about its grasp point (N m); a segment's is the cloth's force on it and the torque about the
segment's origin (its pose's position), the mean over the tick's steps (sim.tick_stats.TickStats).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from geometry_msgs.msg import WrenchStamped

__all__ = ["ARROW_MAX_M", "ARROW_MIN_N", "ARROW_M_PER_N", "WrenchOutputs", "contact_arrows"]

ARROW_M_PER_N = 0.02  # m of arrow per N of contact force
ARROW_MAX_M = 0.5  # m: the longest arrow (a larger force is drawn this long)
ARROW_MIN_N = 0.01  # N: a smaller force draws no arrow
_ZERO = (0.0, 0.0, 0.0)


class WrenchOutputs:
    """The wrench publishers: grippers {name: publisher} and contacts {segment: publisher}
    (rclpy publishers of geometry_msgs/WrenchStamped)."""

    def __init__(self, grippers: Mapping[str, object], contacts: Mapping[str, object]) -> None:
        self.grippers = dict(grippers)
        self.contacts = dict(contacts)
        self._msgs = {key: WrenchStamped() for key in
                      [("gripper", n) for n in self.grippers]
                      + [("contact", s) for s in self.contacts]}

    def publish(self, wrenches: Mapping[str, Mapping[str, Sequence[float]]], sec: int,
                nanosec: int, frame_id: str,
                forces: Mapping[str, Sequence[float]] | None = None,
                torques: Mapping[str, Sequence[float]] | None = None) -> None:
        """A tick's wrenches: every gripper's (wrenches as in publish_grippers) and every
        colliding segment's (forces, torques as in publish_contacts; none given: zero),
        stamped (sec, nanosec) in frame_id."""
        self.publish_grippers(wrenches, sec, nanosec, frame_id)
        if self.contacts:
            self.publish_contacts(forces or {}, torques or {}, sec, nanosec, frame_id)

    def publish_grippers(self, wrenches: Mapping[str, Mapping[str, Sequence[float]]], sec: int,
                         nanosec: int, frame_id: str) -> None:
        """Every gripper's wrench: wrenches {name: {"force": (3,) N, "torque": (3,) N m}}
        (GripperSet.wrenches; a gripper missing from it, or holding nothing, publishes
        zero), stamped (sec, nanosec) in frame_id."""
        for name, pub in self.grippers.items():
            w = wrenches.get(name)
            force, torque = (w["force"], w["torque"]) if w else (_ZERO, _ZERO)
            pub.publish(self._fill(("gripper", name), force, torque, sec, nanosec, frame_id))

    def publish_contacts(self, forces: Mapping[str, Sequence[float]],
                         torques: Mapping[str, Sequence[float]], sec: int, nanosec: int,
                         frame_id: str) -> None:
        """Each colliding segment's wrench: forces {segment: (3,) N}, torques {segment: (3,)
        N m} (TickStats.body_forces, body_torques; a segment missing publishes zero)."""
        for segment, pub in self.contacts.items():
            msg = self._fill(("contact", segment), forces.get(segment, _ZERO),
                             torques.get(segment, _ZERO), sec, nanosec, frame_id)
            pub.publish(msg)

    def _fill(self, key: tuple[str, str], force: Sequence[float], torque: Sequence[float],
              sec: int, nanosec: int, frame_id: str) -> WrenchStamped:
        msg = self._msgs[key]
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(sec), int(nanosec)
        msg.header.frame_id = frame_id
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
