"""The capstan: a strip hung over a rough horizontal cylinder, its two ends hanging free.

A flexible strip of weight w per unit length lying over a cylinder of radius r (its contact
radius: the cylinder's plus the cloth's contact distance) with hanging lengths L1 <= L2
carries T = w L at each tangent point. Where it is about to slide towards the long side,
every element of the half turn in contact, at angle phi from the top, balances its tension
T(phi), its weight and a normal force n = T / r + w cos(phi) per unit length with friction
mu n against the slide:

    dT/dphi = mu (T + w r cos(phi)) - w r sin(phi),

whose solution from T(-pi/2) = w L1 gives T(pi/2) = (w L1 + w b) e^(mu pi) + w b,
b = 2 mu r / (1 + mu^2). So the strip holds exactly where

    L2 <= (L1 + b) e^(mu pi) + b

(Euler 1762 and Eytelwein 1808 for a weightless rope, L2 / L1 <= e^(mu pi); the heavy
rope's terms from the same balance with the weight kept; any statics text, e.g. Meriam and
Kraige, Engineering Mechanics: Statics, section 6/9). Past it the strip slides; moving as one
inextensible body at speed v with L1 - s and L2 + s hanging, its acceleration a obeys the
same balance with the inertia and the centripetal load w v^2 / (g r) added to n:

    a / g = (L2 + s - (L1 - s + b) e^(mu pi) - b - (v^2 / g) (e^(mu pi) - 1))
            / (L2 + s + (L1 - s) e^(mu pi) + r (e^(mu pi) - 1) / mu),

(the last term pi r at mu = 0: the frictionless rope's (L2 - L1 + 2 s) g / L), valid while
the short end still hangs (s < L1).

The scene: a strip meshed flat (`mesh.generators.sheet_hierarchy`) laid isometrically over
the cylinder (a capsule along y at height HEIGHT) and down both sides, at rest; the part
over the cylinder is held for SETTLE s while the hanging parts settle under gravity (the
exact balance is for a strip already loaded: let go at once, its tension would overshoot
the static one by up to twice as a suddenly applied load does), then let go. Measured: the
slide s(t), the median over the particles of how far each has moved along the strip's path
(`path_coordinate`) since it was let go, against the exact s(t). A flexible strip is the
exact answer's; the default fabric (`silk`, bending length 7.7 mm) is a seventh of the
default radius.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from cloth_mg_ros.collision.capsules import CapsuleCollider
from cloth_mg_ros.collision.colliders import RESTING
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.generators import MIN_PARTICLES, sheet_hierarchy
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.contact_friction import check_contact_friction
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model
from cloth_mg_ros.sim.schemes import SCHEMES
from cloth_mg_ros.sim.simulator import Simulator, check_step_options
from cloth_mg_ros.solvers import make_solver

GRAVITY = 9.81  # m/s^2, as sim.model.GRAVITY
DEFAULT_MATERIAL = "silk"
DEFAULT_RADIUS = 0.05  # m, the cylinder's
DEFAULT_WIDTH = 0.04  # m, the strip's
DEFAULT_DT = 1.0 / 60.0  # s
DEFAULT_DURATION = 0.5  # s after the strip is let go
PARTICLES_PER_M2 = 12000  # the default mesh: edges of about 1 cm
SETTLE = 0.5  # s the part over the cylinder is held before it is let go
HEIGHT = 1.0  # m, the cylinder's axis above the floor
THICKNESS = 0.005  # m, the cloth's contact distance (ClothModel.thickness's default)
# m: a slide shorter than this over the run counts as holding. A strip that holds moves
# only by the creep of its settling (under 0.1 mm, measured); the slowest slide the window
# tells, 0.5 % of g over 0.5 s, covers 6 mm.
HOLD_TRAVEL = 1e-3
# m: how far a particle may stray from the strip's path (across it, in the plane of the
# turn) before the run stops counting as a strip over a cylinder: a strip that hangs off
# its path by more has wrapped round, fallen through or swung, and its slide means nothing.
OFF_PATH = 0.02
# %: how close a slide must come to the exact one to meet it (the exact answer's own
# assumptions, an inextensible strip with no bending, are good to about 1 % here)
SLIDE_TOLERANCE_PCT = 10.0


def contact_radius(radius: float) -> float:
    """Where a strip lies over a cylinder of ``radius`` m: that plus the contact distance,
    where the projection leaves a resting particle, m."""
    return radius + THICKNESS * RESTING


def hold_length(short: float, friction: float, radius: float) -> float:
    """The longest hanging length, m, that a strip with ``short`` m hanging on the other side
    holds over a cylinder of contact radius ``radius`` m with Coulomb coefficient
    ``friction`` (module docstring): (L1 + b) e^(mu pi) + b, b = 2 mu r / (1 + mu^2)."""
    b = 2.0 * friction * radius / (1.0 + friction * friction)
    return (short + b) * math.exp(friction * math.pi) + b


def exact_slide(short: float, long: float, friction: float, radius: float,
                times: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
    """The slide s(t), m, of an inextensible flexible strip let go from rest with ``short``
    and ``long`` m hanging (module docstring) at times (k,) s from 0: zero where it holds;
    NaN once the short end has come up to the cylinder (s >= short)."""
    from scipy.integrate import solve_ivp

    times = np.asarray(times, dtype=float)
    if long <= hold_length(short, friction, radius):
        return np.zeros_like(times)
    e = math.exp(friction * math.pi)
    b = 2.0 * friction * radius / (1.0 + friction * friction)
    arc = math.pi * radius if friction == 0.0 else radius * (e - 1.0) / friction

    def rhs(_t, y):
        s, v = y
        l1, l2 = short - s, long + s
        num = l2 - (l1 + b) * e - b - v * v / gravity * (e - 1.0)
        return [v, gravity * num / (l2 + l1 * e + arc)]

    def short_end_up(_t, y):
        return y[0] - short
    short_end_up.terminal = True

    sol = solve_ivp(rhs, (0.0, float(times.max(initial=0.0))), [0.0, 0.0], t_eval=times,
                    events=short_end_up, rtol=1e-10, atol=1e-13)
    out = np.full_like(times, np.nan)
    out[:len(sol.t)] = sol.y[0]
    return out


@dataclass(frozen=True)
class CapstanSpec:
    """A capstan run: Coulomb coefficient mu (>= 0), the short and long hanging lengths (m,
    0 < short <= long), the cylinder's radius and the strip's width (m), material name,
    scheme, step dt (s), duration after the let-go (s), particles (None: PARTICLES_PER_M2 of
    the strip), solver name and tolerance, Newton iterations per step (sim.newton), where a
    step linearises the forces (sim.schemes.LINEARISE_AT), the fabric's damping force
    (sim.newton.DAMPING_MODELS), where friction acts (sim.model.CONTACT_FRICTIONS)."""

    friction: float
    short: float
    long: float
    radius: float = DEFAULT_RADIUS
    width: float = DEFAULT_WIDTH
    material: str = DEFAULT_MATERIAL
    scheme: str = "bdf2"
    dt: float = DEFAULT_DT
    duration: float = DEFAULT_DURATION
    particles: int | None = None
    solver: str = "direct"
    tol: float = 1e-8
    newton: int = 1
    linearise_at: str = "start"
    damping_model: str = "stiffness"
    contact_friction: str = "projection"

    def __post_init__(self) -> None:
        def number(value) -> bool:
            return isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value)

        if not (number(self.friction) and self.friction >= 0.0):
            raise ClothInputError(f"capstan: --friction must be a number >= 0, got "
                                  f"{self.friction!r}")
        for flag in ("short", "long", "radius", "width", "dt", "duration"):
            value = getattr(self, flag)
            if not (number(value) and value > 0.0):
                raise ClothInputError(f"capstan: --{flag} must be a positive number, got "
                                      f"{value!r}")
        if self.long < self.short:
            raise ClothInputError(f"capstan: --long ({self.long:g} m) must be at least --short "
                                  f"({self.short:g} m)")
        if self.scheme not in SCHEMES:
            raise ClothInputError(f"capstan: --scheme must be one of {', '.join(SCHEMES)}, got "
                                  f"{self.scheme!r}")
        if self.particles is not None and (isinstance(self.particles, bool) or not isinstance(
                self.particles, int) or self.particles < MIN_PARTICLES):
            raise ClothInputError(f"capstan: --particles must be an integer >= {MIN_PARTICLES}"
                                  f", got {self.particles!r}")
        get_material(self.material)  # names the unknown material
        check_step_options(self.scheme, self.newton, self.linearise_at, self.damping_model)
        check_contact_friction(self.contact_friction, self.linearise_at)

    @property
    def contact_radius(self) -> float:
        """m: where the strip lies (`contact_radius`)."""
        return contact_radius(self.radius)

    @property
    def strip_length(self) -> float:
        return self.short + math.pi * self.contact_radius + self.long

    @property
    def particle_count(self) -> int:
        if self.particles is not None:
            return self.particles
        return max(MIN_PARTICLES, round(PARTICLES_PER_M2 * self.strip_length * self.width))


def path_point(u: np.ndarray, spec: CapstanSpec) -> np.ndarray:
    """Where the point u (k,) m along the strip's path lies (k, 3) m: up the short side
    (x = -r), over the cylinder, down the long side (x = +r); y across the strip."""
    r, l1 = spec.contact_radius, spec.short
    u = np.asarray(u, dtype=float)
    out = np.zeros((len(u), 3))
    phi = np.clip((u - l1) / r, 0.0, math.pi) - 0.5 * math.pi
    out[:, 0] = r * np.sin(phi)
    out[:, 2] = HEIGHT + r * np.cos(phi)
    up, down = u < l1, u > l1 + math.pi * r
    out[up, 2] = HEIGHT - (l1 - u[up])
    out[down, 2] = HEIGHT - (u[down] - l1 - math.pi * r)
    return out


def off_path(x: np.ndarray, spec: CapstanSpec) -> float:
    """The farthest any point of x (k, 3) m lies from the strip's path, in the plane of the
    turn (y left out), m."""
    x = np.asarray(x, dtype=float)
    gap = (x - path_point(path_coordinate(x, spec), spec))[:, [0, 2]]
    return float(np.max(np.linalg.norm(gap, axis=1), initial=0.0))


def path_coordinate(x: np.ndarray, spec: CapstanSpec) -> np.ndarray:
    """How far along the strip's path (m, `path_point`'s u) the points x (k, 3) m lie: by
    their angle about the axis above it, by their height below it."""
    r, l1 = spec.contact_radius, spec.short
    x = np.asarray(x, dtype=float)
    above = x[:, 2] >= HEIGHT
    phi = np.arctan2(x[:, 0], x[:, 2] - HEIGHT)
    u = np.where(x[:, 0] < 0.0, l1 - (HEIGHT - x[:, 2]),
                 l1 + math.pi * r + (HEIGHT - x[:, 2]))
    return np.where(above, l1 + (phi + 0.5 * math.pi) * r, u)


@dataclass
class CapstanScene:
    """The built scene: hierarchy, model, initial state, the particles held while the strip
    settles (those over the cylinder) and each particle's place along the path (n,) m."""

    spec: CapstanSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    held: np.ndarray
    along: np.ndarray


