"""Coarse-level systems: the paper's energy-conserving coarsening and the Galerkin baseline.

Faithful (paper Sec. 5), every coarse system in the same block-symmetric form:
* diagonal blocks (mass, contact penalties, drag) move by Voronoi-area overlap, W = P^T;
* stretch/shear pair blocks: each fine face side maps onto one coarse pair with weight
  A_child / A_coarse, which is exactly 1/4 for midpoint subdivision; a fine edge maps onto the
  same coarse pair from both its faces, so the scatter runs per fine edge;
* bending pair blocks: per wing, weight (A_fine_wing / A_coarse_wing)^2, through the wing
  vertex correspondence; the stars (physics.bending: the mean-curvature stencils that make
  the plate's Poisson ratio 0) are made anew on each coarse level from its rest shape, which
  gives a smooth field the same star energy on every level. The quadratic bending Hessian is
  constant, so every level's bending is coarsened once at start-up and only scaled by the
  step's h'^2 + h' damping.
* the paper's wing correspondence sends a fine wing parallel to a coarse edge onto the far
  tip of the neighbouring coarse face, as if that face were a 180-degree copy of the parent.
  Where it is not (the sheet's half-triangle border columns, irregular garment meshes) the
  coarsened stencil no longer vanishes on the wing's affine fields, so a rigid rotation
  costs energy on the coarse level. Such wings (`inconsistent_wings`) take the coarse
  level's own hinge entries for the same stiffness instead (`repair_wing_hessians`); every
  consistent wing keeps the paper's entries.

Galerkin (baseline): A_c = P^T A P with 3x3-block P; it is symmetric with symmetric blocks
and zero-row-sum internal part, so it is stored in block-symmetric form too (pairs = its
off-diagonal block pattern, which is wider than the mesh's), and the same smoothers run on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import get_num_threads, njit, prange

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import WING_PAIR_LOCAL, MeshLevel
from cloth_mg_ros.physics.bending import (
    WING_PAIR_VERTS,
    BendingTerms,
    bending_terms,
    outer_pairs,
    pair_bending,
    wing_weights,
)
from cloth_mg_ros.physics.system import BlockSystem
from cloth_mg_ros.solvers.transfer_ops import restrict_blocks, restrict_blocks_split

STRETCH_WEIGHT = 0.25  # A_child / A_coarse under 1-to-4 midpoint subdivision
# Levels with at least this many fine vertices are coarsened on every thread; below, a
# parallel region's start costs more than it saves.
SPLIT_VERTICES = 8000
# A coarsened wing stencil whose response to the wing's affine fields, relative to
# |stencil| |field|, exceeds this does not annihilate them: roundoff gives ~1e-15, a
# wrongly mapped fine wing 1e-2 and more on the sheets and garments.
AFFINE_RESIDUAL_TOL = 1e-8


@njit(cache=True, nogil=True)
def _scatter_range(src, dst, weight, offd, c, bend, out, lo, hi):
    """`scatter_stretch_blocks` onto the coarse pairs lo..hi only (the fine edges in order)."""
    for k in range(src.shape[0]):
        d = dst[k]
        if d < lo or d >= hi:
            continue
        s = src[k]
        for a in range(3):
            for b in range(3):
                out[d, a, b] += weight * offd[s, a, b]
            out[d, a, a] -= weight * c * bend[s]


@njit(cache=True, nogil=True)
def scatter_stretch_blocks(src, dst, weight, offd, c, bend, out):
    """out[dst[k]] += weight * (offd[src[k]] - c bend[src[k]] I) for every fine edge k: the
    faithful stretch/shear coarsening of a level whose pair blocks offd (m, 3, 3) hold c times
    its bending (m,) on their diagonals (out not cleared)."""
    _scatter_range(src, dst, weight, offd, c, bend, out, 0, out.shape[0])


@njit(cache=True, nogil=True, parallel=True)
def scatter_stretch_blocks_split(src, dst, weight, offd, c, bend, out, parts):
    """`scatter_stretch_blocks` on `parts` threads, each taking the coarse pairs of its own
    range and the fine edges in order: every coarse block gets its terms in the order of k,
    the same numbers on any number of threads (a gather per coarse pair read the fine blocks
    out of order and was slower)."""
    m = out.shape[0]
    for part in prange(parts):
        _scatter_range(src, dst, weight, offd, c, bend, out, part * m // parts,
                       (part + 1) * m // parts)


@njit(cache=True, nogil=True)
def add_bending(offd, c, bend):
    """offd[p] += c bend[p] I for every pair p."""
    for p in range(offd.shape[0]):
        for a in range(3):
            offd[p, a, a] += c * bend[p]


def _slot_table() -> np.ndarray:
    table = -np.ones((4, 4), dtype=np.int64)
    for k, (a, b) in enumerate(WING_PAIR_LOCAL):
        table[a, b] = table[b, a] = k
    return table


def coarsen_wing_hessians(hier: MeshHierarchy, level: int, wing_hess: np.ndarray) -> np.ndarray:
    """Bending entries (w_c, 6) of level+1's wings from level's (w_f, 6), paper Sec. 5.3."""
    tr = hier.transfers[level]
    coarse = hier.levels[level + 1]
    valid = np.flatnonzero(tr.wing_map >= 0)
    target = tr.wing_map[valid]
    fine_to_coarse = tr.wing_vertex_map[valid]  # (k, 4) coarse vertex ids
    coarse_wing = coarse.wings[target]  # (k, 4)
    match = fine_to_coarse[:, :, None] == coarse_wing[:, None, :]
    if not np.all(match.sum(axis=2) == 1):
        raise ValueError(f"level {level}: a fine wing does not map onto its coarse wing")
    pos = np.argmax(match, axis=2)  # (k, 4) local index in the coarse wing
    slots = _slot_table()[pos[:, WING_PAIR_LOCAL[:, 0]], pos[:, WING_PAIR_LOCAL[:, 1]]]
    weight = tr.wing_area_ratio[valid] ** 2
    out = np.zeros((coarse.n_wings, 6))
    np.add.at(out, (np.repeat(target, 6), slots.ravel()),
              (weight[:, None] * wing_hess[valid]).ravel())
    return out


def unfolded_wings(rest: np.ndarray, wings: np.ndarray) -> np.ndarray:
    """Each wing [a, b, c, d] laid flat about its edge a-b, (w, 4, 2) m: a at the origin, b
    on +x, tips c above and d below at their rest distances from the edge. The hinge weights
    are made from the faces' own angles, so a curved rest wing counts as this flat one."""
    p = rest[wings]
    a = p[:, 0]
    edge = p[:, 1] - a
    length = np.linalg.norm(edge, axis=1)
    x_hat = edge / length[:, None]
    out = np.zeros((len(wings), 4, 2))
    out[:, 1, 0] = length
    for m, sign in ((2, 1.0), (3, -1.0)):
        r = p[:, m] - a
        t = np.einsum("ij,ij->i", r, x_hat)
        out[:, m, 0] = t
        out[:, m, 1] = sign * np.linalg.norm(r - t[:, None] * x_hat, axis=1)
    return out


