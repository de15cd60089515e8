"""Curvature-based bending with a constant Hessian, for a plate of Poisson ratio 0.

A woven or knitted fabric bends along one direction without curling across it: its bending
energy per area is (B / 2)(kappa_1^2 + kappa_2^2), B the flexural rigidity (N m) measured
on a narrow strip (the cantilever test). Two families of four-vertex stencils carry it, each
a weight vector k (4,) with sum k = 0 and sum k_m u_m = 0 over the flat rest positions
u_m, so s = sum_m k_m x_m vanishes for every rigid or in-plane affine motion and the energy
w |s|^2 has the constant Hessian 2 w k k^T times the 3x3 identity (block-symmetric, zero
row sums: it fits the paper's system and never needs re-assembly):

* hinges (Bergou et al. 2006): every interior edge (a, b) with wing tips c, d and cotangent
  weights; for a hinge folded by a small angle theta, |s| = |e| theta.
  E_e = (3/4) bend / (A0 + A1) |s|^2 / 2.
* stars: an interior vertex v and three of its neighbours (a, b, c) that are pairwise
  linked in the mesh's pair pattern (an edge or a wing-tip pair) and surround v; k = (-1,
  lambda) with lambda the barycentric coordinates of v in (a, b, c), so s = tr(K S) / 2 with
  S = sum lambda_m d_m d_m^T (d_m = u_m - u_v): for the near-isotropic S of a star,
  tr K = 4 s / tr S, the mean curvature. Each vertex's stars share
  E_v = (bend / 8) A_v (tr K)^2.

Why two families: on the near-equilateral meshes the hierarchy builds, every hinge stencil
measures kappa_across - kappa_along / 3, and any sum of hinge energies is the plate energy
(kappa_1^2 + kappa_2^2 - 2/3 kappa_1 kappa_2): a Poisson ratio of -1/3 that no choice of
hinge weights removes. A strip in the cantilever test then bends as a plate of rigidity
B (1 - nu^2) when narrow and B when wide: measured, 6-10 % softer than the exact elastica
on 12-25 mm strips, 5-8 % stiffer on 100 mm ones. Three quarters of the hinge energy plus
the stars' (tr K)^2 is (kappa_1^2 + kappa_2^2) for every curvature tensor: Poisson ratio 0
(test_physics checks cylinder, sphere and saddle).

Free edges: a boundary vertex has no star. The curvature along the edge, which a free edge
keeps in full, gets the missing (bend / 8) A_v kappa_t^2 from the vertex's hinge that runs
most nearly across the edge (its stencil's weight raised), so a strip's border is as stiff
as its middle; the part of the border energy this misses shrinks with the mesh spacing.
An interior vertex where no three linked neighbours surround it (valence 7 or more) has no
star either: the hinges at it keep their full weight there (half a hinge per end), the
hinge model's own (tr K)^2 in place of the star's, so no vertex is left soft.

Curved rest shapes (garments): the fabric's rest is flat, but the stencils' weights come
from the curved mesh as built, each stencil treated as flat: a hinge's cotangents from its
two faces' own angles (the wing laid flat about its edge), a star's barycentric weights from
its centre projected onto the plane of its three neighbours. The quadratic energy then
vanishes on the affine fields of each flat-laid stencil, not on a rigid motion of the curved
mesh, which costs a little bending energy (the physics is unchanged by this note).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from cloth_mg_ros.mesh.topology import MeshLevel

# Pairs of the wing vertices (a, b, c, d) in the mesh's wing_pairs order.
WING_PAIR_VERTS = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
HINGE_SHARE = 0.75  # of the hinge energy, with the stars' (tr K)^2 term: Poisson ratio 0
STAR_SHARE = 0.125  # bend / 8 (tr K)^2 per area
MIN_BARYCENTRIC = 0.05  # a star's centre lies inside its triangle, not on an edge


def _cot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cotangent of the angle between row vectors u and v, (k, 3) -> (k,)."""
    cross = np.linalg.norm(np.cross(u, v), axis=1)
    return np.einsum("ij,ij->i", u, v) / cross


