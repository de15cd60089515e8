"""Robot-assisted dressing: a sleeve held at its opening by two grippers and pulled along an
arm from the hand to the shoulder, with the forces the robot and the person feel.

The scene follows the published sleeve rig of Kapusta et al. 2016 (a straight pull along the
arm at 0.10 or 0.15 m/s over 0.85 m; an emergency stop at 10 N; outcomes missed, caught or
good; its rig_control.py in gt-ros-pkg/hrl-assistive) and Assistive Gym's dressing task
(Erickson et al. 2020: metres of arm dressed, success at 0.4 m or more):

* the arm: three capsules with a person's radii (apps.dressing_arm), held out still, or
  moving as in a bundled mocap clip with its shoulder held in place;
* the sleeve: a straight tube of a measured woven fabric (0.55 m long, r 0.075 m: a gown's
  sleeve is wide), coaxial with the arm and its opening ``start_gap`` beyond the fingertip,
  its length trailing away from the arm;
* two grippers, each holding its rim rigidly at four points (HOLD_ANGLES: the opening held
  open, as Assistive Gym holds its gown by four anchored vertices): ``cuff``, the opening
  pulled over the hand, and ``seam``, the far end, where the sleeve would join the gown,
  ``seam_gap`` sleeve lengths behind it (below 1: slack, free to follow a bent elbow). After
  ``settle_s`` s both carry their rings along the arm's centre line at ``speed`` for
  ``travel`` m, each ring's frame turning with the arm (a robot that tracks a moving arm);
  the seam lets go once the fingertip is through it. ``offset`` m moves the pull line
  sideways (y of the rings' frames), and ``angle_deg`` turns it off the arm's axis (a robot
  that misjudges the arm: the hand inside the sleeve runs into its wall);

Every step records the force on each gripper (exact for the step: the held rows of the
implicit system), the force of the cloth on each arm segment (sim.loads: penalty and
projection with friction), how far the arm is in the sleeve (dressing_arm.dressed_length),
the slip of the held particles from where their gripper's frame puts them, the deepest cloth
particle inside the arm and the deepest cloth edge inside it (dressing_arm.edge_depth: the
contact keeps particles out of the capsules, not edges, so this is the check that no cloth
went through the arm). Units SI: m, s, N.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from tqdm import tqdm

from cloth_mg_ros.apps.dressing_arm import (
    SEGMENTS,
    ArmMotion,
    ArmPose,
    arc_point,
    clip_arm,
    cuff_frame,
    dressed_length,
    edge_depth,
    frame_quaternion,
    still_arm,
)
from cloth_mg_ros.collision.capsules import CapsuleCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.sleeve import sleeve_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.garment_sim import BODY_FRICTION
from cloth_mg_ros.sim.grippers import GripperSet
from cloth_mg_ros.sim.model import COMPRESSION_MODELS, ClothState, build_model
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver, validate_solver_name
from cloth_mg_ros.solvers.threads import use_threads

GRIPPERS = ("cuff", "seam")  # cuff: the opening pulled over the hand; seam: the far end,
# where the sleeve joins the gown
HOLD_ANGLES = np.radians([45.0, 135.0, 225.0, 315.0])  # where each gripper pinches its rim,
# from the ring's x (the opening held open at four points, as Assistive Gym's gown is held by
# four anchored vertices)
SEAM_RELEASE_M = 0.05  # m: the seam is let go once the fingertip is this far through it
E_STOP_N = 10.0  # Kapusta et al. 2016: the rig's emergency stop
SNAG_N = 15.0  # force readings above about 15 N read as a possible snag (Rafiq et al. 2025)
HAZARD_N = 35.0  # and above about 35 N as hazardous (Rafiq et al. 2025)
STOP_N = 25.0  # the runs end here: past the snag level, where no robot should pull on
SUCCESS_M = 0.4  # Assistive Gym: a dressing succeeds with 0.4 m of arm or more in the sleeve
SPEEDS = (0.10, 0.15)  # m/s, Kapusta et al. 2016
TRAVEL_M = 0.85  # m, the same rig's pull
GOWN_FABRIC = "white-dots-on-blk"  # a measured woven of 128 g/m^2 (Wang et al. 2011): a
# hospital gown's cotton-polyester poplin is a woven of about 100-150 g/m^2
WINDOW_S = 0.1  # s: peaks are of forces averaged over this long (a 10 Hz low-pass, as an
# F/T sensor's reading would be filtered), so that one step's contact impulse is not a peak


@dataclass
class DressingSpec:
    """One dressing run. motion: 'still' (the arm held out) or a bundled bag's name (the arm
    as in that clip); speed m/s; travel m; start_gap m: the opening's centre beyond the
    fingertip at the start; offset m: the pull line's sideways distance from the arm's centre
    line (0: on it; a few cm: the cuff catches on the hand); particles: the sleeve's, about;
    material; sleeve_length, sleeve_radius m; seam_gap: how far behind the cuff the seam is
    held, in sleeve lengths along the arm (below 1: the sleeve hangs slack between them);
    grasp_radius m; settle_s s before the pull;
    dt s; solver and tolerance; stop_force N: the run ends when the force on the grippers,
    averaged over WINDOW_S as every force figure is, passes it (no robot should pull on; a
    stop on one step's force could end a run whose figures never passed the emergency
    stop); strain_limit: longest an edge may become, as a
    multiple of its rest length (None: no limit: the woven's own stiffness holds it, and a
    limit's correction would be a force the grippers do not feel); thickness m: contact
    distance; contact_stiffness: the penalty, a multiple of m / h^2 (sim.model): 1000, stiff
    enough for the step's system, not the projection after it, to hold this woven off the
    arm, so that the forces on the arm are the ones the step solved (with the garments' 10
    a sleeve pressed on the fingertip was stretched to 4 times its length, the hand's force
    on it near zero: measured while building this scene); friction: the arm's, Coulomb;
    side: the arm, 'r' or 'l'; label: the run's name in tables; edge_contact: keep the
    sleeve's edges out of the arm too (collision.edge_contact; without it, on the moving arm,
    a rim stretched across the swinging fingertip let the hand through between two
    particles, 4 cm deep); scheme: the implicit integrator (sim.schemes.SCHEMES);
    spectral_radius: generalised-alpha's rho_inf (scheme 'genalpha' only, 0..1);
    start_nudge m: every sleeve particle's start moved this far in a random direction
    (`nudge_positions`, drawn from numpy's default_rng([seed, start])): 0, the rest shape
    exactly; a micrometre, a start that differs from the rest shape by nothing a rig could
    measure, so that runs of one case from several starts sample its chaotic contact;
    seed, start: non-negative integers naming the draw; compression: the membrane's under
    compression (sim.model.COMPRESSION_MODELS: 'elastic', the paper's, or 'buckle')."""

    motion: str = "still"
    speed: float = 0.10
    travel: float = TRAVEL_M
    start_gap: float = 0.10
    offset: float = 0.0
    angle_deg: float = 0.0
    particles: int = 2000
    material: str = GOWN_FABRIC
    sleeve_length: float = 0.55
    sleeve_radius: float = 0.075
    seam_gap: float = 0.85
    grasp_radius: float = 0.012
    settle_s: float = 0.5
    dt: float = 1.0 / 60.0
    solver: str = "mpcg"
    tolerance: float = 1e-4
    stop_force: float = STOP_N
    strain_limit: float | None = None
    thickness: float = 0.005
    contact_stiffness: float = 1000.0
    friction: float = BODY_FRICTION
    side: str = "r"
    label: str = ""
    edge_contact: bool = True
    scheme: str = "bdf2"
    spectral_radius: float = DEFAULT_SPECTRAL_RADIUS
    start_nudge: float = 0.0
    seed: int = 0
    start: int = 0
    compression: str = "elastic"

    def __post_init__(self) -> None:
        positive = {"speed": self.speed, "travel": self.travel, "sleeve_length":
                    self.sleeve_length, "sleeve_radius": self.sleeve_radius, "grasp_radius":
                    self.grasp_radius, "dt": self.dt, "stop_force": self.stop_force,
                    "thickness": self.thickness}
        for name, value in positive.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or value <= 0.0:
                raise ClothInputError(f"dressing: {name} must be a positive number, got "
                                      f"{value!r}")
        for name, value in (("start_gap", self.start_gap), ("offset", self.offset),
                            ("settle_s", self.settle_s), ("angle_deg", self.angle_deg)):
            signed = name in ("offset", "angle_deg")
            if not math.isfinite(value) or (not signed and value < 0.0):
                raise ClothInputError(f"dressing: {name} must be a finite number"
                                      f"{'' if signed else ' >= 0'}, got {value!r}")
        if not math.isfinite(self.start_nudge) or not 0.0 <= self.start_nudge <= 1e-3:
            raise ClothInputError(f"dressing: start_nudge must be in [0, 1e-3] m, got "
                                  f"{self.start_nudge!r}")
        for name, value in (("seed", self.seed), ("start", self.start)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ClothInputError(f"dressing: {name} must be a non-negative integer, got "
                                      f"{value!r}")
        if isinstance(self.friction, bool) or not isinstance(self.friction, (int, float)) \
                or not math.isfinite(self.friction) or self.friction < 0.0:
            raise ClothInputError(f"dressing: friction must be a number >= 0, got "
                                  f"{self.friction!r}")
        if self.scheme not in SCHEMES:
            raise ClothInputError(f"dressing: scheme must be one of {', '.join(SCHEMES)}, got "
                                  f"{self.scheme!r}")
        if not 0.0 <= self.spectral_radius <= 1.0:
            raise ClothInputError(f"dressing: spectral_radius must be in [0, 1], got "
                                  f"{self.spectral_radius!r}")
        if abs(self.angle_deg) >= 45.0:
            raise ClothInputError(f"dressing: angle_deg must be within +-45, got "
                                  f"{self.angle_deg!r}")
        if self.dt > 0.05:
            raise ClothInputError(f"dressing: dt {self.dt} s is too long (at most 0.05 s)")
        if not 0.5 <= self.seam_gap <= 1.0:
            raise ClothInputError(f"dressing: seam_gap must be in [0.5, 1], got "
                                  f"{self.seam_gap!r}")
        if self.grasp_radius >= self.sleeve_radius:
            raise ClothInputError("dressing: the grasp radius must be smaller than the "
                                  "sleeve's radius (each gripper holds its side of the rim)")
        if self.strain_limit is not None and not self.strain_limit > 1.0:
            raise ClothInputError(f"dressing: strain_limit must be above 1, got "
                                  f"{self.strain_limit!r}")
        if self.compression not in COMPRESSION_MODELS:
            raise ClothInputError(f"dressing: compression must be one of "
                                  f"{', '.join(COMPRESSION_MODELS)}, got {self.compression!r}")
        validate_solver_name(self.solver)
        get_material(self.material)

    def arm(self) -> ArmMotion:
        return still_arm(side=self.side) if self.motion == "still" else \
            clip_arm(self.motion, side=self.side)

    @property
    def name(self) -> str:
        return self.label or (f"{self.motion} {self.speed:.2f} m/s"
                              + (f", offset {100 * self.offset:.0f} cm" if self.offset else "")
                              + (f", {self.angle_deg:g} deg off" if self.angle_deg else ""))


@dataclass
class DressingRun:
    """A run's result: the spec, the sleeve's particles and mass (kg), the arm's segment
    lengths (m, hand, forearm, upper arm), steps: one dict per step (`step_record`), frames:
    [(t s, positions (n, 3) m, capsules [(p0, p1, r)])] for pictures, faces (t, 3), wall_s."""

    spec: DressingSpec
    particles: int
    mass_kg: float
    segment_lengths: list
    steps: list
    frames: list = field(default_factory=list)
    faces: np.ndarray | None = None
    wall_s: float = 0.0

    def summary(self) -> dict:
        return summarise(self)


@dataclass
class _Scene:
    sim: Simulator
    grippers: GripperSet
    opening: np.ndarray
    arm: ArmMotion
    reference: np.ndarray


def build_dressing(spec: DressingSpec) -> _Scene:
    """The sleeve, the arm and the grippers at the start, the opening grasped."""
    arm = spec.arm()
    pose = arm.at(0.0)
    way_in = pose.shoulder - pose.tip
    way_in /= np.linalg.norm(way_in)
    up = np.array([0.0, 0.0, 1.0])
    # The top gripper above the opening for an arm held out, in front of it for a hanging one.
    reference = up if abs(way_in @ up) < 0.7 else np.array([1.0, 0.0, 0.0])
    s0 = -spec.start_gap
    rot = cuff_frame(pose, s0, reference)
    centre = arc_point(pose, s0) + spec.offset * rot[:, 1]
    hier, opening, _ = sleeve_hierarchy(spec.particles, spec.sleeve_length, spec.sleeve_radius,
                                        centre, -rot[:, 2], rot[:, 0])
    p0, p1, radius = pose.capsules()
    collider = CapsuleCollider(radius, spec.friction)
    material = get_material(spec.material)
    model = build_model(hier.levels[0], material, colliders=[collider], weft=rot[:, 2],
                        thickness=spec.thickness, compression=spec.compression)
    model = replace(model, strain_limit=spec.strain_limit,
                    contact_stiffness=spec.contact_stiffness, edge_contact=spec.edge_contact)
    solver = make_solver(spec.solver, tol=spec.tolerance, hierarchy=hier,
                         bending=model.bending, threads=1)
    start = nudge_positions(np.array(hier.levels[0].rest), spec.start_nudge, spec.seed,
                            spec.start)
    state = ClothState.at_rest(start)
    state.bodies[0] = collider.moved(None, p0, p1)
    sim = Simulator(model, state, solver, dt=spec.dt, scheme=spec.scheme,
                    track_energy=False, track_contact_forces=True,
                    spectral_radius=spec.spectral_radius)
    grippers = GripperSet(GRIPPERS, spec.grasp_radius)
    _grasp_rims(grippers, _place_grippers(grippers, pose, s0, spec, reference), sim.state.x,
                spec)
    return _Scene(sim, grippers, opening, arm, reference)


def nudge_positions(x: np.ndarray, size: float, seed: int = 0, start: int = 0) -> np.ndarray:
    """(n, 3) m: every point of x (n, 3) m moved ``size`` m in a direction drawn uniformly
    on the sphere by numpy's default_rng([seed, start]) (the same draw for the same seed,
    start and n on any machine). size 0: x unchanged (a copy)."""
    x = np.array(x, dtype=np.float64)
    if size == 0.0:
        return x
    d = np.random.default_rng([seed, start]).standard_normal(x.shape)
    return x + size * d / np.linalg.norm(d, axis=1, keepdims=True)


def _place_grippers(grippers: GripperSet, pose: ArmPose, s: float, spec: DressingSpec,
                    reference: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Put the cuff's gripper at the opening's centre, arc length s (m) along the arm in
    ``pose``, and the seam's spec.seam_gap sleeve lengths behind it on the same line (a slack
    sleeve, free to follow a bent elbow), both moved
    sideways (y of their frames) by spec.offset plus the travel times tan(spec.angle_deg),
    oriented by cuff_frame. Returns their (centre (3,), frame (3, 3))."""
    placed = []
    side = spec.offset + (s + spec.start_gap) * math.tan(math.radians(spec.angle_deg))
    for name, at in zip(GRIPPERS, (s, s - spec.seam_gap * spec.sleeve_length), strict=True):
        rot = cuff_frame(pose, at, reference)
        centre = arc_point(pose, at) + side * rot[:, 1]
        grippers.set_pose(name, centre, frame_quaternion(rot))
        placed.append((centre, rot))
    return placed


def _grasp_rims(grippers: GripperSet, placed: list, x: np.ndarray, spec: DressingSpec) -> None:
    """Each gripper takes the cloth within the grasp radius of the four points of its rim at
    HOLD_ANGLES (x (n, 3) m the rest positions)."""
    for name, (centre, rot) in zip(GRIPPERS, placed, strict=True):
        points = centre + spec.sleeve_radius * (np.cos(HOLD_ANGLES)[:, None] * rot[:, 0]
                                                + np.sin(HOLD_ANGLES)[:, None] * rot[:, 1])
        near = np.linalg.norm(x[:, None, :] - points[None], axis=2) <= spec.grasp_radius
        if not np.all(near.any(axis=0)):
            raise ClothInputError(f"dressing: the {name} gripper found no cloth within "
                                  f"{spec.grasp_radius} m of a point of its rim; use more "
                                  "particles or a larger grasp radius")
        grippers.hold(name, np.flatnonzero(near.any(axis=1)), x)


def run_dressing(spec: DressingSpec, progress: bool = False, shots: int = 4) -> DressingRun:
    """Run ``spec``: settle, pull, stop at the end of the travel or when the grippers' force
    averaged over WINDOW_S (`windowed`, as the summary's) passes spec.stop_force. shots:
    frames kept for a picture (evenly over the pull)."""
    t_start = time.perf_counter()
    use_threads(1)  # one thread: the figures depend on nothing but the spec
    scene = build_dressing(spec)
    sim = scene.sim
    pull_s = spec.travel / spec.speed
    n_steps = math.ceil((spec.settle_s + pull_s) / spec.dt - 1e-9)
    marks = set(np.linspace(round(spec.settle_s / spec.dt), n_steps, max(shots, 2))
                .round().astype(int).tolist()) if shots else set()
    segment_lengths = scene.arm.at(0.0).lengths().tolist()
    steps, frames = [], []
    bar = tqdm(range(1, n_steps + 1), desc=spec.name, unit="step", disable=not progress,
               file=sys.stderr, mininterval=0.1 if sys.stderr.isatty() else 5.0)
    for k in bar:
        t = k * spec.dt
        travel = spec.speed * min(max(t - spec.settle_s, 0.0), pull_s)
        record = _step(scene, spec, t, travel)
        steps.append(record)
        stop = _window_mean(steps, spec.dt) > spec.stop_force
        if k in marks or (stop and shots):
            p0, p1, r = scene.arm.at(t).capsules()
            frames.append((t, sim.state.x.copy(), list(zip(p0, p1, r, strict=True))))
        if not np.all(np.isfinite(sim.state.x)):
            raise FloatingPointError(f"dressing {spec.name}: the cloth became non-finite at "
                                     f"step {k}")
        if stop:
            break
    return DressingRun(spec, int(sim.model.n), float(sim.model.mass.sum()), segment_lengths,
                       steps, frames, np.array(sim.model.mesh.faces),
                       time.perf_counter() - t_start)


def _step(scene: _Scene, spec: DressingSpec, t: float, travel: float) -> dict:
    """One step to time t s with the opening ``travel`` m along the arm; its record."""
    sim, grippers = scene.sim, scene.grippers
    pose = scene.arm.at(t)
    p0, p1, _ = pose.capsules()
    sim.control.collider_poses[0] = (p0, p1)
    s = travel - spec.start_gap
    _place_grippers(grippers, pose, s, spec, scene.reference)
    if len(grippers.gripper("seam").held) and \
            s - spec.seam_gap * spec.sleeve_length > SEAM_RELEASE_M:
        grippers.release("seam")  # the hand is through: the sleeve lies on the arm
    grippers.apply(sim, 1.0)
    stats = sim.step()
    grippers.measure(sim)
    slip = max(float(np.max(np.linalg.norm(sim.state.x[g.held] - g.targets(1.0), axis=1),
                            initial=0.0)) for g in grippers.grippers.values())
    grippers.end_interval()
    body = sim.contact_load.per_part(0, len(SEGMENTS))
    forces = {name: g.force for name, g in grippers.grippers.items()}
    net = np.sum(list(forces.values()), axis=0)
    dressed, s_centre, winding = dressed_length(pose, sim.state.x[scene.opening])
    return {"t": t, "travel": travel, "force_n": float(np.linalg.norm(net)),
            "force": net.tolist(),
            "gripper_wrenches": grippers.wrenches(),
            "body_forces": {n: f.tolist() for n, f in zip(SEGMENTS, body, strict=True)},
            "body_n": np.linalg.norm(body, axis=1).tolist(),
            "dressed": dressed, "opening_s": s_centre, "winding": winding, "slip": slip,
            "edge_depth": edge_depth(sim.state.x, sim.model.mesh.edges, pose),
            "max_penetration": stats.max_penetration, "iterations": stats.iterations,
            "solve_ms": stats.solve_ms, "converged": stats.converged}


def windowed(values: np.ndarray, dt: float, window: float = WINDOW_S) -> np.ndarray:
    """(k, ...) the mean of ``values`` (k, ...) over the last ``window`` s at each step (the
    first steps over what there is)."""
    width = max(1, round(window / dt))
    values = np.asarray(values, dtype=np.float64)
    csum = np.cumsum(np.concatenate([np.zeros((1,) + values.shape[1:]), values]), axis=0)
    idx = np.arange(1, len(values) + 1)
    lo = np.maximum(idx - width, 0)
    return (csum[idx] - csum[lo]) / (idx - lo).reshape((-1,) + (1,) * (values.ndim - 1))


def _window_mean(steps: list[dict], dt: float) -> float:
    """The grippers' force (N) averaged over the last WINDOW_S of ``steps``, as `windowed`
    gives it at the last step."""
    width = max(1, round(WINDOW_S / dt))
    return float(windowed(np.array([r["force_n"] for r in steps[-width:]]), dt)[-1])


def first_travel(travel: np.ndarray, force: np.ndarray, level: float) -> float | None:
    """The gripper travel (m) at which ``force`` first exceeds ``level`` N, None if never."""
    over = np.flatnonzero(force > level)
    return float(travel[over[0]]) if len(over) else None


def summarise(run: DressingRun) -> dict:
    """The run's figures.

    dressed_m: the arm's length in the sleeve at the end (dressing_arm.dressed_length), and
    its most over the run (max_dressed_m); upper_arm_ratio: the dressed part of the upper arm
    over its length; whole_arm_ratio: dressed_m over the arm's length, fingertip to shoulder;
    success: dressed_m >= SUCCESS_M. force: the net force of the cloth on the grippers (their
    sum: one end effector's wrist sensor), averaged over WINDOW_S: peak_force_n, and the
    travel at which it first passed E_STOP_N and SNAG_N (None: never); peak_body_n {segment:
    the largest force on it, averaged likewise}. slip_m: the held particles' largest distance
    from their gripper's frame; max_penetration_m: the deepest free particle inside the arm.
    outcome: 'caught' when the force passed the emergency stop (the rig would have stopped),
    else 'good' with success, else 'missed' (the arm is not in the sleeve).
    """
    spec, steps = run.spec, run.steps
    travel = np.array([r["travel"] for r in steps])
    force = windowed(np.array([r["force_n"] for r in steps]), spec.dt)
    body = windowed(np.array([r["body_n"] for r in steps]), spec.dt)
    lengths = np.array(run.segment_lengths)
    dressed = steps[-1]["dressed"] if steps else 0.0
    upper = float(np.clip(dressed - lengths[:2].sum(), 0.0, lengths[2]) / lengths[2])
    e_stop = first_travel(travel, force, E_STOP_N)
    success = dressed >= SUCCESS_M
    outcome = "caught" if e_stop is not None else ("good" if success else "missed")
    return {
        "name": spec.name, "spec": asdict(spec), "particles": run.particles,
        "mass_kg": run.mass_kg, "arm_length_m": float(lengths.sum()),
        "segment_lengths_m": dict(zip(SEGMENTS, lengths.tolist(), strict=True)),
        "steps": len(steps), "final_travel_m": float(travel[-1]) if len(travel) else 0.0,
        "dressed_m": dressed, "max_dressed_m": max((r["dressed"] for r in steps), default=0.0),
        "upper_arm_ratio": upper, "whole_arm_ratio": dressed / float(lengths.sum()),
        "success": bool(success), "outcome": outcome,
        "peak_force_n": float(force.max(initial=0.0)),
        "peak_force_travel_m": float(travel[np.argmax(force)]) if len(force) else None,
        "e_stop_travel_m": e_stop, "snag_travel_m": first_travel(travel, force, SNAG_N),
        "peak_body_n": dict(zip(SEGMENTS, body.max(axis=0, initial=0.0).tolist(), strict=True)),
        "peak_step_force_n": max((r["force_n"] for r in steps), default=0.0),
        "slip_m": max((r["slip"] for r in steps), default=0.0),
        "max_penetration_m": max((r["max_penetration"] for r in steps), default=0.0),
        "edge_depth_m": max((r["edge_depth"] for r in steps), default=0.0),
        "all_converged": all(r["converged"] for r in steps),
        "median_solve_ms": float(np.median([r["solve_ms"] for r in steps])) if steps else None,
        "wall_s": run.wall_s,
    }
