"""`cloth-mg bag ...`: convert BVH motion capture to pose bags, and summarise bags.

    cloth-mg bag from-bvh IN.bvh OUT [--rate 30] [--topic /avatar/body_poses] [--settle 1.0]
                          [--avatar PATH] [--storage mcap|sqlite3] [--frame-id world] [--force]
                          [--body-input segments|joints|kinect_markers]
                          [--skeleton kinect32|mediapipe33|cmu31]
    cloth-mg bag info BAG

Standalone: `python -m cloth_mg_ros.cli.bag from-bvh ...` / `... info BAG`. The conversion is
`motion.pose_bags.bag_from_bvh` (its docstring says what it samples and what each
--body-input writes: segment poses, a layout's joints as a PoseArray, or the Azure Kinect
driver's MarkerArray).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.pose_bags import BODY_INPUTS, bag_from_bvh

__all__ = ['add_bag_parser', 'main', 'run_bag_command']


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
    f.add_argument('--frame-id', default=None,
                   help='header.frame_id (default world; kinect_markers: depth_camera_link)')
    f.add_argument('--body-input', default='segments', choices=BODY_INPUTS,
                   help='segments: PoseArray of the 16 segment poses (default); joints: '
                   'PoseArray of the --skeleton layout\'s joint positions; kinect_markers: '
                   'MarkerArray of the kinect32 joints as the Azure Kinect ROS driver '
                   'publishes body 1')
    f.add_argument('--skeleton', default=None,
                   help='joint layout for --body-input joints: kinect32, mediapipe33 or cmu31')
    f.add_argument('--camera', default=None,
                   help='a tracker\'s view (joints, kinect_markers): the joints in this '
                   'camera\'s frame (x right, y down, z forward): front (3 m in front of the '
                   'subject, 1 m up) or its pose in the world x,y,z,qx,qy,qz,qw')
    f.add_argument('--jitter-mm', type=float, default=None,
                   help='a tracker\'s view: Gaussian jitter per joint and axis, mm (default 2)')
    f.add_argument('--occlusion', type=float, default=None,
                   help='a tracker\'s view: share of the limb joints\' samples hidden in spans '
                   'of 0.1-0.8 s (default 0.05)')
    f.add_argument('--seed', type=int, default=0, help='a tracker\'s view: the noise\'s seed')
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


def _view(args: argparse.Namespace):
    """The tracker view the flags ask for (None: none of them given)."""
    if args.camera is None and args.jitter_mm is None and args.occlusion is None:
        return None
    # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
    from cloth_mg_ros.motion.tracker_view import TrackerView

    camera = None
    if args.camera not in (None, 'front'):
        try:
            camera = tuple(float(v) for v in args.camera.split(','))
        except ValueError:
            raise ClothInputError(f'--camera must be front or x,y,z,qx,qy,qz,qw, got '
                                  f'{args.camera!r}') from None
    return TrackerView(camera, 2e-3 if args.jitter_mm is None else 1e-3 * args.jitter_mm,
                       0.05 if args.occlusion is None else args.occlusion, args.seed)


def run_bag_command(args: argparse.Namespace) -> int:
    """Run `bag from-bvh` or `bag info` from parsed arguments. Returns 0; raises
    ClothInputError on bad input (the caller prints it)."""
    if args.bag_command == 'from-bvh':
        info = bag_from_bvh(args.bvh, args.out, rate=args.rate, topic=args.topic,
                            settle=args.settle, avatar=args.avatar, storage=args.storage,
                            frame_id=args.frame_id, force=args.force,
                            body_input=args.body_input, skeleton=args.skeleton,
                            view=_view(args))
        what = {'segments': 'poses', 'joints': f'{info["skeleton"]} joints',
                'kinect_markers': f'{info["skeleton"]} joint markers'}[info['body_input']]
        print(f"wrote {info['path']} ({info['storage']}, {info['bytes'] / 1024:.0f} KiB): "
              f"{info['frames']} messages of {info['poses']} {what} on {args.topic} at "
              f"{args.rate:g} Hz, {info['duration_s']:.3f} s = {info['settle_s']:g} s settle + "
              f"{info['clip_duration_s']:.3f} s of {Path(args.bvh).name}")
        return 0
    if args.bag_command == 'info':
        # imported here: a subcommand's modules load when it runs (cloth-mg starts fast)
        from cloth_mg_ros.io.bags import bag_info

        _print_info(bag_info(args.bag))
        return 0
    raise ClothInputError(f'unknown bag command {args.bag_command!r}')


def build_parser() -> argparse.ArgumentParser:
    """The standalone parser: `python -m cloth_mg_ros.cli.bag {from-bvh,info} ...`."""
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
