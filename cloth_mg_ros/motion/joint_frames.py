"""Numba kernels of `joint_body.poses_from_joints`: a body tracker's joints -> the avatar's
segment poses, one frame at a time.

The live node converts one to three frames per tick on the simulation thread. Written as numpy
expressions over (F, 3) arrays the conversion is ~4500 small array operations per call (7 ms
for one frame, a fifth of a 30 Hz tick); here each frame is solved with scalar 3-vectors
(tuples of 3) and 3x3 matrices (tuples of 9, row-major: `vec_tuples`), ~0.03 ms a call, and
every kernel is nogil, so the node's pose ingestion runs meanwhile. The method and its reasons
are in `joint_body`'s docstring: `_triad` (a TRIAD frame), `_swing` (the parent frame turned onto a
new axis), `_aim_root` / `_aim` (axis and twist reference, the latter fading into the parent's
frame), `_bend` (a limb's frame from its bend), then one function per body part; without
spine joints the pelvis's tilt is a model (`_pelvic_tilt`, `_spine_tilt`).

Missing data: a missing joint is NaN and spreads as it did through numpy (division by a zero
length gives NaN or inf, error_model='numpy', not an exception); a segment is valid where its
origin and frame are finite. The branches take a NaN comparison the way np.where, np.clip and
np.maximum did.

Arrays (float64, C-contiguous): joints x (F, J, 3) m; landmark columns P (F, C, 3) m, the
first len(MARKS) columns those of `MARKS` (a layout lacking one leaves it NaN, `has` False),
then the layout's other landmarks; rest landmarks R (C, 3) m on the avatar's zero pose;
rest_rotation (16, 3, 3); flexion (2, 3): the elbow's and the knee's rest flexion directions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cloth_mg_ros.motion import vec_tuples as _vt
from cloth_mg_ros.motion.avatar import SEGMENT_NAMES

__all__ = ['MARKS', 'solve_poses']

# vec_tuples' arithmetic under the short names the kernels below are written with (numba
# compiles tuples of floats without allocating; short names keep the formulas legible)
_get, _put, _add, _sub, _scale, _mid = _vt.get, _vt.put, _vt.add, _vt.sub, _vt.scale, _vt.mid
_dot, _norm, _unit, _cross = _vt.dot, _vt.norm, _vt.unit, _vt.cross
_mv, _mm, _mmt = _vt.mv, _vt.mm, _vt.mmt

# The landmark columns the frames read (the order of the constants below): the trunk's and
# head's, then per side (_L, _R: the first column of a side) the leg's and arm's (offsets).
_SIDED = ('hip', 'knee', 'ankle', 'toe', 'ball', 'heel', 'shoulder', 'elbow', 'wrist',
          'handtip', 'hand', 'thumb', 'index', 'pinky')
MARKS = (('pelvis', 'neck', 'skull', 'mid_spine', 'lumbar', 'chest', 'nose', 'ear_l', 'ear_r')
         + tuple(f'{m}_l' for m in _SIDED) + tuple(f'{m}_r' for m in _SIDED))
_PELVIS, _NECK, _SKULL, _MID_SPINE, _LUMBAR, _CHEST, _NOSE, _EAR_L, _EAR_R = range(9)
_L, _R = 9, 9 + len(_SIDED)
_HIP, _KNEE, _ANKLE, _TOE, _BALL, _HEEL = range(6)
_SHOULDER, _ELBOW, _WRIST, _HANDTIP, _HAND, _THUMB, _INDEX, _PINKY = range(6, 14)
# segment rows of the poses, SEGMENT_NAMES's order (checked here: a cached kernel keeps these
# constants even when avatar.py changes)
_PELVIS_S, _LOWER_TORSO_S, _UPPER_TORSO_S, _HEAD_S, _ARM_L_S, _ARM_R_S = 0, 1, 2, 3, 4, 7
_LEG_L_S, _LEG_R_S = 10, 13
if SEGMENT_NAMES != ('pelvis', 'lower_torso', 'upper_torso', 'head') + tuple(
        f'{p}_{side}' for parts in (('upper_arm', 'lower_arm', 'hand'),
                                     ('upper_leg', 'lower_leg', 'foot'))
        for side in 'lr' for p in parts) or tuple(_SIDED[i] for i in (
            _HIP, _KNEE, _ANKLE, _TOE, _BALL, _HEEL, _SHOULDER, _ELBOW, _WRIST, _HANDTIP, _HAND,
            _THUMB, _INDEX, _PINKY)) != _SIDED:
    raise AssertionError('joint_frames: segment or landmark order out of date')

_FORWARD = (1.0, 0.0, 0.0)  # the rest frame's forward axis
_BLEND = (0.17, 0.34)  # sine of the angle below which a twist reference fades into the parent's
_PELVIC_TILT = 0.4  # the pelvis's share of the trunk's lean without spine joints
# The pelvis's tilt from the spine's length (_spine_tilt): how far it may move from the lean
# share, rad (15 deg: the six CMU subjects' pelvis sits within 9 deg of it; a wrong-sized
# avatar stops here), in _TILT_STEPS grid steps each side; the uncertainties the two are
# weighed by: the share's, rad (5.3 deg, the RMS of the four bundled clips' pelvis off it), and
# the chord's, m (the joint centres' noise: 2 mm, as `bench trackers` jitters them)
_TILT_RANGE = 0.26
_TILT_STEPS = 60
_TILT_SD = 0.0925
_CHORD_SD = 0.002
_CHEST_NECK = 0.25  # weight of the neck's direction in the chest's lean without spine joints


# --------------------------------------------------------------------------------------------
# Frames from directions (joint_body's docstring: TRIAD frames, the swing onto a new axis and
# the blend into the parent's frame where the twist reference vanishes)


@njit(cache=True, nogil=True, error_model='numpy')
def _basis(x, y):
    """Columns x^, the part of y across it (unit), their cross product."""
    e1 = _unit(x)
    e2 = _unit(_sub(y, _scale(_dot(y, e1), e1)))
    e3 = _cross(e1, e2)
    return (e1[0], e2[0], e3[0], e1[1], e2[1], e3[1], e1[2], e2[2], e3[2])


@njit(cache=True, nogil=True, error_model='numpy')
def _triad(a, a0, v, v0):
    """B with B @ a0 = a (directions) and B @ v0 as close to v as that allows."""
    return _mmt(_basis(a, v), _basis(a0, v0))


@njit(cache=True, nogil=True, error_model='numpy')
def _swing(parent, a0, a):
    """The parent frame turned by the smallest rotation taking parent @ a0 onto a."""
    u = _unit(_mv(parent, _unit(a0)))
    au = _unit(a)
    k = _cross(u, au)
    c = _dot(u, au)
    K = (0.0, -k[2], k[1], k[2], 0.0, -k[0], -k[1], k[0], 0.0)
    KK = _mm(K, K)
    d = 1.0 + c
    if d < 1e-9:  # only for an exactly reversed axis (180 deg in one frame); NaN stays NaN
        d = 1e-9
    R = (1.0 + K[0] + KK[0] / d, K[1] + KK[1] / d, K[2] + KK[2] / d,
         K[3] + KK[3] / d, 1.0 + K[4] + KK[4] / d, K[5] + KK[5] / d,
         K[6] + KK[6] / d, K[7] + KK[7] / d, 1.0 + K[8] + KK[8] / d)
    return _mm(R, parent)


@njit(cache=True, nogil=True, error_model='numpy')
def _across(v, a):
    """The part of v across direction a."""
    au = _unit(a)
    return _sub(v, _scale(_dot(v, au), au))


@njit(cache=True, nogil=True, error_model='numpy')
def _sine(a, v):
    """How far v is from parallel to a, as a sine (NaN for a zero v)."""
    return _norm(_across(v, a)) / _norm(v)


@njit(cache=True, nogil=True, error_model='numpy')
def _aim_root(a, a0, v, v0):
    """Frame with axis a (rest a0), twist from v (rest v0); no parent to fade into."""
    return _triad(a, a0, _across(v, a), v0)


@njit(cache=True, nogil=True, error_model='numpy')
def _aim(a, a0, v, v0, weight, parent):
    """Frame with axis a (rest a0) and twist from v (rest v0), fading into the parent frame
    swung onto a where `weight` (a sine) is small."""
    vp = _across(v, a)
    a0u = _unit(a0)
    v0p = _unit(_sub(v0, _scale(_dot(v0, a0u), a0u)))
    w = (weight - _BLEND[0]) / (_BLEND[1] - _BLEND[0])
    w = 0.0 if w < 0.0 else (1.0 if w > 1.0 else w)
    if not math.isfinite(w):  # a missing twist reference: the parent's
        w = 0.0
    ref = _mv(_swing(parent, a0, a), v0p)
    own = _unit(vp)
    mix = _add(_scale(w, own), _scale(1.0 - w, ref))
    if _norm(mix) < 0.1:  # exactly opposed references mid-blend: keep the parent's
        mix = ref
    # at full weight the parent is not needed (it may be missing), at zero weight the own
    # reference is not (0 x NaN would leak in)
    if w >= 1.0:
        mix = own
    elif w <= 0.0:
        mix = ref
    return _triad(a, a0, mix, v0p)


@njit(cache=True, nogil=True, error_model='numpy')
def _bend(a, a0, f, d0, parent):
    """A limb's frame: axis a (rest a0), twist from the plane of the bend with the next bone f,
    whose hinge axis is a0 x d0 (d0: the rest direction the next bone flexes toward)."""
    n = _cross(_unit(a), _unit(f))
    return _aim(a, a0, n, _cross(_unit(a0), d0), _norm(n), parent)


# --------------------------------------------------------------------------------------------
# The body parts of one frame: P (C, 3) its landmarks (the parts write the ones they derive:
# pelvis, neck, skull), R (C, 3) the same on the zero pose, has (C,) the layout's landmarks


@njit(cache=True, nogil=True, error_model='numpy')
def _tilt_cost(s, t, q, a, c, spine):
    """_spine_tilt's cost (dimensionless) of tilt s: its squared distances from the lean share
    t and of the chord (m) from the spine's length (m), each over its uncertainty. s, t: rad;
    q, a, c: m^2, the chord's square at tilt s being q - 2 (a cos s + c sin s)."""
    chord = math.sqrt(max(q - 2.0 * (a * math.cos(s) + c * math.sin(s)), 0.0))
    return ((s - t) / _TILT_SD) ** 2 + ((chord - spine) / _CHORD_SD) ** 2


