"""A tracker's stream into the simulation's world (ros.body_input, motion.input_frame): the
input transform, the floor measured from the stream, the avatar sized from it, and the Azure
Kinect driver's MarkerArray picked apart; the default segment input passes untouched."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("visualization_msgs")

from builtin_interfaces.msg import Time
from log_lines import LogLines
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.motion.input_frame import InputFrame, floor_from_poses
from cloth_mg_ros.motion.joint_body import joints_from_poses, packaged_avatar
from cloth_mg_ros.motion.rotations import matrix_to_quat, transform_poses
from cloth_mg_ros.ros.body_input import WINDOW_S, BodyInput
from cloth_mg_ros.ros.body_topic import KinectMarkerInput
from cloth_mg_ros.ros.ingest import FrameLog, KeyPose, PoseIngest
from cloth_mg_ros.ros.parameters import check_parameters

# A camera 3 m in front of the subject, 1.1 m up, looking at it: its axes x right, y down,
# z forward (the Azure Kinect's depth camera, MediaPipe's world landmarks) in the world.
CAMERA_R = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
CAMERA_T = np.array([-3.0, 0.2, 1.1])
FLOOR_M = 0.8  # the transform given places the floor this high (the camera's height error)




@pytest.fixture(scope="module")
def walk():
    """The bundled walk's first 1.5 s: stamps (F,) s and segment poses (F, 16, 7)."""
    frames = read_pose_frames(resolve_bag("walk"))[:46]
    return (np.array([s for s, _ in frames]), np.stack([p for _, p in frames]))


def transform_param(rotation: np.ndarray, translation: np.ndarray) -> list[float]:
    return [*translation.tolist(), *matrix_to_quat(rotation).tolist()]


def body_input(**params) -> BodyInput:
    values = check_parameters({"scene": "walking", **params})
    return BodyInput(values, LogLines())


def keys_of(stamps: np.ndarray, poses: np.ndarray, frame_id: str = "camera") -> list[KeyPose]:
    return [KeyPose(int(t), round((t % 1) * 1e9), float(t), frame_id, p)
            for t, p in zip(stamps, poses, strict=True)]


def in_camera(points: np.ndarray) -> np.ndarray:
    """World points (..., 3) in the camera's frame (p_cam = R^T (p - t))."""
    return (points - CAMERA_T) @ CAMERA_R


def capsule_error(avatar, got: np.ndarray, want: np.ndarray) -> float:
    a0, a1, _ = avatar.capsules(got)
    b0, b1, _ = avatar.capsules(want)
    return float(max(np.linalg.norm(a0 - b0, axis=-1).max(),
                     np.linalg.norm(a1 - b1, axis=-1).max()))


def test_the_transform_parameter_is_checked_and_named():
    with pytest.raises(ClothInputError, match=r"input_transform must be 7 finite numbers"):
        InputFrame.from_parameters([0.0, 0.0, 1.0], 0.0)
    with pytest.raises(ClothInputError, match=r"not a unit quaternion \(norm 2"):
        InputFrame.from_parameters([0, 0, 0, 0, 0, 0, 2.0], 0.0)
    with pytest.raises(ClothInputError, match="from_joints measures the subject"):
        body_input(avatar="from_joints")  # segments carry no joints to measure
    with pytest.raises(ClothInputError, match="avatar file not found"):
        body_input(avatar="/nonexistent/avatar.yaml")
    assert CAMERA_R.T @ CAMERA_R == pytest.approx(np.eye(3))


def test_segments_with_the_defaults_pass_untouched(walk):
    """The default input (segments, identity, floor 0, packaged avatar): the very arrays."""
    stamps, poses = walk
    keys = keys_of(stamps[:3], poses[:3])
    arrays = [k.poses for k in keys]
    b = body_input()
    assert b.passthrough
    out = b.convert(keys, lambda kind, stamp: None)
    assert out is keys and all(k.poses is p for k, p in zip(out, arrays, strict=True))


def test_segments_from_a_camera_frame_come_back_to_the_world(walk):
    """Segment poses sent in the camera's frame with input_transform = the camera's pose in
    the world: the world poses again (1e-9 m, 1e-9 in the quaternions), published in
    frame_id (the world), not the messages' camera frame."""
    stamps, poses = walk
    sent = transform_poses(poses[:3], CAMERA_R.T, -CAMERA_R.T @ CAMERA_T)
    b = body_input(input_transform=transform_param(CAMERA_R, CAMERA_T))
    out = b.convert(keys_of(stamps[:3], sent), lambda kind, stamp: None)
    got = np.stack([k.poses for k in out])
    assert np.abs(got[..., :3] - poses[:3, :, :3]).max() < 1e-9
    same = np.abs(np.abs(np.sum(got[..., 3:] * poses[:3, :, 3:], axis=-1)) - 1.0)
    assert same.max() < 1e-9  # q and -q are one rotation
    assert {k.frame_id for k in out} == {"world"}


