"""Row-meshed surfaces (the tubes and the cape): a surface tabulated as radius per direction
and height around the torso axis, cut into rows of vertices at equal arc length, consecutive
rows offset by half a spacing and zipped into strips of near-equilateral triangles; the row
plan whose subdivided mesh lands nearest the wanted particle count; and the shared
construction of a row garment (depth, plan, mesh, pinned top row)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.design import UP, Design, choose_depth
from cloth_mg_ros.mesh.hierarchy import subdivided_counts

_ROW_RATIO = math.sqrt(3.0) / 2.0  # row spacing / vertex spacing of equilateral triangles
MAX_EXPLICIT_MISS = 0.25  # an explicit depth may miss the wanted count by at most this

@dataclass
class RowSurface:
    """A surface point(theta, z) = centre + z up + rho(theta, z) (cos theta fwd + sin theta
    left), tabulated on a theta grid (periodic for tubes) and a descending z grid."""

    design: Design
    theta: np.ndarray     # (nt,)
    z: np.ndarray         # (nz,) from top to bottom, uniform
    rho: np.ndarray       # (nz, nt)
    closed: bool
    _meridian: np.ndarray | None = None
    _lengths: np.ndarray | None = None

    def rows(self, zs: np.ndarray) -> np.ndarray:
        """Dense polylines (len(zs), nt (+1 if closed), 3) of the rows at heights zs."""
        f = np.clip((self.z[0] - zs) / (self.z[0] - self.z[-1]) * (len(self.z) - 1),
                    0.0, len(self.z) - 1 - 1e-9)
        i0 = np.floor(f).astype(int)
        w = (f - i0)[:, None]
        rho = (1.0 - w) * self.rho[i0] + w * self.rho[i0 + 1]
        th = self.theta
        if self.closed:
            rho = np.concatenate([rho, rho[:, :1]], axis=1)
            th = np.concatenate([th, th[:1] + 2.0 * math.pi])
        d = self.design
        dirs = np.cos(th)[:, None] * d.fwd + np.sin(th)[:, None] * d.left
        return (d.centre[None, None, :] + zs[:, None, None] * UP
                + rho[..., None] * dirs[None, :, :])

    def lengths(self, zs: np.ndarray) -> np.ndarray:
        """Row lengths (len(zs),) in metres (perimeters for tubes)."""
        pts = self.rows(zs)
        return np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(axis=1)

    def meridian(self) -> np.ndarray:
        """Cumulative length (nz,) from the top along the mean profile."""
        if self._meridian is None:
            mean = self.rho.mean(axis=1)
            step = np.hypot(np.diff(self.z), np.diff(mean))
            self._meridian = np.concatenate([[0.0], np.cumsum(step)])
        return self._meridian

    def interp_lengths(self, zs: np.ndarray) -> np.ndarray:
        """Row lengths at heights zs, interpolated from the tabulated rows (metres)."""
        if self._lengths is None:
            self._lengths = self.lengths(self.z)
        return np.interp(-zs, -self.z, self._lengths)


@dataclass
class RowPlan:
    zs: np.ndarray        # (J+1,) row heights, top first
    counts: np.ndarray    # (J+1,) intervals per row (tube: vertices per ring)
    closed: bool

    def params(self) -> list[np.ndarray]:
        out = []
        for j, m in enumerate(self.counts.tolist()):
            if self.closed:
                out.append((np.arange(m) + 0.5 * (j % 2)) / m)
            elif j % 2 == 0:
                out.append(np.arange(m + 1) / m)
            else:
                out.append(np.concatenate([[0.0], (np.arange(m) + 0.5) / m, [1.0]]))
        return out

    def mesh_counts(self) -> tuple[int, int, int]:
        """(vertices, edges, faces) of the coarse mesh this plan gives."""
        sizes = (self.counts if self.closed
                 else self.counts + 1 + (np.arange(len(self.counts)) % 2))
        if self.closed:
            n, t = int(sizes.sum()), int((sizes[:-1] + sizes[1:]).sum())
            return n, n + t, t
        n, t = int(sizes.sum()), int((sizes[:-1] + sizes[1:] - 2).sum())
        return n, n + t - 1, t


def _zip(a: np.ndarray, ta: np.ndarray, b: np.ndarray, tb: np.ndarray, closed: bool
         ) -> list[tuple[int, int, int]]:
    """Triangles of the strip between row a (lower) and row b (upper), vertex index arrays
    with increasing parameters ta, tb in [0, 1): advance on the row whose next edge's
    midpoint comes first. Faces (a_i, a_i+1, b_j) and (a_i, b_j+1, b_j): outward normals for
    rows running counter-clockwise seen from above (theta increasing)."""
    na, nb = len(a), len(b)
    tris = []
    if closed:
        ta_ext = np.concatenate([ta, [ta[0] + 1.0]])
        diff = (tb - ta[0] + 0.5) % 1.0 - 0.5
        j0 = int(np.argmin(np.abs(diff)))
        order = (j0 + np.arange(nb + 1)) % nb
        steps = np.diff(tb[order]) % 1.0
        tb_ext = ta[0] + diff[j0] + np.concatenate([[0.0], np.cumsum(steps)])
        tb_ext[-1] = tb_ext[0] + 1.0
        bidx = b[order]
        ia = ib = 0
        while ia < na or ib < nb:
            adv_a = ib == nb or (ia < na and ta_ext[ia] + ta_ext[ia + 1]
                                 < tb_ext[ib] + tb_ext[ib + 1])
            if adv_a:
                tris.append((a[ia % na], a[(ia + 1) % na], bidx[ib]))
                ia += 1
            else:
                tris.append((a[ia % na], bidx[ib + 1], bidx[ib]))
                ib += 1
        return tris
    ia = ib = 0
    while ia < na - 1 or ib < nb - 1:
        adv_a = ib == nb - 1 or (ia < na - 1 and ta[ia] + ta[ia + 1] < tb[ib] + tb[ib + 1])
        if adv_a:
            tris.append((a[ia], a[ia + 1], b[ib]))
            ia += 1
        else:
            tris.append((a[ia], b[ib + 1], b[ib]))
            ib += 1
    return tris


def _plan_rows(surface: RowSurface, spacing: float, min_count: int, stretch: float = 1.0
               ) -> RowPlan:
    """Rows about stretch * spacing * sqrt(3)/2 apart along the mean meridian, each cut into
    intervals of about `spacing` metres."""
    ell = surface.meridian()
    n_rows = max(2, round(ell[-1] / (stretch * spacing * _ROW_RATIO)))
    zs = np.interp(np.linspace(0.0, ell[-1], n_rows + 1), ell, surface.z)
    counts = np.maximum(min_count, np.round(surface.interp_lengths(zs) / spacing)).astype(int)
    return RowPlan(zs, counts, surface.closed)


def mesh_rows(surface: RowSurface, plan: RowPlan) -> tuple[np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """(rest (n, 3), faces (t, 3), top row vertex indices) of a row plan."""
    polylines = surface.rows(plan.zs)
    params = plan.params()
    pts, rows, start = [], [], 0
    for line, t in zip(polylines, params, strict=True):
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
        s /= s[-1]
        pts.append(np.stack([np.interp(t, s, line[:, k]) for k in range(3)], axis=1))
        rows.append(np.arange(start, start + len(t)))
        start += len(t)
    faces = []
    for j in range(len(rows) - 1):
        faces += _zip(rows[j + 1], params[j + 1], rows[j], params[j], plan.closed)
    return np.concatenate(pts), np.array(faces, dtype=np.int64), rows[0]


def best_plan(surface: RowSurface, target: int, depth: int, min_count: int
               ) -> tuple[RowPlan, int]:
    """The row plan whose mesh, subdivided `depth` times, comes closest to `target`
    vertices. Scans the spacing, then around the best one also the row spacing (up to 10%
    off the equilateral sqrt(3)/2, weighted like `choose_sheet_resolution`: score
    |log(count / target)| + 0.25 |log(stretch)|). Returns (plan, finest vertex count)."""
    ell = surface.meridian()[-1]
    width = float(surface.interp_lengths(surface.z).max())
    best: tuple[float, RowPlan, int] | None = None
    h_best = 0.0
    for h in np.geomspace(max(ell, width) / 2000.0, max(ell, width) / 2.0, 200):
        plan = _plan_rows(surface, float(h), min_count)
        n = subdivided_counts(*plan.mesh_counts(), depth)[0]
        score = abs(math.log(n / target))
        if best is None or score < best[0]:
            best, h_best = (score, plan, n), float(h)
    for h in np.geomspace(h_best / 1.1, h_best * 1.1, 25):
        for stretch in np.linspace(0.9, 1.1, 11):
            plan = _plan_rows(surface, float(h), min_count, float(stretch))
            n = subdivided_counts(*plan.mesh_counts(), depth)[0]
            score = abs(math.log(n / target)) + 0.25 * abs(math.log(stretch))
            if best is None or score < best[0]:
                best = (score, plan, n)
    assert best is not None
    return best[1], best[2]


def build_row_garment(name: str, surface: RowSurface, pin_segment: str, target: int,
                      depth: int | None
                      ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest (n, 3) m, faces (t, 3)), depth and pins {pin_segment: top row} of a
    row garment whose finest level comes nearest `target` vertices."""
    min_count = 8 if surface.closed else 4

    def coarse_for(dd: int) -> int:
        return round(target / 4 ** dd)

    dd = choose_depth(name, target, depth, coarse_for)
    plan, got = best_plan(surface, target, dd, min_count)
    if abs(got / target - 1.0) > MAX_EXPLICIT_MISS:
        raise ClothInputError(
            f'n_particles={target} is too small for a {name} at depth={dd}: the nearest '
            f'{name} at that depth has {got} particles')
    rest, faces, top_row = mesh_rows(surface, plan)
    return rest, faces, dd, {pin_segment: top_row.astype(np.int64)}
