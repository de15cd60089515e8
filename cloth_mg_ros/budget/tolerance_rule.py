"""The solve tolerance that the time step allows (`tolerance: auto`), measured per level.

An implicit step's linear solve need not be more exact than the step itself: below the
error that the time step makes, a tighter tolerance buys nothing a user can see and costs
iterations. Per pose message and level of detail, from the same starting state, the message
is taken

* with exact (direct) solves at the scene's step rule: ``x_exact``;
* with exact solves and ``small_factor`` times the steps: the step's own error is the RMS
  distance ``|x_exact - x_small|`` (mm);
* with the scene's solver at each tolerance of a ladder, loosest first: the solver's error
  is ``|x_tol - x_exact|``.

The rule (`tolerance: auto`'s promise): over the clip's pose messages, the solver's error per
message averaged over the messages is at most SOLVER_SHARE (a tenth) of the step's error per
message averaged over the same messages. It is a mean over the clip, not a bound on each
message: where the body hardly moves a message's step error is near nil and no tolerance a
tick can afford keeps a tenth of it, and the largest ratio over a clip grows with the clip's
length, so no calibration could promise it for a clip it has not seen (doc/benchmarks/
pareto.md, "Tolerance auto's rule", has the per-message figures). The cost model's
calibration (cost_model.calibrate) measures the rule on messages spread over the bag's whole
motion (the stride, not only its start) at its own garment's two finest rungs, with a margin
(CALIBRATION_SHARE); a garment's finest level takes the finest rung's tolerance, a coarser
level of detail the coarse rung's, each tighter as (n_rung / n)^0.5 above the rung's size
(sim.solve_tolerance.tolerance_at).
`cloth-mg bench pareto` (part 5) measures the rule on every message of a clip, per level.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SOLVER_SHARE = 0.1  # the solver's error may be this fraction of the step's (clip means)
# The share the calibration asks of its messages, below the rule's own for what it does not
# see: its 40 messages of the walk (their clip ratio is within 5 % of all 78's) and garments
# larger than its 2394 particles, which take its tolerance (at 20K the ratio was 1.12 times
# 2394's: 0.064 against 0.057 at 1e-2, the walk's 60 messages, issue 25's eighth stop). Its
# step error is taken against 4x the steps, not bench pareto's 8x: 15-22 % smaller on the
# walk (the step's error shrinks more slowly than second order across contacts), a further
# margin.
CALIBRATION_SHARE = 0.085
REFERENCE_TOL = 1e-4  # the paper's: the scenes' default and the reference
EXACT_SOLVER = "direct"  # the solves whose error is taken as nil
# The ladder auto chooses from, loosest first. Looser than 1e-2 the solve stops after one or
# two iterations whatever the step allows, and contact forces then lag a step; tighter than
# 1e-5 no step in these scenes is accurate enough to need it. Rungs about 1.5x apart down to
# 1e-4, about one MG-PCG iteration each: where 1e-2 just misses (the 20K walking dress, 1.26
# mm against a share of 1.22), a ladder of 3x steps took 3e-3, a fifth more per tick than the
# 7e-3 that meets it (doc/benchmarks/walking.md, issue 25's sixth stop: 1.33 and 1.10 times
# the tick at 1e-2).
LADDER = (1e-2, 7e-3, 5e-3, 3e-3, 2e-3, 1e-3, 7e-4, 5e-4, 3e-4, 2e-4, 1e-4, 3e-5, 1e-5)
CALIBRATION_SMALL_FACTOR = 4  # BDF2: a 4x smaller step leaves ~6 % of the step's error


def rms_max_mm(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(RMS, max) in mm of the vertex distances between position arrays of equal shape, m."""
    d = np.linalg.norm(a - b, axis=-1)
    return 1e3 * float(np.sqrt(np.mean(d * d))), 1e3 * float(d.max())


