"""cloth_node: steps a built-in cloth scene and publishes it as an RViz marker with solver stats.

Run it (in a ROS 2 workspace, or in the project's virtualenv):

    cloth_node --ros-args -p scene:=hang -p particles:=5000 -p rate_hz:=30.0
    python -m cloth_mg_ros.ros.node --ros-args -p material:=denim -p max_steps:=300

Each timer tick (rate_hz) advances the simulation by one step of dt seconds, then publishes

- `marker_topic` (visualization_msgs/Marker): the cloth as one TRIANGLE_LIST in `frame_id`
  (ns 'cloth', id 0), metres, z up; serialised straight from numpy by
  `cloth_mg_ros.ros.markers` and published as bytes (20K particles, 2.8 MB: serialising
  0.5-1 ms, serialising and publishing to a subscriber in another process 2-7 ms; the
  diagnostics report it as marker_ms);
- `stats_topic` (diagnostic_msgs/DiagnosticArray): one DiagnosticStatus 'cloth_node: solver',
  level OK, WARN when the linear solve stopped short of `tolerance`, ERROR when positions
  became non-finite (then no marker is published and the node exits with status 1).

Both publishers are reliable, keep-last 100. The simulation runs on the node's clock tick, not
in real time: when a step takes longer than 1/rate_hz, ticks simply come late. With
max_steps > 0 the node exits (status 0) after that many steps. Ctrl-C exits with status 0.

Start-up failures (an unknown scene, material or solver, a parameter out of its declared range
or of the wrong type, a bad topic name) are logged as one error line naming the value and the
node exits with status 1 before any topic appears.

rclpy notes: a publisher created with the Marker type accepts either a Marker or `bytes`
(exactly `bytes`: a bytearray raises TypeError); subscribers cannot tell the difference.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidTopicNameException, ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from visualization_msgs.msg import Marker

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.integrator import Simulator
from cloth_mg_ros.physics.materials import MATERIALS, get_material
from cloth_mg_ros.ros.markers import marker_triangle_list_bytes, verify_layout
from cloth_mg_ros.scenes import SCENES, build_scene
from cloth_mg_ros.solvers import SOLVERS, make_solver, validate_solver_name

__all__ = ["ClothNode", "main"]

NODE_NAME = "cloth_node"
STATUS_NAME = "cloth_node: solver"
QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                 depth=100)
CLOTH_RGBA = (0.85, 0.35, 0.25, 1.0)


@dataclass(frozen=True)
class _Param:
    """One declared parameter: default, description, whether it needs a restart, range."""

    default: object
    description: str
    read_only: bool = True
    int_range: tuple[int, int] | None = None
    float_range: tuple[float, float] | None = None
    constraints: str = ""


PARAMETERS: dict[str, _Param] = {
    "scene": _Param("drape", "built-in scene", constraints=f"one of {', '.join(SCENES)}"),
    "particles": _Param(2400, "approximate number of cloth particles", int_range=(16, 200_000)),
    "material": _Param("cotton", "cloth material (paper Table 2 stiffness ratios)",
                       constraints=f"one of {', '.join(MATERIALS)}"),
    "solver": _Param("pcg", "linear solver for each implicit step",
                     constraints=f"one of {', '.join(SOLVERS)}"),
    "tolerance": _Param(1e-4, "relative residual the linear solve must reach",
                        float_range=(1e-10, 0.5)),
    "dt": _Param(1.0 / 60.0, "simulation time step, s", float_range=(1e-5, 0.1)),
    "rate_hz": _Param(30.0, "timer rate: simulation steps and messages per second of wall "
                      "time, Hz (may be changed while running)", read_only=False,
                      float_range=(0.1, 1000.0)),
    "frame_id": _Param("world", "frame of the published marker (z up, metres)",
                       constraints="non-empty"),
    "marker_topic": _Param("/cloth/marker", "visualization_msgs/Marker output topic"),
    "stats_topic": _Param("/cloth/stats", "diagnostic_msgs/DiagnosticArray output topic"),
    "max_steps": _Param(0, "exit after this many steps (0: run until shut down)",
                        int_range=(0, 2**31 - 1)),
}


def _descriptor(name: str, spec: _Param) -> ParameterDescriptor:
    """The ParameterDescriptor of one entry of PARAMETERS."""
    kinds = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
             float: ParameterType.PARAMETER_DOUBLE}
    desc = ParameterDescriptor(name=name, type=kinds[type(spec.default)],
                               description=spec.description, read_only=spec.read_only,
                               additional_constraints=spec.constraints)
    if spec.int_range is not None:
        desc.integer_range = [IntegerRange(from_value=spec.int_range[0],
                                           to_value=spec.int_range[1], step=1)]
    if spec.float_range is not None:
        desc.floating_point_range = [FloatingPointRange(from_value=spec.float_range[0],
                                                        to_value=spec.float_range[1], step=0.0)]
    return desc


class ClothNode(Node):
    """Declares the parameters, builds the scene and steps it on a timer (see module docstring).

    Raises ClothInputError (or rclpy's ParameterException) from the constructor when a
    parameter is unusable; the node is destroyed before the exception leaves.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        #: Completed with the exit status when the node should stop (max_steps or a failure).
        self.finished = Future()
        self.steps = 0
        try:
            for name, spec in PARAMETERS.items():
                self.declare_parameter(name, spec.default, _descriptor(name, spec))
            self._setup()
        except Exception:
            self.destroy_node()
            raise

    def _param(self, name: str):
        return self.get_parameter(name).value

    def _setup(self) -> None:
        """Validate every parameter, build the scene and simulator, create topics and timer."""
        self.frame_id = str(self._param("frame_id"))
        if not self.frame_id.strip():
            raise ClothInputError("parameter frame_id must not be empty")
        self.max_steps = int(self._param("max_steps"))
        material = get_material(self._param("material"))
        solver_name = validate_solver_name(self._param("solver"))
        verify_layout()  # the hand-written Marker layout must match the installed definition
        t0 = time.perf_counter()
        self.scene = build_scene(self._param("scene"), int(self._param("particles")), material)
        solver = make_solver(solver_name, tol=float(self._param("tolerance")),
                             hierarchy=self.scene.hierarchy,
                             wing_hess=self.scene.model.wing_hess)
        self.sim = Simulator(self.scene.model, self.scene.state, solver,
                             dt=float(self._param("dt")), scheme="bdf2")
        self.faces = np.ascontiguousarray(self.scene.model.mesh.faces)
        build_ms = 1e3 * (time.perf_counter() - t0)
        pubs = {}
        for key, msg_type in (("marker_topic", Marker), ("stats_topic", DiagnosticArray)):
            topic = str(self._param(key))
            try:
                pubs[key] = self.create_publisher(msg_type, topic, QOS)
            except InvalidTopicNameException as exc:
                raise ClothInputError(f"parameter {key}: invalid topic name {topic!r} "
                                      f"({exc})") from exc
        self.marker_pub, self.stats_pub = pubs["marker_topic"], pubs["stats_topic"]
        self.timer = self.create_timer(1.0 / float(self._param("rate_hz")), self._tick)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.get_logger().info(
            f"scene {self.scene.name!r}: {self.scene.model.n} particles, "
            f"{len(self.faces)} triangles, {material.name}, solver {self._param('solver')} "
            f"(tol {self._param('tolerance'):g}), dt {self.sim.dt:.4g} s, "
            f"{self._param('rate_hz'):g} Hz, built in {build_ms:.0f} ms; publishing "
            f"{self.marker_pub.topic_name} and {self.stats_pub.topic_name} in "
            f"{self.frame_id!r}")

    def _on_parameters_set(self, params: list[Parameter]) -> SetParametersResult:
        """Apply a new rate_hz (the range was already checked against the descriptor)."""
        for p in params:
            if p.name == "rate_hz":
                self.timer.timer_period_ns = round(1e9 / float(p.value))
                self.timer.reset()
                self.get_logger().info(f"rate_hz is now {p.value:g}")
        return SetParametersResult(successful=True)

    def _tick(self) -> None:
        """One simulation step, then the marker and the diagnostics."""
        if self.finished.done():
            return
        stats = self.sim.step()
        self.steps += 1
        x = self.sim.state.x
        finite = bool(np.isfinite(x).all())
        sec, nanosec = self.get_clock().now().seconds_nanoseconds()
        t0 = time.perf_counter()
        if finite:  # RViz rejects a marker holding NaN; the diagnostics say why it is missing
            self.marker_pub.publish(marker_triangle_list_bytes(
                x, self.faces, sec, nanosec, self.frame_id, "cloth", 0, CLOTH_RGBA))
        marker_ms = 1e3 * (time.perf_counter() - t0)
        self.stats_pub.publish(self._diagnostics(stats, finite, sec, nanosec, marker_ms))
        if not finite:
            self.get_logger().error(
                f"cloth positions became non-finite at step {self.steps}; try a smaller dt "
                f"or tolerance")
            self._finish(1)
        elif self.max_steps and self.steps >= self.max_steps:
            self.get_logger().info(f"max_steps {self.max_steps} reached")
            self._finish(0)

    def _finish(self, status: int) -> None:
        self.timer.cancel()
        if not self.finished.done():
            self.finished.set_result(status)

    def _diagnostics(self, stats, finite: bool, sec: int, nanosec: int,
                     marker_ms: float) -> DiagnosticArray:
        """DiagnosticArray with one status: level, message and the step's figures."""
        if not finite:
            level, message = DiagnosticStatus.ERROR, "cloth positions became non-finite"
        elif not stats.converged:
            level = DiagnosticStatus.WARN
            message = (f"solve stopped at relative residual {stats.rel_residual:.3g} after "
                       f"{stats.iterations} iterations")
        else:
            level, message = DiagnosticStatus.OK, "ok"
        values = {
            "step": str(self.steps),
            "solve_ms": f"{stats.solve_ms:.3f}",
            "step_ms": f"{stats.total_ms:.3f}",
            "iterations": str(stats.iterations),
            "rel_residual": f"{stats.rel_residual:.3e}",
            "max_penetration_m": f"{stats.max_penetration:.3e}",
            "contacts": str(stats.contacts),
            "particles": str(self.scene.model.n),
            "marker_ms": f"{marker_ms:.3f}",
        }
        status = DiagnosticStatus(level=level, name=STATUS_NAME, message=message,
                                  hardware_id=NODE_NAME,
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        out = DiagnosticArray(status=[status])
        out.header.stamp.sec, out.header.stamp.nanosec = sec, nanosec
        out.header.frame_id = self.frame_id
        return out


def main(args: list[str] | None = None) -> int:
    """Entry point of `cloth_node`: returns the exit status (0 normal or Ctrl-C, 1 failure)."""
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = ClothNode()
        rclpy.spin_until_future_complete(node, node.finished)
        if node.finished.done():
            status = int(node.finished.result())
    except (ClothInputError, ParameterException) as exc:
        rclpy.logging.get_logger(NODE_NAME).error(f"cannot start: {exc}")
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl-C or an external shutdown is a normal way to stop
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
