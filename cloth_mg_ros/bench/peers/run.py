"""Running the peers: build an engine, step it, time every step and read the sanity figures
(`run_engine`); the warm-up, the run's metadata and the whole benchmark (`bench_peers`).

Per run (one engine, one size): ``ms_per_step``, the median wall time of one ``dt`` step
(substeps included) over the steps after the first ``WARMUP_STEPS``; ``first_step_ms`` and
``setup_s`` (model build) reported apart; each engine is first run for a few steps at
``WARMUP_PARTICLES`` particles so that JIT compilation (numba, Warp kernels) or loading its
cache stays out of the timings (``meta.warmup_s``). Sanity figures, read from the engine's
positions after every step (outside the timed region): ``finite``, ``mean_height_m``,
``sag_m`` (how far the final mean height is below the sphere's top), ``hang_m`` (how far the
lowest particle is below it), ``max_penetration_m`` and ``final_penetration_m`` (deepest any
particle went inside the sphere or below the floor, any step and at the end), ``max_stretch``
and ``peak_stretch`` (longest edge over its rest length at the end and at any step, with
``peak_stretch_step``), ``mass_kg`` (the engine's own masses summed) and ``draped`` (finite and
``sag_m`` > DRAPED_SAG). ``cpu_ms_per_step`` (median process CPU time of a step) and
``cpu_per_wall`` (how many cores the engine kept busy) tell contention on a shared machine
from an engine's own cost.
"""

from __future__ import annotations

import datetime as _dt
import importlib.metadata as md
import importlib.util
import os
import platform
import sys
import time
import traceback

import numpy as np

from cloth_mg_ros.bench.blas_threads import blas_thread_count, blas_threads, one_blas_thread
from cloth_mg_ros.bench.peers.mujoco import _MujocoEngine
from cloth_mg_ros.bench.peers.newton import _NewtonEngine
from cloth_mg_ros.bench.peers.options import (
    DEFAULT_DT,
    DEFAULT_PARTICLES,
    DEFAULT_SETTINGS,
    DEFAULT_STEPS,
    DRAPED_SAG,
    ENGINE_MODULES,
    INSTALL_HINT,
    WARMUP_PARTICLES,
    WARMUP_STEPS,
    parse_engines,
    validate_peers_args,
)
from cloth_mg_ros.bench.peers.ours import _OursEngine
from cloth_mg_ros.bench.peers.report import peer_progress_line
from cloth_mg_ros.bench.peers.scene import DrapeSpec, build_spec, peer_parameters
from cloth_mg_ros.bench.solvers import machine_meta
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.sheets import DRAPE_SPHERE
from cloth_mg_ros.solvers.threads import resolve_threads, threads_for_block

# engine name -> the class `run_engine` builds; a dict so that a test can put a fake in.
ENGINE_CLASSES = {"ours": _OursEngine, "newton": _NewtonEngine, "mujoco": _MujocoEngine}


def missing_modules(engine: str) -> list[str]:
    """The Python modules ``engine`` needs that cannot be found (not imported here)."""
    return [m for m in ENGINE_MODULES[engine] if importlib.util.find_spec(m) is None]


def _sanity(spec: DrapeSpec, x: np.ndarray) -> tuple[float, float]:
    """(deepest penetration into the sphere or below the floor, m >= 0; longest edge over its
    rest length) of positions x (n, 3)."""
    inside = spec.sphere_radius - np.linalg.norm(x - spec.sphere_centre, axis=1)
    depth = max(float(np.max(inside, initial=0.0)), float(np.max(-x[:, 2], initial=0.0)), 0.0)
    e = spec.edges
    stretch = float(np.max(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1) / spec.edge_rest))
    return depth, stretch


