"""What a body scene's key poses hold, turned into the avatar's segment poses in the world.

The ingest (ros.ingest) checks and buffers what arrives: one pose per avatar segment
(`body_input` segments) or a body tracker's joints (joints, kinect_markers). On the simulation
thread, `BodyInput.convert` takes the keys of a tick and

1. moves them into the simulation's world (`input_transform`: motion.input_frame);
2. for joints, holds a missing joint and filters the jitter (motion.joint_track), per stream;
3. over each stream's first second (WINDOW_S of stamps), where the floor (`floor_height`
   auto) or the subject's size (`avatar` from_joints) is measured from the stream, holds the
   keys back, measures, then lets them all through (none is lost: they count as pending);
4. for joints, places the avatar's segments on them (motion.joint_body.poses_from_joints). A
   segment a lost joint cannot place (missing for longer than joint_hold) is dropped from the
   collider until the joint is back (KeyPose.dropped): its pose is held, carried rigidly by
   its parent from where it was last placed, so that the garment's seams on it and the
   display follow the body. A key whose pelvis cannot be placed, or one before the stream's
   first whole body, is skipped and counted (`no_body`);
5. lowers the body by the floor's height, so that the floor is z = 0.

With the defaults (segments, identity, floor 0, the packaged avatar) keys pass untouched: the
segment input stays bit-identical. A transformed stream is published in `frame_id` (the world),
no longer in the tracker's frame its messages name.

Units SI: m, s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cloth_mg_ros.config.schema import AUTO, AVATAR_FROM_JOINTS, AVATAR_PACKAGED, SceneParams
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.motion.avatar import Avatar
from cloth_mg_ros.motion.body_size import avatar_from_joints
from cloth_mg_ros.motion.input_frame import InputFrame, floor_from_poses
from cloth_mg_ros.motion.joint_body import packaged_avatar, poses_from_joints
from cloth_mg_ros.motion.joint_track import JointTrack
from cloth_mg_ros.motion.rotations import matrix_to_quat, quat_to_matrix
from cloth_mg_ros.motion.skeletons import Skeleton, get_skeleton
from cloth_mg_ros.ros.ingest import KeyPose

__all__ = ["WINDOW_S", "BodyInput", "load_avatar"]

WINDOW_S = 1.0  # s of a stream's stamps over which the floor and the subject are measured


def load_avatar(name: str) -> Avatar:
    """The `avatar` parameter's base avatar: the packaged one (also for from_joints, which
    sizes it) or a YAML file's (ClothInputError names the file and the problem)."""
    if name in (AVATAR_PACKAGED, AVATAR_FROM_JOINTS):
        return packaged_avatar()
    return Avatar.load(name)


