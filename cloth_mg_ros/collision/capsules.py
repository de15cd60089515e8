"""A moving body of capsules (the avatar) as a cloth collider.

Each capsule is a segment p0-p1 (m) with a radius (m). `CapsuleCollider` holds what never
changes (radii, friction); where the body is lives in a `CapsulePose` value: the current and
the previous end points and the time between them, hence the velocity of every surface point
(for friction and for the contact's target velocity). A simulation keeps the pose in its State
(sim.model.ClothState.bodies) and queries ``collider.at(pose)``; `PosedCapsules` is that pair,
with ``set_pose`` for a body moved by hand outside a simulation.

Tunnelling. A limb can move further than its own radius in one step (a running foot at
30 Hz: 20 cm and more), and then a cloth particle can end a step inside the capsule or even on
its far side; where capsules overlap (hips, crotch, shoulders) the nearest way out of one
capsule can lead into another. Pushing particles out along the nearest normal then moves cloth
through limbs and wraps it around them. Instead each query is given where the particle was
(``x_prev``, outside the body after the last step): if the particle's side of the capsule
axis (then, carried along by the capsule's motion, against now) flipped, it went through, and
it is sent back out on the side it came from. Otherwise the nearest surface point is used:
a history direction for particles that merely slid around a limb would push them sideways.

The test is continuous (swept): a limb that moved clean through a particle in one step leaves
it beyond the capsule, outside any margin, yet on the other side. Such a particle is caught
when its path relative to the capsule (from where it was, carried along with the capsule, to
where it is) passes within the radius of the axis, and it too is sent back to the side it
came from. So the step need not be short enough for no limb to outrun its own radius: the
body scenes' substep rule only has to serve accuracy (sim.garment_sim).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from cloth_mg_ros.collision.colliders import Contacts
from cloth_mg_ros.errors import ClothInputError

CONTACT_CHUNKS = 64  # particle chunks of a contact query, shared out among the threads


@njit(cache=True, nogil=True)
def _closest_on_segment(x, a, b):
    """Parameter t in [0, 1] of the point of segment a-b closest to x."""
    ab0 = b[0] - a[0]
    ab1 = b[1] - a[1]
    ab2 = b[2] - a[2]
    ll = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
    if ll <= 0.0:
        return 0.0
    t = ((x[0] - a[0]) * ab0 + (x[1] - a[1]) * ab1 + (x[2] - a[2]) * ab2) / ll
    return min(1.0, max(0.0, t))


@njit(cache=True, nogil=True)
def segment_closest(a0, a1, b0, b1):
    """Parameters (s, t) in [0, 1] of the closest points a0 + s (a1 - a0) and b0 + t (b1 - b0)
    of segments a0-a1 and b0-b1 (3,) (clamped; Ericson, Real-Time Collision Detection,
    5.1.9)."""
    d1 = a1 - a0
    d2 = b1 - b0
    r = a0 - b0
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    f = d2[0] * r[0] + d2[1] * r[1] + d2[2] * r[2]
    eps = 1e-18
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = min(1.0, max(0.0, f / e))
    else:
        c = d1[0] * r[0] + d1[1] * r[1] + d1[2] * r[2]
        if e <= eps:
            t = 0.0
            s = min(1.0, max(0.0, -c / a))
        else:
            b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
            denom = a * e - b * b
            s = min(1.0, max(0.0, (b * f - c * e) / denom)) if denom > 0.0 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(1.0, max(0.0, -c / a))
            elif t > 1.0:
                t = 1.0
                s = min(1.0, max(0.0, (b - c) / a))
    return s, t


@njit(cache=True, nogil=True)
def _segment_segment_distance(a0, a1, b0, b1):
    """Distance between segments a0-a1 and b0-b1 (3,) (their closest points, segment_closest)."""
    s, t = segment_closest(a0, a1, b0, b1)
    d1 = a1 - a0
    d2 = b1 - b0
    g0 = a0[0] + d1[0] * s - b0[0] - d2[0] * t
    g1 = a0[1] + d1[1] * s - b0[1] - d2[1] * t
    g2 = a0[2] + d1[2] * s - b0[2] - d2[2] * t
    return np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@njit(cache=True, nogil=True, parallel=True)
def segment_distances(points, p0, p1, out):
    """out (n, k) = distance of each point (n, 3) to each segment p0-p1 (k, 3), m."""
    for i in prange(points.shape[0]):
        for c in range(p0.shape[0]):
            t = _closest_on_segment(points[i], p0[c], p1[c])
            s = 0.0
            for a in range(3):
                g = points[i, a] - (p0[c, a] + t * (p1[c, a] - p0[c, a]))
                s += g * g
            out[i, c] = np.sqrt(s)


def point_segment_distances(points: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """(n, k) distance from each of points (n, 3) to each segment p0-p1 (k, 3), m.

    The one capsule-distance routine of the package: the collider's clearance and the
    garment designs (fitting, implicit surfaces, clearance checks) both call it; a capsule's
    signed distance is this minus its radius.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    a = np.ascontiguousarray(p0, dtype=np.float64).reshape(-1, 3)
    b = np.ascontiguousarray(p1, dtype=np.float64).reshape(-1, 3)
    out = np.empty((len(pts), len(a)))
    if len(pts) and len(a):
        segment_distances(pts, a, b, out)
    return out


