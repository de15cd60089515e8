"""A live simulation session of cloth_node: the loop that drives a scene, without the ROS
wiring (ros.node declares the parameters, topics, services and timers and hands what arrives
here).

`LiveSession` owns the scene (ros.live_scene.LiveScene: a garment on a pose stream,
ros.body_scene, or a sheet, ros.sheet_scene), the simulation thread every kernel runs on
(ros.sim_thread), the requests that arrive from the executor's thread (a solver or tolerance,
a reset, rate_hz) and the parameters' run-time values (`config`). On the simulation thread it
prepares the scene (calibration, build, warm-up), then loops: requests applied, the scene's
inputs taken (the 'messages' clock waits for poses; the timer waits its period: of wall
time, or of the node's ROS clock under use_sim_time, ros.timer_clock), the scene
ticked, and every Frame it returns published through the node's outputs (ros.publishing):
the cloth's markers, the wrenches (ros.wrenches), the status on `cloth/stats`. The scene
never publishes and the session never reaches into the simulation.

Grippers (ros.gripper_desk): their poses, grasp and release calls and a new release_force go
through the scene's desk and are applied on the simulation thread before each tick.
"""

from __future__ import annotations

import gc
import threading
import traceback
from collections.abc import Callable
from concurrent.futures import Future

from cloth_mg_ros.apps.warmup import CompileWatch
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.body_scene import BodyScene
from cloth_mg_ros.ros.gripper_desk import GripperDesk
from cloth_mg_ros.ros.live_scene import Clear, Frame, LiveScene
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.ros.sheet_scene import SheetScene
from cloth_mg_ros.ros.sim_thread import SimThread
from cloth_mg_ros.ros.timer_clock import RosClock, WallClock

__all__ = ["LiveSession"]

TAKE_TIMEOUT_S = 0.1  # s: how long the thread waits for a pose before it looks at requests
# A tick that raises is logged and skipped (its poses counted as skipped, a body scene
# re-dressed on the next valid pose): one bad input or a rare solver failure must not stop a
# live node. So many failures in a row without a tick that stepped mean the scene cannot go
# on at all: the node then stops with status 1.
MAX_FAILED_TICKS = 20


