"""`cloth-mg bench peers`: options, the scene and material handed to the peers, our own row,
skipped and failed rows; tiny Newton and MuJoCo runs where the peers extra is installed."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from matplotlib import pyplot as plt

from cloth_mg_ros.bench import peers
from cloth_mg_ros.bench.peers import (
    DEFAULT_SETTINGS,
    INSTALL_HINT,
    bench_peers,
    build_spec,
    format_peers_report,
    hinge_stiffness,
    membrane_lame,
    mujoco_xml,
    parse_engines,
    parse_settings,
    peer_parameters,
    plot_peers,
    run_engine,
    validate_peers_args,
)
from cloth_mg_ros.bench.peers import run as peers_run  # where bench_peers calls missing_modules
from cloth_mg_ros.bench.peers.mujoco import _MujocoEngine
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.bending import wing_weights
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.stretch import stretch_elements, stretch_energy

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench

ROW_KEYS = ("engine", "solver", "label", "particles", "ms_per_step", "steps", "finite",
            "mean_height_m", "sag_m", "hang_m", "max_penetration_m", "max_stretch",
            "peak_stretch", "mass_kg", "skipped", "draped")


@pytest.fixture(scope="module")
def spec300():
    return build_spec(300, "cotton", 1.0 / 60.0, 6)


# -- options ------------------------------------------------------------------------------
def test_parse_engines():
    assert parse_engines("all") == ["ours:mpcg", "ours:mg", "newton:style3d", "newton:vbd",
                                    "mujoco:newton", "mujoco:cg"]
    assert parse_engines("ours, newton:vbd") == ["ours:mpcg", "ours:mg", "newton:vbd"]
    with pytest.raises(ClothInputError, match="unknown engine 'bullet'"):
        parse_engines("ours,bullet")
    with pytest.raises(ClothInputError, match="no solver 'xpbd'"):
        parse_engines("newton:xpbd")
    with pytest.raises(ClothInputError, match="ours:mg twice"):
        parse_engines("ours,ours:mg")
    with pytest.raises(ClothInputError, match="at least one"):
        parse_engines(" , ")


def test_parse_settings():
    assert parse_settings(["newton:vbd.iterations=20", "newton:vbd.contact_ke=5e3"]) == {
        "newton:vbd": {"iterations": 20, "contact_ke": 5000.0}}
    assert parse_settings(None) == {}
    for bad, what in (("newton:vbd.iterations=2.5", "whole number"),
                      ("newton:vbd.iterations=-1", "positive"),
                      ("newton:vbd.iterations=many", "not a number"),
                      ("newton:vbd.colour=1", "no setting 'colour'"),
                      ("bullet:x.iterations=1", "unknown run"),
                      ("iterations", "expected")):
        with pytest.raises(ClothInputError, match=what):
            parse_settings([bad])


def test_validation_lists_every_problem():
    with pytest.raises(ClothInputError) as err:
        validate_peers_args([10, 300, 300], ["ours:mpcg", "ours:cholesky"], 2, 0.5, "paper")
    text = str(err.value)
    for part in ("got 10", "twice", "'ours:cholesky'", "--steps", "--dt", "'paper'"):
        assert part in text
    validate_peers_args([300], ["ours:mpcg"], 3, 1.0 / 60.0, "Cotton")  # fine


def test_cli_rejects_before_any_work(capsys):
    assert main(["bench", "peers", "--particles", "12"]) == 2
    assert "--particles must be integers in 16..200000, got 12" in capsys.readouterr().err
    assert main(["bench", "peers", "--engines", "ours:amg"]) == 2
    assert "no solver 'amg'" in capsys.readouterr().err
    assert main(["bench", "peers", "--set", "mujoco:cg.iterations=0"]) == 2
    assert "positive" in capsys.readouterr().err
    with pytest.raises(ClothInputError, match="unknown setting"):
        bench_peers([300], "ours:mpcg", steps=3, settings={"ours:mpcg": {"substeps": 2}})


# -- the scene and the mapping ------------------------------------------------------------
def test_spec_is_the_drape_scene(spec300):
    mat = get_material("cotton")
    n = spec300.n
    assert 250 <= n <= 350 and spec300.particles_requested == 300
    assert spec300.rest.shape == (n, 3) and spec300.faces.shape[1] == 3
    assert spec300.faces.min() == 0 and spec300.faces.max() == n - 1
    p = spec300.rest[spec300.faces]
    areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    np.testing.assert_allclose(areas, spec300.areas, rtol=1e-12)
    assert math.isclose(areas.sum(), 1.0, rel_tol=1e-9)  # the 1 m x 1 m sheet
    # Masses: density x a third of each adjacent triangle, summing to density x area.
    lumped = np.bincount(spec300.faces.ravel(), np.repeat(areas / 3.0, 3), n) * mat.density
    np.testing.assert_allclose(spec300.mass, lumped, rtol=1e-12)
    assert math.isclose(spec300.mass.sum(), mat.density * areas.sum(), rel_tol=1e-12)
    assert np.allclose(spec300.rest[:, 2], 0.85) and spec300.sphere_top == pytest.approx(0.75)
    e = spec300.edges
    np.testing.assert_allclose(
        np.linalg.norm(spec300.rest[e[:, 1]] - spec300.rest[e[:, 0]], axis=1), spec300.edge_rest)
    assert spec300.gravity[2] == pytest.approx(-9.81) and spec300.thickness == 0.005


@pytest.mark.parametrize("name", ["cotton", "leather"])
def test_membrane_matches_our_small_strain_energy(name):
    """Our four-measure stretch energy of a small strain equals the isotropic membrane with
    (mu, lambda) = membrane_lame where stretch = 2 shear; for leather only uniaxially."""
    mat = get_material(name)
    mu, lam = membrane_lame(mat)
    rest = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    faces = np.array([[0, 1, 2]])
    area = 0.005
    st = stretch_elements(rest, faces, np.array([area]), mat.stretch, mat.shear)
    strains = [np.array([[1e-4, 0.0], [0.0, 0.0]])]  # weft only, lateral held
    if name == "cotton":
        strains += [np.array([[2e-4, 0.7e-4], [0.7e-4, -1e-4]]),
                    np.array([[0.0, 1e-4], [1e-4, 0.0]])]
    for eps in strains:
        x = rest.copy()
        x[:, :2] = rest[:, :2] @ (np.eye(2) + eps).T
        ours = float(stretch_energy(x, faces, st.coef, st.stiff, st.rest_len))
        iso = area * (mu * np.sum(eps * eps) + 0.5 * lam * np.trace(eps) ** 2)
        assert ours == pytest.approx(iso, rel=2e-3)
    notes = " ".join(peer_parameters(mat)["mujoco"]["notes"])
    assert ("exactly" in notes) == (name == "cotton")


def test_mujoco_parameters_give_our_stiffness_and_bending():
    mat = get_material("cotton")
    p = peer_parameters(mat)["mujoco"]
    mu, lam = membrane_lame(mat)
    e, nu, t = p["young"], p["poisson"], p["thickness"]
    assert e * t / (2.0 * (1.0 + nu)) == pytest.approx(mu)  # shear modulus x thickness
    assert e * t * nu / (1.0 - nu * nu) == pytest.approx(lam)  # plane-stress lambda x t
    assert e * t ** 3 / (12.0 * (1.0 - nu * nu)) == pytest.approx(mat.bend)
    assert p["damping"] == mat.damping
    s3d = peer_parameters(mat)["style3d"]
    assert s3d["tri_aniso_ke"] == (12000.0, 12000.0, 4000.0) and s3d["edge_ke"] == mat.bend / 3
    vbd = peer_parameters(mat)["vbd"]
    assert (vbd["tri_ke"], vbd["tri_ka"]) == (4000.0, 4000.0)


def test_hinge_stiffness_matches_our_bending():
    """Two equilateral triangles folded by a small angle: k L theta^2 / 2 equals our
    bend / (A0 + A1) |sum k_m x_m|^2 / 2; boundary hinges get 0."""
    side, bend = 0.02, 2.4e-5
    h = side * math.sqrt(3.0) / 2.0
    theta = 1e-3
    # edge (0, 1) along x; tips 2 (flat, +y) and 3 (-y, lifted by theta out of the plane)
    x = np.array([[0.0, 0.0, 0.0], [side, 0.0, 0.0], [side / 2, h, 0.0],
                  [side / 2, -h * math.cos(theta), h * math.sin(theta)]])
    flat = x.copy()
    flat[3] = [side / 2, -h, 0.0]
    hinges = np.array([[2, 3, 0, 1], [2, -1, 0, 1]])
    k = hinge_stiffness(flat, hinges, bend)
    assert k[1] == 0.0
    assert k[0] == pytest.approx(2.0 * bend / (math.sqrt(3.0) * side))
    w = wing_weights(flat, np.array([[0, 1, 2, 3]]))[0]
    s = (w[:, None] * x).sum(axis=0)
    ours = bend / (2 * side * h / 2) * float(s @ s) / 2.0
    assert k[0] * side * theta ** 2 / 2.0 == pytest.approx(ours, rel=1e-3)


def test_mujoco_xml_holds_the_same_sheet(spec300):
    root = ET.fromstring(mujoco_xml(spec300, "cg", substeps=2, iterations=50))
    opt = root.find("option")
    assert opt.get("integrator") == "discrete" and opt.get("solver") == "CG"
    assert float(opt.get("timestep")) == pytest.approx(spec300.dt / 2)
    flex = root.find("worldbody/flexcomp")
    pts = np.array(flex.get("point").split(), dtype=float).reshape(-1, 3)
    els = np.array(flex.get("element").split(), dtype=int).reshape(-1, 3)
    np.testing.assert_allclose(pts, spec300.rest, atol=1e-8)
    np.testing.assert_array_equal(els, spec300.faces)
    assert float(flex.get("mass")) == pytest.approx(spec300.mass.sum())
    assert float(flex.get("radius")) == spec300.thickness
    assert flex.find("contact").get("selfcollide") == "none"
    sphere = root.find("worldbody/geom[@name='sphere']")
    assert float(sphere.get("size")) == spec300.sphere_radius
    assert float(sphere.get("friction").split()[0]) == spec300.sphere_friction
    assert flex.find("elasticity").get("elastic2d") == "both"


# -- running ------------------------------------------------------------------------------
def test_our_row(spec300):
    row = run_engine(spec300, "ours:mpcg")
    assert all(k in row for k in ROW_KEYS)
    assert row["particles"] == spec300.n and row["steps"] == 6 and row["timed_steps"] == 4
    assert row["ms_per_step"] > 0 and row["first_step_ms"] > 0 and not row["skipped"]
    assert row["finite"] and row["mass_kg"] == pytest.approx(0.2)
    # 6 steps of 1/60 s: the sheet is still falling, not yet on the sphere.
    assert 0.75 < row["mean_height_m"] < 0.85 and row["sag_m"] < 0 and not row["draped"]
    assert row["max_penetration_m"] == 0.0 and 1.0 <= row["max_stretch"] < 1.1
    # a free fall is a common translation of the sheet, which the solver's first guess
    # finds exactly: no iteration is needed until the sheet meets the sphere
    assert row["iterations"] == 0 and row["settings"]["tol"] == 1e-4


class _FakeEngine:
    """Falls at 1 m/s, goes NaN at step ``nan_at`` (never if None)."""

    nan_at = None

    def __init__(self, spec, solver, settings):
        self.x, self.k, self.dt, self.mass_kg = spec.rest.copy(), 0, spec.dt, 0.2

    def step(self):
        self.k += 1
        self.x[:, 2] -= self.dt
        if self.nan_at is not None and self.k >= self.nan_at:
            self.x[0, 0] = np.nan

    def positions(self):
        return self.x


class _NaNEngine(_FakeEngine):
    nan_at = 4


class _ThreadsEngine(_FakeEngine):
    """Records the kernel threads numba would give a step."""

    seen: list[int] = []

    def step(self):
        import numba

        _ThreadsEngine.seen.append(numba.get_num_threads())
        super().step()


def test_our_engine_and_peers_share_one_thread_count(monkeypatch):
    import numba

    monkeypatch.setitem(peers.ENGINE_CLASSES, "mujoco", _ThreadsEngine)
    monkeypatch.setattr(peers_run, "missing_modules", lambda engine: [])
    before = numba.get_num_threads()
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)  # the default: every core
    try:
        result = bench_peers([300], "mujoco:cg", steps=3, log=lambda line: None)
        assert result["meta"]["threads"] == 1 and set(_ThreadsEngine.seen) == {1}
        assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS
    finally:
        numba.set_num_threads(before)
    with pytest.raises(ClothInputError, match="threads"):
        bench_peers([300], "mujoco:cg", steps=3, threads=-2)


class _BrokenEngine:
    def __init__(self, spec, solver, settings):
        raise RuntimeError("engine exploded")


def test_missing_extra_and_failures_are_recorded_not_raised(monkeypatch, tmp_path):
    monkeypatch.setattr(peers_run, "missing_modules",
                        lambda engine: ["mujoco"] if engine == "mujoco" else [])
    monkeypatch.setitem(peers.ENGINE_CLASSES, "newton", _NaNEngine)
    lines: list[str] = []
    result = bench_peers([300], "ours:mpcg,newton:vbd,mujoco", steps=6, log=lines.append)
    runs = {r["label"]: r for r in result["runs"]}
    assert list(runs) == ["ours:mpcg", "newton:vbd", "mujoco:newton", "mujoco:cg"]
    for label in ("mujoco:newton", "mujoco:cg"):
        assert runs[label]["skipped"] and INSTALL_HINT in runs[label]["skip_reason"]
        assert runs[label]["ms_per_step"] is None
    assert result["meta"]["unavailable"]["mujoco:cg"].startswith("mujoco not installed")
    nan = runs["newton:vbd"]
    assert not nan["finite"] and nan["nan_at_step"] == 4 and nan["steps"] == 4
    assert nan["sag_m"] is None and not nan["draped"]
    assert runs["ours:mpcg"]["finite"] and not runs["ours:mpcg"]["skipped"]
    report = format_peers_report(result)
    assert "skip" in report and "NaN" in report and INSTALL_HINT in report
    png = plot_peers(result, tmp_path / "peers.png")
    assert plt.imread(png).shape[0] > 100
    # An engine that fails to build: a skipped row with the reason, the others still run.
    monkeypatch.setitem(peers.ENGINE_CLASSES, "newton", _BrokenEngine)
    result = bench_peers([300], "newton:vbd,ours:mpcg", steps=3, log=lines.append)
    broken, ours = result["runs"]
    assert broken["skipped"] and "engine exploded" in broken["skip_reason"]
    assert not ours["skipped"] and ours["finite"]


def test_cli_writes_json_png_and_table(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(peers.ENGINE_CLASSES, "mujoco", _FakeEngine)
    monkeypatch.setattr(peers_run, "missing_modules", lambda engine: [])
    out_json, out_png = tmp_path / "peers.json", tmp_path / "peers.png"
    rc = main(["bench", "peers", "--particles", "300", "--steps", "4", "--engines",
               "ours:mpcg,mujoco:cg", "--set", "mujoco:cg.iterations=7", "--json",
               str(out_json), "--png", str(out_png)])
    assert rc == 0
    result = json.loads(out_json.read_text())
    assert [r["label"] for r in result["runs"]] == ["ours:mpcg", "mujoco:cg"]
    assert result["runs"][1]["settings"]["iterations"] == 7
    meta = result["meta"]
    assert meta["steps"] == 4 and meta["dt"] == pytest.approx(1 / 60)
    assert meta["settings"]["mujoco:cg"]["iterations"] == 7
    assert any("walking garment" in n for n in meta["notes"])
    assert "OPENBLAS_NUM_THREADS" in meta and "warmup_s" in meta
    assert meta["threads"] == 1  # our engine on one thread, as the peers' CPU paths
    assert plt.imread(out_png).shape[1] > 100
    text = capsys.readouterr().out
    assert "ms per step" in text and "ours:mpcg" in text and "notes:" in text


# -- the peers themselves, where the extra is installed ------------------------------------
def _check_peer_row(row, spec):
    assert not row["skipped"] and row["finite"] and row["particles"] == spec.n
    assert row["ms_per_step"] > 0 and row["steps"] == spec.steps
    assert row["mass_kg"] == pytest.approx(spec.mass.sum(), rel=1e-5)
    assert 0.75 < row["mean_height_m"] < 0.86  # falling flat, not yet draped
    assert row["max_stretch"] < 1.2


@pytest.mark.parametrize("solver", ["vbd", "style3d"])
def test_newton_tiny_run(solver):
    pytest.importorskip("warp")
    pytest.importorskip("newton")
    spec = build_spec(100, "cotton", 1.0 / 60.0, 3)
    settings = dict(DEFAULT_SETTINGS[f"newton:{solver}"], substeps=2, iterations=4)
    row = run_engine(spec, f"newton:{solver}", settings)
    _check_peer_row(row, spec)
    assert row["substeps"] == 2


@pytest.mark.parametrize("solver", ["newton", "cg"])
def test_mujoco_tiny_run(solver):
    pytest.importorskip("mujoco")
    spec = build_spec(100, "cotton", 1.0 / 60.0, 3)
    row = run_engine(spec, f"mujoco:{solver}")
    _check_peer_row(row, spec)
    eng = _MujocoEngine(spec, solver, DEFAULT_SETTINGS[f"mujoco:{solver}"])
    start = eng.m.flex_vertadr[0]
    bodies = eng.m.flex_vertbodyid[start:start + spec.n]
    np.testing.assert_allclose(eng.m.body_mass[bodies], spec.mass)  # our lumped masses


def test_the_peers_warm_up_skips_what_is_missing_and_refuses_a_failure(monkeypatch, capsys):
    """`cloth-mg warmup --peers` (make test runs it): each installed peer steps a few times,
    one not installed is named with the extra to install, one that fails stops it."""
    monkeypatch.setattr(peers_run, "missing_modules",
                        lambda engine: ["mujoco"] if engine == "mujoco" else [])
    monkeypatch.setitem(peers.ENGINE_CLASSES, "newton", _FakeEngine)
    assert main(["warmup", "--peers"]) == 0
    out = capsys.readouterr().out
    assert "warm-up newton:vbd" in out and "warm-up newton:style3d" in out
    assert f"warm-up mujoco:cg: not installed ({INSTALL_HINT})" in out
    assert "peers' warm-up done" in out
    monkeypatch.setitem(peers.ENGINE_CLASSES, "newton", _BrokenEngine)
    with pytest.raises(RuntimeError, match="newton:vbd failed in warm-up.*engine exploded"):
        peers_run.warm_up_peers(log=lambda line: None)