@njit(cache=True, nogil=True, parallel=True)
def nearest_segment_distances(points, p0, p1):
    """(k,) the smallest distance from any of points (n, 3) to each segment p0-p1 (k, 3), m:
    the column minima of segment_distances without its (n, k) array (the squared distance's
    minimum, then its square root: the same number, as the root is monotonic and exact)."""
    n = points.shape[0]
    k = p0.shape[0]
    chunks = min(CONTACT_CHUNKS, max(n, 1))
    part = np.full((chunks, k), np.inf)
    for ch in prange(chunks):
        for i in range(ch * n // chunks, (ch + 1) * n // chunks):
            for c in range(k):
                t = _closest_on_segment(points[i], p0[c], p1[c])
                s = 0.0
                for a in range(3):
                    g = points[i, a] - (p0[c, a] + t * (p1[c, a] - p0[c, a]))
                    s += g * g
                part[ch, c] = min(part[ch, c], s)
    out = np.empty(k)
    for c in range(k):
        m = np.inf
        for ch in range(chunks):
            m = min(m, part[ch, c])
        out[c] = np.sqrt(m)
    return out


def capsule_clearance(points: np.ndarray, p0: np.ndarray, p1: np.ndarray,
                      radius: np.ndarray) -> np.ndarray:
    """(k,) the smallest distance from any of points (n, 3) to each capsule's surface (p0, p1
    (k, 3) axis ends, radius (k,), m; negative where a point is inside); inf without points."""
    if len(points) == 0:
        return np.full(len(radius), np.inf)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return (nearest_segment_distances(pts, np.ascontiguousarray(p0, dtype=np.float64),
                                      np.ascontiguousarray(p1, dtype=np.float64))
            - np.asarray(radius, dtype=np.float64))


@njit(cache=True, nogil=True, parallel=True)
def _chunk_boxes(points, bounds, lo, hi):
    """lo, hi (c, 3): the bounding box of each chunk bounds[q]..bounds[q + 1] of points."""
    for q in prange(bounds.shape[0] - 1):
        for a in range(3):
            lo[q, a] = np.inf
            hi[q, a] = -np.inf
        for i in range(bounds[q], bounds[q + 1]):
            for a in range(3):
                lo[q, a] = min(lo[q, a], points[i, a])
                hi[q, a] = max(hi[q, a], points[i, a])


@njit(cache=True, nogil=True, parallel=True)
def _within(points, p0, p1, radius, reach, bounds, lo, hi, out):
    """out[c] = 1 where some point's distance to capsule c's surface (capsule_clearance's
    numbers: the segment distance's root less the radius) is at most reach[c]. A chunk of
    points whose box is further from the capsule's box than that is skipped; a capsule's
    scan stops at its first point within reach."""
    for c in prange(p0.shape[0]):
        out[c] = 0
        # a lower bound of a chunk's distance: the gap between its box and the segment's,
        # less a margin for rounding (it only skips what is surely out of reach)
        limit = reach[c] + radius[c] + 1e-9
        for q in range(bounds.shape[0] - 1):
            g = 0.0
            for a in range(3):
                s_lo = min(p0[c, a], p1[c, a])
                s_hi = max(p0[c, a], p1[c, a])
                d = max(0.0, lo[q, a] - s_hi, s_lo - hi[q, a])
                g += d * d
            if g > limit * limit:
                continue
            for i in range(bounds[q], bounds[q + 1]):
                t = _closest_on_segment(points[i], p0[c], p1[c])
                s = 0.0
                for a in range(3):
                    e = points[i, a] - (p0[c, a] + t * (p1[c, a] - p0[c, a]))
                    s += e * e
                if np.sqrt(s) - radius[c] <= reach[c]:
                    out[c] = 1
                    break
            if out[c]:
                break


def capsules_within(points: np.ndarray, p0: np.ndarray, p1: np.ndarray, radius: np.ndarray,
                    reach: np.ndarray) -> np.ndarray:
    """(k,) bool: whether any of points (n, 3) is within reach (k,) m of each capsule's
    surface (p0, p1 (k, 3) axis ends, radius (k,), m): `capsule_clearance(...) <= reach`,
    decided without the distance of every point to every capsule (chunks of points far from
    a capsule are skipped, a capsule's scan stops at its first point within reach: 0.53 ->
    0.23 ms for a 20K garment on a body)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    k = len(radius)
    out = np.zeros(k, dtype=np.uint8)
    if len(pts) and k:
        chunks = min(CONTACT_CHUNKS, len(pts))
        bounds = np.linspace(0, len(pts), chunks + 1).round().astype(np.int64)
        lo, hi = np.empty((chunks, 3)), np.empty((chunks, 3))
        _chunk_boxes(pts, bounds, lo, hi)
        _within(pts, np.ascontiguousarray(p0, dtype=np.float64),
                np.ascontiguousarray(p1, dtype=np.float64),
                np.ascontiguousarray(radius, dtype=np.float64),
                np.ascontiguousarray(np.broadcast_to(reach, (k,)), dtype=np.float64), bounds,
                lo, hi, out)
    return out.astype(bool)


@njit(cache=True, nogil=True)
def _rotate_between(u, v, w):
    """Rotate w (3,) in place by the smallest rotation taking unit u to unit v (Rodrigues);
    a half turn leaves it (the history test then falls back to the nearest surface)."""
    c0 = u[1] * v[2] - u[2] * v[1]
    c1 = u[2] * v[0] - u[0] * v[2]
    c2 = u[0] * v[1] - u[1] * v[0]
    cos = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    if cos < -0.999999:
        return
    # R w = w + c x w + c x (c x w) / (1 + cos)
    cw0 = c1 * w[2] - c2 * w[1]
    cw1 = c2 * w[0] - c0 * w[2]
    cw2 = c0 * w[1] - c1 * w[0]
    k = 1.0 / (1.0 + cos)
    r0 = w[0] + cw0 + k * (c1 * cw2 - c2 * cw1)
    r1 = w[1] + cw1 + k * (c2 * cw0 - c0 * cw2)
    r2 = w[2] + cw2 + k * (c0 * cw1 - c1 * cw0)
    w[0] = r0
    w[1] = r1
    w[2] = r2


@njit(cache=True, nogil=True)
def _capsule_boxes(p0, p1, q0, q1, radius, margin, swept):
    """(k, 6) each capsule's box (lo xyz, hi xyz) around its segment p0-p1 (with swept, also
    around q0-q1 at the previous pose) grown by radius + margin: a particle outside it is
    too far to touch the capsule. Made once per query: testing a particle against the ten
    boxes of a body costs then a few comparisons each (taking each box's min and max per
    particle was most of a query's time)."""
    k = p0.shape[0]
    box = np.empty((k, 6))
    for c in range(k):
        reach = radius[c] + margin
        for a in range(3):
            lo = min(p0[c, a], p1[c, a])
            hi = max(p0[c, a], p1[c, a])
            if swept:
                lo = min(lo, min(q0[c, a], q1[c, a]))
                hi = max(hi, max(q0[c, a], q1[c, a]))
            box[c, a] = lo - reach
            box[c, 3 + a] = hi + reach
    return box


@njit(cache=True, nogil=True, parallel=True)
def capsule_contacts(x, x_prev, p0, p1, q0, q1, radius, margin, dt, use_history,
                     out_dist, out_normal, out_vel, out_capsule):
    """For every particle, the deepest capsule contact within ``margin`` (m), or the capsule
    that swept through it.

    x, x_prev (n, 3): particle positions now and at the previous pose; p0, p1 (k, 3): capsule
    ends now; q0, q1 (k, 3): at the previous pose; radius (k,); use_history: test for
    tunnelling against x_prev (else plain nearest-surface distances). Writes out_dist (n,) signed
    distance to the surface (inf where none; a tunnelled particle's is minus its distance
    through the capsule to the surface on its own side), out_normal (n, 3), out_vel (n, 3)
    surface point velocity (m/s), out_capsule (n,) capsule index or -1. Particles are
    independent: they go in chunks on the threads, with the same result on any number.
    """
    n = x.shape[0]
    box = _capsule_boxes(p0, p1, q0, q1, radius, margin, use_history)
    chunks = min(CONTACT_CHUNKS, max(n, 1))
    for ch in prange(chunks):
        _contacts_chunk(ch * n // chunks, (ch + 1) * n // chunks, x, x_prev, p0, p1, q0, q1,
                        radius, margin, dt, use_history, box, out_dist, out_normal, out_vel,
                        out_capsule)


@njit(cache=True, nogil=True)
def _contacts_chunk(lo, hi, x, x_prev, p0, p1, q0, q1, radius, margin, dt, use_history,
                    box, out_dist, out_normal, out_vel, out_capsule):
    """capsule_contacts for particles lo..hi. Its pieces `_offset_before` and
    `_surface_velocity` are ``inline="always"``: inlined into this loop over particles and
    capsules, as a call per pair would slow it down."""
    k = p0.shape[0]
    axis = np.empty(3)
    axis_prev = np.empty(3)
    d = np.empty(3)
    dp = np.empty(3)
    came = np.empty(3)
    for i in range(lo, hi):
        out_dist[i] = np.inf
        out_capsule[i] = -1
        x0 = x[i, 0]
        x1 = x[i, 1]
        x2 = x[i, 2]
        for c in range(k):
            # Cheap rejection: outside the box of the capsule (for the swept test, of where it
            # went since the previous pose) grown by its reach.
            if (x0 < box[c, 0] or x0 > box[c, 3] or x1 < box[c, 1] or x1 > box[c, 4]
                    or x2 < box[c, 2] or x2 > box[c, 5]):
                continue
            r = radius[c]
            t = _closest_on_segment(x[i], p0[c], p1[c])
            for a in range(3):
                d[a] = x[i, a] - (p0[c, a] + t * (p1[c, a] - p0[c, a]))
            dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            dist = dn - r
            near = dist < margin
            if not near and not use_history:
                continue
            # A shallower contact than one found already matters only if the particle went
            # through this capsule: the crossing test runs even so. (Skipping it let the
            # deeper plain contact of a neighbour win where capsules overlap: at a knee, cloth
            # the shin swept through was pushed out of the thigh instead and left on the
            # shin's far side, a few particles per second of walking.)
            if near and dist >= out_dist[i] and not use_history:
                continue
            crossed, dpn = _went_through(x, x_prev, i, p0, p1, q0, q1, c, r, d, near,
                                         use_history, dp, axis, axis_prev, came)
            if crossed:
                # It passed the axis since the previous pose: it went through the limb.
                # Send it back out on the side it came from.
                if -dn - r >= out_dist[i]:
                    continue
                for a in range(3):
                    out_normal[i, a] = dp[a] / dpn
                out_dist[i] = -dn - r
            elif near and dn > 1e-12 and dist < out_dist[i]:
                for a in range(3):
                    out_normal[i, a] = d[a] / dn
                out_dist[i] = dist
            else:
                continue
            out_capsule[i] = c
            _surface_velocity(p0, p1, q0, q1, c, t, dt, axis_prev, axis, r, out_normal[i],
                              out_vel[i])


@njit(cache=True, nogil=True, inline="always")
def _went_through(x, x_prev, i, p0, p1, q0, q1, c, r, d, near, use_history, dp, axis,
                  axis_prev, came):
    """Whether particle i went through capsule c (radius r) since the previous pose, and
    the length of its offset dp (3,) from the axis then (`_offset_before`, written to dp);
    d (3,): its offset now; near: within the margin now; axis, axis_prev, came (3,):
    scratch."""
    # Where was the particle relative to this capsule at the previous pose?
    tp = _offset_before(x_prev, i, p0, p1, q0, q1, c, dp, axis, axis_prev)
    dpn = np.sqrt(dp[0] * dp[0] + dp[1] * dp[1] + dp[2] * dp[2])
    side = d[0] * dp[0] + d[1] * dp[1] + d[2] * dp[2]
    crossed = use_history and side < 0.0 and dpn > 0.5 * r
    if crossed and not near:
        # Beyond the capsule now: only a path (relative to the capsule, from where it was
        # carried along to where it is) that passes through the capsule counts.
        for a in range(3):
            came[a] = p0[c, a] + tp * (p1[c, a] - p0[c, a]) + dp[a]
        crossed = _segment_segment_distance(came, x[i], p0[c], p1[c]) < r
    return crossed, dpn


@njit(cache=True, nogil=True, inline="always")
def _offset_before(x_prev, i, p0, p1, q0, q1, c, dp, axis, axis_prev):
    """Particle i's offset from capsule c's axis at the previous pose, turned with the
    capsule since (`_rotate_between`), into dp (3,); returns the parameter along the previous
    axis of its nearest point. axis, axis_prev (3,): scratch."""
    tp = _closest_on_segment(x_prev[i], q0[c], q1[c])
    for a in range(3):
        dp[a] = x_prev[i, a] - (q0[c, a] + tp * (q1[c, a] - q0[c, a]))
    la = 0.0
    lp = 0.0
    for a in range(3):
        axis[a] = p1[c, a] - p0[c, a]
        axis_prev[a] = q1[c, a] - q0[c, a]
        la += axis[a] * axis[a]
        lp += axis_prev[a] * axis_prev[a]
    la = np.sqrt(la)
    lp = np.sqrt(lp)
    if la > 0.0 and lp > 0.0:
        for a in range(3):
            axis[a] /= la
            axis_prev[a] /= lp
        _rotate_between(axis_prev, axis, dp)
    return tp


@njit(cache=True, nogil=True, inline="always")
def _surface_velocity(p0, p1, q0, q1, c, t, dt, axis_prev, axis, r, normal, out):
    """Into out (3,): the velocity (m/s) over the last dt s of capsule c's surface point at
    axis parameter t and outward normal ``normal`` (3,): its axis point's velocity plus the
    capsule's turn, w x (r normal), w the rate (rad/s) of the smallest rotation taking unit
    ``axis_prev`` (3,) to unit ``axis`` (3,) (a turn about the capsule's own axis moves no
    surface a capsule can show). The turn matters to friction, which drags cloth towards
    this velocity: a thigh of radius 8 cm swinging at 5 rad/s moves its surface 0.4 m/s along
    its axis relative to the axis point."""
    for a in range(3):
        v0 = (p0[c, a] - q0[c, a]) / dt
        v1 = (p1[c, a] - q1[c, a]) / dt
        out[a] = (1.0 - t) * v0 + t * v1
    k0 = axis_prev[1] * axis[2] - axis_prev[2] * axis[1]
    k1 = axis_prev[2] * axis[0] - axis_prev[0] * axis[2]
    k2 = axis_prev[0] * axis[1] - axis_prev[1] * axis[0]
    sin = np.sqrt(k0 * k0 + k1 * k1 + k2 * k2)
    if sin < 1e-12:
        return
    cos = axis_prev[0] * axis[0] + axis_prev[1] * axis[1] + axis_prev[2] * axis[2]
    w = np.arctan2(sin, cos) / (sin * dt) * r  # |w| r / |k|, so that (w r) = this * k
    out[0] += w * (k1 * normal[2] - k2 * normal[1])
    out[1] += w * (k2 * normal[0] - k0 * normal[2])
    out[2] += w * (k0 * normal[1] - k1 * normal[0])


class CapsulePose(NamedTuple):
    """Where a capsule body is: end points p0, p1 (k, 3) m now, q0, q1 (k, 3) m at the
    previous pose, dt s between the two (the surface velocity is the displacement over dt;
    q = p and dt 1 for a body at rest or just placed); active (k,) bool: the capsules that
    collide (None: all; a tracker's segment whose joints are lost is dropped from the
    collider until they come back). A value: moving makes a new one."""

    p0: np.ndarray
    p1: np.ndarray
    q0: np.ndarray
    q1: np.ndarray
    dt: float
    active: np.ndarray | None = None

    def active_index(self) -> np.ndarray | None:
        """(a,) the indices of the colliding capsules; None when all collide."""
        return None if self.active is None else np.flatnonzero(self.active)


class CapsuleCollider:
    """The capsules of a body: radius (k,) m, friction coefficient (Coulomb). What does not
    change while it moves; its pose is a `CapsulePose` (module docstring).

    ``moved(pose, p0, p1, dt)`` gives the pose after a move to end points p0, p1 (k, 3)
    reached over dt seconds; ``at(pose)`` the body at that pose, for queries.
    """

    def __init__(self, radius: np.ndarray, friction: float = 0.5):
        self.radius = np.ascontiguousarray(radius, dtype=np.float64).reshape(-1)
        if np.any(~np.isfinite(self.radius)) or np.any(self.radius <= 0.0):
            raise ClothInputError(f"capsule radii must be positive, got {self.radius.tolist()}")
        if friction < 0.0:
            raise ClothInputError(f"capsule friction must be >= 0, got {friction}")
        self.friction = float(friction)

    def rest_pose(self) -> CapsulePose:
        """Every end point at the origin, at rest: the pose before the body is placed."""
        zero = np.zeros((len(self.radius), 3))
        return CapsulePose(zero, zero, zero, zero, 1.0)

    def moved(self, pose: CapsulePose | None, p0: np.ndarray, p1: np.ndarray,
              dt: float | None = None, active: np.ndarray | None = None) -> CapsulePose:
        """The pose after moving from ``pose`` to end points p0, p1 (k, 3) m over dt s; dt
        None: a jump with zero velocity and no swept test across it (placing or re-anchoring
        the body; ``pose`` may then be None). active (k,) bool: the capsules that collide
        (None: all); one that comes back jumps to where it is (no swept test from where it
        was held while dropped)."""
        p0 = np.ascontiguousarray(p0, dtype=np.float64)
        p1 = np.ascontiguousarray(p1, dtype=np.float64)
        if p0.shape != (len(self.radius), 3) or p1.shape != p0.shape:
            raise ClothInputError(f"capsule end points must be ({len(self.radius)}, 3), got "
                                  f"{p0.shape} and {p1.shape}")
        if active is not None:
            active = np.asarray(active, dtype=bool).reshape(-1)
            if active.shape != (len(self.radius),):
                raise ClothInputError(f"capsule active mask must be ({len(self.radius)},), got "
                                      f"{active.shape}")
            active = None if active.all() else active.copy()
        if dt is None:
            return CapsulePose(p0, p1, p0, p1, 1.0, active)
        q0, q1 = pose.p0, pose.p1
        if pose.active is not None:
            back = ~pose.active if active is None else ~pose.active & active
            if back.any():
                q0, q1 = q0.copy(), q1.copy()
                q0[back], q1[back] = p0[back], p1[back]
        return CapsulePose(p0, p1, q0, q1, float(dt), active)

    def at(self, pose: CapsulePose | None = None) -> PosedCapsules:
        """The body at ``pose`` (None: `rest_pose`), for queries."""
        return PosedCapsules(self, self.rest_pose() if pose is None else pose)


class PosedCapsules:
    """A capsule body at a pose: `CapsuleCollider` ``collider`` and `CapsulePose` ``pose``.

    ``query`` finds contacts at the pose; ``set_pose(p0, p1, dt)`` replaces the pose by the
    one after a move (``collider.moved``), for a body moved by hand outside a simulation."""

    def __init__(self, collider: CapsuleCollider, pose: CapsulePose):
        self.collider, self.pose = collider, pose

    @property
    def radius(self) -> np.ndarray:
        return self.collider.radius

    @property
    def friction(self) -> float:
        return self.collider.friction

    def set_pose(self, p0: np.ndarray, p1: np.ndarray, dt: float | None = None) -> None:
        """Move to end points p0, p1 (k, 3); dt None: a jump with zero velocity (a reset)."""
        self.pose = self.collider.moved(self.pose, p0, p1, dt)

    def query(self, x: np.ndarray, margin: float, x_prev: np.ndarray | None = None) -> Contacts:
        """Particles of x (n, 3) within ``margin`` of a capsule (the deepest capsule each);
        x_prev (n, 3) their positions at the previous pose, for the tunnelling test (None:
        plain nearest-surface distances)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        xp = x if x_prev is None else np.ascontiguousarray(x_prev, dtype=np.float64)
        n = len(x)
        dist = np.empty(n)
        normal = np.zeros((n, 3))
        vel = np.zeros((n, 3))
        which = np.empty(n, dtype=np.int64)
        p, radius = self.pose, self.radius
        index = p.active_index()
        if index is not None:  # dropped capsules are left out, the others keep their indices
            p = CapsulePose(p.p0[index], p.p1[index], p.q0[index], p.q1[index], p.dt)
            radius = radius[index]
        capsule_contacts(x, xp, p.p0, p.p1, p.q0, p.q1, radius, margin, p.dt,
                         x_prev is not None, dist, normal, vel, which)
        idx = np.flatnonzero(which >= 0)
        hit = which[idx] if index is None else index[which[idx]]
        return Contacts(idx, normal[idx], dist[idx], vel[idx], hit)
