"""Rigid colliders the cloth rests on, and the penalty contact they put into the system.

A contact is a particle closer than the collision thickness to a collider surface. It
enters the implicit system as a stiff penalty on that particle's diagonal block only,
E = k/2 (thickness - distance)^2 along the surface normal n, so B_i += c k n n^T: a
diagonal term coarsens exactly like mass, which keeps the multigrid hierarchy consistent.
After the step, positions that still lie inside are projected out, inward normal velocity
is removed and Coulomb friction acts on the tangential velocity: within a step
(`project_contacts` given a collision.friction.StepFriction) bounded by the step's whole normal
impulse, penalty and projection together.

A collider holds what never changes. A moving one (capsules.CapsuleCollider,
mesh_collider.MeshCollider) keeps where it is in a pose value that the simulation's State
holds (sim.model.ClothState.bodies), and ``collider.at(pose)`` is the body at that pose, which
answers ``query``; a static one (the three here) is its own posed body: `StaticPose`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.collision.friction import StepFriction, project_with_friction
from cloth_mg_ros.errors import ClothInputError


@dataclass
class Contacts:
    """Particles in contact. index (k,), normal (k, 3) unit outward, distance (k,) signed
    distance to the surface in metres (negative inside), velocity (k, 3) of the surface
    point in m/s; part (k,): which part of its collider each touches (a body's capsule; 0 for
    a one-piece collider); collider (k,): the index of the collider in the list `collide`
    was given (0 from a single collider's query). Both say where the contact force goes."""

    index: np.ndarray
    normal: np.ndarray
    distance: np.ndarray
    velocity: np.ndarray
    part: np.ndarray | None = None
    collider: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.part is None:
            self.part = np.zeros(len(self.index), np.int64)
        if self.collider is None:
            self.collider = np.zeros(len(self.index), np.int64)

    @classmethod
    def empty(cls) -> Contacts:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.index)

    def subset(self, keep: np.ndarray) -> Contacts:
        """The contacts selected by ``keep`` (a bool mask or indices)."""
        return Contacts(*(getattr(self, f)[keep] for f in FIELDS))

    @classmethod
    def concatenate(cls, parts: list[Contacts]) -> Contacts:
        if not parts:
            return cls.empty()
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in FIELDS))


FIELDS = ("index", "normal", "distance", "velocity", "part", "collider")
# The projection leaves a particle this share of the thickness from the surface: just inside,
# by far more than rounding (5e-12 m at 5 mm), so that a particle resting on a collider is
# the next step's penalty contact whatever the last bits of its position. Left exactly at
# the thickness, rounding put about half of a sheet lying on a plane in the penalty and the
# rest not: the penalty's particles carried their neighbours' load through the cloth, and
# friction bounded by each particle's own normal impulse let the unloaded ones slip (a sheet
# that had to stick at 20 degrees and mu = 0.5 crept at 6 cm/s).
RESTING = 1.0 - 1e-9


