"""The top, a T-shirt: the offset surface of a smooth union of torso and upper-arm capsules,
cut at the hem, the neck and across the upper arms; meshed by marching tetrahedra, remeshed
isotropically to the exact vertex count the hierarchy needs, pinned at the shoulders."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.collision.capsules import point_segment_distances
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.body import body_arrays
from cloth_mg_ros.mesh.garments.design import Design, boundary_loops, choose_depth
from cloth_mg_ros.mesh.garments.isosurface import clean_open_mesh, marching_tets
from cloth_mg_ros.mesh.garments.remesh import Remesher
from cloth_mg_ros.mesh.hierarchy import subdivided_counts

TOP_MARGIN = 0.02  # m beyond the clearance: ease (slack) so the body can move inside the top
_TOP_BLEND = 0.02  # m, smooth-union radius of the top's capsules (armpits, shoulders)

@dataclass
class TopShape:
    """The top's implicit surface phi = smooth-min of capsule distances - offset, and the
    four cuts that open it (hem, neck, two sleeve ends). A cut c has a removal function
    g_c > 0 inside the removed region; the garment is phi = 0 where every g_c <= 0."""

    p0: np.ndarray
    p1: np.ndarray
    r: np.ndarray
    offset: float
    blend: float
    z_hem: float
    neck_point: np.ndarray
    neck_dir: np.ndarray
    r_neck: float
    arm_p0: np.ndarray   # (2, 3)
    arm_dir: np.ndarray  # (2, 3)
    s_end: np.ndarray    # (2,)
    r_cut: np.ndarray    # (2,)

    def phi(self, x: np.ndarray) -> np.ndarray:
        d = point_segment_distances(x, self.p0, self.p1) - self.r[None, :]
        acc, k = d[:, 0], self.blend
        for i in range(1, d.shape[1]):
            b = d[:, i]
            h = np.maximum(k - np.abs(acc - b), 0.0) / k
            acc = np.minimum(acc, b) - 0.25 * k * h * h
        return acc - self.offset

    def grad(self, x: np.ndarray, eps: float = 1e-5) -> np.ndarray:
        g = np.empty_like(x)
        for k in range(3):
            e = np.zeros(3)
            e[k] = eps
            g[:, k] = (self.phi(x + e) - self.phi(x - e)) / (2.0 * eps)
        return g

    def _neck_radial(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = x - self.neck_point
        along = w @ self.neck_dir
        return along, np.linalg.norm(w - along[:, None] * self.neck_dir, axis=1)

    def cuts(self, x: np.ndarray) -> np.ndarray:
        """(n, 4) removal functions [hem, neck, sleeve left, sleeve right]."""
        out = np.empty((len(x), 4))
        out[:, 0] = self.z_hem - x[:, 2]
        along, radial = self._neck_radial(x)
        out[:, 1] = np.minimum(self.r_neck - radial, along)
        for k in range(2):
            w = x - self.arm_p0[k]
            s = w @ self.arm_dir[k]
            radial = np.linalg.norm(w - s[:, None] * self.arm_dir[k], axis=1)
            out[:, 2 + k] = np.minimum(s - self.s_end[k], self.r_cut[k] - radial)
        return out

    def curve_values(self, x: np.ndarray) -> np.ndarray:
        """(n, 4) the smooth surfaces the boundary curves lie on (zero there)."""
        out = np.empty((len(x), 4))
        out[:, 0] = self.z_hem - x[:, 2]
        out[:, 1] = self.r_neck - self._neck_radial(x)[1]
        for k in range(2):
            out[:, 2 + k] = (x - self.arm_p0[k]) @ self.arm_dir[k] - self.s_end[k]
        return out

    def psi(self, x: np.ndarray) -> np.ndarray:
        return np.maximum(self.phi(x), self.cuts(x).max(axis=1))

    def sizing(self, x: np.ndarray) -> np.ndarray:
        """(n,) relative edge length wanted at x: 1 on the body, 0.8 on the sleeves (their
        tighter curvature), blended over 4 cm."""
        d = point_segment_distances(x, self.p0, self.p1) - self.r[None, :]
        w = np.clip((d[:, :3].min(axis=1) - d[:, 3:].min(axis=1)) / 0.04 + 0.5, 0.0, 1.0)
        return 1.0 - 0.2 * w

    def project(self, x: np.ndarray, iters: int = 4) -> np.ndarray:
        """Newton steps onto phi = 0."""
        for _ in range(iters):
            g = self.grad(x)
            x = x - (self.phi(x) / np.maximum(np.einsum('ij,ij->i', g, g), 1e-12))[:, None] * g
        return x

    def project_curve(self, x: np.ndarray, cut: np.ndarray, iters: int = 6) -> np.ndarray:
        """Alternating projections onto phi = 0 and the boundary's cut surface."""
        for _ in range(iters):
            x = self.project(x, 2)
            hem = cut == 0
            x[hem, 2] = self.z_hem
            neck = cut == 1
            if neck.any():
                w = x[neck] - self.neck_point
                along = w @ self.neck_dir
                rad = w - along[:, None] * self.neck_dir
                norm = np.maximum(np.linalg.norm(rad, axis=1, keepdims=True), 1e-12)
                x[neck] = self.neck_point + along[:, None] * self.neck_dir + rad * (
                    self.r_neck / norm)
            for k in range(2):
                m = cut == 2 + k
                if m.any():
                    s = (x[m] - self.arm_p0[k]) @ self.arm_dir[k] - self.s_end[k]
                    x[m] -= s[:, None] * self.arm_dir[k]
        return x