@pytest.mark.parametrize("skeleton", ["kinect32", "mediapipe33"])
def test_joints_in_a_camera_frame_with_the_floor_measured(walk, skeleton):
    """A tracker's joints in the camera's frame, the transform given putting the floor
    FLOOR_M high and floor_height auto: the first second is held back (nothing lost), then
    every key places the body where the segment input does, lowered by the floor measured
    (FLOOR_M plus the walk's own first-second floor, within a millimetre), capsules within
    1 cm (the mediapipe33 torso's known 1 cm: test_joint_body) of the segment input's."""
    stamps, poses = walk
    avatar = packaged_avatar()
    joints = joints_from_poses(avatar, poses, skeleton)
    up = CAMERA_T + [0.0, 0.0, FLOOR_M]
    sent = np.zeros((*joints.shape[:2], 7))
    sent[..., :3], sent[..., 6] = in_camera(joints), 1.0
    b = body_input(body_input="joints", skeleton=skeleton, joint_filter_hz=0.0,
                   floor_height="auto", input_transform=transform_param(CAMERA_R, up))
    skipped = []
    window = int(np.count_nonzero(stamps - stamps[0] < WINDOW_S))
    keys = keys_of(stamps, sent)
    assert b.convert(keys[:window], lambda *a: skipped.append(a)) == []
    assert b.held == window
    out = b.convert(keys[window:], lambda *a: skipped.append(a))
    assert len(out) == len(keys) and not skipped and b.held == 0
    first_second = poses[stamps - stamps[0] <= WINDOW_S]
    floor0 = floor_from_poses(avatar, first_second)
    assert abs(floor0) < 0.02  # the bundled walk stands on z = 0 (its lowest point, clearance)
    assert b.frame.floor == pytest.approx(FLOOR_M + floor0, abs=1e-3)
    want = poses.copy()
    want[..., 2] -= floor0
    err = capsule_error(avatar, np.stack([k.poses for k in out]), want)
    print(f"{skeleton}: capsules within {1e3 * err:.2f} mm of the segment input's")
    assert err < (1e-3 if skeleton == "kinect32" else 0.013)
    assert {k.frame_id for k in out} == {"world"}
    assert any("the floor at z = " in line for line in b.logger.lines)


def test_the_avatar_sized_from_the_stream(walk):
    """avatar from_joints: the packaged avatar sized to the walk's first second (the walk's
    subject is the packaged avatar's: it stays within a centimetre), every key used."""
    stamps, poses = walk
    avatar = packaged_avatar()
    joints = joints_from_poses(avatar, poses, "kinect32")
    sent = np.zeros((*joints.shape[:2], 7))
    sent[..., :3], sent[..., 6] = joints, 1.0
    b = body_input(body_input="joints", skeleton="kinect32", joint_filter_hz=0.0,
                   avatar="from_joints")
    out = b.convert(keys_of(stamps, sent), lambda *a: pytest.fail(f"skipped {a}"))
    assert len(out) == len(stamps) and b.avatar is not avatar
    assert np.abs(b.avatar.radius - avatar.radius).max() < 0.01
    err = capsule_error(avatar, np.stack([k.poses for k in out]), poses)
    assert err < 0.01
    assert any("avatar sized" in line for line in b.logger.lines)


def marker_array(bodies: dict[int, np.ndarray], stamp: float) -> MarkerArray:
    """A driver-like MarkerArray: per body id its (32, 3) joints (NaN: left out)."""
    msg = MarkerArray()
    for body, joints in bodies.items():
        for j, p in enumerate(joints):
            if not np.all(np.isfinite(p)):
                continue
            m = Marker(id=body * 100 + j, type=Marker.SPHERE)
            m.header.frame_id = "depth_camera_link"
            m.header.stamp = Time(sec=int(stamp), nanosec=round((stamp % 1) * 1e9))
            m.pose.position.x, m.pose.position.y, m.pose.position.z = map(float, p)
            msg.markers.append(m)
    return msg


