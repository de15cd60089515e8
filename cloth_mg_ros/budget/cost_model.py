"""What a tick costs on this machine, measured, and the resolution a budget allows.

A short calibration dresses the scene's garment at `CALIBRATION_PARTICLES` on the avatar, lets
it settle on the bag's opening pose (the bundled bags hold their first pose for a second) and
steps it through the first second of the motion at two rungs of its own hierarchy (the
finest and the next coarser, a quarter of the particles), with the scene's solver, tolerance,
threads, contacts and step rule (with ``tolerance: auto`` each rung's tolerance is measured
first, on messages spread over the bag's whole motion: budget.tolerance_rule): a moving body is
what a tick must keep up with, and the steps the step rule asks for (one per tick for a loose
dress on a walk, five for a skirt on a run) are only seen in motion. Multigrid costs grow
linearly with the particles at one tolerance, so up to the calibration's size each step
costs about ``a + b n`` ms (both rungs timed at the tolerance a garment's finest level of
their size takes). With ``tolerance: auto`` a larger garment's finest level solves tighter
and costs more per particle, so a garment PROBE_FACTOR times the calibration's size is
dressed, settled and timed too, and the model runs on from the fine point to it
(`CostModel.step_ms`). A tick takes as many steps as
the scene's step rule asks at the stream's rate (`CostModel.steps_per_tick`). The
result is cached per machine, package version and code, and scene settings under the user's
cache folder ($CLOTH_MG_CACHE, else $XDG_CACHE_HOME/cloth_mg_ros, else ~/.cache/cloth_mg_ros),
so only the first start pays it.

`cloth-mg bench cost` prints the prediction against measured ticks at several sizes.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass, field, replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from cloth_mg_ros.budget.tolerance_rule import CALIBRATION_SHARE, REFERENCE_TOL, measure_tolerances
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.mesh.garments import MIN_PARTICLES
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.solve_tolerance import AUTO as TOLERANCE_AUTO
from cloth_mg_ros.sim.solve_tolerance import tolerance_at
from cloth_mg_ros.sim.tick_stats import TickStats
from cloth_mg_ros.solvers.threads import resolve_threads

CALIBRATION_PARTICLES = 2400  # its two finest rungs (2400 and ~600) are the two points
CALIBRATION_WARMUP = 15  # ticks at the coarse rung before timing (0.5 s at 30 Hz)
# timed ticks per rung, the median counts: 28 messages, the walk's first 0.93 s of motion (7,
# its first half second, cost more than the clip's median tick at a loose tolerance:
# doc/benchmarks/cost.md)
CALIBRATION_TICKS = 14
CALIBRATION_PERIOD = 1.0 / 30.0  # s, the bundled walking bag's pose period
# tolerance auto's probe garment: this many times CALIBRATION_PARTICLES (the next size up the
# 1-to-4 family, about the body scenes' max_particles), dressed and settled on the hold like
# the calibration's own and timed on the same messages, tick for tick beside its rungs (about
# 5 s more on the walk). A larger garment's finest level solves tighter (4.9e-3 at 9964
# particles against 1e-2 at 2394) and takes more iterations a step, which the line through the
# two rungs cannot show (doc/benchmarks/cost.md). At a fixed tolerance the line alone held
# within 8 % up to 10K particles on the walk.
PROBE_FACTOR = 4
DEFAULT_TICK_BUDGET = 0.7  # of the pose period: what is left covers publishing and jitter
# 3: timed on the motion, not the opening hold; 4: tolerance auto's finer ladder; 5: tolerance
# auto measured over the bag's whole motion (the stride, not only its first half second); 6:
# tolerance auto settled through the bag's whole opening hold; 7: both rungs timed at the finest
# level's tolerance, and the probe garment
CACHE_VERSION = 7
# tolerance auto: the pose messages measured per rung, spread evenly over the bag's motion from
# the settled state on, to the bag's end or TOLERANCE_SPAN_S (s) later: every second message
# of the bundled walk (78). One message's solver error ranges over an order of magnitude (at
# 1e-2 and 2394 particles, 0.3 to 6 mm), so a few messages misjudge the clip's mean; on the
# walk's 78 messages (bench pareto part 5), 26 or 39 evenly spread ones pick what all 78 do.
TOLERANCE_INTERVALS = 40
TOLERANCE_SPAN_S = 20.0
# Slow ticks against the median (slow_ticks): the calibration's first second of motion sees
# too little of a gait cycle to measure the tail, so `auto` keeps at least this margin for its
# slow ticks, about the p95 / median that `bench cost` measured over the walking dress's motion
# (doc/design-measurements.md, 'The cost model's margin', has the figures), and at most
# TAIL_CAP (a stall of the machine is not the motion's).
TAIL_FLOOR = 1.5
TAIL_CAP = 2.0
# The scene settings a tick's cost depends on (BodySimOptions fields).
COST_KEYS = ("garment", "solver", "tolerance", "levels", "substeps", "max_substep_motion",
             "max_step", "floor", "self_contact", "threads", "scheme", "strain_limit",
             "newton_iterations", "linearise_at", "contact_friction")


@dataclass
class CostModel:
    """Tick cost (ms) as a function of particles for one scene's settings on one machine.

    step_ms(n) = a_ms + b_ms * n per step up to the calibration's finest rung, then on to the
    probe garment's point (step_ms); points: the calibration's two rungs' (particles, ms per
    step), each at the tolerance a garment's finest level of its size takes; motion_steps: the
    steps per tick the calibration's motion asked for beyond the rule's floor, at
    CALIBRATION_PERIOD (scaled with the period: a shorter interval moves the body less per
    tick)."""

    a_ms: float
    b_ms: float
    points: list[tuple[int, float]]
    motion_steps: float
    settings: dict
    machine: str
    version: str
    calibration_s: float
    tail: float = 1.0  # slow ticks / median ticks in the calibration (slow_ticks)
    created: float = field(default_factory=time.time)
    # tolerance auto: (particles, tolerance) per rung, measured before the timing:
    # budget.tolerance_rule.measure_tolerances
    tolerances: list[tuple[int, float]] = field(default_factory=list)
    # and per rung what it measured: {"particles", "tolerance", "step_mm", "solver_mm" (per
    # message, mean over the sampled messages), "ratio", "stamps" (the sampled messages, s),
    # "tick_ms" (each sampled message's tick at the rung's tolerance)}
    tolerance_rule: list[dict] = field(default_factory=list)
    # the probe garment's [particles, ms per step] (PROBE_FACTOR times the calibration's size,
    # its finest level at the tolerance a garment that size takes); [] in models without it
    probe: list = field(default_factory=list)

    def upper_ms(self) -> tuple[float, float, float]:
        """(n_fine, its ms a step on the line, ms per particle above it): the model's second
        piece, from the finest rung to the probe, never cheaper per particle than the line."""
        n_fine = float(self.points[-1][0]) if self.points else 0.0
        at_fine = self.a_ms + self.b_ms * n_fine
        if not self.probe or float(self.probe[0]) <= n_fine:
            return n_fine, at_fine, self.b_ms
        rise = (float(self.probe[1]) - at_fine) / (float(self.probe[0]) - n_fine)
        return n_fine, at_fine, max(self.b_ms, rise)

    def step_ms(self, particles: float) -> float:
        """Predicted ms of one step of a garment of ``particles`` at its finest level: the
        line a + b n up to the calibration's finest rung, then on to the probe's point (and
        past it at that slope)."""
        n = float(particles)
        n_fine, at_fine, upper = self.upper_ms()
        return self.a_ms + self.b_ms * n if n <= n_fine else at_fine + upper * (n - n_fine)

    def steps_per_tick(self, period_s: float) -> float:
        """Steps one tick takes at a pose period of period_s: the rule's floor (substeps and
        max_step) or the motion's share, whichever is more."""
        s = self.settings
        floor = max(int(s["substeps"]), math.ceil(period_s / float(s["max_step"]) - 1e-9))
        return max(float(floor), self.motion_steps * period_s / CALIBRATION_PERIOD)

    def tick_ms(self, particles: float, period_s: float) -> float:
        """Predicted ms of one tick of a garment of ``particles`` at pose period period_s."""
        return self.steps_per_tick(period_s) * self.step_ms(particles)

    def particles_for(self, budget_ms: float, period_s: float) -> float:
        """The most particles whose slow ticks (the predicted median times `tail`) fit
        budget_ms (0 if none does)."""
        per_step = budget_ms / (self.steps_per_tick(period_s) * self.tail)
        n_fine, at_fine, upper = self.upper_ms()
        if per_step > at_fine:
            return n_fine + (per_step - at_fine) / upper
        return max(0.0, (per_step - self.a_ms) / self.b_ms)

    def to_json(self) -> dict:
        return asdict(self)


