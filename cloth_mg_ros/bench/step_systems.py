"""Record a scene's step systems once, so that every solver solves exactly the same matrices.

`record_systems` builds a scene, steps it with an accurate reference solver (the sparse direct
solver when `cloth_mg_ros.solvers.baselines` provides it, otherwise block-symmetric CG at
``reference_tol``) until the sheet first touches a collider, then keeps the next ``n_systems``
consecutive step systems (the output of `assemble_step`: A in block-symmetric form, b, x0,
the pinned mask), advancing the state with the reference solution after each. The first
recorded system has contacts (in the drape scene the following ones do too: the sheet stays on
the sphere), and the sequence does not depend on the solver under test.

"First touches": the first assembled step whose contact set is non-empty, or the step after
one whose contact projection moved a particle (`StepStats.contacts > 0`), whichever comes
first. A scene without colliders (``hang``) has nothing to touch: recording starts at step 0.

Memory. A recorded system keeps the BlockSystem (diag n*72 B, pairs m*16 B, offd m*72 B with
m ~ 6n pairs), b, x0 and the pinned mask: about 645 B per particle; the reference solution
adds 24 B. The per-step force/Hessian scratch (`StepSystem.internal`, about as large again) is
dropped (set to None); doc/benchmarks/solvers.md has the sizes measured. `MAX_RECORD_BYTES`
(1.5 GB, ~28 systems at 80K particles) caps a recording: when ``n_systems`` would pass it,
fewer systems are kept and `Recording.truncated` says so.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.integrator import StepSystem, assemble_step, finish_step
from cloth_mg_ros.sim.model import ClothState
from cloth_mg_ros.sim.schemes import SCHEMES
from cloth_mg_ros.sim.sheets import SCENES, Scene, build_scene, validate_particles
from cloth_mg_ros.solvers import make_solver

MAX_SETTLE_STEPS = 600  # 10 s of falling at 60 Hz: a sheet that has not landed by then never will
MAX_RECORD_BYTES = 1.5e9


@dataclass
class Recording:
    """Consecutive step systems of one scene, with the reference solutions.

    scene: the Scene (hierarchy, model; its ``state`` is the initial one, untouched).
    systems: list of StepSystem (``internal`` dropped to save memory).
    contacts: contacts per system (len of its contact set).
    reference: list of (n, 3) reference solutions dv, one per system.
    start_step: the step index (0 = the first step of the run) of systems[0].
    reference_solver: the name of the solver that produced ``reference`` and advanced the state.
    record_s: wall time of building the scene and recording, s.
    truncated: True when MAX_RECORD_BYTES cut the number of systems.
    reference_rel_residual: the worst recomputed relative residual of the reference solutions.
    """

    scene: Scene
    systems: list[StepSystem]
    contacts: list[int]
    reference: list[np.ndarray] = field(default_factory=list)
    start_step: int = 0
    reference_solver: str = ""
    dt: float = 1.0 / 60.0
    scheme: str = "bdf2"
    record_s: float = 0.0
    truncated: bool = False
    reference_rel_residual: float = 0.0

    @property
    def particles(self) -> int:
        return int(self.scene.model.n)

    @property
    def material(self) -> str:
        return self.scene.model.material.name

    def nbytes(self) -> int:
        """Bytes held by the recorded systems (not counting the scene)."""
        return sum(system_nbytes(s) for s in self.systems) + sum(r.nbytes for r in self.reference)


def system_nbytes(step: StepSystem) -> int:
    """Bytes of the arrays a recorded StepSystem keeps."""
    s = step.system
    return int(s.diag.nbytes + s.pairs.nbytes + s.offd.nbytes + step.rhs.nbytes + step.x0.nbytes
               + step.fixed.nbytes)


def filtered_rel_residual(step: StepSystem, x: np.ndarray) -> float:
    """||S (b - A x)|| / ||S b|| for a StepSystem ``step`` and x (n, 3); S zeroes the pinned
    rows. Computed with Algorithm 1, independently of any solver's own bookkeeping."""
    x3 = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    free = ~np.asarray(step.fixed, dtype=bool)
    r = (step.rhs - step.system.matvec(x3))[free]
    bn = float(np.linalg.norm(step.rhs[free])) or 1.0
    return float(np.linalg.norm(r)) / bn


def baselines_available() -> bool:
    """Whether the 'amg' and 'direct' solvers (solvers/baselines.py) can be imported."""
    try:
        # imported here: the baselines need optional packages (pyamg, cvxopt)
        from cloth_mg_ros.solvers import baselines  # noqa: F401
    except ImportError:
        return False
    return True


def reference_solver(tol: float = 1e-8):
    """(name, solver): 'direct' when available, else 'bscg' at relative residual ``tol``."""
    if baselines_available():
        return "direct", make_solver("direct")
    return "bscg", make_solver("bscg", tol=tol, maxiter=200000)


def resolve_material(material: Material | str) -> Material:
    """A Material as is, or a material's name looked up (physics.materials.get_material,
    which raises ClothInputError for an unknown name)."""
    return material if isinstance(material, Material) else get_material(material)


