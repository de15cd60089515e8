"""Compression that buckles (physics.wrinkles): a face wrinkles along the fabric's threads
where its stress is compressive past the buckling stress pi^2 B / h^2; its energy is
continuous with a continuous gradient, the forces are that gradient, tension is untouched,
and the Hessian stays block-symmetric and positive semi-definite."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.tensile import poisson_ratio
from cloth_mg_ros.mesh import sheet_coarse
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.stretch import stretch_energy
from cloth_mg_ros.physics.wrinkles import relax
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.model import build_model

MATERIALS = ["cotton", "white-dots-on-blk"]


def _sheet(material: str, compression: str = "buckle", cells: int = 6):
    mesh = sheet_coarse(0.3, 0.3, cells_x=cells, plane="xy")
    return build_model(mesh, get_material(material), compression=compression)


def _energy(model, x) -> float:
    st = model.stretch
    return float(stretch_energy(x, model.mesh.faces, st.coef, st.stiff, st.rest_len, st.cap))


def _wrinkles(model, x) -> np.ndarray:
    """(t, 2) each face's wrinkle strains along weft and warp."""
    st, faces = model.stretch, model.mesh.faces
    return np.array([relax(x, *faces[t], st.coef[t], st.stiff[t], st.rest_len, st.cap[t])
                     for t in range(len(faces))])


def _squeezed(model, along: float, across: float, noise: float, seed: int = 0) -> np.ndarray:
    """The rest sheet scaled by (along, across) in its plane, plus Gaussian noise (m)."""
    rng = np.random.default_rng(seed)
    x = np.array(model.mesh.rest)
    x[:, 0] *= along
    x[:, 1] *= across
    return x + noise * rng.standard_normal(x.shape)


@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("along,across,noise", [(0.97, 1.0, 5e-4), (0.97, 0.97, 5e-4),
                                                (0.99, 1.002, 2e-3), (1.02, 1.0, 1e-3)])
def test_forces_are_the_energy_gradient_where_faces_wrinkle(material, along, across, noise):
    model = _sheet(material)
    x = _squeezed(model, along, across, noise)
    f = internal_forces(model, x).forces
    bend = internal_forces(model, x).bend_energy  # linear bending: its own exact part

    def total(y):
        return _energy(model, y) + internal_forces(model, y).bend_energy

    assert np.isfinite(bend)
    eps = 1e-7
    worst = 0.0
    for i in range(0, model.n, 4):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            fd = -(total(xp) - total(xm)) / (2 * eps)
            worst = max(worst, abs(fd - f[i, a]))
    assert worst <= 1e-6 * max(1.0, np.abs(f).max())
    if along < 1.0:
        assert np.any(_wrinkles(model, x) > 0.0)  # the case does exercise the wrinkles


@pytest.mark.parametrize("material", MATERIALS)
def test_tension_is_untouched(material):
    """A sheet stretched 2 % along, its sides free to narrow (the crosswise measures shorten
    against the diagonals, the crosswise stress is nil): no face wrinkles and forces, energy
    and Hessian are the elastic membrane's, bit for bit."""
    buckle, elastic = _sheet(material), _sheet(material, "elastic")
    nu = poisson_ratio(get_material(material), "weft")
    x = _squeezed(buckle, 1.02, 1.0 - 0.02 * nu, 0.0)
    assert not np.any(_wrinkles(buckle, x))
    if nu > 0.05:  # the crosswise measures are compressed, as the docstring says
        st = buckle.stretch
        d_v = np.einsum("tm,tma->ta", st.coef[:, 1], x[buckle.mesh.faces])
        assert np.all(np.linalg.norm(d_v, axis=1) < 1.0 - 0.01 * nu)
    # narrowed more than the free contraction, the crosswise threads are compressed: wrinkles
    assert np.any(_wrinkles(buckle, _squeezed(buckle, 1.02, 1.0 - 0.02 * nu - 0.01, 0.0)))
    a, b = internal_forces(buckle, x), internal_forces(elastic, x)
    assert np.array_equal(a.forces, b.forces)
    assert np.array_equal(a.pair_hess, b.pair_hess)
    assert _energy(buckle, x) == _energy(elastic, x)


