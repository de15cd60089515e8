"""Rotation helpers for segment poses [x, y, z, qx, qy, qz, qw] (quaternions in ROS order,
x, y, z, w): quaternions <-> rotation matrices, slerp, the smallest rotation between two
directions, and a rigid world transform of poses."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ['matrix_to_quat', 'quat_to_matrix', 'slerp', 'transform_poses']


def matrix_to_quat(rot: np.ndarray) -> np.ndarray:
    """Unit quaternions [qx, qy, qz, qw] (..., 4) of rotation matrices (..., 3, 3).

    Sign-continuous along the first axis when `rot` has a leading frame axis of more than one
    frame (each quaternion takes the sign closer to its predecessor's).
    """
    rot = np.asarray(rot, dtype=float)
    shape = rot.shape[:-2]
    quat = Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_quat().reshape(shape + (4,))
    if quat.ndim >= 2 and quat.shape[0] > 1:
        flip = np.sum(quat[1:] * quat[:-1], axis=-1) < 0.0
        sign = np.cumprod(np.where(flip, -1.0, 1.0), axis=0)
        quat[1:] *= sign[..., None]
    return quat


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions [qx, qy, qz, qw] (..., 4) (normalised here)."""
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions [qx, qy, qz, qw].

    Args:
        q0, q1: (..., 4) end quaternions (the shorter arc is taken).
        u: (...,) fractions in [0, 1], broadcast against q0[..., 0].

    Returns:
        (..., 4) unit quaternions.
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    u = np.asarray(u, dtype=float)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    s = np.sin(theta)
    small = s < 1e-8
    safe = np.where(small, 1.0, s)
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / safe)
    w1 = np.where(small, u, np.sin(u * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def align_vectors(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) taking direction u to direction v (180 deg about an axis
    perpendicular to u when they are opposite)."""
    u = u / np.linalg.norm(u)
    v = v / np.linalg.norm(v)
    axis = np.cross(u, v)
    s, c = np.linalg.norm(axis), float(np.dot(u, v))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(u, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(u, [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(math.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def transform_poses(poses: np.ndarray, rotation: np.ndarray, translation: np.ndarray
                    ) -> np.ndarray:
    """Apply a rigid world transform p -> rotation @ p + translation to poses (..., 7)."""
    poses = np.array(poses, dtype=float)
    rotation = np.asarray(rotation, dtype=float)
    poses[..., :3] = poses[..., :3] @ rotation.T + translation
    if not np.allclose(rotation, np.eye(3)):
        poses[..., 3:7] = matrix_to_quat(rotation @ quat_to_matrix(poses[..., 3:7]))
    return poses
