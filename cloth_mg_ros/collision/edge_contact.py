"""Cloth edges against capsules: the contact that keeps a limb from passing between particles.

Particle contact (capsules.PosedCapsules.query) keeps every particle out of the capsules,
but a stretched edge whose two ends lie on two sides of a thin limb (a fingertip poking
through a sleeve's rim) passes through it with no particle inside. After the particle
projection, each edge whose interior comes nearer a capsule's axis than the radius plus half
the contact thickness is pushed out along the normal at its closest point: its two ends move
so that that point lands there (weights (1 - s) and s of where along the edge it is, pinned
ends not moving), and the inward part of the point's velocity relative to the limb is removed
the same way, frictionless. The ends it moves may land inside another capsule, so in a step
(`edges_then_particles`) the particles it moved are projected again and the edges looked at
again, the particles' projection last. Units SI: m, m/s.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cloth_mg_ros.collision.capsules import PosedCapsules, segment_closest
from cloth_mg_ros.collision.colliders import ContactImpulses, project_contacts
from cloth_mg_ros.collision.friction import StepFriction

EDGE_END = 0.02  # an edge's ends (s within this of 0 or 1) are the particle contact's
EDGE_ROUNDS = 4  # edge contact, then the particles it moved projected again
EDGE_PASSES = 12  # projection sweeps, until none is left inside: an end pushed out by one edge
# may pull a neighbour in (4 left 2 cm of a stretched rim inside a swinging hand)


@njit(cache=True, nogil=True, parallel=True)
def edge_capsule_contacts(x, edges, p0, p1, radius, margin, out_s, out_t, out_depth,
                          out_normal, out_capsule):
    """For every edge (e, 2) of positions x (n, 3), its deepest capsule (p0, p1 (k, 3) axis
    ends, radius (k,)) whose axis its interior comes nearer than radius + margin: out_s,
    out_t (e,) where along the edge and the axis, out_depth (e,) radius + margin minus the
    distance, m, out_normal (e, 3) from the axis to the edge, out_capsule (e,) the capsule or
    -1 (none)."""
    k = p0.shape[0]
    for i in prange(edges.shape[0]):
        out_capsule[i] = -1
        out_depth[i] = 0.0
        a = x[edges[i, 0]]
        b = x[edges[i, 1]]
        for c in range(k):
            reach = radius[c] + margin
            far = False
            for ax in range(3):
                lo = min(p0[c, ax], p1[c, ax]) - reach
                hi = max(p0[c, ax], p1[c, ax]) + reach
                if max(a[ax], b[ax]) < lo or min(a[ax], b[ax]) > hi:
                    far = True
            if far:
                continue
            s, t = segment_closest(a, b, p0[c], p1[c])
            if s <= EDGE_END or s >= 1.0 - EDGE_END:
                continue
            g = np.empty(3)
            for ax in range(3):
                g[ax] = (a[ax] + s * (b[ax] - a[ax])) - (p0[c, ax] + t * (p1[c, ax] - p0[c, ax]))
            d = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
            depth = reach - d
            if depth <= out_depth[i]:
                continue
            if d < 1e-12:  # on the axis: out across it, square to the edge and the axis
                u = b - a
                w = p1[c] - p0[c]
                g[0] = u[1] * w[2] - u[2] * w[1]
                g[1] = u[2] * w[0] - u[0] * w[2]
                g[2] = u[0] * w[1] - u[1] * w[0]
                d = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
                if d < 1e-18:
                    continue
            out_depth[i] = depth
            out_s[i] = s
            out_t[i] = t
            out_capsule[i] = c
            for ax in range(3):
                out_normal[i, ax] = g[ax] / d


def resolve_edge_contacts(collider, x: np.ndarray, v: np.ndarray, edges: np.ndarray,
                          thickness: float, fixed: np.ndarray | None = None,
                          impulses: ContactImpulses | None = None, which: int = 0) -> int:
    """Push the edges (e, 2) of x (n, 3) out of `collider`'s capsules (a
    capsules.PosedCapsules: the body at its pose) to half the contact thickness, and remove
    their inward velocity relative to it, in place (v (n, 3)); fixed (n,) bool: pinned
    particles, which do not move. impulses: if given, gets the velocity changes, as collider
    ``which``'s parts. Returns how many edge contacts were resolved."""
    x = np.ascontiguousarray(x)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    free = np.ones(len(x)) if fixed is None else (~np.asarray(fixed, dtype=bool)).astype(float)
    margin = 0.5 * thickness
    count = 0
    e = len(edges)
    s, t, depth = np.empty(e), np.empty(e), np.empty(e)
    normal, capsule = np.zeros((e, 3)), np.empty(e, np.int64)
    p0, p1, radius = collider.pose.p0, collider.pose.p1, collider.radius
    index = collider.pose.active_index()
    if index is not None:  # dropped capsules are left out, the others keep their indices
        p0, p1, radius = p0[index], p1[index], radius[index]
    for _ in range(EDGE_PASSES):
        edge_capsule_contacts(x, edges, p0, p1, radius, margin, s, t, depth, normal, capsule)
        hit = np.flatnonzero(capsule >= 0)
        if not len(hit):
            break
        count += len(hit)
        a, b = edges[hit, 0], edges[hit, 1]
        sh, n, c = s[hit], normal[hit], capsule[hit]
        if index is not None:
            c = index[c]
        wa, wb = free[a] * (1.0 - sh), free[b] * sh
        norm = wa * (1.0 - sh) + wb * sh
        ok = norm > 1e-12
        wa, wb = np.where(ok, wa / np.where(ok, norm, 1.0), 0.0), \
            np.where(ok, wb / np.where(ok, norm, 1.0), 0.0)
        push = depth[hit][:, None] * n
        np.add.at(x, a, wa[:, None] * push)
        np.add.at(x, b, wb[:, None] * push)
        surface = _surface_velocity(collider, c, t[hit])
        rel = (1.0 - sh)[:, None] * v[a] + sh[:, None] * v[b] - surface
        inward = np.minimum(np.einsum("ij,ij->i", rel, n), 0.0)
        dva, dvb = (-inward * wa)[:, None] * n, (-inward * wb)[:, None] * n
        np.add.at(v, a, dva)
        np.add.at(v, b, dvb)
        if impulses is not None:
            impulses.add_raw(np.concatenate([a, b]), np.concatenate([dva, dvb]),
                             np.concatenate([c, c]), which)
    return count


