"""The implicit schemes on problems with exact answers: a plate whose only force is the
quadratic (linear-force) bending, where one linearised step is the textbook scheme and the
lowest mode's amplitude and phase per step are known; free fall; the generalised-alpha
history across levels of detail and in a replay; bad spectral radii named."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.linalg

from cloth_mg_ros.config.schema import check
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh import sheet_coarse
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.system import pair_scalar_product_rows
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.schemes import GenAlpha
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

# a plate with bending alone: stretch 1e-12 N/m (the material needs one), no shear, no
# damping, no drag, no gravity: M x'' = -K x with K constant, so each scheme is linear
PLATE = dataclasses.replace(get_material("cotton"), stretch=1e-12, shear=0.0, bend=1e-3,
                            damping=0.0, air_drag=0.0)
AMPLITUDE = 1e-3  # m, the mode's displacement at its largest


@pytest.fixture(scope="module")
def plate():
    """(model, mode (n,) unit-mass-normalised lowest mode of the free z motion, omega rad/s):
    a 0.2 m plate clamped along two rows (one row lets it turn about the row as a rigid
    plane, which bends no hinge)."""
    mesh = sheet_coarse(0.2, 0.2, cells_x=6, plane="xy")
    y = mesh.rest[:, 1]
    rows = np.unique(np.round(y, 9))
    pinned = np.flatnonzero(y <= rows[1] + 1e-9)
    model = build_model(mesh, PLATE, pinned=pinned, gravity=np.zeros(3))
    n = model.n
    inc = model.incidence
    k = np.empty((n, n))
    for col in range(n):
        e = np.zeros((n, 3))
        e[col, 0] = 1.0
        out = np.empty_like(e)
        pair_scalar_product_rows(inc.vp_ptr, inc.vp_pair, inc.vp_other, model.bend_pairs, e, out)
        k[:, col] = out[:, 0]  # H e: the energy is x . H x / 2 (sim.integrator.energies)
    free = np.setdiff1d(np.arange(n), pinned)
    k_ff = k[np.ix_(free, free)]
    w2, vecs = scipy.linalg.eigh(k_ff, np.diag(model.mass[free]))
    mode = np.zeros(n)
    mode[free] = vecs[:, 0] / np.max(np.abs(vecs[:, 0]))
    return model, mode, float(np.sqrt(w2[0]))


def _modal_run(plate, scheme, rho, omega_h, steps):
    """The mode's amplitude after each of `steps` steps (m), stepping the plate from rest
    displaced in its lowest mode, with h = omega_h / omega."""
    model, mode, omega = plate
    x0 = model.mesh.rest.copy()
    x0[:, 2] += AMPLITUDE * mode
    solver = make_solver("direct", tol=1e-12)
    sim = Simulator(model, ClothState.at_rest(x0), solver, dt=omega_h / omega, scheme=scheme,
                    spectral_radius=rho, track_energy=False)
    weight = model.mass * mode
    q = []
    for _ in range(steps):
        sim.step()
        dz = sim.state.x[:, 2] - model.mesh.rest[:, 2]
        q.append(float(weight @ dz / (weight @ mode)))
        # the motion stays in the mode: linear dynamics, an eigenvector start
        assert np.allclose(dz, q[-1] * mode, atol=1e-9 * AMPLITUDE)
    return np.array(q)


def _textbook(scheme, rho, omega_h, steps):
    """The same mode stepped by the textbook scheme on x'' = -w^2 x (w = 1, h = omega_h),
    after an implicit Euler first step: generalised-alpha in Chung and Hulbert's own form
    (balance at n+1-alpha_m / n+1-alpha_f, Newmark updates), solved for a_{n+1}."""
    h, w2 = omega_h, 1.0
    x, v = AMPLITUDE, 0.0
    v1 = (v - h * w2 * x) / (1.0 + h * h * w2)
    a, x, v = (v1 - v) / h, x + h * v1, v1
    out = [x]
    if scheme == "euler":
        for _ in range(steps - 1):
            v = (v - h * w2 * x) / (1.0 + h * h * w2)
            x = x + h * v
            out.append(x)
        return np.array(out)
    g = GenAlpha.of(h, rho)
    am, af, gamma, beta = g.alpha_m, g.alpha_f, g.gamma, g.beta
    for _ in range(steps - 1):
        rhs = -am * a - w2 * (x + (1 - af) * (h * v + h * h * (0.5 - beta) * a))
        a1 = rhs / ((1 - am) + w2 * (1 - af) * h * h * beta)
        x = x + h * v + h * h * ((0.5 - beta) * a + beta * a1)
        v = v + h * ((1 - gamma) * a + gamma * a1)
        a = a1
        out.append(x)
    return np.array(out)


@pytest.mark.parametrize("scheme, rho", [("euler", 0.5), ("genalpha", 0.0),
                                         ("genalpha", 0.5), ("genalpha", 1.0)])
def test_a_linear_plate_steps_exactly_as_the_textbook_scheme(plate, scheme, rho):
    """One linearised step of the simulator is the scheme itself where the forces are linear:
    the lowest mode's amplitude follows the textbook recurrence to rounding, 30 steps at
    omega h = 0.6."""
    q = _modal_run(plate, scheme, rho, 0.6, 30)
    ref = _textbook(scheme, rho, 0.6, 30)
    assert np.allclose(q, ref, rtol=0.0, atol=1e-7 * AMPLITUDE), np.max(np.abs(q - ref))


def _amplitude_per_step(q):
    """The decay factor per step r of a sampled decaying oscillation q_n = A r^n cos(n theta
    + phi): the least-squares fit of q_{n+1} = 2 r cos(theta) q_n - r^2 q_{n-1} past the
    first five steps (where a scheme's spurious root has died out)."""
    rows = np.column_stack([q[5:-1], q[4:-2]])
    (_, c2), *_ = np.linalg.lstsq(rows, q[6:], rcond=None)
    return float(np.sqrt(-c2))


def test_genalpha_keeps_a_slow_mode_that_implicit_euler_damps(plate):
    """At omega h = 0.3 (20 steps a period) implicit Euler multiplies the amplitude by
    1/sqrt(1 + (omega h)^2) a step (a damping ratio near omega h / 2); generalised-alpha at
    rho_inf = 1 keeps it, and at 0.5 damps less than a fifth as much."""
    euler = _amplitude_per_step(_modal_run(plate, "euler", 0.5, 0.3, 80))
    assert euler == pytest.approx(1.0 / np.sqrt(1.0 + 0.3 ** 2), rel=2e-3)
    trapezoid = _amplitude_per_step(_modal_run(plate, "genalpha", 1.0, 0.3, 80))
    assert trapezoid == pytest.approx(1.0, abs=1e-6)
    half = _amplitude_per_step(_modal_run(plate, "genalpha", 0.5, 0.3, 80))
    assert half < 1.0
    assert (1.0 - half) < 0.2 * (1.0 - euler)


def _amplification(rho, omega_h):
    """The textbook generalised-alpha step's matrix on (x, h v, h^2 a) for x'' = -w^2 x."""
    g = GenAlpha.of(1.0, rho)
    am, af, gamma, beta, w2 = g.alpha_m, g.alpha_f, g.gamma, g.beta, omega_h ** 2
    out = np.empty((3, 3))
    for col, (x, v, a) in enumerate(np.eye(3)):
        a1 = (-am * a - w2 * (x + (1 - af) * (v + (0.5 - beta) * a))) / (
            (1 - am) + w2 * (1 - af) * beta)
        out[:, col] = (x + v + (0.5 - beta) * a + beta * a1, v + (1 - gamma) * a + gamma * a1,
                       a1)
    return out


def test_genalpha_damps_the_fastest_modes_by_its_spectral_radius(plate):
    """Far above the step's frequency (omega h = 1000) the simulator still steps the mode as
    the textbook scheme does, and that scheme's amplification there has spectral radius
    rho_inf (Chung and Hulbert's definition); at rho_inf = 1 nothing is damped at any
    frequency."""
    for rho in (0.0, 0.5, 0.8):
        q = _modal_run(plate, "genalpha", rho, 1000.0, 8)
        assert np.allclose(q, _textbook("genalpha", rho, 1000.0, 8), rtol=0.0,
                           atol=1e-9 * AMPLITUDE)
        radius = np.max(np.abs(np.linalg.eigvals(_amplification(rho, 1e6))))
        assert radius == pytest.approx(rho, abs=1e-3)
    for omega_h in (0.1, 1.0, 10.0, 1e3):
        assert np.max(np.abs(np.linalg.eigvals(_amplification(1.0, omega_h)))) == \
            pytest.approx(1.0, abs=1e-9)


def test_free_fall_is_exact_after_the_first_step():
    """Newmark integrates a constant acceleration exactly: after the Euler first step (whose
    error is g h^2 / 2) generalised-alpha falls as x0 + g t^2 / 2, shifted by that error."""
    mesh = sheet_coarse(0.2, 0.2, cells_x=4, plane="xy")
    model = build_model(mesh, dataclasses.replace(get_material("cotton"), air_drag=0.0))
    dt, steps = 1.0 / 60.0, 30
    sim = Simulator(model, ClothState.at_rest(mesh.rest), make_solver("direct", tol=1e-12),
                    dt=dt, scheme="genalpha", track_energy=False)
    for _ in range(steps):
        sim.step()
    g = model.gravity
    t = steps * dt
    expected = mesh.rest + 0.5 * g * t * t + 0.5 * g * dt * dt
    assert np.allclose(sim.state.x, expected, atol=1e-9)
    assert np.allclose(sim.state.v, g * t, atol=1e-9)
    assert np.allclose(sim.state.a, g, atol=1e-9)


def test_the_acceleration_history_crosses_levels_of_detail():
    """A level switch keeps generalised-alpha's history: the coarse vertices' a as they were,
    the new ones' interpolated (sim.detail)."""
    from cloth_mg_ros.mesh import sheet_hierarchy
    from cloth_mg_ros.sim.detail import prolongate_state, restrict_state

    hierarchy = sheet_hierarchy(200, 1, 0.2, 0.2, plane="xy")
    fine = hierarchy.levels[0].rest
    rng = np.random.default_rng(3)
    state = ClothState(fine.copy(), rng.normal(size=fine.shape), None, None, 0.5,
                       rng.normal(size=fine.shape))
    n1 = hierarchy.levels[1].n_vertices
    coarse = restrict_state(state, n1)
    assert np.array_equal(coarse.a, state.a[:n1])
    back = prolongate_state(hierarchy, coarse, 1, 0, [], 0.005)
    assert np.array_equal(back.a[:n1], state.a[:n1]) and back.a.shape == fine.shape
    # each new vertex (an edge's midpoint) takes the mean of its edge's two ends' a
    p = hierarchy.transfers[0].prolongation()
    assert np.allclose(back.a[n1:], (p @ coarse.a)[n1:], rtol=0.0, atol=1e-14)
    assert np.allclose(np.asarray(p[n1:].sum(axis=1)).ravel(), 1.0)
    assert np.all(np.asarray((p[n1:] > 0).sum(axis=1)).ravel() == 2)


def test_a_body_replay_with_genalpha_is_bit_identical(tmp_path):
    """The walking dress stepped twice by generalised-alpha from the same bag: the same
    positions bit for bit, and it moved (the scheme is in the run)."""
    from cloth_mg_ros.apps.runner import run_body_scene
    from cloth_mg_ros.config.scenes import load_scene

    params = load_scene("walking").replace(particles=300, scheme="genalpha", threads=1,
                                           tolerance=1e-4)
    finals = []
    for k in range(2):
        summary = run_body_scene(params, tmp_path / f"r{k}", steps=12, progress=False)
        assert summary["options"]["scheme"] == "genalpha"
        finals.append(np.load(tmp_path / f"r{k}" / "positions.npz")["final"])
    assert np.array_equal(finals[0], finals[1])
    assert np.all(np.isfinite(finals[0]))
    # the scheme reaches the steps: BDF2 from the same bag ends elsewhere
    run_body_scene(params.replace(scheme="bdf2"), tmp_path / "bdf2", steps=12, progress=False)
    assert not np.array_equal(np.load(tmp_path / "bdf2" / "positions.npz")["final"], finals[0])


@pytest.mark.parametrize("rho", [-0.1, 1.5, float("nan")])
def test_a_bad_spectral_radius_is_named(rho):
    with pytest.raises(ClothInputError, match="spectral_radius"):
        GenAlpha.of(0.01, rho)
    with pytest.raises(ClothInputError, match="spectral_radius"):
        check("spectral_radius", rho)


def test_an_unknown_scheme_is_named():
    with pytest.raises(ClothInputError, match="unknown scheme 'rk4'"):
        check("scheme", "rk4")
    assert check("scheme", "genalpha") == "genalpha"


@pytest.mark.parametrize("scheme", ["euler", "bdf2", "genalpha"])
def test_a_position_correction_moves_the_velocity_by_the_schemes_own_factor(scheme):
    """StepSystem.h_move, what the strain limit and the contact projection divide a position
    correction by: x_{n+1}'s factor of v_{n+1} in the scheme's update (generalised-alpha:
    h beta / gamma, not dt), checked against the update itself."""
    from cloth_mg_ros.sim import integrator

    mesh = sheet_coarse(1, 1, 4)
    model = build_model(mesh, get_material("cotton"))
    state = ClothState.at_rest(np.array(mesh.rest, dtype=float))
    dt = 1.0 / 60.0
    if scheme != "euler":  # a state that has a step behind it (BDF2's history, alpha's a)
        sim = Simulator(model, state, make_solver("direct", tol=1e-10), dt=dt, scheme=scheme)
        sim.step()
        state = sim.state
    step = integrator.assemble_step(model, state, dt, scheme)
    dv = np.zeros((model.n, 3))
    x0 = integrator.solved_positions(state, step, dv, dt)[0]
    dv[:, 2] = 1e-3
    x1 = integrator.solved_positions(state, step, dv, dt)[0]
    assert np.allclose((x1 - x0)[:, 2], step.h_move * 1e-3, rtol=1e-8, atol=0.0)


def test_a_new_vertex_projected_out_of_a_collider_takes_its_bdf2_history_along():
    """Stepping up a level: a new vertex found inside a collider is moved out, and its
    previous position moves with it, so BDF2's next step ((4 x_n - x_{n-1}) / 3) sees no
    jump and pushes it no further (sim.detail.prolongate_state)."""
    from cloth_mg_ros.collision.colliders import PlaneCollider
    from cloth_mg_ros.mesh import sheet_hierarchy
    from cloth_mg_ros.sim.detail import prolongate_state

    hierarchy = sheet_hierarchy(200, 1, 0.2, 0.2, plane="xy")
    n1 = hierarchy.levels[1].n_vertices
    coarse = hierarchy.levels[1].rest.copy()
    coarse[:, 2] = 0.001 * np.sign(coarse[:, 0])  # a crease: some new midpoints land inside
    state = ClothState(coarse, np.zeros_like(coarse), coarse.copy(), np.zeros_like(coarse), 0.5)
    floor = PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]), friction=0.0)
    back = prolongate_state(hierarchy, state, 1, 0, [floor], 0.005)
    moved = back.x[n1:] - back.x_prev[n1:]
    assert np.any(back.x[n1:, 2] > 0.004)  # projected out to the thickness
    assert np.allclose(moved, 0.0, atol=1e-15)  # x_prev went along: no velocity implied
