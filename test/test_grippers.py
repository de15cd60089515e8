"""Grippers that hold cloth (sim.grippers) and the forces of contact (sim.loads), checked
against physics: the weight a sheet's grippers carry, the torque of an off-centre grasp, a
released sheet's fall, the momentum balance of a pull across a body, and bad input."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from cloth_mg_ros.collision.colliders import SphereCollider
from cloth_mg_ros.config import schema
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.grippers import GripperScript, GripperSet, play_scripts, step_held
from cloth_mg_ros.sim.model import GRAVITY
from cloth_mg_ros.sim.sheets import SHEET_SIZE, build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

G = float(-GRAVITY[2])


def _sim(scene, scheme: str = "bdf2", solver: str = "direct") -> Simulator:
    return Simulator(scene.model, scene.state,
                     make_solver(solver, tol=1e-10, hierarchy=scene.hierarchy,
                                 bending=scene.model.bending),
                     dt=1.0 / 60.0, scheme=scheme, track_constraint_forces=True)


def _settled_hang(particles: int = 300):
    scene = build_scene("hang", particles, get_material("cotton"))
    sim = _sim(scene)
    for _ in range(480):  # 8 s: the swing has died down
        step_held(sim, scene.grippers)
    return scene, sim


def test_the_hangs_grippers_carry_its_weight_and_letting_go_drops_the_wrench_then_the_sheet():
    scene, sim = _settled_hang()
    grippers = scene.grippers
    weight = float(sim.model.mass.sum()) * G
    forces = {n: np.array(w["force"]) for n, w in grippers.wrenches().items()}
    total = forces["left"] + forces["right"]
    # the cloth pulls the grippers down with its weight, each holding half
    assert np.linalg.norm(total - np.array([0.0, 0.0, -weight])) < 0.005 * weight
    assert forces["left"][2] == pytest.approx(forces["right"][2], rel=0.01)
    assert forces["left"][0] > 0.0 > forces["right"][0]  # and inwards, towards each other
    assert grippers.release("right") == 1
    step_held(sim, grippers)
    assert grippers.wrenches()["right"] == {"force": [0.0, 0.0, 0.0], "torque": [0.0, 0.0, 0.0]}
    assert np.linalg.norm(grippers.wrenches()["left"]["force"]) > 0.5 * weight
    for _ in range(120):  # the sheet swings on one corner until it hangs from it
        step_held(sim, grippers)
    assert grippers.release("left") == 1
    assert len(sim.control.pins(sim.model)) == 1  # until the next step
    step_held(sim, grippers)
    assert len(sim.control.pins(sim.model)) == 0


def test_a_released_sheet_falls_at_g():
    """Released at rest, the centre of mass accelerates at g less the air's drag on it
    (mass-proportional, so it acts on the centre of mass alone): the acceleration is measured
    from the centre of mass's velocity after BDF2's start (its velocity history restarts at
    rest, which delays the first steps by half a step's gravity, a constant offset)."""
    scene, sim = _settled_hang()
    m = sim.model.mass
    for name in ("left", "right"):
        scene.grippers.release(name)
    speeds, times = [], []
    for _ in range(30):
        step_held(sim, scene.grippers)
        speeds.append(float(m @ sim.state.v[:, 2] / m.sum()))
        times.append(sim.state.t)
    v, t = np.array(speeds), np.array(times)
    alpha = sim.model.material.air_drag
    accel = np.diff(v[5:]) / np.diff(t[5:])  # after the start-up (3^-5 of it is left)
    expected = -G - alpha * 0.5 * (v[5:-1] + v[6:])
    assert np.mean(accel) == pytest.approx(np.mean(expected), rel=0.01)
    assert np.mean(accel) == pytest.approx(-G, rel=0.02)  # drag is small over half a second


def test_an_off_centre_grasp_feels_the_moment_of_the_weight():
    """One gripper at the sheet's left corner holds its whole top edge: at rest it carries
    the weight, and its torque about the grasp point is the weight's moment about it."""
    scene = build_scene("hang", 300, get_material("cotton"))
    x = scene.state.x
    top = np.flatnonzero(x[:, 2] > x[:, 2].max() - 1e-9)
    corner = x[top[np.argmin(x[top, 0])]]
    grippers = GripperSet(["clamp"])
    grippers.set_pose("clamp", corner)
    grippers.hold("clamp", top, x)
    sim = _sim(replace(scene, model=replace(scene.model, pinned=top)))
    for _ in range(240):
        step_held(sim, grippers)
    wrench = grippers.wrenches()["clamp"]
    m, xs = sim.model.mass, sim.state.x
    weight = m.sum() * GRAVITY
    moment = np.cross(xs - corner, m[:, None] * GRAVITY).sum(axis=0)
    assert np.linalg.norm(np.array(wrench["force"]) - weight) < 0.005 * np.linalg.norm(weight)
    assert np.linalg.norm(np.array(wrench["torque"]) - moment) < 0.01 * np.linalg.norm(moment)
    assert abs(moment[1]) > 0.1  # the grasp is far off the centre: a real moment


def test_the_cloths_momentum_changes_by_the_grippers_gravity_and_the_body_pull_by_pull():
    """Two grippers drag a sheet sideways across a sphere, with friction: every step, the
    cloth's momentum changes by dt (the grippers' holding forces + gravity - the forces the
    cloth puts on the sphere), penalty and projection alike, to the solver's precision; and
    over the whole pull within 1e-6 of the impulses. Air drag is off, so nothing else acts."""
    scene = build_scene("hang", 300, get_material("cotton", air_drag=0.0))
    sphere = SphereCollider(np.array([0.3, 0.12, 0.85]), 0.2, friction=0.5)
    scene.model.colliders.append(sphere)
    sim = _sim(scene, "euler")
    sim.track_contact_forces = True
    grippers = scene.grippers
    m = sim.model.mass[:, None]
    weight = sim.model.mass.sum() * GRAVITY
    start = {n: grippers.gripper(n).position.copy() for n in grippers.names}
    touched, total_dp, total_impulse = 0, np.zeros(3), np.zeros(3)
    for k in range(1, 91):
        t = k * sim.dt
        for name in grippers.names:
            grippers.set_pose(name, start[name] + np.array([0.6 * t * t, 0.25 * t, 0.0]))
        before = sim.state
        step_held(sim, grippers)
        dp = (m * (sim.state.v - before.v)).sum(axis=0)
        held = sum(np.array(w["force"]) for w in grippers.wrenches().values())
        impulse = sim.dt * (-held + weight - sim.contact_load.total())
        assert np.allclose(dp, impulse, rtol=0.0, atol=1e-8 * np.abs(impulse).max()), k
        touched += len(sim.contact_load) > 0
        total_dp += dp
        total_impulse += impulse
    assert touched > 30  # the sheet was pulled across the sphere for most of the pull
    assert np.linalg.norm(total_dp - total_impulse) < 1e-6 * np.linalg.norm(total_impulse)
    on_sphere = sim.contact_load.per_part(1, 1)[0]
    assert np.allclose(on_sphere, sim.contact_load.total())


def test_release_force_lets_go_by_itself_and_counts():
    scene = build_scene("hang", 200, get_material("cotton"))
    grippers = GripperSet(["left", "right"], release_force=0.5)
    x = scene.state.x
    for name, corner in zip(("left", "right"), scene.model.pinned, strict=True):
        grippers.set_pose(name, x[corner])
        grippers.hold(name, [corner], x)
    sim = _sim(scene)
    released = []
    right = grippers.gripper("right").position.copy()
    for k in range(1, 60):
        grippers.set_pose("right", right + np.array([0.01 * k, 0.0, 0.0]))  # stretch it
        released += step_held(sim, grippers)[1]
        if released:
            break
    assert released == ["right"] or released == ["left"] or sorted(released) == ["left",
                                                                                 "right"]
    g = grippers.gripper(released[0])
    assert g.auto_releases == 1 and len(g.held) == 0 and not np.any(g.force)


def test_grasp_takes_free_particles_in_reach_and_holds_them_rigidly_in_the_grippers_frame():
    scene = build_scene("hang", 300, get_material("cotton"))
    x = scene.state.x
    corners = scene.model.pinned.copy()
    grippers = GripperSet(["hand"], grasp_radius=0.06, base_pins=corners)
    centre = x.mean(axis=0)
    grippers.set_pose("hand", centre)
    count = grippers.grasp("hand", x)
    near = np.linalg.norm(x - centre, axis=1) <= 0.06
    assert count == near.sum() > 1
    assert grippers.grasp("hand", x) == count  # grasping again takes nothing new
    sim = _sim(scene)
    turn = np.array([0.0, 0.0, np.sin(0.25), np.cos(0.25)])  # 0.5 rad about z
    for k in range(1, 31):
        grippers.set_pose("hand", centre + np.array([0.0, 0.01 * k, 0.02 * k]), turn)
        step_held(sim, grippers)
    g = grippers.gripper("hand")
    p, rot = g.pose_at(1.0)
    assert np.array_equal(sim.state.x[g.held], p + g.offsets @ rot.T)  # no slip at all
    # the corners the model pins are never taken by a grasp
    grippers.end_interval()
    grippers.set_pose("hand", sim.state.x[corners[0]])
    grippers.end_interval()
    assert grippers.grasp("hand", sim.state.x) > count
    assert not np.isin(corners, grippers.held()).any()


def test_bad_gripper_input_gets_a_clear_error():
    grippers = GripperSet(["left"])
    with pytest.raises(ClothInputError, match="unknown gripper 'right'; grippers: left"):
        grippers.set_pose("right", [0.0, 0.0, 1.0])
    with pytest.raises(ClothInputError, match="position must be finite"):
        grippers.set_pose("left", [np.nan, 0.0, 1.0])
    with pytest.raises(ClothInputError, match="unit quaternion"):
        grippers.set_pose("left", [0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ClothInputError, match="has no pose yet"):
        grippers.grasp("left", np.zeros((4, 3)))
    grippers.set_pose("left", [5.0, 5.0, 5.0])
    assert grippers.grasp("left", np.zeros((4, 3))) == 0  # nothing in reach: holds nothing
    with pytest.raises(ClothInputError, match="unique"):
        GripperSet(["a", "a"])
    with pytest.raises(ClothInputError, match="path times must increase"):
        GripperScript("a", [[0.0, 0, 0, 1], [0.0, 0, 0, 2]])


def test_a_script_moves_its_gripper_and_grasps_and_releases_on_time():
    script = GripperScript("cuff", [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0], grasp=(0.5,),
                           release=(0.75,))
    assert np.allclose(script.position(0.25), [0.25, 0.0, 1.0])
    assert np.allclose(script.position(2.0), [1.0, 0.0, 1.0])
    grippers = GripperSet(["cuff"], grasp_radius=0.1)
    x = np.array([[0.5, 0.0, 1.0], [0.0, 0.0, 0.0]])
    assert play_scripts(grippers, [script], 0.0, 0.25, x) == []
    grippers.end_interval()
    assert play_scripts(grippers, [script], 0.25, 0.5, x) == []
    grippers.end_interval()
    assert play_scripts(grippers, [script], 0.5, 0.75, x) == [("cuff", "grasp", 1)]
    grippers.end_interval()
    assert play_scripts(grippers, [script], 0.75, 1.0, x) == [("cuff", "release", 1)]


def test_a_scene_file_declares_scripted_grippers(tmp_path):
    from cloth_mg_ros.config.scenes import gripper_scripts, load_scene

    good = tmp_path / "pull.yaml"
    good.write_text("/**:\n  ros__parameters:\n    bag: walk\n    garment: skirt\n"
                    "    grippers: [hem]\n    script:\n      hem:\n"
                    "        path: [0.0, 0.0, 0.0, 1.0, 1.0, 0.1, 0.0, 1.0]\n"
                    "        grasp: [0.0]\n")
    assert load_scene(str(good)).grippers == ("hem",)
    (script,) = gripper_scripts(str(good))
    assert script.name == "hem" and script.grasp == (0.0,) and script.path.shape == (2, 4)
    bad = tmp_path / "bad.yaml"
    bad.write_text(good.read_text().replace("      hem:", "      cuff:"))
    with pytest.raises(ClothInputError, match=r"bad.yaml: script.cuff: no gripper 'cuff'"):
        load_scene(str(bad))
    bad.write_text(good.read_text().replace("1.0, 0.1, 0.0, 1.0]", "0.0, 0.1, 0.0, 1.0]"))
    with pytest.raises(ClothInputError, match=r"script.hem: .*path times must increase"):
        load_scene(str(bad))


def test_run_hang_writes_the_gripper_wrenches_and_the_mass(tmp_path, capsys):
    from cloth_mg_ros.cli.main import main

    assert main(["run", "--scene", "hang", "--particles", "200", "--steps", "30",
                 "--out", str(tmp_path), "--no-progress", "--frames", "2"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["grippers"] == ["left", "right"]
    # the sheet scenes' default fabric over their 1 m square
    fabric = get_material(schema.PARAMETERS["material"].default_for(False))
    assert summary["mass_kg"] == pytest.approx(fabric.density * SHEET_SIZE ** 2, rel=1e-9)
    last = summary["steps"][-1]["gripper_wrenches"]
    assert set(last) == {"left", "right"} and last["left"]["force"][2] < 0.0
    assert "against the cloth's weight" in capsys.readouterr().out


def test_a_scripted_gripper_lifts_a_skirts_hem_and_the_legs_feel_a_walking_skirt():
    """A gripper grasps the front of a skirt's hem on a standing body and lifts it: it feels
    the pull and the held particles stay exactly where its frame puts them; a skirt on a walking
    body reports the force on the legs that swing into it, per segment, every tick."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.sim.garment_sim import GarmentSim

    avatar = Avatar.load()
    walk = read_pose_frames(resolve_bag("walk"))[:40]
    still = [(walk[0][0] + k / 30.0, walk[0][1]) for k in range(16)]
    fabric = get_material("white-dots-on-blk")
    options = schema.body_options(garment="skirt", particles=500, grippers=("hem",),
                             grasp_radius=0.04)
    garment_sim = GarmentSim.dress(avatar, still[0][0], still[0][1], fabric, options)
    x = garment_sim.positions
    low = np.flatnonzero(x[:, 2] < x[:, 2].min() + 0.01)
    front = x[low[np.argmax(x[low, 0])]]
    garment_sim.scripts = [GripperScript("hem", [[0.0, *front], [0.4, *(front + [0, 0, 0.1])]],
                                         grasp=(0.0,))]
    for stamp, poses in still[1:]:
        stats = garment_sim.push(stamp, poses)
    g = garment_sim.grippers.gripper("hem")
    force = np.array(stats.gripper_wrenches["hem"]["force"])
    assert len(g.held) >= 1 and np.all(np.isfinite(force)) and np.linalg.norm(force) > 1e-3
    p, rot = g.pose_at(1.0)
    assert np.array_equal(garment_sim.positions[g.held], p + g.offsets @ rot.T)
    colliding = {avatar.names[i] for i in garment_sim.segments}
    assert set(stats.body_forces) == colliding == set(stats.body_torques)

    walking = GarmentSim.dress(avatar, walk[0][0], walk[0][1], fabric,
                               schema.body_options(garment="skirt", particles=500))
    peaks = [walking.push(stamp, poses) for stamp, poses in walk[1:]]
    legs = [t for t in peaks if t.contact_peak_n > 0.0]
    assert legs and all(t.contact_peak_segment.startswith(("upper_leg", "lower_leg", "lower_torso",
                                                           "pelvis")) for t in legs)
    hit = max(legs, key=lambda t: t.contact_peak_n)
    assert np.linalg.norm(hit.body_forces[hit.contact_peak_segment]) == hit.contact_peak_n


def test_a_coarser_rung_keeps_the_held_particles_it_has_or_the_nearest():
    """A coarser level of detail keeps the first n particles of the finer one (sim.detail):
    a gripper keeps those it held, or holds the coarse particle nearest its grasp point."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.02, 0.0, 0.0],
                  [0.9, 0.0, 0.0]])
    grippers = GripperSet(["a", "b"], grasp_radius=0.05)
    grippers.set_pose("a", [0.0, 0.0, 0.0])
    grippers.set_pose("b", [0.9, 0.0, 0.0])
    assert grippers.grasp("a", x) == 2 and grippers.grasp("b", x) == 1
    grippers.restrict(3, x)
    assert grippers.gripper("a").held.tolist() == [0]  # kept the one of the coarse rung
    assert grippers.gripper("b").held.tolist() == [1]  # none left: the nearest coarse one
    assert np.allclose(grippers.gripper("b").targets(1.0), [[1.0, 0.0, 0.0]])


def test_a_standing_body_carries_its_dress_through_seams_and_contacts():
    """A dress settled on a standing body: what the body carries, the seams' forces at the
    shoulders plus the contact forces on every segment, averaged over the third second, is
    the dress's weight less its momentum's rate of change over that second, within 1 %.
    (A single tick's loads are not: the hem still sways by a percent or two of the weight,
    and at which phase a given tick falls depends on the last bits of the solves.)"""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.sim.garment_sim import GarmentSim

    first = read_pose_frames(resolve_bag("walk"))[0]
    garment_sim = GarmentSim.dress(Avatar.load(), first[0], first[1],
                                   get_material("white-dots-on-blk"),
                                   schema.body_options(garment="dress", particles=600))
    mass = garment_sim.sim.model.mass

    def momentum():
        return (mass[:, None] * garment_sim.sim.state.v).sum(axis=0)

    for k in range(1, 61):  # 2 s standing
        garment_sim.push(first[0] + k / 30.0, first[1])
    before, loads = momentum(), []
    for k in range(61, 91):  # the third second
        stats = garment_sim.push(first[0] + k / 30.0, first[1])
        assert set(stats.seam_forces) == {"upper_torso"}
        loads.append(sum(np.array(f) for f in stats.seam_forces.values())
                     + sum(np.array(f) for f in stats.body_forces.values()))
    rate = (momentum() - before) / 1.0  # N, over the second
    carried = np.mean(loads, axis=0)
    weight = garment_sim.mass_kg * GRAVITY
    assert np.linalg.norm(carried + rate - weight) < 0.01 * np.linalg.norm(weight)
