"""Bodies from joint positions: a body tracker's joints -> the capsule avatar's segment poses, and
an avatar sized to the subject.

A capsule needs only its two end points and a radius, so joint positions are enough to place the
collider; orientations are not input. `poses_from_joints` turns positions (F, J, 3) of a layout
(`cloth_mg_ros.motion.skeletons`: kinect32, mediapipe33, cmu31) in a z-up world frame (m) into
segment poses (F, 16, 7) in exactly the avatar's convention (`cloth_mg_ros.motion.avatar`: the
segment's proximal joint and the quaternion of R_world(joint) @ R0[s]), so capsules, garments and
the collider use them unchanged. `joints_from_poses` is the inverse: where a layout's joints lie on
a posed avatar (to write joint streams from BVH clips, and for the tests).

How each segment's frame B (the joint's world rotation, the world's axes at rest) is found: one
direction between two landmarks fixes the segment's axis exactly (B @ a0 = a, a0 the same
landmarks' difference in the avatar's zero pose, CMU T-pose), a second one sets the twist about it
(a TRIAD frame):

- pelvis: the hip line (right -> left hip); twist from the pelvis joint above the hips (kinect32,
  cmu31) or else the trunk (hips' centre -> neck, or -> the shoulders' centre);
- lower torso: pelvis -> spine (kinect32 spine_navel, cmu31 Spine) or else -> neck (the chord of
  the spine); twist halfway between the pelvis's and the upper torso's;
- upper torso: the shoulder line; twist from chest -> neck (kinect32), shoulders' centre -> neck
  (cmu31 as the avatar places it; where the neck joint is below the shoulders' line, as in the
  raw CMU skeleton, spine -> neck) or else the trunk (mediapipe33);
- head: the ear line; twist from the nose. Without ears (cmu31): base of the neck -> base of the
  skull, twist from the upper torso;
- upper arm, thigh: shoulder -> elbow, hip -> knee; twist from the plane of the bend at the next
  joint (elbow, knee), whose hinge axis is fixed in the limb (the CMU skeleton's elbow flexes
  toward `ELBOW_FLEXION`, its knee toward `KNEE_FLEXION`, in the T-pose; exact hinges in every
  bundled clip);
- forearm, shank: the elbow and the knee are hinges, so the forearm is the upper arm turned about
  the elbow onto elbow -> wrist, the shank the thigh turned about the knee onto knee -> ankle
  (the CMU skeleton twists the hand at the wrist, so the hand does not show the forearm's twist);
- hand: wrist -> fingertips (or knuckles); twist from across the palm (index -> pinky) or the
  thumb, else the forearm's;
- foot: ankle -> toe (or ball); twist from the heel (mediapipe33) or the ankle's bend (shank x
  foot, a hinge in the CMU skeleton), else the shank's.

A twist reference that vanishes (a straight limb, a point on the axis) blends smoothly into the
parent's frame swung onto the new axis (the smallest rotation), so the frame never flips.
Landmarks a layout lacks are derived from the frames and the avatar's rest offsets: the pelvis
joint from the hips, the base of the neck from the shoulders, the base of the skull from the
ears.

Bad input: a wrong number of joints or coordinates raises ClothInputError naming the layout and
the shape. Non-finite coordinates are missing joints: the segments that need them come out NaN
and False in the validity mask (F, 16) that `poses_from_joints` returns with the poses.

The frames are solved one frame at a time by the numba kernels of
`cloth_mg_ros.motion.joint_frames` (nogil; a call with one to three frames takes tens of
microseconds, the live node makes one per tick).

Sizing the avatar to the subject: `cloth_mg_ros.motion.body_size`.
"""

from __future__ import annotations

import functools
import weakref

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import SEGMENT_NAMES, Avatar
from cloth_mg_ros.motion.joint_frames import MARKS, solve_poses
from cloth_mg_ros.motion.skeletons import LANDMARKS, Skeleton, get_skeleton

__all__ = [
    'ELBOW_FLEXION',
    'KNEE_FLEXION',
    'joints_from_poses',
    'landmark_points',
    'landmarks_from_joints',
    'packaged_avatar',
    'poses_from_joints',
    'require_default_segments',
    'rest_landmarks',
    'zero_pose',
]

#: Direction (rest frame, unit) the forearm swings toward as the elbow flexes from the T-pose:
#: forward and 30 deg up, both sides. The CMU skeleton's elbow is a hinge about upper-arm axis
#: (0.5, 0, -0.866) left, (-0.5, 0, 0.866) right (0.0 deg spread over the four bundled clips).
ELBOW_FLEXION = np.array([np.cos(np.radians(30.0)), 0.0, np.sin(np.radians(30.0))])
#: Direction (rest frame) the shank swings toward as the knee flexes: backward (CMU hinge
#: axis (0, 0.940, +-0.342), at right angles to the splayed thighs).
KNEE_FLEXION = np.array([-1.0, 0.0, 0.0])

