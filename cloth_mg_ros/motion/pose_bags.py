"""BVH motion capture to pose bags (`cloth-mg bag from-bvh`, cli/bag.py).

`bag_from_bvh` reads the clip (dropping the T-pose frame 0 and all-zero frames), poses the avatar,
samples the motion at --rate Hz (joint rotations slerped, root translation interpolated linearly
between the clip's 120 Hz frames), holds the first pose still for --settle seconds before the
motion starts (so a garment can settle), and writes one message per frame with stamps from 0,
of the input kind asked for (`BODY_INPUTS`, the node's `body_input`):

- `segments` (default): geometry_msgs/PoseArray of the avatar's 16 segment poses;
- `joints`: geometry_msgs/PoseArray of a tracker layout's joints (`skeleton`: kinect32,
  mediapipe33, cmu31) in its order, where they lie on the posed avatar
  (`joint_body.joints_from_poses`), orientation the identity (io.bags.write_joint_bag);
- `kinect_markers`: visualization_msgs/MarkerArray of the kinect32 joints as the Azure Kinect
  ROS driver publishes body 1 on body_tracking_data (io.kinect_markers; header frame_id
  depth_camera_link unless --frame-id says otherwise, positions in the avatar's world frame).

The bag's metadata.yaml custom_data names the kind and, for joints, the layout
(`cloth_mg_ros.body_input`, `cloth_mg_ros.skeleton`; `cloth-mg bag info` prints them).

With a tracker view (`view`, motion.tracker_view: `--camera`, `--jitter-mm`, `--occlusion`,
`--seed`) the joints are written as a tracker would send them: in a camera's frame (x right,
y down, z forward), jittered, limb joints hidden in spans (NaN in a PoseArray; left out of a
MarkerArray); custom_data `cloth_mg_ros.input_transform` then holds the node's input_transform
(the camera's pose in the world).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import (
    BODY_INPUT_KEY,
    SKELETON_KEY,
    STORAGES,
    bag_info,
    write_joint_bag,
    write_pose_bag,
)
from cloth_mg_ros.io.kinect_markers import DEPTH_CAMERA_FRAME, write_kinect_marker_bag
from cloth_mg_ros.io.topic_names import is_absolute_topic
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.bvh import read_bvh
from cloth_mg_ros.motion.input_frame import BODY_INPUTS
from cloth_mg_ros.motion.joint_body import joints_from_poses, require_default_segments
from cloth_mg_ros.motion.skeletons import SKELETONS
from cloth_mg_ros.motion.tracker_view import TrackerView, tracker_joints, transform_text

__all__ = ['BODY_INPUTS', 'CMU_CREDIT', 'bag_from_bvh', 'sample_times']

KINECT_BODY_ID = 1  # the body id the marker bags carry (marker ids 100..131)

CMU_CREDIT = ('The data used in this project was obtained from mocap.cs.cmu.edu. The database '
              'was created with funding from NSF EIA-0196217.')


def sample_times(duration: float, rate: float, settle: float) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and motion times of a bag.

    Args:
        duration: clip length, s (last frame time).
        rate: output rate, Hz (> 0).
        settle: seconds of the first pose held still before the motion (>= 0).

    Returns:
        stamps (N,): k / rate, k = 0..N-1, s;
        motion (N,): the clip time shown at each stamp: 0 for the round(settle * rate) lead-in
        frames, then 0, 1/rate, ... up to the last sample not after `duration`.
    """
    n_settle = round(settle * rate)
    n_motion = math.floor(duration * rate + 1e-9) + 1
    motion = np.concatenate([np.zeros(n_settle), np.arange(n_motion) / rate])
    stamps = np.arange(n_settle + n_motion) / rate
    return stamps, motion


def _check_output(out: Path, force: bool) -> bool:
    """Validate the output path up front; True when an existing bag is to be replaced."""
    if not out.exists() and not out.is_symlink():
        if not out.parent.is_dir():
            raise ClothInputError(f'{out}: the parent directory {out.parent} does not exist')
        return False
    if not force:
        raise ClothInputError(f'{out}: output exists already (use --force to replace it)')
    if out.is_dir() and not out.is_symlink() and (
            (out / 'metadata.yaml').is_file() or not any(out.iterdir())):
        return True
    raise ClothInputError(f'{out}: exists and is not a rosbag2 bag directory (no metadata.yaml); '
                          'refusing to delete it even with --force')


def _check_body_input(body_input: str, skeleton: str | None) -> None:
    """ClothInputError naming the flag for a body input kind and layout that do not go
    together."""
    if body_input not in BODY_INPUTS:
        raise ClothInputError(f'--body-input must be one of {", ".join(BODY_INPUTS)}, got '
                              f'{body_input!r}')
    if body_input == 'joints' and skeleton is None:
        raise ClothInputError(f'--body-input joints needs --skeleton (one of '
                              f'{", ".join(SKELETONS)})')
    if body_input != 'joints' and skeleton is not None:
        raise ClothInputError(f'--skeleton {skeleton} needs --body-input joints, got '
                              f'--body-input {body_input} (segments are segment poses; '
                              f'kinect_markers are always kinect32)')
    if skeleton is not None and skeleton not in SKELETONS:
        raise ClothInputError(f'--skeleton must be one of {", ".join(SKELETONS)}, got '
                              f'{skeleton!r}')