@dataclass
class ContactImpulses:
    """Velocity changes that the contact projection gave particles, per contact it made:
    index (k,) particle, dv (k, 3) m/s, part and collider (k,) as in Contacts. Collected by
    `resolve_contacts` when it is given one; a particle projected twice appears twice."""

    index: list
    dv: list
    part: list
    collider: list

    @classmethod
    def new(cls) -> ContactImpulses:
        return cls([], [], [], [])

    def add(self, c: Contacts, dv: np.ndarray, collider: int) -> None:
        """Velocity changes dv (k, 3) of contacts c of collider ``collider``."""
        self.add_raw(c.index, dv, c.part, collider)

    def add_raw(self, index: np.ndarray, dv: np.ndarray, part: np.ndarray, collider: int
                ) -> None:
        """Velocity changes dv (k, 3) of particles index (k,), from parts part (k,) of
        collider ``collider`` (an edge contact moves both of its ends)."""
        self.index.append(np.asarray(index, dtype=np.int64))
        self.dv.append(dv)
        self.part.append(np.asarray(part, dtype=np.int64))
        self.collider.append(np.full(len(index), collider, np.int64))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(index (k,), dv (k, 3), part (k,), collider (k,)) of every projection so far."""
        if not self.index:
            return (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64),
                    np.zeros(0, np.int64))
        return (np.concatenate(self.index), np.concatenate(self.dv),
                np.concatenate(self.part), np.concatenate(self.collider))


class StaticPose:
    """The pose protocol of a collider that never moves: no pose value, ``at`` is itself."""

    def rest_pose(self) -> None:
        return None

    def at(self, pose: None = None) -> StaticPose:
        return self


def posed(colliders: list, bodies: dict) -> list:
    """The colliders at their poses: bodies {index into colliders: pose value} (a moving
    collider without one is at its rest pose)."""
    return [c.at(bodies.get(k)) for k, c in enumerate(colliders)]


def rest_bodies(colliders: list) -> dict:
    """{index: rest pose} of the moving colliders among ``colliders``."""
    out = {}
    for k, c in enumerate(colliders):
        pose = c.rest_pose()
        if pose is not None:
            out[k] = pose
    return out


@dataclass
class SphereCollider(StaticPose):
    """A static or moving sphere: centre (3,) m, radius m, friction coefficient."""

    centre: np.ndarray
    radius: float
    friction: float = 0.3
    velocity: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.centre = np.asarray(self.centre, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.centre)):
            raise ClothInputError(f"sphere collider: centre must be finite, got {self.centre}")
        if not (self.radius > 0.0):
            raise ClothInputError(f"sphere collider: radius must be positive, got {self.radius}")
        if not self.friction >= 0.0:  # NaN too
            raise ClothInputError(f"sphere collider: friction must be >= 0, got {self.friction}")
        if self.velocity is None:
            self.velocity = np.zeros(3)

    def query(self, x: np.ndarray, margin: float, x_prev: np.ndarray | None = None) -> Contacts:
        """Particles of x (n, 3) within ``margin`` metres of the surface (x_prev unused: a
        sphere moves too little per step to be tunnelled through)."""
        rel = x - self.centre
        dist_c = np.linalg.norm(rel, axis=1)
        dist = dist_c - self.radius
        idx = np.flatnonzero(dist < margin)
        safe = np.maximum(dist_c[idx], 1e-12)[:, None]
        normal = rel[idx] / safe
        # a particle at the centre has no direction out: push it up (+z), not nowhere
        normal[dist_c[idx] == 0.0] = (0.0, 0.0, 1.0)
        vel = np.broadcast_to(self.velocity, (len(idx), 3)).copy()
        return Contacts(idx, normal, dist[idx], vel)


def collide(colliders: list, x: np.ndarray, margin: float,
            x_prev: np.ndarray | None = None) -> Contacts:
    """All contacts of x (n, 3) with the colliders, within margin metres; x_prev (n, 3) where
    the particles were at the colliders' previous pose (for moving colliders)."""
    parts = []
    for k, col in enumerate(colliders):
        c = col.query(x, margin, x_prev)
        c.collider = np.full(len(c), k, np.int64)
        parts.append(c)
    return Contacts.concatenate(parts)


def penetration(colliders: list, x: np.ndarray, exclude: np.ndarray | None = None) -> float:
    """Deepest penetration of x (n, 3) into any collider, metres (0 when none); exclude (n,)
    bool masks particles not to count (pinned ones, sewn to a body and not collided)."""
    c = collide(colliders, x, 0.0)
    depth = -c.distance
    if exclude is not None and len(c):
        depth = depth[~exclude[c.index]]
    return float(np.max(depth, initial=0.0))


class ContactProjection(NamedTuple):
    """What `project_contacts` did: count, particles in contact; deepest, the deepest
    penetration before the projection (m, >= 0); clear, whether its last pass found nothing
    left inside (False: it ran out of passes, and a particle may still be inside)."""

    count: int
    deepest: float
    clear: bool


