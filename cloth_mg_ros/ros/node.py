"""cloth_node: a garment draped over a moving avatar (or a sheet scene), published for RViz.

Run it (in a ROS 2 workspace, or in the project's virtualenv):

    cloth_node --ros-args --params-file config/walking.yaml      # a body scene
    cloth_node --ros-args -p scene:=running -p particles:=1200   # the scene file's defaults
    cloth_node --ros-args -p scene:=hang -p particles:=5000 -p rate_hz:=30.0   # a sheet
    python -m cloth_mg_ros.ros.node                              # the walking scene
    ros2 launch cloth_mg_ros cloth.launch.py bag:=walk rviz:=true   # node, player, RViz2
    cloth_node --ros-args -p managed:=true                       # a lifecycle node

and, in another shell, play body poses into it: `cloth-mg replay bags/walk`.

Two kinds of scene (parameter `scene`, default 'walking'):

- Body scenes (walking, brisk_walking, running, jumping, their aliases walk, ..., any
  config/<scene>.yaml, or a path to a params .yaml): the parameters not given on the command
  line take their defaults from the scene's file (config.scenes.load_scene). The node subscribes
  to `topic` (geometry_msgs/PoseArray, one pose per avatar segment in Avatar.names order,
  [x, y, z] m and a unit quaternion; raw CDR bytes straight into numpy). Its QoS is
  `input_reliability` (default best_effort, which matches reliable and best-effort publishers
  alike; keep-last 100) or reliable (keep-all: DDS then delivers every pose a reliable
  publisher sends, however long the executor waits, where keep-last would drop the oldest
  without a word); the callback only decodes and checks a message and keeps it as a key
  pose (ros.ingest), so nothing waits in the middleware's queue. A simulation thread of its
  own (ros.session) dresses the garment on the first valid pose (GarmentSim.dress) and, in
  tick mode 'message' (the default), advances the cloth each tick to the newest pose received,
  the body following every pose received since the last tick: a tick that runs long
  coalesces the backlog instead of queueing it. In tick mode 'timer' it steps 1/rate_hz s of
  simulated time every 1/rate_hz s of wall time through the poses that arrived.
- Sheet scenes (drape, hang): always timer mode, one step of `dt` per tick.

Timer mode ticks every 1/rate_hz s of wall time, or of the node's ROS clock (/clock) under
use_sim_time (read at start; ros.timer_clock): a paused /clock pauses the cloth.

Per tick (a dressing, a re-anchoring or a step through key poses; a sheet's step) the node
publishes, stamped with the newest pose's header stamp in message mode and the node's clock
otherwise, in the poses' header.frame_id (`frame_id` when they name none, and for sheets). Topic
names are relative: a namespace (`-r __ns:=/alice`) moves them all (ros.publishing):

- `marker_topic` (visualization_msgs/Marker, default cloth/marker): the cloth as one
  TRIANGLE_LIST (ns 'cloth', id 0), m, z up, serialised straight from numpy
  (`cloth_mg_ros.io.messages.markers`: no `Point` objects, so a large cloth costs little;
  doc/design-measurements.md, 'Publishing', has the figures). With strain_colours,
  per-vertex colours show the stretch (the cloth colour at rest length, red at 10 % and more);
- `markers_topic` (visualization_msgs/MarkerArray, default cloth/markers): per avatar capsule
  a CYLINDER (ns 'avatar', id = segment index) and a SPHERE_LIST of its two end caps (ns
  'avatar_caps'); sheet scenes' sphere collider (ns 'collider'); a TEXT_VIEW_FACING caption of
  the latest status (ns 'caption'). The cloth is not repeated here, so it is drawn once;
- `points_topic` (sensor_msgs/PointCloud2, default cloth/points): the particles, float32 x, y,
  z (m; with points_velocity also vx, vy, vz, m/s); `mesh_topic` (shape_msgs/Mesh, default
  cloth/mesh): triangles over vertices, vertex i particle i (ros.geometry_out);
- `stats_topic` (diagnostic_msgs/DiagnosticArray, default cloth/stats): one status
  'cloth_node: solver' with step_ms, solve_ms, iterations, rel_residual, max_penetration_m,
  contacts, self_contact_dropped (cloth-cloth pairs the self-contact search left out past its
  cap, summed over the tick's steps), substeps, particles, marker_ms, and the pose stream's
  counters: poses_received, poses_used (simulated to or coalesced into a tick),
  poses_coalesced, poses_pending,
  poses_discarded (by a reset), dropped (valid poses never used: 0), lag_ms (newest pose
  received minus simulated time), tick_poses (key poses of this tick), ticks_failed (ticks
  that raised: logged, with the traceback once per kind, skipped, their poses counted as
  skipped_tick_failed and a body scene re-dressed on the next valid pose; the node stops
  after ros.session.MAX_FAILED_TICKS in a row). Level OK; WARN when the
  solve stopped short of `tolerance`, when the tick dropped self-contact pairs, when pose
  frames were skipped since the previous status, or after a re-anchoring; ERROR when a
  simulation step failed (its result was dropped, the cloth held) or positions became
  non-finite (then no marker is published).

Grippers (a robot in the loop; ros.gripper_desk, ros.wrenches): each name of the `grippers`
parameter (and the hang scene's own `left` and `right`, holding its top corners) has
`gripper/<name>/pose` (geometry_msgs/PoseStamped in: the grasp point, m, and orientation in
the poses' frame; with a header.stamp, used at its stamp: each step follows the pose
interpolated at its time, a tick spanning the body poses' stamps in message mode and the
node's clock in timer mode; a zero stamp: the newest wins; NaN or a zero quaternion is
skipped, counted, logged once per kind), `gripper/<name>/grasp` (std_srvs/SetBool: true
holds every free particle within `grasp_radius` of the grasp point, false lets go; the
response says how many, or why not) and `gripper/<name>/wrench` (geometry_msgs/WrenchStamped
out every tick: the cloth's force on the gripper, N, and torque, N m, about the origin of the
frame it names: `wrench_frame` world, the poses' frame, or local, the gripper's own,
`gripper_frame`, at its grasp point; zero when it holds nothing; ros.wrenches). Poses and
calls are applied on the simulation thread before the next tick (a call waits for it, on the
services' own node `cloth_node_grasp` and thread: ros.grasp_services; poses keep arriving).
`release_force` (N, run time) makes a gripper pulled harder let go by itself (logged,
counted). Body scenes also publish `cloth/contact/<segment>` (WrenchStamped, every tick, per
segment the garment collides with: the cloth's force on it, mean over the tick's steps, and
the torque about the named frame's origin: the poses' frame's, or with wrench_frame local the
segment's own, `segment_frame`), drawn as arrows (ns 'contact_forces') on the marker
array; the stats carry mass_kg, contact_peak_n and contact_peak_segment.

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
  before the next tick. `rate_hz` (timer modes) and `release_force` may be changed too. Every other
  parameter is read-only (needs a restart).

With max_steps > 0 the node exits (status 0) after that many simulation ticks. Ctrl-C exits
with status 0. At every such exit (SIGINT, SIGTERM, max_steps) the node ends its tick in
progress, publishes DELETEALL on both marker topics and waits up to SHUTDOWN_ACK_S for every
reliable reader to acknowledge it (logged), so that no display keeps a ghost cloth;
`marker_lifetime` > 0 makes markers expire by themselves should the node be killed.

Before it subscribes, the node warms up on its own tick path (cloth_mg_ros.apps.warmup): a first
tick never waits for numba to compile; `kernels_compiled` in the stats counts any that did.

Start-up failures (an unknown scene, garment, material or solver, a parameter out of its
declared range or of the wrong type, a bad topic name) are logged as one error line naming
the value and the node exits with status 1 before it subscribes to any input or offers a
service (a failure the scene's preparation finds comes after the output topics were
created: the warm-up builds their messages; nothing is published on them).

A managed (lifecycle) node: `-p managed:=true` or `cloth_node_managed` starts it unconfigured;
configure, activate, deactivate, cleanup and shutdown (`<node>/change_state`) do what this
start-up does, in steps (ros.managed_node; doc/node.md, 'A managed node').

rclpy notes: parameter on-set callbacks also run for declarations, so they are added after
declaring.
"""

