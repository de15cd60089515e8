"""cloth_node's parameters, generated from the one parameter schema (config.schema): what it
declares, with descriptors, ranges and the scene's defaults, and the checks of values set while
it runs.

`scene_defaults` reads a scene's file (body scenes) or the sheet defaults; `parameter_table`
lists every parameter the node declares with its default, description, range and whether it
needs a restart; `descriptor` turns one entry into an rcl_interfaces ParameterDescriptor;
`check_runtime_change` is the on-set check of the run-time parameters (solver, tolerance,
rate_hz); `check_parameters` checks the values the node starts with; `usage_text` is
`cloth_node --help`.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)

from cloth_mg_ros.config.scenes import load_scene
from cloth_mg_ros.config.schema import (
    AUTO,
    BODY_SCENES,
    INPUT_RELIABILITY,
    PARAMETERS,
    ROS,
    TICK_MODES,
    Numbers,
    SceneParams,
    scene_params,
)
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.sheets import SCENES
from cloth_mg_ros.solvers import check_solver_installed

__all__ = [
    "INPUT_RELIABILITY",
    "MAX_TOLERANCE",
    "TICK_MODES",
    "Param",
    "check_parameters",
    "check_runtime_change",
    "descriptor",
    "parameter_table",
    "scene_defaults",
    "usage_text",
]

MAX_TOLERANCE = PARAMETERS["tolerance"].range[1]
_TYPES = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, bool: ParameterType.PARAMETER_BOOL,
          tuple: ParameterType.PARAMETER_STRING_ARRAY,
          Numbers: ParameterType.PARAMETER_DOUBLE_ARRAY}


@dataclass(frozen=True)
class Param:
    """One declared parameter: default, description, whether it needs a restart, range."""

    default: object
    description: str
    read_only: bool = True
    int_range: tuple[int, int] | None = None
    float_range: tuple[float, float] | None = None
    constraints: str = ""


def scene_defaults(scene: str, overridden: Sequence[str] = ()) -> tuple[bool, SceneParams]:
    """(is a body scene, the defaults of every parameter) for a scene name.

    Sheet scenes (SCENES) get the sheet defaults. A body scene name, alias, config/<name>.yaml
    or .yaml path gets its file's values (config.scenes.load_scene). A name without a file is
    still a body scene when the parameters `overridden` (from --params-file or -p) include
    'garment' (a params file that holds the scene itself); otherwise ClothInputError.
    """
    if scene in SCENES:
        return False, scene_params({"scene": scene}, body=False)
    try:
        return True, load_scene(scene)
    except ClothInputError as exc:
        if "garment" in overridden and "no file" in str(exc):
            return True, scene_params({"scene": scene})
        raise ClothInputError(
            f"unknown scene {scene!r}: sheet scenes are {', '.join(SCENES)}; body scenes "
            f"{', '.join(BODY_SCENES)}, a config/<scene>.yaml or a params .yaml ({exc})"
        ) from None


def parameter_table(body: bool, d: Mapping) -> dict[str, Param]:
    """Every parameter the node declares (the schema's but ROS 2's own), with defaults `d`
    (scene_defaults; the schema's for a key `d` lacks). Body keys are declared for sheet
    scenes too (so any params file is accepted)."""
    table = {}
    for name, p in PARAMETERS.items():
        if p.scope == ROS:
            continue
        default = d[name] if name in d else p.default_for(body)
        if not (p.auto and default == AUTO):
            default = p.type(default)
        numeric = p.type in (int, float) and p.range is not None
        table[name] = Param(
            default, p.description(), read_only=not p.runtime,
            int_range=p.range if numeric and p.type is int else None,
            float_range=p.range if numeric and p.type is float else None,
            constraints="" if p.type is bool or (numeric and not p.auto) else p.values())
    return table


def descriptor(name: str, spec: Param) -> ParameterDescriptor:
    """The ParameterDescriptor of one parameter_table entry: the schema's kind (a number or
    'auto' is dynamically typed: the value's own check refuses anything else), range,
    description and whether it may change while the node runs."""
    p = PARAMETERS.get(name)
    desc = ParameterDescriptor(name=name, type=_TYPES[p.type if p else type(spec.default)],
                               description=spec.description, read_only=spec.read_only,
                               additional_constraints=spec.constraints)
    if p is not None and p.auto:
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
    """Why a run-time change of parameter `name` to `value` is refused (the schema's check:
    an unknown solver, a tolerance out of range...), or None when it is fine."""
    p = PARAMETERS.get(name)
    if p is None or not p.runtime:
        return None
    try:
        p.check(value, f"parameter {name}")
        if name == "solver":  # one this install cannot build would stop the ticks
            check_solver_installed(str(value))
    except ClothInputError as exc:
        return str(exc)
    return None


def check_parameters(values: Mapping[str, object]) -> SceneParams:
    """The node's parameter values (name: value, every declared one or some) checked against
    the schema and converted, over the defaults; ClothInputError names the first bad one."""
    return scene_params(values, "parameter")


def usage_text() -> str:
    """`cloth_node --help`: how to run it and every parameter with its walking-scene default,
    kind, unit, values and whether it may be set while the node runs."""
    _, scene = scene_defaults("walking")
    table = parameter_table(True, scene)
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
    for name, p in PARAMETERS.items():
        default = table[name].default if name in table else scene[name]
        free = p.type is bool or (p.type is str and not p.choices)
        facts = [p.unit, "" if free else p.values(),
                 "may be set while running" if p.runtime else ""]
        text = f"{p.meaning} [{'; '.join(f for f in facts if f)}]".replace(" []", "")
        lines.append(f"  {name} (default {default!r})")
        lines += textwrap.wrap(text, 88, initial_indent="      ", subsequent_indent="      ")
    lines += ["",
              "Services: ~/reset (std_srvs/Trigger): clear the display, re-dress on the next pose;",
              "  gripper/<name>/grasp (std_srvs/SetBool): grasp what is in reach, or let go.",
              "Topics are relative: they follow the node's namespace; /diagnostics stays global."]
    return "\n".join(lines)
