"""Built-in rectangular cloth sheets of near-equilateral triangles, and their hierarchies.

The paper (Sec. 3) makes every triangle equilateral and equal in area because the multigrid
transfers are exact for such meshes. `sheet_coarse` lays rows of vertices `dy` apart, each row
`dx` spaced, odd rows shifted by dx/2, so the interior triangles have base dx and height dy,
with dy chosen as close to sqrt(3)/2 dx as the requested height allows (equilateral when the
height is a multiple of sqrt(3)/2 dx). To keep the sheet exactly width x height with straight
borders, each odd row also gets a vertex on the left and the right border; the two triangles
at the ends of each row are then halves of an equilateral one (30-60-90 right triangles, about
1/cells_x of all faces). Row j has cells_x + 1 vertices when j is even, cells_x + 2 when odd.

Orientation: faces are counter-clockwise in the sheet's (u, v) coordinates, u along the width
(x) and v along the height (y for plane='xy', z for plane='xz'). The normal is +z for 'xy' and
-y for 'xz'. The sheet is centred on `centre`; for 'xz' (a hanging sheet) the top border is at
centre z + height / 2.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.hierarchy import MAX_DEPTH, MeshHierarchy, subdivided_counts
from cloth_mg_ros.mesh.topology import MeshLevel

__all__ = [
    'MAX_AUTO_DEPTH',
    'MIN_AUTO_CELLS',
    'MIN_PARTICLES',
    'choose_sheet_resolution',
    'sheet_coarse',
    'sheet_counts',
    'sheet_hierarchy',
    'top_corner_vertices',
]

MAX_AUTO_DEPTH = 5   # cap on subdivisions when depth=None
MIN_AUTO_CELLS = 6   # the coarsest level keeps at least this many cells along each side
MIN_PARTICLES = 16
MAX_PARTICLES = 200_000  # the largest cloth any entry point accepts (garment or sheet)
# An explicit depth is refused when the nearest sheet is further than this from the target.
_MAX_EXPLICIT_MISS = 0.25
# Row spacing may deviate this much (ratio) from sqrt(3)/2 of the column spacing to hit a count.
_MAX_ROW_STRETCH = 1.2
_STRETCH_WEIGHT = 0.25
_ROW_RATIO = math.sqrt(3.0) / 2.0
_PLANES = ('xz', 'xy')


def _positive(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ClothInputError(f'{name} must be a number, got {value!r}') from None
    if not math.isfinite(v) or v <= 0.0:
        raise ClothInputError(f'{name} must be positive and finite, got {value!r}')
    return v


def _count(name: str, value: int, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ClothInputError(f'{name} must be an integer >= {minimum}, got {value!r}')
    return int(value)


def _rows_for(width: float, height: float, cells_x: int) -> int:
    return max(1, round(height / (_ROW_RATIO * width / cells_x)))


def sheet_counts(cells_x: int, cells_y: int, depth: int = 0) -> tuple[int, int, int]:
    """(vertices, edges, faces) of `sheet_coarse(cells_x=..., cells_y=...)` after `depth`
    subdivisions, computed without building the mesh."""
    n = (cells_y + 1) * (cells_x + 1) + (cells_y + 1) // 2
    t = cells_y * (2 * cells_x + 1)
    e = n + t - 1  # Euler characteristic 1 (a disc)
    return subdivided_counts(n, e, t, depth)


def _strip_template(cells_x: int, lower_even: bool) -> tuple[np.ndarray, np.ndarray]:
    """Faces of one strip between two rows as (row offset 0/1, index within row), (2nx+1, 3)."""
    nx = cells_x
    i_up = np.arange(nx)              # triangles resting on the even row
    i_dn = np.arange(1, nx)           # triangles resting on the odd row
    zeros_up, zeros_dn = np.zeros(nx, np.int64), np.zeros(nx - 1, np.int64)
    if lower_even:  # lower row even (E), upper row odd (O)
        row = np.concatenate([[[0, 1, 1]], np.stack([zeros_up, zeros_up, zeros_up + 1], 1),
                              np.stack([zeros_dn, zeros_dn + 1, zeros_dn + 1], 1),
                              [[0, 1, 1]]])
        idx = np.concatenate([[[0, 1, 0]], np.stack([i_up, i_up + 1, i_up + 1], 1),
                              np.stack([i_dn, i_dn + 1, i_dn], 1), [[nx, nx + 1, nx]]])
    else:  # lower row odd (O), upper row even (E)
        row = np.concatenate([[[0, 0, 1]], np.stack([zeros_up, zeros_up + 1, zeros_up + 1], 1),
                              np.stack([zeros_dn, zeros_dn, zeros_dn + 1], 1),
                              [[0, 0, 1]]])
        idx = np.concatenate([[[0, 1, 0]], np.stack([i_up + 1, i_up + 1, i_up], 1),
                              np.stack([i_dn, i_dn + 1, i_dn], 1), [[nx, nx + 1, nx]]])
    return row.astype(np.int64), idx.astype(np.int64)


def sheet_coarse(width: float = 1.0, height: float = 1.0, cells_x: int = 8,
                 cells_y: int | None = None, plane: str = 'xz',
                 centre: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> MeshLevel:
    """A width x height (metres) rectangular sheet of near-equilateral triangles.

    cells_x: triangle bases along the width (column spacing dx = width / cells_x).
    cells_y: rows of triangles along the height; None picks the count that makes the row
        spacing closest to sqrt(3)/2 dx (equilateral triangles).
    plane: 'xz' (vertical sheet, height along +z, for hanging) or 'xy' (horizontal sheet).
    centre: (3,) position of the sheet's centre, metres.
    Returns a MeshLevel with sheet_counts(cells_x, cells_y)[0] vertices; see the module
    docstring for the layout.
    """
    width, height = _positive('width', width), _positive('height', height)
    nx = _count('cells_x', cells_x, 1)
    ny = _rows_for(width, height, nx) if cells_y is None else _count('cells_y', cells_y, 1)
    if plane not in _PLANES:
        raise ClothInputError(f'plane must be one of {_PLANES}, got {plane!r}')
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise ClothInputError(f'centre must be 3 finite numbers, got {centre!r}')

    dx, dy = width / nx, height / ny
    j = np.arange(ny + 1)
    odd = j % 2 == 1
    row_len = np.where(odd, nx + 2, nx + 1)
    row_start = np.concatenate([[0], np.cumsum(row_len)])
    n = int(row_start[-1])

    # u of each vertex: even rows i dx; odd rows 0, (i - 1/2) dx for i = 1..nx, then width.
    row_of = np.repeat(j, row_len)
    k = np.arange(n) - row_start[row_of]
    odd_v = odd[row_of]
    u = np.where(odd_v, np.clip((k - 0.5) * dx, 0.0, width), k * dx)
    v = row_of * dy

    faces = []
    for lower_even in (True, False):
        strips = j[:-1][(j[:-1] % 2 == 0) == lower_even]
        if len(strips) == 0:
            continue
        row, idx = _strip_template(nx, lower_even)
        # (strips, 2nx+1, 3): start of the strip's lower or upper row plus index within it.
        faces.append((row_start[strips[:, None, None] + row[None]] + idx[None]).reshape(-1, 3))
    # Strip order does not matter for correctness; sort by lowest vertex for memory locality.
    all_faces = np.concatenate(faces)
    all_faces = all_faces[np.argsort(all_faces.min(axis=1), kind='stable')]

    uc, vc = u - width / 2.0, v - height / 2.0
    zero = np.zeros(n)
    rest = np.stack([uc, vc, zero] if plane == 'xy' else [uc, zero, vc], axis=1) + c
    return MeshLevel(rest, all_faces, source=f'sheet {width:g} x {height:g} m, '
                                              f'{nx} x {ny} cells, plane {plane}')


def choose_sheet_resolution(n_particles: int, depth: int | None = None, width: float = 1.0,
                            height: float = 1.0) -> tuple[int, int, int]:
    """(cells_x, cells_y, depth) whose subdivided sheet has about `n_particles` vertices.

    depth=None: the deepest depth (at most MAX_AUTO_DEPTH) whose coarsest sheet still has at
    least MIN_AUTO_CELLS cells along each side, or depth 0 when none has. For each depth the
    coarse resolution minimises |log(count / n_particles)| + 0.25 |log(stretch)|, where the
    row spacing may stretch up to 20% from the equilateral sqrt(3)/2 dx.
    Raises ClothInputError when n_particles < MIN_PARTICLES or, for an explicit depth, when no
    sheet at that depth comes within 25% of n_particles.
    """
    target = _count('n_particles', n_particles, MIN_PARTICLES)
    width, height = _positive('width', width), _positive('height', height)
    if depth is not None:
        depth = _count('depth', depth, 0)
        if depth > MAX_DEPTH:
            raise ClothInputError(f'depth must be <= {MAX_DEPTH}, got {depth}')

    def best(d: int) -> tuple[float, int, int]:
        cands = []
        nx = 1
        while True:
            ny0 = height / (_ROW_RATIO * width / nx)
            lo = max(1, math.ceil(ny0 / _MAX_ROW_STRETCH))
            hi = max(lo, math.floor(ny0 * _MAX_ROW_STRETCH))
            # The count grows with ny, and a 1% count error outweighs a 1% stretch, so the
            # best ny for this nx is one of the two around where the count crosses the target.
            first_above = lo + bisect.bisect_left(
                range(lo, hi + 1), target, key=lambda ny, nx=nx: sheet_counts(nx, ny, d)[0])
            for ny in {max(lo, first_above - 1), min(hi, first_above)}:
                count = sheet_counts(nx, ny, d)[0]
                score = abs(math.log(count / target)) + _STRETCH_WEIGHT * abs(math.log(ny / ny0))
                cands.append((score, nx, ny))
            if sheet_counts(nx, lo, d)[0] > 2 * target:
                break
            nx += 1
        return min(cands)

    if depth is not None:
        _, nx, ny = best(depth)
        got = sheet_counts(nx, ny, depth)[0]
        if abs(got / target - 1.0) > _MAX_EXPLICIT_MISS:
            smallest = sheet_counts(1, _rows_for(width, height, 1), depth)[0]
            raise ClothInputError(
                f'n_particles={n_particles} is too small for depth={depth}: the nearest sheet '
                f'has {got} particles (the smallest at that depth has {smallest})')
        return nx, ny, depth
    for d in range(MAX_AUTO_DEPTH, -1, -1):
        _, nx, ny = best(d)
        if min(nx, ny) >= MIN_AUTO_CELLS or d == 0:
            return nx, ny, d
    raise AssertionError('unreachable')


def sheet_hierarchy(n_particles: int, depth: int | None = None, width: float = 1.0,
                    height: float = 1.0, plane: str = 'xz',
                    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> MeshHierarchy:
    """A hierarchy of a width x height (metres) sheet whose finest level has about
    `n_particles` vertices (see `choose_sheet_resolution` for how the resolution and, for
    depth=None, the number of subdivisions are chosen). levels[0] is the finest."""
    nx, ny, d = choose_sheet_resolution(n_particles, depth, width, height)
    coarse = sheet_coarse(width, height, nx, ny, plane=plane, centre=centre)
    return MeshHierarchy.from_coarse(coarse, d)


def top_corner_vertices(mesh: MeshLevel | np.ndarray, plane: str = 'xz') -> np.ndarray:
    """Indices [left, right] of the vertices nearest the two top corners of a sheet.

    mesh: a MeshLevel or (n, 3) positions in metres. plane: 'xz' (up is +z) or 'xy' (up is
    +y); left/right is along x. The corners are those of the bounding box in that plane.
    Because subdivision keeps coarse indices, the coarsest level's corner indices are valid on
    every level. Returns a (2,) int64 array.
    """
    if plane not in _PLANES:
        raise ClothInputError(f'plane must be one of {_PLANES}, got {plane!r}')
    pos = np.asarray(mesh.rest if isinstance(mesh, MeshLevel) else mesh, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise ClothInputError(f'positions must have shape (n, 3), got {pos.shape}')
    up = 2 if plane == 'xz' else 1
    xy = pos[:, [0, up]]
    top = xy[:, 1].max()
    corners = np.array([[xy[:, 0].min(), top], [xy[:, 0].max(), top]])
    dist = np.linalg.norm(xy[None, :, :] - corners[:, None, :], axis=2)
    return np.argmin(dist, axis=1).astype(np.int64)
