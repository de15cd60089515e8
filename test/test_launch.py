"""launch/cloth.launch.py and rviz/cloth.rviz.

The `launch` and `launch_ros` packages are not on the package index this project installs
from, so the launch file is loaded with small stand-ins for them that record the actions it
builds: what it starts (the node with which parameters, the player with which command line,
rviz2 with which config) is checked against the package itself (its console scripts, its
CLI's options, its scene files, its node's topic names). Where `launch` is installed (a ROS 2
workspace), the real launch description is built and checked as well.
"""

from __future__ import annotations

import ast
import importlib.util
import sys
import types
from pathlib import Path

import pytest
import yaml

from cloth_mg_ros.cli.main import build_parser
from cloth_mg_ros.config.scenes import scene_path

REPO = Path(__file__).resolve().parents[1]
LAUNCH_FILE = REPO / "launch" / "cloth.launch.py"
RVIZ_FILE = REPO / "rviz" / "cloth.rviz"
ARGUMENTS = {"scene", "particles", "solver", "namespace", "use_sim_time", "bag", "loop", "rviz"}


class _Recorded:
    """A stand-in launch action: keeps its keyword arguments."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class DeclareLaunchArgument(_Recorded):
    """launch.actions.DeclareLaunchArgument(name, *, default_value, description)."""

    def __init__(self, name: str, *, default_value: str, description: str) -> None:
        super().__init__(name=name, default_value=default_value, description=description)


def _stub_modules(prefix: Path) -> dict[str, types.ModuleType]:
    """Stand-ins for launch, launch.actions, launch_ros.actions and ament_index_python."""
    mods = {}
    for name in ("launch", "launch.actions", "launch_ros", "launch_ros.actions",
                 "ament_index_python", "ament_index_python.packages"):
        mods[name] = types.ModuleType(name)
    mods["launch"].LaunchDescription = lambda actions: list(actions)
    for cls in ("ExecuteProcess", "OpaqueFunction"):
        setattr(mods["launch.actions"], cls, type(cls, (_Recorded,), {}))
    mods["launch.actions"].DeclareLaunchArgument = DeclareLaunchArgument
    mods["launch_ros.actions"].Node = type("Node", (_Recorded,), {})
    # The source tree has the share layout (launch/, rviz/, config/ side by side).
    mods["ament_index_python.packages"].get_package_share_directory = lambda pkg: str(REPO)
    mods["ament_index_python.packages"].get_package_prefix = lambda pkg: str(prefix)
    return mods


@pytest.fixture
def launch_module(monkeypatch, tmp_path):
    """The launch file loaded as a module over the stand-ins."""
    for name, mod in _stub_modules(tmp_path / "prefix").items():
        monkeypatch.setitem(sys.modules, name, mod)
    spec = importlib.util.spec_from_file_location("cloth_launch_under_test", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _actions(module, **given):
    """The actions the launch file builds for the given arguments (defaults otherwise)."""
    description = module.generate_launch_description()
    declared = {a.kwargs["name"]: a.kwargs["default_value"] for a in description
                if type(a).__name__ == "DeclareLaunchArgument"}
    assert set(given) <= set(declared), set(given) - set(declared)
    (opaque,) = [a for a in description if type(a).__name__ == "OpaqueFunction"]
    context = types.SimpleNamespace(launch_configurations=declared | given)
    return opaque.kwargs["function"](context)


def _console_scripts() -> set[str]:
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values, strict=True):
                if isinstance(key, ast.Constant) and key.value == "console_scripts":
                    return {ast.literal_eval(v).split("=")[0].strip() for v in value.elts}
    raise AssertionError("setup.py declares no console_scripts")


def test_the_launch_file_parses_and_declares_its_arguments(launch_module):
    compile(LAUNCH_FILE.read_text(), str(LAUNCH_FILE), "exec")
    description = launch_module.generate_launch_description()
    declared = {a.kwargs["name"] for a in description
                if type(a).__name__ == "DeclareLaunchArgument"}
    assert declared == ARGUMENTS
    for action in description:
        if type(action).__name__ == "DeclareLaunchArgument":
            assert action.kwargs["description"], action.kwargs["name"]


def test_defaults_start_only_the_node_on_the_walking_scene(launch_module):
    (node,) = _actions(launch_module)
    kw = node.kwargs
    assert (kw["package"], kw["executable"], kw["name"]) == ("cloth_mg_ros", "cloth_node",
                                                             "cloth_node")
    assert kw["executable"] in _console_scripts()
    assert kw["namespace"] == ""
    assert kw["parameters"] == [{"scene": "walking", "use_sim_time": False}]
    assert scene_path("walking").is_file()


def test_bag_namespace_sim_time_and_rviz(launch_module):
    node, player, rviz = _actions(launch_module, scene="running", particles="1200",
                                  solver="mg", namespace="/alice", use_sim_time="true",
                                  bag="run", rviz="true")
    assert node.kwargs["namespace"] == "alice"
    assert node.kwargs["parameters"] == [{"scene": "running", "use_sim_time": True,
                                          "particles": 1200, "solver": "mg"}]
    assert scene_path("running").is_file()

    # The player: `cloth-mg replay` with options the CLI really has.
    cmd = player.kwargs["cmd"]
    assert Path(cmd[0]).name == "cloth-mg" and "cloth-mg" in _console_scripts()
    args = build_parser().parse_args(cmd[1:])
    assert (args.command, args.bag, args.loop, args.clock, args.namespace) == (
        "replay", "run", True, True, "alice")

    # rviz2: in the namespace, with a copy of cloth.rviz whose topics moved there too.
    assert (rviz.kwargs["package"], rviz.kwargs["executable"]) == ("rviz2", "rviz2")
    assert rviz.kwargs["namespace"] == "alice"
    assert rviz.kwargs["parameters"] == [{"use_sim_time": True}]
    flag, config = rviz.kwargs["arguments"]
    assert flag == "-d"
    topics = _display_topics(Path(config))
    assert topics and all(t.startswith("/alice/cloth/") for t in topics.values()), topics

    # No loop, no sim time: neither flag.
    _, player = _actions(launch_module, bag="walk", loop="false")
    args = build_parser().parse_args(player.kwargs["cmd"][1:])
    assert (args.loop, args.clock, args.namespace) == (False, False, "")


def test_a_bad_boolean_argument_is_named(launch_module):
    with pytest.raises(ValueError, match="maybe"):
        _actions(launch_module, rviz="maybe")


def _display_topics(path: Path) -> dict[str, str]:
    """{display class: topic} of an RViz config's displays that subscribe to a topic."""
    config = yaml.safe_load(path.read_text())
    displays = config["Visualization Manager"]["Displays"]
    return {d["Class"]: d["Topic"]["Value"] for d in displays if "Topic" in d}


