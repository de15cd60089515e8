"""The swing: a strip hung from a clamp along its top edge, swinging freely in its first mode.

A hanging strip whose bending length (B / (rho g))^(1/3) is small against its length L
swings out of its plane as a heavy chain. With s the height above the free end, the
tension is rho g s per unit width and the transverse motion y(s, t) obeys
rho y_tt = (rho g s y_s)_s, whose modes, finite at s = 0 and zero at the clamp s = L, are

    y_n(s) = J0(j0_n sqrt(s / L)),   f_n = j0_n / (4 pi) sqrt(g / L)

with j0_n the zeros of the Bessel function J0 (2.404826, 5.520078, ...; Daniel Bernoulli
1733, Euler 1736; Rayleigh, The Theory of Sound, section 54). L = 0.5 m: f_1 = 0.8477 Hz.
The chain's operator is of Sturm-Liouville form with a uniform weight, so its modes are
orthogonal under the mass: the first mode's coordinate q(t) is the mass-weighted projection
of the sideways displacement onto y_1.

The scene: the strip is meshed flat (`strips.strip_hierarchy`, x from the clamp along the
strip, y across it) and hung with x pointing down (world z = -x, world x = the strip's y,
world y = out of its plane); its top row (x = 0) is pinned. It is settled under gravity
(`settle.settle_specimen`, implicit Euler with air drag); it stretches under its own
weight, so it is cut to the length that hangs at L (`HANG_TOLERANCE`). The settled strip is
displaced by A y_1(s) out of its plane, s the height above its free end, each particle
lifted so that the displaced strip keeps its settled length (a pure sideways shift would
stretch it by (A y_1')^2 / 2, which at A = 2 cm on a 0.5 m woven strip puts more energy
into the stretch modes than the swing has), and released from rest with no air drag. The
fabric's own stiffness-proportional damping (Material.damping) stays; a second run with it
set to zero tells the integrator's damping from the fabric's.

Measured: the damped cosine a exp(-sigma t) cos(omega t + phase) + c fitted to q(t) by
least squares (scipy.optimize.curve_fit): frequency omega / 2 pi, damping ratio
sigma / sqrt(sigma^2 + omega^2); and the mechanical energy (kinetic + gravity + elastic,
relative to the settled rest state) left at the end as a share of the start's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import curve_fit
from scipy.special import j0, j1, jn_zeros

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.elastica import GRAVITY
from cloth_mg_ros.fidelity.settle import SettleResult, settle_specimen
from cloth_mg_ros.fidelity.strips import strip_hierarchy
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.integrator import energies
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, SCHEMES
from cloth_mg_ros.sim.simulator import Simulator, check_step_options
from cloth_mg_ros.solvers import make_solver

# A woven tablecloth fabric: stiff in stretch (4000 N/m, so the strip hangs 0.016 % longer at
# the top at L = 0.5 m) with a bending length of 2.0 cm, 4 % of the default length.
DEFAULT_MATERIAL = "white-dots-on-blk"
DEFAULT_LENGTH = 0.5  # m
DEFAULT_WIDTH = 0.05  # m
# The free end's sideways start, as a share of L. The step is linearised once (Baraff and
# Witkin), and the stretch springs' turning then damps the swing by a share growing with A^2
# and about h^3 (BDF2, 1/60 s, fabric damping off: damping ratio 4.5e-4 / 1.2e-3 / 4.0e-3 /
# 1.6e-2 at A = 0.5 / 1 / 2 / 5 cm, L = 0.5 m; at 1/240 s 2e-5 at 1 cm): 2 % of L keeps
# the measurement that of the linear swing the chain's answer is for.
DEFAULT_AMPLITUDE_FRACTION = 0.02
DEFAULT_PERIODS = 5.0  # default duration, in periods of the exact chain's first mode
DEFAULT_PARTICLES = 200  # the swing is one-dimensional: 150 and 800 agree to 0.02 %
DEFAULT_DT = 1.0 / 60.0  # s
MAX_AMPLITUDE_FRACTION = 0.2  # of L: the chain's modes are those of small motion
MIN_PERIODS = 2.0  # the fit needs two periods of the swing
_SOLVE_TOL = 1e-8  # the direct solver ignores it; kept for a solver that does not


def chain_frequency(length: float, mode: int = 1, gravity: float = GRAVITY) -> float:
    """The heavy chain's mode ``mode`` (1, 2, ...) frequency, Hz, for a chain of ``length`` m:
    j0_n / (4 pi) sqrt(g / L)."""
    if not (isinstance(length, (int, float)) and math.isfinite(length) and length > 0.0):
        raise ClothInputError(f"swing: the length must be a positive number, got {length!r}")
    if isinstance(mode, bool) or not isinstance(mode, int) or mode < 1:
        raise ClothInputError(f"swing: the mode must be an integer >= 1, got {mode!r}")
    return float(jn_zeros(0, mode)[-1]) / (4.0 * math.pi) * math.sqrt(gravity / length)


def chain_mode(s: np.ndarray, length: float, mode: int = 1) -> np.ndarray:
    """The chain's mode shape J0(j0_n sqrt(s / L)) at heights s (k,) m above the free end."""
    zero = float(jn_zeros(0, mode)[-1])
    return j0(zero * np.sqrt(np.clip(np.asarray(s, dtype=float) / length, 0.0, None)))


