"""A garment worn on a moving capsule body: the core that the headless runner and the node drive.

`GarmentSim` is built from the avatar's first pose (the garment is dressed on it, collision
free) and then fed body poses: one frame at a time with `push(stamp, poses)`, or several key
poses at once with `advance(keys)` (a live node that fell behind coalesces what arrived while
it stepped). Each tick advances the cloth from its simulated time to the newest stamp in
steps: the capsules' end points and the garment's pinned vertices follow the body along every
key pose in between, the capsules collide with the cloth (penalty in the system, projection
with friction after each step, tunnelling caught by a swept test against the capsules'
history), and the figures of the tick come back as a `TickStats`. Pushing frames one by one
and advancing them one key per tick is the same computation, bit for bit.

The step rule (`step_count`): at least ``substeps`` steps per tick, none longer than
``max_step`` s, and more while a capsule that can reach the cloth during the tick moves
further than ``max_substep_motion`` per step in a pose interval (a tick that coalesces
several pose intervals takes longer steps, not more). A capsule that cannot reach the cloth (an arm
swinging beside a skirt) never shortens the step, and the swept contact test keeps a limb from
passing through the cloth however far it moves in one step, so the motion rule serves
accuracy, not safety.

Bad frames never reach the cloth (issue: the run goes on and the cloth never becomes NaN):
empty frames, a wrong number of poses, NaN or infinite values and stamps that do not advance
are skipped; a jump of metres between two frames (a teleport) re-anchors the garment: it is
carried rigidly with the body's root to the new place and the body jumps there without
velocity. `GarmentSim.rejected` counts every kind, for the caller to report.
"""

from __future__ import annotations

import itertools
import math
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from cloth_mg_ros.collision.capsules import CapsuleCollider, capsules_within
from cloth_mg_ros.collision.colliders import PlaneCollider, penetration
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments import make_garment
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.frames import FrameStatus, check_frame
from cloth_mg_ros.motion.rotations import quat_to_matrix
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.sim.body_poses import (
    attach_pins,
    blend_poses,
    body_dict,
    pin_positions,
    pose_on_path,
    sleeve_pins,
    standing_at,
)
from cloth_mg_ros.sim.detail import (
    build_rung,
    prolongate_state,
    restrict_state,
    rung_indices,
    rung_solver,
)
from cloth_mg_ros.sim.dropped_segments import as_mask, collider_ends, key_masks, step_mask
from cloth_mg_ros.sim.grippers import GripperSet, play_scripts
from cloth_mg_ros.sim.model import ClothControl, ClothModel, ClothState, require_physical
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.sim.solve_tolerance import AUTO as TOLERANCE_AUTO
from cloth_mg_ros.sim.solve_tolerance import tolerance_at
from cloth_mg_ros.sim.tick_stats import BODY_COLLIDER, BodyLoads, StepTally, TickStats
from cloth_mg_ros.solvers.threads import resolve_threads, use_threads

MAX_FRAME_GAP = 0.25  # s: a longer gap between poses is simulated as if it were this long
DRESSING_TIME = 0.5  # s: from the neutral dressing pose into the first body pose
DRESSING_FRAMES = 15
BODY_FRICTION = 0.5
GRAVITY = 9.81  # m/s^2: how far a free cloth particle can fall in a tick (reach test)
MAX_STEPS_PER_TICK = 64
ARMLESS_GARMENTS = ("skirt", "dress", "cape")


