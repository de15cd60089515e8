"""`cloth-mg bag from-bvh --body-input ...`: bags of segment poses, of a layout's joints
(PoseArray) and of the Azure Kinect driver's body tracking MarkerArray, written from the short
running clip and read back (io.bags.read_joint_frames, io.kinect_markers)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from cloth_mg_ros.cli.bag import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import (
    DEFAULT_TOPIC,
    bag_info,
    jazzy_typestore,
    read_joint_frames,
    read_pose_frames,
    write_joint_bag,
)
from cloth_mg_ros.io.kinect_markers import (
    kinect_joints,
    read_kinect_marker_frames,
    write_kinect_marker_bag,
)
from cloth_mg_ros.motion import Avatar, read_bvh
from cloth_mg_ros.motion.joint_body import joints_from_poses, poses_from_joints
from cloth_mg_ros.motion.pose_bags import sample_times
from cloth_mg_ros.motion.skeletons import SKELETONS

RUN = Path(__file__).parent / 'data' / 'mocap' / '09_01.bvh'  # 1.2 s: 67 messages at 30 Hz
FRAMES = 67


def raw_messages(bag: Path) -> list[tuple[str, str, int, bytes]]:
    with Reader(bag) as reader:
        return [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """The running clip written as every kind: {name: bag path}."""
    root = tmp_path_factory.mktemp('joint_bags')
    kinds = {
        'default': [],
        'segments': ['--body-input', 'segments'],
        'kinect32': ['--body-input', 'joints', '--skeleton', 'kinect32'],
        'mediapipe33': ['--body-input', 'joints', '--skeleton', 'mediapipe33'],
        'cmu31': ['--body-input', 'joints', '--skeleton', 'cmu31'],
        'markers': ['--body-input', 'kinect_markers'],
    }
    for name, flags in kinds.items():
        assert main(['from-bvh', str(RUN), str(root / name), *flags]) == 0, name
    return {name: root / name for name in kinds}


@pytest.fixture(scope='module')
def avatar():
    return Avatar.load()


def test_each_kind_is_written_and_named(bags, capsys):
    expect = {'segments': ('geometry_msgs/msg/PoseArray', None),
              'kinect32': ('geometry_msgs/msg/PoseArray', 'kinect32'),
              'mediapipe33': ('geometry_msgs/msg/PoseArray', 'mediapipe33'),
              'cmu31': ('geometry_msgs/msg/PoseArray', 'cmu31'),
              'markers': ('visualization_msgs/msg/MarkerArray', 'kinect32')}
    for name, (msgtype, layout) in expect.items():
        info = bag_info(bags[name])
        assert info['topics'] == {DEFAULT_TOPIC: {'type': msgtype, 'count': FRAMES,
                                                  'rate_hz': pytest.approx(30.0)}}, name
        data = info['custom_data']
        kind = {'segments': 'segments', 'markers': 'kinect_markers'}.get(name, 'joints')
        assert data['cloth_mg_ros.body_input'] == kind
        assert data.get('cloth_mg_ros.skeleton') == layout
        if layout:
            assert data['cloth_mg_ros.joints'] == ','.join(SKELETONS[layout].joints)
            assert 'cloth_mg_ros.segments' not in data
    for name in ('kinect32', 'mediapipe33', 'cmu31'):
        stamps, joints = read_joint_frames(bags[name], num_joints=SKELETONS[name].num_joints)
        assert joints.shape == (FRAMES, SKELETONS[name].num_joints, 3)
        assert np.allclose(np.diff(stamps), 1 / 30) and stamps[0] == 0.0
        # 1 s of settle: the first pose held for 30 frames, then the motion
        assert np.all(joints[:31] == joints[0]) and not np.allclose(joints[31], joints[0])
        # identity orientations
        poses = np.stack([p for _, p in read_pose_frames(bags[name])])
        assert np.all(poses[..., 3:] == [0.0, 0.0, 0.0, 1.0])
    assert main(['info', str(bags['markers'])]) == 0
    printed = capsys.readouterr().out
    assert 'visualization_msgs/msg/MarkerArray' in printed
    assert 'cloth_mg_ros.body_input: kinect_markers' in printed


def test_segments_output_unchanged(bags, avatar):
    """--body-input segments is the default, byte for byte, and its poses are the avatar's on
    the clip's sampled times (float64 end to end)."""
    assert raw_messages(bags['segments']) == raw_messages(bags['default'])
    clip = read_bvh(RUN)
    stamps, motion = sample_times(clip.duration, 30.0, 1.0)
    frames = read_pose_frames(bags['segments'])
    assert np.allclose([s for s, _ in frames], stamps, rtol=0.0, atol=1e-9)  # ns stamps
    assert np.array_equal(np.stack([p for _, p in frames]),
                          avatar.poses_from_clip(clip, times=motion))
    assert bag_info(bags['segments'])['custom_data']['cloth_mg_ros.body_input'] == 'segments'


