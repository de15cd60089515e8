"""`cloth-mg bag ...`: convert BVH motion capture to pose bags, and summarise bags.

    cloth-mg bag from-bvh IN.bvh OUT [--rate 30] [--topic /avatar/body_poses] [--settle 1.0]
                          [--avatar PATH] [--storage mcap|sqlite3] [--frame-id world] [--force]
    cloth-mg bag info BAG

Standalone: `python -m cloth_mg_ros.motion.bag_cli from-bvh ...` / `... info BAG`.

from-bvh reads the clip (dropping the T-pose frame 0 and all-zero frames), poses the avatar,
samples the motion at --rate Hz (joint rotations slerped, root translation interpolated linearly
between the clip's 120 Hz frames), holds the first pose still for --settle seconds before the
motion starts (so a garment can settle), and writes one PoseArray per frame with stamps from 0.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = ['CMU_CREDIT', 'add_bag_parser', 'bag_from_bvh', 'main', 'run_bag_command',
           'sample_times']

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
    from cloth_mg_ros.bags import STORAGES, bag_info, write_pose_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.motion.bvh import read_bvh

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


# --------------------------------------------------------------------------------------------
# Command line


def _add_subcommands(sub: argparse._SubParsersAction) -> None:
    f = sub.add_parser('from-bvh', help='convert a BVH clip to a rosbag2 bag of avatar body '
                       'poses (geometry_msgs/PoseArray)')
    f.add_argument('bvh', metavar='IN.bvh', help='BVH motion capture clip')
    f.add_argument('out', metavar='OUT', help='bag directory to create')
    f.add_argument('--rate', type=float, default=30.0, help='output rate, Hz (default 30)')
    f.add_argument('--topic', default='/avatar/body_poses', help='topic name')
    f.add_argument('--settle', type=float, default=1.0,
                   help='seconds of the first pose held still before the motion (default 1.0)')
    f.add_argument('--avatar', default=None,
                   help='avatar YAML (default: the packaged config/avatar.yaml)')
    f.add_argument('--storage', default='mcap', choices=['mcap', 'sqlite3'],
                   help='bag storage (default mcap)')
    f.add_argument('--frame-id', default='world', help='header.frame_id (default world)')
    f.add_argument('--force', action='store_true', help='replace an existing output bag')
    i = sub.add_parser('info', help='topics, message counts, rate and duration of a bag')
    i.add_argument('bag', metavar='BAG', help='bag directory (or .mcap / .db3 file)')


def add_bag_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add `bag` (with `from-bvh` and `info`) to a parent parser's subparsers; dispatch the
    parsed arguments with `run_bag_command`."""
    p = subparsers.add_parser('bag', help='motion capture to rosbag2 bags of body poses; bag info')
    sub = p.add_subparsers(dest='bag_command', required=True)
    _add_subcommands(sub)
    return p


def _print_info(info: dict) -> None:
    print(f"{info['path']} ({info['storage']}): {info['message_count']} messages, "
          f"{info['duration_s']:.3f} s, {info['rate_hz']:.2f} Hz")
    for name, t in info['topics'].items():
        print(f"  {name}  {t['type']}  {t['count']} messages  {t['rate_hz']:.2f} Hz")
    for key, value in info.get('custom_data', {}).items():
        print(f'  {key}: {value}')


def run_bag_command(args: argparse.Namespace) -> int:
    """Run `bag from-bvh` or `bag info` from parsed arguments. Returns 0; raises
    ClothInputError on bad input (the caller prints it)."""
    if args.bag_command == 'from-bvh':
        info = bag_from_bvh(args.bvh, args.out, rate=args.rate, topic=args.topic,
                            settle=args.settle, avatar=args.avatar, storage=args.storage,
                            frame_id=args.frame_id, force=args.force)
        print(f"wrote {info['path']} ({info['storage']}, {info['bytes'] / 1024:.0f} KiB): "
              f"{info['frames']} messages of {info['segments']} poses on {args.topic} at "
              f"{args.rate:g} Hz, {info['duration_s']:.3f} s = {info['settle_s']:g} s settle + "
              f"{info['clip_duration_s']:.3f} s of {Path(args.bvh).name}")
        return 0
    if args.bag_command == 'info':
        from cloth_mg_ros.bags import bag_info

        _print_info(bag_info(args.bag))
        return 0
    raise ClothInputError(f'unknown bag command {args.bag_command!r}')


def build_parser() -> argparse.ArgumentParser:
    """The standalone parser: `python -m cloth_mg_ros.motion.bag_cli {from-bvh,info} ...`."""
    parser = argparse.ArgumentParser(prog='cloth-mg bag', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest='bag_command', required=True)
    _add_subcommands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point; prints ClothInputError messages and returns 2 for them."""
    args = build_parser().parse_args(argv)
    try:
        return run_bag_command(args)
    except ClothInputError as exc:
        print(f'cloth-mg bag: error: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
