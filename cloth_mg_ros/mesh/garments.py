"""Procedural garments worn on a capsule body: skirt, dress, cape and top.

`make_garment(name, body, n_particles)` builds a garment around a body given as plain arrays
(no dependency on the avatar code) and returns a `Garment`: a multigrid `MeshHierarchy` whose
finest level has about `n_particles` vertices, its rest positions, the pinned vertices and
their offsets in the local frames of the body segments they are attached to, and a grain hint.

Body
    A dict segment name -> (p0 (3,), p1 (3,), radius) in metres: the capsule of all points
    within `radius` of the segment p0-p1. Names: `BODY_SEGMENTS` (pelvis, lower_torso,
    upper_torso, head, upper_arm_l, lower_arm_l, hand_l, upper_arm_r, ..., foot_r). Frames are
    z-up (ROS): the garments are designed for a body standing upright along +z, facing
    roughly +x with its left along +y (the avatar's first pose). Facing another way is fine:
    the design frame is taken from the body itself (left = left shoulder/hip joint minus the
    right one, horizontal; forward = left x up). Limb segments run from the proximal joint
    (p0: hip, knee, shoulder, elbow, wrist) to the distal one. Extra segment names are allowed
    and only used for the clearance check. `standing_body()` builds a 1.75 m adult.

Garments (`GARMENTS`), all outward-oriented, built from a coarse mesh of near-equilateral,
near-uniform triangles that is 1-to-4 subdivided `depth` times:

- 'skirt': a flared tube (A-line, elliptical sections) from the waist, half a pelvis radius
  above the top of the pelvis segment's axis, to a quarter of the thigh above the knees. Its
  top ring (every coarse vertex of it) is pinned to 'pelvis'.
- 'dress': a tube from the chest at the highest level below the armpits where it clears the
  arms, widening (bell profile) to mid-calf. Top ring pinned to 'upper_torso'.
- 'cape': a curved panel behind the body spanning +-70 degrees about the back direction,
  from the top of the shoulders to knee height; it hangs like a cloth from its top edge over
  the shoulder blades and the seat (per-direction concave hull of the body's profile). Its top
  edge (every coarse vertex) is pinned to 'upper_torso'.
- 'top': a T-shirt: a snug offset surface (clearance + 8 mm) of the smooth union of pelvis,
  torso and upper-arm capsules, cut at the hip (hem), around the neck and across each upper
  arm (short sleeves): one manifold mesh with 4 boundary loops (neck, waist, two sleeve ends),
  closed over the shoulders. It is pinned at the 3 coarse vertices nearest the middle of
  each shoulder (6 pins) to 'upper_torso'. Being closed over the shoulders with a neck opening
  narrower than them, it would also stay on by contact alone; the pins keep it in place
  without relying on contact. Needs a visible gap between the upper arms and the torso (the
  sleeve ends must not touch the torso); otherwise ClothInputError.

Tubes and the cape are meshed as rows of vertices at equal arc length, consecutive rows
offset by half a spacing and zipped into strips of triangles (rows about sqrt(3)/2 apart:
equilateral where the row lengths match). The top is meshed by marching tetrahedra on its
implicit surface, then isotropic remeshing (split / collapse / valence flips / tangential
smoothing with projection onto the surface and of boundary vertices onto their cut curve),
then split/collapse until the vertex count is exactly the one the target needs.

Rest shape: the generated shape itself (rest_positions = finest level's rest); with flat
1-to-4 subdivision the finest level lies on the coarse mesh's facets. Tubes and cones are
developable, so the rest metric is that of a garment that is not pre-stressed.

Clearance: every finest vertex is at least `clearance` (default 1.5 cm) outside every capsule
of the body. The designs keep 1 cm more (8 mm for the top) than `clearance` from the
capsules; the finest level is then checked and, where a vertex is too close (facets of a
coarse ring cut inside the smooth design), the coarse vertices it is interpolated from are
pushed away from that capsule's axis by the deficit and the hierarchy is rebuilt (up to 5
times); ClothInputError if that does not succeed (a body too tight for the garment).

Size policy (like `choose_sheet_resolution`): depth=None picks the deepest depth (at most
`MAX_AUTO_DEPTH`) whose coarsest mesh keeps about `MIN_COARSE_VERTICES[name]` vertices or
more (estimated as n_particles / 4^depth); the coarse resolution is then chosen to land the
finest count as close as possible to `n_particles` (within 1% in practice). An explicit depth
is refused when the nearest garment at that depth misses by more than 25% (skirt, dress,
cape) or its coarse top would have fewer than 80 or more than 4000 vertices.

Pins and frames: pinned vertices are coarse vertices, so the same indices are valid on every
level. `segment_frame(p0, p1, reference)` defines a segment's frame from its capsule and a
reference direction (see there); `segment_reference(body, segment)` gives the reference this
module uses: the vector from the right to the left shoulder joint (upper_arm_l.p0 -
upper_arm_r.p0) for upper_torso, head and the arm segments, from the right to the left hip
joint (upper_leg_l.p0 - upper_leg_r.p0) for every other segment. It turns with the body, so
`pin_targets(body, garment)` follows any rigid motion of the body and the torso's twist.

Grain: `Garment.weft` is the world up direction (0, 0, 1). `physics.stretch.material_frames`
projects it into each triangle: the material u axis then runs down the garment (along the
tube), the v axis horizontally around the body. Weft and warp have the same stiffness in the
material model, so only the consistency of the frames matters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import MAX_AUTO_DEPTH
from cloth_mg_ros.mesh.hierarchy import MAX_DEPTH, MeshHierarchy, subdivided_counts
from cloth_mg_ros.mesh.topology import MeshLevel

__all__ = [
    'ARM_SEGMENTS',
    'BODY_SEGMENTS',
    'DEFAULT_CLEARANCE',
    'GARMENTS',
    'MIN_COARSE_VERTICES',
    'MIN_PARTICLES',
    'NEEDED_SEGMENTS',
    'Garment',
    'boundary_loops',
    'capsule_distances',
    'make_garment',
    'pin_targets',
    'segment_frame',
    'segment_reference',
    'standing_body',
    'transform_body',
    'validate_body',
]

BODY_SEGMENTS = (
    'pelvis', 'lower_torso', 'upper_torso', 'head',
    'upper_arm_l', 'lower_arm_l', 'hand_l', 'upper_arm_r', 'lower_arm_r', 'hand_r',
    'upper_leg_l', 'lower_leg_l', 'foot_l', 'upper_leg_r', 'lower_leg_r', 'foot_r',
)
ARM_SEGMENTS = ('upper_arm_l', 'lower_arm_l', 'hand_l', 'upper_arm_r', 'lower_arm_r', 'hand_r')
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

_UP = np.array([0.0, 0.0, 1.0])
_MARGIN = 0.010        # m, design stand-off beyond the clearance (facet sag of coarse rows)
_TOP_MARGIN = 0.02  # m beyond the clearance: ease (slack) so the body can move inside the top
_TOP_BLEND = 0.02      # m, smooth-union radius of the top's capsules (armpits, shoulders)
_MAX_EXPLICIT_MISS = 0.25
_CAPE_HALF_ANGLE = math.radians(70.0)
_ROW_RATIO = math.sqrt(3.0) / 2.0
_PIN_REFERENCE = {
    'upper_torso': 'shoulders', 'head': 'shoulders',
    'upper_arm_l': 'shoulders', 'lower_arm_l': 'shoulders', 'hand_l': 'shoulders',
    'upper_arm_r': 'shoulders', 'lower_arm_r': 'shoulders', 'hand_r': 'shoulders',
}  # everything else: 'hips'

Capsule = tuple[np.ndarray, np.ndarray, float]


# ---------------------------------------------------------------------------------------------
# Body input
# ---------------------------------------------------------------------------------------------

def _vec3(value: object, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ClothInputError(f'{what} must be 3 numbers, got {value!r}') from None
    if arr.shape != (3,):
        raise ClothInputError(f'{what} must have shape (3,), got shape {arr.shape}')
    if not np.isfinite(arr).all():
        raise ClothInputError(f'{what} is not finite: {arr.tolist()}')
    return arr


def validate_body(body: Mapping, required: tuple[str, ...] = BODY_SEGMENTS
                  ) -> dict[str, Capsule]:
    """Check a body and return it as {name: (p0 (3,) float64, p1 (3,) float64, radius)}.

    body: mapping segment name -> (p0, p1, radius), metres. required: names that must be
    present. Raises ClothInputError naming the missing segment, or the segment and field
    that is malformed or not finite, or a radius that is not positive.
    """
    if not isinstance(body, Mapping):
        raise ClothInputError(
            f'body must be a dict segment name -> (p0, p1, radius), got {type(body).__name__}')
    for name in required:
        if name not in body:
            raise ClothInputError(
                f"body is missing segment '{name}' (needed: {', '.join(required)}; "
                f"given: {', '.join(map(str, body)) or 'nothing'})")
    out: dict[str, Capsule] = {}
    for name, value in body.items():
        if not isinstance(name, str):
            raise ClothInputError(f'body segment names must be strings, got {name!r}')
        try:
            p0, p1, radius = value
        except (TypeError, ValueError):
            raise ClothInputError(
                f"body segment '{name}' must be (p0, p1, radius), got {value!r}") from None
        a = _vec3(p0, f"body segment '{name}' p0")
        b = _vec3(p1, f"body segment '{name}' p1")
        try:
            r = float(radius)
        except (TypeError, ValueError):
            raise ClothInputError(
                f"body segment '{name}' radius must be a number, got {radius!r}") from None
        if not math.isfinite(r) or r <= 0.0:
            raise ClothInputError(
                f"body segment '{name}' radius must be positive and finite, got {radius!r}")
        out[name] = (a, b, r)
    return out


def standing_body() -> dict[str, Capsule]:
    """A 1.75 m adult standing upright in a neutral pose (for tests and development).

    Feet on z = 0, facing +x, left along +y; arms hanging about 18 degrees away from the
    body (forearms 20 degrees, slightly forward), so there is a gap between arms and torso.
    Returns {segment: (p0 (3,), p1 (3,), radius)} in metres for all `BODY_SEGMENTS`; limbs
    run proximal -> distal, torso segments bottom -> top.
    """
    def arm(side: float) -> dict[str, Capsule]:
        sh = np.array([0.0, 0.19 * side, 1.43])
        a1, a2 = math.radians(18.0), math.radians(20.0)
        elbow = sh + 0.29 * np.array([0.0, math.sin(a1) * side, -math.cos(a1)])
        wrist = elbow + np.array([0.03, 0.25 * math.sin(a2) * side, -0.25 * math.cos(a2)])
        tip = wrist + np.array([0.01, 0.02 * side, -0.12])
        s = 'l' if side > 0 else 'r'
        return {f'upper_arm_{s}': (sh, elbow, 0.045), f'lower_arm_{s}': (elbow, wrist, 0.038),
                f'hand_{s}': (wrist, tip, 0.035)}

    def leg(side: float) -> dict[str, Capsule]:
        hip = np.array([0.0, 0.09 * side, 0.90])
        knee = np.array([0.0, 0.095 * side, 0.49])
        ankle = np.array([0.0, 0.095 * side, 0.085])
        s = 'l' if side > 0 else 'r'
        return {f'upper_leg_{s}': (hip, knee, 0.07), f'lower_leg_{s}': (knee, ankle, 0.05),
                f'foot_{s}': (np.array([-0.02, 0.10 * side, 0.045]),
                              np.array([0.16, 0.11 * side, 0.04]), 0.04)}

    body: dict[str, Capsule] = {
        'pelvis': (np.array([0.0, 0.0, 0.90]), np.array([0.0, 0.0, 1.00]), 0.145),
        'lower_torso': (np.array([0.0, 0.0, 1.00]), np.array([0.0, 0.0, 1.18]), 0.12),
        'upper_torso': (np.array([0.0, 0.0, 1.18]), np.array([0.0, 0.0, 1.38]), 0.13),
        'head': (np.array([0.0, 0.0, 1.57]), np.array([0.0, 0.0, 1.66]), 0.09),
    }
    for side in (1.0, -1.0):
        body.update(arm(side))
        body.update(leg(side))
    return {name: body[name] for name in BODY_SEGMENTS}


def transform_body(body: Mapping, rotation: np.ndarray, translation: np.ndarray
                   ) -> dict[str, Capsule]:
    """The body moved rigidly: every p -> rotation @ p + translation (radii unchanged).

    rotation: (3, 3) proper rotation matrix; translation: (3,) metres.
    """
    rot = np.asarray(rotation, dtype=np.float64)
    t = _vec3(translation, 'translation')
    if rot.shape != (3, 3) or not np.isfinite(rot).all():
        raise ClothInputError(f'rotation must be a finite (3, 3) matrix, got shape {rot.shape}')
    checked = validate_body(body, required=())
    return {k: (rot @ p0 + t, rot @ p1 + t, r) for k, (p0, p1, r) in checked.items()}


def _arrays(body: Mapping[str, Capsule], names: tuple[str, ...] | list[str] | None = None
            ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    names = list(body) if names is None else list(names)
    p0 = np.array([body[n][0] for n in names], dtype=np.float64).reshape(-1, 3)
    p1 = np.array([body[n][1] for n in names], dtype=np.float64).reshape(-1, 3)
    r = np.array([body[n][2] for n in names], dtype=np.float64)
    return names, p0, p1, r


def _segment_distances(points: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Distances (n, c) from points (n, 3) to segments p0-p1 (c, 3), chunked for memory."""
    d = p1 - p0
    len2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-300)
    out = np.empty((len(points), len(p0)))
    step = max(1, 2_000_000 // max(1, len(p0)))
    for s in range(0, len(points), step):
        w = points[s:s + step, None, :] - p0[None]
        t = np.clip(np.einsum('ncj,cj->nc', w, d) / len2, 0.0, 1.0)
        out[s:s + step] = np.linalg.norm(w - t[..., None] * d[None], axis=2)
    return out


def capsule_distances(points: np.ndarray, body: Mapping
                      ) -> tuple[list[str], np.ndarray]:
    """Signed distances of points to the capsule surfaces of a body.

    points: (n, 3) metres. Returns (names, d) with d (n, k) metres, column j for segment
    names[j]: distance to segment names[j]'s axis minus its radius (negative inside).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    names, p0, p1, r = _arrays(validate_body(body, required=()))
    return names, _segment_distances(pts, p0, p1) - r[None, :]


def _ray_capsules(origin: np.ndarray, direction: np.ndarray, p0: np.ndarray, p1: np.ndarray,
                  radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit parameters t of the rays origin + t direction (n, 3; unit directions)
    through capsules (c,): arrays (n, c), NaN where the ray's line misses the capsule.

    A capsule is convex, so its intersection with a line is one interval: the smallest entry
    and the largest exit over its cylinder and its two end spheres.
    """
    o, u = origin[:, None, :], direction[:, None, :]
    r2 = (radius ** 2)[None, :]
    t_in = np.full((len(origin), len(p0)), np.nan)
    t_out = t_in.copy()
    with np.errstate(invalid='ignore', divide='ignore'):
        for c in (p0, p1):
            oc = o - c[None]
            b = np.sum(oc * u, axis=2)
            disc = b * b - (np.sum(oc * oc, axis=2) - r2)
            s = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
            t_in, t_out = np.fmin(t_in, -b - s), np.fmax(t_out, -b + s)
        axis = p1 - p0
        length = np.linalg.norm(axis, axis=1)
        a = axis / np.maximum(length, 1e-300)[:, None]
        w = o - p0[None]
        ua, wa = np.sum(u * a[None], axis=2), np.sum(w * a[None], axis=2)
        up, wp = u - ua[..., None] * a[None], w - wa[..., None] * a[None]
        qa, qb = np.sum(up * up, axis=2), np.sum(up * wp, axis=2)
        qc = np.sum(wp * wp, axis=2) - r2
        disc = qb * qb - qa * qc
        par = qa < 1e-12
        s = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        c0 = np.where(par, np.where(qc <= 0.0, -np.inf, np.nan), (-qb - s) / qa)
        c1 = np.where(par, np.where(qc <= 0.0, np.inf, np.nan), (-qb + s) / qa)
        along = np.abs(ua) > 1e-12
        s0, s1 = -wa / ua, (length[None, :] - wa) / ua
        inside_slab = (wa >= 0.0) & (wa <= length[None, :])
        lo = np.where(along, np.minimum(s0, s1), np.where(inside_slab, -np.inf, np.nan))
        hi = np.where(along, np.maximum(s0, s1), np.where(inside_slab, np.inf, np.nan))
        c0, c1 = np.maximum(c0, lo), np.minimum(c1, hi)
        ok = c0 <= c1
        t_in = np.fmin(t_in, np.where(ok, c0, np.nan))
        t_out = np.fmax(t_out, np.where(ok, c1, np.nan))
    return t_in, t_out


# ---------------------------------------------------------------------------------------------
# Segment frames and pins
# ---------------------------------------------------------------------------------------------

def segment_frame(p0: np.ndarray, p1: np.ndarray, reference: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Local frame of a segment from its capsule axis and a reference direction.

    p0, p1: (3,) segment ends, metres; reference: (3,) any direction not parallel to the axis.
    Returns (origin (3,), R (3, 3)): origin = p0; R's columns are the local axes in world
    coordinates: z = unit(p1 - p0) (along the segment), y = the reference made orthogonal to
    z and normalised, x = y cross z. A local point q maps to origin + R @ q; a world point x
    to R.T @ (x - origin). With the reference pointing to the body's left and a segment
    pointing up, x points forward. Where the reference is (nearly) parallel to the axis, the
    world axis least aligned with the segment replaces it. Raises ClothInputError for a
    zero-length segment.
    """
    a = _vec3(p0, 'segment p0')
    axis = _vec3(p1, 'segment p1') - a
    length = float(np.linalg.norm(axis))
    if length < 1e-9:
        raise ClothInputError(f'segment has zero length (p0 = p1 = {a.tolist()}): no frame')
    ez = axis / length
    ref = _vec3(reference, 'reference direction')
    perp = ref - (ref @ ez) * ez
    if np.linalg.norm(perp) < 1e-6 * max(1.0, float(np.linalg.norm(ref))):
        ref = np.eye(3)[int(np.argmin(np.abs(ez)))]
        perp = ref - (ref @ ez) * ez
    ey = perp / np.linalg.norm(perp)
    ex = np.cross(ey, ez)
    return a, np.column_stack([ex, ey, ez])


def segment_reference(body: Mapping, segment: str) -> np.ndarray:
    """The reference direction (3,) this module uses for `segment_frame` of `segment`.

    upper_torso, head and arm segments: upper_arm_l.p0 - upper_arm_r.p0 (right to left
    shoulder joint); every other segment: upper_leg_l.p0 - upper_leg_r.p0 (hip joints).
    Both move with the body, so frames (and pins) follow its rigid motions and the torso's
    twist. Raises ClothInputError if the two segments it needs are missing.
    """
    kind = _PIN_REFERENCE.get(segment, 'hips')
    left, right = (('upper_arm_l', 'upper_arm_r') if kind == 'shoulders'
                   else ('upper_leg_l', 'upper_leg_r'))
    checked = validate_body(body, required=(left, right))
    return checked[left][0] - checked[right][0]


def _frame(body: Mapping[str, Capsule], segment: str) -> tuple[np.ndarray, np.ndarray]:
    p0, p1, _ = body[segment]
    return segment_frame(p0, p1, segment_reference(body, segment))


def pin_targets(body: Mapping, garment: Garment) -> dict[str, np.ndarray]:
    """World positions the garment's pinned vertices should have for this body pose.

    body: the body (any pose of the one the garment was made on); returns {segment: (k, 3)
    metres}, row i for vertex garment.pins[segment][i]. On the body the garment was made on
    they equal the rest positions of the pinned vertices.
    """
    checked = validate_body(body, required=tuple(garment.pins))
    out = {}
    for seg, offsets in garment.pin_offsets.items():
        origin, rot = _frame(checked, seg)
        out[seg] = origin[None, :] + offsets @ rot.T
    return out


# ---------------------------------------------------------------------------------------------
# Helpers: loops, normals, design frame
# ---------------------------------------------------------------------------------------------

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


def _vertex_normals(rest: np.ndarray, faces: np.ndarray) -> np.ndarray:
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
class _Design:
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
    def of(cls, body: dict[str, Capsule]) -> _Design:
        names, p0, p1, r = _arrays(body)
        if 'upper_arm_l' in body and 'upper_arm_r' in body:
            lat = body['upper_arm_l'][0] - body['upper_arm_r'][0]
        else:
            lat = body['upper_leg_l'][0] - body['upper_leg_r'][0]
        left = _horizontal_unit(lat, np.array([0.0, 1.0, 0.0]))
        fwd = np.cross(left, _UP)
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
        o = self.centre[None, None, :] + z[:, None, None] * _UP
        o = np.broadcast_to(o, (len(z), len(theta), 3)).reshape(-1, 3)
        u = np.broadcast_to(dirs[None], (len(z), len(theta), 3)).reshape(-1, 3)
        t_in, t_out = _ray_capsules(o, u, self.p0[mask], self.p1[mask], self.r[mask] + radius_pad)
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


def _smax(a: np.ndarray, b: np.ndarray, eps: float = 0.005) -> np.ndarray:
    """Smooth maximum >= max(a, b), within eps of it."""
    return 0.5 * (a + b) + np.sqrt(0.25 * (a - b) ** 2 + eps * eps)


# ---------------------------------------------------------------------------------------------
# Row-based surfaces (tubes and the cape) and their meshing
# ---------------------------------------------------------------------------------------------

@dataclass
class _RowSurface:
    """A surface point(theta, z) = centre + z up + rho(theta, z) (cos theta fwd + sin theta
    left), tabulated on a theta grid (periodic for tubes) and a descending z grid."""

    design: _Design
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
        return (d.centre[None, None, :] + zs[:, None, None] * _UP
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
class _RowPlan:
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


def _plan_rows(surface: _RowSurface, spacing: float, min_count: int, stretch: float = 1.0
               ) -> _RowPlan:
    """Rows about stretch * spacing * sqrt(3)/2 apart along the mean meridian, each cut into
    intervals of about `spacing` metres."""
    ell = surface.meridian()
    n_rows = max(2, round(ell[-1] / (stretch * spacing * _ROW_RATIO)))
    zs = np.interp(np.linspace(0.0, ell[-1], n_rows + 1), ell, surface.z)
    counts = np.maximum(min_count, np.round(surface.interp_lengths(zs) / spacing)).astype(int)
    return _RowPlan(zs, counts, surface.closed)


def _mesh_rows(surface: _RowSurface, plan: _RowPlan) -> tuple[np.ndarray, np.ndarray,
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


def _best_plan(surface: _RowSurface, target: int, depth: int, min_count: int
               ) -> tuple[_RowPlan, int]:
    """The row plan whose mesh, subdivided `depth` times, comes closest to `target`
    vertices. Scans the spacing, then around the best one also the row spacing (up to 10%
    off the equilateral sqrt(3)/2, weighted like `choose_sheet_resolution`: score
    |log(count / target)| + 0.25 |log(stretch)|). Returns (plan, finest vertex count)."""
    ell = surface.meridian()[-1]
    width = float(surface.interp_lengths(surface.z).max())
    best: tuple[float, _RowPlan, int] | None = None
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


# ---------------------------------------------------------------------------------------------
# Skirt, dress and cape designs
# ---------------------------------------------------------------------------------------------

def _tube_surface(d: _Design, name: str, z_top: float, z_bot: float, flare: float,
                  power: float, pad: float) -> _RowSurface:
    """A flared tube around the torso axis from z_top down to z_bot: radius per direction
    rho = smax(body reach, top ring + s^power * amplitude), s = 0 at the top, 1 at the hem.
    The top ring hugs the body. The flare amplitude per direction is `flare`, reduced
    (smoothly around the body) where the arms leave less room."""
    theta = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
    z = np.linspace(z_top, z_bot, 96)
    inner = d.mask(ARM_SEGMENTS, invert=True)
    reach = d.reach(theta, z, pad, inner)
    room, who = d.room(theta, z, pad, ~inner)
    s = ((z_top - z) / (z_top - z_bot))[:, None] ** power
    base = reach[0][None, :]
    clash = reach > room
    if clash.any():
        iz, it = np.argwhere(clash)[0]
        raise ClothInputError(
            f"{name}: segment '{d.names[who[iz, it]]}' is too close to the body at height "
            f"{z[iz]:.3f} m for the {name} to clear both by the clearance")
    fracs = np.linspace(0.0, 1.0, 41)
    rho_c = _smax(reach[None], base[None] + s[None] * fracs[:, None, None] * flare)
    ok = (rho_c <= room[None]).all(axis=1)   # (41, nt)
    frac = np.where(ok.all(axis=0), 1.0, fracs[np.argmin(ok, axis=0) - 1].clip(0.0))
    if not ok[0].all():
        it = int(np.argmin(ok[0]))
        iz = int(np.argmax(rho_c[0, :, it] > room[:, it]))
        raise ClothInputError(
            f"{name}: segment '{d.names[who[iz, it]]}' leaves no room for the {name} at height "
            f"{z[iz]:.3f} m")
    # Smooth the allowed flare around the body without exceeding it anywhere: a circular
    # minimum over +-32 samples, then a box blur over +-16.
    w = 32
    ext = np.concatenate([frac[-w:], frac, frac[:w]])
    mins = np.lib.stride_tricks.sliding_window_view(ext, 2 * w + 1).min(axis=1)
    ext = np.concatenate([mins[-w // 2:], mins, mins[:w // 2]])
    frac = np.lib.stride_tricks.sliding_window_view(ext, w + 1).mean(axis=1)
    rho = _smax(reach, base + s * frac[None, :] * flare)
    return _RowSurface(d, theta, z, rho, closed=True)


def _dress_top(d: _Design, pad: float) -> float:
    """Highest height below the armpits where a ring around the torso clears the arms with
    2 cm to spare over a 4 cm band below it."""
    theta = np.linspace(0.0, 2.0 * math.pi, 128, endpoint=False)
    shoulder = min(d.body['upper_arm_l'][0][2], d.body['upper_arm_r'][0][2])
    z = np.arange(shoulder - 0.04, d.bottom_z('lower_torso'), -0.005)
    inner = d.mask(ARM_SEGMENTS, invert=True)
    spare = (d.room(theta, z, pad, ~inner)[0] - d.reach(theta, z, pad, inner)).min(axis=1)
    fits = spare >= 0.02
    band = 8
    for i in range(len(z) - band):
        if fits[i:i + band + 1].all():
            return float(z[i])
    raise ClothInputError(
        'dress: the upper arms hang too close to the torso: no height between the shoulders '
        'and the waist leaves room for the top of the dress between torso and arms')


def _cape_surface(d: _Design, pad: float) -> _RowSurface:
    """A panel behind the body, theta in pi +- 70 degrees, from the top of the shoulders to
    the knees, hanging like a cloth: per direction, the concave hull of the body's reach as a
    function of depth below the top edge, vertical below its widest point, plus a slight
    flare (5 cm at the hem)."""
    body = d.body
    shoulder = 0.5 * (body['upper_arm_l'][0][2] + body['upper_arm_r'][0][2])
    arm_r = 0.5 * (body['upper_arm_l'][2] + body['upper_arm_r'][2])
    z_top = shoulder + 0.5 * arm_r
    z_bot = 0.5 * (d.bottom_z('upper_leg_l') + d.bottom_z('upper_leg_r'))
    theta = math.pi + np.linspace(-_CAPE_HALF_ANGLE, _CAPE_HALF_ANGLE, 121)
    z = np.linspace(z_top, z_bot, 120)
    reach = d.reach(theta, z, pad, np.ones(len(d.names), bool))
    depth = z_top - z
    rho = np.empty_like(reach)
    for k in range(len(theta)):
        col = reach[:, k]
        top = int(np.argmax(col))
        hull = [0]
        for i in range(1, top + 1):  # upper concave hull of (depth, reach) up to the maximum
            while len(hull) >= 2:
                i0, i1 = hull[-2], hull[-1]
                cross = ((depth[i1] - depth[i0]) * (col[i] - col[i0])
                         - (col[i1] - col[i0]) * (depth[i] - depth[i0]))
                if cross >= 0.0:
                    hull.pop()
                else:
                    break
            hull.append(i)
        rho[:, k] = np.where(np.arange(len(z)) <= top,
                             np.interp(depth, depth[hull], col[hull]), col[top])
    rho = np.maximum(rho, reach) + 0.05 * (depth / depth[-1])[:, None] ** 2
    return _RowSurface(d, theta, z, rho, closed=False)


# ---------------------------------------------------------------------------------------------
# The top: implicit surface, marching tetrahedra, isotropic remeshing
# ---------------------------------------------------------------------------------------------

_TETS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                  [0, 4, 6, 7]])
_TET_EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def _mt_table() -> dict[int, list[list[int]]]:
    def e(p: int, q: int) -> int:
        return _TET_EDGES.index((min(p, q), max(p, q)))

    table = {}
    for mask in range(1, 15):
        inside = [k for k in range(4) if mask >> k & 1]
        outside = [k for k in range(4) if not mask >> k & 1]
        if len(inside) == 1:
            tris = [[e(inside[0], o) for o in outside]]
        elif len(inside) == 3:
            tris = [[e(outside[0], i) for i in inside]]
        else:
            (i, j), (k, m) = inside, outside
            tris = [[e(i, k), e(i, m), e(j, m)], [e(i, k), e(j, m), e(j, k)]]
        table[mask] = tris
    return table


_MT_TABLE = _mt_table()


def _marching_tets(func: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, step: float,
                   shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Zero surface of func (negative inside) on a grid: (vertices (n, 3), faces (t, 3)),
    faces oriented with normals towards increasing func (outward). A manifold surface: each
    cube is split into 6 tetrahedra along its main diagonal, consistently across cubes."""
    nx, ny, nz = shape
    axes = [lo[k] + step * np.arange(shape[k]) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing='ij'), axis=-1).reshape(-1, 3)
    vals = func(grid)
    vals = np.where(np.abs(vals) < 1e-9, 1e-9, vals)
    ci, cj, ck = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), np.arange(nz - 1),
                             indexing='ij')
    base = ((ci * ny + cj) * nz + ck).ravel()
    off = np.array([(c & 1) * ny * nz + (c >> 1 & 1) * nz + (c >> 2 & 1) for c in range(8)])
    tets = (base[:, None, None] + off[_TETS][None]).reshape(-1, 4)
    mask = ((vals[tets] < 0.0) * np.array([1, 2, 4, 8])).sum(axis=1)
    edges = np.array(_TET_EDGES)
    ends_p, ends_q = [], []
    for m, tris in _MT_TABLE.items():
        sel = tets[mask == m]
        if len(sel) == 0:
            continue
        for tri in tris:
            e = edges[tri]
            ends_p.append(sel[:, e[:, 0]])
            ends_q.append(sel[:, e[:, 1]])
    if not ends_p:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    p, q = np.concatenate(ends_p), np.concatenate(ends_q)
    n_grid = len(grid)
    keys = np.minimum(p, q) * n_grid + np.maximum(p, q)
    uniq, inv = np.unique(keys.ravel(), return_inverse=True)
    a, b = uniq // n_grid, uniq % n_grid
    t = vals[a] / (vals[a] - vals[b])
    verts = grid[a] + t[:, None] * (grid[b] - grid[a])
    faces = inv.reshape(-1, 3).astype(np.int64)
    p0, q0 = p[:, 0], q[:, 0]
    outward = np.where((vals[p0] < 0.0)[:, None], grid[q0] - grid[p0], grid[p0] - grid[q0])
    normal = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]],
                      verts[faces[:, 2]] - verts[faces[:, 0]])
    flip = np.einsum('ij,ij->i', normal, outward) < 0.0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return verts, faces


