"""Where a garment meets the body's poses: the seams that sew it to the segments (pins and
a top's sleeve hems), the neutral pose it is dressed on, and the body's pose between key
poses (positions lerped, rotations slerped). Poses are (S, 7) rows of position (m) and
quaternion xyzw, one per avatar segment.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cloth_mg_ros.mesh.garments import boundary_loops
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.rotations import quat_to_matrix, slerp, transform_poses

DRESSING_ARM_ABDUCTION = 35.0  # deg: room between arms and torso for sleeves and skirts


def sleeve_pins(avatar: Avatar, poses: np.ndarray, garment) -> dict[str, np.ndarray]:
    """A top's sleeve hems sewn to the upper arms: {segment: coarse hem vertices}.

    The armpit is where the upper-arm and chest capsules overlap; a sleeve that had to slide
    through that crease would be pinched between two solids. Sewing the hem to the arm lets
    the sleeve follow the arm instead (the top then collides with the trunk and the head).
    """
    coarse = garment.hierarchy.levels[-1]
    loops = boundary_loops(coarse.faces)
    p0, p1, _ = avatar.capsules(poses)
    out = {}
    for side in ("upper_arm_l", "upper_arm_r"):
        k = avatar.names.index(side)
        mid = 0.5 * (p0[k] + p1[k])
        dist = [np.linalg.norm(coarse.rest[lp].mean(axis=0) - mid) for lp in loops]
        out[side] = np.asarray(loops[int(np.argmin(dist))], dtype=np.int64)
    return out


def attach_pins(avatar: Avatar, poses: np.ndarray, garment,
                extra: dict[str, np.ndarray] | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sew the garment's pinned vertices (and ``extra`` ones, {segment: vertices}) to their
    body segments in ``poses`` (S, 7).

    Returns (vertex indices (k,), segment index of each (k,), offsets (k, 3) in the segment's
    pose frame, m). The pose frames are full rigid frames, so the pins follow every rotation
    of the segment (a capsule alone leaves the spin about its axis undefined).
    """
    groups = list(garment.pins.items()) + list((extra or {}).items())
    if not groups:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    index = {name: i for i, name in enumerate(avatar.names)}
    verts = np.concatenate([np.asarray(v, dtype=np.int64) for _, v in groups])
    segs = np.concatenate([np.full(len(v), index[s], np.int64) for s, v in groups])
    rot = quat_to_matrix(poses[segs, 3:7])
    offsets = np.einsum("kba,kb->ka", rot, garment.rest_positions[verts] - poses[segs, :3])
    return verts, segs, offsets


def pin_positions(poses: np.ndarray, segments: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """World positions (k, 3) of pins sewn at ``offsets`` to ``segments`` of body ``poses``."""
    rot = quat_to_matrix(poses[segments, 3:7])
    return poses[segments, :3] + np.einsum("kab,kb->ka", rot, offsets)


def standing_at(avatar: Avatar, poses: np.ndarray) -> np.ndarray:
    """The avatar's neutral standing pose (S, 7) with its pelvis where and heading as in
    ``poses`` (S, 7)."""
    rest = avatar.rest_poses(DRESSING_ARM_ABDUCTION)
    heading = avatar.body_rotations(poses)[0][:, 0]
    yaw = float(np.arctan2(heading[1], heading[0]))
    rest_heading = avatar.body_rotations(rest)[0][:, 0]
    yaw -= float(np.arctan2(rest_heading[1], rest_heading[0]))
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return transform_poses(rest, rot, poses[0, :3] - rot @ rest[0, :3])


def pose_on_path(stamps: np.ndarray, path: Sequence[np.ndarray], u: float) -> np.ndarray:
    """The body pose (S, 7) a fraction ``u`` in [0, 1] of the time from stamps[0] to
    stamps[-1] along the path through key poses ``path`` at increasing ``stamps`` (s): blended
    between the two keys around it (with two keys, exactly blend_poses(path[0], path[1], u))."""
    if u >= 1.0:
        return path[-1]
    tau = key_fractions(stamps)
    k = int(np.searchsorted(tau, u, side="right"))  # tau[k - 1] <= u < tau[k]
    k = min(max(k, 1), len(tau) - 1)
    w = u if len(tau) == 2 else (u - tau[k - 1]) / (tau[k] - tau[k - 1])
    return blend_poses(path[k - 1], path[k], float(w))


def key_fractions(stamps: np.ndarray) -> np.ndarray:
    """(K,) the fraction of the time from stamps[0] to stamps[-1] (s, increasing) at which
    each stamp lies: 0 first, exactly 1 last."""
    tau = (np.asarray(stamps, dtype=np.float64) - stamps[0]) / (stamps[-1] - stamps[0])
    tau[-1] = 1.0
    return tau


def key_interval(stamps: np.ndarray, u: float) -> int:
    """The key interval k in 1..K-1 (from stamps[k - 1] to stamps[k], s) a step ending a
    fraction ``u`` in (0, 1] of the time along the path through ``stamps`` lies in, by the
    fractions `pose_on_path` blends with: tau[k - 1] < u <= tau[k], so the step that ends on
    key k leads to it (pose_on_path's pose there is key k's, blended at 1 or at 0)."""
    k = int(np.searchsorted(key_fractions(stamps), u, side="left"))
    return min(max(k, 1), len(stamps) - 1)


def blend_poses(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    """Poses (S, 7) a fraction u of the way from a to b (positions lerped, rotations
    slerped)."""
    out = np.empty_like(a)
    out[:, :3] = (1.0 - u) * a[:, :3] + u * b[:, :3]
    out[:, 3:7] = slerp(a[:, 3:7], b[:, 3:7], np.full(len(a), u))
    return out


def body_dict(avatar: Avatar, poses: np.ndarray | None, p0: np.ndarray | None = None,
              p1: np.ndarray | None = None) -> dict:
    """{segment: (p0 (3,), p1 (3,), radius)} from poses (S, 7), or from end points given."""
    if poses is not None:
        p0, p1, radius = avatar.capsules(poses)
    else:
        radius = avatar.radius
    return {name: (p0[i], p1[i], float(radius[i])) for i, name in enumerate(avatar.names)}
