"""Bring a cloth test specimen to static rest with the project's own implicit steps.

The textile tests (cantilever, tensile strip, Cusick drape) read a shape at rest. The
specimen is stepped with implicit Euler (the most dissipative of the two schemes, which is
what a settle wants) under heavy air drag until it is at rest by two stated measures: the
kinetic energy per unit weight-height, KE / (m g L), and the fastest particle's speed in
lengths per second, |v|max / L, both below thresholds. L is the specimen's length scale.
A step that has reached rest is a fixed point of the linearised step only where the forces
balance, so a settled shape is the static equilibrium of the discrete model.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.sim.model import ClothModel, ClothState
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

# Rest thresholds: KE below 1e-10 of (weight x length) and no particle faster than 1e-4
# lengths per second (over a 1 s vibration period the shape would move < 0.01 % of L).
REST_ENERGY = 1e-10
REST_SPEED = 1e-4


@dataclass
class SettleResult:
    """How a settle ended. state: the final state; steps: steps taken; settled: both rest
    measures held; kinetic_ratio: KE / (m g L); speed_ratio: max |v| / L (1/s); wall_s."""

    state: ClothState
    steps: int
    settled: bool
    kinetic_ratio: float
    speed_ratio: float
    wall_s: float

    def as_dict(self) -> dict:
        return {"steps": self.steps, "settled": self.settled,
                "kinetic_ratio": self.kinetic_ratio, "speed_ratio": self.speed_ratio,
                "rest_energy_threshold": REST_ENERGY, "rest_speed_threshold": REST_SPEED,
                "wall_s": self.wall_s}


def settle(model: ClothModel, state: ClothState, solver, dt: float, length: float,
           max_steps: int = 4000, min_steps: int = 20, weight: float | None = None,
           rest_energy: float = REST_ENERGY, rest_speed: float = REST_SPEED,
           on_step=None) -> SettleResult:
    """Step ``model`` from ``state`` with implicit Euler steps of ``dt`` s until at rest.

    length: the specimen's length scale L, m. weight: m g in N for the energy measure
    (default: the model's total mass times |g|, or 1 N where there is no gravity).
    on_step(k, sim): optional callback after every step (for frames or progress).
    """
    sim = Simulator(model, state, solver, dt=dt, scheme="euler", track_energy=False)
    if weight is None:
        g = float(np.linalg.norm(model.gravity))
        weight = float(model.mass.sum()) * g if g > 0.0 else 1.0
    t0 = time.perf_counter()
    ke_ratio = speed_ratio = math.inf
    k = 0
    for k in range(1, max_steps + 1):
        sim.step()
        x, v = sim.state.x, sim.state.v
        if not np.all(np.isfinite(x)):
            raise FloatingPointError(f"settle: positions became non-finite at step {k}")
        ke_ratio = 0.5 * float(np.sum(model.mass[:, None] * v * v)) / (weight * length)
        speed_ratio = float(np.sqrt((v * v).sum(axis=1).max())) / length
        if on_step is not None:
            on_step(k, sim)
        if k >= min_steps and ke_ratio < rest_energy and speed_ratio < rest_speed:
            break
    settled = ke_ratio < rest_energy and speed_ratio < rest_speed
    return SettleResult(sim.state, k, settled, ke_ratio, speed_ratio, time.perf_counter() - t0)


def settle_specimen(model: ClothModel, state: ClothState, hierarchy: MeshHierarchy,
                    period: float, length: float, solver_name: str = "direct",
                    tol: float = 1e-6, max_steps: int = 3000, weight: float | None = None,
                    on_step=None) -> SettleResult:
    """Settle a specimen whose slowest mode has ``period`` s: implicit Euler steps of an
    eighth of it and air drag at about its angular frequency (a test reads a rest shape, not
    a motion, and this drag damps that mode in a period or two): the steps take a copy of
    the model whose material has that drag. The rest shape is the fixed point of the steps
    whatever solves them."""
    model = replace(model, material=replace(model.material, air_drag=2.0 * math.pi / period))
    solver = make_solver(solver_name, tol=tol, hierarchy=hierarchy, bending=model.bending)
    return settle(model, state, solver, dt=period / 8.0, length=length, max_steps=max_steps,
                  weight=weight, on_step=on_step)
