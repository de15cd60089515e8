"""The contacts' laws checked after the step's solve (ClothModel.contact_friction "solve").

A penalty contact is a linear spring for the whole step and a friction damper a linear
force, so one solve can break the laws they stand for: a particle that the cloth lifts off
a limb is pulled back by its penalty (a contact never pulls), and a stuck particle that a
limb drags feels more than mu f_n from its damper (Coulomb's bound). On the walking dress at
9964 particles such steps put 56 N on the pelvis where the projection's friction puts under
1 N (`cloth-mg run --scene walking --particles 10000 --steps 100 --contact-friction solve`
at 7e0c649; 1.2 N with this check). So after the solve: contacts whose penalty pulls at
the solved positions are dropped, dampers whose force passes their bound by more than
BOUND_SLACK are set to give the bound at the solved slip, and the step is assembled and
solved once more from the first solution (an active set's one round; what is still off then
stays for the step). Steps where no law is broken are left as they were. Units SI.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cloth_mg_ros.sim.contact_friction import friction_forces
from cloth_mg_ros.sim.friction import penalty_forces
from cloth_mg_ros.sim.integrator import assemble_step, solved_positions

# A damper's force may pass its Coulomb bound by this share before the step is solved again
# (the lag of its normal force and slip is of that order on a steady slide)
BOUND_SLACK = 0.1
# and a penalty may pull by its stiffness times this share of the thickness (0.5 um at 5 mm:
# at the penalty of 100 m / h'^2 and 1/60 s, a pull of 4 % of a particle's weight)
PULL_SLACK = 1e-4


def broken_laws(model, state, step, dv: np.ndarray, dt: float
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(keep (c,) bool, dampers (c,) N s/m) over ``step``'s contacts where its solution dv
    (n, 3) m/s from ``state`` breaks a contact's law (module docstring): the contacts kept
    and the friction dampers that give each its bound at the solved slip; None where none
    is broken."""
    contacts = step.contacts
    if not len(contacts) or step.friction_damping is None:
        return None
    x_solved = solved_positions(state, step, dv, dt)[0]
    keep = penalty_forces(model, step, state.x, x_solved) >= \
        -PULL_SLACK * model.thickness * step.contact_stiffness
    force = np.linalg.norm(friction_forces(step, state.v, state.v + dv), axis=1)
    bound = step.friction_bound
    over = force > (1.0 + BOUND_SLACK) * bound
    if keep.all() and not over.any():
        return None
    damping = step.friction_damping.copy()
    damping[over] *= bound[over] / force[over]  # the force is linear in it at that slip
    return keep, damping


def settle_contacts(model, state, step, result, solver, dt: float, scheme: str, control,
                    work, spectral_radius: float):
    """(step, solve result): ``step`` and its solve ``result`` as they are where no
    contact's law is broken (`broken_laws`), else the step assembled again with the laws
    kept and solved from result's solution (`assemble_step`'s other arguments)."""
    broken = broken_laws(model, state, step, result.x, dt)
    if broken is None:
        return step, result
    keep, damping = broken
    again = assemble_step(model, state, dt, scheme, control, work, spectral_radius,
                          settled=(keep, damping, step.friction_bound))
    second = solver.solve(again.system, again.rhs, result.x, again.fixed)
    return again, replace(second, iterations=result.iterations + second.iterations,
                          converged=result.converged and second.converged)