def test_joint_bag_capsules_match_the_segment_bag(bags, avatar):
    """The joints bag read back through poses_from_joints places the capsules where the
    segments bag does (the same avatar poses): kinect32 within 1 mm."""
    seg = np.stack([p for _, p in read_pose_frames(bags['segments'])])
    s_stamps = np.array([s for s, _ in read_pose_frames(bags['segments'])])
    stamps, joints = read_joint_frames(bags['kinect32'], num_joints=32)
    assert np.array_equal(stamps, s_stamps)
    assert np.array_equal(joints, joints_from_poses(avatar, seg, 'kinect32'))
    poses, valid = poses_from_joints(joints, 'kinect32', avatar)
    assert valid.all()
    a0, a1, _ = avatar.capsules(poses)
    b0, b1, _ = avatar.capsules(seg)
    err = np.maximum(np.linalg.norm(a0 - b0, axis=-1), np.linalg.norm(a1 - b1, axis=-1))
    print(f'kinect32 joint bag: capsule end points within {1000 * err.max():.3f} mm')
    assert err.max() < 1e-3


def test_marker_bag_mirrors_the_kinect_driver(bags):
    """Each message: 32 SPHERE markers, ids 100..131 (body 1 x 100 + k4abt joint index), header
    depth_camera_link at the frame's stamp, lifetime 0.25 s, scale 0.05 m, body 1's palette
    colour (green); positions those of the kinect32 joint bag."""
    ts = jazzy_typestore()
    stamps, joints = read_joint_frames(bags['kinect32'])
    raw = raw_messages(bags['markers'])
    assert len(raw) == FRAMES
    for k, (_, msgtype, t, data) in enumerate(raw):
        markers = ts.deserialize_cdr(data, msgtype).markers
        assert [m.id for m in markers] == list(range(100, 132))
        for m in markers:
            assert (m.type, m.action, m.ns) == (2, 0, '')  # SPHERE, ADD
            assert m.header.frame_id == 'depth_camera_link'
            assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == t
            assert (m.lifetime.sec, m.lifetime.nanosec) == (0, 250_000_000)
            assert (m.scale.x, m.scale.y, m.scale.z) == (0.05, 0.05, 0.05)
            assert (m.color.r, m.color.g, m.color.b, m.color.a) == (0.0, 1.0, 0.0, 1.0)
            assert (m.pose.orientation.x, m.pose.orientation.w) == (0.0, 1.0)
        got = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                        for m in markers])
        assert np.array_equal(got, joints[k])
    m_stamps, m_joints, body = read_kinect_marker_frames(bags['markers'])
    assert np.array_equal(m_stamps, stamps) and np.array_equal(m_joints, joints)
    assert np.all(body == 1)


