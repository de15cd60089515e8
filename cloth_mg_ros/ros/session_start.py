"""What a live session of cloth_node needs at start: its settings from the node's parameters,
checked before any work (`SessionSettings`), and the scene built and warmed up on the
simulation thread (`prepare_sheet`, `prepare_body`).

The settings are read through the node's parameter getter and raise ClothInputError naming
the parameter and the value when one is unusable; the session (ros.session) never reads a ROS
parameter itself.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from cloth_mg_ros.apps.warmup import warm_up_garment, warm_up_sheet
from cloth_mg_ros.budget.cost_model import (
    CALIBRATION_PARTICLES,
    check_max_particles,
    load_or_calibrate,
)
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.config.schema import SceneParams
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.ros.gripper_desk import GripperDesk, sheet_grippers
from cloth_mg_ros.ros.ingest import FrameLog, PoseIngest
from cloth_mg_ros.sim.garment import BodySimOptions
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.sim.solve_tolerance import describe
from cloth_mg_ros.solvers.threads import resolve_threads

__all__ = ["SessionSettings", "prepare_body", "prepare_sheet"]


@dataclass(frozen=True)
class SessionSettings:
    """body: a body scene (else a sheet); values: every parameter's start value, checked
    against the schema (config.schema.SceneParams: values.garment, values.tick_mode, ...);
    material: the cloth's; threads: the simulation threads (resolved: >= 1)."""

    body: bool
    values: SceneParams
    material: Material
    threads: int

    @classmethod
    def from_values(cls, values: SceneParams, body: bool) -> SessionSettings:
        """The settings from the node's checked parameter values (ros.parameters.
        check_parameters); ClothInputError for what the schema cannot tell alone."""
        if not body and values.tick_mode != "timer":
            raise ClothInputError(f"tick_mode {values.tick_mode!r} needs a body scene; sheet "
                                  f"scene {values.scene!r} runs on the timer")
        return cls(body, values, get_material(values.material), resolve_threads(values.threads))

    @property
    def levels(self) -> int | None:
        """Multigrid levels (None: as many as the mesh size calls for)."""
        return self.values.levels or None

    def sheet_scene(self):
        """The sheet scene the parameters declare (sim.sheets.build_scene: its particles,
        material, levels, friction and compression)."""
        return build_scene(self.values.scene, int(self.values.particles), self.material,
                           levels=self.levels, friction=self.values.friction,
                           compression=self.values.compression)


def prepare_sheet(session) -> str:
    """Build a sheet scene, its grippers (the scene's own and the grippers parameter's:
    ros.gripper_desk.sheet_grippers) and its simulator, warm its kernels up on the simulation
    thread. Returns the start-up log line's description."""
    s, values = session.settings, session.settings.values
    t0 = time.perf_counter()
    for key in ("particles", "tolerance"):
        if values[key] == AUTO:
            raise ClothInputError(f"parameter {key}: 'auto' is for body scenes (a garment "
                                  f"on a pose stream); give a sheet a number")
    session.scene = s.sheet_scene()
    session.initial_state = session.scene.state.copy()
    session.sheet_grippers = sheet_grippers(session.scene, values.grippers,
                                            values.grasp_radius, values.release_force)
    if session.sheet_grippers is not None:
        session.initial_grippers = session.sheet_grippers.copy()
    session.desk = GripperDesk(session.sheet_grippers.names if session.sheet_grippers
                               else (), session.logger)
    session.sim = Simulator(session.scene.model, session.scene.state,
                            session.make_sheet_solver(), dt=values.dt, scheme=values.scheme,
                            spectral_radius=values.spectral_radius)
    build_ms = 1e3 * (time.perf_counter() - t0)
    warm = session.sim_thread.call(
        warm_up_sheet, values.scene, session.material, session.solver, float(session.tolerance),
        session.sim.dt, s.levels, s.threads)
    session.ready()
    return (f"scene {session.scene.name!r}: {session.scene.model.n} particles, "
            f"{len(session.scene.model.mesh.faces)} triangles, {session.material.name}, "
            f"solver {session.solver} (tol {session.tolerance:g}), dt {session.sim.dt:.4g} "
            f"s, {session.rate_hz:g} Hz, built in {build_ms:.0f} ms, warmed up in "
            f"{warm.describe()}{grippers_text(session.desk.names)}")


def prepare_body(session) -> str:
    """Check the garment's parameters, load the avatar, calibrate the cost model when the
    scene needs it (particles auto, lod, tolerance auto), create the pose ingest and warm the
    tick path up on the simulation thread. Returns the start-up log line's description."""
    s, params = session.settings, session.settings.values
    session.avatar = Avatar.load()
    session.particles_auto = params.particles == AUTO
    tolerance_auto = params.tolerance == AUTO
    check_max_particles(params.garment, params.max_particles, "parameter max_particles")
    session.options = BodySimOptions.from_scene(
        params, threads=s.threads,
        particles=CALIBRATION_PARTICLES if session.particles_auto else params.particles)
    if session.particles_auto or params.lod or tolerance_auto:
        session.cost_model, _ = session.sim_thread.call(
            load_or_calibrate, session.options, session.material, session.logger.info,
            bag=params.bag)
        session.options.tolerances = tuple(session.cost_model.tolerances)
    if session.particles_auto and params.tick_mode == "timer":
        session.choose_particles(session.rate_hz)
    session.desk = GripperDesk(params.grippers, session.logger)
    session.frames = FrameLog(session.logger, session.avatar.num_segments)
    session.ingest = PoseIngest(session.avatar.num_segments, session.options.teleport_m,
                                session.frames, on_restart=session.on_stream_restart)
    warm = session.sim_thread.call(warm_up_body, session)
    session.ready()
    o = session.options
    return (f"scene {params.scene!r}: a {o.garment} of about {o.particles} particles, "
            f"{session.material.name}, solver {o.solver} (tol "
            f"{describe(o.tolerance, o.tolerances)}, levels {o.levels or 'auto'}), "
            f"substeps >= {o.substeps}, steps <= {o.max_step:g} s, floor {o.floor}, "
            f"self-contact {o.self_contact}, {s.threads} thread(s); warmed up in {warm}; "
            f"tick mode {params.tick_mode}{grippers_text(session.desk.names)}")


def grippers_text(names) -> str:
    """The start-up line's grippers ('' without any)."""
    return f"; grippers {', '.join(names)}" if names else ""


def warm_up_body(session) -> str:
    """Run every kernel the ticks will use (apps.warmup.warm_up_garment: the scene's
    garment, solver, tolerance, contacts and levels of detail on a moving body) and build
    the outputs' messages once, on the simulation thread, before the node subscribes.
    Returns what it did, for the log."""
    warm, garment_sim = warm_up_garment(session.avatar, session.material, session.options,
                                        lod=session.settings.values.lod)
    session.outputs.cloth_messages(garment_sim.sim.model, garment_sim.positions, 0, 0,
                                   session.outputs.frame_id, garment_sim.sim.state.v,
                                   garment_sim.capsules())
    return warm.describe()

