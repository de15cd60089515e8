"""Grippers that grasp cloth, carry it, feel it and let it go.

A gripper has a pose (its grasp point, m, and orientation, in the poses' frame). Grasping
takes every free particle within the grasp radius of the grasp point and holds it rigidly in
the gripper's frame from then on: the held particles become constraints of the implicit step
(Baraff-Witkin filtered rows, like the pins that sew a garment to the body), placed each step
where the gripper's frame carries them. Releasing frees them with the velocity they have.

Because a held particle is a constraint of the step's own linear system, the force that holds
it is exact for the step (sim.pins.constraint_forces: the row's residual over the
effective step, inertia included). The wrench a gripper feels is minus the sum of those
forces, with the torque about its grasp point. A gripper whose force exceeds
``release_force`` (N; 0: never) lets go by itself, as a gripper's slip or a safety stop would.

A gripper moves over an interval (a tick) from its start pose to its end pose (lerp and slerp
in the interval's fraction), or, given a `Track` (stamped poses and the interval's span on
their time line: `GripperSet.follow`), along the poses at each step's time.

Units SI: m, s, N, N m. Quaternions are (x, y, z, w), as in ROS messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.rotations import quat_to_matrix, slerp

GRASP_RADIUS = 0.02  # m, the node's default (config.schema): about a fingertip pad


@dataclass(frozen=True)
class Track:
    """Stamped poses a gripper follows over one interval: the interval spans t0..t1 s on the
    stamps' time line; stamps (m,) s increasing, positions (m, 3) m, orientations (m, 4)
    xyzw unit."""

    t0: float
    t1: float
    stamps: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,) m, orientation (4,) xyzw) at time t s: linear in position, slerp in
        orientation between the poses around t; the first before it, the last after it."""
        k = int(np.searchsorted(self.stamps, t, side="right"))  # poses at or before t: k
        if k == 0:
            return self.positions[0].copy(), self.orientations[0].copy()
        if k == len(self.stamps):
            return self.positions[-1].copy(), self.orientations[-1].copy()
        a, b = k - 1, k
        u = (t - self.stamps[a]) / (self.stamps[b] - self.stamps[a])
        q = slerp(self.orientations[a][None], self.orientations[b][None], np.array([u]))[0]
        return (1.0 - u) * self.positions[a] + u * self.positions[b], q

    def at(self, u: float) -> tuple[np.ndarray, np.ndarray]:
        """The pose a fraction u in [0, 1] through the interval (time t0 + u (t1 - t0))."""
        return self.pose(self.t0 + min(max(u, 0.0), 1.0) * (self.t1 - self.t0))


