"""BVH motion capture to pose bags (`cloth-mg bag from-bvh`, cli/bag.py).

`bag_from_bvh` reads the clip (dropping the T-pose frame 0 and all-zero frames), poses the avatar,
samples the motion at --rate Hz (joint rotations slerped, root translation interpolated linearly
between the clip's 120 Hz frames), holds the first pose still for --settle seconds before the
motion starts (so a garment can settle), and writes one PoseArray per frame with stamps from 0.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import STORAGES, bag_info, write_pose_bag
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.bvh import read_bvh

__all__ = ['CMU_CREDIT', 'bag_from_bvh', 'sample_times']

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


def bag_from_bvh(bvh: str | Path, out: str | Path, *, rate: float = 30.0,
                 topic: str = '/avatar/body_poses', settle: float = 1.0,
                 avatar: str | Path | None = None, storage: str = 'mcap',
                 frame_id: str = 'world', force: bool = False) -> dict:
    """Convert a BVH clip to a pose bag (see the module docstring). Returns `bag_info` of the
    result plus 'source', 'clip_duration_s', 'settle_s', 'frames', 'segments', 'bytes'.

    Raises:
        ClothInputError: missing or bad BVH, rate <= 0, settle < 0, unknown storage, an existing
            output without `force`, a bad avatar file.
    """
    bvh, out = Path(bvh), Path(out)
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ClothInputError(f'--rate must be a positive number of Hz, got {rate!r}')
    if not (isinstance(settle, (int, float)) and math.isfinite(settle) and settle >= 0):
        raise ClothInputError(f'--settle must be >= 0 s, got {settle!r}')
    if storage not in STORAGES:
        raise ClothInputError(f'--storage must be one of {", ".join(STORAGES)}, got {storage!r}')
    if not topic.startswith('/'):
        raise ClothInputError(f'--topic must be an absolute topic name, got {topic!r}')
    if not bvh.is_file():
        raise ClothInputError(f'{bvh}: BVH file not found')
    replace = _check_output(out, force)
    body = Avatar.load(avatar)
    clip = read_bvh(bvh)
    stamps, motion = sample_times(clip.duration, float(rate), float(settle))
    poses = body.poses_from_clip(clip, times=motion)
    if replace:
        shutil.rmtree(out)
    write_pose_bag(out, stamps, poses, topic=topic, frame_id=frame_id, storage=storage,
                   custom_data={
                       'cloth_mg_ros.segments': ','.join(body.names),
                       'cloth_mg_ros.source': bvh.name,
                       'cloth_mg_ros.avatar': Path(body.source).name,
                       'cloth_mg_ros.rate_hz': f'{float(rate):g}',
                       'cloth_mg_ros.settle_s': f'{float(settle):g}',
                       'cloth_mg_ros.credit': CMU_CREDIT,
                   })
    info = bag_info(out)
    info.update(source=str(bvh), clip_duration_s=clip.duration, settle_s=float(settle),
                frames=len(stamps), segments=body.num_segments,
                bytes=sum(p.stat().st_size for p in out.rglob('*') if p.is_file()))
    return info
