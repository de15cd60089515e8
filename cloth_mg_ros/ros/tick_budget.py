"""A body scene's tick budget: the garment's size for the pose stream (parameter particles
auto), the period a tick must keep up with, and after each tick the threads the steps run on
and the level of detail's switch (parameter lod). The rules are budget.cost_model's,
budget.thread_governor's and sim.detail's; `TickBudget` holds their state for one live scene
(ros.body_scene) and runs on its simulation thread.
"""

from __future__ import annotations

import time

from cloth_mg_ros.budget.contention import ContentionMeter
from cloth_mg_ros.budget.cost_model import AutoChoice, CostModel, choose_particles
from cloth_mg_ros.budget.thread_governor import ThreadChange, ThreadGovernor
from cloth_mg_ros.config.schema import SceneParams
from cloth_mg_ros.mesh.garments.design import MIN_PARTICLES
from cloth_mg_ros.ros.arrivals import ArrivalRate
from cloth_mg_ros.sim.detail import MIN_RUNG_PARTICLES, DetailController
from cloth_mg_ros.sim.garment_sim import GarmentSim
from cloth_mg_ros.solvers.threads import available_threads

__all__ = ["TickBudget"]


class TickBudget:
    """The budget of a body scene's ticks (module docstring).

    params: the scene's parameters at start (tick_budget, max_particles, tick_mode, lod);
    threads: the threads configured (>= 1); logger: the node's (info); rate_hz: returns
    rate_hz now, Hz (a run-time change takes effect at the next tick).
    """

    def __init__(self, params: SceneParams, threads: int, logger, rate_hz) -> None:
        self.params = params
        self.threads = threads
        self.logger = logger
        self.rate_hz = rate_hz
        self.cost_model: CostModel | None = None  # particles auto, lod, tolerance auto
        self.auto_choice: AutoChoice | None = None  # particles auto: the choice made
        self.detail: DetailController | None = None  # lod: the garment's level of detail
        self.arrivals = ArrivalRate()  # the poses the ticks took lately (message mode)
        self.contention = ContentionMeter()  # the cores' contention between ticks
        self.governor: ThreadGovernor | None = None  # made by the first tick (threads > 1)
        self.step_contention: ContentionMeter | None = None  # ... between a tick's steps
        self.wait_share: float | None = None  # the last tick's (budget.contention)

    def choose_particles(self, rate_hz: float, garment: str) -> int:
        """particles auto: the garment's size for a pose stream of rate_hz (logged)."""
        p = self.params
        c = choose_particles(self.cost_model, rate_hz, p.tick_budget, p.max_particles,
                             MIN_PARTICLES[garment])
        self.auto_choice = c
        self.logger.info(
            f"particles auto: {c.particles} particles ({c.capped_by}) for a {rate_hz:.1f} Hz "
            f"pose stream: budget {c.budget_ms:.1f} ms ({p.tick_budget:g} of the "
            f"period), predicted tick {c.predicted_ms:.1f} ms")
        return c.particles

    def budget_ms(self, period_s: float) -> float:
        """The tick budget for a pose period of period_s, ms."""
        return self.params.tick_budget * period_s * 1e3

    def pose_period(self) -> float:
        """The wall-clock period of the pose stream lately, s (what a tick must keep up
        with): the timer's period in timer mode; in message mode measured over the last
        ros.arrivals.ARRIVAL_WINDOW_S, or the stamps' rate that particles auto used until
        then."""
        if self.params.tick_mode == "timer":
            return 1.0 / float(self.rate_hz())
        measured = self.arrivals.period()
        if measured is not None:
            return measured
        if self.auto_choice is not None:
            return self.auto_choice.period_s
        return 1.0 / float(self.rate_hz())

    def dressed(self, garment_sim: GarmentSim) -> None:
        """A garment was just dressed: with lod, its levels of detail and their controller,
        which compares the rungs by their steps timed on this garment now (logged; logged
        too when the garment has no coarser one)."""
        self.detail = None
        if not self.params.lod:
            return
        garment_sim.prepare_rungs()
        rungs = garment_sim.rung_indices()
        if len(rungs) == 1:
            self.logger.info(
                f"lod: a {garment_sim.options.garment} of {garment_sim.particles} particles "
                f"has no coarser level of detail (each needs at least {MIN_RUNG_PARTICLES} "
                f"particles and a multigrid level below it): it stays at this size")
            self.detail = DetailController(rungs)
            return
        timed = garment_sim.time_rungs()
        self.logger.info("lod: steps timed on the garment: " + ", ".join(
            f"{ms:.1f} ms at {garment_sim.rung_particles(r)} particles"
            for r, ms in zip(rungs, timed, strict=True)))
        self.detail = DetailController(rungs, rung_step_ms=timed)

    def follow(self, garment_sim: GarmentSim, step_ms: float, marker_ms: float,
               lag_ms: float, steps: int = 1) -> None:
        """After a tick: feed the share of the process's time spent waiting for a core since
        the last tick (budget.contention) to the thread governor, and run the next steps on
        the threads it says (logged when they change); with lod, feed the tick (its steps'
        time and its publishing, ms; the lag behind the newest pose, ms; its steps) to the
        level of detail controller and make the switch it asks for (logged). The level of
        detail does not step up while the steps run on fewer threads than configured (its
        finer rungs were timed on all of them), and does not see the first tick of a try at
        more threads (on a machine still loaded it runs at half speed or worse, a test of the
        cores that must not step the garment down)."""
        now = time.monotonic()
        share = self.contention.share()
        self.wait_share = share
        if self.governor is None and self.threads > 1:
            self.governor = ThreadGovernor(self.threads, available_threads())
            self.step_contention = ContentionMeter()
        governor = self.governor
        if governor is not None and garment_sim.between_steps is None:
            garment_sim.between_steps = self._between_steps
        # a try at more threads' first tick tests the cores, not the rung
        probe = governor is not None and governor.probing
        if governor is not None:
            self._log_threads(governor.observe(now, share))
            garment_sim.run_threads = governor.threads
        if self.detail is None or probe:
            return
        period = self.pose_period()
        predicted = [self.cost_model.tick_ms(garment_sim.rung_particles(lv), period)
                     for lv in self.detail.rungs]
        switch = self.detail.observe(
            now, step_ms + marker_ms, lag_ms, self.budget_ms(period), 1e3 * period, predicted,
            step_ms, steps, share,
            full_threads=governor is None or governor.threads == governor.configured)
        if switch is None:
            return
        old = garment_sim.particles
        ms = garment_sim.set_rung(switch.rung)
        self.logger.info(
            f"level of detail {switch.rung}: {old} -> {garment_sim.particles} "
            f"particles in {ms:.1f} ms ({switch.reason})")

    def _between_steps(self) -> int | None:
        """Between two steps of a tick: the thread governor's count for the next ones, if a
        step waited so long for a core that the load cannot wait for the tick's end
        (logged)."""
        change = self.governor.observe_step(time.monotonic(), self.step_contention.share())
        self._log_threads(change)
        return None if change is None else change.threads

    def _log_threads(self, change: ThreadChange | None) -> None:
        """Log the thread governor's change, if any."""
        if change is not None:
            self.logger.info(change.describe(self.governor.configured))
