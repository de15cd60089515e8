"""MeshCollider: a closed triangle mesh as a rigid cloth collider (collision/mesh_collider.py)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cloth_mg_ros.collision.colliders import (
    SphereCollider,
    collide,
    penetration,
    resolve_contacts,
)
from cloth_mg_ros.collision.mesh_collider import MeshCollider, PosedMesh
from cloth_mg_ros.errors import ClothInputError

RADIUS = 0.3


@pytest.fixture(scope="module")
def ball() -> PosedMesh:
    """Icosphere of radius 0.3 m at the origin: 5,120 faces, faceting error ~0.25 mm."""
    return MeshCollider(trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)).at()


def shell(rng: np.random.Generator, n: int, r_lo: float, r_hi: float,
          centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    """n points at radii uniform in [r_lo, r_hi] around centre, directions uniform."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.asarray(centre) + d * rng.uniform(r_lo, r_hi, n)[:, None]


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def box_sdf(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Exact signed distance of p (n, 3) to the box |x_i| <= half_i."""
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


# ---------------------------------------------------------------- geometry


def test_icosphere_agrees_with_sphere_collider(ball):
    rng = np.random.default_rng(0)
    x = np.concatenate([shell(rng, 600, 0.25, 0.35),       # near the surface, both sides
                        shell(rng, 100, 0.0, 0.2)])         # deep inside
    margin = 0.1
    sphere = SphereCollider(np.zeros(3), RADIUS)
    a, b = sphere.query(x, margin), ball.query(x, margin)
    np.testing.assert_array_equal(b.index, a.index)
    assert len(b) == len(x)
    np.testing.assert_allclose(b.distance, a.distance, atol=2e-3)
    # Normals: within the facets' angular size, except near the centre (any way out is fine).
    ok = np.linalg.norm(x, axis=1) > 0.1
    assert angle_deg(b.normal[ok], a.normal[ok]).max() < 3.0
    np.testing.assert_allclose(np.linalg.norm(b.normal, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(b.velocity, 0.0)
    # The margin cuts the same particles (away from the faceting band).
    x2 = shell(rng, 2000, 0.2, 0.4)
    r = np.linalg.norm(x2, axis=1)
    clear = np.abs(r - (RADIUS + 0.02)) > 2e-3
    got = np.zeros(len(x2), bool)
    got[ball.query(x2, 0.02).index] = True
    np.testing.assert_array_equal(got[clear], (r < RADIUS + 0.02)[clear])


def test_far_points_give_no_contacts(ball):
    rng = np.random.default_rng(1)
    far = shell(rng, 5000, 0.5, 3.0)
    c = ball.query(far, 0.01)
    assert len(c) == 0
    assert c.index.shape == (0,) and c.normal.shape == (0, 3) and c.velocity.shape == (0, 3)
    assert len(ball.query(far, 0.01, far + 0.01)) == 0
    assert len(ball.query(np.zeros((0, 3)), 0.01)) == 0


def test_closest_points_match_trimesh_and_box_sdf():
    rng = np.random.default_rng(2)
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    col = MeshCollider(mesh).at()
    p = rng.normal(scale=0.2, size=(200, 3))
    # Brute force over all faces with trimesh's exact point-triangle closest point.
    tri = np.repeat(mesh.triangles[None], len(p), axis=0).reshape(-1, 3, 3)
    pts = np.repeat(p, len(mesh.faces), axis=0)
    brute = np.linalg.norm(trimesh.triangles.closest_point(tri, pts) - pts, axis=1)
    brute = brute.reshape(len(p), -1).min(axis=1)
    np.testing.assert_allclose(np.abs(col.signed_distance(p)), brute, atol=1e-12)
    # A box: sharp edges and corners, where the sign needs the edge and vertex pseudonormals.
    half = np.array([0.2, 0.15, 0.005])
    box = MeshCollider(trimesh.creation.box(extents=2 * half)).at()
    q = rng.uniform(-0.25, 0.25, (5000, 3)) * np.array([1.0, 1.0, 0.1])
    np.testing.assert_allclose(box.signed_distance(q), box_sdf(q, half), atol=1e-12)


def test_concave_mesh_cavity_and_two_bodies():
    """Signs on a torus (saddle vertices), a hollow shell (an enclosed outside cavity) and a
    second body; the culled query finds exactly the points the exact search would."""
    rng = np.random.default_rng(6)
    big, small = 0.3, 0.08
    torus = MeshCollider(trimesh.creation.torus(major_radius=big, minor_radius=small,
                                                major_sections=64, minor_sections=24)).at()
    p = rng.uniform(-0.45, 0.45, (20000, 3)) * [1.0, 1.0, 0.35]
    exact = np.hypot(np.hypot(p[:, 0], p[:, 1]) - big, p[:, 2]) - small
    sd = torus.signed_distance(p)
    clear = np.abs(exact) > 3e-3
    np.testing.assert_array_equal(np.sign(sd[clear]), np.sign(exact[clear]))
    np.testing.assert_array_equal(torus.query(p, 0.01).index, np.flatnonzero(sd < 0.01))

    outer = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    inner = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    inner.invert()
    cube = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    cube.apply_translation((1.0, 0.0, 0.0))
    col = MeshCollider(trimesh.util.concatenate([outer, inner, cube])).at()
    q = rng.uniform(-1.2, 1.2, (20000, 3))
    r = np.linalg.norm(q, axis=1)
    solid = ((r < 0.3) & (r > 0.2)) | np.all(np.abs(q - [1.0, 0.0, 0.0]) < 0.05, axis=1)
    sd = col.signed_distance(q)
    clear = (np.abs(r - 0.3) > 3e-3) & (np.abs(r - 0.2) > 3e-3)
    np.testing.assert_array_equal((sd < 0.0)[clear], solid[clear])
    np.testing.assert_array_equal(col.query(q, 0.01).index, np.flatnonzero(sd < 0.01))


def test_inverted_mesh_is_turned_outward_and_file_with_scale(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    inverted = mesh.copy()
    inverted.invert()
    col = MeshCollider(inverted, scale=0.3).at()
    assert col.signed_distance(np.array([[0.0, 0.0, 0.0]]))[0] < -0.29
    path = tmp_path / "ball.stl"
    mesh.export(path)
    col = MeshCollider(str(path), friction=0.2, scale=0.3).at()
    assert col.friction == 0.2 and str(path) in col.collider.source
    d = col.signed_distance(np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(d, [0.2, -0.3], atol=5e-3)


# ---------------------------------------------------------------- motion


def test_rigid_translation_moves_contacts_and_gives_surface_velocity(ball):
    rng = np.random.default_rng(3)
    ball.set_pose(np.eye(3), [0.1, 0.0, 0.0])          # a jump: no velocity
    x = shell(rng, 500, 0.25, 0.35, centre=(0.12, 0.0, 0.0))
    c = ball.query(x, 0.1)
    assert np.all(c.velocity == 0.0)
    ball.set_pose(np.eye(3), [0.12, 0.0, 0.0], dt=0.01)  # 2 cm in 10 ms: 2 m/s along +x
    c = ball.query(x, 0.1)
    ref = SphereCollider([0.12, 0.0, 0.0], RADIUS).query(x, 0.1)
    try:
        np.testing.assert_array_equal(c.index, ref.index)
        np.testing.assert_allclose(c.distance, ref.distance, atol=2e-3)
        np.testing.assert_allclose(c.velocity, np.tile([2.0, 0.0, 0.0], (len(c), 1)),
                                   atol=1e-9)
        # Where the ball was: the particles it left are no longer in contact.
        assert len(ball.query(x - [1.0, 0.0, 0.0], 0.01)) == 0
    finally:
        ball.set_pose(np.eye(3), np.zeros(3))


def test_rotation_gives_rigid_body_velocity():
    box = MeshCollider(trimesh.creation.box(extents=(0.4, 0.2, 0.2))).at()
    dt, w = 0.01, 2.0  # rad/s about z
    ang = w * dt
    rz = np.array([[np.cos(ang), -np.sin(ang), 0.0], [np.sin(ang), np.cos(ang), 0.0],
                   [0.0, 0.0, 1.0]])
    box.set_pose(rz, [0.0, 0.0, 0.0], dt=dt)
    x = (rz @ [0.202, 0.0, 0.05])[None]  # 2 mm off the +x end
    c = box.query(x, 0.01)
    assert len(c) == 1
    np.testing.assert_allclose(c.normal[0], [np.cos(ang), np.sin(ang), 0.0], atol=1e-9)
    np.testing.assert_allclose(c.distance, 0.002, atol=1e-9)
    contact = rz @ [0.2, 0.0, 0.05]
    exact = (contact - [0.2, 0.0, 0.05]) / dt  # that body point's displacement / dt
    np.testing.assert_allclose(c.velocity[0], exact, atol=1e-9)
    np.testing.assert_allclose(c.velocity[0], np.cross([0.0, 0.0, w], contact), atol=5e-3)


# ---------------------------------------------------------------- tunnelling


@pytest.fixture()
def plate() -> PosedMesh:
    """A 1 cm thick plate, z in [-5 mm, 5 mm]."""
    return MeshCollider(trimesh.creation.box(extents=(0.4, 0.4, 0.01))).at()


def test_particle_that_crossed_a_thin_box_goes_back_to_its_side(plate):
    x_prev = np.array([[0.0, 0.0, 0.02],     # from above, now past the middle
                       [0.05, 0.0, 0.02],    # from above, right through and out below
                       [0.1, 0.0, -0.02],    # from below, past the middle
                       [0.15, 0.0, 0.02]])   # from above, not yet at the middle
    x = np.array([[0.0, 0.0, -0.002], [0.05, 0.0, -0.03], [0.1, 0.0, 0.003],
                  [0.15, 0.0, 0.003]])
    nearest = plate.query(x, 0.005)
    assert nearest.index.tolist() == [0, 2, 3]
    assert nearest.normal[0, 2] < 0.0 and nearest.normal[1, 2] > 0.0  # wrong side for 0, 2
    c = plate.query(x, 0.005, x_prev)
    assert c.index.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(c.normal, [[0, 0, 1], [0, 0, 1], [0, 0, -1], [0, 0, 1]],
                               atol=1e-12)
    np.testing.assert_allclose(c.distance, [-0.007, -0.035, -0.008, -0.002], atol=1e-12)
    # Projection sends each back to its own side, at the thickness.
    v = np.zeros_like(x)
    resolve_contacts([plate], x, v, 0.003, x_prev)
    np.testing.assert_allclose(x[:, 2], [0.008, 0.008, -0.008, 0.008], atol=1e-12)
    assert penetration([plate], x) == 0.0


def test_moving_plate_sweeping_through_a_particle_pushes_it_along(plate):
    # The particle stays put; the plate rises 2.2 cm in one step, its top passing the particle.
    plate.set_pose(np.eye(3), [0.0, 0.0, 0.0])
    plate.set_pose(np.eye(3), [0.0, 0.0, 0.022], dt=0.01)
    x = np.array([[0.0, 0.0, 0.02]])
    c = plate.query(x, 0.003, x.copy())
    np.testing.assert_allclose(c.normal, [[0.0, 0.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(c.distance, [-0.007], atol=1e-12)
    np.testing.assert_allclose(c.velocity, [[0.0, 0.0, 2.2]], atol=1e-9)
    # Without the history the nearest face is the bottom one: pushed out the wrong way.
    assert plate.query(x, 0.003).normal[0, 2] < 0.0


def test_sliding_round_a_convex_edge_keeps_the_nearest_normal():
    box = MeshCollider(trimesh.creation.box(extents=(0.2, 0.2, 0.2))).at()
    x_prev = np.array([[0.09, 0.0, 0.105]])  # 5 mm above the top, near the +x edge
    x = np.array([[0.098, 0.0, 0.09]])       # 2 mm inside the +x side, 1 cm below the top
    c = box.query(x, 0.005, x_prev)
    np.testing.assert_allclose(c.normal, [[1.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(c.distance, [-0.002], atol=1e-12)


def test_resolve_contacts_leaves_no_particle_inside(ball):
    rng = np.random.default_rng(4)
    x = shell(rng, 3000, 0.0, 0.36)
    v = rng.normal(size=x.shape)
    assert penetration([ball], x) > 0.25
    thickness = 0.005
    count, deepest = resolve_contacts([ball], x, v, thickness)
    assert count > 0 and deepest > 0.25
    assert penetration([ball], x) == 0.0
    assert ball.signed_distance(x).min() > thickness - 1e-9
    # Inward normal velocity relative to the (static) surface is gone.
    c = collide([ball], x, thickness + 1e-6)
    assert np.einsum("ij,ij->i", v[c.index], c.normal).min() > -1e-9


# ---------------------------------------------------------------- cloth


def test_sheet_drops_onto_a_mesh_ball():
    from cloth_mg_ros.mesh import sheet_coarse
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.model import ClothState, build_model
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import PCGSolver

    sheet = sheet_coarse(0.6, 0.6, cells_x=8, plane="xy", centre=(0, 0, 0.5))
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    mesh.apply_translation((0.0, 0.0, 0.2))
    col = MeshCollider(mesh)
    model = build_model(sheet, get_material("cotton"), colliders=[col])
    positions = sheet.rest
    sim = Simulator(model, ClothState.at_rest(positions), PCGSolver(tol=1e-5), dt=1 / 60)
    centre = int(np.argmin(np.linalg.norm(positions[:, :2], axis=1)))
    touched = 0
    for _ in range(40):
        stats = sim.step()
        assert np.isfinite(sim.state.x).all()
        assert stats.max_penetration < 2e-3
        touched += stats.contacts > 0
    assert touched >= 5 and stats.contacts > 0
    # The middle of the sheet lies on top of the ball, not in it and not fallen past it.
    assert 0.4 < sim.state.x[centre, 2] < 0.43
    assert col.at().signed_distance(sim.state.x).min() > -2e-3


# ---------------------------------------------------------------- bad input


def test_bad_input_names_the_problem(tmp_path):
    missing = tmp_path / "nope.obj"
    with pytest.raises(ClothInputError, match="not found.*nope.obj"):
        MeshCollider(str(missing))
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"solid x\nthis is not a mesh\n")
    with pytest.raises(ClothInputError, match="garbage.stl"):
        MeshCollider(garbage)

    open_ball = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    open_ball.update_faces(np.arange(1, len(open_ball.faces)))
    path = tmp_path / "open.stl"
    open_ball.export(path)
    with pytest.raises(ClothInputError, match=r"open.stl is not watertight: 3 boundary edges"):
        MeshCollider(path)
    with pytest.raises(ClothInputError, match="not watertight"):
        MeshCollider(open_ball)

    flipped = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    faces = flipped.faces.copy()
    faces[0] = faces[0, ::-1]
    flipped = trimesh.Trimesh(flipped.vertices, faces, process=False)
    with pytest.raises(ClothInputError, match="not consistently oriented"):
        MeshCollider(flipped)

    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(ClothInputError, match="empty.obj"):
        MeshCollider(empty)

    flat = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]],
                           [[0, 1, 2], [0, 1, 3]], process=False)
    with pytest.raises(ClothInputError, match="degenerate"):
        MeshCollider(flat)

    good = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    with pytest.raises(ClothInputError, match="scale"):
        MeshCollider(good, scale=0.0)
    with pytest.raises(ClothInputError, match="friction"):
        MeshCollider(good, friction=-1.0)
    col = MeshCollider(good).at()
    with pytest.raises(ClothInputError, match="orthonormal"):
        col.set_pose(2.0 * np.eye(3), np.zeros(3))
    with pytest.raises(ClothInputError, match="orthonormal"):
        col.set_pose(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    with pytest.raises(ClothInputError, match="translation"):
        col.set_pose(np.eye(3), [0.0, np.nan, 0.0])
    with pytest.raises(ClothInputError, match="dt"):
        col.set_pose(np.eye(3), np.zeros(3), dt=0.0)
    with pytest.raises(ClothInputError, match=r"x must be \(n, 3\)"):
        col.query(np.zeros((4, 2)), 0.01)
    with pytest.raises(ClothInputError, match="x_prev"):
        col.query(np.zeros((4, 3)), 0.01, np.zeros((3, 3)))
