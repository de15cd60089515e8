"""A capsule avatar driven by BVH motion capture: segment poses and the capsules of the collider.

The avatar is a tree of 16 body segments (config/avatar.yaml): pelvis, lower_torso, upper_torso,
head, upper_arm_l, lower_arm_l, hand_l, upper_arm_r, lower_arm_r, hand_r, upper_leg_l,
lower_leg_l, foot_l, upper_leg_r, lower_leg_r, foot_r. Each segment is one capsule.

Retargeting. The avatar keeps its own segment lengths (an adult of about 1.75 m) and takes only
rotations from the clip: each segment is oriented by the forward-kinematics world rotation of its
BVH joint (so the rotations of the intermediate joints above it count), and its origin (its
proximal joint) is its parent's origin plus the avatar's own bone vectors, each turned by the
world rotation of the BVH joint that carries that stretch of bone. The root (pelvis) origin is the
BVH root translation. Per clip (`Avatar.clip_transform`) the whole motion is levelled (a capture
floor tilted along the walk, about 1 deg in the subject 7 clips, is rotated level), shifted
horizontally so that the first frame's root is above the origin, and shifted vertically so that
the lowest capsule point over the whole clip sits at `ground_clearance` (the avatar's legs differ
from each subject's).

Frames and conventions (what consumers of the poses must know):

- World: ROS REP 103, z up, x forward (the clip's walking direction), y left, metres.
- A pose is [x, y, z, qx, qy, qz, qw]: the segment frame's origin (the segment's proximal joint:
  hip, knee, ankle, shoulder, elbow, wrist, base of neck, base of skull; the Hips point for the
  pelvis and lower torso) and its orientation as a unit quaternion in ROS order (x, y, z, w).
  Quaternions are sign-continuous from frame to frame.
- The segment frame is R_world(joint) @ R0[s], R0 = `rest_rotation[s]`, the smallest rotation
  taking +z to the capsule's rest direction; so it is not the body frame: for the pelvis and
  upper torso (capsules across the body, along y) local z points left and local x forward; for
  the legs local z points down the leg. `Avatar.body_rotations(poses)` gives the joints' frames.
- Capsule axis = the segment frame's local +z. The capsule's centre is `offset[s]` in the segment
  frame; its axis end points are centre -/+ half_length[s] * (local +z), and `radius[s]` is the
  radius: `Avatar.capsules(poses)` returns those end points in world metres.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.share import config_path
from cloth_mg_ros.motion.bvh import BVH_TO_ROS, BvhClip, forward_kinematics
from cloth_mg_ros.motion.rotations import (
    align_vectors,
    matrix_to_quat,
    quat_to_matrix,
    slerp,
    transform_poses,
)

__all__ = [
    'SEGMENT_NAMES',
    'Avatar',
    'Segment',
]

#: The segments of the default avatar, in pose order.
SEGMENT_NAMES = (
    'pelvis', 'lower_torso', 'upper_torso', 'head',
    'upper_arm_l', 'lower_arm_l', 'hand_l', 'upper_arm_r', 'lower_arm_r', 'hand_r',
    'upper_leg_l', 'lower_leg_l', 'foot_l', 'upper_leg_r', 'lower_leg_r', 'foot_r',
)


# --------------------------------------------------------------------------------------------
# Avatar


@dataclass(frozen=True)
class Segment:
    """One body segment.

    Attributes:
        name: segment name.
        joint: BVH joint whose world rotation orients the segment.
        parent: index of the parent segment, -1 for the root.
        bone: ((via joint, (3,) rest-frame vector in m), ...): the segment origin relative to the
            parent's origin is sum over pieces of R_world(via) @ vector.
        p0, p1: (3,) capsule axis end points, rest frame, m, relative to the segment origin.
        radius: capsule radius, m.
    """

    name: str
    joint: str
    parent: int
    bone: tuple[tuple[str, np.ndarray], ...]
    p0: np.ndarray
    p1: np.ndarray
    radius: float


def _number(source: str, value, field: str, *, positive: bool = False, minimum=None) -> float:
    """A finite number from the avatar file (ClothInputError naming `field` otherwise)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise ClothInputError(f'{source}: {field} must be a finite number, got {value!r}')
    if positive and value <= 0:
        raise ClothInputError(f'{source}: {field} must be positive, got {value!r}')
    if minimum is not None and value < minimum:
        raise ClothInputError(f'{source}: {field} must be >= {minimum}, got {value!r}')
    return float(value)


