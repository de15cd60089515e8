"""The baseline solvers (PyAMG-preconditioned CG, sparse direct) on small real systems: a
sheet resting on the sphere (contacts) and a sheet hung by two pinned corners."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver, make_solver
from cloth_mg_ros.solvers.baselines import (
    AMGSolver,
    DirectSolver,
    filtered_bsr,
    rigid_translations,
)

pytest.importorskip("pyamg")

TOL = 1e-4


def _step_system(scene: str, steps: int, particles: int = 1200):
    sc = build_scene(scene, particles, get_material("cotton"))
    sim = Simulator(sc.model, sc.state, PCGSolver(tol=1e-6))
    for _ in range(steps):
        sim.step()
    return sc, assemble_step(sc.model, sim.state, sim.dt, "bdf2")


@pytest.fixture(scope="module")
def drape():
    _, step = _step_system("drape", 15)
    assert len(step.contacts) > 0, "the sheet should rest on the sphere"
    return step


@pytest.fixture(scope="module")
def hang():
    sc, step = _step_system("hang", 6)
    assert len(sc.model.pinned) == 2 and step.fixed.sum() == 2
    return step


def _filtered_rel_residual(step, x):
    r = step.rhs - step.system.matvec(x)
    sb = step.rhs.copy()
    r[step.fixed] = 0.0
    sb[step.fixed] = 0.0
    return np.linalg.norm(r) / np.linalg.norm(sb)


def _a_norm(step, v):
    return float(np.sqrt(np.sum(v * step.system.matvec(v))))


def _x0(step, seed=0):
    """A nonzero initial guess: pinned values as assembled, noise elsewhere."""
    rng = np.random.default_rng(seed)
    x0 = 1e-3 * rng.standard_normal(step.x0.shape)
    x0[step.fixed] = step.x0[step.fixed]
    return x0


@pytest.mark.parametrize("case", ["drape", "hang"])
def test_direct_and_amg_solve_the_filtered_system(case, request):
    step = request.getfixturevalue(case)
    x0 = _x0(step)
    if case == "hang":  # nonzero pinned values, so that keeping them means something
        x0[step.fixed] = [[0.01, -0.02, 0.03], [-0.04, 0.05, -0.06]]

    direct = DirectSolver()
    ref = direct.solve(step.system, step.rhs, x0, step.fixed)
    assert ref.iterations == 0 and ref.converged
    assert ref.rel_residual < 1e-10
    assert _filtered_rel_residual(step, ref.x) == pytest.approx(ref.rel_residual, rel=1e-6,
                                                                abs=1e-14)
    np.testing.assert_array_equal(ref.x[step.fixed], x0[step.fixed])
    assert direct.last_factor_ms > 0.0 and direct.last_backend

    amg = AMGSolver(tol=TOL)
    res = amg.solve(step.system, step.rhs, x0, step.fixed)
    assert res.converged and 0 < res.iterations < 100
    assert res.rel_residual <= TOL
    # the reported residual is the true filtered one, not the CG recurrence
    assert _filtered_rel_residual(step, res.x) == pytest.approx(res.rel_residual, rel=1e-6)
    np.testing.assert_array_equal(res.x[step.fixed], x0[step.fixed])
    # agreement in the energy norm (measured 4.6 tol on the drape, 0.02 tol on the hang; the
    # Euclidean error is ~150 tol on the drape, for Jacobi PCG too: stiff contacts)
    assert _a_norm(step, res.x - ref.x) <= 10 * TOL * _a_norm(step, ref.x)
    assert amg.last_setup_ms > 0.0 and amg.last_solve_ms > 0.0
    assert amg.last_levels >= 2 and amg.last_operator_complexity >= 1.0


def test_amg_and_pcg_share_the_stopping_rule(drape):
    """Same stopping rule as PCG: both reach tol from the same start, and AMG needs far
    fewer iterations than Jacobi PCG."""
    x0 = _x0(drape, 1)
    pcg = PCGSolver(tol=TOL).solve(drape.system, drape.rhs, x0.copy(), drape.fixed)
    amg = AMGSolver(tol=TOL).solve(drape.system, drape.rhs, x0, drape.fixed)
    assert pcg.converged and amg.converged
    assert amg.iterations < pcg.iterations / 3


def test_direct_backends_agree(hang):
    ref = DirectSolver(backend="splu").solve(hang.system, hang.rhs, hang.x0, hang.fixed)
    assert ref.rel_residual < 1e-10
    auto = DirectSolver()
    res = auto.solve(hang.system, hang.rhs, hang.x0, hang.fixed)
    assert auto.last_backend in ("cholmod", "splu", "splu-colamd")
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        pass
    else:
        assert auto.last_backend == "cholmod"
    np.testing.assert_allclose(res.x, ref.x, rtol=0, atol=1e-9 * np.abs(ref.x).max())


def test_direct_solve_adds_a_spring_on_a_pair_twice(hang):
    """A cloth-cloth spring can join the ends of a bending (wing) pair: the system then holds
    two blocks on one pair, which add. The Cholesky solve must see their sum (cvxopt adds
    repeated triplets; the factor's matrix refill in place must not assume none repeat)."""
    from cloth_mg_ros.physics.system import BlockSystem

    system = hang.system
    p = len(system.pairs) - 1  # a pair of the mesh, its blocks given a second time
    pairs = np.concatenate([system.pairs, system.pairs[p:p + 1]])
    extra = -0.5 * np.abs(system.offd[p:p + 1]).max() * np.eye(3)[None]
    twice = BlockSystem(system.diag, pairs, np.concatenate([system.offd, extra]),
                        system.hess_scale)
    res = DirectSolver().solve(twice, hang.rhs, hang.x0, hang.fixed)
    ref = DirectSolver(backend="splu").solve(twice, hang.rhs, hang.x0, hang.fixed)
    np.testing.assert_allclose(res.x, ref.x, rtol=0, atol=1e-9 * np.abs(ref.x).max())


def test_amg_on_a_one_level_hierarchy():
    """Fewer unknowns than max_coarse: PyAMG makes one level, an exact solve."""
    _, step = _step_system("hang", 2, particles=100)
    assert 3 * step.system.n <= AMGSolver.DEFAULT_OPTIONS["max_coarse"]
    amg = AMGSolver(tol=1e-8)
    res = amg.solve(step.system, step.rhs, step.x0, step.fixed)
    assert amg.last_levels == 1
    assert res.converged and res.iterations <= 2 and res.rel_residual <= 1e-8
    np.testing.assert_array_equal(res.x[step.fixed], step.x0[step.fixed])


def test_zero_rhs_and_exact_start(drape):
    n = drape.system.n
    zero = np.zeros((n, 3))
    for solver in (AMGSolver(), DirectSolver()):
        res = solver.solve(drape.system, zero, None, None)
        assert res.converged and np.all(res.x == 0.0)
    exact = DirectSolver().solve(drape.system, drape.rhs).x
    res = AMGSolver().solve(drape.system, drape.rhs, exact)
    assert res.iterations == 0 and res.converged


def test_filtered_matrix_and_nullspace(hang):
    system, fixed = hang.system, hang.fixed
    A = filtered_bsr(system).tocsr()
    assert A.shape == (3 * system.n, 3 * system.n)
    assert abs(A - A.T).max() <= 1e-12 * abs(A).max()
    d = np.random.default_rng(2).standard_normal((system.n, 3))
    np.testing.assert_allclose(A @ d.ravel(), system.matvec(d).ravel(), rtol=1e-12, atol=1e-12)
    Af = filtered_bsr(system, fixed).tocsr()
    pinned = np.flatnonzero(np.repeat(fixed, 3))
    np.testing.assert_array_equal(Af[pinned].toarray(), np.eye(3 * system.n)[pinned])
    np.testing.assert_array_equal(Af[:, pinned].toarray(), np.eye(3 * system.n)[:, pinned])
    B = rigid_translations(system.n)
    np.testing.assert_array_equal(B.reshape(system.n, 3, 3), np.broadcast_to(np.eye(3),
                                                                             (system.n, 3, 3)))


def test_make_solver_builds_the_baselines():
    amg = make_solver("amg", tol=1e-5)
    assert isinstance(amg, AMGSolver) and amg.name == "amg" and amg.tol == 1e-5
    assert amg.maxiter == 500
    direct = make_solver("direct")
    assert isinstance(direct, DirectSolver) and direct.name == "direct"
    with pytest.raises(ValueError):
        DirectSolver(backend="pardiso")


def test_amg_iteration_cap(drape):
    res = AMGSolver(tol=1e-12, maxiter=3).solve(drape.system, drape.rhs, drape.x0, drape.fixed)
    assert res.iterations == 3 and not res.converged and res.rel_residual > 1e-12
