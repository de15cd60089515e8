"""A live session's budget (body scenes): the level of detail's controller of a garment just
dressed (`detail_controller`, parameter lod) and, after each tick, the switch it asks for and
the threads the steps run on (`follow_budget`). Functions of the session
(ros.session.LiveSession), run on its simulation thread; the rules are sim.detail's and
budget.thread_governor's.
"""

from __future__ import annotations

import time
from functools import partial

from cloth_mg_ros.budget.contention import ContentionMeter
from cloth_mg_ros.budget.thread_governor import ThreadChange, ThreadGovernor
from cloth_mg_ros.sim.detail import MIN_RUNG_PARTICLES, DetailController
from cloth_mg_ros.sim.garment import GarmentSim
from cloth_mg_ros.solvers.threads import available_threads

__all__ = ["detail_controller", "follow_budget"]


def detail_controller(session, garment_sim: GarmentSim) -> DetailController:
    """lod: the garment's levels of detail and their controller, which compares the rungs by
    their steps timed on this garment now (logged; logged too when the garment has no
    coarser one)."""
    garment_sim.prepare_rungs()
    rungs = garment_sim.rung_indices()
    if len(rungs) == 1:
        session.logger.info(
            f"lod: a {session.options.garment} of {garment_sim.sim.model.n} particles has "
            f"no coarser level of detail (each needs at least {MIN_RUNG_PARTICLES} "
            f"particles and a multigrid level below it): it stays at this size")
        return DetailController(rungs)
    timed = garment_sim.time_rungs()
    session.logger.info("lod: steps timed on the garment: " + ", ".join(
        f"{ms:.1f} ms at {garment_sim.rung_particles(r)} particles"
        for r, ms in zip(rungs, timed, strict=True)))
    return DetailController(rungs, rung_step_ms=timed)


def follow_budget(session, step_ms: float, marker_ms: float, lag_ms: float,
                  steps: int = 1) -> None:
    """After a tick: feed the share of the process's time spent waiting for a core since the
    last tick (budget.contention) to the thread governor, and run the next steps on the
    threads it says (logged when they change); with lod, feed the tick (its steps' time and
    its publishing, ms; the lag behind the newest pose, ms; its steps) to the session's level
    of detail controller and make the switch it asks for (logged). The level of detail does
    not step up while the steps run on fewer threads than configured (its finer rungs were
    timed on all of them), and does not see the first tick of a try at more threads (on a
    machine still loaded it runs at half speed or worse, a test of the cores that must not
    step the garment down)."""
    garment_sim = session.garment_sim
    now = time.monotonic()
    share = session.contention.share()
    session.wait_share = share
    if session.governor is None and session.settings.threads > 1:
        session.governor = ThreadGovernor(session.settings.threads, available_threads())
        session.step_contention = ContentionMeter()
    governor = session.governor
    if governor is not None and garment_sim.between_steps is None:
        garment_sim.between_steps = partial(_between_steps, session)
    # a try at more threads' first tick tests the cores, not the rung (budget.thread_governor)
    probe = governor is not None and governor.probing
    if governor is not None:
        _log_threads(session, governor.observe(now, share))
        garment_sim.run_threads = governor.threads
    if session.detail is None or probe:
        return
    period = session.pose_period()
    predicted = [session.cost_model.tick_ms(garment_sim.rung_particles(lv), period)
                 for lv in session.detail.rungs]
    switch = session.detail.observe(
        now, step_ms + marker_ms, lag_ms, session.budget_ms(period), 1e3 * period, predicted,
        step_ms, steps, share,
        full_threads=governor is None or governor.threads == governor.configured)
    if switch is None:
        return
    old = garment_sim.positions.shape[0]
    ms = garment_sim.set_rung(switch.rung)
    session.logger.info(
        f"level of detail {switch.rung}: {old} -> {garment_sim.positions.shape[0]} "
        f"particles in {ms:.1f} ms ({switch.reason})")


def _between_steps(session) -> int | None:
    """Between two steps of a tick: the thread governor's count for the next ones, if a step
    waited so long for a core that the load cannot wait for the tick's end (logged)."""
    change = session.governor.observe_step(time.monotonic(), session.step_contention.share())
    _log_threads(session, change)
    return None if change is None else change.threads


def _log_threads(session, change: ThreadChange | None) -> None:
    """Log the thread governor's change, if any."""
    if change is not None:
        session.logger.info(f"solver threads: {change.threads} of "
                            f"{session.governor.configured} ({change.reason})")