class BodyInput:
    """Key poses in, segment poses in the world out (module docstring).

    params: the scene's parameters (body_input, skeleton, joint_*, input_transform,
    floor_height, avatar, frame_id); logger: the node's (info, warning).
    Raises ClothInputError for an unusable combination (named) at start.
    """

    def __init__(self, params: SceneParams, logger) -> None:
        self.logger = logger
        self.joints = params.body_input != "segments"
        skeleton = "kinect32" if params.body_input == "kinect_markers" else params.skeleton
        self.skeleton: Skeleton | None = get_skeleton(skeleton) if self.joints else None
        self.measure_avatar = params.avatar == AVATAR_FROM_JOINTS
        if self.measure_avatar and not self.joints:
            raise ClothInputError("parameter avatar: from_joints measures the subject from "
                                  "joint positions: set body_input joints or kinect_markers")
        self.base = load_avatar(params.avatar)
        self.avatar = self.base  # the one the garment is dressed on (sized: per stream)
        self.measure_floor = params.floor_height == AUTO
        self.frame = InputFrame.from_parameters(
            params.input_transform, None if self.measure_floor else params.floor_height)
        self.world_frame = params.frame_id
        self.track = (JointTrack(self.skeleton.num_joints, params.joint_hold,
                                 params.joint_filter_hz, params.joint_filter_beta,
                                 parents=self.skeleton.hold_parents())
                      if self.joints else None)
        self._generation = 0  # the stream followed
        self._last: np.ndarray | None = None  # the stream's latest placed segment poses
        self.dropped_samples = 0  # segment samples dropped from the collider (lost joints)
        self._window: list[tuple[KeyPose, np.ndarray]] = []
        self._measured = not (self.measure_floor or self.measure_avatar)
        self.measured_text = ""  # the latest measurement, for the log and the status

    @property
    def count(self) -> int:
        """Poses per message: the skeleton's joints, or the avatar's segments."""
        return self.skeleton.num_joints if self.joints else self.avatar.num_segments

    @property
    def held(self) -> int:
        """Keys held back while the stream's first second is measured."""
        return len(self._window)

    @property
    def passthrough(self) -> bool:
        """Whether keys pass untouched (segments, no transform, floor 0, no measuring)."""
        return not self.joints and self.frame.identity and self._measured

    def convert(self, keys: list[KeyPose], skip) -> list[KeyPose]:
        """`keys` (oldest first) as segment poses in the world (module docstring); skip(kind,
        stamp) counts a key that cannot be used (the ingest's skip_taken)."""
        if self.passthrough or not keys:
            return keys
        ready: list[tuple[KeyPose, np.ndarray]] = []
        for key in keys:  # a handful per tick
            if key.generation != self._generation:
                ready += self._flush()
                self._new_stream(key.generation)
            body = self._moved(key)
            if self._measured:
                ready.append((key, body))
                continue
            self._window.append((key, body))
            if key.stamp - self._window[0][0].stamp >= WINDOW_S:
                ready += self._flush()
        return self._placed(ready, skip)

    def _new_stream(self, generation: int) -> None:
        """A new stream (a reset, a looped bag): its own track, floor and subject."""
        self._generation = generation
        self._last = None
        if self.track is not None:
            self.track.reset()
        self._measured = not (self.measure_floor or self.measure_avatar)

    def _moved(self, key: KeyPose) -> np.ndarray:
        """The key's body in the world (the floor aside): joints (J, 3) held and filtered,
        or segment poses (S, 7)."""
        if not self.joints:
            return key.poses if self.frame.rigid_identity else self.frame.poses(key.poses)
        x = key.poses[:, :3]
        return self.track.update(key.stamp, x if self.frame.rigid_identity
                                 else self.frame.positions(x))

    def _flush(self) -> list[tuple[KeyPose, np.ndarray]]:
        """Measure on the window held (if any) and let its keys through."""
        window, self._window = self._window, []
        if window:
            self._measure(window)
        self._measured = True
        return window

    def _measure(self, window: list[tuple[KeyPose, np.ndarray]]) -> None:
        """The subject's size and the floor from the window's keys (module docstring)."""
        stamps = np.array([k.stamp for k, _ in window])
        bodies = np.stack([b for _, b in window])
        notes = []
        if self.measure_avatar:
            try:
                self.avatar, size = avatar_from_joints(bodies, self.skeleton, stamps=stamps,
                                                       window_s=WINDOW_S, avatar=self.base)
                notes.append(f"a {size.stature:.3f} m subject (avatar sized)")
            except ClothInputError as exc:
                self.avatar = self.base
                self.logger.warning(f"cannot size the avatar from the stream's first "
                                    f"{WINDOW_S:g} s ({exc}): the packaged avatar is used")
        if self.measure_floor:
            poses = self._segments(bodies)[0] if self.joints else bodies
            valid = np.isfinite(poses).all(axis=(1, 2))
            floor = floor_from_poses(self.avatar, poses[valid]) if valid.any() else 0.0
            self.frame = replace(self.frame, floor=floor)
            notes.append(f"the floor at z = {floor:.4f} m"
                         + ("" if valid.any() else " (no frame placed the body: assumed)"))
        self.measured_text = (f"measured over the first {stamps[-1] - stamps[0]:.2f} s "
                              f"({len(window)} poses): {', '.join(notes)}")
        self.logger.info(self.measured_text)

    def _segments(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment poses (F, S, 7) and which are placed (F, S) from joints (F, J, 3)."""
        return poses_from_joints(joints, self.skeleton, self.avatar)

    def _placed(self, ready: list[tuple[KeyPose, np.ndarray]], skip) -> list[KeyPose]:
        """The keys with their segment poses, floor lowered, in the world's frame name."""
        if not ready:
            return []
        bodies = np.stack([b for _, b in ready])
        if self.joints:
            poses, valid = self._segments(bodies)
        else:
            poses, valid = bodies, np.ones(bodies.shape[:2], dtype=bool)
        if self.frame.floor:
            poses = self.frame.lowered(poses)
        renamed = not self.frame.identity  # moved into the world: published in frame_id
        out = []
        for (key, _), segment_poses, placed in zip(ready, poses, valid, strict=True):
            dropped = None
            if not placed.all():
                if self._last is None or not placed[0]:
                    skip("no_body", key.stamp)
                    continue
                segment_poses, dropped = self._held(segment_poses, placed), ~placed
                self.dropped_samples += int(dropped.sum())
            self._last = segment_poses
            out.append(replace(key, poses=segment_poses, dropped=dropped,
                               frame_id=self.world_frame if renamed else key.frame_id))
        return out

    def _held(self, poses: np.ndarray, placed: np.ndarray) -> np.ndarray:
        """poses (S, 7) with each segment not placed carried rigidly by its parent from its
        last pose (the avatar lists parents first; the pelvis is placed)."""
        out = poses.copy()
        last = self._last
        for s in np.flatnonzero(~placed):  # a few segments
            p = self.avatar.parents[s]
            turn = quat_to_matrix(out[p, 3:]) @ quat_to_matrix(last[p, 3:]).T
            out[s, :3] = turn @ (last[s, :3] - last[p, :3]) + out[p, :3]
            out[s, 3:] = matrix_to_quat(turn @ quat_to_matrix(last[s, 3:]))
        return out