def wing_stencil_matrices(wing_hess: np.ndarray) -> np.ndarray:
    """The full 4x4 Hessians (w, 4, 4) of wing entries (w, 6): off-diagonals as stored,
    diagonals from the zero row sums."""
    full = np.zeros((len(wing_hess), 4, 4))
    full[:, WING_PAIR_VERTS[:, 0], WING_PAIR_VERTS[:, 1]] = wing_hess
    full[:, WING_PAIR_VERTS[:, 1], WING_PAIR_VERTS[:, 0]] = wing_hess
    full[:, np.arange(4), np.arange(4)] = -full.sum(axis=2)
    return full


def inconsistent_wings(rest: np.ndarray, wings: np.ndarray, wing_hess: np.ndarray,
                       tol: float = AFFINE_RESIDUAL_TOL) -> np.ndarray:
    """(w,) bool: the wings whose stencils (w, 6) do not annihilate the affine fields of
    the flat-laid wing (constants vanish by the zero row sums; the linear fields are tested)."""
    u = unfolded_wings(rest, wings)
    u -= u.mean(axis=1, keepdims=True)
    full = wing_stencil_matrices(wing_hess)
    resp = np.linalg.norm(np.einsum("wmn,wnk->wmk", full, u), axis=(1, 2))
    scale = np.linalg.norm(full, axis=(1, 2)) * np.linalg.norm(u, axis=(1, 2))
    return resp > tol * scale


