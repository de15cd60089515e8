"""The arm a robot dresses: three capsules with a person's radii, their motion, the path a
held sleeve opening follows along them, and how far the arm is in the sleeve.

The arm is the avatar's (config/avatar.yaml): its shoulder, elbow and wrist joints and its
hand's direction come from a pose of the avatar, its radii are a person's rather than the
avatar's (which are padded for a garment's clearance). Its centre line runs from the
fingertip through the wrist and the elbow to the shoulder joint; arc length along it, from
the fingertip, is the coordinate of every figure here (m).

Radii, 50th-percentile male (Assistive Gym's human model, Erickson et al. 2020): upper arm
r 0.043 m, forearm r 0.033 m. The hand is a capsule
of r 0.04 m reaching 0.19 m from the wrist: a loose fist about as wide as a hand (ANSUR II
50th-percentile male hand breadth about 9 cm, hand length about 19 cm). Segment lengths are
the avatar's: upper arm 0.30 m, forearm 0.26 m, so the whole arm is 0.75 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from cloth_mg_ros.collision.capsules import point_segment_distances, segment_closest
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.rotations import matrix_to_quat

SEGMENTS = ("hand", "forearm", "upper_arm")  # the arm's capsules, fingertip first
RADII = (0.040, 0.033, 0.043)  # m: hand (a loose fist), forearm, upper arm (module docstring)
HAND_LENGTH = 0.19  # m, wrist to fingertip (module docstring)
HELD_OUT_DEG = 90.0  # the still arm's abduction from hanging: straight out sideways
LOOP_PERIODS = (0.8, 1.6)  # s: the range searched for a clip's repeating stretch (a gait cycle)
TOPIC = "/avatar/body_poses"


@dataclass
class ArmPose:
    """One pose of the arm: joints shoulder, elbow, wrist (3,) m and the hand's unit
    direction hand_dir (3,) (from the wrist towards the fingertip)."""

    shoulder: np.ndarray
    elbow: np.ndarray
    wrist: np.ndarray
    hand_dir: np.ndarray

    @property
    def tip(self) -> np.ndarray:
        """(3,) m: the fingertip."""
        return self.wrist + HAND_LENGTH * self.hand_dir

    def centre_line(self) -> np.ndarray:
        """(4, 3) m: fingertip, wrist, elbow, shoulder."""
        return np.stack([self.tip, self.wrist, self.elbow, self.shoulder])

    def lengths(self) -> np.ndarray:
        """(3,) m: hand, forearm, upper arm along the centre line."""
        return np.linalg.norm(np.diff(self.centre_line(), axis=0), axis=1)

    def capsules(self, radii=RADII) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p0 (3, 3), p1 (3, 3), radius (3,)) m of hand, forearm and upper arm: the hand's
        axis ends one radius short of the fingertip, so that its cap reaches it."""
        radius = np.asarray(radii, dtype=np.float64)
        hand_end = self.wrist + (HAND_LENGTH - radius[0]) * self.hand_dir
        p0 = np.stack([self.wrist, self.elbow, self.shoulder])
        p1 = np.stack([hand_end, self.wrist, self.elbow])
        return p0, p1, radius


@dataclass
class ArmMotion:
    """The arm over time: times (F,) s increasing, shoulder, elbow, wrist (F, 3) m, hand_dir
    (F, 3) unit. Beyond the last time it starts again from the first (a clip's repeating
    stretch: `clip_arm` cuts it so that the ends meet); one frame: a still arm."""

    times: np.ndarray
    shoulder: np.ndarray
    elbow: np.ndarray
    wrist: np.ndarray
    hand_dir: np.ndarray
    source: str = ""

    @property
    def still(self) -> bool:
        return len(self.times) == 1

    def at(self, t: float) -> ArmPose:
        """The arm at time t s (linear between frames; the hand's direction renormalised)."""
        if self.still:
            return ArmPose(self.shoulder[0], self.elbow[0], self.wrist[0], self.hand_dir[0])
        span = self.times[-1] - self.times[0]
        u = self.times[0] + (t - self.times[0]) % span

        def lerp(a: np.ndarray) -> np.ndarray:
            return np.array([np.interp(u, self.times, a[:, k]) for k in range(3)])

        d = lerp(self.hand_dir)
        return ArmPose(lerp(self.shoulder), lerp(self.elbow), lerp(self.wrist),
                       d / np.linalg.norm(d))


