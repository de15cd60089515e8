"""An explicit integrator for contrast: symplectic (semi-implicit) Euler with the implicit
path's forces, pins and contact handling.

One step of size h (s), with M the lumped mass (n,) kg and f (n, 3) N the total force at the
start of the step,

    v_{n+1} = v_n + h M^-1 f(x_n, v_n),    x_{n+1} = x_n + h v_{n+1}.

Forces are those of the implicit path (`integrator.assemble_step`), evaluated at x_n, v_n
instead of being linearised: stretch/shear and bending (`forces.internal_forces`), gravity,
air drag -alpha M v and stiffness-proportional damping -beta H v (H the elastic Hessian, the
same compression-clamped pair blocks the implicit system uses).

Pins reach their targets at the end of the step (v = (target - x_n) / h), and the step ends
with the implicit path's own `integrator.finish_step`: strain limit, contact projection with
Coulomb friction against the colliders (tunnelling test against x_n), pins last. Body
contacts are handled by that projection alone: the implicit path's penalty spring
(kappa m / h^2 along the normal) has omega h = sqrt(kappa) > 2 and would itself make an explicit
step unstable. For the same reason cloth-cloth repulsion springs, where the model has them,
use a stiffness of at most ``EXPLICIT_CONTACT_STIFFNESS`` m / h^2 (omega h <= 1 for one spring).
The cloth's own stiffness and damping are left as they are: they are what limits an explicit
step (`critical_step` estimates the bound: a few microseconds for every bundled fabric at a few
hundred particles, set by the stiffness-proportional damping of the stiffest mode, against
1/240 s here). Beyond it the stiff modes grow by a large factor every step.
"""

from __future__ import annotations

import time

import numpy as np

from cloth_mg_ros.collision.colliders import ContactImpulses, Contacts, penetration, posed
from cloth_mg_ros.collision.self_contact import spring_forces_hessians
from cloth_mg_ros.sim.forces import hessian_product, internal_forces
from cloth_mg_ros.sim.integrator import (
    StepStats,
    StepSystem,
    energies,
    finish_step,
)
from cloth_mg_ros.sim.loads import ContactLoad, contact_load
from cloth_mg_ros.sim.model import ClothControl, ClothModel, ClothState
from cloth_mg_ros.sim.pins import pin_targets
from cloth_mg_ros.sim.simulator import Simulator, StepResult, self_contact_dropped

SCHEME = "symplectic_euler"
EXPLICIT_CONTACT_STIFFNESS = 1.0  # cloth-cloth springs, times mean particle mass / h^2


def explicit_forces(model: ClothModel, x: np.ndarray, v: np.ndarray, dt: float,
                    ) -> tuple[np.ndarray, object]:
    """Total force (n, 3) N on every particle at positions x (n, 3) m and velocities v (n, 3)
    m/s, for a step of dt s (the cloth-cloth springs are found at the predicted x + dt v and
    scaled by dt). Returns (forces, the `InternalForces` they came from)."""
    mat, m = model.material, model.mass
    internal = internal_forces(model, x)
    f = internal.forces + model.applied_forces() - mat.air_drag * m[:, None] * v
    f -= mat.damping * hessian_product(model.pairs, internal.pair_hess, v)
    sc = model.self_contact
    if sc is not None:
        pairs = sc.pairs(x + dt * v)
        if len(pairs):
            stiffness = min(sc.stiffness, EXPLICIT_CONTACT_STIFFNESS)
            k_spring = stiffness * float(m.mean()) / (dt * dt)
            hess = np.empty((len(pairs), 3, 3))
            spring_forces_hessians(x, pairs, sc.distance, k_spring, f, hess)
    return f, internal


