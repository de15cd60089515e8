"""A live session's settings: what cloth_node's parameters fix at start, checked before any
work (`SessionSettings`). The node reads its parameters and checks them against the schema
(ros.parameters); what the schema cannot tell alone raises ClothInputError naming the
parameter and the value. The session and its scenes (ros.session, ros.body_scene,
ros.sheet_scene) never read a ROS parameter themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

from cloth_mg_ros.config.schema import PARAMETERS, SceneParams
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import Material, get_material
from cloth_mg_ros.sim.sheets import build_scene, scene_friction
from cloth_mg_ros.solvers.threads import resolve_threads

__all__ = ["SessionSettings"]


@dataclass(frozen=True)
class SessionSettings:
    """body: a body scene (else a sheet); values: every parameter's start value, checked
    against the schema (config.schema.SceneParams: values.garment, values.tick_mode, ...);
    material: the cloth's; threads: the simulation threads (resolved: >= 1)."""

    body: bool
    values: SceneParams
    material: Material
    threads: int

    @classmethod
    def from_values(cls, values: SceneParams, body: bool) -> SessionSettings:
        """The settings from the node's checked parameter values (ros.parameters.
        check_parameters); ClothInputError for what the schema cannot tell alone."""
        if not body and values.tick_mode != "timer":
            raise ClothInputError(f"tick_mode {values.tick_mode!r} needs a body scene; sheet "
                                  f"scene {values.scene!r} runs on the timer")
        return cls(body, values, get_material(values.material), resolve_threads(values.threads))

    @property
    def levels(self) -> int | None:
        """Multigrid levels (None: as many as the mesh size calls for)."""
        return self.values.levels or None

    @property
    def sheet_friction(self) -> float | None:
        """The sheet scene's friction: the parameter's, or None where the scene has no
        collider to rub against (the hang: sim.sheets.scene_friction)."""
        return scene_friction(self.values.scene, self.values.friction)

    def unused_text(self) -> str:
        """The start-up line's note of a parameter the sheet scene has no use for ('' when
        none): the node declares every parameter for every scene (any params file is
        accepted), so the line says which value set away from its default is not used."""
        if (self.body or self.sheet_friction is not None
                or self.values.friction == PARAMETERS["friction"].default):
            return ""  # a default nobody set needs no note
        return (f"; parameter friction {self.values.friction:g} unused (the "
                f"{self.values.scene} scene has no collider)")

    def sheet_scene(self):
        """The sheet scene the parameters declare (sim.sheets.build_scene: its particles,
        material, levels, friction where it has a collider, and compression)."""
        return build_scene(self.values.scene, int(self.values.particles), self.material,
                           levels=self.levels, friction=self.sheet_friction,
                           compression=self.values.compression,
                           contact_friction=self.values.contact_friction)
