"""Model (what does not change during a run), State (what a step advances) and Control (what
the outside world sets before each step), after Newton physics: a step reads a State and a
Control and writes a State.

All quantities SI: positions m, velocities m/s, masses kg, forces N.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.collision.colliders import posed
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.topology import MeshLevel
from cloth_mg_ros.physics.bending import BendingTerms, bending_terms
from cloth_mg_ros.physics.bending_law import FabricBending
from cloth_mg_ros.physics.incidence import MeshIncidence
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.physics.stretch import StretchElements, stretch_elements

GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2, z up as in ROS (REP 103)
COMPRESSION_MODELS = ("buckle", "elastic")
BENDING_MODELS = ("mean", "law")
# Where the cloth's friction against the colliders acts (sim.contact_friction): "projection",
# after the solve on each particle alone (the node's); "solve", inside it, with the contacts
# that pressed at the last step kept (opt-in: see that module)
CONTACT_FRICTIONS = ("projection", "solve")
# The penalty's multiple of m / h^2 with friction in the solve: its contacts then carry the
# load the projection carried (the walking dress at 9964 particles after 100 messages holds
# 0.13 J of stretch with 100, doc/benchmarks/folds.md; 3.9 J with the projection's 10)
SOLVE_CONTACT_STIFFNESS = 100.0


def require_positive(name: str, value) -> None:
    """ClothInputError naming `name` and `value` unless value is a finite number > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not (np.isfinite(value) and value > 0.0):
        raise ClothInputError(f"{name} must be a finite number > 0, got {value!r}")


