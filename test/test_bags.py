"""Pose bags: write/read round trips, bag_info, bad bags, frame checks, the bundled bags and the
`bag` command line."""

from __future__ import annotations

import argparse
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

from cloth_mg_ros.cli.bag import add_bag_parser, main, run_bag_command
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import (
    DEFAULT_TOPIC,
    bag_info,
    bundled_bag,
    iter_pose_frames,
    read_pose_frames,
    write_pose_bag,
)
from cloth_mg_ros.motion.avatar import SEGMENT_NAMES
from cloth_mg_ros.motion.frames import FrameStatus, check_frame
from cloth_mg_ros.motion.pose_bags import CMU_CREDIT

MOCAP = Path(__file__).resolve().parent / 'data' / 'mocap'  # the CMU clips
BUNDLED = {'walk': ('07_01.bvh', 109), 'brisk_walk': ('07_12.bvh', 96),
           'run': ('09_01.bvh', 67), 'jump': ('02_04.bvh', 151)}


def _random_poses(frames=6, segments=16, seed=0):
    rng = np.random.default_rng(seed)
    poses = rng.normal(size=(frames, segments, 7))
    poses[..., 3:] /= np.linalg.norm(poses[..., 3:], axis=-1, keepdims=True)
    return poses


# ------------------------------------------------------------------------------------------
# Round trips and info


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_round_trip(tmp_path, storage):
    poses = _random_poses()
    stamps = np.array([0.0, 0.1, 0.2, 0.3, 1.25, 2.5])
    out = write_pose_bag(tmp_path / 'bag', stamps, poses, storage=storage)
    assert (out / 'metadata.yaml').is_file()
    frames = read_pose_frames(out)
    assert len(frames) == len(stamps)
    for (stamp, got), want_stamp, want in zip(frames, stamps, poses, strict=True):
        assert stamp == pytest.approx(want_stamp, abs=1e-9)
        assert got.dtype == np.float64 and got.shape == (16, 7)
        assert np.array_equal(got, want)  # float64 end to end
    info = bag_info(out)
    assert info['storage'] == storage
    assert info['topics'] == {DEFAULT_TOPIC: {'type': 'geometry_msgs/msg/PoseArray', 'count': 6,
                                              'rate_hz': pytest.approx(5 / 2.5)}}
    assert info['message_count'] == 6
    assert info['duration_s'] == pytest.approx(2.5)
    assert info['start_s'] == 0.0


def test_bag_info_rate_and_custom_data(tmp_path):
    stamps = np.arange(31) / 30.0
    out = write_pose_bag(tmp_path / 'bag', stamps, _random_poses(31), topic='/body',
                         custom_data={'source': 'x.bvh'})
    info = bag_info(out)
    assert info['rate_hz'] == pytest.approx(30.0, rel=1e-6)
    assert info['duration_s'] == pytest.approx(1.0)
    assert info['topics']['/body']['count'] == 31
    assert info['custom_data'] == {'source': 'x.bvh'}
    assert len(read_pose_frames(out, topic='/body')) == 31
    # the iterator checks the bag before the first frame is asked for
    with pytest.raises(ClothInputError):
        iter_pose_frames(out)


def test_bag_without_the_topic_lists_topics(tmp_path):
    out = write_pose_bag(tmp_path / 'bag', [0.0], _random_poses(1), topic='/other/poses')
    with pytest.raises(ClothInputError) as info:
        read_pose_frames(out)
    message = str(info.value)
    assert "no topic '/avatar/body_poses'" in message
    assert '/other/poses [geometry_msgs/msg/PoseArray]' in message