_REQUIRED = ('hip_l', 'hip_r', 'knee_l', 'knee_r', 'ankle_l', 'ankle_r', 'shoulder_l',
             'shoulder_r', 'elbow_l', 'elbow_r', 'wrist_l', 'wrist_r')
_FLEXION = np.stack([ELBOW_FLEXION, KNEE_FLEXION])


# --------------------------------------------------------------------------------------------
# Landmarks on a posed avatar


def require_default_segments(avatar: Avatar) -> None:
    """ClothInputError unless the avatar has the 16 default segments (the joint input and the
    sizing name them)."""
    if tuple(avatar.names) != SEGMENT_NAMES:
        raise ClothInputError(f'{avatar.source}: joint input needs the 16 default segments '
                              f'({", ".join(SEGMENT_NAMES)}), got {", ".join(avatar.names)}')


def landmark_points(avatar: Avatar, poses: np.ndarray, names=None) -> dict[str, np.ndarray]:
    """Landmarks (`skeletons.LANDMARKS`) of the avatar posed by `poses` (..., 16, 7).

    Returns:
        {name: (..., 3) world position, m} for `names` (default: every landmark).
    """
    require_default_segments(avatar)
    unknown = sorted(set(names or ()) - set(LANDMARKS))
    if unknown:
        raise ClothInputError(f'unknown landmarks {unknown} (known: {", ".join(LANDMARKS)})')
    poses = np.asarray(poses, dtype=float)
    origin = poses[..., :3]
    body = avatar.body_rotations(poses)
    index = {n: i for i, n in enumerate(avatar.names)}
    out: dict[str, np.ndarray] = {}

    def place(name: str) -> np.ndarray:
        if name in out:
            return out[name]
        spec = LANDMARKS[name]
        kind = spec[0]
        if kind == 'origin':
            p = origin[..., index[spec[1]], :]
        elif kind == 'bone':
            seg = avatar.segments[index[spec[1]]]
            p = origin[..., seg.parent, :]
            for via, vec in seg.bone[:spec[2] + 1]:
                carriers = [i for i, s in enumerate(avatar.segments) if s.joint == via]
                if not carriers:
                    raise ClothInputError(f'{avatar.source}: landmark {name!r}: bone joint '
                                          f'{via!r} orients no segment')
                p = p + body[..., carriers[0], :, :] @ vec
        elif kind == 'capsule':
            s = index[spec[1]]
            t, e, w = spec[2], spec[3], np.asarray(spec[4], dtype=float)
            seg = avatar.segments[s]
            d = seg.p1 - seg.p0
            u = d / max(float(np.linalg.norm(d)), 1e-12)
            local = seg.p0 + t * d + seg.radius * (e * u + w)
            p = origin[..., s, :] + body[..., s, :, :] @ local
        else:  # lerp
            a, b = place(spec[1]), place(spec[2])
            p = a + spec[3] * (b - a)
        out[name] = p
        return p

    for name in (LANDMARKS if names is None else names):
        place(name)
    return {n: out[n] for n in (LANDMARKS if names is None else names)}


def zero_pose(avatar: Avatar) -> np.ndarray:
    """(1, 16, 7) poses of the avatar's rest (zero-rotation, CMU T-) pose, pelvis at the origin."""
    joints = {s.joint for s in avatar.segments} | {v for s in avatar.segments for v, _ in s.bone}
    return avatar.poses_from_rotations(np.zeros((1, 3)), {j: np.eye(3)[None] for j in joints})


_REST: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@functools.lru_cache(maxsize=1)
def packaged_avatar() -> Avatar:
    """The packaged avatar (config/avatar.yaml), read once: a tracker's stream calls per
    message."""
    return Avatar.load()


def rest_landmarks(avatar: Avatar) -> dict[str, np.ndarray]:
    """{landmark: (3,) m} on the avatar's zero pose (CMU T-pose, pelvis joint at the origin,
    body frames the world's axes); cached per avatar (an avatar does not change)."""
    rest = _REST.get(avatar)
    if rest is None:
        rest = {k: v[0] for k, v in landmark_points(avatar, zero_pose(avatar)).items()}
        _REST[avatar] = rest
    return rest


def joints_from_poses(avatar: Avatar, poses: np.ndarray, skeleton: str | Skeleton
                      ) -> np.ndarray:
    """Where the joints of `skeleton` lie on the avatar posed by `poses` (..., 16, 7).

    Returns:
        (..., J, 3) joint positions, m, in the layout's order.
    """
    sk = get_skeleton(skeleton)
    marks = landmark_points(avatar, poses, sorted(set(sk.landmarks)))
    return np.stack([marks[m] for m in sk.landmarks], axis=-2)


# --------------------------------------------------------------------------------------------
# Joints -> poses (the frames: `joint_frames`, numba kernels over frames)


