"""`cloth-mg bench stability`: where each solver stays stable, over resolutions x materials x
step sizes x motions x solvers.

Every cell is one garment size, one material, one fixed step ``dt``, one motion and one
solver:

* the motion's scene file (``walk``: config/walking.yaml, ``brisk_walk``: brisk_walking,
  ``run``: running, ``jump``: jumping) gives the bag, the garment, self-contact and the floor;
* the garment has about ``particles`` particles (default 500; a list makes the resolution an
  axis) on a hierarchy of at least ``MIN_LEVELS`` levels (a depth-2 subdivision where the
  size policy would give fewer), so the multigrids have real coarse levels;
* the step is fixed, and no extra steps for fast limbs: round(pose interval / dt) steps per
  pose message (1/30 s at the bundled bags' 30 Hz) for a step up to the interval, or one step
  through round(dt / interval) pose messages for a longer one (1/15 s: two, 1/10 s: three):
  the steps a live node takes when a tick coalesces that many messages (GarmentSim.advance);
* the garment is dressed on the pose ``SETTLE_S`` before the motion starts (the bags lead in
  with one second of a still pose) and settles through that still stretch with exact (sparse
  direct) solves at the cell's dt; every solver of a (material, motion, dt) then starts from a
  copy of that settled garment and replays ``seconds`` of the motion (default 2 s; the run
  clip has 1.2 s, so its cells replay all of it);
* ``speed`` (default 1; a list makes it an axis) plays the motion that many times faster:
  every speed-th pose message, still one per 1/30 s, so limbs travel that much further per
  step (walking at 4x: a foot's swing at 10+ m/s). Where no solver fails at the bags' own
  pace, this is how far the motion can be pushed before one does. A sped-up clip shorter than
  ``seconds`` swings back and forth (played backwards from its end, then forwards again)
  until it lasts that long;
* solver ``explicit`` is the contrast: symplectic Euler with the same forces, pins, strain
  limit and contact projection (`physics.explicit.ExplicitSimulator`).

Each cell's outcome is the most severe that applies, checked after every pose message
(figures at the end of the message's substeps, penetration after every substep):

========== ===========================================================================
nan        a step came out non-finite (GarmentSim dropped it: ``gs.failures`` > 0) or the
           positions are not finite
blew_up    a particle faster than ``MAX_SPEED`` m/s, or kinetic energy above
           ``MAX_SPECIFIC_KINETIC`` J per kg of garment (its mean square speed above
           (10 m/s)^2): the fastest body point in the bundled clips moves at about 8.5 m/s.
           At speed k both bounds scale with the body (k times the speed, k^2 the energy)
tunnelled  a free (not pinned) particle deeper than ``MAX_PENETRATION`` m inside the body or
           the floor after a step (after the contact projection, as TickStats reports it)
not_conv.  a linear solve stopped above its tolerance (the iteration or cycle cap: 500 for
           the multigrids, 20000 for pcg) (``not_converged`` in the JSON)
ok         none of the above
========== ===========================================================================

Severity: nan > blew_up > tunnelled > not_converged > ok. A cell stops at its first nan or
blew_up message (nothing after it would change the outcome).

The jump's cells are chaotic (a cape flapping onto itself, struck by the legs): two solvers
that both meet the tolerance, or one solver in two processes (the BLAS's rounding in a coarse
solve depends on memory alignment), end up on visibly different trajectories, so their worst
figures scatter (speeds of 10-16 m/s at the hem, against the 25 m/s bound). The JSON keeps
every cell's worst figures, so the margins can be read beside the outcomes.

Work is split by (material, motion, dt, size, speed) into Dask tasks (cloth_mg_ros.cluster): an
embedded LocalCluster of ``jobs`` single-threaded workers (``--workers``; OPENBLAS_NUM_THREADS=1
in each), or a running cluster (``--scheduler``); with one worker, in this process. Output: ``{"cells": [{"material", "dt", "motion",
"solver", "outcome", ...worst figures...}], "summary": {...}, "meta": {...}}``, a heatmap PNG
and a printed table. The CLI exits 1 when solver mg was run and is not ok in every cell.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

# -- the map's axes ----------------------------------------------------------------------
MOTIONS = {"walk": "walking", "brisk_walk": "brisk_walking", "run": "running",
           "jump": "jumping"}  # motion: its scene file in config/
DEFAULT_MATERIALS = ("silk", "wool", "cotton", "denim", "leather")
DEFAULT_DTS = ("1/240", "1/120", "1/60", "1/30", "1/15", "1/10")
EXPLICIT = "explicit"
DEFAULT_SOLVERS = ("pcg", "galerkin", "mg", "mpcg", EXPLICIT)
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

# -- the outcome bounds ------------------------------------------------------------------
MAX_SPEED = 25.0  # m/s: three times the fastest body point of the bundled clips (8.5 m/s)
MAX_SPECIFIC_KINETIC = 50.0  # J/kg: the garment's mean square speed above (10 m/s)^2
MAX_PENETRATION = 0.015  # m: a free particle this deep inside the body or floor after a step
OUTCOMES = ("ok", "not_converged", "tunnelled", "blew_up", "nan")  # by rising severity
FATAL = ("blew_up", "nan")  # stop the cell: nothing later changes its outcome


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
                            scheduler: str | None = None) -> StabilityConfig:
    """Check every option before any work (comma-separated strings or lists, output paths);
    returns the parsed options, or raises one ClothInputError naming every bad value."""
    from cloth_mg_ros.errors import ClothInputError
    from cloth_mg_ros.physics.materials import MATERIALS
    from cloth_mg_ros.solvers import SOLVERS

    problems = []
    mats = [m.lower() for m in _split(materials)]
    bad = [m for m in mats if m not in MATERIALS]
    if bad:
        problems.append(f"unknown material(s) {', '.join(map(repr, bad))} (choose from "
                        f"{', '.join(MATERIALS)})")
    steps = []
    for item in _split(dts):
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
    moves = _split(motions)
    bad = [m for m in moves if m not in MOTIONS]
    if bad:
        problems.append(f"unknown motion(s) {', '.join(map(repr, bad))} (choose from "
                        f"{', '.join(MOTIONS)})")
    names = _split(solvers)
    known = (*SOLVERS, EXPLICIT)
    bad = [s for s in names if s not in known]
    if bad:
        problems.append(f"unknown solver(s) {', '.join(map(repr, bad))} (choose from "
                        f"{', '.join(known)})")
    for flag, items, values in (("--materials", mats, mats), ("--dts", _split(dts), steps),
                                ("--motions", moves, moves), ("--solvers", names, names)):
        if not items:
            problems.append(f"{flag} must list at least one value")
        elif len(set(values)) != len(values):
            problems.append(f"{flag} lists a value twice: {','.join(items)}")
    sizes = []
    for item in _split(particles):
        n_part = _number(item, int)
        if n_part is None or not MIN_PARTICLES <= n_part <= MAX_PARTICLES:
            problems.append(f"--particles must be integers in {MIN_PARTICLES}.."
                            f"{MAX_PARTICLES}, got {item!r}")
        else:
            sizes.append(n_part)
    if not _split(particles):
        problems.append("--particles must list at least one value")
    elif len(set(sizes)) != len(sizes):
        problems.append(f"--particles lists a value twice: {particles}")
    pace = []
    for item in _split(speeds):
        k = _number(item, int)
        if k is None or not 1 <= k <= MAX_SPEED_UP:
            problems.append(f"--speeds must be integers in 1..{MAX_SPEED_UP}, got {item!r}")
        else:
            pace.append(k)
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
    if problems:
        raise ClothInputError("bench stability: " + "; ".join(problems))
    return StabilityConfig(mats, steps, moves, names, sizes, secs, n_jobs, float(tol),
                           pace or [1], scheduler or None)


# -- outcomes -----------------------------------------------------------------------------
def speed_bounds(speed_up: int = 1) -> tuple[float, float]:
    """(particle speed m/s, kinetic energy J/kg) above which a cell has blown up, for the
    motion played ``speed_up`` times faster: its body points move that much faster, so the
    bounds keep their meaning (three times the fastest body point; its square for the
    energy) instead of failing every solver on the body's own speed."""
    return MAX_SPEED * speed_up, MAX_SPECIFIC_KINETIC * speed_up ** 2


