"""What a live session drives: a scene (`LiveScene`: a garment on a pose stream,
ros.body_scene, or a sheet on the node's timer, ros.sheet_scene) and the values its ticks
return (`Frame`: one drawing of the cloth and its status; `Clear`: the display drops the
cloth). The session (ros.session) keeps the loop and the requests and publishes the values;
the scene never publishes and the session never reaches into the simulation.

Units SI: m, m/s, N, N m, ms for durations in the status.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from cloth_mg_ros.ros.gripper_desk import GripperDesk

__all__ = ["Clear", "ClockSpan", "Frame", "LiveScene"]


class ClockSpan:
    """The span of the node's clock a timer tick covers (its grippers' stamped poses are used
    over it): from the previous tick's reading to this one's; the first tick after a start, a
    resume (`restart`) or a clock that went back spans one period before its reading."""

    def __init__(self) -> None:
        self._last: float | None = None  # s: the previous tick's reading

    def span(self, sec: int, nanosec: int, period_s: float) -> tuple[float, float]:
        """(t0, t1) s for a tick reading the clock at (sec, nanosec); period_s: the tick's
        period, s."""
        t1 = sec + 1e-9 * nanosec
        last = self._last
        t0 = last if last is not None and last <= t1 else t1 - period_s
        self._last = t1
        return t0, t1

    def restart(self) -> None:
        """The ticks start again after a pause: the next spans one period, not the pause."""
        self._last = None


@dataclass(frozen=True)
class Clear:
    """The display drops the cloth and the body (a new pose stream, a reset), stamped (sec,
    nanosec) in frame_id ('' : the frame last drawn in)."""

    sec: int
    nanosec: int
    frame_id: str = ""


@dataclass(frozen=True)
class Frame:
    """One tick's result, everything publishing needs.

    sec, nanosec: the stamp published; frame_id: the poses' frame ('': the node's);
    model: the cloth's ClothModel (its mesh and rest lengths); positions, velocities: (n, 3)
    m and m/s, copies taken at the tick's end; finite: whether every position is finite;
    capsules: the body's (p0 (S, 3), p1 (S, 3), radius (S,)) m, or None; spheres: a sheet's
    obstacles; arrows: the contact forces' arrows {id: (start (3,), end (3,))} m;
    gripper_wrenches: {name: {"force": (3,) N, "torque": (3,) N m}}; body_forces,
    body_torques: {segment: (3,)} N, N m, the cloth's on each colliding segment (the mean
    over the tick's steps); gripper_poses, segment_poses: {name: (position (3,) m, orientation
    (4,) xyzw)} of each gripper and body segment at the tick's end (the wrenches' frames:
    ros.wrenches); stats: the tick's TickStats or StepStats (None: no step, a
    dressing); step_ms: the tick's time, ms; step: the ticks the scene has stepped so far;
    stepped: whether this tick stepped the cloth (max_steps counts it); values: the status's
    key-values; level, note: the status's level and message.
    """

    sec: int
    nanosec: int
    frame_id: str
    model: object
    positions: np.ndarray
    velocities: np.ndarray
    finite: bool
    stats: object
    step_ms: float
    step: int
    stepped: bool
    values: Mapping[str, str]
    level: bytes
    note: str = ""
    capsules: tuple | None = None
    spheres: tuple = ()
    arrows: Mapping[int, tuple] = field(default_factory=dict)
    gripper_wrenches: Mapping[str, Mapping[str, np.ndarray]] = field(default_factory=dict)
    body_forces: Mapping[str, np.ndarray] = field(default_factory=dict)
    body_torques: Mapping[str, np.ndarray] = field(default_factory=dict)
    gripper_poses: Mapping[str, tuple] = field(default_factory=dict)
    segment_poses: Mapping[str, tuple] = field(default_factory=dict)
    lag_ms: float = 0.0


class LiveScene(Protocol):
    """A scene the live session drives, on its simulation thread (except `request_reset`
    and `wake`, called from the executor's thread).

    clock: 'messages' (a tick per arrival of poses: `take` waits for them) or 'timer' (a tick
    every 1/rate_hz s of wall time, of /clock's under use_sim_time: ros.timer_clock); desk:
    its grippers' hand-over (ros.gripper_desk); frame_id: the frame it publishes in now ('':
    the node's).
    """

    clock: str
    desk: GripperDesk | None
    frame_id: str

    def prepare(self, sim_thread, outputs) -> str:
        """Build the scene and warm its kernels up on sim_thread (ros.sim_thread.SimThread);
        outputs (ros.publishing.ClothOutputs) build their messages once. Returns the start-up
        log line's description; raises ClothInputError for an unusable value."""

    def take(self, timeout_s: float) -> object:
        """The inputs of the next tick (waiting up to timeout_s for them when the clock is
        'messages')."""

    def tick(self, inputs: object, period_s: float | None) -> list[Frame | Clear]:
        """Step the cloth through `inputs` (period_s: the timer's period, s; None on the
        'messages' clock); what to publish, in order."""

    def published(self, frame: Frame, marker_ms: float) -> None:
        """After `frame` went out (its markers took marker_ms): follow the tick budget."""

    def resumed(self) -> None:
        """The tick loop starts again after a stop (a managed node activated again): the
        timer's next tick spans one period of the clock, not the time it was inactive."""

    def tick_failed(self) -> int:
        """The tick (or its publishing) raised: count its inputs not yet counted as skipped
        and start clean on the next inputs (a body scene re-dresses). Returns the inputs
        skipped."""

    def not_ticked(self, inputs: object) -> None:
        """Inputs taken when the loop stopped (a shutdown or deactivate woke the take): never
        ticked, counted as discarded, not lost."""

    def apply_gripper_inputs(self) -> None:
        """The desk's poses, calls and release_force applied before a tick."""

    def change_solver(self, solver: str, tolerance: float | str) -> str:
        """Rebuild the solver; returns the tolerance as the log describes it."""

    def tolerance_auto_available(self) -> bool:
        """Whether tolerance auto was measured at start (it may then be chosen again)."""

    def request_reset(self) -> str:
        """~/reset asked (executor's thread); returns what will happen."""

    def reset(self) -> None:
        """The reset, on the simulation thread before the next tick."""

    def wake(self) -> None:
        """Wake a `take` waiting."""

    def waiting_text(self) -> str:
        """The /diagnostics message before the first tick."""

    def periodic_summary(self) -> None:
        """Log what was skipped since the last summary, when anything was."""

    def log_summary(self, resets: int) -> None:
        """Log the inputs' summary at shutdown (resets: ~/reset calls served)."""