class LiveSession:
    """The node's simulation (module docstring).

    settings: what the parameters fixed at start; outputs: the node's ClothOutputs; logger:
    the node's logger (info, warning, error); now: the node's clock as (sec, nanosec);
    finish: called once with the exit status when the node should stop (max_steps, a
    failure); timer_clock: what the timer ticks by (ros.timer_clock; None: wall time, a
    RosClock under use_sim_time); sim_thread: the thread to run on (default: one of its own,
    ended by `close`; one given stays its owner's: a managed node keeps one across configure
    and cleanup). Build it, `prepare` it (calibration, scene, warm-up; may raise
    ClothInputError), then `start` the tick loop; `stop` and `close` end it, `resume` starts
    it again after `stop`.
    """

    def __init__(self, settings: SessionSettings, outputs, logger,
                 now: Callable[[], tuple[int, int]], finish: Callable[[int], None],
                 timer_clock: RosClock | None = None,
                 sim_thread: SimThread | None = None) -> None:
        self.settings = settings
        self.timer_clock = timer_clock or WallClock()
        self.outputs = outputs
        self.logger = logger
        self._finish = finish
        # The parameters now: settings.values, replaced as a whole by a run-time change
        # (solver, tolerance, rate_hz: `request_solver_change`, `set_rate_hz`), on the
        # simulation thread only: the executor's thread queues them under _lock.
        self.config = settings.values
        kind = BodyScene if settings.body else SheetScene
        self.scene: LiveScene = kind(settings, logger, now, lambda: self.rate_hz)
        self.resets = 0
        # Every numba kernel runs on it (ros.sim_thread).
        self._own_thread = sim_thread is None
        self.sim_thread = SimThread() if sim_thread is None else sim_thread
        # Kernels numba compiles once the session is ready (the warm-up should leave none).
        self.compiles = CompileWatch()
        self.now = now
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._solver_change: tuple[str, object] | None = None
        self._rate_change: float | None = None
        self._reset = False
        self.ticks_failed = 0  # ticks that raised (skipped, `_tick_failed`)
        self._failed_in_row = 0  # ... since the last tick that stepped the cloth
        self._failure_kinds: set[tuple[str, str]] = set()  # logged with their traceback
        self._future: Future | None = None
        self._ident: int | None = None  # the simulation thread's, once it runs

    solver = property(lambda self: self.config.solver, doc="The solver now.")
    tolerance = property(lambda self: self.config.tolerance, doc="The tolerance now.")

    @property
    def rate_hz(self) -> float:
        """rate_hz now, Hz (one set but not yet applied to `config` counts already)."""
        pending = self._rate_change  # one read: no lock needed
        return self.config.rate_hz if pending is None else pending

    @property
    def desk(self) -> GripperDesk | None:
        """The scene's grippers' hand-over (made by `prepare`)."""
        return self.scene.desk

    def set_rate_hz(self, rate_hz: float) -> None:
        """A new rate_hz (checked) from the next tick on (applied on the simulation thread,
        which alone replaces `config`)."""
        with self._lock:
            self._rate_change = rate_hz
        self.scene.wake()

    # -- start ---------------------------------------------------------------------------
    def prepare(self) -> str:
        """Prepare the scene on the simulation thread (a sheet: built; a body scene: what
        the first pose needs: calibration, ingest, warm-up), then `ready`. Returns the
        start-up log line's description of the scene; raises ClothInputError for an unusable
        value."""
        described = self.scene.prepare(self.sim_thread, self.outputs)
        self.ready()
        return described

    def ready(self) -> None:
        """The warm-up is done: its garbage goes now, not in a tick, and what is left is kept
        out of the collector's full passes (gc.freeze: fewer pauses in the ticks); from here
        on, a kernel that numba compiles is one the warm-up missed (logged by the ticks)."""
        gc.collect()
        gc.freeze()
        self.compiles.start()

    # -- control, from the executor's thread ------------------------------------------------
    def start(self) -> None:
        """Start the tick loop on the simulation thread."""
        self._future = self.sim_thread.submit(self._main)

    def stop(self, timeout: float = 60.0) -> None:
        """Stop after the tick in progress (waits up to `timeout` s)."""
        self._stop.set()
        if self.desk is not None:
            self.desk.stop()
        self.scene.wake()
        self.timer_clock.wake()
        if self._future is not None and threading.get_ident() != self._ident:
            try:
                self._future.result(timeout)
            except TimeoutError:
                self.logger.error(f"the simulation thread did not stop within {timeout:g} s "
                                  f"(a tick still running); it is left behind: the process "
                                  f"exits without waiting for it (ros.sim_thread)")

    def resume(self) -> None:
        """Start the tick loop again after `stop` (a managed node activated again). A body
        scene re-dresses on the next valid pose (the stream starts afresh: poses buffered
        before are discarded and counted, so a bag may be played again); a sheet goes on."""
        if self._future is not None and not self._future.done():
            return  # still running: nothing to resume
        self._stop.clear()
        if self.desk is not None:
            self.desk.resume()
        if self.settings.body:
            self.scene.request_reset()
        self.scene.resumed()  # the loop is stopped: the scene is the caller's to touch
        self.start()

    def close(self) -> None:
        """Stop the tick loop, end the simulation thread (when it is the session's own) and
        the compile watch."""
        self.stop()
        if self._own_thread:
            self.sim_thread.shutdown()
        self.compiles.stop()
        self.timer_clock.close()
        # what `ready` froze, this session among it (it and its scene refer to each other),
        # back to the collector: a managed node's cleanup then configure frees the old one
        gc.unfreeze()

    def request_solver_change(self, solver: str, tolerance: object) -> None:
        """Rebuild the solver with these before the next tick."""
        with self._lock:
            self._solver_change = (solver, tolerance)
        self.scene.wake()

    def reset(self) -> str:
        """~/reset: re-dress on the next valid pose (body scenes) or restart the sheet before
        the next tick. Returns what will happen, for the response."""
        self.resets += 1
        message = self.scene.request_reset()
        with self._lock:
            self._reset = True
        self.scene.wake()
        return message

    def grasp(self, name: str, grasp: bool) -> tuple[bool, str]:
        """gripper/<name>/grasp: grasp (True) or release (False) before the next tick; waits
        for the simulation thread's answer (success, message for the response)."""
        return self.desk.call(name, grasp, self.scene.wake)

    def request_release_force(self, force: float) -> None:
        """A new release_force (N) for every gripper from the next tick on."""
        self.desk.request_release_force(force)

    def tolerance_auto_available(self) -> bool:
        """Whether tolerance auto was measured at start (it may then be chosen again)."""
        return self.scene.tolerance_auto_available()

    # -- reports ----------------------------------------------------------------------------
    def waiting_text(self) -> str:
        """The /diagnostics message before the first tick."""
        return self.scene.waiting_text()

    def periodic_summary(self) -> None:
        """Log the skipped inputs' summary when anything changed since the last one."""
        self.scene.periodic_summary()

    def log_summary(self) -> None:
        """Log the inputs' summary (called at shutdown)."""
        self.scene.log_summary(self.resets)

    # -- the tick loop ------------------------------------------------------------------------
    def _main(self) -> None:
        self._ident = threading.get_ident()
        try:
            if self.scene.clock == "timer":
                self._run_timer()
            else:
                self._run_messages()
        except Exception:  # a failure outside a tick (a request, the loop): report it, stop
            if not self._stop.is_set():
                self.logger.error(f"the simulation thread failed:\n{traceback.format_exc()}")
                self._finish(1)
        finally:
            if self.desk is not None:
                self.desk.stop()  # a grasp call waiting gets its answer

    def _run_messages(self) -> None:
        while not self._stop.is_set():
            self._apply_requests()  # outside the tick's try, as in _run_timer: not a tick
            try:
                inputs = self.scene.take(TAKE_TIMEOUT_S)
                if not self._stop.is_set():
                    self.tick(inputs)
                else:  # the stop woke the take: what it took is counted, not lost
                    self.scene.not_ticked(inputs)
            except Exception as exc:  # any failure of a tick: logged, skipped (_tick_failed)
                self._tick_failed(exc)

    def _run_timer(self) -> None:
        clock = self.timer_clock  # wall time, or the ROS clock under use_sim_time
        next_t = clock.now()
        while not self._stop.is_set():
            self._apply_requests()
            if not clock.wait_until(next_t, self._stop):
                break
            period = 1.0 / float(self.rate_hz)
            next_t = clock.next_tick(next_t, period)  # late: no burst to catch up
            try:
                self.tick(self.scene.take(0.0), period)
            except Exception as exc:  # any failure of a tick: logged, skipped (_tick_failed)
                self._tick_failed(exc)

    def _tick_failed(self, exc: Exception) -> None:
        """A tick raised: log it (with its traceback the first time this kind, the
        exception's type and where it was raised, is seen), count the tick and its poses
        (skipped, the scene's `tick_failed`: a body scene re-dresses on the next valid pose)
        and go on; stop the node after MAX_FAILED_TICKS in a row."""
        if self._stop.is_set():
            return  # stopping anyway (a wake-up may interrupt a tick's wait)
        self.ticks_failed += 1
        self._failed_in_row += 1
        skipped = self.scene.tick_failed()
        tb = traceback.extract_tb(exc.__traceback__)
        where = f"{tb[-1].filename}:{tb[-1].lineno}" if tb else "?"
        kind = (type(exc).__name__, where)
        text = (f"a tick failed ({type(exc).__name__}: {exc}); it is skipped ({skipped} "
                f"poses counted as skipped), the node goes on; {self.ticks_failed} failed "
                f"so far")
        if kind not in self._failure_kinds:
            self._failure_kinds.add(kind)
            self.logger.error(f"{text}; further failures of this kind are logged without "
                              f"the traceback:\n"
                              f"{''.join(traceback.format_exception(exc))}")
        else:
            self.logger.error(text)
        if self._failed_in_row >= MAX_FAILED_TICKS:
            self.logger.error(f"{self._failed_in_row} ticks in a row failed: the simulation "
                              f"cannot go on; the node stops")
            self._finish(1)
            self._stop.set()

    def _apply_requests(self) -> None:
        with self._lock:
            change, reset, rate = self._solver_change, self._reset, self._rate_change
            if rate is not None:  # before the pending value goes: `rate_hz` reads either
                self.config = self.config.replace(rate_hz=rate)
            self._solver_change, self._reset, self._rate_change = None, False, None
        if reset:
            sec, nanosec = self.now()
            self.outputs.clear(sec, nanosec, self.scene.frame_id)  # the old cloth goes
            self.scene.reset()
        if change is not None:
            self._change_solver(*change)
        self.scene.apply_gripper_inputs()

    def _change_solver(self, solver: str, tol: object) -> None:
        """The requested solver and tolerance, or, where they cannot be built (the parameter
        check passed them, but building failed), the ones before, logged: the ticks go on."""
        before = self.config
        self.config = self.config.replace(solver=solver,
                                          tolerance=tol if tol == AUTO else float(tol))
        try:
            tol_text = self.scene.change_solver(self.solver, self.tolerance)
        except ClothInputError as exc:
            self.config = before
            self.scene.change_solver(self.solver, self.tolerance)
            self.logger.error(f"solver {solver} refused ({exc}); it stays {self.solver}")
            return
        self.logger.info(f"solver is now {self.solver} (tol {tol_text})")

    def tick(self, inputs: object, period_s: float | None = None) -> None:
        """One tick of the scene through `inputs` (its `take`; period_s: the timer's period,
        s), and what it returned published. The loop calls it on the simulation thread; a
        test may drive it with the loop stopped."""
        self._publish(self.scene.tick(inputs, period_s))

    # -- publishing ---------------------------------------------------------------------------
    def _publish(self, items: list[Frame | Clear]) -> None:
        """Publish what a tick returned, in order (a Clear: the display drops the cloth)."""
        for item in items:
            if isinstance(item, Clear):
                self.outputs.clear(item.sec, item.nanosec, item.frame_id)
            else:
                self._publish_frame(item)

    def _publish_frame(self, f: Frame) -> None:
        """The cloth's markers (when finite), the wrenches and the status of one Frame; then
        max_steps and a non-finite cloth are checked and the scene follows its budget."""
        out = self.outputs
        marker_ms = 0.0
        if f.finite:
            marker_ms = out.cloth(f.model, f.positions, f.sec, f.nanosec, f.frame_id,
                                  f.velocities, capsules=f.capsules, spheres=f.spheres,
                                  arrows=f.arrows)
        if out.wrenches is not None:
            out.wrenches.publish(f.gripper_wrenches, f.sec, f.nanosec, out.frame(f.frame_id),
                                 f.body_forces, f.body_torques, f.gripper_poses,
                                 f.segment_poses)
        news = self.compiles.news()
        if news is not None:  # kernels the warm-up missed
            self.logger.warning(news)
        values = {"step": str(f.step), "marker_ms": f"{marker_ms:.3f}", **f.values,
                  "resets": str(self.resets), "kernels_compiled": str(self.compiles.count),
                  "ticks_failed": str(self.ticks_failed)}
        out.status(f.stats, f.step_ms, f.finite, f.sec, f.nanosec, values, f.level, f.note,
                   f.frame_id)
        if f.stepped:
            self._after_tick(f)
            self.scene.published(f, marker_ms)

    def _after_tick(self, f: Frame) -> None:
        self._failed_in_row = 0  # the scene goes on
        max_steps = self.settings.values.max_steps
        if not f.finite:
            self.logger.error(
                f"cloth positions became non-finite at step {f.step}; try a smaller step "
                f"or tolerance")
            self._finish(1)
            self._stop.set()
        elif max_steps and f.step >= max_steps:
            self.logger.info(f"max_steps {max_steps} reached")
            self._finish(0)
            self._stop.set()