def _edge_table(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per face side (t, 3) edge ids and per-edge face counts."""
    a, b = faces, np.roll(faces, -1, axis=1)
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, inv, counts = np.unique(key.ravel(), return_inverse=True, return_counts=True)
    return inv.reshape(-1, 3), counts


def _clean_open_mesh(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the largest edge-connected piece of a cut mesh, without dangling triangles
    (two or more boundary sides) or vertices where two boundary fans touch."""
    n = len(verts)
    for _ in range(50):
        if len(faces) == 0:
            break
        side_edge, counts = _edge_table(faces, n)
        border = counts[side_edge] == 1
        ears = border.sum(axis=1) >= 2
        per_vertex = np.bincount(faces[border].ravel() if border.any() else np.zeros(0, int),
                                 minlength=n)
        pinch = per_vertex > 2
        bad = ears | pinch[faces].any(axis=1)
        # Largest component by shared edges.
        e_ids = side_edge.ravel()
        f_ids = np.repeat(np.arange(len(faces)), 3)
        inc = sp.csr_matrix((np.ones(len(e_ids)), (f_ids, e_ids)))
        _, label = connected_components(inc @ inc.T, directed=False)
        main = label == np.argmax(np.bincount(label))
        keep = main & ~bad
        if keep.all():
            break
        faces = faces[keep]
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]