def _vector(source: str, value, field: str) -> np.ndarray:
    """A (3,) vector from a list of 3 numbers of the avatar file."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ClothInputError(f'{source}: {field} must be a list of 3 numbers, '
                              f'got {value!r}')
    return np.array([_number(source, v, f'{field}[{k}]') for k, v in enumerate(value)])


# The keys an avatar file may hold, at the top, per segment and per capsule: a misspelt one
# would otherwise leave its default silently in force.
_TOP_KEYS = ('units', 'ground_clearance', 'rest_arm_abduction', 'segments')
_SEGMENT_KEYS = ('name', 'joint', 'parent', 'bone', 'capsule')
_CAPSULE_KEYS = ('p0', 'p1', 'radius')
UNITS = {'length': 'm', 'angle': 'deg'}  # what the file's numbers are in (the only units read)


def _known_keys(source: str, where: str, item: dict, known: tuple[str, ...]) -> None:
    """ClothInputError naming the first key of `item` not among `known`."""
    unknown = [k for k in item if k not in known]
    if unknown:
        raise ClothInputError(f'{source}: {where}unknown key {unknown[0]!r} (known: '
                              f'{", ".join(known)})')


def _segment(source: str, i: int, item, index: dict[str, int]) -> Segment:
    """Segment i of the avatar file, its parent among the segments before it (`index`: name
    -> index); only the first may be the root."""
    where = f'segments[{i}]'
    if not isinstance(item, dict):
        raise ClothInputError(f'{source}: {where} must be a mapping, got {item!r}')
    _known_keys(source, f'{where}: ', item, _SEGMENT_KEYS)
    name = item.get('name')
    if not isinstance(name, str) or not name:
        raise ClothInputError(f'{source}: {where}.name must be a string, got {name!r}')
    where = f'segments[{i}] ({name})'
    if name in index:
        raise ClothInputError(f'{source}: {where}: duplicate segment name {name!r}')
    joint = item.get('joint')
    if not isinstance(joint, str) or not joint:
        raise ClothInputError(f'{source}: {where}.joint must be a joint name, '
                              f'got {joint!r}')
    parent_name = item.get('parent')
    if parent_name is None:
        if index:
            raise ClothInputError(f'{source}: {where}.parent is null but only the first '
                                  'segment may be the root')
        parent = -1
    elif parent_name not in index:
        raise ClothInputError(f'{source}: {where}.parent {parent_name!r} is not a '
                              'segment listed before it')
    else:
        parent = index[parent_name]
    if parent < 0 and i > 0:
        raise ClothInputError(f'{source}: {where}: only one root segment is allowed')
    bone = _bone(source, where, item.get('bone', []))
    if parent < 0 and bone:
        raise ClothInputError(f'{source}: {where}.bone must be empty for the root '
                              'segment (its origin is the clip root translation)')
    cap = item.get('capsule')
    if not isinstance(cap, dict):
        raise ClothInputError(f'{source}: {where}.capsule must be a mapping with p0, p1, '
                              f'radius, got {cap!r}')
    _known_keys(source, f'{where}.capsule: ', cap, _CAPSULE_KEYS)
    p0 = _vector(source, cap.get('p0'), f'{where}.capsule.p0')
    p1 = _vector(source, cap.get('p1'), f'{where}.capsule.p1')
    radius = _number(source, cap.get('radius'), f'{where}.capsule.radius', positive=True)
    return Segment(name, joint, parent, tuple(bone), p0, p1, radius)


def _bone(source: str, where: str, bone_raw) -> list[tuple[str, np.ndarray]]:
    """A segment's bone: its [{via: JOINT, vector: [x, y, z]}] pieces."""
    if not isinstance(bone_raw, list):
        raise ClothInputError(f'{source}: {where}.bone must be a list of '
                              f'{{via, vector}} pieces, got {bone_raw!r}')
    bone = []
    for k, piece in enumerate(bone_raw):
        field = f'{where}.bone[{k}]'
        if not isinstance(piece, dict) or not isinstance(piece.get('via'), str):
            raise ClothInputError(f'{source}: {field} must be {{via: JOINT, vector: '
                                  f'[x, y, z]}}, got {piece!r}')
        bone.append((piece['via'], _vector(source, piece.get('vector'), f'{field}.vector')))
    return bone


