"""Joint layouts of body trackers, as data: which joint is which, in the tracker's order, and
where each joint sits on the capsule avatar.

A body tracker publishes J joint positions per body in a fixed order (its *layout*). To drive the
capsule avatar from them (`cloth_mg_ros.motion.joint_body`) each joint is named by a *landmark*
of the avatar: a point fixed on one of its segments (a joint centre such as `elbow_l`, or a
surface point such as `nose` or `toe_l`). Several joints may name one landmark (the CMU skeleton
keeps some joints at one point: Spine1, Neck and both LeftShoulder/RightShoulder sit at the base
of the neck); their mean is used. A layout need not name every landmark: what it lacks is
derived (see `joint_body`), e.g. MediaPipe has no pelvis and no neck joint.

Landmarks (`LANDMARKS`), `_l` / `_r` being the subject's left / right:

- joint centres, the origins of the avatar's segment poses: `pelvis` (the pelvis segment's
  origin, the CMU Hips point, above and behind the hip joints), `hip`, `knee`, `ankle`,
  `shoulder`, `elbow`, `wrist` (each `_l`/`_r`), `neck` (base of the neck, the upper torso's
  origin), `skull` (base of the skull, the head's origin);
- `mid_spine`: the end of the upper torso's first bone piece (the CMU Spine joint);
- points on a segment's capsule: `lumbar` (the lower torso's axis midpoint), `chest` (the upper
  torso capsule's centre), `head_centre`, `nose`, `eye`, `eye_inner`, `eye_outer`, `ear`,
  `mouth`, `hand` (knuckles), `handtip`, `thumb`, `index`, `pinky`, `toe` (tip of the foot),
  `ball` (ball of the foot), `heel`;
- points between two landmarks: `clavicle` (sternoclavicular joint, 0.3 of the way from `neck`
  to `shoulder`), `neck_mid` (the CMU Neck1 joint, 0.45 of the way from `neck` to `skull`).

`LANDMARKS[name]` says how to place it on a posed avatar (used to write joint streams from
segment poses and to know the landmarks' rest positions):

- `('origin', segment)`: the segment's pose origin;
- `('bone', segment, k)`: the end of piece k of the segment's bone (from its parent's origin);
- `('capsule', segment, t, e, w)`: p0 + t (p1 - p0) + radius (e u + w) in the segment's body
  frame, with p0, p1, radius its capsule, u the unit vector p1 - p0, w (3,) in radii; the
  body frame at rest is the world's (x forward, y left, z up, arms out sideways, palms down);
- `('lerp', a, b, t)`: landmark a + t (b - a).

Right-side landmarks mirror the left ones (y -> -y, `_l` -> `_r`). The surface points of the
head, hands and feet are this project's choice (the vendors publish no offsets): they set where
a tracker's nose, ears, fingers and toes are expected on the avatar, which fixes the twist of the
head, hands and feet, and `joints_from_poses` writes them at exactly these points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = [
    'CMU31',
    'HOLD_FALLBACK',
    'HOLD_PARENTS',
    'KINECT32',
    'LANDMARKS',
    'MEDIAPIPE33',
    'SKELETONS',
    'Skeleton',
    'get_skeleton',
]


def _sided(left: dict[str, tuple]) -> dict[str, tuple]:
    """The left landmarks and their mirror images (y -> -y, _l -> _r)."""
    out = {}
    for name, spec in left.items():
        out[name] = spec
        if not name.endswith('_l'):
            continue
        kind = spec[0]
        if kind == 'origin':
            right = ('origin', spec[1][:-2] + '_r')
        elif kind == 'capsule':
            seg, t, e, w = spec[1:]
            seg = seg[:-2] + '_r' if seg.endswith('_l') else seg
            right = ('capsule', seg, t, e, (w[0], -w[1], w[2]))
        elif kind == 'lerp':
            a, b, t = spec[1:]
            right = ('lerp', *(n[:-2] + '_r' if n.endswith('_l') else n for n in (a, b)), t)
        else:  # pragma: no cover - every sided kind is listed above
            raise AssertionError(kind)
        out[name[:-2] + '_r'] = right
    return out


_ZERO = (0.0, 0.0, 0.0)

#: landmark name -> placement on the avatar (see the module docstring).
LANDMARKS: dict[str, tuple] = _sided({
    'pelvis': ('origin', 'pelvis'),
    'neck': ('origin', 'upper_torso'),
    'skull': ('origin', 'head'),
    'mid_spine': ('bone', 'upper_torso', 0),
    'lumbar': ('capsule', 'lower_torso', 0.5, 0.0, _ZERO),
    'chest': ('capsule', 'upper_torso', 0.5, 0.0, _ZERO),
    'neck_mid': ('lerp', 'neck', 'skull', 0.45),
    'head_centre': ('capsule', 'head', 0.5, 0.0, _ZERO),
    'nose': ('capsule', 'head', 0.3, 0.0, (1.05, 0.0, 0.0)),
    'hip_l': ('origin', 'upper_leg_l'),
    'knee_l': ('origin', 'lower_leg_l'),
    'ankle_l': ('origin', 'foot_l'),
    'shoulder_l': ('origin', 'upper_arm_l'),
    'elbow_l': ('origin', 'lower_arm_l'),
    'wrist_l': ('origin', 'hand_l'),
    'clavicle_l': ('lerp', 'neck', 'shoulder_l', 0.3),
    'eye_l': ('capsule', 'head', 0.6, 0.0, (0.85, 0.33, 0.0)),
    'eye_inner_l': ('capsule', 'head', 0.6, 0.0, (0.88, 0.18, 0.0)),
    'eye_outer_l': ('capsule', 'head', 0.6, 0.0, (0.78, 0.48, 0.0)),
    'ear_l': ('capsule', 'head', 0.3, 0.0, (-0.05, 0.8, 0.0)),
    'mouth_l': ('capsule', 'head', 0.0, 0.0, (0.9, 0.25, 0.0)),
    'hand_l': ('capsule', 'hand_l', 0.5, 0.0, _ZERO),
    'handtip_l': ('capsule', 'hand_l', 1.0, 1.0, _ZERO),
    'thumb_l': ('capsule', 'hand_l', 0.3, 0.0, (1.0, 0.0, 0.0)),
    'index_l': ('capsule', 'hand_l', 1.0, 0.4, (0.5, 0.0, 0.0)),
    'pinky_l': ('capsule', 'hand_l', 0.85, 0.0, (-0.6, 0.0, 0.0)),
    'toe_l': ('capsule', 'foot_l', 1.0, 1.0, _ZERO),
    'ball_l': ('capsule', 'foot_l', 0.7, 0.0, _ZERO),
    'heel_l': ('capsule', 'foot_l', 0.0, -1.0, _ZERO),
})


#: landmark -> the landmark a hidden one is carried by (its parent on the body's tree, sides
#: kept): a tracker's hidden wrist follows its elbow (motion.joint_track). The face's points
#: ride on the nose (one rigid head), the nose on the head's centre.
HOLD_PARENTS: dict[str, str | None] = {
    'pelvis': None, 'lumbar': 'pelvis', 'mid_spine': 'lumbar', 'chest': 'mid_spine',
    'neck': 'chest', 'neck_mid': 'neck', 'skull': 'neck_mid', 'head_centre': 'skull',
    'nose': 'head_centre', 'hip': 'pelvis', 'knee': 'hip', 'ankle': 'knee', 'toe': 'ankle',
    'ball': 'ankle', 'heel': 'ankle', 'clavicle': 'neck', 'shoulder': 'clavicle',
    'elbow': 'shoulder', 'wrist': 'elbow', 'hand': 'wrist', 'handtip': 'hand',
    'thumb': 'wrist', 'index': 'wrist', 'pinky': 'wrist', 'eye': 'nose',
    'eye_inner': 'nose', 'eye_outer': 'nose', 'ear': 'nose', 'mouth': 'nose',
}
#: Where the tree leaves a layout without a carrier (mediapipe33 has no neck, spine or pelvis
#: joint): a landmark whose way up passes `key` is carried by the value (the side of the
#: hidden landmark, else the left) instead of being held still in the world, where a walker's
#: hidden ear was 0.2 m behind the head within 0.15 s.
HOLD_FALLBACK: dict[str, str] = {'neck': 'shoulder'}


def _hold_parent(landmark: str) -> str | None:
    """HOLD_PARENTS of a sided landmark name ('wrist_l' -> 'elbow_l')."""
    side = landmark[-2:] if landmark[-2:] in ('_l', '_r') else ''
    parent = HOLD_PARENTS[landmark[:len(landmark) - len(side)]]
    if parent is None:
        return None
    return parent + side if parent + side in LANDMARKS else parent


@dataclass(frozen=True)
class Skeleton:
    """A body tracker's joint layout.

    Attributes:
        name: the layout's name (the `skeleton` parameter's value).
        joints: (J,) joint names in the tracker's order (the order of the positions).
        landmarks: (J,) the avatar landmark (`LANDMARKS`) each joint is placed at.
        source: where the joint list and its order are published.
    """

    name: str
    joints: tuple[str, ...]
    landmarks: tuple[str, ...]
    source: str

    @property
    def num_joints(self) -> int:
        """J, the number of joints per body."""
        return len(self.joints)

    def joint_index(self, name: str) -> int:
        """Index of joint `name` in the layout."""
        try:
            return self.joints.index(name)
        except ValueError:
            raise ClothInputError(f'skeleton {self.name!r} has no joint {name!r} (joints: '
                                  f'{", ".join(self.joints)})') from None

    def hold_parents(self) -> np.ndarray:
        """(J,) each joint's carrier while hidden: the layout's first joint at the nearest
        landmark up the body's tree (HOLD_PARENTS), else at HOLD_FALLBACK's landmark for the
        first key passed on the way up; -1 for none (held in place). Acyclic, in any index
        order (motion.joint_track.JointTrack sorts them)."""
        first: dict[str, int] = {}
        for j, m in enumerate(self.landmarks):
            first.setdefault(m, j)
        out = np.full(self.num_joints, -1, dtype=np.int64)
        for j, m in enumerate(self.landmarks):
            if first[m] != j:  # joints at one landmark (cmu31's LHipJoint at Hips) ride together
                out[j] = first[m]
                continue
            side = m[-2:] if m[-2:] in ('_l', '_r') else '_l'
            up, fallback = _hold_parent(m), None
            while up is not None and (up not in first or first[up] == j):
                if fallback is None and up in HOLD_FALLBACK:
                    fallback = HOLD_FALLBACK[up] + side
                up = _hold_parent(up)
            if up is None and fallback in first and first[fallback] != j:
                up = fallback
            out[j] = -1 if up is None else first[up]
        return out

    def landmark_joints(self) -> dict[str, tuple[int, ...]]:
        """landmark -> indices of the joints placed at it (their mean is the landmark)."""
        out: dict[str, list[int]] = {}
        for j, name in enumerate(self.landmarks):
            out.setdefault(name, []).append(j)
        return {k: tuple(v) for k, v in out.items()}


def _layout(name: str, source: str, table: list[tuple[str, str]]) -> Skeleton:
    joints = tuple(j for j, _ in table)
    marks = tuple(m for _, m in table)
    if len(set(joints)) != len(joints):
        raise AssertionError(f'{name}: duplicate joint names')
    unknown = sorted(set(marks) - set(LANDMARKS))
    if unknown:
        raise AssertionError(f'{name}: unknown landmarks {unknown}')
    return Skeleton(name, joints, marks, source)


# Azure Kinect Body Tracking SDK, k4abt_joint_id_t in k4abttypes.h (K4ABT_JOINT_PELVIS = 0 ...
# K4ABT_JOINT_EAR_RIGHT = 31, K4ABT_JOINT_COUNT = 32), SDK 1.0.1 and 1.1.2:
#   https://microsoft.github.io/Azure-Kinect-Body-Tracking/release/1.1.x/k4abttypes_8h_source.html
# and the joint hierarchy table of "Azure Kinect body tracking joints":
#   https://learn.microsoft.com/en-us/previous-versions/azure/kinect-dk/body-joints
# The Azure Kinect ROS driver publishes the joints in this order (marker id = body id x 100 +
# joint index). Positions are in the depth camera's frame (millimetres in the SDK, metres in the
# ROS driver's markers); `joint_body` takes metres in a z-up world.
KINECT32 = _layout('kinect32', 'https://microsoft.github.io/Azure-Kinect-Body-Tracking/release/'
                   '1.1.x/k4abttypes_8h_source.html', [
                       ('pelvis', 'pelvis'),              # 0
                       ('spine_navel', 'lumbar'),         # 1
                       ('spine_chest', 'chest'),          # 2
                       ('neck', 'neck'),                  # 3
                       ('clavicle_left', 'clavicle_l'),   # 4
                       ('shoulder_left', 'shoulder_l'),   # 5
                       ('elbow_left', 'elbow_l'),         # 6
                       ('wrist_left', 'wrist_l'),         # 7
                       ('hand_left', 'hand_l'),           # 8
                       ('handtip_left', 'handtip_l'),     # 9
                       ('thumb_left', 'thumb_l'),         # 10
                       ('clavicle_right', 'clavicle_r'),  # 11
                       ('shoulder_right', 'shoulder_r'),  # 12
                       ('elbow_right', 'elbow_r'),        # 13
                       ('wrist_right', 'wrist_r'),        # 14
                       ('hand_right', 'hand_r'),          # 15
                       ('handtip_right', 'handtip_r'),    # 16
                       ('thumb_right', 'thumb_r'),        # 17
                       ('hip_left', 'hip_l'),             # 18
                       ('knee_left', 'knee_l'),           # 19
                       ('ankle_left', 'ankle_l'),         # 20
                       ('foot_left', 'toe_l'),            # 21
                       ('hip_right', 'hip_r'),            # 22
                       ('knee_right', 'knee_r'),          # 23
                       ('ankle_right', 'ankle_r'),        # 24
                       ('foot_right', 'toe_r'),           # 25
                       ('head', 'head_centre'),           # 26
                       ('nose', 'nose'),                  # 27
                       ('eye_left', 'eye_l'),             # 28
                       ('ear_left', 'ear_l'),             # 29
                       ('eye_right', 'eye_r'),            # 30
                       ('ear_right', 'ear_r'),            # 31
                   ])

# MediaPipe Pose (BlazePose GHUM), the 33 pose landmarks in index order: mediapipe's
# `PoseLandmark` enum (NOSE = 0 ... RIGHT_FOOT_INDEX = 32) in mediapipe/python/solutions/pose.py,
#   https://github.com/google-ai-edge/mediapipe/blob/master/mediapipe/python/solutions/pose.py
# and the landmark list of the Pose Landmarker guide ("0 - nose ... 32 - right foot index"):
#   https://ai.google.dev/edge/mediapipe/solutions/vision/pose_landmarker
# Left and right are the subject's. Its world landmarks are metres about the hips' centre (y
# down); `joint_body` takes them after the transform to a z-up world.
MEDIAPIPE33 = _layout('mediapipe33', 'https://github.com/google-ai-edge/mediapipe/blob/master/'
                      'mediapipe/python/solutions/pose.py', [
                          ('nose', 'nose'),                          # 0
                          ('left_eye_inner', 'eye_inner_l'),         # 1
                          ('left_eye', 'eye_l'),                     # 2
                          ('left_eye_outer', 'eye_outer_l'),         # 3
                          ('right_eye_inner', 'eye_inner_r'),        # 4
                          ('right_eye', 'eye_r'),                    # 5
                          ('right_eye_outer', 'eye_outer_r'),        # 6
                          ('left_ear', 'ear_l'),                     # 7
                          ('right_ear', 'ear_r'),                    # 8
                          ('mouth_left', 'mouth_l'),                 # 9
                          ('mouth_right', 'mouth_r'),                # 10
                          ('left_shoulder', 'shoulder_l'),           # 11
                          ('right_shoulder', 'shoulder_r'),          # 12
                          ('left_elbow', 'elbow_l'),                 # 13
                          ('right_elbow', 'elbow_r'),                # 14
                          ('left_wrist', 'wrist_l'),                 # 15
                          ('right_wrist', 'wrist_r'),                # 16
                          ('left_pinky', 'pinky_l'),                 # 17
                          ('right_pinky', 'pinky_r'),                # 18
                          ('left_index', 'index_l'),                 # 19
                          ('right_index', 'index_r'),                # 20
                          ('left_thumb', 'thumb_l'),                 # 21
                          ('right_thumb', 'thumb_r'),                # 22
                          ('left_hip', 'hip_l'),                     # 23
                          ('right_hip', 'hip_r'),                    # 24
                          ('left_knee', 'knee_l'),                   # 25
                          ('right_knee', 'knee_r'),                  # 26
                          ('left_ankle', 'ankle_l'),                 # 27
                          ('right_ankle', 'ankle_r'),                # 28
                          ('left_heel', 'heel_l'),                   # 29
                          ('right_heel', 'heel_r'),                  # 30
                          ('left_foot_index', 'toe_l'),              # 31
                          ('right_foot_index', 'toe_r'),             # 32
                      ])

# The bundled CMU skeleton (the "cgspeed" BVH conversion of the CMU Graphics Lab Motion Capture
# Database): its 31 joints in the order of the BVH HIERARCHY (depth first; End Sites are not
# joints), as in test/data/mocap/07_01.bvh and every bundled clip. Joints at one point in that
# skeleton name one landmark: LHipJoint, RHipJoint and LowerBack sit at Hips; Spine1, Neck,
# LeftShoulder and RightShoulder at the base of the neck; LeftFingerBase and LThumb at LeftHand.
CMU31 = _layout('cmu31', 'test/data/mocap/07_01.bvh (CMU mocap.cs.cmu.edu, cgspeed BVH)', [
    ('Hips', 'pelvis'),
    ('LHipJoint', 'pelvis'),
    ('LeftUpLeg', 'hip_l'),
    ('LeftLeg', 'knee_l'),
    ('LeftFoot', 'ankle_l'),
    ('LeftToeBase', 'ball_l'),
    ('RHipJoint', 'pelvis'),
    ('RightUpLeg', 'hip_r'),
    ('RightLeg', 'knee_r'),
    ('RightFoot', 'ankle_r'),
    ('RightToeBase', 'ball_r'),
    ('LowerBack', 'pelvis'),
    ('Spine', 'mid_spine'),
    ('Spine1', 'neck'),
    ('Neck', 'neck'),
    ('Neck1', 'neck_mid'),
    ('Head', 'skull'),
    ('LeftShoulder', 'neck'),
    ('LeftArm', 'shoulder_l'),
    ('LeftForeArm', 'elbow_l'),
    ('LeftHand', 'wrist_l'),
    ('LeftFingerBase', 'wrist_l'),
    ('LeftHandIndex1', 'hand_l'),
    ('LThumb', 'wrist_l'),
    ('RightShoulder', 'neck'),
    ('RightArm', 'shoulder_r'),
    ('RightForeArm', 'elbow_r'),
    ('RightHand', 'wrist_r'),
    ('RightFingerBase', 'wrist_r'),
    ('RightHandIndex1', 'hand_r'),
    ('RThumb', 'wrist_r'),
])

#: layout name -> Skeleton.
SKELETONS: dict[str, Skeleton] = {s.name: s for s in (KINECT32, MEDIAPIPE33, CMU31)}


def get_skeleton(skeleton: str | Skeleton) -> Skeleton:
    """The layout named `skeleton` (or `skeleton` itself).

    Raises:
        ClothInputError: an unknown name, naming the known ones.
    """
    if isinstance(skeleton, Skeleton):
        return skeleton
    try:
        return SKELETONS[skeleton]
    except (KeyError, TypeError):
        raise ClothInputError(f'skeleton must be one of {", ".join(SKELETONS)}, '
                              f'got {skeleton!r}') from None