def classify(failures: int, finite: bool, max_speed: float, specific_kinetic: float,
             max_penetration: float, converged: bool, speed_up: int = 1) -> str:
    """The outcome of figures (see the module docstring): failures (non-finite steps),
    finite (positions), max_speed m/s, specific_kinetic J/kg, max_penetration m, converged
    (every solve reached its tolerance), speed_up (the motion's speed factor)."""
    if failures > 0 or not finite:
        return "nan"
    speed_bound, kinetic_bound = speed_bounds(speed_up)
    if not (max_speed <= speed_bound and specific_kinetic <= kinetic_bound):
        return "blew_up"
    if not max_penetration <= MAX_PENETRATION:
        return "tunnelled"
    if not converged:
        return "not_converged"
    return "ok"


@dataclass
class CellWatch:
    """The worst figures of one cell so far, fed one pose message at a time.

    mass: the garment's mass, kg; speed_up: the motion's speed factor (scales the blow-up
    bounds). Speeds m/s, energies J, penetration m, times s after the motion starts;
    iterations per solve of every message."""

    mass: float
    speed_up: int = 1
    failures: int = 0
    finite: bool = True
    max_speed: float = 0.0
    max_kinetic: float = 0.0
    max_penetration: float = 0.0
    unconverged: int = 0
    skipped: int = 0  # pose messages not simulated (a teleport or a bad frame)
    ticks: int = 0
    steps: int = 0
    iterations: list = field(default_factory=list)
    outcome: str = "ok"
    at_s: float | None = None  # when the outcome was first reached

    def add(self, tick, velocities: np.ndarray, positions_finite: bool, failures: int,
            t: float) -> str:
        """Fold in one message's TickStats ``tick``, the velocities (n, 3) m/s at its end,
        whether the positions are finite and the GarmentSim's failure count; returns the
        outcome so far."""
        self.ticks += 1
        self.steps += int(tick.substeps)
        self.failures = int(failures)
        self.finite = self.finite and bool(positions_finite)
        with np.errstate(all="ignore"):
            speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", velocities, velocities),
                                         initial=0.0)))
        self.max_speed = _worst(self.max_speed, speed)
        self.max_kinetic = _worst(self.max_kinetic, float(tick.kinetic_energy))
        self.max_penetration = _worst(self.max_penetration, float(tick.max_penetration))
        if not tick.converged:
            self.unconverged += 1
        self.iterations.append(tick.iterations / max(1, tick.substeps))
        outcome = classify(self.failures, self.finite, self.max_speed,
                           self.max_kinetic / self.mass, self.max_penetration,
                           self.unconverged == 0, self.speed_up)
        if OUTCOMES.index(outcome) > OUTCOMES.index(self.outcome):
            self.outcome, self.at_s = outcome, float(t)
        return self.outcome

    @property
    def fatal(self) -> bool:
        return self.outcome in FATAL

    def figures(self) -> dict:
        """The JSON figures beside the outcome (None where nothing was measured)."""
        its = self.iterations
        return {
            "max_speed": _json_float(self.max_speed),
            "max_kinetic_energy": _json_float(self.max_kinetic),
            "max_penetration": _json_float(self.max_penetration),
            "iterations_median": float(np.median(its)) if its else None,
            "iterations_max": float(np.max(its)) if its else None,
            "unconverged_messages": self.unconverged, "failures": self.failures,
            "messages": self.ticks, "steps": self.steps, "skipped_messages": self.skipped,
            "outcome_at_s": None if self.at_s is None else round(self.at_s, 4),
        }


