"""What a body scene's status on `cloth/stats` says besides its figures: its message's parts
and its level (pure functions; ros.body_scene calls them for each Frame it returns).
"""

from __future__ import annotations

from collections import Counter

from diagnostic_msgs.msg import DiagnosticStatus

__all__ = ["status_level", "status_notes"]


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
