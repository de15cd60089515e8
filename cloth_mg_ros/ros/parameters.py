"""cloth_node's parameters: what it declares, with descriptors, ranges and the scene's
defaults, and the checks of values set while it runs.

`scene_defaults` reads a scene's file (body scenes) or the sheet defaults; `parameter_table`
lists every parameter with its default, description, range and whether it needs a restart;
`descriptor` turns one entry into an rcl_interfaces ParameterDescriptor;
`check_runtime_change` is the on-set check of the run-time parameters (solver, tolerance).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)

from cloth_mg_ros.config.scenes import AUTO, BODY_SCENES, SCENE_KEYS, load_scene
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import MATERIALS
from cloth_mg_ros.sim.sheets import SCENES
from cloth_mg_ros.sim.tolerance import check_tolerance
from cloth_mg_ros.solvers import SOLVERS

__all__ = [
    "INPUT_RELIABILITY",
    "MAX_TOLERANCE",
    "TICK_MODES",
    "Param",
    "check_runtime_change",
    "descriptor",
    "parameter_table",
    "scene_defaults",
    "usage_text",
]

TICK_MODES = ("message", "timer")
INPUT_RELIABILITY = ("best_effort", "reliable")
MAX_TOLERANCE = 0.5


@dataclass(frozen=True)
class Param:
    """One declared parameter: default, description, whether it needs a restart, range."""

    default: object
    description: str
    read_only: bool = True
    int_range: tuple[int, int] | None = None
    float_range: tuple[float, float] | None = None
    constraints: str = ""


def scene_defaults(scene: str, overridden: Sequence[str] = ()) -> tuple[bool, dict]:
    """(is a body scene, the defaults of every scene key) for a scene name.

    Sheet scenes (SCENES) get the sheet defaults. A body scene name, alias, config/<name>.yaml
    or .yaml path gets its file's values (scene_config.load_scene). A name without a file is
    still a body scene when the parameters `overridden` (from --params-file or -p) include
    'garment' (a params file that holds the scene itself); otherwise ClothInputError.
    """
    defaults = {k: default for k, (_, default) in SCENE_KEYS.items()}
    if scene in SCENES:
        defaults.update(scene=scene, solver="pcg")
        return False, defaults
    try:
        return True, load_scene(scene)
    except ClothInputError as exc:
        if "garment" in overridden and "no file" in str(exc):
            defaults["scene"] = scene
            return True, defaults
        raise ClothInputError(
            f"unknown scene {scene!r}: sheet scenes are {', '.join(SCENES)}; body scenes "
            f"{', '.join(BODY_SCENES)}, a config/<scene>.yaml or a params .yaml ({exc})"
        ) from None


def parameter_table(body: bool, d: dict) -> dict[str, Param]:
    """Every parameter the node declares, with defaults `d` (scene_defaults) for the scene
    keys. Body keys are declared for sheet scenes too (so any params file is accepted)."""
    sheets, bodies = ", ".join(SCENES), ", ".join(BODY_SCENES)
    return {
        "scene": Param(d["scene"], f"scene: a sheet ({sheets}) or a body scene ({bodies}, "
                        f"config/<scene>.yaml or a params .yaml path)"),
        "bag": Param(d["bag"], "the scene's bag of body poses (for reference: the node "
                      "listens on `topic`; play the bag with `cloth-mg replay`)"),
        "topic": Param(d["topic"], "geometry_msgs/PoseArray input topic: the avatar's body "
                       "poses (body scenes)"),
        "input_reliability": Param("best_effort", "QoS reliability of the pose subscription: "
                                   "best_effort matches reliable and best-effort (sensor "
                                   "data) publishers alike; reliable matches reliable ones "
                                   "only", constraints="best_effort or reliable"),
        "garment": Param(d["garment"], "garment of a body scene",
                          constraints="skirt, dress, cape or top"),
        "particles": Param(d["particles"], "approximate number of cloth particles, or 'auto' "
                           "(body scenes): the most whose predicted tick fits tick_budget x "
                           "the pose period (cost model, calibrated once per machine)",
                           constraints="an integer 16..200000 or 'auto'"),
        "tick_budget": Param(float(d["tick_budget"]), "body scenes: fraction of the pose "
                             "period a tick may take (particles auto, lod)",
                             float_range=(1e-3, 1.0)),
        "max_particles": Param(int(d["max_particles"]), "body scenes: particles auto takes "
                               "at most this many (what the scene needs)",
                               int_range=(16, 200_000)),
        "lod": Param(bool(d["lod"]), "body scenes: live level of detail: step down the "
                     "garment's hierarchy when ticks overrun the budget, back up when they "
                     "stay well under it"),
        "material": Param(d["material"], "cloth material: a measured fabric or one of the "
                          "paper's Table 2 set (cloth-mg materials)",
                           constraints=f"one of {', '.join(MATERIALS)}"),
        "solver": Param(d["solver"], "linear solver of each implicit step (may be changed "
                         "while running: rebuilds the solver)", read_only=False,
                         constraints=f"one of {', '.join(SOLVERS)}"),
        "tolerance": Param(d["tolerance"] if d["tolerance"] == AUTO else float(d["tolerance"]),
                           "relative residual the linear solve must reach, or 'auto' (body "
                           "scenes): each level solves to the tolerance its time step allows, "
                           "measured with the cost model (may be changed while running; "
                           "'auto' only if the node started with it)", read_only=False,
                           float_range=(1e-10, MAX_TOLERANCE),
                           constraints=f"a number in (0, {MAX_TOLERANCE:g}] or 'auto'"),
        "levels": Param(d["levels"], "multigrid hierarchy levels (0: as many as the mesh "
                         "size calls for)", int_range=(0, 7)),
        "substeps": Param(d["substeps"], "body scenes: at least this many steps per tick",
                          int_range=(1, 64)),
        "max_substep_motion": Param(float(d["max_substep_motion"]), "body scenes: more "
                                    "steps while a capsule end that can reach the cloth moves "
                                    "further than this per step, m", float_range=(1e-3, 1.0)),
        "max_step": Param(float(d["max_step"]), "body scenes: no step longer than this, s "
                          "(a tick that coalesces several pose messages takes longer steps "
                          "up to this)", float_range=(1e-3, 0.25)),
        "threads": Param(int(d["threads"]), "simulation threads (0: every core); the "
                         "cloth follows this number bit for bit, not the machine's timing",
                         int_range=(0, 1024)),
        "floor": Param(bool(d["floor"]), "body scenes: a ground plane at z = 0"),
        "self_contact": Param(bool(d["self_contact"]), "body scenes: cloth-cloth repulsion"),
        "tick_mode": Param("message" if body else "timer", "message: each tick advances "
                           "the cloth to the newest pose message, through every one received "
                           "since the last tick (body scenes); timer: one tick every "
                           "1/rate_hz s", constraints="message or timer"),
        "rate_hz": Param(30.0, "timer rate: ticks per second of wall time, Hz (may be "
                          "changed while running)", read_only=False, float_range=(0.1, 1000.0)),
        "dt": Param(1.0 / 60.0, "sheet scenes: simulation time step, s",
                     float_range=(1e-5, 0.1)),
        "frame_id": Param("world", "frame of everything published (z up, metres) when the "
                          "body poses' header.frame_id is empty (body scenes publish in "
                          "the poses' frame), and of sheet scenes", constraints="non-empty"),
        "marker_topic": Param("cloth/marker", "visualization_msgs/Marker output: the cloth "
                              "(relative names move with the node's namespace)"),
        "markers_topic": Param("cloth/markers", "visualization_msgs/MarkerArray output: the "
                               "avatar's capsules, the scene's colliders and a caption with the "
                               "node's figures (the cloth is on marker_topic alone, so it is "
                               "drawn once)"),
        "stats_topic": Param("cloth/stats", "diagnostic_msgs/DiagnosticArray output, per tick"),
        "points_topic": Param("cloth/points", "sensor_msgs/PointCloud2 output: the particles "
                              "(x, y, z float32, m; with points_velocity also vx, vy, vz, m/s)"),
        "points_velocity": Param(False, "add the particles' velocities to the point cloud"),
        "mesh_topic": Param("cloth/mesh", "shape_msgs/Mesh output: the garment's triangles "
                            "and vertices (in the markers' frame)"),
        "diagnostics_period": Param(1.0, "seconds between statuses on /diagnostics (the "
                                    "aggregator's topic; per-tick figures stay on "
                                    "stats_topic)", float_range=(0.1, 60.0)),
        "marker_lifetime": Param(0.0, "s a display keeps each marker after its stamp (0: "
                                 "until replaced or deleted; the node deletes its markers at "
                                 "shutdown, and a lifetime clears them also when the node is "
                                 "killed)", float_range=(0.0, 3600.0)),
        "strain_colours": Param(False, "colour the cloth by stretch (per-vertex colours)"),
        "max_steps": Param(0, "exit after this many ticks (0: run until shut down)",
                            int_range=(0, 2**31 - 1)),
    }


def descriptor(name: str, spec: Param) -> ParameterDescriptor:
    """The ParameterDescriptor of one parameter_table entry."""
    kinds = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
             float: ParameterType.PARAMETER_DOUBLE, bool: ParameterType.PARAMETER_BOOL}
    desc = ParameterDescriptor(name=name, type=kinds[type(spec.default)],
                               description=spec.description, read_only=spec.read_only,
                               additional_constraints=spec.constraints)
    if name in ("particles", "tolerance"):  # a number or the string 'auto': checked by the node
        desc.type = ParameterType.PARAMETER_NOT_SET
        desc.dynamic_typing = True
    if spec.int_range is not None:
        desc.integer_range = [IntegerRange(from_value=spec.int_range[0],
                                           to_value=spec.int_range[1], step=1)]
    if spec.float_range is not None:
        desc.floating_point_range = [FloatingPointRange(from_value=spec.float_range[0],
                                                        to_value=spec.float_range[1], step=0.0)]
    return desc


def check_runtime_change(name: str, value: object) -> str | None:
    """Why a run-time change of parameter `name` to `value` is refused, or None when it is
    fine (ranges and types were already checked against the descriptors)."""
    if name == "solver" and value not in SOLVERS:
        return f"unknown solver {value!r}; choose one of {', '.join(SOLVERS)}"
    if name == "tolerance":
        try:
            check_tolerance(value, "tolerance", MAX_TOLERANCE)
        except ClothInputError as exc:
            return str(exc)
    return None


def usage_text() -> str:
    """`cloth_node --help`: how to run it and every parameter with its walking-scene default."""
    import textwrap

    _, defaults = scene_defaults("walking")
    lines = [("usage: cloth_node [--ros-args [--params-file FILE] [-p NAME:=VALUE ...] "
             "[-r __ns:=/NAMESPACE] ...]"),
             "",
             ("A garment draped over a moving avatar, stepped with a faithful multigrid and "
             "published for RViz."),
             "Examples:",
             "  cloth_node --ros-args --params-file config/walking.yaml",
             "  cloth_node --ros-args -p scene:=running -p particles:=1200 -r __ns:=/alice",
             "  ros2 launch cloth_mg_ros cloth.launch.py bag:=walk rviz:=true",
             "",
             "Parameters (defaults of the walking scene; a scene file sets its own):"]
    for name, spec in parameter_table(True, defaults).items():
        extra = "" if spec.read_only else " [may be set while running]"
        text = f"{spec.description}{extra}"
        lines.append(f"  {name} (default {spec.default!r})")
        lines += textwrap.wrap(text, 88, initial_indent="      ", subsequent_indent="      ")
    lines += ["  use_sim_time (default False)",
              "      ROS 2's own: take time from /clock (`cloth-mg replay --clock` publishes it)",
              "",
              "Services: ~/reset (std_srvs/Trigger): clear the display, re-dress on the next pose.",
              "Topics are relative: they follow the node's namespace; /diagnostics stays global."]
    return "\n".join(lines)

