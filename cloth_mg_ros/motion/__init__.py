"""Human motion for the avatar: BVH motion capture, the capsule avatar, bag conversion.

- `bvh`: `read_bvh(path) -> BvhClip` (validated; lengths in metres) and
  `forward_kinematics(clip) -> (rotations (F, J, 3, 3), positions (F, J, 3))` in ROS axes
  (z up, x = the BVH's +Z walking direction, y = BVH +X, the subject's left).
- `avatar`: `Avatar.load()` (config/avatar.yaml), `poses_from_clip(clip) -> (F, S, 7)` poses
  [x, y, z, qx, qy, qz, qw], `capsules(poses) -> (p0, p1, radius)`, `rest_poses()`.
- `rotations`: quaternions and rigid moves of poses; `frames`: pose-frame checks.
- `skeletons`: body trackers' joint layouts (kinect32, mediapipe33, cmu31) as data;
  `joint_body`: `poses_from_joints(joints, skeleton) -> (poses, valid)`, the inverse
  `joints_from_poses`; `body_size`: `avatar_from_joints` (an avatar sized to the subject).
- `config_path(name)` / `share_path(...)` (from `cloth_mg_ros.io.share`) find packaged files in
  the source tree or the installed share/cloth_mg_ros.
- `pose_bags`: `bag_from_bvh`, a BVH clip sampled into a bag of body poses.
"""

from cloth_mg_ros.io.share import config_path, share_path
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.bvh import BvhClip, forward_kinematics, read_bvh

__all__ = ['Avatar', 'BvhClip', 'config_path', 'forward_kinematics', 'read_bvh', 'share_path']
