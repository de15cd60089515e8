"""Numba kernels of the mesh collider (`mesh_collider.py`), and `surface_distances`.

Holds the median-split bounding-volume hierarchy over triangles (`_build_bvh`, built for a
triangle set by `triangle_bvh`), the closest point on a triangle (Ericson's test,
`_closest_on_triangle`) and the BVH descent that finds every point's closest triangle
(`closest_kernel`, with the box distance `_box_d2`), the first crossing of segments with the
triangles (Moeller-Trumbore, `segment_kernel`), and the one-pass culling of particles against
a mesh's local bounding box and voxel grid (`select_kernel`, `_voxel_of`).
`surface_distances` (unsigned distances from points to any triangle soup) uses the same BVH
and descent. Every numba function is ``@njit(cache=True, nogil=True)``; the two pieces of
`segment_kernel` (`_segment_meets_box`, `_segment_crossing`) are also ``inline="always"``:
numba inlines them into the kernel's loop, where a call per node and per triangle would
slow it down.

Units SI: lengths in m. Arrays are float64 / int64, C-contiguous. Shapes: triangles tri
(f, 3, 3) (face, corner, xyz); points (m, 3); the BVH is the tuple (lo, hi (nodes, 3) node
boxes, left, right (nodes,) children (-1 at leaves), start, count (nodes,) each leaf's range in
order, order (f,) faces in leaf order), node 0 the root. Closest-point feature codes
(``_FEATURES`` of them): 0 inside the face, 1 + j on edge j (v_j -> v_j+1), 4 + k at vertex k.
The voxel grid: origin (3,) m, pitch m, shape (3,) voxels, per voxel (flat C order) side
(+1 outside, -1 inside, 0 unknown) and a distance lower bound (m). Kernels write their
results into the caller's out_* arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["surface_distances"]

# Triangles per BVH leaf.
_LEAF = 4
# Depth of the traversal stacks (the BVH is balanced: depth ~ log2(faces / _LEAF)).
_STACK = 256
# Flags of select_kernel: may be within the margin or inside; path may cross the surface.
_NEAR = 1
_PATH = 2
# Closest-point features: 0 inside the face, 1 + j on edge j (v_j -> v_j+1), 4 + k at vertex k.
_FEATURES = 7


def triangle_bvh(tri: np.ndarray) -> tuple:
    """The BVH arrays over triangles (f, 3, 3) m that closest_kernel descends."""
    pad = 1e-9 * float(np.abs(tri).max())  # boxes of flat triangles keep some thickness
    return _build_bvh(tri.min(axis=1) - pad, tri.max(axis=1) + pad, tri.mean(axis=1), _LEAF)


def surface_distances(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unsigned distance (m,) m from each point (m, 3) to the nearest of ``triangles``
    (f, 3, 3), any triangle soup (open cloth meshes too: no closedness needed). The same BVH
    and descent as the collider's, for comparing two cloth surfaces."""
    tri = np.ascontiguousarray(triangles, dtype=np.float64)
    p = np.ascontiguousarray(points, dtype=np.float64)
    bvh = triangle_bvh(tri)
    c = np.empty_like(p)
    face = np.empty(len(p), np.int64)
    feat = np.empty(len(p), np.int64)
    closest_kernel(p, tri, *bvh, c, face, feat)
    return np.linalg.norm(p - c, axis=1)


# -------------------------------------------------------------------- numba kernels


@njit(cache=True, nogil=True)
def _build_bvh(tlo, thi, cen, leaf):
    """Median-split BVH over triangles with boxes tlo, thi (f, 3) and centroids cen (f, 3).

    Returns (lo, hi (nodes, 3) node boxes, left, right (nodes,) children (-1 at leaves),
    start, count (nodes,) the leaf's range in order, order (f,) faces in leaf order); node 0
    is the root.
    """
    nf = tlo.shape[0]
    cap = 2 * nf
    lo = np.empty((cap, 3))
    hi = np.empty((cap, 3))
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    start = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    order = np.arange(nf)
    stack = np.empty(cap, np.int64)
    count[0] = nf
    n_nodes = 1
    stack[0] = 0
    sp = 1
    clo = np.empty(3)
    chi = np.empty(3)
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s = start[node]
        e = s + count[node]
        _fit_node(tlo, thi, cen, order, s, e, lo, hi, node, clo, chi)
        if e - s <= leaf:
            continue
        axis = 0
        for a in range(1, 3):
            if chi[a] - clo[a] > chi[axis] - clo[axis]:
                axis = a
        _sort_along(order, s, e, cen, axis)
        mid = (s + e) // 2
        lc = n_nodes
        rc = n_nodes + 1
        n_nodes += 2
        left[node] = lc
        right[node] = rc
        start[lc] = s
        count[lc] = mid - s
        start[rc] = mid
        count[rc] = e - mid
        stack[sp] = lc
        stack[sp + 1] = rc
        sp += 2
    return (lo[:n_nodes].copy(), hi[:n_nodes].copy(), left[:n_nodes].copy(),
            right[:n_nodes].copy(), start[:n_nodes].copy(), count[:n_nodes].copy(), order)


