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
        return self.call(self.get, GetState.Request()).current_state.label

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
    """Replay `bag` into the active node until its cloth reaches the bag's last pose."""
    player = replay_in_thread(bag, lis.ctx)
    ok = lis.spin_until(lambda: not player.is_alive() and lis.markers
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
    proc = start_node(node_command(f"particles:={BODY_PARTICLES}", "managed:=true",
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