def wing_weights(rest: np.ndarray, wings: np.ndarray) -> np.ndarray:
    """Hinge weights k, (w, 4), for wings [a, b, c, d] (edge a-b, tips c and d).

    k_a = -(cot beta_c + cot beta_d), k_b = -(cot alpha_c + cot alpha_d),
    k_c = cot alpha_c + cot beta_c, k_d = cot alpha_d + cot beta_d, where alpha_* is the
    rest angle at a and beta_* the angle at b in the face of tip c or d. Dimensionless.
    """
    pa, pb, pc, pd = (rest[wings[:, m]] for m in range(4))
    alpha_c, beta_c = _cot(pb - pa, pc - pa), _cot(pa - pb, pc - pb)
    alpha_d, beta_d = _cot(pb - pa, pd - pa), _cot(pa - pb, pd - pb)
    return np.stack(
        [-(beta_c + beta_d), -(alpha_c + alpha_d), alpha_c + beta_c, alpha_d + beta_d], axis=1
    )


def outer_pairs(k: np.ndarray) -> np.ndarray:
    """k_m k_n for the six vertex pairs of a 4-vertex stencil, (s, 4) -> (s, 6)."""
    return k[:, WING_PAIR_VERTS[:, 0]] * k[:, WING_PAIR_VERTS[:, 1]]


def _border_hinges(rest: np.ndarray, wings: np.ndarray, k: np.ndarray, edges: np.ndarray,
                   edge_face_count: np.ndarray, vertex_areas: np.ndarray, bend: float
                   ) -> np.ndarray:
    """Extra hinge Hessian entries (w, 6): at each boundary vertex, the hinge most nearly
    across the border gets (bend / 8) A_v kappa_t^2 (module docstring)."""
    n = len(rest)
    border = edges[edge_face_count == 1]
    # A border vertex's tangent runs from one of its two border neighbours to the other.
    ends = np.concatenate([border[:, 0], border[:, 1]])
    others = np.concatenate([border[:, 1], border[:, 0]])
    order = np.argsort(ends, kind="stable")
    ends, others = ends[order], others[order]
    count = np.bincount(ends, minlength=n)
    first = np.searchsorted(ends, np.arange(n))
    on_border = count == 2
    tangent = np.zeros((n, 3))
    idx = np.flatnonzero(on_border)
    tangent[idx] = rest[others[first[idx] + 1]] - rest[others[first[idx]]]
    norm = np.linalg.norm(tangent[idx], axis=1)
    on_border[idx[norm <= 0.0]] = False
    tangent[idx[norm > 0.0]] /= norm[norm > 0.0, None]
    extra = np.zeros((len(wings), 6))
    if not on_border.any():
        return extra
    # Candidate (wing, border vertex) pairs: the wing's edge ends at the vertex.
    cand_w = np.concatenate([np.flatnonzero(on_border[wings[:, 0]]),
                             np.flatnonzero(on_border[wings[:, 1]])])
    cand_v = np.concatenate([wings[on_border[wings[:, 0]], 0], wings[on_border[wings[:, 1]], 1]])
    if len(cand_w) == 0:
        return extra
    t = tangent[cand_v]
    edge_dir = rest[wings[cand_w, 1]] - rest[wings[cand_w, 0]]
    along = np.abs(np.einsum("ij,ij->i", edge_dir, t)) / np.linalg.norm(edge_dir, axis=1)
    order = np.lexsort((along, cand_v))  # per vertex, the most crossing hinge first
    first = np.ones(len(order), dtype=bool)
    first[1:] = cand_v[order[1:]] != cand_v[order[:-1]]
    pick_w, pick_v = cand_w[order[first]], cand_v[order[first]]
    # tS t = sum_m k_m (d_m . t)^2: s = kappa_t tSt / 2 for curvature kappa_t along t.
    dm = rest[wings[pick_w]] - rest[pick_v][:, None, :]
    tst = np.einsum("wm,wm->w", k[pick_w], np.einsum("wmi,wi->wm", dm, tangent[pick_v]) ** 2)
    # A hinge that measures the along-edge curvature only faintly would need a huge weight:
    # leave such a vertex to the hinges it has (none seen on the sheets, strips and garments).
    ok = np.abs(tst) > 0.0125 * np.einsum("wmi,wmi->w", dm, dm)
    scale = bend * vertex_areas[pick_v[ok]] / tst[ok] ** 2  # 2 w, w = bend A / (2 tSt^2)
    np.add.at(extra, pick_w[ok], scale[:, None] * outer_pairs(k[pick_w[ok]]))
    return extra


