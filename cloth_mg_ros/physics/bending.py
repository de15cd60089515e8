"""Curvature-based bending: the quadratic (isometric) bending energy of Bergou et al. 2006.

Every interior edge (a, b) with wing tips c and d carries weights k (4,) with sum k = 0
and sum k_m u_m = 0 for the flat rest wing, so that s = sum_m k_m x_m is the hinge's
curvature normal: for a hinge folded by a small dihedral angle theta, |s| = |e| theta.
With A0, A1 the rest areas of the two faces,

    E_e = bend / (A0 + A1) * |s|^2 / 2,

the discrete form of (bend / 2) * integral of kappa^2 over the area (flat rest state:
fabric patterns are flat). On the near-equilateral meshes the hierarchy builds, a sheet
rolled into a cylinder of radius R in either direction gets (bend / 2) A / R^2 to within
the missing hinges of the boundary (98 % at 40 cells across; test_physics checks it).
Bergou's normalisation 3 / (A0 + A1) counts each hinge's area share; on these meshes it
overestimates the cylinder energy threefold, so we use the calibrated one.
Its Hessian is the constant scalar matrix Q = bend / (A0 + A1) k k^T times the 3x3
identity: symmetric pair blocks Q_mn I with zero row sums, so bending fits the
block-symmetric system and never needs re-assembly.
"""

from __future__ import annotations

import numpy as np

# Pairs of the wing vertices (a, b, c, d) in the mesh's wing_pairs order.
WING_PAIR_VERTS = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


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


def wing_hessians(
    rest: np.ndarray, wings: np.ndarray, wing_faces: np.ndarray, face_areas: np.ndarray,
    bend: float,
) -> np.ndarray:
    """Scalar Hessian entries Q_mn of every wing for its six vertex pairs, (w, 6), N/m.

    Only off-diagonal entries are kept: the diagonal follows from the zero row sums.
    """
    k = wing_weights(rest, wings)
    area = face_areas[wing_faces[:, 0]] + face_areas[wing_faces[:, 1]]
    scale = bend / area
    return scale[:, None] * k[:, WING_PAIR_VERTS[:, 0]] * k[:, WING_PAIR_VERTS[:, 1]]


def pair_bending(wing_hess: np.ndarray, wing_pairs: np.ndarray, n_pairs: int) -> np.ndarray:
    """Sum the wing Hessian entries onto the mesh pairs: (m,) scalar blocks, N/m."""
    out = np.zeros(n_pairs)
    np.add.at(out, wing_pairs.ravel(), wing_hess.ravel())
    return out