def run_engine(spec: DrapeSpec, label: str, settings: dict | None = None) -> dict:
    """Build ``label`` ('engine:solver') on spec's scene, step it spec.steps times, time every
    step and return the run's row (see the module docstring)."""
    engine, solver = label.split(":")
    conf = dict(DEFAULT_SETTINGS[label], **(settings or {}))
    t0 = time.perf_counter()
    eng = ENGINE_CLASSES[engine](spec, solver, conf)
    setup_s = time.perf_counter() - t0
    times: list[float] = []
    cpu: list[float] = []
    depth, peak, peak_step, nan_at = 0.0, 1.0, 0, None
    x = eng.positions()
    for k in range(spec.steps):
        cs, ts = time.process_time(), time.perf_counter()
        eng.step()
        times.append(time.perf_counter() - ts)
        cpu.append(time.process_time() - cs)
        x = np.asarray(eng.positions(), dtype=np.float64)
        if not np.all(np.isfinite(x)):
            nan_at = k + 1
            break
        d, s = _sanity(spec, x)
        depth = max(depth, d)
        if s > peak:
            peak, peak_step = s, k + 1
    finite = nan_at is None
    timed = times[WARMUP_STEPS:] if len(times) > WARMUP_STEPS else times
    row = {
        "engine": engine, "solver": solver, "label": label, "particles": spec.n,
        "particles_requested": spec.particles_requested, "dt": spec.dt,
        "steps": len(times), "timed_steps": len(timed),
        "ms_per_step": 1e3 * float(np.median(timed)),
        "ms_per_step_p90": 1e3 * float(np.percentile(timed, 90)),
        # CPU time of the process per step: less sensitive than wall time to other load on a
        # shared machine, for engines that run on one thread.
        "cpu_ms_per_step": 1e3 * float(np.median(cpu[WARMUP_STEPS:] or cpu)),
        "first_step_ms": 1e3 * times[0], "setup_s": setup_s,
        # CPU seconds of all the process's threads per wall second: how many cores it used.
        "cpu_per_wall": float(sum(cpu[WARMUP_STEPS:]) / max(sum(times[WARMUP_STEPS:]), 1e-12))
        if len(times) > WARMUP_STEPS else None,
        "substeps": int(conf.get("substeps", 1)), "settings": conf,
        "finite": finite, "nan_at_step": nan_at, "mass_kg": eng.mass_kg,
        "area_m2": float(spec.areas.sum()), "skipped": False, "skip_reason": None,
    }
    if finite:
        final_depth, final_stretch = _sanity(spec, x)
        mean_h = float(np.mean(x[:, 2]))
        row.update(mean_height_m=mean_h, sag_m=spec.sphere_top - mean_h,
                   hang_m=spec.sphere_top - float(np.min(x[:, 2])),
                   max_penetration_m=depth, final_penetration_m=final_depth,
                   max_stretch=final_stretch, peak_stretch=peak, peak_stretch_step=peak_step)
    else:
        row.update(mean_height_m=None, sag_m=None, hang_m=None, max_penetration_m=None,
                   final_penetration_m=None, max_stretch=None, peak_stretch=None,
                   peak_stretch_step=None)
    row["draped"] = bool(finite and row["sag_m"] > DRAPED_SAG)
    if engine == "ours":
        row["iterations"] = float(np.median(eng.iterations))
    row.update(getattr(eng, "extra", {}))
    return row


def skipped_row(label: str, spec_n: int | None, requested: int, reason: str) -> dict:
    """A row for a run that did not happen (missing package, failure)."""
    engine, solver = label.split(":")
    return {"engine": engine, "solver": solver, "label": label, "particles": spec_n,
            "particles_requested": requested, "ms_per_step": None, "skipped": True,
            "skip_reason": reason, "finite": None, "draped": False}


