"""Implicit Euler, BDF2 and generalised-alpha steps, linearised once per step (Baraff and
Witkin).

With h' the effective step (h for implicit Euler, 2h/3 for BDF2), M the lumped mass,
K = df/dx and D = df/dv, the first two schemes solve one system

    A dv = b,   A = M - h' D - h'^2 K,

    Euler: b = h' (f_n + h' K v_n)
    BDF2:  b = (M (v_n - v_{n-1}))/3 + h' (f_n + K ((x_n - x_{n-1})/3 + h' v_n))

then v_{n+1} = v_n + dv and x_{n+1} = x_n + h v_{n+1} (Euler) or
x_{n+1} = (4 x_n - x_{n-1})/3 + h' v_{n+1} (BDF2). The first BDF2 step is an Euler step.

Generalised-alpha (Chung and Hulbert, J. Appl. Mech. 60:371, 1993) balances the forces at
t_{n+1-alpha_f} against the inertia at t_{n+1-alpha_m}, M a_{n+1-alpha_m} =
f(x_{n+1-alpha_f}, v_{n+1-alpha_f}), with Newmark's updates
x_{n+1} = x_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1}),
v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1}); its four constants follow from one
number, the spectral radius rho_inf at infinite frequency (1: the trapezoidal rule, no
numerical damping; 0: the fastest modes gone in one step), and it is second order with
little damping of the slow modes at any rho_inf. Linearised once at (x_n, v_n) and scaled by
s = gamma h / (1 - alpha_m), a step is the same system with other coefficients:

    A = M - h_d D - h_k K,   h_d = s (1 - alpha_f),   h_k = h^2 beta (1 - alpha_f) / (1 - alpha_m),
    b = s f_n + h_d K (h v_n + c a_n) + c_m M a_n,

c = h^2 (1/2 - beta/gamma), c_m = h ((1 - gamma) - gamma alpha_m / (1 - alpha_m)) (`GenAlpha`).
Every pair block is still the elastic Hessian's times one scalar (h_k + h_d damping), so the
faithful hierarchy and the solvers take it unchanged. Its history is the acceleration a_n
(ClothState.a); the first step is an Euler step.

Damping: stiffness-proportional D = -beta H on the elastic part and air drag -alpha M.
Contacts: a penalty k = kappa m_i / h'^2 (h_k for generalised-alpha) along the normal on the
particle's diagonal block, active where the particle is, or is predicted to be, within the collision
thickness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.collision.colliders import (
    ContactImpulses,
    Contacts,
    posed,
    project_contacts,
)
from cloth_mg_ros.collision.edge_contact import edges_then_particles
from cloth_mg_ros.collision.friction import StepFriction
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.frozen_arrays import frozen
from cloth_mg_ros.physics.system import BlockSystem, RotationTerms
from cloth_mg_ros.sim.contact_friction import (
    add_damper_blocks,
    add_damper_forces,
    friction_dampers,
    pressing_forces,
    with_resting,
)
from cloth_mg_ros.sim.forces import (
    InternalForces,
    Workspace,
    hessian_product,
    internal_forces,
    scratch,
)
from cloth_mg_ros.sim.friction import (
    fold_friction,
    penalty_forces,
    restart_acceleration_along,
    restart_history_along,
    step_friction,
)
from cloth_mg_ros.sim.model import ClothControl, ClothModel, ClothState
from cloth_mg_ros.sim.pins import pin_targets, pin_velocity_changes
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES, GenAlpha
from cloth_mg_ros.sim.step_contacts import (
    add_penalty_blocks,
    add_penalty_forces,
    add_penalty_products,
    predicted_contacts,
    self_contact_pairs,
    self_contact_springs,
)
from cloth_mg_ros.sim.step_terms import (
    bdf2_combination,
    bdf2_rhs,
    bdf2_update,
    elastic_combination,
    euler_rhs,
    genalpha_combination,
    genalpha_rhs,
    genalpha_update,
    mass_blocks,
    step_forces,
)
from cloth_mg_ros.sim.strain_contact import limit_after_contacts, limit_strain_moving


@dataclass
class StepSystem:
    """One step's linear system and what built it. h_eff in s; rhs (n, 3) in kg m/s;
    x0 (n, 3) initial guess with pinned values; fixed (n,) bool; pins (k,) the particles
    held this step (ClothControl.pins), fixed's True ones in the control's order."""

    system: BlockSystem
    rhs: np.ndarray
    x0: np.ndarray
    fixed: np.ndarray
    h_eff: float  # b's factor of the forces: (A dv - b) / h_eff is a force
    scheme: str
    contacts: Contacts
    internal: InternalForces
    contact_stiffness: np.ndarray | None = None  # (c,) N/m, the penalty of each contact
    # (c,) N s/m, each contact's damper along its normal (generalised-alpha; None: none)
    contact_damping: np.ndarray | None = None
    contacts_clear: bool = False  # finish_step's projection left no free particle inside
    # generalised-alpha's constants (None: another scheme); `keep_acceleration`: the next
    # state carries a (a generalised-alpha run, its first Euler step included)
    genalpha: GenAlpha | None = None
    keep_acceleration: bool = False
    h_move: float = 0.0  # x_{n+1}'s factor of v_{n+1} a position correction goes by, s
    # the moving colliders' poses at the end of the step (ClothState.bodies: the next
    # state's), and the model's colliders at them (collision.colliders.posed)
    bodies: dict = field(default_factory=dict)
    colliders: list = field(default_factory=list)
    pins: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    # the fabric's damping acts on the strain rates only, not on a turn of the stressed
    # cloth (sim.newton.predicted_step; False: -damping H v, the stiffness-proportional form)
    rate_damping: bool = False
    friction_damping: np.ndarray | None = None  # (c,) N s/m: sim.contact_friction's dampers
    friction_bound: np.ndarray | None = None  # (c,) N: their Coulomb bounds, mu f_n
    # kg m/s: ||S w||, w_i = m_i |g| h_eff, the impulse the step would give the free cloth's
    # weight: the solves' residual floor (solvers.cg's docstring), so that a cloth at rest,
    # whose b is the vanishing imbalance of its weight and its elastic forces, is solved to
    # a fraction tolerance of its weight, not of that imbalance (0: no floor)
    weight_impulse: float = 0.0


@dataclass
class StepStats:
    """Figures of one step. Times in ms, energies in J (nan when the simulator does not track
    them), lengths in m.

    max_penetration: deepest particle inside a collider after the step (what a viewer sees);
    solve_penetration: deepest the solved positions went before the contact projection
    (how much the projection had to repair); self_contact_dropped: the cloth-cloth pairs
    the self-contact search left out past its cap this step (collision.self_contact:
    SelfContact.dropped; 0 without self contact).
    """

    solve_ms: float
    assemble_ms: float
    total_ms: float
    iterations: int
    rel_residual: float
    converged: bool
    kinetic_energy: float
    potential_energy: float
    contacts: int
    max_penetration: float
    solve_penetration: float
    self_contact_dropped: int = 0


_NO_LOAD = np.zeros((0, 3))  # step_forces' external force where a model has none


def check_step_size(dt: float) -> float:
    """dt (s) as a float; ClothInputError unless it is finite and > 0 (a zero step makes
    A = M - 0 K singular in its scaling and ran the solver to its cap into NaN)."""
    try:
        value = float(dt)
    except (TypeError, ValueError):
        raise ClothInputError(f"dt must be a number of seconds, got {dt!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise ClothInputError(f"dt must be finite and > 0 s, got {dt!r}")
    return value


def assemble_step(model: ClothModel, state: ClothState, dt: float, scheme: str,
                  control: ClothControl | None = None, work: Workspace | None = None,
                  spectral_radius: float = DEFAULT_SPECTRAL_RADIUS) -> StepSystem:
    """Build A and b for one step of size dt (s) from state, with the pins going where
    `control` says (None: they stay). work: a Workspace for the large arrays (the system
    is then valid until the workspace's next step; None: arrays of its own).
    spectral_radius: generalised-alpha's rho_inf (scheme 'genalpha' only). The colliders
    collide at their end-of-step poses: those in ``control.collider_poses`` moved there from
    the state's (ClothControl.moved_bodies), the others where the state has them. The forces
    are linearised where the cloth starts (sim.newton.predicted_step: at the prediction)."""
    frame = step_frame(model, state, dt, scheme, control, spectral_radius)
    c = frame.coef
    mat = model.material
    x, v, m = state.x, state.v, model.mass
    y, y_share = history_combination(state, dt, c, work)
    z = scratch(work, "z", x.shape)
    elastic_combination(v, y, mat.damping, y_share, z)
    # the system's pair blocks are the mesh's Hessian blocks times this, written so by
    # internal_forces, with the cloth-cloth springs' rows after them in the same array
    scale = c.h_k + c.h_d * mat.damping
    sc_pairs, contacts, k_c = frame.sc_pairs, frame.contacts, frame.k_c
    internal = internal_forces(model, x, work=work, product_of=z, hess_scale=scale,
                               spare_rows=len(sc_pairs))
    f = scratch(work, "f", x.shape)
    external = model.external_force
    step_forces(internal.forces, np.asarray(model.gravity, dtype=np.float64),
                _NO_LOAD if external is None else np.asarray(external, dtype=np.float64), m, v,
                mat.air_drag, f)
    damping = None if model.contact_friction != "solve" else friction_dampers(
        frame.colliders, contacts, v, state.contact_force, f, m, dt)
    c_t = None if damping is None else damping[0]
    add_damper_forces(contacts, c_t, v, f)
    c_c = add_penalty_forces(model, v, contacts, k_c, c.ga, c.h_d, f)  # generalised-alpha's dampers
    sc_hess = self_contact_springs(model, x, sc_pairs, c.h_k, f)
    rhs = _right_hand_side(model, state, c, y_share, f, internal.product,
                           _k_times_y(x, y, sc_pairs, sc_hess, contacts, k_c))
    diag = _diagonal_blocks(model, contacts, k_c, c_c, c)
    add_damper_blocks(contacts, c_t, c.h_d, diag)
    pairs = frame.pairs(model)
    # cloth-cloth springs: extra pair blocks after the mesh's, in the same array (a copy of
    # the mesh's 10 MB of blocks per step otherwise)
    offd = internal.pair_rows
    if len(sc_pairs):
        np.multiply(c.h_k, sc_hess, out=offd[len(model.pairs):])
    # where the Hessian was taken and the elastic forces there: the first guess's rotations
    # (solvers.first_guess) take A's products with them from these
    rotation = RotationTerms(x, internal.forces)
    return framed_step(model, state, frame, BlockSystem(diag, pairs, offd, scale, rotation),
                       rhs, internal, c_c, damping)


@dataclass(frozen=True)
class StepFrame:
    """What a step is built around besides the cloth's own forces: the scheme asked for, dt
    (s), its coefficients, the control, the moving colliders' end-of-step poses (bodies) and
    the model's colliders there, the contacts predicted with them and each one's penalty k_c
    (c,) N/m, the cloth-cloth pairs (k, 2) and the held particles (p,)."""

    scheme: str
    dt: float
    coef: StepCoefficients
    control: ClothControl
    bodies: dict
    colliders: list
    contacts: Contacts
    k_c: np.ndarray
    sc_pairs: np.ndarray
    pins: np.ndarray

    def pairs(self, model: ClothModel) -> np.ndarray:
        """The system's pairs (m + k, 2): the mesh's, then the cloth-cloth springs'."""
        if not len(self.sc_pairs):
            return model.pairs
        return frozen(np.concatenate([model.pairs, self.sc_pairs]))  # read-only as the mesh's


def step_frame(model: ClothModel, state: ClothState, dt: float, scheme: str,
               control: ClothControl | None = None,
               spectral_radius: float = DEFAULT_SPECTRAL_RADIUS) -> StepFrame:
    """The StepFrame of a step of dt s from ``state`` (`assemble_step`'s arguments)."""
    if scheme not in SCHEMES:
        raise ClothInputError(f"unknown integrator {scheme!r}; choose one of {', '.join(SCHEMES)}")
    check_step_size(dt)
    c = StepCoefficients.of(state, dt, scheme, spectral_radius)
    sc_pairs = self_contact_pairs(model, state.x + dt * state.v)
    control = ClothControl() if control is None else control
    bodies = control.moved_bodies(model, state.bodies, dt)
    colliders = posed(model.colliders, bodies)
    contacts = predicted_contacts(model, colliders, state.x, state.v, dt)
    if model.contact_friction == "solve":  # and the resting ones (sim.contact_friction)
        contacts = with_resting(model, colliders, state.x, state.v, dt, contacts,
                                state.contact_force)
    k_c = model.contact_stiffness * model.mass[contacts.index] / c.h_k
    return StepFrame(scheme, dt, c, control, bodies, colliders, contacts, k_c, sc_pairs,
                     control.pins(model))


def _position_factor(c: StepCoefficients, dt: float) -> float:
    """x_{n+1}'s factor of v_{n+1}, s: h' for BDF2, generalised-alpha's h beta / gamma
    (x_{n+1} = x_n + h v_n + c a_n + h_dv (v_{n+1} - v_n)), dt for implicit Euler."""
    if c.ga is not None:
        return c.ga.h_dv
    return c.h if c.bdf2 else dt


def framed_step(model: ClothModel, state: ClothState, frame: StepFrame,
                system: BlockSystem | None, rhs: np.ndarray | None,
                internal: InternalForces | None, contact_damping: np.ndarray | None = None,
                friction_damping: tuple | None = None) -> StepSystem:
    """The StepSystem of a system A (BlockSystem) and b (n, 3) built in ``frame`` from
    ``state``, with the elastic terms they were built from (None where filled in later);
    friction_damping: (dampers (c,) N s/m, their bounds (c,) N), sim.contact_friction's."""
    c = frame.coef
    fixed = frame.control.fixed_mask(model)
    h_eff = c.ga.s if c.ga is not None else c.h
    weight_impulse = h_eff * float(np.linalg.norm(model.gravity)) * float(
        np.linalg.norm(model.mass[~fixed]))
    return StepSystem(system, rhs,
                      pin_velocity_changes(frame.pins, state, frame.control, c.h, c.bdf2, c.ga),
                      fixed, h_eff, c.name, frame.contacts, internal,
                      frame.k_c, contact_damping=contact_damping, genalpha=c.ga,
                      keep_acceleration=frame.scheme == "genalpha",
                      h_move=_position_factor(c, frame.dt), bodies=frame.bodies,
                      colliders=frame.colliders, pins=frame.pins,
                      friction_damping=None if friction_damping is None else
                      friction_damping[0],
                      friction_bound=None if friction_damping is None else
                      friction_damping[1], weight_impulse=weight_impulse)


@dataclass(frozen=True)
class StepCoefficients:
    """A step's scheme and coefficients: bdf2 (a BDF2 step: the state has its history), ga
    (generalised-alpha's constants, None for the other schemes or its first step), h the
    effective step h' (s), h_d and h_k the factors of D and K in A = M - h_d D - h_k K."""

    bdf2: bool
    ga: GenAlpha | None
    h: float
    h_d: float
    h_k: float

    @classmethod
    def of(cls, state: ClothState, dt: float, scheme: str,
           spectral_radius: float) -> StepCoefficients:
        bdf2 = scheme == "bdf2" and state.x_prev is not None
        ga = GenAlpha.of(dt, spectral_radius) if scheme == "genalpha" and state.a is not None \
            else None
        h = 2.0 * dt / 3.0 if bdf2 else dt
        # h_d = h' and h_k = h'^2 but for generalised-alpha
        h_d, h_k = (ga.h_d, ga.h_k) if ga is not None else (h, h * h)
        return cls(bdf2, ga, h, h_d, h_k)

    @property
    def name(self) -> str:
        return "bdf2" if self.bdf2 else "genalpha" if self.ga is not None else "euler"


def history_combination(state: ClothState, dt: float, c: StepCoefficients,
                         work: Workspace | None) -> tuple[np.ndarray, float]:
    """(y (n, 3), y_share): K y enters b for y = v (Euler), the BDF2 combination or
    generalised-alpha's Newmark displacement, times y_share against the forces.

    The mesh's elastic Hessian H enters the right-hand side twice, as the damping force
    -damping H v and in K y (-H y, an Euler step's times h once more): one product of their
    combination, H (damping v + s y), stands for both (the same sum in another rounding; a
    second product cost 0.85 ms at 20K particles). internal_forces forms it with the
    forces."""
    x, v = state.x, state.v
    if c.bdf2:
        y = scratch(work, "y", x.shape)
        bdf2_combination(x, state.x_prev, v, c.h, y)
        return y, 1.0
    if c.ga is not None:
        y = scratch(work, "y", x.shape)
        genalpha_combination(v, state.a, dt, c.ga.c, y)
        return y, 1.0 - c.ga.alpha_f
    return v, c.h


def _k_times_y(x: np.ndarray, y: np.ndarray, sc_pairs: np.ndarray, sc_hess: np.ndarray,
               contacts: Contacts, k_c: np.ndarray) -> np.ndarray:
    """The rest of K y (n, 3), K = -H - sum k n n^T - (cloth-cloth springs): the contacts'
    and the springs' parts (the mesh's is in internal_forces' product)."""
    if len(sc_pairs):
        k_y = np.negative(hessian_product(sc_pairs, sc_hess, y))
    else:
        k_y = np.zeros_like(x)
    add_penalty_products(y, contacts, k_c, k_y)
    return k_y


def _right_hand_side(model: ClothModel, state: ClothState, c: StepCoefficients,
                     y_share: float, f: np.ndarray, h_z: np.ndarray, k_y: np.ndarray
                     ) -> np.ndarray:
    """b (n, 3) kg m/s of the step's scheme (module docstring); h_z the elastic Hessian's
    product (internal_forces), k_y the rest of K y (`_k_times_y`)."""
    rhs = np.empty_like(state.x)
    m = model.mass
    if c.bdf2:
        bdf2_rhs(m, state.v, state.v_prev, f, h_z, k_y, c.h, rhs)
    elif c.ga is not None:
        genalpha_rhs(m, state.a, f, h_z, k_y, c.ga.s, y_share, c.ga.c_m, rhs)
    else:
        euler_rhs(f, h_z, k_y, c.h, rhs)
    return rhs


def _diagonal_blocks(model: ClothModel, contacts: Contacts, k_c: np.ndarray,
                     c_c: np.ndarray | None, c: StepCoefficients) -> np.ndarray:
    """A's diagonal blocks (n, 3, 3) kg: the mass with air drag, plus each contact's penalty
    (and damper) along its normal."""
    diag = np.empty((model.n, 3, 3))
    mass_blocks(model.mass, 1.0 + c.h_d * model.material.air_drag, diag)
    add_penalty_blocks(contacts, k_c, c_c, c.h_k, c.h_d, diag)
    return diag


def solved_positions(state: ClothState, step: StepSystem, dv: np.ndarray, dt: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(x, v) (n, 3) that the step's solution dv (n, 3) gives by the scheme's update, before
    pins are placed exactly and before any correction (strain limit, contact projection)."""
    if step.genalpha is not None:
        x_new, v_new, _ = genalpha_positions(state, step, dv)
        return x_new, v_new
    if step.scheme == "bdf2":
        x_new, v_new = np.empty_like(state.x), np.empty_like(state.v)
        bdf2_update(state.x, state.x_prev, state.v, np.ascontiguousarray(dv, dtype=np.float64),
                    step.h_eff, x_new, v_new)
        return x_new, v_new
    v_new = state.v + dv
    return state.x + dt * v_new, v_new


def contact_damper_forces(step: StepSystem, v_start: np.ndarray, v_solved: np.ndarray
                          ) -> np.ndarray | None:
    """(c,) N: the force each contact's damper (StepSystem.contact_damping) exerted along its
    normal as the step balanced it, -c (v - v_body) . n at generalised-alpha's
    v_{n+1-alpha_f}, from the velocities (n, 3) m/s at the start and as solved; None where
    the step has no dampers."""
    c = step.contact_damping
    if c is None:
        return None
    idx, ga = step.contacts.index, step.genalpha
    v = v_start[idx] + (1.0 - ga.alpha_f) * (v_solved[idx] - v_start[idx])
    return -c * np.einsum("ij,ij->i", v - step.contacts.velocity, step.contacts.normal)


def genalpha_positions(state: ClothState, step: StepSystem, dv: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, v, a) (n, 3) of a generalised-alpha step's Newmark update with its solution dv."""
    ga = step.genalpha
    x_new, v_new, a_new = (np.empty_like(state.x) for _ in range(3))
    genalpha_update(state.x, state.v, state.a, np.ascontiguousarray(dv, dtype=np.float64),
                    ga.h, ga.c, ga.h_dv, ga.gamma, x_new, v_new, a_new)
    return x_new, v_new, a_new


def solved_rows(state: ClothState, step: StepSystem, dv: np.ndarray, dt: float,
                rows: np.ndarray) -> np.ndarray:
    """`solved_positions`' x on the particles `rows` (k,) only, (k, 3) m: the same numbers."""
    ga = step.genalpha
    if ga is not None:
        return (state.x[rows] + ga.h * state.v[rows] + ga.c * state.a[rows]
                + ga.h_dv * dv[rows])
    v_new = state.v[rows] + dv[rows]
    if step.scheme == "bdf2":
        return (4.0 * state.x[rows] - state.x_prev[rows]) / 3.0 + step.h_eff * v_new
    return state.x[rows] + dt * v_new


def finish_step(model: ClothModel, state: ClothState, step: StepSystem, dv: np.ndarray,
                dt: float, control: ClothControl | None = None,
                impulses: ContactImpulses | None = None) -> tuple[ClothState, int, float]:
    """Advance state with the solved dv (n, 3), the pins put where `control` says.

    impulses: if given, collects the contact projection's velocity changes of free particles
    (sim.loads.contact_load turns them into forces on the colliders). Returns (new state,
    contacts, deepest penetration of the solved positions before the projection, m)."""
    a_new = None
    if step.genalpha is not None:
        x_new, v_new, a_new = genalpha_positions(state, step, dv)
    else:
        x_new, v_new = solved_positions(state, step, dv, dt)
    pins = step.pins
    target = pin_targets(pins, state, control)
    pinned_v = v_new[pins].copy()
    x_new[pins] = target  # exactly, not up to rounding
    x_solved, v_solved = x_new.copy(), v_new.copy()
    count, deepest, friction, corrected = _corrections(model, state, step, dv, x_new, v_new,
                                                       x_solved, impulses)
    x_new[pins] = target  # pins win over contacts
    v_new[pins] = pinned_v
    # Friction is motion (an explicit force's, sim.friction): the solved state takes it in,
    # and only the projection's push restarts the history, along its normal.
    along = fold_friction(friction, step, step.fixed, x_solved, v_solved, a_new, corrected)
    pressed = None if model.contact_friction != "solve" else pressing_forces(
        model.n, model.mass, penalty_forces(model, step, state.x, x_solved),
        step.contacts.index, friction.pushes > 0, friction.normal, v_solved, v_new,
        step.h_eff)
    # The contact projection and the strain limit are corrections, not motion. A corrected
    # particle's BDF2 history restarts from where it ended and how it moves after the
    # correction (x_{n-1} := x_{n+1} - dt v_{n+1}, v_{n-1} := v_{n+1}; a contact's push
    # along its normal only, sim.friction.restart_history_along), so the next step's
    # (4 x_n - x_{n-1}) / 3 and (v_n - v_{n-1}) / 3 carry its corrected velocity only: no
    # third of a push as momentum, and none of the solved motion the correction undid.
    # (Shifting the old history by the correction kept the solved displacement as momentum:
    # a particle the projection stopped at a limb was driven into it again step after step,
    # 25 cm per 1/30 s step for half a second on the jump, and flung at 20-80 m/s.)
    if step.keep_acceleration:
        # Generalised-alpha's history is the acceleration. A corrected particle restarts as
        # BDF2's does, moving on at its corrected velocity (a = 0: the correction is not
        # motion to carry on), and so does a pinned one at the mean velocity that took it
        # to its target (the Newmark velocity of a moving pin rings from step to step).
        if a_new is None:  # the run's first step, an Euler step: its mean acceleration
            a_new = (v_solved - state.v) / dt
        moved = np.any((x_new != x_solved) | (v_new != v_solved), axis=1)
        restart_acceleration_along(a_new, moved, along)
        v_new[pins] = (target - state.x[pins]) / dt
        a_new[pins] = 0.0
        new = ClothState(x_new, v_new, None, None, state.t + dt, a_new, step.bodies, pressed)
        return new, count, deepest
    x_hist, v_hist = np.empty_like(x_new), np.empty_like(v_new)
    restart_history_along(state.x, state.v, x_new, v_new, x_solved, v_solved, dt, along,
                          x_hist, v_hist)
    new = ClothState(x_new, v_new, x_hist, v_hist, state.t + dt, bodies=step.bodies,
                     contact_force=pressed)
    return new, count, deepest


def _corrections(model: ClothModel, state: ClothState, step: StepSystem, dv: np.ndarray,
                 x_new: np.ndarray, v_new: np.ndarray, x_solved: np.ndarray,
                 impulses: ContactImpulses | None
                 ) -> tuple[int, float, StepFriction, np.ndarray | None]:
    """The step's corrections of the solved x_new, v_new (n, 3), in place: the strain limit,
    the contact projection with friction, the edge contact. Returns (contacts, deepest
    penetration before the projection m, the step's friction, (n,) bool the particles a
    correction other than the contact projection moved or None)."""
    corrected = None
    free = (~step.fixed).astype(np.float64) if model.strain_limit is not None else None
    if model.strain_limit is not None:
        # Strain limiting is an inelastic correction: the velocity follows the positions it
        # moved (the scheme's x = ... + h' v), or an edge pulled back would keep its
        # stretching speed, be stretched and pulled back again next step, and its
        # particles' speed would grow unseen (to 45 m/s at a cape's hem on the jump).
        corrected = limit_strain_moving(x_new, v_new, model, free, step.h_move)
    # Coulomb friction bounded by each contact's whole normal impulse, the penalty's in the
    # solve and the projection's (sim.friction, collision.friction)
    friction = step_friction(model, step, state.x, x_solved,
                             contact_damper_forces(step, state.v, state.v + dv))
    if model.contact_friction == "solve":
        friction.mu_scale = 0.0  # it acted in the solve (sim.contact_friction)
    count, deepest, step.contacts_clear = project_contacts(
        step.colliders, x_new, v_new, model.thickness, state.x, impulses=impulses,
        exclude=step.fixed, friction=friction)
    if model.edge_contact:
        # the particles the edge contact moves are projected again (collision.edge_contact)
        edged, clear = edges_then_particles(step.colliders, x_new, v_new, model.mesh.edges,
                                            model.thickness, step.fixed, impulses, friction)
        step.contacts_clear = step.contacts_clear and clear
        corrected = edged if corrected is None else corrected | edged
    if model.strain_limit is not None:
        # the projection stretches what it pushes out radially (sim.strain_contact)
        limited, clear = limit_after_contacts(model, step.colliders, x_new, v_new, step.fixed,
                                              free, step.h_move, friction, impulses)
        step.contacts_clear = step.contacts_clear and clear
        corrected = corrected | limited
    return count, deepest, friction, corrected


def energies(model: ClothModel, state: ClothState) -> tuple[float, float]:
    """(kinetic, potential) energy in J of ``state``; potential = gravity (and any external
    force's) + stretch/shear + bending. The elastic part is the step's own: the energies of
    `internal_forces`, the pass that makes the step's forces (a copy of the energy code here
    could drift from the forces it should be the potential of)."""
    x, v, m = state.x, state.v, model.mass
    kinetic = 0.5 * float(np.sum(m[:, None] * v * v))
    gravity = -float(np.sum(x * model.applied_forces()))
    elastic = internal_forces(model, x)
    return kinetic, gravity + elastic.stretch_energy + elastic.bend_energy