def test_kinect_markers_give_the_nearest_or_the_chosen_body(walk):
    """Two bodies in view: body_id -1 takes the one whose pelvis is nearer the camera, a
    body_id that one; a joint the message lacks arrives as NaN (held by the track); a frame
    of DELETEALL alone (no body) is skipped as empty, counted."""
    _, poses = walk
    joints = in_camera(joints_from_poses(packaged_avatar(), poses[0], "kinect32"))
    far = joints + [0.0, 0.0, 2.0]  # 2 m further from the camera
    near = joints.copy()
    near[5] = np.nan  # an occluded elbow
    for body_id, want in ((-1, near), (4, far)):
        frames = FrameLog(LogLines(), 32, "kinect32 joint")
        ingest = PoseIngest(32, 1.0, frames, joints=True)
        take = KinectMarkerInput(ingest, body_id)
        take(marker_array({4: far, 7: near}, 1.5))
        (key,) = ingest.take()
        assert key.frame_id == "depth_camera_link" and key.stamp == pytest.approx(1.5)
        assert np.array_equal(key.poses[:, :3], want, equal_nan=True)
        empty = MarkerArray(markers=[Marker(action=Marker.DELETEALL)])
        take(empty)
        assert frames.counts["empty"] == 1 and ingest.counts().received == 2
    assert math.isnan(near[5, 0])


def test_a_lost_joint_drops_its_segments_and_they_come_back(walk):
    """An elbow lost for longer than joint_hold: the key still drives the body, the segments
    that need the elbow are dropped (KeyPose.dropped) with their poses carried by their
    parents; the elbow back, nothing is dropped. Before the first whole body, or with the
    pelvis lost, the key is skipped (no_body)."""
    stamps, poses = walk
    avatar = packaged_avatar()
    joints = joints_from_poses(avatar, poses, "kinect32")
    elbow = 13  # kinect32 ELBOW_RIGHT
    sent = np.zeros((*joints.shape[:2], 7))
    sent[..., :3], sent[..., 6] = joints, 1.0
    sent[3:20, elbow, :3] = np.nan  # last seen in frame 2; back in frame 20
    sent[0, 0, :3] = np.nan  # the pelvis missing in the first frame: no body yet
    b = body_input(body_input="joints", skeleton="kinect32", joint_filter_hz=0.0,
                   joint_hold=0.12)
    skipped = []
    out = b.convert(keys_of(stamps[:25], sent[:25]), lambda *a: skipped.append(a))
    assert [kind for kind, _ in skipped] == ["no_body"] and len(out) == 24
    dropped = {i: k for i, k in enumerate(out, start=1) if k.dropped is not None}
    assert sorted(dropped) == [i for i in range(3, 20) if stamps[i] - stamps[2] > 0.12]
    names = {avatar.names[s] for k in dropped.values() for s in np.flatnonzero(k.dropped)}
    assert names and names <= {"upper_arm_r", "lower_arm_r", "hand_r"}
    assert b.dropped_samples == sum(int(k.dropped.sum()) for k in dropped.values())
    torso = avatar.names.index("upper_torso")
    for i, key in dropped.items():  # held segments follow their parents; the rest as sent
        assert np.all(np.isfinite(key.poses))
        kept = ~key.dropped
        assert capsule_error(avatar, np.where(kept[:, None], key.poses, poses[i]),
                             poses[i]) < 1e-3
        for s in np.flatnonzero(key.dropped):  # rigid with the parent since last placed
            p = avatar.parents[s]
            gap = np.linalg.norm(key.poses[s, :3] - key.poses[p, :3])
            assert gap == pytest.approx(np.linalg.norm(poses[2, s, :3] - poses[2, p, :3]),
                                        abs=1e-3)
        assert not key.dropped[torso]
    assert out[-1].dropped is None  # the elbow is back
    err = capsule_error(avatar, out[-1].poses, poses[24])
    assert err < 1e-3


def test_a_dropped_capsule_collides_with_nothing_and_comes_back_without_a_sweep():
    """CapsulePose.active: a dropped capsule finds no contact (the others keep their index);
    back, it jumps to where it is (no swept test from where it was held)."""
    from cloth_mg_ros.collision.capsules import CapsuleCollider

    col = CapsuleCollider(np.array([0.1, 0.1]))
    p0 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    p1 = p0 + [0.0, 0.0, 1.0]
    x = np.array([[0.05, 0.0, 0.5], [1.05, 0.0, 0.5]])  # inside each capsule
    pose = col.moved(None, p0, p1)
    assert col.at(pose).query(x, 0.01).part.tolist() == [0, 1]
    off = col.moved(pose, p0, p1, 0.01, active=[False, True])
    hit = col.at(off).query(x, 0.01, x_prev=x)
    assert hit.index.tolist() == [1] and hit.part.tolist() == [1]
    # while dropped the first capsule was held at x = 0; it comes back at x = -2 (the
    # tracker's joint is back elsewhere): no sweep across the particle at x = 0.05
    moved_p0, moved_p1 = p0.copy(), p1.copy()
    moved_p0[0, 0] = moved_p1[0, 0] = -2.0
    back = col.moved(off, moved_p0, moved_p1, 0.01)
    assert back.active is None and np.array_equal(back.q0[0], moved_p0[0])
    assert col.at(back).query(x, 0.01, x_prev=x).index.tolist() == [1]
