"""What every garment shares: the garment names and size rules, the body as the designs see
it (`Design`: capsule arrays and a horizontal frame, ray casts around the torso axis), the
mesh helpers (boundary loops, normals), the depth policy and `finalise`, which builds the
multigrid hierarchy and pushes the coarse mesh out until every finest vertex clears the
body."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from cloth_mg_ros.collision.capsules import point_segment_distances
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.body import Capsule, body_arrays, ray_capsules
from cloth_mg_ros.mesh.generators import MAX_AUTO_DEPTH
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import MeshLevel

GARMENTS = ('skirt', 'dress', 'cape', 'top')

# Segments each garment's construction reads (the clearance check uses every segment given).
NEEDED_SEGMENTS = {
    'skirt': ('pelvis', 'lower_torso', 'upper_leg_l', 'upper_leg_r'),
    'dress': ('pelvis', 'lower_torso', 'upper_torso', 'upper_arm_l', 'upper_arm_r',
              'upper_leg_l', 'upper_leg_r', 'lower_leg_l', 'lower_leg_r'),
    'cape': ('pelvis', 'lower_torso', 'upper_torso', 'upper_arm_l', 'upper_arm_r',
             'upper_leg_l', 'upper_leg_r'),
    'top': ('pelvis', 'lower_torso', 'upper_torso', 'head', 'upper_arm_l', 'upper_arm_r'),
}
DEFAULT_CLEARANCE = 0.015   # m, minimum distance of every rest vertex from every capsule
MIN_PARTICLES = {'skirt': 100, 'dress': 100, 'cape': 100, 'top': 300}
# depth=None: the deepest depth whose coarsest mesh keeps at least this many vertices.
MIN_COARSE_VERTICES = {'skirt': 100, 'dress': 100, 'cape': 100, 'top': 150}

UP = np.array([0.0, 0.0, 1.0])
DESIGN_MARGIN = 0.010  # m, design stand-off beyond the clearance (facet sag of coarse rows)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of an oriented manifold triangle mesh, faces (t, 3).

    Returns a list of int64 arrays of vertex indices, each in the direction the boundary
    edges run in their faces, longest loop first.
    """
    f = np.asarray(faces, dtype=np.int64)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    n = int(f.max()) + 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    border = counts[inv] == 1
    nxt = dict(zip(a[border].tolist(), b[border].tolist(), strict=True))
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop, dtype=np.int64))
    return sorted(loops, key=len, reverse=True)


