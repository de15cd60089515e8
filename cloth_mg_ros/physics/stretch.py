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

Compression that buckles: each face may wrinkle finer than the mesh, at the load its bending
allows (physics.wrinkles: a tension-field relaxation whose forces stay exact and whose
measures stay scalar functions of one |d|, so H keeps the block-symmetric form).
cap = inf: compression resisted like tension (`compression: elastic`, the paper's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from cloth_mg_ros.physics.wrinkles import measure_coefficients, relax

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
    cap: (t, 2) A sigma_b along u and v, J (`compression_caps`; inf: the membrane does not
    wrinkle).
    """

    coef: np.ndarray
    stiff: np.ndarray
    rest_len: np.ndarray
    cap: np.ndarray | None = None

    def __post_init__(self):
        if self.cap is None:
            object.__setattr__(self, "cap", np.full((self.stiff.shape[0], 2), np.inf))


def compression_caps(n_faces: int, bend: float | tuple[float, float, float]) -> np.ndarray:
    """(n_faces, 2) the faces' buckling stresses times their areas, A sigma_b = pi^2 B / 2
    (J per unit strain; physics.wrinkles: the same for every triangle size), along u and v
    (the threads the wrinkles shorten), from the bending stiffness B (N m): one value, or
    (B along u, B along v, B bias) where the fabric bends differently by direction (a face
    compressed along u wrinkles by bending along u; the bias value is not needed)."""
    b_u, b_v = (bend, bend) if np.isscalar(bend) else bend[:2]
    b = np.array([b_u, b_v], dtype=float)
    if not np.all(np.isfinite(b)) or np.any(b < 0.0):
        raise ValueError(f"bending stiffness must be finite and >= 0, got {bend!r}")
    return np.ascontiguousarray(np.broadcast_to(0.5 * np.pi ** 2 * b, (n_faces, 2)))


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
    stretch_warp: float | None = None,
    buckle_bend: float | tuple[float, float, float] | None = None,
) -> StretchElements:
    """Build the per-triangle constants for stiffness ``stretch`` (weft, u; and warp, v,
    unless ``stretch_warp`` is given) and ``shear`` (N/m). buckle_bend: the bending
    stiffness (N m; or by direction, `compression_caps`) that caps compression; None:
    compression resisted like tension."""
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
    k = np.array([stretch, stretch if stretch_warp is None else stretch_warp, shear, shear])
    stiff = face_areas[:, None] * k[None, :]
    cap = None if buckle_bend is None else compression_caps(len(faces), buckle_bend)
    return StretchElements(np.ascontiguousarray(coef), stiff, REST_LENGTHS.copy(), cap)


@njit(cache=True, nogil=True, inline="always")
def _projector(d0, d1, d2, tang, inv2):
    """The six distinct entries (xx, xy, xz, yy, yz, zz) of the symmetric
    P = dd^T/|d|^2 + tang (I - dd^T/|d|^2), as dd - tang dd (+ tang on the diagonal)."""
    xx = d0 * d0 * inv2
    xy = d0 * d1 * inv2
    xz = d0 * d2 * inv2
    yy = d1 * d1 * inv2
    yz = d1 * d2 * inv2
    zz = d2 * d2 * inv2
    return (xx - tang * xx + tang, xy - tang * xy, xz - tang * xz, yy - tang * yy + tang,
            yz - tang * yz, zz - tang * zz + tang)


@njit(cache=True, nogil=True, parallel=True)
def stretch_face_terms(x, faces, coef, stiff, rest_len, cap, clamp, corner_forces, side_hess,
                       face_energy, z=None, corner_products=None, rate=False):
    """The stretch/shear terms of every face, a face per thread: corner_forces (t, 3, 3) N
    (the force on each face corner), side_hess (t, 3, 6) N/m (the Hessian block of each
    face side, vertex pairs (0,1), (1,2), (2,0), symmetric: its entries xx, xy, xz, yy, yz,
    zz), face_energy (t,) J. cap (t, 2): the faces' buckling loads (physics.wrinkles).
    clamp: clamp the compression term (keeps H PSD). `gather_corners` sums the corner
    forces per vertex. The sums over the four measures stay in local variables, and a side
    block's six distinct entries are all that is written: the kernel is bound by the bytes
    it writes. z (n, 3) and corner_products (t, 3, 3), both given or both None: also each
    corner's share of the stretch Hessian's product with z (`_corner_products`, or with
    ``rate`` of its part along each measure, `_add_rate`; summed per vertex by
    sim.forces.vertex_terms), formed while the blocks are in registers (a later pass over
    the pair blocks read 8.5 MB at 20K particles)."""
    for t in prange(faces.shape[0]):
        i0, i1, i2 = faces[t, 0], faces[t, 1], faces[t, 2]
        f00 = f01 = f02 = f10 = f11 = f12 = f20 = f21 = f22 = 0.0
        side0 = side1 = side2 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # sides (0,1), (1,2), (2,0)
        r = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # `rate`'s corner products
        eu, ev = relax(x, i0, i1, i2, coef[t], stiff[t], rest_len, cap[t])
        wrinkled = eu + ev > 0.0
        energy = cap[t, 0] * eu + cap[t, 1] * ev if wrinkled else 0.0
        for q in range(4):
            if wrinkled:
                c0, c1, c2 = measure_coefficients(coef[t], q, eu, ev)
            else:
                c0 = coef[t, q, 0]
                c1 = coef[t, q, 1]
                c2 = coef[t, q, 2]
            d0 = c0 * x[i0, 0] + c1 * x[i1, 0] + c2 * x[i2, 0]
            d1 = c0 * x[i0, 1] + c1 * x[i1, 1] + c2 * x[i2, 1]
            d2 = c0 * x[i0, 2] + c1 * x[i1, 2] + c2 * x[i2, 2]
            dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            lr, k = rest_len[q], stiff[t, q]
            # a collapsed measure keeps its energy (as in stretch_energy); no force or Hessian
            energy += 0.5 * k * (dn - lr) * (dn - lr)
            if dn < 1e-12:
                continue
            g = k * (dn - lr) / dn
            f00 -= g * c0 * d0
            f10 -= g * c1 * d0
            f20 -= g * c2 * d0
            f01 -= g * c0 * d1
            f11 -= g * c1 * d1
            f21 -= g * c2 * d1
            f02 -= g * c0 * d2
            f12 -= g * c1 * d2
            f22 -= g * c2 * d2
            tang = max(1.0 - lr / dn, 0.0) if clamp else 1.0 - lr / dn
            inv2 = 1.0 / (dn * dn)
            p = _projector(d0, d1, d2, tang, inv2)
            r = _add_rate(r, rate, k * inv2, (c0, c1, c2), (d0, d1, d2), z, i0, i1, i2)
            side0 = _add_scaled(side0, k * c0 * c1, p)
            side1 = _add_scaled(side1, k * c1 * c2, p)
            side2 = _add_scaled(side2, k * c2 * c0, p)
        _store_face(t, (f00, f01, f02, f10, f11, f12, f20, f21, f22), side0, side1, side2,
                    energy, corner_forces, side_hess, face_energy)
        if z is not None and corner_products is not None:
            _write_products(t, rate, r, i0, i1, i2, side0, side1, side2, z, corner_products)


@njit(cache=True, nogil=True, inline="always")
def _store_face(t, f, side0, side1, side2, energy, corner_forces, side_hess, face_energy):
    """Write face t's corner forces (f: 9 values, corner-major), side blocks and energy."""
    for c in range(3):
        for a in range(3):
            corner_forces[t, c, a] = f[3 * c + a]
    for q in range(6):
        side_hess[t, 0, q] = side0[q]
        side_hess[t, 1, q] = side1[q]
        side_hess[t, 2, q] = side2[q]
    face_energy[t] = energy


@njit(cache=True, nogil=True, inline="always")
def _add_rate(r, rate, w, c, d, z, i0, i1, i2):
    """r (9 values, corner-major) plus, where ``rate`` (and z is given), one measure's share
    of its Hessian part along d, k c_m c_n dd^T/|d|^2, times z: w c_m d (d . sum_n c_n z_n),
    w = k / |d|^2. That part changes the measure's length, the rest turns it: a damping of
    strain rates takes this part alone, and a rigid turn of a stressed face none (sim.newton).
    """
    if not rate or z is None:
        return r
    g = w * (d[0] * (c[0] * z[i0, 0] + c[1] * z[i1, 0] + c[2] * z[i2, 0])
             + d[1] * (c[0] * z[i0, 1] + c[1] * z[i1, 1] + c[2] * z[i2, 1])
             + d[2] * (c[0] * z[i0, 2] + c[1] * z[i1, 2] + c[2] * z[i2, 2]))
    return (r[0] + g * c[0] * d[0], r[1] + g * c[0] * d[1], r[2] + g * c[0] * d[2],
            r[3] + g * c[1] * d[0], r[4] + g * c[1] * d[1], r[5] + g * c[1] * d[2],
            r[6] + g * c[2] * d[0], r[7] + g * c[2] * d[1], r[8] + g * c[2] * d[2])


@njit(cache=True, nogil=True, inline="always")
def _write_products(t, rate, r, i0, i1, i2, side0, side1, side2, z, corner_products):
    """Face t's corner products: `_add_rate`'s r (9 values, corner-major) where ``rate``,
    else the full Hessian's (`_corner_products`)."""
    if rate:
        for c in range(3):
            for a in range(3):
                corner_products[t, c, a] = r[3 * c + a]
    else:
        _corner_products(t, i0, i1, i2, side0, side1, side2, z, corner_products)


@njit(cache=True, nogil=True, inline="always")
def _corner_products(t, i0, i1, i2, side0, side1, side2, z, corner_products):
    """Face t's corners' shares of the stretch Hessian's product with z (stretch_face_terms):
    p_s = S_s (z_b - z_a) for side s = (a, b); corner 0 gets p_0 - p_2, corner 1 p_1 - p_0,
    corner 2 p_2 - p_1."""
    p0 = _sym_times(side0, z[i1, 0] - z[i0, 0], z[i1, 1] - z[i0, 1], z[i1, 2] - z[i0, 2])
    p1 = _sym_times(side1, z[i2, 0] - z[i1, 0], z[i2, 1] - z[i1, 1], z[i2, 2] - z[i1, 2])
    p2 = _sym_times(side2, z[i0, 0] - z[i2, 0], z[i0, 1] - z[i2, 1], z[i0, 2] - z[i2, 2])
    for a in range(3):
        corner_products[t, 0, a] = p0[a] - p2[a]
        corner_products[t, 1, a] = p1[a] - p0[a]
        corner_products[t, 2, a] = p2[a] - p1[a]


@njit(cache=True, nogil=True, inline="always")
def _sym_times(m, e0, e1, e2):
    """The symmetric block m (xx, xy, xz, yy, yz, zz) times (e0, e1, e2)."""
    return (m[0] * e0 + m[1] * e1 + m[2] * e2, m[1] * e0 + m[3] * e1 + m[4] * e2,
            m[2] * e0 + m[4] * e1 + m[5] * e2)


@njit(cache=True, nogil=True, inline="always")
def _add_scaled(acc, w, p):
    """acc + w p for the six entries of a symmetric block (tuples: they stay in registers)."""
    return (acc[0] + w * p[0], acc[1] + w * p[1], acc[2] + w * p[2], acc[3] + w * p[3],
            acc[4] + w * p[4], acc[5] + w * p[5])


@njit(cache=True, nogil=True, parallel=True)
def gather_corners(vf_ptr, vf_corner, corner_forces, forces):
    """forces (n, 3) += the corner forces at each vertex (physics.incidence tables), a vertex
    per thread."""
    for i in prange(forces.shape[0]):
        for k in range(vf_ptr[i], vf_ptr[i + 1]):
            fc = vf_corner[k]
            t = fc // 3
            c = fc - 3 * t
            for a in range(3):
                forces[i, a] += corner_forces[t, c, a]


@njit(cache=True, nogil=True)
def stretch_energy(x, faces, coef, stiff, rest_len, cap=None):
    """Stretch/shear energy in J for positions x (n, 3); cap (t, 2) the faces' buckling loads
    (physics.wrinkles; None: none). A plain second formulation, serial, without the forces:
    the reference the tests hold `stretch_face_terms`' face energies to. The simulation's
    energies (sim.integrator.energies) are stretch_face_terms' own (sim.forces
    .internal_forces), so that they are the potential of the forces a step uses."""
    energy = 0.0
    d = np.empty(3)
    for t in range(faces.shape[0]):
        eu = ev = 0.0
        if cap is not None:
            eu, ev = relax(x, faces[t, 0], faces[t, 1], faces[t, 2], coef[t], stiff[t],
                           rest_len, cap[t])
            if eu + ev > 0.0:
                energy += cap[t, 0] * eu + cap[t, 1] * ev
        for q in range(4):
            c0, c1, c2 = measure_coefficients(coef[t], q, eu, ev)
            for a in range(3):
                d[a] = (c0 * x[faces[t, 0], a] + c1 * x[faces[t, 1], a]
                        + c2 * x[faces[t, 2], a])
            dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            energy += 0.5 * stiff[t, q] * (dn - rest_len[q]) ** 2
    return energy