def one_message(garment_sim, snap, rung: int, frame) -> tuple[np.ndarray, float]:
    """From the finest's snapshot `snap` of GarmentSim `garment_sim`, restricted to rung
    `rung`, one message `frame` (stamp s, poses (S, 7)): (positions at the rung (n_rung, 3) m,
    the tick's ms)."""
    garment_sim.set_rung(0)
    garment_sim.restore(snap)
    garment_sim.set_rung(rung)
    stats = garment_sim.push(*frame)
    if not np.all(np.isfinite(garment_sim.positions)):
        raise FloatingPointError(f"rung {rung}: the message at {frame[0]:.3f} s failed")
    return garment_sim.positions.copy(), float(stats.total_ms)


@dataclass
class IntervalTolerance:
    """One interval at one level: the step's error (mm RMS), the solver's error (mm RMS)
    and the tick's ms per tolerance tried (loosest first), and the loosest tolerance whose
    error is within the share (None if none tried was)."""

    step_mm: float
    solver_mm: dict[float, float]
    ms: dict[float, float]
    chosen: float | None


class _SolverKept:
    """Within the block the garment may change its solver and step rule; they are as they
    were afterwards."""

    def __init__(self, garment_sim):
        self.garment_sim, o = garment_sim, garment_sim.options
        self.kept = (o.solver, o.tolerance, o.substeps, o.max_substep_motion)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        o = self.garment_sim.options
        o.substeps, o.max_substep_motion = self.kept[2], self.kept[3]
        self.garment_sim.set_solver(self.kept[0], self.kept[1])


def step_reference(garment_sim, snap, rung: int, frame,
                   small_factor: int = CALIBRATION_SMALL_FACTOR
                   ) -> tuple[np.ndarray, float]:
    """One message `frame` of GarmentSim `garment_sim` at rung `rung` from the finest's
    snapshot `snap`, solved exactly at the scene's step rule: (its positions (n_rung, 3) m, the
    step's own error: their RMS distance from the same message with small_factor times the
    steps, mm).
    The garment's solver and step rule are as they were afterwards."""
    o = garment_sim.options
    with _SolverKept(garment_sim):
        garment_sim.set_solver(EXACT_SOLVER, REFERENCE_TOL)
        exact, _ = one_message(garment_sim, snap, rung, frame)
        o.substeps, o.max_substep_motion = o.substeps * small_factor,\
            o.max_substep_motion / small_factor
        small, _ = one_message(garment_sim, snap, rung, frame)
    return exact, rms_max_mm(exact, small)[0]


def solver_error(garment_sim, snap, rung: int, frame, solver: str, tol: float, exact: np.ndarray
                 ) -> tuple[float, float]:
    """The same message with `solver` at `tol`: (its RMS distance from `exact`, mm; the
    tick's ms). The garment's solver is as it was afterwards."""
    with _SolverKept(garment_sim):
        garment_sim.set_solver(solver, tol)
        x, ms = one_message(garment_sim, snap, rung, frame)
    return rms_max_mm(x, exact)[0], ms


def interval_tolerance(garment_sim, snap, rung: int, frame, solver: str,
                       tols: tuple[float, ...] = LADDER,
                       small_factor: int = CALIBRATION_SMALL_FACTOR,
                       share: float = SOLVER_SHARE) -> IntervalTolerance:
    """One pose interval (module docstring) of GarmentSim `garment_sim` at rung `rung` from the
    finest's snapshot `snap` with message `frame`, every tolerance of `tols` tried (the chart)."""
    exact, step = step_reference(garment_sim, snap, rung, frame, small_factor)
    errors, ms, chosen = {}, {}, None
    for tol in sorted(tols, reverse=True):
        errors[tol], ms[tol] = solver_error(garment_sim, snap, rung, frame, solver, tol, exact)
        if chosen is None and errors[tol] <= share * step:
            chosen = tol
    return IntervalTolerance(step, errors, ms, chosen)


@dataclass
class RungTolerance:
    """tolerance auto at one rung (level of detail, sim.detail): particles, the chosen tolerance,
    the step error and the chosen tolerance's solver error per message averaged over the sampled
    messages (mm RMS), the mean solver error of every tolerance tried, loosest first (those
    looser than the chosen one failed the share), per sampled message (stamp s, step error
    mm, the chosen tolerance's solver error mm), and per sampled message the chosen
    tolerance's tick, ms (each from the same restored state: how the motion's messages
    compare in cost, the cost model's margin for slow ticks)."""

    particles: int
    tolerance: float
    step_mm: float
    solver_mm: float
    tried: dict[float, float]
    messages: list[tuple[float, float, float]]
    tick_ms: list[float] = field(default_factory=list)

    @property
    def ratio(self) -> float:
        """The rule's ratio: mean solver error / mean step error over the sampled messages."""
        return self.solver_mm / self.step_mm if self.step_mm > 0.0 else float("inf")


