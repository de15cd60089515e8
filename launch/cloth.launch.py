"""Launch cloth_node, and optionally a bag player and RViz2.

    ros2 launch cloth_mg_ros cloth.launch.py                    # the walking dress; waits for poses
    ros2 launch cloth_mg_ros cloth.launch.py bag:=walk rviz:=true  # play bags/walk in a loop
    ros2 launch cloth_mg_ros cloth.launch.py scene:=running particles:=1200 solver:=mg bag:=run
    ros2 launch cloth_mg_ros cloth.launch.py namespace:=alice use_sim_time:=true bag:=walk
    ros2 launch cloth_mg_ros cloth.launch.py managed:=true bag:=walk   # configured, activated
    ros2 launch cloth_mg_ros cloth.launch.py params_file:=my.yaml frame_id:=map rviz:=true

Arguments (`ros2 launch cloth_mg_ros cloth.launch.py --show-args` lists them):
    scene         a body scene (walking, brisk_walking, running, jumping), a sheet scene, or a
                  params .yaml path ('' : the params file's, else walking)
    particles     cloth particles, or auto ('' : the scene's)
    solver        mpcg, mg, pcg, ... ('' : the scene's)
    namespace     the node's namespace; its relative topics (avatar/body_poses, cloth/...) move
                  with it, and so do the player's and RViz's
    params_file   a params .yaml for the node ('' : none); the arguments that set a parameter
                  (scene, particles, solver, topic, frame_id, use_sim_time) override it
    topic         the body poses' input topic ('' : the scene's, avatar/body_poses); the
                  player publishes the bag's poses there (`cloth-mg replay --topic-out`)
    frame_id      the frame the node publishes in when the poses name none, and RViz's fixed
                  frame ('' : the node's, world: the bundled bags' frame)
    managed       start cloth_node as a managed (lifecycle) node and bring it up: a configure
                  transition, then activate once it is inactive (default false)
    use_sim_time  take time from /clock (the player publishes it: `cloth-mg replay --clock`)
    bag           a bundled bag (walk, brisk_walk, run, jump) or a bag path to play with
                  `cloth-mg replay` ('' : none; poses come from elsewhere)
    loop          play the bag again and again (default true)
    rviz          start rviz2 with share/cloth_mg_ros/rviz/cloth.rviz (default false): a copy
                  of it when the namespace or frame_id asks for other topics or fixed frame
"""

import hashlib
import os
import shutil
import tempfile

from ament_index_python.packages import get_package_prefix, get_package_share_directory
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    ExecuteProcess,
    OpaqueFunction,
    RegisterEventHandler,
)
from launch.events import matches_action
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from lifecycle_msgs.msg import Transition

from cloth_mg_ros.config.scenes import particles_option
from cloth_mg_ros.ros.processes import START_TIMEOUT_S

PACKAGE = "cloth_mg_ros"
RVIZ_FRAME = "world"  # cloth.rviz's fixed frame: the bundled bags' (and the node's default)
ARGUMENTS = {
    "scene": ("", "body scene, sheet scene or params .yaml path ('' : the params file's, "
                  "else walking)"),
    "particles": ("", "cloth particles or auto ('' : the scene's)"),
    "solver": ("", "linear solver ('' : the scene's)"),
    "namespace": ("", "namespace of the node, the player and RViz"),
    "params_file": ("", "params .yaml for the node ('' : none); the other arguments override "
                        "it"),
    "topic": ("", "the body poses' input topic ('' : the scene's)"),
    "frame_id": ("", "frame when the poses name none, and RViz's fixed frame ('' : world)"),
    "managed": ("false", "start the node managed (lifecycle) and configure, then activate it"),
    "use_sim_time": ("false", "take time from /clock (the player publishes it)"),
    "bag": ("", "bag to play with cloth-mg replay: walk, brisk_walk, run, jump or a path"),
    "loop": ("true", "play the bag again and again"),
    "rviz": ("false", "start rviz2 with the package's cloth.rviz"),
}


def _truthy(value: str) -> bool:
    if value.lower() in ("true", "1", "yes", "on"):
        return True
    if value.lower() in ("false", "0", "no", "off", ""):
        return False
    raise ValueError(f"expected true or false, got {value!r}")


def _executable(name: str) -> str:
    """The package's console script: lib/<package>/ in a colcon install, else on PATH."""
    try:
        candidate = os.path.join(get_package_prefix(PACKAGE), "lib", PACKAGE, name)
        if os.access(candidate, os.X_OK):
            return candidate
    except LookupError:
        pass
    return shutil.which(name) or name


