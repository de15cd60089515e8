"""The multigrid's first guess (solvers.first_guess): the rigid motion of the free particles,
its rotations' products from the elastic energy's rotation invariance."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from packed_rows import first_residual

from cloth_mg_ros.mesh import sheet_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.system import BlockSystem, RotationTerms, bs_matvec
from cloth_mg_ros.sim.forces import hessian_product, internal_forces
from cloth_mg_ros.sim.model import build_model
from cloth_mg_ros.solvers.first_guess import (
    rigid_guess,
    rigid_shift,
    solve_spd,
    translate_rows,
    translation_guess,
)
from cloth_mg_ros.solvers.multigrid import MultigridSolver
from cloth_mg_ros.solvers.packed_kernels import full_residual, residual_rows
from cloth_mg_ros.solvers.packed_levels import PackedLevels, scalar_pairs


def _turned(rest: np.ndarray, stretch: float, seed: int, jitter: float = 1e-4) -> np.ndarray:
    """rest (n, 3) scaled by `stretch`, turned and moved, with a jitter (`jitter` times the
    sheet's size; the default keeps every face stretched, or compressed, in every
    direction)."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    size = float(np.ptp(rest, axis=0).max())
    return (stretch * rest) @ q.T + [0.3, -1.2, 2.0] + jitter * size * rng.standard_normal(
        rest.shape)


def _compressed_faces(model, x: np.ndarray) -> np.ndarray:
    """(t,) bool: faces with a stretch measure shorter than its rest length."""
    st = model.stretch
    d = np.einsum("tqc,tca->tqa", st.coef, x[model.mesh.faces])
    return np.any(np.linalg.norm(d, axis=2) < st.rest_len[None, :], axis=1)


@pytest.fixture(scope="module")
def sheet():
    hier = sheet_hierarchy(700, depth=2, plane="xy")
    return hier, build_model(hier.levels[0], get_material("cotton"))


@pytest.mark.parametrize("clamp", [True, False])
def test_the_elastic_hessian_turns_a_rotation_into_theta_cross_the_gradient(sheet, clamp):
    """H (theta x x) = theta x grad E = -theta x forces, on every particle of a stretched
    sheet (every measure in tension: the compression clamp changes nothing)."""
    _, model = sheet
    x = _turned(model.mesh.rest, 1.03, 0)
    assert not np.any(_compressed_faces(model, x))
    res = internal_forces(model, x, clamp=clamp)
    for theta in np.eye(3).tolist() + [[0.3, -0.7, 0.2]]:
        got = hessian_product(model.pairs, res.pair_hess, np.cross(theta, x))
        want = np.cross(theta, -res.forces)
        assert np.allclose(got, want, rtol=0.0, atol=1e-9 * np.abs(want).max())


def test_the_compression_clamp_is_where_the_rotation_formula_only_approximates(sheet):
    """On a compressed sheet the energy's own Hessian still obeys it; the clamped one (what
    the steps use) differs, and only on particles of compressed faces: why the first guess
    takes its residual anew after the rotations."""
    _, model = sheet
    x = _turned(model.mesh.rest, 0.98, 1)
    compressed = _compressed_faces(model, x)
    assert np.any(compressed)
    near = np.zeros(model.n, dtype=bool)
    near[model.mesh.faces[compressed].ravel()] = True
    theta = np.array([0.2, 0.5, -0.4])
    exact = internal_forces(model, x, clamp=False)
    got = hessian_product(model.pairs, exact.pair_hess, np.cross(theta, x))
    want = np.cross(theta, -exact.forces)
    assert np.allclose(got, want, rtol=0.0, atol=1e-9 * np.abs(want).max())
    clamped = internal_forces(model, x, clamp=True)
    got = hessian_product(model.pairs, clamped.pair_hess, np.cross(theta, x))
    want = np.cross(theta, -clamped.forces)
    off = np.abs(got - want).max(axis=1) > 1e-9 * np.abs(want).max()
    assert np.any(off) and not np.any(off & ~near)