from __future__ import annotations

import os
import signal
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import (
    InvalidTopicNameException,
    ParameterException,
    ParameterUninitializedException,
)
from rclpy.executors import ExternalShutdownException
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
from cloth_mg_ros.config.scenes import AUTO
from cloth_mg_ros.config.schema import PARAMETERS
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.share import config_path
from cloth_mg_ros.ros.body_topic import body_subscription
from cloth_mg_ros.ros.executor import single_threaded_executor
from cloth_mg_ros.ros.geometry_out import verify_geometry_layouts
from cloth_mg_ros.ros.grasp_services import GraspServices
from cloth_mg_ros.ros.ingest import (
    SUMMARY_PERIOD_S,
    verify_pose_array_layout,
)
from cloth_mg_ros.ros.managed_node import ManagedTransitions, wants_managed
from cloth_mg_ros.ros.marker_array import verify_marker_array_layout
from cloth_mg_ros.ros.message_reference import verify_layout
from cloth_mg_ros.ros.parameters import (
    Param,
    check_parameters,
    check_runtime_change,
    descriptor,
    parameter_table,
    scene_defaults,
    usage_text,
)
from cloth_mg_ros.ros.publishing import ClothOutputs, Publishers
from cloth_mg_ros.ros.session import LiveSession
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.ros.timer_clock import RosClock
from cloth_mg_ros.ros.wrenches import WrenchOutputs

