"""Friction against the colliders inside the implicit step (ClothModel.contact_friction "solve").

Why: the node's friction ("projection") acts after the solve, on each particle alone
(collision.friction). A particle it stops is moved back against a membrane that the solve
balanced with that particle sliding, while its free neighbours keep the motion the solve gave
them, so a cloth that sticks where it touches is stretched a little more at every step and
nothing takes it back: a cotton sheet dropped 10 cm onto a sphere, with at most 0.25 J of
kinetic energy, holds 10-20 J of stretch from 1 s on (doc/benchmarks/folds.md). A second leak
is in the contacts' set: a particle resting on a convex collider and sliding along it is
predicted just outside it, (h v_t)^2 / 2R, so it is no penalty contact of the step; gravity
and the cloth's tension press it in during the solve, and the projection pushes it out along
its own normal, stretching what it pushes.

In this mode:

1. **Resting contacts are kept.** A particle that pressed on a collider over the last step
   (ClothState.contact_force > 0) is a penalty contact of this step when its prediction is
   within RESTING_BAND of the thickness beyond it. Its penalty is zero where the particle
   goes at its velocity, so it resists being pressed in from there and pulls on nothing
   that moves on as it moves (a strip that stops wrapping a cylinder leaves it freely). One
   that forces lift off the surface is held back for that step (a linear penalty pulls it)
   and let go at the next, its force then pulling.
2. **Coulomb friction is a tangential damper of each contact**, c_t = mu f_n / max(norm(v_t),
   SLIP_FLOOR) on the tangent plane (I - n n^T): f_n how hard the particle pressed over the
   last step, v_t the slip relative to the surface the step would end with under the forces
   at its start and mu f_n (`friction_dampers`). A sliding particle feels mu f_n against its
   slip; one pressed with f_n and pulled along the surface by less than mu f_n creeps at
   under SLIP_FLOOR. The damper is
   implicit: A gains h_d c_t (I - n n^T) on the particle's diagonal block, so the system
   stays block-symmetric (the faithful coarsening takes the diagonal as it is) and the solve
   sees the friction with the membrane, which the projection's friction cannot. The normal
   force is lagged by a step, as Incremental Potential Contact lags its friction's (Li et
   al., ACM TOG 39(4), 2020): a first step of contact has none. The projection after the
   solve then only removes what is left inside and the inward velocity, without friction.
3. **The normal force for the next step** is the penalty's at the solved position plus the
   projection's push, per particle, N (`pressing_forces`).
4. **The laws are checked after the solve** (sim.contact_set): a penalty that pulls is
   dropped and each damper sized again for the slip the solve gave it (past mu f_n, or
   short of it where the solve slowed the particle down), and the step solved again, until
   none is broken (up to sim.contact_set.SETTLE_ROUNDS rounds).

Implicit Euler, BDF2 and generalised-alpha (whose dampers act at v_{n+1-alpha_f}),
linearised at the start; Newton's further iterations keep the step's dampers (sim.newton).
The step linearised at the prediction has no forces at the start to size them with, and
refuses this mode. Units SI.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.collision.colliders import Contacts, collide
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.model import CONTACT_FRICTIONS

# Resting contacts are kept while their prediction is within this share of the thickness
# beyond it: above the outward drift of a particle sliding along a convex collider in a step,
# (h v_t)^2 / 2R, at a drape's speeds (6 um at 0.1 m/s, 1/60 s and R = 25 cm), not round a
# limb at 1 m/s (2.8 mm at R = 5 cm: such a particle leaves the set for a step). A band of
# a whole thickness, with the penalty's zero on the surface, left the frictionless capstan's
# slide at 1/60 s where it was (11.3 against 11.6 mm of 151 mm; its brake is the step's).
RESTING_BAND = 0.1
# m/s: the slip below which friction is a damper of stiffness mu f_n / SLIP_FLOOR, so the
# creep of a particle held against a pull under mu f_n (the regularisation of Coulomb's law)
SLIP_FLOOR = 1e-4


def check_contact_friction(contact_friction: str, linearise_at: str) -> None:
    """ClothInputError naming a contact_friction that is none of CONTACT_FRICTIONS, or
    friction inside the solve with a step linearised at the prediction (module docstring)."""
    if contact_friction not in CONTACT_FRICTIONS:
        raise ClothInputError(f"contact_friction must be one of {', '.join(CONTACT_FRICTIONS)}"
                              f", got {contact_friction!r}")
    if contact_friction != "solve":
        return
    if linearise_at != "start":
        raise ClothInputError(
            f"contact_friction 'solve' takes steps linearised at the start, not at the "
            f"{linearise_at!r}")


def with_resting(model, colliders: list, x: np.ndarray, v: np.ndarray, dt: float,
                 contacts: Contacts, pressed: np.ndarray | None) -> Contacts:
    """``contacts`` (the step's predicted ones, sim.integrator.predicted_contacts) and the
    resting ones of item 1 of the module docstring: particles with pressed (n,) N > 0 not among
    them whose prediction x + dt v ((n, 3) m, m/s) is within (1 + RESTING_BAND) times the
    model's thickness of a collider of ``colliders`` (at their end-of-step poses), their
    distance set so that the penalty is zero at the prediction (thickness - dt v . n).
    pressed None: ``contacts`` as they are."""
    if pressed is None:
        return contacts
    candidate = pressed > 0.0
    candidate[contacts.index] = False
    rows = np.flatnonzero(candidate)
    if not len(rows):
        return contacts
    xr, vr = x[rows], v[rows]
    extra = collide(colliders, xr + dt * vr, model.thickness * (1.0 + RESTING_BAND), xr)
    if not len(extra):
        return contacts
    # the penalty's zero where the particle goes at its velocity, just outside: it resists
    # being pressed in from there and pulls on nothing that keeps moving as it moves (a
    # strip leaving a cylinder where it stops wrapping it is not held back)
    extra.distance = model.thickness - dt * np.einsum("ij,ij->i", vr[extra.index],
                                                      extra.normal)
    extra.index = rows[extra.index]
    return Contacts.concatenate([contacts, extra])


def friction_dampers(colliders: list, contacts: Contacts, v: np.ndarray,
                     pressed: np.ndarray | None, forces: np.ndarray, mass: np.ndarray,
                     dt: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(c,) N s/m: each contact's tangential damper c_t = mu f_n / max(norm(v_t), SLIP_FLOOR)
    (module docstring): mu its collider's friction; f_n how hard the particle pressed over
    the last step, ``pressed`` (n,) N (None, the run's first step: the forces (n, 3) N that
    act on it at the start pushing it in), shared among its contacts; v_t the slip
    the step would end with under those forces and mu f_n, from its velocity v (n, 3) m/s
    relative to the surface, norm(v_t + dt a_t) - dt mu f_n / m (mass (n,) kg, dt s), so that a
    sliding particle feels mu f_n at the end of the step, not at its start. Returns (c_t,
    Coulomb's bound mu f_n (c,) N), None without contacts."""
    if not len(contacts):
        return None
    idx, normal = contacts.index, contacts.normal
    count = np.bincount(idx, minlength=len(mass))[idx]
    if pressed is None:  # the run's first step: the forces that press it in now
        f_n = np.maximum(-np.einsum("ij,ij->i", forces[idx], normal), 0.0) / count
    else:  # not those: a stretched membrane's unbalanced force is no contact's
        f_n = pressed[idx] / count
    mu = np.array([col.friction for col in colliders], dtype=np.float64)[contacts.collider]
    m = mass[idx]
    slip = tangential(v[idx] - contacts.velocity + dt * forces[idx] / m[:, None], normal)
    speed = np.linalg.norm(slip, axis=1) - dt * mu * f_n / m
    return mu * f_n / np.maximum(speed, SLIP_FLOOR), mu * f_n


def tangential(w: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(c, 3): w's rows (c, 3) on the tangent planes of the unit normals (c, 3)."""
    return w - np.einsum("ij,ij->i", w, normal)[:, None] * normal


def add_damper_forces(contacts: Contacts, c_t: np.ndarray | None, v: np.ndarray,
                      forces: np.ndarray) -> None:
    """Add the dampers' (c_t (c,) N s/m) forces at the start's velocities v (n, 3) m/s,
    -c_t (I - n n^T)(v - v_surface), to ``forces`` (n, 3) N (None: none)."""
    if c_t is not None:
        idx = contacts.index
        np.add.at(forces, idx,
                  -c_t[:, None] * tangential(v[idx] - contacts.velocity, contacts.normal))


def add_damper_blocks(contacts: Contacts, c_t: np.ndarray | None, h_d: float,
                      diag: np.ndarray) -> None:
    """Add h_d c_t (I - n n^T) to A's diagonal blocks ``diag`` (n, 3, 3) kg: the dampers c_t
    (c,) N s/m of `add_damper_forces` (h_d: the step's factor of D in A; None: none)."""
    if c_t is not None:
        normal = contacts.normal
        plane = np.eye(3)[None] - normal[:, :, None] * normal[:, None, :]
        np.add.at(diag, contacts.index, (h_d * c_t)[:, None, None] * plane)


def friction_forces(step, v_start: np.ndarray, v_solved: np.ndarray) -> np.ndarray | None:
    """(c, 3) N: the force each contact's tangential damper put on its particle as the step
    balanced it, at the solved velocity (generalised-alpha's v_{n+1-alpha_f}), from the
    velocities (n, 3) m/s at the start and as solved; None without dampers."""
    c_t = step.friction_damping
    if c_t is None:
        return None
    return -c_t[:, None] * solved_slip(step, v_start, v_solved)


def solved_slip(step, v_start: np.ndarray, v_solved: np.ndarray) -> np.ndarray:
    """(c, 3) m/s: each contact's slip on its tangent plane, relative to the surface, at the
    velocity its damper acts at (the solved one; generalised-alpha's v_{n+1-alpha_f}), from
    the velocities (n, 3) m/s at the start and as solved."""
    idx, ga = step.contacts.index, step.genalpha
    w = 1.0 if ga is None else 1.0 - ga.alpha_f
    v = v_start[idx] + w * (v_solved[idx] - v_start[idx])
    return tangential(v - step.contacts.velocity, step.contacts.normal)


def pressing_forces(n: int, mass: np.ndarray, penalty: np.ndarray, index: np.ndarray,
                    pushed: np.ndarray, normal: np.ndarray, v_solved: np.ndarray,
                    v_new: np.ndarray, h_force: float) -> np.ndarray:
    """(n,) N: how hard each particle pressed on the colliders over a step: its penalty
    contacts' forces ``penalty`` (c,) N at the solved positions (particles ``index`` (c,);
    pulling ones count as none) plus the projection's push, the velocity it added along the
    normal (n, 3) of the particles ``pushed`` (n,) bool, v_new - v_solved (n, 3) m/s, times
    the mass (n,) kg over the step's factor of the forces h_force s."""
    out = np.zeros(n)
    np.add.at(out, index, np.maximum(penalty, 0.0))
    rows = np.flatnonzero(pushed)
    dv_n = np.einsum("ij,ij->i", v_new[rows] - v_solved[rows], normal[rows])
    out[rows] += mass[rows] * np.maximum(dv_n, 0.0) / h_force
    return out
