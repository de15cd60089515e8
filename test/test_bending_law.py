"""A measured fabric's bending by direction and curvature (physics.bending_law)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.cantilever import CantileverSpec, run_cantilever
from cloth_mg_ros.fidelity.elastica import GRAVITY, curvature_of_moment, elastica
from cloth_mg_ros.mesh import sheet_hierarchy
from cloth_mg_ros.mesh.generators import sheet_coarse
from cloth_mg_ros.physics.bending import bending_terms
from cloth_mg_ros.physics.bending_law import BendingLaw, quartic
from cloth_mg_ros.physics.fabrics import MEASURED
from cloth_mg_ros.physics.materials import MEASURED_MATERIALS, get_material
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.model import build_model
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening


def test_interpolation_hits_the_three_measured_directions():
    for rec in MEASURED:
        law = MEASURED_MATERIALS[rec.name].bend_law
        b = rec.bend_directions
        assert law.k1 == pytest.approx((b["weft"], b["warp"], b["bias"]), rel=1e-12)
        for phi, d in ((0.0, "weft"), (0.5 * math.pi, "warp"), (0.25 * math.pi, "bias"),
                       (0.75 * math.pi, "bias")):
            assert float(law.stiffness(phi)) == pytest.approx(b[d], rel=1e-12)
            assert float(quartic(*law.k2, phi)) == pytest.approx(law.k2[("weft", "warp", "bias")
                                                                        .index(d)], abs=1e-18)
        # One rate of rise for the three directions, k2 = r k1, the tangent kept positive.
        assert law.k2 == pytest.approx(tuple(rec.curvature_rate * k for k in law.k1), rel=1e-12)
        assert 1.0 + 2.0 * rec.curvature_rate * law.cap >= 0.5 - 1e-12
        # B = ke / 4 of the table's first column; the hinge along v is the weft strip's.
        assert b["weft"] == pytest.approx(rec.bending[2][0] / 4.0)
        assert b["warp"] == pytest.approx(rec.bending[0][0] / 4.0)
    # The curvature fit reproduces a law it was given exactly (M = k1 kappa + k2 kappa^2).
    rec = MEASURED[0]
    k1, k2 = 5e-6, 0.1e-6
    exact = tuple(tuple((k1 + k2 * c) * 4.0 for c in (0.0, 10.0, 20.0, 30.0, 40.0))
                  for _ in range(3))
    fit = replace(rec, bending=exact).curvature_fit("weft")
    assert fit == pytest.approx((k1, k2), rel=1e-9)


def _cylinder(rest: np.ndarray, psi: float, radius: float) -> np.ndarray:
    """A flat sheet rolled about an axis normal to the direction psi (rad, in its plane)."""
    d = np.array([math.cos(psi), math.sin(psi), 0.0])
    t = np.array([-d[1], d[0], 0.0])
    a, b = rest @ d, rest @ t
    x = np.outer(radius * np.sin(a / radius), d) + np.outer(b, t)
    x[:, 2] = radius * (1.0 - np.cos(a / radius))
    return x


@pytest.mark.parametrize("weft_deg", [0.0, 30.0])
def test_a_rotated_fabric_bends_with_its_directions_stiffness(weft_deg):
    """A sheet rolled along a direction psi from its weft, the weft turned in the rest frame:
    the bending energy is B(psi) / 2 A / R^2 in every direction (the law linear here)."""
    mesh = sheet_coarse(1.0, 1.0, cells_x=24, plane="xy")
    law = BendingLaw((4e-6, 9e-6, 5e-6))  # weft, warp, bias: a 2.2x spread, bias soft
    mat = replace(get_material("cotton", stretch=1.0, shear=1.0), bend_law=law)
    w = math.radians(weft_deg)
    model = build_model(mesh, mat, weft=np.array([math.cos(w), math.sin(w), 0.0]), bending="law")
    rest, area = np.array(mesh.rest), float(np.sum(mesh.face_areas))
    for psi in (0.0, 45.0, 90.0, 135.0, 20.0):
        x = _cylinder(rest, w + math.radians(psi), 0.5)
        e = internal_forces(model, x).bend_energy
        expected = 0.5 * float(law.stiffness(math.radians(psi))) * area / 0.25
        assert e == pytest.approx(expected, rel=0.03), psi
    assert abs(internal_forces(model, rest).bend_energy) < 1e-15


def test_forces_are_the_energy_gradient_and_the_hessian_the_stencils_bound():
    """FD check of the law's forces (orthotropic and curvature-dependent); the Hessian the
    system uses is the stencils' at B_H, block-symmetric as ever."""
    mesh = sheet_coarse(0.2, 0.2, cells_x=6, plane="xy")
    mat = replace(get_material("royal-target"), stretch=50.0, shear=20.0)
    model = build_model(mesh, mat, weft=np.array([math.cos(0.4), math.sin(0.4), 0.0]),
                        bending="law")
    rng = np.random.default_rng(3)
    x = np.array(mesh.rest) + 0.01 * rng.standard_normal((model.n, 3))

    def energy(y: np.ndarray) -> float:
        r = internal_forces(model, y, clamp=False)
        return r.stretch_energy + r.bend_energy

    f = internal_forces(model, x, clamp=False).forces
    for _ in range(3):
        dx = 1e-7 * rng.standard_normal(x.shape)
        fd = (energy(x + dx) - energy(x - dx)) / 2.0
        assert fd == pytest.approx(-float(np.sum(f * dx)), rel=1e-5)
    # Curvature beyond the law's range is exercised: some vertex past kappa_c.
    kv = model.bending_law.fitted_curvature(x)
    assert np.sqrt(np.einsum("vcs,vcs->v", kv, kv * np.array([1, 1, 2])[None, :, None])).max() \
        > mat.bend_law.cap
    law = mat.bend_law
    assert model.bending.bend == pytest.approx(law.hessian_bend)
    assert law.hessian_bend >= max(law.k1) * (1.0 + 1e-12)
    assert np.allclose(model.bend_pairs, bending_terms(mesh, law.hessian_bend).pair_values(mesh))


