"""Friction with an exact answer: a sheet on a tilted plane sticks where tan(theta) <= mu and
otherwise slides at g (sin(theta) - mu cos(theta)), with every integrator scheme; what the
plane feels is the sheet's weight or Coulomb's force; the friction parameter reaches the
colliders of sheet and body scenes and of the node's settings; bad values are named."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.collision.colliders import (
    PlaneCollider,
    SphereCollider,
    project_contacts,
)
from cloth_mg_ros.collision.friction import StepFriction
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.incline import (
    GRAVITY,
    SLID_TRAVEL,
    InclineSpec,
    build_incline,
    run_incline,
)
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions
from cloth_mg_ros.sim.schemes import SCHEMES
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

PARTICLES = 60
DURATION = 0.5  # s
# (mu, angle): each pair a degree or two from tan(angle) = mu, one side then the other
CASES = [(0.4, 20.0), (0.4, 23.5), (0.7, 33.0), (0.7, 36.5)]


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("mu, angle", CASES)
def test_the_sheet_sticks_or_slides_at_coulombs_acceleration(scheme, mu, angle):
    spec = InclineSpec(mu, angle, scheme=scheme, particles=PARTICLES, duration=DURATION)
    block, _, _ = run_incline(spec)
    slides = math.tan(math.radians(angle)) > mu
    assert block["slid"] is slides and block["exact_slid"] is slides
    exact = GRAVITY * (math.sin(math.radians(angle)) - mu * math.cos(math.radians(angle)))
    if slides:
        assert block["exact_acceleration_mps2"] == pytest.approx(exact, rel=1e-12)
        assert block["acceleration_mps2"] == pytest.approx(exact, rel=0.03)
        assert abs(block["error_pct"]) < 3.0
    else:
        assert block["exact_acceleration_mps2"] == 0.0
        assert abs(block["travel_m"]) < 1e-3 * SLID_TRAVEL
    assert block["normal_drift_m"] < 1e-9  # it stays on the plane
    assert block["all_converged"]


@pytest.mark.parametrize("scheme", SCHEMES)
def test_the_plane_feels_the_weight_when_it_sticks_and_coulombs_force_when_it_slides(scheme):
    """The contact loads (sim.loads: penalty and projection, friction included) on the plane,
    after the first tenth of a second: the whole weight where the sheet sticks; where it
    slides, the normal load m g cos(theta) and mu times it up the slope on the cloth (down
    the slope on the plane)."""
    for mu, angle in ((0.6, 25.0), (0.3, 25.0)):
        scene = build_incline(InclineSpec(mu, angle, scheme=scheme, particles=PARTICLES))
        model = scene.model
        sim = Simulator(model, scene.state, make_solver("direct", hierarchy=scene.hierarchy,
                                                        bending=model.bending),
                        dt=1.0 / 60.0, scheme=scheme, track_energy=False,
                        track_contact_forces=True)
        weight = float(model.mass.sum()) * GRAVITY
        theta = math.radians(angle)
        normal = np.cross(scene.down, [0.0, 1.0, 0.0])
        for k in range(1, 19):
            sim.step()
            if k * sim.dt < 0.1:
                continue
            force = sim.contact_load.total()
            if math.tan(theta) <= mu:
                assert np.allclose(force, [0.0, 0.0, -weight], atol=1e-6 * weight), k
            else:
                assert force @ normal == pytest.approx(-weight * math.cos(theta), rel=1e-6)
                assert force @ scene.down == pytest.approx(mu * weight * math.cos(theta),
                                                           rel=1e-6)


def test_coulomb_bounds_the_slip_by_the_whole_normal_impulse():
    """One particle on a floor, its penalty worth 2 m/s of normal velocity this step and the
    projection removing 1 m/s more: mu = 0.25 takes 0.75 m/s off a 2 m/s slip and moves it
    back by h_move times that; a slip under the bound stops (sticks) for good."""
    floor = PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]), friction=0.25)
    for slip, left in ((2.0, 1.25), (0.5, 0.0)):
        x = np.array([[0.0, 0.0, 0.004]])
        v = np.array([[slip, 0.0, -1.0]])
        friction = StepFriction(1, h_force=0.01, h_move=0.02)
        # a 0.2 N penalty on a 1 g particle over h_force = 0.01 s: 2 m/s
        friction.add_penalty(np.array([0]), np.array([0]), np.array([0.2]), np.array([1e-3]))
        project_contacts([floor], x, v, 0.005, friction=friction)
        assert v[0] == pytest.approx([left, 0.0, 0.0])
        assert x[0, 0] == pytest.approx(0.02 * (left - slip))
        assert friction.pushes[0] == 1 and np.allclose(friction.normal[0], [0.0, 0.0, 1.0])
        assert not friction.budget[0].any()  # taken once


def test_a_projection_leaves_a_resting_particle_a_contact_of_the_next_step():
    floor = PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    x = np.array([[0.1, 0.2, 0.001], [0.3, 0.1, -0.002]])
    project_contacts([floor], x, np.zeros((2, 3)), 0.005)
    assert len(floor.query(x, 0.005)) == 2
    assert np.allclose(x[:, 2], 0.005, atol=1e-11)


def test_the_friction_parameter_reaches_the_sheet_scenes_colliders():
    material = get_material("cotton")
    own = build_scene("drape", 200, material)
    assert [c.friction for c in own.model.colliders] == [0.3, 0.5]  # the colliders' own
    scene = build_scene("drape", 200, material, friction=0.8)
    assert isinstance(scene.model.colliders[0], SphereCollider)
    assert [c.friction for c in scene.model.colliders] == [0.8, 0.8]
    with pytest.raises(ClothInputError, match="friction must be a number >= 0, got -0.1"):
        build_scene("drape", 200, material, friction=-0.1)


def test_the_friction_parameter_reaches_the_node_and_the_body_scenes_colliders():
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.ros.parameters import check_parameters
    from cloth_mg_ros.ros.session_settings import SessionSettings
    from cloth_mg_ros.sim.garment_sim import GarmentSim

    values = check_parameters({"scene": "drape", "particles": 200, "friction": 0.25,
                               "tick_mode": "timer"})
    scene = SessionSettings.from_values(values, body=False).sheet_scene()
    assert [c.friction for c in scene.model.colliders] == [0.25, 0.25]

    params = load_scene("walking").replace(friction=0.9, tolerance=1e-4)
    options = BodySimOptions.from_scene(params, particles=300, garment="skirt")
    assert options.friction == 0.9
    first = read_pose_frames(resolve_bag("walk"))[0]
    sim = GarmentSim.dress(Avatar.load(), first[0], first[1], get_material("cotton"), options)
    assert [c.friction for c in sim.sim.model.colliders] == [0.9, 0.9]  # body, floor


@pytest.mark.parametrize("kwargs, words", [
    ({"friction": -0.2, "angle_deg": 10.0}, ["--friction", "-0.2"]),
    ({"friction": float("nan"), "angle_deg": 10.0}, ["--friction", "nan"]),
    ({"friction": 0.5, "angle_deg": 90.0}, ["--angle", "90.0"]),
    ({"friction": 0.5, "angle_deg": 10.0, "scheme": "rk4"}, ["--scheme", "rk4"]),
    ({"friction": 0.5, "angle_deg": 10.0, "dt": 0.0}, ["--dt", "0.0"]),
    ({"friction": 0.5, "angle_deg": 10.0, "duration": 0.05}, ["--duration", "0.05"]),
    ({"friction": 0.5, "angle_deg": 10.0, "particles": 3}, ["--particles", "3"]),
])
def test_bad_incline_values_are_named(kwargs, words):
    with pytest.raises(ClothInputError) as error:
        InclineSpec(**kwargs)
    for word in words:
        assert word in str(error.value)


def test_a_bad_friction_in_a_scene_file_is_named(tmp_path):
    path = tmp_path / "slippery.yaml"
    path.write_text("/**:\n  ros__parameters:\n    garment: dress\n    friction: 20.0\n")
    with pytest.raises(ClothInputError, match="friction") as error:
        load_scene(str(path))
    assert "20.0" in str(error.value) and "0..10" in str(error.value)


def test_cloth_mg_run_incline_writes_its_block(tmp_path, capsys):
    out = tmp_path / "incline"
    assert main(["run", "--scene", "incline", "--friction", "0.2", "--angle", "25",
                 "--scheme", "euler", "--particles", str(PARTICLES), "--duration", "0.3",
                 "--out", str(out)]) == 0
    block = json.loads((out / "summary.json").read_text())["incline"]
    assert {"friction", "angle_deg", "slid", "acceleration_mps2",
            "exact_acceleration_mps2"} <= set(block)
    assert block["friction"] == 0.2 and block["angle_deg"] == 25.0 and block["slid"]
    assert block["acceleration_mps2"] == pytest.approx(block["exact_acceleration_mps2"],
                                                       rel=0.03)
    assert (out / "frames.png").stat().st_size > 0
    assert "slid" in capsys.readouterr().out
    for args, message in ((["--friction", "0.2"], "needs --angle"),
                          (["--angle", "10", "--friction", "-1"], "--friction"),
                          (["--angle", "10", "--overhang", "0.1"], "--overhang")):
        assert main(["run", "--scene", "incline", *args, "--out", str(out)]) == 2
        assert message in capsys.readouterr().err