def test_kinect_joints_picks_a_body():
    """The chosen body, else the one nearest the camera; joints a message lacks are NaN."""
    near = np.arange(96, dtype=float).reshape(32, 3) * 0.01 + [0.0, 0.0, 1.5]
    far = near + [0.0, 0.0, 2.0]
    ids = np.concatenate([300 + np.arange(32), 100 + np.arange(32)])
    pos = np.concatenate([near, far])
    body, x = kinect_joints(ids, pos)
    assert body == 3 and np.array_equal(x, near)
    body, x = kinect_joints(ids, pos, body_id=1)
    assert body == 1 and np.array_equal(x, far)
    assert kinect_joints(ids, pos, body_id=7)[0] is None
    # no pelvis markers: the bodies' mean positions decide
    body, x = kinect_joints(np.concatenate([ids[33:], ids[1:32]]),
                            np.concatenate([pos[33:], pos[1:32]]))
    assert body == 3 and np.isnan(x[0]).all() and np.array_equal(x[1:], near[1:])
    assert kinect_joints(np.zeros(0), np.zeros((0, 3)))[0] is None


def test_reading_a_joint_bag_checks_the_count(bags, tmp_path):
    with pytest.raises(ClothInputError, match='message 0 .* 33 poses, expected 32 joints'):
        read_joint_frames(bags['mediapipe33'], num_joints=32)
    with pytest.raises(ClothInputError, match='MarkerArray topic'):
        read_kinect_marker_frames(bags['kinect32'])
    with pytest.raises(ClothInputError, match=r'\(F, J, 3\)'):
        write_joint_bag(tmp_path / 'x', [0.0], np.zeros((1, 32, 7)))


@pytest.mark.parametrize('flags, named', [
    (['--skeleton', 'kinect32'], '--skeleton kinect32 needs --body-input joints'),
    (['--body-input', 'kinect_markers', '--skeleton', 'kinect32'],
     '--skeleton kinect32 needs --body-input joints'),
    (['--body-input', 'joints'], '--body-input joints needs --skeleton'),
    (['--body-input', 'joints', '--skeleton', 'zed34'], "--skeleton must be one of .*'zed34'"),
])
def test_bad_flag_combinations_are_named_before_any_work(tmp_path, capsys, flags, named):
    bvh = tmp_path / 'clip.bvh'  # never parsed: the flags are refused first
    bvh.write_text('not read')
    assert main(['from-bvh', str(bvh), str(tmp_path / 'out'), *flags]) == 2
    assert re.search(named, capsys.readouterr().err)
    assert not (tmp_path / 'out').exists()


def test_an_unknown_body_input_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(['from-bvh', str(RUN), str(tmp_path / 'out'), '--body-input', 'poses'])
    assert "--body-input: invalid choice: 'poses'" in capsys.readouterr().err


def test_a_frame_with_no_body_in_view_reads_at_its_receive_time(tmp_path):
    """The driver publishes an empty MarkerArray when no body is in view (every joint hidden
    here): it reads as a frame of NaN joints at the bag's receive time, no body chosen."""
    stamps = np.array([0.0, 1.0 / 30.0, 2.0 / 30.0])
    joints = np.tile(np.linspace(0.1, 1.0, 32)[:, None], (3, 1, 3))
    joints[1] = np.nan
    write_kinect_marker_bag(tmp_path / 'b', stamps, joints)
    got_stamps, got, body = read_kinect_marker_frames(tmp_path / 'b')
    assert np.allclose(got_stamps, stamps, rtol=0.0, atol=1e-9)
    assert np.isnan(got[1]).all() and body[1] == -1 and body[0] == body[2] == 1


def test_the_batchs_marker_bags_are_mcap(tmp_path):
    from cloth_mg_ros.io.bags import write_marker_bag

    faces = np.array([[0, 1, 2]])
    write_marker_bag(tmp_path / 'm', np.array([0.0, 0.1]), np.zeros((2, 3, 3)), faces)
    assert list((tmp_path / 'm').glob('*.mcap')) and not list((tmp_path / 'm').glob('*.db3'))
