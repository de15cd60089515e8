"""Index maps between a fine level and the next coarser one (built by `subdivide`).

The maps are fixed at start-up; per-step coarsening is a weighted scatter through them
(paper Sec. 5): diagonal blocks through `vertex_area_overlap`, stretch/shear pair blocks per
fine face side through `face_pair_map` weighted by `face_area_ratio`, bending pair blocks per
fine wing through `wing_pair_map` weighted by `wing_area_ratio` squared.

Scatter per element (face side, wing pair), not per fine pair: a fine pair that is a side of a
face and also a pair of a wing can map to different coarse pairs in the two roles (the
cross pairs of a wing around an interior fine edge parallel to a coarse edge, Fig. 3b).
`pair_map` is a per-pair summary for diagnostics and for blocks that only exist per pair.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from cloth_mg_ros.frozen_arrays import FrozenArrays, frozen

__all__ = ['LevelTransfer']


@dataclass(eq=False)
class LevelTransfer(FrozenArrays):
    """Maps from fine level l (n_f vertices) to coarse level l+1 (n_c vertices).

    Fine vertices 0..n_c-1 are the coarse vertices; fine vertex n_c + e is the midpoint of
    coarse edge e. Fine face 4T + c is child c of coarse face T (c = 0, 1, 2 corners at the
    parent's local vertex c, c = 3 centre).

    Attributes:
        n_fine, n_coarse: vertex counts.
        parents: (n_f, 2) int64, coarse parents of each fine vertex: (i, i) for a copy of coarse
            vertex i, the coarse edge's ends (i < j) for a midpoint.
        children: (t_c, 4) int64, fine faces of each coarse face [corner 0, corner 1,
            corner 2, centre] (= 4T + [0, 1, 2, 3]).
        child_vertex_map: (t_c, 4, 3) int64, coarse vertex that the child's local vertex k
            (in the child's own faces[] order) maps to (see `subdivision` module docstring).
        face_pair_map: (t_f, 3) int64, coarse pair index that each fine face side maps onto;
            a fine edge maps to the same coarse pair from both of its faces.
        wing_map: (w_f,) int64, coarse wing each fine wing maps onto; -1 for the fine wings
            across interior edges parallel to a coarse boundary edge (no coarse wing there).
            Each interior coarse wing receives exactly four fine wings.
        wing_vertex_map: (w_f, 4) int64, coarse vertex of each fine wing vertex [a, b, c, d];
            rows of -1 where wing_map is -1. The mapped (a, b) is the coarse wing's edge (in
            either order) and the mapped {c, d} its tips.
        wing_pair_map: (w_f, 6) int64, coarse pair index of the fine wing's six pairs (order
            (a,b),(a,c),(a,d),(b,c),(b,d),(c,d)); rows of -1 where wing_map is -1.
        pair_map: (m_f,) int64, coarse pair of each fine pair: edges through face_pair_map,
            pure wing-tip pairs through their wing's (c, d) entry, -1 where that wing maps to
            nothing. Where a fine pair is both an edge and a wing-tip pair (possible only on
            unusual meshes) the edge mapping wins; where two wings share a tip pair, the
            last wing wins.
        face_area_ratio: (t_f,) float64, A_child / A_parent (exactly 1/4 up to rounding).
        wing_area_ratio: (w_f,) float64, area of the fine wing's two faces over that of its
            coarse wing's two faces (1/4); 0 where wing_map is -1.
        vertex_area_overlap: (n_c, n_f) scipy.sparse CSR, W[i, j] = fraction of fine vertex
            j's lumped area lying in coarse vertex i's region; W @ fine.vertex_areas equals
            coarse.vertex_areas. With one-third lumping on a midpoint subdivision, W = P^T
            exactly: a coarse vertex keeps its own fine copy (weight 1) and each midpoint gives
            1/2 to each parent. Proof: in a coarse face T (area A) the fine copy of corner p has
            A/12 from its corner child; midpoint m_pq has A/4 from T (a third of each of its
            three children in T: two corners and the centre, each A/4); half of that, A/8,
            from each of p's two midpoints in T, gives p A/12 + 2 A/8 = A/3, its one-third
            share of T. This holds face by face, for any triangle shapes, so the halves
            conserve exactly (for equilateral meshes it is also the Voronoi overlap of the
            paper, Sec. 6).
    """

    n_fine: int
    n_coarse: int
    parents: np.ndarray
    children: np.ndarray
    child_vertex_map: np.ndarray
    face_pair_map: np.ndarray
    wing_map: np.ndarray
    wing_vertex_map: np.ndarray
    wing_pair_map: np.ndarray
    pair_map: np.ndarray
    face_area_ratio: np.ndarray
    wing_area_ratio: np.ndarray
    vertex_area_overlap: sp.csr_matrix = field(init=False, repr=False)
    _prolongation: sp.csr_matrix = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ('parents', 'children', 'child_vertex_map', 'face_pair_map', 'wing_map',
                     'wing_vertex_map', 'wing_pair_map', 'pair_map', 'face_area_ratio',
                     'wing_area_ratio'):
            frozen(getattr(self, name))
        # Row r of P: 1 at the copied vertex, or 1/2 at each end of the coarse edge; the
        # parents table gives both at once (a copy's two equal entries are summed by CSR).
        rows = np.repeat(np.arange(self.n_fine), 2)
        data = np.full(2 * self.n_fine, 0.5)
        p = sp.csr_matrix((data, (rows, self.parents.ravel())),
                          shape=(self.n_fine, self.n_coarse))
        p.sum_duplicates()
        p.sort_indices()
        self._prolongation = p
        self.vertex_area_overlap = p.T.tocsr()

    def prolongation(self) -> sp.csr_matrix:
        """Scalar linear interpolation P, CSR (n_f, n_c): a fine copy of coarse vertex i takes
        its value, a midpoint the mean of its two parents. Rows sum to 1. Expand to 3x3 blocks
        with `scipy.sparse.kron(P, eye(3))`. Returns a copy (safe to modify)."""
        return self._prolongation.copy()

    def restriction(self) -> sp.csr_matrix:
        """Full-weighting restriction R = P^T, CSR (n_c, n_f): a coarse vertex gets its own
        residual plus half of each adjacent midpoint's."""
        return self._prolongation.T.tocsr()
