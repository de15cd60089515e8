"""Friction inside the step's solve (sim.contact_friction, `contact_friction: solve`): a sheet
on a slope sticks and slides at Coulomb's exact answer and loads the slope with its whole
weight; a sheet dropped on a sphere ends with less energy than it started with (friction
after the solve puts tens of joules of stretch into it); a particle resting on a sphere
stays a contact; the pressing force survives a change of resolution; bad values are named
and the parameter reaches the scenes and the command line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scene_parameter import check_scene_parameter

from cloth_mg_ros.collision.colliders import RESTING, Contacts, PlaneCollider, SphereCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.incline import InclineSpec, build_incline, measure, run_incline
from cloth_mg_ros.mesh.generators import sheet_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.contact_friction import SLIP_FLOOR, friction_dampers, with_resting
from cloth_mg_ros.sim.detail import prolongate_state, restrict_state
from cloth_mg_ros.sim.integrator import energies
from cloth_mg_ros.sim.model import SOLVE_CONTACT_STIFFNESS, ClothModel, ClothState, build_model
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver


@pytest.mark.parametrize("friction, angle, scheme", [
    (0.5, 20.0, "bdf2"), (0.5, 26.0, "bdf2"), (0.5, 30.0, "bdf2"), (0.3, 30.0, "bdf2"),
    (0.5, 30.0, "euler")])
def test_a_sheet_on_a_slope_sticks_and_slides_as_coulomb_says(friction, angle, scheme):
    spec = InclineSpec(friction, angle, scheme, contact_friction="solve")
    block, _, _ = run_incline(spec)
    assert block["contact_friction"] == "solve"
    assert block["slid"] == block["exact_slid"]
    if block["exact_slid"]:
        assert block["error_pct"] == pytest.approx(0.0, abs=0.1)
    else:
        # the regularised law's creep: under SLIP_FLOOR for the 0.5 s after the fit's start
        assert abs(block["travel_m"]) < SLIP_FLOOR * spec.duration


@pytest.mark.parametrize("angle", [20.0, 30.0])
def test_newton_iterations_keep_the_friction_of_the_solve(angle):
    spec = InclineSpec(0.5, angle, contact_friction="solve")
    scene = build_incline(spec)
    solver = make_solver("direct", tol=1e-10, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    sim = Simulator(scene.model, scene.state, solver, dt=spec.dt, track_energy=False,
                    newton_iterations=3)
    weights = scene.model.mass / scene.model.mass.sum()
    centre = [weights @ sim.state.x]
    for _ in range(round(spec.duration / spec.dt)):
        sim.step()
        centre.append(weights @ sim.state.x)
    block = measure(spec, scene, np.array(centre))
    assert block["slid"] == block["exact_slid"]
    if block["exact_slid"]:
        assert block["error_pct"] == pytest.approx(0.0, abs=0.1)
    else:  # the regularised law's creep, as with one iteration
        assert abs(block["travel_m"]) < SLIP_FLOOR * spec.duration, block["travel_m"]


def test_a_sheet_stuck_on_a_slope_loads_it_with_its_whole_weight():
    # the friction the solve balances is a force on the slope too (sim.loads): the cloth's
    # weight, along the slope as across it
    scene = build_incline(InclineSpec(0.5, 20.0, contact_friction="solve"))
    model = scene.model
    solver = make_solver("direct", tol=1e-10, hierarchy=scene.hierarchy, bending=model.bending)
    sim = Simulator(model, scene.state, solver, track_energy=False, track_contact_forces=True)
    for _ in range(30):
        sim.step()
    weight = float(model.mass.sum()) * model.gravity
    assert np.allclose(sim.contact_load.total(), weight, rtol=0.0,
                       atol=1e-3 * np.linalg.norm(weight))


def _lying_on_a_floor(contact_friction: str) -> Simulator:
    """A 200-particle cotton sheet resting on a floor, 5 steps (direct solves), its contact
    loads tracked."""
    floor = PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]), friction=0.5)
    hier = sheet_hierarchy(200, None, 0.3, 0.3, plane="xy")
    model = build_model(hier.levels[0], get_material("cotton"), colliders=[floor],
                        contact_friction=contact_friction)
    x = np.array(hier.levels[0].rest) + [0.0, 0.0, model.thickness * RESTING]
    solver = make_solver("direct", tol=1e-10, hierarchy=hier, bending=model.bending)
    sim = Simulator(model, ClothState.at_rest(x), solver, track_energy=False,
                    track_contact_forces=True)
    for _ in range(5):
        sim.step()
    return sim


def _lift(sim: Simulator) -> None:
    """One step with a lift of three times the sheet's weight."""
    model = sim.model
    sim.model = dataclasses.replace(model, external_force=-3.0 * model.mass[:, None]
                                    * model.gravity[None, :])
    sim.step()