def test_coarse_levels_of_a_fabric_conserve_the_fine_bending():
    """The faithful coarsening of an orthotropic fabric's constant Hessian is the project's
    coarsening of the stencils at B_H: the fine entries are the model's, every coarse level
    is a plain material's of stiffness B_H, entry for entry (so it conserves the fine
    energy as the energy tests check for one stiffness), and the coarse bending of the
    coarse mesh matches the coarse mesh's own stencils in size."""
    hier = sheet_hierarchy(1200, depth=2, plane="xy")
    mat = get_material("pink-ribbon-brown")
    b_h = mat.bend_law.hessian_bend
    model = build_model(hier.levels[0], mat, weft=np.array([0.8, 0.6, 0.0]), bending="law")
    plain = build_model(hier.levels[0], replace(mat, bend=b_h, bend_law=None))
    fc = FaithfulCoarsening(hier, model.bending, 3)
    ref = FaithfulCoarsening(hier, plain.bending, 3)
    assert np.allclose(fc.fine_bend, model.bend_pairs)
    assert np.array_equal(fc.fine_bend, ref.fine_bend)
    assert len(fc.maps) == 2
    for got, want in zip(fc.maps, ref.maps, strict=True):
        assert np.array_equal(got.coarse_bend, want.coarse_bend)
    coarse = hier.levels[1]
    direct = bending_terms(coarse, b_h).pair_values(coarse)
    assert np.abs(fc.maps[0].coarse_bend).sum() == pytest.approx(np.abs(direct).sum(), rel=0.2)


def test_one_stiffness_keeps_todays_bending():
    """A paper material, or a measured one given --bend, has no law: today's stencils."""
    mesh = sheet_coarse(0.3, 0.3, cells_x=6, plane="xy")
    assert build_model(mesh, get_material("cotton")).bending_law is None
    plain = get_material("white-dots-on-blk", bend=1e-5)
    assert plain.bend_law is None and plain.bend == 1e-5
    model = build_model(mesh, plain)
    assert model.bending_law is None
    assert np.array_equal(model.bend_pairs, bending_terms(mesh, 1e-5).pair_values(mesh))
    assert get_material("white-dots-on-blk").bend_law is not None
    # the law is opt-in (sim.model.build_model's bending="law"): by default one stiffness,
    # the mean of the three directions
    fabric = get_material("white-dots-on-blk")
    default = build_model(mesh, fabric)
    assert default.bending_law is None
    assert np.array_equal(default.bend_pairs, bending_terms(mesh, fabric.bend).pair_values(mesh))
    assert build_model(mesh, fabric, bending="law").bending_law is not None
    with pytest.raises(ClothInputError, match="bending"):
        build_model(mesh, fabric, bending="stiff")


