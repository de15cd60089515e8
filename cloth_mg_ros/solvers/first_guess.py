"""The first guess of a multigrid solve (solvers.multigrid): the rigid motion of the free
particles that takes most A-norm error out of it, on the finest level's packed rows.

A solve's first guess is zero but on its pins (their velocity changes), and the body drags
the whole garment: a walking dress's first residual is 2.3-2.6 times its right-hand side,
and a good part of it is a common motion of the free particles that the V-cycles take
iterations to find. The guess is projected onto a few such motions T (a Galerkin step:
T^T A T c = T^T r, then x += T c), each needing A's product with T only in sums:

* the three translations: off the pins' neighbours A's rows sum to B_i, so (A t)_i = B_i t,
  and on a pin's neighbour the pinned pairs' blocks come off (`_translation_block`);
* the three rotations r_i = theta x X_i (X_i: particle i's position less a centre), when the
  system carries the elastic forces where its Hessian was taken (physics.system
  RotationTerms): the elastic energy does not change under a rotation, so its Hessian takes
  a rotation field to theta x (its gradient), and (A r)_i = B_i (theta x X_i) + theta x q_i
  with q = hess_scale * (-forces); on a pin's neighbour the pinned pairs' terms come off.
  That is exact where the Hessian is the energy's own; the stretch Hessian's compression
  clamp makes it an approximation on compressed faces, so the rotations' guess is followed
  by the exact residual (one product over every row), not by an update from the formula.

Every sum is formed per chunk of rows and the chunks added in order: the same numbers on
any number of threads. Figures (iterations saved, cost): doc/benchmarks/walking.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit, prange

from cloth_mg_ros.solvers.packed_kernels import ordered_sum

if TYPE_CHECKING:
    from cloth_mg_ros.physics.system import RotationTerms
    from cloth_mg_ros.solvers.packed_levels import PackedLevels


@njit(cache=True, nogil=True)
def _column_sums(partial):
    """(c,): the sums of partial (chunks, c) over its chunks, added in chunk order."""
    out = np.zeros(partial.shape[1])
    for k in range(partial.shape[0]):
        for a in range(partial.shape[1]):
            out[a] += partial[k, a]
    return out


# -- translations -----------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _translation_block(i, slots, bdiag6, free):
    """C_i (6 numbers, a symmetric block) with (A t)_i = C_i t for a translation t of every
    free row, for a row next to a pin: B_i less the pair blocks of its pinned neighbours
    (A's rows sum to B_i; elsewhere C_i = B_i)."""
    fstart, _, fstop, fnbr, frows, sstart, _, sstop, snbr, swts = slots
    c0 = bdiag6[i, 0]
    c1 = bdiag6[i, 1]
    c2 = bdiag6[i, 2]
    c3 = bdiag6[i, 3]
    c4 = bdiag6[i, 4]
    c5 = bdiag6[i, 5]
    for k in range(fstart[i], fstop[i]):
        if free[fnbr[k]] == 0.0:
            c0 -= frows[k, 0]
            c1 -= frows[k, 1]
            c2 -= frows[k, 2]
            c3 -= frows[k, 3]
            c4 -= frows[k, 4]
            c5 -= frows[k, 5]
    for k in range(sstart[i], sstop[i]):
        if free[snbr[k]] == 0.0:
            c0 -= swts[k]
            c3 -= swts[k]
            c5 -= swts[k]
    return c0, c1, c2, c3, c4, c5


@njit(cache=True, nogil=True, inline="always")
def _row_translation(i, slots, bdiag6, free, touched):
    """C_i of `_translation_block`: B_i itself on a row no pin touches (the slots are read,
    and unpacked, only on the few that one does)."""
    if touched[i]:
        return _translation_block(i, slots, bdiag6, free)
    return (bdiag6[i, 0], bdiag6[i, 1], bdiag6[i, 2], bdiag6[i, 3], bdiag6[i, 4],
            bdiag6[i, 5])


@njit(cache=True, nogil=True, parallel=True)
def translation_system(fine, slots, bdiag6, free, touched, r):
    """The Galerkin system of a common translation t of the free rows: (9,) the packed
    T^T A T (six numbers) and T^T r (three), summed per chunk of `fine` in chunk order."""
    ranges = fine.shape[0] - 1
    partial = np.zeros((ranges, 9))
    for k in prange(ranges):
        a0 = a1 = a2 = a3 = a4 = a5 = g0 = g1 = g2 = 0.0
        for i in range(fine[k], fine[k + 1]):
            if free[i] == 0.0:
                continue
            c0, c1, c2, c3, c4, c5 = _row_translation(i, slots, bdiag6, free, touched)
            a0 += c0
            a1 += c1
            a2 += c2
            a3 += c3
            a4 += c4
            a5 += c5
            g0 += r[i, 0]
            g1 += r[i, 1]
            g2 += r[i, 2]
        partial[k, 0] = a0
        partial[k, 1] = a1
        partial[k, 2] = a2
        partial[k, 3] = a3
        partial[k, 4] = a4
        partial[k, 5] = a5
        partial[k, 6] = g0
        partial[k, 7] = g1
        partial[k, 8] = g2
    return _column_sums(partial)


@njit(cache=True, nogil=True)
def solve_spd3(g, t):
    """t (3,) = G^-1 g[6:9] for the symmetric G packed in g[:6] (xx, xy, xz, yy, yz, zz), by
    its Cholesky factor; returns False (t untouched) where G is not positive definite or a
    number is not finite."""
    for a in range(9):
        if not np.isfinite(g[a]):
            return False
    if not g[0] > 0.0:
        return False
    l00 = np.sqrt(g[0])
    l10 = g[1] / l00
    l20 = g[2] / l00
    d1 = g[3] - l10 * l10
    if not d1 > 0.0:
        return False
    l11 = np.sqrt(d1)
    l21 = (g[4] - l20 * l10) / l11
    d2 = g[5] - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return False
    l22 = np.sqrt(d2)
    y0 = g[6] / l00
    y1 = (g[7] - l10 * y0) / l11
    y2 = (g[8] - l20 * y0 - l21 * y1) / l22
    t[2] = y2 / l22
    t[1] = (y1 - l21 * t[2]) / l11
    t[0] = (y0 - l10 * t[1] - l20 * t[2]) / l00
    return True


@njit(cache=True, nogil=True, parallel=True)
def translate_rows(fine, slots, bdiag6, free, touched, t, x, r):
    """x += t and r -= A t (C_i t, `_translation_block`) on the free rows, t (3,); returns
    |r|^2 (summed per chunk in chunk order)."""
    ranges = fine.shape[0] - 1
    partial = np.zeros(ranges)
    t0 = t[0]
    t1 = t[1]
    t2 = t[2]
    for k in prange(ranges):
        s = 0.0
        for i in range(fine[k], fine[k + 1]):
            if free[i] == 0.0:
                continue
            c0, c1, c2, c3, c4, c5 = _row_translation(i, slots, bdiag6, free, touched)
            x[i, 0] += t0
            x[i, 1] += t1
            x[i, 2] += t2
            r0 = r[i, 0] - (c0 * t0 + c1 * t1 + c2 * t2)
            r1 = r[i, 1] - (c1 * t0 + c3 * t1 + c4 * t2)
            r2 = r[i, 2] - (c2 * t0 + c4 * t1 + c5 * t2)
            r[i, 0] = r0
            r[i, 1] = r1
            r[i, 2] = r2
            s += r0 * r0 + r1 * r1 + r2 * r2
        partial[k] = s
    return ordered_sum(partial)


# -- rotations --------------------------------------------------------------------------------
@njit(cache=True, nogil=True, inline="always")
def _sym_cross(s0, s1, s2, s3, s4, s5, x0, x1, x2):
    """S (e_a x X) for a = 0, 1, 2, S the symmetric block (s0..s5: xx, xy, xz, yy, yz, zz)
    and X = (x0, x1, x2): nine numbers, column a's three after column a-1's."""
    # e_0 x X = (0, -x2, x1), e_1 x X = (x2, 0, -x0), e_2 x X = (-x1, x0, 0)
    return (-s1 * x2 + s2 * x1, -s3 * x2 + s4 * x1, -s4 * x2 + s5 * x1,
            s0 * x2 - s2 * x0, s1 * x2 - s4 * x0, s2 * x2 - s5 * x0,
            -s0 * x1 + s1 * x0, -s1 * x1 + s3 * x0, -s2 * x1 + s4 * x0)


@njit(cache=True, nogil=True)
def _pinned_rotation(i, slots, free, X, u):
    """u (nine numbers, as `_sym_cross`) less the pinned neighbours' G_ij (e_a x X_j), for a
    row a pin touches (the slots are read, and unpacked, only on those)."""
    fstart, _, fstop, fnbr, frows, sstart, _, sstop, snbr, swts = slots
    for k in range(fstart[i], fstop[i]):
        j = fnbr[k]
        if free[j] == 0.0:
            g = _sym_cross(frows[k, 0], frows[k, 1], frows[k, 2], frows[k, 3], frows[k, 4],
                           frows[k, 5], X[j, 0], X[j, 1], X[j, 2])
            u = (u[0] - g[0], u[1] - g[1], u[2] - g[2], u[3] - g[3], u[4] - g[4],
                 u[5] - g[5], u[6] - g[6], u[7] - g[7], u[8] - g[8])
    for k in range(sstart[i], sstop[i]):
        j = snbr[k]
        if free[j] == 0.0:
            w = swts[k]
            g = _sym_cross(w, 0.0, 0.0, w, 0.0, w, X[j, 0], X[j, 1], X[j, 2])
            u = (u[0] - g[0], u[1] - g[1], u[2] - g[2], u[3] - g[3], u[4] - g[4],
                 u[5] - g[5], u[6] - g[6], u[7] - g[7], u[8] - g[8])
    return u


@njit(cache=True, nogil=True, inline="always")
def _rotation_columns(i, slots, bdiag6, free, touched, X, q):
    """(A r_a)_i for the rotations r_a = e_a x X of the free rows, a = 0, 1, 2 (nine
    numbers, as `_sym_cross`): B_i (e_a x X_i) + e_a x q_i, less the pinned neighbours'
    G_ij (e_a x X_j) on a row a pin touches."""
    c = _sym_cross(bdiag6[i, 0], bdiag6[i, 1], bdiag6[i, 2], bdiag6[i, 3], bdiag6[i, 4],
                   bdiag6[i, 5], X[i, 0], X[i, 1], X[i, 2])
    q0 = q[i, 0]
    q1 = q[i, 1]
    q2 = q[i, 2]
    u = (c[0], c[1] - q2, c[2] + q1, c[3] + q2, c[4], c[5] - q0, c[6] - q1, c[7] + q0, c[8])
    if touched[i]:
        return _pinned_rotation(i, slots, free, X, u)
    return u


@njit(cache=True, nogil=True, inline="always")
def _cross_dot(x0, x1, x2, v0, v1, v2):
    """((e_a x X) . v for a = 0, 1, 2), that is X x v."""
    return x1 * v2 - x2 * v1, x2 * v0 - x0 * v2, x0 * v1 - x1 * v0


@njit(cache=True, nogil=True, parallel=True)
def rigid_system(fine, slots, bdiag6, free, touched, X, q, r):
    """The Galerkin system of a rigid motion of the free rows (the translations, then the
    rotations e_a x X): (30,) the translations' block T_t^T A T_t packed as six numbers
    (xx, xy, xz, yy, yz, zz), the coupling T_t^T A T_r (3 x 3, row-major), the rotations'
    block T_r^T A T_r (3 x 3, row-major; symmetric up to the approximation, symmetrise it)
    and T^T r (six), summed per chunk of `fine` in chunk order. X (n_0, 3): the rows'
    positions less a centre, m; q (n_0, 3): hess_scale times the elastic gradient there.
    (Thirty sums in locals: in an array they cost ten times the time.)"""
    ranges = fine.shape[0] - 1
    partial = np.zeros((ranges, 30))
    for k in prange(ranges):
        t0 = t1 = t2 = t3 = t4 = t5 = 0.0
        c00 = c01 = c02 = c10 = c11 = c12 = c20 = c21 = c22 = 0.0
        r00 = r01 = r02 = r10 = r11 = r12 = r20 = r21 = r22 = 0.0
        g0 = g1 = g2 = g3 = g4 = g5 = 0.0
        for i in range(fine[k], fine[k + 1]):
            if free[i] == 0.0:
                continue
            c = _row_translation(i, slots, bdiag6, free, touched)
            t0, t1, t2 = t0 + c[0], t1 + c[1], t2 + c[2]
            t3, t4, t5 = t3 + c[3], t4 + c[4], t5 + c[5]
            u = _rotation_columns(i, slots, bdiag6, free, touched, X, q)
            x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
            # the coupling: component a of column b
            c00, c10, c20 = c00 + u[0], c10 + u[1], c20 + u[2]
            c01, c11, c21 = c01 + u[3], c11 + u[4], c21 + u[5]
            c02, c12, c22 = c02 + u[6], c12 + u[7], c22 + u[8]
            # the rotations' block: (e_a x X_i) . column b
            d0, d1, d2 = _cross_dot(x0, x1, x2, u[0], u[1], u[2])
            r00 += d0
            r10 += d1
            r20 += d2
            d0, d1, d2 = _cross_dot(x0, x1, x2, u[3], u[4], u[5])
            r01 += d0
            r11 += d1
            r21 += d2
            d0, d1, d2 = _cross_dot(x0, x1, x2, u[6], u[7], u[8])
            r02 += d0
            r12 += d1
            r22 += d2
            ri0, ri1, ri2 = r[i, 0], r[i, 1], r[i, 2]
            g0, g1, g2 = g0 + ri0, g1 + ri1, g2 + ri2
            d0, d1, d2 = _cross_dot(x0, x1, x2, ri0, ri1, ri2)
            g3 += d0
            g4 += d1
            g5 += d2
        sums = (t0, t1, t2, t3, t4, t5, c00, c01, c02, c10, c11, c12, c20, c21, c22,
                r00, r01, r02, r10, r11, r12, r20, r21, r22, g0, g1, g2, g3, g4, g5)
        for a in range(30):
            partial[k, a] = sums[a]
    return _column_sums(partial)


@njit(cache=True, nogil=True)
def solve_spd(g, rhs, out):
    """out = G^-1 rhs for a small symmetric G (k, k) by its Cholesky factor; returns False
    (out untouched) where G is not positive definite or a number is not finite."""
    k = g.shape[0]
    low = np.zeros((k, k))
    for a in range(k):
        if not np.isfinite(rhs[a]):
            return False
        for b in range(a + 1):
            s = g[a, b]
            if not np.isfinite(s):
                return False
            for c in range(b):
                s -= low[a, c] * low[b, c]
            if a == b:
                if not s > 0.0:
                    return False
                low[a, a] = np.sqrt(s)
            else:
                low[a, b] = s / low[b, b]
    y = np.zeros(k)
    for a in range(k):
        s = rhs[a]
        for c in range(a):
            s -= low[a, c] * y[c]
        y[a] = s / low[a, a]
    for a in range(k - 1, -1, -1):
        s = y[a]
        for c in range(a + 1, k):
            s -= low[c, a] * out[c]
        out[a] = s / low[a, a]
    return True


@njit(cache=True, nogil=True, parallel=True)
def rigid_shift(fine, free, X, c, x):
    """x_i += t + w x X_i on the free rows, c = (t, w) (6,)."""
    ranges = fine.shape[0] - 1
    for k in prange(ranges):
        for i in range(fine[k], fine[k + 1]):
            if free[i] == 0.0:
                continue
            x[i, 0] += c[0] + c[4] * X[i, 2] - c[5] * X[i, 1]
            x[i, 1] += c[1] + c[5] * X[i, 0] - c[3] * X[i, 2]
            x[i, 2] += c[2] + c[3] * X[i, 1] - c[4] * X[i, 0]


@njit(cache=True, nogil=True, parallel=True)
def rotation_rows(fine, order, positions, forces, scale, X, q):
    """The finest level's rows of X = positions less their mean (m) and q = -scale * forces,
    from vertex-ordered positions and forces (n_0, 3); `order`: the vertex of each row. (The
    mean by numpy's axis reduction took 0.29 ms at 20K particles.)"""
    ranges = fine.shape[0] - 1
    n = positions.shape[0]
    partial = np.zeros((ranges, 3))
    for k in prange(ranges):
        s0 = s1 = s2 = 0.0
        for i in range(fine[k], fine[k + 1]):
            v = order[i]
            s0 += positions[v, 0]
            s1 += positions[v, 1]
            s2 += positions[v, 2]
        partial[k, 0] = s0
        partial[k, 1] = s1
        partial[k, 2] = s2
    center = _column_sums(partial)
    for a in range(3):
        center[a] /= max(n, 1)
    for k in prange(ranges):
        for i in range(fine[k], fine[k + 1]):
            v = order[i]
            for a in range(3):
                X[i, a] = positions[v, a] - center[a]
                q[i, a] = -scale * forces[v, a]


def rigid_matrix(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(G (6, 6), rhs (6,)) from `rigid_system`'s 30 numbers, the rotations' block
    symmetrised (where the rotation formula approximates, its two halves differ a little)."""
    g = np.empty((6, 6))
    tt = s[:6]
    g[:3, :3] = [[tt[0], tt[1], tt[2]], [tt[1], tt[3], tt[4]], [tt[2], tt[4], tt[5]]]
    tr = s[6:15].reshape(3, 3)
    g[:3, 3:] = tr
    g[3:, :3] = tr.T
    rr = s[15:24].reshape(3, 3)
    g[3:, 3:] = 0.5 * (rr + rr.T)
    return g, s[24:30].copy()


# -- the guesses ------------------------------------------------------------------------------
def translation_guess(pk: PackedLevels, touched: np.ndarray, r: np.ndarray
                      ) -> np.ndarray | None:
    """The common translation t (3,) of the free particles that takes most A-norm error out
    of the first guess whose residual is r (n_0, 3) (a Galerkin projection onto the three
    translations, T^T A T t = T^T r; touched: packed_kernels.touched_rows), or None where
    there is none (no free particle, a system not positive there). Two passes over the
    diagonal blocks: 0.13 ms at 20K particles."""
    g = translation_system(pk.fine_chunks, pk.slots, pk.bdiag6, pk.free, touched, r)
    t = np.zeros(3)
    return t if solve_spd3(g, t) else None


def rigid_guess(pk: PackedLevels, touched: np.ndarray, r: np.ndarray,
                rotation: RotationTerms, hess_scale: float) -> np.ndarray | None:
    """The rigid motion c = (t, w) (6,) of the free particles (x_i += t + w x X_i) that takes
    most A-norm error out of the first guess whose residual is r (n_0, 3): a Galerkin
    projection onto the three translations and the three rotations about the particles'
    mean, whose products with A come from `rotation` (module docstring). None where there
    is none (no free particle, sizes that do not match, a system not positive there).
    Leaves the rows' X in pk.rigid_rows[0] for `rigid_shift`."""
    n0 = int(pk.voff[1])
    positions, forces = rotation.positions, rotation.forces
    if positions.shape != (n0, 3) or forces.shape != (n0, 3):
        return None
    X, q = pk.rigid_rows
    rotation_rows(pk.fine_chunks, pk.orderings[0].order, positions, forces,
                  float(hess_scale), X, q)
    g, rhs = rigid_matrix(rigid_system(pk.fine_chunks, pk.slots, pk.bdiag6, pk.free, touched,
                                       X, q, r))
    c = np.zeros(6)
    return c if solve_spd(g, rhs, c) else None
