"""A live session's level of detail (parameter lod, body scenes): the controller of a garment
just dressed (`detail_controller`) and, after each tick, the switch it asks for
(`follow_budget`). Functions of the session (ros.session.LiveSession), run on its simulation
thread; the controller's rule is sim.detail's.
"""

from __future__ import annotations

import time

from cloth_mg_ros.sim.detail import MIN_RUNG_PARTICLES, DetailController
from cloth_mg_ros.sim.garment import GarmentSim

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
    """lod: feed the tick (its steps' time and its publishing, ms; the lag behind the newest
    pose, ms; its steps; the share of the process's time spent waiting for a core since the
    last tick, budget.contention) to the session's controller; make the switch it asks for
    (logged)."""
    garment_sim = session.garment_sim
    period = session.pose_period()
    predicted = [session.cost_model.tick_ms(garment_sim.rung_particles(lv), period)
                 for lv in session.detail.rungs]
    switch = session.detail.observe(time.monotonic(), step_ms + marker_ms, lag_ms,
                                    session.budget_ms(period), 1e3 * period, predicted, step_ms,
                                    steps, session.contention.share())
    if switch is None:
        return
    old = garment_sim.positions.shape[0]
    ms = garment_sim.set_rung(switch.rung)
    session.logger.info(
        f"level of detail {switch.rung}: {old} -> {garment_sim.positions.shape[0]} "
        f"particles in {ms:.1f} ms ({switch.reason})")
