"""Physical accuracy: the exact elastica, the plate's bending energy, the cantilever scene
against the exact curve, the measured fabrics and their command line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.cantilever import CantileverSpec, run_cantilever
from cloth_mg_ros.fidelity.elastica import elastica, gamma_at_chord, gamma_of
from cloth_mg_ros.fidelity.strips import strip_hierarchy
from cloth_mg_ros.mesh import sheet_coarse
from cloth_mg_ros.physics.fabrics import MEASURED, spring_constants
from cloth_mg_ros.physics.materials import MATERIALS, MEASURED_MATERIALS, get_material
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.model import build_model


def test_elastica_matches_the_published_points():
    """ASTM D1388's 41.5 degree chord at G = 8.0042 with the tip 0.7243 l out and 0.6408 l
    down; G = 2: chord 13.86 degrees; G = 30: 68.57 degrees (shared/REFERENCES.md)."""
    assert gamma_at_chord(41.5) == pytest.approx(8.0042, abs=2e-4)
    e = elastica(8.0042)
    assert e.tip_reach == pytest.approx(0.7243, abs=1e-4)
    assert e.tip_drop == pytest.approx(0.6408, abs=1e-4)
    assert e.tip_angle_deg == pytest.approx(53.88, abs=0.01)
    assert elastica(2.0).chord_angle_deg == pytest.approx(13.86, abs=0.01)
    assert elastica(30.0).chord_angle_deg == pytest.approx(68.57, abs=0.01)
    # Small G is the linear cantilever: tip drop w l^4 / (8 B), i.e. G / 8 in units of l.
    assert elastica(0.05).tip_drop == pytest.approx(0.05 / 8, rel=2e-3)
    # The strip is inextensible: its arc length is l.
    seg = np.hypot(np.diff(e.x), np.diff(e.z))
    assert seg.sum() == pytest.approx(1.0, rel=1e-4)
    with pytest.raises(ClothInputError, match="G must be a positive"):
        elastica(-1.0)


def _bent(rest: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Rest positions lifted by the height field z = p^T K p / 2 about the sheet's centre."""
    p = rest[:, :2] - rest[:, :2].mean(axis=0)
    out = rest.copy()
    out[:, 2] = 0.5 * np.einsum("ni,ij,nj->n", p, K, p)
    return out


def test_bending_is_a_plate_with_poisson_ratio_zero():
    """(B / 2)(k1^2 + k2^2) for every curvature: cylinders either way, a sphere (twice a
    cylinder) and a saddle (twice too); the hinges alone would give the sphere 4/3 and the
    saddle 8/3 of a cylinder (Poisson ratio -1/3)."""
    mesh = sheet_coarse(1.0, 1.0, cells_x=40, plane="xy")
    mat = get_material("cotton")
    model = build_model(mesh, mat)
    area = float(np.sum(mesh.face_areas))
    kappa = 0.2  # 1/m: small slopes, where the height field is a plate's bending
    energy = {}
    for name, K in (("x", np.diag([kappa, 0.0])), ("y", np.diag([0.0, kappa])),
                    ("sphere", np.diag([kappa, kappa])), ("saddle", np.diag([kappa, -kappa]))):
        x = _bent(np.array(mesh.rest), K)
        energy[name] = internal_forces(model, x).bend_energy
        expected = 0.5 * mat.bend * float(np.sum(K * K)) * area
        assert energy[name] == pytest.approx(expected, rel=0.06), name
    assert energy["sphere"] / energy["x"] == pytest.approx(2.0, rel=0.06)
    assert energy["saddle"] / energy["x"] == pytest.approx(2.0, rel=0.06)


def test_strip_cut_is_a_mesh_line_and_the_count_is_close():
    for kind, angle in (("lattice", 0.0), ("lattice", 45.0), ("garment", 0.0)):
        hier = strip_hierarchy(kind, -0.015, 0.1, 0.025, 1200, angle, cuts=(0.0,))
        rest = hier.finest.rest
        assert 900 < len(rest) < 1600, (kind, angle, len(rest))
        on_cut = np.abs(rest[:, 0]) < 1e-12
        # Every face lies on one side of the cut: none crosses it.
        xs = rest[hier.finest.faces, 0]
        assert not np.any((xs.min(axis=1) < -1e-12) & (xs.max(axis=1) > 1e-12))
        assert on_cut.sum() >= 5


@pytest.mark.parametrize("gamma", [2.0, 20.0])
@pytest.mark.parametrize("mesh, orientation", [("lattice", 0.0), ("lattice", 45.0),
                                               ("garment", 0.0)])