@njit(cache=True, nogil=True, error_model='numpy')
def _spine_tilt(axes, d, line0, o, spine, t):
    """The pelvis's forward tilt (rad, about the hip line from upright) from the lean share t
    and the spine's length: the tilt within _TILT_RANGE of t that best puts the pelvis joint
    `spine` m from the base of the neck, each of the two weighed by its uncertainty.

    Why: the spine between them is nearly straight and does not stretch (in every CMU clip here
    the chord pelvis -> base of the neck is 489.7-489.9 mm of the avatar's two 245 mm pieces),
    and the hips hang 90 mm from the pelvis joint (30 mm forward, 85 mm down): tilting the
    pelvis about the hip line swings the pelvis joint about the hips' centre and changes its
    chord to the neck by up to 0.9 mm per degree. That shows the subject's own pelvic tilt,
    which the trunk's lean does not (the six subjects' pelvis sits -7 to +9 deg from the
    share). Near the tilt where the chord is shortest (about 16 deg forward of the rest pose)
    the chord hardly changes, so a tracker's noise would swing the root: the weights let the
    lean share hold there. Missing joints: t unchanged (NaN where they are).

    axes: lat, up, fwd (the hip line, the vertical across it, lat x up); d: the base of the
    neck from the hips' centre (m, world); line0, o: the hip line and the pelvis joint from the
    hips' centre on the rest pose (m). The frame at tilt s takes the rest axes l0, u0, f0 to
    lat, cos s up + sin s fwd, cos s fwd - sin s up, so the chord^2 is
    q - 2 (a cos s + c sin s). Searched on a grid of _TILT_STEPS per side, then the parabola
    through the best three."""
    lat, up, fwd = axes
    l0 = _unit(line0)
    u0 = _unit(_across((0.0, 0.0, 1.0), l0))
    f0 = _cross(l0, u0)
    ol, ou, of = _dot(o, l0), _dot(o, u0), _dot(o, f0)
    dl, du, df = _dot(d, lat), _dot(d, up), _dot(d, fwd)
    a = ou * du + of * df
    c = ou * df - of * du
    q = _dot(d, d) + _dot(o, o) - 2.0 * ol * dl
    h = _TILT_RANGE / _TILT_STEPS
    best, cost = 0, _tilt_cost(t, t, q, a, c, spine)
    if not math.isfinite(cost):
        return t
    for i in range(-_TILT_STEPS, _TILT_STEPS + 1):
        j = _tilt_cost(t + h * i, t, q, a, c, spine)
        if j < cost:
            best, cost = i, j
    s = t + h * best
    if abs(best) == _TILT_STEPS:  # at the range's end: no parabola past it
        return s
    lo, hi = _tilt_cost(s - h, t, q, a, c, spine), _tilt_cost(s + h, t, q, a, c, spine)
    bend = lo + hi - 2.0 * cost
    return s + (0.5 * h * (lo - hi) / bend if bend > 0.0 else 0.0)