def require_strain_limit(value, name: str = "strain_limit") -> None:
    """ClothInputError unless value is None (no limit) or a finite number > 1: the limiter
    (physics.strain_limit) shortens every edge longer than value times its rest length, so
    1 would hold the cloth at its rest lengths and less would shrink every edge."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not (np.isfinite(value) and value > 1.0):
        raise ClothInputError(f"{name} must be None or a finite number > 1 (the longest an "
                              f"edge may become over its rest length), got {value!r}")


def require_physical(obj, positive: tuple[str, ...]) -> None:
    """ClothInputError unless obj's attributes named in `positive` are finite numbers > 0 and
    its strain_limit is None or a finite number > 1 (`require_strain_limit`)."""
    for name in positive:
        require_positive(name, getattr(obj, name))
    require_strain_limit(obj.strain_limit)


@dataclass(frozen=True)
class ClothModel:
    """A cloth mesh with its material and the constants of its energies: frozen once built
    (a variant is ``dataclasses.replace(model, ...)``; what a run changes is the State's and
    the Control's).

    mesh: the simulated (finest) level. mass: (n,) kg, lumped from vertex areas.
    stretch: per-triangle stretch/shear constants. bending: the bending Hessian's stencils
    (physics.bending.BendingTerms: hinges and stars, N/m), which the faithful coarsening
    carries to every level. bend_pairs: (m,) their entries summed per mesh pair.
    pinned: (k,) indices of the particles the scene holds by Baraff-Witkin filtered
    constraints (sewn pins, a hang's corners) unless the Control names others (grippers
    that grasp and let go: ClothControl.pinned); where they go is the Control's.
    self_contact: cloth-cloth contact (collision.self_contact.SelfContact) or None (off).
    strain_limit: longest an edge may become, as a multiple of its rest length, after each
    step (None: no limit, else finite and > 1); edge_rest (e,) the rest edge lengths, m.
    colliders: rigid bodies (collision.colliders): what never changes of them; where a
    moving one is lives in ClothState.bodies and moves through the Control.
    thickness: contact distance, m (finite, > 0).
    contact_stiffness: penalty stiffness as a multiple of m_i / h^2 (dimensionless; finite,
    > 0). Values out of range raise ClothInputError, in a `replace` too.
    external_force: (n, 3) constant applied forces, N (a load on a test strip), or None.
    edge_contact: also keep the mesh's edges out of capsule colliders after each step
    (collision.edge_contact: a thin limb that would pass between two particles; off unless
    a scene needs it).
    bending_law: a measured fabric's bending by direction and curvature
    (physics.bending_law.FabricBending: the forces add it, ``bending`` holds the constant
    Hessian that bounds it); None: one stiffness, the stencils alone.
    contact_friction: CONTACT_FRICTIONS, where friction against the colliders acts
    (sim.contact_friction).
    """

    mesh: MeshLevel
    material: Material
    mass: np.ndarray
    stretch: StretchElements
    bending: BendingTerms
    bend_pairs: np.ndarray
    gravity: np.ndarray = field(default_factory=lambda: GRAVITY.copy())
    pinned: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    colliders: list = field(default_factory=list)
    thickness: float = 0.005
    strain_limit: float | None = None
    self_contact: object | None = None
    edge_rest: np.ndarray | None = None
    contact_stiffness: float = 10.0
    external_force: np.ndarray | None = None
    edge_contact: bool = False
    bending_law: FabricBending | None = None
    contact_friction: str = "projection"

    def __post_init__(self) -> None:
        require_physical(self, ("thickness", "contact_stiffness"))
        if self.contact_friction not in CONTACT_FRICTIONS:
            raise ClothInputError(f"contact_friction must be one of "
                                  f"{', '.join(CONTACT_FRICTIONS)}, got {self.contact_friction!r}")

    @property
    def n(self) -> int:
        return self.mesh.rest.shape[0]

    @property
    def pairs(self) -> np.ndarray:
        return self.mesh.pairs

    @property
    def incidence(self) -> MeshIncidence:
        """The mesh's incidence tables (physics.incidence), made on first use."""
        inc = self.__dict__.get("_incidence")
        if inc is None:
            m = self.mesh
            inc = MeshIncidence.of(self.n, m.pairs, m.faces, m.face_pairs)
            self.__dict__["_incidence"] = inc
        return inc

    def applied_forces(self) -> np.ndarray:
        """(n, 3) gravity plus any external force, N: the forces that do not depend on x."""
        f = self.mass[:, None] * self.gravity[None, :]
        return f if self.external_force is None else f + self.external_force

    def fixed_mask(self) -> np.ndarray:
        """(n,) bool, True for pinned particles."""
        mask = np.zeros(self.n, dtype=bool)
        mask[self.pinned] = True
        return mask


def build_model(
    mesh: MeshLevel,
    material: Material,
    pinned: np.ndarray | None = None,
    colliders: list | None = None,
    gravity: np.ndarray | None = None,
    weft: np.ndarray | None = None,
    thickness: float = 0.005,
    compression: str = "elastic",
    bending: str = "mean",
    contact_friction: str = "projection",
) -> ClothModel:
    """Assemble the constant parts of a cloth simulation from a mesh level and material.

    compression: "elastic" (the membrane resists compression as tension, the paper's) or
    "buckle" (a face wrinkles along the fabric's threads past the buckling stress its
    bending allows: physics.wrinkles).
    bending: "mean" (one stiffness, the material's bend: for a measured fabric the mean of its
    three directions) or "law" (a measured fabric's bending by direction and curvature,
    physics.bending_law; a material without one bends with its bend). The law stays opt-in
    until a drape with it settles: gray-interlock's 600-particle Cusick drape kept one
    particle moving at 4 cm/s after 1500 steps, and generalised-alpha at rho_inf 0.5 lost the
    swing at 1/30 s.
    contact_friction: CONTACT_FRICTIONS (sim.contact_friction): "solve" also takes that
    mode's penalty, SOLVE_CONTACT_STIFFNESS times m / h^2."""
    if bending not in BENDING_MODELS:
        raise ClothInputError(f"bending must be one of {', '.join(BENDING_MODELS)}, "
                              f"got {bending!r}")
    use_law = bending == "law" and material.bend_law is not None
    if compression not in COMPRESSION_MODELS:
        raise ClothInputError(f"compression must be one of {', '.join(COMPRESSION_MODELS)}, "
                              f"got {compression!r}")
    pinned = np.zeros(0, np.int64) if pinned is None else np.asarray(pinned, dtype=np.int64)
    if pinned.size and (pinned.min() < 0 or pinned.max() >= mesh.rest.shape[0]):
        raise ClothInputError(
            f"pinned particle index out of range 0..{mesh.rest.shape[0] - 1}: {pinned.tolist()}")
    require_positive("collision thickness", thickness)
    mass = material.density * mesh.vertex_areas
    # a face squeezed along a thread wrinkles by bending across it: a fabric with a bending
    # law buckles with that direction's stiffness (weft, warp, bias), the others with one B
    buckle = (None if compression != "buckle" else material.bend
              if not use_law else tuple(material.bend_law.k1))
    st = stretch_elements(mesh.rest, mesh.faces, mesh.face_areas, material.stretch,
                          material.shear, weft, stretch_warp=material.stretch_v,
                          buckle_bend=buckle)
    law = None if not use_law else \
        FabricBending.of(mesh, material.bend_law, None if weft is None else np.asarray(weft))
    bending = bending_terms(mesh, material.bend if law is None else law.hessian_bend)
    bend_pairs = bending.pair_values(mesh)
    g = GRAVITY.copy() if gravity is None else np.asarray(gravity, dtype=float).reshape(3)
    e = mesh.edges
    edge_rest = np.linalg.norm(mesh.rest[e[:, 1]] - mesh.rest[e[:, 0]], axis=1)
    stiff = {} if contact_friction != "solve" else {"contact_stiffness": SOLVE_CONTACT_STIFFNESS}
    return ClothModel(mesh, material, mass, st, bending, bend_pairs, g, pinned,
                      list(colliders or []), thickness, edge_rest=edge_rest, bending_law=law,
                      contact_friction=contact_friction, **stiff)


@dataclass
class ClothState:
    """Positions x and velocities v, (n, 3); x_prev, v_prev for BDF2 (None at the start);
    time t in seconds; a (n, 3) m/s^2, generalised-alpha's acceleration (None at the start
    and for the other schemes); bodies {index into ClothModel.colliders: pose value} where
    each moving collider is now and was a step ago (capsules.CapsulePose,
    mesh_collider.RigidPose: the swept contact test's history), values that a move replaces
    (a moving collider missing here is at its rest pose); contact_force (n,) N, how hard
    each particle pressed on the colliders over the last step (contact_friction "solve"
    only; None: unknown, as at the start)."""

    x: np.ndarray
    v: np.ndarray
    x_prev: np.ndarray | None = None
    v_prev: np.ndarray | None = None
    t: float = 0.0
    a: np.ndarray | None = None
    bodies: dict = field(default_factory=dict)
    contact_force: np.ndarray | None = None

    @classmethod
    def at_rest(cls, positions: np.ndarray) -> ClothState:
        x = np.array(positions, dtype=float)
        return cls(x, np.zeros_like(x))

    def copy(self) -> ClothState:
        cp = None if self.x_prev is None else self.x_prev.copy()
        vp = None if self.v_prev is None else self.v_prev.copy()
        a = None if self.a is None else self.a.copy()
        f = None if self.contact_force is None else self.contact_force.copy()
        return ClothState(self.x.copy(), self.v.copy(), cp, vp, self.t, a, dict(self.bodies),
                          f)

    def colliders(self, model: ClothModel) -> list:
        """The model's colliders at this state's poses (collision.colliders.posed)."""
        return posed(model.colliders, self.bodies)


@dataclass
class ClothControl:
    """What the outside world sets for the next step (Newton's Control).

    pinned: (k,) indices of the particles held this step (the model's base pins and what
    grippers hold); None: `ClothModel.pinned`.
    pin_targets: (k, 3) where the held particles must be at the end of the step, m, in
    `pins` order; None: they stay where they are.
    collider_poses: {index into `ClothModel.colliders`: the arguments of that collider's
    ``moved`` for the end of the step} (a body's capsule ends p0, p1 (S, 3) m, and its
    active mask (S,) bool when some capsules are dropped); the step
    moves each there with its dt (`moved_bodies`), so a pose left unchanged for a second
    step means a collider at rest. Where it was before is the State's (ClothState.bodies).
    """

    pin_targets: np.ndarray | None = None
    collider_poses: dict = field(default_factory=dict)
    pinned: np.ndarray | None = None

    def copy(self) -> ClothControl:
        targets = None if self.pin_targets is None else self.pin_targets.copy()
        poses = {i: tuple(np.array(a, copy=True) for a in args)
                 for i, args in self.collider_poses.items()}
        return ClothControl(targets, poses, None if self.pinned is None else self.pinned.copy())

    def restricted(self, n: int) -> ClothControl:
        """A copy for the first n particles (a coarser level of detail: sim.detail): held
        particles from n on are let go."""
        out = self.copy()
        if out.pinned is not None:
            keep = out.pinned < n
            out.pinned = out.pinned[keep]
            if out.pin_targets is not None:
                out.pin_targets = out.pin_targets[keep]
        return out

    def pins(self, model: ClothModel) -> np.ndarray:
        """(k,) the particles held this step."""
        return model.pinned if self.pinned is None else self.pinned

    def fixed_mask(self, model: ClothModel) -> np.ndarray:
        """(n,) bool, True for the particles held this step."""
        mask = np.zeros(model.n, dtype=bool)
        mask[self.pins(model)] = True
        return mask

    def moved_bodies(self, model: ClothModel, bodies: dict, dt: float) -> dict:
        """The colliders' poses at the end of a step of dt s from ``bodies`` (a State's):
        those in `collider_poses` moved there, the others as they are."""
        out = dict(bodies)
        for index, args in self.collider_poses.items():
            col = model.colliders[index]
            # (p0, p1) or (rotation, translation), then a capsule body's active mask if any
            out[index] = col.moved(bodies.get(index, col.rest_pose()), *args[:2], dt,
                                   *args[2:])
        return out