@njit(cache=True, nogil=True)
def _fit_node(tlo, thi, cen, order, s, e, lo, hi, node, clo, chi):
    """The box of a node (lo, hi) around the boxes of its faces order[s:e], and the box of
    their centroids (clo, chi)."""
    for a in range(3):
        lo[node, a] = np.inf
        hi[node, a] = -np.inf
        clo[a] = np.inf
        chi[a] = -np.inf
    for q in range(s, e):
        f = order[q]
        for a in range(3):
            lo[node, a] = min(lo[node, a], tlo[f, a])
            hi[node, a] = max(hi[node, a], thi[f, a])
            clo[a] = min(clo[a], cen[f, a])
            chi[a] = max(chi[a], cen[f, a])


@njit(cache=True, nogil=True)
def _sort_along(order, s, e, cen, axis):
    """Sort the faces order[s:e] by their centroids' coordinate `axis` (stable)."""
    sub = order[s:e].copy()
    keys = np.empty(e - s)
    for q in range(e - s):
        keys[q] = cen[sub[q], axis]
    srt = np.argsort(keys, kind="mergesort")
    for q in range(e - s):
        order[s + q] = sub[srt[q]]


@njit(cache=True, nogil=True)
def _box_d2(p0, p1, p2, lo, hi, node):
    """Squared distance from point (p0, p1, p2) to the box of a node (0 inside)."""
    d = 0.0
    for a in range(3):
        v = p0 if a == 0 else (p1 if a == 1 else p2)
        if v < lo[node, a]:
            d += (lo[node, a] - v) ** 2
        elif v > hi[node, a]:
            d += (v - hi[node, a]) ** 2
    return d


