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

Sizing the avatar to the subject: `cloth_mg_ros.motion.body_size`.
"""

from __future__ import annotations

import functools
import warnings
import weakref

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import SEGMENT_NAMES, Avatar
from cloth_mg_ros.motion.rotations import matrix_to_quat
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
_BLEND = (0.17, 0.34)  # sine of the angle below which a twist reference fades into the parent's


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


def _zero_pose(avatar: Avatar) -> np.ndarray:
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
        rest = {k: v[0] for k, v in landmark_points(avatar, _zero_pose(avatar)).items()}
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
# Frames from directions


# np.cross and np.linalg.norm cost more in their argument handling than in the arithmetic on
# these (F, 3) arrays; a single-frame call (a tracker's message) is made of hundreds of them


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.sum(v * v, axis=-1))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    with np.errstate(invalid='ignore', divide='ignore'):
        return v / _norm(v)[..., None]


def _triad(a: np.ndarray, a0: np.ndarray, v: np.ndarray, v0: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotation B with B @ a0 = a (directions) and B @ v0 as close to v as that
    allows. a, v: (F, 3); a0, v0: (3,). NaN where v is parallel to a."""
    def basis(x, y):
        e1 = _unit(x)
        e2 = _unit(y - np.sum(y * e1, axis=-1, keepdims=True) * e1)
        return np.stack([e1, e2, _cross(e1, e2)], axis=-1)
    return basis(a, v) @ np.swapaxes(basis(a0, v0), -1, -2)


