"""Cloth-cloth contact: pairs from the spatial hash, spring forces and Jacobians."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cloth_mg_ros.collision.self_contact import SelfContact, spring_forces_hessians
from cloth_mg_ros.mesh import MeshHierarchy, MeshLevel, sheet_coarse
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver, make_solver


def _brute_pairs(x, rest, d0, min_rest):
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    r = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    i, j = np.nonzero((d < d0) & (r >= min_rest))
    keep = i < j
    return {(int(a), int(b)) for a, b in zip(i[keep], j[keep], strict=True)}


def test_hash_finds_exactly_the_close_pairs():
    rng = np.random.default_rng(0)
    rest = rng.uniform(-1, 1, (600, 3))
    x = rng.uniform(-0.3, 0.3, (600, 3))
    sc = SelfContact(rest, 0.05)
    got = {tuple(p) for p in sc.pairs(x).tolist()}
    assert got == _brute_pairs(x, rest, 0.05, 0.1)
    assert len(got) > 20


def test_crowded_cells_give_every_close_pair_once_on_any_number_of_threads():
    """About five particles to a cell (the search walks the particles in their buckets'
    order, the ones after a particle in its own cell and the half of its neighbourhood
    after it): every pair once, the brute force's set, and the same array on one thread
    as on all. Two sheets of cloth far apart at rest, crumpled into one box: only pairs
    across them count (under the 16 a particle the search keeps)."""
    import numba

    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 0.3, (1000, 3))
    rest = x.copy()
    rest[500:] += 10.0
    sc = SelfContact(rest, 0.05)
    pairs = sc.pairs(x)
    got = [tuple(p) for p in pairs.tolist()]
    assert len(got) == len(set(got)) > 2000
    assert set(got) == _brute_pairs(x, rest, 0.05, 0.1)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        assert np.array_equal(sc.pairs(x), pairs)
    finally:
        numba.set_num_threads(before)


def test_cells_that_share_a_bucket_and_a_key_are_told_apart_by_distance():
    """Cells 2^21 apart share a hash bucket (the hash is masked to fewer bits): their
    particles are far apart and no pair; a close pair beside them still is one."""
    d0 = 0.05
    far = 2.0 ** 21 * d0
    x = np.array([[0.01, 0.01, 0.01], [far + 0.01, 0.01, 0.01], [0.01, far + 0.01, 0.01],
                  [0.02, 0.01, 0.01]])
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    pairs = SelfContact(rest, d0).pairs(x)
    assert pairs.tolist() == [[0, 3]]
    assert {tuple(p) for p in pairs.tolist()} == _brute_pairs(x, rest, d0, 2 * d0)


def test_spring_forces_and_jacobian_match_finite_differences():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 0.02, (4, 3))
    pairs = np.array([[0, 1], [1, 3], [0, 2]])
    d0, k = 0.05, 300.0

    def energy(y):
        f = np.zeros_like(y)
        return spring_forces_hessians(y, pairs, d0, k, f, np.empty((3, 3, 3)))

    f = np.zeros_like(x)
    hess = np.empty((3, 3, 3))
    spring_forces_hessians(x, pairs, d0, k, f, hess)
    eps = 1e-7
    for i in range(4):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            assert -(energy(xp) - energy(xm)) / (2 * eps) == pytest.approx(f[i, a], rel=1e-5,
                                                                          abs=1e-8)
    # Hessian block of the pair (i, j): d f_i / d x_j = -H_ij.
    for p, (i, j) in enumerate(pairs):
        for b in range(3):
            xp, xm = x.copy(), x.copy()
            xp[j, b] += eps
            xm[j, b] -= eps
            fp, fm = np.zeros_like(x), np.zeros_like(x)
            spring_forces_hessians(xp, pairs, d0, k, fp, np.empty((3, 3, 3)))
            spring_forces_hessians(xm, pairs, d0, k, fm, np.empty((3, 3, 3)))
            fd = (fp[i] - fm[i]) / (2 * eps)
            # The compression clamp keeps only the d d^T part: compare along d.
            d = x[j] - x[i]
            dhat = d / np.linalg.norm(d)
            assert dhat @ fd == pytest.approx(dhat @ (-hess[p][:, b]), rel=1e-4)
        # ... and the pair's block is that part alone, -k d d^T / |d|^2: nothing across d
        assert np.allclose(hess[p], -k * np.outer(dhat, dhat), rtol=0.0, atol=1e-12 * k)


def _two_layers():
    """Two stacked sheets, the bottom one held at its corners: (hierarchy, model with self
    contact, top-layer mask, start positions with the top one 2 cm above the bottom).

    Two separate pieces: their rest shapes are 10 cm apart (the rest distance is what tells
    a particle's own neighbourhood from cloth it may touch)."""
    a = sheet_coarse(0.3, 0.3, cells_x=8, plane="xy", centre=(0.0, 0.0, 0.5))
    rest = np.concatenate([np.array(a.rest), np.array(a.rest) + [0.0, 0.0, 0.1]])
    faces = np.concatenate([a.faces, a.faces + a.n_vertices])
    level = MeshLevel(rest, faces)
    hier = MeshHierarchy.from_coarse(level, 1)
    mesh = hier.levels[0]
    bottom = np.flatnonzero(mesh.rest[:, 2] < 0.51)
    xy = mesh.rest[bottom, :2]
    corners = bottom[[np.argmin(xy @ s) for s in ([1, 1], [-1, 1], [1, -1], [-1, -1])]]
    model = replace(build_model(mesh, get_material("cotton"), pinned=corners),
                    self_contact=SelfContact.for_mesh(mesh.rest, mesh.edges))
    top = mesh.rest[:, 2] > 0.51
    start = np.array(mesh.rest)
    start[top, 2] -= 0.08
    return hier, model, top, start


@pytest.mark.parametrize("solver", ["bscg", "mpcg"])
def test_two_falling_layers_do_not_pass_through_each_other(solver):
    """The top sheet falls onto the bottom one (`_two_layers`)."""
    hier, model, top, start = _two_layers()
    mesh = hier.levels[0]
    sim = Simulator(model, ClothState.at_rest(start),
                    make_solver(solver, 1e-6, hierarchy=hier, bending=model.bending)
                    if solver == "mpcg" else PCGSolver(1e-6), dt=1 / 60)
    for _ in range(40):
        s = sim.step()
        assert s.converged and np.all(np.isfinite(sim.state.x))
    x = sim.state.x
    # Every top particle stays above the bottom particle it started over (the same rest x, y),
    # by at least half the contact distance (measured: 8.5 mm and more, against 7.4).
    upper, lower = np.flatnonzero(top), np.flatnonzero(~top)
    under = lower[np.lexsort(mesh.rest[lower, :2].T)][np.argsort(np.lexsort(
        mesh.rest[upper, :2].T))]
    assert np.array_equal(mesh.rest[under, :2], mesh.rest[upper, :2])
    assert np.all(x[upper, 2] > x[under, 2] + 0.5 * model.self_contact.distance)


def test_self_contact_tables_are_read_only_as_the_mesh_tables():
    """numba compiles a kernel once per array kind (read-only or writable): the self contact's
    rest shape and pairs, and a step's pairs with the cloth-cloth springs', are read-only as
    the mesh's pairs are, in a copy too, so that no path compiles the kernels again."""
    import copy

    from cloth_mg_ros.sim.integrator import assemble_step
    from cloth_mg_ros.sim.step_contacts import self_contact_pairs

    _, model, _, start = _two_layers()
    sc = model.self_contact
    assert not sc.rest.flags.writeable and not model.pairs.flags.writeable
    assert copy.deepcopy(sc).rest is sc.rest
    near = start.copy()
    near[:, 2] = np.where(near[:, 2] > 0.51, near[:, 2] - 0.02 + 0.3 * sc.distance, near[:, 2])
    pairs = self_contact_pairs(model, near)
    assert len(pairs) and not pairs.flags.writeable and not sc.pairs(near).flags.writeable
    assert not self_contact_pairs(replace(model, self_contact=None), near).flags.writeable
    step = assemble_step(model, ClothState.at_rest(near), 1 / 60, "bdf2")
    assert len(step.system.pairs) > len(model.pairs) and not step.system.pairs.flags.writeable
