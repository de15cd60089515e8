"""Built-in scenes without a body: a sheet draped over a sphere, and a sheet hung by two corners.

Frames are z-up (ROS REP 103), metres. A scene declares only what it needs: the drape has a
sphere and a floor, the hang has two grippers holding its top corners and no collider.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.collision.colliders import PlaneCollider, SphereCollider
from cloth_mg_ros.collision.mesh_collider import MeshCollider, RigidPose
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import (
    MAX_PARTICLES,
    MIN_PARTICLES,
    sheet_hierarchy,
    top_corner_vertices,
)
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.io import hierarchy_from_file
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.sim.grippers import GripperSet
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model

SCENES = ("drape", "hang")
# The sheet scenes with a collider for the cloth to rub against (the `friction` parameter's):
# the hang has none, so a friction given to it would be taken and never used.
FRICTION_SCENES = ("drape",)
SHEET_SIZE = 1.0  # m
DRAPE_SHEET_HEIGHT = 0.85  # m, the sheet starts 10 cm above the sphere
DRAPE_SPHERE = (np.array([0.0, 0.0, 0.5]), 0.25)  # centre m, radius m
HANG_CENTRE = np.array([0.0, 0.0, 1.0])  # m, the sheet's top edge is at 1.5 m
HANG_GRIPPERS = ("left", "right")  # at -x and +x


@dataclass
class Scene:
    """A ready-to-step scene: hierarchy (levels[0] is simulated), model, initial state."""

    name: str
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    spheres: list = field(default_factory=list)
    grippers: GripperSet | None = None


def scene_hierarchy(particles: int, levels: int | None, mesh_path: str | None, plane: str,
               centre: np.ndarray) -> MeshHierarchy:
    depth = None if levels is None else levels - 1
    if mesh_path is None:
        return sheet_hierarchy(particles, depth, SHEET_SIZE, SHEET_SIZE, plane=plane,
                               centre=tuple(centre))
    return hierarchy_from_file(mesh_path, particles, depth)


def scene_friction(name: str, friction: float | None) -> float | None:
    """The friction `build_scene` takes for sheet scene ``name``: ``friction`` for a scene
    with a collider (FRICTION_SCENES), None for one without (the hang)."""
    return friction if name in FRICTION_SCENES else None


def validate_particles(particles: int) -> int:
    """Reject particle counts that cannot make a sheet, naming the value."""
    if isinstance(particles, bool) or not isinstance(particles, (int, np.integer)):
        raise ClothInputError(f"--particles must be an integer, got {particles!r}")
    if not MIN_PARTICLES <= particles <= MAX_PARTICLES:
        raise ClothInputError(f"--particles must be in {MIN_PARTICLES}..{MAX_PARTICLES}, got "
                              f"{particles}")
    return int(particles)


def build_scene(name: str, particles: int, material: Material, mesh_path: str | None = None,
                levels: int | None = None, obstacle: str | None = None,
                friction: float | None = None, compression: str = "elastic",
                contact_friction: str = "projection") -> Scene:
    """Build scene ``name`` with about ``particles`` cloth particles.

    mesh_path: a coarse triangle mesh file replacing the built-in sheet (it is moved to where
    the sheet would be). levels: number of hierarchy levels (None: as many as the size calls
    for). obstacle: drape only, a closed triangle mesh file (metres) replacing the sphere: it
    is moved so that its top is where the sphere's is, centred under the sheet.
    friction: Coulomb coefficient of the cloth against the scene's obstacle and floor (the
    scene parameter ``friction``; None: each collider's own, the sphere 0.3, the floor and a
    mesh obstacle 0.5); FRICTION_SCENES only: the hang refuses one (`scene_friction` gives
    what a scene takes). compression, contact_friction: sim.model.build_model's.
    """
    if name not in SCENES:
        raise ClothInputError(f"unknown scene {name!r}; choose one of {', '.join(SCENES)}")
    validate_particles(particles)
    if friction is not None and not (np.isfinite(friction) and friction >= 0.0):
        raise ClothInputError(f"friction must be a number >= 0, got {friction!r}")
    if friction is not None and name not in FRICTION_SCENES:
        raise ClothInputError(f"friction is not a parameter of the {name} scene: it has no "
                              f"collider to rub against")
    if levels is not None and (levels < 1 or levels > 7):
        raise ClothInputError(f"--levels must be between 1 and 7, got {levels}")
    if name == "drape":
        centre = np.array([0.0, 0.0, DRAPE_SHEET_HEIGHT])
        hier = scene_hierarchy(particles, levels, mesh_path, "xy", centre)
        floor = PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]))
        bodies = {}  # where the obstacle stands (ClothState.bodies)
        if obstacle is None:
            body, spheres = SphereCollider(*DRAPE_SPHERE), [DRAPE_SPHERE]
        else:
            body, spheres = _mesh_obstacle(obstacle), []
            bodies[0] = _obstacle_pose(body)
        if friction is not None:
            body.friction = floor.friction = float(friction)
        rest = placed_on_scene(hier, centre, mesh_path)
        model = build_model(hier.levels[0], material, colliders=[body, floor],
                            compression=compression, contact_friction=contact_friction)
        state = ClothState.at_rest(rest)
        state.bodies.update(bodies)
        return Scene(name, hier, model, state, spheres)
    if obstacle is not None:
        raise ClothInputError("--obstacle replaces the drape scene's sphere; the hang scene has "
                              "no collider")
    hier = scene_hierarchy(particles, levels, mesh_path, "xz", HANG_CENTRE)
    rest = placed_on_scene(hier, HANG_CENTRE, mesh_path)
    corners = top_corner_vertices(rest, plane="xz")
    if corners[0] == corners[1]:
        raise ClothInputError("hang scene: the mesh has a single top corner; it needs two")
    # The model pins the corners as the grippers hold them (GripperSet.apply makes the same
    # list), so a caller that steps the model without its grippers gets the same hang.
    model = build_model(hier.levels[0], material, pinned=corners, compression=compression)
    return Scene(name, hier, model, ClothState.at_rest(rest), grippers=hang_grippers(rest, corners))


def hang_grippers(rest: np.ndarray, corners: np.ndarray) -> GripperSet:
    """The hang's two holders, grippers ``left`` and ``right``, each holding its top corner
    particle (exactly that one, so the hang is the same cloth it was with pinned corners)."""
    grippers = GripperSet(HANG_GRIPPERS)
    for name, corner in zip(HANG_GRIPPERS, corners, strict=True):
        grippers.set_pose(name, rest[corner])
        grippers.hold(name, np.array([corner]), rest)
    return grippers


def _mesh_obstacle(path: str) -> MeshCollider:
    """A mesh collider for the drape (`_obstacle_pose` stands it where the sphere is)."""
    return MeshCollider(path)


def _obstacle_pose(collider: MeshCollider) -> RigidPose:
    """The pose standing ``collider`` where the drape sphere is: top at the sphere's top,
    centred."""
    lo, hi = collider.mesh.bounds
    top = DRAPE_SPHERE[0] + np.array([0.0, 0.0, DRAPE_SPHERE[1]])
    offset = np.array([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -hi[2]]) + top
    return collider.moved(None, np.eye(3), offset)


def placed_on_scene(hier: MeshHierarchy, centre: np.ndarray, mesh_path: str | None) -> np.ndarray:
    """Initial positions: the finest rest shape, a file mesh moved so its box centre is at
    ``centre``."""
    rest = np.array(hier.levels[0].rest)
    if mesh_path is not None:
        box_centre = 0.5 * (rest.min(axis=0) + rest.max(axis=0))
        rest += centre - box_centre
    return rest