def _bag_frame_id(name: str) -> str:
    """header.frame_id of the first message of a bundled bag."""
    from cloth_mg_ros.io.bags import bundled_bag, open_reader
    from cloth_mg_ros.ros.ingest import pose_array_from_cdr

    reader = open_reader(bundled_bag(name))
    try:
        _, _, raw = next(iter(reader.messages()))
        return pose_array_from_cdr(bytes(raw))[2]
    finally:
        reader.close()


def test_the_rviz_config_shows_the_node_outputs_in_the_bags_frame():
    pytest.importorskip("rclpy")
    from cloth_mg_ros.ros.parameters import parameter_table, scene_defaults

    config = yaml.safe_load(RVIZ_FILE.read_text())
    frame = config["Visualization Manager"]["Global Options"]["Fixed Frame"]
    assert frame == _bag_frame_id("walk") == "world"
    table = parameter_table(*scene_defaults("walking"))
    topics = _display_topics(RVIZ_FILE)
    assert topics == {
        "rviz_default_plugins/Marker": "/" + table["marker_topic"].default,
        "rviz_default_plugins/MarkerArray": "/" + table["markers_topic"].default,
        "rviz_default_plugins/PointCloud2": "/" + table["points_topic"].default,
    }


def test_the_real_launch_description_builds():
    # (`import launch` alone would find this repository's launch/ folder as a namespace.)
    pytest.importorskip("launch_ros", reason="the ROS 2 launch packages are not installed "
                        "here (not on PyPI): run in a ROS 2 workspace")
    pytest.importorskip("launch.launch_description_sources",
                        reason="the ROS 2 launch package is not installed here")
    from launch import LaunchDescription
    from launch.launch_description_sources import get_launch_description_from_python_launch_file

    description = get_launch_description_from_python_launch_file(str(LAUNCH_FILE))
    assert isinstance(description, LaunchDescription)
    names = {a.name for a in description.get_launch_arguments()}
    assert names == ARGUMENTS