def measure_tolerances(garment_sim, frames: list, intervals: int = 3,
                       tols: tuple[float, ...] = LADDER,
                       small_factor: int = CALIBRATION_SMALL_FACTOR,
                       share: float = SOLVER_SHARE) -> list[RungTolerance]:
    """`tolerance: auto`'s calibration on a settled GarmentSim `garment_sim` (at any level)
    over pose `frames` [(stamp s, poses (S, 7))] of motion. The finest level steps through
    the frames with the scene's solver at REFERENCE_TOL; from its state before `intervals`
    messages spread evenly from the first frame to the last, every level of detail takes the
    message exactly, with smaller steps, and with the scene's solver at each tolerance of
    `tols`, loosest first. A level's tolerance is the loosest whose solver error per message,
    averaged over the sampled messages, is at most `share` of the step's error per message
    averaged over the same messages (the module docstring says why a mean); the tightest of
    `tols` where none is. Returns one RungTolerance per rung, finest first; garment_sim
    is left at its finest level after the last frame, its solver as it was."""
    solver = garment_sim.options.solver
    levels = garment_sim.rung_indices()
    picked = set(np.linspace(0, len(frames) - 1, max(1, intervals)).round().astype(int))
    starts = []  # (the finest's snapshot, the message) per sampled message
    garment_sim.prepare_rungs()
    garment_sim.set_rung(0)
    with _SolverKept(garment_sim):
        garment_sim.set_solver(solver, REFERENCE_TOL)
        for k, frame in enumerate(frames):
            if k in picked:
                starts.append((garment_sim.snapshot(), frame))
            garment_sim.push(*frame)
        end = garment_sim.snapshot()
        out = [_rung_tolerance(garment_sim, rung, starts, solver, tols, small_factor, share)
               for rung in levels]
        garment_sim.set_rung(0)
        garment_sim.restore(end)
    return out


def _rung_tolerance(garment_sim, rung: int, starts: list, solver: str, tols, small_factor: int,
                    share: float) -> RungTolerance:
    """measure_tolerances at one rung over the sampled (snapshot, message) `starts`. Each pass
    (exact, small steps, one tolerance) sets its solver once for every message (a new solver
    rebuilds every rung's hierarchy); the caller restores the garment's own."""
    o = garment_sim.options
    garment_sim.set_solver(EXACT_SOLVER, REFERENCE_TOL)
    exact = [one_message(garment_sim, snap, rung, frame)[0] for snap, frame in starts]
    kept = o.substeps, o.max_substep_motion
    o.substeps = o.substeps * small_factor
    o.max_substep_motion = o.max_substep_motion / small_factor
    try:
        steps = [rms_max_mm(x, one_message(garment_sim, snap, rung, frame)[0])[0]
                 for x, (snap, frame) in zip(exact, starts, strict=True)]
    finally:
        o.substeps, o.max_substep_motion = kept
    step = float(np.mean(steps))
    tried: dict[float, float] = {}
    for tol in sorted(tols, reverse=True):
        garment_sim.set_solver(solver, tol)
        runs = [one_message(garment_sim, snap, rung, frame) for snap, frame in starts]
        errors = [rms_max_mm(x_tol, x)[0] for (x_tol, _), x in zip(runs, exact, strict=True)]
        tried[tol] = float(np.mean(errors))
        if tried[tol] <= share * step or tol == min(tols):
            messages = [(float(frame[0]), s, e)
                        for (_, frame), s, e in zip(starts, steps, errors, strict=True)]
            return RungTolerance(garment_sim.rung_particles(rung), tol, step, tried[tol],
                                  tried, messages, [ms for _, ms in runs])
    raise ValueError("tols is empty")
