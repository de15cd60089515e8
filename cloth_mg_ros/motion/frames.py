"""Checks of one incoming frame of body poses, for whoever consumes them (the simulator, the
node's ingestion): `check_frame` classifies it, the consumer decides what to do (skip, hold,
re-anchor)."""

from __future__ import annotations

import enum
import math

import numpy as np

__all__ = ["FrameStatus", "check_frame"]


class FrameStatus(enum.StrEnum):
    """Classification of one incoming pose frame (see `check_frame`)."""

    OK = 'ok'
    EMPTY = 'empty'
    WRONG_COUNT = 'wrong_count'
    NON_FINITE = 'non_finite'
    STAMP_BACKWARDS = 'stamp_backwards'
    TELEPORT = 'teleport'
    # Not returned by check_frame: a consumer's verdict on a frame stamped at or before the
    # time it has simulated to (the node's ingestion), or named in another frame than the
    # stream's (poses of two frames make no one body path).
    STALE = 'stale'
    WRONG_FRAME = 'wrong_frame'


def check_frame(prev_stamp: float | None, stamp: float, poses: np.ndarray,
                expected_count: int, prev_poses: np.ndarray | None = None, *,
                teleport_m: float = 1.0) -> FrameStatus:
    """Classify one frame of body poses; the caller decides what to do (skip, hold, reset).

    Checks in this order, returning the first that applies:

    - EMPTY: no poses at all;
    - WRONG_COUNT: not `expected_count` poses (or not 7 values each);
    - NON_FINITE: a NaN or infinite stamp, position or quaternion value, or a quaternion of
      zero length;
    - STAMP_BACKWARDS: `prev_stamp` is given and `stamp` is not after it (equal counts: time
      did not advance);
    - TELEPORT: `prev_poses` (same shape) is given and a segment origin moved more than
      `teleport_m` metres (default 1 m) in this one frame;
    - OK otherwise.

    Args:
        prev_stamp: stamp (s) of the previous accepted frame, or None for the first frame.
        stamp: this frame's stamp, s.
        poses: (k, 7) [x, y, z, qx, qy, qz, qw].
        expected_count: number of segments the consumer expects (16 for the default avatar).
        prev_poses: (k, 7) previous accepted poses, or None.
        teleport_m: largest plausible per-frame segment displacement, m.

    Returns:
        a FrameStatus (a str enum: FrameStatus.OK == 'ok').
    """
    poses = np.asarray(poses, dtype=float)
    if poses.size == 0:
        return FrameStatus.EMPTY
    if poses.ndim != 2 or poses.shape != (expected_count, 7):
        return FrameStatus.WRONG_COUNT
    if not (math.isfinite(stamp) and np.all(np.isfinite(poses))):
        return FrameStatus.NON_FINITE
    if np.any(np.linalg.norm(poses[:, 3:7], axis=1) < 1e-6):
        return FrameStatus.NON_FINITE
    if prev_stamp is not None and not stamp > prev_stamp:
        return FrameStatus.STAMP_BACKWARDS
    if prev_poses is not None:
        prev = np.asarray(prev_poses, dtype=float)
        if prev.shape == poses.shape and np.all(np.isfinite(prev)):
            jump = np.linalg.norm(poses[:, :3] - prev[:, :3], axis=1)
            if np.max(jump) > teleport_m:
                return FrameStatus.TELEPORT
    return FrameStatus.OK
