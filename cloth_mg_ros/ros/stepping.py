"""cloth_node's simulation thread: it takes the key poses that arrived, steps the garment (or
the sheet) through them, and publishes.

Why a thread of its own (measured on this kind of machine with rclpy 7.1.6 and Fast DDS, two
processes, a 30 Hz publisher, an 80 ms step): with the step in a callback of the executor
that also serves the subscription, poses waited 2.7-3.7 s in a FIFO backlog; a
MultiThreadedExecutor starved the step; a thread of its own, with numba kernels that release
the GIL, kept the subscription's delay at 0.4 / 0.6 ms (p50 / p95). So the executor keeps
ingestion, services and parameters, and this thread does all the simulating and publishing.

Body scenes, tick mode 'message': each tick takes every key pose buffered since the last one
(`PoseIngest.take`) and advances the cloth to the newest in one go, the body following every
key in between (`GarmentSim.advance`). While the node keeps up that is one pose per tick;
when a tick runs long, the poses that arrived meanwhile are coalesced into the next one, so
the latency stays about one tick and nothing queues. A teleport among the keys ends the run
before it: the garment is re-anchored there and the rest follows. Which poses are coalesced
depends on timing, so a live run is not reproducible; fed one pose at a time (each marker
awaited before the next pose) the node computes exactly what the headless runner does.

One OS thread runs every numba kernel of the node (`SimThread`): the calibration and the
warm-up at start as well as every tick. numba's parallel kernels (its OpenMP layer) keep a
team of helper threads per OS thread that calls them; a second calling thread doubles the
teams, oversubscribes the cores, and OpenMP stops spinning at its barriers and sleeps in
the kernel instead: every parallel region then pays a sleep and a wake. Measured on 2 cores
beside the pose publisher, with 2 solver threads (`bench node --particles 2400 --lod false
--threads 2`): ticks 63.7 ms p50 when the warm-up ran on the main thread, 22.3 ms with it
on the thread of the ticks (and 28.7 ms with one solver thread).

Body scenes, tick mode 'timer': a tick every 1/rate_hz s of wall time advances 1/rate_hz s
of simulated time, the body moving through the keys that arrived since the last tick (or
standing still). Sheet scenes: a step of `dt` every 1/rate_hz s.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from cloth_mg_ros.budget.cost_model import stream_rate
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.ingest import KeyPose
from cloth_mg_ros.ros.publishing import TickFigures
from cloth_mg_ros.sim.detail import MIN_LOD_PARTICLES, LevelController
from cloth_mg_ros.sim.integrator import Simulator
from cloth_mg_ros.sim.tolerance import describe

__all__ = ["Stepper"]

TAKE_TIMEOUT_S = 0.1  # s: how long the thread waits for a pose before it looks at requests
AUTO_RATE_KEYS = 5  # particles auto in message mode: poses whose stamps give the stream's rate
ARRIVAL_WINDOW_S = 2.0  # s: the pose period the budget follows is measured over this long


class SimThread:
    """The node's simulation thread (see the module docstring): `call` runs a function on
    it and returns its result (or raises its exception) to the caller; `submit` starts one
    without waiting (the stepping loop)."""

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cloth_sim")

    def call(self, fn, *args, **kwargs):
        return self._pool.submit(fn, *args, **kwargs).result()

    def submit(self, fn) -> Future:
        return self._pool.submit(fn)

    def shutdown(self) -> None:
        """No more work: the thread ends once the function it runs returns."""
        self._pool.shutdown(wait=False)


class Stepper:
    """The simulation thread of a ClothNode (see the module docstring).

    node: the ClothNode, whose scene (`gs` or `sim`), options, ingest, outputs and counters
    this thread alone steps and updates once started.
    """

    def __init__(self, node) -> None:
        self.node = node
        self._frame = ""  # the newest key pose's frame (timer ticks publish in it)
        self._dressed_generation = -1  # the pose stream the garment was dressed on
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._solver_change = False
        self._reset = False
        self._future: Future | None = None
        self._ident: int | None = None  # the simulation thread's, once it runs
        self._held: list[KeyPose] = []  # particles auto: the first keys, until the rate is known
        self._arrivals: deque = deque()  # (monotonic s, keys taken) of the last few seconds
        self._compiled_seen = 0  # kernels compiled after the warm-up, already logged

    # -- control, from the executor's thread ----------------------------------------------
    def start(self) -> None:
        self._future = self.node.sim_thread.submit(self._main)

    def stop(self, timeout: float = 60.0) -> None:
        """Stop after the tick in progress (waits up to `timeout` s)."""
        self._stop.set()
        if self.node.ingest is not None:
            self.node.ingest.wake()
        if self._future is not None and threading.get_ident() != self._ident:
            try:
                self._future.result(timeout)
            except TimeoutError:
                self.node.get_logger().warning(f"the simulation thread did not stop within "
                                               f"{timeout:g} s")

    def request_solver_change(self) -> None:
        """Rebuild the solver from the parameters before the next tick."""
        with self._lock:
            self._solver_change = True
        self._wake()

    def request_reset(self) -> None:
        """Re-dress on the next pose (body scenes) or restart the sheet before the next tick."""
        with self._lock:
            self._reset = True
        self._wake()

    def _wake(self) -> None:
        if self.node.ingest is not None:
            self.node.ingest.wake()

    # -- the thread -------------------------------------------------------------------------
    def _main(self) -> None:
        node = self.node
        self._ident = threading.get_ident()
        try:
            if not node.body:
                self._run_timer(self._tick_sheet)
            elif node.tick_mode == "timer":
                self._run_timer(self._tick_body_timer)
            else:
                self._run_messages()
        except Exception:  # noqa: BLE001 - the node must report it and stop, not hang
            if not self._stop.is_set():
                node.get_logger().error(f"the simulation thread failed:\n"
                                        f"{traceback.format_exc()}")
                node.finish(1)

    def _apply_requests(self) -> None:
        with self._lock:
            change, reset = self._solver_change, self._reset
            self._solver_change = self._reset = False
        node = self.node
        if reset:
            sec, nanosec = node.get_clock().now().seconds_nanoseconds()
            node.outputs.clear(sec, nanosec, self._frame)  # the old cloth leaves the display
            if not node.body:  # (a body scene re-dresses on its next stream's first pose)
                node.sim = Simulator(node.scene.model, node.initial_state.copy(),
                                     node.sim.solver, dt=node.sim.dt, scheme=node.sim.scheme)
        if change:
            if node.body:
                node.options.solver = node.param("solver")
                tol = node.param("tolerance")
                node.options.tolerance = tol if tol == AUTO else float(tol)
                if node.gs is not None:  # every level of detail, each on its own hierarchy
                    node.gs.set_solver(node.options.solver, node.options.tolerance)
                tol_text = describe(node.options.tolerance, node.options.tolerances)
            else:
                node.sim.solver = node.make_solver()
                tol_text = f"{float(node.param('tolerance')):g}"
            node.get_logger().info(f"solver is now {node.param('solver')} (tol {tol_text})")

    def _run_messages(self) -> None:
        ingest = self.node.ingest
        while not self._stop.is_set():
            self._apply_requests()
            keys = ingest.take(TAKE_TIMEOUT_S)
            self._note_arrivals(len(keys))
            for run in self._live_streams(keys):
                if self._stop.is_set():
                    break
                self._apply_requests()
                self._new_stream(run[0])
                self._tick_keys(run)

    def _live_streams(self, keys: list[KeyPose]) -> list[list[KeyPose]]:
        """`keys` split into runs of one stream each, oldest first; keys of a stream that
        ~/reset discarded are counted as discarded and left out."""
        ingest = self.node.ingest
        live = ingest.live_from
        stale = sum(k.generation < live for k in keys)
        if stale:
            ingest.discard(stale)
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
        node = self.node
        if node.gs is not None and key.generation != self._dressed_generation:
            node.outputs.clear(key.sec, key.nanosec, key.frame_id or self._frame)
            node.redress = True

    def _run_timer(self, tick) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            self._apply_requests()
            delay = next_t - time.monotonic()
            if delay > 0.0 and self._stop.wait(delay):
                break
            period = 1.0 / float(self.node.param("rate_hz"))
            next_t = max(next_t + period, time.monotonic())  # late: no burst to catch up
            tick(period)

    # -- body scenes ------------------------------------------------------------------------
    def _dress(self, keys: list[KeyPose]) -> list[KeyPose]:
        """Dress the garment on the first key it fits; returns the keys after it."""
        from cloth_mg_ros.sim.garment import GarmentSim

        node = self.node
        for k, key in enumerate(keys):
            t0 = time.perf_counter()
            try:
                gs = GarmentSim.dress(node.avatar, key.stamp, key.poses, node.material,
                                      node.options)
            except ClothInputError as exc:
                if not node.frames.counts["dress_failed"]:
                    node.get_logger().error(f"cannot dress the garment: {exc}")
                node.frames.note("dress_failed", key.stamp)
                node.ingest.discard(1)
                continue
            node.gs, node.redress = gs, False
            node.lod = None
            if node.param("lod"):
                gs.prepare_levels()
                node.lod = LevelController(gs.lod_levels())
                if len(node.lod.levels) == 1:
                    node.get_logger().info(
                        f"lod: a {node.options.garment} of {gs.sim.model.n} particles has no "
                        f"coarser level of detail (each needs at least {MIN_LOD_PARTICLES} "
                        f"particles and a multigrid level below it): it stays at this size")
            node.sim_stamp = key.stamp
            self._dressed_generation = key.generation
            dress_ms = 1e3 * (time.perf_counter() - t0)
            node.ingest.used(1)
            node.get_logger().info(
                f"dressed a {node.options.garment} of {gs.sim.model.n} particles "
                f"({len(gs.garment.hierarchy.levels)} levels) on the body pose at stamp "
                f"{key.stamp:.3f} s in {dress_ms:.0f} ms")
            self._publish_body(key, None, dress_ms, "dressed")
            return keys[k + 1:]
        return []

    def _note_arrivals(self, count: int) -> None:
        now = time.monotonic()
        if count:
            self._arrivals.append((now, count))
        while self._arrivals and self._arrivals[0][0] < now - ARRIVAL_WINDOW_S:
            self._arrivals.popleft()

    def pose_period(self) -> float:
        """The wall-clock period of the pose stream lately, s (what a tick must keep up
        with): the timer's period in timer mode; in message mode measured over the last
        ARRIVAL_WINDOW_S, or the stamps' rate that particles auto used until then."""
        node = self.node
        if node.tick_mode == "timer":
            return 1.0 / float(node.param("rate_hz"))
        if len(self._arrivals) >= 3:
            span = self._arrivals[-1][0] - self._arrivals[0][0]
            count = sum(c for _, c in list(self._arrivals)[1:])
            if span > 0.0 and count:
                return span / count
        if node.auto_choice is not None:
            return node.auto_choice.period_s
        return 1.0 / float(node.param("rate_hz"))

    def _tick_keys(self, keys: list[KeyPose]) -> None:
        """Message mode: advance through `keys` (dressing first if needed), then publish."""
        node = self.node
        if node.gs is None and node.particles_auto and node.auto_choice is None:
            # The garment's size waits for the stream's rate: its first stamps give it.
            self._held += keys
            if len(self._held) < AUTO_RATE_KEYS:
                return
            keys, self._held = self._held, []
            node.choose_particles(stream_rate([k.stamp for k in keys]))
        if node.gs is None or node.redress:
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
                node.gs.reanchor(key.stamp, key.poses)
                node.frames.note("teleport", key.stamp)
                node.ingest.used(1)
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
        node = self.node
        stats = node.gs.advance([(k.stamp, k.poses) for k in run])
        node.steps += 1
        node.ingest.used(len(run), len(run) - 1)
        return stats

    def _tick_body_timer(self, period: float) -> None:
        """Timer mode: advance `period` s of simulated time through the keys that arrived
        (spread evenly over the period), or with the body standing still."""
        node = self.node
        runs = self._live_streams(node.ingest.take())
        if len(runs) > 1:  # the clock is the node's own: only the newest stream is shown
            node.ingest.discard(sum(len(r) for r in runs[:-1]))
        keys = runs[-1] if runs else []
        if keys:
            self._frame = keys[-1].frame_id or self._frame
            self._new_stream(keys[0])
        if node.gs is None or node.redress:
            keys = self._dress(keys)
            if node.gs is None:
                return
        t0 = time.perf_counter()
        events = []
        start = node.sim_stamp
        path = []
        for i, key in enumerate(keys):
            stamp = start + period * (i + 1) / len(keys)
            if key.teleport:
                if path:
                    node.gs.advance(path)
                    path = []
                node.gs.reanchor(stamp, key.poses)
                node.frames.note("teleport", key.stamp)
                events.append("re-anchored after a teleport")
            else:
                path.append((stamp, key.poses))
        if keys:
            node.ingest.used(len(keys), max(len(keys) - 1, 0))
        node.sim_stamp = start + period
        stats = None
        if path or not keys:
            if not keys:  # no pose arrived: the body stands still for the period
                path.append((start + period, node.gs.poses))
            stats = node.gs.advance(path)
            node.steps += 1
        sec, nanosec = node.get_clock().now().seconds_nanoseconds()
        stamped = KeyPose(sec, nanosec, sec + 1e-9 * nanosec, "", node.gs.poses)
        self._publish_body(stamped, stats, 1e3 * (time.perf_counter() - t0),
                           "; ".join(events))

    def _publish_body(self, key: KeyPose, tick, step_ms: float, event: str) -> None:
        """Markers and diagnostics of the garment now, stamped with key's stamp; tick: the
        TickStats of the tick, or None (dressing)."""
        node = self.node
        gs = node.gs
        x = gs.positions
        finite = bool(np.isfinite(x).all())
        marker_ms = 0.0
        if key.frame_id:
            self._frame = key.frame_id
        if finite:
            marker_ms = node.outputs.cloth(gs.sim.model, x, key.sec, key.nanosec, self._frame,
                                           gs.sim.state.v, capsules=gs.capsules())
        counts = node.ingest.counts()
        # The lag: how far the newest pose received is ahead of the simulated time (message
        # mode; in timer mode the simulated clock is the node's own).
        lag_ms = 0.0
        if tick is not None and node.tick_mode == "message":
            lag_ms = 1e3 * (counts.newest_stamp - gs.stamp)
        values = {
            "step": str(node.steps),
            "marker_ms": f"{marker_ms:.3f}",
            "solver": str(node.param("solver")),
            "tolerance": f"{gs.solve_tolerance():.3e}",  # the level's (tolerance auto)
            "tolerance_setting": str(node.param("tolerance")),
            "stamp_s": f"{key.stamp:.6f}",
            "particles": str(gs.sim.model.n),
            "substeps": str(tick.substeps if tick else 0),
            "tick_poses": str(tick.poses if tick else 0),
            "simulated_ms": f"{1e3 * tick.simulated_s:.3f}" if tick else "0",
            "kinetic_energy_j": f"{tick.kinetic_energy:.4e}" if tick else "0",
            "poses_received": str(counts.received),
            "poses_used": str(counts.used),
            "poses_coalesced": str(counts.coalesced),
            "poses_pending": str(counts.pending),
            "poses_discarded": str(counts.discarded),
            "dropped": str(counts.dropped),
            "lag_ms": f"{max(lag_ms, 0.0):.3f}",
            "frames_skipped": str(node.frames.skipped),
            "resets": str(node.resets),
            "stream_restarts": str(counts.restarts),
            "kernels_compiled": str(node.compiles.count),
            "level": str(gs.level),
            "scene_particles": str(gs.level_particles(0)),
            "lod_switches": str(node.lod.switches if node.lod else 0),
            "budget_ms": f"{node.budget_ms(self.pose_period()):.3f}",
        }
        if node.auto_choice is not None:
            values["predicted_ms"] = f"{node.auto_choice.predicted_ms:.3f}"
        since = node.frames.take_since_status()
        notes = [event] if event else []
        skipped_now = {k: n for k, n in since.items() if k != "teleport" and n}
        if skipped_now:
            notes.append("skipped since the last status: " + ", ".join(
                f"{k} {n}" for k, n in sorted(skipped_now.items())))
        for kind, n in node.frames.counts.copy().items():
            values[f"skipped_{kind}"] = str(n)
        compiled = node.compiles.count
        if compiled > self._compiled_seen:
            names = sorted(set(node.compiles.compiled[self._compiled_seen:]))
            node.get_logger().warning(
                f"{compiled - self._compiled_seen} kernel(s) compiled after the warm-up, "
                f"{1e3 * node.compiles.seconds:.0f} ms in all so far (the warm-up missed "
                f"them): {', '.join(names[:6])}")
            self._compiled_seen = compiled
        failed = node.failures_since_status()
        if failed:
            notes.append(f"{failed} simulation step(s) failed")
        if gs.level:
            notes.append(f"level of detail {gs.level}: {len(x)} of the scene's "
                         f"{gs.level_particles(0)} particles")
        level = DiagnosticStatus.ERROR if failed else (
            DiagnosticStatus.WARN if skipped_now or "re-anchored" in event or gs.level else
            DiagnosticStatus.OK)
        node.outputs.status(TickFigures.from_stats(tick, step_ms), finite, key.sec, key.nanosec,
                            values, level, "; ".join(notes), self._frame)
        if tick is not None:
            self._after_tick(finite)
            if node.lod is not None and finite:
                self._level_of_detail(step_ms, marker_ms, max(lag_ms, 0.0))

    def _level_of_detail(self, step_ms: float, marker_ms: float, lag_ms: float) -> None:
        """lod: feed the tick (its steps and its publishing, ms) to the controller; make the
        switch it asks for (logged)."""
        node = self.node
        period = self.pose_period()
        predicted = [node.cost_model.tick_ms(node.gs.level_particles(lv), period)
                     for lv in node.lod.levels]
        switch = node.lod.observe(time.monotonic(), step_ms + marker_ms, lag_ms,
                                  node.budget_ms(period), 1e3 * period, predicted, step_ms)
        if switch is None:
            return
        old = node.gs.positions.shape[0]
        ms = node.gs.set_level(switch.level)
        node.get_logger().info(
            f"level of detail {switch.level}: {old} -> {node.gs.positions.shape[0]} particles "
            f"in {ms:.1f} ms ({switch.reason})")

    # -- sheet scenes ----------------------------------------------------------------------
    def _tick_sheet(self, period: float) -> None:
        """One simulation step of the sheet, then the markers and the diagnostics."""
        node = self.node
        stats = node.sim.step()
        node.steps += 1
        sec, nanosec = node.get_clock().now().seconds_nanoseconds()
        finite = bool(np.isfinite(node.sim.state.x).all())
        marker_ms = node.outputs.cloth(node.scene.model, node.sim.state.x, sec, nanosec,
                                       v=node.sim.state.v,
                                       spheres=node.scene.spheres) if finite else 0.0
        values = {"step": str(node.steps), "marker_ms": f"{marker_ms:.3f}",
                  "solver": str(node.param("solver")),
                  "tolerance": f"{float(node.param('tolerance')):.3e}",
                  "particles": str(node.scene.model.n)}
        node.outputs.status(TickFigures.from_stats(stats), finite, sec, nanosec, values)
        self._after_tick(finite)

    def _after_tick(self, finite: bool) -> None:
        node = self.node
        if not finite:
            node.get_logger().error(
                f"cloth positions became non-finite at step {node.steps}; try a smaller step "
                f"or tolerance")
            node.finish(1)
            self._stop.set()
        elif node.max_steps and node.steps >= node.max_steps:
            node.get_logger().info(f"max_steps {node.max_steps} reached")
            node.finish(0)
            self._stop.set()
