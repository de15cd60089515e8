"""A body tracker's view of a motion: its joints in a camera's frame, with jitter and occlusion.

What a real tracker hands the node differs from the avatar's clean joints in three ways, and
`tracker_joints` reproduces each from a clip's joints (F, J, 3) in the z-up world:

- **The camera's frame.** Positions relative to the camera, x right, y down, z forward (the
  Azure Kinect's depth camera, MediaPipe's world landmarks). `TrackerView.camera` is the
  camera's pose in the world; by default (`front_camera`) it stands CAMERA_DISTANCE_M in front
  of the subject's first pose, CAMERA_HEIGHT_M up, looking at the pelvis level with the floor.
  The node undoes it with `input_transform` = the camera's pose (`transform_text`).
- **Jitter.** Independent Gaussian noise per joint and axis, `jitter_m` standard deviation
  (Azure Kinect body tracking: millimetres at rest).
- **Occlusion.** Limb joints (elbows, wrists, hands, knees, ankles, feet, the head's points;
  by the words of OCCLUDABLE in the layout's joint names) drop out (NaN) in spans of
  OCCLUSION_SPAN_S, `occlusion` being the share of those joints' samples missing; the pelvis
  and spine stay tracked (a tracker that loses them has lost the body). Spans longer than the
  node's joint_hold make it drop segments from the collider.

Seeded: the same view of the same clip gives the same joints. Units SI: m, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.rotations import matrix_to_quat, quat_to_matrix
from cloth_mg_ros.motion.skeletons import Skeleton, get_skeleton

__all__ = ["CAMERA_DISTANCE_M", "CAMERA_HEIGHT_M", "TrackerView", "front_camera",
           "occludable_joints", "tracker_joints", "transform_text"]

CAMERA_DISTANCE_M = 3.0  # the default camera's distance in front of the subject's first pose
CAMERA_HEIGHT_M = 1.0  # ... and its height over the floor, m
OCCLUSION_SPAN_S = (0.1, 0.8)  # s: the shortest and longest span a joint stays hidden
# Joints that a tracker loses behind the body or out of view: a limb's or the head's, matched
# as parts of the layout's own joint names (so also kinect32's hand tips and head and
# mediapipe33's inner and outer eyes; cmu31's forearms match "ear"), and cmu31's knees by
# their whole names (a part, "leg", would take its thighs, LeftUpLeg, too). The bench
# trackers' figures are of this set.
OCCLUDABLE = ("elbow", "wrist", "hand", "thumb", "finger", "index", "pinky", "knee", "ankle",
              "foot", "heel", "toe", "head", "nose", "eye", "ear", "mouth", "skull")
OCCLUDABLE_NAMES = ("leftleg", "rightleg")


@dataclass(frozen=True)
class TrackerView:
    """How a tracker sees the motion: camera (7,) [x, y, z, qx, qy, qz, qw], the camera's
    pose in the world (None: `front_camera`); jitter_m: noise's standard deviation, m;
    occlusion: share of the limb joints' samples hidden (0..0.9); seed: the noise's seed."""

    camera: tuple[float, ...] | None = None
    jitter_m: float = 0.002
    occlusion: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.jitter_m) and 0.0 <= self.jitter_m <= 0.1):
            raise ClothInputError(f"jitter must be 0..100 mm, got {1e3 * self.jitter_m:g} mm")
        if not (math.isfinite(self.occlusion) and 0.0 <= self.occlusion <= 0.9):
            raise ClothInputError(f"occlusion must be a share in 0..0.9, got {self.occlusion}")
        if self.camera is not None:
            c = np.asarray(self.camera, dtype=float)
            if c.shape != (7,) or not np.all(np.isfinite(c)) or abs(
                    np.linalg.norm(c[3:]) - 1.0) > 1e-3:
                raise ClothInputError(f"camera must be [x, y, z, qx, qy, qz, qw] with a unit "
                                      f"quaternion, got {self.camera!r}")


def front_camera(joints: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """(7,) the default camera: CAMERA_DISTANCE_M in front of the first frame's body (its
    centroid; its facing from the hip line, else the shoulders'), CAMERA_HEIGHT_M up, looking
    back level at it."""
    first = joints[0]
    marks = skeleton.landmark_joints()
    pair = next((p for p in (("hip_l", "hip_r"), ("shoulder_l", "shoulder_r"))
                 if p[0] in marks and p[1] in marks), None)
    if pair is None:
        raise ClothInputError(f"skeleton {skeleton.name!r}: no hips or shoulders to face")
    left, right = (first[list(marks[m])].mean(axis=0) for m in pair)
    forward = np.cross(left - right, [0.0, 0.0, 1.0])  # left x up: the way the body faces
    forward[2] = 0.0
    forward /= np.linalg.norm(forward)
    eye = np.nanmean(first, axis=0) + CAMERA_DISTANCE_M * forward
    eye[2] = CAMERA_HEIGHT_M
    z = -forward  # the camera looks back at the subject, level
    y = np.array([0.0, 0.0, -1.0])  # image down is world down
    x = np.cross(y, z)
    return np.concatenate([eye, matrix_to_quat(np.column_stack([x, y, z]))])


def occludable_joints(skeleton: Skeleton) -> np.ndarray:
    """(J,) bool: the layout's joints a tracker may lose (OCCLUDABLE, OCCLUDABLE_NAMES)."""
    return np.array([name.lower() in OCCLUDABLE_NAMES
                     or any(word in name.lower() for word in OCCLUDABLE)
                     for name in skeleton.joints])