@pytest.mark.parametrize("material", MATERIALS)
def test_compression_past_onset_costs_the_buckling_stress(material):
    """A flat sheet squeezed uniformly along its weft to s of its length, width held: past
    the onset its wrinkles take up the squeeze and the force is the buckling stress's,
    A sigma_b = pi^2 B / 2 per face and unit wrinkle strain (d eta / d s = -(1 + eta) / s:
    the wrinkles keep the threads at their elastic length), whatever the squeeze; the
    elastic membrane's grows with it and is far larger."""
    buckle, elastic = _sheet(material), _sheet(material, "elastic")
    cap = np.pi ** 2 * get_material(material).bend / 2.0  # one stiffness (bending "mean")
    assert np.allclose(buckle.stretch.cap[:, 0], cap)

    def slope(model, s, h=1e-7):  # -dE/ds, J
        return -(_energy(model, _squeezed(model, s + h, 1.0, 0.0))
                 - _energy(model, _squeezed(model, s - h, 1.0, 0.0))) / (2 * h)

    for s in (0.99, 0.95, 0.8):
        eta = _wrinkles(buckle, _squeezed(buckle, s, 1.0, 0.0))
        assert np.all(eta[:, 1] == 0.0) and np.all(eta[:, 0] > 0.0)
        expected = np.sum(cap * (1.0 + eta[:, 0]) / s)
        assert slope(buckle, s) == pytest.approx(expected, rel=1e-5)
        assert slope(elastic, s) > 30 * slope(buckle, s)


def _onset(model, taut: float = 1.001, squeezed: float = 0.995) -> float:
    """The squeeze s (along the weft, width held) at which the wrinkle strain leaves zero,
    by bisection to the last bit."""
    assert _wrinkles(model, _squeezed(model, taut, 1.0, 0.0)).max() == 0.0
    assert _wrinkles(model, _squeezed(model, squeezed, 1.0, 0.0)).max() > 0.0
    for _ in range(60):
        mid = 0.5 * (taut + squeezed)
        if _wrinkles(model, _squeezed(model, mid, 1.0, 0.0)).max() > 0.0:
            squeezed = mid
        else:
            taut = mid
    return 0.5 * (taut + squeezed)


@pytest.mark.parametrize("material", MATERIALS)
def test_energy_and_its_slope_are_continuous_through_the_onset(material):
    """Along a path from taut to squeezed the energy has no jump and no kink where the
    wrinkle strain leaves zero. Measured at the onset s0 itself: one-sided slopes from
    points d and 2d on either side, and the energy's change over [s0 - d, s0 + d]. Where
    the energy and its slope are continuous both gaps shrink in proportion to d; a jump J
    or a kink K would leave them at J and K however small d gets."""
    model = _sheet(material, cells=3)

    def energy(v: float) -> float:
        return _energy(model, _squeezed(model, v, 1.0, 0.0))

    s0 = _onset(model)
    assert 0.99 < s0 < 1.0  # the sheet's threads wrinkle once shortened, not before

    def gaps(d: float) -> tuple[float, float, float]:
        taut = (energy(s0 + 2 * d) - energy(s0 + d)) / d
        wrinkled = (energy(s0 - d) - energy(s0 - 2 * d)) / d
        return abs(taut - wrinkled), abs(energy(s0 - d) - energy(s0 + d)), abs(wrinkled)

    kink_wide, jump_wide, _ = gaps(1e-7)
    kink, jump, slope = gaps(1e-8)
    assert slope > 0.0  # past the onset the squeeze costs energy (the buckling stress)
    # no kink: the one-sided slopes meet, their gap shrinking with d (linearly: 0.1)
    assert kink < 0.2 * kink_wide and kink < 0.02 * slope
    # no jump: the energy's change across the onset is what the slope carries over 2d
    assert jump < 0.2 * jump_wide and jump <= 2.2e-8 * slope


@pytest.mark.parametrize("material", MATERIALS)
def test_hessian_block_symmetric_and_psd_where_faces_wrinkle(material):
    model = _sheet(material)
    x = _squeezed(model, 0.97, 0.99, 1e-3, seed=3)
    assert np.any(_wrinkles(model, x) > 1e-3)
    res = internal_forces(model, x)
    assert np.allclose(res.pair_hess, np.transpose(res.pair_hess, (0, 2, 1)), atol=1e-12)
    n = model.n
    H = np.zeros((3 * n, 3 * n))
    for p, (i, j) in enumerate(model.pairs):
        blk = res.pair_hess[p]
        H[3 * i:3 * i + 3, 3 * j:3 * j + 3] += blk
        H[3 * j:3 * j + 3, 3 * i:3 * i + 3] += blk.T
        H[3 * i:3 * i + 3, 3 * i:3 * i + 3] -= blk
        H[3 * j:3 * j + 3, 3 * j:3 * j + 3] -= blk
    # H is the stiffness, -df/dx (test_physics): positive semi-definite
    assert np.linalg.eigvalsh(H).min() > -1e-9 * np.abs(H).max()


def test_unknown_compression_model_is_refused():
    mesh = sheet_coarse(0.1, 0.1, cells_x=2, plane="xy")
    with pytest.raises(ClothInputError, match="compression"):
        build_model(mesh, get_material("cotton"), compression="plastic")