def arm_joints(avatar: Avatar, poses: np.ndarray, side: str = "r"
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(shoulder, elbow, wrist, hand_dir), each (F, 3), of the arm on ``side`` ('l' or 'r')
    in avatar poses (F, S, 7): the segments' origins and the hand capsule's axis."""
    if side not in ("l", "r"):
        raise ClothInputError(f"arm side must be 'l' or 'r', got {side!r}")
    idx = [avatar.segment_index(f"{n}_{side}") for n in ("upper_arm", "lower_arm", "hand")]
    p0, p1, _ = avatar.capsules(poses)
    hand = p1[:, idx[2]] - p0[:, idx[2]]
    hand /= np.linalg.norm(hand, axis=1, keepdims=True)
    return poses[:, idx[0], :3], poses[:, idx[1], :3], poses[:, idx[2], :3], hand


def still_arm(avatar: Avatar | None = None, side: str = "r",
              abduction_deg: float = HELD_OUT_DEG) -> ArmMotion:
    """The arm held still, straight and out sideways: the avatar's neutral standing pose
    (Avatar.rest_poses) with its arms ``abduction_deg`` from hanging (90: horizontal)."""
    avatar = avatar or Avatar.load()
    joints = arm_joints(avatar, avatar.rest_poses(abduction_deg)[None], side)
    return ArmMotion(np.zeros(1), *joints, source=f"still, {abduction_deg:g} deg out")


def clip_arm(bag: str, avatar: Avatar | None = None, side: str = "r",
             settle_s: float = 1.0) -> ArmMotion:
    """The arm moving as in a bundled bag (`io.bags.resolve_bag`: walk, run, ...), its shoulder
    held where it starts (the body's travel removed: a person who stands and moves the arm as
    in the clip), cut to one repeating stretch: from the clip's start after ``settle_s`` (the
    bags hold their first pose still for 1 s) over the period in LOOP_PERIODS whose end pose
    comes nearest its start (a gait cycle for a walk), so that looping it has no jump."""
    avatar = avatar or Avatar.load()
    frames = read_pose_frames(resolve_bag(bag), TOPIC)
    times = np.array([st for st, _ in frames])
    poses = np.array([p for _, p in frames])
    keep = times >= times[0] + settle_s
    times, poses = times[keep] - times[keep][0], poses[keep]
    shoulder, elbow, wrist, hand = arm_joints(avatar, poses, side)
    shift = shoulder - shoulder[0]
    elbow, wrist, shoulder = elbow - shift, wrist - shift, shoulder - shift
    rel = np.concatenate([elbow - shoulder, wrist - shoulder, 0.2 * hand], axis=1)
    ends = np.flatnonzero((times >= LOOP_PERIODS[0]) & (times <= LOOP_PERIODS[1]))
    if not len(ends):
        raise ClothInputError(f"bag {bag}: its motion is shorter than {LOOP_PERIODS[0]} s "
                              "after the settling second; the arm needs a repeating stretch")
    mismatch = np.linalg.norm(rel[ends] - rel[0], axis=1) + 0.05 * np.linalg.norm(
        (rel[ends] - rel[ends - 1]) - (rel[1] - rel[0]), axis=1) / max(times[1], 1e-9)
    end = int(ends[np.argmin(mismatch)])
    cut = slice(0, end)  # the end frame repeats the start: looping returns to frame 0
    return ArmMotion(np.append(times[cut], times[end]),
                     *(np.concatenate([a[cut], a[:1]]) for a in (shoulder, elbow, wrist, hand)),
                     source=f"{bag}, {times[end]:.2f} s loop, shoulder held")


def arc_point(pose: ArmPose, s: float) -> np.ndarray:
    """(3,) m: the point at arc length s (m) from the fingertip along the centre line; s < 0
    lies beyond the fingertip on the line from the shoulder through it (where cuff_frame's
    axis points, so a sleeve laid out there is straight), s past the shoulder on the upper
    arm's line."""
    line = pose.centre_line()
    if s < 0.0:
        way_in = pose.shoulder - pose.tip
        return pose.tip + s * way_in / np.linalg.norm(way_in)
    lengths = pose.lengths()
    start = np.concatenate([[0.0], np.cumsum(lengths)])
    k = int(np.clip(np.searchsorted(start, s, side="right") - 1, 0, 2))
    return line[k] + (s - start[k]) * (line[k + 1] - line[k]) / lengths[k]


