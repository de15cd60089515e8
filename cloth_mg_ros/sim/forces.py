"""Internal forces of the cloth and their pair Hessian blocks, evaluated together.

The Hessian of all internal energies is held by pair blocks H (m, 3, 3) (N/m): the
Hessian's off-diagonal block for the vertex pair (i, j), with the diagonal implied by
zero row sums. The force Jacobian is K = -H.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from cloth_mg_ros.physics.bending import normal_product
from cloth_mg_ros.physics.stretch import gather_corners, stretch_face_terms
from cloth_mg_ros.physics.system import (
    pair_difference_product,
    pair_scalar_product_rows,
)
from cloth_mg_ros.sim.model import ClothModel


@njit(cache=True, nogil=True, inline="always")
def _pair_block(p, side_hess, ps_ptr, ps_side, bend_pairs, scale, out):
    """out[p] = scale (bend_pairs[p] I + the stretch blocks of the face sides on pair p)."""
    w = bend_pairs[p]
    xx = w
    xy = 0.0
    xz = 0.0
    yy = w
    yz = 0.0
    zz = w
    for k in range(ps_ptr[p], ps_ptr[p + 1]):
        fs = ps_side[k]
        t = fs // 3
        s = fs - 3 * t
        xx += side_hess[t, s, 0]
        xy += side_hess[t, s, 1]
        xz += side_hess[t, s, 2]
        yy += side_hess[t, s, 3]
        yz += side_hess[t, s, 4]
        zz += side_hess[t, s, 5]
    out[p, 0, 0] = scale * xx
    out[p, 0, 1] = scale * xy
    out[p, 0, 2] = scale * xz
    out[p, 1, 0] = scale * xy
    out[p, 1, 1] = scale * yy
    out[p, 1, 2] = scale * yz
    out[p, 2, 0] = scale * xz
    out[p, 2, 1] = scale * yz
    out[p, 2, 2] = scale * zz


@njit(cache=True, nogil=True, parallel=True)
def gather_pair_hessians(side_hess, ps_ptr, ps_side, bend_pairs, scale, out):
    """out (m, 3, 3) = scale (bend_pairs * I + the stretch blocks of the face sides on each
    pair) (physics.incidence tables; side_hess (t, 3, 6) their six distinct entries), a pair
    per thread. The scale is applied to each sum (the step's system wants its blocks times
    h'^2 + h' damping: a pass of its own over 17 MB cost 0.25-0.3 ms at 20K particles)."""
    for p in prange(out.shape[0]):
        _pair_block(p, side_hess, ps_ptr, ps_side, bend_pairs, scale, out)


@njit(cache=True, nogil=True, parallel=True)
def gather_edge_hessians(side_hess, ps_ptr, ps_side, bend_pairs, scale, edges, out):
    """`gather_pair_hessians` on the pairs `edges` (k,) only: the others' blocks (no face
    side: scale bend_pairs I) are already in out."""
    for q in prange(edges.shape[0]):
        _pair_block(edges[q], side_hess, ps_ptr, ps_side, bend_pairs, scale, out)


@njit(cache=True, nogil=True, parallel=True)
def vertex_terms(vp_ptr, vp_pair, vp_other, vf_ptr, vf_corner, bend_pairs, corner_forces,
                 corner_products, x, z, hx, forces, hz, z_bend=1.0):
    """Per vertex, in one pass over its pairs and one over its face corners (physics.incidence
    tables), a vertex per thread, all (n, 3): hx = the bending product at x (bend_pairs (m,),
    pair_scalar_product_rows' sum), forces = -hx + the corner forces, and hz = the elastic
    Hessian's sum_j H_ij (z_j - z_i): the bending pairs' part plus the stretch corners'
    (stretch_face_terms' corner_products). z_bend: the bending pairs' share of hz (0: the
    stretch corners' alone)."""
    for i in prange(x.shape[0]):
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(vp_ptr[i], vp_ptr[i + 1]):
            w = bend_pairs[vp_pair[k]]
            j = vp_other[k]
            b0 += w * (x[j, 0] - x[i, 0])
            b1 += w * (x[j, 1] - x[i, 1])
            b2 += w * (x[j, 2] - x[i, 2])
            wz = w * z_bend  # w itself at 1
            s0 += wz * (z[j, 0] - z[i, 0])
            s1 += wz * (z[j, 1] - z[i, 1])
            s2 += wz * (z[j, 2] - z[i, 2])
        hx[i, 0] = b0
        hx[i, 1] = b1
        hx[i, 2] = b2
        f0 = -b0
        f1 = -b1
        f2 = -b2
        for k in range(vf_ptr[i], vf_ptr[i + 1]):
            fc = vf_corner[k]
            t = fc // 3
            c = fc - 3 * t
            f0 += corner_forces[t, c, 0]
            f1 += corner_forces[t, c, 1]
            f2 += corner_forces[t, c, 2]
            s0 += corner_products[t, c, 0]
            s1 += corner_products[t, c, 1]
            s2 += corner_products[t, c, 2]
        forces[i, 0] = f0
        forces[i, 1] = f1
        forces[i, 2] = f2
        hz[i, 0] = s0
        hz[i, 1] = s1
        hz[i, 2] = s2


@dataclass
class InternalForces:
    """forces (n, 3) N (elastic only); side_hess (t, 3, 6) (each face side's symmetric block:
    xx, xy, xz, yy, yz, zz) N/m; pair_hess (m, 3, 3): the pair blocks times hess_scale (N/m
    times its unit; 1 unless asked); stretch_energy and bend_energy in J; product: the
    pair-held Hessian's product sum_j H_ij (z_j - z_i) (n, 3) (N/m times z's unit) for the
    z asked for (not scaled), None where none was; pair_rows: the (m + spare rows, 3, 3) array whose
    first m rows are pair_hess, the rest left for the caller."""

    forces: np.ndarray
    side_hess: np.ndarray
    pair_hess: np.ndarray
    stretch_energy: float
    bend_energy: float
    product: np.ndarray | None = None
    hess_scale: float = 1.0
    pair_rows: np.ndarray | None = None


class Workspace:
    """Arrays a simulator's steps write anew every step, kept from one step to the next: a
    fresh 10-20 MB of them per step at 20K particles came back from the system as new pages
    every time, and the page faults cost more than filling them. Arrays got from it hold
    their values only until the next step asks for them again."""

    def __init__(self) -> None:
        self._arrays: dict[str, np.ndarray] = {}
        self._keys: dict[str, tuple] = {}

    def get(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialised float64 array of ``shape``, the same one each time it fits."""
        a = self._arrays.get(name)
        if a is None or a.shape != shape:
            a = self._arrays[name] = np.empty(shape)
        return a

    def kept_rows(self, name: str, rows: int, shape: tuple[int, ...], key: tuple
                  ) -> tuple[np.ndarray, bool]:
        """`rows`, and whether its first rows are in the array the last call for ``name``
        returned with the same ``key`` (its arrays compared by identity, the rest by value):
        whatever of those rows depends on the key alone is still there."""
        a = self._arrays.get(name)
        same = (a is not None and a.shape[1:] == shape and len(a) >= rows
                and _same_key(self._keys.get(name), key))
        self._keys[name] = key
        return self.rows(name, rows, shape), same

    def rows(self, name: str, rows: int, shape: tuple[int, ...] = ()) -> np.ndarray:
        """An uninitialised float64 array of (rows, *shape): the first rows of one kept
        with room to spare, for arrays whose length changes from step to step."""
        a = self._arrays.get(name)
        if a is None or a.shape[1:] != shape or len(a) < rows:
            a = self._arrays[name] = np.empty((rows + rows // 8 + 16, *shape))
        return a[:rows]


def _same_key(old: tuple | None, new: tuple) -> bool:
    if old is None or len(old) != len(new):
        return False
    return all(a is b if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else a == b
               for a, b in zip(old, new, strict=True))


def scratch(work: Workspace | None, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialised float64 array: the workspace's ``name`` one, or a new one without a
    workspace."""
    return np.empty(shape) if work is None else work.get(name, shape)


def internal_forces(model: ClothModel, x: np.ndarray, clamp: bool = True,
                    work: Workspace | None = None, product_of: np.ndarray | None = None,
                    hess_scale: float = 1.0, spare_rows: int = 0,
                    rate_product: bool = False) -> InternalForces:
    """Elastic forces and Hessian blocks at positions x (n, 3).

    Bending is linear (flat rest state): f_bend = -H_bend x, E_bend = x . H_bend x / 2.
    work: where the Hessian blocks go (a Workspace: valid until its next use; None: new
    arrays). product_of: a z (n, 3) whose Hessian product the step needs (``product``:
    `hessian_product` over the mesh pairs, summed in another order), formed from the face
    blocks as they are computed and in the same pass over the vertices as the forces (a
    product over the pair blocks afterwards read their 8.5 MB again at 20K particles).
    hess_scale: the factor the pair blocks are returned times (a step's system takes them
    times h'^2 + h' damping); spare_rows: rows left after them in the same array
    (``pair_rows``; the step's cloth-cloth springs go there without a copy of the mesh's).
    rate_product: ``product`` is the Hessian's part that changes the elastic measures (each
    stretch measure's length, each bending stencil's curvature along its normal) times z,
    without the part a turn of the stressed cloth adds: with z = c v, the fabric's damping of
    its strain rates, which a rigid turn leaves alone (sim.newton).
    """
    mesh = model.mesh
    inc = model.incidence
    x = np.ascontiguousarray(x, dtype=np.float64)
    nt, m = len(mesh.faces), len(mesh.pairs)
    corner = scratch(work, "corner", (nt, 3, 3))
    side_hess = scratch(work, "side_hess", (nt, 3, 6))
    face_energy = scratch(work, "face_energy", (nt,))
    st = model.stretch
    z = products = None
    if product_of is not None:
        z = np.ascontiguousarray(product_of, dtype=np.float64)
        products = scratch(work, "corner_products", (nt, 3, 3))
    stretch_face_terms(x, mesh.faces, st.coef, st.stiff, st.rest_len, st.cap, clamp, corner,
                       side_hess, face_energy, z, products, rate_product)
    scale = float(hess_scale)
    pair_rows = _pair_hessians(model, side_hess, scale, m + int(spare_rows), work)
    pair_hess = pair_rows[:m]
    hx = np.empty((model.n, 3))
    product = None
    if z is None:
        pair_scalar_product_rows(inc.vp_ptr, inc.vp_pair, inc.vp_other, model.bend_pairs, x,
                                 hx)
        forces = -hx
        gather_corners(inc.vf_ptr, inc.vf_corner, corner, forces)
    else:
        forces, product = np.empty((model.n, 3)), np.empty((model.n, 3))
        vertex_terms(inc.vp_ptr, inc.vp_pair, inc.vp_other, inc.vf_ptr, inc.vf_corner,
                     model.bend_pairs, corner, products, x, z, hx, forces, product,
                     0.0 if rate_product else 1.0)
        if rate_product:
            product += normal_product(model.bending, mesh.wings, x, z)
    e_bend = 0.5 * float(np.sum(x * hx))
    if model.bending_law is not None:  # a measured fabric's: exact forces, bounding Hessian
        e_bend, forces = model.bending_law.correct(x, hx, forces)
    return InternalForces(forces, side_hess, pair_hess, float(face_energy.sum()), e_bend,
                          product, scale, pair_rows)


def _pair_hessians(model: ClothModel, side_hess: np.ndarray, scale: float, rows: int,
                   work: Workspace | None) -> np.ndarray:
    """The pair blocks times ``scale`` (the mesh's pairs first, then spare rows), (rows, 3,
    3), gathered from the faces' side blocks (nt, 3, 6) and the bending's constant pairs."""
    inc = model.incidence
    m = len(model.mesh.pairs)
    # A pair that is no mesh edge (a bending wing tip, half of them) has the constant block
    # scale bend I: a kept array has it from the step before while the scale repeats
    # (writing it again cost 0.2-0.35 ms at 20K particles)
    if work is None:
        pair_rows, kept = np.empty((rows, 3, 3)), False
    else:
        pair_rows, kept = work.kept_rows("pair_hess", rows, (3, 3), (model.bend_pairs, scale))
    if kept:
        gather_edge_hessians(side_hess, inc.ps_ptr, inc.ps_side, model.bend_pairs, scale,
                             inc.edge_pairs, pair_rows[:m])
    else:
        gather_pair_hessians(side_hess, inc.ps_ptr, inc.ps_side, model.bend_pairs, scale,
                             pair_rows[:m])
    return pair_rows


def hessian_product(pairs: np.ndarray, pair_hess: np.ndarray, y: np.ndarray) -> np.ndarray:
    """H y for the pair-held Hessian of any pairs (m, 2) (m, 3, 3), y (n, 3) -> (n, 3)."""
    out = np.zeros_like(y)
    pair_difference_product(pairs, pair_hess, np.ascontiguousarray(y), out)
    return out
