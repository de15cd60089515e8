"""The capsule body collider: distances, clearance and the swept (continuous) tunnelling test."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.collision.capsules import (
    CapsuleCollider,
    PosedCapsules,
    capsule_clearance,
    capsules_within,
    segment_distances,
)
from cloth_mg_ros.collision.colliders import resolve_contacts

THICKNESS = 0.006


def _moving_capsule(start_y: float, end_y: float, radius: float = 0.05) -> PosedCapsules:
    """A vertical capsule (z from 0 to 0.5 m) that moves along y from start_y to end_y in one
    step of 1/30 s."""
    cap = CapsuleCollider(np.array([radius])).at()
    cap.set_pose(np.array([[0.0, start_y, 0.0]]), np.array([[0.0, start_y, 0.5]]))
    cap.set_pose(np.array([[0.0, end_y, 0.0]]), np.array([[0.0, end_y, 0.5]]), 1.0 / 30.0)
    return cap


def test_segment_distances_and_clearance():
    p0 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    p1 = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    pts = np.array([[0.3, 0.0, 0.5], [0.0, 0.0, 2.0], [0.5, 0.4, -0.3]])
    out = np.empty((3, 2))
    segment_distances(pts, p0, p1, out)
    expected = [[0.3, 0.7], [1.0, np.sqrt(2.0)], [np.hypot(0.5, 0.5), np.hypot(0.5, 0.5)]]
    assert np.allclose(out, expected)
    clear = capsule_clearance(pts, p0, p1, np.array([0.1, 0.2]))
    assert np.allclose(clear, [0.2, 0.5])
    assert np.all(capsule_clearance(np.zeros((0, 3)), p0, p1, np.ones(2)) == np.inf)


def test_capsules_within_reach_decide_as_the_clearance_does():
    """capsules_within(points, ..., reach) == (capsule_clearance(points, ...) <= reach) for
    a cloud of points and capsules near and far, with reaches on both sides of each
    capsule's clearance and exactly at it (the skipped chunks and the early stops change
    nothing)."""
    rng = np.random.default_rng(0)
    # a sheet-like cloud in horizontal bands, as a garment's particle order runs
    t = np.linspace(0.0, 1.0, 3000)
    pts = np.stack([np.cos(40 * t), np.sin(40 * t), 1.5 * t], axis=1) * [0.3, 0.3, 1.0]
    pts += 0.01 * rng.standard_normal(pts.shape)
    k = 12
    p0 = rng.uniform(-1.0, 1.0, (k, 3)) * [1.0, 1.0, 2.0]
    p1 = p0 + rng.uniform(-0.3, 0.3, (k, 3))
    radius = rng.uniform(0.02, 0.1, k)
    clear = capsule_clearance(pts, p0, p1, radius)
    for reach in (clear, np.nextafter(clear, -np.inf), clear - 0.05, clear + 0.05,
                  np.full(k, 0.1), np.full(k, -1.0)):
        assert np.array_equal(capsules_within(pts, p0, p1, radius, reach), clear <= reach)
    assert not capsules_within(np.zeros((0, 3)), p0, p1, radius, np.ones(k)).any()


def test_a_limb_that_sweeps_through_a_particle_sends_it_back_to_its_side():
    """A capsule of radius 5 cm moves 20 cm along +y in one step (a swinging shin at 30 Hz)
    clean through a particle: the particle ends 5 cm behind it, outside any margin, yet it is
    caught and sent back to the side it came from: the limb pushes it along, ahead of it."""
    cap = _moving_capsule(-0.10, 0.10)
    x_prev = np.array([[0.0, 0.0, 0.25]])  # 10 cm ahead of the axis (its +y side)
    x = x_prev.copy()  # the particle did not move; the limb passed over it
    c = cap.query(x, THICKNESS, x_prev)
    assert len(c) == 1
    assert np.allclose(c.normal[0], [0.0, 1.0, 0.0])  # back to its own side, +y
    assert c.distance[0] < -0.05
    v = np.zeros_like(x)
    resolve_contacts([cap], x, v, THICKNESS, x_prev)
    assert np.isclose(x[0, 1], 0.10 + 0.05 + THICKNESS, atol=1e-9)  # ahead of the limb
    assert v[0, 1] >= 6.0 - 1e-9  # and moving with it (0.2 m in 1/30 s)


def test_a_particle_passed_beside_the_limb_is_left_alone():
    """The swept test needs the particle's path relative to the capsule to cross it: a limb
    that passes 8 cm beside a particle (radius 5 cm) does not touch it."""
    cap = _moving_capsule(-0.10, 0.10)
    x = np.array([[0.08, 0.0, 0.25]])
    assert len(cap.query(x, THICKNESS, x.copy())) == 0


def test_without_history_only_nearby_particles_count():
    cap = _moving_capsule(-0.10, 0.10)
    x = np.array([[0.0, 0.0, 0.25], [0.0, 0.13, 0.25]])
    c = cap.query(x, THICKNESS)
    assert c.index.tolist() == [1]  # inside the capsule now; the particle behind it is not


def test_a_turning_limb_moves_its_surface_with_the_turn():
    """A capsule (radius 5 cm, 0.5 m long) turning about its lower end at 0.6 rad/s about -x:
    the contact's surface velocity is the turn's at the surface point, w x (s - pivot), not
    the axis point's (which misses w x r n: 3 cm/s along the axis here, the part friction
    drags the cloth with)."""
    r, h, theta = 0.05, 1.0 / 30.0, 0.02
    cap = CapsuleCollider(np.array([r])).at()
    cap.set_pose(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 0.5]]))
    top = 0.5 * np.array([0.0, np.sin(theta), np.cos(theta)])
    cap.set_pose(np.array([[0.0, 0.0, 0.0]]), top[None], h)
    axis = top / np.linalg.norm(top)
    side = np.array([0.0, np.cos(theta), -np.sin(theta)])  # outward, square to the axis
    x = (0.25 * axis + (r + 0.5 * THICKNESS) * side)[None]
    c = cap.query(x, THICKNESS)
    assert len(c) == 1
    w = np.array([-theta / h, 0.0, 0.0])
    centre = (0.25 * axis - np.array([0.0, 0.0, 0.25])) / h  # the axis point's, over the step
    np.testing.assert_allclose(c.velocity[0], centre + np.cross(w, r * side), atol=1e-9)
    assert abs(np.dot(c.velocity[0] - centre, axis)) == pytest.approx(theta / h * r)


def test_a_limb_that_swept_through_is_caught_inside_an_overlapping_one():
    """Two overlapping capsules, as a thigh's and a shin's at a knee: the particle ends 2 cm
    deep in the still one and 2 mm inside the one that swept 20 cm through it. The sweep
    decides: it goes back to the side it came from, ahead of the moving limb, not out of the
    still one on the moving limb's far side."""
    cap = CapsuleCollider(np.array([0.05, 0.05])).at()
    still = ([0.03, 0.052, 0.0], [0.03, 0.052, 0.5])
    cap.set_pose(np.array([still[0], [0.0, -0.10, 0.0]]), np.array([still[1], [0.0, -0.10, 0.5]]))
    cap.set_pose(np.array([still[0], [0.0, 0.10, 0.0]]), np.array([still[1], [0.0, 0.10, 0.5]]),
                 1.0 / 30.0)
    x_prev = np.array([[0.0, 0.0, 0.25]])  # 10 cm ahead of the moving axis (+y)
    x = np.array([[0.0, 0.052, 0.25]])  # 4.8 cm behind it now
    c = cap.query(x, THICKNESS, x_prev)
    assert c.part.tolist() == [1]
    np.testing.assert_allclose(c.normal[0], [0.0, 1.0, 0.0], atol=1e-12)
    assert c.distance[0] < -0.09  # through the moving limb to its front
    plain = cap.query(x, THICKNESS)  # without the history: the deeper, still capsule
    assert plain.part.tolist() == [0]
