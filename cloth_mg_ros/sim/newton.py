"""Newton iterations of an implicit step: its equations linearised where the cloth goes, or
solved at the step's end, not only linearised at its start.

An implicit Euler or BDF2 step solves

    R(v) = M (v - v_hat) - h' F(x_hat + h' v, v) = 0

(h' = dt and v_hat = v_n, x_hat = x_n for implicit Euler; h' = 2 dt / 3, v_hat = (4 v_n -
v_{n-1}) / 3 and x_hat = (4 x_n - x_{n-1}) / 3 for BDF2; F the forces: elastic, damping -c H
v, gravity, external, air drag, the contacts' penalties and the cloth-cloth springs). The
step (sim.integrator.assemble_step) takes one Newton iteration from v_n, the forces
linearised where the cloth starts. That is exact for what is linear in x, and poor for a
membrane that turns under load: a taut or bent face that rotates by theta in a step keeps,
in the linearisation, its forces' old directions, and the step brakes the turn (a silk tube
spinning at 0.1 m/s rim speed keeps -0.11 of its angular momentum after 0.1 s at 1/60 s:
doc/benchmarks/fidelity.md, "The spinning tube"). An iteration at v_k (x_k = x_hat + h'
v_k) solves

    (M (1 + h' drag) + h' (h' + c) H(x_k) + h'^2 K_c) dv = h' F(x_k, v_k) - M (v_k - v_hat)

for the correction dv (K_c the penalties' and the springs' stiffness; the damping's own
change with x is left out, as every implicit cloth step leaves it), with the same block
system the step uses, so any of the solvers takes it:

* `predicted_step` takes the first iteration at the prediction v_k = v_n (where the cloth
  goes if nothing acts on it), in place of the start's: the same cost, and a face that turns
  in the step is linearised turned (the tube keeps 0.62; 0.99 without the fabric's damping).
  The fabric's damping -c H v also brakes a turn of stressed cloth (H v of a rigid turn is
  the turn of the forces); on the strain rates alone (DAMPING_MODELS' strain_rate, the
  Hessian's part along each stretch measure and each bending stencil's normal) the tube
  keeps 0.995.
* `newton_correction` takes one more from the last iterate (`newton_iterate`).

Pinned particles keep the step's velocity (their rows are fixed at zero correction). The
contacts are the step's: the same particles, normals and planes (the penalty is linear in x,
so its force at x_k is exact); the corrections after the solve (projection, friction, strain
limit) follow the last iterate. Generalised-alpha is left at one iteration from the start
(its forces act at a blend of the two ends of the step, a different residual). Units SI.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.system import BlockSystem, RotationTerms
from cloth_mg_ros.sim.contact_friction import add_damper_blocks, add_damper_forces
from cloth_mg_ros.sim.forces import Workspace, internal_forces
from cloth_mg_ros.sim.friction import penalty_forces
from cloth_mg_ros.sim.integrator import (
    StepSystem,
    framed_step,
    solved_positions,
    step_frame,
)
from cloth_mg_ros.sim.model import ClothControl, ClothModel, ClothState
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, LINEARISE_AT
from cloth_mg_ros.sim.step_contacts import add_penalty_blocks, self_contact_springs
from cloth_mg_ros.sim.step_terms import mass_blocks, step_forces

__all__ = ["DAMPING_MODELS", "check_damping_model", "check_linearise_at", "linearised_system",
           "newton_correction",
           "newton_iterate", "predicted_step"]

_NO_LOAD = np.zeros((0, 3))
# the loosest relative tolerance a correction is solved to (its residual still shrinks by
# half); a correction far smaller than the step's own change needs no more than the step's
CORRECTION_TOL_CAP = 0.5


# the fabric's damping force: -c H v (stiffness-proportional, Rayleigh: it also brakes a turn
# of the stressed cloth) or -c H_rate v, H_rate the Hessian's part along the measures (each
# stretch measure's length, each bending stencil's curvature along its normal: their rates
# alone; no force on a rigid turn, nor on a taut face's sideways sway, which then only the
# step and the air damp: particles of the brisk walk's dress moved a third faster at the
# median, doc/benchmarks/dynamics.md). strain_rate is taken at the prediction.
DAMPING_MODELS = ("stiffness", "strain_rate")


def check_damping_model(value, linearise_at: str) -> None:
    """ClothInputError unless ``value`` is one of DAMPING_MODELS ('strain_rate' only with
    linearise_at 'prediction')."""
    if value not in DAMPING_MODELS:
        raise ClothInputError(f"damping_model must be one of {', '.join(DAMPING_MODELS)}, got "
                              f"{value!r}")
    if value == "strain_rate" and linearise_at != "prediction":
        raise ClothInputError(f"damping_model 'strain_rate' needs linearise_at 'prediction', "
                              f"got {linearise_at!r}")


def check_linearise_at(value, scheme: str) -> None:
    """ClothInputError unless ``value`` is one of LINEARISE_AT ('prediction' only for
    implicit Euler and BDF2)."""
    if value not in LINEARISE_AT:
        raise ClothInputError(f"linearise_at must be one of {', '.join(LINEARISE_AT)}, got "
                              f"{value!r}")
    if value == "prediction" and scheme not in ("euler", "bdf2"):
        raise ClothInputError(f"linearise_at 'prediction' needs the scheme euler or bdf2, got "
                              f"{scheme!r}")


def predicted_step(model: ClothModel, state: ClothState, dt: float, scheme: str,
                   control: ClothControl | None = None, work: Workspace | None = None,
                   spectral_radius: float = DEFAULT_SPECTRAL_RADIUS,
                   rate_damping: bool = False) -> StepSystem:
    """`sim.integrator.assemble_step`'s step (same arguments; implicit Euler or BDF2), its
    forces linearised at the prediction instead of where the cloth starts: the first Newton
    iterate v_k = v_n (the held particles' v where their targets put them), x_k = x_hat +
    h' v_k, where the cloth goes if nothing acts on it. One assembly and one solve, as the
    start's: A and the residual at x_k (`linearised_system`); the unknown stays dv = v_{n+1} -
    v_n, with b = residual + A dv_k, so the solvers, the pins' rows and the wrenches
    (sim.pins.constraint_forces: the pinned rows' residual) take it unchanged. A face that
    turns in the step is then linearised turned, and keeps its forces' directions: a silk tube
    spinning at 0.1 m/s keeps 0.99 of its angular momentum over 0.1 s at 1/60 s without the
    fabric's damping, against -0.03 linearised at the start. rate_damping: the fabric's
    damping on its strain rates alone (DAMPING_MODELS' strain_rate; with it the tube keeps
    0.995), else -c H v at the prediction."""
    check_linearise_at("prediction", scheme)
    frame = step_frame(model, state, dt, scheme, control, spectral_radius)
    step = framed_step(model, state, frame, None, None, None)
    step.rate_damping = bool(rate_damping)
    system, rhs, internal = linearised_system(model, state, step, step.x0, frame.pairs(model),
                                              work)
    rhs += system.matvec(step.x0)
    step.system, step.rhs, step.internal = system, rhs, internal
    return step


def newton_correction(model: ClothModel, state: ClothState, step: StepSystem,
                      dv: np.ndarray, solver, reference: float | None = None):
    """One more Newton iteration of ``step`` (an implicit Euler or BDF2 step from ``state``)
    from its solution dv (n, 3) m/s: returns (the corrected dv (n, 3) m/s, the correction's
    solve result). reference: the norm of the step's own right-hand side (its free rows):
    the correction is then solved to the residual the step's own solve was held to, not to
    the solver's tolerance relative to its own small right-hand side (which took a walking
    dress's corrections 50 iterations each against the step's 15), or to the solver's own
    tolerance where that is looser; None: the solver's tolerance as it is."""
    system, rhs, _ = linearised_system(model, state, step, dv, step.system.pairs)
    rhs[step.fixed] = 0.0
    result = _solve_correction(solver, system, rhs, step.fixed, reference)
    return dv + result.x, result


def linearised_system(model: ClothModel, state: ClothState, step: StepSystem, dv: np.ndarray,
                      pairs: np.ndarray, work: Workspace | None = None):
    """The equations of ``step`` (implicit Euler or BDF2, from ``state``) linearised at the
    iterate v_k = v_n + dv, dv (n, 3) m/s: returns (A at x_k as a BlockSystem, the residual
    h' F(x_k, v_k) - M (v_k - v_hat) (n, 3) kg m/s on every row, the elastic terms at x_k).
    pairs: the mesh's pairs, then the step's cloth-cloth pairs. work: a Workspace for the
    elastic terms' arrays (None: arrays of their own)."""
    if step.genalpha is not None or step.scheme not in ("euler", "bdf2"):
        raise ClothInputError(f"Newton iterations take implicit Euler and BDF2 steps, not "
                              f"{step.scheme!r}")
    h = step.h_eff
    mat = model.material
    c = mat.damping
    x_k, v_k = solved_positions(state, step, dv, h)  # h = dt for implicit Euler
    v_hat = (4.0 * state.v - state.v_prev) / 3.0 if step.scheme == "bdf2" else state.v
    n_mesh = len(model.pairs)
    sc_pairs = pairs[n_mesh:]
    scale = h * h + h * c
    internal = internal_forces(model, x_k, work=work, product_of=c * v_k, hess_scale=scale,
                               spare_rows=len(sc_pairs), rate_product=step.rate_damping)
    m = model.mass
    forces = np.empty_like(x_k)
    external = model.external_force
    step_forces(internal.forces, np.asarray(model.gravity, dtype=np.float64),
                _NO_LOAD if external is None else np.asarray(external, dtype=np.float64), m,
                v_k, mat.air_drag, forces)
    diag = np.empty((model.n, 3, 3))
    mass_blocks(m, 1.0 + h * mat.air_drag, diag)
    contacts = step.contacts
    if len(contacts):
        push = penalty_forces(model, step, state.x, x_k)
        np.add.at(forces, contacts.index, push[:, None] * contacts.normal)
    add_penalty_blocks(contacts, step.contact_stiffness, None, h * h, h, diag)
    # friction inside the solve: the step's dampers, lagged as its normal forces are
    add_damper_forces(contacts, step.friction_damping, v_k, forces)
    add_damper_blocks(contacts, step.friction_damping, h, diag)
    offd = internal.pair_rows
    if len(sc_pairs):
        offd[n_mesh:] = h * h * self_contact_springs(model, x_k, sc_pairs, h * h, forces)
    rhs = h * (forces - internal.product) - m[:, None] * (v_k - v_hat)
    system = BlockSystem(diag, pairs, offd, scale, RotationTerms(x_k, internal.forces))
    return system, rhs, internal


def _solve_correction(solver, system: BlockSystem, rhs: np.ndarray, fixed: np.ndarray,
                      reference: float | None):
    """The correction's solve from zero, its tolerance loosened to reach the residual norm
    ``reference`` times the solver's tolerance (`newton_correction`), and put back."""
    tol = getattr(solver, "tol", None)
    size = float(np.linalg.norm(rhs))
    if reference is None or tol is None or size == 0.0:
        return solver.solve(system, rhs, np.zeros_like(rhs), fixed)
    solver.tol = min(CORRECTION_TOL_CAP, max(tol, tol * reference / size))
    try:
        return solver.solve(system, rhs, np.zeros_like(rhs), fixed)
    finally:
        solver.tol = tol


def newton_iterate(model: ClothModel, state: ClothState, step: StepSystem, first,
                   solver, iterations: int):
    """The step's solve result after ``iterations`` Newton iterations in all, the first
    (``first``, the step's own solve) included: its dv the last iterate, its iterations the
    solves' total, converged when every solve did (each correction to the step's own
    residual: `newton_correction`'s reference)."""
    dv, total, converged = first.x, first.iterations, first.converged
    reference = max(float(np.linalg.norm(step.rhs[~step.fixed])), step.weight_impulse)
    for _ in range(iterations - 1):
        dv, more = newton_correction(model, state, step, dv, solver, reference)
        total += more.iterations
        converged = converged and more.converged
    return replace(first, x=dv, iterations=total, converged=converged)
