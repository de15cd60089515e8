"""The hinge measure of saw teeth: triangles whose hinges bend both ways (issue 41's).

Definitions (``hinge_angles``, ``fold_figures``):

* hinge: an interior edge (a, b) with its two faces (a, b, c) and (b, a, d), consistently
  oriented (`mesh.topology.MeshLevel.wings`). Its signed angle theta in (-pi, pi] is the angle
  between the two faces' normals n0 = e x (x_c - x_a) and n1 = (x_d - x_a) x e (e = x_b - x_a),
  signed by (n0 x n1) . e: 0 flat, positive where the surface bends away from the side its
  normals point to (convex seen from that side), negative where it bends towards it. The sign
  of every hinge flips with the mesh's orientation; which triangles are zig-zag does not.
* bending of a hinge: l0^2 theta^2 / (A0 + A1), l0 the edge's rest length and A0, A1 its two
  faces' rest areas (dimensionless). Times (3/8) B (B the flexural rigidity, N m) it is the
  hinge energy of discrete shells (Grinspun et al. 2003; the project's hinge stencil,
  physics.bending, for small angles), so it weights a hinge as the fabric's bending energy
  does, independent of the resolution. A triangle's bending is half of each of its hinges'
  (each hinge's bending split equally between its two faces), so the triangles' bending adds
  up to the garment's: "the share of all bending held by zig-zag triangles" is the zig-zag
  triangles' sum over the total. (Giving each triangle all of its hinges' bending instead
  doubles both sums: the same share.) ``bending_share_hinges`` is a second reading: the share
  of the bending on hinges that touch a zig-zag triangle, each such hinge counted whole.
* a triangle is bent when one of its hinges bends past the threshold (|theta| > threshold),
  and zig-zag when two of its hinges past the threshold bend in opposite directions.
  ``zigzag_share`` is the zig-zag triangles over the bent ones (0 when none is bent);
  ``bending_share`` the zig-zag triangles' bending over all the garment's (0 when it is flat).

A smooth fold whose axis follows the lattice's edges (a cylinder along a grid's lines)
bends all hinges one way: no zig-zag. The angle is measured from flat, not from the rest
shape: the walking dress's rest shape is a tube whose hinges bend one way by a few degrees,
which a smooth fold keeps. What the measure cannot tell from saw teeth:

* a fold whose axis crosses the lattice's rows (the sheet scenes' and the garments'
  lattices have edges along the rows and at 60 or 90 degrees to them; the dress's vertical
  folds cross its horizontal rows): the two triangles on either side of a row's edge
  reach the fold's curve at different points, so the edges along its curvature bend both
  ways by up to half the hinge angle across it (a cylinder of radius 10 cm at 2.5 cm
  spacing: up to 4.1 degrees against 8.3), and past the threshold the whole fold reads as
  zig-zag triangles (95 % for that cylinder), while an accordion pleated at every row, each
  triangle touching one bent row, reads as none;
* a saddle, whose hinges across its two principal directions bend opposite ways, by about
  kappa h (h the mesh spacing): it counts where both curvature radii are under about
  h / 0.052 at 3 degrees (0.5 m at 2.5 cm spacing, 0.25 m at 1.25 cm).

`bench.saw_teeth` measures at the vertices instead, which tells folds from saw teeth on any
lattice; `bench.fold_calibration` shows both measures on known shapes.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.errors import ClothInputError

DEFAULT_THRESHOLD_DEG = 3.0


def checked_positions(x: np.ndarray, mesh) -> np.ndarray:
    """x as (n, 3) float64; ClothInputError naming the shape or the bad value."""
    x = np.asarray(x, dtype=np.float64)
    n = len(mesh.rest)
    if x.shape != (n, 3):
        raise ClothInputError(f"positions must have shape ({n}, 3) for this mesh, got "
                              f"{x.shape}")
    if not np.all(np.isfinite(x)):
        raise ClothInputError(f"positions hold non-finite values (first at row "
                              f"{int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])})")
    return x


def hinge_angles(x: np.ndarray, mesh) -> np.ndarray:
    """Signed angle of every interior edge (hinge), radians, (w,) in the order of
    ``mesh.wings`` (a, b, c, d): 0 flat, positive where the surface bends away from its
    normals' side (module docstring).

    x: (n, 3) positions, m; mesh: a `mesh.topology.MeshLevel` (consistently oriented faces).
    A mesh without interior edges gives an empty array.
    """
    x = checked_positions(x, mesh)
    wings = np.asarray(mesh.wings, dtype=np.int64).reshape(-1, 4)
    if len(wings) == 0:
        return np.zeros(0)
    xa, xb, xc, xd = (x[wings[:, k]] for k in range(4))
    e = xb - xa
    n0 = np.cross(e, xc - xa)
    n1 = np.cross(xd - xa, e)
    # atan2 of (|n0| |n1| |e| sin, |n0| |n1| |e| cos): no normalisation needed, exact near 0
    # and near pi, where arccos of a dot product loses its digits.
    sin = np.einsum("ij,ij->i", np.cross(n0, n1), e)
    cos = np.einsum("ij,ij->i", n0, n1) * np.linalg.norm(e, axis=1)
    return np.arctan2(sin, cos)


def hinge_bending(mesh, theta: np.ndarray) -> np.ndarray:
    """Each hinge's bending l0^2 theta^2 / (A0 + A1) (module docstring), (w,), dimensionless:
    l0 the rest edge length, A0 and A1 its faces' rest areas; theta (w,) radians."""
    wings = np.asarray(mesh.wings, dtype=np.int64).reshape(-1, 4)
    rest = np.asarray(mesh.rest, dtype=np.float64)
    l0_sq = np.sum((rest[wings[:, 1]] - rest[wings[:, 0]]) ** 2, axis=1)
    areas = np.asarray(mesh.face_areas, dtype=np.float64)
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    return l0_sq * theta ** 2 / (areas[pair[:, 0]] + areas[pair[:, 1]])


