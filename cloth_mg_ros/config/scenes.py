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
from cloth_mg_ros.mesh.garments import MIN_PARTICLES as GARMENT_MIN_PARTICLES
from cloth_mg_ros.sim.grippers import GripperScript
from cloth_mg_ros.sim.sheets import SCENES as SHEET_SCENES

__all__ = ["ALIASES", "AUTO", "BODY_SCENES", "check_garment_size", "gripper_scripts",
           "is_body_scene", "load_scene", "particles_option", "scene_path"]

ALIASES = {"walk": "walking", "brisk_walk": "brisk_walking", "run": "running",
           "jump": "jumping"}
NODE_NAME = "cloth_node"
SCRIPT = "script"  # a scene file's scripted grippers (gripper_scripts)
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
    path, params = _read(name)
    values = {k: v for k, v in params.items() if k != SCRIPT}
    for key in values:
        if key not in PARAMETERS:
            raise ClothInputError(f"scene file {path}: unknown parameter {key!r}; known: "
                                  f"{', '.join(PARAMETERS)}")
    scene = scene_params({"scene": path.stem, **values}, f"scene file {path}")
    if scene.scene in SHEET_SCENES:  # cloth_node runs it as a sheet; `run` would dress it
        raise ClothInputError(f"scene file {path}: scene {scene.scene!r} is a sheet scene: run "
                              f"it as --scene {scene.scene} (options set its parameters)")
    check_garment_size(scene, f"scene file {path}")
    gripper_scripts(name, scene)  # a bad script is refused when the file is loaded
    return scene


def check_garment_size(scene: SceneParams, where: str) -> SceneParams:
    """``scene`` when its particles (a number, not 'auto') can make its garment, else a
    ClothInputError naming `where`, the count and the garment's smallest mesh (before a
    calibration or a bag is read)."""
    smallest = GARMENT_MIN_PARTICLES[scene.garment]
    if scene.particles != AUTO and scene.particles < smallest:
        raise ClothInputError(f"{where}: particles {scene.particles} is too few for a "
                              f"{scene.garment}: at least {smallest}")
    return scene


def gripper_scripts(name: str, scene: SceneParams | None = None) -> list[GripperScript]:
    """The scripted grippers of a scene file: its ``script`` mapping, one entry per gripper
    named in ``grippers``::

        script:
          cuff:
            path: [0.0, 0.60, 0.20, 1.30,  8.5, -0.25, 0.20, 1.30]  # t s, x y z m, ...
            orientation: [0.0, 0.0, 0.0, 1.0]                     # x y z w, optional
            grasp: [0.0]                                           # s
            release: [8.5]                                         # s

    (a ROS params file flattens it to parameters ``script.cuff.path`` and so on, which the
    node does not read: a live robot sends its own poses). Times are seconds after the first
    pose the garment is dressed on. [] for a built-in sheet scene or a file without one;
    ClothInputError naming the file and the gripper for a bad entry."""
    if not is_body_scene(name):
        return []
    path, params = _read(name)
    script = params.get(SCRIPT) or {}
    names = (scene or load_scene(name)).grippers
    if not isinstance(script, dict):
        raise ClothInputError(f"scene file {path}: {SCRIPT} must map gripper names to "
                              "{path, grasp, release}")
    out = []
    for gripper, entry in script.items():
        where = f"scene file {path}: {SCRIPT}.{gripper}"
        if gripper not in names:
            raise ClothInputError(f"{where}: no gripper {gripper!r} in grippers {list(names)}")
        if not isinstance(entry, dict) or "path" not in entry or \
                set(entry) - {"path", "orientation", "grasp", "release"}:
            raise ClothInputError(f"{where} must hold path and optionally orientation, grasp, "
                                  f"release; got {entry!r}")
        try:
            out.append(GripperScript(gripper, entry["path"],
                                     entry.get("orientation", (0.0, 0.0, 0.0, 1.0)),
                                     tuple(entry.get("grasp", ())),
                                     tuple(entry.get("release", ()))))
        except (ClothInputError, TypeError, ValueError) as exc:
            raise ClothInputError(f"{where}: {exc}") from None
    return out


def _read(name: str) -> tuple[Path, dict]:
    """(the scene file's path, its ros__parameters mapping), ClothInputError naming the file
    when it is missing or not a cloth_node params file."""
    path = scene_path(name)
    if not path.is_file():
        known = ", ".join(BODY_SCENES + tuple(ALIASES))
        raise ClothInputError(f"scene {name!r}: no file {path} (body scenes: {known}, or a "
                              f"path to a params .yaml)")
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
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
    return path, params


def particles_option(text: str | None) -> int | str | None:
    """A --particles option: an integer, 'auto', or None; ClothInputError naming anything
    else."""
    if text is None or text == AUTO:
        return text
    try:
        return int(text)
    except ValueError:
        raise ClothInputError(f"--particles must be an integer or 'auto', got {text!r}") from None
