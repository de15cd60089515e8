"""motion.tracker_view: a tracker's joints are the clip's in the camera's frame (x right, y down,
z forward; undone exactly by the camera's pose), jittered by the requested standard deviation,
limb joints hidden (NaN) in spans for about the requested share of their samples, the pelvis,
spine and hips never; seeded."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.motion.joint_body import joints_from_poses, packaged_avatar, zero_pose
from cloth_mg_ros.motion.rotations import quat_to_matrix
from cloth_mg_ros.motion.skeletons import get_skeleton
from cloth_mg_ros.motion.tracker_view import (
    CAMERA_DISTANCE_M,
    CAMERA_HEIGHT_M,
    OCCLUSION_SPAN_S,
    TrackerView,
    front_camera,
    occludable_joints,
    tracker_joints,
)

RATE_HZ = 30.0
# an oblique camera: 0.3 rad about a tilted axis, off the origin (m)
AXIS = np.array([0.2, -0.5, 0.8]) / np.linalg.norm([0.2, -0.5, 0.8])
CAMERA = (1.5, -2.0, 1.2, *(np.sin(0.15) * AXIS), np.cos(0.15))


def _walk(seconds: float, skeleton: str = "kinect32") -> tuple[np.ndarray, np.ndarray]:
    """(F, J, 3) m: the avatar's rest pose walking along world x at 1 m/s, feet near the
    floor, swaying sideways; (F,) stamps, s, at RATE_HZ."""
    avatar = packaged_avatar()
    rest = joints_from_poses(avatar, zero_pose(avatar)[0], skeleton)
    stamps = np.arange(round(seconds * RATE_HZ)) / RATE_HZ
    shift = np.column_stack([stamps, 0.05 * np.sin(2.0 * stamps), np.full_like(stamps, 1.0)])
    return rest[None] + shift[:, None, :], stamps


def _to_world(cam_joints: np.ndarray, camera: np.ndarray) -> np.ndarray:
    """Camera-frame points back into the world: p = R p_cam + t (camera = [t, q])."""
    rot = quat_to_matrix(np.asarray(camera[3:]))
    return np.einsum("ab,...b->...a", rot, cam_joints) + camera[:3]


@pytest.mark.parametrize("camera", [None, CAMERA], ids=["front", "oblique"])
def test_the_camera_frame_round_trips_to_the_world(camera):
    joints, stamps = _walk(2.0)
    out, pose = tracker_joints(joints, stamps, "kinect32", TrackerView(camera, 0.0, 0.0, 0))
    assert not np.isnan(out).any()
    if camera is not None:
        assert np.array_equal(pose, CAMERA)  # the given pose is the one used and returned
    assert np.max(np.abs(_to_world(out, pose) - joints)) < 1e-12
    # a real change of frame, not the identity
    assert np.max(np.abs(out - joints)) > 0.5


def test_the_front_camera_looks_level_at_the_subject_z_forward_y_down():
    joints, stamps = _walk(2.0)
    sk = get_skeleton("kinect32")
    out, pose = tracker_joints(joints, stamps, sk, TrackerView(None, 0.0, 0.0, 0))
    assert np.array_equal(pose, front_camera(joints, sk))
    first = joints[0].mean(axis=0)
    # the first frame's centroid straight ahead (z) at CAMERA_DISTANCE_M, below the camera
    # by its height over the floor minus CAMERA_HEIGHT_M (y down)
    assert out[0].mean(axis=0) == pytest.approx(
        [0.0, CAMERA_HEIGHT_M - first[2], CAMERA_DISTANCE_M], abs=1e-12)
    j = {n: k for k, n in enumerate(sk.joints)}
    head, feet = out[:, j["head"]], out[:, [j["foot_left"], j["foot_right"]]]
    assert np.all(head[:, 1] < feet[:, :, 1].min(axis=1) - 1.0)  # the head is up: smaller y
    # the subject faces the camera: its left hand on the image's right (x), both ahead (z)
    left, right = out[:, j["hand_left"]], out[:, j["hand_right"]]
    assert np.all(left[:, 0] > right[:, 0] + 1.0) and np.all(out[..., 2] > 0.5)


def test_the_jitter_has_the_requested_deviation_per_joint_and_axis():
    joints, stamps = _walk(60.0)
    clean, _ = tracker_joints(joints, stamps, "kinect32", TrackerView(None, 0.0, 0.0, 3))
    noisy, _ = tracker_joints(joints, stamps, "kinect32", TrackerView(None, 0.004, 0.0, 3))
    noise = (noisy - clean).reshape(-1, 3)  # 57600 samples per axis
    assert np.all(np.abs(noise.std(axis=0) / 0.004 - 1.0) < 0.1)
    assert np.all(np.abs(noise.mean(axis=0)) < 0.1 * 0.004)  # zero mean
    assert np.abs(np.corrcoef(noise.T) - np.eye(3)).max() < 0.05  # axes independent
    # seeded: the same view gives the same joints, another seed other noise
    again, _ = tracker_joints(joints, stamps, "kinect32", TrackerView(None, 0.004, 0.0, 3))
    other, _ = tracker_joints(joints, stamps, "kinect32", TrackerView(None, 0.004, 0.0, 4))
    assert np.array_equal(again, noisy) and not np.allclose(other, noisy)


# per layout: joints the module keeps tracked (the pelvis and spine; MediaPipe has neither,
# its hips then) and limb joints it may hide
KEPT = {"kinect32": ("pelvis", "spine_navel", "spine_chest"),
        "mediapipe33": ("left_hip", "right_hip"),
        "cmu31": ("Hips", "LeftUpLeg", "RightUpLeg", "Spine", "Spine1", "LeftArm")}
LIMBS = {"kinect32": ("wrist_left", "ankle_right", "knee_left", "nose"),
         "mediapipe33": ("left_wrist", "right_ankle", "left_knee", "nose"),
         "cmu31": ("LeftForeArm", "RightFoot", "LeftLeg", "RightLeg", "Head")}


@pytest.mark.parametrize("skeleton", ["kinect32", "mediapipe33", "cmu31"])
def test_limb_joints_are_hidden_in_spans_for_about_the_share_the_trunk_never(skeleton):
    share = 0.1
    joints, stamps = _walk(600.0, skeleton)
    out, _ = tracker_joints(joints, stamps, skeleton, TrackerView(None, 0.002, share, 0))
    nan = np.isnan(out)
    hidden = nan.any(axis=2)
    assert np.array_equal(nan, np.repeat(hidden[:, :, None], 3, axis=2))  # whole joints
    sk = get_skeleton(skeleton)
    limbs = occludable_joints(sk)
    index = [sk.joints.index(n) for n in KEPT[skeleton]]
    assert not hidden[:, index].any() and not hidden[:, ~limbs].any()  # the trunk: never
    assert hidden[:, [sk.joints.index(n) for n in LIMBS[skeleton]]].any(axis=0).all()
    # about `share` of the limb joints' samples (overlapping spans make it a little less),
    # every limb joint hidden at some time
    assert abs(hidden[:, limbs].mean() / share - 1.0) < 0.2, hidden[:, limbs].mean()
    assert hidden[:, limbs].any(axis=0).all()
    # in spans of OCCLUSION_SPAN_S, not scattered samples: runs of a few frames at least
    runs = _runs(hidden[:, limbs])
    assert runs.min() >= round(OCCLUSION_SPAN_S[0] * RATE_HZ) - 1
    assert np.median(runs) >= 0.5 * sum(OCCLUSION_SPAN_S) * RATE_HZ * 0.8
    none, _ = tracker_joints(joints[:300], stamps[:300], skeleton, TrackerView(None, 0.002,
                                                                               0.0, 0))
    assert not np.isnan(none).any()


def _runs(hidden: np.ndarray) -> np.ndarray:
    """Lengths (frames) of the hidden runs of each column of hidden (F, k), bar those cut by
    the clip's end."""
    edges = np.diff(np.vstack([np.zeros((1, hidden.shape[1]), bool), hidden]).astype(int),
                    axis=0)
    out = []
    for col in range(hidden.shape[1]):
        starts = np.flatnonzero(edges[:, col] == 1)
        ends = np.flatnonzero(edges[:, col] == -1)
        out.extend(ends - starts[:len(ends)])
    return np.array(out)
