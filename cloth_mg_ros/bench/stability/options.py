"""`bench stability`'s options: the map's axes (materials, steps, motions, solvers, schemes,
sizes, speeds) with their defaults and limits, `StabilityConfig`, `map_columns` (the map's
(scheme, solver) columns) and `validate_stability_args`, which checks every option before any
work. Steps are in s, parsed from '1/240'-style text."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import MATERIALS
from cloth_mg_ros.sim.explicit import SCHEME as EXPLICIT_SCHEME
from cloth_mg_ros.sim.model import CONTACT_FRICTIONS
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS, LINEARISE_AT, SCHEMES
from cloth_mg_ros.solvers import SOLVERS

# -- the map's axes ----------------------------------------------------------------------
MOTIONS = {"walk": "walking", "brisk_walk": "brisk_walking", "run": "running",
           "jump": "jumping"}  # motion: its scene file in config/
DEFAULT_MATERIALS = ("silk", "wool", "cotton", "denim", "leather")
DEFAULT_DTS = ("1/240", "1/120", "1/60", "1/30", "1/15", "1/10")
EXPLICIT = "explicit"
DEFAULT_SOLVERS = ("pcg", "galerkin", "mg", "mpcg", EXPLICIT)
# Every implicit scheme by default: the map answers where a scheme that damps less (genalpha)
# fails where implicit Euler and BDF2 hold. The explicit column has no implicit scheme (it is
# symplectic Euler, EXPLICIT_SCHEME) and is run once, not per scheme.
DEFAULT_SCHEMES = SCHEMES
SETTLE_SCHEME = "bdf2"  # the common settle's scheme (the scenes' default)
DEFAULT_PARTICLES = 500
DEFAULT_SECONDS = 2.0
DEFAULT_JOBS = 2
DEFAULT_TOL = 1e-4
POSE_INTERVAL = 1.0 / 30.0  # s, the bundled bags' message interval
MAX_SUBSTEPS = 64  # BodySimOptions' limit
MAX_MESSAGES_PER_STEP = 7  # a step through at most 7/30 s: below MAX_FRAME_GAP (0.25 s)
MAX_SPEED_UP = 64  # the motion played at most 64 times faster
MIN_LEVELS = 3  # hierarchy levels, so that every multigrid has two coarse levels
MIN_DEPTH = MIN_LEVELS - 1  # 1-to-4 subdivisions giving MIN_LEVELS levels
MIN_PARTICLES = 300  # the smallest garments a depth-2 hierarchy still fits
MAX_PARTICLES = 20000
MAX_SECONDS = 10.0
MAX_JOBS = 64
SETTLE_S = 0.5  # s of the still lead-in the garment settles through before the motion
SETTLE_SOLVER = "direct"  # exact solves: the common start does not favour any solver
SUBSTEP_MOTION_OFF = 1e9  # m: max_substep_motion that never adds substeps


# -- options ------------------------------------------------------------------------------
@dataclass
class StabilityConfig:
    """The checked options: dts in s, seconds of motion per cell, particles requested (one
    count per resolution)."""

    materials: list[str]
    dts: list[float]
    motions: list[str]
    solvers: list[str]
    particles: list[int] = field(default_factory=lambda: [DEFAULT_PARTICLES])
    seconds: float = DEFAULT_SECONDS
    jobs: int = DEFAULT_JOBS  # Dask workers of the embedded cluster (1: in this process)
    tol: float = DEFAULT_TOL
    speeds: list[int] = field(default_factory=lambda: [1])
    scheduler: str | None = None  # a running Dask scheduler, tcp://HOST:PORT
    schemes: list[str] = field(default_factory=lambda: list(DEFAULT_SCHEMES))
    spectral_radius: float = DEFAULT_SPECTRAL_RADIUS  # genalpha's rho_inf
    linearise: str = "start"  # where euler and bdf2 linearise (sim.schemes.LINEARISE_AT)
    contact_friction: str = "projection"  # where friction acts (sim.model.CONTACT_FRICTIONS)


def map_columns(solvers: list[str], schemes: list[str]) -> list[tuple[str, str]]:
    """The map's (scheme, solver) columns: every implicit solver under each scheme, scheme by
    scheme, then the explicit solver once under its own scheme (symplectic Euler)."""
    cols = [(sc, s) for sc in schemes for s in solvers if s != EXPLICIT]
    return cols + [(EXPLICIT_SCHEME, EXPLICIT)] if EXPLICIT in solvers else cols


def cell_scheme(cell: dict, default: str = SETTLE_SCHEME) -> str:
    """A cell's scheme: its own, the explicit solver's, or ``default`` for an implicit cell of
    a map written before the scheme axis (those ran BDF2)."""
    if cell.get("scheme"):
        return cell["scheme"]
    return EXPLICIT_SCHEME if cell["solver"] == EXPLICIT else default


def _split(value) -> list[str]:
    """Comma-separated text, a list, or one value, as a list of stripped strings."""
    if isinstance(value, str):
        return [v.strip() for v in value.split(",") if v.strip()]
    if isinstance(value, (list, tuple)):
        return [str(v).strip() for v in value]
    return [str(value).strip()]


def parse_dt(text) -> float | None:
    """A step in s from '1/240', '0.004166' or a number; None when it is not one."""
    if isinstance(text, bool):
        return None
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        try:
            value = float(Fraction(str(text).strip()))
        except (ValueError, ZeroDivisionError):
            return None
    return value if math.isfinite(value) and value > 0.0 else None


def substeps_for(dt: float, interval: float = POSE_INTERVAL) -> int:
    """Substeps per pose message of ``interval`` s for a step of ``dt`` s (1 for a step that
    spans several messages)."""
    return max(1, round(interval / dt))


def messages_per_step(dt: float, interval: float = POSE_INTERVAL) -> int:
    """Pose messages one step of ``dt`` s goes through (1 for a step within a message)."""
    return max(1, round(dt / interval))


def dt_label(dt: float) -> str:
    """'1/240' for 1/240 s, else the value in s."""
    inv = 1.0 / dt
    return f"1/{round(inv)}" if abs(inv - round(inv)) < 1e-6 * inv else f"{dt:g}"


def _number(text, kind: type):
    if isinstance(text, bool):
        return None
    try:
        value = kind(text)
    except (TypeError, ValueError):
        return None
    if kind is int and not isinstance(text, (int, np.integer)) and str(text).strip() != str(value):
        return None
    return value


def validate_stability_args(materials, dts, motions, solvers, particles, seconds, jobs,
                            tol: float = DEFAULT_TOL, json_path: str | None = "-",
                            png_path: str | None = "-", speeds="1",
                            scheduler: str | None = None, schemes=DEFAULT_SCHEMES,
                            spectral_radius=None, linearise: str = "start",
                            contact_friction: str = "projection") -> StabilityConfig:
    """Check every option before any work (comma-separated strings or lists, output paths);
    returns the parsed options, or raises one ClothInputError naming every bad value.

    schemes: the implicit schemes (euler, bdf2, genalpha); spectral_radius: genalpha's rho_inf
    in 0..1 (None: DEFAULT_SPECTRAL_RADIUS; given, it needs genalpha among the schemes);
    linearise: where euler's and bdf2's steps linearise (generalised-alpha's at the start);
    contact_friction: where the body's and the floor's friction acts (the garment's, every
    cell's settle included; 'solve' with steps linearised at the start)."""
    problems: list[str] = []
    integrators = _check_schemes(schemes, problems)
    rho = _check_radius(spectral_radius, integrators, problems)
    mats, steps, moves, names = _check_axes(materials, dts, motions, solvers, problems)
    sizes = _check_counts(particles, "--particles", MIN_PARTICLES, MAX_PARTICLES, problems)
    if not _split(particles):
        problems.append("--particles must list at least one value")
    elif len(set(sizes)) != len(sizes):
        problems.append(f"--particles lists a value twice: {particles}")
    pace = _check_counts(speeds, "--speeds", 1, MAX_SPEED_UP, problems)
    if len(set(pace)) != len(pace):
        problems.append(f"--speeds lists a value twice: {speeds}")
    secs = _number(seconds, float)
    if secs is None or not (math.isfinite(secs) and 0.0 < secs <= MAX_SECONDS):
        problems.append(f"--seconds must be in (0, {MAX_SECONDS:g}], got {seconds!r}")
    n_jobs = _number(jobs, int)
    if n_jobs is None or not 1 <= n_jobs <= MAX_JOBS:
        problems.append(f"--workers must be an integer in 1..{MAX_JOBS}, got {jobs!r}")
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and 0.0 < tol < 1.0):
        problems.append(f"--tol must be in (0, 1), got {tol!r}")
    for flag, path in (("--json", json_path), ("--png", png_path)):
        if not path or Path(path).is_dir():
            problems.append(f"{flag} must be a file path, got {path!r}")
    if linearise not in LINEARISE_AT:
        problems.append(f"--linearise must be one of {', '.join(LINEARISE_AT)}, got "
                        f"{linearise!r}")
    if contact_friction not in CONTACT_FRICTIONS:
        problems.append(f"--contact-friction must be one of {', '.join(CONTACT_FRICTIONS)}, "
                        f"got {contact_friction!r}")
    elif contact_friction == "solve" and linearise != "start":
        problems.append("--contact-friction solve takes steps linearised at the start, not "
                        f"--linearise {linearise}")
    if problems:
        raise ClothInputError("bench stability: " + "; ".join(problems))
    return StabilityConfig(mats, steps, moves, names, sizes, secs, n_jobs, float(tol),
                           pace or [1], scheduler or None, integrators, rho, linearise,
                           contact_friction)


def _check_schemes(value, problems: list[str]) -> list[str]:
    """The implicit schemes of --schemes (lower case); bad, missing or repeated ones go to
    `problems`."""
    given = [v.lower() for v in _split(value)]
    _unknown("scheme", given, SCHEMES, problems)
    if not given:
        problems.append("--schemes must list at least one value")
    elif len(set(given)) != len(given):
        problems.append(f"--schemes lists a value twice: {','.join(given)}")
    return given


def _check_radius(value, schemes: list[str], problems: list[str]) -> float:
    """--spectral-radius in 0..1 (None: the default); given without genalpha, it would change
    nothing and goes to `problems`."""
    if value is None:
        return DEFAULT_SPECTRAL_RADIUS
    rho = _number(value, float)
    if rho is None or not (math.isfinite(rho) and 0.0 <= rho <= 1.0):
        problems.append(f"--spectral-radius must be in 0..1, got {value!r}")
        return DEFAULT_SPECTRAL_RADIUS
    if "genalpha" not in schemes:
        problems.append(f"--spectral-radius {value!r} sets genalpha's rho_inf, but --schemes "
                        f"does not list genalpha")
    return rho


def _check_axes(materials, dts, motions, solvers,
                problems: list[str]) -> tuple[list[str], list[float], list[str], list[str]]:
    """(materials, steps in s, motions, solvers) as given, each bad, missing or repeated
    value added to `problems`."""
    mats = [m.lower() for m in _split(materials)]
    _unknown("material", mats, MATERIALS, problems)
    steps = _check_steps(_split(dts), problems)
    moves = _split(motions)
    _unknown("motion", moves, MOTIONS, problems)
    names = _split(solvers)
    _unknown("solver", names, (*SOLVERS, EXPLICIT), problems)
    for flag, items, values in (("--materials", mats, mats), ("--dts", _split(dts), steps),
                                ("--motions", moves, moves), ("--solvers", names, names)):
        if not items:
            problems.append(f"{flag} must list at least one value")
        elif len(set(values)) != len(values):
            problems.append(f"{flag} lists a value twice: {','.join(items)}")
    return mats, steps, moves, names


def _unknown(what: str, given: list[str], known, problems: list[str]) -> None:
    """Add the values of `given` not in `known` to `problems`, with the choices."""
    bad = [m for m in given if m not in known]
    if bad:
        problems.append(f"unknown {what}(s) {', '.join(map(repr, bad))} (choose from "
                        f"{', '.join(known)})")


def _check_steps(items: list[str], problems: list[str]) -> list[float]:
    """The steps (s) of --dts that GarmentSim takes exactly: a whole number of steps per pose
    interval, or a step through a whole number of intervals; the others go to `problems`."""
    steps = []
    for item in items:
        dt = parse_dt(item)
        if dt is None:
            problems.append(f"--dts: {item!r} is not a positive step in s (e.g. 1/240 or "
                            f"0.004)")
            continue
        ratio, span = POSE_INTERVAL / dt, dt / POSE_INTERVAL
        n, k = round(ratio), round(span)
        if 1 <= n <= MAX_SUBSTEPS and abs(ratio - n) <= 1e-3 * ratio:
            steps.append(POSE_INTERVAL / n)  # exactly the step GarmentSim will take
        elif 2 <= k <= MAX_MESSAGES_PER_STEP and abs(span - k) <= 1e-3 * span:
            steps.append(POSE_INTERVAL * k)
        else:
            problems.append(f"--dts: {item!r} neither divides the pose interval 1/30 s into "
                            f"1..{MAX_SUBSTEPS} equal steps (1/30, 1/60, ... 1/1920) nor spans "
                            f"2..{MAX_MESSAGES_PER_STEP} of them (1/15, 1/10, ... 7/30)")
    return steps


def _check_counts(value, flag: str, lo: int, hi: int, problems: list[str]) -> list[int]:
    """The integers in lo..hi of a comma list; the others go to `problems`."""
    out = []
    for item in _split(value):
        k = _number(item, int)
        if k is None or not lo <= k <= hi:
            problems.append(f"{flag} must be integers in {lo}..{hi}, got {item!r}")
        else:
            out.append(k)
    return out