def resolve_contacts(
    colliders: list, x: np.ndarray, v: np.ndarray, thickness: float,
    x_prev: np.ndarray | None = None, friction_scale: float = 1.0, passes: int = 8,
    impulses: ContactImpulses | None = None, exclude: np.ndarray | None = None,
) -> tuple[int, float]:
    """`project_contacts`, returning (number of particles in contact, deepest penetration
    before the projection, metres, >= 0)."""
    done = project_contacts(colliders, x, v, thickness, x_prev, friction_scale, passes,
                            impulses, exclude)
    return done.count, done.deepest


def project_contacts(
    colliders: list, x: np.ndarray, v: np.ndarray, thickness: float,
    x_prev: np.ndarray | None = None, friction_scale: float = 1.0, passes: int = 8,
    impulses: ContactImpulses | None = None, exclude: np.ndarray | None = None,
    friction: StepFriction | None = None, only: np.ndarray | None = None,
) -> ContactProjection:
    """Project particles out of the colliders in place and apply Coulomb friction.

    x, v (n, 3) are modified; x_prev (n, 3): at the start of the step (a moving collider
    keeps a particle on the side it came from). Overlapping colliders (a body's capsules)
    can push a particle from one into another: the projection repeats, up to ``passes``
    times, until nothing is left inside. A particle pushed back against its last
    push (normals more than 90 degrees apart: pinched between two overlapping solids, such as
    cloth between a jumper's thighs) would go back and forth between them and stay inside
    one; it is pushed along the two normals' bisector instead, out of the crease, by enough
    to clear the current solid (at most twice its depth per pass).

    The first pass looks at every particle, a later one only at those moved since the same
    collider last looked (the others are where it found them clear): per-particle queries,
    so exactly what querying all of them would find, in the same order.

    impulses: if given, gets each projection's velocity change (the body's contact force is
    that times the mass over the step); exclude (n,) bool: particles not recorded there
    (pinned ones, whose velocity the pin restores).
    friction: an implicit step's (collision.friction): Coulomb friction bounded by its whole
    normal impulse (penalty and projection), the position moved with the velocity; None:
    friction scaled by the normal velocity the projection removes (outside a step).
    only (m,) int: look at these particles alone, by their nearest surface (no tunnelling
    test): those another correction moved after a full projection (the edge contact's push
    can move an edge's end into a limb); None: every particle.
    """
    touched = np.zeros(len(x), dtype=bool)
    last = np.zeros_like(x)  # the normal of each particle's latest push (0: none yet)
    deepest = 0.0
    moved_before = np.zeros(len(x), dtype=bool)  # moved in the previous pass
    for k in range(passes):
        moved_now = np.zeros(len(x), dtype=bool)
        for which, col in enumerate(colliders):
            look = None if k == 0 else np.flatnonzero(moved_before | moved_now)
            c = _pass_contacts(col, x, thickness, x_prev if k == 0 else None,
                               only if k == 0 else look, k > 0)
            if c is None or len(c) == 0:
                continue
            moved_now[c.index] = True
            touched[c.index] = True
            if k == 0:
                deepest = max(deepest, float(np.max(-c.distance, initial=0.0)))
            own = c.normal.copy()
            if k > 0:
                _unpinch(c, last[c.index], thickness)
            last[c.index] = own
            before = v[c.index] if impulses is not None else None
            _project(c, x, v, thickness, col.friction * friction_scale, friction, which)
            if impulses is not None:
                keep = slice(None) if exclude is None else ~exclude[c.index]
                impulses.add(c.subset(keep), (v[c.index] - before)[keep], which)
        if not moved_now.any():
            return ContactProjection(int(touched.sum()), deepest, True)
        moved_before = moved_now
    return ContactProjection(int(touched.sum()), deepest, False)


