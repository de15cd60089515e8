"""Scenes as config files: config/<scene>.yaml, ROS 2 params files the node and the headless
runner both read (``/**: ros__parameters: {...}``: they apply to the node under any name or
namespace; files keyed by the node's default name, ``cloth_node:``, are read too).

A body scene names its motion (``bag``), its ``garment`` and only what it needs: substeps,
the floor. Anything it leaves off takes the schema's default (config.schema, where every
parameter, its kind, range and meaning is declared) and costs no time.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from cloth_mg_ros.config.schema import (
    AUTO,
    BODY_SCENES,
    PARAMETERS,
    SceneParams,
    scene_params,
)
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.share import config_path

__all__ = ["ALIASES", "AUTO", "BODY_SCENES", "is_body_scene", "load_scene", "scene_path"]

ALIASES = {"walk": "walking", "brisk_walk": "brisk_walking", "run": "running",
           "jump": "jumping"}
NODE_NAME = "cloth_node"
WILDCARD = "/**"  # a params file's key that matches every node name and namespace


def scene_path(name: str) -> Path:
    """config/<name>.yaml for a scene name (or alias), or the path itself for a .yaml file."""
    if name.endswith((".yaml", ".yml")):
        return Path(name)
    return config_path(f"{ALIASES.get(name, name)}.yaml")


def is_body_scene(name: str) -> bool:
    return ALIASES.get(name, name) in BODY_SCENES or name.endswith((".yaml", ".yml"))


def load_scene(name: str) -> SceneParams:
    """The parameters of a body scene (every parameter of the schema: read them as
    attributes, ``params.garment``), defaults filled in and every value checked.

    Raises ClothInputError naming the file and the key for a missing or unreadable file, a
    file that is not a cloth_node params file, an unknown key or a bad value. A file that does
    not set ``scene`` takes its file's name.
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
    for key in params:
        if key not in PARAMETERS:
            raise ClothInputError(f"scene file {path}: unknown parameter {key!r}; known: "
                                  f"{', '.join(PARAMETERS)}")
    return scene_params({"scene": path.stem, **params}, f"scene file {path}")
