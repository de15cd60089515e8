"""The buckle scene: a strip clamped level at both ends, pushed together, settled.

The strip lies along +x in the xy plane. Its free span is x in [0, L]; beyond each end a
clamp of ``CLAMP_SPACINGS`` mesh spacings (x in [-c, 0] and [L, L + c]) is held, every
particle in it pinned, the lines x = 0 and x = L included (they are mesh lines,
`fidelity.strips`). A clamp is two or more rows of pinned particles, so the triangles in it
are held and the hinges on its line hold the strip's end level, rotation included. L, the
length of the exact answer, is the free span from clamp line to clamp line; the clamps' rows
do not count.

Both clamps slide towards each other along x by S L / 2 each on a smooth ramp
(1 - cos) / 2 lasting ``RAMP_PERIODS`` of the straight strip's first period, then hold; the
strip is stepped on until it is at rest by `fidelity.settle`'s criteria. Gravity is off
unless asked for. The answer (`fidelity.buckle_exact`): the force along the strip from the
clamps' exact reactions (the constraint forces of the implicit step, as the grippers'
wrenches are, `sim.grippers`), and the midpoint's lift, against the first-mode elastica.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.buckle_exact import BuckledStrip, buckled_strip, onset_force
from cloth_mg_ros.fidelity.settle import SettleResult, settle
from cloth_mg_ros.fidelity.strips import EQUILATERAL_AREA, MESH_KINDS, strip_coarse
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.mesh.topology import MeshLevel
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model
from cloth_mg_ros.solvers import make_solver

DEFAULT_WIDTH = 0.025  # m, the cantilever's strip
# The default mesh spacing: the finer of L / 120 and W / 10 (the clamps' and the free edges'
# first-order errors, module docstring, each near 0.7 % of the force there).
SPACINGS_ALONG = 120
SPACINGS_ACROSS = 10
CLAMP_SPACINGS = 2  # each clamp's length in mesh spacings (plus a quarter): 3 columns pinned
# Stretch plays no part in the elastica (an inextensible strip); as the cantilever's, the
# strip gets a stiff woven membrane unless a material is named. At the onset load the
# membrane then shortens by 4 pi^2 B / (L^2 k), 1e-6 of L for B = 1e-5 N m, L = 0.2 m.
BUCKLE_STRETCH = 8000.0  # N/m
BUCKLE_SHEAR = 4000.0  # N/m
# The seed: the clamped-clamped first mode's shape, z = a (1 - cos(2 pi x / L)) / 2 at rest x,
# of amplitude a = SEED_AMPLITUDE L. A flat strip with gravity off is an equilibrium at every
# load and never leaves its plane; the seed only starts it off it: the rest shape stays flat,
# so the settled shape, an equilibrium of the flat strip's energy with its ends held, does
# not depend on it (seeds of 1e-4 L and 1e-3 L settle to the same force and lift to within
# 1e-6 relative, test/test_buckle.py). 1e-4 L is 20 um on a 20 cm strip, far under a real
# fabric's waviness (its thickness, 0.3-1 mm). Its slack is tiny against the clamps' first
# travel, so the strip leaves its plane briskly at the ramp's start and may settle on either
# side (up with the default ramp in every run measured; a 3-period ramp has settled one
# down): both are the exact first mode, so the lift is measured as a magnitude.
SEED_AMPLITUDE = 1e-4
RAMP_PERIODS = 10.0  # the ramp lasts ten periods of the straight strip's first mode
# Euler-Bernoulli clamped-clamped beam, first mode: beta_1 L = 4.7300.
CLAMPED_BETA = 4.730041
MIDDLE_BAND = 0.125  # the lift is fitted to particles within L/8 of the midpoint


@dataclass(frozen=True)
class BuckleSpec:
    """A buckle test: bend B (N m), density rho (kg/m^2), length L between the clamps (m),
    shortening S (a share of L, 0 < S < 1), width (m), gravity (m/s^2, down -z; 0: off),
    mesh kind and orientation (degrees), particles (over the free span; None: the default
    spacing, `strip_spacing`), seed amplitude (a share of L) and the point set's seed for
    garment meshes."""

    bend: float
    density: float
    length: float
    shortening: float
    width: float = DEFAULT_WIDTH
    gravity: float = 0.0
    mesh: str = "lattice"
    orientation: float = 0.0
    particles: int | None = None
    seed_amplitude: float = SEED_AMPLITUDE
    seed: int = 0

    def __post_init__(self) -> None:
        def number(value) -> bool:
            return isinstance(value, (int, float)) and not isinstance(value, bool) \
                and math.isfinite(value)

        for name in ("bend", "density", "length", "width"):
            value = getattr(self, name)
            if not (number(value) and value > 0.0):
                raise ClothInputError(f"buckle: --{name} must be a positive number, got "
                                      f"{value!r}")
        if not (number(self.shortening) and 0.0 < self.shortening < 1.0):
            raise ClothInputError(f"buckle: --shortening must be a share of the length, "
                                  f"0 < S < 1, got {self.shortening!r}")
        if not (number(self.gravity) and self.gravity >= 0.0):
            raise ClothInputError(f"buckle: --gravity must be a number >= 0 (m/s^2), got "
                                  f"{self.gravity!r}")
        if not number(self.orientation):
            raise ClothInputError(f"buckle: --orientation must be finite, got "
                                  f"{self.orientation!r}")
        if self.mesh not in MESH_KINDS:
            raise ClothInputError(f"buckle: --mesh must be one of {', '.join(MESH_KINDS)}, "
                                  f"got {self.mesh!r}")
        if self.particles is not None and (isinstance(self.particles, bool) or not isinstance(
                self.particles, (int, np.integer)) or self.particles < 16):
            raise ClothInputError(f"buckle: --particles must be an integer >= 16, got "
                                  f"{self.particles!r}")
        if not (number(self.seed_amplitude) and 0.0 < self.seed_amplitude < 0.01):
            raise ClothInputError(f"buckle: the seed amplitude must be in (0, 0.01) of L, got "
                                  f"{self.seed_amplitude!r}")

    @property
    def exact(self) -> BuckledStrip:
        return buckled_strip(self.bend, self.width, self.length, self.shortening)

    @property
    def period(self) -> float:
        """The straight strip's first bending period, s (Euler-Bernoulli, clamped-clamped:
        omega_1 = 4.7300^2 sqrt(B / (rho L^4)))."""
        omega = CLAMPED_BETA ** 2 * math.sqrt(self.bend / (self.density * self.length ** 4))
        return 2.0 * math.pi / omega


@dataclass
class BuckleScene:
    """The built scene: hierarchy, model, seeded initial state, the two clamps' particles
    (left at x <= 0, right at x >= L, rest positions), the pinned list's rows of each, the
    mesh spacing along the strip (m) and its rows of triangles across."""

    spec: BuckleSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    left: np.ndarray
    right: np.ndarray
    rows_left: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    rows_right: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    spacing: float = 0.0
    rows: int = 0


def strip_spacing(spec: BuckleSpec) -> float:
    """The mesh spacing asked for, m: from --particles (over the free span) when given, else
    the finer of L / SPACINGS_ALONG and W / SPACINGS_ACROSS."""
    if spec.particles is None:
        return min(spec.length / SPACINGS_ALONG, spec.width / SPACINGS_ACROSS)
    return math.sqrt(spec.length * spec.width / (2.0 * EQUILATERAL_AREA * spec.particles))


def buckle_mesh(spec: BuckleSpec) -> tuple[MeshLevel, float, float, int]:
    """The strip with its clamps; its clamps' length c (m), its spacing along the strip (m)
    and its rows of triangles across.

    The mesh is the `fidelity.strips` strip of the spec's kind over [-c, m h + c] with mesh
    lines at 0 and m h, h the aligned lattice's spacing for its rows across and m a whole or
    half number of spacings, then scaled along x by L / (m h): so both clamp lines cut the
    lattice at the same place and the mesh beside one is the other's mirror image (left to
    where the lattice happens to fall, the force scattered by 2-3 % between neighbouring
    resolutions). The rows are chosen within 10 % of those the spacing asks for to make the
    scale closest to 1, since the bending stencils are exact for equilateral triangles only
    (measured: stretched along x by 0.3 %, the strip's force moved by 0.4 %). c is
    CLAMP_SPACINGS + 1/4 spacings: a quarter spacing off the lattice, so no lattice point
    falls on the half-spacing boundary within which `strips` drops points beside a line."""
    target = spec.width / (strip_spacing(spec) * math.sqrt(3.0) / 2.0)
    candidates = range(max(2, math.floor(0.9 * target)), max(2, math.ceil(1.1 * target)) + 1)

    def misfit(r: int) -> tuple[float, float]:
        along = spec.length * math.sqrt(3.0) * r / (2.0 * spec.width)  # L / h
        return abs(along / max(0.5 * round(2.0 * along), 2.0) - 1.0), abs(r - target)

    rows = min(candidates, key=misfit)
    h = spec.width / rows * 2.0 / math.sqrt(3.0)
    n = max(2.0, 0.5 * round(2.0 * spec.length / h))
    clamp = (CLAMP_SPACINGS + 0.25) * h
    mesh = strip_coarse(spec.mesh, -clamp, n * h + clamp, spec.width, h, spec.orientation,
                        cuts=(0.0, n * h), seed=spec.seed)
    scale = spec.length / (n * h)
    rest = np.array(mesh.rest)
    rest[:, 0] *= scale
    return MeshLevel(rest, np.array(mesh.faces), source=f"buckle strip {spec.length:g} x "
                     f"{spec.width:g} m, spacing {h * scale:.4g} x {h:.4g} m"), clamp * scale, \
        h * scale, rows


def build_buckle(spec: BuckleSpec, material: Material | None = None) -> BuckleScene:
    """The strip of ``spec`` with its clamps, seeded (``material``: its stretch, shear and
    damping; default a stiff woven membrane; bend and density are the spec's, one stiffness
    in every direction: a measured fabric's bending law by direction and curvature is
    dropped, since the exact elastica is that of a moment linear in the curvature)."""
    base = material or Material("buckle", BUCKLE_STRETCH, BUCKLE_SHEAR, spec.bend)
    mat = replace(base, bend=float(spec.bend), density=float(spec.density), bend_law=None,
                  name=f"{base.name} (B {spec.bend:.3g} N m, rho {spec.density:.3g} kg/m^2)")
    length = spec.length
    mesh, _, spacing, rows = buckle_mesh(spec)
    hier = MeshHierarchy.from_coarse(mesh, 0)
    rest = np.array(mesh.rest)
    eps = 1e-9 * length
    left = np.flatnonzero(rest[:, 0] <= eps)
    right = np.flatnonzero(rest[:, 0] >= length - eps)
    pinned = np.concatenate([left, right])
    model = build_model(mesh, mat, pinned=pinned, gravity=np.array([0.0, 0.0, -spec.gravity]))
    x = rest.copy()
    free = (rest[:, 0] > eps) & (rest[:, 0] < length - eps)
    amplitude = spec.seed_amplitude * length
    x[free, 2] = 0.5 * amplitude * (1.0 - np.cos(2.0 * math.pi * rest[free, 0] / length))
    return BuckleScene(spec, hier, model, ClothState.at_rest(x), left, right,
                       np.arange(len(left)), len(left) + np.arange(len(right)), spacing, rows)


def clamp_targets(scene: BuckleScene, t: float, ramp: float) -> np.ndarray:
    """(k, 3) m: where the pinned particles are at time t (s) of a ramp lasting ``ramp`` s:
    each clamp moved rigidly along x towards the other by S L / 2 (1 - cos(pi t / ramp)) / 2."""
    rest = scene.model.mesh.rest
    share = 0.5 * (1.0 - math.cos(math.pi * min(t / ramp, 1.0)))
    shift = 0.5 * scene.spec.shortening * scene.spec.length * share
    out = np.concatenate([rest[scene.left], rest[scene.right]])
    out[scene.rows_left, 0] += shift
    out[scene.rows_right, 0] -= shift
    return out


def midpoint_lift(scene: BuckleScene, x: np.ndarray) -> float:
    """The centre line's height at the midpoint, m: z = c0 + c2 u^2 + c4 u^4 (u = rest x -
    L/2; the first mode is even about the midpoint) fitted by least squares to every particle
    within L/8 of it across the whole width; returns c0."""
    rest = scene.model.mesh.rest
    u = rest[:, 0] - 0.5 * scene.spec.length
    near = np.abs(u) <= MIDDLE_BAND * scene.spec.length
    uu = u[near] / scene.spec.length
    design = np.stack([np.ones_like(uu), uu ** 2, uu ** 4], axis=1)
    coef, *_ = np.linalg.lstsq(design, x[near, 2], rcond=None)
    return float(coef[0])


def clamp_forces(scene: BuckleScene, reaction: np.ndarray) -> tuple[float, float]:
    """(left, right) N: the compressive force along the strip that each clamp feels, from the
    step's constraint forces ``reaction`` (k, 3) N on the pinned rows (what holds each pinned
    particle; the strip pushes a clamp outwards, so the left one is held by +x)."""
    return (float(reaction[scene.rows_left, 0].sum()),
            float(-reaction[scene.rows_right, 0].sum()))


@dataclass
class BuckleRun:
    """A settled run: the settle's result and each step's time (s), clamp forces (N, (steps,
    2): the left and right ends') and midpoint lift (m)."""

    result: SettleResult
    t: np.ndarray
    ends: np.ndarray
    lift: np.ndarray

    @property
    def force(self) -> np.ndarray:
        """Each step's force along the strip, N: the mean of the two clamps'."""
        return self.ends.mean(axis=1)


def settle_buckle(scene: BuckleScene, solver_name: str = "direct", tol: float = 1e-8,
                  max_steps: int = 4000) -> BuckleRun:
    """Ramp the clamps together and settle: implicit Euler steps of an eighth of the straight
    strip's first period and air drag at its angular frequency (`fidelity.settle_specimen`'s
    choice), no rest check before the ramp has ended. The energy measure's force scale is the
    onset load 4 pi^2 B W / L^2 (gravity is off, so the weight is not the strip's scale)."""
    spec, model = scene.spec, scene.model
    period = spec.period
    dt = period / 8.0
    ramp = RAMP_PERIODS * period
    ramp_steps = math.ceil(ramp / dt)
    model = replace(model, material=replace(model.material, air_drag=2.0 * math.pi / period))
    solver = make_solver(solver_name, tol=tol, hierarchy=scene.hierarchy,
                         bending=model.bending)
    t, ends, lift = [0.0], [(0.0, 0.0)], [midpoint_lift(scene, scene.state.x)]

    def on_step(k: int, sim) -> None:
        # the targets of step k + 1 (the first step holds the clamps where they start); the
        # reactions are tracked from the second step on
        sim.control.pin_targets = clamp_targets(scene, (k + 1) * dt, ramp)
        if sim.track_constraint_forces:
            ends.append(clamp_forces(scene, sim.constraint_forces))
            t.append(k * dt)
            lift.append(midpoint_lift(scene, sim.state.x))
        sim.track_constraint_forces = True

    weight = onset_force(spec.bend, spec.width, spec.length)
    if spec.gravity > 0.0:
        weight = max(weight, float(model.mass.sum()) * spec.gravity)
    result = settle(model, scene.state, solver, dt=dt, length=spec.length, max_steps=max_steps,
                    min_steps=ramp_steps + 2, weight=weight, on_step=on_step)
    return BuckleRun(result, np.array(t), np.array(ends), np.array(lift))


def measure(scene: BuckleScene, run: BuckleRun) -> dict:
    """The summary's "buckle" block of a settled run: the clamps' force along the strip (N,
    the mean of both ends; each end's too) and the midpoint's lift (m), against the exact
    first mode, errors in %."""
    spec = scene.spec
    exact = spec.exact
    force = float(run.force[-1])
    lift = abs(float(run.lift[-1]))  # either side is the exact first mode
    x = run.result.state.x
    return {
        "bend_nm": spec.bend, "density_kgm2": spec.density, "width_m": spec.width,
        "length_m": spec.length, "shortening": spec.shortening, "gravity_mps2": spec.gravity,
        "mesh": spec.mesh, "orientation_deg": spec.orientation,
        "particles": int(scene.model.n), "spacing_m": scene.spacing,
        "rows_across": scene.rows, "clamp_particles": [len(scene.left),
                                                            len(scene.right)],
        "seed_amplitude_m": spec.seed_amplitude * spec.length,
        "force_n": force, "force_ends_n": run.ends[-1].tolist(),
        "exact_force_n": exact.force_n,
        "force_error_pct": 100.0 * (force - exact.force_n) / exact.force_n,
        "onset_force_n": onset_force(spec.bend, spec.width, spec.length),
        "lift_m": lift, "exact_lift_m": exact.lift_m,
        "lift_error_pct": 100.0 * (lift - exact.lift_m) / exact.lift_m,
        "buckled": "up" if run.lift[-1] > 0.0 else "down",
        "modulus_k": exact.k,
        "sideways_m": float(np.abs(x[:, 1] - scene.model.mesh.rest[:, 1]).max()),
        "settled": bool(run.result.settled),
        "settle": run.result.as_dict(),
    }


def run_buckle(spec: BuckleSpec, material: Material | None = None,
               solver_name: str = "direct", tol: float = 1e-8
               ) -> tuple[dict, BuckleScene, BuckleRun]:
    """Build, ramp, settle and measure one buckle; returns (the "buckle" block, the scene,
    the run)."""
    scene = build_buckle(spec, material)
    run = settle_buckle(scene, solver_name, tol)
    return measure(scene, run), scene, run


def centre_line(scene: BuckleScene, x: np.ndarray) -> np.ndarray:
    """(k, 2) the centre line (x from the left clamp line, z) in m of positions ``x`` (n, 3):
    the free span's particles averaged in bins of one spacing of rest x."""
    rest = scene.model.mesh.rest
    free = (rest[:, 0] >= 0.0) & (rest[:, 0] <= scene.spec.length)
    bins = max(2, round(scene.spec.length / scene.spacing))
    idx = np.clip((rest[free, 0] / scene.spec.length * bins).astype(np.int64), 0, bins - 1)
    count = np.bincount(idx, minlength=bins)
    keep = count > 0
    left = float(np.mean(x[scene.left, 0] - rest[scene.left, 0]))  # the clamp line's x
    out = [np.bincount(idx, x[free, 0] - left, minlength=bins),
           np.bincount(idx, x[free, 2], minlength=bins)]
    return np.stack(out, axis=1)[keep] / count[keep, None]


def buckle_picture(path: str | Path, scene: BuckleScene, run: BuckleRun, block: dict
                   ) -> Path:
    """Side view of the settled strip over the exact elastica, and the clamps' force and the
    midpoint's lift through the ramp and the settle, each over its exact value (PNG)."""
    # imported here: matplotlib (charts), loaded only when needed
    from cloth_mg_ros.fidelity.charts import chart_pyplot, save_chart_png

    plt = chart_pyplot()
    spec = scene.spec
    exact = spec.exact
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(6.4, 6.4))
    prof = exact.profile()
    ax.plot(1e3 * prof[:, 0], 1e3 * prof[:, 1], "-", lw=1.0, color="C0", label="exact elastica")
    line = centre_line(scene, run.result.state.x)
    ax.plot(1e3 * line[:, 0], 1e3 * np.sign(run.lift[-1]) * line[:, 1], "o", ms=2.5, color="C1",
            label=f"simulated, {block['particles']} particles")
    ax.set_aspect("equal")
    ax.set_xlabel("x from the left clamp, mm")
    ax.set_ylabel("height, mm" if run.lift[-1] > 0.0 else "depth, mm")
    ax.set_title(f"buckle: L {1e3 * spec.length:g} mm shortened {100 * spec.shortening:g} %; "
                 f"force {block['force_error_pct']:+.2f} %, lift {block['lift_error_pct']:+.2f} %",
                 fontsize=9)
    ax.legend(fontsize=7)
    bx.plot(run.t, run.force / exact.force_n, "-", color="C2", label="clamp force / exact")
    bx.plot(run.t, np.abs(run.lift) / exact.lift_m, "-", color="C3",
            label="midpoint lift / exact")
    bx.axhline(1.0, color="0.6", lw=0.8, ls=":")
    bx.axvline(RAMP_PERIODS * spec.period, color="0.6", lw=0.8, ls="--")
    bx.set_ylim(-0.1, 1.5)
    # The first steps' force, the membrane's before the strip has left its plane, is off the
    # scale; the stiff axial motion then rings out over a few periods of the ramp.
    bx.set_xlabel("time, s (dashed: the ramp ends)")
    bx.set_ylabel("share of the exact value")
    bx.legend(fontsize=7)
    return save_chart_png(plt, fig, path)
