"""`cloth-mg bench peers` options: the engines and their solvers, the defaults, each run's
settings (overridable with ``--set``), and parsing and checking the command line's values."""

from __future__ import annotations

import math

from cloth_mg_ros.bench.solvers import particle_problems
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import MATERIALS

# engine: its solvers, in the order the benchmark runs them.
ENGINES: dict[str, tuple[str, ...]] = {
    "ours": ("mpcg", "mg"),
    "newton": ("style3d", "vbd"),
    "mujoco": ("newton", "cg"),
}
ENGINE_MODULES = {"ours": (), "newton": ("warp", "newton"), "mujoco": ("mujoco",)}
INSTALL_HINT = "pip install -e .[peers]"
DEFAULT_PARTICLES = (1200, 2400, 4500)
DEFAULT_STEPS = 120
DEFAULT_DT = 1.0 / 60.0
DEFAULT_TOL = 1e-4  # relative residual of our solves, as in the other benchmarks
WARMUP_STEPS = 2  # first steps of every run left out of the median
WARMUP_PARTICLES = 300
DRAPED_SAG = 0.1  # m: a sheet lying flat on the sphere has sag ~0; a draped one ~0.2

# Per-engine settings, overridable with --set solver.key=value. Newton's are the ones its
# cloth examples use (example_cloth_hanging: VBD 10 substeps x 10 iterations, Style3D 2
# substeps x 10 iterations of 10 PCG iterations); MuJoCo's are its defaults.
DEFAULT_SETTINGS: dict[str, dict[str, float]] = {
    "ours:mpcg": {"tol": DEFAULT_TOL},
    "ours:mg": {"tol": DEFAULT_TOL},
    "newton:style3d": {"substeps": 2, "iterations": 10, "linear_iterations": 10,
                       "contact_ke": 1.0e4, "contact_kd": 10.0},
    "newton:vbd": {"substeps": 10, "iterations": 10, "contact_ke": 1.0e4, "contact_kd": 10.0},
    "mujoco:newton": {"substeps": 1, "iterations": 100, "tolerance": 1e-8},
    "mujoco:cg": {"substeps": 1, "iterations": 100, "tolerance": 1e-8},
}
INTEGER_SETTINGS = ("substeps", "iterations", "linear_iterations")


def parse_engines(text: str | list) -> list[str]:
    """'ours,newton:vbd' -> ['ours:mpcg', 'ours:mg', 'newton:vbd']; 'all' -> every one.

    ClothInputError names an unknown engine or solver, or one listed twice."""
    items = text if isinstance(text, (list, tuple)) else str(text).split(",")
    out: list[str] = []
    for raw in items:
        item = str(raw).strip().lower()
        if not item:
            continue
        if item == "all":
            out += [f"{e}:{s}" for e, ss in ENGINES.items() for s in ss]
            continue
        engine, _, solver = item.partition(":")
        if engine not in ENGINES:
            raise ClothInputError(f"--engines: unknown engine {engine!r} (choose from "
                                  f"{', '.join(ENGINES)}, or engine:solver, or all)")
        if solver and solver not in ENGINES[engine]:
            raise ClothInputError(f"--engines: {engine} has no solver {solver!r} (choose from "
                                  f"{', '.join(ENGINES[engine])})")
        out += [f"{engine}:{s}" for s in ((solver,) if solver else ENGINES[engine])]
    if not out:
        raise ClothInputError("--engines must list at least one engine")
    dupes = sorted({e for e in out if out.count(e) > 1})
    if dupes:
        raise ClothInputError(f"--engines lists {', '.join(dupes)} twice")
    return out


def parse_settings(items: list[str] | None) -> dict[str, dict[str, float]]:
    """--set values 'newton:vbd.iterations=20' -> {'newton:vbd': {'iterations': 20}}.

    ClothInputError names an unknown run or key, or a value that is not a positive number
    (a positive integer for substeps and iterations)."""
    out: dict[str, dict[str, float]] = {}
    for item in items or []:
        key, eq, value = str(item).partition("=")
        label, dot, name = key.strip().lower().rpartition(".")
        if not eq or not dot:
            raise ClothInputError(f"--set {item!r}: expected ENGINE:SOLVER.KEY=VALUE, e.g. "
                                  f"newton:vbd.iterations=20")
        if label not in DEFAULT_SETTINGS:
            raise ClothInputError(f"--set {item!r}: unknown run {label!r} (choose from "
                                  f"{', '.join(DEFAULT_SETTINGS)})")
        if name not in DEFAULT_SETTINGS[label]:
            raise ClothInputError(f"--set {item!r}: {label} has no setting {name!r} (it has "
                                  f"{', '.join(DEFAULT_SETTINGS[label])})")
        try:
            number = float(value)
        except ValueError:
            raise ClothInputError(f"--set {item!r}: {value!r} is not a number") from None
        if not (math.isfinite(number) and number > 0.0):
            raise ClothInputError(f"--set {item!r}: the value must be positive")
        if name in INTEGER_SETTINGS:
            if number != int(number):
                raise ClothInputError(f"--set {item!r}: {name} must be a whole number")
            number = int(number)
        out.setdefault(label, {})[name] = number
    return out


def validate_peers_args(particles: list, engines: list, steps: int, dt: float,
                        material: str) -> None:
    """Check every option before any work; one ClothInputError lists all the problems."""
    problems = []
    if not particles:
        problems.append("--particles must list at least one count")
    problems += particle_problems(particles)
    if len(set(particles)) != len(particles):
        problems.append(f"--particles lists a count twice: {particles}")
    known = {f"{e}:{s}" for e, ss in ENGINES.items() for s in ss}
    bad = [e for e in engines if e not in known]
    if bad or not engines:
        problems.append(f"--engines: unknown {', '.join(map(repr, bad)) or 'empty list'}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps <= WARMUP_STEPS:
        problems.append(f"--steps must be an integer > {WARMUP_STEPS} (the first "
                        f"{WARMUP_STEPS} are not timed), got {steps!r}")
    if not (isinstance(dt, (int, float)) and not isinstance(dt, bool) and math.isfinite(dt)
            and 0.0 < dt <= 0.1):
        problems.append(f"--dt must be a step in (0, 0.1] seconds, got {dt!r}")
    if str(material).strip().lower() not in MATERIALS:
        problems.append(f"unknown material {material!r} (choose from {', '.join(MATERIALS)})")
    if problems:
        raise ClothInputError("bench peers: " + "; ".join(problems))