def build_capstan(spec: CapstanSpec, material: Material | None = None) -> CapstanScene:
    """The strip of ``spec`` laid over its cylinder at rest (``material``: default the
    spec's; air drag off either way: the exact answer has none)."""
    mat = replace(material or get_material(spec.material), air_drag=0.0)
    hier = sheet_hierarchy(spec.particle_count, None, spec.strip_length, spec.width,
                           plane="xy")
    flat = np.array(hier.levels[0].rest)
    along = flat[:, 0] - flat[:, 0].min()
    x = path_point(along, spec)
    x[:, 1] = flat[:, 1]
    half = 0.5 * spec.width + 4.0 * spec.radius  # the cylinder reaches past both edges
    cylinder = CapsuleCollider(np.array([spec.radius]), friction=spec.friction)
    pose = cylinder.moved(None, np.array([[0.0, -half, HEIGHT]]),
                          np.array([[0.0, half, HEIGHT]]))
    model = build_model(hier.levels[0], mat, colliders=[cylinder],
                        gravity=np.array([0.0, 0.0, -GRAVITY]), thickness=THICKNESS,
                        contact_friction=spec.contact_friction)
    state = ClothState.at_rest(x)
    state.bodies = {0: pose}
    over = (along >= spec.short) & (along <= spec.short + math.pi * spec.contact_radius)
    return CapstanScene(spec, hier, model, state, np.flatnonzero(over), along)