@njit(cache=True, nogil=True, error_model='numpy')
def _pelvic_tilt(line, trunk, trunk0, lean_only, d, line0, o, spine):
    """The pelvis's up direction and its rest one for a layout with the hips and shoulders
    alone: the pelvis leans forward about the hip line by _PELVIC_TILT of the trunk's lean from
    its rest (both from the vertical). The trunk's own lean put the pelvis off by 31 deg (p95)
    in the jump and 16 deg in the run, the pelvis joint 23 mm; _PELVIC_TILT fits the four
    bundled CMU clips (p95 8 deg or less in each; 0.4 of the lean, as the lumbopelvic rhythm
    of trunk flexion has it). Unless lean_only, that tilt is then set by the spine's length
    (`_spine_tilt`; d, line0, o, spine as there). Lying down (the hip line near vertical): the
    trunk itself."""
    lat = _unit(line)
    up = _across((0.0, 0.0, 1.0), lat)
    if not _norm(up) > 0.3:
        return trunk, trunk0
    up = _unit(up)
    fwd = _cross(lat, up)
    lean = math.atan2(_dot(trunk, fwd), _dot(trunk, up)) - math.atan2(trunk0[0], trunk0[2])
    t = _PELVIC_TILT * lean
    if not lean_only:
        t = _spine_tilt((lat, up, fwd), d, line0, o, spine, t)
    return _add(_scale(math.cos(t), up), _scale(math.sin(t), fwd)), (0.0, 0.0, 1.0)