@dataclass
class _TopShape:
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
        d = _segment_distances(x, self.p0, self.p1) - self.r[None, :]
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
        d = _segment_distances(x, self.p0, self.p1) - self.r[None, :]
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


def _top_shape(d: _Design, clearance: float) -> _TopShape:
    body = d.body
    blend_names = ['pelvis', 'lower_torso', 'upper_torso', 'upper_arm_l', 'upper_arm_r']
    _, p0, p1, r = _arrays(body, blend_names)
    offset = clearance + _TOP_MARGIN
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
    _, t0, t1, tr = _arrays(body, torso_names)
    arm_p0, arm_dir, s_end, r_cut = [], [], [], []
    for side in ('l', 'r'):
        a0, a1, ar = body[f'upper_arm_{side}']
        # The shoulder end is the one nearer the upper torso's axis.
        if (_segment_distances(a1[None], ut0[None], ut1[None])[0, 0]
                < _segment_distances(a0[None], ut0[None], ut1[None])[0, 0]):
            a0, a1 = a1, a0
        length = float(np.linalg.norm(a1 - a0))
        u = (a1 - a0) / max(length, 1e-12)
        # The sleeve end is cut by a cylinder of radius rc around the arm; it must stay off the
        # torso's surface, so the arm needs a gap `need` (axis to torso capsule surfaces,
        # minus the arm radius) everywhere below the sleeve end.
        rc = ar + offset + 0.25 * k + 0.004
        need = 2.0 * offset + 0.25 * k + 0.012
        s = np.linspace(0.0, length + ar, 80)
        gap = (_segment_distances(a0 + s[:, None] * u, t0, t1) - tr).min(axis=1) - ar
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
    return _TopShape(p0, p1, r, offset, k, float(z_hem), collar, neck_dir, float(r_neck),
                     np.array(arm_p0), np.array(arm_dir), np.array(s_end), np.array(r_cut))


