"""The contacts' laws checked after the step's solve (ClothModel.contact_friction "solve").

A penalty contact is a linear spring for the whole step and a friction damper a linear
force, so one solve can break the laws they stand for: a particle that the cloth lifts off
a limb is pulled back by its penalty (a contact never pulls), a stuck particle that a limb
drags feels more than mu f_n from its damper (Coulomb's bound), and a particle the solve
slowed down feels less than the friction it should: its damper was sized for the slip the
step was predicted to end with. On the walking dress at 9964 particles such steps put 56 N
on the pelvis where the projection's friction puts under 1 N (`cloth-mg run --scene walking
--particles 10000 --steps 100 --contact-friction solve` at 7e0c649; 1.2 N with this check).
So after the solve: contacts whose penalty pulls at the solved positions are dropped, every
damper is sized again for the slip the solve gave it, c_t = mu f_n / max(norm(v_t),
SLIP_FLOOR) (where that changes it by more than DAMPER_SLACK: the regularised Coulomb law,
iterated as a reweighted least-squares problem is), and the step's system is corrected on
those contacts' particles (`settled_step`) and solved again from the last solution, unless
that solution already meets the solver's tolerance on it: an active set's rounds, up to
SETTLE_ROUNDS, until no law is broken. Steps where no law is broken are left as they were.

Why every damper, not only those past their bound: lowering those alone, round after round,
only ever loosened the cloth's grip. A silk strip over a rough cylinder at 0.8 of the load
it holds (the capstan, mu 0.2, 1/240 s) slid 83 mm with four rounds and 2.4 mm with one;
sized again both ways it creeps 0.2 mm, and a strip at 1.25 of its load at mu 0.5 slides
120-138 mm of the exact 158 instead of 238 (fidelity/capstan.py;
doc/benchmarks/fidelity.md).
Units SI.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cloth_mg_ros.sim.contact_friction import (
    SLIP_FLOOR,
    add_damper_blocks,
    add_damper_forces,
    solved_slip,
)
from cloth_mg_ros.sim.friction import penalty_forces
from cloth_mg_ros.sim.integrator import (
    StepCoefficients,
    StepSystem,
    history_combination,
    solved_positions,
)
from cloth_mg_ros.sim.step_contacts import (
    add_penalty_blocks,
    add_penalty_forces,
    add_penalty_products,
)

# A damper may differ by this share from the one Coulomb's law gives at the solved slip
# before the step is solved again (the lag of its normal force and slip is of that order on
# a steady slide)
DAMPER_SLACK = 0.1
# and a penalty may pull by its stiffness times this share of the thickness (0.5 um at 5 mm:
# at the penalty of 100 m / h'^2 and 1/60 s, a pull of 4 % of a particle's weight)
PULL_SLACK = 1e-4
# Rounds of the check and solve: a contact let go moves its neighbours, and some of theirs
# then pull. On brisk_walking at 2400 particles (40 messages) one round left pulls of up to
# 0.385 N on the skirt (p90 over the steps 0.126 N), two 0.026 N, three 1 mN, for 8 % and 9 %
# more solver iterations; on walking one round left 0.53 N, two none (a throwaway script
# timing settle_contacts' rounds, the pull as sim.loads.ContactLoad.pull counts it).
SETTLE_ROUNDS = 4


def broken_laws(model, state, step, dv: np.ndarray, dt: float
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(keep (c,) bool, dampers (c,) N s/m) over ``step``'s contacts where its solution dv
    (n, 3) m/s from ``state`` breaks a contact's law (module docstring): the contacts kept
    and each friction damper as Coulomb's regularised law sizes it at the solved slip,
    mu f_n / max(norm(v_t), SLIP_FLOOR) (those within DAMPER_SLACK of it as they were);
    None where none is broken."""
    contacts = step.contacts
    if not len(contacts) or step.friction_damping is None:
        return None
    x_solved = solved_positions(state, step, dv, dt)[0]
    keep = penalty_forces(model, step, state.x, x_solved) >= \
        -PULL_SLACK * model.thickness * step.contact_stiffness
    old = step.friction_damping
    slip = np.linalg.norm(solved_slip(step, state.v, state.v + dv), axis=1)
    lawful = step.friction_bound / np.maximum(slip, SLIP_FLOOR)
    off = np.abs(lawful - old) > DAMPER_SLACK * old
    if keep.all() and not off.any():
        return None
    return keep, np.where(off, lawful, old)