def repair_wing_hessians(coarse: MeshLevel, wing_hess: np.ndarray,
                         own: np.ndarray | None) -> np.ndarray:
    """wing_hess (w, 6) with its inconsistent wings replaced.

    own: the coarse level's own hinge entries for the same stiffness (with its free-edge
    term), which the consistent wings equal in a uniform interior (test_multigrid), so the
    replacement is the operator the paper's mapping approximates; it keeps a smooth field's
    coarse energy within a few per cent of the fine one where the mapped stencil gave up to
    4 times it. None (hinge entries given without a stiffness): the stencil is projected
    onto the wing's only affine-free direction, the hinge weights k, keeping k^T K k.
    """
    bad = inconsistent_wings(coarse.rest, coarse.wings, wing_hess)
    if not bad.any():
        return wing_hess
    out = wing_hess.copy()
    if own is not None:
        out[bad] = own[bad]
        return out
    k = wing_weights(coarse.rest, coarse.wings[bad])
    full = wing_stencil_matrices(wing_hess[bad])
    size = np.einsum("wm,wmn,wn->w", k, full, k) / np.einsum("wm,wm->w", k, k) ** 2
    out[bad] = size[:, None] * outer_pairs(k)
    return out


def usable_levels(hier: MeshHierarchy, levels: int) -> int:
    """How many of `hier`'s levels a coarsening of ``levels`` levels uses: ``levels``, or all
    of the hierarchy's where it asks for more (on purpose: a garment's coarser rungs run on
    the shallower hierarchy below them with the options' one number, sim.detail).
    ClothInputError for a levels that is not an integer >= 1."""
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or levels < 1:
        raise ClothInputError(f"levels must be an integer >= 1, got {levels!r}")
    return min(int(levels), len(hier.levels))


@dataclass
class FaithfulLevelMaps:
    """What coarsening level l onto l+1 needs: parents (n_f, 2); fine edge pair indices and
    the coarse pair each maps onto, (e_f,) each; the coarse level's pairs and bending (its
    hinges' entries, (w_c, 6) N/m, then summed per pair with its stars, (m_c,) N/m)."""

    parents: np.ndarray
    edge_src: np.ndarray
    edge_dst: np.ndarray
    coarse_pairs: np.ndarray
    coarse_bend: np.ndarray
    coarse_wing_hess: np.ndarray