@dataclass
class Gripper:
    """One gripper. position (3,) m and orientation (4,) xyzw: its pose at the end of the
    current interval (None until a pose arrives); start_*: at its start (the tick's steps go
    from one to the other). held (k,) particle indices; offsets (k, 3) m in the gripper's
    frame. force (3,) N and torque (3,) N m: what the cloth exerted on it over the last step
    (torque about the grasp point). auto_releases: times it let go by `release_force`.
    track: stamped poses it follows over the current interval instead (None: from start to
    end pose)."""

    name: str
    position: np.ndarray | None = None
    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    start_position: np.ndarray | None = None
    start_orientation: np.ndarray = field(
        default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    held: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    auto_releases: int = 0
    track: Track | None = None

    def pose_at(self, u: float) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), rotation (3, 3)) a fraction u in [0, 1] of the way through the
        current interval (position lerped, orientation slerped)."""
        if self.position is None:
            raise ClothInputError(f"gripper {self.name!r} has no pose yet")
        if self.track is not None:
            p, q = self.track.at(u)
            return p, quat_to_matrix(q[None])[0]
        if u >= 1.0 or self.start_position is None:
            return self.position, quat_to_matrix(self.orientation[None])[0]
        q = slerp(self.start_orientation[None], self.orientation[None], np.array([u]))
        return (1.0 - u) * self.start_position + u * self.position, quat_to_matrix(q)[0]

    def targets(self, u: float) -> np.ndarray:
        """(k, 3) m: where the held particles go a fraction u through the interval."""
        p, rot = self.pose_at(u)
        return p + self.offsets @ rot.T

    def copy(self) -> Gripper:
        def c(a):
            return None if a is None else np.array(a, copy=True)
        return Gripper(self.name, c(self.position), c(self.orientation), c(self.start_position),
                       c(self.start_orientation), c(self.held), c(self.offsets), c(self.force),
                       c(self.torque), self.auto_releases, self.track)


def unit_quaternion(orientation, name: str) -> np.ndarray:
    """(4,) the quaternion xyzw normalised; ClothInputError naming the gripper if it is not
    finite or not near unit length (a zero quaternion from an unset message field)."""
    q = np.asarray(orientation, dtype=np.float64).reshape(4)
    norm = float(np.linalg.norm(q))
    if not np.all(np.isfinite(q)) or abs(norm - 1.0) > 0.1:
        raise ClothInputError(f"gripper {name!r}: orientation must be a unit quaternion "
                              f"(x, y, z, w), got {q.tolist()}")
    return q / norm


class GripperSet:
    """The grippers of one cloth simulation, in a fixed order.

    names: the grippers; grasp_radius m; release_force N (0: never); base_pins (b,): the
    particles pinned by something else (a garment's seams to the body), which a gripper never
    takes and which stay first in the model's pinned list.
    """

    def __init__(self, names: Sequence[str], grasp_radius: float = GRASP_RADIUS,
                 release_force: float = 0.0, base_pins: np.ndarray | None = None):
        names = list(names)
        if len(set(names)) != len(names):
            raise ClothInputError(f"grippers: names must be unique, got {names}")
        for name in names:
            if not isinstance(name, str) or not name or "/" in name:
                raise ClothInputError(f"grippers: {name!r} is not a usable name (one word, "
                                      "no '/')")
        if not (np.isfinite(grasp_radius) and grasp_radius > 0.0):
            raise ClothInputError(f"grasp_radius must be positive, got {grasp_radius!r}")
        if not (np.isfinite(release_force) and release_force >= 0.0):
            raise ClothInputError(f"release_force must be >= 0 N, got {release_force!r}")
        self.grippers = {name: Gripper(name) for name in names}
        self.grasp_radius = float(grasp_radius)
        self.release_force = float(release_force)
        self.base_pins = (np.zeros(0, np.int64) if base_pins is None
                          else np.asarray(base_pins, dtype=np.int64))

    @property
    def names(self) -> list[str]:
        return list(self.grippers)

    def __len__(self) -> int:
        return len(self.grippers)

    def gripper(self, name: str) -> Gripper:
        """The gripper called ``name``; ClothInputError listing the known ones otherwise."""
        try:
            return self.grippers[name]
        except KeyError:
            known = ", ".join(self.grippers) or "none"
            raise ClothInputError(f"unknown gripper {name!r}; grippers: {known}") from None

    # -- the outside world ----------------------------------------------------------------
    def set_pose(self, name: str, position, orientation=(0.0, 0.0, 0.0, 1.0)) -> None:
        """Move gripper ``name`` to ``position`` (3,) m, ``orientation`` xyzw by the end of
        the current interval. ClothInputError (nothing changes) for non-finite values."""
        g = self.gripper(name)
        p = np.asarray(position, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(p)):
            raise ClothInputError(f"gripper {name!r}: position must be finite, got {p.tolist()}")
        q = unit_quaternion(orientation, name)
        if g.position is None:  # the first pose: no motion into it
            g.start_position, g.start_orientation = p.copy(), q.copy()
        g.position, g.orientation = p, q

    def follow(self, name: str, track: Track) -> None:
        """Gripper ``name`` follows ``track`` over the current interval (its stamped poses at
        each step's time): its start and end poses become the track's at t0 and t1."""
        g = self.gripper(name)
        g.start_position, g.start_orientation = track.pose(track.t0)
        g.position, g.orientation = track.pose(track.t1)
        g.track = track

    def grasp(self, name: str, x: np.ndarray, pinned: np.ndarray | None = None) -> int:
        """Gripper ``name`` grasps every particle of x (n, 3) m within the grasp radius of its
        grasp point now that nothing holds yet (neither another gripper nor ``pinned`` (n,)
        bool). A gripper that already holds keeps what it holds and adds those. Returns how
        many particles it holds."""
        g = self.gripper(name)
        p, _ = g.pose_at(0.0)
        taken = self.held_mask(len(x))
        if pinned is not None:
            taken |= pinned
        taken[self.base_pins] = True
        near = np.flatnonzero(np.linalg.norm(x - p, axis=1) <= self.grasp_radius)
        return self.hold(name, near[~taken[near]], x)

    def hold(self, name: str, indices: np.ndarray, x: np.ndarray) -> int:
        """Gripper ``name`` holds particles ``indices`` of x (n, 3) m as they lie now, in its
        frame (a scene that grasps exactly its corners). Returns how many it holds."""
        g = self.gripper(name)
        p, rot = g.pose_at(0.0)
        indices = np.setdiff1d(np.asarray(indices, dtype=np.int64), g.held)  # sorted, unique
        if len(indices):
            g.held = np.concatenate([g.held, indices])
            g.offsets = np.concatenate([g.offsets, (x[indices] - p) @ rot])
        return len(g.held)

    def release(self, name: str) -> int:
        """Gripper ``name`` lets go of everything. Returns how many particles it released."""
        g = self.gripper(name)
        count = len(g.held)
        g.held, g.offsets = np.zeros(0, np.int64), np.zeros((0, 3))
        g.force, g.torque = np.zeros(3), np.zeros(3)
        return count

    # -- stepping ----------------------------------------------------------------------------
    def held(self) -> np.ndarray:
        """(k,) every held particle, gripper by gripper."""
        parts = [g.held for g in self.grippers.values()]
        return np.concatenate(parts) if parts else np.zeros(0, np.int64)

    def held_mask(self, n: int) -> np.ndarray:
        mask = np.zeros(n, dtype=bool)
        mask[self.held()] = True
        return mask

    def apply(self, sim, u: float, base_targets: np.ndarray | None = None) -> None:
        """Before a step of ``sim`` (sim.integrator.Simulator) that ends a fraction u through
        the interval: the control's pinned list becomes the base pins then the held
        particles, and its pin targets their places (base_targets (b, 3) m, None: where the
        base pins are)."""
        state = sim.state
        held = [g for g in self.grippers.values() if len(g.held)]
        base = state.x[self.base_pins] if base_targets is None else base_targets
        sim.control.pinned = np.concatenate([self.base_pins] + [g.held for g in held])
        sim.control.pin_targets = np.concatenate([base] + [g.targets(u) for g in held])
        sim.track_constraint_forces = True

    def measure(self, sim) -> list[str]:
        """After a step of ``sim``: each gripper's force and torque from the step's constraint
        forces (the cloth pulls on the gripper with minus the force that holds it; torque
        about the grasp point, at the particles' end-of-step places). Grippers whose force
        exceeds release_force let go; returns their names."""
        reaction = sim.constraint_forces
        at = len(self.base_pins)
        released = []
        for g in self.grippers.values():
            k = len(g.held)
            if not k:
                g.force, g.torque = np.zeros(3), np.zeros(3)
                continue
            on_gripper = -reaction[at:at + k]
            at += k
            p, _ = g.pose_at(1.0)
            g.force = on_gripper.sum(axis=0)
            g.torque = np.cross(sim.state.x[g.held] - p, on_gripper).sum(axis=0)
            if self.release_force > 0.0 and np.linalg.norm(g.force) > self.release_force:
                g.auto_releases += 1
                released.append(g.name)
        for name in released:
            self.release(name)
        return released

    def end_interval(self) -> None:
        """The interval's end pose becomes the next interval's start (a track is done)."""
        for g in self.grippers.values():
            g.track = None
            if g.position is not None:
                g.start_position = g.position.copy()
                g.start_orientation = g.orientation.copy()

    def frames(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """{name: (grasp point (3,) m, orientation (4,) xyzw)} at the interval's end: where
        each gripper's wrench was measured (a gripper without a pose: origin, identity)."""
        return {g.name: (np.zeros(3) if g.position is None else g.position.copy(),
                         g.orientation.copy()) for g in self.grippers.values()}

    def wrenches(self) -> dict[str, dict[str, list[float]]]:
        """{name: {"force": [fx, fy, fz] N, "torque": [tx, ty, tz] N m}} of the last step."""
        return {g.name: {"force": g.force.tolist(), "torque": g.torque.tolist()}
                for g in self.grippers.values()}

    def restrict(self, n: int, x: np.ndarray) -> None:
        """Keep only held particles below index n (a coarser rung keeps the first n of the
        finer one's vertices, sim.detail); a gripper left with none holds the rung's particle
        nearest its grasp point, x (n, 3) m the coarse positions."""
        for g in self.grippers.values():
            if not len(g.held):
                continue
            keep = g.held < n
            if np.any(keep):
                g.held, g.offsets = g.held[keep], g.offsets[keep]
                continue
            p, _ = g.pose_at(1.0)
            nearest = int(np.argmin(np.linalg.norm(x[:n] - p, axis=1)))
            g.held, g.offsets = np.zeros(0, np.int64), np.zeros((0, 3))
            self.hold(g.name, np.array([nearest]), x)

    def copy(self) -> GripperSet:
        out = GripperSet(self.names, self.grasp_radius, self.release_force, self.base_pins)
        out.grippers = {name: g.copy() for name, g in self.grippers.items()}
        return out


def step_held(sim, grippers: GripperSet | None):
    """One step of ``sim`` (sim.integrator.Simulator) with ``grippers`` holding what they
    hold at the end of their interval (a sheet's step is a whole interval). Returns (the
    step's StepStats, the names of grippers that let go by release_force)."""
    if grippers is None:
        return sim.step(), []
    grippers.apply(sim, 1.0)
    stats = sim.step()
    released = grippers.measure(sim)
    grippers.end_interval()
    return stats, released


@dataclass
class GripperScript:
    """A scripted gripper (a scene file's): path (m, 4) rows (t s, x, y, z m), the grasp
    point's waypoints, increasing in t, linear in between and held before the first and
    after the last; orientation (4,) xyzw, fixed; grasp and release: times (s) of the
    events (a grasp at t takes what is in reach when the step that starts at or after t
    begins)."""

    name: str
    path: np.ndarray
    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    grasp: tuple[float, ...] = ()
    release: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        path = np.asarray(self.path, dtype=np.float64)
        if path.ndim == 1 and path.size % 4 == 0:
            path = path.reshape(-1, 4)
        if path.ndim != 2 or path.shape[1] != 4 or not len(path) or \
                not np.all(np.isfinite(path)):
            raise ClothInputError(f"gripper {self.name!r}: path must be rows of finite "
                                  f"(t, x, y, z), got {np.asarray(self.path).tolist()}")
        if np.any(np.diff(path[:, 0]) <= 0.0):
            raise ClothInputError(f"gripper {self.name!r}: path times must increase, got "
                                  f"{path[:, 0].tolist()}")
        self.path = path
        self.orientation = unit_quaternion(self.orientation, self.name)
        for kind in ("grasp", "release"):
            times = tuple(float(t) for t in getattr(self, kind))
            if not all(np.isfinite(times)):
                raise ClothInputError(f"gripper {self.name!r}: {kind} times must be finite")
            setattr(self, kind, times)

    def position(self, t: float) -> np.ndarray:
        """(3,) m: the grasp point at time t s."""
        p = self.path
        return np.array([np.interp(t, p[:, 0], p[:, k]) for k in (1, 2, 3)])


def play_scripts(grippers: GripperSet, scripts: Sequence[GripperScript], t0: float, t1: float,
                 x: np.ndarray, pinned: np.ndarray | None = None) -> list[tuple[str, str, int]]:
    """Before a step from t0 to t1 (s): each script's gripper goes to its place at t1, and
    its grasp and release events in [t0, t1) happen, in time order, grasping from x (n, 3) m.
    Returns the events [(gripper, 'grasp' or 'release', particles held or released)]."""
    events = []
    for s in scripts:
        if grippers.gripper(s.name).position is None:
            grippers.set_pose(s.name, s.position(t0), s.orientation)
    happening = sorted((t, kind, s) for s in scripts for kind in ("grasp", "release")
                       for t in getattr(s, kind) if t0 <= t < t1)
    for _, kind, s in happening:
        if kind == "grasp":
            events.append((s.name, kind, grippers.grasp(s.name, x, pinned)))
        else:
            events.append((s.name, kind, grippers.release(s.name)))
    for s in scripts:
        grippers.set_pose(s.name, s.position(t1), s.orientation)
    return events
