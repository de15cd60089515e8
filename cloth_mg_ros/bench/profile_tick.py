"""`cloth-mg bench profile`: where a walking tick's time goes.

The walking benchmark's scene (the dress of config/walking.yaml on a bag, from the end of
its still lead-in) at one size and solver: a few ticks run first (numba caches, the cloth's
first contacts), then ``ticks`` ticks run under cProfile. Every profiled function's own
time (tottime) is put in one part of the tick by the module that holds it:

* solve: the linear solver (multigrid set-up and cycles, smoothers, transfers, CG, the
  coarsest level's Cholesky, scipy.sparse and the factorisations);
* assembly: forces and Jacobians (stretch, shear, bending), the step's system and
  right-hand side, energies;
* collisions: body capsules, floor, cloth self-contact;
* strain limit and the rest (body poses, bookkeeping, numpy built-ins called from anywhere).

The step's system (physics/system.py: BlockSystem.matvec, full_diagonal, to_bsr, to_csr and
their numba kernels) serves both sides, so its time goes by caller (`split_parts`): what the
solvers (solvers/, and the other solve modules) call counts as solve, with everything those
calls run below them (the numpy built-ins they call too: their inclusive time), the rest as
assembly. pstats keeps one edge per caller and callee, not whole stacks, so below a
system.py function a callee called from several places is split in proportion (its share
of calls from the solvers by inclusive time).

The report gives each part's ms per tick and share, and the functions that cost most.
cProfile's own overhead inflates the many small calls a little; the shares are what count.

After the profiled ticks, with a multigrid on packed levels, a memory-traffic estimate
(bench.traffic): the bytes one V-cycle and one CG iteration move, their kernels timed on the
solver's own levels (no profiler), the GB/s that makes and its share of a STREAM-like triad
on the same threads; per solve and per tick, the solver's bytes over the run's median wall
times of a whole solve and tick (an average over work whose bytes are not counted, so not
set against the triad).
"""

from __future__ import annotations

import cProfile
import pstats
import sys

from cloth_mg_ros.bench.results import write_json
from cloth_mg_ros.bench.traffic import format_traffic, measure_traffic
from cloth_mg_ros.bench.walking import (
    DEFAULT_START,
    DEFAULT_TOL,
    auto_tolerances,
    dress_garment,
    garment_options,
    replay,
    size_tolerance,
    skip_lead_in,
    tol_option,
    validate_walking_args,
    warm_up,
    with_solver,
)
from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
from cloth_mg_ros.io.text_table import text_table
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.solve_tolerance import AUTO, describe
from cloth_mg_ros.solvers.threads import resolve_threads

PARTS = {
    "solve": ("solvers/", "cvxopt", "_superlu", "scipy/sparse"),
    "assembly": ("physics/stretch", "physics/bending", "sim/forces", "physics/system",
                 "sim/integrator", "sim/model"),
    "collisions": ("collision/",),
    "strain limit": ("physics/strain_limit.py",),
}


# modules whose functions both sides call: their time goes by caller (split_parts)
BY_CALLER = ("physics/system.py",)


def part_of(filename: str, function: str) -> str:
    """The part of the tick (a PARTS key, or 'other') a profiled function belongs to by its
    module (physics/system.py: assembly; split_parts moves what the solvers call to
    solve)."""
    where = f"{filename}:{function}"
    for part, keys in PARTS.items():
        if any(k in where for k in keys):
            return part
    return "other"



def _solver_shares(stats: dict) -> dict:
    """Per profiled function (a pstats key), the fraction of its inclusive time (cumtime)
    spent under a BY_CALLER function that a solve-part function called (`_edge_share`),
    each caller's edge weighted by its cumtime; a caller without an entry of its own (the
    frame that started the profiler) adds nothing."""
    shares: dict = {}

    def share(key) -> float:
        if key not in shares:
            shares[key] = 0.0  # a recursive cycle back to key adds nothing
            entry = stats.get(key)
            if entry is not None and entry[3] > 0.0:
                shares[key] = min(1.0, sum(edge[3] * _edge_share(key, caller, share)
                                           for caller, edge in entry[4].items()) / entry[3])
        return shares[key]

    for key in stats:
        share(key)
    return shares


