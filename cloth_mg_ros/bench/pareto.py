"""`cloth-mg bench pareto`: speed against accuracy on the walking garment.

The scene is the walking one (config/walking.yaml: the dress, self contact, floor, its
substeps) on a bag. The garment is dressed on the bag's first pose and settles through the
bag's still lead-in (``settle`` s) with exact (direct) solves; that settled garment is the
common start of every run, which then replays the next ``steps`` pose messages (the walking).

Accuracy is measured against references that start from the same settled state:

* the exact-solve reference: the same step, every linear system solved by the sparse
  direct factorisation. A run's error is the distance of every vertex from where the
  reference has it after the same pose message; ``rms_mm`` is the root mean square over
  every vertex and pose message of the run, ``max_mm`` the largest (mm). This is the error
  the iterative solver's tolerance (and levels) costs.
* the small-step reference: direct solves with ``REF_SUBSTEP_FACTOR`` times as many
  substeps per message. Its distance from the exact-solve reference is the time
  discretisation error of the scene's step, the floor below which a tighter tolerance buys
  nothing.

Part 1 (the Pareto chart): every solver in ``solvers`` at every tolerance in ``tols`` and,
for the multigrids, every number of levels in ``levels`` (a number deeper than the garment's
hierarchy is recorded as unavailable), at ``particles``. Each solver's Pareto front is its set
of runs that no other run of the same solver beats in both ms per tick and RMS error.

Part 3 (the step as an axis, bench.pareto_steps): step rules (the scene's, a 5 cm one,
1-8 fixed steps per message) against 16 steps per message, per pose interval and over the
clip, beside the floor that any perturbation grows to, and each rule's ms per tick.

Parts 4 and 5 (the level of detail as an axis, bench.pareto_rungs and
bench.pareto_tolerance): every level the garment may be simulated at live against the finest,
per pose interval and over the clip, with the deepest penetration, worst stretch and the
drape's outline; and per level the loosest tolerance whose solver error stays within a tenth
of the step's error, over part 5's ladder and the tolerances of ``tols`` within its range.
Part 5 measures every ``every``-th pose message (default 1: every one, the mean over the clip
rather than a sample of it) and, with ``auto``, checks `tolerance: auto`'s rule at the
tolerance it gives each level (its calibration is the cost model's, cached per machine).
``lod=False`` leaves parts 4 and 5 out.

Part 2 (error against particles): at each size in ``sizes`` the exact and small-step
references and the default solver (``DEFAULT_SOLVER`` at ``DEFAULT_TOL``), plus the exact
reference of the ``finest`` size. Three errors per size: the solver's (vs exact, same size),
the time step's (small step vs exact, same size) and the resolution's: the symmetric surface
distance between the size's exact trajectory and the finest's (each vertex of either surface
to the nearest point of the other's triangles, RMS over both and every pose message), so a
user can pick the smallest mesh that meets an error budget. Sizes are dressed with the same
garment design, so they differ only in resolution.

ms per tick is the median of TickStats.total_ms (the whole tick: body, collisions,
assembly, every substep's solve, projections). The timed cells run with every loaded OpenBLAS on
one thread (bench.blas_threads; each run's ``blas_threads`` and meta.blas_threads record it).

The cells run as Dask tasks (bench.pareto_tasks, cloth_mg_ros.apps.cluster): by default on an
embedded one-worker cluster, one at a time with every core; ``--workers N`` runs N at once
(one thread each: the errors are the same, the times grow with the sharing), ``--scheduler``
on a running cluster.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from cloth_mg_ros.apps.cluster import dask_client, run_tasks
from cloth_mg_ros.bench.pareto_report import format_pareto_report, plot_pareto
from cloth_mg_ros.bench.pareto_runs import (
    DEFAULT_SOLVER,
    DEFAULT_TOL,
    REF_SUBSTEP_FACTOR,
    REFERENCE_SOLVER,
)
from cloth_mg_ros.bench.pareto_steps import RULES
from cloth_mg_ros.bench.pareto_tasks import (
    Setup,
    finest_cell,
    lod_cell,
    reference_cell,
    rules_cell,
    size_cell,
    solver_cell,
    warm_worker,
)
from cloth_mg_ros.bench.pareto_tolerance import (
    calibrated_points,
)
from cloth_mg_ros.bench.results import recorded_path, write_json
from cloth_mg_ros.bench.solvers import parse_list, particle_problems
from cloth_mg_ros.bench.solvers import solvers_meta as solver_meta
from cloth_mg_ros.bench.walking import validate_walking_args
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import resolve_bag
from cloth_mg_ros.solvers import HIERARCHY_SOLVERS
from cloth_mg_ros.solvers.threads import resolve_threads

if TYPE_CHECKING:
    from cloth_mg_ros.config.schema import SceneParams

DEFAULT_TOLS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
DEFAULT_LEVELS = (2, 3, 4)
DEFAULT_SOLVERS = ("pcg", "bscg", "galerkin", "mg", "mpcg", "amg")
LADDERS = ("full", "auto")  # part 5's tolerances: its ladder, or tolerance auto's alone


# -- options ------------------------------------------------------------------------------
def validate_pareto_args(bag: str, garment: str, particles: int, solvers: list, tols: list,
                         levels: list, sizes: list, finest: int | None, material: str,
                         steps: int, settle: float, every: int = 1, ladder: str = "full",
                         auto: bool = True) -> None:
    """Check every option before any work; one ClothInputError lists all the problems."""
    problems = []
    try:
        validate_walking_args(bag, garment, [particles], solvers or ["mpcg"], material, steps,
                              DEFAULT_TOL, None, command="bench pareto")
    except ClothInputError as exc:
        problems.append(str(exc).removeprefix("bench pareto: "))
    problems += particle_problems(sizes, "--sizes")
    problems += particle_problems([finest] if finest else [], "--finest")
    if REFERENCE_SOLVER in solvers:
        problems.append("--solvers: 'direct' is the reference, not a solver to compare")
    for t in tols:
        if not (isinstance(t, (int, float)) and math.isfinite(t) and 0.0 < t < 1.0):
            problems.append(f"--tols must be in (0, 1), got {t!r}")
    for lv in levels:
        if isinstance(lv, bool) or not isinstance(lv, int) or lv < 1:
            problems.append(f"--levels must be integers >= 1, got {lv!r}")
    if not tols:
        problems.append("--tols must list at least one tolerance")
    if finest is not None and sizes and finest <= max(sizes):
        problems.append(f"--finest ({finest}) must be larger than every --sizes "
                        f"({max(sizes)})")
    if not (isinstance(settle, (int, float)) and math.isfinite(settle) and settle >= 0.0):
        problems.append(f"--settle must be >= 0 s, got {settle!r}")
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        problems.append(f"--every must be an integer >= 1, got {every!r}")
    if ladder not in LADDERS:
        problems.append(f"--ladder must be one of {', '.join(LADDERS)}, got {ladder!r}")
    elif ladder == "auto" and not auto:
        problems.append("--ladder auto measures tolerance auto's own tolerances: it needs the "
                        "rule checked (leave out --no-auto)")
    if problems:
        raise ClothInputError("bench pareto: " + "; ".join(problems))


# -- trajectories -------------------------------------------------------------------------
@dataclass(frozen=True)
class ParetoRun:
    """The checked options of one `bench_pareto` run (see there), threads resolved."""

    bag: str
    garment: str
    particles: int
    solvers: list[str]
    tols: list[float]
    levels: list[int]
    sizes: list[int]
    finest: int | None
    material: str
    steps: int
    settle: float
    rules: tuple[str, ...] | None
    scheduler: str | None
    workers: int
    threads: int
    lod: bool
    every: int = 1
    auto: bool = True
    ladder: str = "full"

    def setup(self, n: int):
        """The `pareto_tasks.Setup` of the garment at about n particles."""
        return Setup(self.bag, self.garment, n, self.material, self.settle, self.steps,
                     self.threads)


def bench_pareto(bag: str = "walk", garment: str = "dress", particles: int = 2400,
                 solvers: list[str] | None = None, tols: list[float] | None = None,
                 levels: list[int] | None = None, sizes: list[int] | None = None,
                 finest: int | None = 9600, material: str = "cotton", steps: int = 30,
                 settle: float = 1.0, log=None, rules: tuple[str, ...] | None = None,
                 client=None, scheduler: str | None = None, workers: int = 1,
                 threads: int | None = None, lod: bool = True, every: int = 1,
                 auto: bool = True, ladder: str = "full") -> dict:
    """Run the parts; returns {"runs": [...], "reference": {...}, "sizes": [...], "steps":
    {...} (part 3, or None without rules), "lod_levels": {...} and "lod_tolerance": {...}
    (parts 4 and 5, or None without lod), "meta": {...}} (see the module docstring).

    Every cell is a Dask task (bench.pareto_tasks): on `client`, else on the running
    `scheduler`, else on an embedded LocalCluster of `workers` workers (default 1: the cells
    one at a time, so that each has the machine's cores to itself). threads: each run's
    simulation threads (None: every core with one worker, else one). every: part 5 measures
    every every-th pose message; auto: part 5 checks tolerance auto's rule; ladder: part 5's
    tolerances, "full" (its ladder and the run's tols within it) or "auto" (only those
    tolerance auto gives each level, and the reference: the rule's check alone, affordable
    at 20K particles)."""
    solvers = list(DEFAULT_SOLVERS if solvers is None else solvers)
    tols = list(DEFAULT_TOLS if tols is None else tols)
    levels = list(DEFAULT_LEVELS if levels is None else levels)
    sizes = list((600, 1200, 2400, 4800) if sizes is None else sizes)
    material = str(material).strip().lower()
    validate_pareto_args(bag, garment, particles, solvers, tols, levels, sizes, finest,
                         material, steps, settle, every, ladder, auto)
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    if client is None:
        with dask_client(scheduler, workers, log) as c:
            return bench_pareto(bag, garment, particles, solvers, tols, levels, sizes, finest,
                                material, steps, settle, log, rules, client=c,
                                scheduler=scheduler, workers=workers, threads=threads,
                                lod=lod, every=every, auto=auto, ladder=ladder)
    if threads is None:
        threads = 0 if workers == 1 and not scheduler else 1
    return run_pareto(ParetoRun(bag, garment, particles, solvers, tols, levels, sizes, finest,
                                material, steps, settle, rules, scheduler, workers, threads,
                                lod, every, auto, ladder), client, log)


def run_pareto(run: ParetoRun, client, log) -> dict:
    """The parts of `bench_pareto`, their cells on `client`, in the order parts 1, 3, 4 and
    5, 2."""
    t_start = time.perf_counter()
    params = load_scene("walking")
    _warm_workers(client, run)
    main = run.setup(run.particles)
    reference = _reference(client, main, log)
    runs, order = _solver_runs(client, run, main, reference, log)
    rules = RULES if run.rules is None else tuple(run.rules)
    step_part = _step_rules(client, main, rules, log) if rules else None
    rung_axis = lod_tolerance = None
    if run.lod:
        points = calibrated_points(run.bag, run.garment, run.material, run.threads, log)\
            if run.auto else None
        tols = run.tols if run.ladder == "full" else None
        rung_axis, lod_tolerance = _rung_axis(client, main, tols, run.every, points, log)
    size_rows, finest_n = _size_rows(client, run, log)
    meta = _pareto_meta(run, params, rules, reference["particles"], finest_n, t_start)
    meta["blas_threads"] = max((r["blas_threads"] for r in runs.values()
                                if r.get("blas_threads") is not None), default=None)
    return {"runs": [runs[key] for key in order], "reference": reference,
            "sizes": size_rows, "steps": step_part, "lod_levels": rung_axis,
            "lod_tolerance": lod_tolerance, "meta": meta}


def _warm_workers(client, run: ParetoRun) -> None:
    """Compile the kernels of every solver once on each worker.

    The warm-up is a task on each worker, not client.run: client.run calls it on the
    worker's event-loop thread, and numba's OpenMP layer keeps a team of threads per
    calling OS thread; a second team oversubscribes the cores, OpenMP then sleeps at its
    barriers instead of spinning, and every cell's parallel kernels pay it
    (doc/benchmarks/pareto.md has the cost measured)."""
    names = sorted(set(run.solvers) | {REFERENCE_SOLVER, DEFAULT_SOLVER})
    client.gather([client.submit(warm_worker, names, run.bag, run.garment, run.material,
                                 DEFAULT_TOL, workers=[w], allow_other_workers=False,
                                 pure=False)
                   for w in client.scheduler_info()["workers"]])


def _reference(client, main, log) -> dict:
    """Part 1's references (exact solves, and the small step) at the main size."""
    reference = client.submit(reference_cell, main, pure=False).result()
    log(f"pareto at {reference['particles']} particles ({reference['levels']} levels), "
        f"{reference['messages']} pose messages after {reference['settle_messages']} "
        f"settling ones; direct {reference['ms_per_tick']:.1f} ms/tick; time-step error "
        f"{reference['time_rms_mm']:.3f} mm RMS ({reference['time_max_mm']:.2f} max) against "
        f"{REF_SUBSTEP_FACTOR}x substeps")
    for key in ("messages", "settle_messages"):
        reference.pop(key)
    return reference


def _solver_runs(client, run: ParetoRun, main, reference: dict, log) -> tuple[dict, list]:
    """Part 1: ({(solver, levels, tol): run}, the keys in report order) of every solver,
    tolerance and level count at the main size; a level count deeper than the garment's
    hierarchy is recorded as unavailable."""
    n, depth = reference["particles"], reference["levels"]
    order, cells, runs = [], [], {}
    for solver in run.solvers:
        for lv in (run.levels if solver in HIERARCHY_SOLVERS else [None]):
            if lv is not None and lv > depth:
                runs[(solver, lv, None)] = {
                    "solver": solver, "levels": lv, "particles": n, "tol": None,
                    "available": False,
                    "why": f"the {n}-particle garment's hierarchy has {depth} levels"}
                order.append((solver, lv, None))
                log(f"  {solver} levels {lv}: unavailable (hierarchy has {depth})")
                continue
            for tol in run.tols:
                order.append((solver, lv, tol))
                cells.append((main, solver, tol, lv))
    for (_, solver, tol, lv), rec, error in run_tasks(client, solver_cell, cells,
                                                        desc="pareto", progress=False):
        if error is not None:
            raise error
        runs[(solver, lv, tol)] = rec
        log(f"  {solver:8s} levels {lv or '-'} tol {tol:.0e}: "
            f"{rec['ms_per_tick']:8.1f} ms/tick {rec['iterations']:7.1f} it  "
            f"error {rec['rms_mm']:.4f} mm RMS ({rec['max_mm']:.3f} max)"
            + ("" if rec["converged"] else "  NOT CONVERGED"))
    return runs, order


def _step_rules(client, main, rules: tuple[str, ...], log) -> dict:
    """Part 3: the step rules' own error."""
    step_part, lines = client.submit(rules_cell, (main, rules, DEFAULT_SOLVER, DEFAULT_TOL),
                                     pure=False).result()
    for line in lines:
        log(line)
    return step_part


def _rung_axis(client, main, tols, every: int, points, log) -> tuple[dict, dict]:
    """Parts 4 and 5: the level of detail as an axis, and the tolerance per level (part 5's
    ladder with those of the run's tolerances `tols` that lie within its range, or with tols
    None only tolerance auto's, measured on every `every`-th pose message; with tolerance
    auto's points, its rule checked)."""
    rung_axis, lod_tolerance, lines = client.submit(
        lod_cell, (main, DEFAULT_SOLVER, DEFAULT_TOL, None if tols is None else tuple(tols),
                   every, points),
        pure=False).result()
    for line in lines:
        log(line)
    return rung_axis, lod_tolerance


def _size_rows(client, run: ParetoRun, log) -> tuple[list[dict], int | None]:
    """Part 2: (a row per size, the finest size's particles (None without one)): the
    error against particles."""
    finest_future = (client.submit(finest_cell, run.setup(run.finest), pure=False)
                     if run.finest else None)
    size_futures = [client.submit(size_cell, run.setup(size), finest_future, pure=False)
                    for size in run.sizes]
    size_rows = []
    for future in size_futures:
        row = future.result()
        size_rows.append(row)
        log(f"  size {row['particles']}: solver {row['solver_rms_mm']:.4f} mm, time step "
            f"{row['time_rms_mm']:.3f} mm, resolution "
            f"{row.get('resolution_rms_mm', float('nan')):.2f} mm RMS; "
            f"{row['ms_per_tick']:.1f} ms/tick")
    finest_n = finest_future.result()[0].shape[1] if finest_future is not None else None
    return size_rows, finest_n


def _pareto_meta(run: ParetoRun, params: SceneParams, rules: tuple[str, ...], n: int,
                 finest_n: int | None, t_start: float) -> dict:
    """The result's "meta": the machine (as bench solvers records it) and the run's
    options; wall_s since t_start."""
    meta = solver_meta("walking", DEFAULT_TOL, None, None, 1, None, None, "bdf2")
    for key in ("systems", "repeat", "dt", "levels", "tol"):
        meta.pop(key, None)
    meta.update(bag=recorded_path(resolve_bag(run.bag)), garment=run.garment, material=run.material,
                steps=run.steps, settle_s=run.settle, particles=n, tols=run.tols,
                levels=run.levels, solvers=run.solvers, ref_substep_factor=REF_SUBSTEP_FACTOR,
                default_solver=DEFAULT_SOLVER, default_tol=DEFAULT_TOL, finest=finest_n,
                substeps=params.substeps, max_substep_motion=params.max_substep_motion,
                max_step=params.max_step, self_contact=params.self_contact,
                rules=list(rules), threads=resolve_threads(run.threads), workers=run.workers,
                scheduler=run.scheduler, every=run.every, auto=run.auto, ladder=run.ladder,
                wall_s=time.perf_counter() - t_start)
    return meta


def add_cli(bsub) -> None:
    """Register `cloth-mg bench pareto`."""
    p = bsub.add_parser("pareto", help="speed against accuracy: every solver, tolerance and "
                        "level count against exact-solve and small-step references")
    p.add_argument("--bag", default="walk", help="pose bag (default walk)")
    p.add_argument("--garment", default="dress", help="garment (default dress)")
    p.add_argument("--particles", type=int, default=2400,
                   help="size of the Pareto chart's runs (default 2400)")
    p.add_argument("--solvers", default=",".join(DEFAULT_SOLVERS),
                   help=f"comma-separated (default {','.join(DEFAULT_SOLVERS)})")
    p.add_argument("--tols", default=",".join(f"{t:.0e}" for t in DEFAULT_TOLS),
                   help="comma-separated relative tolerances (default 1e-1..1e-8)")
    p.add_argument("--levels", default=",".join(map(str, DEFAULT_LEVELS)),
                   help="level counts for the multigrids (default 2,3,4)")
    p.add_argument("--sizes", default="600,1200,2400,4800",
                   help="particle counts of the error-against-size chart ('' for none)")
    p.add_argument("--finest", type=int, default=9600,
                   help="the resolution reference's particle count (0: none)")
    p.add_argument("--material", default="cotton")
    p.add_argument("--steps", type=int, default=30,
                   help="pose messages per run after the settle (default 30: 1 s)")
    p.add_argument("--settle", type=float, default=1.0,
                   help="seconds of the bag's lead-in to settle through (default 1)")
    p.add_argument("--rules", default="scene,5cm,1x,2x,4x,8x",
                   help="step rules of part 3: scene, 5cm, Nx (N steps per message); '' for "
                        "none")
    p.add_argument("--every", type=int, default=1,
                   help="part 5 measures every Nth pose message (default 1: every one)")
    p.add_argument("--ladder", choices=LADDERS, default="full",
                   help="part 5's tolerances: full (its ladder, default) or auto (only those "
                        "tolerance auto gives each level, and the reference: the rule's check "
                        "alone, for large garments)")
    p.add_argument("--no-auto", action="store_true",
                   help="part 5 without tolerance auto's rule checked (and its calibration)")
    p.add_argument("--no-lod", action="store_true",
                   help="leave out parts 4 and 5 (the level of detail as an axis, the "
                        "tolerance per level)")
    p.add_argument("--workers", type=int, default=1,
                   help="Dask workers of the embedded cluster (default 1: one cell at a time, "
                        "every core to it; more cells at once share the cores, and their "
                        "times grow)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run the cells on this running Dask scheduler instead")
    p.add_argument("--json", default="out/bench_pareto.json")
    p.add_argument("--png", default="out/bench_pareto.png")
    p.set_defaults(bench_func=run_cli)


def run_cli(args) -> int:
    solvers = parse_list(args.solvers, "solvers")
    tols = parse_list(args.tols, "tols", float)
    levels = parse_list(args.levels, "levels", int)
    sizes = parse_list(args.sizes, "sizes", int) if args.sizes.strip() else []
    finest = args.finest or None
    validate_pareto_args(args.bag, args.garment, args.particles, solvers, tols, levels, sizes,
                         finest, args.material.strip().lower(), args.steps, args.settle,
                         args.every, args.ladder, not args.no_auto)
    rules = tuple(parse_list(args.rules, "rules")) if args.rules.strip() else ()
    bad = [r for r in rules if r not in ("scene", "5cm") and not (
        r.endswith("x") and r[:-1].isdigit() and int(r[:-1]) >= 1)]
    if bad:
        raise ClothInputError(f"bench pareto: --rules must be scene, 5cm or Nx (N steps per "
                              f"message), got {', '.join(bad)}")
    if args.workers < 1:
        raise ClothInputError(f"bench pareto: --workers must be at least 1, got {args.workers}")
    result = bench_pareto(args.bag, args.garment, args.particles, solvers, tols, levels, sizes,
                          finest, args.material, args.steps, args.settle, rules=rules,
                          scheduler=args.scheduler, workers=args.workers,
                          lod=not args.no_lod, every=args.every, auto=not args.no_auto,
                          ladder=args.ladder)
    print(format_pareto_report(result))
    write_json(args.json, result)
    print(f"wrote {args.json} and {plot_pareto(result, args.png)}")
    return 0
