"""cloth_node's interfaces as a ROS user wires them: names that follow a namespace, the input's
frame carried to every output, /diagnostics, the garment as PointCloud2 and Mesh, DELETEALL,
a looped bag that re-dresses by itself, `cloth_node --help`.

The node runs as a subprocess over Fast DDS on loopback (node_harness.py); the geometry is
decoded with rclpy's own deserialiser.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("sensor_msgs")
pytest.importorskip("shape_msgs")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_harness import (
    BODY_PARTICLES,
    MESSAGES,
    QOS,
    RELIABLE_INPUT,
    REPO,
    Listener,
    check_marker,
    kill_node,
    node_command,
    stamps_ns,
    start_node,
    status_values,
    stop_node,
)
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import PointCloud2
from shape_msgs.msg import Mesh
from visualization_msgs.msg import Marker, MarkerArray

from cloth_mg_ros.io.bags import write_pose_bag
from cloth_mg_ros.io.messages.markers import marker_arrays_from_bytes
from cloth_mg_ros.ros.geometry_out import mesh_bytes, pointcloud2_bytes, verify_geometry_layouts

NS = "/alice"
FRAME = "mocap_origin"  # the pose bag's header.frame_id (not the `frame_id` parameter's world)

# ------------------------------------------------------------------------------------------
# In-process checks


def test_geometry_layouts_decode_with_rclpy():
    verify_geometry_layouts()
    rng = np.random.default_rng(3)
    x, v = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    faces = rng.integers(0, 50, size=(40, 3))
    cloud = deserialize_message(pointcloud2_bytes(x, 7, 8, FRAME, v), PointCloud2)
    assert (cloud.header.frame_id, cloud.width, cloud.height) == (FRAME, 50, 1)
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "vx", "vy", "vz"]
    rows = np.frombuffer(bytes(cloud.data), dtype="<f4").reshape(50, 6)
    assert np.array_equal(rows, np.hstack([x, v]).astype(np.float32))
    mesh = deserialize_message(mesh_bytes(x, faces), Mesh)
    assert np.array_equal([list(t.vertex_indices) for t in mesh.triangles], faces)
    assert np.array_equal([[p.x, p.y, p.z] for p in mesh.vertices], x)


def test_help_prints_usage_and_starts_nothing(ros_env):
    run = subprocess.run([sys.executable, "-m", "cloth_mg_ros.ros.node", "--help"],
                         env=ros_env, cwd=REPO, capture_output=True, text=True, timeout=60,
                         check=False)
    assert run.returncode == 0, run.stderr
    for text in ("cloth_node", "--ros-args", "marker_topic", "cloth/marker", "points_topic",
                 "use_sim_time", "__ns"):
        assert text in run.stdout, text
    assert "dressed" not in run.stderr and "waiting" not in run.stderr


def test_the_node_page_lists_every_topic():
    """doc/node.md's topics table names every input and output topic at its default (the
    parameter table is generated from the schema: test_docs checks it)."""
    from cloth_mg_ros.ros.parameters import parameter_table, scene_defaults

    rows = [line for line in (REPO / "doc" / "node.md").read_text().splitlines()
            if line.startswith("| `")]
    table = parameter_table(*scene_defaults("walking"))
    for key in ("marker_topic", "markers_topic", "stats_topic", "points_topic", "mesh_topic",
                "topic"):
        assert any(line.startswith(f"| `{table[key].default}`") for line in rows), key


# ------------------------------------------------------------------------------------------
# A namespaced node on a bag played twice (the second pass starts over, as --loop does)


class GeometryListener(Listener):
    """A Listener in NS that also takes the point cloud, the mesh and /diagnostics."""

    def __init__(self) -> None:
        super().__init__(NS)
        self.points: list[bytes] = []
        self.meshes: list[bytes] = []
        self.diagnostics: list[tuple[float, DiagnosticArray]] = []
        self.subs += [
            self.node.create_subscription(PointCloud2, f"{NS}/cloth/points",
                                          self.points.append, QOS, raw=True),
            self.node.create_subscription(Mesh, f"{NS}/cloth/mesh", self.meshes.append, QOS,
                                          raw=True),
            self.node.create_subscription(
                DiagnosticArray, "/diagnostics",
                lambda m: self.diagnostics.append((time.monotonic(), m)), QOS),
        ]


def _play_twice(bag, ctx, errors: list) -> threading.Thread:
    from cloth_mg_ros.ros.replay import replay_bag

    def run() -> None:
        try:
            for _ in range(2):
                replay_bag(bag, context=ctx, wait_s=30.0, settle_s=0.3, namespace=NS,
                           node_name="test_replay", log=lambda line: None)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_namespaced_node_frames_geometry_diagnostics_and_a_looped_bag(
        ros_env, tmp_path, walk_frames):
    bag = write_pose_bag(tmp_path / "walk_mocap", np.array([s for s, _ in walk_frames]),
                         np.stack([p for _, p in walk_frames]), frame_id=FRAME)
    log_path = tmp_path / "node.log"
    # the level of detail off: on a loaded machine it may step the dress down mid-test
    proc = start_node(node_command(f"particles:={BODY_PARTICLES}", "lod:=false", RELIABLE_INPUT,
                                   params_file=str(REPO / "config" / "walking.yaml"))
                      + ["-r", f"__ns:={NS}"], ros_env, log_path)
    lis = GeometryListener()
    try:
        lis.wait_matched(proc, log_path)
        # Every output moved into the namespace; nothing is left at the global names. The
        # node's own entry in the graph may arrive after its topics' endpoints (seen once in
        # 12 runs): wait by spinning until discovery lists it.
        assert lis.spin_until(
            lambda: ("cloth_node", NS) in lis.node.get_node_names_and_namespaces(), 30.0,
            proc, log_path)
        names = dict(lis.node.get_publisher_names_and_types_by_node("cloth_node", NS))
        for topic in ("cloth/marker", "cloth/markers", "cloth/stats", "cloth/points",
                      "cloth/mesh"):
            assert f"{NS}/{topic}" in names and f"/{topic}" not in names, names
        assert "/diagnostics" in names  # the aggregator's topic stays global

        errors: list = []
        t0 = time.monotonic()
        player = _play_twice(bag, lis.ctx, errors)
        expected = [round(s * 1e9) for s, _ in walk_frames]

        def done() -> bool:
            if player.is_alive() or not lis.stats:
                return False
            _, values = status_values(lis.stats[-1])
            return int(values["poses_used"]) == 2 * MESSAGES

        ok = lis.spin_until(done, 120.0, proc, log_path)
        assert not errors, errors
        assert ok, (f"{len(lis.markers)} markers; last status "
                    f"{status_values(lis.stats[-1]) if lis.stats else None}:\n"
                    f"{log_path.read_text()}")
        # Every tick's outputs are out once the last status is (no pose is left to tick on):
        # wait until the point clouds and meshes have caught up with the markers.
        lis.spin_until(lambda: stamps_ns(lis.markers[-1:]) == expected[-1:]
                       and len(lis.points) == len(lis.meshes) == len(lis.markers), 60.0,
                       proc, log_path)
        wall = time.monotonic() - t0

        # The frame: the poses' header.frame_id on markers, point clouds and stats.
        for data in lis.markers:
            assert marker_arrays_from_bytes(data).frame_id == FRAME
        for data in lis.arrays:
            assert {m.header.frame_id for m in deserialize_message(data, MarkerArray).markers
                    } == {FRAME}
        clouds = [deserialize_message(d, PointCloud2) for d in lis.points]
        assert {c.header.frame_id for c in clouds} == {FRAME}
        assert {a.header.frame_id for a in lis.stats} == {FRAME}

        # One marker, point cloud and mesh per tick; those of a tick describe one garment.
        ticks = len(lis.markers)
        assert len(lis.points) == len(lis.meshes) == ticks
        for k in (0, ticks // 2, ticks - 1):
            mesh = deserialize_message(lis.meshes[k], Mesh)
            verts = np.array([[p.x, p.y, p.z] for p in mesh.vertices])
            tris = np.array([list(t.vertex_indices) for t in mesh.triangles])
            points = check_marker(lis.markers[k], 3 * len(tris), FRAME)
            assert np.array_equal(verts[tris].reshape(-1, 3), points)
            cloud = clouds[k]
            assert [f.name for f in cloud.fields] == ["x", "y", "z"]  # points_velocity off
            xyz = np.frombuffer(bytes(cloud.data), dtype="<f4").reshape(-1, 3)
            assert np.array_equal(xyz, verts.astype(np.float32))
            assert cloud.header.stamp == deserialize_message(lis.markers[k], Marker).header.stamp

        # The second pass went back in time: the node cleared the display (DELETEALL on both
        # marker topics), re-dressed by itself and used every pose of both passes.
        stamps = stamps_ns(lis.markers)
        restart = next(i for i in range(1, ticks) if stamps[i] < stamps[i - 1])
        assert stamps[0] == stamps[restart] == expected[0]
        assert stamps[restart - 1] == stamps[-1] == expected[-1]
        assert sorted(t for t, _ in lis.cleared) == ["marker", "markers"], lis.cleared
        assert all(stamp == expected[0] for _, stamp in lis.cleared)
        messages = [status_values(a)[0].message for a in lis.stats]
        assert sum(m.startswith("dressed") for m in messages) == 2
        values = status_values(lis.stats[-1])[1]
        assert int(values["poses_received"]) == int(values["poses_used"]) == 2 * MESSAGES
        assert int(values["poses_discarded"]) == int(values["dropped"]) == 0
        assert int(values["resets"]) == 0

        # /diagnostics: about once a second, named by the node's full name.
        assert len(lis.diagnostics) >= 2, f"{len(lis.diagnostics)} in {wall:.1f} s"
        # their stamps (the node's clock when it published each): the times they arrived here
        # bunch up whenever this process is slow to spin. An rcl timer keeps its phase (a
        # late callback is followed one period less the delay later), so over the span no
        # more fire than one a second allows, however their gaps fall.
        stamps = [a.header.stamp.sec + 1e-9 * a.header.stamp.nanosec
                  for _, a in lis.diagnostics]
        assert len(stamps) <= (stamps[-1] - stamps[0]) / 1.0 + 2, np.diff(stamps)
        for _, arr in lis.diagnostics:
            (st,) = arr.status
            assert st.name == "cloth_node: solver" and st.hardware_id == f"{NS}/cloth_node"
            assert st.level in (DiagnosticStatus.OK, DiagnosticStatus.WARN), st.message
        assert "particles" in {kv.key for kv in lis.diagnostics[-1][1].status[0].values}

        text = stop_node(proc, log_path)
        assert "went back" in text and "new stream" in text, text
    finally:
        kill_node(proc)
        lis.close()


def test_every_kernel_of_the_node_runs_on_its_one_simulation_thread(monkeypatch):
    """The warm-up at start runs on the thread that later steps the cloth, not on the main
    thread: numba's OpenMP layer keeps a thread team per calling thread, and two teams on
    the same cores make every parallel kernel sleep at its barriers (ros.sim_thread docstring)."""
    from node_harness import DOMAIN_ID
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from cloth_mg_ros.ros import body_scene
    from cloth_mg_ros.ros.node import ClothNode

    seen = []
    warm_up = body_scene.warm_up_body

    def recording(scene, outputs):
        seen.append(threading.get_ident())
        return warm_up(scene, outputs)

    monkeypatch.setattr(body_scene, "warm_up_body", recording)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    try:
        node = ClothNode(context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in {"scene": "walking", "particles": 300,
                                               "lod": False, "threads": 2}.items()])
        try:
            deadline = time.monotonic() + 30.0
            while node.session._ident is None and time.monotonic() < deadline:
                time.sleep(0.01)
            assert seen == [node.session._ident]
            assert seen[0] != threading.get_ident()
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