def test_cantilever_tip_on_the_exact_elastica(gamma, mesh, orientation):
    """A strip at a small resolution settles within 2.5 % of l of the exact tip."""
    density, overhang = 0.25, 0.08
    bend = density * 9.81 * overhang ** 3 / gamma
    spec = CantileverSpec(bend, density, overhang, orientation=orientation, mesh=mesh,
                          particles=900)
    assert spec.gamma == pytest.approx(gamma)
    block, _, result = run_cantilever(spec)
    assert block["settled"] and result.settled
    assert block["tip_error_pct_of_overhang"] < 2.5
    exact = elastica(gamma)
    assert block["chord_angle_deg"] == pytest.approx(exact.chord_angle_deg, abs=2.0)
    assert block["tip_angle_deg"] == pytest.approx(exact.tip_angle_deg, abs=4.0)


def test_cantilever_rejects_bad_input():
    with pytest.raises(ClothInputError, match="--overhang must be a positive"):
        CantileverSpec(1e-5, 0.2, -0.1)
    with pytest.raises(ClothInputError, match="--mesh must be one of"):
        CantileverSpec(1e-5, 0.2, 0.1, mesh="quads")
    assert gamma_of(1e-5, 0.2, 0.1) == pytest.approx(0.2 * 9.81 * 1e-3 / 1e-5)


def test_measured_fabrics_carry_their_sources_and_moduli():
    measured = [m for m in MATERIALS.values() if m.kind == "measured"]
    assert len(measured) >= 5
    for m in measured:
        assert "Wang" in m.source and "2011" in m.source
        assert 0.1 < m.density < 0.35
        assert 0.5 < 100.0 * m.bending_length() < 4.0  # cm, the cantilever's usual range
    # ARCSim's bending table holds 4 B: gray-interlock's curvature-0 column averages
    # 20.74e-6 N m, so B = 5.18e-6 N m.
    gray = MEASURED_MATERIALS["gray-interlock"]
    assert gray.bend == pytest.approx(np.mean([23.191698e-6, 24.749964e-6, 14.267624e-6]) / 4.0)
    # The uniaxial moduli of the data (E = k0 - k1^2 / k2, k = 2 C) are met exactly.
    for rec in MEASURED:
        e_u, e_v, _ = rec.moduli
        m = MATERIALS[rec.name]
        assert m.uniaxial_stiffness("weft") == pytest.approx(e_u, rel=1e-6)
        assert m.uniaxial_stiffness("warp") == pytest.approx(e_v, rel=1e-6)
    # Where the spring membrane cannot have the measured shear too, it says so.
    k_u, k_v, k_s, exact = spring_constants(25.0, 6.5, 17.6)
    assert not exact and k_s < 17.6 and min(k_u, k_v) >= 0.0
    assert "instead of the measured" in MATERIALS["navy-sparkle-sweat"].note
    assert MATERIALS["cotton"].kind == "paper"


def test_materials_command_lists_them(tmp_path, capsys):
    out = tmp_path / "materials.json"
    assert main(["materials", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "11oz-black-denim" in text and "Wang, O'Brien, Ramamoorthi" in text
    rows = json.loads(out.read_text())
    assert sum(r["kind"] == "measured" for r in rows) == 10
    assert all(math.isfinite(r["bend_nm"]) for r in rows)


def test_cantilever_command_writes_its_block(tmp_path, capsys):
    out = tmp_path / "cant"
    code = main(["run", "--scene", "cantilever", "--bend", "2e-5", "--density", "0.2",
                 "--overhang", "0.06", "--particles", "500", "--orientation", "30",
                 "--out", str(out)])
    assert code == 0
    block = json.loads((out / "summary.json").read_text())["cantilever"]
    for key in ("overhang_m", "bend_nm", "density_kgm2", "gamma", "tip_reach_m", "tip_drop_m",
                "chord_angle_deg", "tip_angle_deg", "settled"):
        assert key in block
    assert block["settled"] is True
    assert (out / "frames.png").stat().st_size > 1000
    assert main(["run", "--scene", "cantilever", "--bend", "2e-5", "--density", "0.2",
                 "--out", str(out)]) == 2
    assert "--overhang" in capsys.readouterr().err


def test_cusick_and_tensile_commands_write_their_blocks(tmp_path):
    out = tmp_path / "cusick"
    assert main(["run", "--scene", "cusick", "--material", "royal-target", "--particles",
                 "400", "--out", str(out)]) == 0
    block = json.loads((out / "summary.json").read_text())["cusick"]
    assert 0.0 < block["dc"] < 1.0 and block["nodes"] >= 3 and block["settled"] is True
    assert (out / "frames.png").stat().st_size > 1000
    out = tmp_path / "tensile"
    assert main(["run", "--scene", "tensile", "--material", "11oz-black-denim", "--axis",
                 "warp", "--particles", "300", "--out", str(out)]) == 0
    block = json.loads((out / "summary.json").read_text())["tensile"]
    assert abs(block["error_pct"]) < 1.0
    assert main(["run", "--scene", "cusick", "--overhang", "0.1", "--out", str(out)]) == 2