def run_capstan(spec: CapstanSpec, material: Material | None = None
                ) -> tuple[dict, CapstanScene, np.ndarray, np.ndarray]:
    """Build, settle held, let go and step one capstan; returns (the summary's "capstan"
    block, the scene, times (k,) s since the let-go and the measured slide (k,) m)."""
    scene = build_capstan(spec, material)
    model = scene.model
    solver = make_solver(spec.solver, tol=spec.tol, hierarchy=scene.hierarchy,
                         bending=model.bending)
    sim = Simulator(model, scene.state, solver, dt=spec.dt, scheme=spec.scheme,
                    track_energy=False, newton_iterations=spec.newton,
                    linearise_at=spec.linearise_at,
                    damping_model=spec.damping_model)
    sim.control.pinned = scene.held
    converged = True
    for _ in range(round(SETTLE / spec.dt)):
        converged = sim.step().converged and converged
    sim.control.pinned = np.zeros(0, np.int64)
    start = path_coordinate(sim.state.x, spec)
    steps = round(spec.duration / spec.dt)
    slide = np.zeros(steps + 1)
    stray = np.full(steps + 1, np.inf)  # a step that failed strays without bound
    stray[0] = off_path(sim.state.x, spec)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        converged = sim.step().converged and converged
        if not np.isfinite(sim.state.x).all():
            slide[k:] = np.nan
            break
        slide[k] = float(np.median(path_coordinate(sim.state.x, spec) - start))
        stray[k] = off_path(sim.state.x, spec)
    wall = time.perf_counter() - t0
    times = spec.dt * np.arange(steps + 1)
    block = measure(spec, times, slide, stray)
    block.update({"particles": int(model.n), "material": model.material.name,
                  "all_converged": bool(converged), "wall_s": wall})
    return block, scene, times, slide


