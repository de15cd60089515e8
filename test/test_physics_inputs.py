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


def test_sphere_pushes_a_particle_at_its_centre_up_and_colliders_refuse_nan():
    from cloth_mg_ros.collision.colliders import PlaneCollider, SphereCollider

    sphere = SphereCollider(np.zeros(3), 0.1)
    c = sphere.query(np.zeros((1, 3)), 0.01)
    assert np.allclose(c.normal, [[0.0, 0.0, 1.0]])
    with pytest.raises(ClothInputError, match="friction"):
        SphereCollider(np.zeros(3), 0.1, friction=float("nan"))
    with pytest.raises(ClothInputError, match="friction"):
        PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]), friction=float("nan"))
    with pytest.raises(ClothInputError, match="point"):
        PlaneCollider(np.array([0.0, np.inf, 0.0]), np.array([0.0, 0.0, 1.0]))
    PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]))  # the defaults pass


def test_hang_scene_checks_friction_and_explicit_stepper_skips_untracked_energy(model):
    from cloth_mg_ros.sim.explicit import ExplicitStepper
    from cloth_mg_ros.sim.sheets import build_scene

    with pytest.raises(ClothInputError, match="friction"):
        build_scene("hang", 100, get_material("cotton"), friction=float("nan"))
    # a valid friction too: the hang has no collider to give it to (before: taken, unused)
    with pytest.raises(ClothInputError, match="friction is not a parameter of the hang"):
        build_scene("hang", 100, get_material("cotton"), friction=0.5)
    stepper = ExplicitStepper()
    stepper.track_energy = False
    state = ClothState.at_rest(np.array(model.mesh.rest))
    stats = stepper.step(model, state, None, 1e-4).stats
    assert np.isnan(stats.kinetic_energy) and np.isnan(stats.potential_energy)
    stepper.track_energy = True
    assert np.isfinite(stepper.step(model, state, None, 1e-4).stats.potential_energy)


def test_bending_law_refuses_bad_coefficients_with_a_cloth_input_error():
    from cloth_mg_ros.physics.bending_law import BendingLaw

    with pytest.raises(ClothInputError, match="k1"):
        BendingLaw((1e-5, float("nan"), 1e-5))


BAD_POSITIVE = [0.0, -1.0, float("nan"), float("inf")]
BAD_STRAIN_LIMITS = [1.0, 0.9, 0.0, -2.0, float("nan"), float("inf")]


@pytest.mark.parametrize("value", BAD_POSITIVE)
def test_model_refuses_a_thickness_or_contact_stiffness_not_finite_and_positive(model, value):
    from dataclasses import replace

    for name in ("thickness", "contact_stiffness"):
        with pytest.raises(ClothInputError, match=rf"{name} .*{value!r}"):
            replace(model, **{name: value})
    with pytest.raises(ClothInputError, match=rf"thickness .*{value!r}"):
        build_model(model.mesh, get_material("cotton"), thickness=value)


@pytest.mark.parametrize("value", BAD_STRAIN_LIMITS)
def test_model_and_body_options_refuse_a_strain_limit_that_would_shorten_edges(model, value):
    """A limit <= 1 would pull every edge to or below its rest length (physics.strain_limit);
    None (no limit) and the defaults pass."""
    from dataclasses import replace

    from cloth_mg_ros.config.schema import body_options

    with pytest.raises(ClothInputError, match=rf"strain_limit .*{value!r}"):
        replace(model, strain_limit=value)
    with pytest.raises(ClothInputError, match=rf"strain_limit .*{value!r}"):
        body_options(strain_limit=value)
    assert replace(model, strain_limit=None).strain_limit is None
    assert replace(model, strain_limit=1.1).strain_limit == 1.1
    assert body_options(strain_limit=None).strain_limit is None
    assert body_options().strain_limit == 1.1


@pytest.mark.parametrize("value", BAD_POSITIVE)
def test_body_options_refuse_a_thickness_or_teleport_distance_not_finite_and_positive(value):
    from cloth_mg_ros.config.schema import body_options

    for name in ("thickness", "teleport_m"):
        with pytest.raises(ClothInputError, match=rf"{name} .*{value!r}"):
            body_options(**{name: value})


@pytest.mark.parametrize("value", BAD_POSITIVE)
def test_self_contact_refuses_a_stiffness_not_finite_and_positive(model, value):
    from cloth_mg_ros.collision.self_contact import SelfContact

    with pytest.raises(ClothInputError, match=rf"stiffness .*{value!r}"):
        SelfContact(np.array(model.mesh.rest), 0.01, stiffness=value)
    assert SelfContact(np.array(model.mesh.rest), 0.01).stiffness == 10.0
