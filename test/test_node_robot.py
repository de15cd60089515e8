"""cloth_node's robot side (issue 43, item 6): gripper poses used at their stamps, wrenches
that name the frame their torque is taken about, and timer scenes stepped by the ROS clock
under use_sim_time.

Headless (no DDS): a Track moves held particles along stamped poses (lerp, slerp) within an
interval; the desk starts a span from the pose stamped at or before it, holds the newest past
its stamp and keeps the newest-wins behaviour for unstamped poses; a hang's gripper moved by
two stamped poses carries its corner to the pose interpolated at the tick's stamp (the old
newest-wins took it to the newer pose); a wrench published in one frame, re-expressed by
hand (rotate, shift the torque by p x F), is what the other setting publishes.

Over DDS: the hang under use_sim_time ticks while a test /clock advances, not at all while it
pauses (a bounded wait, stated below), again when it resumes, and at /clock's rate, not the
wall's, when /clock runs at half speed.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("geometry_msgs")
pytest.importorskip("rosgraph_msgs")

from log_lines import LogLines
from node_harness import Listener, kill_node, node_command, start_node, status_values, stop_node
from rosgraph_msgs.msg import Clock

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.rotations import quat_to_matrix
from cloth_mg_ros.ros.gripper_desk import GripperDesk
from cloth_mg_ros.ros.parameters import check_parameters
from cloth_mg_ros.ros.session import LiveSession
from cloth_mg_ros.ros.session_settings import SessionSettings
from cloth_mg_ros.ros.wrenches import WrenchOutputs, express
from cloth_mg_ros.sim.grippers import GripperSet, Track


class _Outputs:
    """(What a body scene's warm-up asks of the node's outputs.)"""

    frame_id = "world"

    def cloth_messages(self, *args, **kwargs) -> None:
        return None




def _about_z(deg: float) -> np.ndarray:
    h = np.radians(deg) / 2.0
    return np.array([0.0, 0.0, np.sin(h), np.cos(h)])


# ------------------------------------------------------------------------------------------
# Stamped poses (headless)


def test_a_track_moves_the_held_particles_along_the_stamped_poses_within_an_interval():
    grippers = GripperSet(["g"])
    grippers.set_pose("g", (0.0, 0.0, 1.0))
    x = np.array([[0.1, 0.0, 1.0], [5.0, 5.0, 5.0]])
    assert grippers.hold("g", np.array([0]), x) == 1
    # Two stamped poses: at 10 s where it is, at 12 s 1 m along x and turned 90 degrees.
    track = Track(10.5, 11.5, np.array([10.0, 12.0]),
                  np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]),
                  np.array([_about_z(0.0), _about_z(90.0)]))
    grippers.follow("g", track)
    g = grippers.gripper("g")
    for u in (0.0, 0.25, 0.5, 1.0):
        s = (10.5 + u - 10.0) / 2.0  # how far between the two stamps step u's time is
        rot = quat_to_matrix(_about_z(90.0 * s)[None])[0]
        want = np.array([s, 0.0, 1.0]) + rot @ np.array([0.1, 0.0, 0.0])
        np.testing.assert_allclose(g.targets(u)[0], want, atol=1e-12)
    np.testing.assert_allclose(g.position, [0.75, 0.0, 1.0], atol=1e-15)
    grippers.end_interval()  # the track is done: the end pose holds
    assert g.track is None
    np.testing.assert_allclose(g.targets(0.5)[0], g.targets(1.0)[0], atol=1e-15)


def test_the_desk_uses_stamped_poses_at_their_stamps_and_unstamped_ones_at_once():
    log = LogLines()
    desk = GripperDesk(["g"], log)
    grippers = GripperSet(["g"])
    assert desk.offer_pose("g", (0.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=10.0)
    assert desk.offer_pose("g", (2.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=11.0)
    desk.apply(grippers, None, None, "world")  # the first stamped pose, at once
    np.testing.assert_array_equal(grippers.gripper("g").position, [0.0, 0.0, 0.0])
    # A span inside the stamps: from the pose at 10.5 s to the one at 10.75 s.
    desk.place_stamped(grippers, 10.5, 10.75, "world")
    g = grippers.gripper("g")
    np.testing.assert_allclose(g.pose_at(0.0)[0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.pose_at(0.5)[0], [1.25, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.position, [1.5, 0.0, 0.0], atol=1e-12)
    grippers.end_interval()
    # Past the newest stamp the newest holds; the span starts from the pose at 10.75 s.
    desk.place_stamped(grippers, 10.75, 12.0, "world")
    np.testing.assert_allclose(g.pose_at(0.0)[0], [1.5, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.pose_at(0.2)[0], [2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(g.position, [2.0, 0.0, 0.0], atol=1e-12)
    grippers.end_interval()
    # An unstamped pose wins at once (as before stamps were read) and ends the stamped ones.
    assert desk.offer_pose("g", (0.0, 3.0, 0.0), (0, 0, 0, 1), "world")
    desk.apply(grippers, None, None, "world")
    desk.place_stamped(grippers, 12.0, 13.0, "world")
    assert g.track is None
    np.testing.assert_array_equal(g.position, [0.0, 3.0, 0.0])
    # A stamped pose in another frame is skipped and counted.
    assert desk.offer_pose("g", (9.0, 9.0, 9.0), (0, 0, 0, 1), "odom", stamp=14.0)
    desk.place_stamped(grippers, 13.0, 15.0, "world")
    assert desk.skipped["wrong_frame"] == 1 and g.track is None
    assert desk.skipped["stale"] == 0  # every stamped pose so far was on a span's track


def test_stamped_gripper_poses_no_span_used_are_counted():
    """A pose that arrives after the span its stamp belonged to (older than the one the next
    span starts from) is counted as stale; past the poses kept per gripper the oldest go and
    are counted as overflow: every pose received is used, skipped or still waiting."""
    from cloth_mg_ros.ros.gripper_desk import STAMPED_POSES

    desk = GripperDesk(["g"], LogLines())
    grippers = GripperSet(["g"])
    desk.offer_pose("g", (0.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=10.0)
    desk.apply(grippers, None, None, "world")
    desk.place_stamped(grippers, 10.0, 11.0, "world")
    grippers.end_interval()
    desk.offer_pose("g", (1.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=10.5)  # late
    desk.offer_pose("g", (2.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=10.8)  # late
    desk.place_stamped(grippers, 11.0, 12.0, "world")  # starts from the one at 10.8 s
    assert desk.skipped["stale"] == 1
    grippers.end_interval()
    for k in range(STAMPED_POSES + 3):
        desk.offer_pose("g", (0.0, 0.0, 0.0), (0, 0, 0, 1), "world", stamp=20.0 + k)
    assert desk.skipped["overflow"] == 3 and desk.skipped["stale"] == 1
    # Every pose received is accounted for: the two the spans started from (10 s, 10.8 s)
    # were used, four were skipped, the newest STAMPED_POSES wait for a span.
    waiting = sum(not pose.used for pose in desk._stamped["g"])
    assert waiting == STAMPED_POSES
    assert desk.received == STAMPED_POSES + 6 == 2 + sum(desk.skipped.values()) + waiting


def test_a_hang_gripper_moved_by_two_stamped_poses_carries_its_corner_along_them():
    """The hang's left gripper: a pose at 100 s where it holds its corner, one at 101 s 0.2 m
    along x; ticks at the node's clock 100.25 s and 100.5 s put the corner a quarter and
    half of the way (newest-wins would have put it at the newer pose at once)."""
    values = check_parameters({"scene": "hang", "particles": 120, "tick_mode": "timer",
                               "threads": 1})
    clock = [100.25]

    def now() -> tuple[int, int]:
        ns = round(clock[0] * 1e9)
        return ns // 1_000_000_000, ns % 1_000_000_000

    session = LiveSession(SessionSettings.from_values(values, body=False), None, LogLines(), now,
                          lambda status: None)
    session.prepare()
    try:
        scene = session.scene
        g = scene.grippers.gripper("left")
        p0, corner = g.position.copy(), int(g.held[0])
        offset = scene.sim.state.x[corner] - p0
        p1 = p0 + np.array([0.2, 0.0, 0.0])
        scene.desk.offer_pose("left", p0, (0, 0, 0, 1), "", stamp=100.0)
        scene.desk.offer_pose("left", p1, (0, 0, 0, 1), "", stamp=101.0)
        for t, s in ((100.25, 0.25), (100.5, 0.5)):
            clock[0] = t
            scene.apply_gripper_inputs()
            (frame,) = scene.tick(None, 0.02)
            want = (1.0 - s) * p0 + s * p1 + offset
            np.testing.assert_allclose(frame.positions[corner], want, atol=1e-9)
            assert frame.sec + 1e-9 * frame.nanosec == pytest.approx(t, abs=1e-9)
            np.testing.assert_allclose(frame.gripper_poses["left"][0], want - offset,
                                       atol=1e-12)
    finally:
        session.close()


def test_a_body_scene_gripper_follows_its_stamped_poses_on_the_body_stamps():
    """Message mode: a tick from body stamp t0 to t1 takes the gripper to its stamped poses'
    pose at t1 (its poses at t0 and t0 + 2 (t1 - t0): half way), the held particles with it."""
    from cloth_mg_ros.io.bags import read_pose_frames, resolve_bag
    from cloth_mg_ros.ros.ingest import KeyPose

    values = check_parameters({"scene": "walking", "particles": 300, "lod": False,
                               "threads": 1, "self_contact": False, "grippers": ["probe"]})
    session = LiveSession(SessionSettings.from_values(values, body=True), _Outputs(), LogLines(),
                          lambda: (7, 500), lambda status: None)
    try:
        session.prepare()
        scene = session.scene
        frames = read_pose_frames(resolve_bag("walk"))[:3]

        def key(k: int) -> KeyPose:
            stamp, poses = frames[k]
            sec = int(stamp)
            return KeyPose(sec, round((stamp - sec) * 1e9), stamp, "map", poses)

        scene.tick([key(0)], None)  # dressed
        g = scene.garment_sim
        free = np.flatnonzero(~g.held_mask())
        p = g.positions[free[len(free) // 2]].copy()
        g.grippers.set_pose("probe", p)
        assert g.grippers.grasp("probe", g.positions, g.held_mask()) >= 1
        held, offsets = g.grippers.gripper("probe").held, g.grippers.gripper("probe").offsets
        t0, t1 = frames[0][0], frames[2][0]
        move = np.array([0.1, 0.0, 0.0])
        scene.desk.offer_pose("probe", p, (0, 0, 0, 1), "map", stamp=t0)
        scene.desk.offer_pose("probe", p + move, (0, 0, 0, 1), "map", stamp=t0 + 2 * (t1 - t0))
        scene.apply_gripper_inputs()
        (frame,) = scene.tick([key(1), key(2)], None)
        np.testing.assert_allclose(frame.positions[held], p + 0.5 * move + offsets, atol=1e-9)
        np.testing.assert_allclose(frame.gripper_poses["probe"][0], p + 0.5 * move, atol=1e-12)
    finally:
        session.close()


# ------------------------------------------------------------------------------------------
# Wrench frames (headless)


class _Pub:
    def __init__(self) -> None:
        self.got: list[tuple[str, np.ndarray, np.ndarray]] = []

    def publish(self, msg) -> None:
        f, t = msg.wrench.force, msg.wrench.torque
        self.got.append((msg.header.frame_id, np.array([f.x, f.y, f.z]),
                         np.array([t.x, t.y, t.z])))


def _outputs(mode: str) -> WrenchOutputs:
    return WrenchOutputs({"left": _Pub()}, {"torso": _Pub()}, mode)


def test_a_wrench_re_expressed_by_hand_is_what_the_other_frame_setting_publishes():
    rng = np.random.default_rng(43)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    p = rng.normal(size=3)
    force, torque = rng.normal(size=3), rng.normal(size=3)  # world axes, about p
    qs, ps = _about_z(30.0), np.array([0.2, -0.1, 1.3])
    fs, ts = rng.normal(size=3), rng.normal(size=3)
    published = {}
    for mode in ("world", "local"):
        out = _outputs(mode)
        out.publish({"left": {"force": force, "torque": torque}}, 3, 4, "mocap",
                    {"torso": fs}, {"torso": ts}, {"left": (p, q)}, {"torso": (ps, qs)})
        published[mode] = (out.grippers["left"].got[-1], out.contacts["torso"].got[-1])
    (wg, wc), (lg, lc) = published["world"], published["local"]
    assert wg[0] == wc[0] == "mocap" and lg[0] == "gripper/left" and lc[0] == "torso"
    for world, local, (origin, quat) in ((wg, lg, (p, q)), (wc, lc, (ps, qs))):
        rot = quat_to_matrix(quat[None])[0]
        f_w = rot @ local[1]  # local -> world: rotate, then shift the torque to the origin
        t_w = rot @ local[2] + np.cross(origin, f_w)
        np.testing.assert_allclose(world[1], f_w, rtol=1e-9, atol=1e-9 * np.abs(f_w).max())
        np.testing.assert_allclose(world[2], t_w, rtol=1e-9, atol=1e-9 * np.abs(t_w).max())
    # The world setting's torque is about the origin, not the grasp point (the old message).
    assert not np.allclose(wg[2], torque)
    f, t = express("world", force, torque, p, q)
    np.testing.assert_array_equal(f, force)
    np.testing.assert_allclose(t, torque + np.cross(p, force), rtol=1e-12)


def test_local_frames_need_a_name_each():
    with pytest.raises(ClothInputError, match="gripper_frame: 'tool0' names one frame"):
        WrenchOutputs({"a": _Pub(), "b": _Pub()}, {}, "local", gripper_frame="tool0")
    out = WrenchOutputs({"a": _Pub(), "b": _Pub()}, {}, "local", gripper_frame="{name}_tool0")
    assert out.frame_names[("gripper", "b")] == "b_tool0"


def test_an_idle_gripper_publishes_an_exact_zero_in_either_frame():
    for mode in ("world", "local"):
        out = _outputs(mode)
        out.publish({}, 0, 0, "world", gripper_poses={"left": (np.ones(3), _about_z(45.0))})
        _, f, t = out.grippers["left"].got[-1]
        assert f.tolist() == [0.0, 0.0, 0.0] and t.tolist() == [0.0, 0.0, 0.0]


# ------------------------------------------------------------------------------------------
# The ROS clock (DDS)

RATE_HZ = 20.0
PAUSE_S = 2.0  # s of wall time the test watches a paused /clock (40 wall periods)


class _ClockPublisher:
    """/clock from the test: `advance()` in a spin loop publishes speed x the wall time passed
    since the last message, every 50 ms of wall time."""

    def __init__(self, lis: Listener, start_s: float) -> None:
        self.pub = lis.node.create_publisher(Clock, "/clock", 10)
        self.t = start_s
        self.speed = 1.0
        self.running = True
        self._wall = time.monotonic()

    def publish(self) -> None:
        ns = round(self.t * 1e9)
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        self.pub.publish(msg)

    def resume(self, speed: float) -> None:
        self.running, self.speed, self._wall = True, speed, time.monotonic()

    def advance(self) -> None:
        wall = time.monotonic()
        if wall - self._wall < 0.05:
            return
        if self.running:
            self.t += self.speed * (wall - self._wall)
            self.publish()
        self._wall = wall


def _step(lis: Listener) -> int:
    return int(status_values(lis.stats[-1])[1]["step"]) if lis.stats else 0


def _stamp_s(lis: Listener) -> float:
    s = lis.stats[-1].header.stamp
    return s.sec + 1e-9 * s.nanosec


def test_the_hang_under_use_sim_time_steps_by_the_clock(ros_env, listener, tmp_path):
    log_path = tmp_path / "node.log"
    proc = start_node(node_command("scene:=hang", "particles:=100", f"rate_hz:={RATE_HZ}",
                                   "use_sim_time:=true"), ros_env, log_path)
    lis = listener
    clock = _ClockPublisher(lis, 1000.0)
    try:
        lis.wait_matched(proc, log_path)
        assert lis.spin_until(lambda: clock.pub.get_subscription_count() >= 1, 30.0, proc,
                              log_path)

        def ticks_past(stamp_s: float, steps: int):
            def done() -> bool:
                clock.advance()
                return bool(lis.stats) and _stamp_s(lis) > stamp_s and _step(lis) >= steps
            return done

        # /clock advances: the node ticks, stamped with /clock's time.
        assert lis.spin_until(ticks_past(1000.0, 5), 60.0, proc, log_path), log_path.read_text()
        # /clock pauses: once the tick due at the paused time is out, nothing more comes.
        clock.running = False
        paused_at = clock.t
        clock.publish()
        assert lis.spin_until(lambda: _stamp_s(lis) >= paused_at - 1.0 / RATE_HZ - 1e-6, 10.0,
                              proc, log_path)
        seen = [len(lis.stats), time.monotonic()]

        def settled() -> bool:  # no status for 0.5 s: the ticks due by the paused time are out
            if len(lis.stats) != seen[0]:
                seen[:] = [len(lis.stats), time.monotonic()]
            return time.monotonic() - seen[1] > 0.5
        assert lis.spin_until(settled, 10.0, proc, log_path)
        paused_step = _step(lis)
        # A bounded wait to show that nothing happens: PAUSE_S of wall time, 40 periods at
        # rate_hz, in which a wall-clock timer would have ticked about 40 times.
        lis.spin_until(lambda: False, PAUSE_S, proc, log_path)
        # Up to two ticks may still have been due at the paused time (a /clock that jumped
        # by more than a period makes the next one due at once) and come late behind a
        # stall of the node's thread longer than `settled`'s 0.5 s; none is past the pause.
        assert _step(lis) - paused_step <= 2, (paused_step, _step(lis))
        assert _stamp_s(lis) <= paused_at + 1e-6
        # /clock resumes at half speed: the node ticks again, at /clock's rate (1 s of /clock
        # in 2 s of wall time: about 20 ticks, not the wall's 40).
        clock.resume(0.5)
        resumed_at = clock.t
        assert lis.spin_until(lambda: (clock.advance() or clock.t >= resumed_at + 1.0), 30.0,
                              proc, log_path)
        clock.running = False
        end = clock.t
        clock.publish()
        assert lis.spin_until(lambda: _stamp_s(lis) >= end - 1.0 / RATE_HZ - 1e-6, 10.0, proc,
                              log_path)
        gained = _step(lis) - paused_step
        assert 5 <= gained <= RATE_HZ * (end - paused_at) + 2, (gained, end - paused_at)
        stop_node(proc, log_path)
    finally:
        kill_node(proc)


def test_use_sim_time_is_kept_as_the_node_was_started_with():
    """The ticks' clock (wall or /clock) is chosen when the node starts, so a run-time
    change of use_sim_time, which would move the stamps to /clock's time and leave the
    ticks on the other clock, is refused with the reason; the same value is accepted."""
    from node_harness import domain_id
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from cloth_mg_ros.ros.node import ClothNode

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id())
    try:
        node = ClothNode(context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in {
                "scene": "hang", "particles": 120, "tick_mode": "timer",
                "threads": 1}.items()])
        try:
            (refused,) = node.set_parameters([Parameter("use_sim_time", value=True)])
            assert not refused.successful and "read at start" in refused.reason
            assert node.get_parameter("use_sim_time").value is False
            (same,) = node.set_parameters([Parameter("use_sim_time", value=False)])
            assert same.successful
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
