"""A measured fabric's bending: by direction (orthotropic) and rising with curvature.

The law. A strip of the fabric running at angle phi to the weft (u) bends with the moment

    M(kappa) = k1(phi) kappa + k2(phi) kappa^2      (Feng et al. 2022's two-term form)

up to the measured range's end kappa_c (`fabrics.CURVATURE_CAP`, 40 1/m) and with the
tangent it has there beyond it. k1 and k2 are given along the weft, the warp and the bias
(a measured fabric's: `fabrics.FabricRecord.curvature_law`) and interpolated as an
orthotropic plate of Poisson ratio 0 turned by phi (plate theory's D'11):

    k(phi) = k_weft cos^4 phi + k_warp sin^4 phi + (4 k_bias - k_weft - k_warp) sin^2 cos^2,

which is k_weft, k_warp and k_bias at 0, 90 and 45 degrees. In the fabric's axes the energy
per area of a curvature tensor K (Voigt (k11, k22, k12), |K|^2 = k11^2 + k22^2 + 2 k12^2) is

    W(K) = 1/2 K:D0:K + g(|K|) K:D1:K,    D = diag(k_weft, k_warp, 4 k_bias - k_weft - k_warp)

with g = |K| / 3 up to kappa_c (a strip bent by kappa: 1/2 k1 kappa^2 + 1/3 k2 kappa^3) and
its C1 continuation with the end tangent beyond.

Why not stencil weights. The bending Hessian (physics.bending) is a sum of four-vertex
stencils, each measuring one fixed combination of the curvature tensor (a hinge:
4/3 k_across - 1/3 tr K; a star: tr K). On a regular triangulation any such sum, and any
Hessian on the mesh's pair pattern, has a three-parameter response to a strip's direction:
a constant and one linked pair of 2-phi and 4-phi harmonics. An orthotropic fabric needs
five in a mesh turned against it, so no choice of hinge weights gives weft, warp and bias
at once. From the stencils' response on a regular lattice: weighting each hinge by k(phi)
of its direction makes gray-interlock's weft strip on the aligned lattice 50 % too stiff,
and the best weights for each lattice orientation still miss a direction by 16-33 % for
five of the fabrics.

What this does instead. Each vertex gets a curvature tensor K_v fitted by least squares to
the readings of the hinges on its edges (at a border, of every hinge whose stencil holds it) s_h =
1/2 S_h : K (exact for every constant K: S_h = sum_m k_m d_m d_m^T over the hinge's rest positions
in the vertex's fabric frame), one per spatial coordinate as the stencils' linear model has. The
energy is

    E = B_ref E_stencils(x) + sum_v A_v (W(K_v) - 1/2 B_ref |K_v|^2)

E_stencils the project's isotropic hinges and stars at unit stiffness: B_ref (the least
stiffness the law reaches in any direction) is carried by them, so no zig-zag that the
fitted tensors miss is free, and the rest by the fitted tensors, exact for every constant
curvature of any direction. The forces are this energy's exact gradient. The linear
system's Hessian stays the stencils' constant, block-symmetric one, at B_H (the largest
tangent the law reaches): it bounds the true tangent, so the step stays as stable as with
one stiffness, the coarse levels are made once at start-up and keep conserving the fine
energy of that Hessian, and a settled shape is the law's (the forces are exact at rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.topology import MeshLevel
from cloth_mg_ros.physics.bending import wing_weights

DIRECTIONS = ("weft", "warp", "bias")
METRIC = np.array([1.0, 1.0, 2.0])  # |K|^2 in Voigt (k11, k22, k12)
MIN_REF_SHARE = 0.25  # B_ref at least this share of the least curvature-0 stiffness


def quartic(weft: float, warp: float, bias: float, phi: float | np.ndarray) -> np.ndarray:
    """k(phi) of the interpolation (module docstring), phi radians from the weft."""
    c2, s2 = np.cos(phi) ** 2, np.sin(phi) ** 2
    return weft * c2 * c2 + warp * s2 * s2 + (4.0 * bias - weft - warp) * s2 * c2


@dataclass(frozen=True)
class BendingLaw:
    """A fabric's bending by direction and curvature: k1 (N m) and k2 (N m^2) along the weft,
    warp and bias; cap: kappa_c, 1/m (the law's range)."""

    k1: tuple[float, float, float]
    k2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cap: float = 40.0

    def __post_init__(self) -> None:
        for name in ("k1", "k2"):
            v = getattr(self, name)
            if len(v) != 3 or not all(isinstance(a, (int, float)) and math.isfinite(a)
                                      for a in v):
                raise ClothInputError(
                    f"bending law: {name} must be three finite numbers, got {v!r}")
        if min(self.k1) <= 0.0 or not self.cap > 0.0:
            raise ClothInputError(f"bending law: k1 must be positive and cap > 0, got "
                                  f"{self.k1!r}, {self.cap!r}")

    def stiffness(self, phi: float | np.ndarray, kappa: float | np.ndarray = 0.0) -> np.ndarray:
        """Secant stiffness M / kappa (N m) of a strip at phi rad from the weft bent to
        kappa 1/m (within the law's range: k1 + k2 kappa)."""
        k = np.minimum(np.abs(kappa), self.cap)
        return quartic(*self.k1, phi) + quartic(*self.k2, phi) * k

    def moment(self, phi: float, kappa: float) -> float:
        """M (N) of a strip at phi rad from the weft bent to kappa >= 0 1/m, beyond the
        range continued with the tangent at its end."""
        k1, k2 = float(quartic(*self.k1, phi)), float(quartic(*self.k2, phi))
        if kappa <= self.cap:
            return k1 * kappa + k2 * kappa * kappa
        c = self.cap
        return k1 * c + k2 * c * c + (k1 + 2.0 * k2 * c) * (kappa - c)

    @property
    def d0(self) -> np.ndarray:
        """Voigt diagonal of D0 in the fabric axes, N m."""
        w, v, b = self.k1
        return np.array([w, v, 4.0 * b - w - v])

    @property
    def d1(self) -> np.ndarray:
        """Voigt diagonal of D1 in the fabric axes, N m^2."""
        w, v, b = self.k2
        return np.array([w, v, 4.0 * b - w - v])

    @property
    def hessian_bend(self) -> float:
        """B_H (N m): the largest stiffness, per |K|^2 / 2, that the law's tangent reaches
        (curvature 0 or the range's end), for the constant Hessian."""
        tangent = self.d0 + 2.0 * self.cap * np.maximum(self.d1, 0.0)
        return float(np.max(np.maximum(self.d0, tangent) / METRIC))

    @property
    def base_bend(self) -> float:
        """B_ref (N m): the least stiffness per |K|^2 / 2 of the law at any curvature,
        at least MIN_REF_SHARE of curvature 0's, carried by the isotropic stencils."""
        low = np.minimum(self.d0, self.d0 + 2.0 * self.cap * np.minimum(self.d1, 0.0))
        return float(max(np.min(low / METRIC), MIN_REF_SHARE * np.min(self.d0 / METRIC)))

    def as_dict(self) -> dict:
        return {"k1_nm": dict(zip(DIRECTIONS, self.k1, strict=True)),
                "k2_nm2": dict(zip(DIRECTIONS, self.k2, strict=True)),
                "curvature_cap_per_m": self.cap, "hessian_bend_nm": self.hessian_bend,
                "base_bend_nm": self.base_bend}


def vertex_frames(mesh: MeshLevel, weft: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2), (n, 3) each: each vertex's fabric axes, t1 the weft projected into the
    plane normal to the area-weighted mean of its faces' normals (an edge where the weft
    is normal to it), t2 = normal x t1."""
    rest, faces = mesh.rest, mesh.faces
    fn = np.cross(rest[faces[:, 1]] - rest[faces[:, 0]], rest[faces[:, 2]] - rest[faces[:, 0]])
    normal = np.zeros_like(rest)
    for c in range(3):
        np.add.at(normal, faces[:, c], fn)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    t1 = weft[None, :] - (normal @ weft)[:, None] * normal
    weak = np.linalg.norm(t1, axis=1) < 1e-6
    if weak.any():
        e = mesh.edges
        other = np.zeros_like(rest)
        other[e[:, 1]] = rest[e[:, 0]] - rest[e[:, 1]]  # every vertex an edge's end (i < j)
        other[e[:, 0]] = rest[e[:, 1]] - rest[e[:, 0]]
        t1[weak] = other[weak] - np.einsum("ij,ij->i", other[weak], normal[weak])[:, None] \
            * normal[weak]
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(normal, t1)


def _readings(rest: np.ndarray, wings: np.ndarray, k: np.ndarray, t1: np.ndarray,
              t2: np.ndarray, v: np.ndarray, h: np.ndarray, n: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """(a (p, 3), fitted (n,)): for each (vertex v, hinge h) pair, the hinge's reading of a
    constant curvature in v's fabric frame, s_h = a . (k11, k22, k12) with a = 1/2 (S11, S22,
    2 S12); and which vertices' readings fix all three components."""
    d = rest[wings[h]] - rest[v][:, None, :]  # (p, 4, 3)
    du = np.einsum("pmi,pi->pm", d, t1[v])
    dv = np.einsum("pmi,pi->pm", d, t2[v])
    kh = k[h]
    a = 0.5 * np.stack([np.einsum("pm,pm->p", kh, du * du),
                        np.einsum("pm,pm->p", kh, dv * dv),
                        2.0 * np.einsum("pm,pm->p", kh, du * dv)], axis=1)
    normal = np.zeros((n, 3, 3))
    np.add.at(normal, v, a[:, :, None] * a[:, None, :])
    scale = np.trace(normal, axis1=1, axis2=2)
    fitted = np.linalg.det(normal) > 1e-6 * np.maximum(scale, 1e-300) ** 3
    return a, fitted