def classify_faces(x: np.ndarray, mesh, threshold_deg: float = DEFAULT_THRESHOLD_DEG
                   ) -> dict[str, np.ndarray]:
    """Per-hinge and per-face arrays of the measure: {"theta" (w,) rad, "hinge_bending" (w,),
    "face_bending" (t,) (half of each hinge to each of its faces), "bent" (t,) bool (a hinge
    past the threshold), "zigzag" (t,) bool (hinges past it bending both ways)}."""
    threshold_deg = checked_threshold(threshold_deg)
    theta = hinge_angles(x, mesh)
    t = len(mesh.faces)
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    bend = hinge_bending(mesh, theta)
    face_bending = np.bincount(pair.ravel(), weights=np.repeat(0.5 * bend, 2), minlength=t)
    limit = np.radians(threshold_deg)
    up = np.bincount(pair.ravel(), weights=np.repeat(theta > limit, 2).astype(float),
                     minlength=t) > 0
    down = np.bincount(pair.ravel(), weights=np.repeat(theta < -limit, 2).astype(float),
                       minlength=t) > 0
    return {"theta": theta, "hinge_bending": bend, "face_bending": face_bending,
            "bent": up | down, "zigzag": up & down}


def checked_threshold(threshold_deg: float) -> float:
    if not (isinstance(threshold_deg, (int, float)) and np.isfinite(threshold_deg)
            and 0.0 <= threshold_deg < 180.0):
        raise ClothInputError(f"--threshold must be in [0, 180) degrees, got {threshold_deg!r}")
    return float(threshold_deg)


def fold_figures(x: np.ndarray, mesh, threshold_deg: float = DEFAULT_THRESHOLD_DEG) -> dict:
    """The saw-teeth figures of positions x (n, 3) m on mesh (`MeshLevel`), hinges counted
    bent past threshold_deg degrees (module docstring):

    {"triangles", "hinges", "hinges_past_threshold", "bent_triangles" (a hinge past the
    threshold), "zigzag_triangles", "zigzag_share" (zig-zag over bent triangles),
    "bending_share" (the zig-zag triangles' share of all bending, each hinge's bending split
    between its faces), "bending_share_hinges" (the share on hinges touching a zig-zag
    triangle), "bending_total" (the sum of l0^2 theta^2 / (A0 + A1)), "theta_rms_deg",
    "theta_p95_deg", "theta_max_deg", "threshold_deg"}. Shares are fractions in [0, 1].
    """
    c = classify_faces(x, mesh, threshold_deg)
    theta, bend, zig = c["theta"], c["hinge_bending"], c["zigzag"]
    pair = np.asarray(mesh.wing_faces, dtype=np.int64).reshape(-1, 2)
    total = float(bend.sum())
    bent = int(c["bent"].sum())
    on_zig = zig[pair].any(axis=1) if len(pair) else np.zeros(0, dtype=bool)
    deg = np.degrees(np.abs(theta))
    return {
        "threshold_deg": float(threshold_deg),
        "triangles": len(mesh.faces),
        "hinges": len(theta),
        "hinges_past_threshold": int((deg > threshold_deg).sum()),
        "bent_triangles": bent,
        "zigzag_triangles": int(zig.sum()),
        "zigzag_share": float(zig.sum() / bent) if bent else 0.0,
        "bending_share": float(c["face_bending"][zig].sum() / total) if total > 0 else 0.0,
        "bending_share_hinges": float(bend[on_zig].sum() / total) if total > 0 else 0.0,
        "bending_total": total,
        "theta_rms_deg": float(np.sqrt(np.mean(deg ** 2))) if len(deg) else 0.0,
        "theta_p95_deg": float(np.percentile(deg, 95)) if len(deg) else 0.0,
        "theta_max_deg": float(deg.max()) if len(deg) else 0.0,
    }
