"""Segments a tracker lost leave the collider per key pose (sim.dropped_segments): within a
tick that follows several key poses, each step takes the mask of the key pose that ends the
key interval it lies in, so a segment is out only while the body moves toward a pose that
lost it."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.config import schema
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.body_poses import blend_poses, key_fractions, key_interval, pose_on_path
from cloth_mg_ros.sim.garment_sim import GarmentSim
from cloth_mg_ros.sim.tick_stats import BODY_COLLIDER


@pytest.fixture(scope="module")
def walk():
    avatar = Avatar.load()
    frames = read_pose_frames(bundled_bag("walk"))
    return avatar, frames


def _dress(avatar, frames) -> GarmentSim:
    return GarmentSim.dress(avatar, frames[0][0], frames[0][1], get_material("cotton"),
                            schema.body_options(garment="dress", particles=300, threads=1,
                                                substeps=6, self_contact=False))


def _record_steps(garment_sim: GarmentSim, shin: int) -> list[bool]:
    """Wrap the simulator's step: whether the capsule at `shin` (an index into the colliding
    segments) collides, per step."""
    sim, out = garment_sim.sim, []
    step = sim.step

    def recording_step():
        ends = sim.control.collider_poses[BODY_COLLIDER]
        out.append(len(ends) == 2 or bool(ends[2][shin]))
        return step()

    sim.step = recording_step
    return out


def _steps_toward(stamps: np.ndarray, steps: int) -> list[int]:
    """The key (1..K-1) each of `steps` even steps along `stamps` moves toward."""
    return [key_interval(stamps, k / steps) for k in range(1, steps + 1)]


@pytest.mark.parametrize("lost_in", [0, 2])
def test_a_segment_leaves_the_collider_only_toward_the_keys_that_lost_it(walk, lost_in):
    """Three keys in one tick, the left shin dropped in key `lost_in` only: the steps toward
    that key leave it out, every other step has it colliding (the old rule, the union of the
    tick's masks, left it out for the whole tick); `dropped` is the last key's after."""
    avatar, frames = walk
    garment_sim = _dress(avatar, frames)
    shin_segment = avatar.names.index("lower_leg_l")
    shin = int(np.flatnonzero(garment_sim.segments == shin_segment)[0])
    keys = frames[1:4]
    lost = np.zeros(avatar.num_segments, bool)
    lost[shin_segment] = True
    masks = [lost if i == lost_in else None for i in range(3)]
    colliding = _record_steps(garment_sim, shin)
    stats = garment_sim.advance(keys, masks)
    stamps = np.array([frames[0][0]] + [st for st, _ in keys])
    toward = _steps_toward(stamps, stats.substeps)
    assert len(colliding) == stats.substeps >= 3
    assert set(toward) == {1, 2, 3}  # every key interval has steps
    assert colliding == [t != lost_in + 1 for t in toward]
    assert (garment_sim.dropped is None) == (lost_in != 2)
    assert np.all(np.isfinite(garment_sim.positions))


def test_keys_that_share_a_mask_step_as_set_dropped_does(walk):
    """A tick whose keys all lose the same segments computes what set_dropped and a tick
    without masks do, bit for bit (the node's old rule for such ticks)."""
    avatar, frames = walk
    lost = np.zeros(avatar.num_segments, bool)
    lost[avatar.names.index("lower_leg_r")] = True
    a, b = _dress(avatar, frames), _dress(avatar, frames)
    b.set_dropped(lost)
    for k in (1, 4):
        a.advance(frames[k:k + 3], [lost] * 3)
        b.advance(frames[k:k + 3])
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.velocities, b.velocities)
    assert np.array_equal(a.dropped, b.dropped)


def test_masks_must_match_the_keys(walk):
    avatar, frames = walk
    garment_sim = _dress(avatar, frames)
    with pytest.raises(ValueError, match="one dropped mask per key"):
        garment_sim.advance(frames[1:3], [None])


@pytest.mark.parametrize("stamps", [[0.0, 0.1], [0.0, 0.03, 0.1], [1.0, 1.25, 1.5, 1.75, 2.0],
                                    [0.0, 1 / 30, 2 / 30, 3 / 30]])
@pytest.mark.parametrize("steps", [1, 2, 3, 4, 6, 7, 12])
def test_a_steps_key_interval_holds_its_pose(walk, stamps, steps):
    """key_interval and pose_on_path agree: each step's pose lies on the key interval its
    mask is taken from (blended from that interval's start key to its end key)."""
    avatar, frames = walk
    path = [p for _, p in frames[:len(stamps)]]
    stamps = np.array(stamps)
    tau = key_fractions(stamps)
    for k in range(1, steps + 1):
        u = k / steps
        i = key_interval(stamps, u)
        assert tau[i - 1] < u <= tau[i] + 1e-12
        w = (u - tau[i - 1]) / (tau[i] - tau[i - 1])
        assert np.allclose(pose_on_path(stamps, path, u), blend_poses(path[i - 1], path[i], w),
                           atol=1e-12)


def test_the_key_fractions_are_the_stamps_times(walk):
    """Written out, not from the library: keys at 0, 0.03 and 0.1 s lie at 0, 0.3 and 1 of
    the tick; a step ending at 0.3 of it reaches the second key, at 0.65 it is half way from
    the second to the third, and its mask is the third key's."""
    _, frames = walk
    stamps = np.array([0.0, 0.03, 0.1])
    path = [p for _, p in frames[:3]]
    np.testing.assert_allclose(key_fractions(stamps), [0.0, 0.3, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(key_fractions(stamps + 7.0), [0.0, 0.3, 1.0], atol=1e-12)
    assert [key_interval(stamps, u) for u in (0.1, 0.3, 0.31, 0.65, 1.0)] == [1, 1, 2, 2, 2]
    assert np.allclose(pose_on_path(stamps, path, 0.3), path[1], atol=1e-12)
    assert np.allclose(pose_on_path(stamps, path, 0.15), blend_poses(path[0], path[1], 0.5),
                       atol=1e-12)
    assert np.allclose(pose_on_path(stamps, path, 0.65), blend_poses(path[1], path[2], 0.5),
                       atol=1e-12)
