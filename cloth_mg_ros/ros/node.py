"""cloth_node: a garment draped over a moving avatar (or a sheet scene), published for RViz.

Run it (in a ROS 2 workspace, or in the project's virtualenv):

    cloth_node --ros-args --params-file config/walking.yaml      # a body scene
    cloth_node --ros-args -p scene:=running -p particles:=1200   # the scene file's defaults
    cloth_node --ros-args -p scene:=hang -p particles:=5000 -p rate_hz:=30.0   # a sheet
    python -m cloth_mg_ros.ros.node                              # the walking scene
    ros2 launch cloth_mg_ros cloth.launch.py bag:=walk rviz:=true   # node, player, RViz2

and, in another shell, play body poses into it: `cloth-mg replay bags/walk`.

Two kinds of scene (parameter `scene`, default 'walking'):

- Body scenes (walking, brisk_walking, running, jumping, their aliases walk, ..., any
  config/<scene>.yaml, or a path to a params .yaml): the parameters not given on the command
  line take their defaults from the scene's file (scene_config.load_scene). The node subscribes
  to `topic` (geometry_msgs/PoseArray, one pose per avatar segment in Avatar.names order,
  [x, y, z] m and a unit quaternion; raw CDR bytes straight into numpy). Its QoS is
  `input_reliability` (default best_effort, which matches reliable and best-effort publishers
  alike), keep-last 100; the callback only decodes and checks a message and keeps it as a key
  pose (ros.ingest), so nothing waits in the middleware's queue. A simulation thread of its
  own (ros.stepping) dresses the garment on the first valid pose (GarmentSim.dress) and, in
  tick mode 'message' (the default), advances the cloth each tick to the newest pose received,
  the body following every pose received since the last tick: a tick that runs long
  coalesces the backlog instead of queueing it. In tick mode 'timer' it steps 1/rate_hz s of
  simulated time every 1/rate_hz s of wall time through the poses that arrived.
- Sheet scenes (drape, hang): always timer mode, one step of `dt` per tick.

Per tick (a dressing, a re-anchoring or a step through key poses; a sheet's step) the node
publishes, stamped with the newest pose's header stamp in message mode and the node's clock
otherwise, in the poses' header.frame_id (`frame_id` when they name none, and for sheets). Topic
names are relative: a namespace (`-r __ns:=/alice`) moves them all (ros.publishing):

- `marker_topic` (visualization_msgs/Marker, default cloth/marker): the cloth as one
  TRIANGLE_LIST (ns 'cloth', id 0), m, z up, serialised straight from numpy
  (`cloth_mg_ros.io.messages.markers`; 20K particles: about 1 ms). With strain_colours, per-vertex
  colours show the stretch (the cloth colour at rest length, red at 10 % and more);
- `markers_topic` (visualization_msgs/MarkerArray, default cloth/markers): per avatar capsule
  a CYLINDER (ns 'avatar', id = segment index) and a SPHERE_LIST of its two end caps (ns
  'avatar_caps'); sheet scenes' sphere collider (ns 'collider'); a TEXT_VIEW_FACING caption of
  the latest status (ns 'caption'). The cloth is not repeated here, so it is drawn once;
- `points_topic` (sensor_msgs/PointCloud2, default cloth/points): the particles, float32 x, y,
  z (m; with points_velocity also vx, vy, vz, m/s); `mesh_topic` (shape_msgs/Mesh, default
  cloth/mesh): triangles over vertices, vertex i particle i (ros.geometry_out);
- `stats_topic` (diagnostic_msgs/DiagnosticArray, default cloth/stats): one status
  'cloth_node: solver' with step_ms, solve_ms, iterations, rel_residual, max_penetration_m,
  contacts, substeps, particles, marker_ms, and the pose stream's counters: poses_received,
  poses_used (simulated to or coalesced into a tick), poses_coalesced, poses_pending,
  poses_discarded (by a reset), dropped (valid poses never used: 0), lag_ms (newest pose
  received minus simulated time), tick_poses (key poses of this tick). Level OK; WARN when the
  solve stopped short of `tolerance`, when pose frames were skipped since the previous
  status, or after a re-anchoring; ERROR when a simulation step failed (its result was
  dropped, the cloth held) or positions became non-finite (then no marker is published).

Every `diagnostics_period` s (1 s) the latest status goes to the global /diagnostics too, at
the worst level seen since the previous one, hardware_id the node's full name. Outputs are
reliable, keep-last 5. DELETEALL clears both marker topics on a reset, when a new stream
re-dresses the garment and at shutdown.

Bad pose input never reaches the cloth: empty messages, a wrong number of poses, NaN or
infinite values, stale stamps (at or before the simulated time) and undecodable bytes are
skipped; a jump of more than a metre re-anchors the garment (carried rigidly with the
body). Each kind is logged once
as a warning when first seen, then counted: a summary is logged every 10 s while the counts
change, and at shutdown ('pose frames: 40 received, 36 used; skipped 4: non_finite 2 ...').

Services and run-time parameters:

- `~/reset` (std_srvs/Trigger): body scenes re-dress the garment on the next valid pose
  (stamps start afresh, so a bag can be replayed again; poses of the old stream still
  buffered are discarded and counted); sheet scenes restart. A new time line (`ros2 bag play
  --loop`, a restarted publisher) starts a new stream by itself once NEW_STREAM_KEYS poses
  went on from the earlier stamp: the old stream's buffered poses are simulated, then the
  garment is re-dressed (ros.ingest); one stale pose alone is skipped.
- `cloth_node --help` prints the usage and every parameter.
- `solver` and `tolerance` may be set while running (`ros2 param set`); an unknown solver or a
  tolerance out of (0, 0.5] is rejected with the reason; a valid change rebuilds the solver
  before the next tick. `rate_hz` may be changed too (timer modes). Every other parameter is
  read-only (needs a restart).

With max_steps > 0 the node exits (status 0) after that many simulation ticks. Ctrl-C exits
with status 0. At every such exit (SIGINT, SIGTERM, max_steps) the node ends its tick in
progress, publishes DELETEALL on both marker topics and waits up to SHUTDOWN_ACK_S for every
reliable reader to acknowledge it (logged), so that no display keeps a ghost cloth;
`marker_lifetime` > 0 makes markers expire by themselves should the node be killed.

Before it subscribes, the node warms up on its own tick path (cloth_mg_ros.apps.warmup): a first
tick never waits for numba to compile; `kernels_compiled` in the stats counts any that did.

Start-up failures (an unknown scene, garment, material or solver, a parameter out of its
declared range or of the wrong type, a bad topic name) are logged as one error line naming
the value and the node exits with status 1 before any topic appears.

rclpy notes: parameter on-set callbacks also run for declarations, so they are added after
declaring.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import InvalidTopicNameException, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from sensor_msgs.msg import PointCloud2
from shape_msgs.msg import Mesh
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.apps.memory import keep_freed_memory
from cloth_mg_ros.apps.warmup import CompileWatch, warm_up_garment, warm_up_sheet
from cloth_mg_ros.budget.cost_model import (
    CALIBRATION_PARTICLES,
    check_max_particles,
    choose_particles,
    load_or_calibrate,
)
from cloth_mg_ros.config.scenes import AUTO, SCENE_KEYS, check_value
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.messages.markers import verify_layout
from cloth_mg_ros.io.share import config_path
from cloth_mg_ros.mesh.garments.design import MIN_PARTICLES
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.ros.geometry_out import verify_geometry_layouts
from cloth_mg_ros.ros.ingest import (
    NEW_STREAM_KEYS,
    SUMMARY_PERIOD_S,
    FrameLog,
    PoseIngest,
    verify_pose_array_layout,
)
from cloth_mg_ros.ros.marker_array import verify_marker_array_layout
from cloth_mg_ros.ros.parameters import (
    INPUT_RELIABILITY,
    TICK_MODES,
    Param,
    check_runtime_change,
    descriptor,
    parameter_table,
    scene_defaults,
    usage_text,
)
from cloth_mg_ros.ros.publishing import ClothOutputs, Publishers
from cloth_mg_ros.ros.stepping import SimThread, Stepper
from cloth_mg_ros.sim.integrator import Simulator
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.tolerance import describe
from cloth_mg_ros.solvers import make_solver, validate_solver_name
from cloth_mg_ros.solvers.threads import resolve_threads

__all__ = ["ClothNode", "main"]

NODE_NAME = "cloth_node"
# Outputs keep the last few messages only: a display wants the newest cloth, and a message is
# up to a few MB; a reliable recorder still receives every one it subscribed to.
OUTPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                        history=HistoryPolicy.KEEP_LAST, depth=5)
DIAGNOSTICS_TOPIC = "/diagnostics"
INPUT_DEPTH = 100
# The simulation thread runs Python between its (GIL-free) kernels; a shorter switch interval
# than CPython's 5 ms lets the subscription's callback in within a millisecond.
SWITCH_INTERVAL_S = 0.001
# At shutdown, how long the DELETEALL waits for every reliable reader's acknowledgement: DDS
# does not deliver a sample whose writer is destroyed first (a display would keep the cloth).
SHUTDOWN_ACK_S = 1.0


def input_qos(reliability: str) -> QoSProfile:
    """The pose subscription's QoS: best_effort (matches every publisher) or reliable."""
    policy = (ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort"
              else ReliabilityPolicy.RELIABLE)
    return QoSProfile(reliability=policy, history=HistoryPolicy.KEEP_LAST, depth=INPUT_DEPTH)