def test_the_elastica_with_a_moment_law_balances_its_moments():
    """The shot elastica with M = k1 kappa + k2 kappa^2 (and its tangent past the cap)
    satisfies the moment balance M(s) = w int_s^l (x(s') - x(s)) ds' along the strip."""
    gamma, growth, cap = 8.0, 0.15, 2.0
    e = elastica(gamma, samples=2001, growth=growth, cap=cap)
    u, th, x = e.u, e.theta, e.x
    k = np.gradient(th, u)
    mu_cap = cap + growth * cap * cap
    mu = np.where(k <= cap, k + growth * k * k, mu_cap + (1 + 2 * growth * cap) * (k - cap))
    tail = np.array([np.trapezoid(x[i:] - x[i], u[i:]) for i in range(len(u))])
    inner = slice(50, -50)
    assert np.allclose(mu[inner], gamma * tail[inner], atol=2e-3 * gamma)
    assert e.root_curvature > cap  # the continuation is exercised
    assert curvature_of_moment(mu_cap, growth, cap) == pytest.approx(cap)
    # The law stiffens the strip: less drop than the linear elastica of the same k1.
    assert e.tip_drop < elastica(gamma).tip_drop


def _strip(mat, direction: str, particles: int) -> dict:
    k1, _ = mat.direction_bend(direction)
    overhang = (8.0 * k1 / (mat.density * GRAVITY)) ** (1.0 / 3.0)
    spec = CantileverSpec.of_material(mat, direction, overhang, particles=particles)
    return run_cantilever(spec, mat)[0]


def test_a_strip_with_a_rising_moment_matches_its_elastica():
    """An isotropic fabric whose moment rises with curvature (past the law's range at the
    root): the settled strip against the elastica of the same law."""
    law = BendingLaw((2e-5, 2e-5, 2e-5), (5e-7, 5e-7, 5e-7), cap=40.0)
    mat = replace(get_material("white-dots-on-blk"), bend_law=law)
    block = _strip(mat, "weft", 800)
    assert block["settled"]
    assert block["tip_error_pct_of_overhang"] < 3.0
    # The law matters here: the linear elastica of k1 is farther off than the tolerance.
    lin = elastica(block["gamma"])
    off = math.hypot(block["tip_reach_m"] - lin.tip_reach * block["overhang_m"],
                     block["tip_drop_m"] - lin.tip_drop * block["overhang_m"])
    assert 100.0 * off / block["overhang_m"] > 5.0


@pytest.mark.parametrize("name", ["white-dots-on-blk", "white-swim-solid"])
def test_cantilever_by_direction_matches_the_exact_elastica(name):
    """Cut along the weft, warp and bias, each strip's tip against the elastica of that
    direction's law (k1, k2), within 3 % of l on a small mesh."""
    mat = get_material(name)
    for direction in ("weft", "warp", "bias"):
        block = _strip(mat, direction, 800)
        assert block["settled"]
        assert block["direction"] == direction
        assert block["tip_error_pct_of_overhang"] < 3.0, (direction, block)


def test_fabric_axes_with_the_weft_normal_to_the_cloth_fall_back_to_an_edge_everywhere():
    """Where the weft has no part in the cloth's plane, each vertex takes an edge of its own
    as t1: every vertex's axes are unit and orthogonal (a vertex that was only ever an
    edge's second end had none: NaN)."""
    from cloth_mg_ros.physics.bending_law import vertex_frames

    mesh = sheet_coarse(1, 1, 4)
    normal = np.cross(mesh.rest[mesh.faces[0, 1]] - mesh.rest[mesh.faces[0, 0]],
                      mesh.rest[mesh.faces[0, 2]] - mesh.rest[mesh.faces[0, 0]])
    t1, t2 = vertex_frames(mesh, normal / np.linalg.norm(normal))
    assert np.all(np.isfinite(t1)) and np.all(np.isfinite(t2))
    assert np.allclose(np.linalg.norm(t1, axis=1), 1.0)
    assert np.allclose(np.einsum("ij,ij->i", t1, t2), 0.0, atol=1e-12)
