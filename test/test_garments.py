"""Tests of cloth_mg_ros.mesh.garments: procedural garments worn on a capsule body.

Every garment at ~1200 and ~4500 particles (and the counts at 20000): particle count, valid
manifold oriented levels, clearance from every capsule, pins (coarse, on the garment, their
targets reproduce the rest positions and follow a rigidly moved body), topology (one piece;
boundary loops: top 4, skirt and dress 2, cape 1), outward normals, and the input errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments import (
    BODY_SEGMENTS,
    GARMENTS,
    Garment,
    boundary_loops,
    capsule_distances,
    make_garment,
    pin_targets,
    segment_frame,
    segment_reference,
    standing_body,
    transform_body,
)
from cloth_mg_ros.mesh.topology import MeshLevel

SIZES = (1200, 4500)
EXPECTED_LOOPS = {'skirt': 2, 'dress': 2, 'cape': 1, 'top': 4}
PINNED_SEGMENT = {'skirt': 'pelvis', 'dress': 'upper_torso', 'cape': 'upper_torso',
                  'top': 'upper_torso'}


@pytest.fixture(scope='module')
def body() -> dict:
    return standing_body()


@pytest.fixture(scope='module', params=[(g, n) for g in GARMENTS for n in SIZES],
                ids=lambda p: f'{p[0]}-{p[1]}')
def garment(request, body) -> tuple[Garment, int]:
    name, n = request.param
    return make_garment(name, body, n), n


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    return rz @ ry @ rx


def _n_components(faces: np.ndarray, n: int) -> int:
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    graph = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[0]


# ------------------------------------------------------------------------------------------
# The body fixture
# ------------------------------------------------------------------------------------------

def test_standing_body_is_a_plausible_adult(body):
    assert tuple(body) == BODY_SEGMENTS
    _, d = capsule_distances(np.array([[0.0, 0.0, 1.75]]), body)
    assert abs(d.min()) < 0.01            # top of the head at 1.75 m
    lowest = min(min(p0[2] - r, p1[2] - r) for p0, p1, r in body.values())
    assert abs(lowest) < 0.01             # feet on the floor
    # left is +y, the arms hang away from the torso
    assert body['upper_arm_l'][1][1] > body['upper_arm_l'][0][1] > 0.0
    assert body['upper_arm_r'][1][1] < body['upper_arm_r'][0][1] < 0.0
    assert body['foot_l'][1][0] > body['foot_l'][0][0]  # toes forward (+x)


# ------------------------------------------------------------------------------------------
# Every garment at ~1200 and ~4500 particles
# ------------------------------------------------------------------------------------------

def test_particle_count_and_levels(garment):
    g, n = garment
    assert abs(g.n_particles / n - 1.0) < 0.10
    assert g.rest_positions.shape == (g.n_particles, 3)
    assert g.rest_positions is g.hierarchy.finest.rest
    coarse = g.hierarchy.coarsest.n_vertices
    assert 50 <= coarse <= 700
    for level in g.hierarchy.levels:
        # re-validate from scratch: manifold, consistently oriented, no degenerate faces
        MeshLevel(np.array(level.rest), np.array(level.faces))
    # subdivision keeps the coarse vertices first
    np.testing.assert_array_equal(g.hierarchy.finest.rest[:coarse], g.hierarchy.coarsest.rest)


def test_clearance_from_every_capsule(garment, body):
    g, _ = garment
    _, d = capsule_distances(g.rest_positions, body)
    assert d.min() >= g.clearance - 1e-9
    assert g.min_distance == pytest.approx(d.min())
    assert g.clearance == 0.015


def test_topology_and_outward_orientation(garment, body):
    g, _ = garment
    fine = g.hierarchy.finest
    assert _n_components(fine.faces, fine.n_vertices) == 1
    loops = boundary_loops(fine.faces)
    assert len(loops) == EXPECTED_LOOPS[g.name]
    assert sum(len(lp) for lp in loops) == int(fine.boundary_vertices.sum())
    # Euler characteristic: 2 - holes for these sphere-with-holes surfaces
    assert fine.n_vertices - fine.n_edges + fine.n_faces == 2 - len(loops)
    # normals point away from the nearest capsule's axis
    x, faces = fine.rest, fine.faces
    fn = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    vn = np.zeros_like(x)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    # Skirts and dresses flare out towards the hanging hands: judge them by the trunk and legs.
    trunk = body if g.name in ("top", "cape") else {k: v for k, v in body.items()
                                                    if not k.startswith(("upper_arm", "lower_arm",
                                                                         "hand"))}
    names, d = capsule_distances(x, trunk)
    seg = np.argmin(d, axis=1)
    p0 = np.array([trunk[names[s]][0] for s in seg])
    p1 = np.array([trunk[names[s]][1] for s in seg])
    t = np.clip(np.einsum('ij,ij->i', x - p0, p1 - p0) / np.einsum('ij,ij->i', p1 - p0, p1 - p0),
                0.0, 1.0)
    away = x - (p0 + t[:, None] * (p1 - p0))
    assert np.mean(np.einsum('ij,ij->i', vn, away) > 0.0) > 0.97


def test_triangles_near_equilateral_and_uniform(garment):
    g, _ = garment
    coarse = g.hierarchy.coarsest
    tri = coarse.rest[coarse.faces]
    sides = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)
    # quality 4 sqrt(3) A / (sum of squared sides): 1 for an equilateral triangle
    quality = 4.0 * math.sqrt(3.0) * coarse.face_areas / (sides ** 2).sum(axis=1)
    assert np.median(quality) > 0.9
    assert quality.min() > 0.4
    areas = coarse.face_areas
    assert areas.max() / np.median(areas) < 2.5 and areas.min() / np.median(areas) > 0.3


def test_pins(garment, body):
    g, _ = garment
    assert set(g.pins) == {PINNED_SEGMENT[g.name]}
    n_coarse = g.hierarchy.coarsest.n_vertices
    for seg, idx in g.pins.items():
        assert idx.dtype == np.int64 and idx.ndim == 1 and len(idx) >= 2
        assert len(np.unique(idx)) == len(idx)
        assert idx.min() >= 0 and idx.max() < n_coarse          # coarse: valid on every level
        assert g.pin_offsets[seg].shape == (len(idx), 3)
        if g.name == 'top':
            assert len(idx) == 6
            # three on each shoulder, above the shoulder joints
            y = g.rest_positions[idx, 1]
            assert (y > 0).sum() == 3 and (y < 0).sum() == 3
            assert (g.rest_positions[idx, 2] > body['upper_arm_l'][0][2]).all()
        else:
            # the whole top edge: the highest coarse vertices
            top = g.hierarchy.coarsest.rest[:, 2].max()
            assert np.allclose(g.rest_positions[idx, 2], top, atol=1e-9)
    np.testing.assert_array_equal(g.pinned_vertices,
                                  np.unique(np.concatenate(list(g.pins.values()))))
    targets = pin_targets(body, g)
    for seg, idx in g.pins.items():
        np.testing.assert_allclose(targets[seg], g.rest_positions[idx], atol=1e-12)


def test_pin_targets_follow_a_rigidly_moved_body(garment, body):
    g, _ = garment
    rot = _rotation(0.9, 0.3, -0.2)
    shift = np.array([1.5, -0.7, 0.25])
    moved = transform_body(body, rot, shift)
    targets = pin_targets(moved, g)
    for seg, idx in g.pins.items():
        np.testing.assert_allclose(targets[seg], g.rest_positions[idx] @ rot.T + shift,
                                   atol=1e-12)


def test_weft_is_a_unit_vector(garment):
    g, _ = garment
    assert g.weft.shape == (3,)
    assert np.linalg.norm(g.weft) == pytest.approx(1.0)


# ------------------------------------------------------------------------------------------
# Sizes, frames, errors
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize('name', GARMENTS)
def test_count_at_20000(name, body):
    g = make_garment(name, body, 20000)
    assert abs(g.n_particles / 20000 - 1.0) < 0.10
    sizes = [lv.n_vertices for lv in g.hierarchy.levels]
    assert sizes == sorted(sizes, reverse=True) and len(sizes) >= 4
    assert 50 <= sizes[-1] <= 700


def test_explicit_depth(body):
    g = make_garment('skirt', body, 4500, depth=1)
    assert g.hierarchy.depth == 1 and abs(g.n_particles / 4500 - 1.0) < 0.10
    with pytest.raises(ClothInputError, match='too small for a skirt at depth=5'):
        make_garment('skirt', body, 1200, depth=5)
    with pytest.raises(ClothInputError, match='depth'):
        make_garment('cape', body, 1200, depth=-1)


def test_segment_frame():
    origin, rot = segment_frame(np.zeros(3), np.array([0.0, 0.0, 2.0]), np.array([0.0, 3.0, 1.0]))
    np.testing.assert_allclose(origin, 0.0)
    np.testing.assert_allclose(rot, np.eye(3), atol=1e-15)  # z up, y left: x forward
    _, rot = segment_frame(np.zeros(3), np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)  # parallel reference
    assert np.linalg.det(rot) == pytest.approx(1.0)
    with pytest.raises(ClothInputError, match='zero length'):
        segment_frame(np.ones(3), np.ones(3), np.array([0.0, 1.0, 0.0]))


def test_segment_reference(body):
    ref = segment_reference(body, 'upper_torso')
    np.testing.assert_allclose(ref, body['upper_arm_l'][0] - body['upper_arm_r'][0])
    ref = segment_reference(body, 'pelvis')
    np.testing.assert_allclose(ref, body['upper_leg_l'][0] - body['upper_leg_r'][0])


def test_unknown_garment_lists_the_known_ones(body):
    with pytest.raises(ClothInputError,
                       match="unknown garment 'trousers'.*skirt, dress, cape, top"):
        make_garment('trousers', body, 1200)


@pytest.mark.parametrize('name, n', [('skirt', 50), ('top', 200), ('cape', 0)])
def test_too_few_particles(name, n, body):
    with pytest.raises(ClothInputError, match=f'n_particles={n} is too small for a {name}'):
        make_garment(name, body, n)


def test_n_particles_must_be_an_integer(body):
    with pytest.raises(ClothInputError, match='n_particles must be an integer'):
        make_garment('skirt', body, 1200.0)


@pytest.mark.parametrize('name, segment', [('skirt', 'pelvis'), ('dress', 'lower_leg_r'),
                                           ('cape', 'upper_torso'), ('top', 'head')])
def test_missing_segment_is_named(name, segment, body):
    partial = {k: v for k, v in body.items() if k != segment}
    with pytest.raises(ClothInputError, match=f"body is missing segment '{segment}'"):
        make_garment(name, partial, 1200)


def test_non_finite_body(body):
    bad = dict(body)
    bad['upper_torso'] = (body['upper_torso'][0], np.array([0.0, np.nan, 1.4]),
                          body['upper_torso'][2])
    with pytest.raises(ClothInputError, match="'upper_torso' p1 is not finite"):
        make_garment('top', bad, 1200)
    bad = dict(body)
    bad['hand_l'] = (body['hand_l'][0], body['hand_l'][1], math.inf)
    with pytest.raises(ClothInputError, match="'hand_l' radius"):
        make_garment('skirt', bad, 1200)
    bad = dict(body)
    bad['pelvis'] = (body['pelvis'][0], body['pelvis'][1])
    with pytest.raises(ClothInputError, match="'pelvis' must be \\(p0, p1, radius\\)"):
        make_garment('skirt', bad, 1200)
    with pytest.raises(ClothInputError, match='body must be a dict'):
        make_garment('skirt', [1, 2, 3], 1200)


def test_arms_too_close_to_the_torso(body):
    close = dict(body)
    for side in ('l', 'r'):  # arms hanging straight down at the sides
        shoulder = body[f'upper_arm_{side}'][0]
        elbow, wrist = shoulder - [0.0, 0.0, 0.29], shoulder - [0.0, 0.0, 0.54]
        close[f'upper_arm_{side}'] = (shoulder, elbow, 0.045)
        close[f'lower_arm_{side}'] = (elbow, wrist, 0.038)
        close[f'hand_{side}'] = (wrist, wrist - [0.0, 0.0, 0.12], 0.035)
    with pytest.raises(ClothInputError, match="'upper_arm_l' hangs too close to the torso"):
        make_garment('top', close, 1200)
    with pytest.raises(ClothInputError, match='dress: the upper arms hang too close'):
        make_garment('dress', close, 1200)
    with pytest.raises(ClothInputError, match="skirt: segment '(lower_arm|hand)_[lr]' is too "
                                              "close to the body"):
        make_garment('skirt', close, 1200)