def vertex_normals(rest: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) of an oriented mesh."""
    fn = np.cross(rest[faces[:, 1]] - rest[faces[:, 0]], rest[faces[:, 2]] - rest[faces[:, 0]])
    vn = np.zeros_like(rest)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def _horizontal_unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    h = np.array([v[0], v[1], 0.0])
    norm = float(np.linalg.norm(h))
    return h / norm if norm > 1e-9 else fallback


@dataclass
class Design:
    """The body as the garment builders see it: capsule arrays and a horizontal frame."""

    body: dict[str, Capsule]
    names: list[str]
    p0: np.ndarray
    p1: np.ndarray
    r: np.ndarray
    fwd: np.ndarray      # (3,) horizontal forward
    left: np.ndarray     # (3,) horizontal left
    centre: np.ndarray   # (3,) a point on the torso's vertical axis (z = 0)

    @classmethod
    def of(cls, body: dict[str, Capsule]) -> Design:
        names, p0, p1, r = body_arrays(body)
        if 'upper_arm_l' in body and 'upper_arm_r' in body:
            lat = body['upper_arm_l'][0] - body['upper_arm_r'][0]
        else:
            lat = body['upper_leg_l'][0] - body['upper_leg_r'][0]
        left = _horizontal_unit(lat, np.array([0.0, 1.0, 0.0]))
        fwd = np.cross(left, UP)
        torso = [s for s in ('pelvis', 'lower_torso', 'upper_torso') if s in body]
        pts = np.array([body[s][k] for s in torso for k in (0, 1)])
        centre = np.array([pts[:, 0].mean(), pts[:, 1].mean(), 0.0])
        return cls(body, names, p0, p1, r, fwd, left, centre)

    def mask(self, names: tuple[str, ...] | list[str], invert: bool = False) -> np.ndarray:
        m = np.array([n in names for n in self.names])
        return ~m if invert else m

    def top_z(self, seg: str) -> float:
        return float(max(self.body[seg][0][2], self.body[seg][1][2]))

    def bottom_z(self, seg: str) -> float:
        return float(min(self.body[seg][0][2], self.body[seg][1][2]))

    def rays(self, theta: np.ndarray, z: np.ndarray, radius_pad: float, mask: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal rays from the torso axis at heights z (nz,) in directions theta (nt,)
        (0 = forward, pi/2 = left) through the capsules selected by mask, inflated by
        radius_pad: (t_in, t_out), each (nz, nt, c)."""
        dirs = np.cos(theta)[:, None] * self.fwd + np.sin(theta)[:, None] * self.left
        o = self.centre[None, None, :] + z[:, None, None] * UP
        o = np.broadcast_to(o, (len(z), len(theta), 3)).reshape(-1, 3)
        u = np.broadcast_to(dirs[None], (len(z), len(theta), 3)).reshape(-1, 3)
        t_in, t_out = ray_capsules(o, u, self.p0[mask], self.p1[mask], self.r[mask] + radius_pad)
        shape = (len(z), len(theta), int(mask.sum()))
        return t_in.reshape(shape), t_out.reshape(shape)

    def reach(self, theta: np.ndarray, z: np.ndarray, pad: float, mask: np.ndarray
              ) -> np.ndarray:
        """(nz, nt): the farthest exit along each ray of the inflated capsules in mask
        (0 where none is hit ahead): the smallest radius that clears them."""
        if not mask.any():
            return np.zeros((len(z), len(theta)))
        _, t_out = self.rays(theta, z, pad, mask)
        return np.maximum(np.nan_to_num(np.nanmax(np.where(np.isnan(t_out), -np.inf, t_out),
                                                  axis=2), neginf=0.0), 0.0)

    def room(self, theta: np.ndarray, z: np.ndarray, pad: float, mask: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """(nz, nt) nearest entry ahead along each ray of the inflated capsules in mask (inf
        where none; 0 where the ray starts inside one) and the index into names of it."""
        if not mask.any():
            return np.full((len(z), len(theta)), np.inf), np.zeros((len(z), len(theta)), int)
        t_in, t_out = self.rays(theta, z, pad, mask)
        ahead = np.where(np.isnan(t_in) | (t_out <= 0.0), np.inf, np.maximum(t_in, 0.0))
        idx = np.argmin(ahead, axis=2)
        return np.take_along_axis(ahead, idx[..., None], axis=2)[..., 0], \
            np.flatnonzero(mask)[idx]


def smax(a: np.ndarray, b: np.ndarray, eps: float = 0.005) -> np.ndarray:
    """Smooth maximum >= max(a, b), within eps of it."""
    return 0.5 * (a + b) + np.sqrt(0.25 * (a - b) ** 2 + eps * eps)


def choose_depth(name: str, target: int, depth: int | None,
                 coarse_for: Callable[[int], int]) -> int:
    """depth=None: deepest depth <= MAX_AUTO_DEPTH whose coarse mesh (coarse_for(depth)
    vertices) keeps MIN_COARSE_VERTICES[name]; explicit depths are checked."""
    if depth is not None:
        return depth
    for dd in range(MAX_AUTO_DEPTH, -1, -1):
        if coarse_for(dd) >= MIN_COARSE_VERTICES[name]:
            return dd
    return 0


def finalise(name: str, rest: np.ndarray, faces: np.ndarray, depth: int, d: Design,
             clearance: float) -> MeshHierarchy:
    """Build the hierarchy from the coarse mesh (rest (n, 3) m, faces (t, 3)); where a finest
    vertex is closer than clearance + 1 mm to a capsule, move the coarse vertices it is
    interpolated from away from that capsule's axis and rebuild; raise ClothInputError if
    8 rounds do not bring every vertex at least clearance away (the extra 1 mm is a target,
    not a requirement: pushes near two capsules, the neck between head and chest, can trade
    a fraction of it back and forth)."""
    rest = rest.copy()
    for _ in range(8):
        coarse = MeshLevel(rest, faces, source=f'{name} garment (coarse)')
        hier = MeshHierarchy.from_coarse(coarse, depth)
        fine = hier.finest.rest
        dist = point_segment_distances(fine, d.p0, d.p1) - d.r[None, :]
        dmin = dist.min(axis=1)
        deficit = clearance + 0.001 - dmin
        if (deficit <= 0.0).all():
            return hier
        # Each coarse vertex whose facets carry a too-close finest vertex moves by the largest
        # such deficit, away from the axis of the capsule that finest vertex is closest to.
        prolong = sp.identity(len(fine), format='csr')
        for tr in hier.transfers:
            prolong = prolong @ tr.prolongation()
        bad = np.flatnonzero(deficit > 0.0)
        seg = np.argmin(dist[bad], axis=1)
        a, ab = d.p0[seg], d.p1[seg] - d.p0[seg]
        t = np.clip(np.einsum('ij,ij->i', fine[bad] - a, ab)
                    / np.maximum(np.einsum('ij,ij->i', ab, ab), 1e-300), 0.0, 1.0)
        away = fine[bad] - (a + t[:, None] * ab)
        away /= np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-12)
        infl = prolong.tocsr()[bad].tocoo()
        order = np.lexsort((deficit[bad][infl.row], infl.col))
        col, row = infl.col[order], infl.row[order]
        last = np.append(col[1:] != col[:-1], True)   # the largest deficit per coarse vertex
        rest[col[last]] += (away * (deficit[bad] + 0.002)[:, None])[row[last]]
    if dmin.min() >= clearance:
        return hier
    worst = int(np.argmin(dmin))
    seg = d.names[int(np.argmin(dist[worst]))]
    raise ClothInputError(
        f"{name}: cannot keep the garment {clearance:.3f} m clear of segment '{seg}' (a vertex "
        f"stays {dmin[worst]:.4f} m from it); the body is too tight for this garment")
