"""Physics of the cloth core: finite-difference checks of forces and Jacobian blocks,
block symmetry, Algorithm 1 against scipy, free fall, a hanging sheet coming to rest."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh import sheet_coarse
from cloth_mg_ros.physics.materials import MATERIALS, PAPER_TABLE2, get_material
from cloth_mg_ros.physics.stretch import stretch_energy
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.integrator import assemble_step, energies
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver


@pytest.fixture(scope="module")
def small_model():
    mesh = sheet_coarse(0.3, 0.3, cells_x=5, plane="xy")
    return build_model(mesh, get_material("cotton"))


def _deformed(model, seed=0, stretch=1.05, noise=0.004):
    """A stretched, randomly perturbed, non-planar configuration (every stretch term in
    tension so the clamp is inactive)."""
    rng = np.random.default_rng(seed)
    x = np.array(model.mesh.rest) * stretch
    x += noise * rng.standard_normal(x.shape)
    return x


def _total_energy(model, x):
    st = model.stretch
    e_st = stretch_energy(x, model.mesh.faces, st.coef, st.stiff, st.rest_len, st.cap)
    return float(e_st) + internal_forces(model, x).bend_energy


def _dense_hessian(model, pair_hess):
    n = model.n
    H = np.zeros((3 * n, 3 * n))
    for p, (i, j) in enumerate(model.pairs):
        H[3 * i:3 * i + 3, 3 * j:3 * j + 3] += pair_hess[p]
        H[3 * j:3 * j + 3, 3 * i:3 * i + 3] += pair_hess[p].T
        H[3 * i:3 * i + 3, 3 * i:3 * i + 3] -= pair_hess[p]
        H[3 * j:3 * j + 3, 3 * j:3 * j + 3] -= pair_hess[p]
    return H


def test_materials_keep_paper_ratios():
    cotton = MATERIALS["cotton"]
    for name, (s, h, b) in PAPER_TABLE2.items():
        m = MATERIALS[name]
        assert m.stretch / cotton.stretch == pytest.approx(s / PAPER_TABLE2["cotton"][0])
        assert m.shear / cotton.shear == pytest.approx(h / PAPER_TABLE2["cotton"][1])
        assert m.bend / cotton.bend == pytest.approx(b / PAPER_TABLE2["cotton"][2])
    # A 1 m sheet should drape like fabric: bending lengths of a few millimetres to centimetres.
    assert 0.005 < MATERIALS["silk"].bending_length() < 0.015
    assert 0.015 < cotton.bending_length() < 0.035


def test_forces_match_energy_gradient(small_model):
    model = small_model
    x = _deformed(model)
    f = internal_forces(model, x, clamp=False).forces
    eps = 1e-6
    rng = np.random.default_rng(1)
    for i in rng.choice(model.n, size=12, replace=False):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            fd = -(_total_energy(model, xp) - _total_energy(model, xm)) / (2 * eps)
            assert abs(fd - f[i, a]) <= 1e-5 * max(1.0, np.abs(f).max())


def test_jacobian_blocks_match_finite_differences(small_model):
    """Every pair block and diagonal block of K = df/dx against central differences (the
    membrane resisting compression as tension: where a face wrinkles, physics.wrinkles,
    the Hessian drops the wrinkles' share and test_wrinkles checks it)."""
    model = build_model(small_model.mesh, small_model.material, compression="elastic")
    x = _deformed(model, seed=2)
    res = internal_forces(model, x, clamp=False)
    H = _dense_hessian(model, res.pair_hess)
    eps = 1e-6
    K_fd = np.zeros_like(H)
    for c in range(3 * model.n):
        xp, xm = x.copy().reshape(-1), x.copy().reshape(-1)
        xp[c] += eps
        xm[c] -= eps
        fp = internal_forces(model, xp.reshape(-1, 3), clamp=False).forces.reshape(-1)
        fm = internal_forces(model, xm.reshape(-1, 3), clamp=False).forces.reshape(-1)
        K_fd[:, c] = (fp - fm) / (2 * eps)
    err = np.abs(-H - K_fd).max() / np.abs(K_fd).max()
    assert err < 1e-5
    # Every stored block individually, relative to its own size where it is not tiny.
    for p, (i, j) in enumerate(model.pairs):
        blk_fd = K_fd[3 * i:3 * i + 3, 3 * j:3 * j + 3]
        scale = max(np.abs(blk_fd).max(), 1e-3 * np.abs(K_fd).max())
        assert np.abs(-res.pair_hess[p] - blk_fd).max() / scale < 1e-5


def test_blocks_symmetric_and_rows_sum_to_zero(small_model):
    model = small_model
    x = _deformed(model, seed=3)
    res = internal_forces(model, x)
    # G_ij = G_ji: each stored pair block is symmetric, so the (j, i) block is the same.
    assert np.allclose(res.pair_hess, np.transpose(res.pair_hess, (0, 2, 1)), atol=1e-12)
    H = _dense_hessian(model, res.pair_hess)
    assert np.allclose(H, H.T, atol=1e-10)
    # Translation invariance: H times a rigid translation vanishes.
    for a in range(3):
        t = np.zeros((model.n, 3))
        t[:, a] = 1.0
        assert np.abs(H @ t.reshape(-1)).max() < 1e-9 * np.abs(H).max()


@pytest.mark.parametrize("clamp", [True, False])
def test_hessian_product_formed_with_the_forces_is_the_pair_blocks_product(small_model, clamp):
    """internal_forces' product_of: H z formed from the face blocks and the bending pairs in
    the pass that forms the forces equals the product over the pair blocks it also returns,
    on stretched and compressed (clamped) faces alike, and asking for it changes neither the
    forces nor the blocks."""
    from cloth_mg_ros.sim.forces import hessian_product

    model = small_model
    rng = np.random.default_rng(7)
    for x in (_deformed(model, seed=4), _deformed(model, seed=5, stretch=0.9)):
        z = rng.standard_normal(x.shape)
        plain = internal_forces(model, x, clamp=clamp)
        res = internal_forces(model, x, clamp=clamp, product_of=z)
        assert plain.product is None
        reference = hessian_product(model.pairs, res.pair_hess, z)
        assert np.abs(res.product - reference).max() <= 1e-12 * np.abs(reference).max()
        # and the dense matrix's product (the pair blocks off the diagonal, minus their sum
        # on it, as the force Jacobian K = -H is checked above)
        H = _dense_hessian(model, res.pair_hess)
        assert np.allclose(res.product.reshape(-1), H @ z.reshape(-1), rtol=0,
                           atol=1e-10 * np.abs(H).max())
        assert np.array_equal(res.forces, plain.forces)
        assert np.array_equal(res.pair_hess, plain.pair_hess)
        assert res.bend_energy == plain.bend_energy


def test_compression_clamp_keeps_hessian_psd(small_model):
    model = small_model
    x = np.array(model.mesh.rest) * 0.8  # every term compressed
    H = _dense_hessian(model, internal_forces(model, x, clamp=True).pair_hess)
    assert np.linalg.eigvalsh(H).min() > -1e-9 * np.abs(H).max()
    H_exact = _dense_hessian(model, internal_forces(model, x, clamp=False).pair_hess)
    assert np.linalg.eigvalsh(H_exact).min() < 0.0  # why the clamp exists


def test_bending_energy_matches_cylinder():
    """A sheet rolled into a cylinder of radius R has bending energy bend / 2 * A / R^2."""
    mesh = sheet_coarse(1.0, 1.0, cells_x=40, plane="xy")
    mat = get_material("cotton", stretch=1.0, shear=1.0)
    model = build_model(mesh, mat)
    rest = np.array(mesh.rest)
    area = float(np.sum(mesh.face_areas))
    R = 0.3
    for axis in (0, 1):
        th = rest[:, axis] / R
        x = np.zeros_like(rest)
        x[:, axis] = R * np.sin(th)
        x[:, 1 - axis] = rest[:, 1 - axis]
        x[:, 2] = R * (1 - np.cos(th))
        e = internal_forces(model, x).bend_energy
        assert e == pytest.approx(0.5 * mat.bend * area / R**2, rel=0.05)
    assert abs(internal_forces(model, rest).bend_energy) < 1e-15  # flat is the rest state


def test_algorithm1_equals_scipy_product(small_model):
    model = small_model
    state = ClothState(_deformed(model, seed=4), np.zeros((model.n, 3)))
    system = assemble_step(model, state, 1 / 60, "euler").system
    d = np.random.default_rng(5).standard_normal((model.n, 3))
    ref_csr = system.to_csr() @ d.reshape(-1)
    ref_bsr = system.to_bsr() @ d.reshape(-1)
    got = system.matvec(d).reshape(-1)
    assert np.allclose(got, ref_csr, rtol=1e-12, atol=1e-14 * np.abs(ref_csr).max())
    assert np.allclose(ref_bsr, ref_csr, rtol=1e-12, atol=1e-14 * np.abs(ref_csr).max())
    A = system.to_csr()
    assert abs(A - A.T).max() < 1e-12 * abs(A).max()


def test_pcg_matches_direct_solve(small_model):
    import scipy.sparse.linalg as spla

    model = small_model
    state = ClothState(_deformed(model, seed=6), np.zeros((model.n, 3)))
    step = assemble_step(model, state, 1 / 60, "euler")
    res = PCGSolver(tol=1e-10, maxiter=5000).solve(step.system, step.rhs)
    exact = spla.spsolve(step.system.to_csr().tocsc(), step.rhs.reshape(-1)).reshape(-1, 3)
    assert res.converged
    assert np.abs(res.x - exact).max() < 1e-8 * np.abs(exact).max()


@pytest.mark.parametrize("scheme", ["euler", "bdf2"])
def test_free_fall_matches_analytic(scheme):
    """No collider, no drag: a rigidly falling sheet follows z = z0 - g t^2 / 2."""
    mesh = sheet_coarse(0.2, 0.2, cells_x=4, plane="xy")
    mat = get_material("cotton", air_drag=0.0)
    model = build_model(mesh, mat)
    sim = Simulator(model, ClothState.at_rest(np.array(mesh.rest)), PCGSolver(tol=1e-12),
                    dt=0.01, scheme=scheme)
    steps = 50
    for _ in range(steps):
        sim.step()
    t = steps * 0.01
    g = 9.81
    dz = sim.state.x[:, 2] - np.array(mesh.rest)[:, 2]
    assert np.allclose(sim.state.v[:, 2], -g * t, rtol=1e-9)
    if scheme == "euler":
        # Implicit Euler's exact discrete answer: z_n = z0 - g h^2 n (n + 1) / 2.
        assert np.allclose(dz, -g * 0.01**2 * steps * (steps + 1) / 2, rtol=1e-9)
    else:
        # BDF2 (one Euler start step) is second-order: within a fraction of g h t.
        assert np.allclose(dz, -0.5 * g * t**2, atol=0.5 * g * 0.01 * t)
    assert np.allclose(sim.state.x[:, :2], np.array(mesh.rest)[:, :2], atol=1e-12)


def test_hanging_sheet_comes_to_rest_with_bounded_energy():
    scene = build_scene("hang", 300, get_material("cotton"))
    model, state = scene.model, scene.state
    pins = model.pinned.copy()
    x_pins = state.x[pins].copy()
    kinetic0, potential0 = energies(model, state)
    sim = Simulator(model, state, PCGSolver(tol=1e-6), dt=1 / 60, scheme="bdf2")
    kinetic, total = [], []
    for _ in range(240):
        s = sim.step()
        assert s.converged
        kinetic.append(s.kinetic_energy)
        total.append(s.kinetic_energy + s.potential_energy)
    assert np.all(np.isfinite(sim.state.x))
    assert np.allclose(sim.state.x[pins], x_pins)  # pins held
    # Implicit integration dissipates: the total never rises above the start.
    assert max(total) <= kinetic0 + potential0 + 1e-9
    # It comes to rest: kinetic energy at the end is a tiny fraction of its peak.
    assert kinetic[-1] < 1e-3 * max(kinetic)
    assert sim.state.x[:, 2].min() < x_pins[:, 2].min() - 0.5  # it hangs down


def test_drape_touches_sphere_without_nan():
    scene = build_scene("drape", 300, get_material("silk"))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-4), dt=1 / 60)
    contacts = 0
    for _ in range(40):
        s = sim.step()
        contacts = max(contacts, s.contacts)
        assert np.all(np.isfinite(sim.state.x))
        assert s.max_penetration < 1e-9  # the projection leaves nothing inside
        assert s.solve_penetration < 0.05  # and never had to repair a tunnel
    assert contacts > 0