def test_run_takes_the_compression_model_and_refuses_an_unknown_one(tmp_path, capsys):
    """`cloth-mg run --compression buckle` drapes the sheet with wrinkling faces (the summary
    says which model); an unknown model is one clear error naming the flag before anything
    runs."""
    from cloth_mg_ros.cli.main import main

    out = tmp_path / "out"
    args = ["run", "--scene", "hang", "--steps", "4", "--particles", "300", "--no-progress",
            "--frames", "1", "--out", str(out)]
    assert main([*args, "--compression", "buckle"]) == 0
    summary = (out / "summary.json").read_text()
    assert '"compression": "buckle"' in summary
    bad = tmp_path / "bad"
    assert main([*args[:-1], str(bad), "--compression", "plastic"]) == 2
    err = capsys.readouterr().err
    assert "--compression" in err and "plastic" in err and err.count("error:") == 1
    assert not bad.exists()


def test_a_hanging_sheet_never_gains_energy_with_wrinkles():
    """The hang scene (cotton, two corners held): the step's Hessian holds the wrinkles, an
    energy above the relaxed one that touches it where the step starts, so no step lands
    higher than the start's total energy."""
    from cloth_mg_ros.sim.integrator import energies
    from cloth_mg_ros.sim.sheets import build_scene
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import PCGSolver

    scene = build_scene("hang", 300, get_material("cotton"), compression="buckle")
    start = sum(energies(scene.model, scene.state))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-6), dt=1 / 60, scheme="euler")
    totals = []
    for _ in range(120):
        s = sim.step()
        totals.append(s.kinetic_energy + s.potential_energy)
    assert np.all(np.isfinite(sim.state.x))
    assert max(totals) <= start + 1e-9
    assert np.all(np.diff(totals) <= 1e-9)


def test_a_sheet_held_short_in_its_plane_settles_and_hardly_pushes_back():
    """A 1 m cotton sheet held along its top and bottom edges, the bottom lifted 10 cm in the
    sheet's plane (nothing makes it leave the plane): with wrinkles it settles (no step
    blows up, the kinetic energy dies away) and its holders carry about its weight; resisting
    compression as tension it pushes back with hundreds of newtons."""
    from cloth_mg_ros.sim.model import ClothControl, ClothState
    from cloth_mg_ros.sim.sheets import HANG_CENTRE, placed_on_scene, scene_hierarchy
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import PCGSolver

    hier = scene_hierarchy(300, None, None, "xz", HANG_CENTRE)
    rest = placed_on_scene(hier, HANG_CENTRE, None)
    top = np.flatnonzero(rest[:, 2] > rest[:, 2].max() - 1e-9)
    bottom = np.flatnonzero(rest[:, 2] < rest[:, 2].min() + 1e-9)
    pins = np.concatenate([top, bottom])
    pushed, held = {}, {}
    for compression in ("buckle", "elastic"):
        model = build_model(hier.levels[0], get_material("cotton"), pinned=pins,
                            compression=compression)
        sim = Simulator(model, ClothState.at_rest(rest.copy()), PCGSolver(tol=1e-8),
                        dt=1 / 60, track_constraint_forces=True)
        kinetic = []
        for k in range(150):
            targets = rest[pins].copy()
            targets[len(top):, 2] += 0.1 * min(1.0, (k + 1) / 60)
            sim.control = ClothControl(pin_targets=targets)
            kinetic.append(sim.step().kinetic_energy)
        assert np.all(np.isfinite(sim.state.x))
        assert kinetic[-1] < 1e-3 * max(kinetic)
        pushed[compression] = float(sim.constraint_forces[len(top):, 2].sum())
        held[compression] = sim.constraint_forces.sum(axis=0)
    weight = float(build_model(hier.levels[0], get_material("cotton")).mass.sum() * 9.81)
    for force in held.values():  # settled: the holders together carry the weight, no more
        assert np.allclose(force, [0.0, 0.0, weight], rtol=0.0, atol=1e-3 * weight), force
    assert abs(pushed["buckle"]) < weight
    assert pushed["elastic"] > 100 * weight


def test_a_fabric_with_a_bending_law_wrinkles_with_each_directions_stiffness():
    """white-dots-on-blk bends differently along its weft, warp and bias (physics.bending_law):
    a face squeezed along a thread buckles with that direction's k1."""
    mat = get_material("white-dots-on-blk")
    assert mat.bend_law is not None
    mesh = sheet_coarse(0.2, 0.2, cells_x=3, plane="xy")
    caps = build_model(mesh, mat, compression="buckle", bending="law").stretch.cap
    k1 = np.array(mat.bend_law.k1)
    expected = 0.5 * np.pi ** 2 * np.array([k1[0], k1[1]])
    assert np.allclose(caps, expected[None, :], rtol=1e-12)
    assert np.ptp(k1) > 0.1 * k1.mean()  # the directions do differ for this fabric
