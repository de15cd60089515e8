"""The multigrid hierarchy: faithful coarsening (paper Sec. 5), Galerkin baseline, cycles."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from cloth_mg_ros.mesh import sheet_hierarchy
from cloth_mg_ros.physics.bending import bending_terms, wing_hessians
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.system import BlockSystem
from cloth_mg_ros.sim.forces import internal_forces
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver, make_solver
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening, GalerkinCoarsening
from cloth_mg_ros.solvers.multigrid import MultigridSolver

AFFINE = np.array([[1.10, 0.04, 0.0], [-0.02, 0.96, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def hier():
    return sheet_hierarchy(1200, depth=2, plane="xy")


def _planar_system(hier, material, with_mass=True, scale=1e-3):
    """Fine system of a planar, uniformly stretched sheet (every child triangle has its
    parent's deformation), with hess_scale = ``scale``."""
    model = build_model(hier.levels[0], material)
    x = np.array(hier.levels[0].rest) @ AFFINE.T
    res = internal_forces(model, x)
    diag = np.zeros((model.n, 3, 3))
    if with_mass:
        diag[:] = model.mass[:, None, None] * np.eye(3)
    system = BlockSystem(diag, model.pairs, scale * res.pair_hess, scale)
    return model, x, res, system


def test_faithful_stretch_equals_direct_coarse_and_conserves_energy(hier):
    mat = get_material("cotton", bend=0.0)
    model, _, res, system = _planar_system(hier, mat)
    coarse_mesh = hier.levels[1]
    coarse_model = build_model(coarse_mesh, mat)
    xc = np.array(coarse_mesh.rest) @ AFFINE.T
    direct = internal_forces(coarse_model, xc)
    # Energy: the fine elements' sum equals the coarse triangle energies (Eq. 9).
    assert res.stretch_energy == pytest.approx(direct.stretch_energy, rel=1e-12)
    # Forces: restricted fine forces are the coarse forces.
    P = hier.transfers[0].prolongation()
    assert np.allclose(P.T @ res.forces, direct.forces, atol=1e-9 * np.abs(direct.forces).max())
    # Jacobians: the faithful coarse pair blocks are the directly differentiated ones.
    faithful = FaithfulCoarsening(hier, model.bending, 2).coarsen(system)[1]
    assert np.allclose(faithful.offd, 1e-3 * direct.pair_hess,
                       atol=1e-10 * np.abs(faithful.offd).max())


def test_faithful_and_galerkin_stretch_blocks_agree_for_linear_triangles(hier):
    mat = get_material("cotton", bend=0.0)
    model, _, _, system = _planar_system(hier, mat, with_mass=False)
    faithful = FaithfulCoarsening(hier, model.bending, 3).coarsen(system)
    galerkin = GalerkinCoarsening(hier, 3).coarsen(system)
    for f, g in zip(faithful[1:], galerkin[1:], strict=True):
        Af, Ag = f.to_csr(), g.to_csr()
        assert abs(Af - Ag).max() < 1e-10 * abs(Af).max()


def test_galerkin_smears_mass_faithful_keeps_it_diagonal(hier):
    """The paper's Fig. 2: with mass only, R M P has off-diagonal blocks; faithful has none,
    and both conserve the total mass."""
    mat = get_material("cotton")
    model, _, _, system = _planar_system(hier, mat, scale=0.0)
    faithful = FaithfulCoarsening(hier, model.bending, 2).coarsen(system)[1]
    galerkin = GalerkinCoarsening(hier, 2).coarsen(system)[1]
    assert np.abs(faithful.offd).max() == 0.0
    assert np.abs(galerkin.offd).max() > 0.01 * np.abs(galerkin.diag).max()
    total = model.mass.sum() * 3
    assert np.trace(faithful.full_diagonal(), axis1=1, axis2=2).sum() == pytest.approx(total)
    ones = np.ones(3 * galerkin.n)
    assert ones @ (galerkin.to_csr() @ ones) == pytest.approx(total)


def test_mass_conserved_level_to_level(hier):
    mat = get_material("wool")
    model, _, _, system = _planar_system(hier, mat)
    systems = FaithfulCoarsening(hier, model.bending, 3).coarsen(system)
    masses = [float(np.sum(s.diag[:, 0, 0])) for s in systems]
    assert masses == pytest.approx([model.mass.sum()] * 3, rel=1e-12)


def test_faithful_bending_matches_coarse_mesh_bending(hier):
    """Bending coarsened faithfully (hinges per wing with (A_f/A_c)^2, stars made anew on the
    coarse level) equals the coarse mesh's own bending on interior pairs (uniform mesh)."""
    mat = get_material("leather")
    fine, coarse = hier.levels[0], hier.levels[1]
    model = build_model(fine, mat)
    fc = FaithfulCoarsening(hier, model.bending, 2)
    direct = bending_terms(coarse, mat.bend).pair_values(coarse)
    got = fc.maps[0].coarse_bend
    # The fine level's own entries are what the model steps with.
    assert np.allclose(fc.fine_bend, model.bend_pairs)
    q_f = wing_hessians(fine.rest, fine.wings, fine.wing_faces, fine.face_areas, mat.bend)
    inner_f = ~fine.boundary_vertices[fine.wings].any(axis=1)
    assert np.allclose(model.bending.wing_hess[inner_f], q_f[inner_f])
    # Away from the border (where the sheet has half triangles and the free-edge term)
    # they agree exactly: a pair is interior when every wing and star touching it is.
    inner = ~coarse.boundary_vertices
    near = np.concatenate([coarse.boundary_vertices.nonzero()[0]])
    interior = np.ones(coarse.n_pairs, dtype=bool)
    touching = np.zeros(coarse.n_vertices, dtype=bool)
    touching[near] = True
    for w in range(coarse.n_wings):
        if not inner[coarse.wings[w]].all():
            interior[coarse.wing_pairs[w]] = False
    stars = model_stars = bending_terms(coarse, mat.bend).stars
    for s_verts, s_pairs in zip(stars.verts, stars.pairs, strict=True):
        if touching[s_verts].any() or not inner[s_verts].all():
            interior[s_pairs] = False
    # Pairs one ring in from the border see stars of the fine level that straddle it.
    ring = np.zeros(coarse.n_vertices, dtype=bool)
    ring[coarse.edges[touching[coarse.edges].any(axis=1)].ravel()] = True
    interior &= ~ring[coarse.pairs].any(axis=1)
    assert model_stars.verts.shape[0] > 50
    assert interior.sum() > 50
    assert np.allclose(got[interior], direct[interior], rtol=1e-9,
                       atol=1e-12 * np.abs(direct).max())
    # Total bending stiffness is of the same size everywhere.
    assert np.abs(got).sum() == pytest.approx(np.abs(direct).sum(), rel=0.2)


def test_every_coarse_system_is_spd_and_block_symmetric(contact_step):
    scene, step = contact_step
    for coarsening in (FaithfulCoarsening(scene.hierarchy, scene.model.bending, 3),
                       GalerkinCoarsening(scene.hierarchy, 3)):
        for s in coarsening.coarsen(step.system)[1:]:
            assert np.allclose(s.offd, np.transpose(s.offd, (0, 2, 1)), atol=1e-14)
            A = s.to_csr().toarray()
            assert np.allclose(A, A.T, atol=1e-12 * np.abs(A).max())
            assert np.linalg.eigvalsh(A).min() > 0.0
            d = np.random.default_rng(0).standard_normal((s.n, 3))
            assert np.allclose(s.matvec(d).reshape(-1), A @ d.reshape(-1))


@pytest.mark.parametrize("coarsening, smoother", [("faithful", "gs"), ("faithful", "cg"),
                                                  ("galerkin", "gs"), ("faithful", "jacobi")])
def test_vcycle_reduces_residual_of_random_rhs(contact_step, coarsening, smoother):
    """Each V-cycle contracts the error in the energy norm (the residual in the A^-1 norm),
    which is the norm multigrid reduces; the 2-norm of the residual may not be monotone."""
    scene, step = contact_step
    mg = MultigridSolver(scene.hierarchy, scene.model.bending, 3, coarsening, "vcycle",
                         smoother)
    levels = mg.setup(step.system, None)
    A = step.system.to_csr().tocsc()
    b = np.random.default_rng(1).standard_normal((step.system.n, 3))
    exact = spla.spsolve(A, b.reshape(-1))

    def energy_error(x):
        e = exact - x.reshape(-1)
        return float(np.sqrt(e @ (A @ e)))

    x = np.zeros_like(b)
    errors = [energy_error(x)]
    for _ in range(3):
        mg.vcycle(levels, 0, b, x)
        errors.append(energy_error(x))
    assert errors[1] < 0.9 * errors[0]
    assert all(later < earlier for earlier, later in itertools.pairwise(errors))


@pytest.mark.parametrize("name", ["pcg", "bjpcg", "bscg", "galerkin", "mg", "mpcg"])
def test_every_solver_agrees_with_direct_solve(contact_step, name):
    scene, step = contact_step
    tol = 1e-5
    solver = make_solver(name, tol=tol, maxiter=5000, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    res = solver.solve(step.system, step.rhs, step.x0, step.fixed)
    A = step.system.to_csr()
    exact = spla.spsolve(A.tocsc(), step.rhs.reshape(-1)).reshape(-1, 3)
    assert res.converged
    resid = np.linalg.norm(step.rhs.reshape(-1) - A @ res.x.reshape(-1))
    assert resid <= 1.01 * tol * np.linalg.norm(step.rhs)
    # Error bounded by the condition-number-weighted tolerance; far tighter in practice.
    assert np.linalg.norm(res.x - exact) <= 1e-2 * np.linalg.norm(exact)


@pytest.mark.parametrize("name", ["galerkin", "mg", "mpcg"])
def test_multigrid_holds_pins(name):
    scene = build_scene("hang", 1200, get_material("denim"))
    solver = make_solver(name, tol=1e-6, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    sim = Simulator(scene.model, scene.state, solver, dt=1 / 60)
    pins = scene.model.pinned
    start = scene.state.x[pins].copy()
    for _ in range(10):
        s = sim.step()
        assert s.converged
    assert np.array_equal(sim.state.x[pins], start)
    assert np.all(np.isfinite(sim.state.x))


def test_multigrid_iterations_flat_with_size():
    """Preconditioned CG iterations barely grow with the mesh (Jacobi PCG's do)."""
    its_mg, its_pcg = [], []
    for n in (300, 1200, 4500):
        scene = build_scene("hang", n, get_material("cotton"))
        state = ClothState(scene.state.x.copy(), np.zeros_like(scene.state.x))
        state.x[:, 2] += 0.02 * np.sin(3 * state.x[:, 0])  # a non-trivial, bent state
        step = assemble_step(scene.model, state, 1 / 60, "bdf2")
        mg = make_solver("mpcg", tol=1e-4, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
        its_mg.append(mg.solve(step.system, step.rhs, step.x0, step.fixed).iterations)
        its_pcg.append(PCGSolver(1e-4).solve(step.system, step.rhs, step.x0,
                                             step.fixed).iterations)
    assert max(its_mg) <= 35
    assert its_mg[-1] <= its_mg[0] + 10
    assert its_pcg[-1] > 2 * its_pcg[0]