@njit(cache=True, nogil=True, error_model='numpy')
def _pelvis(P, R, has, spine):
    """The pelvis frame: the hip line, twist from the pelvis joint, the neck or the shoulders'
    centre; derives the pelvis joint where the layout has none (without a neck joint from the
    base of the neck derived before it and `spine`, m, the pelvis-neck chord; NaN: from the
    trunk's lean alone)."""
    hip_c, hip_c0 = _mid(_get(P, _L + _HIP), _get(P, _R + _HIP)), \
        _mid(_get(R, _L + _HIP), _get(R, _R + _HIP))
    line = _sub(_get(P, _L + _HIP), _get(P, _R + _HIP))
    line0 = _sub(_get(R, _L + _HIP), _get(R, _R + _HIP))
    o = _sub(_get(R, _PELVIS), hip_c0)
    if has[_PELVIS]:
        v, v0 = _sub(_get(P, _PELVIS), hip_c), _sub(_get(R, _PELVIS), hip_c0)
    elif has[_NECK]:
        v, v0 = _sub(_get(P, _NECK), hip_c), _sub(_get(R, _NECK), hip_c0)
    else:
        v = _sub(_mid(_get(P, _L + _SHOULDER), _get(P, _R + _SHOULDER)), hip_c)
        v0 = _sub(_mid(_get(R, _L + _SHOULDER), _get(R, _R + _SHOULDER)), hip_c0)
        v, v0 = _pelvic_tilt(line, v, v0, math.isnan(spine), _sub(_get(P, _NECK), hip_c),
                             line0, o, spine)
    B = _aim_root(line, line0, v, v0)
    if not has[_PELVIS]:
        _put(P, _PELVIS, _add(hip_c, _mv(B, o)))
    return B


