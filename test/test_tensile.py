"""The tensile strip test (`fidelity.tensile`): a strip pulled by a known force stretches by
F / (k W) within 1 %, along and across the material, on every mesh kind and orientation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.tensile import (
    DEFAULT_STRAIN,
    TensileSpec,
    build_tensile,
    edge_shares,
    homogeneous_strain,
    poisson_ratio,
    run_tensile,
)
from cloth_mg_ros.physics.materials import get_material

PARTICLES = 400  # the strain is exact on any mesh (see below), so a small one will do
MESHES = [("lattice", 0.0), ("lattice", 45.0), ("garment", 0.0)]


@pytest.mark.parametrize("mesh,orientation", MESHES)
@pytest.mark.parametrize("axis", ["weft", "warp"])
@pytest.mark.parametrize("material", ["11oz-black-denim", "cotton"])
def test_strain_matches_linear_stiffness(material, axis, mesh, orientation):
    """The issue's bound: strain within 1 % of F / (k W) at the default 1 % strain."""
    spec = TensileSpec(material, axis=axis, mesh=mesh, orientation=orientation,
                       particles=PARTICLES)
    block, _, result = run_tensile(spec)
    assert result.settled
    assert block["force_residual"] < 1e-4
    assert block["expected_strain"] == pytest.approx(DEFAULT_STRAIN, rel=1e-12)
    assert abs(block["error_pct"]) < 1.0, block
    # What is left after the springs' own nonlinearity is the discretisation and the held
    # end: linear triangles hold a uniform stretch exactly, so that is tiny on every mesh.
    assert abs(block["error_vs_model_pct"]) < 0.05, block
    # The sideways contraction (for information in the block) follows the model as well.
    assert block["lateral_strain"] == pytest.approx(block["model_lateral_strain"], rel=0.01)


def test_same_force_stretches_weft_and_warp_by_their_own_stiffness():
    """An anisotropic fabric pulled by one force along and across: strains in the ratio of
    the two uniaxial stiffnesses (denim's warp is about five times its weft)."""
    mat = get_material("11oz-black-denim")
    force = 0.005 * mat.uniaxial_stiffness("weft") * 0.05  # 0.5 % along the weft
    strains = {}
    for axis in ("weft", "warp"):
        block, _, _ = run_tensile(TensileSpec("11oz-black-denim", force=force, axis=axis,
                                              particles=200))
        strains[axis] = block["strain"]
        assert abs(block["error_pct"]) < 1.0, block
    ratio = mat.uniaxial_stiffness("warp") / mat.uniaxial_stiffness("weft")
    assert ratio > 4.0
    assert strains["weft"] / strains["warp"] == pytest.approx(ratio, rel=0.01)


def test_load_is_a_uniform_traction_on_the_free_end():
    spec = TensileSpec("cotton", force=3.0, particles=200)
    scene = build_tensile(spec)
    f = scene.model.external_force
    assert f.shape == (scene.model.n, 3)
    assert f[:, 0].sum() == pytest.approx(3.0, rel=1e-12)
    assert np.all(f[:, 1:] == 0.0)
    assert np.count_nonzero(f[:, 0]) == len(scene.loaded)
    rest = scene.model.mesh.rest
    # Traction: each end particle's load over its share of the edge is F / W.
    shares = edge_shares(rest[scene.loaded, 1])
    assert np.allclose(f[scene.loaded, 0] / shares, 3.0 / spec.width, rtol=1e-12)
    assert np.allclose(rest[scene.held, 0], 0.0)
    assert np.all(np.isin(scene.held, scene.model.pinned))
    g0, g1 = spec.gauge_x
    assert np.allclose(rest[scene.gauge_start, 0], g0)
    assert np.allclose(rest[scene.gauge_end, 0], g1)
    # The gauge marks are mesh lines across the whole width.
    for idx in (scene.gauge_start, scene.gauge_end):
        assert rest[idx, 1].min() == pytest.approx(-0.5 * spec.width)
        assert rest[idx, 1].max() == pytest.approx(0.5 * spec.width)


def test_edge_shares_are_the_trapezoid_weights():
    y = np.array([0.3, -0.5, 0.0, 0.5])
    assert np.allclose(edge_shares(y), [0.25, 0.25, 0.4, 0.1])
    assert edge_shares(y).sum() == pytest.approx(1.0)


@pytest.mark.parametrize("material", ["cotton", "11oz-black-denim", "gray-interlock"])
@pytest.mark.parametrize("axis", ["weft", "warp"])
def test_homogeneous_strain_linearises_to_the_material_law(material, axis):
    mat = get_material(material)
    k = mat.uniaxial_stiffness(axis)
    e = 1e-6
    axial, lateral = homogeneous_strain(mat, axis, e * k)
    assert axial == pytest.approx(e, rel=1e-5)
    assert lateral == pytest.approx(-poisson_ratio(mat, axis) * e, rel=1e-5)
    # At 1 % the springs' nonlinearity is below 1 % of the strain for these fabrics.
    axial, _ = homogeneous_strain(mat, axis, 0.01 * k)
    assert abs(axial / 0.01 - 1.0) < 0.01


@pytest.mark.parametrize("kwargs,bad", [
    ({"force": -1.0}, "-1.0"),
    ({"force": 0.0}, "0.0"),
    ({"force": math.nan}, "nan"),
    ({"axis": "bias"}, "'bias'"),
    ({"mesh": "quad"}, "'quad'"),
    ({"width": -0.05}, "-0.05"),
    ({"length": 0.0}, "0.0"),
    ({"particles": 4}, "4"),
    ({"gauge": (0.9, 0.5)}, "(0.9, 0.5)"),
    ({"orientation": math.inf}, "inf"),
])
def test_bad_input_names_the_value(kwargs, bad):
    with pytest.raises(ClothInputError) as err:
        TensileSpec("cotton", **kwargs)
    assert bad in str(err.value)
    assert next(iter(kwargs)) in str(err.value)


def test_unknown_material_is_named():
    with pytest.raises(ClothInputError, match="'felt'"):
        TensileSpec("felt")