def wing_hessians(
    rest: np.ndarray, wings: np.ndarray, wing_faces: np.ndarray, face_areas: np.ndarray,
    bend: float, border: tuple | None = None, starless: np.ndarray | None = None,
) -> np.ndarray:
    """Scalar Hessian entries Q_mn of every hinge for its six vertex pairs, (w, 6), N/m.

    border: (edges, edge_face_count, vertex_areas) of the mesh to add the free-edge term;
    starless: (n,) bool, interior vertices without a star, whose share of each hinge at
    them (half a hinge per end) keeps its full weight (module docstring); None: hinges at
    HINGE_SHARE only. Only off-diagonal entries are kept: the diagonal follows from the
    zero row sums.
    """
    k = wing_weights(rest, wings)
    area = face_areas[wing_faces[:, 0]] + face_areas[wing_faces[:, 1]]
    share = np.full(len(wings), HINGE_SHARE)
    if starless is not None:
        share += 0.5 * (1.0 - HINGE_SHARE) * (starless[wings[:, 0]].astype(float)
                                              + starless[wings[:, 1]])
    out = (share * bend / area)[:, None] * outer_pairs(k)
    if border is not None:
        out += _border_hinges(rest, wings, k, *border, bend)
    return out


@njit(cache=True, nogil=True)
def _find_stars(rest, nbr_ptr, nbr, pair_keys, interior, min_bary, out_verts, out_bary):
    """Fill out_verts (cap, 4) [v, a, b, c] and out_bary (cap, 3) with every star; returns
    the count. pair_keys: sorted i * n + j (i < j) of the mesh's pairs."""
    n = rest.shape[0]
    count = 0
    for v in range(n):
        if not interior[v]:
            continue
        lo, hi = nbr_ptr[v], nbr_ptr[v + 1]
        for ia in range(lo, hi):
            a = nbr[ia]
            for ib in range(ia + 1, hi):
                b = nbr[ib]
                if not _linked(pair_keys, a, b, n):
                    continue
                for ic in range(ib + 1, hi):
                    c = nbr[ic]
                    if not (_linked(pair_keys, a, c, n) and _linked(pair_keys, b, c, n)):
                        continue
                    # Barycentric coordinates of v projected onto the plane of (a, b, c).
                    e1 = rest[a] - rest[c]
                    e2 = rest[b] - rest[c]
                    r = rest[v] - rest[c]
                    d11 = e1 @ e1
                    d12 = e1 @ e2
                    d22 = e2 @ e2
                    r1 = r @ e1
                    r2 = r @ e2
                    det = d11 * d22 - d12 * d12
                    if det <= 1e-30 * d11 * d22:
                        continue
                    la = (d22 * r1 - d12 * r2) / det
                    lb = (d11 * r2 - d12 * r1) / det
                    lc = 1.0 - la - lb
                    if la > min_bary and lb > min_bary and lc > min_bary:
                        out_verts[count, 0] = v
                        out_verts[count, 1] = a
                        out_verts[count, 2] = b
                        out_verts[count, 3] = c
                        out_bary[count, 0] = la
                        out_bary[count, 1] = lb
                        out_bary[count, 2] = lc
                        count += 1
    return count


@njit(cache=True, nogil=True)
def _linked(pair_keys, i, j, n):
    key = min(i, j) * n + max(i, j)
    k = np.searchsorted(pair_keys, key)
    return k < pair_keys.shape[0] and pair_keys[k] == key