def _edge_share(key, caller, share) -> float:
    """The fraction of key's time called from caller that is the solver's: all of it for a
    BY_CALLER function called from the solve part, else the caller's own share (share:
    a pstats key -> that fraction)."""
    if any(k in key[0] for k in BY_CALLER) and part_of(caller[0], caller[2]) == "solve":
        return 1.0
    return share(caller)


def split_parts(stats: pstats.Stats) -> tuple[dict, list]:
    """Every profiled function's own time (tottime, s) put in the tick's parts: by module
    (part_of), less the solver's share of it, which counts as solve: the time under a
    physics/system.py function that the solvers called (`_solver_shares`; a function's own
    time is split over its callers' edges by their tottime). Returns ({part: s}, rows):
    one row per function, {"function", "part" (the part most of its time went to), "split"
    ({part: s}), "calls", "s" (its tottime)}; the parts add up to stats.total_tt."""
    table = stats.stats
    shares = _solver_shares(table)
    parts: dict[str, float] = {p: 0.0 for p in (*PARTS, "other")}
    rows = []
    for key, (_cc, ncalls, tottime, _ct, callers) in table.items():
        own = part_of(key[0], key[2])
        solve = tottime
        if own != "solve":
            solve = min(tottime, sum(edge[2] * _edge_share(key, c, lambda k: shares.get(k, 0.0))
                                     for c, edge in callers.items()))
        split = {p: t for p, t in (("solve", solve), (own, tottime - solve)) if t > 0.0}
        for p, t in split.items():
            parts[p] += t
        rows.append({"function": f"{key[0].split('cloth_mg_ros/')[-1]}:{key[2]}",
                     "part": max(split, key=split.get) if split else own, "split": split,
                     "calls": ncalls, "s": tottime})
    return parts, rows


def profile_ticks(bag: str = "walk", garment: str = "dress", particles: int = 20000,
                  solver: str = "mpcg", material: str = "cotton", ticks: int = 5,
                  warm: int = 5, tol: float | str = 1e-4, threads: int = 0) -> dict:
    """Profile ``ticks`` walking ticks after ``warm`` unprofiled ones; see the module
    docstring; tol: every solve's relative residual, or 'auto' (bench.walking's module
    docstring); threads: the solver's and the kernels' threads (0: every core). Returns
    {"parts": {part: ms per tick}, "top": [...], "run": {...}, "threads", "traffic", "tol",
    ...}; "top": the 20 functions of most own time, {"function", "part" (the part most of it
    went to), "calls_per_tick", "ms_per_tick", "ms_by_part" ({part: ms per tick}, split_parts)};
    "traffic": bench.traffic.measure_traffic's figures (None for a solver without
    packed levels); with 'auto' also "tolerances", the measured points."""
    validate_walking_args(bag, garment, [particles], [solver], material, ticks, tol, None,
                          command="bench profile", steps_flag="--ticks")
    count = resolve_threads(threads)  # before any work: a bad count is refused first
    params = load_scene("walking")
    path = resolve_bag(bag)
    frames = read_pose_frames(path, params.topic)
    mat = get_material(material)
    tolerances = (auto_tolerances(params, garment, mat, str(path), threads, None)
                  if tol == AUTO else ())
    warm_up([solver], frames, params, garment, mat, DEFAULT_TOL if tol == AUTO else tol)
    frames = skip_lead_in(frames, DEFAULT_START)
    base, first = dress_garment(Avatar.load(), frames, mat, garment_options(
        params, garment, particles, solver, size_tolerance(tol, tolerances, particles), threads))
    size_tol = size_tolerance(tol, tolerances, int(base.sim.model.n))
    garment_sim = with_solver(base, solver, size_tol)
    replay(garment_sim, frames[first + 1: first + 1 + warm])
    todo = frames[first + 1 + warm: first + 1 + warm + ticks]
    prof = cProfile.Profile()
    prof.enable()
    run = replay(garment_sim, todo, per_tick=False)
    prof.disable()
    stats = pstats.Stats(prof)
    n_ticks = max(1, run["ticks"])
    parts, functions = split_parts(stats)
    rows = [{"function": r["function"], "part": r["part"], "calls_per_tick": r["calls"] / n_ticks,
             "ms_per_tick": 1e3 * r["s"] / n_ticks,
             "ms_by_part": {p: 1e3 * t / n_ticks for p, t in r["split"].items()}}
            for r in functions]
    rows.sort(key=lambda r: -r["ms_per_tick"])
    traffic = measure_traffic(garment_sim.sim, run, threads)  # after the profiler stopped

    return {"particles": int(garment_sim.sim.model.n),
            "levels": len(garment_sim.garment.hierarchy.levels),
            "solver": solver, "tol": size_tol, "tol_setting": tol,
            "tolerances": [list(p) for p in tolerances], "ticks": run["ticks"],
            "threads": count,
            "parts": {p: 1e3 * t / n_ticks for p, t in parts.items()},
            "profiled_ms_per_tick": 1e3 * stats.total_tt / n_ticks,
            "top": rows[:20], "run": run, "traffic": traffic}


