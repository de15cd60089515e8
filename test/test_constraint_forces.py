"""The force that holds a pinned particle, from the implicit step's own equations
(`sim.pins.constraint_forces`): a sheet held at two corners carries its weight there, and
the cloth's momentum changes by exactly what gravity and the holders give it."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.model import GRAVITY
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver


def _hang(scheme: str, solver: str = "direct", particles: int = 300) -> Simulator:
    scene = build_scene("hang", particles, get_material("cotton"))
    return Simulator(scene.model, scene.state,
                     make_solver(solver, tol=1e-10, hierarchy=scene.hierarchy,
                                 bending=scene.model.bending),
                     dt=1.0 / 60.0, scheme=scheme, track_constraint_forces=True)


def test_forces_are_only_computed_when_asked_for():
    scene = build_scene("hang", 200, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, make_solver("pcg"), dt=1.0 / 60.0)
    sim.step()
    assert sim.constraint_forces.shape == (2, 3) and not sim.constraint_forces.any()


@pytest.mark.parametrize("solver", ["direct", "mpcg"])
def test_two_held_corners_carry_the_weight_of_a_sheet_at_rest(solver):
    sim = _hang("bdf2", solver)
    for _ in range(480):  # 8 s: the sheet's swing has died down
        sim.step()
    weight = float(sim.model.mass.sum()) * -GRAVITY
    total = sim.constraint_forces.sum(axis=0)
    assert np.linalg.norm(total - weight) < 0.005 * np.linalg.norm(weight)
    # each corner holds half, by symmetry, and pulls up and outwards
    left, right = sim.constraint_forces
    assert left[2] == pytest.approx(right[2], rel=0.01)
    assert left[0] * right[0] < 0.0
    # about the left corner, the right corner's force balances the moment of the weight
    x = sim.state.x
    pivot = x[sim.model.pinned[0]]
    held = np.cross(x[sim.model.pinned[1]] - pivot, right)
    of_weight = np.cross(x - pivot, sim.model.mass[:, None] * GRAVITY).sum(axis=0)
    assert np.linalg.norm(held + of_weight) < 0.01 * np.linalg.norm(of_weight)


@pytest.mark.parametrize("scheme", ["euler", "bdf2"])
def test_momentum_changes_by_what_gravity_and_the_holders_give(scheme):
    """A sheet whose corners are carried up and sideways with a changing velocity: every step,
    the cloth's momentum change is h (the holders' forces + the weight + the air's drag on the
    new velocities), to the solver's precision (BDF2's update also carries a third of the
    last velocity change). Internal forces, elastic and damping, cancel in pairs."""
    sim = _hang(scheme)
    m = sim.model.mass[:, None]
    start = sim.state.x[sim.model.pinned].copy()
    weight = float(sim.model.mass.sum()) * GRAVITY
    for k in range(1, 61):
        t = k * sim.dt
        sim.control.pin_targets = start + np.array([0.2 * t * t, 0.0, 0.1 * np.sin(4.0 * t)])
        before = sim.state
        sim.step()
        h = 2.0 * sim.dt / 3.0 if scheme == "bdf2" and before.v_prev is not None else sim.dt
        dp = (m * (sim.state.v - before.v)).sum(axis=0)
        if h != sim.dt:
            dp -= (m * (before.v - before.v_prev)).sum(axis=0) / 3.0
        drag = -sim.model.material.air_drag * (m * sim.state.v).sum(axis=0)
        impulse = h * (sim.constraint_forces.sum(axis=0) + weight + drag)
        assert np.allclose(dp, impulse, rtol=0.0, atol=1e-9 * np.abs(impulse).max() + 1e-12), k


def test_the_mesh_tables_find_the_same_pairs_as_a_pass_over_all():
    """constraint_forces with the mesh's incidence tables (what the Simulator passes) gives
    the same numbers, bit for bit, as the pass over every pair, for pins in the middle of the
    sheet, at its corners, and with cloth-cloth springs after the mesh's pairs."""
    from cloth_mg_ros.physics.system import BlockSystem
    from cloth_mg_ros.sim.integrator import assemble_step
    from cloth_mg_ros.sim.pins import constraint_forces

    sim = _hang("bdf2", "pcg")
    for _ in range(5):
        sim.step()
    step = assemble_step(sim.model, sim.state, sim.dt, "bdf2")
    rng = np.random.default_rng(0)
    dv = rng.standard_normal((sim.model.n, 3))
    n = sim.model.n
    springs = np.array([[0, n - 1], [3, n // 2], [n // 3, n // 2 + 5]])
    extra = BlockSystem(step.system.diag, np.concatenate([step.system.pairs, springs]),
                        np.concatenate([step.system.offd, rng.standard_normal((3, 3, 3))]),
                        step.system.hess_scale)
    for system in (step.system, extra):
        step.system = system
        for rows in (sim.model.pinned, np.array([n // 2, 0, n - 1]), np.array([3])):
            plain = constraint_forces(step, dv, rows)
            looked_up = constraint_forces(step, dv, rows, sim.model.incidence)
            assert np.array_equal(plain, looked_up) and np.any(plain != 0.0)
