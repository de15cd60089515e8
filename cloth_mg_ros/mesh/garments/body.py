"""The capsule body the garments are designed on: checks, a standard body, rigid motion,
signed distances, ray casts and the segments' local frames (see the package docstring for
the body's conventions: segment name -> (p0 (3,), p1 (3,), radius), metres, z up)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numba import njit

from cloth_mg_ros.collision.capsules import point_segment_distances
from cloth_mg_ros.errors import ClothInputError

BODY_SEGMENTS = (
    'pelvis', 'lower_torso', 'upper_torso', 'head',
    'upper_arm_l', 'lower_arm_l', 'hand_l', 'upper_arm_r', 'lower_arm_r', 'hand_r',
    'upper_leg_l', 'lower_leg_l', 'foot_l', 'upper_leg_r', 'lower_leg_r', 'foot_r',
)
ARM_SEGMENTS = ('upper_arm_l', 'lower_arm_l', 'hand_l', 'upper_arm_r', 'lower_arm_r', 'hand_r')


_PIN_REFERENCE = {
    'upper_torso': 'shoulders', 'head': 'shoulders',
    'upper_arm_l': 'shoulders', 'lower_arm_l': 'shoulders', 'hand_l': 'shoulders',
    'upper_arm_r': 'shoulders', 'lower_arm_r': 'shoulders', 'hand_r': 'shoulders',
}  # everything else: 'hips'

Capsule = tuple[np.ndarray, np.ndarray, float]


def _vec3(value: object, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ClothInputError(f'{what} must be 3 numbers, got {value!r}') from None
    if arr.shape != (3,):
        raise ClothInputError(f'{what} must have shape (3,), got shape {arr.shape}')
    if not np.isfinite(arr).all():
        raise ClothInputError(f'{what} is not finite: {arr.tolist()}')
    return arr


def validate_body(body: Mapping, required: tuple[str, ...] = BODY_SEGMENTS
                  ) -> dict[str, Capsule]:
    """Check a body and return it as {name: (p0 (3,) float64, p1 (3,) float64, radius)}.

    body: mapping segment name -> (p0, p1, radius), metres. required: names that must be
    present. Raises ClothInputError naming the missing segment, or the segment and field
    that is malformed or not finite, or a radius that is not positive.
    """
    if not isinstance(body, Mapping):
        raise ClothInputError(
            f'body must be a dict segment name -> (p0, p1, radius), got {type(body).__name__}')
    for name in required:
        if name not in body:
            raise ClothInputError(
                f"body is missing segment '{name}' (needed: {', '.join(required)}; "
                f"given: {', '.join(map(str, body)) or 'nothing'})")
    out: dict[str, Capsule] = {}
    for name, value in body.items():
        if not isinstance(name, str):
            raise ClothInputError(f'body segment names must be strings, got {name!r}')
        try:
            p0, p1, radius = value
        except (TypeError, ValueError):
            raise ClothInputError(
                f"body segment '{name}' must be (p0, p1, radius), got {value!r}") from None
        a = _vec3(p0, f"body segment '{name}' p0")
        b = _vec3(p1, f"body segment '{name}' p1")
        try:
            r = float(radius)
        except (TypeError, ValueError):
            raise ClothInputError(
                f"body segment '{name}' radius must be a number, got {radius!r}") from None
        if not math.isfinite(r) or r <= 0.0:
            raise ClothInputError(
                f"body segment '{name}' radius must be positive and finite, got {radius!r}")
        out[name] = (a, b, r)
    return out


def standing_body() -> dict[str, Capsule]:
    """A 1.75 m adult standing upright in a neutral pose (for tests and development).

    Feet on z = 0, facing +x, left along +y; arms hanging about 18 degrees away from the
    body (forearms 20 degrees, slightly forward), so there is a gap between arms and torso.
    Returns {segment: (p0 (3,), p1 (3,), radius)} in metres for all `BODY_SEGMENTS`; limbs
    run proximal -> distal, torso segments bottom -> top.
    """
    def arm(side: float) -> dict[str, Capsule]:
        sh = np.array([0.0, 0.19 * side, 1.43])
        a1, a2 = math.radians(18.0), math.radians(20.0)
        elbow = sh + 0.29 * np.array([0.0, math.sin(a1) * side, -math.cos(a1)])
        wrist = elbow + np.array([0.03, 0.25 * math.sin(a2) * side, -0.25 * math.cos(a2)])
        tip = wrist + np.array([0.01, 0.02 * side, -0.12])
        s = 'l' if side > 0 else 'r'
        return {f'upper_arm_{s}': (sh, elbow, 0.045), f'lower_arm_{s}': (elbow, wrist, 0.038),
                f'hand_{s}': (wrist, tip, 0.035)}

    def leg(side: float) -> dict[str, Capsule]:
        hip = np.array([0.0, 0.09 * side, 0.90])
        knee = np.array([0.0, 0.095 * side, 0.49])
        ankle = np.array([0.0, 0.095 * side, 0.085])
        s = 'l' if side > 0 else 'r'
        return {f'upper_leg_{s}': (hip, knee, 0.07), f'lower_leg_{s}': (knee, ankle, 0.05),
                f'foot_{s}': (np.array([-0.02, 0.10 * side, 0.045]),
                              np.array([0.16, 0.11 * side, 0.04]), 0.04)}

    body: dict[str, Capsule] = {
        'pelvis': (np.array([0.0, 0.0, 0.90]), np.array([0.0, 0.0, 1.00]), 0.145),
        'lower_torso': (np.array([0.0, 0.0, 1.00]), np.array([0.0, 0.0, 1.18]), 0.12),
        'upper_torso': (np.array([0.0, 0.0, 1.18]), np.array([0.0, 0.0, 1.38]), 0.13),
        'head': (np.array([0.0, 0.0, 1.57]), np.array([0.0, 0.0, 1.66]), 0.09),
    }
    for side in (1.0, -1.0):
        body.update(arm(side))
        body.update(leg(side))
    return {name: body[name] for name in BODY_SEGMENTS}


def transform_body(body: Mapping, rotation: np.ndarray, translation: np.ndarray
                   ) -> dict[str, Capsule]:
    """The body moved rigidly: every p -> rotation @ p + translation (radii unchanged).

    rotation: (3, 3) proper rotation matrix; translation: (3,) metres.
    """
    rot = np.asarray(rotation, dtype=np.float64)
    t = _vec3(translation, 'translation')
    if rot.shape != (3, 3) or not np.isfinite(rot).all():
        raise ClothInputError(f'rotation must be a finite (3, 3) matrix, got shape {rot.shape}')
    checked = validate_body(body, required=())
    return {k: (rot @ p0 + t, rot @ p1 + t, r) for k, (p0, p1, r) in checked.items()}


def body_arrays(body: Mapping[str, Capsule], names: tuple[str, ...] | list[str] | None = None
                ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(names, p0 (k, 3), p1 (k, 3), radius (k,)) of the named segments (default: all), m."""
    names = list(body) if names is None else list(names)
    p0 = np.array([body[n][0] for n in names], dtype=np.float64).reshape(-1, 3)
    p1 = np.array([body[n][1] for n in names], dtype=np.float64).reshape(-1, 3)
    r = np.array([body[n][2] for n in names], dtype=np.float64)
    return names, p0, p1, r


