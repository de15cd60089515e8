"""The spinning tube: a cloth tube turning freely about its axis, no gravity, nothing to touch.

No external force acts, and the cloth's forces are internal and central (each face's pull
on its corners sums to zero, as does its moment), so the tube's angular momentum about its
axis is conserved exactly; started as a rigid rotation, it goes on turning at the same rate
(a turning ring stretches by rho v^2 / k to carry its centripetal load, 5e-5 for silk at
1 m/s, and turns on). An integrator that damps rotation shows it here alone, apart from contact and
friction: the capstan's strip (`fidelity.capstan`) turns about the cylinder's axis as it
slides, a sleeve about an arm.

The scene: a tube (`mesh.garments.sleeve.sleeve_hierarchy`) of radius RADIUS and length
LENGTH along y, at rest shape, every particle given the rim speed v across the axis
(v / r times the rigid rotation's field); air drag off. Measured: the share of the start's
angular momentum about the axis left after the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.sleeve import sleeve_hierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.model import ClothState, build_model
from cloth_mg_ros.sim.schemes import SCHEMES
from cloth_mg_ros.sim.simulator import Simulator, check_step_options
from cloth_mg_ros.solvers import make_solver

RADIUS = 0.05  # m: an arm's
LENGTH = 0.1  # m
DEFAULT_PARTICLES = 800
DEFAULT_DURATION = 0.1  # s


@dataclass(frozen=True)
class SpinSpec:
    """A spin: rim speed (m/s, > 0), material name, scheme, step dt (s), duration (s),
    particles, Newton iterations per step (sim.newton), where a step linearises the forces
    (sim.schemes.LINEARISE_AT), the fabric's damping force (sim.newton.DAMPING_MODELS)."""

    speed: float
    material: str = "silk"
    scheme: str = "bdf2"
    dt: float = 1.0 / 60.0
    duration: float = DEFAULT_DURATION
    particles: int = DEFAULT_PARTICLES
    newton: int = 1
    linearise_at: str = "start"
    damping_model: str = "stiffness"

    def __post_init__(self) -> None:
        for flag in ("speed", "dt", "duration"):
            value = getattr(self, flag)
            if isinstance(value, bool) or not (isinstance(value, (int, float))
                                               and math.isfinite(value) and value > 0.0):
                raise ClothInputError(f"spin: {flag} must be a positive number, got {value!r}")
        if self.scheme not in SCHEMES:
            raise ClothInputError(f"spin: scheme must be one of {', '.join(SCHEMES)}, got "
                                  f"{self.scheme!r}")
        get_material(self.material)  # names the unknown material
        check_step_options(self.scheme, self.newton, self.linearise_at, self.damping_model)


def angular_momentum(mass: np.ndarray, x: np.ndarray, v: np.ndarray) -> float:
    """The angular momentum about the y axis, kg m^2/s, of masses (n,) kg at x (n, 3) m
    moving at v (n, 3) m/s."""
    return float(np.sum(mass * (x[:, 2] * v[:, 0] - x[:, 0] * v[:, 2])))


def run_spin(spec: SpinSpec) -> dict:
    """Spin one tube; returns {"speed_mps", "material", "scheme", "dt_s", "duration_s",
    "particles", "kept": the share of the angular momentum left at the end (exact 1),
    "kept_trace": that share after every step}."""
    hier, _, _ = sleeve_hierarchy(spec.particles, LENGTH, RADIUS, (0.0, -0.5 * LENGTH, 0.0),
                                  (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    x = np.array(hier.finest.rest)
    v = (spec.speed / RADIUS) * np.stack([x[:, 2], np.zeros(len(x)), -x[:, 0]], axis=1)
    mat = replace(get_material(spec.material), air_drag=0.0)
    model = build_model(hier.finest, mat, colliders=[], gravity=np.zeros(3))
    solver = make_solver("direct", tol=1e-8, hierarchy=hier, bending=model.bending)
    sim = Simulator(model, ClothState(x, v), solver, dt=spec.dt, scheme=spec.scheme,
                    track_energy=False, newton_iterations=spec.newton,
                    linearise_at=spec.linearise_at,
                    damping_model=spec.damping_model)
    start = angular_momentum(model.mass, x, v)
    trace = []
    for _ in range(round(spec.duration / spec.dt)):
        sim.step()
        trace.append(angular_momentum(model.mass, sim.state.x, sim.state.v) / start)
    return {"speed_mps": spec.speed, "material": mat.name, "scheme": spec.scheme,
            "newton": spec.newton, "linearise_at": spec.linearise_at,
        "damping_model": spec.damping_model,
            "dt_s": spec.dt, "duration_s": spec.duration, "particles": int(model.n),
            "kept": trace[-1], "kept_trace": trace}