def machine_id() -> str:
    """A name for this machine's speed: processor model, core count, architecture, host."""
    model = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.node()}|{model}|{os.cpu_count()}|{platform.machine()}"


def package_version() -> str:
    try:
        return version("cloth_mg_ros")
    except PackageNotFoundError:
        return "0+unknown"


@functools.cache
def code_fingerprint() -> str:
    """A digest of the package's Python sources: what a calibration measured depends on the
    code that ran it, and a version number does not change with every edit (a calibration
    cached before a change to the solver or the garment was used after it). 16-33 ms, once
    a process."""
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def cache_dir() -> Path:
    base = os.environ.get("CLOTH_MG_CACHE")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "cloth_mg_ros"


def cost_settings(options) -> dict:
    """The settings of a BodySimOptions a tick's cost depends on (JSON-ready)."""
    return {k: getattr(options, k) for k in COST_KEYS}


def cache_path(options, bag: str = "walk", material=None) -> Path:
    """The cache file of a cost model for BodySimOptions `options` on `bag` with `material`
    (physics.materials.Material; its parameters are part of the key: the iterations a tick
    takes and the tolerance auto measures depend on the fabric)."""
    fabric = None if material is None else asdict(material)
    # One entry per bag and thread count however they are spelled ("walk" or its folder;
    # threads 0 or the cores it means): each spelling was calibrated again, 30-60 s.
    settings = dict(cost_settings(options), threads=resolve_threads(options.threads))
    try:
        where = str(resolve_bag(bag).resolve())
    except ClothInputError:
        where = str(bag)  # calibrating it names the problem
    key = json.dumps({"settings": settings, "bag": where, "machine": machine_id(),
                      "version": package_version(), "code": code_fingerprint(),
                      "cache": CACHE_VERSION,
                      "material": fabric}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return cache_dir() / f"cost-{digest}.json"


def fit_linear(points: list[tuple[int, float]]) -> tuple[float, float]:
    """Least-squares a + b n through (n, ms) points, with a >= 0 and b > 0."""
    n = np.array([p[0] for p in points], dtype=float)
    ms = np.array([p[1] for p in points], dtype=float)
    b, a = np.polyfit(n, ms, 1) if len(points) > 1 else (ms[0] / n[0], 0.0)
    if b <= 0.0:  # noise made the coarse rung dearer: all the cost per particle
        a, b = 0.0, float(ms.max() / n.max())
    if a < 0.0:
        a, b = 0.0, float(np.sum(n * ms) / np.sum(n * n))
    return float(a), float(b)


def motion_start(frames: list) -> int:
    """Index of the first pose frame [(stamp s, poses (S, 7))] that differs from the first
    (the bundled bags hold their opening pose for a second); 1 for a bag that moves at once,
    len(frames) for one that never moves."""
    first = frames[0][1]
    for k in range(1, len(frames)):
        if not np.array_equal(frames[k][1], first):
            return k
    return len(frames)


def calibration_frames(frames: list) -> tuple[list, int]:
    """The frames a calibration uses and how many of them (after the first, the dressing
    pose) are warm-up: up to CALIBRATION_WARMUP ticks on the opening hold (the settling), then
    2 x CALIBRATION_TICKS of motion. A bag with no hold warms up on its first motion."""
    timed = 2 * CALIBRATION_TICKS
    start = motion_start(frames)
    if start >= len(frames):
        start = 1  # a still bag: time the hold
    dress = max(start - 1 - CALIBRATION_WARMUP, 0)
    warmup = start - 1 - dress if start > 1 else CALIBRATION_WARMUP
    picked = frames[dress:dress + 1 + warmup + timed]
    if len(picked) < 1 + warmup + timed:
        raise ClothInputError(f"{len(frames)} poses are too few to calibrate the cost model "
                              f"({dress + 1 + warmup + timed} needed: the opening hold, then "
                              f"{timed} poses of motion); give the scene a longer bag, or a "
                              f"fixed particles and tolerance")
    return picked, warmup


def calibrate(options, material, log=None, bag: str = "walk") -> CostModel:
    """Measure the cost model for a scene's options (BodySimOptions) and material on the
    scene's bag (a bundled name or a path): its opening hold settles the garment, its first
    motion is timed and sets how many steps the step rule asks for."""
    t0 = time.perf_counter()
    auto_tol = options.tolerance == TOLERANCE_AUTO
    try:
        every_frame = read_pose_frames(resolve_bag(bag), "avatar/body_poses")
        frames, warmup = calibration_frames(every_frame)
    except ClothInputError as exc:
        raise ClothInputError(f"bag {bag}: {exc}") from None
    period = 1.0 / stream_rate([st for st, _ in frames])
    # tolerance auto settles at the reference tolerance until the rungs' own are measured
    opts = replace(options, particles=CALIBRATION_PARTICLES, depth=None,
                   tolerance=REFERENCE_TOL if auto_tol else options.tolerance)
    timed = frames[1 + warmup][0]  # the first message after the settle
    garment_sim = _settled(opts, material, every_frame, frames[:1 + warmup], timed, auto_tol)
    fine, coarse = garment_sim.rung_indices()[0], garment_sim.rung_indices()[1]
    tolerances: list[tuple[int, float]] = []
    rule: list[dict] = []
    if auto_tol:
        tolerances, rule = _rung_tolerances(
            garment_sim, tolerance_frames(every_frame, timed), coarse, log)
        opts.tolerances = tuple(tolerances)
    # both rungs at the tolerance a garment's finest level of their size takes (a coarse
    # rung's level-of-detail tolerance is tighter: sim.solve_tolerance.tolerance_at)
    tol = tolerance_at(tolerances, garment_sim.rung_particles(fine), 0) if auto_tol else None
    big = None if not auto_tol else _settled(
        replace(opts, tolerance=options.tolerance, depth=None,
                particles=PROBE_FACTOR * CALIBRATION_PARTICLES),
        material, every_frame, frames[:1 + warmup], timed, True, rungs=False)
    per_step, steps, big_ms = _time_rungs(garment_sim, [fine, coarse], tol,
                                          frames[1 + warmup:], big)
    points = [(garment_sim.rung_particles(lv), float(np.median(per_step[k])))
              for k, lv in ((1, coarse), (0, fine)) if per_step[k]]
    a, b = fit_linear(points)
    probe = [int(big.particles), float(np.median(big_ms))] if big_ms else []
    # tolerance auto's 40 messages per rung span the bag's motion, not only its first second
    tail = slow_ticks([*per_step, big_ms, *(r["tick_ms"] for r in rule)])
    floor = max(int(opts.substeps), math.ceil(period / opts.max_step - 1e-9))
    motion = (float(np.mean(steps)) if steps else float(floor)) * CALIBRATION_PERIOD / period
    model = CostModel(a, b, points, motion if motion > floor else 0.0, cost_settings(options),
                      machine_id(), package_version(), time.perf_counter() - t0, tail,
                      tolerances=tolerances, tolerance_rule=rule, probe=probe)
    if log is not None:
        log(f"cost model calibrated in {model.calibration_s:.2f} s: "
            f"{a:.2f} ms + {1e3 * b:.2f} ms per 1000 particles per step up to {points[-1][0]}"
            f" particles, {1e3 * model.upper_ms()[2]:.2f} ms per 1000 above" + (
                f" (the probe: {probe[1]:.2f} ms a step at {probe[0]} particles)"
                if probe else ""))
    return model


def slow_ticks(sets: list[list[float]]) -> float:
    """The 95th percentile of ticks (ms per step or per tick, one list per rung or garment),
    each against its own list's median and all of them pooled (14 or 40 ticks are few for a
    95th percentile each), within [TAIL_FLOOR, TAIL_CAP]."""
    ratios = [np.asarray(v, dtype=float) / np.median(v) for v in sets if len(v)]
    if not ratios:
        return TAIL_FLOOR
    return min(max(float(np.percentile(np.concatenate(ratios), 95)), TAIL_FLOOR), TAIL_CAP)


def _time_rungs(garment_sim: GarmentSim, rungs: list[int], tol: float | None, frames: list,
                probe: GarmentSim | None) -> tuple[list[list[float]], list[int], list[float]]:
    """Time CALIBRATION_TICKS ticks per rung of `rungs`, in turn on `frames` [(stamp s,
    poses)] (each rung's ticks spread over the same stretch of motion as the others'), every
    rung solving to `tol` (None: its own), and the `probe` garment at its finest on every one
    of those frames, each tick of it right after the rung's (so that both see the machine as
    loaded; None: no probe): (ms per step per rung, the steps of every tick, the probe's ms
    per step)."""
    per_step: list[list[float]] = [[] for _ in rungs]
    steps, probe_ms = [], []
    garment_sim.hold_tolerance(tol)
    for i in range(len(rungs) * CALIBRATION_TICKS):
        garment_sim.set_rung(rungs[i % len(rungs)])
        stats = garment_sim.push(*frames[i])
        if isinstance(stats, TickStats):
            per_step[i % len(rungs)].append(stats.total_ms / stats.substeps)
            steps.append(stats.substeps)
        stats = None if probe is None else probe.push(*frames[i])
        if isinstance(stats, TickStats):
            probe_ms.append(stats.total_ms / stats.substeps)
    garment_sim.hold_tolerance(None)
    return per_step, steps, probe_ms


def _settled(opts, material, every_frame: list, warmup: list, timed: float, at_finest: bool,
             rungs: bool = True) -> GarmentSim:
    """The calibration's garment (BodySimOptions `opts`, `material`), dressed and settled up to
    stamp `timed` (s): with tolerance auto (`at_finest`) as the node's garment is, on the
    bag's first pose and at its finest rung through the whole opening hold of `every_frame`;
    else on the `warmup` frames [(stamp s, poses)], the first its dressing pose, at the
    coarse rung (a cloth just dressed is at rest and solves in a few iterations: the coarse
    rung settles it cheaply).

    The rule's ratio depends on the settle: on the walk at 1e-2 and 2394 particles (4x steps)
    it was 0.083 and 0.097 on a garment dressed 0.5 s before the motion, 0.139 and 0.153 on
    one dressed 1 s before it (bench pareto's, settled 1 s: 0.12 against 8x steps); and a
    state restricted from a coarse rung lacks the fine folds whose solves err most (1.3
    against 1.9 mm at 1e-2). rungs: False leaves it at its finest level without building the
    coarser ones (the probe garment)."""
    settle = [f for f in every_frame[:motion_start(every_frame)] if f[0] < timed] \
        if at_finest else []
    if len(settle) < 2:
        settle = warmup  # the timing's settle (or a bag that moves at once)
    garment_sim = GarmentSim.dress(Avatar.load(), settle[0][0], settle[0][1], material, opts)
    if rungs:  # (the probe garment is timed at its finest only)
        garment_sim.prepare_rungs()
        garment_sim.set_rung(garment_sim.rung_indices()[0 if at_finest else 1])
    for frame in settle[1:]:
        garment_sim.push(*frame)
    return garment_sim


def tolerance_frames(every_frame: list, first_stamp: float) -> list:
    """tolerance auto's motion: the bag's pose frames [(stamp s, poses)] from `first_stamp`
    (the first message after the calibration's settling) to the bag's end, or to
    TOLERANCE_SPAN_S later."""
    return [f for f in every_frame
            if first_stamp - 1e-9 <= f[0] <= first_stamp + TOLERANCE_SPAN_S + 1e-9]


def _rung_tolerances(garment_sim: GarmentSim, frames: list, coarse: int, log=None
                     ) -> tuple[list[tuple[int, float]], list[dict]]:
    """tolerance auto: the tolerance each rung's step allows, measured on TOLERANCE_INTERVALS
    messages spread over `frames` (tolerance_frames: the bag's motion from the settled state
    on); the garment then starts again from its settled state at rung `coarse`, each rung
    solving to its own. Returns ([(particles, tolerance)], CostModel.tolerance_rule's)."""
    settled = garment_sim.snapshot()  # at the finest rung (calibrate)
    t1 = time.perf_counter()
    measured = measure_tolerances(garment_sim, frames, TOLERANCE_INTERVALS,
                                  share=CALIBRATION_SHARE)
    tolerances = [(m.particles, m.tolerance) for m in measured]
    garment_sim.options.tolerances = tuple(tolerances)
    garment_sim.set_rung(0)
    garment_sim.restore(settled)
    garment_sim.set_rung(coarse)
    garment_sim.set_solver(garment_sim.options.solver, TOLERANCE_AUTO)
    if log is not None:
        log(f"tolerance auto measured in {time.perf_counter() - t1:.2f} s on "
            f"{len(measured[0].messages)} messages from {frames[0][0]:.2f} to "
            f"{frames[-1][0]:.2f} s: " + "; ".join(
                f"{m.tolerance:g} at {m.particles} particles (solver error {m.solver_mm:.2f} mm "
                f"against a step error of {m.step_mm:.1f} mm per message, mean over them: "
                f"ratio {m.ratio:.3f})" for m in measured))
    rule = [{"particles": m.particles, "tolerance": m.tolerance, "step_mm": m.step_mm,
             "solver_mm": m.solver_mm, "ratio": m.ratio,
             "stamps": [st for st, _, _ in m.messages], "tick_ms": m.tick_ms}
            for m in measured]
    return tolerances, rule


def load_or_calibrate(options, material, log=None, refresh: bool = False, bag: str = "walk"
                      ) -> tuple[CostModel, bool]:
    """The cached cost model for these options on this machine, or a fresh calibration
    (then cached). Returns (model, from_cache)."""
    path = cache_path(options, bag, material)
    if not refresh and path.is_file():
        try:
            data = json.loads(path.read_text())
            data["points"] = [tuple(p) for p in data["points"]]
            data["tolerances"] = [tuple(p) for p in data.get("tolerances", [])]
            model = CostModel(**data)
            if log is not None:  # (a calibration logs its own line)
                log(f"cost model cached: {model.a_ms:.2f} ms + {1e3 * model.b_ms:.2f} ms per "
                    f"1000 particles per step")
            return model, True
        except (OSError, ValueError, TypeError):
            pass  # a damaged cache entry is measured again
    model = calibrate(options, material, log, bag)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(model.to_json(), indent=1))
        tmp.replace(path)
    except OSError as exc:
        if log is not None:
            log(f"cost model not cached ({exc}); it is measured again next start")
    return model, False


