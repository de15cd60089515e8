"""A live simulation session of cloth_node: everything the node simulates, without the ROS
wiring (ros.node declares the parameters, topics, services and timers and hands messages here).

`LiveSession` owns the garment simulation (or a sheet scene's simulator), its level of detail,
the simulated stamp, the re-dress and stream state, the pose ingest and the counters, and runs
them on the simulation thread (ros.sim_thread): the cost model's calibration and the warm-up at
start, then every tick, which it publishes through the node's outputs (ros.publishing).

Body scenes, tick mode 'message': each tick takes every key pose buffered since the last one
(`PoseIngest.take`) and advances the cloth to the newest in one go, the body following every
key in between (`GarmentSim.advance`). While the node keeps up that is one pose per tick;
when a tick runs long, the poses that arrived meanwhile are coalesced into the next one, so
the latency stays about one tick and nothing queues. A teleport among the keys ends the run
before it: the garment is re-anchored there and the rest follows. Which poses are coalesced
depends on timing, so a live run is not reproducible; fed one pose at a time (each marker
awaited before the next pose) the node computes exactly what the headless runner does.

Body scenes, tick mode 'timer': a tick every 1/rate_hz s of wall time advances 1/rate_hz s
of simulated time, the body moving through the keys that arrived since the last tick (or
standing still). Sheet scenes: a step of `dt` every 1/rate_hz s, its grippers holding what
they hold (sim.grippers.step_held: a gripper's new pose carries its particles in that step).

Grippers (ros.gripper_desk): their poses, grasp and release calls and a new release_force are
applied on the simulation thread before each tick; each tick publishes their wrenches, and in
body scenes the cloth's force on each colliding segment (ros.wrenches) and its arrows.
"""

from __future__ import annotations

import gc
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Future

import numpy as np

from cloth_mg_ros.apps.warmup import CompileWatch
from cloth_mg_ros.budget.contention import ContentionMeter
from cloth_mg_ros.budget.cost_model import (
    choose_particles,
    stream_rate,
)
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.design import MIN_PARTICLES
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.ros.arrivals import ArrivalRate
from cloth_mg_ros.ros.gripper_desk import GripperDesk, apply_gripper_inputs
from cloth_mg_ros.ros.ingest import NEW_STREAM_KEYS, FrameLog, KeyPose, PoseIngest
from cloth_mg_ros.ros.session_detail import detail_controller, follow_budget
from cloth_mg_ros.ros.session_start import SessionSettings, prepare_body, prepare_sheet
from cloth_mg_ros.ros.sim_thread import SimThread
from cloth_mg_ros.ros.tick_status import (
    body_values,
    sheet_values,
    status_level,
    status_notes,
)
from cloth_mg_ros.ros.wrenches import contact_arrows
from cloth_mg_ros.sim.detail import DetailController
from cloth_mg_ros.sim.garment import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.grippers import GripperSet, step_held
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.sim.solve_tolerance import describe
from cloth_mg_ros.solvers import make_solver

__all__ = ["LiveSession"]

TAKE_TIMEOUT_S = 0.1  # s: how long the thread waits for a pose before it looks at requests
AUTO_RATE_KEYS = 5  # particles auto in message mode: poses whose stamps give the stream's rate


