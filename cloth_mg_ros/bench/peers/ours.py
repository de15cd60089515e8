"""``ours:mpcg``, ``ours:mg``: this project's solver on the drape scene (BDF2, one linearised
solve per step, tol 1e-4)."""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.bench.peers.scene import DrapeSpec
from cloth_mg_ros.sim.forces import Workspace
from cloth_mg_ros.sim.integrator import assemble_step, finish_step
from cloth_mg_ros.sim.model import ClothState
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver


class _OursEngine:
    """This project's simulator, stepping with assemble / solve / finish as `Simulator.step`
    does, with a Workspace reused step after step (the per-step energy diagnostics of
    `Simulator.step` are left out, as they are for the peers)."""

    def __init__(self, spec: DrapeSpec, solver: str, settings: dict):
        scene = spec.scene
        lin = make_solver(solver, tol=float(settings["tol"]), hierarchy=scene.hierarchy,
                          bending=scene.model.bending)
        self.sim = Simulator(scene.model, ClothState.at_rest(spec.rest), lin, dt=spec.dt,
                             scheme="bdf2")
        # the large arrays reused step after step, as Simulator.step's stepper does (its own
        # is private; this engine never calls Simulator.step, so one of its own is the same)
        self.work = Workspace()
        self.mass_kg = float(scene.model.mass.sum())
        self.iterations: list[int] = []

    def step(self) -> None:
        sim = self.sim
        system = assemble_step(sim.model, sim.state, sim.dt, sim.scheme, None, self.work)
        result = sim.solver.solve(system.system, system.rhs, system.x0, system.fixed,
                                  floor=system.weight_impulse)  # as Simulator.step solves
        sim.state, _, _ = finish_step(sim.model, sim.state, system, result.x, sim.dt)
        self.iterations.append(int(result.iterations))

    def positions(self) -> np.ndarray:
        return self.sim.state.x