def _pass_contacts(col, x: np.ndarray, thickness: float, x_prev: np.ndarray | None,
                   look: np.ndarray | None, later: bool) -> Contacts | None:
    """One projection pass's contacts of collider ``col``: every particle of x (n, 3) with
    the tunnelling test against x_prev (look None), or only particles ``look`` by their
    nearest surface (None when there are none); a later pass (``later``) keeps those clearly
    inside."""
    if look is None:
        return col.query(x, thickness, x_prev)
    if not len(look):
        return None
    c = col.query(x[look], thickness, None)
    c.index = look[c.index]
    return c.subset(c.distance < thickness * 0.999) if later else c


def _unpinch(c: Contacts, prev: np.ndarray, thickness: float) -> None:
    """Where a contact's normal opposes the particle's previous push ``prev`` (k, 3), turn it
    into the bisector of the two and scale its distance so that the push along it, taken
    against the current surface as a plane, clears it (at most twice the depth)."""
    cos = np.einsum("ij,ij->i", prev, c.normal)
    bis = prev + c.normal
    size = np.linalg.norm(bis, axis=1)
    pinched = np.flatnonzero((cos < 0.0) & (size > 1e-3))
    if len(pinched) == 0:
        return
    b = bis[pinched] / size[pinched, None]
    along = np.maximum(np.einsum("ij,ij->i", b, c.normal[pinched]), 0.5)
    depth = thickness - c.distance[pinched]
    c.normal[pinched] = b
    c.distance[pinched] = thickness - depth / along


def _project(c: Contacts, x: np.ndarray, v: np.ndarray, thickness: float, mu: float,
             friction: StepFriction | None = None, which: int = 0) -> None:
    """Move contacts c to the thickness along their normals, remove inward velocity relative
    to the surface and apply Coulomb friction to the tangential slip (with ``friction``: a
    step's, bounded by its whole normal impulse, `collision.friction`; c are contacts
    of collider ``which``)."""
    if friction is not None:
        project_with_friction(x, v, c.index, c.normal, c.distance, c.velocity,
                              thickness * RESTING, mu, friction, which)
        return
    x[c.index] += (thickness * RESTING - c.distance)[:, None] * c.normal
    rel = v[c.index] - c.velocity
    vn = np.einsum("ij,ij->i", rel, c.normal)
    inward = np.minimum(vn, 0.0)
    rel -= inward[:, None] * c.normal
    vt = rel - np.einsum("ij,ij->i", rel, c.normal)[:, None] * c.normal
    vt_norm = np.linalg.norm(vt, axis=1)
    # Coulomb: the tangential slip shrinks by mu times the normal velocity removed.
    keep = np.where(vt_norm > 1e-12,
                    np.maximum(0.0, 1.0 - mu * (-inward) / np.maximum(vt_norm, 1e-12)), 1.0)
    rel -= (1.0 - keep)[:, None] * vt
    v[c.index] = rel + c.velocity


@dataclass
class PlaneCollider(StaticPose):
    """A static half-space {x : (x - point) . normal >= 0}: a floor. point, normal (3,)."""

    point: np.ndarray
    normal: np.ndarray
    friction: float = 0.5

    def __post_init__(self) -> None:
        self.point = np.asarray(self.point, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.point)):
            raise ClothInputError(f"plane collider: point must be finite, got {self.point}")
        if not self.friction >= 0.0:  # NaN too
            raise ClothInputError(f"plane collider: friction must be >= 0, got {self.friction}")
        nrm = np.asarray(self.normal, dtype=float).reshape(3)
        length = float(np.linalg.norm(nrm))
        if not np.isfinite(length) or length == 0.0:
            raise ClothInputError(f"plane collider: normal must be non-zero, got {nrm}")
        self.normal = nrm / length

    def query(self, x: np.ndarray, margin: float, x_prev: np.ndarray | None = None) -> Contacts:
        """Particles of x (n, 3) within ``margin`` metres of the plane (or below it)."""
        dist = (x - self.point) @ self.normal
        idx = np.flatnonzero(dist < margin)
        k = len(idx)
        return Contacts(idx, np.broadcast_to(self.normal, (k, 3)).copy(), dist[idx],
                        np.zeros((k, 3)))