def _swing(parent: np.ndarray, a0: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The parent frame (F, 3, 3) turned by the smallest rotation that takes parent @ a0 onto a
    (F, 3): the segment's frame with no twist relative to its parent."""
    u = _unit(parent @ _unit(a0))
    a = _unit(a)
    k = _cross(u, a)
    c = np.sum(u * a, axis=-1)
    K = np.zeros(k.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    # 1 + c -> 0 only for an exactly reversed axis (180 deg in one frame)
    R = np.eye(3) + K + (K @ K) / np.maximum(1.0 + c, 1e-9)[..., None, None]
    return R @ parent


def _aim_frame(a, a0, v, v0, *, weight=None, parent=None) -> np.ndarray:
    """Frame with axis a (rest a0) and twist from v (rest v0), fading into the parent frame
    swung onto a where `weight` (default: how far v is from parallel to a, as a sine) is small."""
    au = _unit(a)
    vp = v - np.sum(v * au, axis=-1, keepdims=True) * au
    if weight is None:
        with np.errstate(invalid='ignore', divide='ignore'):
            weight = _norm(vp) / _norm(v)
    if parent is None:
        return _triad(a, a0, vp, v0)
    a0u = _unit(a0)
    v0p = _unit(v0 - np.dot(v0, a0u) * a0u)
    w = np.clip((weight - _BLEND[0]) / (_BLEND[1] - _BLEND[0]), 0.0, 1.0)[..., None]
    w = np.where(np.isfinite(w), w, 0.0)  # a missing twist reference: the parent's
    ref = _swing(parent, a0, a) @ v0p
    own = _unit(vp)
    mix = w * own + (1.0 - w) * ref
    # exactly opposed references mid-blend: keep the parent's
    mix = np.where(_norm(mix)[..., None] < 0.1, ref, mix)
    # at full weight the parent is not needed (it may be missing), at zero weight the own
    # reference is not (0 x NaN would leak in)
    mix = np.where(w >= 1.0, own, np.where(w <= 0.0, ref, mix))
    return _triad(a, a0, mix, v0p)


def _bend_frame(a, a0, f, d0, parent) -> np.ndarray:
    """A limb's frame: axis a (rest a0), twist from the plane of the bend with the next bone f,
    whose hinge axis is a0 x d0 (d0: the rest direction the next bone flexes toward)."""
    n = _cross(_unit(a), _unit(f))
    with np.errstate(invalid='ignore'):
        sine = _norm(n)
    return _aim_frame(a, a0, n, _cross(_unit(a0), d0), weight=sine, parent=parent)


# --------------------------------------------------------------------------------------------
# Joints -> poses


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


def _observed(x: np.ndarray, sk: Skeleton) -> dict[str, np.ndarray]:
    """Landmark -> (F, 3) mean of the joints placed at it (NaN where all of them are)."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)  # all-NaN means: missing
        for mark, idx in sk.landmark_joints().items():
            out[mark] = x[:, idx[0]] if len(idx) == 1 else np.nanmean(x[:, list(idx)], axis=1)
    return out


# Each part below takes the landmarks P (observed, {name: (F, 3)}; the parts add the ones they
# derive) and the same landmarks R on the avatar's zero pose ({name: (3,)}), and returns
# [(segment, origin (F, 3), body frame (F, 3, 3))].
_FORWARD = np.array([1.0, 0.0, 0.0])  # the rest frame's forward axis


def _mid(src: dict, a: str, b: str) -> np.ndarray:
    return 0.5 * (src[a] + src[b])


def _pair(src: dict, a: str, b: str) -> np.ndarray:
    return src[a] - src[b]


def _pelvis(P: dict, R: dict) -> np.ndarray:
    """The pelvis frame: the hip line, twist from the pelvis joint or the trunk; derives the
    pelvis joint from the hips where the layout has none."""
    hip_c, hip_c0 = _mid(P, 'hip_l', 'hip_r'), _mid(R, 'hip_l', 'hip_r')
    if 'pelvis' in P:
        v, v0 = P['pelvis'] - hip_c, R['pelvis'] - hip_c0
    elif 'neck' in P:
        v, v0 = P['neck'] - hip_c, R['neck'] - hip_c0
    else:
        sh_c, sh_c0 = _mid(P, 'shoulder_l', 'shoulder_r'), _mid(R, 'shoulder_l', 'shoulder_r')
        v, v0 = sh_c - hip_c, sh_c0 - hip_c0
    B = _aim_frame(_pair(P, 'hip_l', 'hip_r'), _pair(R, 'hip_l', 'hip_r'), v, v0)
    if 'pelvis' not in P:
        P['pelvis'] = hip_c + B @ (R['pelvis'] - hip_c0)
    return B


def _upper_torso(P: dict, R: dict) -> np.ndarray:
    """The chest frame: the shoulder line, twist from the chest, the neck or the trunk; derives
    the base of the neck from the shoulders where the layout has none."""
    sh_c, sh_c0 = _mid(P, 'shoulder_l', 'shoulder_r'), _mid(R, 'shoulder_l', 'shoulder_r')
    line, line0 = _pair(P, 'shoulder_l', 'shoulder_r'), _pair(R, 'shoulder_l', 'shoulder_r')
    if 'neck' in P and 'chest' in P:
        B = _aim_frame(line, line0, P['neck'] - P['chest'], R['neck'] - R['chest'])
    elif 'neck' in P:
        # the base of the neck above the shoulders' line, as on the avatar, tilts the chest
        # exactly; a skeleton whose shoulder joints sit higher (the raw CMU one: 5 cm above
        # Spine1) falls back on the spine below the neck
        v, v0 = P['neck'] - sh_c, R['neck'] - sh_c0
        low = 'mid_spine' if 'mid_spine' in P else 'pelvis'
        w, w0 = P['neck'] - P[low], R['neck'] - R[low]
        above = np.sum(v * _unit(w), axis=-1) > 0.0
        B = np.where(above[:, None, None], _aim_frame(line, line0, v, v0),
                     _aim_frame(line, line0, w, w0))
    else:
        hip_c, hip_c0 = _mid(P, 'hip_l', 'hip_r'), _mid(R, 'hip_l', 'hip_r')
        B = _aim_frame(line, line0, sh_c - hip_c, sh_c0 - hip_c0)
    if 'neck' not in P:
        P['neck'] = sh_c + B @ (R['neck'] - sh_c0)
    return B


def _trunk(P: dict, R: dict) -> tuple[list, np.ndarray, np.ndarray]:
    """Pelvis, upper and lower torso; also returns the pelvis's and the chest's frames (the
    legs', the arms' and the head's parents)."""
    pelvis_B = _pelvis(P, R)
    chest_B = _upper_torso(P, R)
    # lower torso: pelvis -> spine (or the spine's chord to the neck), its twist halfway
    # between the pelvis's and the chest's
    top = next(m for m in ('lumbar', 'mid_spine', 'neck') if m in P)
    a, a0 = P[top] - P['pelvis'], R[top] - R['pelvis']
    lower = _aim_frame(a, a0, pelvis_B @ _FORWARD + chest_B @ _FORWARD, _FORWARD,
                       parent=pelvis_B)
    parts = [('pelvis', P['pelvis'], pelvis_B), ('upper_torso', P['neck'], chest_B),
             ('lower_torso', P['pelvis'], lower)]
    return parts, pelvis_B, chest_B


def _head(P: dict, R: dict, chest_B: np.ndarray, sk: Skeleton) -> list:
    """The head: the ear line, twist from the nose (else the chest's forward), or without ears
    the neck's direction to the base of the skull; derives the skull from the ears."""
    if 'ear_l' in P and 'ear_r' in P:
        ear_c, ear_c0 = _mid(P, 'ear_l', 'ear_r'), _mid(R, 'ear_l', 'ear_r')
        if 'nose' in P:
            v, v0 = P['nose'] - ear_c, R['nose'] - ear_c0
        else:
            v, v0 = chest_B @ [1.0, 0.0, 0.0], np.array([1.0, 0.0, 0.0])
        B = _aim_frame(_pair(P, 'ear_l', 'ear_r'), _pair(R, 'ear_l', 'ear_r'), v, v0)
        if 'skull' not in P:
            P['skull'] = ear_c + B @ (R['skull'] - ear_c0)
    elif 'skull' in P:
        a, a0 = P['skull'] - P['neck'], R['skull'] - R['neck']
        B = _aim_frame(a, a0, chest_B @ [1.0, 0.0, 0.0], np.array([1.0, 0.0, 0.0]),
                       parent=chest_B)
    else:
        raise ClothInputError(f'skeleton {sk.name!r} has neither ears nor a skull joint')
    return [('head', P['skull'], B)]


def _arm(P: dict, R: dict, side: str, chest_B: np.ndarray) -> list:
    """Upper arm, forearm and hand of one side ('l' or 'r')."""
    def m(name):
        return f'{name}_{side}'

    sh, el, wr = P[m('shoulder')], P[m('elbow')], P[m('wrist')]
    a0 = R[m('elbow')] - R[m('shoulder')]
    upper = _bend_frame(el - sh, a0, wr - el, ELBOW_FLEXION, chest_B)
    # the elbow is a hinge: the forearm is the upper arm turned about it (pronation is the
    # wrist's twist in the CMU skeleton, so the hand does not show the forearm's)
    f0 = R[m('wrist')] - R[m('elbow')]
    fore = _swing(upper, f0, wr - el)
    palm = None
    if m('index') in P and m('pinky') in P:
        palm = (P[m('index')] - P[m('pinky')], R[m('index')] - R[m('pinky')])
    elif m('thumb') in P:
        palm = (P[m('thumb')] - wr, R[m('thumb')] - R[m('wrist')])
    tip = next((t for t in ('handtip', 'hand') if m(t) in P), None)
    if tip is not None:
        a, a0 = P[m(tip)] - wr, R[m(tip)] - R[m('wrist')]
    elif m('index') in P and m('pinky') in P:
        a = 0.5 * (P[m('index')] + P[m('pinky')]) - wr
        a0 = 0.5 * (R[m('index')] + R[m('pinky')]) - R[m('wrist')]
    else:  # no hand landmark: the hand continues the forearm
        a, a0 = wr - el, f0
    v, v0 = (palm if palm is not None
             else (fore @ [1.0, 0.0, 0.0], np.array([1.0, 0.0, 0.0])))
    hand = _aim_frame(a, a0, v, v0, parent=fore)
    return [(m('upper_arm'), sh, upper), (m('lower_arm'), el, fore), (m('hand'), wr, hand)]


def _leg(P: dict, R: dict, side: str, pelvis_B: np.ndarray) -> list:
    """Thigh, shank and foot of one side ('l' or 'r')."""
    def m(name):
        return f'{name}_{side}'

    hp, kn, an = P[m('hip')], P[m('knee')], P[m('ankle')]
    a0 = R[m('knee')] - R[m('hip')]
    thigh = _bend_frame(kn - hp, a0, an - kn, KNEE_FLEXION, pelvis_B)
    # the knee is a hinge too: the shank is the thigh turned about it
    s0 = R[m('ankle')] - R[m('knee')]
    shank = _swing(thigh, s0, an - kn)
    parts = [(m('upper_leg'), hp, thigh), (m('lower_leg'), kn, shank)]
    toe = next((t for t in ('toe', 'ball') if m(t) in P), None)
    if toe is None:  # no foot landmark: the foot keeps its rest angle to the shank
        return parts + [(m('foot'), an, shank)]
    t, t0 = P[m(toe)] - an, R[m(toe)] - R[m('ankle')]
    if m('heel') in P:
        foot = _aim_frame(t, t0, P[m('heel')] - an, R[m('heel')] - R[m('ankle')], parent=shank)
    else:
        # the ankle's bend (shank x foot) is a hinge in the CMU skeleton
        hinge0 = _cross(_unit(s0), _unit(t0))
        ankle = _cross(_unit(an - kn), _unit(t))
        with np.errstate(invalid='ignore'):
            sine = _norm(ankle)
        foot = _aim_frame(t, t0, ankle, hinge0, weight=sine, parent=shank)
    return parts + [(m('foot'), an, foot)]


def _solve(avatar: Avatar, sk: Skeleton, x: np.ndarray):
    """Origins (F, 16, 3), body frames (F, 16, 3, 3) and every landmark used (observed and
    derived) from joint positions x (F, J, 3)."""
    missing = [m for m in _REQUIRED if m not in sk.landmarks]
    if missing:  # a layout's table is wrong, not the user's data
        raise ClothInputError(f'skeleton {sk.name!r} lacks landmarks {missing}')
    R = rest_landmarks(avatar)
    P = _observed(x, sk)
    # the order matters: each part derives landmarks the next ones use (pelvis, neck, skull)
    parts, pelvis_B, chest_B = _trunk(P, R)
    parts += _head(P, R, chest_B, sk)
    for side in ('l', 'r'):
        parts += _arm(P, R, side, chest_B) + _leg(P, R, side, pelvis_B)
    F = x.shape[0]
    origin = np.full((F, 16, 3), np.nan)
    body = np.full((F, 16, 3, 3), np.nan)
    idx = {n: i for i, n in enumerate(SEGMENT_NAMES)}
    for seg, o, b in parts:
        origin[:, idx[seg]] = o
        body[:, idx[seg]] = b
    return origin, body, P


def _continuous_quats(frames: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Unit quaternions (F, S, 4) of frames (F, S, 3, 3), sign-continuous over each segment's
    valid frames, NaN elsewhere."""
    F, S = valid.shape
    safe = np.where(valid[..., None, None], frames, np.eye(3))
    q = matrix_to_quat(safe.reshape(-1, 3, 3)).reshape(F, S, 4)
    for s in range(S):
        k = np.flatnonzero(valid[:, s])
        if len(k) > 1:
            flip = np.sum(q[k[1:], s] * q[k[:-1], s], axis=-1) < 0.0
            q[k[1:], s] *= np.cumprod(np.where(flip, -1.0, 1.0))[:, None]
    q[~valid] = np.nan
    return q


def landmarks_from_joints(joints: np.ndarray, skeleton: str | Skeleton,
                          avatar: Avatar | None = None) -> dict[str, np.ndarray]:
    """Every landmark the poses are made from, (F, 3) m each: the layout's (the mean of its
    joints at each) and those derived from the frames (e.g. mediapipe33's pelvis and neck).
    Arguments as `poses_from_joints`; NaN where missing."""
    sk = get_skeleton(skeleton)
    avatar = packaged_avatar() if avatar is None else avatar
    require_default_segments(avatar)
    x, _ = _check_joints(joints, sk)
    with np.errstate(invalid='ignore', divide='ignore'):
        return _solve(avatar, sk, x)[2]


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
    with np.errstate(invalid='ignore', divide='ignore'):
        origin, body, _ = _solve(avatar, sk, x)
        frames = body @ avatar.rest_rotation
    valid = np.isfinite(origin).all(-1) & np.isfinite(frames).all((-2, -1))
    poses = np.concatenate([np.where(valid[..., None], origin, np.nan),
                            _continuous_quats(frames, valid)], axis=-1)
    return (poses[0], valid[0]) if single else (poses, valid)