def _worst(old: float, new: float) -> float:
    """max that keeps NaN (a NaN figure is the worst)."""
    if math.isnan(old) or math.isnan(new):
        return math.nan
    return max(old, new)


def _json_float(value: float) -> float | str:
    return value if math.isfinite(value) else str(value)


# -- running ------------------------------------------------------------------------------
def garment_depth(garment: str, particles: int) -> int | None:
    """None where the size policy already gives MIN_LEVELS levels, else MIN_DEPTH."""
    from cloth_mg_ros.mesh.garments import MIN_COARSE_VERTICES

    return None if particles >= 4 ** MIN_DEPTH * MIN_COARSE_VERTICES[garment] else MIN_DEPTH


def motion_window(frames: list, seconds: float) -> tuple[int, int, int]:
    """Indices into ``frames`` [(stamp, poses)]: (dress, first moving, end) such that the
    garment is dressed on frames[dress] (SETTLE_S before the motion), settles through
    frames[dress + 1:first] (the still lead-in) and replays frames[first:end] (``seconds``
    of motion, or to the end of the clip)."""
    ref = frames[0][1]
    first = next((k for k, (_, p) in enumerate(frames) if p.shape != ref.shape
                  or np.max(np.abs(p - ref)) > 1e-9), len(frames) - 1)
    first = max(first, 1)
    still = frames[first - 1][0]
    dress = first - 1
    while dress > 0 and still - frames[dress - 1][0] <= SETTLE_S + 1e-9:
        dress -= 1
    end = first
    while end < len(frames) and frames[end][0] - still <= seconds + 1e-9:
        end += 1
    return dress, first, end