@njit(cache=True, nogil=True, error_model='numpy')
def _upper_torso(P, R, has):
    """The chest frame: the shoulder line, twist from the chest, the neck or the trunk; derives
    the base of the neck where the layout has none."""
    sh_c = _mid(_get(P, _L + _SHOULDER), _get(P, _R + _SHOULDER))
    sh_c0 = _mid(_get(R, _L + _SHOULDER), _get(R, _R + _SHOULDER))
    line = _sub(_get(P, _L + _SHOULDER), _get(P, _R + _SHOULDER))
    line0 = _sub(_get(R, _L + _SHOULDER), _get(R, _R + _SHOULDER))
    neck, neck0 = _get(P, _NECK), _get(R, _NECK)
    if has[_NECK] and has[_CHEST]:
        B = _aim_root(line, line0, _sub(neck, _get(P, _CHEST)), _sub(neck0, _get(R, _CHEST)))
    elif has[_NECK]:
        # the neck above the shoulders' line tilts the chest exactly; else the spine below it
        # (joint_body._upper_torso)
        v, v0 = _sub(neck, sh_c), _sub(neck0, sh_c0)
        low = _MID_SPINE if has[_MID_SPINE] else _PELVIS
        w, w0 = _sub(neck, _get(P, low)), _sub(neck0, _get(R, low))
        if _dot(v, _unit(w)) > 0.0:
            B = _aim_root(line, line0, v, v0)
        else:
            B = _aim_root(line, line0, w, w0)
    else:
        hip_c = _mid(_get(P, _L + _HIP), _get(P, _R + _HIP))
        hip_c0 = _mid(_get(R, _L + _HIP), _get(R, _R + _HIP))
        v, v0 = _unit(_sub(sh_c, hip_c)), _unit(_sub(sh_c0, hip_c0))
        if has[_EAR_L] and has[_EAR_R]:
            # the trunk leans the chest only in part: a quarter of the neck's direction (the
            # shoulders' centre -> the ears') with it took the CMU clips' chest closer (capsule
            # ends p95 over the four bundled clips, noise-free: 42 -> 37 mm summed, worst 16 ->
            # 15; an unseen clip 12 -> 9), from half of it on, the jump went worse
            n = _sub(_mid(_get(P, _EAR_L), _get(P, _EAR_R)), sh_c)
            n0 = _sub(_mid(_get(R, _EAR_L), _get(R, _EAR_R)), sh_c0)
            if math.isfinite(_norm(n)):
                v, v0 = _add(v, _scale(_CHEST_NECK, _unit(n))), _add(v0, _scale(_CHEST_NECK,
                                                                                _unit(n0)))
        B = _aim_root(line, line0, v, v0)
    if not has[_NECK]:
        _put(P, _NECK, _add(sh_c, _mv(B, _sub(neck0, sh_c0))))
    return B


@njit(cache=True, nogil=True, error_model='numpy')
def _lower_torso(P, R, has, pelvis_B, chest_B):
    """Pelvis -> spine (or the spine's chord to the neck, or without a neck joint the trunk's
    line), its twist halfway between the pelvis's and the chest's."""
    top = _LUMBAR if has[_LUMBAR] else (_MID_SPINE if has[_MID_SPINE] else _NECK)
    a, a0 = _sub(_get(P, top), _get(P, _PELVIS)), _sub(_get(R, top), _get(R, _PELVIS))
    if not has[_NECK] and top == _NECK:
        # hips and shoulders alone: the trunk's line (hips' centre -> shoulders') leans as the
        # lower torso does within 1.3 deg in every bundled clip; the chord between the derived
        # pelvis and neck joints carries both their errors
        a = _sub(_mid(_get(P, _L + _SHOULDER), _get(P, _R + _SHOULDER)),
                 _mid(_get(P, _L + _HIP), _get(P, _R + _HIP)))
        a0 = _sub(_mid(_get(R, _L + _SHOULDER), _get(R, _R + _SHOULDER)),
                  _mid(_get(R, _L + _HIP), _get(R, _R + _HIP)))
    v = _add(_mv(pelvis_B, _FORWARD), _mv(chest_B, _FORWARD))
    return _aim(a, a0, v, _FORWARD, _sine(a, v), pelvis_B)