@njit(cache=True, nogil=True)
def _closest_on_triangle(p0, p1, p2, t):
    """Closest point on triangle t (3, 3) to (p0, p1, p2) (Ericson, Real-Time Collision
    Detection 5.1.5): (x, y, z, feature), feature 0 inside the face, 1 + j on edge j
    (vertex j to j + 1), 4 + k at vertex k."""
    ax, ay, az = t[0, 0], t[0, 1], t[0, 2]
    abx, aby, abz = t[1, 0] - ax, t[1, 1] - ay, t[1, 2] - az
    acx, acy, acz = t[2, 0] - ax, t[2, 1] - ay, t[2, 2] - az
    apx, apy, apz = p0 - ax, p1 - ay, p2 - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 4
    bpx, bpy, bpz = p0 - t[1, 0], p1 - t[1, 1], p2 - t[1, 2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return t[1, 0], t[1, 1], t[1, 2], 5
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 1
    cpx, cpy, cpz = p0 - t[2, 0], p1 - t[2, 1], p2 - t[2, 2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return t[2, 0], t[2, 1], t[2, 2], 6
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 3
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (t[1, 0] + w * (t[2, 0] - t[1, 0]), t[1, 1] + w * (t[2, 1] - t[1, 1]),
                t[1, 2] + w * (t[2, 2] - t[1, 2]), 2)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (ax + v * abx + w * acx, ay + v * aby + w * acy, az + v * abz + w * acz, 0)


@njit(cache=True, nogil=True)
def closest_kernel(p, tri, lo, hi, left, right, start, count, order, out_c, out_face,
                    out_feat):
    """For every point of p (m, 3) the closest point on the triangles tri (f, 3, 3), through
    the BVH: writes out_c (m, 3), out_face (m,) and out_feat (m,) (feature code)."""
    stack = np.empty(_STACK, np.int64)
    for i in range(p.shape[0]):
        p0, p1, p2 = p[i, 0], p[i, 1], p[i, 2]
        best = np.inf
        bx = by = bz = 0.0
        bf = 0
        bt = 0
        stack[0] = 0
        sp = 1
        while sp > 0:
            sp -= 1
            node = stack[sp]
            if _box_d2(p0, p1, p2, lo, hi, node) >= best:
                continue
            if left[node] < 0:
                for q in range(start[node], start[node] + count[node]):
                    f = order[q]
                    cx, cy, cz, ft = _closest_on_triangle(p0, p1, p2, tri[f])
                    d2 = (p0 - cx) ** 2 + (p1 - cy) ** 2 + (p2 - cz) ** 2
                    if d2 < best:
                        best = d2
                        bx, by, bz, bf, bt = cx, cy, cz, f, ft
                continue
            lc = left[node]
            rc = right[node]
            dl = _box_d2(p0, p1, p2, lo, hi, lc)
            dr = _box_d2(p0, p1, p2, lo, hi, rc)
            if dl <= dr:  # nearer child on top: visited first
                if dr < best:
                    stack[sp] = rc
                    sp += 1
                if dl < best:
                    stack[sp] = lc
                    sp += 1
            else:
                if dl < best:
                    stack[sp] = lc
                    sp += 1
                if dr < best:
                    stack[sp] = rc
                    sp += 1
        out_c[i, 0] = bx
        out_c[i, 1] = by
        out_c[i, 2] = bz
        out_face[i] = bf
        out_feat[i] = bt


@njit(cache=True, nogil=True)
def segment_kernel(a, b, tri, lo, hi, left, right, start, count, order, out_t, out_face):
    """First crossing of each segment a -> b (m, 3) with the triangles tri (f, 3, 3)
    (Moeller-Trumbore, edges included): writes out_t (m,) in [0, 1] and out_face (m,) (-1
    where the segment crosses nothing)."""
    stack = np.empty(_STACK, np.int64)
    for i in range(a.shape[0]):
        o0, o1, o2 = a[i, 0], a[i, 1], a[i, 2]
        d0, d1, d2 = b[i, 0] - o0, b[i, 1] - o1, b[i, 2] - o2
        dlen = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        best = 2.0
        bf = -1
        stack[0] = 0
        sp = 1
        while sp > 0:
            sp -= 1
            node = stack[sp]
            # Only the segment's part [0, min(1, best)] can hold a nearer crossing.
            if not _segment_meets_box(o0, o1, o2, d0, d1, d2, min(1.0, best), lo, hi, node):
                continue
            if left[node] >= 0:
                stack[sp] = left[node]
                stack[sp + 1] = right[node]
                sp += 2
                continue
            for q in range(start[node], start[node] + count[node]):
                f = order[q]
                t = _segment_crossing(o0, o1, o2, d0, d1, d2, dlen, tri, f)
                if t < 0.0 or t > 1.0 or t >= best:
                    continue
                best = t
                bf = f
        out_t[i] = best if bf >= 0 else 1.0
        out_face[i] = bf


@njit(cache=True, nogil=True, inline="always")
def _segment_meets_box(o0, o1, o2, d0, d1, d2, tmax, lo, hi, node):
    """Whether the points o + t d, t in [0, tmax], meet the box of a node (slab test)."""
    tmin = 0.0
    for ax in range(3):
        o = o0 if ax == 0 else (o1 if ax == 1 else o2)
        d = d0 if ax == 0 else (d1 if ax == 1 else d2)
        if d == 0.0:
            if o < lo[node, ax] or o > hi[node, ax]:
                return False
        else:
            t1 = (lo[node, ax] - o) / d
            t2 = (hi[node, ax] - o) / d
            if t1 > t2:
                t1, t2 = t2, t1
            tmin = max(tmin, t1)
            tmax = min(tmax, t2)
            if tmin > tmax:
                return False
    return True


@njit(cache=True, nogil=True, inline="always")
def _segment_crossing(o0, o1, o2, d0, d1, d2, dlen, tri, f):
    """Parameter t of the point o + t d where the line of the segment (direction d, length
    dlen) crosses triangle f (Moeller-Trumbore, edges included); -1.0 when it runs parallel
    to the triangle's plane or passes beside the triangle."""
    eps = 1e-9
    v0, v1, v2 = tri[f, 0, 0], tri[f, 0, 1], tri[f, 0, 2]
    e10, e11, e12 = tri[f, 1, 0] - v0, tri[f, 1, 1] - v1, tri[f, 1, 2] - v2
    e20, e21, e22 = tri[f, 2, 0] - v0, tri[f, 2, 1] - v1, tri[f, 2, 2] - v2
    pv0 = d1 * e22 - d2 * e21
    pv1 = d2 * e20 - d0 * e22
    pv2 = d0 * e21 - d1 * e20
    det = e10 * pv0 + e11 * pv1 + e12 * pv2
    scale = dlen * np.sqrt((e10 * e10 + e11 * e11 + e12 * e12)
                           * (e20 * e20 + e21 * e21 + e22 * e22))
    if abs(det) <= 1e-12 * scale:
        return -1.0  # parallel to the triangle's plane
    inv = 1.0 / det
    s0, s1, s2 = o0 - v0, o1 - v1, o2 - v2
    u = (s0 * pv0 + s1 * pv1 + s2 * pv2) * inv
    if u < -eps or u > 1.0 + eps:
        return -1.0
    q0 = s1 * e12 - s2 * e11
    q1 = s2 * e10 - s0 * e12
    q2 = s0 * e11 - s1 * e10
    v = (d0 * q0 + d1 * q1 + d2 * q2) * inv
    if v < -eps or u + v > 1.0 + eps:
        return -1.0
    return (e20 * q0 + e21 * q1 + e22 * q2) * inv


@njit(cache=True, nogil=True)
def select_kernel(x, xp, use_prev, r, t, rp, tp, lo, hi, margin, origin, pitch, shape,
                   vox_side, vox_lb, out_idx, out_flag, out_xl, out_xpl):
    """Cull the particles x (n, 3) (world) against a mesh with local box lo, hi and voxel
    grid (origin, pitch m, shape (3,), per voxel side and distance lower bound), pose r, t.

    A particle is kept with flag _NEAR if it lies in the box grown by margin and its voxel is
    not outside and farther than margin; with use_prev, also with flag _PATH if its local path
    from xp (at the previous pose rp, tp) to x may cross the surface. Writes the kept
    particles' indices, flags and local positions now and before into out_*; returns their
    count.
    """
    m = 0
    q = np.empty(3)
    qp = np.empty(3)
    for i in range(x.shape[0]):
        for a in range(3):
            q[a] = ((x[i, 0] - t[0]) * r[0, a] + (x[i, 1] - t[1]) * r[1, a]
                    + (x[i, 2] - t[2]) * r[2, a])
        flag = 0
        inside_box = True
        for a in range(3):
            if not (q[a] >= lo[a] - margin and q[a] <= hi[a] + margin):  # NaN: not inside
                inside_box = False
                break
        if inside_box:
            flag = _NEAR
            flat = _voxel_of(q[0], q[1], q[2], origin, pitch, shape)
            if flat >= 0 and vox_side[flat] == 1 and vox_lb[flat] > margin:
                flag = 0
        if use_prev:
            moved = False
            for a in range(3):
                qp[a] = ((xp[i, 0] - tp[0]) * rp[0, a] + (xp[i, 1] - tp[1]) * rp[1, a]
                         + (xp[i, 2] - tp[2]) * rp[2, a])
                moved = moved or qp[a] != q[a]
            overlap = moved
            for a in range(3):
                if not (min(q[a], qp[a]) <= hi[a] and max(q[a], qp[a]) >= lo[a]):
                    overlap = False
            if overlap:
                half = 0.5 * np.sqrt((q[0] - qp[0]) ** 2 + (q[1] - qp[1]) ** 2
                                     + (q[2] - qp[2]) ** 2)
                flat = _voxel_of(0.5 * (q[0] + qp[0]), 0.5 * (q[1] + qp[1]),
                                 0.5 * (q[2] + qp[2]), origin, pitch, shape)
                # The path reaches the surface only if its midpoint is within half its length.
                if flat < 0 or vox_lb[flat] <= half:
                    flag |= _PATH
        if flag:
            out_idx[m] = i
            out_flag[m] = flag
            for a in range(3):
                out_xl[m, a] = q[a]
                out_xpl[m, a] = qp[a] if use_prev else q[a]
            m += 1
    return m


@njit(cache=True, nogil=True)
def _voxel_of(q0, q1, q2, origin, pitch, shape):
    """Flat (C order) index of the voxel holding local point (q0, q1, q2), -1 outside."""
    i = int(np.floor((q0 - origin[0]) / pitch))
    j = int(np.floor((q1 - origin[1]) / pitch))
    k = int(np.floor((q2 - origin[2]) / pitch))
    if i < 0 or j < 0 or k < 0 or i >= shape[0] or j >= shape[1] or k >= shape[2]:
        return -1
    return (i * shape[1] + j) * shape[2] + k