@dataclass
class FabricBending:
    """The model's side of a `BendingLaw` (module docstring): curvature (3n, n) maps x (n, 3)
    to each vertex's fitted K (rows 3 v + Voigt component); area (n,) m^2; fitted (n,) bool,
    the vertices with a fit (three or more independent hinges; a sheet's corner may have
    fewer, and keeps the stencils' B_ref alone)."""

    law: BendingLaw
    curvature: sp.csr_matrix
    area: np.ndarray
    fitted: np.ndarray

    @property
    def hessian_bend(self) -> float:
        return self.law.hessian_bend

    @property
    def base_bend(self) -> float:
        return self.law.base_bend

    @classmethod
    def of(cls, mesh: MeshLevel, law: BendingLaw, weft: np.ndarray | None = None
           ) -> FabricBending:
        """Fit every vertex's curvature from the hinges that hold it (module docstring)."""
        weft = np.array([1.0, 0.0, 0.0]) if weft is None else np.asarray(weft, dtype=float)
        n = len(mesh.rest)
        wings = mesh.wings
        k = wing_weights(mesh.rest, wings)  # (w, 4)
        t1, t2 = vertex_frames(mesh, weft)
        hinges = np.arange(len(wings))
        # The hinges on a vertex's own edges (the nearest readings); a border vertex has too
        # few of them for a fit, and takes every hinge whose stencil holds it.
        v = wings[:, :2].T.ravel()
        h = np.tile(hinges, 2)
        a, fitted = _readings(mesh.rest, wings, k, t1, t2, v, h, n)
        if not fitted.all():
            more = np.flatnonzero(~fitted[wings[:, 2:].T.ravel()])
            v = np.concatenate([v, wings[:, 2:].T.ravel()[more]])
            h = np.concatenate([h, np.tile(hinges, 2)[more]])
            a, fitted = _readings(mesh.rest, wings, k, t1, t2, v, h, n)
        normal = np.zeros((n, 3, 3))
        np.add.at(normal, v, a[:, :, None] * a[:, None, :])
        inv = np.zeros_like(normal)
        inv[fitted] = np.linalg.inv(normal[fitted])
        g = np.einsum("pij,pj->pi", inv[v], a)  # (p, 3): K_v += g s_h
        kh = k[h]
        rows = (3 * v[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 4), int)
        cols = np.broadcast_to(wings[h][:, None, :], rows.shape)
        vals = g[:, :, None] * kh[:, None, :]
        keep = np.broadcast_to(fitted[v][:, None, None], rows.shape)
        curv = sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(3 * n, n))
        curv.sum_duplicates()
        return cls(law, curv, np.asarray(mesh.vertex_areas, dtype=float).copy(), fitted)

    def fitted_curvature(self, x: np.ndarray) -> np.ndarray:
        """(n, 3, 3) K_v[Voigt, spatial coordinate], 1/m, of positions x (n, 3)."""
        return np.asarray(self.curvature @ x).reshape(len(self.area), 3, 3)

    def correct(self, x: np.ndarray, hx: np.ndarray, forces: np.ndarray
                ) -> tuple[float, np.ndarray]:
        """(bending energy J, forces (n, 3) N) of the law, given the stencils' product hx =
        H_B x at B_H (the Hessian the system uses) and the forces holding -hx: the
        stencils keep B_ref of it, the fitted curvatures add the rest (forces is updated
        in place)."""
        share = self.base_bend / self.hessian_bend
        e_stencils = 0.5 * share * float(np.sum(x * hx))
        # forces += (1 - share) hx - grad: the kernel subtracts the gradient in place.
        forces += (1.0 - share) * hx
        e_fit = self._kernel(np.ascontiguousarray(x, dtype=np.float64), forces, -1.0)
        return e_stencils + e_fit, forces

    def _kernel(self, x: np.ndarray, out: np.ndarray, sign: float = 1.0) -> float:
        law, c = self.law, self.curvature
        return _fit_terms(c.indptr, c.indices, c.data, self.area, law.d0, law.d1, law.cap,
                          law.base_bend, x, out, sign)


