"""launch/cloth.launch.py and rviz/cloth.rviz.

The `launch` and `launch_ros` packages are not on the package index this project installs
from, so the launch file is loaded with small stand-ins for them that record the actions it
builds: what it starts (the node with which parameters, the player with which command line,
rviz2 with which config) is checked against the package itself (its console scripts, its
CLI's options, its scene files, its node's topic names). The real description is not built
here: a test that could only skip on every machine the project installs itself is none (in a
ROS 2 workspace, `ros2 launch cloth_mg_ros cloth.launch.py --show-args` lists the arguments).
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
from cloth_mg_ros.config.schema import PARAMETERS

REPO = Path(__file__).resolve().parents[1]
LAUNCH_FILE = REPO / "launch" / "cloth.launch.py"
RVIZ_FILE = REPO / "rviz" / "cloth.rviz"
ARGUMENTS = {"scene", "particles", "solver", "namespace", "params_file", "topic", "frame_id",
             "managed", "use_sim_time", "bag", "loop", "rviz"}


class _Recorded:
    """A stand-in launch action: keeps its keyword arguments."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class DeclareLaunchArgument(_Recorded):
    """launch.actions.DeclareLaunchArgument(name, *, default_value, description)."""

    def __init__(self, name: str, *, default_value: str, description: str) -> None:
        super().__init__(name=name, default_value=default_value, description=description)


class _Matcher:
    """launch.events.matches_action(action): keeps the action it matches."""

    def __init__(self, action) -> None:
        self.action = action


def _stub_modules(prefix: Path) -> dict[str, types.ModuleType]:
    """Stand-ins for launch, launch.actions, launch.events, launch_ros.actions,
    launch_ros.event_handlers, launch_ros.events.lifecycle and ament_index_python (the
    launch file takes lifecycle_msgs, installed here, as it is)."""
    mods = {}
    for name in ("launch", "launch.actions", "launch.events", "launch_ros",
                 "launch_ros.actions", "launch_ros.event_handlers", "launch_ros.events",
                 "launch_ros.events.lifecycle", "ament_index_python",
                 "ament_index_python.packages"):
        mods[name] = types.ModuleType(name)
    mods["launch"].LaunchDescription = lambda actions: list(actions)
    for cls in ("ExecuteProcess", "OpaqueFunction", "EmitEvent", "RegisterEventHandler"):
        setattr(mods["launch.actions"], cls, type(cls, (_Recorded,), {}))
    mods["launch.actions"].DeclareLaunchArgument = DeclareLaunchArgument
    mods["launch.events"].matches_action = _Matcher
    for cls in ("Node", "LifecycleNode"):
        setattr(mods["launch_ros.actions"], cls, type(cls, (_Recorded,), {}))
    mods["launch_ros.event_handlers"].OnStateTransition = type("OnStateTransition",
                                                               (_Recorded,), {})
    mods["launch_ros.events.lifecycle"].ChangeState = type("ChangeState", (_Recorded,), {})
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
    # No scene given: the node's own default, walking.
    assert kw["parameters"] == [{"use_sim_time": False}]
    assert PARAMETERS["scene"].default == "walking" and scene_path("walking").is_file()


