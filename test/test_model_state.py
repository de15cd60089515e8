"""Newton's split: the Model is frozen, the colliders' poses are the State's, and a step is a
function of (model, state, control, dt) through a stepper that holds no simulation state."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cloth_mg_ros.collision.capsules import CapsuleCollider, CapsulePose
from cloth_mg_ros.config import schema
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import GarmentSim
from cloth_mg_ros.sim.model import ClothControl
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import ImplicitStepper, Simulator
from cloth_mg_ros.solvers import make_solver


def _drape(particles: int = 300):
    scene = build_scene("drape", particles, get_material("cotton"))
    solver = make_solver("mpcg", tol=1e-6, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    return scene, solver


def test_the_model_is_frozen():
    scene, _ = _drape()
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.model.strain_limit = 1.1
    other = dataclasses.replace(scene.model, strain_limit=1.1)
    assert other.strain_limit == 1.1 and scene.model.strain_limit is None


def test_a_step_is_a_function_of_its_arguments():
    """The stepper on (model, state, control, dt) gives the Simulator's steps bit for bit,
    leaves the state it was given untouched, and two runs interleaved on one stepper give
    what each gives alone: the stepper keeps nothing of a run between steps."""
    scene, solver = _drape()
    sim = Simulator(scene.model, scene.state.copy(), solver, dt=1 / 60)
    for _ in range(25):
        sim.step()
    stepper = ImplicitStepper(solver)
    start = scene.state.copy()
    a, b = scene.state, scene.state.copy()
    b.v[:] = 0.05  # another run: the sheet thrown sideways
    alone = scene.state.copy()
    alone.v[:] = 0.05
    control = ClothControl()
    for _ in range(25):
        a = stepper.step(scene.model, a, control, 1 / 60).state
        b = stepper.step(scene.model, b, control, 1 / 60).state
    for _ in range(25):
        alone = stepper.step(scene.model, alone, control, 1 / 60).state
    assert np.array_equal(a.x, sim.state.x) and np.array_equal(a.v, sim.state.v)
    assert np.array_equal(b.x, alone.x) and not np.array_equal(a.x, b.x)
    assert np.array_equal(scene.state.x, start.x)  # the given state is not written


def _walking_skirt() -> tuple[GarmentSim, list]:
    frames = read_pose_frames(resolve_bag("walk"))[30:40]
    options = schema.body_options(garment="skirt", particles=300, tolerance=1e-4, threads=1)
    sim = GarmentSim.dress(Avatar.load(), frames[0][0], frames[0][1], get_material("cotton"),
                           options)
    return sim, frames[1:]


def test_the_body_pose_lives_in_the_state():
    """Stepping a garment moves the capsules' pose in the State only: the collider holds its
    radii and friction and nothing a step changes; each state's pose is where the body was
    at that state's time, and the pose a step ago is its history."""
    garment_sim, frames = _walking_skirt()
    collider = garment_sim.sim.model.colliders[0]
    assert isinstance(collider, CapsuleCollider)
    before = dict(vars(collider))
    first = garment_sim.sim.state.bodies[0]
    for stamp, poses in frames[:3]:
        garment_sim.push(stamp, poses)
    assert vars(collider).keys() == before.keys()
    assert all(np.array_equal(vars(collider)[k], v) for k, v in before.items())
    pose = garment_sim.sim.state.bodies[0]
    assert isinstance(pose, CapsulePose)
    p0, p1, _ = garment_sim.avatar.capsules(frames[2][1])
    seg = garment_sim.segments
    np.testing.assert_array_equal(pose.p0, p0[seg])
    np.testing.assert_array_equal(pose.p1, p1[seg])
    assert not np.array_equal(pose.q0, pose.p0)  # the step's previous pose: the body moved
    assert not np.array_equal(first.p0, pose.p0)


def test_a_snapshot_is_the_state_and_the_control():
    """Restoring a snapshot and stepping again repeats the run bit for bit, the body's swept
    history included (it is in the snapshot's state)."""
    garment_sim, frames = _walking_skirt()
    for stamp, poses in frames[:3]:
        garment_sim.push(stamp, poses)
    snap = garment_sim.snapshot()
    assert set(vars(snap)) == {"state", "control", "poses", "stamp", "grippers"}
    for stamp, poses in frames[3:6]:
        garment_sim.push(stamp, poses)
    first = garment_sim.positions.copy()
    garment_sim.restore(snap)
    for stamp, poses in frames[3:6]:
        garment_sim.push(stamp, poses)
    assert np.array_equal(garment_sim.positions, first)