def _pinned_system(sheet, stretch: float, parts: int, jitter: float = 1e-4):
    """A step-like system of the turned sheet (mass and a few contact-like diagonal blocks
    plus h'^2 H), every ninth particle pinned, packed; and a first guess that moves the
    pins."""
    hier, model = sheet
    x = _turned(model.mesh.rest, stretch, 2, jitter)
    res = internal_forces(model, x)
    scale = 2e-4
    rng = np.random.default_rng(3)
    diag = model.mass[:, None, None] * np.eye(3)
    touch = rng.random(model.n) < 0.1
    normals = rng.standard_normal((model.n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    diag[touch] += 10.0 * model.mass[touch, None, None] * np.einsum(
        "ka,kb->kab", normals[touch], normals[touch])
    system = BlockSystem(diag, model.pairs, scale * res.pair_hess, scale,
                         RotationTerms(x, res.forces))
    fixed = np.zeros(model.n, dtype=bool)
    fixed[::9] = True
    mg = MultigridSolver(hier, model.bending, 3, parts=parts)
    systems = mg._coarse_systems(system, fixed)
    meshes = hier.levels[: len(systems)]
    pk = PackedLevels([s.n for s in systems], mg._parents[: len(systems) - 1],
                      [lv.rest for lv in meshes], [scalar_pairs(lv) for lv in meshes], parts)
    pk.fill(systems, fixed)
    moved = 1e-2 * rng.standard_normal((model.n, 3)) * fixed[:, None]
    b = rng.standard_normal((model.n, 3)) + [0.0, 0.0, -2.0]
    return system, fixed, pk, moved, b


@pytest.mark.parametrize("parts", [1, 2])
def test_rigid_guess_is_the_galerkin_projection_onto_rigid_motions(sheet, parts):
    """On a stretched sheet (where the rotations' products are exact) the guess is the
    Galerkin projection onto the six rigid motions of the free particles: its coefficients
    are those of T^T A T c = T^T r with A's own matrix, the residual afterwards (taken anew)
    is S (b - A x) and has no part along any rigid motion, the pins stay, and the error's
    A-norm falls below the translations' alone."""
    system, fixed, pk, moved, b = _pinned_system(sheet, 1.03, parts)
    n, free = system.n, ~fixed
    x, touched, r, rows_b = first_residual(pk, moved, b)
    c = rigid_guess(pk, touched, r, system.rotation, system.hess_scale)
    assert c is not None and np.linalg.norm(c[3:]) > 0.0
    # the exact Galerkin system over the free particles, rotations about the mean position
    pos = system.rotation.positions
    offsets = pos - pos.mean(axis=0)
    modes = np.zeros((n, 3, 6))
    modes[:, :, :3] = np.eye(3)
    for a in range(3):
        modes[:, :, 3 + a] = np.cross(np.eye(3)[a], offsets)
    modes[fixed] = 0.0
    t = modes.reshape(3 * n, 6)
    a_mat = system.to_csr()
    s = np.repeat(free.astype(float), 3)
    sas = a_mat.multiply(s[:, None]).multiply(s[None, :]).tocsr()
    r0 = pk.from_rows(r).reshape(-1)
    want = np.linalg.solve(t.T @ (sas @ t), t.T @ r0)
    assert np.allclose(c, want, rtol=1e-8, atol=1e-12 * np.abs(want).max())

    rr = full_residual(pk.fine_chunks, pk.slots, pk.diag6, pk.free, rows_b,
                       _shifted(pk, x, c), r)
    guess = pk.from_rows(x)
    assert np.array_equal(guess[fixed], moved[fixed])
    motion = (t @ c).reshape(n, 3)
    assert np.allclose(guess[free], moved[free] + motion[free], rtol=0.0,
                       atol=1e-12 * np.abs(motion).max())
    ref = _residual(system, b, guess, free)
    assert np.allclose(pk.from_rows(r), ref, rtol=0.0, atol=1e-10 * np.abs(ref).max())
    assert rr == pytest.approx(float(np.sum(ref * ref)), rel=1e-9)
    assert np.allclose(t.T @ ref.reshape(-1), 0.0, atol=1e-9 * np.abs(t).max()
                       * np.abs(ref).sum())

    # A-norm of the error: before, after the translations alone, after the rigid motion
    x2, touched2, r2, _ = first_residual(pk, moved, b)
    shift = translation_guess(pk, touched2, r2)
    translate_rows(pk.fine_chunks, pk.slots, pk.bdiag6, pk.free, touched2, shift, x2, r2)
    a_ff = a_mat[np.repeat(free, 3)][:, np.repeat(free, 3)].tocsc()
    energy = [float(v @ spla.spsolve(a_ff, v)) for v in (
        _residual(system, b, moved, free)[free].ravel(), pk.from_rows(r2)[free].ravel(),
        ref[free].ravel())]
    assert energy[2] < energy[1] < energy[0]


def _shifted(pk, x, c):
    rigid_shift(pk.fine_chunks, pk.free, pk.rigid_rows[0], c, x)
    return x


def _residual(system, b, v, free):
    out = np.empty_like(v)
    bs_matvec(system.diag, system.pairs, system.offd, v, out)
    return (b - out) * free[:, None]


def test_a_crumpled_sheets_rigid_guess_still_lowers_the_error(sheet):
    """Where the clamp makes the rotations' products approximate (a crumpled sheet, most
    of its faces compressed), the guess is no longer the exact projection, but the residual
    taken anew is still exactly S (b - A x), and the error's A-norm still falls."""
    system, fixed, pk, moved, b = _pinned_system(sheet, 1.0, 1, jitter=2e-3)
    model = sheet[1]
    assert 0.2 < _compressed_faces(model, system.rotation.positions).mean() < 0.95
    free = ~fixed
    x, touched, r, rows_b = first_residual(pk, moved, b)
    c = rigid_guess(pk, touched, r, system.rotation, system.hess_scale)
    assert c is not None
    full_residual(pk.fine_chunks, pk.slots, pk.diag6, pk.free, rows_b, _shifted(pk, x, c), r)
    guess = pk.from_rows(x)
    ref = _residual(system, b, guess, free)
    assert np.allclose(pk.from_rows(r), ref, rtol=0.0, atol=1e-10 * np.abs(ref).max())
    a_ff = system.to_csr()[np.repeat(free, 3)][:, np.repeat(free, 3)].tocsc()
    energy = [float(v @ spla.spsolve(a_ff, v)) for v in (
        _residual(system, b, moved, free)[free].ravel(), ref[free].ravel())]
    assert energy[1] < energy[0]


def test_the_full_residual_is_the_gather_over_every_row(sheet):
    system, _, pk, moved, b = _pinned_system(sheet, 1.03, 2)
    n = system.n
    x = pk.to_rows(moved + 1e-3 * np.random.default_rng(9).standard_normal((n, 3)))
    rows_b = pk.to_rows(b)
    r, r_all = np.empty_like(x), np.empty_like(x)
    rr = full_residual(pk.fine_chunks, pk.slots, pk.diag6, pk.free, rows_b, x, r)
    rr_all = residual_rows(pk.fine_chunks, pk.slots, pk.diag6, pk.free, rows_b, x, r_all,
                           np.ones(n, dtype=np.uint8))
    assert np.array_equal(r, r_all) and rr == rr_all


def test_the_solver_takes_the_rigid_guess_where_the_system_carries_its_forces(sheet):
    """MultigridSolver: a system with RotationTerms starts from the rigid motion, one without
    from the translations; both converge to the same solution."""
    hier, model = sheet
    system, fixed, _, moved, b = _pinned_system(sheet, 1.03, 1)
    solver = MultigridSolver(hier, model.bending, 3, tol=1e-10)
    with_rotation = solver.solve(system, b, moved, fixed)
    assert solver._packed.last_guess == "rigid" and with_rotation.converged
    bare = BlockSystem(system.diag, system.pairs, system.offd, system.hess_scale)
    without = solver.solve(bare, b, moved, fixed)
    assert solver._packed.last_guess == "translation" and without.converged
    scale = np.abs(without.x).max()
    assert np.allclose(with_rotation.x, without.x, rtol=0.0, atol=1e-7 * scale)
    assert with_rotation.iterations <= without.iterations


def test_solve_spd_solves_and_refuses_what_is_not_positive_definite():
    rng = np.random.default_rng(7)
    for k in range(1, 7):
        m = rng.standard_normal((k, k))
        spd = m @ m.T + 0.1 * np.eye(k)
        rhs = rng.standard_normal(k)
        out = np.zeros(k)
        assert solve_spd(spd, rhs, out)
        assert np.allclose(spd @ out, rhs, rtol=1e-11, atol=1e-11 * np.abs(rhs).max())
    for bad in (np.diag([1.0, -1.0, 1.0, 1.0, 1.0, 1.0]), np.zeros((6, 6)), np.full((6, 6), 1.0)):
        out = np.full(6, 5.0)
        assert not solve_spd(bad, np.ones(6), out)
        assert np.all(out == 5.0)
    out = np.zeros(2)
    assert not solve_spd(np.eye(2), np.array([np.nan, 0.0]), out)
