"""What a garment's tick reports: its figures (`TickStats`) and the loads the body receives
from the cloth over its steps (`BodyLoads`, summed for their mean)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.sim.loads import ContactLoad

BODY_COLLIDER = 0  # the body's capsules: the first of the model's colliders (the floor after)


@dataclass
class TickStats:
    """One tick's figures: times in ms, penetration in m (after the step); substeps: the
    linear solves (steps) of the tick; poses: the key poses it followed; simulated_s: the
    simulated time it advanced (s).

    body_forces {segment: [fx, fy, fz] N}: the force of the cloth on each body segment it
    collides with, averaged over the tick's steps (sim.loads: penalty and projection with
    friction); body_torques {segment: [tx, ty, tz] N m} about the segment's origin;
    contact_peak_n, contact_peak_segment: the largest of those forces and its segment.
    gripper_wrenches {name: {"force", "torque"}}: on each gripper at the tick's last step
    (N, N m about the grasp point); released: grippers that let go by release_force.
    seam_forces {segment: [fx, fy, fz] N}: the force of the garment on each segment it is
    sewn to (its pins' holding forces, the dress's weight on the shoulders), mean over the
    tick's steps: with body_forces and gravity, what the body carries.
    self_contact_dropped: the cloth-cloth pairs the self-contact search left out past its
    cap, summed over the tick's steps (StepStats.self_contact_dropped).
    contact_pull_n N: what the penalty contacts pulled the cloth onto the colliders with
    (sim.loads.ContactLoad.pull), the mean over the tick's steps: 0 for a contact that only
    pushes."""

    stamp: float
    total_ms: float
    solve_ms: float
    iterations: int
    rel_residual: float
    converged: bool
    max_penetration: float
    contacts: int
    substeps: int
    kinetic_energy: float
    poses: int = 1
    simulated_s: float = 0.0
    body_forces: dict = field(default_factory=dict)
    body_torques: dict = field(default_factory=dict)
    contact_peak_n: float = 0.0
    contact_peak_segment: str = ""
    gripper_wrenches: dict = field(default_factory=dict)
    released: list = field(default_factory=list)
    seam_forces: dict = field(default_factory=dict)
    self_contact_dropped: int = 0
    contact_pull_n: float = 0.0


class BodyLoads:
    """What a body receives from the cloth over a tick's steps, summed for the mean over
    them: the contact forces and torques on its colliding segments (TickStats.body_forces,
    body_torques) and the forces through the seams that sew the garment to its segments
    (TickStats.seam_forces)."""

    def __init__(self, colliding: int, segments: int):
        self.force = np.zeros((colliding, 3))
        self.torque = np.zeros((colliding, 3))
        self.seam = np.zeros((segments, 3))
        self.pull = 0.0
        self.steps = 0

    def add(self, load: ContactLoad, origins: np.ndarray, pin_segments: np.ndarray,
            holding: np.ndarray) -> None:
        """One step's contact load; origins (colliding, 3) m: the colliding segments' origins
        at its end; pin_segments (k,): each pin's segment; holding (k, 3) N: the force that
        held each pin on the cloth (the seam pulls its segment the other way)."""
        self.force += load.per_part(BODY_COLLIDER, len(self.force))
        self.torque += load.torques(BODY_COLLIDER, origins)
        np.add.at(self.seam, pin_segments, -holding)
        self.pull += load.pull
        self.steps += 1

    def result(self, names: list[str], colliding: np.ndarray) -> tuple[dict, dict, float, str]:
        """({segment: mean force [N]}, {segment: mean torque [N m]}, the largest force's
        magnitude N, its segment ('' when there is none)) of the colliding segments
        (indices into names)."""
        if not self.steps:
            return {}, {}, 0.0, ""
        names = [names[i] for i in colliding]
        force, torque = self.force / self.steps, self.torque / self.steps
        size = np.linalg.norm(force, axis=1)
        k = int(np.argmax(size)) if len(size) else -1
        peak, where = (float(size[k]), names[k]) if k >= 0 and size[k] > 0.0 else (0.0, "")
        return ({n: f.tolist() for n, f in zip(names, force, strict=True)},
                {n: t.tolist() for n, t in zip(names, torque, strict=True)}, peak, where)

    def pull_n(self) -> float:
        """N: the steps' mean pull of the penalty contacts (ContactLoad.pull)."""
        return self.pull / max(self.steps, 1)

    def seams(self, names: list[str], sewn: np.ndarray) -> dict:
        """{segment: mean seam force [N]} of the sewn segments (indices into names)."""
        return {names[i]: (self.seam[i] / max(self.steps, 1)).tolist() for i in sewn}


@dataclass
class StepTally:
    """A tick's figures summed over its steps (TickStats' solve and contact fields)."""

    solve_ms: float = 0.0
    iterations: int = 0
    worst: float = 0.0
    converged: bool = True
    penetration: float = 0.0
    contacts: int = 0
    self_contact_dropped: int = 0

    def add(self, stats) -> None:
        """Count one step's StepStats."""
        self.solve_ms += stats.solve_ms
        self.iterations += stats.iterations
        self.worst = max(self.worst, stats.rel_residual)
        self.converged = self.converged and stats.converged
        self.penetration = max(self.penetration, stats.max_penetration)
        self.contacts = max(self.contacts, stats.contacts)
        self.self_contact_dropped += stats.self_contact_dropped
