"""Strain limiting that the contact projection cannot undo (sim.integrator.finish_step).

The step's corrections run in turn: the strain limit shortens over-stretched edges
(physics.strain_limit), then the contact projection moves each particle out of the colliders
along its own normal (collision.colliders.project_contacts). A limb that enters the cloth
deeply in one step (a walking thigh moves up to 25 cm per 30 Hz step under the walking
scene's step rule) has its particles pushed out radially, each on its own, and the patch it
entered is stretched over it: with the limit before the projection only, a walking dress kept
edges at 2-11 times their rest length, its stretch energy reached 15 kJ, and the stored
energy threw the skirt up to the waist within 10 s of walking (and made it climb a body held
still). So the limit runs again after the projection, and the particles it moved are projected
again, until no edge is more than a tenth past the bound (at most 30 rounds): the last word
is the contacts'. Units SI.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.collision.colliders import ContactImpulses, project_contacts
from cloth_mg_ros.collision.friction import StepFriction
from cloth_mg_ros.physics.strain_limit import limit_strain, max_stretch_ratio

# Gauss-Seidel sweeps of one limit; 4 left a walking cape at 1.21x rest with 1-2 steps per pose
STRAIN_LIMIT_PASSES = 8
# Limit-then-project rounds after the first projection, while an edge is more than
# STRAIN_SLACK past the bound; each round projects only the particles the limit moved. The
# pathology is edges at several times their rest length; a tenth past the bound (1.21x rest
# for 1.1) stores little energy and takes few rounds. A bar pushed 10 cm through a sheet with
# 5 cm edges in one step leaves the longest edge at 2.32x rest with no round.
CONTACT_ROUNDS = 30
STRAIN_SLACK = 0.1


def limit_strain_moving(x: np.ndarray, v: np.ndarray, model, free: np.ndarray,
                        h_move: float) -> np.ndarray:
    """Shorten x's (n, 3) edges past the model's strain limit in place, the velocity v (n, 3)
    following the positions moved (an inelastic correction: x = ... + h_move v, so an edge
    pulled back does not keep its stretching speed); free (n,) 1.0 movable, 0.0 held.
    Returns the (n,) bool mask of the particles moved."""
    moved = np.zeros(len(x), dtype=np.bool_)
    limit_strain(x, v, model.mesh.edges, model.edge_rest, model.strain_limit, free,
                 STRAIN_LIMIT_PASSES, h_move, moved)
    return moved


def limit_after_contacts(model, colliders: list, x: np.ndarray, v: np.ndarray,
                         fixed: np.ndarray, free: np.ndarray, h_move: float,
                         friction: StepFriction | None, impulses: ContactImpulses | None
                         ) -> tuple[np.ndarray, bool]:
    """After the contact projection: while an edge of x (n, 3) is more than STRAIN_SLACK past
    the model's strain limit, limit the strain again and project the particles that moved,
    in place in x and v (n, 3), for at most CONTACT_ROUNDS rounds; colliders: the model's at
    their end-of-step poses (collision.colliders.posed); fixed (n,) bool: pinned
    particles (not moved, not recorded in ``impulses``), free (n,) its complement as 1.0 and
    0.0; friction: the step's (each new push's Coulomb bound). Returns ((n,) bool, the
    particles the limit moved; whether the last projection left nothing inside)."""
    moved_any = np.zeros(len(x), dtype=bool)
    clear = True
    bound = model.strain_limit * (1.0 + STRAIN_SLACK)
    for _ in range(CONTACT_ROUNDS):
        if max_stretch_ratio(x, model.mesh.edges, model.edge_rest) <= bound:
            break
        moved = limit_strain_moving(x, v, model, free, h_move)
        moved_any |= moved
        again = project_contacts(colliders, x, v, model.thickness, None,
                                 impulses=impulses, exclude=fixed, friction=friction,
                                 only=np.flatnonzero(moved))
        clear = again.clear
    return moved_any, clear