def validate_record_args(scene_name: str, particles: int, material: Material | str,
                         n_systems: int, dt: float, scheme: str, levels: int | None,
                         reference_tol: float) -> Material:
    """Reject bad recording parameters before any work; returns the Material."""
    if scene_name not in SCENES:
        raise ClothInputError(f"unknown scene {scene_name!r}; choose one of {', '.join(SCENES)}")
    validate_particles(particles)
    mat = resolve_material(material)
    if isinstance(n_systems, bool) or not isinstance(n_systems, (int, np.integer)) \
            or n_systems < 1:
        raise ClothInputError(f"number of systems must be a positive integer, got {n_systems!r}")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and 0.0 < dt <= 0.1):
        raise ClothInputError(f"time step must be in (0, 0.1] s, got {dt!r}")
    if scheme not in SCHEMES:
        raise ClothInputError(f"unknown integrator {scheme!r}; choose one of {', '.join(SCHEMES)}")
    if levels is not None and (isinstance(levels, bool) or not isinstance(levels, (int, np.integer))
                               or not 1 <= levels <= 7):
        raise ClothInputError(f"levels must be an integer between 1 and 7, got {levels!r}")
    if not (isinstance(reference_tol, (int, float)) and 0.0 < reference_tol < 1.0):
        raise ClothInputError(f"reference tolerance must be in (0, 1), got {reference_tol!r}")
    return mat


def iter_systems(scene: Scene, dt: float = 1.0 / 60.0, scheme: str = "bdf2",
                 after_contact: bool = True, reference_tol: float = 1e-8,
                 solver=None, delay: int = 0,
                 ) -> Iterator[tuple[int, StepSystem, np.ndarray, ClothState]]:
    """Yield (step index, StepSystem, reference dv, the state the step was assembled from)
    forever, advancing ``scene``'s model from a
    copy of its initial state with the reference solution. With ``after_contact`` the steps
    before the first contact, and ``delay`` more after it, are taken but not yielded.
    ``solver``: the reference solver (default: `reference_solver(reference_tol)`)."""
    model = scene.model
    if solver is None:
        solver = reference_solver(reference_tol)[1]
    state = scene.state.copy()
    waiting = after_contact and len(model.colliders) > 0
    touched = False
    first_touch = None if waiting else 0
    k = 0
    while True:
        step = assemble_step(model, state, dt, scheme)
        if first_touch is None and (touched or len(step.contacts) > 0):
            first_touch = k
        waiting = first_touch is None or k < first_touch + delay
        if waiting and k >= MAX_SETTLE_STEPS:
            raise RuntimeError(f"the cloth did not touch a collider in {MAX_SETTLE_STEPS} steps")
        result = solver.solve(step.system, step.rhs, step.x0, step.fixed)
        dv = np.asarray(result.x, dtype=np.float64).reshape(model.n, 3)
        if not np.all(np.isfinite(dv)):
            raise FloatingPointError(f"step {k}: the reference solution is not finite")
        keep = None if waiting else replace(step, internal=None)
        before = state
        state, count, _ = finish_step(model, state, step, dv.copy(), dt)
        touched = touched or count > 0
        if keep is not None:
            yield k, keep, dv, before
        k += 1


def record_systems(scene_name: str, particles: int, material: Material | str, n_systems: int,
                   dt: float = 1.0 / 60.0, scheme: str = "bdf2", levels: int | None = None,
                   after_contact: bool = True, reference_tol: float = 1e-8,
                   delay: int = 0) -> Recording:
    """Build scene ``scene_name`` at about ``particles`` particles of ``material`` (a Material
    or its name) and record ``n_systems`` consecutive step systems, the first one ``delay``
    steps after the first contact (``after_contact``) or at step ``delay``. Right at the first
    touch a falling sheet is still flat and its systems are easy; a delay of 20 steps (1/3 s)
    records the sheet folding over the sphere. See the module docstring."""
    mat = validate_record_args(scene_name, particles, material, n_systems, dt, scheme, levels,
                               reference_tol)
    t0 = time.perf_counter()
    scene = build_scene(scene_name, particles, mat, levels=levels)
    ref_name, solver = reference_solver(reference_tol)
    rec = Recording(scene, [], [], [], 0, ref_name, float(dt), scheme)
    budget = float(MAX_RECORD_BYTES)
    for k, step, dv, _ in iter_systems(scene, dt, scheme, after_contact, reference_tol, solver,
                                       delay):
        if not rec.systems:
            rec.start_step = k
        rec.systems.append(step)
        rec.contacts.append(len(step.contacts))
        rec.reference.append(dv)
        rec.reference_rel_residual = max(rec.reference_rel_residual,
                                         filtered_rel_residual(step, dv))
        if len(rec.systems) >= n_systems:
            break
        if rec.nbytes() * (len(rec.systems) + 1) / len(rec.systems) > budget:
            rec.truncated = True
            break
    rec.record_s = time.perf_counter() - t0
    return rec
