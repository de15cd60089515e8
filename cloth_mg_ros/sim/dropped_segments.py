"""Body segments left out of the collider: a tracker lost their joints, so their poses are
only held (ros.body_input, KeyPose.dropped). Each key pose carries its own mask; a step takes
the mask of the key pose that ends the key interval it lies in (sim.body_poses.key_interval),
so a segment is out while the body moves toward a pose that lost it and back from the first
step toward a pose that has it. Masks are (S,) bool over the avatar's segments, or None: every
segment collides.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.sim.body_poses import key_interval


def as_mask(dropped: np.ndarray | None) -> np.ndarray | None:
    """A copy of the (S,) bool mask ``dropped``, or None where it drops nothing."""
    if dropped is None or not np.any(dropped):
        return None
    return np.asarray(dropped, dtype=bool).copy()


def key_masks(dropped: Sequence[np.ndarray | None], keys: int) -> list[np.ndarray | None]:
    """The masks of ``keys`` key poses, one per key in order (as_mask each)."""
    if len(dropped) != keys:
        raise ValueError(f"one dropped mask per key pose: {keys} keys, {len(dropped)} masks")
    return [as_mask(m) for m in dropped]


def step_mask(masks: Sequence[np.ndarray | None], stamps: np.ndarray,
              u: float) -> np.ndarray | None:
    """The mask of a step ending a fraction ``u`` in (0, 1] of the time along the key poses
    at ``stamps`` (s; stamps[0]: where the body is now, stamps[i] key i's, masks[i - 1]
    its mask): the mask of the key that ends the step's key interval."""
    return masks[key_interval(stamps, u) - 1]


def collider_ends(avatar: Avatar, segments: np.ndarray, poses: np.ndarray,
                  dropped: np.ndarray | None) -> tuple:
    """The body collider's arguments (collision.capsules.CapsuleCollider.moved) for the body
    at ``poses`` (S, 7): the colliding ``segments``' capsule end points (k, 3) m each, and
    their active mask (k,) bool when ``dropped`` (S,) leaves some out."""
    p0, p1, _ = avatar.capsules(poses)
    ends = (p0[segments], p1[segments])
    return ends if dropped is None else (*ends, ~dropped[segments])