@dataclass
class BodySimOptions:
    """The simulation's options. The fields named like scene parameters (garment, particles,
    solver, tolerance, levels, substeps, max_substep_motion, max_step, floor, scheme,
    spectral_radius, newton_iterations, linearise_at, friction, compression, contact_friction,
    self_contact, threads,
    grippers, grasp_radius, release_force) are those parameters, with no defaults of their
    own: `from_scene` takes them from a scene's configuration (config.schema.SceneParams:
    its defaults, kinds and ranges, checked where the values enter: scene files, the node's
    parameters, the command line); the others (thickness, teleport_m, strain_limit, ...)
    are the simulation's own: thickness and teleport_m finite and > 0 (m), strain_limit
    None or finite and > 1.

    levels: 0 (or None): as many as the mesh size calls for, stored as None; tolerance: a
    relative residual, or 'auto': `tolerances` per level."""

    # the scene parameters' (config.schema's): no defaults here, from_scene gives them
    garment: str
    particles: int
    solver: str
    tolerance: float | str
    levels: int | None
    substeps: int
    max_substep_motion: float
    max_step: float
    floor: bool
    scheme: str
    spectral_radius: float
    newton_iterations: int  # per step (sim.newton)
    linearise_at: str  # sim.schemes.LINEARISE_AT
    friction: float  # Coulomb coefficient against the body and the floor
    compression: str  # the membrane's: sim.model.COMPRESSION_MODELS
    contact_friction: str  # where friction acts: sim.model.CONTACT_FRICTIONS
    self_contact: bool
    threads: int  # solver threads (0: every core); the cloth depends on it bit for bit
    grippers: tuple[str, ...]
    grasp_radius: float
    release_force: float
    # the simulation's own
    thickness: float = 0.006  # collision distance, m
    teleport_m: float = 1.0
    strain_limit: float | None = 1.1
    collide: tuple[str, ...] | None = None
    depth: int | None = None  # subdivisions of the garment's hierarchy (None: size policy)
    # tolerance auto: (particles, tolerance) measured by the cost model's calibration
    # (budget.tolerance_rule.measure_tolerances); a level takes sim.solve_tolerance.tolerance_at's.
    tolerances: tuple[tuple[int, float], ...] = ()

    @classmethod
    def from_scene(cls, params: Mapping, **overrides) -> BodySimOptions:
        """The options a body scene's parameters declare: every field named like one of the
        parameters (config.scenes.load_scene's, or a dict of the node's values) takes its
        value, ``overrides`` (e.g. particles, solver) taking precedence."""
        values = {f.name: params[f.name] for f in fields(cls) if f.name in params}
        values.update(overrides)
        return cls(**values)

    def solve_tolerance(self, particles: int, rung: int = 0) -> float:
        """The relative residual level of detail `rung` (0: the garment's finest) of
        ``particles`` solves to: `tolerance`, or with tolerance auto the measured one for that
        size and rung (sim.solve_tolerance.tolerance_at)."""
        if self.tolerance == TOLERANCE_AUTO:
            return tolerance_at(self.tolerances, particles, rung)
        return float(self.tolerance)

    def colliding_segments(self, names: tuple[str, ...]) -> np.ndarray:
        """Indices of the body segments the garment collides with (``collide``, or the
        garment's default: skirts, dresses and capes leave the arms out, since an arm swung
        against the hip or the back overlaps the body's capsules there and would pinch the
        cloth between two solids; a top too, its sleeves' hems sewn to the upper arms)."""
        wanted = self.collide
        if wanted is None:
            wanted = tuple(n for n in names if not (n.startswith(("upper_arm", "lower_arm",
                                                                  "hand"))
                                                   and self.garment in ARMLESS_GARMENTS + ("top",)))
        unknown = [n for n in wanted if n not in names]
        if unknown:
            raise ClothInputError(f"collide: unknown body segments {unknown}; the avatar has "
                                  f"{', '.join(names)}")
        return np.array([names.index(n) for n in wanted], dtype=np.int64)

    def __post_init__(self) -> None:
        if self.levels == 0:
            self.levels = None
        require_physical(self, ("thickness", "teleport_m"))


@dataclass
class GarmentSnapshot:
    """What changes while a GarmentSim steps: the simulation's state (the cloth with its BDF2
    history, the capsules' current and previous ends), the control of the next step (pin
    targets, capsule ends), the body pose and stamp the driver reached, and the grippers."""

    state: ClothState
    control: ClothControl
    poses: np.ndarray
    stamp: float
    grippers: GripperSet | None = None