def measure(spec: CapstanSpec, times: np.ndarray, slide: np.ndarray,
            stray: float | np.ndarray = 0.0) -> dict:
    """The "capstan" block from the measured slide (k,) m at times (k,) s since the let-go
    and how far any particle strayed from the path (m, `off_path`; (k,) at those times, or
    the farthest over the run): whether the strip stayed on its path and held, its slide
    against the exact one over the part of the run where the short end still hangs (the
    exact slide under 0.8 of it) and the hold length. Where the strip must slide, the path
    counts over that part only: past it the short end comes over the top, where the strip
    has no path to stay on (`off_path_after_m` keeps how far it strayed there)."""
    exact = exact_slide(spec.short, spec.long, spec.friction, spec.contact_radius, times)
    hold = hold_length(spec.short, spec.friction, spec.contact_radius)
    exact_held = spec.long <= hold
    valid = np.flatnonzero(np.isfinite(exact) & (exact < 0.8 * spec.short))
    last = int(valid[-1]) if len(valid) else 0
    end = float(slide[last])
    ex = float(exact[last])
    error = 100.0 * (end - ex) / ex if ex > 0.0 else None
    strays = np.broadcast_to(np.asarray(stray, dtype=float), np.shape(times))
    span = len(times) if exact_held else last + 1
    within = float(np.max(strays[:span], initial=0.0))
    after = float(np.max(strays[span:], initial=0.0))
    on_path = within < OFF_PATH
    held = bool(on_path and np.isfinite(slide).all() and abs(float(slide[-1])) < HOLD_TRAVEL)
    meets = on_path and (held if exact_held else
                         (error is not None and abs(error) <= SLIDE_TOLERANCE_PCT))
    return {
        "friction": spec.friction, "short_m": spec.short, "long_m": spec.long,
        "radius_m": spec.radius, "contact_radius_m": spec.contact_radius,
        "width_m": spec.width, "hold_long_m": hold, "load_ratio": spec.long / hold,
        "exact_held": bool(exact_held), "on_path": bool(on_path), "off_path_m": within,
        "off_path_after_m": after,
        "held": held, "slide_m": end, "exact_slide_m": ex, "at_s": float(times[last]),
        "slide_error_pct": error, "meets_exact": bool(meets),
        "final_slide_m": float(slide[-1]),
        "scheme": spec.scheme, "dt_s": spec.dt, "duration_s": spec.duration,
        "newton": spec.newton, "linearise_at": spec.linearise_at,
        "damping_model": spec.damping_model, "contact_friction": spec.contact_friction,
        "settle_s": SETTLE,
    }


def capstan_picture(path: str | Path, spec: CapstanSpec, times: np.ndarray,
                    slide: np.ndarray, block: dict) -> None:
    """frames.png: the measured slide against the exact one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fine = np.linspace(0.0, float(times[-1]), 400)
    exact = exact_slide(spec.short, spec.long, spec.friction, spec.contact_radius, fine)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(fine, 1e3 * exact, "k--", label="exact (flexible, inextensible strip)")
    ax.plot(times, 1e3 * slide, "C0", label=f"measured ({block['particles']} particles)")
    ax.set_xlabel("time since let go, s")
    ax.set_ylabel("slide towards the long side, mm")
    ax.set_title(f"capstan: mu {spec.friction:g}, hanging {1e3 * spec.short:.0f} / "
                 f"{1e3 * spec.long:.0f} mm (holds to {1e3 * block['hold_long_m']:.0f})",
                 fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
