"""The packed MG-preconditioned CG (solvers.packed_levels, packed_kernels): the packed V-cycle
against the level list's, its preconditioner symmetric positive definite, the last sweep's
product, the first residual near the pins, the translation guess, the parts a level splits
into and their threads, and the levels as data. The step system is the drape's
(conftest.contact_step); the hierarchy's coarsening and cycles: test_multigrid.py."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from packed_rows import first_residual

from cloth_mg_ros.mesh import sheet_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.physics.system import BlockSystem
from cloth_mg_ros.sim.integrator import assemble_step
from cloth_mg_ros.sim.model import ClothState
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import PCGSolver, make_solver
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening
from cloth_mg_ros.solvers.multigrid import MultigridSolver


# -- the packed MG-preconditioned CG (solvers.packed_levels, packed_kernels) ---------------
def _packed_preconditioner(scene, system, fixed, levels=3, parts=1):
    """z = M^-1 r as the packed path applies it (one V-cycle), as a function of r (n, 3) in
    vertex order."""
    from cloth_mg_ros.solvers.packed_kernels import vcycle_down, vcycle_up
    from cloth_mg_ros.solvers.packed_levels import PackedLevels, scalar_pairs

    mg = MultigridSolver(scene.hierarchy, scene.model.bending, levels)
    systems = mg._coarse_systems(system, fixed)
    meshes = scene.hierarchy.levels[: len(systems)]
    pk = PackedLevels([s.n for s in systems], mg._parents[: len(systems) - 1],
                      [lv.rest for lv in meshes], [scalar_pairs(lv) for lv in meshes], parts)
    pk.fill(systems, fixed)
    coarse = mg._coarse_solver(systems[-1]) if len(systems) > 1 else None
    lo = int(pk.voff[-2])
    args = (pk.slots, pk.dinv6, pk.free, pk.kids)

    def apply(r, product=None):
        """M^-1 r; with product (n, 3), also S A M^-1 r as the last sweep forms it."""
        rows = pk.to_rows(r)
        z = np.zeros_like(rows)
        w = np.zeros_like(rows)
        vcycle_down(pk.n_levels, pk.voff, pk.bounds, pk.chunks, *args, rows, pk.b, pk.x,
                    pk.r)
        if coarse is not None:
            pk.x[lo:] = coarse.solve(pk.b[lo:])
        vcycle_up(pk.n_levels, pk.voff, pk.bounds, pk.chunks, pk.slots, pk.dinv6, pk.diag6,
                  pk.free, pk.parents, pk.b, pk.x, rows, z, w)
        if product is not None:
            product[:] = pk.from_rows(w)
        return pk.from_rows(z)

    return apply, pk


@pytest.mark.parametrize("levels", [1, 2, 3])
def test_packed_vcycle_equals_the_level_list_vcycle(contact_step, levels):
    """With one part (the natural order) the packed V-cycle (a one-pass first sweep with its
    residual, flat arrays) applies the same preconditioner as the level-list V-cycle."""
    scene, step = contact_step
    apply, _ = _packed_preconditioner(scene, step.system, step.fixed, levels)
    ref = MultigridSolver(scene.hierarchy, scene.model.bending, levels)
    ref._rows_dtype = np.float64
    lv = ref.setup(step.system, step.fixed)
    r = np.random.default_rng(3).standard_normal((step.system.n, 3)) * lv[0].free[:, None]
    z_ref = np.zeros_like(r)
    ref.vcycle(lv, 0, r, z_ref)
    z = apply(r)
    assert np.allclose(z, z_ref * lv[0].free[:, None], rtol=1e-9,
                       atol=1e-12 * np.abs(z_ref).max())


@pytest.mark.parametrize("parts", [1, 2, 3])
def test_packed_preconditioner_is_symmetric_positive_definite(parts):
    """CG needs M^-1 symmetric positive definite: u . M^-1 v == v . M^-1 u, u . M^-1 u > 0,
    in the natural order and in the parts-then-separator orders of threaded sweeps."""
    scene = build_scene("drape", 4500, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, make_solver("direct"), dt=1 / 60)
    for _ in range(25):
        sim.step()
    step = assemble_step(scene.model, sim.state, sim.dt, "bdf2")
    apply, pk = _packed_preconditioner(scene, step.system, step.fixed, parts=parts)
    if parts > 1:
        assert pk.orderings[0].parts == parts and 0 < pk.orderings[0].separator
    rng = np.random.default_rng(4)
    free = pk.free[: step.system.n, None]
    u, v = (pk.from_rows(rng.standard_normal((step.system.n, 3)) * free) for _ in range(2))
    assert np.isclose(np.sum(u * apply(v)), np.sum(v * apply(u)), rtol=1e-9)
    assert np.sum(u * apply(u)) > 0.0


@pytest.mark.parametrize("parts", [1, 2, 3])
def test_last_sweep_forms_the_product_of_its_result(contact_step, parts):
    """The V-cycle's last (backward) sweep forms w = S A z of the z it leaves, the product the
    outer CG then needs: equal to a separate product to rounding, with pinned particles
    (zero rows) and in the parts-then-separator orders of threaded sweeps."""
    from cloth_mg_ros.physics.system import bs_matvec

    scene, step = contact_step
    fixed = np.zeros(step.system.n, dtype=bool)
    fixed[:: max(1, step.system.n // 7)] = True
    apply, pk = _packed_preconditioner(scene, step.system, fixed, parts=parts)
    if parts > 1:
        assert pk.orderings[0].separator > 0
    free = ~fixed
    r = np.random.default_rng(5).standard_normal((step.system.n, 3)) * free[:, None]
    w = np.empty_like(r)
    z = apply(r, product=w)
    assert np.all(z[fixed] == 0.0) and np.all(w[fixed] == 0.0)
    ref = np.empty_like(z)
    bs_matvec(step.system.diag, step.system.pairs, step.system.offd, z, ref)
    ref[fixed] = 0.0
    assert np.allclose(w, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())


def _pinned_packed(contact_step, parts):
    """The contact step's packed levels with every seventh particle pinned, and a first
    guess (n, 3) that moves the pins but one (zero elsewhere)."""
    scene, step = contact_step
    n = step.system.n
    fixed = np.zeros(n, dtype=bool)
    fixed[:: max(1, n // 7)] = True
    _, pk = _packed_preconditioner(scene, step.system, fixed, parts=parts)
    moved = np.random.default_rng(3).standard_normal((n, 3)) * fixed[:, None]
    moved[np.flatnonzero(fixed)[0]] = 0.0  # a pin that stays
    return step, fixed, pk, moved


@pytest.mark.parametrize("parts", [1, 2])
def test_first_residual_gathers_only_near_the_pins(contact_step, parts):
    """A solve's first guess is zero but on its pins: the first residual S (b - A x) gathers
    A x only on the pinned rows and their neighbours, and is the same, bit for bit, as the
    gather over every row; a guess nonzero on a free row (a warm start) gathers everywhere."""
    from cloth_mg_ros.physics.system import bs_matvec
    from cloth_mg_ros.solvers.packed_kernels import residual_rows, touched_rows

    step, fixed, pk, moved = _pinned_packed(contact_step, parts)
    n = step.system.n
    rng = np.random.default_rng(4)
    b = pk.to_rows(rng.standard_normal((n, 3)))
    everywhere = np.ones(n, dtype=np.uint8)
    for guess in (moved, moved + 1e-3 * rng.standard_normal((n, 3))):
        x = pk.to_rows(guess)
        touched = np.empty(n, dtype=np.uint8)
        touched_rows(n, pk.slots, pk.free[:n], x, touched)
        r, r_all = np.empty_like(x), np.empty_like(x)
        rr = residual_rows(pk.fine_chunks, pk.slots, pk.diag6, pk.free, b, x, r, touched)
        rr_all = residual_rows(pk.fine_chunks, pk.slots, pk.diag6, pk.free, b, x, r_all,
                               everywhere)
        assert np.array_equal(r, r_all) and rr == rr_all
        ax = np.empty_like(guess)
        bs_matvec(step.system.diag, step.system.pairs, step.system.offd, guess, ax)
        reached = np.zeros(n, dtype=bool)
        reached[np.any(ax != 0.0, axis=1)] = True
        assert np.all(touched[pk.orderings[0].pos[reached]] == 1)  # every row A x reaches
        if np.any(guess[~fixed] != 0.0):
            assert np.all(touched == 1)
        else:
            # the pins, the one that stays too, and their neighbours: a few rows
            near = fixed.copy()
            for i, j in step.system.pairs:
                near[i] |= fixed[j]
                near[j] |= fixed[i]
            assert np.array_equal(touched.astype(bool), near[pk.orderings[0].order])
            assert 0 < touched.sum() < n // 2


@pytest.mark.parametrize("parts", [1, 2])
def test_translation_guess_is_the_galerkin_projection_onto_translations(contact_step, parts):
    """The first guess's common translation of the free particles: afterwards the residual
    has no part along any translation (T^T r = 0 over the free rows), it is exactly
    S (b - A x) of the moved guess, the pins did not move, and the error in the A-norm
    fell (the projection minimises it over the translations)."""
    from cloth_mg_ros.physics.system import bs_matvec
    from cloth_mg_ros.solvers.first_guess import translate_rows, translation_guess

    step, fixed, pk, moved = _pinned_packed(contact_step, parts)
    system, n = step.system, step.system.n
    free = ~fixed
    b = np.random.default_rng(5).standard_normal((n, 3)) + [0.0, 0.0, -2.0]  # a weight
    x, touched, r, rows_b = first_residual(pk, moved, b)
    t = translation_guess(pk, touched, r)
    assert t is not None and np.linalg.norm(t) > 0.0
    rr = translate_rows(pk.fine_chunks, pk.slots, pk.bdiag6, pk.free, touched, t, x, r)
    guess = pk.from_rows(x)
    assert np.array_equal(guess[fixed], moved[fixed])
    assert np.allclose(guess[free] - moved[free], t, rtol=0.0, atol=1e-15)

    def residual(v):
        out = np.empty_like(v)
        bs_matvec(system.diag, system.pairs, system.offd, v, out)
        return (b - out) * free[:, None]

    ref = residual(guess)
    scale = np.abs(ref).max()
    assert np.allclose(pk.from_rows(r), ref, rtol=0.0, atol=1e-10 * scale)
    assert rr == pytest.approx(float(np.sum(ref * ref)), rel=1e-9)
    assert np.allclose(ref[free].sum(axis=0), 0.0, atol=1e-10 * np.abs(ref).sum())
    # the error's A-norm, e^T A e = r^T A_ff^-1 r, with A_ff the free particles' block
    a_ff = system.to_csr()[np.repeat(free, 3)][:, np.repeat(free, 3)].tocsc()
    before, after = residual(moved)[free].ravel(), ref[free].ravel()
    energy = [float(v @ spla.spsolve(a_ff, v)) for v in (before, after)]
    assert energy[1] < energy[0]


def test_solve_spd3_solves_and_refuses_what_is_not_positive_definite():
    from cloth_mg_ros.solvers.first_guess import solve_spd3

    rng = np.random.default_rng(7)
    upper = [0, 1, 2, 4, 5, 8]  # xx, xy, xz, yy, yz, zz of a flattened 3 x 3
    for _ in range(20):
        m = rng.standard_normal((3, 3))
        spd = m @ m.T + 0.1 * np.eye(3)
        rhs = rng.standard_normal(3)
        t = np.zeros(3)
        assert solve_spd3(np.concatenate([spd.ravel()[upper], rhs]), t)
        assert np.allclose(spd @ t, rhs, rtol=1e-12, atol=1e-12 * np.abs(rhs).max())
    for bad in (np.diag([1.0, -1.0, 1.0]), np.zeros((3, 3)),
                np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])):
        t = np.full(3, 5.0)
        assert not solve_spd3(np.concatenate([bad.ravel()[upper], np.ones(3)]), t)
        assert np.all(t == 5.0)
    t = np.zeros(3)
    assert not solve_spd3(np.array([1.0, 0, 0, 1.0, 0, 1.0, np.nan, 0, 0]), t)


def test_pairs_off_the_mesh_edges_carry_scalar_blocks_on_every_level(contact_step):
    """The packed levels keep one weight for a pair that is no mesh edge (a bending wing
    tip): its block must be w I on every level of the faithful hierarchy."""
    from cloth_mg_ros.solvers.packed_levels import scalar_pairs

    scene, step = contact_step
    mg = MultigridSolver(scene.hierarchy, scene.model.bending, 3)
    for lvl, s in enumerate(mg._coarse_systems(step.system, step.fixed)):
        mask = scalar_pairs(scene.hierarchy.levels[lvl])
        assert mask.any() and not mask.all()
        blocks = s.offd[: len(mask)][mask]
        w = blocks[:, 0, 0]
        assert np.array_equal(blocks, w[:, None, None] * np.eye(3)[None])


def test_parts_split_levels_into_independent_parts_and_a_separator():
    """No pair joins two different parts; the separator is a thin cut; the order is a
    permutation; one part is the natural order."""
    from cloth_mg_ros.solvers.dissection import slabs, split_ordering

    hier = sheet_hierarchy(4500, depth=2, plane="xy")
    level = hier.levels[0]
    for parts in (1, 2, 4):
        o = split_ordering(slabs(level.rest, parts), level.pairs, parts)
        n = level.n_vertices
        assert np.array_equal(np.sort(o.order), np.arange(n))
        assert np.array_equal(o.pos[o.order], np.arange(n))
        part = np.searchsorted(o.bounds, o.pos, side="right") - 1  # parts; `parts` = separator
        a, b = part[level.pairs[:, 0]], part[level.pairs[:, 1]]
        assert np.all((a == b) | (a == parts) | (b == parts))
        if parts == 1:
            assert np.array_equal(o.order, np.arange(n)) and o.separator == 0
        else:
            assert 0 < o.separator < 0.1 * n * (parts - 1)


@pytest.mark.parametrize("parts", [1, 2])
def test_packed_solver_follows_changing_pairs(contact_step, parts):
    """Extra pair blocks on the finest level (cloth-cloth springs) come and go between solves,
    within one part or across the cut: the finest level's slots (and its ordering where a
    spring crosses the cut) are rebuilt, the coarse levels' kept; every solve agrees with a
    direct solve of its own system, and bit for bit with a new solver's (what came before
    does not change the arithmetic)."""
    from cloth_mg_ros.solvers.dissection import slabs

    scene, step = contact_step
    system = step.system
    rng = np.random.default_rng(5)
    slab = slabs(scene.hierarchy.levels[0].rest, parts)
    first, second = np.flatnonzero(slab == 0), np.flatnonzero(slab == slab.max())
    solver = MultigridSolver(scene.hierarchy, scene.model.bending, 3, tol=1e-8, parts=parts)
    for extra, across in ((0, False), (40, True), (30, False), (0, False), (25, True),
                          (20, False), (20, False)):
        pairs, offd = system.pairs, system.offd
        if extra:
            ends = rng.choice(first, 2 * extra, replace=False)
            i, j = ends[:extra], ends[extra:]
            if across:
                j = rng.choice(second, extra, replace=False)
            d = rng.standard_normal((extra, 3))
            springs = -50.0 * d[:, :, None] * d[:, None, :]  # -k d d^T, as a contact spring
            pairs = np.concatenate([pairs, np.stack([np.minimum(i, j), np.maximum(i, j)], 1)])
            offd = np.concatenate([offd, springs])
        s = BlockSystem(system.diag, pairs, offd, system.hess_scale)
        res = solver.solve(s, step.rhs, step.x0, step.fixed)
        exact = spla.spsolve(s.to_csr().tocsc(), step.rhs.reshape(-1)).reshape(-1, 3)
        assert res.converged
        assert np.linalg.norm(res.x - exact) <= 1e-5 * np.linalg.norm(exact)
        fresh = MultigridSolver(scene.hierarchy, scene.model.bending, 3, tol=1e-8,
                                parts=parts).solve(s, step.rhs, step.x0, step.fixed)
        assert res.iterations == fresh.iterations
        assert np.array_equal(res.x, fresh.x)


@pytest.mark.skipif(__import__("numba").config.NUMBA_NUM_THREADS < 2,
                    reason="numba has one thread here: nothing to compare one thread with")
def test_threaded_sweeps_give_the_same_iterates_on_any_number_of_threads():
    """Two parts swept on one thread or on two: bit-identical solutions (the ordering, not the
    threads, decides the arithmetic)."""
    import numba

    scene = build_scene("hang", 4500, get_material("cotton"))
    state = ClothState(scene.state.x.copy(), np.zeros_like(scene.state.x))
    state.x[:, 2] += 0.02 * np.sin(3 * state.x[:, 0])
    step = assemble_step(scene.model, state, 1 / 60, "bdf2")
    results = []
    before = numba.get_num_threads()
    try:
        for threads in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(threads)
            solver = MultigridSolver(scene.hierarchy, scene.model.bending, 3, parts=2)
            results.append(solver.solve(step.system, step.rhs, step.x0, step.fixed))
    finally:
        numba.set_num_threads(before)
    assert results[0].iterations == results[1].iterations
    assert np.array_equal(results[0].x, results[1].x)


@pytest.mark.parametrize("parts", [2, 3])
def test_split_coarsening_kernels_give_the_serial_numbers(contact_step, parts):
    """The coarsening's scatters on several threads (each its own range of coarse blocks,
    the fine ones in order) are the serial scatters, bit for bit."""
    from cloth_mg_ros.solvers.coarsening import (
        STRETCH_WEIGHT,
        scatter_stretch_blocks,
        scatter_stretch_blocks_split,
    )
    from cloth_mg_ros.solvers.transfer_ops import restrict_blocks, restrict_blocks_split

    scene, step = contact_step
    system = step.system
    co = FaithfulCoarsening(scene.hierarchy, scene.model.bending, 2)
    mp = co.maps[0]
    n_c = int(mp.parents.max()) + 1
    one, many = np.empty((n_c, 3, 3)), np.full((n_c, 3, 3), np.nan)
    restrict_blocks(mp.parents, system.diag, one)
    restrict_blocks_split(mp.parents, system.diag, many, parts)
    assert np.array_equal(one, many)
    one, many = (np.zeros((len(mp.coarse_pairs), 3, 3)) for _ in range(2))
    args = (mp.edge_src, mp.edge_dst, STRETCH_WEIGHT, system.offd, system.hess_scale,
            co.fine_bend)
    scatter_stretch_blocks(*args, one)
    scatter_stretch_blocks_split(*args, many, parts)
    assert np.array_equal(one, many) and np.any(one != 0.0)


def test_pinned_sizes_from_the_mesh_tables_are_those_of_a_pass_over_every_pair(contact_step):
    """pinned_diagonal_size with the mesh's pairs looked up by vertex (what the solver does)
    gives the pass over every pair's numbers, bit for bit, with cloth-cloth springs after
    the mesh's pairs (one of them repeating a mesh pair)."""
    from cloth_mg_ros.solvers.multigrid import pair_ends, pinned_diagonal_size

    scene, step = contact_step
    system = step.system
    n, mesh = system.n, scene.hierarchy.levels[0]
    rng = np.random.default_rng(1)
    springs = np.array([[0, n - 1], [3, n // 2], [int(mesh.pairs[5, 0]), int(mesh.pairs[5, 1])]])
    extra = BlockSystem(system.diag, np.concatenate([system.pairs, springs]),
                        np.concatenate([system.offd, rng.standard_normal((3, 3, 3))]),
                        system.hess_scale)
    ends = pair_ends(mesh.pairs, mesh.n_vertices)
    for s in (system, extra):
        for rows in ([0, 3, n // 2, n - 1], [int(mesh.pairs[5, 0])], list(range(0, n, 7))):
            fixed = np.zeros(n, dtype=bool)
            fixed[rows] = True
            want = pinned_diagonal_size(s, fixed)
            got = pinned_diagonal_size(s, fixed, ends, len(mesh.pairs))
            assert np.array_equal(got, want) and np.all(want > 0.0)


def test_the_hierarchy_prints_its_levels_and_preconditions_scipys_cg():
    """PyAMG's print(ml) and ml.aspreconditioner(): the levels a step builds (particles,
    nonzero blocks, complexities), and one V-cycle as a LinearOperator that cuts scipy's CG
    iterations on the step's system (pinned particles held)."""
    scene = build_scene("drape", 2400, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, make_solver("direct"), dt=1 / 60)
    for _ in range(10):
        sim.step()
    step = assemble_step(scene.model, sim.state, sim.dt, "bdf2")
    solver = make_solver("mpcg", hierarchy=scene.hierarchy, bending=scene.model.bending)
    text = solver.summary(step.system)
    rows = [line.split() for line in text.splitlines()[3:]]
    assert len(rows) == solver.n_levels >= 2
    sizes = [int(r[1]) for r in rows]
    assert sizes[0] == step.system.n and sizes == sorted(sizes, reverse=True)
    assert all(int(r[2]) == 3 * int(r[1]) for r in rows)
    complexity = float(text.splitlines()[1].split("operator complexity ")[1].split(";")[0])
    assert 1.0 < complexity < 2.0  # each level about a quarter of the one above
    A = step.system.to_csr()
    b = step.rhs.reshape(-1)
    counts = {}
    for name, M in (("plain", None), ("mg", solver.aspreconditioner(step.system, step.fixed))):
        its = []
        x, info = spla.cg(A, b, rtol=1e-8, maxiter=5000, M=M,
                          callback=lambda xk, its=its: its.append(1))
        assert info == 0
        assert np.linalg.norm(A @ x - b) <= 1e-7 * np.linalg.norm(b)
        counts[name] = len(its)
    assert counts["mg"] * 5 < counts["plain"], counts


def test_the_packed_levels_as_data_match_the_hierarchy():
    """After a packed solve, the solver's levels are data: one PackedLevel per level with
    the hierarchy's sizes, the nonzero blocks the unpacked summary counts, the finest
    level's diagonal blocks those of the step's system (in sweep order), each level's rows
    pointing at the next one's; print(solver.packed) prints them as PyAMG prints ml."""
    scene = build_scene("drape", 600, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, make_solver("direct"), dt=1 / 60)
    for _ in range(15):  # onto the sphere: contacts on the finest diagonal
        sim.step()
    step = assemble_step(scene.model, sim.state, sim.dt, "bdf2")
    solver = make_solver("mpcg", tol=1e-6, hierarchy=scene.hierarchy,
                         bending=scene.model.bending)
    assert solver.levels == [] and solver.packed is None
    solver.solve(step.system, step.rhs, step.x0, step.fixed)
    levels = solver.levels
    summary = solver.summary(step.system).splitlines()[3:]
    assert len(levels) == solver.n_levels == len(summary) >= 2
    for lv, row in zip(levels, summary, strict=True):
        k, particles, unknowns, nonzero = (int(v) for v in row.split()[:4])
        assert (lv.index, lv.particles, 3 * lv.particles, lv.nonzero_blocks) == \
            (k, particles, unknowns, nonzero)
        assert lv.rows.stop - lv.rows.start == lv.particles
    fine = levels[0]
    full = step.system.full_diagonal()[fine.order]
    upper = np.stack([full[:, 0, 0], full[:, 0, 1], full[:, 0, 2], full[:, 1, 1],
                      full[:, 1, 2], full[:, 2, 2]], axis=1)
    free = fine.free > 0.0
    np.testing.assert_allclose(fine.diag6[free], upper[free], rtol=1e-9,
                               atol=1e-12 * np.abs(upper).max())
    for lv, below in itertools.pairwise(levels):
        assert lv.parents.min() >= below.rows.start and lv.parents.max() < below.rows.stop
    assert levels[-1].parents is None
    text = str(solver.packed)
    assert f"{len(levels)} levels" in text and "operator complexity" in text


def test_one_level_mpcg_is_a_symmetric_preconditioner(contact_step):
    """With a single level (no coarse grid) the cycle is forward then backward Gauss-Seidel:
    M^-1 symmetric positive definite (u . M^-1 v == v . M^-1 u, u . M^-1 u > 0), so CG
    converges on it, in fewer iterations than with Jacobi's diagonal."""
    scene, step = contact_step
    apply, pk = _packed_preconditioner(scene, step.system, step.fixed, levels=1)
    rng = np.random.default_rng(5)
    free = pk.free[: step.system.n, None]
    u, v = (pk.from_rows(rng.standard_normal((step.system.n, 3)) * free) for _ in range(2))
    assert np.isclose(np.sum(u * apply(v)), np.sum(v * apply(u)), rtol=1e-9)
    assert np.sum(u * apply(u)) > 0.0
    solver = MultigridSolver(scene.hierarchy, scene.model.bending, 1, tol=1e-6, maxiter=2000)
    res = solver.solve(step.system, step.rhs, step.x0, step.fixed)
    jacobi = PCGSolver(1e-6, maxiter=2000).solve(step.system, step.rhs, step.x0, step.fixed)
    assert res.converged and res.iterations < jacobi.iterations  # 100 against 144 here
