"""The subject's size from a joint stream: measured segment lengths and an avatar sized to them.

`measure_body` takes the joint-to-joint distances of the first `window_s` seconds of a stream
(the median per length over the valid frames): hip width, torso (pelvis -> base of the neck),
neck, shoulder width, upper arms, forearms, thighs, shanks.
`sized_avatar` sets the avatar's bones and capsule lengths from them (each segment scaled along
with the length that spans it). The radii, and the head, hands and feet, are scaled by the
subject's stature over the base avatar's (isometric scaling of the packaged avatar's girths: no
girth proportions are applied), both statures estimated the same way, as the median over the
eight limb lengths of length / proportion, with the Drillis & Contini segment lengths as
fractions of stature H (`STATURE_RATIOS`: thigh 0.245 H, shank 0.246 H, upper arm 0.186 H,
forearm 0.146 H; Drillis and Contini 1966, Tech. Rep. 1166.03, New York University, as
tabulated in D. A. Winter, "Biomechanics and Motor Control of Human Movement", 4th ed., Wiley
2009, Fig. 4.1; see also R. Contini, "Body segment parameters, part II", Artificial Limbs
16(1):1-19, 1972, http://www.oandplibrary.org/al/pdf/1972_01_001.pdf). The median keeps one
badly tracked limb from setting the girths. The torso and neck lengths are chords of two-piece
bones (the CMU spine and neck bend between their pieces), so a bent posture in the window reads
a little short (2.5 mm on the neck over 07_01's first second). Poses for the sized avatar are
made the same way (`poses_from_joints(joints, skeleton, sized)`): the origins are the measured
joints, so its capsules end at the subject's joints.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.joint_body import (
    landmarks_from_joints,
    packaged_avatar,
    require_default_segments,
    rest_landmarks,
)
from cloth_mg_ros.motion.skeletons import Skeleton, get_skeleton

__all__ = [
    'LENGTHS',
    'STATURE_RATIOS',
    'BodySize',
    'avatar_from_joints',
    'measure_body',
    'sized_avatar',
]

#: Measured lengths: name -> (landmark, landmark, segment whose capsule it scales, segments whose
#: bones it scales).
LENGTHS: dict[str, tuple[str, str, str | None, tuple[str, ...]]] = {
    'hip_width': ('hip_l', 'hip_r', 'pelvis', ('upper_leg_l', 'upper_leg_r')),
    'torso': ('pelvis', 'neck', 'lower_torso', ('upper_torso',)),
    'neck': ('neck', 'skull', None, ('head',)),
    'shoulder_width': ('shoulder_l', 'shoulder_r', 'upper_torso',
                       ('upper_arm_l', 'upper_arm_r')),
    'upper_arm_l': ('shoulder_l', 'elbow_l', 'upper_arm_l', ('lower_arm_l',)),
    'upper_arm_r': ('shoulder_r', 'elbow_r', 'upper_arm_r', ('lower_arm_r',)),
    'forearm_l': ('elbow_l', 'wrist_l', 'lower_arm_l', ('hand_l',)),
    'forearm_r': ('elbow_r', 'wrist_r', 'lower_arm_r', ('hand_r',)),
    'thigh_l': ('hip_l', 'knee_l', 'upper_leg_l', ('lower_leg_l',)),
    'thigh_r': ('hip_r', 'knee_r', 'upper_leg_r', ('lower_leg_r',)),
    'shank_l': ('knee_l', 'ankle_l', 'lower_leg_l', ('foot_l',)),
    'shank_r': ('knee_r', 'ankle_r', 'lower_leg_r', ('foot_r',)),
}

#: Segment length / stature (Drillis & Contini; Winter 2009 Fig. 4.1), for the stature estimate.
STATURE_RATIOS = {'thigh': 0.245, 'shank': 0.246, 'upper_arm': 0.186, 'forearm': 0.146}


@dataclass(frozen=True)
class BodySize:
    """A subject's size measured from a joint stream.

    Attributes:
        lengths: {LENGTHS name: m} median over the window's valid frames.
        reference: {name: m} the same lengths of the base avatar (its zero pose).
        stature: m, the subject's stature estimated from the limb lengths (STATURE_RATIOS).
        reference_stature: m, the base avatar's, estimated the same way.
        frames: number of frames in the window.
    """

    lengths: dict[str, float]
    reference: dict[str, float]
    stature: float
    reference_stature: float
    frames: int

    @property
    def radius_scale(self) -> float:
        """Factor on every radius (and the head, hands and feet): stature / reference."""
        return self.stature / self.reference_stature


def _stature(lengths: dict[str, float]) -> float:
    est = [lengths[f'{k}_{s}'] / r for k, r in STATURE_RATIOS.items() for s in 'lr']
    return float(np.median(est))


def _lengths(marks: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.linalg.norm(marks[a] - marks[b], axis=-1) for k, (a, b, _, _) in
            LENGTHS.items()}


def measure_body(joints: np.ndarray, skeleton: str | Skeleton, *,
                 stamps: np.ndarray | None = None, rate_hz: float | None = None,
                 window_s: float = 1.0, avatar: Avatar | None = None) -> BodySize:
    """Segment lengths of the subject: the median over the first `window_s` seconds.

    Args:
        joints: (F, J, 3) positions (m) in a z-up world (as `poses_from_joints`).
        skeleton: the layout.
        stamps: (F,) s, the frames' times; or `rate_hz`, frames per second.
        window_s: s, the measuring window from the first frame (at least one frame).
        avatar: the base avatar (its rest offsets derive the landmarks a layout lacks).

    Raises:
        ClothInputError: bad shapes, neither or both of stamps / rate_hz, a non-positive rate or
            window, or a length with no valid frame in the window (naming it and its joints).
    """
    sk = get_skeleton(skeleton)
    avatar = packaged_avatar() if avatar is None else avatar
    shape = np.shape(joints)
    if len(shape) != 3:
        raise ClothInputError(f'skeleton {sk.name!r}: measuring takes positions of shape '
                              f'(F, {sk.num_joints}, 3), got {shape}')
    if (stamps is None) == (rate_hz is None):
        raise ClothInputError('measure_body: give the frames\' stamps or rate_hz (one of them)')
    if not (isinstance(window_s, (int, float)) and np.isfinite(window_s) and window_s > 0):
        raise ClothInputError(f'window_s must be a positive number of seconds, got {window_s!r}')
    if stamps is None:
        if not (isinstance(rate_hz, (int, float)) and np.isfinite(rate_hz) and rate_hz > 0):
            raise ClothInputError(f'rate_hz must be a positive number, got {rate_hz!r}')
        t = np.arange(shape[0]) / float(rate_hz)
    else:
        t = np.asarray(stamps, dtype=float).reshape(-1)
        if t.shape != shape[:1] or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
            raise ClothInputError(f'stamps must be {shape[0]} finite non-decreasing times (s), '
                                  f'got shape {t.shape}')
    count = int(np.count_nonzero(t - t[0] <= window_s + 1e-9)) if len(t) else 0
    # the base avatar's spine length would set the torso it measures (joint_frames._spine_tilt)
    marks = landmarks_from_joints(np.asarray(joints)[:count], sk, avatar, lean_only=True)
    per_frame = _lengths(marks)
    lengths = {}
    for k, v in per_frame.items():
        ok = np.isfinite(v)
        if not ok.any():
            a, b = LENGTHS[k][:2]
            raise ClothInputError(f'skeleton {sk.name!r}: no frame in the first {window_s:g} s '
                                  f'has the joints for {k} ({a} to {b})')
        lengths[k] = float(np.median(v[ok]))
    rest = {k: float(v[0]) for k, v in _lengths({k: v[None] for k, v in
                                                 rest_landmarks(avatar).items()}).items()}
    return BodySize(lengths, rest, _stature(lengths), _stature(rest), count)


def sized_avatar(size: BodySize, avatar: Avatar | None = None) -> Avatar:
    """The base avatar with the subject's size: bones and capsule lengths from the measured
    lengths, radii (and head, hands, feet) scaled by stature (see the module docstring)."""
    avatar = packaged_avatar() if avatar is None else avatar
    require_default_segments(avatar)
    g = size.radius_scale
    cap = dict.fromkeys(avatar.names, g)
    bone = dict.fromkeys(avatar.names, g)
    for k, (_, _, seg, children) in LENGTHS.items():
        s = size.lengths[k] / size.reference[k]
        if seg is not None:
            cap[seg] = s
        for c in children:
            bone[c] = s
    segments = [dataclasses.replace(
        seg, p0=seg.p0 * cap[seg.name], p1=seg.p1 * cap[seg.name], radius=seg.radius * g,
        bone=tuple((via, vec * bone[seg.name]) for via, vec in seg.bone))
        for seg in avatar.segments]
    return Avatar(segments, avatar.ground_clearance, avatar.rest_arm_abduction,
                  source=f'{avatar.source} sized to a {size.stature:.3f} m subject')


def avatar_from_joints(joints: np.ndarray, skeleton: str | Skeleton, *,
                       stamps: np.ndarray | None = None, rate_hz: float | None = None,
                       window_s: float = 1.0, avatar: Avatar | None = None
                       ) -> tuple[Avatar, BodySize]:
    """An avatar sized to the subject of a joint stream (`measure_body`, then `sized_avatar`).

    The landmarks a layout lacks (mediapipe33's pelvis and neck) are derived with the avatar's
    rest offsets, so the lengths are measured twice: with the base avatar, then with the avatar
    sized by that first measurement. Returns (the sized avatar, the final measurement).
    """
    base = packaged_avatar() if avatar is None else avatar
    size = measure_body(joints, skeleton, stamps=stamps, rate_hz=rate_hz, window_s=window_s,
                        avatar=base)
    first = sized_avatar(size, base)
    again = measure_body(joints, skeleton, stamps=stamps, rate_hz=rate_hz, window_s=window_s,
                         avatar=first)
    size = dataclasses.replace(again, reference=size.reference,
                               reference_stature=size.reference_stature)
    return sized_avatar(size, base), size