def _contact_terms(model, state, step: StepSystem, coef: StepCoefficients, y: np.ndarray,
                   y_share: float, rows: np.ndarray, c_t: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """What the step's contacts ``rows`` (k,) put into A and b with the friction dampers
    c_t (k,) N s/m: (diagonal blocks (n, 3, 3) kg, b's part (n, 3) kg m/s), each the sum of
    the assembly's own terms (sim.integrator.assemble_step; b = h_eff (f + y_share K y))."""
    n = model.n
    contacts, k_c = step.contacts.subset(rows), step.contact_stiffness[rows]
    f, k_y, diag = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3))
    add_damper_forces(contacts, c_t, state.v, f)
    c_c = add_penalty_forces(model, state.v, contacts, k_c, coef.ga, coef.h_d, f)
    add_penalty_products(y, contacts, k_c, k_y)
    add_penalty_blocks(contacts, k_c, c_c, coef.h_k, coef.h_d, diag)
    add_damper_blocks(contacts, c_t, coef.h_d, diag)
    return diag, step.h_eff * (f + y_share * k_y)


def settled_step(model, state, step: StepSystem, keep: np.ndarray, damping: np.ndarray,
                 dt: float, scheme: str, spectral_radius: float) -> StepSystem:
    """``step`` with only the contacts ``keep`` (c,) bool, their friction dampers set to
    ``damping`` (c,) N s/m: A's diagonal blocks and b corrected by what the contacts that
    changed put into them (the system the assembly builds with those contacts and dampers,
    to rounding, for a fraction of its cost: the elastic terms stay)."""
    old = step.friction_damping
    changed = np.flatnonzero(~keep | (damping != old))
    again = changed[keep[changed]]
    coef = StepCoefficients.of(state, dt, scheme, spectral_radius)
    y, y_share = history_combination(state, dt, coef, None)
    diag_out, rhs_out = _contact_terms(model, state, step, coef, y, y_share, changed,
                                       old[changed])
    diag_in, rhs_in = _contact_terms(model, state, step, coef, y, y_share, again,
                                     damping[again])
    system = replace(step.system, diag=step.system.diag - diag_out + diag_in)
    damped = step.contact_damping
    return replace(step, system=system, rhs=step.rhs - rhs_out + rhs_in,
                   contacts=step.contacts.subset(keep),
                   contact_stiffness=step.contact_stiffness[keep],
                   contact_damping=None if damped is None else damped[keep],
                   friction_damping=damping[keep], friction_bound=step.friction_bound[keep])


def _meets_tolerance(solver, step: StepSystem, dv: np.ndarray) -> bool:
    """Whether dv (n, 3) meets the solver's tolerance on ``step``'s system, its residual on
    the free particles within tol of b's there or of the step's weight impulse, whichever is
    larger (as the solvers stop); False for a solver without one."""
    tol = getattr(solver, "tol", None)
    if tol is None:
        return False
    free = ~step.fixed
    b = step.rhs[free]
    r = b - step.system.matvec(dv)[free]
    scale = max(float(np.linalg.norm(b)), step.weight_impulse)
    return float(np.linalg.norm(r)) <= tol * (scale or 1.0)


def settle_contacts(model, state, step, result, solver, dt: float, scheme: str,
                    spectral_radius: float):
    """(step, solve result): ``step`` and its solve ``result`` as they are where no
    contact's law is broken (`broken_laws`), else the step with the laws kept
    (`settled_step`) and its solve from the last solution (that solution where it meets the
    solver's tolerance there already), round after round up to SETTLE_ROUNDS while a law is
    broken; the result's iterations are all the rounds'."""
    for _ in range(SETTLE_ROUNDS):
        broken = broken_laws(model, state, step, result.x, dt)
        if broken is None:
            break
        step = settled_step(model, state, step, *broken, dt, scheme, spectral_radius)
        if _meets_tolerance(solver, step, result.x):
            break  # the same solution: the same forces, no law newly broken
        again = solver.solve(step.system, step.rhs, result.x, step.fixed,
                             floor=step.weight_impulse)
        result = replace(again, iterations=result.iterations + again.iterations,
                         converged=result.converged and again.converged)
    return step, result
