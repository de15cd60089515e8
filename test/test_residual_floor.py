"""The solves' residual floor (solvers.cg's docstring): every iterative solver measures the
residual against max(||S b||, floor), the simulator's floor being the step's weight impulse;
below ||S b|| the floor changes nothing, above it a solve stops at a fraction tol of it; a
sheet at rest is solved to a fraction of its weight, not of its vanishing imbalance, and
carries its weight as exactly as before."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.grippers import step_held
from cloth_mg_ros.sim.model import GRAVITY
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

SOLVERS = ("pcg", "mg", "mpcg", "amg")


@pytest.mark.parametrize("name", SOLVERS)
def test_a_floor_over_b_stops_the_solve_at_tol_of_the_floor_and_one_under_it_does_nothing(
        contact_step, name):
    scene, step = contact_step
    free = ~step.fixed
    b = 1e-2 * step.rhs  # an imbalance a hundredth of the step's own
    x0 = np.where(step.fixed[:, None], step.x0, 0.0)
    big = float(np.linalg.norm(step.rhs[free]))

    def solve(floor: float):
        solver = make_solver(name, tol=1e-6, hierarchy=scene.hierarchy,
                             bending=scene.model.bending)
        return solver.solve(step.system, b, x0.copy(), step.fixed, floor=floor)

    plain, under, over = solve(0.0), solve(0.5 * np.linalg.norm(b[free])), solve(big)
    assert plain.converged and under.converged and over.converged
    assert np.array_equal(under.x, plain.x) and under.iterations == plain.iterations
    residual = np.linalg.norm((b - step.system.matvec(over.x))[free])
    assert residual <= 1e-6 * big and over.rel_residual == pytest.approx(residual / big)
    assert over.iterations < plain.iterations


def test_a_hanging_sheet_at_rest_solves_to_its_weight_and_carries_it_as_before():
    """The hang (400 particles, mpcg at 1e-4) settled for 4 s: its solves take a few
    iterations with the floor (3 at the median here) and several times more without it (21;
    the same solver, its floor dropped), and both sheets hang in the same place and load
    their grippers alike, with the weight."""
    class NoFloor:
        """The solver as it solved before the floor."""

        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, key):
            return getattr(self.inner, key)

        def solve(self, system, b, x0=None, fixed=None, floor=0.0):
            return self.inner.solve(system, b, x0, fixed)

    def settle(floored: bool):
        scene = build_scene("hang", 400, get_material("white-dots-on-blk"))
        solver = make_solver("mpcg", tol=1e-4, hierarchy=scene.hierarchy,
                             bending=scene.model.bending, threads=1)
        sim = Simulator(scene.model, scene.state, solver if floored else NoFloor(solver),
                        dt=1 / 60, track_energy=False)
        iterations = [step_held(sim, scene.grippers)[0].iterations for _ in range(240)]
        force = sum(np.array(w["force"]) for w in scene.grippers.wrenches().values())
        return sim.state.x, iterations[-30:], force, float(sim.model.mass.sum())

    x, its, force, mass = settle(True)
    x_plain, its_plain, force_plain, _ = settle(False)
    weight = np.array([0.0, 0.0, -mass * float(np.linalg.norm(GRAVITY))])
    assert np.median(its) <= 6 and np.median(its_plain) >= 4 * max(np.median(its), 1)
    # still settling after 4 s: both 1e-4 of the weight off it, and 1e-6 apart
    for f in (force, force_plain):
        assert np.allclose(f, weight, rtol=0.0, atol=1e-3 * mass * 9.81), f
    assert np.allclose(force, force_plain, rtol=0.0, atol=1e-5 * mass * 9.81)
    assert np.abs(x - x_plain).max() < 1e-5  # m, of a 1 m sheet
