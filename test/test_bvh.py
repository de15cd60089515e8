"""BVH reading, forward kinematics and the capsule avatar driven by the CMU clips."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.share import config_path
from cloth_mg_ros.motion.avatar import SEGMENT_NAMES, Avatar
from cloth_mg_ros.motion.bvh import (
    BVH_TO_ROS,
    CMU_UNITS_TO_M,
    euler_to_matrix,
    forward_kinematics,
    read_bvh,
)
from cloth_mg_ros.motion.rotations import matrix_to_quat, quat_to_matrix, slerp

MOCAP = Path(__file__).resolve().parent / 'data' / 'mocap'  # the CMU clips
# file: (frames in the file, frames kept after dropping the T-pose frame 0 and all-zero frames)
CLIPS = {'07_01': (317, 316), '07_12': (264, 262), '09_01': (149, 148), '02_04': (484, 483)}



@pytest.fixture(scope='module')
def clips():
    return {name: read_bvh(MOCAP / f'{name}.bvh') for name in CLIPS}


@pytest.fixture(scope='module')
def avatar():
    return Avatar.load()


@pytest.fixture(scope='module')
def walk_poses(clips, avatar):
    return avatar.poses_from_clip(clips['07_01'])


# ------------------------------------------------------------------------------------------
# The CMU clips


@pytest.mark.parametrize('name', list(CLIPS))
def test_cmu_clip_structure(clips, name):
    clip = clips[name]
    total, kept = CLIPS[name]
    assert clip.num_joints == 31
    assert clip.joint_names[0] == 'Hips' and clip.parents[0] == -1
    assert clip.channels[0] == ('Xposition', 'Yposition', 'Zposition',
                                'Zrotation', 'Yrotation', 'Xrotation')
    assert all(c == ('Zrotation', 'Yrotation', 'Xrotation') for c in clip.channels[1:])
    assert clip.frames.shape == (kept, 96)
    assert clip.num_frames == kept
    assert clip.source_frames[0] == (2 if name == '07_12' else 1)
    assert clip.source_frames[-1] == total - 1
    assert clip.frame_time == pytest.approx(1 / 120, rel=1e-3)
    assert np.all(np.isfinite(clip.frames))
    # offsets in metres: the CMU thigh is about 0.39-0.43 m long
    thigh = np.linalg.norm(clip.offsets[clip.joint_index('LeftLeg')])
    assert 0.35 < thigh < 0.45


def test_skip_options_keep_every_row(tmp_path):
    clip = read_bvh(MOCAP / '07_12.bvh', skip_first=0, skip_zero_frames=False)
    assert clip.num_frames == 264
    assert np.all(clip.frames[1] == 0.0)


def test_walk_pelvis_height_and_speed(clips):
    clip = clips['07_01']
    _, pos = forward_kinematics(clip)
    hips = pos[:, 0]
    assert 0.85 <= hips[:, 2].min() and hips[:, 2].max() <= 1.1
    velocity = (hips[-1] - hips[0]) / clip.duration
    assert 1.1 <= velocity[0] <= 1.6  # along +x (BVH +Z), an adult's walking pace
    assert abs(velocity[1]) < 0.1


@pytest.mark.parametrize('name, low, high', [('07_12', 1.6, 2.3), ('09_01', 2.5, 5.0)])
def test_forward_speeds(clips, name, low, high):
    # a brisk walk and a run: faster than the walk, forward along +x
    clip = clips[name]
    _, pos = forward_kinematics(clip)
    velocity = (pos[-1, 0] - pos[0, 0]) / clip.duration
    assert low <= velocity[0] <= high
    assert abs(velocity[1]) < 0.1


@pytest.mark.parametrize('name', list(CLIPS))
def test_the_root_is_the_files_root_in_metres_and_ros_axes(clips, name):
    # what the figures above stand on, exactly: the file's root offset plus its position
    # channels, in CMU units times CMU_UNITS_TO_M, turned by BVH_TO_ROS
    raw = read_bvh(MOCAP / f'{name}.bvh', units_to_m=1.0)
    channels = np.stack([raw.channel(0, c) for c in ('Xposition', 'Yposition', 'Zposition')], 1)
    _, pos = forward_kinematics(clips[name])
    expected = (raw.offsets[0] + channels) * CMU_UNITS_TO_M @ BVH_TO_ROS.T
    assert np.allclose(pos[:, 0], expected, rtol=0.0, atol=1e-12)


def test_jump_stays_in_place_and_rises(clips):
    _, pos = forward_kinematics(clips['02_04'])
    hips = pos[:, 0]
    assert np.ptp(hips[:, 0]) < 0.5 and np.ptp(hips[:, 1]) < 0.5
    standing = hips[0, 2]  # it crouches by over 10 cm, then rises over 30 cm above standing
    assert hips[:, 2].min() < standing - 0.1 and hips[:, 2].max() > standing + 0.3


def test_ros_axes_subject_left_is_plus_y(clips):
    clip = clips['07_01']
    _, pos = forward_kinematics(clip)
    left, right = clip.joint_index('LeftUpLeg'), clip.joint_index('RightUpLeg')
    head = clip.joint_index('Head')
    # the subject walks along +x, so its left hip is at larger y, its head above the hips
    assert np.all(pos[:, left, 1] > pos[:, right, 1])
    assert np.all(pos[:, head, 2] > pos[:, 0, 2] + 0.3)


def test_bvh_to_ros_is_a_proper_rotation():
    assert np.allclose(BVH_TO_ROS @ BVH_TO_ROS.T, np.eye(3))
    assert np.linalg.det(BVH_TO_ROS) == pytest.approx(1.0)
    assert np.allclose(BVH_TO_ROS @ [0, 0, 1], [1, 0, 0])  # forward: BVH +Z -> x
    assert np.allclose(BVH_TO_ROS @ [1, 0, 0], [0, 1, 0])  # left: BVH +X -> y
    assert np.allclose(BVH_TO_ROS @ [0, 1, 0], [0, 0, 1])  # up: BVH +Y -> z


# ------------------------------------------------------------------------------------------
# Synthetic files: forward kinematics against a hand computation, and bad input

TWO_JOINTS = """HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Child
  {
    OFFSET 0 2 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 0 0
1 2 3 0 90 0 0 0 90
"""


def _write(tmp_path, text, name='clip.bvh'):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_fk_two_joints_matches_hand_computation(tmp_path):
    clip = read_bvh(_write(tmp_path, TWO_JOINTS), units_to_m=0.5, skip_first=0,
                    skip_zero_frames=False)
    assert clip.joint_names == ['Root', 'Child']
    assert clip.parents.tolist() == [-1, 0]
    assert np.allclose(clip.offsets, [[0, 0, 0], [0, 1.0, 0]])  # 2 units * 0.5 m
    assert np.allclose(clip.end_sites[1], [0.5, 0, 0])
    assert clip.frame_time == 0.5
    rot, pos = forward_kinematics(clip, ros=False)
    assert rot.shape == (3, 2, 3, 3) and pos.shape == (3, 2, 3)
    # frame 0: identity everywhere, child one metre above the root
    assert np.allclose(rot[0], np.eye(3))
    assert np.allclose(pos[0], [[0, 0, 0], [0, 1, 0]])
    # frame 1: root at (0.5, 1, 1.5) m, turned 90 deg about Z: the child's +Y offset -> -X
    rz90 = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    assert np.allclose(pos[1, 0], [0.5, 1.0, 1.5])
    assert np.allclose(rot[1, 0], rz90)
    assert np.allclose(pos[1, 1], [0.5 - 1.0, 1.0, 1.5])
    # frame 2: root (z, y, x) = (0, 90, 0) deg, child (0, 0, 90): R_local = Rz Ry Rx
    ry90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0.0]])
    rx90 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0.0]])
    assert np.allclose(rot[2, 0], ry90)
    assert np.allclose(rot[2, 1], ry90 @ rx90)
    assert np.allclose(euler_to_matrix('ZYX', [90.0, 90.0, 90.0]), rz90 @ ry90 @ rx90)
    assert np.allclose(pos[2, 1], [0.5, 1.0, 1.5] + ry90 @ [0, 1.0, 0])
    # ROS axes: the same motion under (x, y, z)_ros = (Z, X, Y)_bvh
    rot_r, pos_r = forward_kinematics(clip, ros=True)
    assert np.allclose(pos_r[1, 1], [1.5, -0.5, 1.0])
    assert np.allclose(rot_r, BVH_TO_ROS @ rot @ BVH_TO_ROS.T)


def test_channel_order_as_declared(tmp_path):
    text = TWO_JOINTS.replace('CHANNELS 3 Zrotation Yrotation Xrotation',
                              'CHANNELS 3 Xrotation Yrotation Zrotation')
    clip = read_bvh(_write(tmp_path, text), skip_first=0, skip_zero_frames=False)
    rot, _ = forward_kinematics(clip, ros=False)
    # frame 2's child channels are now (x, y, z) = (0, 0, 90): R = Rx(0) Ry(0) Rz(90)
    assert np.allclose(rot[2, 1], rot[2, 0] @ euler_to_matrix('Z', [90.0]))
    angles = np.array([10.0, 20.0, 30.0])
    expected = Rotation.from_euler('XYZ', angles, degrees=True).as_matrix()  # intrinsic
    assert np.allclose(euler_to_matrix('XYZ', angles), expected)


def test_default_skip_drops_first_and_zero_frames(tmp_path):
    clip = read_bvh(_write(tmp_path, TWO_JOINTS))
    assert clip.num_frames == 2 and clip.source_frames.tolist() == [1, 2]
    assert clip.frames[0, 0] == pytest.approx(1 * CMU_UNITS_TO_M)  # positions in metres
    assert clip.frames[0, 3] == 90.0  # angles in degrees


@pytest.mark.parametrize('edit, expected', [
    (lambda t: t.replace('1 2 3 0 90 0 0 0 90\n', ''), ['line', 'truncated', 'Frames: 3',
                                                         'only 2']),
    (lambda t: t.replace('1 2 3 0 90 0 0 0 90', '1 2 3 0 90'), ['line 21', 'expected 9 values',
                                                                  'found 5']),
    (lambda t: t.replace('1 2 3 90 0 0', '1 2 x3 90 0 0'), ['line 20', "'x3'", 'column 2']),
    (lambda t: t.replace('1 2 3 90 0 0', '1 nan 3 90 0 0'), ['line 20', 'non-finite', 'nan']),
    (lambda t: t.replace('1 2 3 90 0 0', '1 inf 3 90 0 0'), ['line 20', 'non-finite']),
    (lambda t: t.replace('Zrotation Yrotation Xrotation\n    End',
                         'Zrotation Yrotation Wrotation\n    End'), ['line 9', 'unknown channel',
                                                                    'Wrotation']),
    (lambda t: t.replace('OFFSET 0 2 0', 'OFFSET 0 two 0'), ['line 8', "'two'", 'OFFSET Y']),
    (lambda t: t[:t.index('MOTION')], ['no MOTION']),
    (lambda t: t[:t.index('End Site')], ['line', 'truncated HIERARCHY']),
    (lambda t: t.replace('Frames: 3', 'Frames: three'), ['line 17', 'Frames:']),
    (lambda t: t.replace('Frame Time: 0.5', 'Frame Time: 0'), ['Frame Time', 'positive']),
    (lambda t: t.replace('HIERARCHY', 'HIERARCHIES'), ['line 1', 'HIERARCHY']),
    (lambda t: t + '0 0 0 0 0 0 0 0 0\n', ['line 22', 'more frame rows']),
])
def test_bad_bvh_raises_naming_file_line_and_problem(tmp_path, edit, expected):
    path = _write(tmp_path, edit(TWO_JOINTS), 'bad.bvh')
    with pytest.raises(ClothInputError) as info:
        read_bvh(path)
    message = str(info.value)
    assert 'bad.bvh' in message
    for part in expected:
        assert part in message, (part, message)


def test_missing_bvh_file(tmp_path):
    with pytest.raises(ClothInputError, match='not found'):
        read_bvh(tmp_path / 'nope.bvh')


def test_all_frames_skipped_is_an_error(tmp_path):
    text = TWO_JOINTS.replace('Frames: 3', 'Frames: 1').split('0 0 0 0 0 0 0 0 0')[0]
    with pytest.raises(ClothInputError, match='no motion frames left'):
        read_bvh(_write(tmp_path, text + '0 0 0 0 0 0 0 0 0\n'))


# ------------------------------------------------------------------------------------------
# Rotation helpers


def test_quaternion_helpers_round_trip_and_slerp():
    rng = np.random.default_rng(1)
    rots = Rotation.random(20, random_state=2).as_matrix()
    q = matrix_to_quat(rots)
    assert np.allclose(quat_to_matrix(q), rots)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1.0)
    # sign continuity along frames
    assert np.all(np.sum(q[1:] * q[:-1], axis=-1) >= 0)
    q0, q1 = q[:10], q[10:]
    u = rng.random(10)
    for k in range(10):
        ref = Slerp([0, 1], Rotation.from_quat([q0[k], q1[k]]))(u[k]).as_matrix()
        assert np.allclose(quat_to_matrix(slerp(q0[k], q1[k], u[k])), ref)
    # vectorised over leading axes
    assert np.allclose(slerp(q0, q1, np.zeros(10)), q0 * np.sign(np.sum(q0 * q0, -1))[:, None])


# ------------------------------------------------------------------------------------------
# The avatar


def test_avatar_config_segments_and_dimensions(avatar):
    assert config_path('avatar.yaml').is_file()
    assert tuple(avatar.names) == SEGMENT_NAMES and avatar.num_segments == 16
    assert np.all(avatar.radius > 0) and np.all(avatar.half_length >= 0)
    assert avatar.offset.shape == (16, 3)
    rest = avatar.rest_poses()
    assert rest.shape == (16, 7)
    p0, p1, radius = avatar.capsules(rest)
    top = np.max(np.maximum(p0[:, 2], p1[:, 2]) + radius)
    bottom = np.min(np.minimum(p0[:, 2], p1[:, 2]) - radius)
    assert top == pytest.approx(1.75, abs=0.03)  # an adult of about 1.75 m
    assert bottom == pytest.approx(avatar.ground_clearance, abs=1e-9)
    # capsule axis = local +z, centre = offset in the segment frame
    rot = quat_to_matrix(rest[:, 3:])
    axis = (p1 - p0) / np.maximum(np.linalg.norm(p1 - p0, axis=1, keepdims=True), 1e-12)
    long = avatar.half_length > 0
    assert np.allclose(axis[long], rot[long, :, 2])
    assert np.allclose(0.5 * (p0 + p1), rest[:, :3] + np.einsum('sab,sb->sa', rot, avatar.offset))


def test_rest_pose_is_neutral_standing(avatar):
    rest = avatar.rest_poses()
    idx = {n: i for i, n in enumerate(avatar.names)}
    pelvis = rest[idx['pelvis'], :3]
    assert 0.9 < pelvis[2] < 1.1
    for side, sign in (('l', 1), ('r', -1)):
        hip, wrist = rest[idx[f'upper_leg_{side}'], :3], rest[idx[f'hand_{side}'], :3]
        ankle = rest[idx[f'foot_{side}'], :3]
        # legs straight down, hands hanging beside the hips, outside the pelvis
        assert np.allclose(ankle[:2], hip[:2], atol=1e-6)
        assert abs(wrist[2] - hip[2]) < 0.1
        assert 0.2 < sign * wrist[1] < 0.4 and abs(wrist[0]) < 0.05


def test_walk_avatar_plausible(clips, avatar, walk_poses):
    clip = clips['07_01']
    assert walk_poses.shape == (clip.num_frames, 16, 7)
    assert np.all(np.isfinite(walk_poses))
    assert np.allclose(np.linalg.norm(walk_poses[..., 3:], axis=-1), 1.0)
    pelvis = walk_poses[:, 0, :3]
    assert 0.85 <= pelvis[:, 2].min() and pelvis[:, 2].max() <= 1.1
    assert np.allclose(pelvis[0, :2], 0.0)  # recentred
    speed = (pelvis[-1, 0] - pelvis[0, 0]) / clip.duration
    hips = forward_kinematics(clip)[1][:, 0]
    assert speed == pytest.approx((hips[-1, 0] - hips[0, 0]) / clip.duration, abs=0.01)
    p0, p1, radius = avatar.capsules(walk_poses)
    low = np.minimum(p0[..., 2], p1[..., 2]) - radius  # (F, S)
    feet = [avatar.segment_index('foot_l'), avatar.segment_index('foot_r')]
    # lowest foot point over the clip at the clearance; some foot within 5 cm of the floor in
    # every frame (the levelled floor); nothing else lower than 5 cm
    assert low[:, feet].min() == pytest.approx(avatar.ground_clearance, abs=1e-9)
    assert low[:, feet].min(axis=1).max() < 0.05
    others = np.delete(low, feet, axis=1)
    assert others.min() > 0.05
    # the limb chains stay connected: each joint lies at the end of its parent's capsule
    for name in ('lower_arm_l', 'hand_l', 'lower_arm_r', 'hand_r', 'lower_leg_l', 'foot_l',
                 'lower_leg_r', 'foot_r'):
        s = avatar.segment_index(name)
        parent = avatar.parents[s]
        seg = p1[:, parent] - p0[:, parent]
        t = np.clip(np.einsum('fa,fa->f', walk_poses[:, s, :3] - p0[:, parent], seg)
                    / np.maximum(np.einsum('fa,fa->f', seg, seg), 1e-12), 0, 1)
        gap = np.linalg.norm(p0[:, parent] + t[:, None] * seg - walk_poses[:, s, :3], axis=1)
        assert gap.max() < radius[parent], name


def test_walk_first_frame_hands_near_hips(avatar, walk_poses):
    idx = {n: i for i, n in enumerate(avatar.names)}
    pelvis = walk_poses[0, idx['pelvis'], :3]
    for side in 'lr':
        wrist = walk_poses[0, idx[f'hand_{side}'], :3]
        assert abs(wrist[2] - pelvis[2]) < 0.2  # hanging at hip height, swinging
        assert np.linalg.norm(wrist[:2] - pelvis[:2]) < 0.5


@pytest.mark.parametrize('name', ['07_12', '09_01', '02_04'])
def test_other_clips_grounded(clips, avatar, name):
    poses = avatar.poses_from_clip(clips[name])
    assert avatar.lowest_point(poses) == pytest.approx(avatar.ground_clearance, abs=1e-9)
    assert np.all(np.isfinite(poses))


def test_resampled_poses_match_frames(clips, avatar, walk_poses):
    clip = clips['07_01']
    times = clip.times()[::4]
    sampled = avatar.poses_from_clip(clip, times=times)
    assert np.allclose(sampled[:, :, :3], walk_poses[::4, :, :3], atol=1e-9)
    assert np.allclose(quat_to_matrix(sampled[..., 3:]), quat_to_matrix(walk_poses[::4, :, 3:]),
                       atol=1e-9)
    # half-way between frames: close to both neighbours
    mid = avatar.poses_from_clip(clip, times=times[:-1] + clip.frame_time / 2)
    step = np.linalg.norm(mid[:, :, :3] - walk_poses[::4, :, :3][:-1], axis=-1)
    assert step.max() < 0.05


def test_avatar_rejects_clip_without_joint(tmp_path, avatar):
    with pytest.raises(ClothInputError, match="needs joint 'Hips'"):
        avatar.poses_from_clip(read_bvh(_write(tmp_path, TWO_JOINTS)))


def test_avatar_yaml_errors(tmp_path):
    with pytest.raises(ClothInputError, match='not found'):
        Avatar.load(tmp_path / 'none.yaml')
    bad = tmp_path / 'bad.yaml'
    text = config_path('avatar.yaml').read_text()
    bad.write_text(text.replace('radius: 0.11}', 'radius: -0.11}'))
    with pytest.raises(ClothInputError, match=r'bad.yaml.*segments\[0\] \(pelvis\)'
                                              r'.capsule.radius.*-0.11'):
        Avatar.load(bad)
    bad.write_text(text.replace('parent: upper_arm_l', 'parent: elbow'))
    with pytest.raises(ClothInputError, match="parent 'elbow'"):
        Avatar.load(bad)
    bad.write_text(text.replace('{via: LeftArm, vector: [0.0, 0.30, 0.0]}',
                                '{via: LeftArm, vector: [0.0, 0.30]}'))
    with pytest.raises(ClothInputError, match='vector must be a list of 3 numbers'):
        Avatar.load(bad)


def test_rest_pose_mismatch_detected(tmp_path, clips):
    text = config_path('avatar.yaml').read_text()
    # legs straight down in the rest pose: wrong for the CMU skeleton (legs splayed 20 deg)
    text = text.replace('{via: LeftUpLeg, vector: [0.0, 0.1437, -0.3947]}',
                        '{via: LeftUpLeg, vector: [0.0, 0.0, -0.42]}')
    path = tmp_path / 'straight.yaml'
    path.write_text(text)
    with pytest.raises(ClothInputError, match='rest pose mismatch.*lower_leg_l'):
        Avatar.load(path).poses_from_clip(clips['07_01'])


def test_capsules_shapes(avatar):
    rest = avatar.rest_poses()
    frames = np.stack([rest, rest])
    p0, p1, radius = avatar.capsules(frames)
    assert p0.shape == p1.shape == (2, 16, 3) and radius.shape == (16,)
    with pytest.raises(ClothInputError, match='shape'):
        avatar.capsules(rest[:3])
    assert math.isfinite(avatar.lowest_point(frames))


def test_config_path_finds_installed_share(tmp_path, monkeypatch):
    # an install prefix as colcon / ament_python lays it out
    (tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'cloth_mg_ros').touch()
    config = tmp_path / 'share' / 'cloth_mg_ros' / 'config'
    config.mkdir(parents=True)
    (config / 'only_installed.yaml').write_text('x: 1\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    assert config_path('only_installed.yaml') == config / 'only_installed.yaml'
    # the source tree wins for files it has
    assert config_path('avatar.yaml') == Path(__file__).resolve().parents[1] / 'config' / \
        'avatar.yaml'
    with pytest.raises(ClothInputError, match='not found.*looked in'):
        config_path('missing.yaml')


def test_body_rotations_are_upright_at_rest(avatar):
    rest = avatar.rest_poses()
    body = avatar.body_rotations(rest)
    for name in ('pelvis', 'lower_torso', 'upper_torso', 'head', 'foot_l', 'foot_r'):
        assert np.allclose(body[avatar.segment_index(name)], np.eye(3), atol=1e-9), name
    # the pelvis capsule lies across the body (along y) although the frame is upright
    p0, p1, _ = avatar.capsules(rest)
    pelvis = avatar.segment_index('pelvis')
    assert np.allclose(np.abs((p1 - p0)[pelvis] / np.linalg.norm((p1 - p0)[pelvis])), [0, 1, 0])


def test_an_all_zero_row_inside_the_motion_is_kept(tmp_path):
    # dropping it would pull every later frame a frame time earlier; the leading ones go
    lines = (MOCAP / '09_01.bvh').read_text().splitlines()
    first = lines.index(next(ln for ln in lines if ln.startswith('Frame Time'))) + 1
    width = len(lines[first].split())
    zero = ' '.join(['0'] * width)
    lines[first + 1] = zero  # a leading zero row (after the T-pose): dropped
    lines[first + 50] = zero  # one inside the motion: kept, in its place
    path = tmp_path / 'gap.bvh'
    path.write_text('\n'.join(lines) + '\n')
    clip = read_bvh(path)
    assert clip.num_frames == CLIPS['09_01'][1] - 1
    assert np.all(clip.frames[48] == 0.0) and np.any(clip.frames[47] != 0.0)
