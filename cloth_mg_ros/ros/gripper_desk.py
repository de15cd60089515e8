"""cloth_node's grippers: what arrives for them on the executor's thread (poses, grasp and
release calls, a new release_force), handed to the simulation thread and applied there
between ticks, so that nothing races a step.

`GripperDesk` is the hand-over. The pose subscription's callback checks a PoseStamped and
keeps it (`offer_pose`, microseconds: a bad one is skipped, counted and logged once per kind,
then summarised): a pose with a zero (unset) header.stamp as its gripper's newest pose, one
with a stamp in its gripper's short buffer of stamped poses (STAMPED_POSES, by stamp); the
grasp service's callback queues a request and waits until the simulation thread answered
it (`call`, at most about one tick; the services run on a node and thread of their own,
ros.grasp_services, so the poses keep arriving meanwhile). Before
each tick the scene calls `apply` on the simulation thread with the GripperSet it steps:
the newest poses become the grippers' targets for the coming tick (`GripperSet.set_pose`:
the held particles follow over the tick), then the calls are answered (a grasp takes what is
in reach of where the gripper is at the tick's start: its first pose at once, a later one
once a tick has carried it there). Stamped poses are used at their stamps: once the scene
knows the span of stamps a tick (or a part of one) simulates, `place_stamped` makes each
gripper with stamped poses follow them (sim.grippers.Track: at each step's time, linear in
position and slerp in orientation; the newest held past its stamp; the newest pose stamped
at or before the span's start is where it starts, else where the gripper is). A zero-stamped
pose discards its gripper's stamped ones (the newest wins, as always). A gripper whose poses
stop arriving holds still. A GripperSet
made afresh (a body scene re-dressed, a sheet restarted) gets each gripper's newest pose where it
has none.

`sheet_grippers` is a sheet scene's set: the scene's own (the hang's `left` and `right`)
and those of the `grippers` parameter.

Units SI: m, N; quaternions (x, y, z, w).
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.grippers import GripperSet, Track, unit_quaternion

__all__ = ["POSE_KINDS", "GripperDesk", "grippers_text", "sheet_grippers"]

# Stamped poses kept per gripper (the oldest goes first): a second of a 100 Hz controller
# beyond the tick that uses them.
STAMPED_POSES = 128

#: What each kind of skipped gripper pose means, for the log.
POSE_KINDS = {
    "non_finite": "a NaN or infinite position or orientation",
    "not_unit": "an orientation that is not a unit quaternion (a zero quaternion: an unset "
                "field)",
    "wrong_frame": "a header.frame_id other than the poses' frame (the node does not "
                   "transform)",
    "stale": "stamped before the pose a tick's span starts from (the newest at or before "
             "its start): time the cloth has already simulated",
    "overflow": f"more stamped poses waiting than {STAMPED_POSES} (the oldest go): poses "
                "far ahead of the ticks",
}
CALL_TIMEOUT_S = 10.0  # s: how long a grasp call waits for the simulation thread


@dataclass
class GraspCall:
    """One grasp (True) or release (False) call of gripper `name`, answered by the simulation
    thread: success, message; done is set once answered. taken: the simulation thread is
    answering it; abandoned: its caller gave up waiting before that (it is dropped)."""

    name: str
    grasp: bool
    done: threading.Event = field(default_factory=threading.Event)
    success: bool = False
    message: str = ""
    taken: bool = False
    abandoned: bool = False


@dataclass
class _Pose:
    position: np.ndarray  # (3,) m
    orientation: np.ndarray  # (4,) xyzw, unit
    frame_id: str
    stamp: float = 0.0  # s; 0: unset ("now")
    used: bool = False  # a span's track went through it (stamped poses)


def sheet_grippers(scene, names: Sequence[str], grasp_radius: float,
                   release_force: float) -> GripperSet | None:
    """A sheet scene's grippers: the scene's own (scene.grippers: the hang's left and right,
    holding its corners) followed by `names` (the grippers parameter; a name the scene
    already has is that one), all with grasp_radius m and release_force N. None when there
    are none (the drape without the parameter: it steps as it always did)."""
    own = scene.grippers
    everyone = (own.names if own is not None else []) + [
        n for n in names if own is None or n not in own.grippers]
    if not everyone:
        return None
    out = GripperSet(everyone, grasp_radius, release_force)
    if own is not None:
        for name, g in own.grippers.items():
            out.grippers[name] = g.copy()
    return out


class GripperDesk:
    """The grippers' inputs between the executor's thread and the simulation thread (module
    docstring). names: every gripper the node offers topics for; logger: the node's."""

    def __init__(self, names: Sequence[str], logger) -> None:
        self.names = list(names)
        self.logger = logger
        self._lock = threading.Lock()
        self._newest: dict[str, _Pose] = {}  # every gripper's newest valid pose
        self._stamped: dict[str, list[_Pose]] = {}  # stamped poses by stamp, per gripper
        self._fresh: set[str] = set()  # grippers whose newest pose is not applied yet
        self._calls: list[GraspCall] = []
        self._release_force: float | None = None
        self._target: GripperSet | None = None  # the set the newest poses were applied to
        self.received = 0
        self.skipped: Counter = Counter()
        self._summarised: Counter = Counter()
        self.auto_releases = 0
        self.stopped = False  # the simulation thread no longer answers calls

    # -- the executor's thread ------------------------------------------------------------
    def offer_pose(self, name: str, position: Sequence[float], orientation: Sequence[float],
                   frame_id: str = "", stamp: float = 0.0) -> bool:
        """A pose of gripper `name` (grasp point (3,) m, orientation (4,) xyzw) in frame_id
        at `stamp` s (header.stamp; 0: unset): kept as its newest (stamp 0) or among its
        stamped poses, or skipped (non-finite, not a unit quaternion: counted, the first of
        each kind logged). Returns whether it was kept."""
        p = np.asarray(position, dtype=np.float64).reshape(3)
        with self._lock:
            self.received += 1
        if not np.all(np.isfinite(p)) or not np.all(np.isfinite(orientation)):
            self._skip(name, "non_finite", p, orientation)
            return False
        try:
            q = unit_quaternion(orientation, name)
        except ClothInputError:
            self._skip(name, "not_unit", p, orientation)
            return False
        pose = _Pose(p, q, frame_id, float(stamp))
        with self._lock:
            if pose.stamp > 0.0:
                kept = self._stamped.setdefault(name, [])
                at = len(kept)
                while at and kept[at - 1].stamp > pose.stamp:  # (poses arrive nearly in order)
                    at -= 1
                if at and kept[at - 1].stamp == pose.stamp:
                    kept[at - 1] = pose  # the same stamp again: the newer message wins
                else:
                    kept.insert(at, pose)
                over = [k for k in kept[:-STAMPED_POSES] if not k.used]
                del kept[:-STAMPED_POSES]
                self._newest.pop(name, None)  # stamped poses rule from now on
                self._fresh.discard(name)
            else:
                over = []
                self._newest[name] = pose
                self._fresh.add(name)
                self._stamped.pop(name, None)
        for old in over:
            self._skip(name, "overflow", old.position, old.orientation)
        return True

    def call(self, name: str, grasp: bool, wake: Callable[[], None] = lambda: None,
             timeout_s: float = CALL_TIMEOUT_S) -> tuple[bool, str]:
        """Grasp (True) or release (False) with gripper `name` before the next tick: queue
        the call, wake the simulation thread, wait for its answer (success, message)."""
        call = GraspCall(name, grasp)
        with self._lock:
            if self.stopped:
                return False, "the simulation has stopped"
            self._calls.append(call)
        wake()
        if not call.done.wait(timeout_s):
            with self._lock:
                call.abandoned = not call.taken
            if call.abandoned:
                return False, (f"the simulation did not take the call within {timeout_s:g} s "
                               f"(a tick running long); nothing changed")
            call.done.wait()  # being answered now
        return call.success, call.message

    @property
    def queued_calls(self) -> int:
        """Grasp and release calls waiting for the simulation thread."""
        with self._lock:
            return len(self._calls)

    def request_release_force(self, force: float) -> None:
        """A new release_force (N) for every gripper from the next tick on."""
        with self._lock:
            self._release_force = float(force)

    def stop(self) -> None:
        """The simulation thread stopped: answer waiting and later calls that it did."""
        with self._lock:
            self.stopped = True
            calls, self._calls = self._calls, []
        for call in calls:
            call.message = "the simulation has stopped"
            call.done.set()

    def resume(self) -> None:
        """The simulation thread runs again (a managed node activated again): take calls."""
        with self._lock:
            self.stopped = False

    # -- the simulation thread ------------------------------------------------------------
    def apply(self, grippers: GripperSet | None, x: np.ndarray | None,
              pinned: np.ndarray | None, frame_id: str) -> float | None:
        """Between ticks, on the simulation thread: make the newest poses the targets of
        `grippers` (None: no cloth yet) for the next tick (poses in a frame other than
        frame_id, the poses' frame, are skipped), set a new release_force, then answer the
        queued calls with the cloth at x (n, 3) m and `pinned` (n,) bool (particles something
        else holds). A grasp takes what is in reach of where the gripper is at the tick's
        start: its first pose at once, a later one once a tick has carried it there.
        Returns the new release_force (N) set, or None."""
        with self._lock:
            calls, self._calls = self._calls, []
            force, self._release_force = self._release_force, None
            fresh, newest = set(self._fresh), dict(self._newest)
            firsts = {n: kept[0] for n, kept in self._stamped.items()
                      if kept and kept[0].frame_id in ("", frame_id)}
            new_set = grippers is not None and grippers is not self._target
            if grippers is not None:
                self._fresh.clear()
                self._target = grippers
            elif force is not None:
                self._release_force = force  # kept, with the poses, for the set to come
        if grippers is not None:
            if force is not None:
                grippers.release_force = force
            for name in sorted(newest if new_set else fresh):
                g = grippers.grippers.get(name)
                if g is None or (name not in fresh and g.position is not None):
                    continue  # a new set's own pose (the hang's corners) stays till one comes
                self._place(grippers, name, newest[name], frame_id)
            for name, first in firsts.items():  # stamped poses only: the first one, at once
                g = grippers.grippers.get(name)
                if g is not None and g.position is None:
                    self._place(grippers, name, first, frame_id)
        for call in calls:
            self._answer(call, grippers, x, pinned)
        return force if grippers is not None else None

    def place_stamped(self, grippers: GripperSet | None, t0: float, t1: float,
                      frame_id: str) -> None:
        """On the simulation thread, once the scene knows the span t0..t1 s (on the stamps'
        time line) of the steps it is about to take: every gripper with stamped poses follows
        them over it (module docstring); poses in a frame other than frame_id are skipped.
        Poses older than the newest at or before t1 are dropped (that one is kept: the next
        span starts from it)."""
        if grippers is None:
            return
        with self._lock:
            stamped = {n: list(kept) for n, kept in self._stamped.items() if kept}
        for name, kept in sorted(stamped.items()):
            g = grippers.grippers.get(name)
            if g is None:
                continue
            usable = [k for k in kept if self._in_frame(name, k, frame_id)]
            start = [k for k in usable if k.stamp <= t0]
            for old in start[:-1]:  # the span starts from the newest of them
                if not old.used:  # one that arrived after the span it belonged to: counted
                    self._skip(name, "stale", old.position, old.orientation)
            track = start[-1:] + [k for k in usable if k.stamp > t0]
            with self._lock:  # what the span used up goes (poses may have come meanwhile)
                for k in track:  # (offer_pose reads it under the lock)
                    k.used = True
                now = self._stamped.get(name, [])
                drop = {id(k) for k in kept} - {id(k) for k in usable}
                drop |= {id(k) for k in [k for k in now if k.stamp <= t1][:-1]}
                self._stamped[name] = [k for k in now if id(k) not in drop]
            if not track:
                continue
            stamps = [k.stamp for k in track]
            positions, orientations = [k.position for k in track], [k.orientation for k in track]
            if not start and g.position is not None:  # from where it is, at the span's start
                stamps.insert(0, t0)
                positions.insert(0, g.position)
                orientations.insert(0, g.orientation)
            grippers.follow(name, Track(float(t0), float(t1), np.asarray(stamps),
                                        np.asarray(positions), np.asarray(orientations)))

    def _in_frame(self, name: str, pose: _Pose, frame_id: str) -> bool:
        if pose.frame_id and pose.frame_id != frame_id:
            self._skip(name, "wrong_frame", pose.position, pose.orientation,
                       f" ({pose.frame_id!r}, the poses' frame is {frame_id!r})")
            return False
        return True

    def _place(self, grippers: GripperSet, name: str, pose: _Pose, frame_id: str) -> None:
        """Gripper `name` goes to `pose` over the next tick, unless it is in another frame."""
        if self._in_frame(name, pose, frame_id):
            grippers.set_pose(name, pose.position, pose.orientation)

    def _answer(self, call: GraspCall, grippers: GripperSet | None, x: np.ndarray | None,
                pinned: np.ndarray | None) -> None:
        with self._lock:
            if call.abandoned:
                return
            call.taken = True
        call.success, call.message = self._do(call, grippers, x, pinned)
        call.done.set()
        # (rclpy: one call site logs at one severity only)
        if call.success:
            self.logger.info(f"gripper {call.name}: {call.message}")
        else:
            self.logger.warning(f"gripper {call.name}: {call.message}")

    def _do(self, call: GraspCall, grippers: GripperSet | None, x: np.ndarray | None,
            pinned: np.ndarray | None) -> tuple[bool, str]:
        """(success, message) of one call."""
        if grippers is None or x is None:
            return False, "no cloth yet (the garment is dressed on the first body pose)"
        try:
            g = grippers.gripper(call.name)
            if not call.grasp:
                count = grippers.release(call.name)
                return True, f"released {count} particle{'s' * (count != 1)}"
            if g.position is None:
                return False, (f"no pose yet: publish one on gripper/{call.name}/pose "
                               f"first (a grasp takes what is within the grasp radius of it)")
            before = len(g.held)
            count = grippers.grasp(call.name, x, pinned)
        except ClothInputError as exc:
            return False, str(exc)
        p = g.position if g.start_position is None else g.start_position
        if count == 0:
            return False, (f"nothing in reach: no free particle within grasp_radius "
                           f"{grippers.grasp_radius:g} m of the grasp point "
                           f"({', '.join(f'{c:.3f}' for c in p)}) m; holds 0 particles")
        return True, (f"holds {count} particle{'s' * (count != 1)} "
                      f"({count - before} taken now)")

    def note_released(self, names: Sequence[str], release_force: float) -> None:
        """Grippers that let go by themselves this tick (release_force): counted, logged."""
        for name in names:
            self.auto_releases += 1
            self.logger.warning(
                f"gripper {name} let go by itself: the cloth pulled it harder than "
                f"release_force {release_force:g} N ({self.auto_releases} automatic "
                f"release{'s' * (self.auto_releases != 1)} so far)")

    # -- reports ----------------------------------------------------------------------------
    def _skip(self, name: str, kind: str, p, q, detail: str = "") -> None:
        with self._lock:
            first = not self.skipped[kind]
            self.skipped[kind] += 1
        if first:
            self.logger.warning(
                f"skipped a pose of gripper {name}: {kind}: {POSE_KINDS[kind]}{detail} "
                f"(position {np.asarray(p).tolist()}, orientation "
                f"{np.asarray(q, dtype=float).tolist()}); the gripper holds still; further "
                f"{kind} poses are counted and summarised")

    def summary(self) -> str:
        """One line: 'gripper poses: R received; skipped S: kind n, ...; A automatic
        releases'."""
        with self._lock:
            skipped = {k: n for k, n in sorted(self.skipped.items()) if n}
            line = f"gripper poses: {self.received} received"
        if skipped:
            line += "; skipped " + ", ".join(f"{k} {n}" for k, n in skipped.items())
        return f"{line}; {self.auto_releases} automatic releases"

    def changed(self) -> bool:
        """Whether poses were skipped since the last periodic summary."""
        with self._lock:
            if self.skipped == self._summarised:
                return False
            self._summarised = self.skipped.copy()
            return True

    def values(self, grippers: GripperSet | None) -> dict[str, str]:
        """The stats' key-values: poses received and skipped (in all and per kind of fault,
        POSE_KINDS), automatic releases, and per
        gripper the particles it holds and the force on it (N)."""
        with self._lock:
            out = {"gripper_poses_received": str(self.received),
                   "gripper_poses_skipped": str(sum(self.skipped.values())),
                   **{f"gripper_poses_skipped_{kind}": str(self.skipped.get(kind, 0))
                      for kind in POSE_KINDS},
                   "gripper_auto_releases": str(self.auto_releases)}
        for name in self.names:
            g = None if grippers is None else grippers.grippers.get(name)
            out[f"gripper_{name}_held"] = str(0 if g is None else len(g.held))
            out[f"gripper_{name}_force_n"] = (
                f"{0.0 if g is None else float(np.linalg.norm(g.force)):.4f}")
        return out


def grippers_text(names: Sequence[str]) -> str:
    """The start-up line's grippers ('' without any)."""
    return f"; grippers {', '.join(names)}" if names else ""
