"""Scenes as config files: config/<scene>.yaml, ROS 2 params files the node and the headless
runner both read (``/**: ros__parameters: {...}``: they apply to the node under any name or
namespace; files keyed by the node's default name, ``cloth_node:``, are read too).

A body scene names its motion (``bag``), its ``garment`` and only what it needs: substeps,
the floor. Anything it leaves off takes the default below and costs no time.
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from cloth_mg_ros.errors import ClothInputError

BODY_SCENES = ("walking", "brisk_walking", "running", "jumping")
ALIASES = {"walk": "walking", "brisk_walk": "brisk_walking", "run": "running",
           "jump": "jumping"}
NODE_NAME = "cloth_node"
WILDCARD = "/**"  # a params file's key that matches every node name and namespace

# key: (type, default) of what a body scene may declare.
SCENE_KEYS: dict[str, tuple[type, object]] = {
    "scene": (str, ""),
    "bag": (str, "walk"),
    "topic": (str, "avatar/body_poses"),
    "garment": (str, "dress"),
    "particles": (int, 2400),
    "material": (str, "white-dots-on-blk"),  # a measured light woven (physics.fabrics)
    "solver": (str, "mpcg"),
    "tolerance": (float, 1e-4),
    "levels": (int, 0),
    "substeps": (int, 1),
    "max_substep_motion": (float, 0.05),
    "max_step": (float, 0.1),
    "floor": (bool, True),
    "self_contact": (bool, False),
    "threads": (int, 0),
    # What the scene may cost: particles: auto takes the most particles whose predicted
    # tick fits tick_budget x the pose period, up to max_particles; lod: step down and up
    # the garment's hierarchy while running to keep within the budget (cost_model,
    # garment_levels).
    "tick_budget": (float, 0.7),
    "max_particles": (int, 20000),
    "lod": (bool, False),
}
AUTO = "auto"  # particles: auto (and tolerance: auto, tolerance_model)
# Parameters only the ROS node uses; the headless runner accepts and ignores them.
NODE_ONLY_KEYS = ("tick_mode", "rate_hz", "frame_id", "marker_topic", "markers_topic",
                  "stats_topic", "points_topic", "points_velocity", "mesh_topic",
                  "diagnostics_period", "strain_colours", "max_steps", "dt",
                  "input_reliability", "use_sim_time")


def scene_path(name: str) -> Path:
    """config/<name>.yaml for a scene name (or alias), or the path itself for a .yaml file."""
    from cloth_mg_ros.io.share import config_path

    if name.endswith((".yaml", ".yml")):
        return Path(name)
    return config_path(f"{ALIASES.get(name, name)}.yaml")


def is_body_scene(name: str) -> bool:
    return ALIASES.get(name, name) in BODY_SCENES or name.endswith((".yaml", ".yml"))


def load_scene(name: str) -> dict:
    """The parameters of a body scene, defaults filled in and every value checked.

    Raises ClothInputError naming the file and the key for a missing or unreadable file, a
    file that is not a cloth_node params file, an unknown key or a value of the wrong type.
    """
    path = scene_path(name)
    if not path.is_file():
        known = ", ".join(BODY_SCENES + tuple(ALIASES))
        raise ClothInputError(f"scene {name!r}: no file {path} (body scenes: {known}, or a "
                              f"path to a params .yaml)")
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ClothInputError(f"scene file {path} is not readable YAML: {exc}") from None
    key = next((k for k in (WILDCARD, NODE_NAME, "/" + NODE_NAME)
                if isinstance(data, dict) and k in data), None)
    try:
        params = data[key]["ros__parameters"]
    except (TypeError, KeyError):
        raise ClothInputError(f"scene file {path} must hold '{WILDCARD}: ros__parameters: "
                              f"{{...}}' (a ROS 2 params file)") from None
    if not isinstance(params, dict):
        raise ClothInputError(f"scene file {path}: ros__parameters must be a mapping")
    out = {k: default for k, (_, default) in SCENE_KEYS.items()}
    for key, value in params.items():
        if key in NODE_ONLY_KEYS:
            continue
        if key not in SCENE_KEYS:
            raise ClothInputError(f"scene file {path}: unknown parameter {key!r}; known: "
                                  f"{', '.join(SCENE_KEYS)}")
        out[key] = check_value(key, value, str(path))
    if not out["scene"]:
        out["scene"] = path.stem
    return out


def check_value(key: str, value: object, where: str = "scene") -> object:
    """A scene parameter converted to its type, or ClothInputError naming key and value."""
    kind = SCENE_KEYS[key][0]
    if key == "particles" and value == AUTO:
        return AUTO
    if key == "particles" and isinstance(value, str):
        raise ClothInputError(f"{where}: particles must be an integer or '{AUTO}', got "
                              f"{value!r}")
    if key == "tolerance":
        from cloth_mg_ros.sim.tolerance import check_tolerance

        return check_tolerance(value, f"{where}: tolerance")
    if key == "tick_budget":
        from cloth_mg_ros.budget.cost_model import check_budget

        return check_budget(value, f"{where}: tick_budget")
    if kind is bool:
        if not isinstance(value, bool):
            raise ClothInputError(f"{where}: {key} must be true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ClothInputError(f"{where}: {key} must be an integer, got {value!r}")
        if value < 0:
            raise ClothInputError(f"{where}: {key} must not be negative, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ClothInputError(f"{where}: {key} must be a number, got {value!r}")
        if not math.isfinite(value) or value <= 0:
            raise ClothInputError(f"{where}: {key} must be positive and finite, got {value!r}")
        return float(value)
    if not isinstance(value, str) or not value:
        raise ClothInputError(f"{where}: {key} must be a non-empty string, got {value!r}")
    return value