@dataclass
class AutoChoice:
    """What `particles: auto` chose: the garment's particles, the budget (ms), the stream's
    period (s) and the predicted tick (ms) of the particles asked for."""

    particles: int
    budget_ms: float
    period_s: float
    predicted_ms: float
    capped_by: str  # "budget", "max_particles" or "minimum"


def check_budget(tick_budget: object, where: str = "tick_budget") -> float:
    """tick_budget as a float in (0, 1], or ClothInputError naming it."""
    if isinstance(tick_budget, bool) or not isinstance(tick_budget, (int, float)) or\
            not math.isfinite(tick_budget) or not 0.0 < tick_budget <= 1.0:
        raise ClothInputError(f"{where} must be a fraction of the pose period in (0, 1], got "
                              f"{tick_budget!r}")
    return float(tick_budget)


def choose_particles(model: CostModel, rate_hz: float, tick_budget: float,
                     max_particles: int, min_particles: int) -> AutoChoice:
    """The largest garment whose predicted tick fits tick_budget x the pose period, within
    [min_particles, max_particles]."""
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ClothInputError(f"rate_hz must be a positive number of poses per second, got "
                              f"{rate_hz!r}")
    period = 1.0 / rate_hz
    budget = check_budget(tick_budget) * period * 1e3
    fit = model.particles_for(budget, period)
    if fit >= max_particles:
        n, why = max_particles, "max_particles"
    elif fit <= min_particles:
        n, why = min_particles, "minimum"
    else:
        n, why = int(fit), "budget"
    return AutoChoice(int(n), budget, period, model.tick_ms(n, period), why)


