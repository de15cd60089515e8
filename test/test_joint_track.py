"""motion.joint_track: a missing joint held for joint_hold then lost, and the 1 Euro filter:
still at rest, following a step, and on the walk with tracker-like jitter smoothing the
capsules' velocities without moving them further than the jitter does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.bvh import read_bvh
from cloth_mg_ros.motion.joint_body import joints_from_poses, poses_from_joints
from cloth_mg_ros.motion.joint_track import JointTrack
from cloth_mg_ros.motion.pose_bags import sample_times
from cloth_mg_ros.motion.skeletons import get_skeleton
from cloth_mg_ros.ros.parameters import check_parameters


def test_a_missing_joint_is_held_then_lost_then_back():
    track = JointTrack(2, hold_s=0.1)
    a = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    gone = a.copy()
    gone[1] = np.nan
    assert np.array_equal(track.update(0.0, a), a)
    assert np.array_equal(track.update(0.05, gone), a)  # held
    assert np.array_equal(track.update(0.10, gone), a)  # still within 0.1 s
    out = track.update(0.15, gone)
    assert np.isnan(out[1]).all() and np.array_equal(out[0], a[0])  # lost
    assert np.array_equal(track.update(0.2, a), a)  # back
    assert (track.counts.held, track.counts.lost) == (2, 1)
    never = JointTrack(1, hold_s=1.0)
    assert np.isnan(never.update(0.0, np.full((1, 3), np.nan))).all()  # never seen


def test_the_filter_rests_still_and_follows_a_step():
    track = JointTrack(1, min_cutoff=5.0, beta=100.0)
    x = np.array([[0.3, -0.2, 1.1]])
    for k in range(10):
        assert np.array_equal(track.update(k / 30, x), x)  # a joint at rest stays put
    step = x + [0.1, 0.0, 0.0]
    out = [track.update((10 + k) / 30, step)[0, 0] for k in range(30)]
    assert x[0, 0] < out[0] < step[0, 0]  # smoothed, not jumped
    assert np.all(np.diff(out) >= 0.0)  # no overshoot on the way
    assert out[-1] == pytest.approx(step[0, 0], abs=1e-4)  # there within a second
    track.reset()
    assert np.array_equal(track.update(0.0, x), x)  # a new stream starts from itself


def test_bad_settings_are_named():
    with pytest.raises(ClothInputError, match="hold_s"):
        JointTrack(3, hold_s=-1.0)
    with pytest.raises(ClothInputError, match="shape"):
        JointTrack(3).update(0.0, np.zeros((4, 3)))


RUN = Path(__file__).parent / "data" / "mocap" / "09_01.bvh"  # 1.2 s of running


@pytest.mark.parametrize(("clip", "jitter_m"), [("walk", 0.002), ("walk", 0.005),
                                                 ("run", 0.002)])
def test_the_default_filter_smooths_the_capsules_without_lagging(clip, jitter_m):
    """kinect32 joints at 30 Hz with Gaussian jitter (seeded): the node's default filter
    (joint_filter_hz 5 Hz, joint_filter_beta 1000 Hz per m/s) cuts the capsule ends' velocity
    error on the walk by 5 % or more and moves them no further than the raw jitter does
    (measured, RMS: 2 mm 150 to 136 mm/s, 3.51 to 3.39 mm; 5 mm 376 to 340 mm/s, 8.78 to
    8.32 mm). Running at 3.6 m/s any low-pass lags: it may cost at most 1 mm and 10 %
    (measured: 3.53 to 3.96 mm, 151 to 162 mm/s)."""
    avatar, skeleton = Avatar.load(), get_skeleton("kinect32")
    if clip == "walk":
        frames = read_pose_frames(bundled_bag("walk"))
        stamps = np.array([s for s, _ in frames])
        truth = np.stack([p for _, p in frames])
    else:
        stamps, motion = sample_times(read_bvh(RUN).duration, 30.0, 0.0)
        truth = avatar.poses_from_clip(read_bvh(RUN), times=motion)
    joints = joints_from_poses(avatar, truth, skeleton)
    noisy = joints + np.random.default_rng(1).normal(0.0, jitter_m, joints.shape)
    defaults = check_parameters({"scene": "walking"})
    track = JointTrack(skeleton.num_joints, min_cutoff=defaults.joint_filter_hz,
                       beta=defaults.joint_filter_beta)
    smooth = np.stack([track.update(t, j) for t, j in zip(stamps, noisy, strict=True)])
    ends = np.concatenate(avatar.capsules(truth)[:2], axis=1)
    dt = np.diff(stamps)[:, None, None]

    def errors(js: np.ndarray) -> tuple[float, float]:
        poses, valid = poses_from_joints(js, skeleton, avatar)
        assert valid.all()
        got = np.concatenate(avatar.capsules(poses)[:2], axis=1)
        pos = np.linalg.norm(got - ends, axis=-1)[10:]
        vel = np.linalg.norm(np.diff(got - ends, axis=0) / dt, axis=-1)[10:]
        return float(np.sqrt(np.mean(pos**2))), float(np.sqrt(np.mean(vel**2)))

    raw_pos, raw_vel = errors(noisy)
    pos, vel = errors(smooth)
    print(f"{clip} {1e3 * jitter_m:g} mm: pos {1e3 * raw_pos:.2f} -> {1e3 * pos:.2f} mm RMS, "
          f"vel {1e3 * raw_vel:.0f} -> {1e3 * vel:.0f} mm/s RMS")
    if clip == "walk":
        assert vel < 0.95 * raw_vel, (vel, raw_vel)
        assert pos < raw_pos, (pos, raw_pos)
    else:
        assert vel < 1.1 * raw_vel, (vel, raw_vel)
        assert pos < raw_pos + 0.001, (pos, raw_pos)


def test_a_hidden_joint_is_carried_by_its_parent():
    """kinect32's hold parents put a wrist on its elbow and an ankle on its knee; a hidden
    wrist keeps its last offset from its elbow while the elbow moves (held still in the world
    it would lag behind), one whose parent is hidden too follows where the parent is carried
    (the chain up to a seen joint), and past hold_s it is lost (NaN)."""
    sk = get_skeleton("kinect32")
    parents = sk.hold_parents()
    wrist, elbow = sk.joint_index("wrist_left"), sk.joint_index("elbow_left")
    assert parents[wrist] == elbow
    assert parents[sk.joint_index("ankle_left")] == sk.joint_index("knee_left")
    assert parents[sk.joint_index("pelvis")] == -1
    assert np.all(parents < np.arange(sk.num_joints))  # parents first
    track = JointTrack(sk.num_joints, hold_s=0.2, parents=parents)
    x = np.random.default_rng(0).normal(size=(sk.num_joints, 3))
    track.update(0.0, x)
    walked = x + [0.1, 0.0, 0.0]  # the body moved 10 cm; the wrist is hidden
    walked[wrist] = np.nan
    out = track.update(0.1, walked)
    assert np.allclose(out[wrist], x[wrist] + [0.1, 0.0, 0.0])
    both = walked.copy()
    both[elbow] = np.nan  # the elbow hidden too: carried by the shoulder, the wrist by it
    out = track.update(0.15, both)
    assert np.allclose(out[elbow], x[elbow] + [0.1, 0.0, 0.0])
    assert np.allclose(out[wrist], x[wrist] + [0.1, 0.0, 0.0])
    assert np.isnan(track.update(0.25, both)[wrist]).all()  # hidden 0.25 s > hold_s
    with pytest.raises(ClothInputError, match="parents"):
        JointTrack(3, parents=[0, 0, 1])  # a joint its own parent


def test_mediapipe33_face_rides_on_the_nose_and_the_nose_on_a_shoulder():
    """mediapipe33 has no neck or spine joint, so its face had no carrier and a hidden ear
    was held still in the world (a walker's head capsule 0.1 m off within the hold). The
    face's points ride on the nose and the nose on the left shoulder, though the shoulder
    comes later in the layout's order."""
    sk = get_skeleton("mediapipe33")
    parents = sk.hold_parents()
    nose, ear, shoulder = (sk.joint_index(n) for n in ("nose", "right_ear", "left_shoulder"))
    assert parents[ear] == nose and parents[nose] == shoulder > nose
    track = JointTrack(sk.num_joints, hold_s=0.2, parents=parents)
    x = np.random.default_rng(1).normal(size=(sk.num_joints, 3))
    track.update(0.0, x)
    walked = x + [0.2, 0.0, 0.0]
    walked[[nose, ear]] = np.nan  # both hidden: the ear follows the nose the shoulder carries
    out = track.update(0.1, walked)
    assert np.allclose(out[[nose, ear]], x[[nose, ear]] + [0.2, 0.0, 0.0])
    with pytest.raises(ClothInputError, match="cycle"):
        JointTrack(3, parents=[2, 0, 1])