def test_material_errors():
    with pytest.raises(ClothInputError, match="unknown material 'velvet'"):
        get_material("velvet")
    with pytest.raises(ClothInputError, match="stretch must not be negative"):
        get_material("cotton", stretch=-5.0)
    with pytest.raises(ClothInputError, match="bend must be a finite"):
        get_material("cotton", bend=float("nan"))


def test_simulator_rejects_bad_step(small_model):
    with pytest.raises(ClothInputError, match="time step"):
        Simulator(small_model, ClothState.at_rest(np.array(small_model.mesh.rest)),
                  PCGSolver(), dt=0.0)


def test_a_kept_workspace_assembles_the_same_system_as_a_fresh_one():
    """The step's arrays are kept from one step to the next, and the constant blocks of the
    pairs that are no mesh edge (bend I, scaled) are written only when the array or the
    scale is new: every assembly must equal, bit for bit, one made with fresh arrays,
    through other states and a change of step."""
    from cloth_mg_ros.sim.forces import Workspace

    scene = build_scene("drape", 400, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-8), dt=1 / 60)
    states = []
    for _ in range(3):
        sim.step()
        states.append(sim.state)
    work = Workspace()
    for state, dt in ((states[0], 1 / 60), (states[1], 1 / 60), (states[2], 1 / 30),
                      (states[0], 1 / 60), (states[2], 1 / 60)):
        kept = assemble_step(scene.model, state, dt, "bdf2", work=work)
        fresh = assemble_step(scene.model, state, dt, "bdf2")
        for a, b in ((kept.system.offd, fresh.system.offd), (kept.system.diag, fresh.system.diag),
                     (kept.rhs, fresh.rhs), (kept.internal.pair_hess, fresh.internal.pair_hess)):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("scheme", ["euler", "bdf2"])