def cuff_frame(pose: ArmPose, s: float, reference: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the held opening at arc length s: columns x (``reference`` (3,) made
    perpendicular to z: where the top gripper sits), y = z cross x, z (the way in: towards the
    shoulder from the opening's centre while it is short of the elbow, the upper arm's
    direction from there on; turning smoothly from the hand's line onto the upper arm's)."""
    lengths = pose.lengths()
    c = arc_point(pose, s)
    if s < lengths[0] + lengths[1] - 1e-9:
        z = pose.shoulder - c
    else:
        z = pose.shoulder - pose.elbow
    z = z / np.linalg.norm(z)
    x = reference - np.dot(reference, z) * z
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def frame_quaternion(rot: np.ndarray) -> np.ndarray:
    """(4,) xyzw of a rotation (3, 3)."""
    return matrix_to_quat(rot[None])[0]


def dressed_length(pose: ArmPose, ring: np.ndarray) -> tuple[float, float, float]:
    """How far the arm is in the sleeve: (dressed m, s m, winding).

    ring (k, 3) m: the held opening's rim, in order around it. Its centre (the rim's mean)
    is projected on the arm's centre line: s, the arc length of the nearest point from the
    fingertip. The rim encircles the arm there when it winds around that point once: the
    winding number of the rim about the centre line, seen along the line's direction there
    (the sum of the turns between consecutive rim points, over 2 pi), is near +-1 (|w| > 0.5),
    and 0 when the arm is beside the rim or the rim is caught on it. The dressed length is s
    clipped to [0, arm length] where the rim encircles the arm, 0 otherwise.
    """
    line = pose.centre_line()
    centre = ring.mean(axis=0)
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", centre - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    near = a + t[:, None] * ab
    k = int(np.argmin(np.linalg.norm(centre - near, axis=1)))
    lengths = pose.lengths()
    s = float(np.sum(lengths[:k]) + t[k] * lengths[k])
    if k == 0 and t[0] == 0.0:  # short of the fingertip: how far short, on the hand's line
        s = float(np.dot(centre - line[0], ab[0]) / lengths[0])
    axis = ab[k] / lengths[k]
    rel = ring - near[k]
    rel -= np.outer(rel @ axis, axis)
    ref = rel[0] / max(np.linalg.norm(rel[0]), 1e-12)
    other = np.cross(axis, ref)
    angle = np.arctan2(rel @ other, rel @ ref)
    turns = np.diff(np.append(angle, angle[0]))
    winding = float(np.sum((turns + np.pi) % (2.0 * np.pi) - np.pi) / (2.0 * np.pi))
    dressed = float(np.clip(s, 0.0, lengths.sum())) if abs(winding) > 0.5 else 0.0
    return dressed, s, winding


def segments_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
                      ) -> np.ndarray:
    """(k,) m: the distance between segments a0-a1 and b0-b1, each (k, 3) (their closest
    points: collision.capsules.segment_closest, the contact's own)."""
    return _segments_distance(*(np.ascontiguousarray(v, dtype=np.float64)
                                for v in (a0, a1, b0, b1)))


@njit(cache=True, nogil=True)
def _segments_distance(a0, a1, b0, b1):
    out = np.empty(a0.shape[0])
    for i in range(a0.shape[0]):
        s, t = segment_closest(a0[i], a1[i], b0[i], b1[i])
        g = a0[i] + (a1[i] - a0[i]) * s - b0[i] - (b1[i] - b0[i]) * t
        out[i] = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    return out


def edge_depth(x: np.ndarray, edges: np.ndarray, pose: ArmPose, radii=RADII) -> float:
    """m: how deep the deepest cloth edge cuts into the arm (0 when none does). x (n, 3) m,
    edges (e, 2). A particle-only contact keeps every particle out of the capsules, but an
    edge whose ends lie on two sides of a limb passes through it: this is the test that the
    cloth has not gone through the arm. Only edges with an end within 5 cm of a capsule's
    surface are measured."""
    p0, p1, radius = pose.capsules(radii)
    near = (point_segment_distances(x, p0, p1) - radius).min(axis=1) < 0.05
    e = edges[near[edges[:, 0]] | near[edges[:, 1]]]
    if not len(e):
        return 0.0
    k = len(radius)
    a0, a1 = np.repeat(x[e[:, 0]], k, axis=0), np.repeat(x[e[:, 1]], k, axis=0)
    dist = segments_distance(a0, a1, np.tile(p0, (len(e), 1)), np.tile(p1, (len(e), 1)))
    return float(max(0.0, np.max(np.tile(radius, len(e)) - dist)))