def chain_mode_slope(s: np.ndarray, length: float) -> np.ndarray:
    """d/ds of the first mode shape at heights s (k,) m, 1/m (zero at the free end's limit
    is -j0_1^2 / (4 L), finite)."""
    zero = float(jn_zeros(0, 1)[0])
    r = np.sqrt(np.clip(np.asarray(s, dtype=float) / length, 1e-300, None))
    return -j1(zero * r) * zero / (2.0 * length * r)


@dataclass(frozen=True)
class SwingSpec:
    """A swing: material name, strip length and width (m), the free end's sideways start
    amplitude (m; None: DEFAULT_AMPLITUDE_FRACTION of the length), scheme, step dt (s),
    duration (s; None: DEFAULT_PERIODS periods of the exact chain), particles, genalpha's
    spectral radius (None: the integrator's default), whether the fabric keeps its
    stiffness-proportional damping, Newton iterations per step (sim.newton) and where a step
    linearises the forces (sim.schemes.LINEARISE_AT) and the fabric's damping force
    (sim.newton.DAMPING_MODELS)."""

    material: str = DEFAULT_MATERIAL
    length: float = DEFAULT_LENGTH
    width: float = DEFAULT_WIDTH
    amplitude: float | None = None
    scheme: str = "bdf2"
    dt: float = DEFAULT_DT
    duration: float | None = None
    particles: int = DEFAULT_PARTICLES
    spectral_radius: float | None = None
    fabric_damping: bool = True
    newton: int = 1
    linearise_at: str = "start"
    damping_model: str = "stiffness"

    def __post_init__(self) -> None:
        get_material(self.material)  # names the unknown material
        check_step_options(self.scheme, self.newton, self.linearise_at, self.damping_model)
        for flag in ("length", "width", "amplitude", "dt"):
            value = getattr(self, flag)
            if flag == "amplitude" and value is None:
                continue
            if isinstance(value, bool) or not (isinstance(value, (int, float))
                                               and math.isfinite(value) and value > 0.0):
                raise ClothInputError(f"swing: --{flag} must be a positive number, got "
                                      f"{value!r}")
        if self.start_amplitude > MAX_AMPLITUDE_FRACTION * self.length:
            raise ClothInputError(
                f"swing: --amplitude {self.start_amplitude:g} m is not a small displacement of a "
                f"{self.length:g} m strip (at most {MAX_AMPLITUDE_FRACTION:g} of --length)")
        if self.scheme not in SCHEMES:
            raise ClothInputError(f"swing: --scheme must be one of {', '.join(SCHEMES)}, got "
                                  f"{self.scheme!r}")
        period = 1.0 / chain_frequency(self.length)
        if self.dt > period / 4.0:
            raise ClothInputError(f"swing: --dt {self.dt:g} s is more than a quarter of the "
                                  f"swing's period ({period:.3g} s)")
        if self.duration is not None:
            d = self.duration
            if isinstance(d, bool) or not (isinstance(d, (int, float)) and math.isfinite(d)):
                raise ClothInputError(f"swing: --duration must be a number, got {d!r}")
            if d < MIN_PERIODS * period:
                raise ClothInputError(
                    f"swing: --duration {d:g} s is under {MIN_PERIODS:g} periods of the "
                    f"swing ({MIN_PERIODS * period:.3g} s at --length {self.length:g} m)")
        if isinstance(self.particles, bool) or not isinstance(self.particles, (int, np.integer)) \
                or self.particles < 16:
            raise ClothInputError(f"swing: --particles must be an integer >= 16, got "
                                  f"{self.particles!r}")
        r = self.spectral_radius
        if r is not None and (isinstance(r, bool) or not isinstance(r, (int, float))
                              or not 0.0 <= r <= 1.0):
            raise ClothInputError(f"swing: --spectral-radius must be in [0, 1], got {r!r}")

    @property
    def exact_frequency(self) -> float:
        return chain_frequency(self.length)

    @property
    def start_amplitude(self) -> float:
        """The free end's sideways start, m."""
        if self.amplitude is not None:
            return float(self.amplitude)
        return DEFAULT_AMPLITUDE_FRACTION * self.length

    @property
    def run_duration(self) -> float:
        """The simulated time, s."""
        if self.duration is not None:
            return float(self.duration)
        return DEFAULT_PERIODS / self.exact_frequency