@njit(cache=True, nogil=True)
def _fit_terms(c_ptr, c_idx, c_val, area, d0, d1, cap, bref, x, out, sign):
    """Energy of the fitted curvatures at x (n, 3); adds sign times its gradient to out
    (n, 3). c: the (3n, n) curvature map, CSR; d0, d1 (3,) the law's Voigt diagonals
    (module docstring)."""
    n = area.shape[0]
    metric = np.array([1.0, 1.0, 2.0])
    energy = 0.0
    kv = np.empty((3, 3))
    for v in range(n):
        rho2 = 0.0
        q0 = 0.0
        q1 = 0.0
        for comp in range(3):
            row = 3 * v + comp
            a0 = 0.0
            a1 = 0.0
            a2 = 0.0
            for j in range(c_ptr[row], c_ptr[row + 1]):
                c = c_idx[j]
                a0 += c_val[j] * x[c, 0]
                a1 += c_val[j] * x[c, 1]
                a2 += c_val[j] * x[c, 2]
            kv[comp, 0] = a0
            kv[comp, 1] = a1
            kv[comp, 2] = a2
            sq = a0 * a0 + a1 * a1 + a2 * a2
            rho2 += metric[comp] * sq
            q0 += d0[comp] * sq
            q1 += d1[comp] * sq
        rho = np.sqrt(rho2)
        if rho <= cap:
            g = rho / 3.0
            gp = 1.0 / 3.0
        else:
            g = cap - cap * cap / rho + cap ** 3 / (3.0 * rho * rho)
            gp = cap * cap / (rho * rho) - 2.0 * cap ** 3 / (3.0 * rho ** 3)
        energy += area[v] * (0.5 * q0 + g * q1 - 0.5 * bref * rho2)
        coef = (gp * q1 / rho if rho > 0.0 else 0.0) - bref
        for comp in range(3):
            row = 3 * v + comp
            scale = sign * area[v] * (d0[comp] + 2.0 * g * d1[comp] + coef * metric[comp])
            w0 = scale * kv[comp, 0]
            w1 = scale * kv[comp, 1]
            w2 = scale * kv[comp, 2]
            for j in range(c_ptr[row], c_ptr[row + 1]):
                c = c_idx[j]
                out[c, 0] += c_val[j] * w0
                out[c, 1] += c_val[j] * w1
                out[c, 2] += c_val[j] * w2
    return energy
