"""`cloth-mg bench stability`: where each solver and integration scheme stays stable, over
resolutions x materials x step sizes x motions x schemes x solvers.

Every cell is one garment size, one material, one fixed step ``dt``, one motion, one implicit
scheme and one solver:

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
* ``schemes`` (default euler, bdf2, genalpha) are the implicit integrators
  (`sim.integrator`); every scheme replays from the same settled garment (settled with
  SETTLE_SCHEME, BDF2), genalpha at ``spectral_radius`` (rho_inf) and from one implicit Euler
  step (no acceleration history yet);
* solver ``explicit`` is the contrast: symplectic Euler with the same forces, pins, strain
  limit and contact projection (`sim.explicit.ExplicitSimulator`), one column whatever the
  schemes (its cells' scheme is ``symplectic_euler``).

Each cell's outcome is the most severe that applies, checked after every pose message
(figures at the end of the message's substeps, penetration after every substep):

========== ===========================================================================
nan        a step came out non-finite (GarmentSim dropped it: ``garment_sim.failures`` > 0) or the
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

Work is split by (material, motion, dt, size, speed) into Dask tasks (cloth_mg_ros.apps.cluster): an
embedded LocalCluster of ``jobs`` single-threaded workers (``--workers``; OPENBLAS_NUM_THREADS=1
in each), or a running cluster (``--scheduler``); with one worker, in this process. Output:
``{"cells": [{"material", "dt", "motion", "solver", "scheme", "spectral_radius", "outcome",
...worst figures...}], "summary": {"counts" (per solver), "by_scheme" (per scheme and
solver), ...}, "meta": {...}}``, a heatmap PNG and a printed table. The CLI exits 1 when
solver mg was run and is not ok in every cell (of every scheme).

The modules: `options` (the map's axes, the options and their checks), `cells` (the outcome
bounds and rules, and running one unit: every solver's cell of one material, motion, step, size
and speed; `cells.run_unit` is the function shipped to the Dask workers), `sweep` (every unit
on the workers, or in this process; the summary), `report` (the printed map and the heatmap)
and `cli` (the sub-command). This package re-exports their public names; a test that patches a
function must patch it in the module that calls it.
"""

from cloth_mg_ros.bench.stability.cells import (
    FATAL,
    MAX_PENETRATION,
    MAX_SPECIFIC_KINETIC,
    MAX_SPEED,
    OUTCOMES,
    CellWatch,
    classify,
    faster,
    garment_depth,
    motion_window,
    run_unit,
    speed_bounds,
    with_scheme,
)
from cloth_mg_ros.bench.stability.cli import add_cli, cmd_stability
from cloth_mg_ros.bench.stability.options import (
    DEFAULT_DTS,
    DEFAULT_JOBS,
    DEFAULT_MATERIALS,
    DEFAULT_PARTICLES,
    DEFAULT_SCHEMES,
    DEFAULT_SECONDS,
    DEFAULT_SOLVERS,
    DEFAULT_TOL,
    EXPLICIT,
    EXPLICIT_SCHEME,
    MAX_JOBS,
    MAX_MESSAGES_PER_STEP,
    MAX_PARTICLES,
    MAX_SECONDS,
    MAX_SPEED_UP,
    MAX_SUBSTEPS,
    MIN_DEPTH,
    MIN_LEVELS,
    MIN_PARTICLES,
    MOTIONS,
    POSE_INTERVAL,
    SETTLE_S,
    SETTLE_SCHEME,
    SETTLE_SOLVER,
    SUBSTEP_MOTION_OFF,
    StabilityConfig,
    cell_scheme,
    dt_label,
    map_columns,
    messages_per_step,
    parse_dt,
    substeps_for,
    validate_stability_args,
)
from cloth_mg_ros.bench.stability.report import (
    CODES,
    COLOURS,
    format_stability_report,
    plot_stability,
)
from cloth_mg_ros.bench.stability.sweep import bench_stability, summarise

__all__ = [
    "CODES", "COLOURS", "DEFAULT_DTS", "DEFAULT_JOBS", "DEFAULT_MATERIALS", "DEFAULT_PARTICLES",
    "DEFAULT_SCHEMES", "DEFAULT_SECONDS", "DEFAULT_SOLVERS", "DEFAULT_TOL", "EXPLICIT",
    "EXPLICIT_SCHEME", "FATAL", "MAX_JOBS",
    "MAX_MESSAGES_PER_STEP", "MAX_PARTICLES", "MAX_PENETRATION", "MAX_SECONDS",
    "MAX_SPECIFIC_KINETIC", "MAX_SPEED", "MAX_SPEED_UP", "MAX_SUBSTEPS", "MIN_DEPTH",
    "MIN_LEVELS", "MIN_PARTICLES", "MOTIONS", "OUTCOMES", "POSE_INTERVAL", "SETTLE_S",
    "SETTLE_SCHEME", "SETTLE_SOLVER", "SUBSTEP_MOTION_OFF", "CellWatch", "StabilityConfig",
    "add_cli", "bench_stability", "cell_scheme", "classify", "cmd_stability", "dt_label",
    "faster", "format_stability_report", "garment_depth", "map_columns", "messages_per_step",
    "motion_window", "parse_dt", "plot_stability",
    "run_unit", "speed_bounds", "substeps_for", "summarise", "validate_stability_args",
    "with_scheme",
]
