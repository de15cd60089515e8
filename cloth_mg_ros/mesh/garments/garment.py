"""`Garment` and `make_garment`: the entry point that checks its arguments and the body,
builds the named garment's coarse mesh, its hierarchy and its pins; `pin_targets` gives the
pinned vertices' positions for any pose of the body."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.collision.capsules import point_segment_distances
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.body import body_segment_frame, validate_body
from cloth_mg_ros.mesh.garments.cape import build_cape
from cloth_mg_ros.mesh.garments.design import (
    DEFAULT_CLEARANCE,
    DESIGN_MARGIN,
    GARMENTS,
    MIN_PARTICLES,
    NEEDED_SEGMENTS,
    UP,
    Design,
    finalise,
)
from cloth_mg_ros.mesh.garments.top import build_top
from cloth_mg_ros.mesh.garments.tube import build_tube
from cloth_mg_ros.mesh.hierarchy import MAX_DEPTH, MeshHierarchy


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
    d = Design.of(checked)

    if name == 'top':
        rest, faces, dd, pins = build_top(d, clearance, target, depth)
    elif name == 'cape':
        rest, faces, dd, pins = build_cape(d, clearance + DESIGN_MARGIN, target, depth)
    else:
        rest, faces, dd, pins = build_tube(name, d, clearance + DESIGN_MARGIN, target, depth)
    hier = finalise(name, rest, faces, dd, d, clearance)
    fine = hier.finest.rest
    offsets = {}
    for seg, idx in pins.items():
        origin, rot = body_segment_frame(checked, seg)
        offsets[seg] = (fine[idx] - origin) @ rot
    dmin = float((point_segment_distances(fine, d.p0, d.p1) - d.r[None, :]).min())
    return Garment(name=name, hierarchy=hier, rest_positions=fine, pins=pins,
                   pin_offsets=offsets, weft=UP.copy(), clearance=clearance, min_distance=dmin)


def pin_targets(body: Mapping, garment: Garment) -> dict[str, np.ndarray]:
    """World positions the garment's pinned vertices should have for this body pose.

    body: the body (any pose of the one the garment was made on); returns {segment: (k, 3)
    metres}, row i for vertex garment.pins[segment][i]. On the body the garment was made on
    they equal the rest positions of the pinned vertices.
    """
    checked = validate_body(body, required=tuple(garment.pins))
    out = {}
    for seg, offsets in garment.pin_offsets.items():
        origin, rot = body_segment_frame(checked, seg)
        out[seg] = origin[None, :] + offsets @ rot.T
    return out


# ---------------------------------------------------------------------------------------------
# Helpers: loops, normals, design frame
