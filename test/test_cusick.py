"""The Cusick drape test (fidelity.cusick): the support disc collider, the specimen mesh, the
shadow and drape coefficient of known shapes, the node counter on synthetic outlines, input
checks and one small real settle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cloth_mg_ros.collision.colliders import DiscCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity import cusick as C

R_S = 0.5 * C.SUPPORT_DIAMETER


# ---------------------------------------------------------------------------- the collider


def test_disc_collider_signed_distance_and_normals():
    disc = DiscCollider(np.array([0.0, 0.0, 0.5]), 0.09, 0.01)
    x = np.array([
        [0.0, 0.0, 0.51],  # above the centre
        [0.10, 0.0, 0.495],  # beside the side, at mid height
        [0.0, 0.12, 0.53],  # above and outside the rim: distance to the rim circle
        [0.0, 0.0, 0.499],  # just inside, under the top face
        [0.0895, 0.0, 0.495],  # just inside, by the side
        [0.0, 0.0, 0.48],  # below the bottom face
    ])
    d, n = disc.signed_distance(x)
    np.testing.assert_allclose(d, [0.01, 0.01, math.hypot(0.03, 0.03), -0.001, -0.0005, 0.01],
                               atol=1e-12)
    np.testing.assert_allclose(n, [[0, 0, 1], [1, 0, 0], [0, math.sqrt(0.5), math.sqrt(0.5)],
                                   [0, 0, 1], [1, 0, 0], [0, 0, -1]], atol=1e-12)
    c = disc.query(x, 0.002)
    assert c.index.tolist() == [3, 4]


def test_disc_collider_catches_a_particle_that_fell_through_its_top():
    disc = DiscCollider(np.array([0.0, 0.0, 0.5]), 0.09, 0.01)
    prev = np.array([[0.05, 0.0, 0.503], [0.12, 0.0, 0.503]])
    now = np.array([[0.05, 0.0, 0.47], [0.12, 0.0, 0.47]])  # 3 cm down: through the plate
    assert len(disc.query(now, 0.002)) == 0
    c = disc.query(now, 0.002, prev)
    assert c.index.tolist() == [0]  # the one outside the radius passed beside the disc
    np.testing.assert_allclose(c.normal, [[0.0, 0.0, 1.0]])
    assert c.distance[0] == pytest.approx(-0.03)


@pytest.mark.parametrize("field,value", [("radius", 0.0), ("height", -1.0)])
def test_disc_collider_rejects_bad_sizes(field, value):
    kwargs = {"top": np.zeros(3), "radius": 0.09, "height": 0.01, field: value}
    with pytest.raises(ClothInputError, match=field):
        DiscCollider(**kwargs)


# ---------------------------------------------------------------------------- mesh and shadow


@pytest.mark.parametrize("particles,graded", [(400, True), (2500, True), (2500, False)])
def test_flat_specimen_has_dc_one(particles, graded):
    """The unmoved specimen's shadow is the specimen: DC = 1 within the raster's error (the
    out-of-plane perturbation does not change the shadow)."""
    scene = C.build_cusick(C.CusickSpec(particles=particles, seed=3, graded=graded))
    assert abs(scene.model.n - particles) < 0.1 * particles
    # Every chord of the support polygon is an edge of the coarse mesh (so of every level).
    coarse = scene.hierarchy.coarsest
    rho_c = np.hypot(*coarse.rest[:, :2].T)
    ring = np.flatnonzero(np.abs(rho_c - scene.support_radius) < 1e-12)
    ring = ring[np.argsort(np.arctan2(coarse.rest[ring, 1], coarse.rest[ring, 0]))]
    edges = {tuple(e) for e in np.sort(coarse.edges, axis=1).tolist()}
    chords = np.sort(np.stack([ring, np.roll(ring, -1)], axis=1), axis=1)
    assert len(ring) >= 12 and all(tuple(c) in edges for c in chords.tolist())
    shadow = C.shadow_mask(scene.state.x, scene.model.mesh.faces)
    assert shadow.area == pytest.approx(C.A_SPECIMEN, rel=2e-4)
    assert C.drape_coefficient(shadow.area) == pytest.approx(1.0, abs=5e-4)
    # The support circle is a mesh line: every held particle lies on or inside it.
    rho = np.hypot(*scene.state.x[:, :2].T)
    assert rho[scene.held].max() == pytest.approx(scene.support_radius)
    assert np.all(rho[np.setdiff1d(np.arange(scene.model.n), scene.held)] > scene.support_radius)
    # The hem: the boundary's vertices, all on the rim polygon.
    rim = C.rim_vertices(scene.model.mesh.faces)
    assert len(rim) > 30 and np.all(rho[rim] > 0.149) and np.sum(rho > 0.149) == len(rim)
    # The support polygon is as large as the support disc.
    inside = C.shadow_mask(scene.state.x, _faces_within(scene, scene.support_radius))
    assert inside.area == pytest.approx(C.A_DISC, rel=1e-3)


def _faces_within(scene, radius):
    faces = scene.model.mesh.faces
    rho = np.hypot(*scene.model.mesh.rest[:, :2].T)
    return faces[np.all(rho[faces] <= radius * (1 + 1e-9), axis=1)]


def _cone(scene, angle_deg):
    """The flat specimen with its annulus turned down about the support circle as a cone at
    ``angle_deg`` below horizontal: r -> R_s + (r - R_s) cos a, z -> -(r - R_s) sin a."""
    x = scene.model.mesh.rest.copy()
    rho = np.hypot(x[:, 0], x[:, 1])
    out = rho > scene.support_radius
    s = rho[out] - scene.support_radius
    a = math.radians(angle_deg)
    x[out, :2] *= ((scene.support_radius + s * math.cos(a)) / rho[out])[:, None]
    x[out, 2] = -s * math.sin(a)
    return x


@pytest.mark.parametrize("angle", [30.0, 60.0, 90.0])
def test_cone_dc_is_its_projected_area(angle):
    """A cone hung at a known angle: its shadow is the disc of radius R_s + (R - R_s) cos a,
    so DC = ((R_s + l cos a)^2 - R_s^2) / (R^2 - R_s^2); at 90 degrees the annulus is seen
    edge-on and DC = 0."""
    scene = C.build_cusick(C.CusickSpec(particles=2500))
    x = _cone(scene, angle)
    dc = C.drape_coefficient(C.shadow_mask(x, scene.model.mesh.faces).area)
    a = math.radians(angle)
    r, l_ = 0.5 * C.SPECIMEN_DIAMETER, 0.5 * C.SPECIMEN_DIAMETER - R_S
    exact = ((R_S + l_ * math.cos(a)) ** 2 - R_S ** 2) / (r ** 2 - R_S ** 2)
    assert dc == pytest.approx(exact, abs=3e-3)


def test_shadow_counts_overlaps_once_and_either_orientation():
    scene = C.build_cusick(C.CusickSpec(particles=400))
    faces = scene.model.mesh.faces
    x = scene.state.x
    one = C.shadow_mask(x, faces).area
    both = C.shadow_mask(x, np.concatenate([faces, faces[:, ::-1]])).area
    assert both == one
    # A cone at 45 degrees with its annulus flipped over the top of itself (a fold turned
    # over) still casts the cone's shadow.
    cone = _cone(scene, 45.0)
    assert C.shadow_mask(cone, faces[:, ::-1]).area == C.shadow_mask(cone, faces).area


def test_outline_of_a_disc_is_its_radius():
    scene = C.build_cusick(C.CusickSpec(particles=2500))
    outline = C.shadow_mask(scene.state.x, scene.model.mesh.faces).outline()
    assert outline.shape == (C.OUTLINE_BINS,)
    # The polygon's vertices stand out of the circle, its edges' middles inside it.
    assert np.all(np.abs(outline - 0.15) < 1.5e-3)
    assert C.count_nodes(outline) == 0


def test_spacing_profile_is_finest_at_the_support_edge():
    r = np.array([0.0, 0.06, 0.09, 0.10, 0.11, 0.15])
    np.testing.assert_allclose(C.spacing_profile(r), [1.5, 1.5, 0.3, 0.65, 1.0, 1.0])
    np.testing.assert_array_equal(C.spacing_profile(r, graded=False), np.ones(6))
    graded = C.build_cusick(C.CusickSpec(particles=2500))
    edge = graded.model.edge_rest
    mesh = graded.model.mesh
    mid = 0.5 * np.hypot(*(mesh.rest[mesh.edges[:, 0], :2] + mesh.rest[mesh.edges[:, 1], :2]).T)
    near, far = np.abs(mid - R_S) < 0.003, np.abs(mid - 0.13) < 0.01
    assert np.median(edge[near]) < 0.45 * np.median(edge[far])


# ---------------------------------------------------------------------------- node counter


@pytest.mark.parametrize("n", [3, 4, 5, 6, 7, 8, 9, 11, 13])
def test_node_counter_counts_cosine_lobes(n):
    phi = (np.arange(C.OUTLINE_BINS) + 0.5) * 2.0 * math.pi / C.OUTLINE_BINS
    rng = np.random.default_rng(n)
    r = 0.12 + 0.01 * np.cos(n * phi + rng.uniform(0, 2 * math.pi))
    assert C.count_nodes(r) == n
    # Pixel-scale noise (0.5 mm) does not split a lobe.
    assert C.count_nodes(r + rng.uniform(-2.5e-4, 2.5e-4, r.shape)) == n
    peaks = C.node_peaks(r)
    assert np.all(np.diff(peaks) > 0) and len(set(peaks)) == n


def test_node_counter_thresholds_and_edges():
    phi = (np.arange(360) + 0.5) * 2.0 * math.pi / 360
    assert C.count_nodes(np.full(360, 0.12)) == 0
    ripple = 0.12 + 0.002 * np.cos(8 * phi)  # crests 4 mm above troughs: below 5 mm
    assert C.count_nodes(ripple) == 0
    assert C.count_nodes(ripple, prominence=0.003) == 8
    # A lobe cut by phi = 0 is counted once.
    assert C.count_nodes(0.12 + 0.01 * np.cos(5 * phi - 0.01)) == 5
    with pytest.raises(ClothInputError, match="finite"):
        C.count_nodes(np.array([0.1, np.nan, 0.1, 0.2]))


# ---------------------------------------------------------------------------- input


@pytest.mark.parametrize("field,value", [
    ("material", "no-such-cloth"), ("particles", 50), ("particles", 2.5e3),
    ("particles", True), ("seed", -1), ("perturbation", -0.001), ("perturbation", 0.5),
    ("perturbation", float("nan")), ("diameter", 0.18), ("diameter", "30 cm"),
    ("graded", "yes"),
])
def test_bad_spec_raises_naming_the_value(field, value):
    with pytest.raises(ClothInputError) as err:
        C.CusickSpec(**{field: value})
    assert repr(value) in str(err.value) or str(value) in str(err.value)


def test_perturbation_is_deterministic_and_bounded():
    spec = C.CusickSpec(particles=400, seed=7, perturbation=0.003)
    rng = np.random.default_rng(0)
    r = np.sqrt(rng.uniform(0, 0.15 ** 2, 2000))
    t = rng.uniform(0, 2 * math.pi, 2000)
    xy = np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    w = C.perturbation_field(xy, spec, R_S)
    np.testing.assert_array_equal(w, C.perturbation_field(xy, spec, R_S))
    assert np.all(w[r <= R_S] == 0.0)
    assert np.abs(w).max() <= 0.003 + 1e-15
    other = C.perturbation_field(xy, C.CusickSpec(particles=400, seed=8, perturbation=0.003),
                                 R_S)
    assert np.abs(w - other).max() > 1e-4


def test_summarise_repeats_reports_dc_at_the_most_frequent_node_count():
    blocks = [{"seed": k, "dc": dc, "nodes": n, "settled": True}
              for k, (dc, n) in enumerate([(0.40, 9), (0.36, 10), (0.37, 10), (0.41, 9),
                                           (0.35, 10)])]
    out = C.summarise_repeats(blocks)
    assert out["node_mode"] == 10
    assert out["dc_at_node_mode"] == pytest.approx(0.36)
    assert out["dc_mean"] == pytest.approx(0.378)
    assert out["dc_std"] == pytest.approx(np.std([0.40, 0.36, 0.37, 0.41, 0.35], ddof=1))
    assert out["all_settled"] and out["seeds"] == [0, 1, 2, 3, 4]
    with pytest.raises(ClothInputError, match="no blocks"):
        C.summarise_repeats([])


# ---------------------------------------------------------------------------- a real settle


@pytest.fixture
def one_numba_thread():
    """Run the settle's numba kernels on one thread: at 600 particles a parallel kernel's
    start-up is most of its time, and on a shared two-core machine it took the settle from
    2 s to 17 s. The previous thread count is restored."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def test_small_drape_settles(tmp_path, one_numba_thread):
    spec = C.CusickSpec(material="gray-interlock", particles=600, seed=0)
    block, scene, result = C.run_cusick(spec, solver_name="direct", max_steps=1500)
    assert result.settled and block["settled"]
    assert np.all(np.isfinite(result.state.x))
    assert 0.0 < block["dc"] < 1.0
    assert block["nodes"] >= 3
    assert len(block["outline_r_m"]) == C.OUTLINE_BINS
    assert block["bending_length_m"] == pytest.approx(0.0141, abs=2e-4)
    # The clamped particles did not move, and no particle went into the clamp's plates.
    np.testing.assert_array_equal(result.state.x[scene.held], scene.state.x[scene.held])
    depth = [-(c.signed_distance(result.state.x)[0].min()) for c in scene.model.colliders]
    assert max(depth) < 1e-3
    path = tmp_path / "drape.png"
    C.render_top_view(str(path), scene, result.state, block)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