class Avatar:
    """Capsule avatar (see the module docstring for the conventions).

    Attributes:
        segments: the S segments in pose order.
        names: (S,) segment names.
        parents: (S,) int parent segment index, -1 for the root.
        joints: (S,) BVH joint orienting each segment.
        radius: (S,) capsule radii, m.
        half_length: (S,) half the capsule axis length, m.
        offset: (S, 3) capsule centre in the segment frame, m.
        rest_rotation: (S, 3, 3) R0, segment frame relative to its joint's frame (R0 @ +z is the
            rest direction of the capsule axis).
        ground_clearance: m, height of the lowest capsule point after grounding.
        rest_arm_abduction: deg, arm angle from vertical in `rest_poses`.
        source: the file it was loaded from (or '<dict>').
    """

    def __init__(self, segments: list[Segment], ground_clearance: float = 0.01,
                 rest_arm_abduction: float = 12.0, source: str = '<dict>') -> None:
        self.segments = list(segments)
        self.source = source
        self.ground_clearance = float(ground_clearance)
        self.rest_arm_abduction = float(rest_arm_abduction)
        self.names = [s.name for s in self.segments]
        self.parents = np.array([s.parent for s in self.segments], dtype=np.int64)
        self.joints = [s.joint for s in self.segments]
        self.radius = np.array([s.radius for s in self.segments], dtype=float)
        S = len(self.segments)
        self.half_length = np.empty(S)
        self.offset = np.empty((S, 3))
        self.rest_rotation = np.empty((S, 3, 3))
        for i, s in enumerate(self.segments):
            d = s.p1 - s.p0
            length = float(np.linalg.norm(d))
            r0 = align_vectors(np.array([0.0, 0.0, 1.0]), d) if length > 1e-9 else np.eye(3)
            self.half_length[i] = 0.5 * length
            self.rest_rotation[i] = r0
            self.offset[i] = r0.T @ (0.5 * (s.p0 + s.p1))
        self._required = sorted({s.joint for s in self.segments}
                                | {via for s in self.segments for via, _ in s.bone})

    # ---- construction

    @classmethod
    def load(cls, path: str | os.PathLike | None = None) -> Avatar:
        """Load an avatar YAML file (default: the packaged config/avatar.yaml).

        Raises:
            ClothInputError: missing or unreadable file, or a bad field (named with its value).
        """
        p = Path(path) if path is not None else config_path('avatar.yaml')
        if not p.is_file():
            raise ClothInputError(f'{p}: avatar file not found')
        try:
            data = yaml.safe_load(p.read_text(encoding='utf-8'))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise ClothInputError(f'{p}: cannot read avatar YAML: {exc}') from None
        return cls.from_dict(data, source=str(p))

    @classmethod
    def from_dict(cls, data: dict, source: str = '<dict>') -> Avatar:
        """Build an avatar from the parsed YAML structure (see config/avatar.yaml)."""
        if not isinstance(data, dict):
            raise ClothInputError(f'{source}: expected a mapping at the top level, '
                                  f'got {type(data).__name__}')
        _known_keys(source, '', data, _TOP_KEYS)
        if data.get('units', UNITS) != UNITS:
            raise ClothInputError(f'{source}: units must be {UNITS} (lengths in metres, angles '
                                  f'in degrees), got {data["units"]!r}')
        clearance = _number(source, data.get('ground_clearance', 0.01), 'ground_clearance')
        abduction = _number(source, data.get('rest_arm_abduction', 12.0), 'rest_arm_abduction',
                            minimum=0.0)
        raw = data.get('segments')
        if not isinstance(raw, list) or not raw:
            raise ClothInputError(f'{source}: segments must be a non-empty list, got {raw!r}')
        segments: list[Segment] = []
        index: dict[str, int] = {}
        for i, item in enumerate(raw):
            segments.append(_segment(source, i, item, index))
            index[segments[-1].name] = i
        return cls(segments, clearance, abduction, source)

    # ---- basic queries

    @property
    def num_segments(self) -> int:
        """S, the number of segments (poses per message)."""
        return len(self.segments)

    def segment_index(self, name: str) -> int:
        """Index of segment `name` in the pose arrays."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ClothInputError(f'{self.source}: no segment named {name!r} (segments: '
                                  f'{", ".join(self.names)})') from None

    # ---- kinematics

    def check_clip(self, clip: BvhClip, *, max_angle_deg: float = 10.0) -> None:
        """Check that `clip` has every joint the avatar uses and the same rest pose.

        For each segment whose bone is a single piece carried by the parent segment's joint,
        which is also the BVH parent of the segment's joint (forearm, hand, shank, foot),
        the rest direction of the avatar's bone must lie within `max_angle_deg` of the clip's
        OFFSET of the segment's joint (after the axis change): the avatar's rest pose must be the
        skeleton's zero pose (e.g. CMU legs splayed 20 deg, arms out sideways).

        Raises:
            ClothInputError: naming the clip, the segment and the joint or the two directions.
        """
        names = set(clip.joint_names)
        for s in self.segments:
            for joint in [s.joint] + [via for via, _ in s.bone]:
                if joint not in names:
                    raise ClothInputError(
                        f'{clip.path}: the avatar ({self.source}) segment {s.name!r} needs joint '
                        f'{joint!r}, which the clip lacks (joints: {", ".join(clip.joint_names)})')
        for s in self.segments:
            if len(s.bone) != 1:
                continue
            via, vec = s.bone[0]
            j = clip.joint_index(s.joint)
            parent = clip.parents[j]
            if (s.parent < 0 or via != self.segments[s.parent].joint or parent < 0
                    or clip.joint_names[parent] != via):
                continue
            off = BVH_TO_ROS @ clip.offsets[j]
            if np.linalg.norm(off) < 1e-6 or np.linalg.norm(vec) < 1e-6:
                continue
            cos = np.dot(off, vec) / (np.linalg.norm(off) * np.linalg.norm(vec))
            angle = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
            if angle > max_angle_deg:
                raise ClothInputError(
                    f'{clip.path}: rest pose mismatch: avatar ({self.source}) segment '
                    f'{s.name!r} bone {np.round(vec, 4).tolist()} is {angle:.1f} deg away from '
                    f'the clip OFFSET of {s.joint!r} {np.round(off, 4).tolist()} (ROS axes)')

    def poses_from_rotations(self, root: np.ndarray, rotations: dict[str, np.ndarray]
                             ) -> np.ndarray:
        """Segment poses from joint world rotations and a root position (no grounding).

        Args:
            root: (F, 3) world position of the root segment's origin, m.
            rotations: joint name -> (F, 3, 3) world rotation (ROS axes) for every joint the
                avatar uses (segment joints and bone `via` joints).

        Returns:
            (F, S, 7) poses [x, y, z, qx, qy, qz, qw].
        """
        root = np.asarray(root, dtype=float)
        F = root.shape[0]
        S = self.num_segments
        origin = np.empty((F, S, 3))
        frame = np.empty((F, S, 3, 3))
        for i, s in enumerate(self.segments):
            if s.parent < 0:
                origin[:, i] = root
            else:
                origin[:, i] = origin[:, s.parent]
                for via, vec in s.bone:
                    origin[:, i] += rotations[via] @ vec
            frame[:, i] = rotations[s.joint] @ self.rest_rotation[i]
        quat = matrix_to_quat(frame)
        return np.concatenate([origin, quat], axis=-1)

    def poses_from_clip(self, clip: BvhClip, *, times: np.ndarray | None = None,
                        ground: bool = True, recentre: bool = True,
                        level: bool = True) -> np.ndarray:
        """Segment poses over a clip.

        Args:
            clip: a parsed BVH clip (any skeleton with the avatar's joints; CMU here).
            times: (N,) seconds from the first kept frame at which to sample the motion, within
                [0, clip.duration] (clamped). Joint world rotations are slerped and the root
                translation interpolated linearly between the two nearest frames, then the avatar
                is posed, so the capsule chain stays rigid. None: every kept frame.
            ground: shift the root vertically so that the lowest capsule point over the whole
                clip (every kept frame, whatever `times`) sits at `ground_clearance`.
            recentre: shift the root horizontally so that the first kept frame's root is at
                x = y = 0.
            level: level a tilted capture floor (see `clip_transform`).

        Returns:
            (F, S, 7) poses [x, y, z, qx, qy, qz, qw] in ROS world axes, metres; F = len(times)
            or clip.num_frames.
        """
        self.check_clip(clip)
        rot, pos = forward_kinematics(clip, ros=True)
        root_joint = clip.joint_index(self.segments[0].joint)
        needed = {name: clip.joint_index(name) for name in self._required}
        full = self.poses_from_rotations(pos[:, root_joint],
                                         {n: rot[:, j] for n, j in needed.items()})
        transform, translation = self.clip_transform(full, ground=ground, recentre=recentre,
                                                     level=level)
        if times is None:
            poses = full
        else:
            times = np.asarray(times, dtype=float).reshape(-1)
            if not np.all(np.isfinite(times)):
                raise ClothInputError(f'{clip.path}: sample times must be finite')
            names = list(needed)
            quats = matrix_to_quat(rot[:, [needed[n] for n in names]])  # (F, K, 4)
            F = clip.num_frames
            if F == 1:
                i0 = np.zeros(len(times), dtype=np.int64)
                i1, u = i0, np.zeros(len(times))
            else:
                x = np.clip(times / clip.frame_time, 0.0, F - 1)
                i0 = np.minimum(np.floor(x).astype(np.int64), F - 2)
                i1 = i0 + 1
                u = x - i0
            q = slerp(quats[i0], quats[i1], np.broadcast_to(u[:, None], (len(times), len(names))))
            mats = quat_to_matrix(q)
            root = (1.0 - u)[:, None] * pos[i0, root_joint] + u[:, None] * pos[i1, root_joint]
            poses = self.poses_from_rotations(root, {n: mats[:, k] for k, n in enumerate(names)})
        return transform_poses(poses, transform, translation)

    def clip_transform(self, poses: np.ndarray, *, ground: bool = True, recentre: bool = True,
                       level: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The rigid world transform (G, t), p -> G @ p + t, that places a clip's poses.

        Steps, on the poses (F, S, 7) of every frame of the clip:

        1. level: motion capture floors are not always level (the subject 7 clips climb about
           1 deg along the walk, so stance feet rise by 6 cm over 3.4 m). The lowest capsule
           point of every frame is projected on the travel direction d (first to last root,
           horizontal); a line is fitted through the vertices of the lower convex hull of
           (distance along d, height), i.e. the support points, and the motion is rotated about
           the horizontal axis z x d (through the origin) so that line is level. Skipped when
           the root travels less than 1 m or the fitted slope exceeds 5 deg.
        2. recentre: translate horizontally so that frame 0's root is at x = y = 0.
        3. ground: translate vertically so that the lowest capsule point over all frames sits at
           `ground_clearance`.

        Returns:
            G (3, 3) rotation, t (3,) translation in metres.
        """
        poses = np.asarray(poses, dtype=float)
        G = self._levelling(poses) if level else np.eye(3)
        t = np.zeros(3)
        if recentre:
            t[:2] = -(G @ poses[0, 0, :3])[:2]
        if ground:
            t[2] += self.ground_clearance - self.lowest_point(transform_poses(poses, G, t))
        return G, t

    def _levelling(self, poses: np.ndarray) -> np.ndarray:
        travel = poses[-1, 0, :2] - poses[0, 0, :2]
        dist = float(np.linalg.norm(travel))
        if dist < 1.0:
            return np.eye(3)
        d = np.array([travel[0] / dist, travel[1] / dist, 0.0])
        p0, p1, radius = self.capsules(poses)
        ends = np.concatenate([p0, p1], axis=1)  # (F, 2S, 3)
        heights = ends[..., 2] - np.concatenate([radius, radius])
        k = np.argmin(heights, axis=1)
        f = np.arange(len(poses))
        s = ends[f, k] @ d
        z = heights[f, k]
        order = np.argsort(s, kind='stable')
        hull: list[int] = []
        for i in order:  # lower convex hull, monotone chain
            while len(hull) >= 2:
                a, b = hull[-2], hull[-1]
                if (s[b] - s[a]) * (z[i] - z[a]) - (z[b] - z[a]) * (s[i] - s[a]) <= 0:
                    hull.pop()
                else:
                    break
            hull.append(int(i))
        if len(hull) < 2:
            return np.eye(3)
        slope = np.polyfit(s[hull], z[hull], 1)[0]
        angle = math.atan(slope)
        if abs(angle) > math.radians(5.0):
            return np.eye(3)
        return Rotation.from_rotvec(np.cross([0.0, 0.0, 1.0], d) * angle).as_matrix()

    def rest_poses(self, arm_abduction_deg: float | None = None) -> np.ndarray:
        """A neutral standing pose (S, 7): legs straight down, feet forward, arms hanging
        `arm_abduction_deg` (default: the YAML's rest_arm_abduction) from vertical, head and
        torso upright, root above the origin, lowest point at `ground_clearance`.

        Usable as the garment's dressing pose. Legs and arms are recognised by the default
        segment names (upper_leg_l/r, lower_leg_l/r, upper_arm_l/r, lower_arm_l/r, hand_l/r);
        other segments keep the rest orientation.
        """
        a = math.radians(self.rest_arm_abduction if arm_abduction_deg is None
                         else float(arm_abduction_deg))
        rotations = {name: np.eye(3)[None] for name in self._required}
        index = {n: i for i, n in enumerate(self.names)}
        for side in ('l', 'r'):
            leg = [f'upper_leg_{side}', f'lower_leg_{side}']
            if all(n in index for n in leg) and self.segments[index[leg[1]]].bone:
                thigh = sum(v for _, v in self.segments[index[leg[1]]].bone)
                straighten = align_vectors(thigh, np.array([0.0, 0.0, -1.0]))
                for n in leg:
                    rotations[self.segments[index[n]].joint] = straighten[None]
            arm = [f'upper_arm_{side}', f'lower_arm_{side}', f'hand_{side}']
            if all(n in index for n in arm) and self.segments[index[arm[1]]].bone:
                upper = sum(v for _, v in self.segments[index[arm[1]]].bone)
                lateral = 1.0 if upper[1] >= 0 else -1.0
                target = np.array([0.0, lateral * math.sin(a), -math.cos(a)])
                lower = align_vectors(upper, target)
                for n in arm:
                    rotations[self.segments[index[n]].joint] = lower[None]
        poses = self.poses_from_rotations(np.zeros((1, 3)), rotations)[0]
        poses[:, 2] += self.ground_clearance - self.lowest_point(poses)
        return poses

    # ---- capsules

    def capsules(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Capsules of the collider in world coordinates.

        Args:
            poses: (S, 7) or (F, S, 7) segment poses [x, y, z, qx, qy, qz, qw].

        Returns:
            p0, p1: (..., S, 3) capsule axis end points, m (p1 - p0 along local +z);
            radius: (S,) capsule radii, m.
        """
        poses = np.asarray(poses, dtype=float)
        if poses.shape[-2:] != (self.num_segments, 7):
            raise ClothInputError(f'poses must have shape (..., {self.num_segments}, 7), '
                                  f'got {poses.shape}')
        rot = quat_to_matrix(poses[..., 3:7])
        centre = poses[..., :3] + np.einsum('...ab,...b->...a', rot, self.offset)
        axis = rot[..., :, 2] * self.half_length[:, None]
        return centre - axis, centre + axis, self.radius.copy()

    def body_rotations(self, poses: np.ndarray) -> np.ndarray:
        """(..., S, 3, 3) world rotations of the segments' BVH joints (the body frames: at rest
        aligned with the world, x forward, y left, z up), R_pose @ R0^T: use these, not the pose
        quaternions, for e.g. the pelvis heading. poses: (S, 7) or (F, S, 7)."""
        poses = np.asarray(poses, dtype=float)
        return quat_to_matrix(poses[..., 3:7]) @ np.swapaxes(self.rest_rotation, -1, -2)

    def lowest_point(self, poses: np.ndarray) -> float:
        """Lowest z (m) of any capsule surface over `poses` (S, 7) or (F, S, 7)."""
        p0, p1, radius = self.capsules(poses)
        return float(np.min(np.minimum(p0[..., 2], p1[..., 2]) - radius))

    def __repr__(self) -> str:
        return f'Avatar({self.num_segments} segments from {self.source})'