@njit(cache=True, nogil=True, error_model='numpy')
def _head(P, R, has, chest_B):
    """The head: the ear line, twist from the nose (else the chest's forward), or without ears
    the neck's direction to the base of the skull; derives the skull from the ears."""
    fwd = _mv(chest_B, _FORWARD)
    if has[_EAR_L] and has[_EAR_R]:
        ear_c, ear_c0 = _mid(_get(P, _EAR_L), _get(P, _EAR_R)), \
            _mid(_get(R, _EAR_L), _get(R, _EAR_R))
        if has[_NOSE]:
            v, v0 = _sub(_get(P, _NOSE), ear_c), _sub(_get(R, _NOSE), ear_c0)
        else:
            v, v0 = fwd, _FORWARD
        B = _aim_root(_sub(_get(P, _EAR_L), _get(P, _EAR_R)),
                      _sub(_get(R, _EAR_L), _get(R, _EAR_R)), v, v0)
        if not has[_SKULL]:
            _put(P, _SKULL, _add(ear_c, _mv(B, _sub(_get(R, _SKULL), ear_c0))))
        return B
    # no ears: the caller has checked that the layout has the skull
    a, a0 = _sub(_get(P, _SKULL), _get(P, _NECK)), _sub(_get(R, _SKULL), _get(R, _NECK))
    return _aim(a, a0, fwd, _FORWARD, _sine(a, fwd), chest_B)


@njit(cache=True, nogil=True, error_model='numpy')
def _arm(P, R, has, s, chest_B, flexion):
    """Upper arm, forearm and hand frames of the side whose first column is s."""
    sh, el, wr = _get(P, s + _SHOULDER), _get(P, s + _ELBOW), _get(P, s + _WRIST)
    el0, wr0 = _get(R, s + _ELBOW), _get(R, s + _WRIST)
    upper = _bend(_sub(el, sh), _sub(el0, _get(R, s + _SHOULDER)), _sub(wr, el), flexion,
                  chest_B)
    # the elbow is a hinge: the forearm is the upper arm turned about it
    f0 = _sub(wr0, el0)
    fore = _swing(upper, f0, _sub(wr, el))
    fingers = has[s + _INDEX] and has[s + _PINKY]
    if fingers:  # across the palm
        v = _sub(_get(P, s + _INDEX), _get(P, s + _PINKY))
        v0 = _sub(_get(R, s + _INDEX), _get(R, s + _PINKY))
    elif has[s + _THUMB]:
        v, v0 = _sub(_get(P, s + _THUMB), wr), _sub(_get(R, s + _THUMB), wr0)
    else:
        v, v0 = _mv(fore, _FORWARD), _FORWARD
    tip = s + _HANDTIP if has[s + _HANDTIP] else (s + _HAND if has[s + _HAND] else -1)
    if tip >= 0:
        a, a0 = _sub(_get(P, tip), wr), _sub(_get(R, tip), wr0)
    elif fingers:
        a = _sub(_mid(_get(P, s + _INDEX), _get(P, s + _PINKY)), wr)
        a0 = _sub(_mid(_get(R, s + _INDEX), _get(R, s + _PINKY)), wr0)
    else:  # no hand landmark: the hand continues the forearm
        a, a0 = _sub(wr, el), f0
    hand = _aim(a, a0, v, v0, _sine(a, v), fore)
    return upper, fore, hand


@njit(cache=True, nogil=True, error_model='numpy')
def _leg(P, R, has, s, pelvis_B, flexion):
    """Thigh, shank and foot frames of the side whose first column is s."""
    hp, kn, an = _get(P, s + _HIP), _get(P, s + _KNEE), _get(P, s + _ANKLE)
    kn0, an0 = _get(R, s + _KNEE), _get(R, s + _ANKLE)
    thigh = _bend(_sub(kn, hp), _sub(kn0, _get(R, s + _HIP)), _sub(an, kn), flexion, pelvis_B)
    # the knee is a hinge too: the shank is the thigh turned about it
    s0 = _sub(an0, kn0)
    shank = _swing(thigh, s0, _sub(an, kn))
    toe = s + _TOE if has[s + _TOE] else (s + _BALL if has[s + _BALL] else -1)
    if toe < 0:  # no foot landmark: the foot keeps its rest angle to the shank
        return thigh, shank, shank
    t, t0 = _sub(_get(P, toe), an), _sub(_get(R, toe), an0)
    if has[s + _HEEL]:
        v, v0 = _sub(_get(P, s + _HEEL), an), _sub(_get(R, s + _HEEL), an0)
        return thigh, shank, _aim(t, t0, v, v0, _sine(t, v), shank)
    # the ankle's bend (shank x foot) is a hinge in the CMU skeleton
    hinge0 = _cross(_unit(s0), _unit(t0))
    ankle = _cross(_unit(_sub(an, kn)), _unit(t))
    return thigh, shank, _aim(t, t0, ankle, hinge0, _norm(ankle), shank)


