"""cloth_node as a managed (lifecycle) node, driven over DDS through its lifecycle services
as a launch system or `ros2 lifecycle set` would: configure -> activate -> deactivate ->
activate -> shutdown, with body poses played in every state (ros.managed_node).

The cloth is published only while the node is active: every cloth marker carries the stamp
of a pose played while it was active (poses published while it was inactive have stamps of
their own and never show up), nothing is drawn between configure and the first activate,
nothing after the deactivate's DELETEALL until the node is activated again; the shutdown
transition clears the display once more and the process exits 0.

The node runs as a subprocess over Fast DDS on loopback (node_harness.py).
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("lifecycle_msgs")

from geometry_msgs.msg import PoseArray
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from node_harness import (
    BODY_PARTICLES,
    MESSAGES,
    QOS,
    RELIABLE_INPUT,
    REPO,
    START_TIMEOUT_S,
    STOP_TIMEOUT_S,
    Listener,
    check_marker,
    kill_node,
    node_command,
    pose_array_cdr,
    replay_in_thread,
    stamps_ns,
    start_node,
    status_values,
)
from visualization_msgs.msg import Marker

from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes

POSE_TOPIC = "/avatar/body_poses"
OFF_STAMP_S = 500.0  # added to the stamps of the poses published while the node is inactive


class LifecycleListener(Listener):
    """A Listener that also keeps the order in which cloth markers and DELETEALLs arrived,
    calls the node's lifecycle services and publishes poses of its own."""

    def __init__(self) -> None:
        super().__init__()
        self.events: list[str] = []  # 'add' (a cloth marker) or 'clear' (DELETEALL), in order
        self.change = self.node.create_client(ChangeState, "/cloth_node/change_state")
        self.get = self.node.create_client(GetState, "/cloth_node/get_state")
        self.poses = self.node.create_publisher(PoseArray, POSE_TOPIC, QOS)

    def _on_marker(self, data: bytes) -> None:
        super()._on_marker(data)
        action = marker_arrays_from_bytes(data).action
        self.events.append("clear" if action == Marker.DELETEALL else "add")

    def state(self) -> str:
        return self.call(self.get, GetState.Request(), 60.0).current_state.label

    def transition(self, transition_id: int, timeout: float = 120.0) -> bool:
        request = ChangeState.Request(transition=Transition(id=transition_id))
        return self.call(self.change, request, timeout).success


def _play_while_inactive(lis: LifecycleListener, walk_frames) -> None:
    """Publish the first poses (stamps moved OFF_STAMP_S on) while the node is inactive: it
    has no subscription then, so none may reach the cloth."""
    assert lis.spin_until(lambda: lis.poses.get_subscription_count() == 0, 60.0), (
        "the inactive node still subscribes to the poses")
    for stamp_s, poses in walk_frames[:5]:
        lis.poses.publish(pose_array_cdr(round((stamp_s + OFF_STAMP_S) * 1e9), poses))
    assert lis.state() == "inactive"


def _play_until_drawn(lis: LifecycleListener, bag, proc, log_path, last_ns: int) -> None:
    """Replay `bag` into the active node until a new cloth marker reaches the bag's last
    pose."""
    since = len(lis.markers)
    player = replay_in_thread(bag, lis.ctx)
    ok = lis.spin_until(lambda: not player.is_alive() and len(lis.markers) > since
                        and stamps_ns(lis.markers[-1:])[0] == last_ns, 180.0, proc, log_path)
    assert not player.errors, player.errors
    assert ok, (f"{len(lis.markers)} markers; last status "
                f"{status_values(lis.stats[-1]) if lis.stats else None}:\n"
                f"{log_path.read_text()}")


