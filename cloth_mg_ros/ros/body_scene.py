"""A live body scene: a garment dressed on the first body pose of a stream and driven by the
poses that follow (`BodyScene`, a ros.live_scene.LiveScene the session drives).

Clock 'messages' (tick_mode message): each tick takes every key pose buffered since the last
one (`PoseIngest.take`) and advances the cloth to the newest in one go, the body following
every key in between (`GarmentSim.advance`). While the node keeps up that is one pose per
tick; when a tick runs long, the poses that arrived meanwhile are coalesced into the next one,
so the latency stays about one tick and nothing queues. A teleport among the keys ends the run
before it: the garment is re-anchored there and the rest follows. Which poses are coalesced
depends on timing, so a live run is not reproducible; fed one pose at a time (each marker
awaited before the next pose) the node computes exactly what the headless runner does.

Clock 'timer' (tick_mode timer): a tick every 1/rate_hz s of wall time (of /clock's under
use_sim_time) advances 1/rate_hz s of simulated time, the body moving through the keys that
arrived since the last tick (or standing still).

Grippers' stamped poses (ros.gripper_desk) are used over each advance's span of stamps: the
body poses' in message mode (the garment's stamp to the newest key's), the node's clock in
timer mode (the previous tick's reading to this one's).

A key of a newer stream (after ~/reset, or stamps that went back: a looped bag) clears the
display and re-dresses the garment on it. Each tick returns its Frame: the cloth, the body and
its contact arrows, the grippers' and segments' wrenches (ros.wrenches) and the status.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from cloth_mg_ros.apps.warmup import warm_up_garment, warm_up_joints
from cloth_mg_ros.budget.cost_model import (
    CALIBRATION_PARTICLES,
    check_max_particles,
    load_or_calibrate,
    stream_rate,
)
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.config.schema import AVATAR_PACKAGED
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.ros.body_input import BodyInput
from cloth_mg_ros.ros.gripper_desk import GripperDesk, grippers_text
from cloth_mg_ros.ros.ingest import NEW_STREAM_KEYS, FrameLog, KeyPose, PoseCounts, PoseIngest
from cloth_mg_ros.ros.live_scene import Clear, ClockSpan, Frame
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.ros.tick_budget import TickBudget
from cloth_mg_ros.ros.tick_status import status_level, status_notes
from cloth_mg_ros.ros.wrenches import contact_arrows
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.solve_tolerance import describe
from cloth_mg_ros.sim.tick_stats import TickStats

__all__ = ["AUTO_RATE_KEYS", "BodyScene"]

AUTO_RATE_KEYS = 5  # particles auto in message mode: poses whose stamps give the stream's rate


class BodyScene:
    """A garment on a body pose stream (module docstring).

    settings: the parameters fixed at start; logger: the node's; now: the node's clock as
    (sec, nanosec) (the timer's ticks are stamped with it); rate_hz: rate_hz now, Hz.
    `prepare` it, then the session calls `take` and `tick` on its simulation thread.
    """

    def __init__(self, settings: SessionSettings, logger, now: Callable[[], tuple[int, int]],
                 rate_hz: Callable[[], float]) -> None:
        self.settings = settings
        self.params = settings.values
        self.logger = logger
        self.now = now
        self.clock = "timer" if self.params.tick_mode == "timer" else "messages"
        self.budget = TickBudget(self.params, settings.threads, logger, rate_hz)
        self.options: BodySimOptions | None = None
        self.garment_sim: GarmentSim | None = None  # once dressed
        self.desk: GripperDesk | None = None
        self.ingest: PoseIngest | None = None
        self.frames: FrameLog | None = None
        self.particles_auto = self.params.particles == AUTO
        self.steps = 0  # ticks that advanced the garment
        self.redress = False
        self.sim_stamp = 0.0  # timer mode: simulated time, s
        self._span = ClockSpan()  # timer mode: the node's clock over each tick
        self.frame_id = ""  # the newest key pose's frame (timer ticks publish in it)
        self._dressed_generation = -1  # the pose stream the garment was dressed on
        self._held: list[KeyPose] = []  # particles auto: the first keys, until the rate is known
        self._failures_reported = 0
        # Keys a tick took on and has not yet counted (used, discarded, skipped or held): a
        # tick that raises counts them as skipped (`tick_failed`).
        self._open = 0
        self._open_stamp = float("nan")  # the newest of them, s (for the log)
        self.input: BodyInput | None = None  # key poses to segment poses in the world

    # -- start ---------------------------------------------------------------------------
    def prepare(self, sim_thread, outputs) -> str:
        """Check the garment's parameters, load the avatar, calibrate the cost model when the
        scene needs it (particles auto, lod, tolerance auto), create the pose ingest and warm
        the tick path up on sim_thread (outputs build their messages once). Returns the
        start-up log line's description."""
        params, threads = self.params, self.settings.threads
        self.input = BodyInput(params, self.logger)
        check_max_particles(params.garment, params.max_particles, "parameter max_particles")
        self.options = BodySimOptions.from_scene(
            params, threads=threads,
            particles=CALIBRATION_PARTICLES if self.particles_auto else params.particles)
        if self.particles_auto or params.lod or params.tolerance == AUTO:
            self.budget.cost_model, _ = sim_thread.call(
                load_or_calibrate, self.options, self.settings.material, self.logger.info,
                bag=params.bag)
            self.options.tolerances = tuple(self.budget.cost_model.tolerances)
        if self.particles_auto and self.clock == "timer":
            self.options.particles = self.budget.choose_particles(self.budget.rate_hz(),
                                                                  self.options.garment)
        self.desk = GripperDesk(params.grippers, self.logger)
        joints, sk = self.input.joints, self.input.skeleton
        self.frames = FrameLog(self.logger, self.input.count,
                               f"{sk.name} joint" if joints else "avatar segment")
        self.ingest = PoseIngest(self.input.count, self.options.teleport_m, self.frames,
                                 on_restart=self.on_stream_restart, joints=joints)
        warm = sim_thread.call(warm_up_body, self, outputs)
        o = self.options
        return (f"scene {params.scene!r}: a {o.garment} of about {o.particles} particles, "
                f"{self.settings.material.name}, solver {o.solver} (tol "
                f"{describe(o.tolerance, o.tolerances)}, levels {o.levels or 'auto'}), "
                f"substeps >= {o.substeps}, steps <= {o.max_step:g} s, floor {o.floor}, "
                f"self-contact {o.self_contact}, {threads} thread(s); warmed up in {warm}; "
                f"tick mode {params.tick_mode}; body input {params.body_input}"
                f"{f' ({sk.name})' if joints else ''}{self._frame_text()}"
                f"{grippers_text(self.desk.names)}")

    def _frame_text(self) -> str:
        """The start-up line's words on the input's frame, floor and avatar."""
        params, frame = self.params, self.input.frame
        words = []
        if not frame.rigid_identity:
            words.append(f"input_transform {list(params.input_transform)}")
        if frame.floor != 0.0:
            words.append("the floor measured over each stream's first second"
                         if frame.floor is None else f"the floor at {frame.floor:g} m")
        if params.avatar != AVATAR_PACKAGED:
            words.append(f"avatar {params.avatar}")
        return "; " + ", ".join(words) if words else ""

    @property
    def avatar(self) -> Avatar | None:
        """The avatar the garment is dressed on (sized per stream with avatar from_joints)."""
        return None if self.input is None else self.input.avatar

    def tolerance_auto_available(self) -> bool:
        """Whether tolerance auto was measured at start (it may then be chosen again)."""
        return self.options is not None and bool(self.options.tolerances)

    # -- requests ------------------------------------------------------------------------
    def apply_gripper_inputs(self) -> None:
        """The desk's calls, poses and release_force applied to the garment's grippers (none
        before it is dressed), in the poses' frame."""
        g = self.garment_sim
        grippers, x, pinned = (None, None, None) if g is None else (
            g.grippers, g.positions, g.held_mask())
        force = self.desk.apply(grippers, x, pinned, self.frame_id or self.params.frame_id)
        if force is not None:
            self.options.release_force = force  # a garment dressed later takes it too

    def change_solver(self, solver: str, tolerance: float | str) -> str:
        """The solver and tolerance of every level of detail, each its own; returns the
        tolerance as the log describes it."""
        self.options.solver, self.options.tolerance = solver, tolerance
        if self.garment_sim is not None:
            self.garment_sim.set_solver(solver, tolerance)
        return describe(tolerance, self.options.tolerances)

    def request_reset(self) -> str:
        """~/reset: the stream starts over (its stamps may too); the garment is re-dressed on
        its first valid pose."""
        self.ingest.reset()
        return "the garment is re-dressed on the next valid body pose"

    def reset(self) -> None:
        """On the simulation thread after ~/reset: the keys held for particles auto of the
        stream it discarded go too (counted as discarded); the rest waits for the new
        stream's first pose (`request_reset` began it)."""
        self._drop_held(self.ingest.live_from)

    def resumed(self) -> None:
        self._span.restart()

    def wake(self) -> None:
        if self.ingest is not None:
            self.ingest.wake()

    # -- ticks ---------------------------------------------------------------------------
    def take(self, timeout_s: float) -> list[KeyPose]:
        """Every key pose buffered (the 'messages' clock waits up to timeout_s for one), as
        the avatar's segment poses."""
        if self.clock == "timer":
            return self.input.convert(self.ingest.take(), self.ingest.skip_taken)
        keys = self.ingest.take(timeout_s)
        self.budget.arrivals.note(len(keys))
        return self.input.convert(keys, self.ingest.skip_taken)

    def tick(self, keys: list[KeyPose], period_s: float | None) -> list[Frame | Clear]:
        """Advance through `keys` (the 'messages' clock: to the newest; the timer's: period_s s
        of simulated time), dressing first when needed. Returns what to publish."""
        self._open = len(keys)
        self._open_stamp = keys[-1].stamp if keys else float("nan")
        if self.clock == "timer":
            return self._tick_timer(keys, period_s)
        out: list[Frame | Clear] = []
        for run in self._live_streams(keys):
            out += self._new_stream(run[0])
            out += self._tick_keys(run)
        return out

    def published(self, frame: Frame, marker_ms: float) -> None:
        """After a tick that stepped: the budget follows it (threads, level of detail)."""
        if frame.stepped and frame.finite:
            self.budget.follow(self.garment_sim, frame.step_ms, marker_ms,
                               max(frame.lag_ms, 0.0), frame.stats.substeps)

    def _live_streams(self, keys: list[KeyPose]) -> list[list[KeyPose]]:
        """`keys` split into runs of one stream each, oldest first; keys of a stream that
        ~/reset discarded are counted as discarded and left out."""
        live = self.ingest.live_from
        stale = sum(k.generation < live for k in keys)
        if stale:
            self._discarded(stale)
        runs: list[list[KeyPose]] = []
        for key in keys:  # a handful of keys per tick
            if key.generation < live:
                continue
            if runs and runs[-1][-1].generation == key.generation:
                runs[-1].append(key)
            else:
                runs.append([key])
        return runs

    def _new_stream(self, key: KeyPose) -> list[Clear]:
        """A key of a newer stream than the garment's (after ~/reset, or stamps that jumped
        back: a looped bag): the display is cleared and the garment re-dressed on it."""
        if self.garment_sim is None or key.generation == self._dressed_generation:
            return []
        self.redress = True
        return [Clear(key.sec, key.nanosec, key.frame_id or self.frame_id)]

    def _dress(self, keys: list[KeyPose]) -> tuple[list[Frame], list[KeyPose]]:
        """Dress the garment on the first key it fits; returns its frame and the keys after
        it."""
        for k, key in enumerate(keys):
            t0 = time.perf_counter()
            try:
                garment_sim = GarmentSim.dress(self.avatar, key.stamp, key.poses,
                                               self.settings.material, self.options)
            except ClothInputError as exc:
                if not self.frames.count("dress_failed"):
                    self.logger.error(f"cannot dress the garment: {exc}")
                self.ingest.skip_taken("dress_failed", key.stamp)  # skipped, not discarded
                self._open -= 1
                continue
            self.garment_sim, self.redress = garment_sim, False
            self.budget.dressed(garment_sim)
            self.sim_stamp = key.stamp
            self._dressed_generation = key.generation
            dress_ms = 1e3 * (time.perf_counter() - t0)
            self._used(1)
            self.logger.info(
                f"dressed a {self.options.garment} of {garment_sim.particles} particles "
                f"({len(garment_sim.garment.hierarchy.levels)} levels) on the body pose at "
                f"stamp {key.stamp:.3f} s in {dress_ms:.0f} ms")
            return [self._frame(key, None, dress_ms, "dressed")], keys[k + 1:]
        return [], []

    def _drop_held(self, generation: int) -> None:
        """Forget the keys held for particles auto that are not of stream `generation` (a
        reset or a new time line came before AUTO_RATE_KEYS of them): counted as discarded.
        Mixed with the new stream's, their stamps would go back."""
        stale = sum(k.generation != generation for k in self._held)
        if stale:
            self._held = [k for k in self._held if k.generation == generation]
            self.ingest.discard(stale)

    def _tick_keys(self, keys: list[KeyPose]) -> list[Frame]:
        """The 'messages' clock: advance through `keys` (one stream's, dressing first if
        needed)."""
        if self.garment_sim is None and self.particles_auto and self.budget.auto_choice is None:
            # The garment's size waits for the stream's rate: its first stamps give it.
            self._drop_held(keys[0].generation)
            self._held += keys
            self._open -= len(keys)  # held: pending, counted
            if len(self._held) < AUTO_RATE_KEYS:
                return []
            keys, self._held = self._held, []
            self._open += len(keys)
            self.options.particles = self.budget.choose_particles(
                stream_rate([k.stamp for k in keys]), self.options.garment)
        out: list[Frame] = []
        if self.garment_sim is None or self.redress:
            out, keys = self._dress(keys)
        if not keys:
            return out
        t0 = time.perf_counter()
        run: list[KeyPose] = []
        stats, events = None, []
        for key in keys:
            if key.teleport:
                stats = self._advance(run) or stats
                run = []
                self._reanchor(key.stamp, key)
                self.frames.note("teleport", key.stamp)
                self._used(1)
                events.append("re-anchored after a teleport")
            else:
                run.append(key)
        stats = self._advance(run) or stats
        out.append(self._frame(keys[-1], stats, 1e3 * (time.perf_counter() - t0),
                               "; ".join(events)))
        return out

    def _used(self, keys: int, coalesced: int = 0) -> None:
        """Count keys of this tick used (PoseIngest.used)."""
        self.ingest.used(keys, coalesced)
        self._open -= keys

    def _discarded(self, keys: int) -> None:
        """Count keys of this tick discarded (PoseIngest.discard)."""
        self.ingest.discard(keys)
        self._open -= keys

    def not_ticked(self, keys: list[KeyPose]) -> None:
        """Keys taken as the loop stopped: counted as discarded (a reset's count)."""
        self.ingest.discard(len(keys))

    def tick_failed(self) -> int:
        """The tick raised: its keys not yet counted are counted as skipped (kind
        'tick_failed') and the garment is re-dressed on the next valid pose (whatever state
        the failure left it in). Returns the keys skipped."""
        skipped, self._open = max(self._open, 0), 0
        for _ in range(skipped):
            self.ingest.skip_taken("tick_failed", self._open_stamp)
        if self.garment_sim is not None:
            self.redress = True
        return skipped

    def _reanchor(self, stamp: float, key: KeyPose) -> None:
        """Re-anchor the garment at `key` (a teleport) placed at `stamp` s, the segments the
        tracker lost in it out of the collider."""
        self.garment_sim.set_dropped(key.dropped)
        self.garment_sim.reanchor(stamp, key.poses)

    def _advance(self, run: list[KeyPose]) -> TickStats | None:
        """One GarmentSim.advance through `run` (none: None), each step with the segments
        the tracker lost in the key it moves toward out of the collider; counts the keys."""
        if not run:
            return None
        self._place_stamped(self.garment_sim.stamp, run[-1].stamp, run[-1].frame_id)
        stats = self.garment_sim.advance([(k.stamp, k.poses) for k in run],
                                         [k.dropped for k in run])
        self.steps += 1
        self._used(len(run), len(run) - 1)
        return stats

    def _place_stamped(self, t0: float, t1: float, frame_id: str) -> None:
        """The grippers' stamped poses over the span t0..t1 s of the steps to come."""
        self.desk.place_stamped(self.garment_sim.grippers, t0, t1,
                                frame_id or self.frame_id or self.params.frame_id)

    def _tick_timer(self, keys: list[KeyPose], period: float) -> list[Frame | Clear]:
        """The timer: advance `period` s of simulated time through the keys that arrived
        (spread evenly over the period), or with the body standing still."""
        runs = self._live_streams(keys)
        if len(runs) > 1:  # the clock is the node's own: only the newest stream is shown
            self._discarded(sum(len(r) for r in runs[:-1]))
        keys = runs[-1] if runs else []
        out: list[Frame | Clear] = []
        if keys:
            self.frame_id = keys[-1].frame_id or self.frame_id
            out += self._new_stream(keys[0])
        if self.garment_sim is None or self.redress:
            dressed, keys = self._dress(keys)
            out += dressed
            if self.garment_sim is None:
                return out
        t0 = time.perf_counter()
        start = self.sim_stamp
        path, masks, events = self._timer_path(keys, start, period)
        self.sim_stamp = start + period
        stats = None
        if path or not keys:
            if not keys:  # no pose arrived: the body stands still for the period, as it was
                path.append((start + period, self.garment_sim.poses))
                masks.append(self.garment_sim.dropped)
            sec, nanosec = self.now()  # grippers' stamps: on the node's clock
            c0, c1 = self._span.span(sec, nanosec, period)
            self._place_stamped(c0, c1, keys[-1].frame_id if keys else "")
            stats = self.garment_sim.advance(path, masks)
            self.steps += 1
        if keys:
            self._used(len(keys), max(len(keys) - 1, 0))
        sec, nanosec = self.now()
        stamped = KeyPose(sec, nanosec, sec + 1e-9 * nanosec, "", self.garment_sim.poses)
        out.append(self._frame(stamped, stats, 1e3 * (time.perf_counter() - t0),
                               "; ".join(events)))
        return out

    def _timer_path(self, keys: list[KeyPose], start: float, period: float
                    ) -> tuple[list, list, list[str]]:
        """The keys spread evenly over the period from `start`: the (stamp, poses) path after
        the last teleport (those before it advanced, then re-anchored), its keys' dropped
        masks, and the events."""
        path, masks, events = [], [], []
        for i, key in enumerate(keys):
            stamp = start + period * (i + 1) / len(keys)
            if key.teleport:
                if path:
                    self.garment_sim.advance(path, masks)
                    path, masks = [], []
                self._reanchor(stamp, key)
                self.frames.note("teleport", key.stamp)
                events.append("re-anchored after a teleport")
            else:
                path.append((stamp, key.poses))
                masks.append(key.dropped)
        return path, masks, events

    # -- what a tick returns ---------------------------------------------------------------
    def _frame(self, key: KeyPose, tick: TickStats | None, step_ms: float, event: str
               ) -> Frame:
        """The garment now, stamped with key's stamp; tick: the tick's TickStats, or None
        (dressing); step_ms: its time, ms; event: what it did besides stepping."""
        g = self.garment_sim
        if key.frame_id:
            self.frame_id = key.frame_id
        x = g.positions.copy()
        finite = bool(np.isfinite(x).all())
        capsules = g.capsules()
        forces = tick.body_forces if tick is not None else {}
        counts = self.ingest.counts()
        # The lag: how far the newest pose received is ahead of the simulated time (message
        # mode; in timer mode the simulated clock is the node's own).
        lag_ms = 0.0
        if tick is not None and self.clock == "messages":
            lag_ms = 1e3 * (counts.newest_stamp - g.stamp)
        if tick is not None and tick.released:
            self.desk.note_released(tick.released, g.grippers.release_force)
        values = self.status_values(tick, key.stamp, lag_ms, counts)
        failed = self._failures_since_status()
        notes, skipped_now = status_notes(event, self.frames.take_since_status(), failed,
                                          g.rung, len(x), g.rung_particles(0))
        return Frame(
            key.sec, key.nanosec, self.frame_id, g.model, x, g.velocities.copy(), finite,
            tick, step_ms, self.steps, tick is not None, values,
            status_level(failed, skipped_now, event, g.rung), "; ".join(notes),
            capsules=capsules, arrows=contact_arrows(forces, self.avatar.names, capsules),
            gripper_wrenches={} if g.grippers is None else g.grippers.wrenches(),
            body_forces=forces, body_torques=tick.body_torques if tick is not None else {},
            gripper_poses={} if g.grippers is None else g.grippers.frames(),
            segment_poses={s: (g.poses[k, :3].copy(), g.poses[k, 3:7].copy())
                           for k, s in enumerate(self.avatar.names) if s in forces},
            lag_ms=lag_ms)

    def status_values(self, tick: TickStats | None, stamp_s: float, lag_ms: float,
                      counts: PoseCounts) -> dict[str, str]:
        """The status's key-values of the garment now. tick: the tick's TickStats, or None
        (dressing); stamp_s: the stamp published, s; lag_ms: the newest pose received minus
        the simulated time, ms; counts: the pose stream's."""
        g, budget = self.garment_sim, self.budget
        values = {
            "solver": str(self.options.solver),
            "tolerance": f"{g.solve_tolerance():.3e}",  # the level's (tolerance auto)
            "tolerance_setting": str(self.options.tolerance),
            "stamp_s": f"{stamp_s:.6f}",
            "particles": str(g.particles),
            "substeps": str(tick.substeps if tick else 0),
            "tick_poses": str(tick.poses if tick else 0),
            "simulated_ms": f"{1e3 * tick.simulated_s:.3f}" if tick else "0",
            "kinetic_energy_j": f"{tick.kinetic_energy:.4e}" if tick else "0",
            "poses_received": str(counts.received),
            "poses_used": str(counts.used),
            "poses_coalesced": str(counts.coalesced),
            "poses_pending": str(self.pending(counts)),
            "poses_discarded": str(counts.discarded),
            "dropped": str(self.dropped(counts)),
            "lag_ms": f"{max(lag_ms, 0.0):.3f}",
            "frames_skipped": str(self.frames.skipped),
            "stream_restarts": str(counts.restarts),
            "level": str(g.rung),  # the level of detail (the key predates "rung")
            "scene_particles": str(g.rung_particles(0)),
            "lod_switches": str(budget.detail.switches if budget.detail else 0),
            # the threads the steps ran on (fewer than `threads` while other work holds cores)
            "threads": str(g.run_threads or self.settings.threads),
            # the share of the process's threads' time spent waiting for a core over the
            # tick before (budget.contention; -1: unknown)
            "wait_share": f"{-1.0 if budget.wait_share is None else budget.wait_share:.3f}",
            "budget_ms": f"{budget.budget_ms(budget.pose_period()):.3f}",
            "mass_kg": f"{g.mass_kg:.6g}",
            # The cloth's largest force on a body segment (mean over the tick's steps), N.
            "contact_peak_n": f"{tick.contact_peak_n if tick else 0.0:.4f}",
            "contact_peak_segment": tick.contact_peak_segment if tick else "",
            # What the penalty contacts pulled the cloth onto the colliders with, N (mean
            # over the tick's steps; sim.loads.ContactLoad.pull): 0 where contacts only push.
            "contact_pull_n": f"{tick.contact_pull_n if tick else 0.0:.4f}",
        }
        if budget.auto_choice is not None:
            values["predicted_ms"] = f"{budget.auto_choice.predicted_ms:.3f}"
        for kind, n in self.frames.snapshot().items():
            values[f"skipped_{kind}"] = str(n)
        track = self.input.track
        if track is not None:  # joint samples held (missing, within joint_hold), lost
            values["joints_held"] = str(track.counts.held)
            values["joints_lost"] = str(track.counts.lost)
            # segment samples left out of the collider (their joints lost), and now
            values["segments_dropped"] = str(self.input.dropped_samples)
            values["dropped_now"] = ",".join(
                self.avatar.names[s] for s in np.flatnonzero(g.dropped)
            ) if g.dropped is not None else ""
        if self.desk.names:
            values.update(self.desk.values(g.grippers))
        return values

    def pending(self, counts: PoseCounts) -> int:
        """Valid poses not yet simulated nor discarded: buffered (counts.pending), held by the
        body input while it measures, held for particles auto's rate."""
        return counts.pending + self.input.held + len(self._held)

    def dropped(self, counts: PoseCounts) -> int:
        """Poses received that no count holds (PoseCounts.lost, given what this scene holds:
        the body input's and particles auto's held keys, and the tick's keys not yet
        counted). 0 unless the accounting lost one; the tests and `bench faults` say so."""
        return counts.lost(self.input.held + len(self._held) + max(self._open, 0))

    def _failures_since_status(self) -> int:
        """Simulation steps that failed since the last call."""
        total = self.garment_sim.failures if self.garment_sim is not None else 0
        new, self._failures_reported = total - self._failures_reported, total
        return max(new, 0)

    # -- reports ----------------------------------------------------------------------------
    def waiting_text(self) -> str:
        """The /diagnostics message before the first tick."""
        return "waiting for body poses" if self.garment_sim is None else "starting"

    def on_stream_restart(self, previous: float, stamp: float) -> None:
        """A new time line (a looped bag, a restarted publisher): a new stream."""
        self.logger.info(
            f"body pose stamps went back from {previous:.3f} s to {stamp:.3f} s and "
            f"{NEW_STREAM_KEYS} poses went on from there: a new stream (a looped bag, a "
            f"restarted publisher); the garment is re-dressed on it")

    def periodic_summary(self) -> None:
        """Log the skipped frames' and gripper poses' summary when either changed since the
        last one."""
        if self.frames is not None and self.frames.changed():
            c = self.ingest.counts()
            self.logger.warning(self.frames.summary(c.received, c.used))
        if self.desk is not None and self.desk.changed():
            self.logger.warning(self.desk.summary())

    def log_summary(self, resets: int) -> None:
        """Log the pose stream's summary (at shutdown)."""
        if self.ingest is None:
            return
        self.ingest.close()
        c = self.ingest.counts()
        self.logger.info(
            f"{self.frames.summary(c.received, c.used)}; {self.steps} ticks, "
            f"{c.coalesced} poses coalesced, {self.pending(c)} pending at shutdown, "
            f"{c.discarded} discarded by resets, {self.dropped(c)} dropped; "
            f"{resets} resets, {c.restarts} new streams")
        if self.desk.names:
            self.logger.info(self.desk.summary())


def warm_up_body(scene: BodyScene, outputs) -> str:
    """Run every kernel the ticks will use (apps.warmup.warm_up_garment: the scene's
    garment, solver, tolerance, contacts and levels of detail on a moving body) and build
    the outputs' messages once, on the simulation thread, before the node subscribes.
    Returns what it did, for the log."""
    warm, garment_sim = warm_up_garment(scene.avatar, scene.settings.material, scene.options,
                                        lod=scene.params.lod)
    if scene.input.skeleton is not None:  # the joints' conversion, as a tick makes it
        warm_up_joints(scene.avatar, scene.input.skeleton)
    outputs.cloth_messages(garment_sim.model, garment_sim.positions, 0, 0, outputs.frame_id,
                           garment_sim.velocities, garment_sim.capsules())
    return warm.describe()