# --------------------------------------------------------------------------------------------
# Joints -> poses


@njit(cache=True, nogil=True, error_model='numpy')
def _observe(x, col, count, C):
    """(F, C, 3) landmarks: the mean of the finite joints placed at each (per coordinate, as
    np.nanmean), NaN where none is or the layout has none there."""
    F, J = x.shape[0], x.shape[1]
    P = np.full((F, C, 3), np.nan)
    total, finite = np.empty((C, 3)), np.empty((C, 3))
    for f in range(F):
        total[:] = 0.0
        finite[:] = 0.0
        for j in range(J):
            c = col[j]
            for k in range(3):
                if count[c] == 1:
                    P[f, c, k] = x[f, j, k]
                elif not math.isnan(x[f, j, k]):
                    total[c, k] += x[f, j, k]
                    finite[c, k] += 1.0
        for c in range(C):
            if count[c] > 1:
                for k in range(3):
                    P[f, c, k] = total[c, k] / finite[c, k]  # 0 / 0: none is finite, NaN
    return P


@njit(cache=True, nogil=True, error_model='numpy')
def _place(origin, body, seg, P, m, B):
    """Segment seg: origin at landmark column m, body frame B."""
    for k in range(3):
        origin[seg, k] = P[m, k]
    for k in range(9):
        body[seg, k] = B[k]


@njit(cache=True, nogil=True, error_model='numpy')
def _limbs(P, R, has, flexion, pelvis_B, chest_B, origin, body):
    """The arms' and legs' origins and frames of one frame into `origin`, `body`."""
    for i in range(2):
        s, arm, leg = (_L, _ARM_L_S, _LEG_L_S) if i == 0 else (_R, _ARM_R_S, _LEG_R_S)
        upper, fore, hand = _arm(P, R, has, s, chest_B, _get(flexion, 0))
        _place(origin, body, arm, P, s + _SHOULDER, upper)
        _place(origin, body, arm + 1, P, s + _ELBOW, fore)
        _place(origin, body, arm + 2, P, s + _WRIST, hand)
        thigh, shank, foot = _leg(P, R, has, s, pelvis_B, _get(flexion, 1))
        _place(origin, body, leg, P, s + _HIP, thigh)
        _place(origin, body, leg + 1, P, s + _KNEE, shank)
        _place(origin, body, leg + 2, P, s + _ANKLE, foot)


@njit(cache=True, nogil=True, error_model='numpy')
def _solve_frame(P, R, has, flexion, spine, origin, body):
    """Origins (16, 3) and body frames (16, 9) of one frame into `origin`, `body`. The order
    matters: each part derives landmarks the next ones use (pelvis, neck, skull). Without a
    pelvis or neck joint the pelvis is placed from the derived neck (`spine`, m: see _pelvis),
    and that chest reads no pelvis."""
    if has[_PELVIS] or has[_NECK]:
        pelvis_B = _pelvis(P, R, has, spine)
        chest_B = _upper_torso(P, R, has)
    else:
        chest_B = _upper_torso(P, R, has)
        pelvis_B = _pelvis(P, R, has, spine)
    _place(origin, body, _PELVIS_S, P, _PELVIS, pelvis_B)
    _place(origin, body, _UPPER_TORSO_S, P, _NECK, chest_B)
    _place(origin, body, _LOWER_TORSO_S, P, _PELVIS, _lower_torso(P, R, has, pelvis_B, chest_B))
    _place(origin, body, _HEAD_S, P, _SKULL, _head(P, R, has, chest_B))
    _limbs(P, R, has, flexion, pelvis_B, chest_B, origin, body)


