"""Launch cloth_node, and optionally a bag player and RViz2.

    ros2 launch cloth_mg_ros cloth.launch.py                    # the walking dress; waits for poses
    ros2 launch cloth_mg_ros cloth.launch.py bag:=walk rviz:=true  # play bags/walk in a loop
    ros2 launch cloth_mg_ros cloth.launch.py scene:=running particles:=1200 solver:=mg bag:=run
    ros2 launch cloth_mg_ros cloth.launch.py namespace:=alice use_sim_time:=true bag:=walk

Arguments (`ros2 launch cloth_mg_ros cloth.launch.py --show-args` lists them):
    scene         a body scene (walking, brisk_walking, running, jumping), a sheet scene, or a
                  params .yaml path (default walking)
    particles     cloth particles ('' : the scene's)
    solver        mpcg, mg, pcg, ... ('' : the scene's)
    namespace     the node's namespace; its relative topics (avatar/body_poses, cloth/...) move
                  with it, and so do the player's and RViz's
    use_sim_time  take time from /clock (the player publishes it: `cloth-mg replay --clock`)
    bag           a bundled bag (walk, brisk_walk, run, jump) or a bag path to play with
                  `cloth-mg replay` ('' : none; poses come from elsewhere)
    loop          play the bag again and again (default true)
    rviz          start rviz2 with share/cloth_mg_ros/rviz/cloth.rviz (default false)
"""

import os
import shutil
import tempfile

from ament_index_python.packages import get_package_prefix, get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch_ros.actions import Node

PACKAGE = "cloth_mg_ros"
ARGUMENTS = {
    "scene": ("walking", "body scene, sheet scene or params .yaml path"),
    "particles": ("", "cloth particles ('' : the scene's)"),
    "solver": ("", "linear solver ('' : the scene's)"),
    "namespace": ("", "namespace of the node, the player and RViz"),
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


def _rviz_config(share: str, namespace: str) -> str:
    """The installed cloth.rviz, or a copy whose topics live under `namespace`."""
    path = os.path.join(share, "rviz", "cloth.rviz")
    if not namespace:
        return path
    with open(path, encoding="utf-8") as f:
        text = f.read().replace("Value: /cloth/", f"Value: /{namespace}/cloth/")
    with tempfile.NamedTemporaryFile("w", suffix=".rviz", prefix="cloth_", delete=False) as out:
        out.write(text)
    return out.name


def _actions(context):
    arg = {name: context.launch_configurations[name] for name in ARGUMENTS}
    namespace = arg["namespace"].strip("/")
    sim_time = _truthy(arg["use_sim_time"])
    share = get_package_share_directory(PACKAGE)
    params = {"scene": arg["scene"], "use_sim_time": sim_time}
    if arg["particles"]:
        params["particles"] = int(arg["particles"])
    if arg["solver"]:
        params["solver"] = arg["solver"]
    actions = [Node(package=PACKAGE, executable="cloth_node", name="cloth_node",
                    namespace=namespace, parameters=[params], output="screen",
                    emulate_tty=True)]
    if arg["bag"]:
        cmd = [_executable("cloth-mg"), "replay", arg["bag"], "--wait", "120"]
        if _truthy(arg["loop"]):
            cmd.append("--loop")
        if sim_time:
            cmd.append("--clock")
        if namespace:
            cmd += ["--namespace", namespace]
        actions.append(ExecuteProcess(cmd=cmd, name="cloth_replay", output="screen"))
    if _truthy(arg["rviz"]):
        actions.append(Node(package="rviz2", executable="rviz2", name="rviz2",
                            namespace=namespace, output="screen",
                            arguments=["-d", _rviz_config(share, namespace)],
                            parameters=[{"use_sim_time": sim_time}]))
    return actions


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, (default, text) in ARGUMENTS.items()]
        + [OpaqueFunction(function=_actions)])
