"""`bench stability`'s sweep: every unit of a `StabilityConfig` as a Dask task (or in this
process with one worker), the cells in the map's order, and their summary per solver and per
scheme."""

from __future__ import annotations

import sys
import time

from cloth_mg_ros.apps.cluster import run_tasks
from cloth_mg_ros.bench.solvers import solvers_meta as solver_meta
from cloth_mg_ros.bench.stability.cells import (
    MAX_PENETRATION,
    MAX_SPECIFIC_KINETIC,
    MAX_SPEED,
    OUTCOMES,
    run_unit,
)
from cloth_mg_ros.bench.stability.options import (
    EXPLICIT,
    MIN_LEVELS,
    MOTIONS,
    SETTLE_S,
    SETTLE_SCHEME,
    SETTLE_SOLVER,
    StabilityConfig,
    cell_scheme,
    map_columns,
)


def _run_units(client, units: list, done) -> None:
    """Every unit as a Dask task on `client`; done(cells) as each finishes. A unit that
    raises stops the map (its cells would be missing from it)."""
    for _, unit_cells, error in run_tasks(client, run_unit, units, desc="stability",
                                          progress=False):
        if error is not None:
            raise error
        done(unit_cells)


def _meta(cfg: StabilityConfig) -> dict:
    """The run's meta: the machine's and the libraries' (bench.solver_meta), the axes, the
    settle, the outcome bounds and the scenes."""
    meta = solver_meta("stability", cfg.tol, None, None, 1, None, None, None)
    # every cell records its scheme; meta lists them (`scheme` alone: a map before the axis)
    for key in ("systems", "repeat", "dt", "max_seconds", "levels", "scheme"):
        meta.pop(key, None)
    meta.update(materials=cfg.materials, dts=cfg.dts, motions=cfg.motions,
                solvers=cfg.solvers, schemes=cfg.schemes,
                spectral_radius=cfg.spectral_radius if "genalpha" in cfg.schemes else None,
                settle_scheme=SETTLE_SCHEME, linearise_at=cfg.linearise,
                contact_friction=cfg.contact_friction,
                particles_requested=cfg.particles,
                speeds=cfg.speeds, seconds=cfg.seconds, jobs=cfg.jobs,
                scheduler=cfg.scheduler, settle_s=SETTLE_S, settle_solver=SETTLE_SOLVER,
                min_levels=MIN_LEVELS,
                bounds={"max_speed_m_s": MAX_SPEED,
                        "max_specific_kinetic_J_kg": MAX_SPECIFIC_KINETIC,
                        "max_penetration_m": MAX_PENETRATION},
                scenes={m: MOTIONS[m] for m in cfg.motions})
    return meta


def bench_stability(cfg: StabilityConfig, log=None, client=None) -> dict:
    """Run every cell of ``cfg``; returns {"cells": [...], "summary": {...}, "meta": {...}}.

    The units (one material, motion, step, size and speed: every solver's cell) run as Dask
    tasks: on `client` when given, else on an embedded LocalCluster of ``cfg.jobs`` workers or
    on the running scheduler ``cfg.scheduler``; with one worker and no scheduler, in this
    process. log: a callable taking one line of progress (default: print to stderr)."""
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    meta = _meta(cfg)
    # The most work first (smallest dt), so that the workers finish together.
    units = [(mat, motion, dt, tuple(cfg.solvers), n, cfg.seconds, cfg.tol, speed,
              tuple(cfg.schemes), cfg.spectral_radius, cfg.linearise, cfg.contact_friction)
             for n in sorted(cfg.particles, reverse=True) for speed in cfg.speeds
             for dt in sorted(cfg.dts) for mat in cfg.materials for motion in cfg.motions]
    t0 = time.perf_counter()
    cells: list[dict] = []
    columns = map_columns(cfg.solvers, cfg.schemes)

    def done(unit_cells: list[dict]) -> None:
        cells.extend(unit_cells)
        c = unit_cells[0]
        line = " ".join(f"{x['solver']}={x['outcome']}" if x["solver"] == EXPLICIT else
                        f"{x['scheme']}/{x['solver']}={x['outcome']}" for x in unit_cells)
        log(f"[{len(cells) // len(columns)}/{len(units)}] {c['particles']:6d} "
            f"x{c['speed']} "
            f"{c['material']:7s} {c['dt_label']:>6s} {c['motion']:10s} {line} "
            f"({time.perf_counter() - t0:.0f} s)")

    if client is not None:
        _run_units(client, units, done)
    elif cfg.jobs == 1 and not cfg.scheduler:
        for unit in units:  # in this process, no cluster
            done(run_unit(unit))
    else:
        # imported here: dask.distributed (the cluster), loaded only when needed
        from cloth_mg_ros.apps.cluster import dask_client

        with dask_client(cfg.scheduler, min(cfg.jobs, len(units)), log) as c:
            _run_units(c, units, done)
    order = {key: i for i, key in enumerate(
        (n, v, m, d, mo, s) for n in cfg.particles for v in cfg.speeds for m in cfg.materials
        for d in cfg.dts for mo in cfg.motions for s in columns)}
    cells.sort(key=lambda c: order[(c["particles_requested"], c["speed"], c["material"],
                                    c["dt"], c["motion"], (c["scheme"], c["solver"]))])
    meta["wall_s"] = round(time.perf_counter() - t0, 1)
    return {"cells": cells, "summary": summarise(cells, cfg.solvers, cfg.schemes),
            "meta": meta}


def summarise(cells: list[dict], solvers: list[str], schemes: list[str] | None = None) -> dict:
    """Counts per outcome: per solver over every scheme (``counts``), and per scheme and solver
    (``by_scheme``: {scheme: {solver: {outcome: n}}}, the explicit solver under its own
    scheme); whether mg is ok in every cell (None: not run), and in every cell of each
    scheme (``mg_ok_by_scheme``).

    schemes: the implicit schemes run (None: those the cells name); a cell without a scheme
    (a map before the axis) counts as bdf2's."""
    counts = {s: {o: 0 for o in OUTCOMES} for s in solvers}
    if schemes is None:
        schemes = list(dict.fromkeys(cell_scheme(c) for c in cells if c["solver"] != EXPLICIT))
    by_scheme = {sc: {s: {o: 0 for o in OUTCOMES} for s in sol}
                 for sc, sol in _group(map_columns(solvers, schemes)).items()}
    for c in cells:
        counts[c["solver"]][c["outcome"]] += 1
        by_scheme[cell_scheme(c)][c["solver"]][c["outcome"]] += 1
    mg = [c for c in cells if c["solver"] == "mg"]
    ok_by_scheme = {sc: all(c["outcome"] == "ok" for c in mg if cell_scheme(c) == sc)
                    for sc in schemes} if mg else None
    return {"counts": counts, "by_scheme": by_scheme,
            "mg_ok_everywhere": None if not mg else all(c["outcome"] == "ok" for c in mg),
            "mg_ok_by_scheme": ok_by_scheme, "cells": len(cells)}


def _group(columns: list[tuple[str, str]]) -> dict[str, list[str]]:
    """{scheme: [solver, ...]} of the map's (scheme, solver) columns, in their order."""
    out: dict[str, list[str]] = {}
    for scheme, solver in columns:
        out.setdefault(scheme, []).append(solver)
    return out