__all__ = ["ClothNode", "ManagedClothNode", "main", "main_managed"]

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
    """The pose subscription's QoS: best_effort (matches every publisher; keep-last
    INPUT_DEPTH) or reliable (keep-all)."""
    if reliability == "best_effort":
        return QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                          history=HistoryPolicy.KEEP_LAST, depth=INPUT_DEPTH)
    # Keep-all: a reliable reader's keep-last history drops its oldest sample when the
    # executor has not taken it in time (7 of 300 poses at 450 Hz on a loaded CI machine).
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL)


class ClothNode(Node):
    """Declares the parameters, creates the topics, services and timers, and hands what
    arrives to its LiveSession (ros.session), which simulates (module docstring).

    Raises ClothInputError (or rclpy's ParameterException) from the constructor when a
    parameter is unusable; the node is destroyed before the exception leaves.
    """

    #: The thread the session runs on (None: one of the session's own; ros.sim_thread).
    _sim_thread = None

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        #: Completed with the exit status when the node should stop (max_steps or a failure).
        self.finished = Future()
        self.session: LiveSession | None = None
        self._sim_time = False  # use_sim_time as the session was configured with
        self.outputs: ClothOutputs | None = None
        self.grasp_services: GraspServices | None = None
        self._shut_down = False
        try:
            self._declare()
            self._start_up()
        except Exception:
            self.destroy_node()
            raise

    def _start_up(self) -> None:
        """Set up (parameters checked, scene prepared, topics, services) and start ticking; a
        managed node (ros.managed_node) waits for its transitions instead."""
        self._setup()
        self.session.start()

    def param(self, name: str):
        """The current value of parameter `name` (a string array declared empty and not
        given: its default, ())."""
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return self.declared[name].default

    def _declare(self) -> None:
        """Declare `scene` first, then every other parameter with the scene's defaults."""
        overrides = tuple(getattr(self, "_parameter_overrides", {}))
        scene = PARAMETERS["scene"]
        spec = Param(scene.default, scene.description())
        self.declare_parameter("scene", scene.default, descriptor("scene", spec))
        self.body, defaults = scene_defaults(str(self.param("scene")), overrides)
        self.declared = parameter_table(self.body, defaults)
        for name, spec in self.declared.items():
            if name == "scene":
                continue
            # rclpy types an empty default as a byte array, and would then refuse
            # grippers:=[left]: an empty string array is declared by its type (unset).
            empty = spec.default == ()
            self.declare_parameter(name, Parameter.Type.STRING_ARRAY if empty
                                   else spec.default, descriptor(name, spec))

    def _setup(self) -> None:
        """Configure (`_configure`), subscribe (`_subscribe`), log the start-up line and
        watch the run-time parameters."""
        if self.param("managed"):
            raise ClothInputError("parameter managed: true was not seen before the node "
                                  "started (start cloth_node_managed, or give -p "
                                  "managed:=true on the command line)")
        self.get_logger().info(self._configure() + self._subscribe())
        self._watch_parameters()

    def _watch_parameters(self) -> None:
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def _configure(self) -> str:
        """Check every parameter, create the outputs and the session, prepare it (scene,
        calibration, warm-up), the grippers' interfaces and the reset service. Returns the
        scene's description (raises ClothInputError for an unusable value)."""
        values = check_parameters({name: self.param(name) for name in self.declared})
        self.values = values
        settings = SessionSettings.from_values(values, self.body)
        verify_layout()  # the hand-written layouts must match the installed definitions
        verify_marker_array_layout()
        verify_geometry_layouts()
        verify_pose_array_layout()
        self.outputs = self._create_outputs(values.frame_id)
        sim_time = bool(self.get_parameter("use_sim_time").value)  # (read at start)
        self._sim_time = sim_time
        self.session = LiveSession(settings, self.outputs, self.get_logger(),
                                   lambda: self.get_clock().now().seconds_nanoseconds(),
                                   self.finish,
                                   timer_clock=RosClock(self.get_clock()) if sim_time else None,
                                   sim_thread=self._sim_thread)
        described = self.session.prepare()
        self._gripper_interfaces(values.input_reliability)
        self.reset_srv = self.create_service(Trigger, "~/reset", self._on_reset)
        return described

    def _subscribe(self) -> str:
        """Subscribe to the body poses and start the timers (/diagnostics, the inputs'
        summary). Returns the start-up line's '; waiting for ...; publishing ...' part."""
        frame_id, reliability = self.values.frame_id, self.values.input_reliability
        self.diagnostics_timer = self.create_timer(float(self.param("diagnostics_period")),
                                                   self._publish_diagnostics)
        if self.body or self.gripper_subs:  # (sheets summarise their grippers' poses)
            self.summary_timer = self.create_timer(SUMMARY_PERIOD_S,
                                                   self.session.periodic_summary)
        if not self.body:
            return f"; publishing {self._outputs_line()} in {frame_id!r}"
        self.pose_sub = self._topic("topic", lambda t: body_subscription(
            self, t, self.values.body_input, self.values.body_id, self.session.scene.ingest,
            input_qos(reliability)))
        return (f"; waiting for body poses on {self.pose_sub.topic_name} ({reliability}); "
                f"publishing {self._outputs_line()} in the poses' frame ({frame_id!r} when "
                f"they name none)")

    def _create_outputs(self, frame_id: str) -> ClothOutputs:
        """The publishers of every output topic, wrapped in ClothOutputs."""
        pubs = {}
        for key, msg_type in (("marker_topic", Marker), ("markers_topic", MarkerArray),
                              ("stats_topic", DiagnosticArray), ("points_topic", PointCloud2),
                              ("mesh_topic", Mesh)):
            pubs[key] = self._topic(key, lambda t, m=msg_type: self.create_publisher(
                m, t, OUTPUT_QOS))
        pubs["diagnostics"] = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                                    OUTPUT_QOS)
        return ClothOutputs(
            Publishers(pubs["marker_topic"], pubs["markers_topic"], pubs["stats_topic"],
                       pubs["diagnostics"], pubs["points_topic"], pubs["mesh_topic"]),
            frame_id, bool(self.param("strain_colours")), bool(self.param("points_velocity")),
            self.get_fully_qualified_name(), float(self.param("marker_lifetime")))

    def _gripper_interfaces(self, reliability: str) -> None:
        """Per gripper: gripper/<name>/pose (in), grasp (service), wrench (out); per body
        segment the garment collides with: cloth/contact/<segment> (out)."""
        self.gripper_subs, wrenches = [], {}
        names = self.session.desk.names
        for name in names:
            try:
                self.gripper_subs.append(self.create_subscription(
                    PoseStamped, f"gripper/{name}/pose",
                    lambda msg, n=name: self._on_gripper_pose(n, msg), input_qos(reliability)))
                wrenches[name] = self.create_publisher(
                    WrenchStamped, f"gripper/{name}/wrench", OUTPUT_QOS)
            except InvalidTopicNameException as exc:
                raise ClothInputError(f"parameter grippers: {name!r} makes no valid topic "
                                      f"name ({exc})") from exc
        if names:  # served off this node's executor: a call waits without holding poses
            self.grasp_services = GraspServices(self, names, self.session.grasp)
        contacts = {}
        if self.body:
            scene = self.session.scene
            names = scene.avatar.names
            for k in scene.options.colliding_segments(tuple(names)):
                contacts[names[k]] = self.create_publisher(
                    WrenchStamped, f"cloth/contact/{names[k]}", OUTPUT_QOS)
        if wrenches or contacts:
            self.outputs.wrenches = WrenchOutputs(
                wrenches, contacts, str(self.param("wrench_frame")),
                str(self.param("gripper_frame")), str(self.param("segment_frame")))

    def _on_gripper_pose(self, name: str, msg: PoseStamped) -> None:
        p, q, t = msg.pose.position, msg.pose.orientation, msg.header.stamp
        self.session.desk.offer_pose(name, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w),
                                     msg.header.frame_id, t.sec + 1e-9 * t.nanosec)

    def _topic(self, key: str, create):
        """create(topic name of parameter `key`), a bad name turned into ClothInputError."""
        topic = str(self.param(key))
        try:
            return create(topic)
        except InvalidTopicNameException as exc:
            raise ClothInputError(f"parameter {key}: invalid topic name {topic!r} "
                                  f"({exc})") from exc

    def _outputs_line(self) -> str:
        p = self.outputs.pubs
        return ", ".join(x.topic_name for x in (p.marker, p.markers, p.points, p.mesh, p.stats,
                                                p.diagnostics))

    def finish(self, status: int) -> None:
        """Complete `finished` with the exit status (once)."""
        if not self.finished.done():
            self.finished.set_result(status)

    # -- parameters and services ---------------------------------------------------------
    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Reject an unknown solver or a tolerance out of (0, MAX_TOLERANCE] with the reason
        (ranges and types were already checked against the descriptors)."""
        for p in params:
            reason = check_runtime_change(p.name, p.value)
            if p.name == "tolerance" and p.value == AUTO and not reason and (
                    self.session is None or not self.session.tolerance_auto_available()):
                reason = ("tolerance auto is measured at start: start the node with "
                          "tolerance:=auto (body scenes)")
            if p.name == "use_sim_time" and self.session is not None and \
                    bool(p.value) != self._sim_time:
                # the ticks' clock is chosen at start: stamps would follow /clock, ticks not
                reason = ("use_sim_time is read at start: start the node (or configure the "
                          "managed one) with the value wanted")
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, params: list[Parameter]) -> None:
        """Hand a new rate_hz, release_force, solver or tolerance to the session."""
        names = {p.name for p in params}
        if "rate_hz" in names and self.session is not None:
            self.session.set_rate_hz(float(self.param("rate_hz")))
            self.get_logger().info(f"rate_hz is now {self.param('rate_hz'):g}")
        if "release_force" in names and self.session is not None:
            self.session.request_release_force(float(self.param("release_force")))
            self.get_logger().info(f"release_force is now {self.param('release_force'):g} N")
        if names & {"solver", "tolerance"} and self.session is not None:
            self.session.request_solver_change(str(self.param("solver")),
                                               self.param("tolerance"))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        """~/reset: re-dress on the next valid pose (body scenes) or restart the sheet."""
        response.message = self.session.reset()
        response.success = True
        self.get_logger().info(f"reset: {response.message}")
        return response

    def _publish_diagnostics(self) -> None:
        """The periodic status on /diagnostics (rqt's robot monitor, an aggregator)."""
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        self.outputs.diagnostics(sec, nanosec, self.session.waiting_text())

    def shutdown(self) -> None:
        """The shutdown contract (SIGINT, SIGTERM, max_steps): stop the session after its tick
        in progress, DELETEALL on both marker topics, wait (at most SHUTDOWN_ACK_S) until
        every reliable reader acknowledged it, log the outcome and the pose-stream summary
        (once: a managed node's shutdown transition and its exit both call it)."""
        if self._shut_down:
            return
        self._shut_down = True
        if self.session is not None:
            self.session.stop()
        self.clear_display("shutdown")
        if self.session is not None:
            self.session.log_summary()

    def clear_display(self, when: str) -> None:
        """DELETEALL on both marker topics (when anything was drawn since the last one) and
        wait up to SHUTDOWN_ACK_S for every reliable reader's acknowledgement; `when` names
        the occasion in the log ('shutdown', 'deactivate')."""
        if self.outputs is not None and self.context.ok():
            sec, nanosec = self.get_clock().now().seconds_nanoseconds()
            if self.outputs.clear(sec, nanosec):
                self._await_clear_acks(when)

    def _await_clear_acks(self, when: str) -> None:
        t0 = time.monotonic()
        topics = (f"{self.outputs.pubs.marker.topic_name} and "
                  f"{self.outputs.pubs.markers.topic_name}")
        if self.outputs.wait_for_acks(SHUTDOWN_ACK_S):
            self.get_logger().info(
                f"{when}: DELETEALL on {topics} acknowledged by every reliable "
                f"reader in {1e3 * (time.monotonic() - t0):.0f} ms")
        else:
            self.get_logger().warning(
                f"{when}: DELETEALL on {topics} not acknowledged by every reliable "
                f"reader within {SHUTDOWN_ACK_S:g} s: a display may keep the last "
                f"cloth (parameter marker_lifetime makes markers expire by themselves)")

    def destroy_node(self) -> None:
        """Stop the session (after its tick in progress) and its thread, the grasp services,
        then the node."""
        if self.session is not None:
            self.session.close()
        if self.grasp_services is not None:
            self.grasp_services.close()
        super().destroy_node()


class ManagedClothNode(ManagedTransitions, ClothNode):
    """cloth_node as a managed (lifecycle) node: unconfigured at construction; its
    transitions (ros.managed_node) configure, activate, deactivate, clean up and shut down
    the same node."""


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
    executor = single_threaded_executor(node.context)
    executor.add_node(node)
    try:
        while not future.done() and node.context.ok():
            executor.spin_once(timeout_sec=period_s)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.0)


def main_managed(args: list[str] | None = None) -> int:
    """Entry point of `cloth_node_managed`: `cloth_node` as a managed node."""
    return main(args, managed=True)


def main(args: list[str] | None = None, managed: bool = False) -> int:
    """Entry point of `cloth_node`: returns the exit status (0 normal, Ctrl-C or a managed
    node's shutdown transition; 1 failure). managed (or -p managed:=true on the command
    line): a ManagedClothNode.

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
        node = (ManagedClothNode if managed or wants_managed(argv) else ClothNode)()
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