def top_shape(d: Design, clearance: float) -> TopShape:
    body = d.body
    blend_names = ['pelvis', 'lower_torso', 'upper_torso', 'upper_arm_l', 'upper_arm_r']
    _, p0, p1, r = body_arrays(body, blend_names)
    offset = clearance + TOP_MARGIN
    k = _TOP_BLEND
    pelvis = body['pelvis']
    z_hem = 0.5 * (pelvis[0][2] + pelvis[1][2])
    head = body['head']
    neck_dir = head[1] - head[0]
    neck_dir = neck_dir / max(float(np.linalg.norm(neck_dir)), 1e-12)
    ut0, ut1, ut_r = body['upper_torso']
    collar = ut1 if ut1[2] >= ut0[2] else ut0
    r_neck = head[2] + clearance + 0.02
    if r_neck > ut_r + offset - 0.02:
        raise ClothInputError(
            f"top: the head (radius {head[2]:.3f} m) is too wide for a neck opening in a top "
            f"around 'upper_torso' (radius {ut_r:.3f} m)")
    torso_names = ['pelvis', 'lower_torso', 'upper_torso']
    _, t0, t1, tr = body_arrays(body, torso_names)
    arm_p0, arm_dir, s_end, r_cut = [], [], [], []
    for side in ('l', 'r'):
        a0, a1, ar = body[f'upper_arm_{side}']
        # The shoulder end is the one nearer the upper torso's axis.
        if (point_segment_distances(a1[None], ut0[None], ut1[None])[0, 0]
                < point_segment_distances(a0[None], ut0[None], ut1[None])[0, 0]):
            a0, a1 = a1, a0
        length = float(np.linalg.norm(a1 - a0))
        u = (a1 - a0) / max(length, 1e-12)
        # The sleeve end is cut by a cylinder of radius rc around the arm; it must stay off the
        # torso's surface, so the arm needs a gap `need` (axis to torso capsule surfaces,
        # minus the arm radius) everywhere below the sleeve end.
        rc = ar + offset + 0.25 * k + 0.004
        need = 2.0 * offset + 0.25 * k + 0.012
        s = np.linspace(0.0, length + ar, 80)
        gap = (point_segment_distances(a0 + s[:, None] * u, t0, t1) - tr).min(axis=1) - ar
        tight = np.flatnonzero(gap < need)
        s_min = 0.0 if len(tight) == 0 else float(s[min(tight[-1] + 1, len(s) - 1)])
        if len(tight) and (tight[-1] == len(s) - 1 or s_min > 0.95 * length):
            at = int(np.searchsorted(s, 0.95 * length))
            raise ClothInputError(
                f"top: 'upper_arm_{side}' hangs too close to the torso for a sleeve: the gap "
                f"between the arm and the torso capsules must reach {need:.3f} m above the "
                f"elbow (it is {gap[at]:.3f} m at 95% of the upper arm's length); hold the arms "
                f"further away from the body")
        arm_p0.append(a0)
        arm_dir.append(u)
        s_end.append(min(max(0.5 * length, s_min + 0.01), 0.97 * length))
        r_cut.append(rc)
    return TopShape(p0, p1, r, offset, k, float(z_hem), collar, neck_dir, float(r_neck),
                     np.array(arm_p0), np.array(arm_dir), np.array(s_end), np.array(r_cut))


