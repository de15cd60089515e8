"""Stepping a cloth: the Solver of Newton's Model / State / Control / Solver split, and a small
driver that keeps a run's State.

`ImplicitStepper` is the Solver: ``step(model, state, control, dt)`` reads a frozen
`ClothModel`, a `ClothState` and a `ClothControl` and returns a `StepResult` (the next state
and what the step measured). It holds the linear solver, the scheme and what to measure, and
scratch arrays reused from step to step (a Workspace: no simulation state), so two runs may
share one stepper and a step is a function of its arguments.

`Simulator` drives one run: it holds the model, the state, the control the caller sets before
each step and the step size, and replaces its state with each step's.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from cloth_mg_ros.collision.colliders import ContactImpulses, penetration
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.contact_friction import check_contact_friction, friction_forces
from cloth_mg_ros.sim.contact_set import settle_contacts
from cloth_mg_ros.sim.forces import Workspace
from cloth_mg_ros.sim.integrator import (
    StepStats,
    assemble_step,
    contact_damper_forces,
    energies,
    finish_step,
    solved_rows,
)
from cloth_mg_ros.sim.loads import ContactLoad, contact_load
from cloth_mg_ros.sim.model import ClothControl, ClothModel, ClothState
from cloth_mg_ros.sim.newton import (
    check_damping_model,
    check_linearise_at,
    newton_iterate,
    predicted_step,
)
from cloth_mg_ros.sim.pins import constraint_forces
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES, GenAlpha


def self_contact_dropped(model: ClothModel) -> int:
    """The pairs ``model``'s last self-contact search (sim.integrator.self_contact_pairs)
    left out past its cap (0 without self contact): a step reports its own search's."""
    return 0 if model.self_contact is None else int(model.self_contact.dropped)