def stream_rate(stamps: list[float] | np.ndarray) -> float:
    """Poses per second of a stream from its first stamps (s): the median interval's
    inverse (a gap or a repeated stamp does not skew it). ClothInputError with fewer than two
    increasing stamps."""
    d = np.diff(np.asarray(stamps, dtype=np.float64))
    d = d[d > 0.0]
    if len(d) == 0:
        raise ClothInputError("cannot measure the pose stream's rate: fewer than two poses "
                              "with increasing stamps (give the rate, e.g. --rate-hz 30)")
    return float(1.0 / np.median(d))


def check_max_particles(garment: str, max_particles: int, where: str = "max_particles") -> int:
    """max_particles if a garment that small exists, else ClothInputError naming both."""
    smallest = MIN_PARTICLES[garment]
    if int(max_particles) < smallest:
        raise ClothInputError(f"{where} {max_particles} is below the smallest {garment} "
                              f"({smallest} particles)")
    return int(max_particles)


def scene_cost_model(params, material, log=None) -> tuple[CostModel, bool]:
    """The cost model (cached or calibrated, with the rungs' tolerances when the scene says
    tolerance auto) of a body scene's parameters (config.scenes.load_scene's, read as
    attributes): (model, from_cache)."""
    options = BodySimOptions.from_scene(params, particles=CALIBRATION_PARTICLES)
    return load_or_calibrate(options, material, log, bag=params.bag)


def auto_particles(params, rate_hz: float, material, log=None,
                   model: CostModel | None = None) -> AutoChoice:
    """`particles: auto` for a body scene's parameters (config.scenes.load_scene) at a pose
    stream of rate_hz: the cost model (`model`, else cached or calibrated) and the scene's
    tick_budget and max_particles decide. Raises ClothInputError for max_particles below the
    garment's smallest size."""
    smallest = MIN_PARTICLES[params.garment]
    cap = check_max_particles(params.garment, params.max_particles)
    source = ""
    if model is None:
        model, cached = scene_cost_model(params, material, log)
        source = f"; cost model {'cached' if cached else 'calibrated'}"
    choice = choose_particles(model, rate_hz, params.tick_budget, cap, smallest)
    if log is not None:
        log(f"particles auto: {choice.particles} particles ({choice.capped_by}); budget "
            f"{choice.budget_ms:.1f} ms ({params.tick_budget:g} of a {1e3 * choice.period_s:.1f}"
            f" ms pose period), predicted tick {choice.predicted_ms:.1f} ms{source}")
    return choice