def test_lifecycle_transitions_publish_only_while_active(ros_env, tmp_path, walk_frames,
                                                         short_bag):
    played = {round(s * 1e9) for s, _ in walk_frames}
    last_ns = round(walk_frames[-1][0] * 1e9)
    log_path = tmp_path / "node.log"
    # lod off and a fixed tolerance: no cost-model calibration (a minute on this VM), which
    # the transitions do not need
    proc = start_node(node_command(f"particles:={BODY_PARTICLES}", "managed:=true",
                                   "lod:=false", "tolerance:=0.0001", RELIABLE_INPUT,
                                   params_file=str(REPO / "config" / "walking.yaml")),
                      ros_env, log_path)
    lis = LifecycleListener()
    try:
        # Unconfigured: the lifecycle services answer, the node's topics do not exist yet.
        assert lis.spin_until(lambda: lis.change.service_is_ready()
                              and lis.get.service_is_ready(), START_TIMEOUT_S, proc,
                              log_path), f"no lifecycle services:\n{log_path.read_text()}"
        assert lis.state() == "unconfigured"
        assert lis.subs[0].get_publisher_count() == 0

        # configure: the scene is loaded, calibrated and warmed up; outputs exist, no cloth.
        assert lis.transition(Transition.TRANSITION_CONFIGURE, START_TIMEOUT_S), (
            log_path.read_text())
        assert lis.state() == "inactive"
        assert lis.spin_until(lambda: all(s.get_publisher_count() for s in lis.subs)
                              and lis.reset.service_is_ready(), 60.0, proc, log_path)
        _play_while_inactive(lis, walk_frames)
        assert lis.events == [] and lis.markers == []

        # activate: poses in, cloth out.
        assert lis.transition(Transition.TRANSITION_ACTIVATE)
        assert lis.state() == "active"
        _play_until_drawn(lis, short_bag, proc, log_path, last_ns)
        first_pass = len(lis.markers)
        n_points = len(marker_arrays_from_bytes(lis.markers[0]).points)
        check_marker(lis.markers[0], n_points)
        check_marker(lis.markers[-1], n_points)
        assert lis.spin_until(lambda: int(status_values(lis.stats[-1])[1]["poses_used"])
                              == MESSAGES, 30.0, proc, log_path)

        # deactivate: ticks stop, the display is cleared on both marker topics.
        assert lis.transition(Transition.TRANSITION_DEACTIVATE)
        assert lis.spin_until(lambda: sorted(t for t, _ in lis.cleared)
                              == ["marker", "markers"], 30.0, proc, log_path), lis.cleared
        assert lis.state() == "inactive"
        _play_while_inactive(lis, walk_frames)
        assert lis.events == ["add"] * first_pass + ["clear"], lis.events

        # activate again: the garment is re-dressed on the next pose (the bag once more).
        assert lis.transition(Transition.TRANSITION_ACTIVATE)
        _play_until_drawn(lis, short_bag, proc, log_path, last_ns)
        assert len(lis.markers) > first_pass
        assert lis.events[first_pass + 1:] == ["add"] * (len(lis.markers) - first_pass)
        # Only poses played while active reached the cloth (inactive ones: OFF_STAMP_S on).
        assert set(stamps_ns(lis.markers)) <= played
        assert stamps_ns(lis.markers[first_pass:first_pass + 1]) == [min(played)]

        # shutdown: the node's shutdown contract, then the process ends with status 0.
        future = lis.change.call_async(ChangeState.Request(
            transition=Transition(id=Transition.TRANSITION_ACTIVE_SHUTDOWN)))
        assert lis.spin_until(lambda: future.done() or proc.poll() is not None,
                              STOP_TIMEOUT_S), log_path.read_text()
        assert proc.wait(STOP_TIMEOUT_S) == 0, log_path.read_text()
        assert lis.spin_until(lambda: len(lis.cleared) == 4, 30.0), lis.cleared
        assert lis.events[-1] == "clear"
        text = log_path.read_text()
        assert "Traceback" not in text, text
        assert "shutdown: DELETEALL" in text and "pose frames:" in text, text
        if future.done():  # the answer may be lost with the process: its exit is the proof
            assert future.result().success
    finally:
        kill_node(proc)
        lis.close()


# ------------------------------------------------------------------------------------------
# In-process checks: which class main makes, and a configure that fails


def test_managed_is_read_from_the_command_line(tmp_path):
    from cloth_mg_ros.ros.managed_node import wants_managed

    assert not wants_managed(["cloth_node"])
    assert not wants_managed(["cloth_node", "--ros-args", "-p", "particles:=400"])
    assert wants_managed(["cloth_node", "--ros-args", "-p", "managed:=true"])
    assert wants_managed(["x", "--ros-args", "--param", "cloth_node:managed:=True"])
    assert not wants_managed(["x", "--ros-args", "-p", "other_node:managed:=true"])
    assert not wants_managed(["x", "--ros-args", "-p", "managed:=true", "-p", "managed:=false"])
    assert not wants_managed(["x", "-p", "managed:=true"])  # not a ROS argument
    everyone, other = tmp_path / "all.yaml", tmp_path / "other.yaml"
    everyone.write_text("/**:\n  ros__parameters:\n    managed: true\n")
    other.write_text("/alice/other_node:\n  ros__parameters:\n    managed: true\n")
    assert wants_managed(["x", "--ros-args", "--params-file", str(everyone)])
    assert not wants_managed(["x", "--ros-args", "--params-file", str(other)])
    # The last setting wins, -p or file, as rcl has it (measured with rclpy 7.1).
    assert not wants_managed(["x", "--ros-args", "--params-file", str(everyone), "-p",
                              "managed:=false"])
    assert wants_managed(["x", "--ros-args", "-p", "managed:=false", "--params-file",
                          str(everyone)])


@pytest.fixture
def ros_context():
    from node_harness import DOMAIN_ID
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _overrides(**values):
    from rclpy.parameter import Parameter

    return [Parameter(k, value=v) for k, v in values.items()]


def test_the_plain_node_refuses_managed_it_was_not_started_as(ros_context):
    from cloth_mg_ros.errors import ClothInputError
    from cloth_mg_ros.ros.node import ClothNode

    with pytest.raises(ClothInputError, match="cloth_node_managed"):
        ClothNode(context=ros_context, parameter_overrides=_overrides(managed=True))


@pytest.mark.parametrize("bad", [{"topic": "1 body"}, {"marker_topic": "cloth marker"}])
def test_a_failed_configure_is_reported_and_leaves_nothing_built(ros_context, bad, capfd):
    """A bad topic name fails the configure (FAILURE, not a crash): the node is unconfigured
    again and holds no topic, service or simulation it made for it."""
    from rclpy.lifecycle import TransitionCallbackReturn

    from cloth_mg_ros.ros.node import ManagedClothNode

    node = ManagedClothNode(context=ros_context,
                            parameter_overrides=_overrides(particles=300, **bad))
    try:
        before = node._entities()
        assert node._state_machine.current_state[1] == "unconfigured"
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        (name,) = bad
        assert f"configure failed: parameter {name}: invalid topic name" in capfd.readouterr().err
        assert node._state_machine.current_state[1] == "unconfigured"
        assert node._entities() == before and node.session is None
        assert node.trigger_shutdown() == TransitionCallbackReturn.SUCCESS
        assert node.finished.result() == 0
    finally:
        node.destroy_node()