def _top_initial_mesh(shape: _TopShape, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Marching tetrahedra of the top's solid, cut faces removed: the open top surface."""
    pad = shape.offset + shape.blend + 2.0 * step
    ends = np.concatenate([shape.p0, shape.p1])
    radii = np.concatenate([shape.r, shape.r])
    lo = (ends - radii[:, None]).min(axis=0) - pad
    hi = (ends + radii[:, None]).max(axis=0) + pad
    lo[2] = max(lo[2], shape.z_hem - 2.0 * step)
    dims = tuple(math.ceil((hi[k] - lo[k]) / step) + 1 for k in range(3))
    verts, faces = _marching_tets(shape.psi, lo, step, dims)
    cen = verts[faces].mean(axis=1)
    keep = shape.phi(cen) >= shape.cuts(cen).max(axis=1)
    verts, faces = _clean_open_mesh(verts, faces[keep])
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


class _Remesher:
    """Isotropic remeshing of an open surface on the top's implicit shape (Botsch-Kobbelt:
    split long edges, collapse short ones, flip towards valence 6 (4 on the boundary),
    tangential smoothing, projection). Boundary vertices stay on their boundary curve.
    Topology changes are limited to these local operations with link-condition checks, so
    the surface keeps its topology (one piece, four boundary loops)."""

    def __init__(self, verts: np.ndarray, faces: np.ndarray, shape: _TopShape):
        self.shape = shape
        self.P: list[list[float]] = verts.tolist()
        self.F: list[list[int]] = faces.tolist()
        self.falive = [True] * len(self.F)
        self.valive = [True] * len(self.P)
        self.vf: list[set[int]] = [set() for _ in self.P]
        for fi, f in enumerate(self.F):
            for v in f:
                self.vf[v].add(fi)
        side_edge, counts = _edge_table(faces, len(verts))
        border = np.zeros(len(verts), bool)
        border[faces[counts[side_edge] == 1].ravel()] = True
        cut = np.argmin(np.abs(shape.curve_values(verts)), axis=1)
        self.vcut: list[int] = np.where(border, cut, -1).tolist()
        self.vsize: list[float] = shape.sizing(verts).tolist()

    # --- small helpers -----------------------------------------------------------------
    def nbrs(self, v: int) -> set[int]:
        out: set[int] = set()
        for f in self.vf[v]:
            out.update(self.F[f])
        out.discard(v)
        return out

    def _normal(self, a: list[float], b: list[float], c: list[float]) -> tuple[float, ...]:
        ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        return (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)

    def _quality(self, tri: list[list[float]], twice_area: float | None = None) -> float:
        """2 area / (longest side)^2: 0.87 for an equilateral triangle, 0 for a sliver."""
        if twice_area is None:
            twice_area = math.sqrt(sum(x * x for x in self._normal(*tri)))
        longest = max(math.dist(tri[0], tri[1]), math.dist(tri[1], tri[2]),
                      math.dist(tri[2], tri[0]))
        return twice_area / max(longest * longest, 1e-300)

    def _len(self, a: int, b: int) -> float:
        p, q = self.P[a], self.P[b]
        return math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Compacted (verts, faces, vcut)."""
        alive = np.array(self.valive)
        remap = np.cumsum(alive) - 1
        faces = np.array([f for f, ok in zip(self.F, self.falive, strict=True) if ok])
        return (np.array(self.P)[alive], remap[faces].astype(np.int64),
                np.array(self.vcut)[alive])

    def edges(self) -> np.ndarray:
        faces = np.array([f for f, ok in zip(self.F, self.falive, strict=True) if ok])
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        return np.unique(np.sort(e, axis=1), axis=0)

    @property
    def n_vertices(self) -> int:
        return sum(self.valive)

    # --- operations ----------------------------------------------------------------------
    def split(self, a: int, b: int) -> int:
        fs = list(self.vf[a] & self.vf[b])
        p, q = self.P[a], self.P[b]
        m = len(self.P)
        self.P.append([(p[0] + q[0]) / 2, (p[1] + q[1]) / 2, (p[2] + q[2]) / 2])
        self.valive.append(True)
        self.vf.append(set())
        self.vcut.append(self.vcut[a] if len(fs) == 1 else -1)
        self.vsize.append(0.5 * (self.vsize[a] + self.vsize[b]))
        for f in fs:
            tri = self.F[f]
            k = next(i for i in range(3) if {tri[i], tri[(i + 1) % 3]} == {a, b})
            u, v, w = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            self.F[f] = [u, m, w]
            g = len(self.F)
            self.F.append([m, v, w])
            self.falive.append(True)
            self.vf[v].discard(f)
            self.vf[v].add(g)
            self.vf[w].add(g)
            self.vf[m].update((f, g))
        return m

    def try_collapse(self, a: int, b: int, hi: float) -> bool:
        """Collapse edge (a, b) if legal; hi: maximum length of the edges it creates."""
        shared = self.vf[a] & self.vf[b]
        if not shared:
            return False
        ba, bb = self.vcut[a] >= 0, self.vcut[b] >= 0
        border_edge = len(shared) == 1
        if ba and bb and not border_edge:
            return False
        if ba and not bb:
            a, b = b, a  # keep the boundary vertex b
        na, nb = self.nbrs(a), self.nbrs(b)
        opp = {v for f in shared for v in self.F[f]} - {a, b}
        if na & nb != opp:
            return False
        if border_edge:
            c = next(iter(opp))
            if self.vcut[c] >= 0 and len(self.vf[a] & self.vf[c]) == 1 \
                    and len(self.vf[b] & self.vf[c]) == 1:
                return False
            p = [(self.P[a][k] + self.P[b][k]) / 2 for k in range(3)]
        elif ba or bb:
            p = list(self.P[b])
        else:
            p = [(self.P[a][k] + self.P[b][k]) / 2 for k in range(3)]
        size = 0.5 * (self.vsize[a] + self.vsize[b])
        for v in (na | nb) - {a, b}:
            if math.dist(p, self.P[v]) > hi * 0.5 * (size + self.vsize[v]):
                return False
        for f in (self.vf[a] | self.vf[b]) - shared:
            tri = self.F[f]
            old = [self.P[v] for v in tri]
            new = [p if v in (a, b) else self.P[v] for v in tri]
            n0, n1 = self._normal(*old), self._normal(*new)
            l0 = math.sqrt(sum(x * x for x in n0))
            l1 = math.sqrt(sum(x * x for x in n1))
            if self._quality(new, l1) < min(0.1, 0.5 * self._quality(old, l0)):
                return False
            if l0 > 1e-14 and sum(x * y for x, y in zip(n0, n1, strict=True)) < 0.3 * l0 * l1:
                return False
        for f in shared:
            self.falive[f] = False
            for v in self.F[f]:
                self.vf[v].discard(f)
        for f in self.vf[a]:
            self.F[f] = [b if v == a else v for v in self.F[f]]
            self.vf[b].add(f)
        self.vf[a] = set()
        self.valive[a] = False
        self.P[b] = p
        self.vsize[b] = size
        return True

    def try_flip(self, a: int, b: int) -> bool:
        shared = list(self.vf[a] & self.vf[b])
        if len(shared) != 2:
            return False
        f1 = f2 = -1
        c = d = -1
        for f in shared:
            tri = self.F[f]
            k = tri.index(a)
            if tri[(k + 1) % 3] == b:
                f1, c = f, tri[(k + 2) % 3]
            else:
                f2, d = f, tri[(k + 1) % 3]
        if f1 < 0 or f2 < 0 or c == d or d in self.nbrs(c):
            return False

        def target(v: int) -> int:
            return 4 if self.vcut[v] >= 0 else 6

        val = {v: len(self.nbrs(v)) for v in (a, b, c, d)}
        before = sum((val[v] - target(v)) ** 2 for v in (a, b, c, d))
        after = ((val[a] - 1 - target(a)) ** 2 + (val[b] - 1 - target(b)) ** 2
                 + (val[c] + 1 - target(c)) ** 2 + (val[d] + 1 - target(d)) ** 2)
        if after >= before:
            return False
        pa, pb, pc, pd = self.P[a], self.P[b], self.P[c], self.P[d]
        n0 = [x + y for x, y in zip(self._normal(pa, pb, pc), self._normal(pb, pa, pd),
                                    strict=True)]
        n1, n2 = self._normal(pa, pd, pc), self._normal(pd, pb, pc)
        l0 = math.sqrt(sum(x * x for x in n0))
        q_old = min(self._quality([pa, pb, pc]), self._quality([pb, pa, pd]))
        for n, tri in ((n1, [pa, pd, pc]), (n2, [pd, pb, pc])):
            ln = math.sqrt(sum(x * x for x in n))
            if self._quality(tri, ln) < min(0.1, 0.5 * q_old) or \
                    sum(x * y for x, y in zip(n, n0, strict=True)) < 0.5 * ln * l0:
                return False
        self.F[f1] = [a, d, c]
        self.F[f2] = [d, b, c]
        self.vf[b].discard(f1)
        self.vf[d].add(f1)
        self.vf[a].discard(f2)
        self.vf[c].add(f2)
        return True

    # --- passes --------------------------------------------------------------------------
    def scaled_lengths(self) -> tuple[np.ndarray, np.ndarray]:
        """Edges (e, 2) and their lengths over the wanted relative size (e,)."""
        e = self.edges()
        pos, size = np.array(self.P), np.array(self.vsize)
        length = np.linalg.norm(pos[e[:, 0]] - pos[e[:, 1]], axis=1)
        return e, length / (0.5 * (size[e[:, 0]] + size[e[:, 1]]))

    def _scaled(self, a: int, b: int) -> float:
        return self._len(a, b) / (0.5 * (self.vsize[a] + self.vsize[b]))

    def split_long(self, hi: float) -> None:
        e, length = self.scaled_lengths()
        for k in np.argsort(-length):
            if length[k] <= hi:
                break
            a, b = int(e[k, 0]), int(e[k, 1])
            if self.vf[a] & self.vf[b] and self._scaled(a, b) > hi:
                self.split(a, b)

    def collapse_short(self, lo: float, hi: float) -> None:
        e, length = self.scaled_lengths()
        for k in np.argsort(length):
            if length[k] >= lo:
                break
            a, b = int(e[k, 0]), int(e[k, 1])
            if self.valive[a] and self.valive[b] and self._scaled(a, b) < lo:
                self.try_collapse(a, b, hi)

    def flip_all(self) -> None:
        for a, b in self.edges().tolist():
            self.try_flip(a, b)

    def relax(self, iters: int = 1, lam: float = 0.5) -> None:
        verts, faces, cut = self.arrays()
        alive = np.flatnonzero(np.array(self.valive))
        n = len(verts)
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        adj = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        adj = ((adj + adj.T) > 0).astype(float)
        bmask = cut >= 0
        # boundary adjacency: edges with one face
        side_edge, counts = _edge_table(faces, n)
        be = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])[
            (counts[side_edge] == 1).T.ravel()]
        badj = sp.csr_matrix((np.ones(len(be)), (be[:, 0], be[:, 1])), shape=(n, n))
        badj = ((badj + badj.T) > 0).astype(float)
        deg = np.asarray(adj.sum(axis=1)).ravel()
        bdeg = np.maximum(np.asarray(badj.sum(axis=1)).ravel(), 1.0)
        x = verts
        for _ in range(iters):
            normals = _vertex_normals(x, faces)
            lap = adj @ x / deg[:, None] - x
            lap -= np.einsum('ij,ij->i', lap, normals)[:, None] * normals
            blap = badj @ x / bdeg[:, None] - x
            x = x + lam * np.where(bmask[:, None], blap, lap)
            inner = ~bmask
            x[inner] = self.shape.project(x[inner])
            x[bmask] = self.shape.project_curve(x[bmask], cut[bmask])
        size = self.shape.sizing(x)
        for i, v in enumerate(alive.tolist()):
            self.P[v] = x[i].tolist()
            self.vsize[v] = float(size[i])


def _remesh_top(shape: _TopShape, verts: np.ndarray, faces: np.ndarray, length: float,
                n_target: Callable[[int], int], iters: int = 8
                ) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic remeshing to edge length `length`, then interior splits/collapses until the
    vertex count is n_target(boundary vertex count), then flips and smoothing."""
    rm = _Remesher(verts, faces, shape)
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


def _top_pins(d: _Design, rest: np.ndarray, per_side: int = 3) -> np.ndarray:
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


# ---------------------------------------------------------------------------------------------
# Size policy, final check, make_garment
# ---------------------------------------------------------------------------------------------

def _top_counts(n: int, n_border: int, depth: int) -> int:
    """Finest vertex count of a top (sphere with 4 holes, Euler characteristic -2) with n
    coarse vertices, n_border of them on the boundary."""
    t = 2 * n - n_border + 4
    return subdivided_counts(n, n + t + 2, t, depth)[0]


def _choose_depth(name: str, target: int, depth: int | None,
                  coarse_for: Callable[[int], int]) -> int:
    """depth=None: deepest depth <= MAX_AUTO_DEPTH whose coarse mesh (coarse_for(depth)
    vertices) keeps MIN_COARSE_VERTICES[name]; explicit depths are checked."""
    if depth is not None:
        return depth
    for dd in range(MAX_AUTO_DEPTH, -1, -1):
        if coarse_for(dd) >= MIN_COARSE_VERTICES[name]:
            return dd
    return 0


def _finalise(name: str, rest: np.ndarray, faces: np.ndarray, depth: int, d: _Design,
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
        dist = _segment_distances(fine, d.p0, d.p1) - d.r[None, :]
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


_MAX_TOP_COARSE = 4000   # the top's remeshing runs in Python: refuse huge coarse meshes
_MIN_TOP_COARSE = 80     # fewer coarse vertices cannot shape the sleeves


def _build_top(d: _Design, clearance: float, target: int, depth: int | None
               ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest, faces), depth and pins of the top."""
    shape = _top_shape(d, clearance)
    border_guess = 60  # boundary vertices of a typical coarse top (only to pick the depth)

    def coarse_for(dd: int) -> int:
        return max(1, round((target + (4 ** dd - 1) * border_guess / 2) / 4 ** dd))

    dd = _choose_depth('top', target, depth, coarse_for)
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

    rest, faces = _remesh_top(shape, verts, faces, length, goal)
    return rest, faces, dd, {'upper_torso': _top_pins(d, rest)}


# Flare at the hem (m) and how it grows from the top ring (power of the fraction of the
# length). Walking asks for room: a thigh swung forward by 30 degrees moves the knee about
# 0.2 m forward, so an A-line (power ~1) with a generous flare lets the avatar stride without
# the legs stretching the cloth; a narrow bell (power 2) would be stretched by every step.
SKIRT_FLARE, SKIRT_FLARE_POWER = 0.22, 1.0
DRESS_FLARE, DRESS_FLARE_POWER = 0.34, 1.1


def _build_rows(name: str, d: _Design, pad: float, target: int, depth: int | None
                ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest, faces), depth and pins of the skirt, the dress or the cape."""
    body = d.body
    if name == 'skirt':
        z_top = d.top_z('pelvis') + 0.5 * body['pelvis'][2]
        knee = 0.5 * (d.bottom_z('upper_leg_l') + d.bottom_z('upper_leg_r'))
        hip = 0.5 * (d.top_z('upper_leg_l') + d.top_z('upper_leg_r'))
        surface = _tube_surface(d, name, z_top, knee + 0.25 * (hip - knee), SKIRT_FLARE,
                                SKIRT_FLARE_POWER, pad)
        pin_seg = 'pelvis'
    elif name == 'dress':
        z_top = _dress_top(d, pad)
        calf = 0.25 * sum(body[f'lower_leg_{s}'][k][2] for s in 'lr' for k in (0, 1))
        surface = _tube_surface(d, name, z_top, calf, DRESS_FLARE, DRESS_FLARE_POWER, pad)
        pin_seg = 'upper_torso'
    else:
        surface = _cape_surface(d, pad)
        pin_seg = 'upper_torso'
    min_count = 8 if surface.closed else 4

    def coarse_for(dd: int) -> int:
        return round(target / 4 ** dd)

    dd = _choose_depth(name, target, depth, coarse_for)
    plan, got = _best_plan(surface, target, dd, min_count)
    if abs(got / target - 1.0) > _MAX_EXPLICIT_MISS:
        raise ClothInputError(
            f'n_particles={target} is too small for a {name} at depth={dd}: the nearest '
            f'{name} at that depth has {got} particles')
    rest, faces, top_row = _mesh_rows(surface, plan)
    return rest, faces, dd, {pin_seg: top_row.astype(np.int64)}


@dataclass(eq=False)
class Garment:
    """A garment ready to simulate.

    Attributes:
        name: one of GARMENTS.
        hierarchy: MeshHierarchy, levels[0] the finest (simulated) mesh, levels[-1] the
            coarse mesh it was subdivided from.
        rest_positions: (n, 3) float64, metres: hierarchy.finest.rest (the start and rest
            shape; read-only).
        pins: {segment: (k,) int64} pinned vertex indices (coarse vertices, valid on every
            level) attached to that body segment.
        pin_offsets: {segment: (k, 3) float64} the pinned vertices' positions in the
            segment's local frame (`segment_frame` with `segment_reference`), metres.
        weft: (3,) unit grain hint for `build_model(..., weft=)`: world up (see module doc).
        clearance: requested minimum distance to every capsule, metres.
        min_distance: the smallest distance of any rest vertex to any capsule, metres.
    """

    name: str
    hierarchy: MeshHierarchy
    rest_positions: np.ndarray
    pins: dict[str, np.ndarray]
    pin_offsets: dict[str, np.ndarray]
    weft: np.ndarray
    clearance: float
    min_distance: float

    @property
    def n_particles(self) -> int:
        """Vertices of the finest level."""
        return self.hierarchy.finest.n_vertices

    @property
    def pinned_vertices(self) -> np.ndarray:
        """All pinned vertex indices, sorted (k_total,) int64."""
        if not self.pins:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(list(self.pins.values())))


def _positive_float(value: object, what: str) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ClothInputError(f'{what} must be a number, got {value!r}') from None
    if not math.isfinite(v) or v <= 0.0:
        raise ClothInputError(f'{what} must be positive and finite, got {value!r}')
    return v


def make_garment(name: str, body: Mapping, n_particles: int, depth: int | None = None,
                 clearance: float = DEFAULT_CLEARANCE) -> Garment:
    """Build garment `name` ('skirt', 'dress', 'cape', 'top') around `body`.

    body: {segment: (p0 (3,), p1 (3,), radius)} in metres (see module docstring; at least
        NEEDED_SEGMENTS[name]). n_particles: wanted finest vertex count (>= MIN_PARTICLES).
    depth: number of 1-to-4 subdivisions (None: the size policy in the module docstring).
    clearance: minimum distance of every rest vertex from every capsule, metres.
    Returns a Garment. Raises ClothInputError for an unknown garment (listing the known ones),
    a too small or non-integer n_particles, a bad depth, a missing segment (named), a
    malformed or non-finite body, or a body the garment cannot be fitted to.
    """
    if name not in GARMENTS:
        raise ClothInputError(f"unknown garment {name!r}; known garments: {', '.join(GARMENTS)}")
    if isinstance(n_particles, bool) or not isinstance(n_particles, (int, np.integer)):
        raise ClothInputError(f'n_particles must be an integer, got {n_particles!r}')
    if n_particles < MIN_PARTICLES[name]:
        raise ClothInputError(
            f'n_particles={n_particles} is too small for a {name}: at least '
            f'{MIN_PARTICLES[name]} particles')
    if depth is not None and (isinstance(depth, bool) or not isinstance(depth, (int, np.integer))
                              or not 0 <= depth <= MAX_DEPTH):
        raise ClothInputError(f'depth must be None or an integer in [0, {MAX_DEPTH}], '
                              f'got {depth!r}')
    depth = None if depth is None else int(depth)
    clearance = _positive_float(clearance, 'clearance')
    target = int(n_particles)
    checked = validate_body(body, required=NEEDED_SEGMENTS[name])
    d = _Design.of(checked)

    if name == 'top':
        rest, faces, dd, pins = _build_top(d, clearance, target, depth)
    else:
        rest, faces, dd, pins = _build_rows(name, d, clearance + _MARGIN, target, depth)
    hier = _finalise(name, rest, faces, dd, d, clearance)
    fine = hier.finest.rest
    offsets = {}
    for seg, idx in pins.items():
        origin, rot = _frame(checked, seg)
        offsets[seg] = (fine[idx] - origin) @ rot
    dmin = float((_segment_distances(fine, d.p0, d.p1) - d.r[None, :]).min())
    return Garment(name=name, hierarchy=hier, rest_positions=fine, pins=pins,
                   pin_offsets=offsets, weft=_UP.copy(), clearance=clearance, min_distance=dmin)
