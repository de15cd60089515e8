"""The Cusick drape test (BS 5058; ISO 9073-9 for nonwovens): a disc specimen on a smaller
support disc, settled, and its shadow measured.

A 30 cm specimen (24 and 36 cm are the standard's other sizes) is centred on an 18 cm support
disc and hangs around it under gravity (-z). The standard clamps the specimen between two
18 cm discs: the particles on the support are held (pins), and the lower and upper discs
are `DiscCollider` solids whose contact surfaces end at the support radius, so the drape
line is the 18 cm circle and a fold cannot pass through the plates. (A specimen resting on
the support by contact and friction alone was tried: a soft knit slid off it, DC 0.10.)

The drape coefficient is DC = (A_shadow - A_disc) / (A_specimen - A_disc) with the nominal
areas (A_disc 254.47 cm^2, A_specimen 706.86 cm^2 for 30 on 18 cm): DC = 1 for a specimen
that stays flat, 0 for one that hangs straight down. The shadow is the union of the settled
cloth's triangles projected on the xy plane (`shadow_mask`), its outline r(phi) the farthest
shadow radius in each of ``OUTLINE_BINS`` angular bins, and the node count the number of
peaks of r(phi) standing at least ``NODE_PROMINENCE`` (5 mm) above the troughs between them
and their higher neighbours (`count_nodes`). DC depends on shear stiffness as well as
bending (BS 5058), and both DC and the node count scatter between repeats of one fabric
(draped sheets switch between metastable fold counts), so `CusickSpec.seed` gives each
repeat its own small initial out-of-plane perturbation of the hanging annulus;
`summarise_repeats` reports the spread and DC at the most frequent node count.

The specimen mesh (`disc_hierarchy`): the rim and the support circle sampled at the local
coarse spacing (the support edge is a mesh line), interior points relaxed towards a
centroidal Voronoi tessellation, Delaunay-triangulated, subdivided 1-to-4; graded by default
(`spacing_profile`: 0.3 times as fine at the support edge, where the cloth turns down from
the clamp in a boundary layer a few mm wide). Both circles are polygons whose radii are
enlarged to the circle's area, so a flat specimen's shadow is A_specimen (DC = 1).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.signal import find_peaks

from cloth_mg_ros.collision.colliders import DiscCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.elastica import GRAVITY
from cloth_mg_ros.fidelity.settle import SettleResult, settle_specimen
from cloth_mg_ros.fidelity.strips import EQUILATERAL_AREA, cvt_relax, triangulate
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import MeshLevel
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model
from cloth_mg_ros.solvers import validate_solver_name

# BS 5058 (and ISO 9073-9): specimen discs of 24, 30 or 36 cm on an 18 cm support disc.
SUPPORT_DIAMETER = 0.18  # m
SPECIMEN_DIAMETER = 0.30  # m, the usual size
A_DISC = math.pi * (0.5 * SUPPORT_DIAMETER) ** 2  # 254.47 cm^2
A_SPECIMEN = math.pi * (0.5 * SPECIMEN_DIAMETER) ** 2  # 706.86 cm^2
SUPPORT_TOP = 0.5  # m: height of the clamped cloth (the floor is left out: it hangs freely)
PLATE_HEIGHT = 0.01  # m: thickness of the support (and clamp) discs
CONTACT_THICKNESS = 0.002  # m: rounds the support rim only this much (the drape line stays)
# The clamp's plates are frictionless where the hanging cloth meets them (their rims and
# undersides; the clamp itself is the pins): with friction the step's Coulomb projection
# and the penalty made a stick-slip cycle at 1e-4 m/s that never came to rest.
CLAMP_FRICTION = 0.0

DEFAULT_PARTICLES = 2500
DEFAULT_PERTURBATION = 0.002  # m: the largest initial lift or drop of the annulus' rim
PERTURBATION_MODES = 12  # angular Fourier modes 1..12 of the initial perturbation
MESH_SEED = 0  # the mesh is the same for every repeat; the spec's seed perturbs it only
MIN_CELLS_ACROSS = 6  # coarse triangles across the support radius
MAX_DEPTH = 3
_CVT_ITERATIONS = 25
# Mesh grading (`spacing_profile`): the cloth turns down from the clamp in a boundary layer
# about sqrt(B / (rho g l)) wide, 7 mm for gray-interlock, under a uniform 2.5K mesh's
# 5.7 mm spacing; a coarse layer bends too easily (a kink in one row of hinges costs less
# the wider the row), so DC rose with resolution (gray-interlock, uniform: 0.354, 0.375,
# 0.393 at 2.5K, 5K, 20K). Graded, 2.5K gives what a uniform 5K mesh gives (five seeds
# each: 0.379 / 0.375, denim 0.601 / 0.600, royal-target 0.822 / 0.822).
CLAMP_SPACING = 0.3
GRADING_WIDTH = 0.02  # m
HELD_SPACING = 1.5
HELD_GRADING_WIDTH = 0.03  # m

PIXEL = 2.5e-4  # m: shadow raster pixel (0.25 mm)
OUTLINE_BINS = 360  # 1 degree bins of the shadow outline r(phi)
NODE_PROMINENCE = 0.005  # m: a node's crest stands at least 5 mm above the troughs around it


@dataclass(frozen=True)
class CusickSpec:
    """One Cusick drape test: a measured (or paper) material by name, the specimen's particle
    count, the repeat's seed (it draws the initial perturbation), the perturbation's largest
    out-of-plane displacement (m), the specimen diameter (m; BS 5058: 0.24, 0.30 or 0.36)
    and whether the mesh is graded towards the support edge (`spacing_profile`)."""

    material: str = "gray-interlock"
    particles: int = DEFAULT_PARTICLES
    seed: int = 0
    perturbation: float = DEFAULT_PERTURBATION
    diameter: float = SPECIMEN_DIAMETER
    graded: bool = True

    def __post_init__(self) -> None:
        get_material(self.material)  # names the unknown material and the known ones

        def bad(name: str, want: str) -> ClothInputError:
            return ClothInputError(f"cusick: --{name} must be {want}, got "
                                   f"{getattr(self, name)!r}")

        def integer(v) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        def number(v) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        if not isinstance(self.graded, (bool, np.bool_)):
            raise bad("graded", "true or false")
        if not (integer(self.particles) and 300 <= self.particles <= 400_000):
            raise bad("particles", "an integer in [300, 400000]")
        if not (integer(self.seed) and self.seed >= 0):
            raise bad("seed", "a non-negative integer")
        d_min = SUPPORT_DIAMETER + 0.02
        if not (number(self.diameter) and d_min <= self.diameter <= 1.0):
            raise bad("diameter", f"a number of metres in [{d_min:g}, 1]")
        limit = 0.25 * (self.diameter - SUPPORT_DIAMETER)
        if not (number(self.perturbation) and 0.0 <= self.perturbation <= limit):
            raise bad("perturbation", f"a number of metres in [0, {limit:g}]")

    @property
    def radius(self) -> float:
        """Specimen radius, m."""
        return 0.5 * self.diameter

    @property
    def overhang(self) -> float:
        """The annulus' width R - R_support, m: the drape's length scale."""
        return 0.5 * (self.diameter - SUPPORT_DIAMETER)

    @property
    def specimen_area(self) -> float:
        """Nominal specimen area pi R^2, m^2."""
        return math.pi * self.radius ** 2


@dataclass
class CusickScene:
    """The built test: hierarchy, model, initial state; held (k,) the clamped particles;
    support: the lower (support) disc; outer_radius, support_radius: the mesh's
    area-preserving polygon circumradii, m."""

    spec: CusickSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    held: np.ndarray
    support: DiscCollider
    outer_radius: float
    support_radius: float


# ---------------------------------------------------------------------------- the mesh


def _ring(radius: float, n: int, phase: float = 0.0) -> tuple[np.ndarray, float]:
    """(n, 2) the vertices of the regular n-gon with the area of the circle of ``radius``
    (m), and its circumradius, m."""
    big = radius * math.sqrt(2.0 * math.pi / (n * math.sin(2.0 * math.pi / n)))
    t = phase + 2.0 * math.pi * np.arange(n) / n
    return big * np.stack([np.cos(t), np.sin(t)], axis=1), big


def spacing_profile(r: np.ndarray, graded: bool = True) -> np.ndarray:
    """(k,) the mesh spacing at radii r (k,) m, as a multiple of the spacing far from the
    support edge (see the module docstring): CLAMP_SPACING at the support radius, rising
    linearly to 1 over GRADING_WIDTH outwards and to HELD_SPACING over HELD_GRADING_WIDTH
    inwards; 1 everywhere when not ``graded``."""
    r = np.asarray(r, dtype=float)
    if not graded:
        return np.ones_like(r)
    r_s, g = 0.5 * SUPPORT_DIAMETER, CLAMP_SPACING
    out = np.clip(g + (1.0 - g) * (r - r_s) / GRADING_WIDTH, g, 1.0)
    held = np.clip(g + (HELD_SPACING - g) * (r_s - r) / HELD_GRADING_WIDTH, g, HELD_SPACING)
    return np.where(r >= r_s, out, held)


def _vertex_count(radius: float, spacing: float, graded: bool) -> float:
    """Vertices of a near-equilateral mesh of the disc at ``spacing`` (far) m: the integral
    of 1 / (triangle pair area) = 1 / (sqrt(3)/2 h(r)^2) over the disc (a radial sum)."""
    r = np.linspace(0.0, radius, 4001)
    h = spacing * spacing_profile(r, graded)
    f = 2.0 * math.pi * r / (2.0 * EQUILATERAL_AREA * h * h)
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(r)))


def _graded_relax(frame: np.ndarray, inner: np.ndarray, spacing: float, graded: bool,
                  iterations: int) -> np.ndarray:
    """`strips.cvt_relax` towards the density 1 / h(r)^2 of `spacing_profile`."""
    def density(c: np.ndarray) -> np.ndarray:
        return 1.0 / (spacing * spacing_profile(np.hypot(c[:, 0], c[:, 1]), graded)) ** 2

    return cvt_relax(frame, inner, iterations, density)


def disc_coarse(radius: float, support_radius: float, spacing: float, graded: bool = True,
                seed: int = MESH_SEED) -> tuple[MeshLevel, float, float]:
    """A flat disc specimen (z = 0, centred at the origin) of triangles about ``spacing`` m
    across away from the support edge (finer near it when ``graded``: `spacing_profile`),
    with the support circle as a mesh line. Returns (level, outer polygon circumradius,
    support polygon circumradius), m (see the module docstring)."""
    if not (0.0 < support_radius < radius and 0.0 < spacing < 0.25 * support_radius):
        raise ClothInputError(f"disc: need 0 < support radius < radius and 0 < spacing < "
                              f"support radius / 4, got radius={radius}, "
                              f"support_radius={support_radius}, spacing={spacing}")
    h_out, h_sup = (spacing * float(spacing_profile(np.array([r]), graded)[0])
                    for r in (radius, support_radius))
    n_out = max(12, round(2.0 * math.pi * radius / h_out))
    n_sup = max(12, round(2.0 * math.pi * support_radius / h_sup))
    outer, r_out = _ring(radius, n_out)
    ring, r_sup = _ring(support_radius, n_sup, math.pi / n_sup)
    frame = np.concatenate([outer, ring])
    count = max(1, int(_vertex_count(radius, spacing, graded)) - n_out // 2 - n_sup)
    rng = np.random.default_rng(seed)
    # Points drawn with density 1 / h^2 (uniform in the disc, kept with probability
    # (h_min / h)^2), clear of both circles by half the local spacing.
    h_min = float(spacing_profile(np.linspace(0.0, radius, 2001), graded).min())
    inner = np.zeros((0, 2))
    while len(inner) < count:
        r = radius * np.sqrt(rng.uniform(0.0, 1.0, size=4 * count))
        t = rng.uniform(0.0, 2.0 * math.pi, size=4 * count)
        g = spacing_profile(r, graded)
        ok = (rng.uniform(0.0, 1.0, size=len(r)) < (h_min / g) ** 2) \
            & (r < radius - 0.5 * spacing * g) & (np.abs(r - support_radius) > 0.5 * spacing * g)
        inner = np.concatenate([inner, np.stack([r * np.cos(t), r * np.sin(t)], axis=1)[ok]])
    inner = _graded_relax(frame, inner[:count], spacing, graded, _CVT_ITERATIONS)
    rr = np.hypot(inner[:, 0], inner[:, 1])
    h = spacing * spacing_profile(rr, graded)
    keep = (rr < r_out * math.cos(math.pi / n_out) - 0.25 * h) & (np.abs(rr - r_sup) > 0.25 * h)
    # Every support chord must be a mesh edge: it is a Delaunay edge when no point lies in
    # the circle on it as diameter (a Gabriel edge), so points in those circles go.
    sup = frame[n_out:]
    mid = 0.5 * (sup + np.roll(sup, -1, axis=0))
    half = 0.5 * np.linalg.norm(np.roll(sup, -1, axis=0) - sup, axis=1)
    near = np.flatnonzero(keep & (np.abs(rr - r_sup) < 2.0 * half.max()))
    gap = np.linalg.norm(inner[near, None, :] - mid[None, :, :], axis=2) - 1.01 * half
    keep[near[np.any(gap < 0.0, axis=1)]] = False
    pts = np.concatenate([frame, inner[keep]])
    faces = triangulate(pts)
    rest = np.concatenate([pts, np.zeros((len(pts), 1))], axis=1)
    level = MeshLevel(rest, faces, source=f"cusick disc {2 * radius:g} m on {2 * support_radius:g}"
                                          f" m, spacing {spacing:.4g} m"
                                          f"{', graded' if graded else ''}")
    return level, r_out, r_sup


def disc_hierarchy(diameter: float, particles: int, graded: bool = True,
                   seed: int = MESH_SEED) -> tuple[MeshHierarchy, float, float]:
    """A hierarchy of the specimen disc (`disc_coarse`) whose finest level has about
    ``particles`` vertices: as many 1-to-4 subdivisions (at most MAX_DEPTH) as keep
    MIN_CELLS_ACROSS coarse triangles (of the far spacing) across the support radius.
    Returns (hierarchy, outer and support polygon circumradii in m)."""
    radius, support = 0.5 * diameter, 0.5 * SUPPORT_DIAMETER
    # The far spacing that gives the count: the count goes as 1 / spacing^2.
    unit = _vertex_count(radius, 1.0, graded)
    fine = math.sqrt(unit / particles)
    depth = 0
    while depth < MAX_DEPTH and support / (fine * 2 ** (depth + 1)) >= MIN_CELLS_ACROSS:
        depth += 1
    coarse, r_out, r_sup = disc_coarse(radius, support, fine * 2 ** depth, graded, seed)
    return MeshHierarchy.from_coarse(coarse, depth), r_out, r_sup


def perturbation_field(xy: np.ndarray, spec: CusickSpec, support_radius: float
                       ) -> np.ndarray:
    """(n,) the repeat's initial out-of-plane displacement (m) of the points xy (n, 2):
    amplitude * s(phi) * ((r - R_s) / (R - R_s))^2 on the annulus, 0 on the support, where
    s is a random sum of angular modes 1..PERTURBATION_MODES drawn from the seed and scaled
    to max |s| = 1 (no fold count is favoured)."""
    rng = np.random.default_rng(spec.seed)
    k = np.arange(1, PERTURBATION_MODES + 1)
    amp = rng.normal(size=len(k))
    phase = rng.uniform(0.0, 2.0 * math.pi, size=len(k))
    grid = np.linspace(0.0, 2.0 * math.pi, 4096, endpoint=False)
    peak = np.abs(np.cos(np.outer(grid, k) + phase) @ amp).max()
    phi = np.arctan2(xy[:, 1], xy[:, 0])
    s = np.cos(np.outer(phi, k) + phase) @ amp / peak
    r = np.hypot(xy[:, 0], xy[:, 1])
    u = np.clip((r - support_radius) / (spec.radius - support_radius), 0.0, None)
    return spec.perturbation * s * u * u


# ---------------------------------------------------------------------------- the scene


def build_cusick(spec: CusickSpec, material: Material | None = None) -> CusickScene:
    """The test of ``spec``: the specimen flat (plus the seed's perturbation) and centred on
    the support, z up, the clamped cloth plane at SUPPORT_TOP. ``material`` overrides the
    spec's named material (e.g. a modified copy)."""
    mat = material or get_material(spec.material)
    hier, r_out, r_sup = disc_hierarchy(spec.diameter, int(spec.particles), bool(spec.graded))
    rest = np.array(hier.finest.rest)
    xy = rest[:, :2]
    rho = np.hypot(xy[:, 0], xy[:, 1])
    t = CONTACT_THICKNESS
    r_s = 0.5 * SUPPORT_DIAMETER
    z0 = SUPPORT_TOP
    held = np.flatnonzero(rho <= r_sup * (1.0 + 1e-9))
    # Solids shrunk by the contact thickness, so that their contact surfaces (offset by t)
    # are discs of the support radius whose faces touch the clamped cloth's plane.
    lower = DiscCollider(np.array([0.0, 0.0, z0 - t]), r_s - t, PLATE_HEIGHT, CLAMP_FRICTION)
    upper = DiscCollider(np.array([0.0, 0.0, z0 + t + PLATE_HEIGHT]), r_s - t, PLATE_HEIGHT,
                         CLAMP_FRICTION)
    x = np.empty_like(rest)
    x[:, :2] = xy
    x[:, 2] = z0 + perturbation_field(xy, spec, r_sup)
    model = build_model(hier.finest, mat, pinned=held, colliders=[lower, upper],
                        gravity=np.array([0.0, 0.0, -GRAVITY]), thickness=t)
    return CusickScene(spec, hier, model, ClothState.at_rest(x), held, lower, r_out, r_sup)


def natural_period(material: Material, overhang: float) -> float:
    """Period of the hanging annulus' slowest swing, s: a strip of length ``overhang`` (m)
    held at one end, restored by gravity (a pendulum, omega^2 ~ g / l) and by bending (a
    linear cantilever, omega^2 = 1.8751^4 B / (rho l^4)); the sum of the two."""
    w2 = GRAVITY / overhang + 1.8751 ** 4 * material.bend / (material.density * overhang ** 4)
    return 2.0 * math.pi / math.sqrt(w2)


# The sparse direct solver: faster than "mg" on these specimens, at the default 2.5K
# particles and at 20K (doc/design-measurements.md, 'Fidelity', has the figures).
DEFAULT_SOLVER = "direct"


def settle_cusick(scene: CusickScene, solver_name: str = DEFAULT_SOLVER, tol: float = 1e-6,
                  max_steps: int = 3000, on_step=None) -> SettleResult:
    """Settle the specimen (`fidelity.settle.settle_specimen`: steps of an eighth of its
    swing period, air drag at about its angular frequency).
    Every specimen tried came to rest by `fidelity.settle`'s thresholds well within the
    default max_steps (doc/design-measurements.md, 'Fidelity', has the step counts)."""
    return settle_specimen(scene.model, scene.state, scene.hierarchy,
                           natural_period(scene.model.material, scene.spec.overhang),
                           scene.spec.overhang, solver_name, tol, max_steps, on_step=on_step)


# ---------------------------------------------------------------------------- measuring


@njit(cache=True, nogil=True)
def _raster(xy: np.ndarray, faces: np.ndarray, x0: float, y0: float, pixel: float,
            mask: np.ndarray) -> None:
    """Set mask[j, i] where the pixel centre (x0 + (i + 1/2) p, y0 + (j + 1/2) p) lies in a
    triangle of faces (f, 3) over the points xy (n, 2); either orientation."""
    ny, nx = mask.shape
    for f in range(faces.shape[0]):
        ax, ay = xy[faces[f, 0], 0], xy[faces[f, 0], 1]
        bx, by = xy[faces[f, 1], 0], xy[faces[f, 1], 1]
        cx, cy = xy[faces[f, 2], 0], xy[faces[f, 2], 1]
        area2 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area2 == 0.0:
            continue  # seen edge-on: no area
        if area2 < 0.0:  # face seen from below (a fold turned over): flip to ccw
            bx, by, cx, cy = cx, cy, bx, by
        i0 = max(0, math.floor((min(ax, bx, cx) - x0) / pixel - 0.5))
        i1 = min(nx - 1, math.ceil((max(ax, bx, cx) - x0) / pixel - 0.5))
        j0 = max(0, math.floor((min(ay, by, cy) - y0) / pixel - 0.5))
        j1 = min(ny - 1, math.ceil((max(ay, by, cy) - y0) / pixel - 0.5))
        for j in range(j0, j1 + 1):
            py = y0 + (j + 0.5) * pixel
            for i in range(i0, i1 + 1):
                px = x0 + (i + 0.5) * pixel
                if ((bx - ax) * (py - ay) - (by - ay) * (px - ax) >= 0.0
                        and (cx - bx) * (py - by) - (cy - by) * (px - bx) >= 0.0
                        and (ax - cx) * (py - cy) - (ay - cy) * (px - cx) >= 0.0):
                    mask[j, i] = 1


@njit(cache=True, nogil=True)
def _outline(mask: np.ndarray, x0: float, y0: float, pixel: float, cx: float, cy: float,
             bins: int) -> np.ndarray:
    """(bins,) the largest distance from (cx, cy) of a set pixel's centre in each angular
    bin [2 pi k / bins, 2 pi (k + 1) / bins), m (0 where a bin has none)."""
    out = np.zeros(bins)
    ny, nx = mask.shape
    for j in range(ny):
        dy = y0 + (j + 0.5) * pixel - cy
        for i in range(nx):
            if mask[j, i]:
                dx = x0 + (i + 0.5) * pixel - cx
                r = math.sqrt(dx * dx + dy * dy)
                phi = math.atan2(dy, dx)
                if phi < 0.0:
                    phi += 2.0 * math.pi
                k = min(bins - 1, int(phi * bins / (2.0 * math.pi)))
                out[k] = max(out[k], r)
    return out


@dataclass
class Shadow:
    """A shadow raster: mask (ny, nx) uint8, 1 where shaded; pixel i, j covers x0 + [i, i+1) p,
    y0 + [j, j+1) p (m)."""

    mask: np.ndarray
    x0: float
    y0: float
    pixel: float

    @property
    def area(self) -> float:
        """Shaded area, m^2."""
        return float(np.count_nonzero(self.mask)) * self.pixel ** 2

    def outline(self, bins: int = OUTLINE_BINS, centre: tuple[float, float] = (0.0, 0.0)
                ) -> np.ndarray:
        """(bins,) r(phi): the farthest shaded pixel centre from ``centre`` in each angular
        bin (phi from +x, counter-clockwise), m."""
        return _outline(self.mask, self.x0, self.y0, self.pixel, float(centre[0]),
                        float(centre[1]), int(bins))


def shadow_mask(x: np.ndarray, faces: np.ndarray, pixel: float = PIXEL) -> Shadow:
    """The shadow of the triangles faces (f, 3) over the points x (n, 3 or 2) on the xy
    plane: the union of their projections, sampled at the centres of square pixels of side
    ``pixel`` m (a pixel is shaded when its centre lies in a projected triangle; overlaps,
    such as a fold lying over the cloth beneath, count once).

    Error: only pixels that the shadow's outline passes through can be misjudged, each by
    at most p^2, and a curve of length P passes through at most about 2 P / p of them, so
    |area error| <= ~2 P p: 4.5 cm^2 (0.01 in DC) for a drape's 0.9 m outline at 0.25 mm.
    The misjudged pixels' errors cancel, so the actual error, checked against a much finer
    raster, is far smaller (doc/design-measurements.md, 'Fidelity', has the figures).
    """
    xy = np.ascontiguousarray(np.asarray(x, dtype=float)[:, :2])
    lo = xy.min(axis=0) - 2.0 * pixel
    hi = xy.max(axis=0) + 2.0 * pixel
    nx, ny = (math.ceil(v) for v in (hi - lo) / pixel)
    mask = np.zeros((ny, nx), np.uint8)
    _raster(xy, np.ascontiguousarray(faces, dtype=np.int64), float(lo[0]), float(lo[1]),
            float(pixel), mask)
    return Shadow(mask, float(lo[0]), float(lo[1]), float(pixel))


def drape_coefficient(shadow_area: float, specimen_area: float = A_SPECIMEN,
                      disc_area: float = A_DISC) -> float:
    """DC = (A_shadow - A_disc) / (A_specimen - A_disc), areas in m^2 (BS 5058)."""
    return (shadow_area - disc_area) / (specimen_area - disc_area)


def node_peaks(outline: np.ndarray, prominence: float = NODE_PROMINENCE) -> np.ndarray:
    """Indices of the peaks of the periodic outline r(phi) (k,) that stand at least
    ``prominence`` m above the higher of the two troughs that part them from higher crests
    on either side (scipy's topographic prominence, taken on three periods laid end to end
    so that every peak sees both its neighbours); each peak once, sorted. A crest split by
    a shallow dip (less than ``prominence`` deep) counts once."""
    r = np.asarray(outline, dtype=float)
    n = len(r)
    if n < 3 or not np.all(np.isfinite(r)):
        raise ClothInputError(f"node count: the outline must have >= 3 finite radii, got {n}")
    peaks, _ = find_peaks(np.concatenate([r, r, r]), prominence=prominence)
    return np.sort(peaks[(peaks >= n) & (peaks < 2 * n)] - n)


def count_nodes(outline: np.ndarray, prominence: float = NODE_PROMINENCE) -> int:
    """The number of nodes (folds) of a drape: peaks of its periodic outline r(phi) (k,)
    standing at least ``prominence`` m above their troughs (`node_peaks`)."""
    return len(node_peaks(outline, prominence))


def rim_vertices(faces: np.ndarray) -> np.ndarray:
    """Sorted indices of the vertices on the mesh's boundary (edges of one face only) of
    the triangles faces (f, 3): the specimen's hem."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    return np.unique(edges[count == 1])


def measure(scene: CusickScene, state: ClothState, pixel: float = PIXEL,
            bins: int = OUTLINE_BINS, prominence: float = NODE_PROMINENCE) -> dict:
    """The summary's "cusick" block for a settled ``state``: DC, nodes, shadow area (cm^2),
    outline r(phi) (m, ``bins`` values from phi = 0 counter-clockwise), node angles (degrees),
    lengths in m."""
    spec = scene.spec
    mat = scene.model.material
    shadow = shadow_mask(state.x, scene.model.mesh.faces, pixel)
    outline = shadow.outline(bins)
    peaks = node_peaks(outline, prominence)
    area = shadow.area
    x = state.x
    rim = rim_vertices(scene.model.mesh.faces)
    return {
        "material": mat.name, "bend_nm": mat.bend, "density_kgm2": mat.density,
        "stretch_nm": mat.stretch, "shear_nm": mat.shear,
        "bending_length_m": mat.bending_length(GRAVITY), "particles": int(scene.model.n),
        "particles_requested": int(spec.particles), "seed": int(spec.seed),
        "mesh": "graded" if spec.graded else "uniform", "perturbation_m": spec.perturbation,
        "specimen_diameter_m": spec.diameter, "support_diameter_m": SUPPORT_DIAMETER,
        "dc": drape_coefficient(area, spec.specimen_area, A_DISC), "nodes": len(peaks),
        "node_angles_deg": [float(a) for a in (peaks + 0.5) * 360.0 / bins],
        "shadow_area_cm2": 1e4 * area, "specimen_area_cm2": 1e4 * spec.specimen_area,
        "disc_area_cm2": 1e4 * A_DISC, "outline_r_m": [float(r) for r in outline],
        "outline_min_m": float(outline.min()), "outline_max_m": float(outline.max()),
        "outline_mean_m": float(outline.mean()),
        "hem_drop_mean_m": float(np.mean(SUPPORT_TOP - x[rim, 2])),
        "hem_drop_max_m": float(np.max(SUPPORT_TOP - x[rim, 2])),
        "method": {"shadow": f"union raster, {1e3 * pixel:g} mm pixels",
                   "outline_bins": int(bins), "node_prominence_m": prominence},
    }


def run_cusick(spec: CusickSpec, material: Material | None = None,
               solver_name: str = DEFAULT_SOLVER,
               tol: float = 1e-6, max_steps: int = 3000, on_step=None
               ) -> tuple[dict, CusickScene, SettleResult]:
    """Build, settle and measure one Cusick test; the block also carries the settle's
    figures and the whole run's wall time (s)."""
    validate_solver_name(solver_name)
    t0 = time.perf_counter()
    scene = build_cusick(spec, material)
    result = settle_cusick(scene, solver_name, tol, max_steps, on_step)
    block = measure(scene, result.state)
    block["settled"] = bool(result.settled)
    block["settle"] = result.as_dict()
    block["solver"] = solver_name
    block["wall_s"] = time.perf_counter() - t0
    return block, scene, result


def summarise_repeats(blocks: list[dict]) -> dict:
    """Repeatability of a fabric's repeats (blocks of `run_cusick`, one per seed): DC mean,
    sample standard deviation, range; the node counts, their most frequent value (the
    smallest where tied) and the mean DC of the repeats with it (Jeong and Phillips 1998
    report DC at the most frequent node count, as the node count and DC scatter together)."""
    if not blocks:
        raise ClothInputError("cusick repeats: no blocks to summarise")
    dc = np.array([b["dc"] for b in blocks], dtype=float)
    nodes = np.array([b["nodes"] for b in blocks], dtype=np.int64)
    values, counts = np.unique(nodes, return_counts=True)
    mode = int(values[np.argmax(counts)])
    return {
        "repeats": len(blocks), "seeds": [int(b["seed"]) for b in blocks],
        "dc": dc.tolist(), "nodes": nodes.tolist(),
        "dc_mean": float(dc.mean()),
        "dc_std": float(dc.std(ddof=1)) if len(dc) > 1 else 0.0,
        "dc_min": float(dc.min()), "dc_max": float(dc.max()),
        "node_mode": mode, "dc_at_node_mode": float(dc[nodes == mode].mean()),
        "all_settled": all(bool(b.get("settled", False)) for b in blocks),
    }


# ---------------------------------------------------------------------------- the picture


def render_top_view(path: str, scene: CusickScene, state: ClothState, block: dict) -> None:
    """A top-view PNG of the settled drape at ``path``: the shadow filled, the support disc
    and the flat specimen's circle drawn, the outline r(phi) and its nodes marked; the title
    names the material, DC and node count."""
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib

    matplotlib.use("Agg")
    # imported here: matplotlib (charts), loaded only when needed
    import matplotlib.pyplot as plt

    shadow = shadow_mask(state.x, scene.model.mesh.faces)
    ny, nx = shadow.mask.shape
    ext = [shadow.x0, shadow.x0 + nx * shadow.pixel, shadow.y0, shadow.y0 + ny * shadow.pixel]
    fig, ax = plt.subplots(figsize=(6.0, 6.0), dpi=110)
    cm = 100.0  # draw in centimetres
    ax.imshow(shadow.mask, origin="lower", extent=[v * cm for v in ext], cmap="Greys",
              vmin=0, vmax=2.5, interpolation="nearest")
    t = np.linspace(0.0, 2.0 * math.pi, 361)
    for rad, style, label in ((0.5 * SUPPORT_DIAMETER, "-", "support disc"),
                              (scene.spec.radius, "--", "specimen (flat)")):
        ax.plot(cm * rad * np.cos(t), cm * rad * np.sin(t), style, c="tab:blue", lw=1.0,
                label=label)
    r = np.asarray(block["outline_r_m"])
    phi = (np.arange(len(r) + 1) + 0.5) * 2.0 * math.pi / len(r)  # closed: first bin again
    loop = cm * np.append(r, r[0])
    ax.plot(loop * np.cos(phi), loop * np.sin(phi), color="tab:red", lw=1.0,
            label="outline r(phi)")
    ang = np.radians(np.asarray(block["node_angles_deg"], dtype=float))
    if len(ang):
        k = np.minimum((ang / (2.0 * math.pi) * len(r)).astype(int), len(r) - 1)
        ax.plot(cm * r[k] * np.cos(ang), cm * r[k] * np.sin(ang), "o", color="tab:red", ms=4,
                label="nodes")
    lim = cm * (scene.spec.radius + 0.01)
    ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", xlabel="x (cm)",
           ylabel="y (cm)")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title(f"Cusick drape: {block['material']}\nDC {block['dc']:.3f}, "
                 f"{block['nodes']} nodes, {block['particles']} particles, seed {block['seed']}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