def test_topic_of_another_type(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    path = tmp_path / 'strings'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(DEFAULT_TOPIC, 'std_msgs/msg/String', typestore=ts)
        msg = ts.types['std_msgs/msg/String'](data='hello')
        writer.write(conn, 0, ts.serialize_cdr(msg, 'std_msgs/msg/String'))
    with pytest.raises(ClothInputError, match='has type std_msgs/msg/String, expected '
                                              'geometry_msgs/msg/PoseArray'):
        read_pose_frames(path)
    assert bag_info(path)['topics'][DEFAULT_TOPIC]['type'] == 'std_msgs/msg/String'


def test_missing_and_unreadable_bags(tmp_path):
    with pytest.raises(ClothInputError, match='bag not found'):
        read_pose_frames(tmp_path / 'nope')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(ClothInputError, match='no metadata.yaml'):
        bag_info(tmp_path / 'empty')
    broken = tmp_path / 'broken'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text('rosbag2_bagfile_information: {version: 9}\n')
    with pytest.raises(ClothInputError, match='cannot read bag'):
        read_pose_frames(broken)


def test_write_validation(tmp_path):
    poses = _random_poses(3)
    with pytest.raises(ClothInputError, match='stamps go backwards at frame 2'):
        write_pose_bag(tmp_path / 'a', [0.0, 0.2, 0.1], poses)
    with pytest.raises(ClothInputError, match=r'shape \(F, S, 7\)'):
        write_pose_bag(tmp_path / 'b', [0.0, 0.1, 0.2], poses[..., :6])
    bad = poses.copy()
    bad[1, 3, 2] = np.nan
    with pytest.raises(ClothInputError, match='frame 1 are not finite'):
        write_pose_bag(tmp_path / 'c', [0.0, 0.1, 0.2], bad)
    with pytest.raises(ClothInputError, match='storage'):
        write_pose_bag(tmp_path / 'd', [0.0, 0.1, 0.2], poses, storage='rosbag1')
    write_pose_bag(tmp_path / 'e', [0.0, 0.1, 0.2], poses)
    with pytest.raises(ClothInputError, match='exists already'):
        write_pose_bag(tmp_path / 'e', [0.0, 0.1, 0.2], poses)


# ------------------------------------------------------------------------------------------
# Frame checks


def test_check_frame_classifications():
    poses = _random_poses(2)
    a, b = poses[0], poses[0].copy()
    b[:, :3] += 0.05
    assert check_frame(None, 0.0, a, 16) == FrameStatus.OK == 'ok'
    assert check_frame(0.0, 0.033, b, 16, a) == FrameStatus.OK
    assert check_frame(0.0, 0.033, np.zeros((0, 7)), 16, a) == FrameStatus.EMPTY
    assert check_frame(0.0, 0.033, b[:15], 16, a) == FrameStatus.WRONG_COUNT
    assert check_frame(0.0, 0.033, b[:, :6], 16, a) == FrameStatus.WRONG_COUNT
    nan = b.copy()
    nan[4, 1] = np.nan
    assert check_frame(0.0, 0.033, nan, 16, a) == FrameStatus.NON_FINITE
    assert check_frame(0.0, float('inf'), b, 16, a) == FrameStatus.NON_FINITE
    zero_q = b.copy()
    zero_q[2, 3:] = 0.0
    assert check_frame(0.0, 0.033, zero_q, 16, a) == FrameStatus.NON_FINITE
    assert check_frame(0.5, 0.4, b, 16, a) == FrameStatus.STAMP_BACKWARDS
    assert check_frame(0.5, 0.5, b, 16, a) == FrameStatus.STAMP_BACKWARDS
    far = b.copy()
    far[7, :3] += [1.2, 0.0, 0.0]
    assert check_frame(0.0, 0.033, far, 16, a) == FrameStatus.TELEPORT
    assert check_frame(0.0, 0.033, far, 16, a, teleport_m=2.0) == FrameStatus.OK
    assert check_frame(0.0, 0.033, far, 16, None) == FrameStatus.OK


# ------------------------------------------------------------------------------------------
# The bundled bags


@pytest.mark.parametrize('name', list(BUNDLED))
def test_bundled_bags(name):
    source, count = BUNDLED[name]
    path = bundled_bag(name)
    assert path.name == name and (path / 'metadata.yaml').is_file()
    assert (path / f'{name}.mcap').is_file()
    size = sum(p.stat().st_size for p in path.iterdir())
    assert size < 400_000
    info = bag_info(path)
    assert info['storage'] == 'mcap'
    assert info['message_count'] == count
    assert info['rate_hz'] == pytest.approx(30.0, rel=1e-6)
    assert info['custom_data']['cloth_mg_ros.segments'] == ','.join(SEGMENT_NAMES)
    assert info['custom_data']['cloth_mg_ros.source'] == source
    assert info['custom_data']['cloth_mg_ros.credit'] == CMU_CREDIT
    frames = read_pose_frames(path)
    stamps = np.array([s for s, _ in frames])
    poses = np.stack([p for _, p in frames])
    assert poses.shape == (count, 16, 7)
    assert stamps[0] == 0.0
    assert np.allclose(np.diff(stamps), 1 / 30, atol=1e-9)
    assert info['duration_s'] == pytest.approx(stamps[-1])
    # settle lead-in: 1 s (30 frames) of the first pose, then the motion starts from it
    assert np.all(poses[:31] == poses[0])
    assert not np.allclose(poses[31], poses[0])
    assert np.allclose(np.linalg.norm(poses[..., 3:], axis=-1), 1.0)
    status = [check_frame(s0, s1, p1, 16, p0) for (s0, p0), (s1, p1) in pairwise(frames)]
    assert set(status) == {FrameStatus.OK}


def test_bundled_walk_is_up_to_date(tmp_path):
    assert main(['from-bvh', str(MOCAP / '07_01.bvh'), str(tmp_path / 'walk')]) == 0
    fresh = read_pose_frames(tmp_path / 'walk')
    shipped = read_pose_frames(bundled_bag('walk'))
    assert len(fresh) == len(shipped)
    for (s0, p0), (s1, p1) in zip(fresh, shipped, strict=True):
        assert s0 == s1
        assert np.allclose(p0, p1, atol=1e-9)


# ------------------------------------------------------------------------------------------
# Command line


def test_cli_from_bvh_and_info(tmp_path, capsys):
    out = tmp_path / 'run'
    code = main(['from-bvh', str(MOCAP / '09_01.bvh'), str(out), '--rate', '20', '--settle',
                 '0.5', '--topic', '/body', '--storage', 'sqlite3'])
    assert code == 0
    assert 'wrote' in capsys.readouterr().out
    info = bag_info(out)
    assert info['storage'] == 'sqlite3'
    # 0.5 s * 20 Hz = 10 settle frames + floor(1.225 s * 20) + 1 = 25 motion frames
    assert info['topics']['/body']['count'] == 35
    assert info['rate_hz'] == pytest.approx(20.0, rel=1e-6)
    assert info['duration_s'] == pytest.approx(34 / 20)
    assert main(['info', str(out)]) == 0
    printed = capsys.readouterr().out
    assert '/body' in printed and '35 messages' in printed and '20.00 Hz' in printed
    # the output exists: refused without --force, replaced with it
    assert main(['from-bvh', str(MOCAP / '09_01.bvh'), str(out)]) == 2
    assert 'exists already' in capsys.readouterr().err
    assert main(['from-bvh', str(MOCAP / '09_01.bvh'), str(out), '--force']) == 0
    assert bag_info(out)['storage'] == 'mcap'


def test_cli_errors_up_front(tmp_path, capsys):
    bvh = tmp_path / 'clip.bvh'  # never parsed: every error below comes before reading it
    bvh.write_text('not read')
    assert main(['from-bvh', str(bvh), str(tmp_path / 'a'), '--rate', '0']) == 2
    assert '--rate must be a positive' in capsys.readouterr().err
    assert main(['from-bvh', str(bvh), str(tmp_path / 'a'), '--rate', '-5']) == 2
    assert main(['from-bvh', str(bvh), str(tmp_path / 'a'), '--settle', '-1']) == 2
    assert '--settle' in capsys.readouterr().err
    assert main(['from-bvh', str(tmp_path / 'none.bvh'), str(tmp_path / 'a')]) == 2
    assert 'BVH file not found' in capsys.readouterr().err
    precious = tmp_path / 'precious'
    precious.mkdir()
    (precious / 'notes.txt').write_text('keep me')
    assert main(['from-bvh', str(bvh), str(precious), '--force']) == 2
    assert 'refusing to delete' in capsys.readouterr().err
    assert (precious / 'notes.txt').read_text() == 'keep me'
    assert main(['info', str(tmp_path / 'nothing')]) == 2
    assert not (tmp_path / 'a').exists()


def test_add_bag_parser_hooks_into_a_parent_cli(tmp_path, capsys):
    parser = argparse.ArgumentParser(prog='cloth-mg')
    sub = parser.add_subparsers(dest='command', required=True)
    add_bag_parser(sub)
    args = parser.parse_args(['bag', 'info', str(bundled_bag('run'))])
    assert args.command == 'bag'
    assert run_bag_command(args) == 0
    assert '67 messages' in capsys.readouterr().out
    args = parser.parse_args(['bag', 'from-bvh', 'in.bvh', 'out'])
    assert (args.rate, args.topic, args.settle, args.avatar, args.force) == (
        30.0, '/avatar/body_poses', 1.0, None, False)
