"""Garments worn on the capsule avatar replaying the bundled motion-capture bags."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.config import schema
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.frames import FrameStatus
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.body_poses import pin_positions
from cloth_mg_ros.sim.garment_sim import GarmentSim

PARTICLES = 500


@pytest.fixture(scope="module")
def avatar():
    return Avatar.load()


def _dress(avatar, frames, garment):
    return GarmentSim.dress(avatar, frames[0][0], frames[0][1], get_material("cotton"),
                            schema.body_options(garment=garment, particles=PARTICLES))


@pytest.mark.parametrize("bag", ["walk", "run"])
@pytest.mark.parametrize("garment", ["skirt", "dress", "cape", "top"])
def test_garment_stays_on_the_moving_body(avatar, bag, garment):
    frames = read_pose_frames(bundled_bag(bag))
    garment_sim = _dress(avatar, frames, garment)
    model = garment_sim.sim.model
    for stamp, poses in frames[1:]:
        stats = garment_sim.push(stamp, poses)
        assert not isinstance(stats, FrameStatus), stats
        assert np.all(np.isfinite(garment_sim.positions))
        assert stats.max_penetration < 0.005  # after each step, pinned vertices excluded
        # Pins held: the sewn vertices are exactly where the body carries them.
        target = pin_positions(garment_sim.poses, garment_sim.pin_segments, garment_sim.pin_offsets)
        assert np.allclose(garment_sim.positions[model.pinned], target, atol=1e-9)
    # Still on the body at the end: around the pelvis, above the floor, not torn.
    pelvis = garment_sim.poses[0, :3]
    horizontal = np.linalg.norm(garment_sim.positions[:, :2] - pelvis[:2], axis=1)
    assert horizontal.max() < 0.9
    assert garment_sim.positions[:, 2].min() > 0.0
    assert garment_sim.positions[:, 2].max() < pelvis[2] + 0.7
    edges = model.mesh.edges
    x = garment_sim.positions
    stretch = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1) / model.edge_rest
    # The top is dressed on a neutral pose and its snug torso is stretched by the walk's
    # twist of chest against pelvis (a known limitation, see the issue notes); the others
    # stay close to their rest lengths: nearly every edge within the strain limit (1.1), and
    # none torn. (A single edge where a hem wraps a swinging thigh can stand at 1.2-1.3 for a
    # tick, the contact projection pushing its ends apart; which tick that is depends on the
    # trajectory, so the final frame's worst edge is bounded loosely. The top's worst edge at
    # the end of the walk was 1.94 / 1.83 / 1.47 / 1.65 at 450 / 500 / 550 / 700 particles with
    # the hinge-only bending, 1.69 / 2.20 / 1.46 / 1.57 with today's: the same spread, one
    # unlucky size each; its 99th percentile, 1.25-1.8, is what the twist does.)
    if garment == "top":
        assert np.percentile(stretch, 99) < 2.0 and stretch.max() < 3.0
    else:
        assert np.percentile(stretch, 99) < 1.1 and stretch.max() < 1.5
    assert not garment_sim.rejected


def test_bad_frames_are_skipped_or_repaired(avatar):
    frames = read_pose_frames(bundled_bag("walk"))
    garment_sim = _dress(avatar, frames, "skirt")
    stamp, poses = frames[40]
    assert not isinstance(garment_sim.push(stamp, poses), FrameStatus)
    nan = poses.copy()
    nan[3, 1] = np.nan
    inf = poses.copy()
    inf[0, 6] = np.inf
    assert garment_sim.push(stamp + 0.03, nan) == FrameStatus.NON_FINITE
    assert garment_sim.push(stamp + 0.03, inf) == FrameStatus.NON_FINITE
    assert garment_sim.push(stamp + 0.03, poses[:10]) == FrameStatus.WRONG_COUNT
    assert garment_sim.push(stamp + 0.03, np.zeros((0, 7))) == FrameStatus.EMPTY
    assert garment_sim.push(stamp - 0.5, poses) == FrameStatus.STAMP_BACKWARDS
    # A teleport of 3 m: the garment is carried along with the body, not left behind.
    jumped = poses.copy()
    jumped[:, 0] += 3.0
    before = garment_sim.positions.mean(axis=0)
    assert garment_sim.push(stamp + 0.033, jumped) == FrameStatus.TELEPORT
    assert garment_sim.positions.mean(axis=0)[0] == pytest.approx(before[0] + 3.0, abs=1e-6)
    # And the run goes on from there.
    moved = jumped.copy()
    moved[:, 0] += 0.02
    stats = garment_sim.push(stamp + 0.066, moved)
    assert not isinstance(stats, FrameStatus)
    assert np.all(np.isfinite(garment_sim.positions))
    assert garment_sim.rejected == {"non_finite": 2, "wrong_count": 1, "empty": 1,
                           "stamp_backwards": 1, "teleport": 1}


def test_headless_body_run_writes_ticks(tmp_path, capsys):
    out = tmp_path / "walk"
    # the dress: its tolerance auto calibration is the one other tests of the walk share
    code = main(["run", "--scene", "walk", "--bag", str(bundled_bag("walk")), "--garment",
                 "dress", "--particles", "400", "--steps", "40", "--no-progress", "--frames",
                 "2", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["garment"] == "dress" and len(summary["ticks"]) == 40
    for tick in summary["ticks"]:
        for key in ("total_ms", "solve_ms", "iterations", "max_penetration", "contacts"):
            assert np.isfinite(tick[key])
        assert tick["contact_pull_n"] >= 0.0
    pulls = [t["contact_pull_n"] for t in summary["ticks"]]
    assert summary["contact_pull_max_n"] == max(pulls)
    assert summary["contact_pull_p95_n"] == np.percentile(pulls, 95)
    assert (out / "frames.png").is_file()
    printed = capsys.readouterr().out
    assert "median tick" in printed and "penalties pulling the cloth" in printed


def test_scene_files_declare_only_what_they_need():
    for name in ("walking", "brisk_walking", "running", "jumping"):
        params = load_scene(name)
        assert params.scene == name
        assert bundled_bag(params.bag).exists()
    assert load_scene("walk").scene == "walking"


@pytest.mark.parametrize("content, message", [
    ("cloth_node:\n  ros__parameters:\n    garment: dress\n    wings: 3\n", "unknown parameter"),
    ("cloth_node:\n  ros__parameters:\n    particles: many\n", "particles must be an integer"),
    ("cloth_node:\n  ros__parameters:\n    tolerance: -1.0\n",
     "tolerance must be a relative residual"),
    ("cloth_node:\n  ros__parameters:\n    tolerance: fast\n", "or .auto., got .fast."),
    ("something: else\n", "ros__parameters"),
    ("cloth_node: [unclosed\n", "not readable YAML"),
])
def test_bad_scene_files(tmp_path, content, message):
    path = tmp_path / "scene.yaml"
    path.write_text(content)
    with pytest.raises(ClothInputError, match=message):
        load_scene(str(path))


@pytest.mark.parametrize("args, message", [
    (["--scene", "walk", "--garment", "kilt"], "unknown garment 'kilt'"),
    (["--scene", "walk", "--bag", "/nonexistent/bag"], "/nonexistent/bag"),
    (["--scene", "moonwalk"], "unknown scene 'moonwalk'"),
    (["--scene", "drape", "--garment", "dress"], "--garment is for body scenes"),
])
def test_bad_body_run_input(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    code = main(["run", *args, "--particles", "300", "--no-progress", "--out", str(out)])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_only_capsules_that_can_reach_the_cloth_shorten_the_step(avatar):
    """The step rule counts the travel of capsules that can reach the cloth during the tick:
    the head above a skirt may move 30 cm without a shorter step, the legs inside it may
    not; and no step is longer than max_step."""
    frames = read_pose_frames(bundled_bag("walk"))
    garment_sim = _dress(avatar, frames, "skirt")
    o = garment_sim.options
    now = garment_sim.poses
    head = now.copy()
    head[avatar.names.index("head"), 0] += 0.3
    assert garment_sim.step_count([now, head], 1.0 / 30.0) == o.substeps
    legs = now.copy()
    for name in ("upper_leg_l", "lower_leg_l"):
        legs[avatar.names.index(name), 0] += 0.3
    assert garment_sim.step_count([now, legs],
                                  1.0 / 30.0) == int(np.ceil(0.3 / o.max_substep_motion))
    # A tick that coalesces pose intervals takes as many steps as the liveliest interval
    # alone: legs out 15 cm and back, two intervals, make no more steps than 15 cm in one.
    half = now.copy()
    for name in ("upper_leg_l", "lower_leg_l"):
        half[avatar.names.index(name), 0] += 0.15
    assert garment_sim.step_count([now, half, now], 1.0 / 15.0) == \
        garment_sim.step_count([now, half], 1 / 30)
    assert garment_sim.step_count([now, half], 1 / 30) == int(np.ceil(0.15 / o.max_substep_motion))
    assert garment_sim.step_count([now, now], 0.25) == int(np.ceil(0.25 / o.max_step))


@pytest.mark.parametrize("garment", ["dress", "skirt"])
def test_coalesced_ticks_follow_every_key_pose_and_stay_out_of_the_body(avatar, garment):
    """A live node that fell behind advances through three pose messages at once (a 1/10 s
    tick, its steps following the body along all three): the cloth stays finite and out of
    the body, and each tick ends at the newest key pose."""
    frames = read_pose_frames(bundled_bag("walk"))
    garment_sim = _dress(avatar, frames, garment)
    todo = frames[1:]
    for k in range(0, len(todo) - 2, 3):
        keys = todo[k:k + 3]
        stats = garment_sim.advance(keys)
        assert stats.poses == 3 and stats.stamp == keys[-1][0]
        assert stats.simulated_s == pytest.approx(keys[-1][0] - todo[k - 1][0] if k else
                                                  keys[-1][0] - frames[0][0])
        assert stats.substeps >= int(np.ceil(stats.simulated_s / garment_sim.options.max_step -
        1e-9))
        assert np.array_equal(garment_sim.poses, keys[-1][1])
        assert np.all(np.isfinite(garment_sim.positions))
        assert stats.max_penetration < 0.005
    target = pin_positions(garment_sim.poses, garment_sim.pin_segments, garment_sim.pin_offsets)
    assert np.allclose(garment_sim.positions[garment_sim.sim.model.pinned], target, atol=1e-9)


def test_advance_rejects_stamps_that_do_not_increase(avatar):
    frames = read_pose_frames(bundled_bag("walk"))
    garment_sim = _dress(avatar, frames, "skirt")
    with pytest.raises(ValueError, match="increase"):
        garment_sim.advance([frames[2], frames[1]])
    with pytest.raises(ValueError, match="at least one"):
        garment_sim.advance([])