def _rviz_config(share: str, namespace: str, frame_id: str = "") -> str:
    """The installed cloth.rviz, or a copy whose topics live under `namespace` and whose
    fixed frame is `frame_id` ('' : the file's, RVIZ_FRAME)."""
    path = os.path.join(share, "rviz", "cloth.rviz")
    if not namespace and frame_id in ("", RVIZ_FRAME):
        return path
    with open(path, encoding="utf-8") as f:
        text = f.read()
    if namespace:
        text = text.replace("Value: /cloth/", f"Value: /{namespace}/cloth/")
    if frame_id:
        text = text.replace(f"Fixed Frame: {RVIZ_FRAME}\n", f"Fixed Frame: {frame_id}\n")
    # named by its content, so every launch with these arguments shares one file instead of
    # leaving a new one in the temporary directory each time; written whole, then renamed, so
    # a launch beside another never reads half of it
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = os.path.join(tempfile.gettempdir(), f"cloth_mg_ros_{digest}.rviz")
    if not os.path.isfile(path):
        with tempfile.NamedTemporaryFile("w", suffix=".rviz", prefix="cloth_", delete=False,
                                         dir=tempfile.gettempdir()) as out:
            out.write(text)
        os.replace(out.name, path)
    return path


def _node_parameters(arg: dict) -> list:
    """The node's parameters: the params file (when given), then the arguments (they win)."""
    params = {"use_sim_time": _truthy(arg["use_sim_time"])}
    if arg["scene"]:
        params["scene"] = arg["scene"]
    if arg["particles"]:
        params["particles"] = particles_option(arg["particles"].strip().lower())
    for name in ("solver", "topic", "frame_id"):
        if arg[name]:
            params[name] = arg[name]
    return ([arg["params_file"]] if arg["params_file"] else []) + [params]


def _managed_node(namespace: str, parameters: list) -> list:
    """cloth_node_managed, a configure transition at start and an activate one as soon as
    the configure ends in 'inactive' (the scene loaded, calibrated and warmed up)."""
    node = LifecycleNode(package=PACKAGE, executable="cloth_node_managed", name="cloth_node",
                         namespace=namespace, parameters=parameters, output="screen",
                         emulate_tty=True)

    def change(transition_id: int) -> EmitEvent:
        return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                           transition_id=transition_id))

    activate = RegisterEventHandler(OnStateTransition(
        target_lifecycle_node=node, start_state="configuring", goal_state="inactive",
        entities=[change(Transition.TRANSITION_ACTIVATE)]))
    return [activate, node, change(Transition.TRANSITION_CONFIGURE)]


def _actions(context):
    arg = {name: context.launch_configurations[name] for name in ARGUMENTS}
    namespace = arg["namespace"].strip("/")
    sim_time = _truthy(arg["use_sim_time"])
    share = get_package_share_directory(PACKAGE)
    parameters = _node_parameters(arg)
    if _truthy(arg["managed"]):
        actions = _managed_node(namespace, parameters)
    else:
        actions = [Node(package=PACKAGE, executable="cloth_node", name="cloth_node",
                        namespace=namespace, parameters=parameters, output="screen",
                        emulate_tty=True)]
    if arg["bag"]:
        # the player waits for the node as long as a node may take to start (its first run
        # compiles the kernels and calibrates the cost model)
        cmd = [_executable("cloth-mg"), "replay", arg["bag"], "--wait", f"{START_TIMEOUT_S:g}"]
        if _truthy(arg["loop"]):
            cmd.append("--loop")
        if sim_time:
            cmd.append("--clock")
        if namespace:
            cmd += ["--namespace", namespace]
        if arg["topic"]:  # the node listens there, not on the bag's own topic
            cmd += ["--topic-out", arg["topic"]]
        actions.append(ExecuteProcess(cmd=cmd, name="cloth_replay", output="screen"))
    if _truthy(arg["rviz"]):
        actions.append(Node(package="rviz2", executable="rviz2", name="rviz2",
                            namespace=namespace, output="screen",
                            arguments=["-d", _rviz_config(share, namespace,
                                                          arg["frame_id"])],
                            parameters=[{"use_sim_time": sim_time}]))
    return actions


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, (default, text) in ARGUMENTS.items()]
        + [OpaqueFunction(function=_actions)])