def _ticks(frames: list, per_step: int) -> list[list]:
    """The frames in consecutive groups of ``per_step`` messages (the last may be short)."""
    return [frames[k:k + per_step] for k in range(0, len(frames), per_step)]


def _run_cell(base, solver: str, frames: list, start: float, tol: float,
              per_step: int = 1, speed_up: int = 1) -> dict:
    """One cell: a copy of the settled GarmentSim ``base`` replays ``frames`` (a motion played
    ``speed_up`` times faster) with ``solver``, a step through ``per_step`` messages at a time
    (1: each message on its own)."""
    import copy

    from cloth_mg_ros.bench.walking import _with_solver
    from cloth_mg_ros.motion.frames import FrameStatus
    from cloth_mg_ros.physics.explicit import ExplicitSimulator

    t0 = time.perf_counter()
    if solver == EXPLICIT:
        gs = copy.deepcopy(base)
        gs.sim = ExplicitSimulator(gs.sim.model, gs.sim.state, gs.sim.dt)
    else:
        gs = _with_solver(base, solver, tol)
    gs.failures = 0
    watch = CellWatch(float(gs.sim.model.mass.sum()), speed_up)
    # A blowing-up run overflows on purpose; its warnings would drown the report.
    with np.errstate(all="ignore"):
        for group in _ticks(frames, per_step):
            res = gs.push(*group[0]) if len(group) == 1 else gs.advance(group)
            if isinstance(res, FrameStatus):
                watch.skipped += 1  # not simulated: the cell must say so
                continue
            finite = bool(np.all(np.isfinite(gs.sim.state.x)))
            watch.add(res, gs.sim.state.v, finite, gs.failures, group[-1][0] - start)
            if watch.fatal:
                break
    cell = {"outcome": watch.outcome, **watch.figures(),
            "wall_s": round(time.perf_counter() - t0, 3)}
    cell["stopped_early"] = watch.fatal and watch.ticks < len(_ticks(frames, per_step))
    return cell


def faster(frames: list, speed: int, seconds: float | None = None) -> list:
    """The motion of ``frames`` [(stamp, poses)] played ``speed`` times faster: its still
    lead-in as it is, then every speed-th message of the motion, one per original interval.

    seconds: with speed > 1, a sped-up clip shorter than this many seconds plays on backwards,
    then forwards again (turning at its ends, as a limb swinging back), until it lasts that
    long, so that fast cells step as long as the others do."""
    if speed == 1:
        return frames
    ref = frames[0][1]
    first = next((k for k, (_, p) in enumerate(frames) if p.shape != ref.shape
                  or np.max(np.abs(p - ref)) > 1e-9), len(frames))
    sampled = [poses for _, poses in frames[max(first - 1, 0)::speed]]
    out = list(frames[:first])
    stamp, gap = frames[first - 1][0], frames[1][0] - frames[0][0]
    moving = sampled[1:]
    if seconds is not None and len(sampled) > 1:
        back, forth = sampled[-2::-1], sampled[1:]
        while len(moving) * gap < seconds - 1e-9:
            moving += back if len(moving) // (len(sampled) - 1) % 2 else forth
        moving = moving[:max(1, round(seconds / gap))]
    for k, poses in enumerate(moving, start=1):
        out.append((stamp + k * gap, poses))
    return out


def _settle(gs, frames: list, per_step: int) -> dict:
    """Settle ``gs`` through ``frames`` with its own step; returns {"solver_failures"}."""
    from cloth_mg_ros.bench.walking import replay

    if per_step == 1:
        return replay(gs, frames)
    for group in _ticks(frames, per_step):
        gs.advance(group)
    return {"solver_failures": gs.failures}