def critical_step(model: ClothModel, x: np.ndarray | None = None, iterations: int = 60) -> float:
    """Largest stable symplectic Euler step (s) of the cloth's stiffest mode at positions
    x (n, 3) m (default: the rest shape), damping included.

    For a mode of angular frequency omega damped at the rate c = alpha + beta omega^2 (air
    drag alpha 1/s, stiffness-proportional damping beta s), symplectic Euler's update matrix
    [[1 - h^2 omega^2, h (1 - h c)], [-h omega^2, 1 - h c]] has determinant 1 - h c and trace
    2 - h c - h^2 omega^2; its eigenvalues stay in the unit disc while
    h^2 omega^2 + 2 h c <= 4, i.e. h <= (sqrt(c^2 + 4 omega^2) - c) / omega^2 (2 / omega
    undamped). The bound falls with omega, so the stiffest mode sets it: omega_max^2 is the
    largest eigenvalue of M^-1 H, estimated by power iteration on M^-1/2 H M^-1/2 (from
    below, so the step returned errs on the large side by well under a per cent after 60
    iterations). Stiffness-proportional damping makes the stiff modes' bound much smaller
    than 2 / omega_max (cotton at 300 particles: 4e-6 s against 1.2e-4 s).
    """
    # a writable copy: the rest shape is read-only, and the kernels are compiled (and
    # cached by the warm-up) for the writable positions of the steps
    x = np.array(model.mesh.rest if x is None else x, dtype=np.float64)
    hess = internal_forces(model, x).pair_hess
    s = 1.0 / np.sqrt(model.mass)[:, None]
    rng = np.random.default_rng(0)
    y = rng.standard_normal((model.n, 3))
    lam = 0.0
    for _ in range(iterations):
        y /= np.linalg.norm(y)
        # hessian_product(y) = H y: the pair blocks with the zero-row-sum diagonal implied.
        z = s * hessian_product(model.pairs, hess, s * y)
        lam = float(np.sum(z * y))
        y = z
    if not lam > 0.0:
        return float("inf")
    c = model.material.air_drag + model.material.damping * lam
    return float((np.sqrt(c * c + 4.0 * lam) - c) / lam)


class ExplicitStepper:
    """Newton's Solver for symplectic Euler (see the module docstring): ``step(model, state,
    control, dt)`` returns a simulator.StepResult (no solve: 0 iterations, converged, solve_ms
    0; assemble_ms the force evaluation). With ``track_constraint_forces`` it gives the force
    on each pinned particle (its mass times its velocity change over dt, less the forces on
    it); with ``track_contact_forces`` the projection's forces on the colliders (the only
    contact forces of this step: it has no penalty). Holds no simulation state."""

    scheme = SCHEME
    solver = None  # no linear system
    spectral_radius = 0.0  # unused: no numerical damping to set
    track_energy = True

    def __init__(self):
        self.track_constraint_forces = self.track_contact_forces = False

    def step(self, model: ClothModel, state: ClothState, control: ClothControl | None,
             dt: float) -> StepResult:
        t0 = time.perf_counter()
        control = ClothControl() if control is None else control
        bodies = control.moved_bodies(model, state.bodies, dt)
        colliders = posed(model.colliders, bodies)
        f, internal = explicit_forces(model, state.x, state.v, dt)
        dv = dt * f / model.mass[:, None]
        pins = control.pins(model)
        if len(pins):
            dv[pins] = (pin_targets(pins, state, control) - state.x[pins]) / dt - \
                state.v[pins]
        held = np.zeros((len(pins), 3))
        if self.track_constraint_forces:
            held = model.mass[pins, None] * dv[pins] / dt - f[pins]
        t1 = time.perf_counter()
        # finish_step's Euler position update x + h (v + dv) is the symplectic one; it then
        # applies the strain limit, the contact projection and the pins as the implicit path.
        fixed = control.fixed_mask(model)
        step = StepSystem(None, None, None, fixed, dt, "euler", Contacts.empty(),
                          internal, h_move=dt, bodies=bodies, colliders=colliders, pins=pins)
        impulses = ContactImpulses.new() if self.track_contact_forces else None
        new, count, deepest = finish_step(model, state, step, dv, dt, control, impulses)
        load = ContactLoad.empty()
        if impulses is not None:
            load = contact_load(model.mass, Contacts.empty(), np.zeros(0), model.thickness,
                                np.zeros((0, 3)), impulses, new.x, dt)
        # The implicit path's BDF2 history is of no use here; drop it so the state stays small.
        new = ClothState(new.x, new.v, None, None, new.t, bodies=new.bodies)
        kinetic = potential = float("nan")
        if self.track_energy:  # a pass over every face and pair: skipped when not asked for
            kinetic, potential = energies(model, new)
        after = penetration(colliders, new.x, fixed)
        t2 = time.perf_counter()
        stats = StepStats(0.0, 1e3 * (t1 - t0), 1e3 * (t2 - t0), 0, 0.0, True, kinetic,
                          potential, count, after, deepest, self_contact_dropped(model))
        return StepResult(new, stats, held, load)


class ExplicitSimulator(Simulator):
    """A run stepped with symplectic Euler (`ExplicitStepper`): the interface of
    simulator.Simulator, with ``scheme`` 'symplectic_euler' and ``solver`` None."""

    def __init__(self, model: ClothModel, state: ClothState, dt: float = 1.0 / 60.0):
        super().__init__(model, state, None, dt, stepper=ExplicitStepper())
