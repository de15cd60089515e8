"""Internal forces of the cloth and their pair Hessian blocks, evaluated together.

The Hessian of all internal energies is held by pair blocks H (m, 3, 3) (N/m): the
Hessian's off-diagonal block for the vertex pair (i, j), with the diagonal implied by
zero row sums. The force Jacobian is K = -H.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from cloth_mg_ros.physics.model import ClothModel
from cloth_mg_ros.physics.stretch import stretch_forces_hessians
from cloth_mg_ros.physics.system import pair_difference_product


@njit(cache=True, nogil=True)
def gather_pair_hessians(side_hess, face_pairs, bend_pairs, out):
    """out (m, 3, 3) = stretch side blocks scattered onto their pairs + bend_pairs * I."""
    m = out.shape[0]
    for p in range(m):
        for a in range(3):
            for b in range(3):
                out[p, a, b] = 0.0
            out[p, a, a] = bend_pairs[p]
    for t in range(face_pairs.shape[0]):
        for s in range(3):
            p = face_pairs[t, s]
            for a in range(3):
                for b in range(3):
                    out[p, a, b] += side_hess[t, s, a, b]


@dataclass
class InternalForces:
    """forces (n, 3) N (elastic only); side_hess (t, 3, 3, 3) and pair_hess (m, 3, 3) N/m;
    stretch_energy and bend_energy in J."""

    forces: np.ndarray
    side_hess: np.ndarray
    pair_hess: np.ndarray
    stretch_energy: float
    bend_energy: float


def internal_forces(model: ClothModel, x: np.ndarray, clamp: bool = True) -> InternalForces:
    """Elastic forces and Hessian blocks at positions x (n, 3).

    Bending is linear (flat rest state): f_bend = -H_bend x, E_bend = x . H_bend x / 2.
    """
    mesh = model.mesh
    n, nt, m = model.n, len(mesh.faces), len(mesh.pairs)
    forces = np.zeros((n, 3))
    side_hess = np.empty((nt, 3, 3, 3))
    st = model.stretch
    e_stretch = stretch_forces_hessians(x, mesh.faces, st.coef, st.stiff, st.rest_len, clamp,
                                        forces, side_hess)
    bend_blocks = np.zeros((m, 3, 3))
    bend_blocks[:, 0, 0] = bend_blocks[:, 1, 1] = bend_blocks[:, 2, 2] = model.bend_pairs
    hx = np.zeros((n, 3))
    pair_difference_product(mesh.pairs, bend_blocks, x, hx)
    forces -= hx
    e_bend = 0.5 * float(np.sum(x * hx))
    pair_hess = np.empty((m, 3, 3))
    gather_pair_hessians(side_hess, mesh.face_pairs, model.bend_pairs, pair_hess)
    return InternalForces(forces, side_hess, pair_hess, float(e_stretch), e_bend)


def hessian_product(pairs: np.ndarray, pair_hess: np.ndarray, y: np.ndarray) -> np.ndarray:
    """H y for the pair-held Hessian, y (n, 3) -> (n, 3)."""
    out = np.zeros_like(y)
    pair_difference_product(pairs, pair_hess, np.ascontiguousarray(y), out)
    return out