def tracker_joints(joints: np.ndarray, stamps: np.ndarray, skeleton: str | Skeleton,
                   view: TrackerView) -> tuple[np.ndarray, np.ndarray]:
    """The tracker's joints (F, J, 3) in the camera's frame, jittered, NaN where hidden, and
    the camera's pose (7,) in the world. joints: (F, J, 3) m in the world; stamps (F,) s."""
    sk = get_skeleton(skeleton)
    joints = np.asarray(joints, dtype=float)
    stamps = np.asarray(stamps, dtype=float)
    if joints.ndim != 3 or joints.shape[1:] != (sk.num_joints, 3) or len(stamps) != len(joints):
        raise ClothInputError(f"tracker view: joints (F, {sk.num_joints}, 3) and F stamps, got "
                              f"{joints.shape} and {stamps.shape}")
    camera = (front_camera(joints, sk) if view.camera is None
              else np.asarray(view.camera, dtype=float))
    rot = quat_to_matrix(camera[3:] / np.linalg.norm(camera[3:]))
    out = (joints - camera[:3]) @ rot  # p_cam = R^T (p - t)
    rng = np.random.default_rng(view.seed)
    out += rng.normal(0.0, view.jitter_m, out.shape)
    hidden = _hidden(stamps, occludable_joints(sk), view.occlusion, rng)
    out[hidden] = np.nan
    return out, camera


def _hidden(stamps: np.ndarray, which: np.ndarray, share: float,
            rng: np.random.Generator) -> np.ndarray:
    """(F, J) bool: spans of OCCLUSION_SPAN_S of the joints `which`, about `share` of their
    samples, placed at random."""
    hidden = np.zeros((len(stamps), len(which)), dtype=bool)
    duration = float(stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0
    if share <= 0.0 or duration <= 0.0:
        return hidden
    lo, hi = OCCLUSION_SPAN_S
    spans = share * duration / (0.5 * (lo + hi))  # expected spans per joint
    for j in np.flatnonzero(which):  # a few dozen joints
        for _ in range(rng.poisson(spans)):
            start = stamps[0] + rng.uniform(0.0, duration)
            span = rng.uniform(lo, hi)
            hidden[(stamps >= start) & (stamps < start + span), j] = True
    return hidden


def transform_text(camera: np.ndarray) -> str:
    """The node's input_transform for this camera, as a `-p` value: '[x, y, z, qx, qy, qz,
    qw]'."""
    # repr of a float: '0.0', not '0' (a ROS double array takes no integers)
    return "[" + ", ".join(repr(float(f"{float(v):.9g}")) for v in camera) + "]"