def _top_initial_mesh(shape: TopShape, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Marching tetrahedra of the top's solid, cut faces removed: the open top surface."""
    pad = shape.offset + shape.blend + 2.0 * step
    ends = np.concatenate([shape.p0, shape.p1])
    radii = np.concatenate([shape.r, shape.r])
    lo = (ends - radii[:, None]).min(axis=0) - pad
    hi = (ends + radii[:, None]).max(axis=0) + pad
    lo[2] = max(lo[2], shape.z_hem - 2.0 * step)
    dims = tuple(math.ceil((hi[k] - lo[k]) / step) + 1 for k in range(3))
    verts, faces = marching_tets(shape.psi, lo, step, dims)
    cen = verts[faces].mean(axis=1)
    keep = shape.phi(cen) >= shape.cuts(cen).max(axis=1)
    verts, faces = clean_open_mesh(verts, faces[keep])
    # Faces straddling a cut can leave small spurious holes: keep, per cut, the longest loop
    # lying on it and close every other loop with a fan around a new vertex.
    loops = boundary_loops(faces)
    owner = [int(np.bincount(np.argmin(np.abs(shape.curve_values(verts[lp])), axis=1),
                             minlength=4).argmax()) for lp in loops]
    openings = {c: next((i for i, o in enumerate(owner) if o == c), -1) for c in range(4)}
    if -1 in openings.values():
        raise ClothInputError('top: the garment surface does not reach one of its openings '
                              '(hem, neck or sleeve ends); the body is unsuitable for a top')
    extra_v, extra_f = [], []
    for i, lp in enumerate(loops):
        if i in openings.values():
            continue
        centre = len(verts) + len(extra_v)
        extra_v.append(shape.project(verts[lp].mean(axis=0)[None])[0])
        extra_f += [(int(b), int(a), centre) for a, b in zip(lp, np.roll(lp, -1), strict=True)]
    if extra_v:
        verts = np.concatenate([verts, np.array(extra_v)])
        faces = np.concatenate([faces, np.array(extra_f, dtype=np.int64)])
    return verts, faces


def remesh_top(shape: TopShape, verts: np.ndarray, faces: np.ndarray, length: float,
                n_target: Callable[[int], int], iters: int = 8
                ) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic remeshing to edge length `length`, then interior splits/collapses until the
    vertex count is n_target(boundary vertex count), then flips and smoothing."""
    rm = Remesher(verts, faces, shape)
    lo, hi = 0.8 * length, 4.0 / 3.0 * length
    for _ in range(iters):
        rm.split_long(hi)
        rm.collapse_short(lo, hi)
        rm.flip_all()
        rm.relax(2)
    n_border = sum(1 for v, c in zip(rm.valive, rm.vcut, strict=True) if v and c >= 0)
    goal = n_target(n_border)
    for _ in range(20):
        n = rm.n_vertices
        if n == goal:
            break
        e, length_e = rm.scaled_lengths()
        interior = np.array([len(rm.vf[a] & rm.vf[b]) == 2 for a, b in e.tolist()])
        if n > goal:
            need = n - goal
            for k in np.argsort(length_e):
                if need == 0:
                    break
                a, b = int(e[k, 0]), int(e[k, 1])
                if interior[k] and rm.valive[a] and rm.valive[b] and \
                        len(rm.vf[a] & rm.vf[b]) == 2 and rm.try_collapse(a, b, 1.6 * length):
                    need -= 1
        else:
            need = goal - n
            touched: set[int] = set()
            for k in np.argsort(-length_e):
                if need == 0:
                    break
                a, b = int(e[k, 0]), int(e[k, 1])
                if interior[k] and not ({a, b} & touched) and len(rm.vf[a] & rm.vf[b]) == 2:
                    touched.update((a, b, rm.split(a, b)))
                    need -= 1
        rm.flip_all()
        rm.relax(2)
    for _ in range(3):
        rm.flip_all()
        rm.relax(2)
    v, f, _ = rm.arrays()
    return v, f


def _top_pins(d: Design, rest: np.ndarray, per_side: int = 3) -> np.ndarray:
    """The coarse vertices nearest the middle of each shoulder, on its top side."""
    body = d.body
    ut0, ut1, _ = body['upper_torso']
    neck = ut1 if ut1[2] >= ut0[2] else ut0
    out = []
    for side in ('l', 'r'):
        sh = body[f'upper_arm_{side}'][0]
        mid = 0.5 * (neck + sh)
        cand = np.flatnonzero(rest[:, 2] > sh[2])
        if len(cand) < per_side:
            cand = np.arange(len(rest))
        dist = np.linalg.norm((rest[cand] - mid)[:, :2], axis=1)
        out.append(cand[np.argsort(dist)[:per_side]])
    return np.sort(np.concatenate(out))


def _top_counts(n: int, n_border: int, depth: int) -> int:
    """Finest vertex count of a top (sphere with 4 holes, Euler characteristic -2) with n
    coarse vertices, n_border of them on the boundary."""
    t = 2 * n - n_border + 4
    return subdivided_counts(n, n + t + 2, t, depth)[0]


_MAX_TOP_COARSE = 4000   # the top's remeshing runs in Python: refuse huge coarse meshes
_MIN_TOP_COARSE = 80     # fewer coarse vertices cannot shape the sleeves


def build_top(d: Design, clearance: float, target: int, depth: int | None
               ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest, faces), depth and pins of the top."""
    shape = top_shape(d, clearance)
    border_guess = 60  # boundary vertices of a typical coarse top (only to pick the depth)

    def coarse_for(dd: int) -> int:
        return max(1, round((target + (4 ** dd - 1) * border_guess / 2) / 4 ** dd))

    dd = choose_depth('top', target, depth, coarse_for)
    n_c = coarse_for(dd)
    if n_c < _MIN_TOP_COARSE:
        raise ClothInputError(
            f'n_particles={target} is too small for a top at depth={dd}: its coarse mesh '
            f'would have {n_c} vertices (at least {_MIN_TOP_COARSE} needed)')
    if n_c > _MAX_TOP_COARSE:
        raise ClothInputError(
            f'n_particles={target} at depth={dd} needs a coarse top of {n_c} vertices (at '
            f'most {_MAX_TOP_COARSE}): use a larger depth or depth=None')
    for step in (0.03, 0.02, 0.0125):
        verts, faces = _top_initial_mesh(shape, step)
        n_edges = len(np.unique(np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1),
                                axis=0))
        if len(verts) - n_edges + len(faces) == -2 and len(boundary_loops(faces)) == 4:
            break
    else:
        raise ClothInputError(
            'top: the body leaves no clean surface for a top (the sleeves touch the torso or '
            'the neck opening touches the sleeves)')
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    # Equivalent area in units of the wanted local size: sleeves get 0.8x shorter edges.
    area_eq = float((area / shape.sizing(tri.mean(axis=1)) ** 2).sum())
    length = math.sqrt(4.0 * area_eq / (math.sqrt(3.0) * 2.0 * n_c)) * 1.03

    def goal(n_border: int) -> int:
        cand = np.arange(max(10, n_c // 2), 2 * n_c + 10)
        counts = np.array([_top_counts(int(c), n_border, dd) for c in cand])
        return int(cand[np.argmin(np.abs(np.log(counts / target)))])

    rest, faces = remesh_top(shape, verts, faces, length, goal)
    return rest, faces, dd, {'upper_torso': _top_pins(d, rest)}