def test_a_sheet_lifting_off_a_floor_is_not_held_back():
    # resting on a floor, then lifted: its contacts pressed at the last step, but a contact
    # never pulls (sim.contact_set drops the penalties that would)
    sim = _lying_on_a_floor("solve")
    assert sim.contact_load.total()[2] == pytest.approx(
        float(sim.model.mass.sum()) * -9.81, rel=1e-3)  # it lies with its weight on the floor
    assert np.all(sim.state.contact_force > 0.0)
    _lift(sim)  # free, it rises at 2 g (BDF2 from rest: v = (2/3) dt a)
    assert sim.contact_load.total()[2] <= 1e-9  # no pull on the floor
    assert sim.contact_load.pull <= 1e-9
    assert sim.state.v[:, 2].mean() == pytest.approx(2.0 / 3.0 * sim.dt * 2.0 * 9.81, rel=1e-3)


def test_the_projections_penalties_hold_a_lifting_sheet_and_its_pull_is_counted():
    # the same lift with friction after the solve: its penalties are springs for the whole
    # step, so they hold the sheet back, and ContactLoad.pull counts it (the floor pulled up)
    sim = _lying_on_a_floor("projection")
    assert sim.contact_load.pull == 0.0  # lying on it: the penalties push
    _lift(sim)
    up = sim.contact_load.total()[2]
    assert up > 0.1 * float(sim.model.mass.sum()) * 9.81  # held back by a tenth of its weight
    assert sim.contact_load.pull == pytest.approx(up, rel=1e-9)  # every contact pulls, along z