def check_newton_iterations(value, scheme: str) -> None:
    """ClothInputError unless ``value`` is an integer >= 1 (above 1 only for implicit Euler
    and BDF2: sim.newton)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ClothInputError(f"newton_iterations must be an integer >= 1, got {value!r}")
    if value > 1 and scheme not in ("euler", "bdf2"):
        raise ClothInputError(f"newton_iterations {value} needs the scheme euler or bdf2, "
                              f"got {scheme!r}")


def check_step_options(scheme: str, newton_iterations=1, linearise_at="start",
                       damping_model="stiffness") -> None:
    """ClothInputError naming the first of a step's Newton options that ``scheme`` cannot
    take or that is no value of its own (`check_newton_iterations`, sim.newton's
    check_linearise_at and check_damping_model)."""
    check_newton_iterations(newton_iterations, scheme)
    check_linearise_at(linearise_at, scheme)
    check_damping_model(damping_model, linearise_at)


class StepResult(NamedTuple):
    """What one step gives: the next state; its figures; the force (k, 3) N holding each
    pinned particle (empty unless the stepper tracks them); each contact's force on the
    colliders (empty unless tracked)."""

    state: ClothState
    stats: StepStats
    constraint_forces: np.ndarray
    contact_load: ContactLoad


class ImplicitStepper:
    """One implicit step of a cloth (sim.integrator: implicit Euler, BDF2, generalised-alpha).

    solver: an object with ``solve(system, b, x0, fixed, floor=...) -> SolveResult`` (floor:
    the step's weight impulse, the residual's scale at rest: solvers.cg); scheme: 'euler',
    'bdf2' or 'genalpha' (spectral_radius: its rho_inf, 0..1); track_energy: each step's
    kinetic and potential energy in its StepStats (a garment on a body reports its own and
    turns this off rather than pay for them every step; doc/design-measurements.md,
    'Energy bookkeeping'); track_constraint_forces: the force that holds each pinned
    particle (`sim.pins.constraint_forces`); track_contact_forces: the force of each
    contact on the colliders (sim.loads.ContactLoad). newton_iterations: how many Newton
    iterations a step takes (1: the step's one linearisation; more: re-solved where the
    last iterate ends, sim.newton; implicit Euler and BDF2 only). linearise_at: where the
    first iteration linearises the forces, 'start' (where the cloth starts: the paper's step)
    or 'prediction' (where it goes at its velocities: sim.newton.predicted_step; implicit
    Euler and BDF2 only). damping_model: the fabric's damping force, 'stiffness' (-c H v) or
    'strain_rate' (on the strain rates alone, sim.newton.DAMPING_MODELS; with 'prediction').
    """

    def __init__(self, solver, scheme: str = "bdf2",
                 spectral_radius: float = DEFAULT_SPECTRAL_RADIUS, track_energy: bool = True,
                 track_constraint_forces: bool = False, track_contact_forces: bool = False,
                 newton_iterations: int = 1, linearise_at: str = "start",
                 damping_model: str = "stiffness"):
        if scheme not in SCHEMES:
            raise ClothInputError(f"unknown integrator {scheme!r}; choose one of "
                                  f"{', '.join(SCHEMES)}")
        GenAlpha.of(1.0, spectral_radius)  # checks it
        check_step_options(scheme, newton_iterations, linearise_at, damping_model)
        self.newton_iterations = int(newton_iterations)
        self.linearise_at, self.damping_model = linearise_at, damping_model
        self.solver, self.scheme = solver, scheme
        self.spectral_radius = float(spectral_radius)
        self.track_energy = track_energy
        self.track_constraint_forces = track_constraint_forces
        self.track_contact_forces = track_contact_forces
        self._work = Workspace()  # the steps' large arrays, reused step after step

    def step(self, model: ClothModel, state: ClothState, control: ClothControl | None,
             dt: float) -> StepResult:
        """Advance ``state`` by dt s, the pins and the colliders going where ``control``
        says (None: they stay)."""
        t0 = time.perf_counter()
        check_step_options(self.scheme, self.newton_iterations, self.linearise_at,
                           self.damping_model)  # any of them set since?
        check_contact_friction(model.contact_friction, self.linearise_at)
        if self.linearise_at == "start":
            step = assemble_step(model, state, dt, self.scheme, control, self._work,
                                 self.spectral_radius)
        else:
            step = predicted_step(model, state, dt, self.scheme, control, self._work,
                                  self.spectral_radius, self.damping_model == "strain_rate")
        t1 = time.perf_counter()
        result = self.solver.solve(step.system, step.rhs, step.x0, step.fixed,
                                   floor=step.weight_impulse)
        if step.friction_damping is not None:  # contact_friction "solve" (sim.contact_set)
            step, result = settle_contacts(model, state, step, result, self.solver, dt,
                                           self.scheme, self.spectral_radius)
        if self.newton_iterations > 1:
            result = newton_iterate(model, state, step, result, self.solver,
                                    self.newton_iterations)
        t2 = time.perf_counter()
        held = np.zeros((len(step.pins), 3))
        if self.track_constraint_forces:
            held = constraint_forces(step, result.x, step.pins, model.incidence)
        impulses = ContactImpulses.new() if self.track_contact_forces else None
        new, count, deepest = finish_step(model, state, step, result.x, dt, control, impulses)
        load = ContactLoad.empty()
        if impulses is not None:
            rows = step.contacts.index
            moved = solved_rows(state, step, result.x, dt, rows) - state.x[rows]
            if step.genalpha is not None:  # its forces act at x_{n+1-alpha_f}
                moved *= 1.0 - step.genalpha.alpha_f
            load = contact_load(model.mass, step.contacts, step.contact_stiffness,
                                model.thickness, moved, impulses, new.x, step.h_eff,
                                contact_damper_forces(step, state.v, state.v + result.x),
                                friction_forces(step, state.v, state.v + result.x))
        kinetic = potential = float("nan")
        if self.track_energy:
            kinetic, potential = energies(model, new)
        after = 0.0  # the projection's last pass found every free particle clear
        if not step.contacts_clear or model.edge_contact:
            after = penetration(step.colliders, new.x, step.fixed)
        t3 = time.perf_counter()
        stats = StepStats(1e3 * (t2 - t1), 1e3 * (t1 - t0), 1e3 * (t3 - t0), result.iterations,
                          result.rel_residual, result.converged, kinetic, potential, count,
                          after, deepest, self_contact_dropped(model))
        return StepResult(new, stats, held, load)


class Simulator:
    """One run of a cloth model: ``step()`` takes a step of ``dt`` s from ``state`` with the
    `control` the caller set (pin targets, collider poses) and replaces ``state`` with the
    next one. ``stepper`` (an ImplicitStepper made from solver, scheme, spectral_radius and
    the track_* flags, which are also readable and settable here; or any object with its
    ``step``, such as explicit.ExplicitStepper) takes the step; after it,
    ``constraint_forces`` and ``contact_load`` hold what it measured (when tracked).
    """

    def __init__(self, model: ClothModel, state: ClothState, solver, dt: float = 1.0 / 60.0,
                 scheme: str = "bdf2", track_energy: bool = True,
                 track_constraint_forces: bool = False, track_contact_forces: bool = False,
                 spectral_radius: float = DEFAULT_SPECTRAL_RADIUS, stepper=None,
                 newton_iterations: int = 1, linearise_at: str = "start",
                 damping_model: str = "stiffness"):
        if not (dt > 0.0) or not np.isfinite(dt):
            raise ClothInputError(f"time step must be positive and finite, got {dt}")
        if stepper is None:
            check_contact_friction(model.contact_friction, linearise_at)
            stepper = ImplicitStepper(solver, scheme, spectral_radius, track_energy,
                                      track_constraint_forces, track_contact_forces,
                                      newton_iterations, linearise_at, damping_model)
        self.stepper = stepper
        self.model, self.state = model, state
        self.control = ClothControl()
        self.dt = float(dt)
        self.constraint_forces = np.zeros((len(model.pinned), 3))
        self.contact_load = ContactLoad.empty()

    def step(self) -> StepStats:
        out = self.stepper.step(self.model, self.state, self.control, self.dt)
        self.state = out.state
        if self.stepper.track_constraint_forces:
            self.constraint_forces = out.constraint_forces
        if self.stepper.track_contact_forces:
            self.contact_load = out.contact_load
        return out.stats

    # The stepper's settings, read and set through the run (a scene switches its solver,
    # a garment turns the force tracking on).
    solver = property(lambda self: self.stepper.solver,
                      lambda self, value: setattr(self.stepper, "solver", value))
    scheme = property(lambda self: self.stepper.scheme,
                      lambda self, value: setattr(self.stepper, "scheme", value))
    spectral_radius = property(lambda self: self.stepper.spectral_radius,
                               lambda self, value: setattr(self.stepper, "spectral_radius",
                                                           value))
    newton_iterations = property(
        lambda self: self.stepper.newton_iterations,
        lambda self, value: setattr(self.stepper, "newton_iterations", value))
    linearise_at = property(lambda self: self.stepper.linearise_at,
                            lambda self, value: setattr(self.stepper, "linearise_at", value))
    damping_model = property(lambda self: self.stepper.damping_model,
                             lambda self, value: setattr(self.stepper, "damping_model", value))
    track_energy = property(lambda self: self.stepper.track_energy,
                            lambda self, value: setattr(self.stepper, "track_energy", value))
    track_constraint_forces = property(
        lambda self: self.stepper.track_constraint_forces,
        lambda self, value: setattr(self.stepper, "track_constraint_forces", value))
    track_contact_forces = property(
        lambda self: self.stepper.track_contact_forces,
        lambda self, value: setattr(self.stepper, "track_contact_forces", value))
