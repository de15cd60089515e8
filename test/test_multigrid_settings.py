"""The multigrid solver's settings: impossible values refused, `levels` above the hierarchy's
depth taking all of it, and the CG smoother doing `sweeps` passes."""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh import sheet_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.solvers import make_solver
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening, GalerkinCoarsening
from cloth_mg_ros.solvers.multigrid import MultigridSolver


@pytest.fixture(scope="module")
def sheet():
    """A 3-level hierarchy of a hanging-sheet size, its model and one implicit step."""
    hier = sheet_hierarchy(1200, depth=2, plane="xz")
    model = build_model(hier.levels[0], get_material("cotton"), pinned=np.array([0, 1]))
    rest = np.array(hier.levels[0].rest)
    state = ClothState.at_rest(rest + 0.01 * np.sin(7.0 * rest[:, [2, 0, 1]]))
    step = assemble_step(model, state, 1 / 60, "bdf2")
    return hier, model, step


@pytest.mark.parametrize("name, value", [
    ("tol", 0.0), ("tol", 1.0), ("tol", -1e-4), ("tol", float("nan")), ("tol", float("inf")),
    ("smooth_ratio", 0.0), ("smooth_ratio", 1.5), ("smooth_ratio", float("nan")),
    ("maxiter", 0), ("maxiter", -5), ("maxiter", 2.5),
    ("sweeps", 0), ("sweeps", -1), ("sweeps", 1.5),
    ("parts", 0), ("parts", -2),
])
def test_impossible_settings_are_refused_by_name_and_value(sheet, name, value):
    hier, model, _ = sheet
    with pytest.raises(ClothInputError, match=rf"{name} .*{re.escape(repr(value))}"):
        MultigridSolver(hier, model.bending, 3, **{name: value})


@pytest.mark.parametrize("levels", [0, -1, 2.0, True])
def test_coarsenings_refuse_a_levels_below_one_or_not_an_integer(sheet, levels):
    hier, model, _ = sheet
    with pytest.raises(ClothInputError, match="levels"):
        FaithfulCoarsening(hier, model.bending, levels)
    with pytest.raises(ClothInputError, match="levels"):
        GalerkinCoarsening(hier, levels)
    with pytest.raises(ClothInputError, match="levels"):
        MultigridSolver(hier, model.bending, levels)


def test_levels_above_the_depth_take_the_whole_hierarchy(sheet):
    """Documented on purpose: a garment's coarser rungs (sim.detail) pass the options' one
    `levels` to the shallower hierarchy below them."""
    hier, model, step = sheet
    deep = MultigridSolver(hier, model.bending, 5)
    assert deep.n_levels == len(hier.levels) == 3
    exact = MultigridSolver(hier, model.bending, 3)
    a = deep.solve(step.system, step.rhs, step.x0, step.fixed)
    b = exact.solve(step.system, step.rhs, step.x0, step.fixed)
    assert a.iterations == b.iterations and np.array_equal(a.x, b.x)


def test_make_solver_defaults_still_build_every_multigrid(sheet):
    hier, model, step = sheet
    for name in ("galerkin", "mg", "mpcg"):
        solver = make_solver(name, hierarchy=hier, bending=model.bending)
        assert solver.solve(step.system, step.rhs, step.x0, step.fixed).converged


def test_cg_smoother_honours_sweeps(sheet):
    """Two CG smoothing passes (each to a smooth_ratio drop) contract a V-cycle's error more
    than one; one pass is what sweeps=1 (the default) always did."""
    hier, model, step = sheet
    A = step.system.to_csr().tocsc()
    b = np.random.default_rng(2).standard_normal((step.system.n, 3))
    exact = spla.spsolve(A, b.reshape(-1))

    def energy_error(sweeps: int) -> float:
        mg = MultigridSolver(hier, model.bending, 3, "faithful", "vcycle", "cg", sweeps=sweeps)
        levels = mg.setup(step.system, None)
        x = np.zeros_like(b)
        mg.vcycle(levels, 0, b, x)
        e = exact - x.reshape(-1)
        return float(np.sqrt(e @ (A @ e)))

    one, two = energy_error(1), energy_error(2)
    assert two < 0.9 * one