@dataclass
class DiscCollider(StaticPose):
    """A static flat-topped disc: a solid upright cylinder (axis +z) with sharp rims, such as
    the support of a drape test. top (3,): the centre of its top face, m; radius, height m
    (the solid spans top_z - height <= z <= top_z); friction coefficient.

    The signed distance is exact for the solid cylinder (negative inside); outside, near a
    rim, it is the distance to the rim circle, so the offset surface at the contact thickness
    is the cylinder with rims rounded to that thickness.
    """

    top: np.ndarray
    radius: float
    height: float
    friction: float = 0.5

    def __post_init__(self) -> None:
        self.top = np.asarray(self.top, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.top)):
            raise ClothInputError(f"disc collider: top must be finite, got {self.top}")
        for name in ("radius", "height"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ClothInputError(f"disc collider: {name} must be positive, got {value!r}")
        if not self.friction >= 0.0:
            raise ClothInputError(f"disc collider: friction must be >= 0, got {self.friction}")

    def signed_distance(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) signed distance (m, negative inside) and (n, 3) unit outward normal (the
        distance's gradient) of the points x (n, 3)."""
        rel = x - self.top
        rho = np.hypot(rel[:, 0], rel[:, 1])
        # Radial unit vector; on the axis (rho = 0) any horizontal direction serves, and
        # there the radial side is never the nearest (a point on the axis is nearer a face).
        safe = np.maximum(rho, 1e-15)
        e_r = np.zeros_like(x)
        e_r[:, 0] = np.where(rho > 0.0, rel[:, 0] / safe, 1.0)
        e_r[:, 1] = np.where(rho > 0.0, rel[:, 1] / safe, 0.0)
        half = 0.5 * self.height
        dz_c = rel[:, 2] + half  # height above the mid-plane
        side = np.where(dz_c >= 0.0, 1.0, -1.0)
        d_r = rho - self.radius
        d_z = np.abs(dz_c) - half
        out_r, out_z = np.maximum(d_r, 0.0), np.maximum(d_z, 0.0)
        outside = np.hypot(out_r, out_z)
        inside = np.minimum(np.maximum(d_r, d_z), 0.0)
        dist = outside + inside
        normal = np.empty_like(x)
        is_out = outside > 0.0
        safe_out = np.maximum(outside, 1e-300)
        # Outside: gradient of the distance to the nearest point of the solid.
        normal_out = (out_r / safe_out)[:, None] * e_r
        normal_out[:, 2] += out_z / safe_out * side
        # Inside (or on the surface): the nearest face's normal.
        radial = d_r >= d_z
        normal_in = np.where(radial[:, None], e_r, 0.0)
        normal_in[:, 2] += np.where(radial, 0.0, side)
        normal[:] = np.where(is_out[:, None], normal_out, normal_in)
        return dist, normal

    def query(self, x: np.ndarray, margin: float, x_prev: np.ndarray | None = None) -> Contacts:
        """Particles of x (n, 3) within ``margin`` metres of the disc. x_prev (n, 3): where
        they were; a particle that was above the top face and is now below its plane within
        the radius crossed the top (a falling cloth moves g dt^2, more than a thin plate, in
        one step) and is a contact of the top face, at its depth below it."""
        dist, normal = self.signed_distance(x)
        if x_prev is not None:
            rel = x - self.top
            crossed = (x_prev[:, 2] >= self.top[2]) & (rel[:, 2] < 0.0) & \
                (np.hypot(rel[:, 0], rel[:, 1]) <= self.radius)
            dist[crossed] = rel[crossed, 2]
            normal[crossed] = (0.0, 0.0, 1.0)
        idx = np.flatnonzero(dist < margin)
        return Contacts(idx, normal[idx], dist[idx], np.zeros((len(idx), 3)))