def warm_up(labels: list[str], material: str, dt: float, settings: dict,
            unavailable: dict[str, str], log) -> dict[str, float]:
    """A few steps of every run at WARMUP_PARTICLES, so that JIT compilation (numba, Warp
    kernels) and loading its caches stay out of the timings. Returns {label: seconds};
    runs that fail here are added to ``unavailable`` with the reason."""
    spec = build_spec(WARMUP_PARTICLES, material, dt, WARMUP_STEPS + 1)
    out = {}
    for label in labels:
        if label in unavailable:
            continue
        t0 = time.perf_counter()
        try:
            run_engine(spec, label, settings.get(label))
        except Exception as exc:  # noqa: BLE001 - a peer's failure must not end the benchmark
            unavailable[label] = f"failed in warm-up: {type(exc).__name__}: {exc}"
            log(traceback.format_exc())
            continue
        out[label] = time.perf_counter() - t0
        log(f"warm-up {label}: {out[label]:.1f} s (JIT compilation or cache loading)")
    return out


def warm_up_peers(log=print) -> dict[str, float]:
    """`cloth-mg warmup --peers`: a few steps of every installed peer engine (Newton's
    solvers, MuJoCo's), so that Warp compiles the kernels `bench peers` and its tests use into
    its own cache (about 85 s on 2 cores the first time, a few seconds after). Returns
    {label: seconds}; a peer not installed is logged and left out, one that fails raises."""
    labels = [lb for lb in parse_engines("all") if not lb.startswith("ours:")]
    unavailable = {lb: "not installed" for lb in labels
                   if missing_modules(lb.split(":")[0])}
    for label in unavailable:
        log(f"warm-up {label}: not installed ({INSTALL_HINT})")
    with one_blas_thread():
        out = warm_up(labels, "cotton", DEFAULT_DT, {}, unavailable, log)
    failed = {lb: why for lb, why in unavailable.items() if why != "not installed"}
    if failed:
        raise RuntimeError("peer warm-up failed: " + "; ".join(f"{lb} {why}"
                                                                for lb, why in failed.items()))
    return out