def edges_then_particles(colliders: list, x: np.ndarray, v: np.ndarray, edges: np.ndarray,
                         thickness: float, fixed: np.ndarray | None = None,
                         impulses: ContactImpulses | None = None,
                         friction: StepFriction | None = None) -> tuple[np.ndarray, bool]:
    """The edge contact of every capsule collider in ``colliders`` after a particle
    projection, in place in x, v (n, 3), fixed, impulses as in `resolve_edge_contacts`.

    The edge contact moves an edge's two ends to push its middle out of a limb and knows
    nothing of the particle contacts: an end can land inside a neighbouring capsule (a rim
    stretched over the hand and the wrist of the dressing arm was left 18-32 mm inside it).
    So the particles it moved are projected again (collision.colliders.project_contacts by
    their nearest surface, with the step's ``friction``: each new push's Coulomb bound), and
    the edges looked at again, for up to EDGE_ROUNDS rounds until one moves nothing: the last
    word is the particles'. Returns ((n,) bool, the particles the edge contact moved; whether
    the last particle projection found nothing left inside)."""
    edged = np.zeros(len(x), dtype=bool)
    clear = True
    for _ in range(EDGE_ROUNDS):
        x_edge, v_edge = x.copy(), v.copy()
        for which, col in enumerate(colliders):
            if isinstance(col, PosedCapsules):
                resolve_edge_contacts(col, x, v, edges, thickness, fixed, impulses, which)
        now = np.any((x != x_edge) | (v != v_edge), axis=1)
        if not now.any():
            break
        edged |= now
        again = project_contacts(colliders, x, v, thickness, None, impulses=impulses,
                                 exclude=fixed, friction=friction, only=np.flatnonzero(now))
        clear = again.clear
        if again.count == 0:
            break
    return edged, clear


def _surface_velocity(collider, capsule: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(k, 3) m/s: the velocity over the collider's last move of the points at parameters t
    (k,) of capsules ``capsule`` (k,) axes. The limb's turn (w x r n, which the particle
    contact's friction needs: capsules._surface_velocity) is left out on purpose: it is
    square to the normal n, and the edge contact removes only the normal part of the
    relative velocity."""
    p = collider.pose
    v0 = (p.p0[capsule] - p.q0[capsule]) / p.dt
    v1 = (p.p1[capsule] - p.q1[capsule]) / p.dt
    return (1.0 - t)[:, None] * v0 + t[:, None] * v1