def capsule_distances(points: np.ndarray, body: Mapping
                      ) -> tuple[list[str], np.ndarray]:
    """Signed distances of points to the capsule surfaces of a body.

    points: (n, 3) metres. Returns (names, d) with d (n, k) metres, column j for segment
    names[j]: distance to segment names[j]'s axis minus its radius (negative inside).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    names, p0, p1, r = body_arrays(validate_body(body, required=()))
    return names, point_segment_distances(pts, p0, p1) - r[None, :]


def ray_capsules(origin: np.ndarray, direction: np.ndarray, p0: np.ndarray, p1: np.ndarray,
                  radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit parameters t of the rays origin + t direction (n, 3; unit directions)
    through capsules (c,): arrays (n, c), NaN where the ray's line misses the capsule.

    A capsule is convex, so its intersection with a line is one interval: the smallest entry
    and the largest exit over its cylinder and its two end spheres.
    """
    o = np.ascontiguousarray(origin, dtype=np.float64).reshape(-1, 3)
    u = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, 3)
    t_in = np.empty((len(o), len(p0)))
    t_out = np.empty_like(t_in)
    # A kernel, not numpy: a garment's design casts a few thousand rays at 16 capsules, and
    # numpy's (n, c, 3) temporaries would make this most of dressing a garment
    # (doc/scenes.md), which a live node pays while the first poses wait.
    _ray_capsules(o, u, np.ascontiguousarray(p0, dtype=np.float64),
                  np.ascontiguousarray(p1, dtype=np.float64),
                  np.ascontiguousarray(radius, dtype=np.float64), t_in, t_out)
    return t_in, t_out


@njit(cache=True, nogil=True)
def _fmin(a: float, b: float) -> float:
    """np.fmin: the smaller, ignoring a NaN."""
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return min(a, b)


@njit(cache=True, nogil=True)
def _fmax(a: float, b: float) -> float:
    """np.fmax: the larger, ignoring a NaN."""
    if math.isnan(a):
        return b
    if math.isnan(b):
        return a
    return max(a, b)


