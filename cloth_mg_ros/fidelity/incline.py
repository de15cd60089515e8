"""The incline: a sheet laid on a plane tilted by theta, under gravity, with Coulomb friction mu.

A rigid block on a slope stays where tan(theta) <= mu and otherwise slides down it at

    a = g (sin(theta) - mu cos(theta))

(Coulomb's law of friction; any mechanics text, e.g. Meriam and Kraige, Engineering Mechanics:
Dynamics, section 3/4). A sheet lying flat on the slope moves as one: every particle has the
same weight per unit mass and the same friction per unit normal load, so its elastic forces
stay zero and its centre of mass obeys the block's law exactly.

The scene: a square sheet (`mesh.generators.sheet_hierarchy`) turned onto the plane through
the origin with outward normal (sin theta, 0, cos theta), its particles at the contact
distance (ClothModel.thickness) above it, at rest; gravity -z; no air drag (the exact answer
has none). Down the slope is d = (cos theta, 0, -sin theta). The sheet is stepped for
``duration`` s by the chosen scheme; the centre of mass's distance along d, s(t), is fitted
from the first tenth of a second on by s0 + v0 t + a t^2 / 2 (linear least squares), and
``slid`` says whether it travelled more than SLID_TRAVEL over that window.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cloth_mg_ros.collision.colliders import RESTING, PlaneCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import MIN_PARTICLES, sheet_hierarchy
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.contact_friction import check_contact_friction
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver

GRAVITY = 9.81  # m/s^2, as sim.model.GRAVITY
DEFAULT_MATERIAL = "cotton"
DEFAULT_SIZE = 0.3  # m, the sheet's side
DEFAULT_PARTICLES = 200
DEFAULT_DT = 1.0 / 60.0  # s
DEFAULT_DURATION = 0.6  # s
MEASURE_FROM = 0.1  # s: the fit starts after the first tenth of a second
# m: travel along the slope over the fitted window that counts as sliding. Sticking leaves
# the sheet where it is to the solver's precision (1e-10 m and less, measured); a slide at
# the smallest acceleration the window resolves, 1e-3 m/s^2 over 0.5 s, covers 1.2e-4 m.
SLID_TRAVEL = 1e-4


@dataclass(frozen=True)
class InclineSpec:
    """An incline run: friction mu (Coulomb, >= 0), angle theta (degrees, 0 <= theta < 90),
    integrator scheme, step dt (s), duration (s), particles, material name, sheet side (m),
    generalised-alpha's spectral radius, solver name and tolerance, where friction acts
    (sim.model.CONTACT_FRICTIONS)."""

    friction: float
    angle_deg: float
    scheme: str = "bdf2"
    dt: float = DEFAULT_DT
    duration: float = DEFAULT_DURATION
    particles: int = DEFAULT_PARTICLES
    material: str = DEFAULT_MATERIAL
    size: float = DEFAULT_SIZE
    spectral_radius: float = DEFAULT_SPECTRAL_RADIUS
    solver: str = "direct"
    tol: float = 1e-8
    contact_friction: str = "projection"

    def __post_init__(self) -> None:
        def number(value) -> bool:
            return isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value)

        if not (number(self.friction) and self.friction >= 0.0):
            raise ClothInputError(f"incline: --friction must be a number >= 0, got "
                                  f"{self.friction!r}")
        if not (number(self.angle_deg) and 0.0 <= self.angle_deg < 90.0):
            raise ClothInputError(f"incline: --angle must be in degrees, 0 <= angle < 90, got "
                                  f"{self.angle_deg!r}")
        if self.scheme not in SCHEMES:
            raise ClothInputError(f"incline: --scheme must be one of {', '.join(SCHEMES)}, got "
                                  f"{self.scheme!r}")
        if not (number(self.dt) and self.dt > 0.0):
            raise ClothInputError(f"incline: --dt must be a positive number, got {self.dt!r}")
        if not (number(self.duration) and self.duration >= MEASURE_FROM + 4.0 * self.dt):
            raise ClothInputError(f"incline: --duration must be at least {MEASURE_FROM} s and "
                                  f"four steps, got {self.duration!r}")
        if isinstance(self.particles, bool) or not isinstance(self.particles, int) \
                or self.particles < MIN_PARTICLES:
            raise ClothInputError(f"incline: --particles must be an integer >= {MIN_PARTICLES}"
                                  f", got {self.particles!r}")
        check_contact_friction(self.contact_friction, "start")

    @property
    def theta(self) -> float:
        return math.radians(self.angle_deg)

    @property
    def exact_acceleration(self) -> float:
        """m/s^2 down the slope: 0 where tan(theta) <= mu, else g (sin - mu cos)."""
        if math.tan(self.theta) <= self.friction:
            return 0.0
        return GRAVITY * (math.sin(self.theta) - self.friction * math.cos(self.theta))


@dataclass
class InclineScene:
    """The built scene: hierarchy, model, initial state, and the unit vector down the slope."""

    spec: InclineSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    down: np.ndarray


def build_incline(spec: InclineSpec, material: Material | None = None) -> InclineScene:
    """The sheet of ``spec`` lying at rest on its slope (``material``: default the spec's,
    with air drag off either way)."""
    mat = replace(material or get_material(spec.material), air_drag=0.0)
    s, c = math.sin(spec.theta), math.cos(spec.theta)
    normal = np.array([s, 0.0, c])
    down = np.array([c, 0.0, -s])
    hier = sheet_hierarchy(spec.particles, None, spec.size, spec.size, plane="xy")
    flat = np.array(hier.levels[0].rest)  # z = 0
    rest = flat[:, :1] * down + flat[:, 1:2] * np.array([0.0, 1.0, 0.0])
    plane = PlaneCollider(np.zeros(3), normal, friction=spec.friction)
    model = build_model(hier.levels[0], mat, colliders=[plane],
                        gravity=np.array([0.0, 0.0, -GRAVITY]),
                        contact_friction=spec.contact_friction)
    rest += model.thickness * RESTING * normal  # where a projection leaves a resting particle
    return InclineScene(spec, hier, model, ClothState.at_rest(rest), down)


def run_incline(spec: InclineSpec, material: Material | None = None
                ) -> tuple[dict, InclineScene, np.ndarray]:
    """Build and step one incline; returns (the summary's "incline" block, the scene, the
    centre of mass's (steps + 1, 3) positions, m)."""
    scene = build_incline(spec, material)
    model = scene.model
    solver = make_solver(spec.solver, tol=spec.tol, hierarchy=scene.hierarchy,
                         bending=model.bending)
    sim = Simulator(model, scene.state, solver, dt=spec.dt, scheme=spec.scheme,
                    track_energy=False, spectral_radius=spec.spectral_radius)
    steps = round(spec.duration / spec.dt)
    weights = model.mass / model.mass.sum()
    centre = np.empty((steps + 1, 3))
    centre[0] = weights @ sim.state.x
    t0 = time.perf_counter()
    converged = True
    for k in range(1, steps + 1):
        stats = sim.step()
        converged = converged and stats.converged
        centre[k] = weights @ sim.state.x
    wall = time.perf_counter() - t0
    block = measure(spec, scene, centre)
    block.update({"particles": int(model.n), "material": model.material.name,
                  "all_converged": bool(converged), "wall_s": wall})
    return block, scene, centre


def measure(spec: InclineSpec, scene: InclineScene, centre: np.ndarray) -> dict:
    """The "incline" block from the centre of mass's positions (steps + 1, 3) m, one per step
    from the start: the fitted acceleration down the slope (m/s^2) from MEASURE_FROM s on,
    whether the sheet slid, and the exact answer."""
    t = spec.dt * np.arange(len(centre))
    along = (centre - centre[0]) @ scene.down
    lift = (centre - centre[0]) @ np.cross(scene.down, [0.0, 1.0, 0.0])
    window = t >= MEASURE_FROM - 1e-9 * spec.dt
    tw, sw = t[window], along[window]
    design = np.stack([np.ones_like(tw), tw, 0.5 * tw * tw], axis=1)
    coef, *_ = np.linalg.lstsq(design, sw, rcond=None)
    accel = float(coef[2])
    travel = float(sw[-1] - sw[0])
    exact = spec.exact_acceleration
    block = {
        "friction": spec.friction, "angle_deg": spec.angle_deg,
        "slid": bool(abs(travel) > SLID_TRAVEL),
        "acceleration_mps2": accel, "exact_acceleration_mps2": exact,
        "error_pct": 100.0 * (accel - exact) / exact if exact > 0.0 else None,
        "exact_slid": bool(math.tan(spec.theta) > spec.friction),
        "travel_m": travel, "fit_from_s": MEASURE_FROM,
        "fit_start": [float(coef[0]), float(coef[1])],
        "normal_drift_m": float(np.max(np.abs(lift))),
        "scheme": spec.scheme, "dt_s": spec.dt, "duration_s": spec.duration,
        "contact_friction": spec.contact_friction,
        "spectral_radius": spec.spectral_radius if spec.scheme == "genalpha" else None,
    }
    return block


def incline_picture(path: str | Path, spec: InclineSpec, centre: np.ndarray, block: dict,
                    scene: InclineScene) -> Path:
    """The centre of mass's distance down the slope against time, with the exact law's
    (the block's fit's start, s0 + v0 t, plus the exact a t^2 / 2) (PNG)."""
    # imported here: matplotlib (charts), loaded only when needed
    from cloth_mg_ros.fidelity.charts import chart_pyplot, save_chart_png

    plt = chart_pyplot()
    t = spec.dt * np.arange(len(centre))
    along = (centre - centre[0]) @ scene.down
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(t, 1e3 * along, "o", ms=3, label="simulated (centre of mass)")
    exact = block["exact_acceleration_mps2"]
    s0, v0 = block["fit_start"]
    ax.plot(t, 1e3 * (s0 + v0 * t + 0.5 * exact * t * t), "-", lw=1.0,
            label=f"exact a = {exact:.4g} m/s^2")
    ax.axvline(MEASURE_FROM, color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("time, s")
    ax.set_ylabel("distance down the slope, mm")
    ax.set_title(f"incline {spec.angle_deg:g} deg, mu {spec.friction:g}: {spec.scheme}, "
                 f"measured a = {block['acceleration_mps2']:.4g} m/s^2")
    ax.legend(fontsize=8)
    return save_chart_png(plt, fig, path)
