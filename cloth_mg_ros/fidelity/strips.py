"""Flat rectangular test specimens (strips, in the xy plane) triangulated three ways.

A textile test must not depend on how the specimen is triangulated, so every test runs on
three kinds of mesh:

* ``lattice`` at orientation 0: equilateral triangles with one edge family along the strip
  (x); at 45: the same lattice turned 45 degrees against the strip (any angle is allowed).
* ``garment``: an isotropic unstructured mesh, the kind the garments' remesher makes
  (near-equilateral triangles, valence 6 with scattered 5s and 7s): random points relaxed
  towards a centroidal Voronoi tessellation, then Delaunay-triangulated.

The mesh is a Delaunay triangulation (scipy.spatial, qhull) of points that include the
rectangle's sides and any ``cuts`` (lines x = const, such as the ledge edge of a
cantilever) sampled at the mesh spacing, with no interior point closer than half a spacing
to them, so those lines are mesh lines. It is made at the simulated resolution, not
subdivided from a coarser one: subdivision keeps the coarse level's irregular border
triangles at the coarse level's size, and the cantilever's error then stopped shrinking
with resolution (45 degrees, G = 8: 2.28 / 1.57 / 1.63 / 1.05 % of l at 1.5K / 3K / 6K /
12K particles subdivided, 1.51 / 1.09 / 0.77 / 0.55 % made directly). A strip's hierarchy
therefore has one level; the textile tests solve with the direct solver.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
from scipy.spatial import Delaunay

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import MeshLevel

MESH_KINDS = ("lattice", "garment")
_CVT_ITERATIONS = 25
_BORDER_SWEEPS = 6
EQUILATERAL_AREA = math.sqrt(3.0) / 4.0  # area of a unit-edge equilateral triangle


def _line(a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
    """Points from a to b (2-vectors) inclusive, about ``spacing`` apart."""
    n = max(1, round(float(np.linalg.norm(b - a)) / spacing))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return a[None, :] * (1.0 - t) + b[None, :] * t


def _lattice_points(x0: float, x1: float, width: float, h: float, angle: float) -> np.ndarray:
    """An equilateral lattice of spacing h turned by ``angle`` rad, covering the strip."""
    cx, cy = 0.5 * (x0 + x1), 0.0
    reach = math.hypot(x1 - x0, width)
    n = int(reach / h) + 3
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-2 * n, 2 * n + 1))
    px = (i + 0.5 * (j % 2)) * h
    py = j * h * math.sqrt(3.0) / 2.0
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * px - s * py + cx, s * px + c * py + cy], axis=-1).reshape(-1, 2)


def _keep_clear(pts: np.ndarray, x0: float, x1: float, width: float, cuts: tuple[float, ...],
                gap: float) -> np.ndarray:
    """Interior points at least ``gap`` from the sides and the cut lines."""
    x, y = pts[:, 0], pts[:, 1]
    ok = (x > x0 + gap) & (x < x1 - gap) & (np.abs(y) < 0.5 * width - gap)
    for c in cuts:
        ok &= np.abs(x - c) > gap
    return pts[ok]


def _frame_points(x0: float, x1: float, width: float, cuts: tuple[float, ...],
                  h: float) -> np.ndarray:
    """The rectangle's sides and the cut lines sampled about h apart (no duplicates)."""
    hw = 0.5 * width
    xs = sorted({x0, x1, *cuts})
    parts = []
    for a, b in itertools.pairwise(xs):  # long sides, piece by piece
        parts += [_line(np.array([a, -hw]), np.array([b, -hw]), h)[:-1],
                  _line(np.array([a, hw]), np.array([b, hw]), h)[:-1]]
    parts += [np.array([[x1, -hw], [x1, hw]])]
    for x in xs:  # across: the two ends and every cut, without their corners
        parts.append(_line(np.array([x, -hw]), np.array([x, hw]), h)[1:-1])
    return np.concatenate(parts)


def triangulate(pts: np.ndarray) -> np.ndarray:
    """Delaunay faces of 2-D points, counter-clockwise (normal +z)."""
    faces = Delaunay(pts).simplices.astype(np.int64)
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    faces[cross < 0.0] = faces[cross < 0.0][:, [0, 2, 1]]
    return faces


def triangulate_pieces(pts: np.ndarray, xs: list[float]) -> np.ndarray:
    """Delaunay faces of the points between each pair of consecutive lines x = xs[k], each
    piece on its own, so every line is a mesh line (a Delaunay triangulation of the whole
    set need not keep them); points on a line belong to both its pieces."""
    tol = 1e-9 * (xs[-1] - xs[0])
    faces = []
    for a, b in itertools.pairwise(xs):
        idx = np.flatnonzero((pts[:, 0] >= a - tol) & (pts[:, 0] <= b + tol))
        faces.append(idx[triangulate(pts[idx])])
    return np.concatenate(faces)


