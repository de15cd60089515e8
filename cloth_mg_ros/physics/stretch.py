"""Triangle stretch and shear (paper Sec. 4.2, Baraff-Witkin style), forces and pair Hessians.

For a triangle with rest frame coordinates u and current positions x,
[d_u d_v] = [x_1 - x_0, x_2 - x_0] Dm^-1. Each of the four measures d_u, d_v (weft, warp,
rest length 1) and d_u + d_v, d_u - d_v (the shear diagonals, rest length sqrt 2) is
d = sum_m c_m x_m with sum_m c_m = 0, and carries the energy E = A k / 2 (|d| - l)^2 with A
the rest area. Its Hessian block between vertices m and n is

    H_mn = A k c_m c_n P,   P = dd^T/|d|^2 + (1 - l/|d|) (I - dd^T/|d|^2),

which is symmetric and equal for (m, n) and (n, m): the block-symmetric form of the
paper. Under compression (|d| < l) the second term would make H indefinite, so it is
clamped at zero; forces are always exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

SQRT2 = float(np.sqrt(2.0))
REST_LENGTHS = np.array([1.0, 1.0, SQRT2, SQRT2])
# Face side k joins local vertices SIDE_VERTS[k] (the mesh convention: k and k+1).
SIDE_VERTS = np.array([[0, 1], [1, 2], [2, 0]], dtype=np.int64)


@dataclass(frozen=True)
class StretchElements:
    """Per-triangle constants of the stretch/shear energy.

    coef: (t, 4, 3) c_m of the four measures (d_u, d_v, d_u+d_v, d_u-d_v) for local vertex m.
    stiff: (t, 4) rest area times stiffness, A k, in N m (energy per unit squared strain).
    rest_len: (4,) rest lengths of the measures (dimensionless).
    """

    coef: np.ndarray
    stiff: np.ndarray
    rest_len: np.ndarray


def material_frames(rest: np.ndarray, faces: np.ndarray, weft: np.ndarray) -> np.ndarray:
    """Dm^-1 per triangle, (t, 2, 2), from rest positions (n, 3) in metres.

    Each triangle's material frame has its u axis along the weft direction projected into
    the triangle's plane (falling back to the first edge where the weft is normal to it),
    so a flat sheet gets exactly its planar (u, v) coordinates and a curved mesh a
    consistent weft direction.
    """
    p0, p1, p2 = rest[faces[:, 0]], rest[faces[:, 1]], rest[faces[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    normal = np.cross(e1, e2)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    t1 = weft[None, :] - (normal @ weft)[:, None] * normal
    norm_t1 = np.linalg.norm(t1, axis=1)
    weak = norm_t1 < 1e-6
    t1[weak] = e1[weak]
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    dm = np.empty((len(faces), 2, 2))
    dm[:, 0, 0] = np.einsum("ij,ij->i", e1, t1)
    dm[:, 1, 0] = np.einsum("ij,ij->i", e1, t2)
    dm[:, 0, 1] = np.einsum("ij,ij->i", e2, t1)
    dm[:, 1, 1] = np.einsum("ij,ij->i", e2, t2)
    return np.linalg.inv(dm)


def stretch_elements(
    rest: np.ndarray,
    faces: np.ndarray,
    face_areas: np.ndarray,
    stretch: float,
    shear: float,
    weft: np.ndarray | None = None,
) -> StretchElements:
    """Build the per-triangle constants for stiffness ``stretch`` and ``shear`` (N/m)."""
    weft = np.array([1.0, 0.0, 0.0]) if weft is None else np.asarray(weft, dtype=float)
    dinv = material_frames(rest, faces, weft)
    cu = np.empty((len(faces), 3))
    cv = np.empty((len(faces), 3))
    # d_u = (x1 - x0) Dinv[0,0] + (x2 - x0) Dinv[1,0]; d_v likewise with column 1.
    cu[:, 1], cu[:, 2] = dinv[:, 0, 0], dinv[:, 1, 0]
    cv[:, 1], cv[:, 2] = dinv[:, 0, 1], dinv[:, 1, 1]
    cu[:, 0] = -(cu[:, 1] + cu[:, 2])
    cv[:, 0] = -(cv[:, 1] + cv[:, 2])
    coef = np.stack([cu, cv, cu + cv, cu - cv], axis=1)
    k = np.array([stretch, stretch, shear, shear])
    stiff = face_areas[:, None] * k[None, :]
    return StretchElements(np.ascontiguousarray(coef), stiff, REST_LENGTHS.copy())


@njit(cache=True, nogil=True)
def stretch_forces_hessians(x, faces, coef, stiff, rest_len, clamp, forces, side_hess):
    """Add stretch/shear forces to ``forces`` (n, 3), N, and write pair Hessians.

    side_hess: (t, 3, 3, 3) output, the Hessian block of each face side (vertex pairs
    (0,1), (1,2), (2,0)), N/m. clamp: clamp the compression term (keeps H PSD).
    Returns the elastic energy in J.
    """
    energy = 0.0
    nf = faces.shape[0]
    d = np.empty(3)
    P = np.empty((3, 3))
    for t in range(nf):
        i0 = faces[t, 0]
        i1 = faces[t, 1]
        i2 = faces[t, 2]
        for s in range(3):
            for a in range(3):
                for b in range(3):
                    side_hess[t, s, a, b] = 0.0
        for q in range(4):
            c0 = coef[t, q, 0]
            c1 = coef[t, q, 1]
            c2 = coef[t, q, 2]
            for a in range(3):
                d[a] = c0 * x[i0, a] + c1 * x[i1, a] + c2 * x[i2, a]
            dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            if dn < 1e-12:
                continue
            lr = rest_len[q]
            k = stiff[t, q]
            energy += 0.5 * k * (dn - lr) * (dn - lr)
            g = k * (dn - lr) / dn
            for a in range(3):
                forces[i0, a] -= g * c0 * d[a]
                forces[i1, a] -= g * c1 * d[a]
                forces[i2, a] -= g * c2 * d[a]
            tang = 1.0 - lr / dn
            if clamp and tang < 0.0:
                tang = 0.0
            inv2 = 1.0 / (dn * dn)
            for a in range(3):
                for b in range(3):
                    dd = d[a] * d[b] * inv2
                    P[a, b] = dd - tang * dd
                P[a, a] += tang
            w01 = k * c0 * c1
            w12 = k * c1 * c2
            w20 = k * c2 * c0
            for a in range(3):
                for b in range(3):
                    side_hess[t, 0, a, b] += w01 * P[a, b]
                    side_hess[t, 1, a, b] += w12 * P[a, b]
                    side_hess[t, 2, a, b] += w20 * P[a, b]
    return energy


@njit(cache=True, nogil=True)
def stretch_energy(x, faces, coef, stiff, rest_len):
    """Stretch/shear energy in J for positions x (n, 3)."""
    energy = 0.0
    d = np.empty(3)
    for t in range(faces.shape[0]):
        for q in range(4):
            for a in range(3):
                d[a] = (coef[t, q, 0] * x[faces[t, 0], a] + coef[t, q, 1] * x[faces[t, 1], a]
                        + coef[t, q, 2] * x[faces[t, 2], a])
            dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            energy += 0.5 * stiff[t, q] * (dn - rest_len[q]) ** 2
    return energy
