"""Newton iterations of an implicit step (sim.newton): a step whose forces are linear is
solved by the first iteration, so the next correct nothing; on a turning membrane the
corrections shrink iteration by iteration and the step keeps the turn the one-iteration step
brakes; pins stay where they are put, cloth on a floor stays on it; bad counts are named."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.collision.colliders import RESTING, PlaneCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.spin import SpinSpec, run_spin
from cloth_mg_ros.mesh.generators import sheet_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.newton import newton_correction
from cloth_mg_ros.sim.simulator import ImplicitStepper, Simulator
from cloth_mg_ros.solvers import make_solver


def _sheet(particles: int = 200, colliders=None, pinned=None):
    hier = sheet_hierarchy(particles, None, 0.3, 0.3, plane="xy")
    model = build_model(hier.levels[0], get_material("cotton"), pinned=pinned,
                        colliders=colliders, gravity=np.array([0.0, 0.0, -9.81]))
    solver = make_solver("direct", tol=1e-10, hierarchy=hier, bending=model.bending)
    return hier, model, solver


@pytest.mark.parametrize("scheme", ["euler", "bdf2"])
def test_a_linear_step_is_solved_by_the_first_iteration(scheme):
    # a flat sheet falling as a whole: its elastic forces stay zero, every force is linear
    hier, model, solver = _sheet()
    x = np.array(hier.levels[0].rest)
    state = ClothState(x, np.tile([0.0, 0.0, -0.3], (len(x), 1)))
    if scheme == "bdf2":
        state.x_prev, state.v_prev = x + [0.0, 0.0, 0.005], state.v + [0.0, 0.0, 0.16]
    step = assemble_step(model, state, 1.0 / 60.0, scheme)
    dv = solver.solve(step.system, step.rhs, step.x0, step.fixed).x
    again, _ = newton_correction(model, state, step, dv, solver)
    assert np.max(np.abs(again - dv)) < 1e-12 * np.max(np.abs(dv))


def test_the_corrections_shrink_on_a_turning_tube():
    from cloth_mg_ros.mesh.garments.sleeve import sleeve_hierarchy

    hier, _, _ = sleeve_hierarchy(400, 0.1, 0.05, (0.0, -0.05, 0.0), (0.0, 1.0, 0.0),
                                  (0.0, 0.0, 1.0))
    x = np.array(hier.finest.rest)
    v = 2.0 * np.stack([x[:, 2], np.zeros(len(x)), -x[:, 0]], axis=1)  # 0.1 m/s rim
    model = build_model(hier.finest, get_material("silk"), gravity=np.zeros(3))
    solver = make_solver("direct", tol=1e-12, hierarchy=hier, bending=model.bending)
    step = assemble_step(model, ClothState(x, v), 1.0 / 60.0, "euler")
    dv = solver.solve(step.system, step.rhs, step.x0, step.fixed).x
    sizes = []
    for _ in range(5):
        new, _ = newton_correction(model, ClothState(x, v), step, dv, solver)
        sizes.append(float(np.max(np.abs(new - dv))))
        dv = new
    # measured: 1.0e-2, 8.5e-3, 1.9e-3, 2.3e-4, 2.9e-5 m/s
    assert all(b < a for a, b in zip(sizes, sizes[1:], strict=False))
    assert sizes[-1] < 1e-2 * sizes[0]


def test_three_iterations_keep_the_turn_one_iteration_brakes():
    one = run_spin(SpinSpec(0.1, "silk"))["kept"]
    three = run_spin(SpinSpec(0.1, "silk", newton=3))["kept"]
    assert one < 0.5 < 0.9 < three <= 1.0 + 1e-9


def test_pins_and_a_floor_hold_through_the_iterations():
    hier, model, solver = _sheet(colliders=[PlaneCollider(np.zeros(3), np.array([0, 0, 1.0]),
                                                          friction=0.5)])
    x = np.array(hier.levels[0].rest) + [0.0, 0.0, model.thickness * RESTING]
    sim = Simulator(model, ClothState.at_rest(x), solver, newton_iterations=3,
                    track_energy=False)
    for _ in range(20):
        assert sim.step().converged
    assert np.isfinite(sim.state.x).all()
    assert np.max(np.abs(sim.state.x - x)) < 1e-6  # lying on the floor, it stays

    hier, model, solver = _sheet(pinned=np.array([0, 1]))
    x = np.array(hier.levels[0].rest)
    sim = Simulator(model, ClothState.at_rest(x), solver, newton_iterations=3,
                    track_energy=False)
    for _ in range(20):
        sim.step()
    assert np.array_equal(sim.state.x[[0, 1]], x[[0, 1]])
    assert sim.state.x[:, 2].min() < -0.05  # the rest fell


@pytest.mark.parametrize("value, scheme, word", [(0, "bdf2", "0"), (True, "bdf2", "True"),
                                                 (1.5, "bdf2", "1.5"),
                                                 (2, "genalpha", "genalpha")])
def test_bad_newton_counts_are_named(value, scheme, word):
    with pytest.raises(ClothInputError, match=word):
        ImplicitStepper(None, scheme, newton_iterations=value)


def test_three_iterations_take_most_of_bdf2s_own_damping_off_the_swing(tmp_path):
    # the swinging strip turns as a loaded pendulum: one linearisation per step brakes it
    from cloth_mg_ros.cli.main import main
    from cloth_mg_ros.fidelity.swing import SwingSpec, chain_frequency, run_swing

    duration = 2.5 / chain_frequency(0.5)
    ratios = {}
    for k in (1, 3):
        block, _, _ = run_swing(SwingSpec(dt=1.0 / 30.0, duration=duration, particles=48,
                                          newton=k))
        ratios[k] = block["damping_ratio_fabric_off"]
        assert block["newton"] == k
    assert 0.0 < ratios[3] < 0.5 * ratios[1]
    out = tmp_path / "swing"
    assert main(["run", "--scene", "swing", "--newton", "2", "--particles", "48",
                 "--duration", str(duration), "--out", str(out)]) == 0
    assert main(["run", "--scene", "cusick", "--newton", "2", "--out", str(out)]) == 2


def test_the_parameter_reaches_the_body_scenes_the_sheets_and_the_node(tmp_path):
    from cloth_mg_ros.cli.main import main
    from cloth_mg_ros.config.scenes import load_scene
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.ros.parameters import check_parameters
    from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim

    assert check_parameters({"scene": "drape", "newton_iterations": 3})[
        "newton_iterations"] == 3
    with pytest.raises(ClothInputError, match="newton_iterations"):
        check_parameters({"scene": "drape", "newton_iterations": 0})
    params = load_scene("walking").replace(newton_iterations=2, tolerance=1e-4)
    options = BodySimOptions.from_scene(params, particles=300, garment="skirt")
    first = read_pose_frames(resolve_bag("walk"))[0]
    sim = GarmentSim.dress(Avatar.load(), first[0], first[1], get_material("cotton"), options)
    assert sim.sim.newton_iterations == 2
    assert BodySimOptions.from_scene(load_scene("walking"), particles=300).newton_iterations \
        == 1
    out = tmp_path / "hang"
    assert main(["run", "--scene", "hang", "--particles", "200", "--steps", "3", "--newton",
                 "2", "--out", str(out), "--no-progress"]) == 0
    import json

    assert json.loads((out / "summary.json").read_text())["newton_iterations"] == 2
    assert main(["run", "--scene", "dressing", "--newton", "2", "--out", str(out)]) == 2
    assert main(["run", "--scene", "hang", "--newton", "0", "--out", str(out)]) == 2


def test_a_correction_is_solved_to_the_steps_own_residual_and_the_tolerance_restored():
    hier = sheet_hierarchy(400, None, 0.3, 0.3, plane="xz")
    model = build_model(hier.levels[0], get_material("cotton"), pinned=np.array([0, 1]),
                        gravity=np.array([0.0, 0.0, -9.81]))
    solver = make_solver("pcg", tol=1e-3, hierarchy=hier, bending=model.bending)
    sim = Simulator(model, ClothState.at_rest(np.array(hier.levels[0].rest)), solver,
                    track_energy=False)
    for _ in range(20):  # swinging: the step's own change is large, its correction small
        sim.step()
    state = sim.state
    step = assemble_step(model, state, 1.0 / 60.0, "bdf2")
    dv = solver.solve(step.system, step.rhs, step.x0, step.fixed).x
    reference = float(np.linalg.norm(step.rhs[~step.fixed]))
    _, loose = newton_correction(model, state, step, dv, solver, reference)
    _, tight = newton_correction(model, state, step, dv, solver)
    assert solver.tol == 1e-3
    assert loose.converged and tight.converged and loose.iterations < tight.iterations