def cvt_relax(frame: np.ndarray, inner: np.ndarray, iterations: int,
              density: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Lloyd relaxation towards a centroidal Voronoi tessellation: each interior point (k, 2)
    moves to the centroid of its barycentric cell (the area-weighted mean of its triangles'
    centroids, each also weighted by ``density`` at its centroid when given), the frame
    points (f, 2) fixed."""
    nf = len(frame)
    for _ in range(iterations):
        pts = np.concatenate([frame, inner])
        faces = triangulate(pts)
        tri = pts[faces]
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        cen = tri.mean(axis=1)
        w = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        if density is not None:
            w = w * density(cen)
        idx, wk = faces.ravel(), np.repeat(w, 3)
        den = np.bincount(idx, wk, len(pts))
        num = [np.bincount(idx, wk * np.repeat(cen[:, d], 3), len(pts)) for d in (0, 1)]
        inner = np.stack(num, axis=1)[nf:] / den[nf:, None]
    return inner


def _aligned_strip(x0: float, x1: float, width: float, spacing: float,
                   cuts: tuple[float, ...]) -> MeshLevel:
    """Edges along the strip: rows of exactly equilateral triangles whose first and last
    rows are the strip's sides (the spacing is adjusted so that a whole number of rows fills
    the width), and a vertex on every row at both ends and on every cut, so the ends and
    cuts are straight mesh lines; lattice points closer than half a spacing to them are
    dropped (the triangles beside a cut are halves or near-halves of the lattice's)."""
    rows = max(1, round(width / (spacing * math.sqrt(3.0) / 2.0)))
    dy = width / rows
    h = dy * 2.0 / math.sqrt(3.0)
    xs = sorted({x0, x1, *(c for c in cuts if x0 < c < x1)})
    j = np.arange(rows + 1)
    y = -0.5 * width + j * dy
    count = int((x1 - x0) / h) + 3
    i = np.arange(-1, count)
    px = x0 + (i[None, :] + 0.5 * (j[:, None] % 2)) * h
    py = np.broadcast_to(y[:, None], px.shape)
    pts = np.stack([px.ravel(), py.ravel()], axis=1)
    keep = (pts[:, 0] > x0) & (pts[:, 0] < x1)
    for c in xs:
        keep &= np.abs(pts[:, 0] - c) > 0.5 * h
    columns = np.array([[c, yy] for c in xs for yy in y])
    pts = np.concatenate([columns, pts[keep]])
    rest = np.concatenate([pts, np.zeros((len(pts), 1))], axis=1)
    return MeshLevel(rest, triangulate_pieces(pts, xs),
                     source=f"aligned strip {x1 - x0:g} x {width:g} m, spacing {h:.4g} m")


def strip_coarse(kind: str, x0: float, x1: float, width: float, spacing: float,
                 orientation_deg: float = 0.0, cuts: tuple[float, ...] = (),
                 seed: int = 0) -> MeshLevel:
    """A flat strip x in [x0, x1], y in [-width/2, width/2] (m, z = 0) of triangles about
    ``spacing`` m across, of mesh kind ``kind`` (see the module docstring)."""
    if kind not in MESH_KINDS:
        raise ClothInputError(f"unknown strip mesh {kind!r}; choose one of {', '.join(MESH_KINDS)}")
    if not (x1 > x0 and width > 0.0 and spacing > 0.0):
        raise ClothInputError(f"strip: need x1 > x0, width > 0 and spacing > 0, got x0={x0}, "
                              f"x1={x1}, width={width}, spacing={spacing}")
    if kind == "lattice" and math.isclose(math.remainder(orientation_deg, 180.0), 0.0,
                                          abs_tol=1e-9):
        return _aligned_strip(x0, x1, width, spacing, cuts)
    frame = _frame_points(x0, x1, width, cuts, spacing)
    gap = 0.5 * spacing
    if kind == "lattice":
        inner = _keep_clear(_lattice_points(x0, x1, width, spacing,
                                             math.radians(orientation_deg)),
                            x0, x1, width, cuts, gap)
        # Where a lattice row runs just over half a spacing inside a side, the whole row of
        # border triangles is flat; a few relaxation sweeps even them out and leave the
        # interior (a relaxed lattice is its own fixed point) as it was.
        inner = cvt_relax(frame, inner, _BORDER_SWEEPS)
    else:
        area = (x1 - x0) * width
        count = max(1, int(area / (2.0 * EQUILATERAL_AREA * spacing ** 2)) - len(frame) // 2)
        rng = np.random.default_rng(seed)
        inner = rng.uniform([x0 + gap, -0.5 * width + gap], [x1 - gap, 0.5 * width - gap],
                            size=(count, 2))
        inner = _keep_clear(cvt_relax(frame, inner, _CVT_ITERATIONS), x0, x1, width, cuts,
                            0.25 * spacing)
    pts = np.concatenate([frame, inner])
    faces = triangulate_pieces(pts, sorted({x0, x1, *(c for c in cuts if x0 < c < x1)}))
    rest = np.concatenate([pts, np.zeros((len(pts), 1))], axis=1)
    return MeshLevel(rest, faces, source=f"{kind} strip {x1 - x0:g} x {width:g} m, "
                                         f"spacing {spacing:.4g} m, {orientation_deg:g} deg")


def strip_hierarchy(kind: str, x0: float, x1: float, width: float, particles: int,
                    orientation_deg: float = 0.0, cuts: tuple[float, ...] = (),
                    seed: int = 0) -> MeshHierarchy:
    """A one-level hierarchy of a strip (see `strip_coarse`) of about ``particles``
    vertices (the module docstring says why it is not subdivided)."""
    if isinstance(particles, bool) or not isinstance(particles, (int, np.integer)) \
            or particles < 16:
        raise ClothInputError(f"strip: --particles must be an integer >= 16, got {particles!r}")
    spacing = math.sqrt((x1 - x0) * width / (2.0 * EQUILATERAL_AREA * particles))
    mesh = strip_coarse(kind, x0, x1, width, spacing, orientation_deg, cuts, seed)
    return MeshHierarchy.from_coarse(mesh, 0)