class FaithfulCoarsening:
    """Builds the coarse systems of the first ``levels`` hierarchy levels (all of them where
    it has fewer: `usable_levels`), faithfully.

    bending: the finest level's bending stencils (the model's ``bending``), or its hinge
    entries alone, (w_0, 6) N/m, for a model without stars.
    """

    name = "faithful"

    def __init__(self, hier: MeshHierarchy, bending: BendingTerms | np.ndarray, levels: int):
        self.levels = usable_levels(hier, levels)
        fine0 = hier.levels[0]
        if isinstance(bending, BendingTerms):
            q, bend = bending.wing_hess, bending.bend
            self.fine_bend = bending.pair_values(fine0)
        else:
            q, bend = np.asarray(bending), None
            self.fine_bend = pair_bending(q, fine0.wing_pairs, fine0.n_pairs)
        self.maps: list[FaithfulLevelMaps] = []
        for lvl in range(self.levels - 1):
            fine, coarse, tr = hier.levels[lvl], hier.levels[lvl + 1], hier.transfers[lvl]
            own = bending_terms(coarse, bend) if bend is not None else None
            q = repair_wing_hessians(coarse, coarsen_wing_hessians(hier, lvl, q),
                                     None if own is None else own.wing_hess)
            coarse_bend = pair_bending(q, coarse.wing_pairs, coarse.n_pairs)
            if own is not None:
                coarse_bend += own.stars.pair_values(coarse.n_pairs)
            src = fine.edge_pairs
            dst = tr.pair_map[src]
            keep = dst >= 0
            self.maps.append(FaithfulLevelMaps(
                np.ascontiguousarray(tr.parents), np.ascontiguousarray(src[keep]),
                np.ascontiguousarray(dst[keep]), np.ascontiguousarray(coarse.pairs),
                coarse_bend, q))

    def coarsen(self, fine: BlockSystem) -> list[BlockSystem]:
        """[fine, level 1, ...]: the coarse systems of one step's fine system."""
        if fine.hess_scale is None:
            raise ValueError("faithful coarsening needs a system built from element Hessians "
                             "(BlockSystem.hess_scale)")
        c = fine.hess_scale
        # The mesh's pairs come first; pairs beyond them (cloth-cloth contact springs) stay on
        # the fine level. Each level's stretch part (its pair blocks less c times its bending)
        # is scattered onto the next without a copy of the fine level's blocks.
        systems = [fine]
        diag, offd, bend = fine.diag, fine.offd, self.fine_bend
        for mp in self.maps:
            n_c = int(mp.parents.max()) + 1
            diag_c = np.empty((n_c, 3, 3))
            offd_c = np.zeros((len(mp.coarse_pairs), 3, 3))
            parts = get_num_threads() if len(mp.parents) >= SPLIT_VERTICES else 1
            if parts > 1:
                restrict_blocks_split(mp.parents, diag, diag_c, parts)
                scatter_stretch_blocks_split(mp.edge_src, mp.edge_dst, STRETCH_WEIGHT, offd, c,
                                             bend, offd_c, parts)
            else:
                restrict_blocks(mp.parents, diag, diag_c)
                scatter_stretch_blocks(mp.edge_src, mp.edge_dst, STRETCH_WEIGHT, offd, c,
                                       bend, offd_c)
            add_bending(offd_c, c, mp.coarse_bend)
            systems.append(BlockSystem(diag_c, mp.coarse_pairs, offd_c, c))
            diag, offd, bend = diag_c, offd_c, mp.coarse_bend
        return systems


def block_system_from_sparse(A: sp.spmatrix, n: int) -> BlockSystem:
    """A symmetric (3n, 3n) matrix with symmetric 3x3 blocks in block-symmetric form:
    G_ij = A_ij for i < j, B_i = A_ii + sum_j A_ij."""
    bsr = sp.bsr_matrix(A, blocksize=(3, 3))
    bsr.sort_indices()
    rows = np.repeat(np.arange(n), np.diff(bsr.indptr))
    cols = bsr.indices
    blocks = bsr.data
    upper = cols > rows
    pairs = np.stack([rows[upper], cols[upper]], axis=1).astype(np.int64)
    offd = np.ascontiguousarray(blocks[upper])
    diag = np.zeros((n, 3, 3))
    np.add.at(diag, rows, blocks)  # B_i = sum over the whole block row
    return BlockSystem(diag, np.ascontiguousarray(pairs), offd, None)


class GalerkinCoarsening:
    """Coarse systems by the Galerkin product R A P (the standard multigrid baseline) of the
    first ``levels`` hierarchy levels (all of them where it has fewer: `usable_levels`)."""

    name = "galerkin"

    def __init__(self, hier: MeshHierarchy, levels: int):
        self.levels = usable_levels(hier, levels)
        self.P3 = [sp.kron(hier.transfers[lvl].prolongation(), sp.identity(3), format="csr")
                   for lvl in range(self.levels - 1)]

    def coarsen(self, fine: BlockSystem) -> list[BlockSystem]:
        systems = [fine]
        A = fine.to_csr()
        for P in self.P3:
            A = (P.T @ A @ P).tocsr()
            systems.append(block_system_from_sparse(A, P.shape[1] // 3))
        return systems