def _part_label(row: dict) -> str:
    """A top row's part; a function whose time went to several parts (split_parts) gives
    each one's share, the largest first."""
    split = row.get("ms_by_part") or {}
    if len(split) < 2 or row["ms_per_tick"] <= 0.0:
        return row["part"]
    return ", ".join(f"{p} {100 * ms / row['ms_per_tick']:.0f} %"
                     for p, ms in sorted(split.items(), key=lambda kv: -kv[1]))


def format_profile(result: dict) -> str:
    """The printed breakdown."""
    total = result["profiled_ms_per_tick"]
    run = result["run"]
    auto = (f", tolerance {describe(AUTO, [tuple(p) for p in result['tolerances']])}"
            if result.get("tol_setting") == AUTO else "")
    lines = [(f"bench profile: {result['solver']} (tol {result.get('tol', 1e-4):g}{auto}) at "
              f"{result['particles']} particles "
             f"({result['levels']} levels, {result.get('threads', 1)} threads), "
             f"{result['ticks']} ticks under cProfile: "
             f"{total:.1f} ms per tick profiled ({run['ms_per_tick']:.1f} ms median tick, "
             f"{run['substeps']:.1f} substeps, {run['iterations']:.1f} iterations per solve)")]
    rows = [[p, f"{ms:.1f}", f"{100 * ms / total:.0f} %"]
            for p, ms in sorted(result["parts"].items(), key=lambda kv: -kv[1])]
    lines += ["", text_table(["part", "ms/tick", "share"], rows), ""]
    rows = [[r["function"], _part_label(r), f"{r['calls_per_tick']:.0f}",
             f"{r['ms_per_tick']:.1f}"] for r in result["top"][:15]]
    lines.append(text_table(["function", "part", "calls/tick", "ms/tick"], rows))
    if result.get("traffic"):
        lines += ["", format_traffic(result["traffic"])]
    return "\n".join(lines)


def add_cli(bsub) -> None:
    """Register `cloth-mg bench profile`."""
    p = bsub.add_parser("profile", help="where a walking tick's time goes (cProfile of a few "
                        "ticks, grouped into solve, assembly, collisions, ...)")
    p.add_argument("--bag", default="walk")
    p.add_argument("--garment", default="dress")
    p.add_argument("--particles", type=int, default=20000)
    p.add_argument("--solver", default="mpcg")
    p.add_argument("--material", default="cotton")
    p.add_argument("--ticks", type=int, default=5, help="profiled ticks (default 5)")
    p.add_argument("--tol", default="1e-4",
                   help="relative residual of every solve (default 1e-4), or 'auto': the "
                        "tolerance the walking scene's tolerance auto gives the size (as "
                        "bench walking --tol auto)")
    p.add_argument("--threads", type=int, default=0,
                   help="solver and kernel threads (default 0: every core)")
    p.add_argument("--json", default=None, help="also write the figures here")
    p.set_defaults(bench_func=run_cli)


def run_cli(args) -> int:
    result = profile_ticks(args.bag, args.garment, args.particles, args.solver,
                           args.material.strip().lower(), args.ticks,
                           tol=tol_option(args.tol), threads=args.threads)
    print(format_profile(result))
    if args.json:
        write_json(args.json, result)
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
