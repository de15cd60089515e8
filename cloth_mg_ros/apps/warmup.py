"""Every kernel a scene's ticks use, compiled (or loaded from numba's on-disk cache) before the
first tick needs it.

numba compiles a kernel the first time it is called with new argument types and keeps the
machine code under __pycache__ (`cache=True`). That cache is stale once a source file changes
(after a `git pull`), and a kernel that only some ticks reach compiles in the middle of a live
run: the coarse levels' assembly (a garment with more than one multigrid level), self-contact
(once the cloth folds onto itself), a level-of-detail switch. A small stand-in warm-up
leaves such kernels to the live run: its first tick then stalls for seconds, it stalls again
when the cloth first folds, and the demo draws only a few markers for its first poses
(doc/design-measurements.md, 'Warm-up', has the figures).

So the warm-up runs the tick path itself (`warm_up_garment`): the scene's garment, solver,
tolerance, threads, floor and self-contact, dressed on the avatar's standing pose at the
scene's size (at most WARM_PARTICLES: kernels compile per argument type, not per size, and a
garment of that size has every level kind the multigrid builds), advanced through a few key
poses of a body that moves (several keys in one tick, then one per tick), squashed so that the
cloth touches itself, re-anchored after a teleport, and, with level of detail, stepped down
through every coarser level and back up. `CompileWatch` counts what numba compiles (the node
watches after its warm-up: nothing should compile while it ticks). `cloth-mg warmup` runs the
warm-up for the bundled scenes, so that `make` fills numba's cache after installing and a
user who upgraded gets the first start as fast as any later one.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Self

import numpy as np
from numba.core import event as numba_event
from numba.core.registry import CPUDispatcher

from cloth_mg_ros.config.scenes import AUTO, BODY_SCENES, load_scene
from cloth_mg_ros.config.schema import defaults
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.joint_body import joints_from_poses, poses_from_joints
from cloth_mg_ros.motion.skeletons import SKELETONS, Skeleton
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.garment_sim import BodySimOptions, GarmentSim
from cloth_mg_ros.sim.schemes import DEFAULT_SPECTRAL_RADIUS
from cloth_mg_ros.sim.sheets import SCENES, build_scene, scene_friction
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver
from cloth_mg_ros.solvers.threads import use_threads

__all__ = [
    "WARM_PARTICLES",
    "CompileWatch",
    "WarmUp",
    "kernel_signatures",
    "warm_up_garment",
    "warm_up_scenes",
    "warm_up_sheet",
]

WARM_PARTICLES = 2400  # three multigrid levels and two levels of detail for every garment
WARM_PERIOD = 1.0 / 30.0  # s between the warm-up's key poses
WARM_STEP_M = 0.03  # m the body walks per key pose: the cloth and the capsules move
WARM_KEYS = 5  # key poses of that walk (two in one tick, then one per tick)
SQUASH = 0.2  # the cloth's height is scaled by this about its centre: it touches itself
TELEPORT_M = 2.0  # m: the re-anchoring's jump
SHEET_PARTICLES = 400  # a sheet scene's warm-up size


@dataclass
class CompileWatch:
    """Counts the kernels numba compiles while it is on (`start` / `stop`, or `with`): a
    listener of numba's 'numba:compile' event, which fires for a real compilation only (not
    for a load from the on-disk cache). Thread-safe; nested compilations (a kernel's callees)
    count once each, their time once (the outermost)."""

    compiled: list[str] = field(default_factory=list)  # module.name of each, in order
    seconds: float = 0.0  # of the outermost compilations
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _local: threading.local = field(default_factory=threading.local)
    _listener: numba_event.Listener | None = None
    _reported: int = 0  # compilations `news` has told of

    def start(self) -> Self:
        watch = self

        class _Listener(numba_event.Listener):
            def on_start(self, event) -> None:
                depth = getattr(watch._local, "depth", 0)
                if depth == 0:
                    watch._local.t0 = time.perf_counter()
                watch._local.depth = depth + 1

            def on_end(self, event) -> None:
                watch._local.depth = getattr(watch._local, "depth", 1) - 1
                fn = event.data["dispatcher"].py_func
                with watch._lock:
                    watch.compiled.append(f"{fn.__module__}.{fn.__qualname__}")
                    if watch._local.depth == 0:
                        watch.seconds += time.perf_counter() - watch._local.t0

        self._listener = _Listener()
        numba_event.register("numba:compile", self._listener)
        return self

    def stop(self) -> None:
        if self._listener is not None:
            numba_event.unregister("numba:compile", self._listener)
            self._listener = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def count(self) -> int:
        with self._lock:
            return len(self.compiled)

    def news(self) -> str | None:
        """A line on the kernels compiled since the last call (None: none were)."""
        with self._lock:
            fresh, self._reported = self.compiled[self._reported:], len(self.compiled)
        if not fresh:
            return None
        return (f"{len(fresh)} kernel(s) compiled after the warm-up, "
                f"{1e3 * self.seconds:.0f} ms in all so far (the warm-up missed them): "
                f"{', '.join(sorted(set(fresh))[:6])}")


def kernel_signatures() -> int:
    """How many (kernel, argument types) of this package this process has compiled or loaded
    from numba's cache: a tick that adds one was not warmed up."""
    seen: set[int] = set()
    total = 0
    for name, module in list(sys.modules.items()):
        if not name.startswith("cloth_mg_ros") or module is None:
            continue
        for obj in vars(module).values():
            if isinstance(obj, CPUDispatcher) and id(obj) not in seen:
                seen.add(id(obj))
                total += len(obj.overloads)
    return total


@dataclass
class WarmUp:
    """What a warm-up did: wall time (ms), the kernels it compiled (not found in numba's
    cache) and their compile time (ms), the garment's particles and levels of detail run."""

    ms: float
    compiled: int
    compile_ms: float
    particles: int
    levels: list[int]

    def describe(self) -> str:
        cache = ("every kernel from numba's cache" if not self.compiled else
                 f"{self.compiled} kernels compiled in {self.compile_ms / 1e3:.1f} s, the "
                 f"rest from numba's cache")
        lod = (f", levels of detail {self.levels}" if len(self.levels) > 1 else "")
        return f"{self.ms:.0f} ms ({self.particles} particles{lod}; {cache})"


def _walked(poses: np.ndarray, metres: float) -> np.ndarray:
    """The body poses (S, 7) moved `metres` along x (a walk forward, no rotation)."""
    out = np.array(poses, dtype=np.float64)
    out[:, 0] += metres
    return out


def warm_up_garment(avatar: Avatar, material: Material, options: BodySimOptions,
                    lod: bool = False) -> tuple[WarmUp, GarmentSim]:
    """Run every kernel a body scene's ticks use (module docstring) on a throw-away garment of
    the scene's kind (options; at most WARM_PARTICLES particles); lod: also switch through its
    levels of detail and back. Returns what it did and the garment (for the caller's own
    first-time work, e.g. building the outputs once)."""
    t0 = time.perf_counter()
    with CompileWatch() as watch:
        opts = replace(options, particles=min(int(options.particles), WARM_PARTICLES))
        rest = avatar.rest_poses()
        garment_sim = GarmentSim.dress(avatar, 0.0, rest, material, opts)
        keys = [(k * WARM_PERIOD, _walked(rest, k * WARM_STEP_M))
                for k in range(1, WARM_KEYS + 1)]
        garment_sim.advance(keys[:2])  # a tick that coalesces two poses, then one pose per tick
        for key in keys[2:]:
            garment_sim.advance([key])
        stamp, poses = keys[-1]
        x = garment_sim.sim.state.x  # squashed: the cloth lies on itself, self-contact has pairs
        centre = float(x[:, 2].mean())
        x[:, 2] = centre + SQUASH * (x[:, 2] - centre)
        stamp += WARM_PERIOD
        garment_sim.advance([(stamp, poses)])
        stamp += WARM_PERIOD
        poses = _walked(poses, TELEPORT_M)
        garment_sim.reanchor(stamp, poses)  # the step after it has no history (backward Euler)
        levels = garment_sim.rung_indices() if lod else [0]
        order = levels
        if len(levels) > 1:  # down through every level of detail, then back up
            garment_sim.prepare_rungs()
            order = [*levels, levels[0]]
        for level in order:
            garment_sim.set_rung(level)
            stamp += WARM_PERIOD
            poses = _walked(poses, WARM_STEP_M)
            garment_sim.advance([(stamp, poses)])
    watch_ms = 1e3 * watch.seconds
    return WarmUp(1e3 * (time.perf_counter() - t0), watch.count, watch_ms, garment_sim.sim.model.n,
                  levels), garment_sim


def warm_up_sheet(scene_name: str, material: Material, solver: str, tolerance: float,
                  dt: float, levels: int | None = None, threads: int = 0,
                  particles: int = SHEET_PARTICLES, scheme: str = "bdf2",
                  spectral_radius: float = DEFAULT_SPECTRAL_RADIUS,
                  friction: float | None = None, compression: str = "elastic") -> WarmUp:
    """Two steps of a throw-away sheet scene (`sheets.build_scene`) with the node's solver,
    tolerance (relative), step dt (s), threads (0: every core; set for the calling thread,
    as a sheet's ticks set it), integrator (scheme, spectral_radius), friction and
    compression: the kernels a sheet's ticks use (an integrator or a membrane that only the
    warm-up left out would compile in the first live tick)."""
    t0 = time.perf_counter()
    with CompileWatch() as watch:
        use_threads(threads)
        scene = build_scene(scene_name, particles, material, levels=levels, friction=friction,
                            compression=compression)
        solver_obj = make_solver(solver, tol=tolerance, hierarchy=scene.hierarchy,
                                 bending=scene.model.bending, levels=levels,
                                 threads=threads)
        sim = Simulator(scene.model, scene.state.copy(), solver_obj, dt=dt, scheme=scheme,
                        spectral_radius=spectral_radius)
        sim.step()
        sim.step()
    return WarmUp(1e3 * (time.perf_counter() - t0), watch.count, 1e3 * watch.seconds,
                  scene.model.n, [0])


def warm_up_scenes(scenes: Iterable[str] = (*BODY_SCENES, *SCENES), threads: int = 0,
                   log: Callable[[str], None] = print) -> dict[str, WarmUp]:
    """Warm up each scene as the node would run it (body scenes with their garment, options
    and level of detail; tolerance 'auto' stands in as 1e-2, a number of the same type as
    the measured one) and log a line each. Returns {scene: WarmUp}."""
    avatar = None
    out: dict[str, WarmUp] = {}
    for name in scenes:
        if name in SCENES:  # as the node runs a sheet with its defaults
            p = defaults(body=False)
            result = warm_up_sheet(name, get_material(p.material), p.solver,
                                   float(p.tolerance), p.dt, levels=p.levels or None,
                                   threads=threads, scheme=p.scheme,
                                   spectral_radius=p.spectral_radius,
                                   friction=scene_friction(name, p.friction),
                                   compression=p.compression)
        else:
            params = load_scene(name)
            avatar = avatar or Avatar.load()
            options = BodySimOptions.from_scene(
                params, threads=threads,
                particles=WARM_PARTICLES if params.particles == AUTO else params.particles,
                tolerance=1e-2 if params.tolerance == AUTO else params.tolerance)
            result, _ = warm_up_garment(avatar, get_material(params.material), options,
                                        lod=params.lod)
        out[name] = result
        log(f"warm-up {name}: {result.describe()}")
    t0 = time.perf_counter()
    for skeleton in SKELETONS.values():
        warm_up_joints(avatar or Avatar.load(), skeleton)
    log(f"warm-up body_input joints: {1e3 * (time.perf_counter() - t0):.0f} ms")
    return out


def warm_up_joints(avatar: Avatar, skeleton: Skeleton) -> None:
    """body_input joints: turn the rest pose's joints of `skeleton` into segment poses once,
    as a tick does (motion.joint_body's kernels)."""
    rest = joints_from_poses(avatar, avatar.rest_poses(), skeleton)
    poses_from_joints(rest[None], skeleton, avatar)