def bag_from_bvh(bvh: str | Path, out: str | Path, *, rate: float = 30.0,
                 topic: str = '/avatar/body_poses', settle: float = 1.0,
                 avatar: str | Path | None = None, storage: str = 'mcap',
                 frame_id: str | None = None, force: bool = False, body_input: str = 'segments',
                 skeleton: str | None = None, view: TrackerView | None = None) -> dict:
    """Convert a BVH clip to a bag of body input (see the module docstring). frame_id: the
    header's (default 'world', for kinect_markers 'depth_camera_link'). Returns `bag_info` of
    the result plus 'source', 'clip_duration_s', 'settle_s', 'frames', 'segments',
    'body_input', 'skeleton' (the layout written, None for segments), 'poses' (poses or markers
    per message), 'bytes', and with a tracker `view` 'input_transform' (the camera's pose:
    the node's parameter).

    Raises:
        ClothInputError: missing or bad BVH, rate <= 0, settle < 0, unknown storage, an unknown
            body input or layout, --skeleton without --body-input joints (or joints without
            it), an existing output without `force`, a bad avatar file (joints and markers:
            one without the 16 default segments).
    """
    bvh, out = Path(bvh), Path(out)
    _check_arguments(bvh, rate, settle, storage, topic, body_input, skeleton, view)
    replace = _check_output(out, force)
    body = Avatar.load(avatar)
    if body_input != 'segments':
        require_default_segments(body)
    clip = read_bvh(bvh)
    stamps, motion = sample_times(clip.duration, float(rate), float(settle))
    poses = body.poses_from_clip(clip, times=motion)
    if replace:
        shutil.rmtree(out)
    layout = 'kinect32' if body_input == 'kinect_markers' else skeleton
    custom = _custom_data(body, bvh, rate, settle, body_input, layout)
    joints, camera = None, None
    if view is not None:
        joints, camera = tracker_joints(joints_from_poses(body, poses, layout), stamps,
                                        layout, view)
        custom['cloth_mg_ros.input_transform'] = transform_text(camera)
        custom['cloth_mg_ros.tracker_view'] = (f'jitter {1e3 * view.jitter_m:g} mm, occlusion '
                                               f'{view.occlusion:g}, seed {view.seed}')
        frame_id = 'camera' if frame_id is None and body_input == 'joints' else frame_id
    count = _write(out, stamps, poses, body, layout, body_input, topic=topic, frame_id=frame_id,
                   storage=storage, custom_data=custom, joints=joints)
    info = bag_info(out)
    info.update(source=str(bvh), clip_duration_s=clip.duration, settle_s=float(settle),
                frames=len(stamps), segments=body.num_segments, body_input=body_input,
                skeleton=layout, poses=count,
                **({} if camera is None else {'input_transform': camera.tolist()}),
                bytes=sum(p.stat().st_size for p in out.rglob('*') if p.is_file()))
    return info


def _check_arguments(bvh: Path, rate: float, settle: float, storage: str, topic: str,
                     body_input: str, skeleton: str | None, view: TrackerView | None) -> None:
    """ClothInputError naming the flag for an argument `bag_from_bvh` cannot use."""
    _check_body_input(body_input, skeleton)
    if view is not None and body_input == 'segments':
        raise ClothInputError('a tracker view (--camera, --jitter-mm, --occlusion) needs '
                              '--body-input joints or kinect_markers')
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ClothInputError(f'--rate must be a positive number of Hz, got {rate!r}')
    if not (isinstance(settle, (int, float)) and math.isfinite(settle) and settle >= 0):
        raise ClothInputError(f'--settle must be >= 0 s, got {settle!r}')
    if storage not in STORAGES:
        raise ClothInputError(f'--storage must be one of {", ".join(STORAGES)}, got {storage!r}')
    if not is_absolute_topic(topic):
        raise ClothInputError(f"--topic must be an absolute ROS topic name ('/', then "
                              f"/-separated parts of letters, digits and _), got {topic!r}")
    if not bvh.is_file():
        raise ClothInputError(f'{bvh}: BVH file not found')


def _custom_data(body: Avatar, bvh: Path, rate: float, settle: float, body_input: str,
                 layout: str | None) -> dict[str, str]:
    data = {
        BODY_INPUT_KEY: body_input,
        'cloth_mg_ros.segments': ','.join(body.names),
        'cloth_mg_ros.source': bvh.name,
        'cloth_mg_ros.avatar': Path(body.source).name,
        'cloth_mg_ros.rate_hz': f'{float(rate):g}',
        'cloth_mg_ros.settle_s': f'{float(settle):g}',
        'cloth_mg_ros.credit': CMU_CREDIT,
    }
    if layout is not None:
        del data['cloth_mg_ros.segments']  # the messages hold joints, not segments
        data[SKELETON_KEY] = layout
        data['cloth_mg_ros.joints'] = ','.join(SKELETONS[layout].joints)
    return data


def _write(out: Path, stamps: np.ndarray, poses: np.ndarray, body: Avatar, layout: str | None,
           body_input: str, *, topic: str, frame_id: str | None, storage: str,
           custom_data: dict[str, str], joints: np.ndarray | None = None) -> int:
    """Write the bag of the input kind; returns the poses (or markers) per message. joints:
    the joints to write (a tracker's view), None: the avatar's at the poses."""
    common = dict(topic=topic, storage=storage, custom_data=custom_data)
    world = 'world' if frame_id is None else frame_id
    if body_input == 'segments':
        write_pose_bag(out, stamps, poses, frame_id=world, **common)
        return body.num_segments
    if joints is None:
        joints = joints_from_poses(body, poses, layout)
    if body_input == 'joints':
        write_joint_bag(out, stamps, joints, frame_id=world, **common)
    else:
        write_kinect_marker_bag(out, stamps, joints, body_id=KINECT_BODY_ID,
                                frame_id=DEPTH_CAMERA_FRAME if frame_id is None else frame_id,
                                **common)
    return joints.shape[1]