class ClothNode(Node):
    """Declares the parameters, builds the scene, and runs the simulation thread (module
    docstring).

    Raises ClothInputError (or rclpy's ParameterException) from the constructor when a
    parameter is unusable; the node is destroyed before the exception leaves.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        #: Completed with the exit status when the node should stop (max_steps or a failure).
        self.finished = Future()
        self.steps = 0  # simulation ticks done (sheet steps, or ticks through key poses)
        self.gs = None  # the GarmentSim of a body scene, once dressed
        self.options = None  # a body scene's BodySimOptions
        self.cost_model = None  # particles auto or lod: cost_model.CostModel
        self.auto_choice = None  # particles auto: the cost_model.AutoChoice made
        self.lod = None  # lod: the garment_levels.LevelController of the garment
        self.resets = 0
        self.ingest: PoseIngest | None = None
        self.stepper: Stepper | None = None
        self.sim_thread = SimThread()  # every numba kernel runs on it (stepping docstring)
        # Kernels numba compiles once the node is ready (the warm-up should leave none).
        self.compiles = CompileWatch()
        self._failures_reported = 0
        try:
            self._declare()
            self._setup()
        except Exception:
            self.destroy_node()
            raise
        self.stepper.start()

    # -- set-up --------------------------------------------------------------------------
    def param(self, name: str):
        """The current value of parameter `name`."""
        return self.get_parameter(name).value

    def _declare(self) -> None:
        """Declare `scene` first, then every other parameter with the scene's defaults."""
        overrides = tuple(getattr(self, "_parameter_overrides", {}))
        spec = Param("walking", "scene: a sheet or a body scene (see the node's docs)")
        self.declare_parameter("scene", "walking", descriptor("scene", spec))
        scene = str(self.param("scene"))
        self.body, defaults = scene_defaults(scene, overrides)
        self.table = parameter_table(self.body, defaults)
        for name, spec in self.table.items():
            if name != "scene":
                self.declare_parameter(name, spec.default, descriptor(name, spec))

    def _setup(self) -> None:
        """Validate every parameter, build the scene or wait for poses, create topics."""
        frame_id = str(self.param("frame_id"))
        if not frame_id.strip():
            raise ClothInputError("parameter frame_id must not be empty")
        for key in SCENE_KEYS:
            check_value(key, self.param(key), "parameter")
        self.max_steps = int(self.param("max_steps"))
        self.material = get_material(self.param("material"))
        validate_solver_name(self.param("solver"))
        self.tick_mode = str(self.param("tick_mode"))
        if self.tick_mode not in TICK_MODES:
            raise ClothInputError(f"parameter tick_mode must be one of {', '.join(TICK_MODES)}, "
                                  f"got {self.tick_mode!r}")
        if not self.body and self.tick_mode != "timer":
            raise ClothInputError(f"tick_mode {self.tick_mode!r} needs a body scene; sheet "
                                  f"scene {self.param('scene')!r} runs on the timer")
        # 0: every core. It pays even on 2 cores beside the bench node's pose publisher, now
        # that every kernel runs on the one simulation thread (ros.stepping): 2400-particle
        # dress, ticks 23.1 / 22.3 ms p50 with two threads against 30.2 / 28.7 ms with one
        # (two paired runs). Before, the warm-up's second OpenMP team made two threads 3x
        # slower than one, and the default was every core but one.
        self.sim_threads = resolve_threads(int(self.param("threads")))
        reliability = str(self.param("input_reliability"))
        if reliability not in INPUT_RELIABILITY:
            raise ClothInputError(f"parameter input_reliability must be one of "
                                  f"{', '.join(INPUT_RELIABILITY)}, got {reliability!r}")
        verify_layout()  # the hand-written layouts must match the installed definitions
        verify_marker_array_layout()
        verify_geometry_layouts()
        pubs = {}
        for key, msg_type in (("marker_topic", Marker), ("markers_topic", MarkerArray),
                              ("stats_topic", DiagnosticArray), ("points_topic", PointCloud2),
                              ("mesh_topic", Mesh)):
            pubs[key] = self._topic(key, lambda t, m=msg_type: self.create_publisher(
                m, t, OUTPUT_QOS))
        pubs["diagnostics"] = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                                    OUTPUT_QOS)
        self.outputs = ClothOutputs(
            Publishers(pubs["marker_topic"], pubs["markers_topic"], pubs["stats_topic"],
                       pubs["diagnostics"], pubs["points_topic"], pubs["mesh_topic"]),
            frame_id, bool(self.param("strain_colours")), bool(self.param("points_velocity")),
            self.get_fully_qualified_name(), float(self.param("marker_lifetime")))
        self.diagnostics_timer = self.create_timer(float(self.param("diagnostics_period")),
                                                   self._publish_diagnostics)
        if self.body:
            self._setup_body(reliability)
        else:
            self._setup_sheet()
        self.stepper = Stepper(self)
        self.reset_srv = self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def _topic(self, key: str, create):
        """create(topic name of parameter `key`), a bad name turned into ClothInputError."""
        topic = str(self.param(key))
        try:
            return create(topic)
        except InvalidTopicNameException as exc:
            raise ClothInputError(f"parameter {key}: invalid topic name {topic!r} "
                                  f"({exc})") from exc

    def _levels(self) -> int | None:
        return int(self.param("levels")) or None

    def _setup_sheet(self) -> None:
        t0 = time.perf_counter()
        for key in ("particles", "tolerance"):
            if self.param(key) == AUTO:
                raise ClothInputError(f"parameter {key}: 'auto' is for body scenes (a garment "
                                      f"on a pose stream); give a sheet a number")
        self.scene = build_scene(self.param("scene"), int(self.param("particles")),
                                 self.material, levels=self._levels())
        self.initial_state = self.scene.state.copy()
        self.sim = Simulator(self.scene.model, self.scene.state, self.make_solver(),
                             dt=float(self.param("dt")), scheme="bdf2")
        build_ms = 1e3 * (time.perf_counter() - t0)
        warm = self.sim_thread.call(
            warm_up_sheet, self.param("scene"), self.material, self.param("solver"),
            float(self.param("tolerance")), self.sim.dt, self._levels(), self.sim_threads)
        self._ready()
        self.get_logger().info(
            f"scene {self.scene.name!r}: {self.scene.model.n} particles, "
            f"{len(self.scene.model.mesh.faces)} triangles, {self.material.name}, solver "
            f"{self.param('solver')} (tol {self.param('tolerance'):g}), dt {self.sim.dt:.4g} "
            f"s, {self.param('rate_hz'):g} Hz, built in {build_ms:.0f} ms, warmed up in "
            f"{warm.describe()}; publishing {self._outputs_line()} in "
            f"{self.outputs.frame_id!r}")

    def _setup_body(self, reliability: str) -> None:
        from cloth_mg_ros.mesh.garments import GARMENTS
        from cloth_mg_ros.motion.avatar import Avatar
        from cloth_mg_ros.sim.garment import BodySimOptions

        if self.param("garment") not in GARMENTS:
            raise ClothInputError(f"parameter garment: unknown garment "
                                  f"{self.param('garment')!r}; choose one of "
                                  f"{', '.join(GARMENTS)}")
        self.avatar = Avatar.load()
        params = {key: self.param(key) for key in SCENE_KEYS}
        params["tolerance"] = check_value("tolerance", params["tolerance"],
                                          "parameter tolerance")
        self.particles_auto = params["particles"] == AUTO
        tolerance_auto = params["tolerance"] == AUTO
        if not self.particles_auto and not 16 <= int(params["particles"]) <= 200_000:
            raise ClothInputError(f"parameter particles must be in 16..200000 or 'auto', got "
                                  f"{params['particles']!r}")
        check_max_particles(params["garment"], params["max_particles"],
                            "parameter max_particles")
        self.options = BodySimOptions.from_scene(
            params, levels=self._levels(), threads=self.sim_threads,
            particles=CALIBRATION_PARTICLES if self.particles_auto else params["particles"])
        if self.particles_auto or bool(self.param("lod")) or tolerance_auto:
            self.cost_model, _ = self.sim_thread.call(
                load_or_calibrate, self.options, self.material, self.get_logger().info,
                bag=params["bag"])
            self.options.tolerances = tuple(self.cost_model.tolerances)
        if self.particles_auto and self.tick_mode == "timer":
            self.choose_particles(float(self.param("rate_hz")))
        self.frames = FrameLog(self.get_logger(), self.avatar.num_segments)
        self.ingest = PoseIngest(self.avatar.num_segments, self.options.teleport_m, self.frames,
                                 on_restart=self._on_stream_restart)
        self.redress = False
        self.sim_stamp = 0.0  # timer mode: simulated time, s
        verify_pose_array_layout()
        warm = self.sim_thread.call(self._warm_up)
        self._ready()
        self.pose_sub = self._topic("topic", lambda t: self.create_subscription(
            PoseArray, t, self.ingest.offer, input_qos(reliability), raw=True))
        self.summary_timer = self.create_timer(SUMMARY_PERIOD_S, self._periodic_summary)
        o, out = self.options, self.outputs
        self.get_logger().info(
            f"scene {self.param('scene')!r}: a {o.garment} of about {o.particles} particles, "
            f"{self.material.name}, solver {o.solver} (tol {describe(o.tolerance, o.tolerances)}"
            f", levels "
            f"{o.levels or 'auto'}), substeps >= {o.substeps}, steps <= {o.max_step:g} s, "
            f"floor {o.floor}, self-contact {o.self_contact}, {self.sim_threads} thread(s); "
            f"warmed up in {warm}; "
            f"tick mode {self.tick_mode}; waiting for body poses on "
            f"{self.pose_sub.topic_name} ({reliability}); publishing {self._outputs_line()} "
            f"in the poses' frame ({out.frame_id!r} when they name none)")

    def choose_particles(self, rate_hz: float) -> None:
        """particles auto: the garment's size for a pose stream of rate_hz (logged)."""
        c = choose_particles(self.cost_model, rate_hz, float(self.param("tick_budget")),
                             int(self.param("max_particles")),
                             MIN_PARTICLES[self.options.garment])
        self.auto_choice = c
        self.options.particles = c.particles
        self.get_logger().info(
            f"particles auto: {c.particles} particles ({c.capped_by}) for a {rate_hz:.1f} Hz "
            f"pose stream: budget {c.budget_ms:.1f} ms ({self.param('tick_budget'):g} of the "
            f"period), predicted tick {c.predicted_ms:.1f} ms")

    def budget_ms(self, period_s: float) -> float:
        """The tick budget for a pose period of period_s, ms."""
        return float(self.param("tick_budget")) * period_s * 1e3

    def _warm_up(self) -> str:
        """Run every kernel the ticks will use (warmup.warm_up_garment: the scene's garment,
        solver, tolerance, contacts and levels of detail on a moving body) and build the
        outputs' messages once, on the simulation thread, before the node subscribes.
        Returns what it did, for the log."""
        warm, gs = warm_up_garment(self.avatar, self.material, self.options,
                                   lod=bool(self.param("lod")))
        self.outputs.cloth_messages(gs.sim.model, gs.positions, 0, 0, self.outputs.frame_id,
                                    gs.sim.state.v, gs.capsules())
        return warm.describe()

    def _ready(self) -> None:
        """The warm-up is done: its garbage goes now, not in a tick, and what is left is kept
        out of the collector's full passes (gc.freeze: fewer pauses in the ticks); from here
        on, a kernel that numba compiles is one the warm-up missed (logged by the ticks)."""
        gc.collect()
        gc.freeze()
        self.compiles.start()

    def make_solver(self):
        """A solver for the sheet (make_solver with its hierarchy and bending Hessians) from
        the parameters `solver` and `tolerance` (a garment's: GarmentSim.set_solver)."""
        return make_solver(self.param("solver"), tol=float(self.param("tolerance")),
                           hierarchy=self.scene.hierarchy, bending=self.scene.model.bending,
                           levels=self._levels(), threads=self.sim_threads)

    def _outputs_line(self) -> str:
        p = self.outputs.pubs
        return ", ".join(x.topic_name for x in (p.marker, p.markers, p.points, p.mesh, p.stats,
                                                p.diagnostics))

    # -- the simulation thread's helpers -------------------------------------------------
    def finish(self, status: int) -> None:
        """Complete `finished` with the exit status (once)."""
        if not self.finished.done():
            self.finished.set_result(status)

    def failures_since_status(self) -> int:
        """Simulation steps that failed since the last call (body scenes)."""
        total = self.gs.failures if self.gs is not None else 0
        new, self._failures_reported = total - self._failures_reported, total
        return max(new, 0)

    # -- parameters and services ---------------------------------------------------------
    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Reject an unknown solver or a tolerance out of (0, MAX_TOLERANCE] with the reason
        (ranges and types were already checked against the descriptors)."""
        for p in params:
            reason = check_runtime_change(p.name, p.value)
            if p.name == "tolerance" and p.value == AUTO and not reason and (
                    not self.body or self.options is None or not self.options.tolerances):
                reason = ("tolerance auto is measured at start: start the node with "
                          "tolerance:=auto (body scenes)")
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, params: list[Parameter]) -> None:
        """Apply a new rate_hz (read by the thread each tick), solver or tolerance."""
        names = {p.name for p in params}
        if "rate_hz" in names:
            self.get_logger().info(f"rate_hz is now {self.param('rate_hz'):g}")
        if names & {"solver", "tolerance"} and self.stepper is not None:
            self.stepper.request_solver_change()

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        """~/reset: re-dress on the next valid pose (body scenes) or restart the sheet."""
        self.resets += 1
        if self.body:
            self.ingest.reset()  # a new stream: its stamps may start over
            response.message = "the garment is re-dressed on the next valid body pose"
        else:
            response.message = "the sheet restarts from its initial state"
        self.stepper.request_reset()
        response.success = True
        self.get_logger().info(f"reset: {response.message}")
        return response

    def _publish_diagnostics(self) -> None:
        """The 1 Hz status on /diagnostics (rqt's robot monitor, an aggregator)."""
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        waiting = "waiting for body poses" if self.body and self.gs is None else "starting"
        self.outputs.diagnostics(sec, nanosec, waiting)

    def _on_stream_restart(self, previous: float, stamp: float) -> None:
        """A new time line (a looped bag, a restarted publisher): a new stream."""
        self.get_logger().info(
            f"body pose stamps went back from {previous:.3f} s to {stamp:.3f} s and "
            f"{NEW_STREAM_KEYS} poses went on from there: a new stream (a looped bag, a "
            f"restarted publisher); the garment is re-dressed on it")

    def _periodic_summary(self) -> None:
        if self.frames.changed():
            c = self.ingest.counts()
            self.get_logger().warning(self.frames.summary(c.received, c.used))

    def log_summary(self) -> None:
        """Log the pose-stream summary (body scenes; called at shutdown)."""
        if self.body:
            self.ingest.close()
            c = self.ingest.counts()
            self.get_logger().info(
                f"{self.frames.summary(c.received, c.used)}; {self.steps} ticks, "
                f"{c.coalesced} poses coalesced, {c.pending} pending at shutdown, "
                f"{c.discarded} discarded by resets, {c.dropped} dropped; "
                f"{self.resets} resets, {c.restarts} new streams")

    def shutdown(self) -> None:
        """The shutdown contract (SIGINT, SIGTERM, max_steps): stop the simulation thread
        after its tick in progress, DELETEALL on both marker topics, wait (at most
        SHUTDOWN_ACK_S) until every reliable reader acknowledged it, log the outcome and the
        pose-stream summary."""
        if self.stepper is not None:
            self.stepper.stop()
        if getattr(self, "outputs", None) is not None and self.context.ok():
            sec, nanosec = self.get_clock().now().seconds_nanoseconds()
            if self.outputs.clear(sec, nanosec):
                t0 = time.monotonic()
                topics = (f"{self.outputs.pubs.marker.topic_name} and "
                          f"{self.outputs.pubs.markers.topic_name}")
                if self.outputs.wait_for_acks(SHUTDOWN_ACK_S):
                    self.get_logger().info(
                        f"shutdown: DELETEALL on {topics} acknowledged by every reliable "
                        f"reader in {1e3 * (time.monotonic() - t0):.0f} ms")
                else:
                    self.get_logger().warning(
                        f"shutdown: DELETEALL on {topics} not acknowledged by every reliable "
                        f"reader within {SHUTDOWN_ACK_S:g} s: a display may keep the last "
                        f"cloth (parameter marker_lifetime makes markers expire by themselves)")
        self.log_summary()

    def destroy_node(self) -> None:
        """Stop the simulation thread (after its tick in progress), then the node."""
        if self.stepper is not None:
            self.stepper.stop()
        self.sim_thread.shutdown()
        self.compiles.stop()
        super().destroy_node()


FASTDDS_PROFILE_VARS = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")


def use_fastdds_profile() -> str | None:
    """Point Fast DDS at config/fastdds.xml (its writers' heartbeat every 100 ms, so that the
    shutdown's DELETEALL is acknowledged within SHUTDOWN_ACK_S) unless the user names a
    profiles file of their own. Call before rclpy.init; returns the file used, or None."""
    if any(os.environ.get(var) for var in FASTDDS_PROFILE_VARS):
        return None
    path = str(config_path("fastdds.xml"))
    for var in FASTDDS_PROFILE_VARS:  # the Jazzy wheels' Fast DDS reads the second (measured)
        os.environ[var] = path
    return path


def _interrupt(signum: int, frame) -> None:
    """SIGTERM handler: stop like Ctrl-C."""
    raise KeyboardInterrupt


def spin_until_done(node: Node, future: Future, period_s: float = 0.1) -> None:
    """Spin `node` until `future` is done, waking every `period_s` s so that Ctrl-C (a
    KeyboardInterrupt, with rclpy's own signal handlers off) is seen promptly."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while not future.done() and node.context.ok():
            executor.spin_once(timeout_sec=period_s)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.0)


def main(args: list[str] | None = None) -> int:
    """Entry point of `cloth_node`: returns the exit status (0 normal or Ctrl-C, 1 failure).

    rclpy's signal handlers are off: Ctrl-C and SIGTERM raise KeyboardInterrupt here, so the
    context is still valid while the node logs its final summary and is destroyed.
    """
    argv = sys.argv if args is None else list(args)
    own = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if {"-h", "--help"} & set(own):
        print(usage_text())
        return 0
    use_fastdds_profile()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    keep_freed_memory()  # a step's large temporaries are not paged in afresh every step
    previous = signal.signal(signal.SIGTERM, _interrupt)
    # A process started in the background of a non-interactive shell inherits SIGINT ignored.
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    node = None
    status = 0
    try:
        node = ClothNode()
        spin_until_done(node, node.finished)
        if node.finished.done():
            status = int(node.finished.result())
    except (ClothInputError, ParameterException) as exc:
        rclpy.logging.get_logger(NODE_NAME).error(f"cannot start: {exc}")
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl-C or an external shutdown is a normal way to stop
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        if node is not None:
            node.shutdown()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
