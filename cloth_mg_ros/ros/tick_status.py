"""What cloth_node's per-tick status says: the figures of a body scene's tick or a sheet's
step as the DiagnosticStatus key-values of `cloth/stats`, its level and its message.

Pure functions of the session's state: the session (ros.session) calls them on the simulation
thread and hands the result to the outputs (ros.publishing).
"""

from __future__ import annotations

from collections import Counter

from diagnostic_msgs.msg import DiagnosticStatus

from cloth_mg_ros.ros.ingest import PoseCounts

__all__ = ["body_values", "sheet_values", "status_level", "status_notes"]


def body_values(session, tick, stamp_s: float, marker_ms: float, lag_ms: float,
                counts: PoseCounts) -> dict[str, str]:
    """The key-values of a body scene's status. session: the LiveSession (its garment
    simulation, counters and settings); tick: the TickStats of the tick, or None (dressing);
    stamp_s: the stamp published, s; marker_ms: the time the outputs took, ms; lag_ms: the
    newest pose received minus the simulated time, ms."""
    garment_sim = session.garment_sim
    values = {
        "step": str(session.steps),
        "marker_ms": f"{marker_ms:.3f}",
        "solver": str(session.solver),
        "tolerance": f"{garment_sim.solve_tolerance():.3e}",  # the level's (tolerance auto)
        "tolerance_setting": str(session.tolerance),
        "stamp_s": f"{stamp_s:.6f}",
        "particles": str(garment_sim.sim.model.n),
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
        "frames_skipped": str(session.frames.skipped),
        "resets": str(session.resets),
        "stream_restarts": str(counts.restarts),
        "kernels_compiled": str(session.compiles.count),
        "level": str(garment_sim.rung),  # the level of detail (the key predates "rung")
        "scene_particles": str(garment_sim.rung_particles(0)),
        "lod_switches": str(session.detail.switches if session.detail else 0),
        # the threads the steps ran on (fewer than `threads` while other work holds cores)
        "threads": str(garment_sim.run_threads or session.settings.threads),
        # the share of the process's threads' time spent waiting for a core over the tick
        # before (budget.contention; -1: unknown)
        "wait_share": f"{-1.0 if session.wait_share is None else session.wait_share:.3f}",
        "budget_ms": f"{session.budget_ms(session.pose_period()):.3f}",
        "mass_kg": f"{garment_sim.mass_kg:.6g}",
        # The cloth's largest force on a body segment (mean over the tick's steps), N.
        "contact_peak_n": f"{tick.contact_peak_n if tick else 0.0:.4f}",
        "contact_peak_segment": tick.contact_peak_segment if tick else "",
    }
    if session.auto_choice is not None:
        values["predicted_ms"] = f"{session.auto_choice.predicted_ms:.3f}"
    for kind, n in session.frames.counts.copy().items():
        values[f"skipped_{kind}"] = str(n)
    return values


def sheet_values(session, marker_ms: float) -> dict[str, str]:
    """The key-values of a sheet scene's status (besides the step's own figures). session:
    the LiveSession (its scene, solver, counters, grippers); marker_ms: the time the outputs
    took, ms."""
    values = {"step": str(session.steps), "marker_ms": f"{marker_ms:.3f}",
              "solver": str(session.solver),
              "tolerance": f"{float(session.tolerance):.3e}",
              "particles": str(session.scene.model.n),
              "mass_kg": f"{float(session.scene.model.mass.sum()):.6g}"}
    if session.desk is not None and session.desk.names:
        values.update(session.desk.values(session.sheet_grippers))
    return values


def status_notes(event: str, skipped_since: Counter, failed: int, rung: int,
                 particles: int, scene_particles: int) -> tuple[list[str], dict[str, int]]:
    """The status message's parts and the frames skipped since the last status (teleports are
    events, not skips). event: what the tick did besides stepping ('' if nothing); failed:
    simulation steps that failed since the last status; rung: the garment's level of detail
    (0: the scene's own mesh) of `particles` against the scene's `scene_particles`."""
    notes = [event] if event else []
    skipped_now = {k: n for k, n in skipped_since.items() if k != "teleport" and n}
    if skipped_now:
        notes.append("skipped since the last status: " + ", ".join(
            f"{k} {n}" for k, n in sorted(skipped_now.items())))
    if failed:
        notes.append(f"{failed} simulation step(s) failed")
    if rung:
        notes.append(f"level of detail {rung}: {particles} of the scene's "
                     f"{scene_particles} particles")
    return notes, skipped_now


def status_level(failed: int, skipped_now: dict[str, int], event: str, rung: int) -> bytes:
    """ERROR when a step failed; WARN after skipped frames, a re-anchoring or while the
    garment runs below its scene's level of detail; OK otherwise."""
    if failed:
        return DiagnosticStatus.ERROR
    if skipped_now or "re-anchored" in event or rung:
        return DiagnosticStatus.WARN
    return DiagnosticStatus.OK
