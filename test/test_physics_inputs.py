"""Bad step sizes, non-finite right-hand sides and collapsed faces are handled, not run."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh import sheet_coarse
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.stretch import stretch_energy
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.simulator import ImplicitStepper
from cloth_mg_ros.solvers import PCGSolver


@pytest.fixture(scope="module")
def model():
    return build_model(sheet_coarse(0.5, 0.5, cells_x=6), get_material("cotton"))


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), float("inf"), "x"])
def test_a_step_refuses_a_step_size_that_is_not_finite_and_positive(model, dt):
    state = ClothState.at_rest(np.array(model.mesh.rest))
    with pytest.raises(ClothInputError, match="dt"):
        assemble_step(model, state, dt, "euler")
    with pytest.raises(ClothInputError, match="dt"):
        ImplicitStepper(PCGSolver(maxiter=50)).step(model, state, None, dt)


def test_pcg_stops_at_once_on_a_non_finite_right_hand_side(model):
    step = assemble_step(model, ClothState.at_rest(np.array(model.mesh.rest)), 1 / 60, "euler")
    b = step.rhs.copy()
    b[3, 1] = np.nan
    result = PCGSolver(tol=1e-6, maxiter=20000).solve(step.system, b)
    assert result.iterations == 0
    assert not result.converged
    assert np.isnan(result.rel_residual)
    assert np.all(result.x == 0.0)  # x0 untouched


def test_pcg_counts_no_iteration_for_a_breakdown(model):
    """An indefinite system breaks down (p . q < 0) before its first update of x: that is
    0 iterations, not 1."""
    step = assemble_step(model, ClothState.at_rest(np.array(model.mesh.rest)), 1 / 60, "euler")
    system = step.system
    system.offd[:] = 0.0
    system.diag[:] = np.eye(3)
    system.diag[0] = -np.eye(3)
    b = np.zeros((system.n, 3))
    b[0, 0] = 1.0
    result = PCGSolver(tol=1e-6, maxiter=100, preconditioner="scalar").solve(system, b)
    assert result.iterations == 0
    assert not result.converged
    assert np.all(result.x == 0.0)


def test_collapsed_face_energy_is_counted_by_both_energy_paths(model):
    x = np.array(model.mesh.rest)
    f = model.mesh.faces[0]
    x[f[1]] = x[f[0]]
    x[f[2]] = x[f[0]]
    st = model.stretch
    direct = stretch_energy(x, model.mesh.faces, st.coef, st.stiff, st.rest_len, st.cap)
    assert internal_forces(model, x).stretch_energy == pytest.approx(direct, rel=1e-12)
