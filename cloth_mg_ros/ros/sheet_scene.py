"""A live sheet scene: a cloth sheet (sim.sheets: the hang, the drape) stepped by `dt` every
1/rate_hz s of the node's clock (wall time; /clock's under use_sim_time: ros.session), its
grippers holding what they hold (sim.grippers.step_held: a gripper's new pose carries its
particles in that step). A tick spans the node's clock from the previous tick's stamp to its
own (the first: one period): a gripper's stamped poses are used at the tick's stamp
(ros.gripper_desk.GripperDesk.place_stamped), which the tick's Frame carries. `SheetScene` is the
ros.live_scene.LiveScene the session drives; each tick returns its Frame.

On more than one thread, the steps run on as many as the thread governor leaves them
(budget.thread_governor, as a body scene's: fewer while other work holds the cores, whose
barriers would otherwise wait a scheduler slice each; the hang at 2491 particles beside two
busy processes solved in 19-35 ms a step on one thread against 55-72 ms on two). The solver's
sweeps split into `threads` parts whatever runs them, so the cloth is the same bit for bit.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from cloth_mg_ros.apps.warmup import warm_up_sheet
from cloth_mg_ros.budget.contention import ContentionMeter
from cloth_mg_ros.budget.thread_governor import ThreadGovernor
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.gripper_desk import GripperDesk, grippers_text, sheet_grippers
from cloth_mg_ros.ros.live_scene import Clear, ClockSpan, Frame
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.sim.grippers import GripperSet, step_held
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver
from cloth_mg_ros.solvers.threads import available_threads, resolve_threads, use_threads

__all__ = ["SheetScene"]


class SheetScene:
    """A sheet on the node's timer (module docstring).

    settings: the parameters fixed at start; logger: the node's; now: the node's clock as
    (sec, nanosec) (each step is stamped with it); rate_hz: rate_hz now, Hz (for the start-up
    line).
    """

    clock = "timer"

    def __init__(self, settings: SessionSettings, logger, now: Callable[[], tuple[int, int]],
                 rate_hz: Callable[[], float]) -> None:
        self.settings = settings
        self.params = settings.values
        self.logger = logger
        self.now = now
        self.rate_hz = rate_hz
        self.solver = self.params.solver
        self.tolerance = self.params.tolerance
        self.frame_id = ""  # the node's frame
        self.scene = None  # sim.sheets.SheetScene
        self.sim: Simulator | None = None
        self.grippers: GripperSet | None = None  # the sheet's (ros.gripper_desk)
        self.initial_grippers: GripperSet | None = None  # ... as they start (for a reset)
        self.initial_state = None
        self.desk: GripperDesk | None = None
        self.steps = 0
        self._span = ClockSpan()  # the node's clock over each tick
        self.governor: ThreadGovernor | None = None  # on more than one thread (module doc)
        self.contention = ContentionMeter()
        self.wait_share: float | None = None  # over the last tick (None: unknown)

    def prepare(self, sim_thread, outputs) -> str:
        """Build the sheet, its grippers (the scene's own and the grippers parameter's:
        ros.gripper_desk.sheet_grippers) and its simulator; warm its kernels up on
        sim_thread. Returns the start-up log line's description."""
        s, values = self.settings, self.params
        t0 = time.perf_counter()
        for key in ("particles", "tolerance"):
            if values[key] == AUTO:
                raise ClothInputError(f"parameter {key}: 'auto' is for body scenes (a garment "
                                      f"on a pose stream); give a sheet a number")
        self.scene = s.sheet_scene()
        self.initial_state = self.scene.state.copy()
        self.grippers = sheet_grippers(self.scene, values.grippers, values.grasp_radius,
                                       values.release_force)
        if self.grippers is not None:
            self.initial_grippers = self.grippers.copy()
        self.desk = GripperDesk(self.grippers.names if self.grippers else (), self.logger)
        # track_energy off: the node publishes no energy, and counting it costs each step a
        # second force pass (sim.integrator.energies)
        self.sim = Simulator(self.scene.model, self.scene.state, self._solver(),
                             dt=values.dt, scheme=values.scheme,
                             spectral_radius=values.spectral_radius, track_energy=False,
                             newton_iterations=values.newton_iterations,
                             linearise_at=values.linearise_at)
        build_ms = 1e3 * (time.perf_counter() - t0)
        warm = sim_thread.call(warm_up_sheet, values.scene, s.material, self.solver,
                               float(self.tolerance), self.sim.dt, s.levels, s.threads,
                               scheme=values.scheme, spectral_radius=values.spectral_radius,
                               friction=s.sheet_friction, compression=values.compression)
        threads = resolve_threads(s.threads)
        self.governor = ThreadGovernor(threads, available_threads()) if threads > 1 else None
        return (f"scene {self.scene.name!r}: {self.scene.model.n} particles, "
                f"{len(self.scene.model.mesh.faces)} triangles, {s.material.name}, "
                f"solver {self.solver} (tol {self.tolerance:g}), dt {self.sim.dt:.4g} "
                f"s, {self.rate_hz():g} Hz, built in {build_ms:.0f} ms, warmed up in "
                f"{warm.describe()}{grippers_text(self.desk.names)}{s.unused_text()}")

    def _solver(self):
        """A solver for the sheet (make_solver with its hierarchy and bending Hessians) from
        the current solver and tolerance."""
        return make_solver(self.solver, tol=float(self.tolerance),
                           hierarchy=self.scene.hierarchy, bending=self.scene.model.bending,
                           levels=self.settings.levels, threads=self.settings.threads)

    # -- requests ------------------------------------------------------------------------
    def apply_gripper_inputs(self) -> None:
        """The desk's calls, poses and release_force applied to the sheet's grippers."""
        self.desk.apply(self.grippers, self.sim.state.x, None, self.params.frame_id)

    def change_solver(self, solver: str, tolerance: float | str) -> str:
        """A new solver for the next steps; returns the tolerance as the log says it."""
        self.solver, self.tolerance = solver, tolerance
        self.sim.solver = self._solver()
        return f"{float(tolerance):g}"

    def tolerance_auto_available(self) -> bool:
        """(tolerance auto is for body scenes.)"""
        return False

    def request_reset(self) -> str:
        return "the sheet restarts from its initial state"

    def reset(self) -> None:
        """The sheet and its grippers as they started (at today's release_force)."""
        self.sim = Simulator(self.scene.model, self.initial_state.copy(), self.sim.solver,
                             dt=self.sim.dt, scheme=self.sim.scheme,
                             spectral_radius=self.sim.spectral_radius, track_energy=False,
                             newton_iterations=self.sim.newton_iterations,
                             linearise_at=self.sim.linearise_at)
        if self.initial_grippers is not None:
            force = self.grippers.release_force
            self.grippers = self.initial_grippers.copy()
            self.grippers.release_force = force

    def wake(self) -> None:
        """(Nothing waits: the timer ticks.)"""

    # -- ticks ---------------------------------------------------------------------------
    def take(self, timeout_s: float) -> None:
        """(A sheet has no inputs besides its grippers'.)"""

    def tick(self, inputs: None, period_s: float | None) -> list[Frame | Clear]:
        """One step of the sheet (its grippers holding): the Frame to publish."""
        # numba's thread count is the calling thread's own (solvers.threads): the parameter
        # `threads` (or the governor's count) holds for every kernel of the step, not only
        # the mpcg solver's.
        running = use_threads(self.settings.threads if self.governor is None
                              else self.governor.threads)
        sec, nanosec = self.now()
        t0, t1 = self._span.span(sec, nanosec, period_s or self.sim.dt)
        self.desk.place_stamped(self.grippers, t0, t1, self.params.frame_id)
        stats, released = step_held(self.sim, self.grippers)
        self.steps += 1
        if released:
            self.desk.note_released(released, self.grippers.release_force)
        state, model = self.sim.state, self.scene.model
        x = state.x.copy()
        values = {"solver": str(self.solver), "tolerance": f"{float(self.tolerance):.3e}",
                  "particles": str(model.n), "mass_kg": f"{float(model.mass.sum()):.6g}",
                  # the threads the step ran on, and the share of the process's threads'
                  # time spent waiting for a core over the tick before (-1: unknown)
                  "threads": str(running),
                  "wait_share": f"{-1.0 if self.wait_share is None else self.wait_share:.3f}"}
        if self.desk.names:
            values.update(self.desk.values(self.grippers))
        return [Frame(sec, nanosec, "", model, x, state.v.copy(), bool(np.isfinite(x).all()),
                      stats, stats.total_ms, self.steps, True, values, level=DiagnosticStatus.OK,
                      spheres=self.scene.spheres,
                      gripper_wrenches={} if self.grippers is None
                      else self.grippers.wrenches(),
                      gripper_poses={} if self.grippers is None else self.grippers.frames())]

    def published(self, frame: Frame, marker_ms: float) -> None:
        """After a tick: the share of the time the process waited for a core since the last
        one (budget.contention) to the thread governor, whose count the next steps run on
        (a change logged). (A sheet's size is fixed.)"""
        self.wait_share = self.contention.share()
        if self.governor is not None:
            change = self.governor.observe(time.monotonic(), self.wait_share)
            if change is not None:
                self.logger.info(change.describe(self.governor.configured))

    def resumed(self) -> None:
        self._span.restart()

    def tick_failed(self) -> int:
        """(A sheet has no inputs to count; the next tick steps from the state the last
        complete step left.)"""
        return 0

    def not_ticked(self, inputs: None) -> None:
        """(A sheet has no inputs to count.)"""

    # -- reports ----------------------------------------------------------------------------
    def waiting_text(self) -> str:
        return "starting"

    def periodic_summary(self) -> None:
        """Log the gripper poses' summary when it changed since the last one."""
        if self.desk.changed():
            self.logger.warning(self.desk.summary())

    def log_summary(self, resets: int) -> None:
        """Log the gripper poses' summary (at shutdown)."""
        if self.desk is not None and self.desk.names:
            self.logger.info(self.desk.summary())
