"""`cloth-mg bench peers`: the drape scene in this solver, in Newton and in MuJoCo, side by side.

One scene, handed to every engine: the ``drape`` sheet of `sheets.build_scene` (a square sheet
of about ``particles`` particles, 1 m wide, released flat 10 cm above a sphere of radius
0.25 m centred 0.5 m above a floor), the same triangles, the same lumped masses (areal
density x one third of each adjacent rest triangle), gravity -9.81 m/s^2 along z, the sphere
and floor friction of the scene (0.3 and 0.5), a contact distance of the model's thickness
(5 mm) and the same step ``dt`` and duration (``steps`` x ``dt``). The engines:

* ``ours:mpcg``, ``ours:mg``: this project (BDF2, one linearised solve per step, tol 1e-4).
* ``newton:style3d``, ``newton:vbd``: Newton's SolverStyle3D (projective-dynamics Hessian
  with PCG) and SolverVBD (vertex block descent) on the Warp device ``cpu``, each step of
  ``dt`` split into the engine's substeps; the sphere and floor are static Newton shapes.
* ``mujoco:newton``, ``mujoco:cg``: a MuJoCo flex (``flexcomp type="direct"``, one slide-jointed
  body per particle) with the ``discrete`` integrator (implicit in position, so one step of
  ``dt`` is stable) and MuJoCo's own Newton or CG constraint solver.

A missing engine package is not an error: its rows are recorded as skipped with the install
command in the reason. Every loaded OpenBLAS runs on one thread (bench.blas_threads).

The modules: `options` (engines, default settings, option parsing and checks), `scene` (the
drape scene as arrays, the material mapped onto each peer), one per engine (`ours`, `newton`,
`mujoco`), `run` (running and timing the engines: what a row holds), `report` (table and
chart) and `cli` (the sub-command). This package re-exports their public names; a test that
patches a function must patch it in the module that calls it (``missing_modules`` in `run`).
"""

from cloth_mg_ros.bench.peers.cli import add_cli, cmd_bench_peers
from cloth_mg_ros.bench.peers.mujoco import mujoco_xml
from cloth_mg_ros.bench.peers.options import (
    DEFAULT_DT,
    DEFAULT_PARTICLES,
    DEFAULT_SETTINGS,
    DEFAULT_STEPS,
    DEFAULT_TOL,
    DRAPED_SAG,
    ENGINE_MODULES,
    ENGINES,
    INSTALL_HINT,
    INTEGER_SETTINGS,
    WARMUP_PARTICLES,
    WARMUP_STEPS,
    parse_engines,
    parse_settings,
    validate_peers_args,
)
from cloth_mg_ros.bench.peers.report import format_peers_report, plot_peers
from cloth_mg_ros.bench.peers.run import (
    ENGINE_CLASSES,
    bench_peers,
    missing_modules,
    run_engine,
    skipped_row,
    warm_up,
)
from cloth_mg_ros.bench.peers.scene import (
    DrapeSpec,
    build_spec,
    hinge_stiffness,
    membrane_lame,
    peer_parameters,
)

__all__ = [
    "DEFAULT_DT", "DEFAULT_PARTICLES", "DEFAULT_SETTINGS", "DEFAULT_STEPS", "DEFAULT_TOL",
    "DRAPED_SAG", "ENGINES", "ENGINE_CLASSES", "ENGINE_MODULES", "INSTALL_HINT",
    "INTEGER_SETTINGS", "WARMUP_PARTICLES", "WARMUP_STEPS", "DrapeSpec", "add_cli", "bench_peers",
    "build_spec", "cmd_bench_peers", "format_peers_report", "hinge_stiffness", "membrane_lame",
    "missing_modules", "mujoco_xml", "parse_engines", "parse_settings", "peer_parameters",
    "plot_peers", "run_engine", "skipped_row", "validate_peers_args", "warm_up",
]