@dataclass
class SwingScene:
    """The built, settled scene: hierarchy, model (air drag off, the fabric's damping as the
    spec says), the settled rest state, its potential energy (J), the displaced start, each
    particle's height above the settled free end s (n,) m, the first mode's shape phi (n,)
    there, and the strip's rest length (m: the length that hangs at the spec's length)."""

    spec: SwingSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    rest: ClothState
    rest_potential: float
    start: ClothState
    s: np.ndarray
    phi: np.ndarray
    settle: SettleResult
    rest_length: float


def _hang(flat: np.ndarray) -> np.ndarray:
    """World positions (n, 3) of the flat strip's (x along it, y across): x down, y along
    world x, the strip's plane the world's xz plane."""
    return np.stack([flat[:, 1], np.zeros(len(flat)), -flat[:, 0]], axis=1)


def displaced(spec: SwingSpec, rest_x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The settled positions rest_x (n, 3) m displaced by amplitude * y_1(s) out of the
    strip's plane (world y), s (n,) m the heights above the free end, each lifted by
    int_s^L (1 - sqrt(1 - (A y_1')^2)) ds' so that the strip keeps its settled length (to
    within its settled strain times (A y_1')^2)."""
    length, amp = spec.length, spec.start_amplitude
    grid = np.linspace(0.0, length, 4001)
    slope = amp * chain_mode_slope(grid, length)
    gap = 1.0 - np.sqrt(1.0 - np.minimum(slope * slope, 1.0))
    below_clamp = cumulative_trapezoid(gap[::-1], grid, initial=0.0)[::-1]
    x = rest_x.copy()
    x[:, 1] += amp * chain_mode(s, length)
    x[:, 2] += np.interp(s, grid, below_clamp)
    return x


# The strip is cut so that it hangs at the spec's length: a knit stretches by up to a few %
# under its own weight (gray-interlock, 2 m: 5.2 %), which the chain's answer for the cut
# length would count as a 2.6 % frequency error. Passes of cut, hang and settle until the
# hanging length is within this share of the spec's.
HANG_TOLERANCE = 1e-3
_HANG_PASSES = 5


def build_swing(spec: SwingSpec) -> SwingScene:
    """Mesh, hang, settle and displace the strip of ``spec`` (the module docstring)."""
    base = get_material(spec.material)
    period = 1.0 / spec.exact_frequency
    rest_length = spec.length
    for _ in range(_HANG_PASSES):
        hier = strip_hierarchy("lattice", 0.0, rest_length, spec.width, spec.particles)
        flat = np.array(hier.finest.rest)
        held = np.flatnonzero(flat[:, 0] <= 1e-9 * rest_length)
        model = build_model(hier.finest, base, pinned=held,
                            gravity=np.array([0.0, 0.0, -GRAVITY]))
        settled = settle_specimen(model, ClothState.at_rest(_hang(flat)), hier, period,
                                  spec.length)
        hanging = -float(np.min(settled.state.x[:, 2]))
        if abs(hanging / spec.length - 1.0) <= HANG_TOLERANCE:
            break
        rest_length *= spec.length / hanging
    model = replace(model, material=replace(
        base, air_drag=0.0, damping=base.damping if spec.fabric_damping else 0.0))
    rest = ClothState.at_rest(settled.state.x)
    rest_potential = energies(model, rest)[1]
    s = rest.x[:, 2] + hanging
    start = ClothState.at_rest(displaced(spec, rest.x, s))
    phi = chain_mode(s, spec.length)
    return SwingScene(spec, hier, model, rest, rest_potential, start, s, phi, settled,
                      rest_length)


def make_simulator(model: ClothModel, state: ClothState, hierarchy: MeshHierarchy,
                   spec: SwingSpec) -> Simulator:
    """A direct-solver simulator of ``spec``'s scheme, step and spectral radius."""
    solver = make_solver("direct", tol=_SOLVE_TOL, hierarchy=hierarchy, bending=model.bending)
    kwargs = {}
    if spec.scheme == "genalpha" and spec.spectral_radius is not None:
        kwargs["spectral_radius"] = float(spec.spectral_radius)
    return Simulator(model, state.copy(), solver, dt=spec.dt, scheme=spec.scheme,
                     track_energy=True, newton_iterations=spec.newton,
                     linearise_at=spec.linearise_at,
                     damping_model=spec.damping_model, **kwargs)


@dataclass
class SwingRun:
    """A swing's record: times t (k,) s, modal coordinate q (k,) m, mechanical energy
    energy (k,) J above the rest state, the step's median wall time and median CPU time of
    the stepping thread (s: on a shared machine the wall time also counts the others'
    work), and the whole stepping's wall time (s)."""

    t: np.ndarray
    q: np.ndarray
    energy: np.ndarray
    median_step_s: float
    wall_s: float
    median_step_cpu_s: float = math.nan


def simulate(scene: SwingScene) -> SwingRun:
    """Step the displaced strip for the spec's duration, recording q and the energy."""
    spec, model = scene.spec, scene.model
    sim = make_simulator(model, scene.start, scene.hierarchy, spec)
    steps = max(1, round(spec.run_duration / spec.dt))
    weights = model.mass * scene.phi
    norm = float(np.sum(weights * scene.phi))
    y_rest = scene.rest.x[:, 1]
    t = np.zeros(steps + 1)
    q = np.zeros(steps + 1)
    energy = np.zeros(steps + 1)
    kinetic, potential = energies(model, sim.state)
    q[0] = float(weights @ (sim.state.x[:, 1] - y_rest)) / norm
    energy[0] = kinetic + potential - scene.rest_potential
    step_s = np.zeros(steps)
    cpu_s = np.zeros(steps)
    t_start = time.perf_counter()
    for k in range(1, steps + 1):
        t0, c0 = time.perf_counter(), time.thread_time()
        stats = sim.step()
        step_s[k - 1] = time.perf_counter() - t0
        cpu_s[k - 1] = time.thread_time() - c0
        x = sim.state.x
        if not np.all(np.isfinite(x)):
            raise FloatingPointError(f"swing: positions became non-finite at step {k} "
                                     f"({spec.scheme}, dt {spec.dt:g} s)")
        t[k] = k * spec.dt
        q[k] = float(weights @ (x[:, 1] - y_rest)) / norm
        energy[k] = stats.kinetic_energy + stats.potential_energy - scene.rest_potential
    return SwingRun(t, q, energy, float(np.median(step_s)), time.perf_counter() - t_start,
                    float(np.median(cpu_s)))


def _damped_cosine(t, a, sigma, omega, phase, offset):
    return a * np.exp(-sigma * t) * np.cos(omega * t + phase) + offset


def fit_oscillation(t: np.ndarray, q: np.ndarray, omega_guess: float) -> dict:
    """Least-squares fit of a exp(-sigma t) cos(omega t + phase) + c to q(t) (k,): omega in
    rad/s, sigma in 1/s, the damping ratio sigma / sqrt(sigma^2 + omega^2), and the fit's
    rms residual as a share of the start amplitude (a poor fit says the record is not one
    decaying mode)."""
    a0 = float(q[0])
    # the log decrement between the first and last thirds' peaks seeds sigma
    third = max(2, len(q) // 3)
    p0, p1 = np.max(np.abs(q[:third])), np.max(np.abs(q[-third:]))
    span = float(t[-third // 2] - t[third // 2])
    sigma0 = max(0.0, math.log(max(p0, 1e-300) / max(p1, 1e-300)) / span) if span > 0 else 0.0
    guess = (a0, sigma0, omega_guess, 0.0, 0.0)
    params, _ = curve_fit(_damped_cosine, t, q, p0=guess, maxfev=20000)
    a, sigma, omega, phase, offset = (float(v) for v in params)
    if omega < 0.0:  # cos is even: the same curve with omega > 0
        omega, phase = -omega, -phase
    resid = q - _damped_cosine(t, a, sigma, omega, phase, offset)
    return {"omega": omega, "sigma": sigma, "damping_ratio": sigma / math.hypot(sigma, omega),
            "fit_rms_rel": float(np.sqrt(np.mean(resid ** 2)) / max(abs(a0), 1e-300)),
            "curve": [a, sigma, omega, phase, offset]}


def measure(scene: SwingScene, run: SwingRun) -> dict:
    """The summary's "swing" block of one run (frequencies Hz, step s, energy share)."""
    spec = scene.spec
    exact = spec.exact_frequency
    fit = fit_oscillation(run.t, run.q, 2.0 * math.pi * exact)
    freq = fit["omega"] / (2.0 * math.pi)
    return {
        "length_m": spec.length, "scheme": spec.scheme, "dt_s": spec.dt, "newton": spec.newton,
        "linearise_at": spec.linearise_at,
        "damping_model": spec.damping_model,
        "frequency_hz": freq, "exact_frequency_hz": exact,
        "frequency_error_pct": 100.0 * (freq / exact - 1.0),
        "damping_ratio": fit["damping_ratio"],
        "energy_left": float(run.energy[-1] / run.energy[0]),
        "natural_frequency_hz": math.hypot(fit["omega"], fit["sigma"]) / (2.0 * math.pi),
        "fit_rms_rel": fit["fit_rms_rel"], "fit_curve": fit["curve"],
        "spectral_radius": (DEFAULT_SPECTRAL_RADIUS if spec.spectral_radius is None
                            else spec.spectral_radius) if spec.scheme == "genalpha" else None,
        "width_m": spec.width, "amplitude_m": spec.start_amplitude, "duration_s": float(run.t[-1]),
        "material": scene.model.material.name, "particles": int(scene.model.n),
        "fabric_damping_s": float(scene.model.material.damping),
        "bending_length_m": scene.model.material.bending_length(GRAVITY),
        "hanging_length_m": float(-np.min(scene.rest.x[:, 2])),
        "rest_length_m": scene.rest_length,
        "start_energy_j": float(run.energy[0]),
        # a swing never gains energy: above 1 beyond rounding, the step pumps it
        "max_energy_ratio": float(np.max(run.energy) / run.energy[0]),
        "median_step_s": run.median_step_s, "wall_s": run.wall_s,
        "cost_s_per_simulated_s": run.median_step_s / spec.dt,
        "median_step_cpu_s": run.median_step_cpu_s,
        "cpu_s_per_simulated_s": run.median_step_cpu_s / spec.dt,
        "settled": bool(scene.settle.settled),
    }


def run_swing(spec: SwingSpec, fabric_split: bool = True
              ) -> tuple[dict, SwingScene, SwingRun]:
    """Build, settle, swing and measure. fabric_split: also swing the same start with the
    fabric's damping set to zero, and report that run's damping ratio
    ("damping_ratio_fabric_off", the integrator's own) and the difference
    ("fabric_damping_ratio", the fabric's); where the fabric has none, or the spec turns it
    off, those are the run's own figures and 0."""
    scene = build_swing(spec)
    run = simulate(scene)
    block = measure(scene, run)
    if not fabric_split:
        return block, scene, run
    off = block
    if scene.model.material.damping > 0.0:
        undamped = replace(scene, spec=replace(spec, fabric_damping=False),
                           model=_without_damping(scene.model))
        off = measure(undamped, simulate(undamped))
    block["damping_ratio_fabric_off"] = off["damping_ratio"]
    block["frequency_hz_fabric_off"] = off["frequency_hz"]
    block["energy_left_fabric_off"] = off["energy_left"]
    block["fabric_damping_ratio"] = block["damping_ratio"] - off["damping_ratio"]
    return block, scene, run


def _without_damping(model: ClothModel) -> ClothModel:
    """A shallow copy of ``model`` whose material has no stiffness-proportional damping."""
    return replace(model, material=replace(model.material, damping=0.0))


def swing_picture(path: str | Path, run: SwingRun, block: dict) -> Path:
    """The modal coordinate against time with the fitted damped cosine, and the energy
    left (PNG)."""
    # imported here: matplotlib (charts), loaded only when needed
    from cloth_mg_ros.fidelity.charts import chart_pyplot, save_chart_png

    plt = chart_pyplot()
    fig, (ax, ax_e) = plt.subplots(2, 1, figsize=(6.4, 5.2), sharex=True)
    ax.plot(run.t, 1e3 * run.q, "-", lw=1.2, label="simulated")
    ax.plot(run.t, 1e3 * _damped_cosine(run.t, *block["fit_curve"]), "--", lw=1.0,
            label=f"fit: {block['frequency_hz']:.4f} Hz, damping ratio "
                  f"{block['damping_ratio']:.4f}")
    ax.set_ylabel("first-mode coordinate, mm")
    ax.set_title(f"swing: {block['scheme']}, dt {block['dt_s']:.4g} s, L {block['length_m']:g} "
                 f"m (exact chain {block['exact_frequency_hz']:.4f} Hz)")
    ax.legend(fontsize=8)
    ax_e.plot(run.t, run.energy / run.energy[0])
    ax_e.set_xlabel("time, s")
    ax_e.set_ylabel("energy / start's")
    return save_chart_png(plt, fig, path)
