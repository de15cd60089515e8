"""From a body tracker's frame to the simulation's world: a rigid transform, then the floor.

The simulation's world is z up with the floor at z = 0 (gravity along -z, the floor collider
the plane z = 0). A tracker reports in its own frame: a camera's (Azure Kinect's depth camera
and MediaPipe's world landmarks: x right, y down, z forward), a capture room's. `InputFrame`
maps its poses into the world: p_world = R p + t (the node's `input_transform`, translation
and unit quaternion of the tracker's frame in the world, as a tf2 static transform states
it), then lowers everything by the floor's height in that frame (`floor_height`: a number,
or measured from the stream: `floor_from_poses`).

The floor measured: over the stream's first second, the lowest point any capsule of the body
reaches, less the avatar's ground clearance (the bundled bags' convention: a standing foot's
capsule clears the floor by that much). A subject who stands or walks in that second touches
the floor with a foot; one who jumps throughout would read it too high (give the number).

Units SI: m; quaternions (x, y, z, w).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.rotations import quat_to_matrix, transform_poses

__all__ = ["BODY_INPUTS", "IDENTITY_TRANSFORM", "InputFrame", "floor_from_poses"]

#: The body inputs a stream may carry (the node's `body_input`, `cloth-mg bag from-bvh
#: --body-input`): segment poses, joint positions (PoseArray), the Azure Kinect MarkerArray.
BODY_INPUTS = ("segments", "joints", "kinect_markers")

#: input_transform's identity: translation (0, 0, 0), quaternion (0, 0, 0, 1).
IDENTITY_TRANSFORM = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
QUATERNION_TOLERANCE = 1e-3  # |q| may differ from 1 by this much (rounded YAML); normalised


@dataclass(frozen=True)
class InputFrame:
    """The tracker's frame in the world: rotation (3, 3), translation (3,) m; floor: the
    floor's height (m) after the transform, None while it is to be measured."""

    rotation: np.ndarray
    translation: np.ndarray
    floor: float | None = 0.0

    @classmethod
    def from_parameters(cls, transform: Sequence[float], floor: float | None,
                        where: str = "input_transform") -> InputFrame:
        """From [x, y, z, qx, qy, qz, qw] (m; a unit quaternion) and the floor's height (m;
        None: measured). ClothInputError names `where` and the value when it is unusable."""
        values = np.asarray(transform, dtype=np.float64).reshape(-1)
        if values.shape != (7,) or not np.all(np.isfinite(values)):
            raise ClothInputError(f"{where} must be 7 finite numbers [x, y, z, qx, qy, qz, qw] "
                                  f"(m; a unit quaternion), got {list(transform)!r}")
        norm = float(np.linalg.norm(values[3:]))
        if abs(norm - 1.0) > QUATERNION_TOLERANCE:
            raise ClothInputError(f"{where}: the quaternion {values[3:].tolist()} is not a "
                                  f"unit quaternion (norm {norm:.6g})")
        if floor is not None and not math.isfinite(floor):
            raise ClothInputError(f"floor_height must be a finite number of metres or 'auto', "
                                  f"got {floor!r}")
        return cls(quat_to_matrix(values[3:] / norm), values[:3].copy(),
                   None if floor is None else float(floor))

    @property
    def rigid_identity(self) -> bool:
        """Whether the transform (the floor aside) leaves poses as they are."""
        return bool(np.array_equal(self.rotation, np.eye(3))
                    and not np.any(self.translation))

    @property
    def identity(self) -> bool:
        """Whether poses pass unchanged: no transform and the floor at 0 (the default)."""
        return self.rigid_identity and self.floor == 0.0

    def positions(self, x: np.ndarray) -> np.ndarray:
        """Points (..., 3) m in the tracker's frame, rigidly moved into the world (the floor
        not yet lowered: `lowered`)."""
        return np.asarray(x, dtype=np.float64) @ self.rotation.T + self.translation

    def poses(self, poses: np.ndarray) -> np.ndarray:
        """Poses (..., 7) [x, y, z, qx, qy, qz, qw] rigidly moved into the world."""
        return transform_poses(poses, self.rotation, self.translation)

    def lowered(self, poses: np.ndarray) -> np.ndarray:
        """Segment poses (..., 7) with the floor brought to z = 0 (a copy; the floor must be
        known)."""
        out = np.array(poses, dtype=np.float64)
        out[..., 2] -= self.floor
        return out


def floor_from_poses(avatar: Avatar, poses: np.ndarray) -> float:
    """The floor's height (m) under a body's segment poses (F, S, 7) in a z-up frame: the
    lowest capsule point over the frames less the avatar's ground clearance (module
    docstring). ClothInputError when no frame is given."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or not len(poses):
        raise ClothInputError(f"measuring the floor takes segment poses (F, S, 7) of at least "
                              f"one frame, got shape {poses.shape}")
    return avatar.lowest_point(poses) - avatar.ground_clearance