def run_unit(unit: tuple) -> list[dict]:
    """Every solver's cell of one (material, motion, dt, size, speed): dress, settle, replay
    each."""
    material, motion, dt, solvers, particles, seconds, tol, speed = unit
    from cloth_mg_ros.bags import read_pose_frames
    from cloth_mg_ros.bench.walking import _dress, _options
    from cloth_mg_ros.motion.avatar import Avatar
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.runner import resolve_bag
    from cloth_mg_ros.scene_config import load_scene

    t0 = time.perf_counter()
    params = load_scene(MOTIONS[motion])
    frames = read_pose_frames(resolve_bag(params["bag"]), params["topic"])
    frames = faster(frames, speed, seconds)
    dress, first, end = motion_window(frames, seconds)
    # One thread per cell: the workers already take every core.
    opts = _options(params, params["garment"], particles, SETTLE_SOLVER, tol, threads=1)
    per_step = messages_per_step(dt)
    opts.substeps = substeps_for(dt)
    opts.max_step = max(dt * (1.0 + 1e-9), opts.max_step) if per_step > 1 else opts.max_step
    opts.max_substep_motion = SUBSTEP_MOTION_OFF
    # A k-times faster body moves k times further per message: that is motion to simulate,
    # not a teleport for the garment to be carried across.
    opts.teleport_m *= speed
    opts.depth = garment_depth(params["garment"], particles)
    base, k = _dress(Avatar.load(), frames[dress:], get_material(material), opts)
    with np.errstate(all="ignore"):
        settle = _settle(base, frames[dress + k + 1:first], per_step)
    start = frames[first - 1][0]
    common = {"material": material, "dt": dt, "motion": motion,
              "dt_label": dt_label(dt), "garment": params["garment"],
              "particles": int(base.sim.model.n),
              "levels": len(base.garment.hierarchy.levels),
              "particles_requested": particles, "speed": speed, "substeps": opts.substeps,
              "messages_per_step": per_step,
              "simulated_s": round(frames[end - 1][0] - start, 4),
              "settle_failures": settle["solver_failures"],
              "prepare_s": round(time.perf_counter() - t0, 3)}
    cells = []
    for solver in solvers:
        cell = {**common, "solver": solver}
        cell.update(_run_cell(base, solver, frames[first:end], start, tol, per_step, speed))
        cells.append(cell)
    return cells


def _run_units(client, units: list, done) -> None:
    """Every unit as a Dask task on `client`; done(cells) as each finishes. A unit that
    raises stops the map (its cells would be missing from it)."""
    from cloth_mg_ros.cluster import run_tasks

    for _, unit_cells, error in run_tasks(client, run_unit, units, desc="stability",
                                          progress=False):
        if error is not None:
            raise error
        done(unit_cells)


