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

Modules: `body` (the capsule body: checks, `standing_body`, distances, segment frames),
`design` (what every garment shares: sizes, `Design`, depth policy, `finalise`), `rows`
(row-meshed surfaces), `tube` (skirt, dress), `cape`, `top` with `isosurface` and `remesh`,
and `garment` (`Garment`, `make_garment`, `pin_targets`).

Grain: `Garment.weft` is the world up direction (0, 0, 1). `physics.stretch.material_frames`
projects it into each triangle: the material u axis then runs down the garment (along the
tube), the v axis horizontally around the body. Weft and warp have the same stiffness in the
material model, so only the consistency of the frames matters.
"""

from cloth_mg_ros.mesh.garments.body import (
    ARM_SEGMENTS,
    BODY_SEGMENTS,
    Capsule,
    capsule_distances,
    segment_frame,
    segment_reference,
    standing_body,
    transform_body,
    validate_body,
)
from cloth_mg_ros.mesh.garments.design import (
    DEFAULT_CLEARANCE,
    GARMENTS,
    MIN_COARSE_VERTICES,
    MIN_PARTICLES,
    NEEDED_SEGMENTS,
    boundary_loops,
)
from cloth_mg_ros.mesh.garments.garment import Garment, make_garment, pin_targets
from cloth_mg_ros.mesh.garments.tube import (
    DRESS_FLARE,
    DRESS_FLARE_POWER,
    SKIRT_FLARE,
    SKIRT_FLARE_POWER,
)

__all__ = [
    'ARM_SEGMENTS',
    'BODY_SEGMENTS',
    'DEFAULT_CLEARANCE',
    'DRESS_FLARE',
    'DRESS_FLARE_POWER',
    'GARMENTS',
    'MIN_COARSE_VERTICES',
    'MIN_PARTICLES',
    'NEEDED_SEGMENTS',
    'SKIRT_FLARE',
    'SKIRT_FLARE_POWER',
    'Capsule',
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