def test_solved_rows_are_the_solved_positions_of_those_rows(scheme):
    from cloth_mg_ros.sim.integrator import solved_positions, solved_rows

    scene = build_scene("drape", 300, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-8), dt=1 / 60)
    for _ in range(3):
        sim.step()
    step = assemble_step(scene.model, sim.state, sim.dt, scheme)
    dv = np.random.default_rng(2).standard_normal((scene.model.n, 3))
    rows = np.array([5, 0, 17, 5, scene.model.n - 1])
    x, _ = solved_positions(sim.state, step, dv, sim.dt)
    assert np.array_equal(solved_rows(sim.state, step, dv, sim.dt, rows), x[rows])


@pytest.mark.parametrize("material, compression", [
    ("cotton", "elastic"), ("cotton", "buckle"),
    ("white-dots-on-blk", "elastic"), ("white-dots-on-blk", "buckle"),  # a bending law
])
def test_energies_are_the_steps_own_energy_terms(material, compression):
    """`energies` counts a bending law's energy as the forces do, and takes the elastic
    energy from the step's own code (sim.forces.internal_forces, the pass that makes the
    step's forces), not a copy of it: its potential is exactly gravity plus internal_forces'
    stretch and bending energies (before: a copy of its own that agreed to round-off only,
    1e-15 J here, and could drift further), and it is the potential of the forces the step
    uses (central differences along a direction)."""
    mesh = sheet_coarse(0.2, 0.2, cells_x=6, plane="xy")
    model = build_model(mesh, get_material(material), compression=compression, bending="law")
    assert (model.bending_law is not None) == (material != "cotton")
    rng = np.random.default_rng(6)
    x = _deformed(model, seed=6, stretch=1.02, noise=0.003)
    v = 0.1 * rng.standard_normal(x.shape)
    kinetic, potential = energies(model, ClothState(x, v))
    internal = internal_forces(model, x)
    gravity = -float(np.sum(x * model.applied_forces()))
    assert potential == gravity + internal.stretch_energy + internal.bend_energy
    assert kinetic == 0.5 * float(np.sum(model.mass[:, None] * v * v))
    d, eps = rng.standard_normal(x.shape), 1e-6
    slope = (energies(model, ClothState(x + eps * d, v))[1]
             - energies(model, ClothState(x - eps * d, v))[1]) / (2 * eps)
    work = float(np.sum((internal.forces + model.applied_forces()) * d))
    assert slope == pytest.approx(-work, rel=1e-6)
