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
from numba import njit


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
    surfaces, its history restarts whole); mu_scale: the share of each collider's friction
    the projection applies (0: friction acts inside the solve, sim.contact_friction).
    """

    n: int
    h_force: float
    h_move: float
    budget: dict = field(default_factory=dict)
    dv: np.ndarray = field(default=None)
    normal: np.ndarray = field(default=None)
    pushes: np.ndarray = field(default=None)
    mu_scale: float = 1.0

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


_NO_BUDGET = np.zeros(0)


def project_with_friction(x: np.ndarray, v: np.ndarray, index: np.ndarray, normal: np.ndarray,
                          distance: np.ndarray, velocity: np.ndarray, rest: float, mu: float,
                          friction: StepFriction, which: int) -> None:
    """Contacts of collider ``which`` (particles index (k,), unique; outward normals (k, 3),
    signed distances (k,) m, the surface's velocity there (k, 3) m/s), projected in place in
    x, v (n, 3): each particle moved out to ``rest`` m from the surface, its inward velocity
    relative to the surface removed, then Coulomb friction with the module docstring's bound
    (its penalty budget against this collider taken), the position moved with the velocity
    and what friction did recorded in ``friction``."""
    budget = friction.budget.get(int(which), _NO_BUDGET)
    _project_kernel(x, v, np.ascontiguousarray(index, dtype=np.int64),
                    np.ascontiguousarray(normal, dtype=np.float64),
                    np.ascontiguousarray(distance, dtype=np.float64),
                    np.ascontiguousarray(velocity, dtype=np.float64), float(rest),
                    float(mu) * friction.mu_scale,
                    budget, float(friction.h_move), friction.dv, friction.normal,
                    friction.pushes)


@njit(cache=True, nogil=True)
def _project_kernel(x, v, index, normal, distance, velocity, rest, mu, budget, h_move, dv_out,
                    normal_out, pushes):
    """`project_with_friction`'s loop, a contact at a time (numpy's row gathers and scatters
    on (k, 3) arrays cost milliseconds a step at 8K contacts)."""
    for k in range(index.shape[0]):
        i = index[k]
        push = rest - distance[k]
        rel = np.empty(3)
        vn = 0.0
        for a in range(3):
            x[i, a] += push * normal[k, a]
            rel[a] = v[i, a] - velocity[k, a]
            vn += rel[a] * normal[k, a]
        removed = -vn if vn < 0.0 else 0.0
        bound = removed
        if budget.shape[0] > 0:
            bound += budget[i]
            budget[i] = 0.0  # taken once
        bound *= mu
        slip = 0.0
        vt = np.empty(3)
        for a in range(3):
            rel[a] += removed * normal[k, a]
        along = 0.0
        for a in range(3):
            along += rel[a] * normal[k, a]
        for a in range(3):
            vt[a] = rel[a] - along * normal[k, a]
            slip += vt[a] * vt[a]
        slip = np.sqrt(slip)
        # the share of the slip friction takes away: all of it where the bound reaches it
        cut = bound / slip if slip > bound else 1.0
        for a in range(3):
            d = -cut * vt[a]
            v[i, a] = rel[a] + d + velocity[k, a]
            x[i, a] += h_move * d
            dv_out[i, a] += d
            normal_out[i, a] = normal[k, a]
        pushes[i] += 1