def bench_stability(cfg: StabilityConfig, log=None, client=None) -> dict:
    """Run every cell of ``cfg``; returns {"cells": [...], "summary": {...}, "meta": {...}}.

    The units (one material, motion, step, size and speed: every solver's cell) run as Dask
    tasks: on `client` when given, else on an embedded LocalCluster of ``cfg.jobs`` workers or
    on the running scheduler ``cfg.scheduler``; with one worker and no scheduler, in this
    process. log: a callable taking one line of progress (default: print to stderr)."""
    from cloth_mg_ros.bench.solvers import _meta as solver_meta

    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    meta = solver_meta("stability", cfg.tol, None, None, 1, None, None, "bdf2")
    for key in ("systems", "repeat", "dt", "max_seconds", "levels"):
        meta.pop(key, None)
    meta.update(materials=cfg.materials, dts=cfg.dts, motions=cfg.motions,
                solvers=cfg.solvers, particles_requested=cfg.particles, speeds=cfg.speeds,
                seconds=cfg.seconds,
                jobs=cfg.jobs, scheduler=cfg.scheduler, settle_s=SETTLE_S, settle_solver=SETTLE_SOLVER,
                min_levels=MIN_LEVELS,
                bounds={"max_speed_m_s": MAX_SPEED,
                        "max_specific_kinetic_J_kg": MAX_SPECIFIC_KINETIC,
                        "max_penetration_m": MAX_PENETRATION},
                scenes={m: MOTIONS[m] for m in cfg.motions})
    # The most work first (smallest dt), so that the workers finish together.
    units = [(mat, motion, dt, tuple(cfg.solvers), n, cfg.seconds, cfg.tol, speed)
             for n in sorted(cfg.particles, reverse=True) for speed in cfg.speeds
             for dt in sorted(cfg.dts) for mat in cfg.materials for motion in cfg.motions]
    t0 = time.perf_counter()
    cells: list[dict] = []

    def done(unit_cells: list[dict]) -> None:
        cells.extend(unit_cells)
        c = unit_cells[0]
        line = " ".join(f"{x['solver']}={x['outcome']}" for x in unit_cells)
        log(f"[{len(cells) // len(cfg.solvers)}/{len(units)}] {c['particles']:6d} "
            f"x{c['speed']} "
            f"{c['material']:7s} {c['dt_label']:>6s} {c['motion']:10s} {line} "
            f"({time.perf_counter() - t0:.0f} s)")

    if client is not None:
        _run_units(client, units, done)
    elif cfg.jobs == 1 and not cfg.scheduler:
        for unit in units:  # in this process, no cluster
            done(run_unit(unit))
    else:
        from cloth_mg_ros.cluster import dask_client

        with dask_client(cfg.scheduler, min(cfg.jobs, len(units)), log) as c:
            _run_units(c, units, done)
    order = {key: i for i, key in enumerate(
        (n, v, m, d, mo, s) for n in cfg.particles for v in cfg.speeds for m in cfg.materials
        for d in cfg.dts for mo in cfg.motions for s in cfg.solvers)}
    cells.sort(key=lambda c: order[(c["particles_requested"], c["speed"], c["material"],
                                    c["dt"], c["motion"], c["solver"])])
    meta["wall_s"] = round(time.perf_counter() - t0, 1)
    return {"cells": cells, "summary": summarise(cells, cfg.solvers), "meta": meta}


def summarise(cells: list[dict], solvers: list[str]) -> dict:
    """Counts per solver per outcome, and whether mg is ok in every cell (None: not run)."""
    counts = {s: {o: 0 for o in OUTCOMES} for s in solvers}
    for c in cells:
        counts[c["solver"]][c["outcome"]] += 1
    mg = [c for c in cells if c["solver"] == "mg"]
    return {"counts": counts,
            "mg_ok_everywhere": None if not mg else all(c["outcome"] == "ok" for c in mg),
            "cells": len(cells)}


# -- reporting ----------------------------------------------------------------------------
CODES = {"ok": ".", "not_converged": "NC", "tunnelled": "T", "blew_up": "B", "nan": "N"}
COLOURS = {"ok": "#4caf50", "not_converged": "#ffd54f", "tunnelled": "#ff9800",
           "blew_up": "#e53935", "nan": "#4a148c"}


def _sizes(meta: dict) -> list[int]:
    """The particle counts requested (one int in JSON written before the resolution axis)."""
    req = meta["particles_requested"]
    return list(req) if isinstance(req, (list, tuple)) else [int(req)]


def _key(c: dict, sizes: list[int]) -> tuple:
    """(particles requested, speed, material, dt, motion, solver) of a cell."""
    return (c.get("particles_requested", sizes[0]), c.get("speed", 1), c["material"], c["dt"],
            c["motion"], c["solver"])


