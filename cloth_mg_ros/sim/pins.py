"""A step's held particles: where they must end (`pin_targets`), the velocity change that takes
them there (`pin_velocity_changes`, the Baraff-Witkin constraint values the solve keeps
fixed) and the force holding them (`constraint_forces`, the pinned rows' residual). Units SI.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.physics.incidence import MeshIncidence
from cloth_mg_ros.sim.model import ClothControl, ClothState
from cloth_mg_ros.sim.schemes import GenAlpha


def pin_velocity_changes(pins: np.ndarray, state: ClothState, control: ClothControl | None,
                         h: float, bdf2: bool, ga: GenAlpha | None = None) -> np.ndarray:
    """(n, 3) dv of the step's constraints: zero for free particles; for the held ones, pins
    (k,), the change
    that lands them on their targets at the end of the step (v_new from the scheme's position
    update with effective step h s, dv = v_new - v: Baraff-Witkin constraint values;
    generalised-alpha: dv from its Newmark position update)."""
    x, v = state.x, state.v
    x0 = np.zeros_like(x)
    target = pin_targets(pins, state, control)
    if ga is not None:
        start = x[pins] + ga.h * v[pins] + ga.c * state.a[pins]
        x0[pins] = (target - start) / ga.h_dv
        return x0
    start = (4.0 * x[pins] - state.x_prev[pins]) / 3.0 if bdf2 else x[pins]
    x0[pins] = (target - start) / h - v[pins]
    return x0


def pin_targets(pins: np.ndarray, state: ClothState, control: ClothControl | None = None
                ) -> np.ndarray:
    """Where the held particles pins (k,) must be at the end of the step, (k, 3) m: the
    control's targets when something carries them (a body), else where they are."""
    if control is not None and control.pin_targets is not None:
        return control.pin_targets
    return state.x[pins]


def constraint_forces(step, dv: np.ndarray, rows: np.ndarray,
                      incidence: MeshIncidence | None = None) -> np.ndarray:
    """(k, 3) N: the force that the constraints holding particles `rows` (k,) (the pinned
    ones) exert on them over the step (a sim.integrator.StepSystem) solved with `dv` (n, 3).

    The implicit step solves M dv = h (F + R) linearised, A dv = b, with the constraint force
    R zero on free particles and whatever holds a pinned particle where its constraint puts it.
    So R at a pinned row is that row's residual over the effective step, (A dv - b)_i / h: the
    particle's inertia (a holder that accelerates the cloth feels it), the elastic, damping
    and drag forces, gravity and contact penalties are all in it, exactly as the step used
    them. Only the rows asked for are computed (their blocks and the pairs that touch them).
    incidence: the mesh's tables (physics.incidence), whose pairs come first in the system:
    the mesh pairs at the rows are looked up there instead of found by a pass over all.
    """
    rows = np.asarray(rows, dtype=np.int64)
    if not len(rows):
        return np.zeros((0, 3))
    system = step.system
    d = np.asarray(dv, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((system.n, 3))
    out[rows] = np.einsum("kab,kb->ka", system.diag[rows], d[rows])
    wanted = np.zeros(system.n, dtype=bool)
    wanted[rows] = True
    i, j = system.pairs[:, 0], system.pairs[:, 1]
    if incidence is None:
        touch = np.flatnonzero(wanted[i] | wanted[j])
    else:
        n_mesh = len(incidence.ps_ptr) - 1
        lo, hi = incidence.vp_ptr[rows], incidence.vp_ptr[rows + 1]
        at = np.repeat(lo - np.cumsum(hi - lo) + (hi - lo), hi - lo) + np.arange(int(
            np.sum(hi - lo)))
        touch = np.concatenate([np.unique(incidence.vp_pair[at]), n_mesh + np.flatnonzero(
            wanted[i[n_mesh:]] | wanted[j[n_mesh:]])])
    if len(touch):
        c = np.einsum("kab,kb->ka", system.offd[touch], d[j[touch]] - d[i[touch]])
        np.add.at(out, i[touch], c)
        np.add.at(out, j[touch], -c)
    return (out[rows] - step.rhs[rows]) / step.h_eff