def test_bag_namespace_sim_time_and_rviz(launch_module):
    node, player, rviz = _actions(launch_module, scene="running", particles="1200",
                                  solver="mg", namespace="/alice", use_sim_time="true",
                                  bag="run", rviz="true")
    assert node.kwargs["namespace"] == "alice"
    assert node.kwargs["parameters"] == [{"use_sim_time": True, "scene": "running",
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

    # frame_id moves RViz's fixed frame (a copy of cloth.rviz; the topics stay put).
    node, rviz = _actions(launch_module, frame_id="map", rviz="true")
    config = rviz.kwargs["arguments"][1]
    assert Path(config) != RVIZ_FILE and _fixed_frame(Path(config)) == "map"
    assert _display_topics(Path(config)) == _display_topics(RVIZ_FILE)
    assert node.kwargs["parameters"] == [{"use_sim_time": False, "frame_id": "map"}]
    # Both: the namespace's topics in the frame's view.
    _, rviz = _actions(launch_module, frame_id="map", namespace="alice", rviz="true")
    config = Path(rviz.kwargs["arguments"][1])
    assert _fixed_frame(config) == "map"
    assert all(t.startswith("/alice/cloth/") for t in _display_topics(config).values())
    # The same arguments again share that file: launches leave one per view, not one each.
    _, again = _actions(launch_module, frame_id="map", namespace="alice", rviz="true")
    assert Path(again.kwargs["arguments"][1]) == config
    # The default frame: the installed file itself.
    _, rviz = _actions(launch_module, rviz="true")
    assert rviz.kwargs["arguments"] == ["-d", str(RVIZ_FILE)]


def _fixed_frame(path: Path) -> str:
    config = yaml.safe_load(path.read_text())
    return config["Visualization Manager"]["Global Options"]["Fixed Frame"]


def test_params_file_topic_and_frame_reach_the_node(launch_module, tmp_path):
    params = tmp_path / "my.yaml"
    params.write_text("/**:\n  ros__parameters:\n    scene: running\n")
    (node,) = _actions(launch_module, params_file=str(params), topic="mocap/poses",
                       frame_id="map", particles="900")
    # The file first, the arguments after it (rclpy applies them in order: they win); no
    # scene argument, so the file's scene stands.
    assert node.kwargs["parameters"] == [str(params), {
        "use_sim_time": False, "particles": 900, "topic": "mocap/poses", "frame_id": "map"}]
    table = {p.name for p in PARAMETERS.values()}
    assert {"topic", "frame_id", "particles", "use_sim_time"} <= table


def test_managed_starts_a_lifecycle_node_and_brings_it_up(launch_module):
    from lifecycle_msgs.msg import Transition

    actions = _actions(launch_module, managed="true", namespace="alice", bag="walk")
    handler, node, configure, player = actions
    assert type(node).__name__ == "LifecycleNode"
    kw = node.kwargs
    assert (kw["package"], kw["executable"], kw["name"], kw["namespace"]) == (
        "cloth_mg_ros", "cloth_node_managed", "cloth_node", "alice")
    assert kw["executable"] in _console_scripts()
    assert kw["parameters"] == [{"use_sim_time": False}]
    # configure at once, for this node ...
    assert type(configure).__name__ == "EmitEvent"
    event = configure.kwargs["event"]
    assert event.kwargs["transition_id"] == Transition.TRANSITION_CONFIGURE
    assert event.kwargs["lifecycle_node_matcher"].action is node
    # ... and activate once the configure ended in 'inactive' (the handler is registered
    # before the node starts, so the transition cannot pass unseen).
    assert type(handler).__name__ == "RegisterEventHandler"
    (on_state,) = handler.args
    assert on_state.kwargs["target_lifecycle_node"] is node
    assert (on_state.kwargs["start_state"], on_state.kwargs["goal_state"]) == (
        "configuring", "inactive")
    (activate,) = on_state.kwargs["entities"]
    assert activate.kwargs["event"].kwargs["transition_id"] == Transition.TRANSITION_ACTIVATE
    assert activate.kwargs["event"].kwargs["lifecycle_node_matcher"].action is node
    assert "replay" in player.kwargs["cmd"]
    # managed:=false (the default) is the plain node.
    (plain,) = _actions(launch_module, managed="false")
    assert type(plain).__name__ == "Node" and plain.kwargs["executable"] == "cloth_node"


def test_particles_auto_reaches_the_node(launch_module):
    """particles:=auto is the schema's 'auto' (before: a bare ValueError from int())."""
    (node,) = _actions(launch_module, particles="auto")
    assert node.kwargs["parameters"] == [{"use_sim_time": False, "particles": "auto"}]
    assert PARAMETERS["particles"].check("auto") == "auto"
    with pytest.raises(ValueError, match="particles must be an integer or 'auto', got 'lots'"):
        _actions(launch_module, particles="lots")


def test_the_player_publishes_on_the_nodes_topic_and_waits_for_its_start(launch_module):
    """topic:=X with bag:=...: the player publishes the bag's poses on X, where the node
    listens (before: on the bag's own topic, so the node never got a pose), under the
    namespace as the node's relative topic is; it waits for a subscriber as long as a node
    may take to start (ros.processes.START_TIMEOUT_S; before: 120 s)."""
    from cloth_mg_ros.ros.processes import START_TIMEOUT_S

    node, player = _actions(launch_module, bag="walk", topic="mocap/poses", namespace="alice")
    assert node.kwargs["parameters"] == [{"use_sim_time": False, "topic": "mocap/poses"}]
    args = build_parser().parse_args(player.kwargs["cmd"][1:])
    assert (args.topic_out, args.namespace, args.wait) == ("mocap/poses", "alice",
                                                           START_TIMEOUT_S)
    # no topic argument: the bag's own topic, the scene's default (avatar/body_poses)
    _, player = _actions(launch_module, bag="walk")
    assert build_parser().parse_args(player.kwargs["cmd"][1:]).topic_out is None


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