@dataclass(frozen=True)
class Stars:
    """The star stencils of a mesh: verts (s, 4) [v, a, b, c]; hess (s, 6) Hessian entries
    (N/m) for the pairs (v,a), (v,b), (v,c), (a,b), (a,c), (b,c); pairs (s, 6) their
    mesh pair indices."""

    verts: np.ndarray
    hess: np.ndarray
    pairs: np.ndarray

    def pair_values(self, n_pairs: int) -> np.ndarray:
        """The stars' Hessian entries summed per mesh pair, (n_pairs,) N/m."""
        out = np.zeros(n_pairs)
        np.add.at(out, self.pairs.ravel(), self.hess.ravel())
        return out


def star_hessians(mesh: MeshLevel, bend: float) -> Stars:
    """The stars of ``mesh`` with their Hessian entries for
    bending stiffness ``bend`` N m (module docstring)."""
    n = mesh.rest.shape[0]
    e = mesh.edges
    ends = np.concatenate([e[:, 0], e[:, 1]])
    others = np.concatenate([e[:, 1], e[:, 0]])
    order = np.argsort(ends, kind="stable")
    nbr = np.ascontiguousarray(others[order])
    nbr_ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(nbr_ptr, ends + 1, 1)
    nbr_ptr = np.cumsum(nbr_ptr)
    valence = np.diff(nbr_ptr)
    cap = int(np.sum(valence * (valence - 1) * (valence - 2) // 6))
    verts = np.empty((max(cap, 1), 4), dtype=np.int64)
    bary = np.empty((max(cap, 1), 3))
    keys = np.ascontiguousarray(mesh.pairs[:, 0] * n + mesh.pairs[:, 1])
    interior = np.ascontiguousarray(~mesh.boundary_vertices)
    count = _find_stars(np.ascontiguousarray(mesh.rest, dtype=np.float64), nbr_ptr, nbr, keys,
                        interior, MIN_BARYCENTRIC, verts, bary)
    verts, bary = verts[:count], bary[:count]
    v = verts[:, 0]
    d = mesh.rest[verts[:, 1:]] - mesh.rest[v][:, None, :]
    tr_s = np.einsum("sm,sm->s", bary, np.einsum("smi,smi->sm", d, d))
    stars_at = np.bincount(v, minlength=n)
    # E = w s^2 with w = STAR_SHARE bend A_v 16 / (c_v trS^2) (tr K = 4 s / trS, the vertex's
    # c_v stars averaged); Hessian entries 2 w k_m k_n.
    scale = 32.0 * STAR_SHARE * bend * mesh.vertex_areas[v] / (stars_at[v] * tr_s ** 2)
    k = np.concatenate([-np.ones((count, 1)), bary], axis=1)
    pairs = mesh.pair_index(verts[:, WING_PAIR_VERTS[:, 0]], verts[:, WING_PAIR_VERTS[:, 1]])
    return Stars(verts, scale[:, None] * outer_pairs(k), pairs)


@dataclass(frozen=True)
class BendingTerms:
    """A mesh's constant bending Hessian as stencils: wing_hess (w, 6) the hinges' entries
    (N/m, in the mesh's wing_pairs order), stars their own, bend the stiffness (N m) they
    were made for (coarse levels re-make their stars with it)."""

    wing_hess: np.ndarray
    stars: Stars
    bend: float

    def pair_values(self, mesh: MeshLevel) -> np.ndarray:
        """All entries summed per mesh pair, (m,) N/m."""
        return pair_bending(self.wing_hess, mesh.wing_pairs, mesh.n_pairs) + \
            self.stars.pair_values(mesh.n_pairs)


def bending_terms(mesh: MeshLevel, bend: float) -> BendingTerms:
    """Hinges (with the free-edge term) and stars of ``mesh`` for stiffness ``bend`` N m."""
    stars = star_hessians(mesh, bend)
    starless = np.bincount(stars.verts[:, 0], minlength=len(mesh.rest)) == 0
    starless &= ~mesh.boundary_vertices
    wing = wing_hessians(mesh.rest, mesh.wings, mesh.wing_faces, mesh.face_areas, bend,
                         border=(mesh.edges, mesh.edge_face_count, mesh.vertex_areas),
                         starless=starless)
    return BendingTerms(wing, stars, float(bend))


def pair_bending(wing_hess: np.ndarray, wing_pairs: np.ndarray, n_pairs: int) -> np.ndarray:
    """Sum the wing Hessian entries onto the mesh pairs: (m,) scalar blocks, N/m."""
    out = np.zeros(n_pairs)
    np.add.at(out, wing_pairs.ravel(), wing_hess.ravel())
    return out


@njit(cache=True, nogil=True)
def _normal_products(x, z, verts, hess, hinge, out):
    """Add to out (n, 3), for each four-vertex stencil verts (s, 4) with Hessian entries hess
    (s, 6) (pairs WING_PAIR_VERTS), its product with z (n, 3), sum_b Q_ab (z_b - z_a) at its
    vertex a, projected on the stencil's normal nn: nn (nn . it). hinge: hinges [a, b, c, d]
    (nn along (x_b - x_a) x (x_d - x_c), the mean of the faces' normals), else stars
    [v, a, b, c] (nn normal to the plane of a, b, c). Serial: stencils share vertices; the
    projection of the product onto nn is nn times sum_b Q_ab (z_b - z_a) . nn, so each
    vertex's z . nn is all the stencil needs."""
    for s in range(verts.shape[0]):
        i0, i1, i2, i3 = verts[s, 0], verts[s, 1], verts[s, 2], verts[s, 3]
        if hinge:
            p, q, r, u = i0, i1, i2, i3
        else:
            p, q, r, u = i1, i2, i1, i3
        e0 = x[q, 0] - x[p, 0]
        e1 = x[q, 1] - x[p, 1]
        e2 = x[q, 2] - x[p, 2]
        f0 = x[u, 0] - x[r, 0]
        f1 = x[u, 1] - x[r, 1]
        f2 = x[u, 2] - x[r, 2]
        n0 = e1 * f2 - e2 * f1
        n1 = e2 * f0 - e0 * f2
        n2 = e0 * f1 - e1 * f0
        size = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if size == 0.0:
            continue
        n0 /= size
        n1 /= size
        n2 /= size
        zn0 = z[i0, 0] * n0 + z[i0, 1] * n1 + z[i0, 2] * n2
        zn1 = z[i1, 0] * n0 + z[i1, 1] * n1 + z[i1, 2] * n2
        zn2 = z[i2, 0] * n0 + z[i2, 1] * n1 + z[i2, 2] * n2
        zn3 = z[i3, 0] * n0 + z[i3, 1] * n1 + z[i3, 2] * n2
        # pairs (0,1), (0,2), (0,3), (1,2), (1,3), (2,3)
        d01 = hess[s, 0] * (zn1 - zn0)
        d02 = hess[s, 1] * (zn2 - zn0)
        d03 = hess[s, 2] * (zn3 - zn0)
        d12 = hess[s, 3] * (zn2 - zn1)
        d13 = hess[s, 4] * (zn3 - zn1)
        d23 = hess[s, 5] * (zn3 - zn2)
        t0 = d01 + d02 + d03
        t1 = -d01 + d12 + d13
        t2 = -d02 - d12 + d23
        t3 = -d03 - d13 - d23
        for i, tv in ((i0, t0), (i1, t1), (i2, t2), (i3, t3)):
            out[i, 0] += tv * n0
            out[i, 1] += tv * n1
            out[i, 2] += tv * n2


def normal_product(terms: BendingTerms, wings: np.ndarray, x: np.ndarray, z: np.ndarray
                   ) -> np.ndarray:
    """The bending Hessian's product with z (n, 3), each stencil's part along its normal
    only (`_normal_products`), at positions x (n, 3) m; wings (w, 4) the mesh's. A stencil
    measures its curvature along its normal, so this is the Hessian's product less what a
    turn of a bent stencil adds: for z a rigid turn's velocities, s = sum k_m x_m of a
    stencil bent along its normal turns with it, and ds/dt . nn = 0 (sim.newton: the
    fabric's damping on the rates of curvature, not on a turn)."""
    out = np.zeros_like(z)
    x = np.ascontiguousarray(x, dtype=np.float64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    _normal_products(x, z, wings, terms.wing_hess, True, out)
    _normal_products(x, z, terms.stars.verts, terms.stars.hess, False, out)
    return out
