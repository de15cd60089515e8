"""The forces the cloth exerts on what touches it, exact for the implicit step.

Two kinds of contact act in a step (sim.integrator): the penalty springs that the linear
system holds, and the projection with friction that `resolve_contacts` applies after the
solve. Both are counted here, as the step used them, so that over a step the cloth's change
of momentum is h' times (gravity + drag + the holders' forces) minus what the colliders
receive (test_loads checks the balance). Units SI: N, m, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.collision.colliders import ContactImpulses, Contacts


@dataclass
class ContactLoad:
    """The forces of one step's contacts on the colliders.

    index (c,): the cloth particle of each contact; collider (c,): its collider's index in the
    model's list; part (c,): the part of that collider (a body's capsule); force (c, 3) N: the
    force the cloth exerts on the collider there, averaged over the step (penalty as the step
    solved it, plus the projection's impulse over the step's force factor h'); point (c, 3) m:
    where (the particle at the end of the step). pull N: what the step's penalty contacts pulled
    the cloth onto the colliders with, the sum of their normal forces past zero (a linearised
    penalty, with its damper, holds a particle that the solve carried beyond the penalty's zero:
    an adhesion no contact law allows). The projection mode does not check it; friction inside
    the solve drops such a contact and solves again (sim.contact_set), so there it stays under
    that check's slack.
    """

    index: np.ndarray
    collider: np.ndarray
    part: np.ndarray
    force: np.ndarray
    point: np.ndarray
    pull: float = 0.0

    @classmethod
    def empty(cls) -> ContactLoad:
        z = np.zeros(0, np.int64)
        return cls(z, z, z, np.zeros((0, 3)), np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.index)

    def per_part(self, collider: int, parts: int) -> np.ndarray:
        """(parts, 3) N: the force on each part of collider ``collider``."""
        out = np.zeros((parts, 3))
        on = self.collider == collider
        np.add.at(out, self.part[on], self.force[on])
        return out

    def torques(self, collider: int, origins: np.ndarray) -> np.ndarray:
        """(parts, 3) N m: the torque on each part of collider ``collider`` about its origin,
        origins (parts, 3) m."""
        out = np.zeros_like(np.asarray(origins, dtype=np.float64))
        on = np.flatnonzero(self.collider == collider)
        arm = self.point[on] - np.asarray(origins, dtype=np.float64)[self.part[on]]
        np.add.at(out, self.part[on], np.cross(arm, self.force[on]))
        return out

    def total(self) -> np.ndarray:
        """(3,) N: the force on every collider together."""
        return self.force.sum(axis=0)


def contact_load(mass: np.ndarray, contacts: Contacts, stiffness: np.ndarray,
                 thickness: float, displacement: np.ndarray, impulses: ContactImpulses,
                 points: np.ndarray, dt: float, damper: np.ndarray | None = None,
                 friction: np.ndarray | None = None) -> ContactLoad:
    """The ContactLoad of one step.

    mass (n,) kg; contacts: the step's penalty contacts (their distance measured at the
    start of the step, as the system was built) with their stiffness (c,) N/m; thickness m;
    displacement (c, 3) m: each contact's particle's solved position minus its start (the
    penalty is linear in it, so this is the penalty force the solve balanced, not a later
    estimate); impulses: the
    projection's velocity changes; points (n, 3) m: positions at the end of the step; dt: the
    step's force factor h', s (the projection's impulse over it is its force);
    damper (c,) N: each contact's damper force along its normal as the step balanced it
    (sim.integrator.contact_damper_forces; None: no dampers); friction (c, 3) N: each
    contact's friction on its particle inside the solve (sim.contact_friction.friction_forces;
    None: friction acted in the projection, whose impulses carry it).
    """
    n_pen = len(contacts)
    index, dv, part, collider = impulses.arrays()
    pen = np.zeros((n_pen, 3))
    pull = 0.0
    if n_pen:
        normal = contacts.normal
        gap = thickness - contacts.distance - np.einsum(
            "ij,ij->i", displacement, normal)
        push = stiffness * gap if damper is None else stiffness * gap + damper
        pen = push[:, None] * normal
        pull = float(np.maximum(-push, 0.0).sum())
        if friction is not None:
            pen = pen + friction
    proj = mass[index, None] * dv / dt
    all_index = np.concatenate([contacts.index, index])
    return ContactLoad(all_index, np.concatenate([contacts.collider, collider]),
                       np.concatenate([contacts.part, part]),
                       -np.concatenate([pen, proj]), points[all_index], pull)
