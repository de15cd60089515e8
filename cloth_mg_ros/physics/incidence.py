"""Which vertices, pairs and faces of a mesh touch which, as CSR tables, so that forces,
Hessian blocks and pair products can be gathered a row at a time on several threads.

The serial kernels scatter: a face adds its forces to its three vertices, a pair block adds
to both its ends. Scattering from several threads races; gathering does not: each vertex (or
pair) sums what touches it, in a fixed order (the tables' order), so the result is the same on
any number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MeshIncidence"]


def _csr(owner: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(ptr (count + 1,), order): the entries of each owner in ascending entry order."""
    order = np.argsort(owner, kind="stable").astype(np.int64)
    ptr = np.zeros(count + 1, dtype=np.int64)
    np.add.at(ptr, owner + 1, 1)
    return np.cumsum(ptr), order


@dataclass(frozen=True)
class MeshIncidence:
    """vp_ptr (n + 1,), vp_pair, vp_other (2m,): the pairs at each vertex and their other
    ends; vf_ptr (n + 1,), vf_corner (3t,): the face corners (3 f + c) at each vertex;
    ps_ptr (m + 1,), ps_side (3t,): the face sides (3 f + s) on each pair; edge_pairs (k,):
    the pairs with a face side (the mesh's edges; the others are bending wing tips)."""

    vp_ptr: np.ndarray
    vp_pair: np.ndarray
    vp_other: np.ndarray
    vf_ptr: np.ndarray
    vf_corner: np.ndarray
    ps_ptr: np.ndarray
    ps_side: np.ndarray
    edge_pairs: np.ndarray

    @classmethod
    def of(cls, n: int, pairs: np.ndarray, faces: np.ndarray,
           face_pairs: np.ndarray) -> MeshIncidence:
        """The tables of a mesh of n vertices: pairs (m, 2), faces (t, 3), face_pairs (t, 3)
        the pair of each face side."""
        m = len(pairs)
        ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
        others = np.concatenate([pairs[:, 1], pairs[:, 0]])
        vp_ptr, order = _csr(ends, n)
        pair_ids = np.concatenate([np.arange(m), np.arange(m)])
        vf_ptr, vf_corner = _csr(np.asarray(faces, dtype=np.int64).ravel(), n)
        ps_ptr, ps_side = _csr(np.asarray(face_pairs, dtype=np.int64).ravel(), m)
        return cls(vp_ptr, pair_ids[order].astype(np.int64), others[order].astype(np.int64),
                   vf_ptr, vf_corner, ps_ptr, ps_side, np.flatnonzero(np.diff(ps_ptr) > 0))
