"""An implicit step's friction bookkeeping (sim.integrator.finish_step): the penalty's share of
each contact's normal impulse, and a history that keeps the motion friction leaves.

Coulomb's bound uses the step's whole normal impulse (collision.friction). The penalty's part
comes from the solve: each penalty contact's force at the particle's solved position (the
penalty is linear in it, as sim.loads counts it) times the step's factor of the forces.

Friction's velocity change, with the position moved by the scheme's own factor, is what an
explicit force added to the step would have done, so it is motion, not a correction: the
step's solved state takes it in before the history is restarted. The projection's push out
along the normal stays a correction, and BDF2's history (generalised-alpha's acceleration)
restarts along that normal only: the tangential history goes on, so a sliding particle keeps
accelerating at the scheme's own rate. (Restarting the whole history, as every correction
did, made every step of a particle resting on a surface an Euler-like step of 2h/3 for BDF2
and 5h/6 for generalised-alpha at rho_inf = 0.5: cloth sliding on a slope gained a third or a
sixth too little speed a step.) A particle pushed along more than one normal (pinched between
surfaces) or moved by another correction (strain limit, edge contact) restarts whole, as
before. Units SI.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cloth_mg_ros.collision.friction import StepFriction


def penalty_forces(model, step, x_start: np.ndarray, x_solved: np.ndarray) -> np.ndarray:
    """(c,) N: each of the step's penalty contacts' force along its normal with the cloth at
    x_solved (n, 3) m, from x_start (n, 3) m where the step was built: k (thickness -
    distance - w (x_solved - x_start) . n), the penalty being linear in the position, w = 1
    but for generalised-alpha, whose forces act at x_{n+1-alpha_f}, w = 1 - alpha_f
    (negative: a linearised penalty pulling inwards)."""
    contacts, ga = step.contacts, step.genalpha
    idx = contacts.index
    moved = np.einsum("ij,ij->i", x_solved[idx] - x_start[idx], contacts.normal)
    if ga is not None:
        moved *= 1.0 - ga.alpha_f
    return step.contact_stiffness * (model.thickness - contacts.distance - moved)


def step_friction(model, step, x_start: np.ndarray, x_solved: np.ndarray,
                  damper: np.ndarray | None = None) -> StepFriction:
    """The StepFriction of a solved step: model a ClothModel, step its StepSystem; x_start,
    x_solved (n, 3) m: positions at the start of the step and as solved (pins placed, before
    any correction); damper (c,) N: each contact's damper force along its normal as the step
    balanced it (sim.integrator.contact_damper_forces; None: no dampers). A contact's normal
    force is its penalty k (thickness - distance - w (x_solved - x_start) . n) plus its damper,
    N, as sim.loads.contact_load counts it: the penalty linearised where the step balances the
    forces, w = 1 but for generalised-alpha, whose forces act at x_{n+1-alpha_f},
    w = 1 - alpha_f."""
    friction = StepFriction(model.n, step.h_eff, step.h_move)
    contacts = step.contacts
    if len(contacts):
        force = penalty_forces(model, step, x_start, x_solved)
        if damper is not None:
            force = force + damper
        friction.add_penalty(contacts.index, contacts.collider, force, model.mass)
    return friction


def fold_friction(friction: StepFriction, step, fixed: np.ndarray, x_solved: np.ndarray,
                  v_solved: np.ndarray, a_solved: np.ndarray | None,
                  corrected: np.ndarray | None = None) -> np.ndarray:
    """Take friction's velocity changes (none on the ``fixed`` (n,) particles, which their pins
    put back) into the solved state in place: x_solved, v_solved (n, 3), and a_solved (n, 3)
    (generalised-alpha's acceleration, or None). corrected (n,) bool: particles another
    correction moved (strain limit, edge contact), or None. Returns (n, 3) the normal along
    which each particle's history restarts (zero: whole, or not at all where nothing
    corrected it)."""
    ga = step.genalpha
    # Newmark: v_{n+1} = v_n + h (... + gamma a_{n+1}), so a velocity change dv is dv / (gamma h)
    # of acceleration
    a_scale = 1.0 / (ga.gamma * ga.h) if ga is not None else 0.0
    along = np.empty_like(friction.normal)
    _fold(friction.dv, friction.normal, friction.pushes, fixed,
          _NONE_BOOL if corrected is None else corrected, friction.h_move, a_scale, x_solved,
          v_solved, _NONE_3 if a_solved is None else a_solved, along)
    return along


_NONE_BOOL = np.zeros(0, dtype=bool)
_NONE_3 = np.zeros((0, 3))


@njit(cache=True, nogil=True)
def _fold(dv, normal, pushes, fixed, corrected, h_move, a_scale, x_solved, v_solved, a_solved,
          along):
    """`fold_friction`'s loop (a particle at a time: numpy made five (n, 3) passes)."""
    with_a = a_solved.shape[0] > 0
    with_corrected = corrected.shape[0] > 0
    for i in range(dv.shape[0]):
        whole = pushes[i] != 1 or (with_corrected and corrected[i])
        for a in range(3):
            along[i, a] = 0.0 if whole else normal[i, a]
        if pushes[i] == 0 or fixed[i]:
            continue
        for a in range(3):
            x_solved[i, a] += h_move * dv[i, a]
            v_solved[i, a] += dv[i, a]
            if with_a:
                a_solved[i, a] += a_scale * dv[i, a]


@njit(cache=True, nogil=True)
def restart_history_along(x, v, x_new, v_new, x_solved, v_solved, dt, along, x_hist, v_hist):
    """The next step's BDF2 history (x_hist, v_hist (n, 3)): (x, v) where the step left a
    particle as solved; where a correction moved it, the restarted history (x_new - dt v_new,
    v_new) along its unit normal ``along`` (n, 3) and (x, v) across it, or the restarted one
    whole where along is zero."""
    for i in range(x.shape[0]):
        moved = False
        for a in range(3):
            if x_new[i, a] != x_solved[i, a] or v_new[i, a] != v_solved[i, a]:
                moved = True
        whole = along[i, 0] == 0.0 and along[i, 1] == 0.0 and along[i, 2] == 0.0
        if not moved:
            for a in range(3):
                x_hist[i, a] = x[i, a]
                v_hist[i, a] = v[i, a]
        elif whole:
            for a in range(3):
                x_hist[i, a] = x_new[i, a] - dt * v_new[i, a]
                v_hist[i, a] = v_new[i, a]
        else:
            px = 0.0
            pv = 0.0
            for a in range(3):
                px += along[i, a] * (x_new[i, a] - dt * v_new[i, a] - x[i, a])
                pv += along[i, a] * (v_new[i, a] - v[i, a])
            for a in range(3):
                x_hist[i, a] = x[i, a] + px * along[i, a]
                v_hist[i, a] = v[i, a] + pv * along[i, a]


def restart_acceleration_along(a_new: np.ndarray, moved: np.ndarray, along: np.ndarray) -> None:
    """Generalised-alpha's history: the acceleration a_new (n, 3) m/s^2 of the ``moved`` (n,)
    particles (a correction moved them) loses its component along their normal ``along``
    (n, 3), or all of it where along is zero; in place."""
    whole = moved & ~np.any(along != 0.0, axis=1)
    part = moved & ~whole
    a_new[whole] = 0.0
    n = along[part]
    a_new[part] -= np.einsum("ij,ij->i", a_new[part], n)[:, None] * n