@njit(cache=True, nogil=True, error_model='numpy')
def _quat(M):
    """Unit quaternion [x, y, z, w] of a rotation matrix (9,), the one (sign included) scipy's
    Rotation.from_matrix gives: scipy cannot run in a nogil kernel, and one call of it costs
    more than solving a frame. Computed from the largest of the diagonal and the trace (the
    first of equals), which keeps the normalised vector's length away from zero, so no branch
    loses precision. The frames here are orthonormal to rounding, where scipy projects nothing
    first."""
    tr = M[0] + M[4] + M[8]
    i, best = 0, M[0]
    if M[4] > best:
        i, best = 1, M[4]
    if M[8] > best:
        i, best = 2, M[8]
    if tr > best:
        i = 3
    if i == 0:
        q = (1.0 - tr + 2.0 * M[0], M[3] + M[1], M[6] + M[2], M[7] - M[5])
    elif i == 1:
        q = (M[3] + M[1], 1.0 - tr + 2.0 * M[4], M[7] + M[5], M[2] - M[6])
    elif i == 2:
        q = (M[6] + M[2], M[7] + M[5], 1.0 - tr + 2.0 * M[8], M[3] - M[1])
    else:
        q = (M[7] - M[5], M[2] - M[6], M[3] - M[1], 1.0 + tr)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit(cache=True, nogil=True, error_model='numpy')
def _segment_frame(body, rest_rotation, s):
    """The segment frame body[s] @ rest_rotation[s] (9,)."""
    r0 = rest_rotation[s]
    return _mm((body[s, 0], body[s, 1], body[s, 2], body[s, 3], body[s, 4], body[s, 5],
                body[s, 6], body[s, 7], body[s, 8]),
               (r0[0, 0], r0[0, 1], r0[0, 2], r0[1, 0], r0[1, 1], r0[1, 2], r0[2, 0], r0[2, 1],
                r0[2, 2]))


@njit(cache=True, nogil=True, error_model='numpy')
def _dot4(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


@njit(cache=True, nogil=True, error_model='numpy')
def solve_poses(x, col, count, R, has, rest_rotation, flexion, spine):
    """Segment poses of every frame of joints x (F, J, 3) m.

    Args:
        col: (J,) the landmark column of each joint; count: (C,) joints per column.
        R, has, rest_rotation, flexion: as in the module docstring (`has` True for MARKS the
            layout has; a layout without ears has the skull).
        spine: m, the pelvis joint's distance from the base of the neck that sets the pelvis's
            tilt where the layout has neither (`_spine_tilt`); NaN: the trunk's lean alone.

    Returns:
        poses (F, 16, 7) [x, y, z, qx, qy, qz, qw], NaN where not valid; valid (F, 16) bool;
        P (F, C, 3) the landmarks, observed and derived (pelvis, neck, skull), m.
    """
    F = x.shape[0]
    P = _observe(x, col, count, R.shape[0])
    poses = np.full((F, 16, 7), np.nan)
    valid = np.zeros((F, 16), np.bool_)
    origin, body = np.empty((16, 3)), np.empty((16, 9))
    # Quaternion signs: continuous along all (frame, segment) pairs in order, an invalid one
    # counting as the identity, then along each segment's valid frames (what matrix_to_quat on
    # the (F x 16) stack and the continuity per segment make, so the poses are unchanged)
    last, flip = (0.0, 0.0, 0.0, 1.0), 1.0
    prev = np.zeros((16, 4))  # each segment's last valid quaternion, before its own flips
    sign = np.ones(16)
    seen = np.zeros(16, np.bool_)
    for f in range(F):
        _solve_frame(P[f], R, has, flexion, spine, origin, body)
        for s in range(16):
            frame = _segment_frame(body, rest_rotation, s)
            ok = True
            for k in range(9):
                ok = ok and math.isfinite(frame[k]) and (k > 2 or math.isfinite(origin[s, k]))
            q = _quat(frame) if ok else (0.0, 0.0, 0.0, 1.0)
            if (f > 0 or s > 0) and _dot4(q, last) < 0.0:
                flip = -flip
            last = q
            if not ok:
                continue
            valid[f, s] = True
            q = (flip * q[0], flip * q[1], flip * q[2], flip * q[3])
            if seen[s] and _dot4(q, prev[s]) < 0.0:
                sign[s] = -sign[s]
            seen[s] = True
            for k in range(4):
                prev[s, k] = q[k]
                poses[f, s, 3 + k] = sign[s] * q[k]
            for k in range(3):
                poses[f, s, k] = origin[s, k]
    return poses, valid, P