def _drape(contact_friction: str, steps: int) -> tuple[float, float, np.ndarray]:
    scene = build_scene("drape", 600, get_material("cotton"), friction=0.5,
                        contact_friction=contact_friction)
    solver = make_solver("mpcg", tol=1e-4, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    sim = Simulator(scene.model, scene.state, solver, dt=1.0 / 60.0, scheme="bdf2")
    start = sum(energies(scene.model, sim.state))
    for _ in range(steps):
        sim.step()
    assert np.isfinite(sim.state.x).all()
    kinetic, potential = energies(scene.model, sim.state)
    return start, kinetic + potential, sim.state.x


def test_a_sheet_dropped_on_a_sphere_ends_with_less_energy_than_it_started_with():
    # 1 s after a 10 cm drop, the sheet lies on the sphere: its kinetic, gravitational and
    # elastic energy together under the start's (friction after the solve leaves it holding
    # about 19 J of stretch here, far more than its fall released)
    start, end, x = _drape("solve", 60)
    assert end < start
    # on the sphere (top at 0.75 m), centred on it, not sliding off
    assert 0.75 < x[:, 2].max() < 0.80
    assert np.linalg.norm(x[:, :2].mean(axis=0)) < 0.05


def test_a_particle_resting_on_a_sphere_stays_a_contact():
    sphere = SphereCollider(np.zeros(3), 0.25, friction=0.5)
    hier = sheet_hierarchy(200, None, 0.1, 0.1, plane="xy")
    model = build_model(hier.levels[0], get_material("cotton"), colliders=[sphere],
                        contact_friction="solve")
    x = np.array([[0.0, 0.0, 0.25 + model.thickness * RESTING]])
    v = np.array([[0.1, 0.0, 0.0]])  # sliding along the top: predicted just outside it
    none = Contacts.empty()
    dt = 1.0 / 60.0
    kept = with_resting(model, [sphere], x, v, dt, none, np.array([1e-3]))
    assert len(kept) == 1
    # its penalty is zero where the particle goes at its velocity
    assert kept.distance[0] == pytest.approx(
        model.thickness - dt * float(v[0] @ kept.normal[0]), abs=1e-15)
    assert len(with_resting(model, [sphere], x, v, dt, none, np.array([0.0]))) == 0
    assert len(with_resting(model, [sphere], x, v, dt, none, None)) == 0


def test_a_sliding_particle_feels_mu_times_its_normal_force_at_the_end_of_the_step():
    sphere = SphereCollider(np.zeros(3), 0.25, friction=0.4)
    normal = np.array([[0.0, 0.0, 1.0]])
    contacts = Contacts(np.array([0]), normal, np.array([0.005]), np.zeros((1, 3)))
    mass, dt, pressed = np.array([2e-3]), 0.01, np.array([0.02])
    v = np.array([[0.3, 0.0, 0.0]])
    forces = np.array([[0.01, 0.0, -0.005]])  # pulled along, and pressed by 0.005 N
    c_t, bound = friction_dampers([sphere], contacts, v, pressed, forces, mass, dt)
    assert bound[0] == pytest.approx(0.4 * 0.02)
    end = 0.3 + dt * 0.01 / 2e-3 - dt * 0.4 * 0.02 / 2e-3  # the slip the step ends with
    assert c_t[0] * end == pytest.approx(0.4 * 0.02)
    # the run's first step: pressed by the forces at the start
    c_t, bound = friction_dampers([sphere], contacts, v, None, forces, mass, dt)
    assert bound[0] == pytest.approx(0.4 * 0.005)
    assert c_t[0] * (0.3 + dt * 5.0 - dt * 0.4 * 2.5) == pytest.approx(0.4 * 0.005)
    stuck, _ = friction_dampers([sphere], contacts, np.zeros((1, 3)), pressed,
                             np.array([[0.001, 0.0, 0.0]]), mass, dt)
    assert stuck[0] == pytest.approx(0.4 * 0.02 / SLIP_FLOOR)


def test_the_pressing_force_survives_a_change_of_resolution():
    hier = sheet_hierarchy(600, None, 0.3, 0.3, plane="xy")
    fine, coarse = hier.levels[0].n_vertices, hier.levels[1].n_vertices
    x = np.array(hier.levels[0].rest)
    state = ClothState(x, np.zeros_like(x), contact_force=np.arange(fine, dtype=float))
    down = restrict_state(state, coarse)
    assert np.array_equal(down.contact_force, np.arange(coarse, dtype=float))
    up = prolongate_state(hier, down, 1, 0, [], 0.005)
    assert np.array_equal(up.contact_force[:coarse], down.contact_force)
    assert np.all(up.contact_force[coarse:] == 0.0)  # new vertices: not known yet
    assert np.array_equal(state.copy().contact_force, state.contact_force)


def test_bad_values_are_named():
    hier = sheet_hierarchy(200, None, 0.1, 0.1, plane="xy")
    model = build_model(hier.levels[0], get_material("cotton"), contact_friction="solve")
    assert model.contact_stiffness == SOLVE_CONTACT_STIFFNESS
    with pytest.raises(ClothInputError, match="contact_friction"):
        dataclasses.replace(model, contact_friction="after")
    with pytest.raises(ClothInputError, match="contact_friction"):
        build_model(hier.levels[0], get_material("cotton"), contact_friction="")
    solver = make_solver("direct", hierarchy=hier, bending=model.bending)
    state = ClothState.at_rest(np.array(hier.levels[0].rest))
    with pytest.raises(ClothInputError, match="linearised at the start"):
        Simulator(model, state, solver, linearise_at="prediction")
    assert isinstance(model, ClothModel)


def test_the_parameter_reaches_the_scenes_and_the_command_line(tmp_path):
    from cloth_mg_ros.cli.main import main

    out = tmp_path / "drape"
    check_scene_parameter("contact_friction", "solve", "after", "--contact-friction", "drape",
                          out)
    for scene in ("hang", "dressing", "cusick"):  # no collider, or a contact of its own
        assert main(["run", "--scene", scene, "--contact-friction", "solve",
                     "--out", str(out)]) == 2
    assert main(["run", "--scene", "incline", "--angle", "20", "--friction", "0.5",
                 "--contact-friction", "solve", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["incline"]["contact_friction"] \
        == "solve"