def format_stability_report(result: dict) -> str:
    """The printed map (one block per motion: rows material x dt, columns solvers; '.' ok,
    NC not converged, T tunnelled, B blew up, N NaN), the counts per solver and the verdict
    on mg."""
    from cloth_mg_ros.text_table import text_table

    cells, meta, summary = result["cells"], result["meta"], result["summary"]
    solvers = meta["solvers"]
    sizes = _sizes(meta)
    speeds = meta.get("speeds", [1])
    find = {_key(c, sizes): c for c in cells}
    head = (f"bench stability: {', '.join(map(str, sizes))} particles requested, motion "
            f"speed {', '.join(f'x{v}' for v in speeds)}, "
            f"{meta['seconds']:g} s of motion after a {meta['settle_s']:g} s settle, tol "
            f"{meta['tol']:g}, OPENBLAS_NUM_THREADS={meta['OPENBLAS_NUM_THREADS']}, "
            f"{meta['machine']}")
    key = (f"cells: . ok, NC not converged, T tunnelled (penetration > "
           f"{MAX_PENETRATION * 100:g} cm), B blew up (speed > {MAX_SPEED:g} m/s or "
           f"kinetic energy > {MAX_SPECIFIC_KINETIC:g} J/kg; at speed xk, k times and k^2 "
           f"times those), N NaN; a step longer than the 1/30 s pose interval goes through 2 "
           f"or more pose messages")
    lines = [head, key]
    for n in sizes:
        for v in speeds:
            for motion in meta["motions"]:
                some = next((c for c in cells if c["motion"] == motion
                             and _key(c, sizes)[:2] == (n, v)), None)
                if some is None:
                    continue
                title = (f"{motion} x{v} ({some['garment']}, {some['particles']} particles, "
                         f"{some['levels']} levels, {some['simulated_s']:g} s)")
                lines += ["", title]
                rows = []
                for mat in meta["materials"]:
                    for dt in meta["dts"]:
                        rows.append([f"{mat} {dt_label(dt)}"] + [
                            CODES[find[(n, v, mat, dt, motion, s)]["outcome"]]
                            if (n, v, mat, dt, motion, s) in find else "-" for s in solvers])
                lines.append(text_table(["material dt"] + list(solvers), rows))
    lines += ["", "outcomes per solver"]
    rows = [[s] + [str(summary["counts"][s][o]) for o in OUTCOMES] for s in solvers]
    lines.append(text_table(["solver", *OUTCOMES], rows))
    verdict = summary["mg_ok_everywhere"]
    if verdict is not None:
        bad = [c for c in cells if c["solver"] == "mg" and c["outcome"] != "ok"]
        lines.append("mg ok in every cell: " + ("yes" if verdict else
                     f"NO ({len(bad)} cells: " + ", ".join(
                         f"{c['material']} {c['dt_label']} {c['motion']} {c['outcome']}"
                         for c in bad[:10]) + ")"))
    skipped = [c for c in cells if c.get("skipped_messages")]
    if skipped:
        lines.append(f"NOT SIMULATED: {sum(c['skipped_messages'] for c in skipped)} pose "
                     f"messages (teleports or bad frames) in {len(skipped)} cells")
    where = f"on {meta['scheduler']}" if meta.get("scheduler") else (
        f"with {meta['jobs']} worker(s)")
    lines.append(f"wall time {meta['wall_s']:.0f} s {where}")
    return "\n".join(lines)