def _check_joints(joints, sk: Skeleton) -> tuple[np.ndarray, bool]:
    try:
        x = np.asarray(joints, dtype=float)
    except (TypeError, ValueError):
        raise ClothInputError(f'skeleton {sk.name!r}: joint positions must be numbers '
                              f'(F, {sk.num_joints}, 3)') from None
    single = x.ndim == 2
    if single:
        x = x[None]
    if x.ndim != 3 or x.shape[1:] != (sk.num_joints, 3):
        raise ClothInputError(f'skeleton {sk.name!r} has {sk.num_joints} joints: positions '
                              f'must have shape ({sk.num_joints}, 3) or (F, {sk.num_joints}, 3), '
                              f'got {x.shape}')
    if x.shape[0] == 0:
        raise ClothInputError(f'skeleton {sk.name!r}: no frames of joint positions')
    return np.where(np.isfinite(x), x, np.nan), single


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _plan(avatar: Avatar, sk: Skeleton) -> tuple:
    """joint_frames.solve_poses's arguments after the joints, for this avatar and layout (the
    last, spine: the rest pelvis joint's distance from the base of the neck, m), and
    {landmark: column} of the landmarks `landmarks_from_joints` returns (the layout's, then the
    derived ones); cached per avatar (an avatar does not change) and layout."""
    plans = _PLANS.setdefault(avatar, {})
    if sk in plans:
        return plans[sk]
    missing = [m for m in _REQUIRED if m not in sk.landmarks]
    if missing:  # a layout's table is wrong, not the user's data
        raise ClothInputError(f'skeleton {sk.name!r} lacks landmarks {missing}')
    ears = 'ear_l' in sk.landmarks and 'ear_r' in sk.landmarks
    if not ears and 'skull' not in sk.landmarks:
        raise ClothInputError(f'skeleton {sk.name!r} has neither ears nor a skull joint')
    observed = list(sk.landmark_joints())
    columns = list(MARKS) + [m for m in observed if m not in MARKS]
    index = {m: c for c, m in enumerate(columns)}
    rest = rest_landmarks(avatar)
    col = np.array([index[m] for m in sk.landmarks], dtype=np.int64)
    count = np.bincount(col, minlength=len(columns))
    derived = [m for m in ('pelvis', 'neck') + (('skull',) if ears else ()) if m not in observed]
    plans[sk] = (col, count, np.array([rest[m] for m in columns]), count > 0,
                 np.ascontiguousarray(avatar.rest_rotation, dtype=float), _FLEXION,
                 float(np.linalg.norm(rest['neck'] - rest['pelvis'])),
                 {m: index[m] for m in observed + derived})
    return plans[sk]


def landmarks_from_joints(joints: np.ndarray, skeleton: str | Skeleton,
                          avatar: Avatar | None = None, *, lean_only: bool = False
                          ) -> dict[str, np.ndarray]:
    """Every landmark the poses are made from, (F, 3) m each: the layout's (the mean of its
    joints at each) and those derived from the frames (e.g. mediapipe33's pelvis and neck).
    Arguments as `poses_from_joints`; NaN where missing. lean_only: a layout with neither a
    pelvis nor a neck joint tilts its pelvis by the trunk's lean alone, not also to the
    avatar's spine length (to measure that length: `body_size`)."""
    sk = get_skeleton(skeleton)
    avatar = packaged_avatar() if avatar is None else avatar
    require_default_segments(avatar)
    x, _ = _check_joints(joints, sk)
    *args, spine, names = _plan(avatar, sk)
    P = solve_poses(x, *args, np.nan if lean_only else spine)[2]
    return {m: P[:, c] for m, c in names.items()}


def poses_from_joints(joints: np.ndarray, skeleton: str | Skeleton,
                      avatar: Avatar | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Segment poses of the avatar from joint positions.

    Args:
        joints: (F, J, 3) or (J, 3) positions (m) of the layout's J joints in its order, in a
            z-up world frame (REP 103: x forward, y left, z up). Non-finite entries are missing
            joints.
        skeleton: the layout (`kinect32`, `mediapipe33`, `cmu31` or a `Skeleton`).
        avatar: the avatar whose convention and rest offsets to use (default: the packaged
            one, read once; use `avatar_from_joints` for one sized to the subject).

    Returns:
        poses: (F, 16, 7) or (16, 7) [x, y, z, qx, qy, qz, qw] in the avatar's convention
            (origin at the segment's proximal joint, frame R_world(joint) @ R0[s]); quaternions
            sign-continuous over each segment's valid frames. NaN rows where not valid.
        valid: (F, 16) or (16,) bool: the segment's pose could be made (every joint it needs is
            finite and its directions are not degenerate). Drop the invalid segments from the
            collider or hold their last pose.

    Raises:
        ClothInputError: positions not of shape (J, 3) / (F, J, 3) for the layout, an unknown
            layout, or an avatar without the 16 default segments.
    """
    sk = get_skeleton(skeleton)
    avatar = packaged_avatar() if avatar is None else avatar
    require_default_segments(avatar)
    x, single = _check_joints(joints, sk)
    poses, valid, _ = solve_poses(x, *_plan(avatar, sk)[:-1])
    return (poses[0], valid[0]) if single else (poses, valid)