def _versions() -> dict:
    out = {}
    for pkg in ("numpy", "scipy", "numba", "warp-lang", "newton", "mujoco"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


def _meta(particles, labels, steps, dt, material, settings) -> dict:
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    mat = get_material(material)
    params = peer_parameters(mat)
    conf = {label: dict(DEFAULT_SETTINGS[label], **settings.get(label, {})) for label in labels}
    notes = [
        ("ms_per_step: one step of dt (all of an engine's substeps), median over the steps after "
        f"the first {WARMUP_STEPS}; cpu_per_wall (process CPU time over wall time in the timed "
        "steps) shows how many cores each engine kept busy"),
        ("ours: BDF2, one linearised implicit solve per step (tol 1e-4), penalty contacts then "
        "projection with Coulomb friction; timings leave out the per-step energy diagnostics"),
        ("newton: settings of Newton's cloth examples (VBD 10 substeps x 10 iterations; Style3D "
        "2 substeps x 10 nonlinear x 10 PCG iterations); contacts: penalty "
        f"{DEFAULT_SETTINGS['newton:vbd']['contact_ke']:g} N/m (ours projects particles out "
        "instead); self-contact off as in ours"),
        ("mujoco: discrete integrator (implicit in position; the flex's elasticity enters the "
        "solver's metric), one step per dt, soft-constraint contacts of the flex radius; "
        "compiling a 2D flex with bending grows steeply with its size (compile_s per row), so "
        "both MuJoCo solvers of a size share one compile (setup, not timed)"),
        ("walking garment: not run. A like-for-like run needs the dress's sewn particles to "
        "follow the body and its 16 capsules to move every substep: Newton could do it "
        "(kinematic capsule bodies posed each substep, zero-mass sewn particles moved by hand) "
        "but it is not implemented here; MuJoCo cannot attach flex vertices with elasticity "
        "to mocap bodies (its documentation), so the avatar would have to become an actuated "
        "articulated body tracking the poses, a different problem from ours"),
    ]
    for key in ("vbd", "style3d", "mujoco"):
        notes += [f"{key}: {n}" for n in params[key]["notes"]]
    return {
        "machine": machine_meta(), "cpus": os.cpu_count(), "platform": platform.platform(),
        "python": sys.version.split()[0], "versions": _versions(),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "scene": "drape", "material": mat.name, "particles_requested": list(particles),
        "engines": list(labels), "steps": steps, "dt": dt, "duration_s": steps * dt,
        "warmup_steps": WARMUP_STEPS, "warmup_particles": WARMUP_PARTICLES,
        "draped_sag_m": DRAPED_SAG, "settings": conf,
        "sphere_top_m": float(DRAPE_SPHERE[0][2] + DRAPE_SPHERE[1]),
        "sphere": {"centre_m": DRAPE_SPHERE[0].tolist(), "radius_m": DRAPE_SPHERE[1]},
        "parameters": {k: {kk: vv for kk, vv in v.items() if kk != "notes"}
                       for k, v in params.items()},
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS", "unset"),
        "loadavg_start": load, "notes": notes,
    }


def bench_peers(particles: list[int] | tuple = DEFAULT_PARTICLES, engines: list[str] | str = "all",
                steps: int = DEFAULT_STEPS, dt: float = DEFAULT_DT, material: str = "cotton",
                settings: dict | None = None, log=None, threads: int = 1) -> dict:
    """Run the benchmark; returns {"runs": [...], "meta": {...}}.

    engines: labels 'engine:solver' or engine names (see `parse_engines`); settings:
    {label: {key: value}} overriding DEFAULT_SETTINGS; log: a callable taking one line of
    progress (default: print to stderr); threads: our engine's kernel threads (default 1, as
    the peers' CPU paths run on one; 0: every core), recorded as meta["threads"]."""
    labels = parse_engines(engines)
    material = str(material).strip().lower()
    particles = list(particles)
    count = resolve_threads(threads)
    validate_peers_args(particles, labels, steps, dt, material)
    settings = settings or {}
    for label, conf in settings.items():
        if label not in DEFAULT_SETTINGS or any(k not in DEFAULT_SETTINGS[label] for k in conf):
            raise ClothInputError(f"bench peers: unknown setting(s) for {label!r}: {conf}")
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    meta = _meta(particles, labels, steps, dt, material, settings)
    # every engine's BLAS on one thread, whatever the environment
    with threads_for_block(count) as meta["threads"], one_blas_thread():
        result = _bench_all(particles, labels, material, dt, steps, settings, meta, log)
        meta.update(blas_threads=blas_thread_count(), blas_libraries=blas_threads())
    return result


def _bench_all(particles: list[int], labels: list[str], material: str, dt: float, steps: int,
               settings: dict, meta: dict, log) -> dict:
    """`bench_peers`' runs: every engine at every size, on the calling thread's kernel
    threads."""
    t_start = time.perf_counter()
    unavailable: dict[str, str] = {}
    for label in labels:
        engine = label.split(":")[0]
        missing = missing_modules(engine)
        if missing:
            unavailable[label] = (f"{', '.join(missing)} not installed ({INSTALL_HINT} installs "
                                  f"the peers extra)")
            log(f"{label}: skipped: {unavailable[label]}")
    meta["warmup_s"] = warm_up(labels, material, dt, settings, unavailable, log)
    runs = []
    for n in particles:
        spec = build_spec(n, material, dt, steps)
        log(f"{spec.n} particles ({spec.steps} steps of {spec.dt:.4g} s)")
        for label in labels:
            if label in unavailable:
                runs.append(skipped_row(label, spec.n, n, unavailable[label]))
                continue
            try:
                row = run_engine(spec, label, settings.get(label))
            except Exception as exc:  # noqa: BLE001 - one failing peer must not end the run
                log(traceback.format_exc())
                row = skipped_row(label, spec.n, n, f"failed: {type(exc).__name__}: {exc}")
            runs.append(row)
            log("  " + peer_progress_line(row))
    meta["wall_s"] = time.perf_counter() - t_start
    meta["unavailable"] = unavailable
    return {"runs": runs, "meta": meta}
