"""Cloth edges against capsules (collision.edge_contact): a limb that would pass between two
particles pushes the edge out instead, and the push is counted as a force on the limb."""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.collision.capsules import CapsuleCollider, PosedCapsules
from cloth_mg_ros.collision.colliders import ContactImpulses, penetration
from cloth_mg_ros.collision.edge_contact import edges_then_particles, resolve_edge_contacts

THICKNESS = 0.006


def _finger() -> PosedCapsules:
    """A still capsule along x, radius 2 cm, its axis through the origin."""
    cap = CapsuleCollider(np.array([0.02])).at()
    cap.set_pose(np.array([[-0.1, 0.0, 0.0]]), np.array([[0.1, 0.0, 0.0]]))
    return cap


def test_an_edge_across_a_finger_is_pushed_out_and_stops_going_in():
    # two particles outside the finger on either side, the edge between them through it
    x = np.array([[0.0, -0.03, 0.005], [0.0, 0.03, 0.005], [0.5, 0.5, 0.5]])
    v = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])
    impulses = ContactImpulses.new()
    assert resolve_edge_contacts(_finger(), x, v, np.array([[0, 1], [1, 2]]), THICKNESS,
                                 impulses=impulses, which=3) >= 1
    mid = 0.5 * (x[0] + x[1])
    assert np.linalg.norm(mid[1:]) >= 0.02 + 0.5 * THICKNESS - 1e-12  # out, above the axis
    assert np.allclose(x[0, :2], [0.0, -0.03]) and np.allclose(x[1, :2], [0.0, 0.03])
    assert v[0, 2] >= 0.0 and v[1, 2] >= 0.0  # no longer moving into the finger
    index, dv, part, collider = impulses.arrays()
    assert set(index.tolist()) == {0, 1} and np.all(collider == 3) and np.all(part == 0)
    assert np.allclose(dv.sum(axis=0), [0.0, 0.0, 2.0])  # the momentum the finger gave


def test_a_pinned_end_stays_and_the_free_end_takes_the_push():
    x = np.array([[0.0, -0.03, 0.005], [0.0, 0.03, 0.005]])
    v = np.zeros_like(x)
    fixed = np.array([True, False])
    resolve_edge_contacts(_finger(), x, v, np.array([[0, 1]]), THICKNESS, fixed)
    assert np.array_equal(x[0], [0.0, -0.03, 0.005])
    a, b = x
    t = np.clip(-a[1] / (b[1] - a[1]), 0.0, 1.0)
    assert np.linalg.norm((a + t * (b - a))[1:]) >= 0.02 + 0.5 * THICKNESS - 1e-3


def test_edges_clear_of_the_finger_and_edge_ends_are_left_alone():
    x = np.array([[0.0, -0.03, 0.05], [0.0, 0.03, 0.05], [0.0, 0.0, 0.021]])
    before = x.copy()
    v = np.zeros_like(x)
    # above the finger; and an edge ending just outside it (its end is the particle
    # contact's)
    assert resolve_edge_contacts(_finger(), x, v, np.array([[0, 1], [2, 0]]), THICKNESS) == 0
    assert np.array_equal(x, before)


def _finger_and_hand() -> PosedCapsules:
    """The finger (`_finger`) and a second capsule beside it, 2 cm radius along x through
    (0, 0.03, 0.055): a free edge end pushed up off the finger lands inside it."""
    cap = CapsuleCollider(np.array([0.02, 0.02])).at()
    cap.set_pose(np.array([[-0.1, 0.0, 0.0], [-0.1, 0.03, 0.055]]),
                 np.array([[0.1, 0.0, 0.0], [0.1, 0.03, 0.055]]))
    return cap


def test_an_edge_end_pushed_into_a_neighbouring_capsule_is_projected_out():
    x = np.array([[0.0, -0.03, 0.005], [0.0, 0.03, 0.005]])
    fixed = np.array([True, False])
    edges = np.array([[0, 1]])
    # the edge contact alone moves the free end into the second capsule
    alone = x.copy()
    resolve_edge_contacts(_finger_and_hand(), alone, np.zeros_like(x), edges, THICKNESS, fixed)
    assert penetration([_finger_and_hand()], alone) > 1e-3
    v = np.zeros_like(x)
    edged, clear = edges_then_particles([_finger_and_hand()], x, v, edges, THICKNESS, fixed)
    assert edged.tolist() == [False, True] and clear
    assert np.array_equal(x[0], [0.0, -0.03, 0.005])
    assert penetration([_finger_and_hand()], x) == 0.0
