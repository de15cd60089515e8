"""Coulomb friction of the cloth against rigid colliders, bounded by a step's whole normal impulse.

A contact pushes a particle out twice in an implicit step (sim.integrator): the penalty
k = kappa m / h_k along the normal inside the solve, and the projection after it
(collision.colliders.project_contacts), which removes the inward velocity the penalty left.
On cloth at rest or sliding on a surface the penalty carries most of the load (kappa / (1 +
kappa) of it where the particle starts at the contact distance), so friction scaled by the
projection's share alone is a small fraction of mu. Coulomb's law bounds the tangential
impulse by mu times the whole normal one:

    |dv_t| <= mu (h_f f_pen / m + dv_n),

with f_pen >= 0 the penalty force the solve balanced (the particle's solved position against
its contact, as sim.loads counts it), h_f the step's factor of the forces in its right-hand
side (StepSystem.h_eff: h for implicit Euler, 2h/3 for BDF2, gamma h / (1 - alpha_m) for
generalised-alpha) and dv_n the normal velocity the projection removed. The slip relative to
the surface shrinks by that bound (to zero where it is larger: sticking), and the position
moves with the velocity change by the scheme's own factor, x += h_x dv_t (h_x: dx_{n+1} /
dv_{n+1}). So the correction is exactly what an explicit force m dv_t / h_f added to the
step's forces would have done, and stays a velocity-level projection: the block-symmetric
system is unchanged. On a plane tilted by theta, a particle's tangential velocity change in a
step is h_f g sin(theta) and its normal impulse h_f g cos(theta) per unit mass, so it sticks
exactly where tan(theta) <= mu and otherwise slides at g (sin(theta) - mu cos(theta)) in every
scheme, provided the scheme's history keeps the tangential motion (sim.friction restarts the
history only along the normal the projection pushed along). Units SI: m, s, kg.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class StepFriction:
    """One step's friction state, shared by the projection's passes.

    h_force: the step's factor of the forces, s (a velocity change dv is the force m dv /
    h_force); h_move: the position update's factor of the new velocity, s; budget {collider:
    (n,) m/s}: the normal velocity change each particle's penalty contacts with that collider
    gave it over the step (>= 0; a projection of that particle by that collider takes it, so a
    later pass does not count it twice); dv (n, 3) m/s: the tangential velocity changes
    friction made; normal (n, 3): the outward normal of each particle's latest push; pushes
    (n,): how many times the projection pushed each particle (more than one: pinched between
    surfaces, its history restarts whole).
    """

    n: int
    h_force: float
    h_move: float
    budget: dict = field(default_factory=dict)
    dv: np.ndarray = field(default=None)
    normal: np.ndarray = field(default=None)
    pushes: np.ndarray = field(default=None)

    def __post_init__(self) -> None:
        if self.dv is None:
            self.dv = np.zeros((self.n, 3))
        if self.normal is None:
            self.normal = np.zeros((self.n, 3))
        if self.pushes is None:
            self.pushes = np.zeros(self.n, np.int64)

    def add_penalty(self, index: np.ndarray, collider: np.ndarray, force: np.ndarray,
                    mass: np.ndarray) -> None:
        """Penalty contacts: particles index (c,), their colliders (c,), the penalty's normal
        force on each (c,) N (negative, a linearised penalty pulling inwards, counts as
        none); mass (n,) kg."""
        dv_n = self.h_force * np.maximum(force, 0.0) / mass[index]
        for which in np.unique(collider):
            on = collider == which
            into = self.budget.setdefault(int(which), np.zeros(self.n))
            np.add.at(into, index[on], dv_n[on])

    def take(self, which: int, index: np.ndarray) -> np.ndarray:
        """(k,) m/s: the penalty's normal velocity change of particles index (k,) against
        collider ``which``, removed from the budget (a particle counts it once)."""
        into = self.budget.get(int(which))
        if into is None:
            return np.zeros(len(index))
        out = into[index]
        into[index] = 0.0
        return out


def coulomb(x: np.ndarray, v: np.ndarray, index: np.ndarray, normal: np.ndarray,
            velocity: np.ndarray, removed: np.ndarray, mu: float, friction: StepFriction,
            which: int) -> None:
    """Coulomb friction on contacts of collider ``which`` after their inward velocity was
    removed: particles index (k,) with outward normals (k, 3), the surface's velocity there
    (k, 3) m/s and the normal velocity the projection removed (k,) m/s (>= 0). x, v (n, 3)
    are changed in place (the module docstring's bound and position update)."""
    rel = v[index] - velocity
    vt = rel - np.einsum("ij,ij->i", rel, normal)[:, None] * normal
    slip = np.linalg.norm(vt, axis=1)
    bound = mu * (removed + friction.take(which, index))
    # the share of the slip friction takes away: all of it where the bound reaches it
    cut = np.where(slip > bound, bound / np.maximum(slip, 1e-300), 1.0)
    dv = -cut[:, None] * vt
    v[index] += dv
    x[index] += friction.h_move * dv
    np.add.at(friction.dv, index, dv)
    friction.normal[index] = normal
    np.add.at(friction.pushes, index, 1)
