"""cloth_node as a ROS 2 managed (lifecycle) node: `cloth_node --ros-args -p managed:=true`,
or `cloth_node_managed`, or the launch file's `managed:=true`.

The node starts unconfigured: its parameters are declared (and run-time changes checked),
its lifecycle services (`<node>/change_state`, `<node>/get_state`, ...) answer, nothing else
exists. The transitions do what the plain node does at start, in steps (ros.node's
ClothNode._configure and _subscribe, shared, not copied):

- configure: check every parameter, create the output topics, the grippers' interfaces and
  `~/reset`, load the scene, calibrate and warm up (the session's `prepare`). An unusable
  value (a ClothInputError, a parameter of the wrong type) is logged as one error line and
  the transition FAILS (back to unconfigured, nothing left built); anything else is logged
  with its traceback and returns ERROR.
- activate: subscribe to the body poses, start the timers (/diagnostics, the inputs'
  summary) and the tick loop. Activated again after a deactivate, a body scene re-dresses
  the garment on the next valid pose (ros.session.LiveSession.resume); a sheet goes on.
- deactivate: unsubscribe, stop the timers, stop ticking after the tick in progress, and
  clear the display (DELETEALL on both marker topics, acknowledged as at shutdown).
- cleanup: release what configure built (topics, services, the session); configure may
  follow again.
- shutdown (from any state): the node's shutdown contract (ros.node.ClothNode.shutdown:
  stop after the tick in progress, DELETEALL, acknowledgements, the inputs' summary), then
  the process exits with status 0.

What a transition built is found by comparing the node's publishers, subscriptions, timers,
services and clients before and after it, so the release never lags behind what
`_configure` and `_subscribe` create. One simulation thread (ros.sim_thread) serves every
session the node configures: numba's thread teams are per calling thread.
"""

from __future__ import annotations

import traceback
from collections.abc import Iterable, Sequence
from pathlib import Path

import yaml
from rclpy.client import Client
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.ros.sim_thread import SimThread

__all__ = ["ManagedTransitions", "wants_managed"]

SUCCESS, FAILURE, ERROR = (TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE,
                           TransitionCallbackReturn.ERROR)
_DESTROY = ((Publisher, "destroy_publisher"), (Subscription, "destroy_subscription"),
            (Timer, "destroy_timer"), (Service, "destroy_service"), (Client, "destroy_client"))


class ManagedTransitions(LifecycleNodeMixin):
    """The lifecycle transitions of a ClothNode (ros.node.ManagedClothNode mixes them in
    before ClothNode): the module docstring says what each does."""

    def __init__(self, **kwargs) -> None:
        # The node's own constructor (ClothNode's, past the mixin's, which needs the node
        # made first: `_start_up` calls it).
        super(LifecycleNodeMixin, self).__init__(**kwargs)

    def _start_up(self) -> None:
        """Instead of ClothNode's set-up at construction: the lifecycle services, the
        simulation thread, the run-time parameters' checks; then wait for configure."""
        LifecycleNodeMixin.__init__(self)
        self._sim_thread = SimThread()
        self._built: dict[str, set] = {}
        self._watch_parameters()
        self.get_logger().info(
            f"managed node {self.get_fully_qualified_name()}: unconfigured, waiting for a "
            f"configure transition ({self.get_fully_qualified_name()}/change_state)")

    # -- transitions ----------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        before = self._entities()
        try:
            if self.body:  # activate subscribes: a bad name fails here, not there
                _check_topic_name(self, "topic")
            described = self._configure()
        except (ClothInputError, ParameterException) as exc:
            self.get_logger().error(f"configure failed: {exc}")
            self._release(self._entities() - before)
            return FAILURE
        except Exception:
            self.get_logger().error(f"configure failed:\n{traceback.format_exc()}")
            self._release(self._entities() - before)
            return ERROR
        self._built["configure"] = self._entities() - before
        self.get_logger().info(f"configured: {described}")
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        before = self._entities()
        try:
            text = self._subscribe()
        except ClothInputError as exc:
            self.get_logger().error(f"activate failed: {exc}")
            self._destroy(self._entities() - before)
            return FAILURE
        self._built["activate"] = self._entities() - before
        self.session.resume()
        self.get_logger().info(f"activated{text}")
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._destroy(self._built.pop("activate", ()))
        self.session.stop()
        self.clear_display("deactivate")
        self.get_logger().info("deactivated: ticks stopped, poses no longer received")
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release(self._built.pop("activate", set()) | self._built.pop("configure", set()))
        self.get_logger().info("cleaned up: unconfigured")
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.shutdown()
        self.finish(0)
        return SUCCESS

    def destroy_node(self) -> None:
        super().destroy_node()
        if self._sim_thread is not None:  # (None: the node failed before _start_up)
            self._sim_thread.shutdown()

    # -- what a transition built ----------------------------------------------------------
    def _entities(self) -> set:
        """The node's publishers, subscriptions, timers, services and clients now."""
        return {*self.publishers, *self.subscriptions, *self.timers, *self.services,
                *self.clients}

    def _destroy(self, entities: Iterable) -> None:
        for entity in entities:
            for kind, method in _DESTROY:
                if isinstance(entity, kind):
                    getattr(self, method)(entity)
                    break

    def _release(self, entities: Iterable) -> None:
        """Close the session (and its grippers' services) and destroy `entities`."""
        if self.session is not None:
            self.session.close()
        if self.grasp_services is not None:
            self.grasp_services.close()
        self._destroy(entities)
        self.session = self.outputs = self.grasp_services = None


def _check_topic_name(node, key: str) -> None:
    """ClothInputError unless parameter `key` names a valid topic."""
    topic = str(node.param(key))
    try:
        node.resolve_topic_name(topic)
    except RuntimeError as exc:  # rclpy's RCLError
        raise ClothInputError(f"parameter {key}: invalid topic name {topic!r} "
                              f"({exc})") from exc


# -- is it managed? ---------------------------------------------------------------------------
def wants_managed(argv: Sequence[str], node_name: str = "cloth_node") -> bool:
    """Whether the command line's ROS arguments set parameter `managed` true, as rcl reads
    them (measured: the last setting wins, in command-line order): `-p managed:=...`,
    `-p <node_name>:managed:=...` and the `--params-file` sections that apply to every node
    (a key with a '*') or name `node_name`. Read before rclpy starts the node, which needs
    to know its class; the plain node refuses a managed:=true it was not told of here (a
    case this reading misses)."""
    value, in_ros, items = False, False, list(argv)
    for i, arg in enumerate(items):
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and i + 1 < len(items) and arg in ("-p", "--param"):
            name, _, text = items[i + 1].partition(":=")
            node, _, key = name.rpartition(":")
            if key == "managed" and node in ("", node_name):
                value = _as_bool(text, value)
        elif in_ros and i + 1 < len(items) and arg == "--params-file":
            value = _from_params_file(Path(items[i + 1]), node_name, value)
    return value


def _from_params_file(path: Path, node_name: str, value: bool) -> bool:
    try:
        document = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError):
        return value  # rcl reports an unreadable file itself
    for key, section in document.items() if isinstance(document, dict) else ():
        if "*" in str(key) or str(key).rstrip("/").rpartition("/")[2] == node_name:
            params = (section or {}).get("ros__parameters") or {}
            if "managed" in params:
                value = _as_bool(params["managed"], value)
    return value


def _as_bool(raw: object, default: bool) -> bool:
    parsed = yaml.safe_load(raw) if isinstance(raw, str) else raw
    return parsed if isinstance(parsed, bool) else default