@dataclass
class GarmentSim:
    """A garment on the avatar; see the module docstring. Build with `GarmentSim.dress`."""

    avatar: Avatar
    garment: object
    sim: Simulator
    options: BodySimOptions
    stamp: float
    poses: np.ndarray
    segments: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    pin_segments: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    pin_offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rejected: Counter = field(default_factory=Counter)
    failures: int = 0
    material: Material | None = None
    pins: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    rung: int = 0  # the level of detail simulated: its hierarchy's level (0: the finest)
    rungs: dict = field(default_factory=dict)  # rung -> its Simulator (sim.detail)
    grippers: GripperSet | None = None
    # (S,) bool: segments dropped from the collider (a tracker lost their joints); None: none
    dropped: np.ndarray | None = None
    scripts: list = field(default_factory=list)  # GripperScript: scripted grippers (headless)
    clock0: float = 0.0  # s: the simulated time of the first pose (scripts count from it)
    # Threads to run the steps on now (None: options.threads), fewer while other work holds
    # the cores (budget.thread_governor). The sweeps still split into options.threads parts,
    # so the cloth does not depend on it.
    run_threads: int | None = None
    # Called between the steps of a tick; returns the threads to run the next ones on (None:
    # as they are). A live node drops threads here when a load begins mid-tick.
    between_steps: Callable[[], int | None] | None = None

    @classmethod
    def dress(cls, avatar: Avatar, stamp: float, poses: np.ndarray, material: Material,
              options: BodySimOptions) -> GarmentSim:
        """Dress the garment on the body in ``poses`` (S, 7) at time ``stamp`` (s)."""
        poses = np.asarray(poses, dtype=np.float64)
        status = check_frame(None, stamp, poses, avatar.num_segments)
        if status != FrameStatus.OK:
            raise ClothInputError(f"the first body pose cannot dress a garment: {status.value}")
        # Dress on the body in its first pose. Segments the garment does not collide with
        # (the arms, for skirts and dresses) are shaped as in the neutral standing pose, so
        # an arm swung against the hip does not get in the way of the design. Where the first
        # pose leaves no room (an arm held against the chest for a top), dress on the neutral
        # standing pose placed where the body stands, then move the body into its first pose
        # while the cloth follows.
        segments = options.colliding_segments(tuple(avatar.names))
        standing = standing_at(avatar, poses)
        design = standing.copy()
        design[segments] = poses[segments]
        dressing = poses
        try:
            garment = make_garment(options.garment, body_dict(avatar, design), options.particles,
                                   depth=options.depth)
        except ClothInputError:
            dressing = standing
            garment = make_garment(options.garment, body_dict(avatar, standing),
                                   options.particles, depth=options.depth)
        p0, p1, radius = avatar.capsules(dressing)
        collider = CapsuleCollider(radius[segments], options.friction)
        colliders: list = [collider]
        if options.floor:
            colliders.append(PlaneCollider(np.zeros(3), np.array([0.0, 0.0, 1.0]),
                                           options.friction))
        extra = sleeve_pins(avatar, dressing, garment) if options.garment == "top" else {}
        pins, pin_segments, pin_offsets = attach_pins(avatar, dressing, garment, extra)
        sim = build_rung(garment.hierarchy, 0, material, pins, colliders, options,
                         garment.weft)
        sim.state.bodies[BODY_COLLIDER] = collider.moved(None, p0[segments], p1[segments])
        garment_sim = cls(avatar, garment, sim, options, float(stamp), dressing,
                 pin_segments=pin_segments, pin_offsets=pin_offsets, segments=segments,
                 material=material, pins=np.asarray(pins, dtype=np.int64), rungs={0: sim})
        if dressing is not poses:
            for u in np.linspace(0.0, 1.0, DRESSING_FRAMES + 1)[1:]:
                garment_sim._move_body([0.0, 1.0], [garment_sim.poses, blend_poses(dressing, poses,
                                                                                   u)],
                              DRESSING_TIME / DRESSING_FRAMES)
        garment_sim.poses = poses
        garment_sim.clock0 = garment_sim.sim.state.t
        if options.grippers:
            garment_sim.grippers = GripperSet(options.grippers, options.grasp_radius,
                                              options.release_force, garment_sim.pins)
        return garment_sim

    # ------------------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Cloth positions (n, 3), m."""
        return self.sim.state.x

    @property
    def velocities(self) -> np.ndarray:
        """Cloth velocities (n, 3), m/s."""
        return self.sim.state.v

    @property
    def model(self) -> ClothModel:
        """The ClothModel simulated now (its level of detail's)."""
        return self.sim.model

    @property
    def particles(self) -> int:
        """The particles simulated now (its level of detail's)."""
        return self.sim.model.n

    def held_mask(self) -> np.ndarray:
        """(n,) bool: the particles the pins and grippers hold now (a grasp leaves them)."""
        return self.sim.control.fixed_mask(self.sim.model)

    @property
    def faces(self) -> np.ndarray:
        return self.sim.model.mesh.faces

    def capsules(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The body's capsules now: p0, p1 (S, 3), radius (S,)."""
        return self.avatar.capsules(self.poses)

    def snapshot(self) -> GarmentSnapshot:
        """A copy of what stepping changes (`restore` returns to it): cheap next to a deep
        copy, which would duplicate the mesh, the hierarchy and the solver."""
        return GarmentSnapshot(self.sim.state.copy(), self.sim.control.copy(),
                               self.poses.copy(), self.stamp,
                               None if self.grippers is None else self.grippers.copy())

    def restore(self, snap: GarmentSnapshot) -> None:
        """Return to a snapshot taken from this garment (or an identical copy of it)."""
        self.sim.state = snap.state.copy()
        self.sim.control = snap.control.copy()
        self.poses, self.stamp = snap.poses.copy(), snap.stamp
        if snap.grippers is not None:
            self.grippers = snap.grippers.copy()

    # -- levels of detail (sim.detail): rung k is the garment on its hierarchy's level k ----
    def rung_indices(self) -> list[int]:
        """The rungs this garment may be simulated at, finest first."""
        return rung_indices(self.garment.hierarchy)

    def rung_particles(self, rung: int) -> int:
        return self.garment.hierarchy.levels[rung].n_vertices

    def prepare_rungs(self) -> None:
        """Build every rung's simulation now, so that a later switch costs no set-up."""
        for rung in self.rung_indices():
            self._rung(rung)

    def time_rungs(self, steps: int = 3) -> list[float]:
        """Each rung's ms per step (`rung_indices` order), timed on this garment as it is now:
        from its state, the body still, the median of ``steps`` steps after an untimed one
        (sim.detail.DetailController compares the rungs by these). The garment is left as it
        was."""
        snap = self.snapshot()
        out = []
        for rung in self.rung_indices():
            sim = self._rung(rung)
            ms = []
            for k in range(steps + 1):
                sim.state = restrict_state(snap.state, self.rung_particles(rung))
                sim.control = snap.control.restricted(self.rung_particles(rung))
                sim.dt = self.sim.dt
                t0 = time.perf_counter()
                sim.step()
                if k:
                    ms.append(1e3 * (time.perf_counter() - t0))
            out.append(float(np.median(ms)))
        self.restore(snap)
        return out

    def _rung(self, rung: int) -> Simulator:
        if rung not in self.rungs:
            self.rungs[rung] = build_rung(self.garment.hierarchy, rung, self.material,
                                          self.pins, self.sim.model.colliders, self.options,
                                          self.garment.weft, self.sim.dt)
        return self.rungs[rung]

    def set_solver(self, solver: str, tolerance: float | str) -> None:
        """Solve with ``solver`` at relative ``tolerance`` ('auto': each rung its measured
        one, options.tolerances) from now on, on every rung: each rung built so far gets a
        new solver on its own part of the hierarchy."""
        tolerance = TOLERANCE_AUTO if tolerance == TOLERANCE_AUTO else float(tolerance)
        self.options.solver, self.options.tolerance = solver, tolerance
        for rung, sim in self.rungs.items():
            sim.solver = rung_solver(self.garment.hierarchy, rung, sim.model.bending,
                                     self.options)

    def solve_tolerance(self) -> float:
        """The relative residual the rung simulated now solves to."""
        return self.options.solve_tolerance(self.sim.model.n, self.rung)

    def hold_tolerance(self, tolerance: float | None) -> None:
        """Solve every rung built so far to relative residual ``tolerance`` until this is
        called again (None: each rung its own, options.solve_tolerance): the cost model's
        calibration times a rung at the tolerance another garment's finest level takes."""
        for rung, sim in self.rungs.items():
            sim.solver.tol = self.options.solve_tolerance(sim.model.n, rung) \
                if tolerance is None else float(tolerance)

    def set_rung(self, rung: int) -> float:
        """Simulate at ``rung`` from now on (0: the finest). Down: the coarse vertices keep
        their state bit for bit; up: the state is prolongated (new vertices found inside the
        body are projected out). Returns the switch's cost, ms."""
        if rung not in self.rung_indices():
            raise ClothInputError(f"rung {rung} is not one of this garment's rungs "
                                  f"{self.rung_indices()}")
        t0 = time.perf_counter()
        if rung != self.rung:
            old = self.sim
            if rung > self.rung:
                state = restrict_state(old.state, self.rung_particles(rung))
            else:
                state = prolongate_state(self.garment.hierarchy, old.state, self.rung, rung,
                                         old.state.colliders(old.model),
                                         self.options.thickness)
            sim = self._rung(rung)
            sim.state, sim.dt = state, old.dt
            sim.control = old.control.restricted(sim.model.n)
            if self.grippers is not None:
                self.grippers.restrict(sim.model.n, state.x)
            self.sim, self.rung = sim, rung
        return 1e3 * (time.perf_counter() - t0)

    def push(self, stamp: float, poses: np.ndarray) -> TickStats | FrameStatus:
        """Advance to the body pose ``poses`` (S, 7) at ``stamp`` (s) in one tick. Returns the
        tick's figures, or the FrameStatus of a frame that was skipped or re-anchored."""
        poses = np.asarray(poses, dtype=np.float64) if np.size(poses) else np.zeros((0, 7))
        status = check_frame(self.stamp, stamp, poses, self.avatar.num_segments, self.poses,
                             teleport_m=self.options.teleport_m)
        if status == FrameStatus.TELEPORT:
            self.rejected[status.value] += 1
            self.reanchor(stamp, poses)
            return status
        if status != FrameStatus.OK:
            self.rejected[status.value] += 1
            return status
        return self.advance([(stamp, poses)])

    def advance(self, keys: Sequence[tuple[float, np.ndarray]],
                dropped: Sequence[np.ndarray | None] | None = None) -> TickStats:
        """Advance the cloth to the newest of ``keys`` in one tick, the body following every
        key pose in between: keys [(stamp s, poses (S, 7))], stamps increasing and after the
        current one, each a valid frame that is no teleport (check_frame). A stretch longer
        than MAX_FRAME_GAP is simulated as if it were that long (the body then moves faster
        than it did). dropped: each key's segments (S,) bool to leave out of the collider
        (None: none), in order; a step takes the mask of the key that ends the key interval
        it lies in (sim.dropped_segments) and `dropped` is the last key's after the tick.
        Without it the segments `set_dropped` left out stay out for the whole tick."""
        if not keys:
            raise ValueError("advance needs at least one key pose")
        stamps = np.array([self.stamp] + [float(st) for st, _ in keys])
        if np.any(np.diff(stamps) <= 0.0):
            raise ValueError(f"key pose stamps must increase after {self.stamp}: "
                             f"{stamps[1:].tolist()}")
        path = [self.poses] + [np.asarray(p, dtype=np.float64) for _, p in keys]
        masks = None if dropped is None else key_masks(dropped, len(keys))
        stats = self._move_body(stamps, path, min(stamps[-1] - stamps[0], MAX_FRAME_GAP),
                                masks)
        stats.stamp = float(stamps[-1])
        stats.poses = len(keys)
        self.stamp = float(stamps[-1])
        return stats

    # ------------------------------------------------------------------------------------
    def step_count(self, path: Sequence[np.ndarray], interval: float) -> int:
        """Steps to move the body along key poses ``path`` (S, 7) each (path[0]: where it is
        now) over ``interval`` s: the module docstring's rule.

        A colliding capsule can reach the cloth during the tick when its clearance from the
        cloth now is within how far its ends travel along the path, plus how far a cloth
        particle can travel (its speed now and free fall over the interval), plus the contact
        thickness; only such capsules' travel counts, and per key interval: a tick that
        coalesces several pose messages takes as many steps as the liveliest of them alone
        would (longer steps, up to max_step), so a late tick costs about what one pose does
        and the next one catches up, instead of costing more the later it is.
        """
        o = self.options
        ends = [self.avatar.capsules(p) for p in path]
        seg = self.segments
        travel = np.zeros(len(seg))  # along the whole path: how far a capsule can reach
        liveliest = np.zeros(len(seg))  # in the liveliest key interval
        for (a0, a1, _), (b0, b1, _) in itertools.pairwise(ends):
            moved = np.maximum(np.linalg.norm(b0 - a0, axis=1),
                               np.linalg.norm(b1 - a1, axis=1))[seg]
            travel += moved
            liveliest = np.maximum(liveliest, moved)
        p0, p1, radius = ends[0]
        state = self.sim.state
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", state.v, state.v), initial=0.0)))
        cloth = speed * interval + 0.5 * GRAVITY * interval * interval
        near = capsules_within(state.x, p0[seg], p1[seg], radius[seg],
                               travel + cloth + o.thickness)
        motion = float(liveliest[near].max(initial=0.0))
        count = max(o.substeps, math.ceil(interval / o.max_step - 1e-9),
                    math.ceil(motion / o.max_substep_motion - 1e-9))
        return int(min(max(count, 1), MAX_STEPS_PER_TICK))

    def _move_body(self, stamps: Sequence[float], path: Sequence[np.ndarray],
                   interval: float, masks: list | None = None) -> TickStats:
        """Move the body along key poses ``path`` at ``stamps`` (path[0] where it is now) over
        ``interval`` s of simulated time, stepping the cloth; masks: path[1:]'s dropped
        segments (advance's), or None: `dropped` as it is."""
        t0 = time.perf_counter()
        use_threads(self._running_threads())  # per calling thread: a node steps in its own
        stamps = np.asarray(stamps, dtype=np.float64)
        n_sub = self.step_count(path, interval)
        dt = interval / n_sub
        self.sim.dt = dt
        self.sim.track_contact_forces = True
        self.sim.track_constraint_forces = True
        tally = StepTally()
        loads = BodyLoads(len(self.segments), len(self.avatar.names))
        released: list[str] = []
        for k in range(1, n_sub + 1):
            now = pose_on_path(stamps, path, k / n_sub)
            if masks is not None:
                self.dropped = step_mask(masks, stamps, k / n_sub)
            self._set_control(now, k / n_sub, dt)
            before = self.sim.state
            stats = self.sim.step()
            if not np.all(np.isfinite(self.sim.state.x)) or not np.all(
                    np.isfinite(self.sim.state.v)):
                # Never let NaN reach the cloth: drop the step, stop the cloth where it was.
                self.failures += 1
                self.rejected["solver_failure"] += 1
                self.sim.state = ClothState(before.x.copy(), np.zeros_like(before.v), None, None,
                                            before.t + dt, bodies=self.sim.state.bodies)
                tally.converged = False
                continue
            if self.grippers is not None:
                released += self.grippers.measure(self.sim)
                if self.scripts:
                    self.grippers.end_interval()
            loads.add(self.sim.contact_load, now[self.segments, :3], self.pin_segments,
                      self.sim.constraint_forces[:len(self.pins)])
            tally.add(stats)
            if self.between_steps is not None and k < n_sub:
                threads = self.between_steps()
                if threads is not None and threads != self.run_threads:
                    self.run_threads = threads
                    use_threads(self._running_threads())
        if self.grippers is not None:
            self.grippers.end_interval()
        self.poses = path[-1]
        kinetic = 0.5 * float(np.sum(self.sim.model.mass[:, None] * self.sim.state.v ** 2))
        forces, torques, peak, where = loads.result(self.avatar.names, self.segments)
        return TickStats(self.stamp, 1e3 * (time.perf_counter() - t0), tally.solve_ms,
                         tally.iterations, tally.worst, tally.converged, tally.penetration,
                         tally.contacts, n_sub, kinetic, len(path) - 1, interval,
                         forces, torques, peak, where,
                         {} if self.grippers is None else self.grippers.wrenches(), released,
                         loads.seams(self.avatar.names, np.unique(self.pin_segments)),
                         tally.self_contact_dropped, loads.pull_n())

    def set_dropped(self, dropped: np.ndarray | None) -> None:
        """The segments (S,) bool to leave out of the collider from the next step on (a body
        tracker lost their joints: their poses are only held), until an `advance` with masks
        sets each step's; None or none: every one collides. One that comes back jumps to
        where it is (no swept test)."""
        self.dropped = as_mask(dropped)

    def _body_ends(self, poses: np.ndarray) -> tuple:
        """The collider's arguments for the body at ``poses`` (S, 7): the colliding capsules'
        end points, and their active mask when some are dropped."""
        return collider_ends(self.avatar, self.segments, poses, self.dropped)

    def _set_control(self, now: np.ndarray, u: float, dt: float) -> None:
        """The next step's control, for the body at pose ``now`` (S, 7) a fraction u through
        the tick: the capsules' end points, the sewn pins' targets and the grippers'."""
        control = self.sim.control
        control.collider_poses[BODY_COLLIDER] = self._body_ends(now)
        base = (pin_positions(now, self.pin_segments, self.pin_offsets)
                if len(self.pin_segments) else None)
        if self.grippers is not None:
            self._hold(u, base, dt)
        elif base is not None:
            control.pin_targets = base

    def _running_threads(self) -> int:
        """The threads the steps run on now: run_threads, never more than options.threads
        (0: every core)."""
        if self.run_threads is None:
            return resolve_threads(self.options.threads)
        return min(self.run_threads, resolve_threads(self.options.threads))

    def _hold(self, u: float, base: np.ndarray | None, dt: float) -> None:
        """Before a step ending a fraction u through the tick: the scripted grippers move and
        grasp or let go (their own clock), and every gripper's held particles and the sewn
        pins (base (b, 3) m, or None) become the step's pins."""
        if self.scripts:
            t = self.sim.state.t - self.clock0
            play_scripts(self.grippers, self.scripts, t, t + dt, self.sim.state.x,
                         self.sim.control.fixed_mask(self.sim.model))
            u = 1.0  # a script sets each step's end pose
        self.grippers.apply(self.sim, u, base)

    @property
    def mass_kg(self) -> float:
        """The garment's mass at the rung simulated, kg."""
        return float(self.sim.model.mass.sum())

    def reanchor(self, stamp: float, poses: np.ndarray) -> None:
        """Carry the garment rigidly with the body's root to a pose far away (a teleport)."""
        r_old = quat_to_matrix(self.poses[0, 3:7])
        r_new = quat_to_matrix(poses[0, 3:7])
        rot = r_new @ r_old.T
        o_old, o_new = self.poses[0, :3], poses[0, :3]
        state = self.sim.state
        x = (state.x - o_old) @ rot.T + o_new
        ends = self._body_ends(poses)
        bodies = dict(state.bodies)  # the body jumps: no velocity, no swept test across it
        bodies[BODY_COLLIDER] = self.sim.model.colliders[BODY_COLLIDER].moved(
            None, *ends[:2], None, *ends[2:])
        self.sim.state = ClothState(x, state.v @ rot.T, None, None, state.t, bodies=bodies)
        self.sim.control.collider_poses[BODY_COLLIDER] = ends
        self.stamp, self.poses = float(stamp), poses

    def max_penetration(self) -> float:
        """Deepest cloth particle inside the body or floor now, m."""
        return penetration(self.sim.state.colliders(self.sim.model), self.sim.state.x,
                           self.sim.control.fixed_mask(self.sim.model))