@njit(cache=True, nogil=True)
def _ray_capsules(o, u, p0, p1, radius, t_in, t_out):  # pragma: no cover - numba
    nan, inf = np.nan, np.inf
    for i in range(o.shape[0]):
        ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
        ux, uy, uz = u[i, 0], u[i, 1], u[i, 2]
        for j in range(p0.shape[0]):
            r2 = radius[j] * radius[j]
            lo_t, hi_t = nan, nan
            for e in range(2):  # the end spheres
                cx, cy, cz = (p0[j, 0], p0[j, 1], p0[j, 2]) if e == 0 else (
                    p1[j, 0], p1[j, 1], p1[j, 2])
                wx, wy, wz = ox - cx, oy - cy, oz - cz
                b = wx * ux + wy * uy + wz * uz
                disc = b * b - ((wx * wx + wy * wy + wz * wz) - r2)
                if disc >= 0.0:
                    s = math.sqrt(disc)
                    lo_t, hi_t = _fmin(lo_t, -b - s), _fmax(hi_t, -b + s)
            ax, ay, az = p1[j, 0] - p0[j, 0], p1[j, 1] - p0[j, 1], p1[j, 2] - p0[j, 2]
            length = math.sqrt(ax * ax + ay * ay + az * az)
            d = max(length, 1e-300)
            ax, ay, az = ax / d, ay / d, az / d
            wx, wy, wz = ox - p0[j, 0], oy - p0[j, 1], oz - p0[j, 2]
            ua = ux * ax + uy * ay + uz * az
            wa = wx * ax + wy * ay + wz * az
            upx, upy, upz = ux - ua * ax, uy - ua * ay, uz - ua * az
            wpx, wpy, wpz = wx - wa * ax, wy - wa * ay, wz - wa * az
            qa = upx * upx + upy * upy + upz * upz
            qb = upx * wpx + upy * wpy + upz * wpz
            qc = (wpx * wpx + wpy * wpy + wpz * wpz) - r2
            if qa < 1e-12:  # the ray runs along the axis: inside the infinite cylinder or not
                c0, c1 = (-inf, inf) if qc <= 0.0 else (nan, nan)
            else:
                disc = qb * qb - qa * qc
                s = math.sqrt(disc) if disc >= 0.0 else nan
                c0, c1 = (-qb - s) / qa, (-qb + s) / qa
            if abs(ua) > 1e-12:  # the slab between the end caps' planes
                s0, s1 = -wa / ua, (length - wa) / ua
                lo, hi = min(s0, s1), max(s0, s1)
            elif 0.0 <= wa <= length:
                lo, hi = -inf, inf
            else:
                lo, hi = nan, nan
            # np.maximum / np.minimum: a NaN wins (no interval)
            c0 = nan if (math.isnan(c0) or math.isnan(lo)) else max(c0, lo)
            c1 = nan if (math.isnan(c1) or math.isnan(hi)) else min(c1, hi)
            if c0 <= c1:
                lo_t, hi_t = _fmin(lo_t, c0), _fmax(hi_t, c1)
            t_in[i, j], t_out[i, j] = lo_t, hi_t


def segment_frame(p0: np.ndarray, p1: np.ndarray, reference: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Local frame of a segment from its capsule axis and a reference direction.

    p0, p1: (3,) segment ends, metres; reference: (3,) any direction not parallel to the axis.
    Returns (origin (3,), R (3, 3)): origin = p0; R's columns are the local axes in world
    coordinates: z = unit(p1 - p0) (along the segment), y = the reference made orthogonal to
    z and normalised, x = y cross z. A local point q maps to origin + R @ q; a world point x
    to R.T @ (x - origin). With the reference pointing to the body's left and a segment
    pointing up, x points forward. Where the reference is (nearly) parallel to the axis, the
    world axis least aligned with the segment replaces it. Raises ClothInputError for a
    zero-length segment.
    """
    a = _vec3(p0, 'segment p0')
    axis = _vec3(p1, 'segment p1') - a
    length = float(np.linalg.norm(axis))
    if length < 1e-9:
        raise ClothInputError(f'segment has zero length (p0 = p1 = {a.tolist()}): no frame')
    ez = axis / length
    ref = _vec3(reference, 'reference direction')
    perp = ref - (ref @ ez) * ez
    if np.linalg.norm(perp) < 1e-6 * max(1.0, float(np.linalg.norm(ref))):
        ref = np.eye(3)[int(np.argmin(np.abs(ez)))]
        perp = ref - (ref @ ez) * ez
    ey = perp / np.linalg.norm(perp)
    ex = np.cross(ey, ez)
    return a, np.column_stack([ex, ey, ez])


def segment_reference(body: Mapping, segment: str) -> np.ndarray:
    """The reference direction (3,) this module uses for `segment_frame` of `segment`.

    upper_torso, head and arm segments: upper_arm_l.p0 - upper_arm_r.p0 (right to left
    shoulder joint); every other segment: upper_leg_l.p0 - upper_leg_r.p0 (hip joints).
    Both move with the body, so frames (and pins) follow its rigid motions and the torso's
    twist. Raises ClothInputError if the two segments it needs are missing.
    """
    kind = _PIN_REFERENCE.get(segment, 'hips')
    left, right = (('upper_arm_l', 'upper_arm_r') if kind == 'shoulders'
                   else ('upper_leg_l', 'upper_leg_r'))
    checked = validate_body(body, required=(left, right))
    return checked[left][0] - checked[right][0]


def body_segment_frame(body: Mapping[str, Capsule], segment: str
                       ) -> tuple[np.ndarray, np.ndarray]:
    """`segment_frame` of a segment of a checked body, with this module's reference."""
    p0, p1, _ = body[segment]
    return segment_frame(p0, p1, segment_reference(body, segment))
