"""`bench stability`'s cells: the outcome bounds and rules (`classify`, `CellWatch`, which folds
in one pose message at a time), and running one unit (`run_unit`: dress and settle the garment
of one material, motion, step, size and speed, then replay the motion with every implicit
scheme and solver, and with the explicit solver once).

`run_unit` is the function the sweep ships to its Dask workers: it stays at module level under
this name."""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.bench.stability.options import (
    EXPLICIT,
    MIN_DEPTH,
    MOTIONS,
    SETTLE_S,
    SETTLE_SCHEME,
    SETTLE_SOLVER,
    SUBSTEP_MOTION_OFF,
    dt_label,
    map_columns,
    messages_per_step,
    substeps_for,
)
from cloth_mg_ros.bench.walking import dress_garment, garment_options, replay, with_solver
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.mesh.garments import MIN_COARSE_VERTICES
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.frames import FrameStatus
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.explicit import ExplicitSimulator
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS

# -- the outcome bounds ------------------------------------------------------------------
MAX_SPEED = 25.0  # m/s: three times the fastest body point of the bundled clips (8.5 m/s)
MAX_SPECIFIC_KINETIC = 50.0  # J/kg: the garment's mean square speed above (10 m/s)^2
MAX_PENETRATION = 0.015  # m: a free particle this deep inside the body or floor after a step
OUTCOMES = ("ok", "not_converged", "tunnelled", "blew_up", "nan")  # by rising severity
FATAL = ("blew_up", "nan")  # stop the cell: nothing later changes its outcome


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


def with_scheme(garment_sim, scheme: str, spectral_radius: float, linearise: str = "start"):
    """``garment_sim`` (a GarmentSim) stepping with the implicit ``scheme`` from now on,
    linearised at ``linearise`` (euler and bdf2; generalised-alpha at the start), on every
    rung built so far and any built later (its options); returns it.

    The state keeps its history: a BDF2 history (x_prev, v_prev) is what BDF2 steps on and
    the other schemes ignore; a scheme whose history is missing (generalised-alpha's
    acceleration after a BDF2 settle) starts with an implicit Euler step, as it does from
    rest."""
    lin = linearise if scheme in ("euler", "bdf2") else "start"
    garment_sim.options.scheme = scheme
    garment_sim.options.spectral_radius = float(spectral_radius)
    garment_sim.options.linearise_at = lin
    for sim in (garment_sim.sim, *garment_sim.rungs.values()):
        sim.scheme, sim.spectral_radius, sim.linearise_at = scheme, float(spectral_radius), lin
    return garment_sim


def _run_cell(base, solver: str, frames: list, start: float, tol: float,
              per_step: int = 1, speed_up: int = 1, scheme: str = SETTLE_SCHEME,
              spectral_radius: float = DEFAULT_SPECTRAL_RADIUS, linearise: str = "start") -> dict:
    """One cell: a copy of the settled GarmentSim ``base`` replays ``frames`` (a motion played
    ``speed_up`` times faster) with ``solver`` and the implicit ``scheme`` (genalpha at
    ``spectral_radius``; the explicit solver has its own; euler and bdf2 linearised at
    ``linearise``), a step through ``per_step`` messages at a time (1: each message on its
    own)."""

    t0 = time.perf_counter()
    if solver == EXPLICIT:
        garment_sim = copy.deepcopy(base)
        garment_sim.sim = ExplicitSimulator(garment_sim.sim.model, garment_sim.sim.state,
                                            garment_sim.sim.dt)
    else:
        garment_sim = with_scheme(with_solver(base, solver, tol), scheme, spectral_radius,
                                  linearise)
    garment_sim.failures = 0
    watch = CellWatch(float(garment_sim.sim.model.mass.sum()), speed_up)
    # A blowing-up run overflows on purpose; its warnings would drown the report.
    with np.errstate(all="ignore"):
        for group in _ticks(frames, per_step):
            res = garment_sim.push(*group[0]) if len(group) == 1 else garment_sim.advance(group)
            if isinstance(res, FrameStatus):
                watch.skipped += 1  # not simulated: the cell must say so
                continue
            finite = bool(np.all(np.isfinite(garment_sim.sim.state.x)))
            watch.add(res, garment_sim.sim.state.v, finite, garment_sim.failures,
                      group[-1][0] - start)
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


def _settle(garment_sim, frames: list, per_step: int) -> dict:
    """Settle ``garment_sim`` through ``frames`` with its own step; returns {"solver_failures"}."""
    if per_step == 1:
        return replay(garment_sim, frames)
    for group in _ticks(frames, per_step):
        garment_sim.advance(group)
    return {"solver_failures": garment_sim.failures}


def run_unit(unit: tuple) -> list[dict]:
    """Every cell of one (material, motion, dt, size, speed): dress, settle (SETTLE_SOLVER and
    SETTLE_SCHEME, common to every cell), then replay the motion with each implicit scheme
    and solver, and the explicit solver once (`options.map_columns`).

    unit: (material, motion, dt, solvers, particles, seconds, tol, speed, schemes,
    spectral_radius, linearise, contact_friction)."""
    (material, motion, dt, solvers, particles, seconds, tol, speed, schemes,
     spectral_radius, linearise, contact_friction) = unit

    t0 = time.perf_counter()
    params = load_scene(MOTIONS[motion])
    frames = read_pose_frames(resolve_bag(params.bag), params.topic)
    frames = faster(frames, speed, seconds)
    dress, first, end = motion_window(frames, seconds)
    # One thread per cell: the workers already take every core.
    opts = garment_options(params, params.garment, particles, SETTLE_SOLVER, tol, threads=1)
    # every cell starts from the same settle, whatever the scene file's scheme
    opts.scheme = SETTLE_SCHEME
    opts.contact_friction = contact_friction
    per_step = messages_per_step(dt)
    opts.substeps = substeps_for(dt)
    opts.max_step = max(dt * (1.0 + 1e-9), opts.max_step) if per_step > 1 else opts.max_step
    opts.max_substep_motion = SUBSTEP_MOTION_OFF
    # A k-times faster body moves k times further per message: that is motion to simulate,
    # not a teleport for the garment to be carried across.
    opts.teleport_m *= speed
    opts.depth = garment_depth(params.garment, particles)
    base, k = dress_garment(Avatar.load(), frames[dress:], get_material(material), opts)
    with np.errstate(all="ignore"):
        settle = _settle(base, frames[dress + k + 1:first], per_step)
    start = frames[first - 1][0]
    common = {"material": material, "dt": dt, "motion": motion,
              "dt_label": dt_label(dt), "garment": params.garment,
              "particles": int(base.sim.model.n),
              "levels": len(base.garment.hierarchy.levels),
              "particles_requested": particles, "speed": speed, "substeps": opts.substeps,
              "contact_friction": base.sim.model.contact_friction,  # as the model took it
              "messages_per_step": per_step,
              "simulated_s": round(frames[end - 1][0] - start, 4),
              "settle_failures": settle["solver_failures"],
              "prepare_s": round(time.perf_counter() - t0, 3)}
    cells = []
    for scheme, solver in map_columns(list(solvers), list(schemes)):
        rho = spectral_radius if scheme == "genalpha" else None
        lin = linearise if scheme in ("euler", "bdf2") else "start"
        cell = {**common, "solver": solver, "scheme": scheme, "spectral_radius": rho,
                "linearise_at": lin}
        cell.update(_run_cell(base, solver, frames[first:end], start, tol, per_step, speed,
                              scheme, spectral_radius, lin))
        cells.append(cell)
    return cells