class LiveSession:
    """The node's simulation (module docstring).

    settings: what the parameters fixed at start; outputs: the node's ClothOutputs; logger:
    the node's logger (info, warning, error); now: the node's clock as (sec, nanosec);
    finish: called once with the exit status when the node should stop (max_steps, a
    failure). Build it, `prepare` it (calibration, scene, warm-up; may raise
    ClothInputError), then `start` the tick loop; `stop` and `close` end it.
    """

    def __init__(self, settings: SessionSettings, outputs, logger,
                 now: Callable[[], tuple[int, int]], finish: Callable[[int], None]) -> None:
        self.settings = settings
        self.outputs = outputs
        self.logger = logger
        self.now = now
        self._finish = finish
        # The parameters now: settings.values, replaced as a whole by a run-time change
        # (solver, tolerance, rate_hz: `request_solver_change`, `set_rate_hz`).
        self.config = settings.values
        self.material = settings.material
        self.steps = 0  # simulation ticks done (sheet steps, or ticks through key poses)
        self.resets = 0
        # Body scenes:
        self.avatar: Avatar | None = None
        self.options: BodySimOptions | None = None
        self.garment_sim: GarmentSim | None = None  # once dressed
        self.cost_model = None  # particles auto or lod: budget.cost_model.CostModel
        self.auto_choice = None  # particles auto: the cost_model.AutoChoice made
        self.detail: DetailController | None = None  # lod: the garment's level of detail
        self.contention = ContentionMeter()  # the cores' contention between ticks
        self.governor = None  # the steps' running threads (made by the first tick)
        self.step_contention = None  # ... its contention between a tick's steps
        self.wait_share = None  # the last tick's (budget.contention), for the status
        self.particles_auto = False
        self.ingest: PoseIngest | None = None
        self.frames: FrameLog | None = None
        self.redress = False
        self.sim_stamp = 0.0  # timer mode: simulated time, s
        # Sheet scenes:
        self.scene = None
        self.sim: Simulator | None = None
        self.initial_state = None
        self.sheet_grippers: GripperSet | None = None  # the sheet's grippers (ros.gripper_desk)
        self.initial_grippers: GripperSet | None = None  # ... as they start (for a reset)
        # The grippers' poses and calls, from the executor's thread (prepare makes it).
        self.desk: GripperDesk | None = None
        self.sim_thread = SimThread()  # every numba kernel runs on it (ros.sim_thread)
        # Kernels numba compiles once the session is ready (the warm-up should leave none).
        self.compiles = CompileWatch()
        self._failures_reported = 0
        self._frame = ""  # the newest key pose's frame (timer ticks publish in it)
        self._dressed_generation = -1  # the pose stream the garment was dressed on
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._solver_change: tuple[str, object] | None = None
        self._reset = False
        self._future: Future | None = None
        self._ident: int | None = None  # the simulation thread's, once it runs
        self._held: list[KeyPose] = []  # particles auto: the first keys, until the rate is known
        self.arrivals = ArrivalRate()  # the poses the ticks took lately (message mode)

    @property
    def body(self) -> bool:
        return self.settings.body

    solver = property(lambda self: self.config.solver, doc="The solver now.")
    tolerance = property(lambda self: self.config.tolerance, doc="The tolerance now.")
    rate_hz = property(lambda self: self.config.rate_hz, doc="rate_hz now, Hz.")

    def set_rate_hz(self, rate_hz: float) -> None:
        """A new rate_hz (checked) from the next tick on."""
        self.config = self.config.replace(rate_hz=rate_hz)

    # -- start ---------------------------------------------------------------------------
    def prepare(self) -> str:
        """Build the scene (sheets) or everything the first pose needs (body scenes:
        calibration, ingest, warm-up), on the simulation thread. Returns the start-up log
        line's description of the scene; raises ClothInputError for an unusable value."""
        return prepare_body(self) if self.body else prepare_sheet(self)

    def choose_particles(self, rate_hz: float) -> None:
        """particles auto: the garment's size for a pose stream of rate_hz (logged)."""
        s = self.settings.values
        c = choose_particles(self.cost_model, rate_hz, s.tick_budget, s.max_particles,
                             MIN_PARTICLES[self.options.garment])
        self.auto_choice = c
        self.options.particles = c.particles
        self.logger.info(
            f"particles auto: {c.particles} particles ({c.capped_by}) for a {rate_hz:.1f} Hz "
            f"pose stream: budget {c.budget_ms:.1f} ms ({s.tick_budget:g} of the "
            f"period), predicted tick {c.predicted_ms:.1f} ms")

    def ready(self) -> None:
        """The warm-up is done: its garbage goes now, not in a tick, and what is left is kept
        out of the collector's full passes (gc.freeze: fewer pauses in the ticks); from here
        on, a kernel that numba compiles is one the warm-up missed (logged by the ticks)."""
        gc.collect()
        gc.freeze()
        self.compiles.start()

    def make_sheet_solver(self):
        """A solver for the sheet (make_solver with its hierarchy and bending Hessians) from
        the current solver and tolerance (a garment's: GarmentSim.set_solver)."""
        return make_solver(self.solver, tol=float(self.tolerance),
                           hierarchy=self.scene.hierarchy, bending=self.scene.model.bending,
                           levels=self.settings.levels, threads=self.settings.threads)

    def budget_ms(self, period_s: float) -> float:
        """The tick budget for a pose period of period_s, ms."""
        return self.settings.values.tick_budget * period_s * 1e3

    # -- control, from the executor's thread ------------------------------------------------
    def start(self) -> None:
        """Start the tick loop on the simulation thread."""
        self._future = self.sim_thread.submit(self._main)

    def stop(self, timeout: float = 60.0) -> None:
        """Stop after the tick in progress (waits up to `timeout` s)."""
        self._stop.set()
        if self.desk is not None:
            self.desk.stop()
        if self.ingest is not None:
            self.ingest.wake()
        if self._future is not None and threading.get_ident() != self._ident:
            try:
                self._future.result(timeout)
            except TimeoutError:
                self.logger.warning(f"the simulation thread did not stop within "
                                    f"{timeout:g} s")

    def close(self) -> None:
        """Stop the tick loop, end the simulation thread and the compile watch."""
        self.stop()
        self.sim_thread.shutdown()
        self.compiles.stop()

    def request_solver_change(self, solver: str, tolerance: object) -> None:
        """Rebuild the solver with these before the next tick."""
        with self._lock:
            self._solver_change = (solver, tolerance)
        self._wake()

    def reset(self) -> str:
        """~/reset: re-dress on the next valid pose (body scenes) or restart the sheet before
        the next tick. Returns what will happen, for the response."""
        self.resets += 1
        if self.body:
            self.ingest.reset()  # a new stream: its stamps may start over
            message = "the garment is re-dressed on the next valid body pose"
        else:
            message = "the sheet restarts from its initial state"
        with self._lock:
            self._reset = True
        self._wake()
        return message

    def grasp(self, name: str, grasp: bool) -> tuple[bool, str]:
        """gripper/<name>/grasp: grasp (True) or release (False) before the next tick; waits
        for the simulation thread's answer (success, message for the response)."""
        return self.desk.call(name, grasp, self._wake)

    def request_release_force(self, force: float) -> None:
        """A new release_force (N) for every gripper from the next tick on."""
        self.desk.request_release_force(force)

    def tolerance_auto_available(self) -> bool:
        """Whether tolerance auto was measured at start (it may then be chosen again)."""
        return self.body and self.options is not None and bool(self.options.tolerances)

    def _wake(self) -> None:
        if self.ingest is not None:
            self.ingest.wake()

    # -- reports ----------------------------------------------------------------------------
    def waiting_text(self) -> str:
        """The /diagnostics message before the first tick."""
        return "waiting for body poses" if self.body and self.garment_sim is None else "starting"

    def failures_since_status(self) -> int:
        """Simulation steps that failed since the last call (body scenes)."""
        total = self.garment_sim.failures if self.garment_sim is not None else 0
        new, self._failures_reported = total - self._failures_reported, total
        return max(new, 0)

    def on_stream_restart(self, previous: float, stamp: float) -> None:
        """A new time line (a looped bag, a restarted publisher): a new stream."""
        self.logger.info(
            f"body pose stamps went back from {previous:.3f} s to {stamp:.3f} s and "
            f"{NEW_STREAM_KEYS} poses went on from there: a new stream (a looped bag, a "
            f"restarted publisher); the garment is re-dressed on it")

    def periodic_summary(self) -> None:
        """Log the skipped frames' (and gripper poses') summary when anything changed since
        the last one."""
        if self.frames is not None and self.frames.changed():
            c = self.ingest.counts()
            self.logger.warning(self.frames.summary(c.received, c.used))
        if self.desk is not None and self.desk.changed():
            self.logger.warning(self.desk.summary())

    def log_summary(self) -> None:
        """Log the pose-stream summary (body scenes; called at shutdown)."""
        if self.body and self.ingest is not None:
            self.ingest.close()
            c = self.ingest.counts()
            self.logger.info(
                f"{self.frames.summary(c.received, c.used)}; {self.steps} ticks, "
                f"{c.coalesced} poses coalesced, {c.pending} pending at shutdown, "
                f"{c.discarded} discarded by resets, {c.dropped} dropped; "
                f"{self.resets} resets, {c.restarts} new streams")
        if self.desk is not None and self.desk.names:
            self.logger.info(self.desk.summary())

    # -- the tick loop ------------------------------------------------------------------------
    def _main(self) -> None:
        self._ident = threading.get_ident()
        try:
            if not self.body:
                self._run_timer(self._tick_sheet)
            elif self.settings.values.tick_mode == "timer":
                self._run_timer(self._tick_body_timer)
            else:
                self._run_messages()
        except Exception:  # noqa: BLE001 - the node must report it and stop, not hang
            if not self._stop.is_set():
                self.logger.error(f"the simulation thread failed:\n{traceback.format_exc()}")
                self._finish(1)
        finally:
            if self.desk is not None:
                self.desk.stop()  # a grasp call waiting gets its answer

    def _apply_requests(self) -> None:
        with self._lock:
            change, reset = self._solver_change, self._reset
            self._solver_change, self._reset = None, False
        if reset:
            sec, nanosec = self.now()
            self.outputs.clear(sec, nanosec, self._frame)  # the old cloth leaves the display
            if not self.body:  # (a body scene re-dresses on its next stream's first pose)
                self.sim = Simulator(self.scene.model, self.initial_state.copy(),
                                     self.sim.solver, dt=self.sim.dt, scheme=self.sim.scheme,
                                     spectral_radius=self.sim.spectral_radius)
                if self.initial_grippers is not None:  # as at start, at today's release_force
                    force = self.sheet_grippers.release_force
                    self.sheet_grippers = self.initial_grippers.copy()
                    self.sheet_grippers.release_force = force
        if change is not None:
            solver, tol = change
            self.config = self.config.replace(solver=solver,
                                              tolerance=tol if tol == AUTO else float(tol))
            if self.body:
                self.options.solver, self.options.tolerance = self.solver, self.tolerance
                if self.garment_sim is not None:  # every level of detail, each its own
                    self.garment_sim.set_solver(self.options.solver, self.options.tolerance)
                tol_text = describe(self.options.tolerance, self.options.tolerances)
            else:
                self.sim.solver = self.make_sheet_solver()
                tol_text = f"{float(self.tolerance):g}"
            self.logger.info(f"solver is now {self.solver} (tol {tol_text})")
        apply_gripper_inputs(self)

    def _run_messages(self) -> None:
        while not self._stop.is_set():
            self._apply_requests()
            keys = self.ingest.take(TAKE_TIMEOUT_S)
            self.arrivals.note(len(keys))
            for run in self._live_streams(keys):
                if self._stop.is_set():
                    break
                self._apply_requests()
                self._new_stream(run[0])
                self._tick_keys(run)

    def _live_streams(self, keys: list[KeyPose]) -> list[list[KeyPose]]:
        """`keys` split into runs of one stream each, oldest first; keys of a stream that
        ~/reset discarded are counted as discarded and left out."""
        live = self.ingest.live_from
        stale = sum(k.generation < live for k in keys)
        if stale:
            self.ingest.discard(stale)
        runs: list[list[KeyPose]] = []
        for key in keys:  # a handful of keys per tick
            if key.generation < live:
                continue
            if runs and runs[-1][-1].generation == key.generation:
                runs[-1].append(key)
            else:
                runs.append([key])
        return runs

    def _new_stream(self, key: KeyPose) -> None:
        """A key of a newer stream than the garment's (after ~/reset, or stamps that jumped
        back: a looped bag): clear the display and re-dress on it."""
        if self.garment_sim is not None and key.generation != self._dressed_generation:
            self.outputs.clear(key.sec, key.nanosec, key.frame_id or self._frame)
            self.redress = True

    def _run_timer(self, tick: Callable[[float], None]) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            self._apply_requests()
            delay = next_t - time.monotonic()
            if delay > 0.0 and self._stop.wait(delay):
                break
            period = 1.0 / float(self.rate_hz)
            next_t = max(next_t + period, time.monotonic())  # late: no burst to catch up
            tick(period)

    def pose_period(self) -> float:
        """The wall-clock period of the pose stream lately, s (what a tick must keep up
        with): the timer's period in timer mode; in message mode measured over the last
        ros.arrivals.ARRIVAL_WINDOW_S, or the stamps' rate that particles auto used until
        then."""
        if self.settings.values.tick_mode == "timer":
            return 1.0 / float(self.rate_hz)
        measured = self.arrivals.period()
        if measured is not None:
            return measured
        if self.auto_choice is not None:
            return self.auto_choice.period_s
        return 1.0 / float(self.rate_hz)

    # -- body scenes ------------------------------------------------------------------------
    def _dress(self, keys: list[KeyPose]) -> list[KeyPose]:
        """Dress the garment on the first key it fits; returns the keys after it."""
        for k, key in enumerate(keys):
            t0 = time.perf_counter()
            try:
                garment_sim = GarmentSim.dress(self.avatar, key.stamp, key.poses,
                                               self.material, self.options)
            except ClothInputError as exc:
                if not self.frames.counts["dress_failed"]:
                    self.logger.error(f"cannot dress the garment: {exc}")
                self.frames.note("dress_failed", key.stamp)
                self.ingest.discard(1)
                continue
            self.garment_sim, self.redress = garment_sim, False
            self.detail = (detail_controller(self, garment_sim) if self.settings.values.lod
                           else None)
            self.sim_stamp = key.stamp
            self._dressed_generation = key.generation
            dress_ms = 1e3 * (time.perf_counter() - t0)
            self.ingest.used(1)
            self.logger.info(
                f"dressed a {self.options.garment} of {garment_sim.sim.model.n} particles "
                f"({len(garment_sim.garment.hierarchy.levels)} levels) on the body pose at "
                f"stamp {key.stamp:.3f} s in {dress_ms:.0f} ms")
            self._publish_body(key, None, dress_ms, "dressed")
            return keys[k + 1:]
        return []

    def _tick_keys(self, keys: list[KeyPose]) -> None:
        """Message mode: advance through `keys` (dressing first if needed), then publish."""
        if self.garment_sim is None and self.particles_auto and self.auto_choice is None:
            # The garment's size waits for the stream's rate: its first stamps give it.
            self._held += keys
            if len(self._held) < AUTO_RATE_KEYS:
                return
            keys, self._held = self._held, []
            self.choose_particles(stream_rate([k.stamp for k in keys]))
        if self.garment_sim is None or self.redress:
            keys = self._dress(keys)
        if not keys:
            return
        t0 = time.perf_counter()
        run: list[KeyPose] = []
        stats, events = None, []
        for key in keys:
            if key.teleport:
                stats = self._advance(run) or stats
                run = []
                self.garment_sim.reanchor(key.stamp, key.poses)
                self.frames.note("teleport", key.stamp)
                self.ingest.used(1)
                events.append("re-anchored after a teleport")
            else:
                run.append(key)
        stats = self._advance(run) or stats
        self._publish_body(keys[-1], stats, 1e3 * (time.perf_counter() - t0),
                           "; ".join(events))

    def _advance(self, run: list[KeyPose]):
        """One GarmentSim.advance through `run` (none: None); counts the keys."""
        if not run:
            return None
        stats = self.garment_sim.advance([(k.stamp, k.poses) for k in run])
        self.steps += 1
        self.ingest.used(len(run), len(run) - 1)
        return stats

    def _tick_body_timer(self, period: float) -> None:
        """Timer mode: advance `period` s of simulated time through the keys that arrived
        (spread evenly over the period), or with the body standing still."""
        runs = self._live_streams(self.ingest.take())
        if len(runs) > 1:  # the clock is the node's own: only the newest stream is shown
            self.ingest.discard(sum(len(r) for r in runs[:-1]))
        keys = runs[-1] if runs else []
        if keys:
            self._frame = keys[-1].frame_id or self._frame
            self._new_stream(keys[0])
        if self.garment_sim is None or self.redress:
            keys = self._dress(keys)
            if self.garment_sim is None:
                return
        t0 = time.perf_counter()
        start = self.sim_stamp
        path, events = self._timer_path(keys, start, period)
        if keys:
            self.ingest.used(len(keys), max(len(keys) - 1, 0))
        self.sim_stamp = start + period
        stats = None
        if path or not keys:
            if not keys:  # no pose arrived: the body stands still for the period
                path.append((start + period, self.garment_sim.poses))
            stats = self.garment_sim.advance(path)
            self.steps += 1
        sec, nanosec = self.now()
        stamped = KeyPose(sec, nanosec, sec + 1e-9 * nanosec, "", self.garment_sim.poses)
        self._publish_body(stamped, stats, 1e3 * (time.perf_counter() - t0),
                           "; ".join(events))

    def _timer_path(self, keys: list[KeyPose], start: float, period: float
                    ) -> tuple[list, list[str]]:
        """The keys spread evenly over the period from `start`: the (stamp, poses) path after
        the last teleport (those before it advanced, then re-anchored), and the events."""
        path, events = [], []
        for i, key in enumerate(keys):
            stamp = start + period * (i + 1) / len(keys)
            if key.teleport:
                if path:
                    self.garment_sim.advance(path)
                    path = []
                self.garment_sim.reanchor(stamp, key.poses)
                self.frames.note("teleport", key.stamp)
                events.append("re-anchored after a teleport")
            else:
                path.append((stamp, key.poses))
        return path, events

    def _publish_body(self, key: KeyPose, tick, step_ms: float, event: str) -> None:
        """Markers and diagnostics of the garment now, stamped with key's stamp; tick: the
        TickStats of the tick, or None (dressing)."""
        garment_sim = self.garment_sim
        x = garment_sim.positions
        finite = bool(np.isfinite(x).all())
        marker_ms = 0.0
        if key.frame_id:
            self._frame = key.frame_id
        capsules = garment_sim.capsules()
        forces = tick.body_forces if tick is not None else {}
        if finite:
            marker_ms = self.outputs.cloth(
                garment_sim.sim.model, x, key.sec, key.nanosec, self._frame,
                garment_sim.sim.state.v, capsules=capsules,
                arrows=contact_arrows(forces, self.avatar.names, capsules))
        self._publish_wrenches(garment_sim.grippers, key.sec, key.nanosec, forces,
                               tick.body_torques if tick is not None else {})
        counts = self.ingest.counts()
        # The lag: how far the newest pose received is ahead of the simulated time (message
        # mode; in timer mode the simulated clock is the node's own).
        lag_ms = 0.0
        if tick is not None and self.settings.values.tick_mode == "message":
            lag_ms = 1e3 * (counts.newest_stamp - garment_sim.stamp)
        if tick is not None and tick.released:
            self.desk.note_released(tick.released, garment_sim.grippers.release_force)
        values = body_values(self, tick, key.stamp, marker_ms, lag_ms, counts)
        values.update(self.desk.values(garment_sim.grippers) if self.desk.names else {})
        self._log_compiles()
        failed = self.failures_since_status()
        notes, skipped_now = status_notes(event, self.frames.take_since_status(), failed,
                                          garment_sim.rung, len(x),
                                          garment_sim.rung_particles(0))
        level = status_level(failed, skipped_now, event, garment_sim.rung)
        self.outputs.status(tick, step_ms, finite, key.sec, key.nanosec, values, level,
                            "; ".join(notes), self._frame)
        if tick is not None:
            self._after_tick(finite)
            if finite:
                follow_budget(self, step_ms, marker_ms, max(lag_ms, 0.0), tick.substeps)

    def _publish_wrenches(self, grippers: GripperSet | None, sec: int, nanosec: int,
                          forces: dict | None = None, torques: dict | None = None) -> None:
        """The tick's wrenches (ros.wrenches), stamped (sec, nanosec) in the tick's frame."""
        if self.outputs.wrenches is not None:
            self.outputs.wrenches.publish(grippers, sec, nanosec,
                                          self.outputs.frame(self._frame), forces, torques)

    def _log_compiles(self) -> None:
        """Warn about kernels numba compiled since the last tick (the warm-up missed them)."""
        news = self.compiles.news()
        if news is not None:
            self.logger.warning(news)

    # -- sheet scenes ----------------------------------------------------------------------
    def _tick_sheet(self, period: float) -> None:
        """One simulation step of the sheet (its grippers holding), then the markers, the
        wrenches and the diagnostics."""
        stats, released = step_held(self.sim, self.sheet_grippers)
        self.steps += 1
        sec, nanosec = self.now()
        state = self.sim.state
        finite = bool(np.isfinite(state.x).all())
        marker_ms = self.outputs.cloth(self.scene.model, state.x, sec, nanosec, v=state.v,
                                       spheres=self.scene.spheres) if finite else 0.0
        self._publish_wrenches(self.sheet_grippers, sec, nanosec)
        if released:
            self.desk.note_released(released, self.sheet_grippers.release_force)
        values = sheet_values(self, marker_ms)
        self.outputs.status(stats, stats.total_ms, finite, sec, nanosec, values)
        self._after_tick(finite)

    def _after_tick(self, finite: bool) -> None:
        max_steps = self.settings.values.max_steps
        if not finite:
            self.logger.error(
                f"cloth positions became non-finite at step {self.steps}; try a smaller step "
                f"or tolerance")
            self._finish(1)
            self._stop.set()
        elif max_steps and self.steps >= max_steps:
            self.logger.info(f"max_steps {max_steps} reached")
            self._finish(0)
            self._stop.set()