def plot_stability(result: dict, png: str | Path) -> Path:
    """Heatmap: rows material x dt, columns motion x solver, one colour per outcome (and its
    code in the cell), a legend. Returns the written path."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from cloth_mg_ros.bench.charts import save_chart

    meta, cells = result["meta"], result["cells"]
    mats, dts, motions, solvers = meta["materials"], meta["dts"], meta["motions"], \
        meta["solvers"]
    sizes = _sizes(meta)
    speeds = meta.get("speeds", [1])
    rows = [(n, v, m, d) for n in sizes for v in speeds for m in mats for d in dts]
    cols = [(mo, s) for mo in motions for s in solvers]
    grid = np.full((len(rows), len(cols)), np.nan)
    find = {_key(c, sizes): c["outcome"] for c in cells}
    for i, (n, v, m, d) in enumerate(rows):
        for j, (mo, s) in enumerate(cols):
            if (n, v, m, d, mo, s) in find:
                grid[i, j] = OUTCOMES.index(find[(n, v, m, d, mo, s)])
    cmap = ListedColormap([COLOURS[o] for o in OUTCOMES]).with_extremes(bad="#dddddd")
    fig, ax = plt.subplots(figsize=(max(7.0, 3.0 + 0.42 * len(cols)), 2.0 + 0.32 * len(rows)),
                           layout="constrained")
    ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-0.5, vmax=len(OUTCOMES) - 0.5,
              aspect="auto", interpolation="nearest")
    for i in range(len(rows)):
        for j in range(len(cols)):
            if not np.isnan(grid[i, j]) and grid[i, j] > 0:
                code = CODES[OUTCOMES[int(grid[i, j])]]
                ax.text(j, i, code, ha="center", va="center", fontsize=6,
                        color="white" if grid[i, j] >= 3 else "black")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([(f"{n} " if len(sizes) > 1 else "")
                        + (f"x{v} " if len(speeds) > 1 else "") + f"{m} {dt_label(d)}"
                        for n, v, m, d in rows], fontsize=7)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels([s for _, s in cols], rotation=90, fontsize=7)
    for k in range(1, len(mats) * len(sizes) * len(speeds)):
        ax.axhline(k * len(dts) - 0.5, color="white" if k % len(mats) else "black", lw=2.5)
    for k in range(1, len(motions)):
        ax.axvline(k * len(solvers) - 0.5, color="white", lw=2.5)
    top = ax.secondary_xaxis("top")
    top.set_xticks([(k + 0.5) * len(solvers) - 0.5 for k in range(len(motions))],
                   labels=motions, fontsize=9, fontweight="bold")
    top.tick_params(length=0)
    fig.suptitle(f"stability: {', '.join(map(str, sizes))} particles, motion "
                 f"{', '.join(f'x{v}' for v in speeds)}, {meta['seconds']:g} s "
                 f"of motion per cell, tol {meta['tol']:g}\nrows: "
                 + ("particles, " if len(sizes) > 1 else "")
                 + ("speed, " if len(speeds) > 1 else "")
                 + "material and step (s); columns: motion and solver", fontsize=9)
    ax.legend(handles=[Patch(color=COLOURS[o], label=o.replace("_", " ")) for o in OUTCOMES],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    return save_chart(fig, png)


# -- command line -------------------------------------------------------------------------
def add_cli(bsub) -> None:
    """Add ``stability`` to the bench sub-parsers ``bsub``."""
    p = bsub.add_parser("stability", help="materials x step sizes x motions x solvers: ok, "
                        "not converged, NaN, blew up or tunnelled (heatmap and JSON)")
    p.add_argument("--materials", default=",".join(DEFAULT_MATERIALS),
                   help=f"comma-separated materials (default {','.join(DEFAULT_MATERIALS)})")
    p.add_argument("--dts", default=",".join(DEFAULT_DTS),
                   help=f"comma-separated steps in s, dividing 1/30 s or spanning 2-7 pose "
                        f"messages (default {','.join(DEFAULT_DTS)})")
    p.add_argument("--motions", default=",".join(MOTIONS),
                   help=f"comma-separated motions (default {','.join(MOTIONS)})")
    p.add_argument("--solvers", default=",".join(DEFAULT_SOLVERS),
                   help=f"comma-separated solvers, 'explicit' for symplectic Euler (default "
                        f"{','.join(DEFAULT_SOLVERS)})")
    p.add_argument("--particles", default=str(DEFAULT_PARTICLES),
                   help=f"comma-separated garment particle counts, the resolution axis "
                        f"(default {DEFAULT_PARTICLES}; at least {MIN_LEVELS} hierarchy "
                        f"levels each)")
    p.add_argument("--speeds", default="1",
                   help=f"comma-separated motion speed-ups, an axis (default 1; at most "
                        f"{MAX_SPEED_UP}): every speed-th pose message, still one per 1/30 s")
    p.add_argument("--seconds", default=str(DEFAULT_SECONDS),
                   help=f"seconds of motion per cell after the still lead-in (default "
                        f"{DEFAULT_SECONDS:g})")
    p.add_argument("--workers", "--jobs", dest="workers", default=str(DEFAULT_JOBS),
                   help=f"Dask workers of the embedded cluster (default {DEFAULT_JOBS}; 1: "
                        f"in this process)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the cells on this running Dask scheduler instead")
    p.add_argument("--json", default="out/bench_stability.json", help="JSON output file")
    p.add_argument("--png", default="out/bench_stability.png", help="heatmap PNG file")
    p.set_defaults(bench_func=cmd_stability)


def cmd_stability(args) -> int:
    """Run the map from parsed CLI args; exit 0, or 1 when mg is not ok in every cell."""
    from cloth_mg_ros.bench.results import write_json

    cfg = validate_stability_args(args.materials, args.dts, args.motions, args.solvers,
                                  args.particles, args.seconds, args.workers,
                                  json_path=args.json, png_path=args.png, speeds=args.speeds,
                                  scheduler=args.scheduler)
    result = bench_stability(cfg)
    print(format_stability_report(result))
    write_json(args.json, result)
    plot_stability(result, args.png)
    print(f"wrote {args.json} and {args.png}")
    return 1 if result["summary"]["mg_ok_everywhere"] is False else 0
