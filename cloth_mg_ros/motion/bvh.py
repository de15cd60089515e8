"""Biovision Hierarchy (BVH) motion capture: a validating reader and vectorised forward kinematics.

A BVH file has two parts. HIERARCHY declares a tree of joints, each with an OFFSET from its
parent (in file units) and a CHANNELS list (any order of Xposition, Yposition, Zposition,
Xrotation, Yrotation, Zrotation); an `End Site` closes a chain with an offset and no channels.
MOTION declares `Frames: N`, `Frame Time: t` (s) and N rows holding one value per channel, in the
order the channels were declared, joint by joint (depth first).

Conventions implemented here (those of the CMU "cgspeed" conversion and of most BVH tools):

- Rotation channels are in degrees. A joint's local rotation is the product of the elementary
  rotations in the order its channels declare them, e.g. `Zrotation Yrotation Xrotation` gives
  R_local = Rz(z) @ Ry(y) @ Rx(x) (intrinsic; column vectors, R maps child to parent coordinates).
- A joint's world rotation is R_world(parent) @ R_local, its world position is
  p_world(parent) + R_world(parent) @ (OFFSET + position channels). Position channels (normally
  only on the root) are added to the OFFSET.
- Lengths (OFFSET, position channels) are converted to metres with `units_to_m` at load time;
  the CMU conversion uses 1 unit = 0.056444 m (`CMU_UNITS_TO_M`).

Axes. BVH files here are Y-up with the subject walking along +Z and its left along +X. ROS (REP
103) is z-up with x forward and y left. `forward_kinematics(..., ros=True)` (the default) maps a
BVH vector v to ROS coordinates with the proper rotation (det = +1, no mirroring)

    (x_ros, y_ros, z_ros) = (Z_bvh, X_bvh, Y_bvh),   v_ros = BVH_TO_ROS @ v_bvh,

and a rotation matrix with R_ros = BVH_TO_ROS @ R_bvh @ BVH_TO_ROS.T. So locomotion along +Z_bvh
runs along +x, up is +z, and the subject's left (+X_bvh) is +y. `BvhClip` itself keeps the file's
axes; only the forward-kinematics output is converted.

Frames. CMU frame 0 is a reference T-pose, not motion, and some clips hold all-zero frames (07_12
frame 1): `read_bvh` drops the first `skip_first` frames (default 1) and, with
`skip_zero_frames=True` (default), the rows after them whose channels are all exactly zero,
up to the first that is not (one inside the motion is kept: the clip's frames are evenly
spaced in time).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = [
    'BVH_TO_ROS',
    'CMU_UNITS_TO_M',
    'BvhClip',
    'euler_to_matrix',
    'forward_kinematics',
    'read_bvh',
]

#: Metres per BVH unit in the CMU "cgspeed" conversion.
CMU_UNITS_TO_M = 0.056444

#: Rotation taking BVH (Y-up, walking along +Z, left +X) to ROS (z-up, x forward, y left):
#: (x, y, z)_ros = (Z, X, Y)_bvh. A cyclic permutation, so det = +1 (no mirroring).
BVH_TO_ROS = np.array([[0.0, 0.0, 1.0],
                       [1.0, 0.0, 0.0],
                       [0.0, 1.0, 0.0]])

_POSITION_CHANNELS = ('Xposition', 'Yposition', 'Zposition')
_ROTATION_CHANNELS = ('Xrotation', 'Yrotation', 'Zrotation')
_CHANNELS = _POSITION_CHANNELS + _ROTATION_CHANNELS


@dataclass
class BvhClip:
    """A parsed BVH clip (file axes: Y up for CMU; lengths in metres; angles in degrees).

    Attributes:
        path: the file it was read from.
        joint_names: J joint names in file (depth-first) order; `End Site`s are not joints.
        parents: (J,) int index of each joint's parent, -1 for the root; parents come first.
        offsets: (J, 3) float OFFSET of each joint from its parent, metres, file axes.
        end_sites: (J, 3) float End Site offset of each joint, metres (NaN where it has none).
        channels: per joint, the tuple of its channel names in declared order.
        channel_start: (J,) int column of each joint's first channel in `frames`.
        frames: (F, C) float64 channel values of the kept frames: rotations in degrees,
            positions converted to metres.
        frame_time: seconds between frames (1/120 for CMU).
        source_frames: (F,) int index of each kept frame in the file's MOTION rows.
        units_to_m: metres per file unit used for the conversion.
    """

    path: str
    joint_names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    end_sites: np.ndarray
    channels: list[tuple[str, ...]]
    channel_start: np.ndarray
    frames: np.ndarray
    frame_time: float
    source_frames: np.ndarray
    units_to_m: float = CMU_UNITS_TO_M
    _index: dict[str, int] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._index = {name: i for i, name in enumerate(self.joint_names)}

    @property
    def num_frames(self) -> int:
        """F, the number of kept frames."""
        return int(self.frames.shape[0])

    @property
    def num_joints(self) -> int:
        """J, the number of joints (End Sites excluded)."""
        return len(self.joint_names)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last kept frame: (F - 1) * frame_time."""
        return max(self.num_frames - 1, 0) * self.frame_time

    @property
    def rate(self) -> float:
        """Frames per second, 1 / frame_time."""
        return 1.0 / self.frame_time

    def times(self) -> np.ndarray:
        """(F,) time of each kept frame in seconds, the first kept frame at 0."""
        return np.arange(self.num_frames, dtype=float) * self.frame_time

    def joint_index(self, name: str) -> int:
        """Index of joint `name`; ClothInputError naming the file if it has no such joint."""
        try:
            return self._index[name]
        except KeyError:
            raise ClothInputError(
                f'{self.path}: no joint named {name!r} (joints: {", ".join(self.joint_names)})'
            ) from None

    def channel(self, joint: str | int, name: str) -> np.ndarray:
        """(F,) values of one channel (e.g. 'Yposition') of a joint, as stored in `frames`."""
        j = self.joint_index(joint) if isinstance(joint, str) else int(joint)
        if name not in self.channels[j]:
            raise ClothInputError(f'{self.path}: joint {self.joint_names[j]!r} has no channel '
                                  f'{name!r} (has {", ".join(self.channels[j]) or "none"})')
        return self.frames[:, self.channel_start[j] + self.channels[j].index(name)]


# --------------------------------------------------------------------------------------------
# Reading


class _Tokens:
    """Whitespace tokens of the HIERARCHY part, each with its 1-based line number."""

    def __init__(self, path: str, lines: list[str]) -> None:
        self.path = path
        self.items: list[tuple[str, int]] = []
        self.motion_line = None
        for lineno, line in enumerate(lines, start=1):
            words = line.split()
            if words and words[0] == 'MOTION':
                self.motion_line = lineno
                break
            self.items.extend((w, lineno) for w in words)
        self.pos = 0
        self.last_line = len(lines)

    def error(self, lineno: int, problem: str) -> ClothInputError:
        return ClothInputError(f'{self.path}: line {lineno}: {problem}')

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            where = self.motion_line or self.last_line
            raise self.error(where, f'truncated HIERARCHY: expected {what}, found '
                                    f'{"MOTION" if self.motion_line else "end of file"}')
        item = self.items[self.pos]
        self.pos += 1
        return item

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    def expect(self, word: str) -> int:
        token, lineno = self.next(repr(word))
        if token != word:
            raise self.error(lineno, f'expected {word!r}, found {token!r}')
        return lineno

    def number(self, what: str) -> float:
        token, lineno = self.next(what)
        try:
            value = float(token)
        except ValueError:
            raise self.error(lineno, f'{what}: cannot read {token!r} as a number') from None
        if not math.isfinite(value):
            raise self.error(lineno, f'{what}: non-finite value {token!r}')
        return value


class _Hierarchy:
    """The joints of a HIERARCHY as they are read (depth first): names, parents, OFFSETs and
    End Site offsets (m; NaN where a joint has none), channels."""

    def __init__(self, tok: _Tokens, units_to_m: float) -> None:
        self.tok, self.units_to_m = tok, units_to_m
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[list[float]] = []
        self.end_sites: list[list[float]] = []
        self.channels: list[tuple[str, ...]] = []

    def offset(self, owner: str) -> list[float]:
        self.tok.expect('OFFSET')
        return [self.tok.number(f'OFFSET {axis} of {owner}') * self.units_to_m
                for axis in 'XYZ']

    def joint(self, parent: int) -> None:
        """A joint (its name token next), its channels and, recursively, its children."""
        tok = self.tok
        name, lineno = tok.next('a joint name')
        if name in ('{', '}'):
            raise tok.error(lineno, f'expected a joint name, found {name!r}')
        if name in self.names:
            raise tok.error(lineno, f'duplicate joint name {name!r}')
        index = len(self.names)
        self.names.append(name)
        self.parents.append(parent)
        self.end_sites.append([math.nan] * 3)
        tok.expect('{')
        self.offsets.append(self.offset(name))
        self.channels.append(self._channels(name))
        self._children(name, index)

    def _channels(self, name: str) -> tuple[str, ...]:
        tok = self.tok
        token, lineno = tok.next(f'CHANNELS of {name}')
        if token != 'CHANNELS':
            raise tok.error(lineno, f'joint {name!r}: expected CHANNELS, found {token!r}')
        count_token, lineno = tok.next(f'channel count of {name}')
        try:
            count = int(count_token)
        except ValueError:
            raise tok.error(lineno, f'joint {name!r}: channel count {count_token!r} is not an '
                                    'integer') from None
        if not 0 <= count <= 6:
            raise tok.error(lineno, f'joint {name!r}: channel count {count} outside 0..6')
        chans = []
        for _ in range(count):
            ch, lineno = tok.next(f'a channel name of {name}')
            if ch not in _CHANNELS:
                raise tok.error(lineno, f'joint {name!r}: unknown channel {ch!r} (known: '
                                        f'{", ".join(_CHANNELS)})')
            if ch in chans:
                raise tok.error(lineno, f'joint {name!r}: channel {ch!r} declared twice')
            chans.append(ch)
        return tuple(chans)

    def _children(self, name: str, index: int) -> None:
        """The JOINTs and End Site of joint `index`, up to its closing brace."""
        tok = self.tok
        while True:
            token, lineno = tok.next(f'JOINT, End Site or }} closing {name}')
            if token == '}':
                return
            if token == 'JOINT':
                self.joint(index)
            elif token == 'End':
                site, lineno = tok.next("'Site'")
                if site != 'Site':
                    raise tok.error(lineno, f"expected 'Site' after 'End', found {site!r}")
                tok.expect('{')
                self.end_sites[index] = self.offset(f'End Site of {name}')
                tok.expect('}')
            else:
                raise tok.error(lineno, f'joint {name!r}: expected JOINT, End Site or }}, '
                                        f'found {token!r}')


def _parse_hierarchy(tok: _Tokens, units_to_m: float):
    """(names, parents, offsets, end_sites, channels) of the one ROOT's tree (`_Hierarchy`)."""
    h = _Hierarchy(tok, units_to_m)
    token, lineno = tok.next('HIERARCHY')
    if token != 'HIERARCHY':
        raise tok.error(lineno, f'not a BVH file: expected HIERARCHY, found {token!r}')
    tok.expect('ROOT')
    h.joint(-1)
    extra = tok.peek()
    if extra is not None:
        raise tok.error(tok.items[tok.pos][1], f'unexpected {extra!r} after the root joint '
                                               '(a second ROOT is not supported)')
    return h.names, h.parents, h.offsets, h.end_sites, h.channels


def _parse_motion(path: str, lines: list[str], start: int, num_channels: int):
    """Parse MOTION from 0-based line index `start` (the MOTION line). Returns (rows,
    frame_time)."""

    def err(lineno: int, problem: str) -> ClothInputError:
        return ClothInputError(f'{path}: line {lineno}: {problem}')

    num_frames, frame_time, i = _motion_header(lines, start + 1, err)
    rows = np.empty((num_frames, num_channels))
    k = 0
    while i < len(lines) and k < num_frames:
        lineno = i + 1
        words = lines[i].split()
        i += 1
        if not words:
            continue
        rows[k] = _frame_row(words, k, num_channels, lineno, err)
        k += 1
    if k < num_frames:
        raise err(len(lines), f'truncated MOTION: Frames: {num_frames} declared but only {k} '
                              'frame rows found')
    for j in range(i, len(lines)):
        if lines[j].strip():
            raise err(j + 1, f'more frame rows than Frames: {num_frames} declares')
    return rows, frame_time


def _motion_header(lines: list[str], i: int, err) -> tuple[int, float, int]:
    """("Frames: N", "Frame Time: t" (s)) from line index i on (blank lines skipped), and the
    index of the line after them."""
    header = {}
    for key in ('Frames:', 'Frame Time:'):
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise err(len(lines), f'truncated MOTION: missing {key!r}')
        line = lines[i].strip()
        if not line.startswith(key):
            raise err(i + 1, f'expected {key!r}, found {line[:40]!r}')
        value = line[len(key):].strip()
        try:
            header[key] = int(value) if key == 'Frames:' else float(value)
        except ValueError:
            raise err(i + 1, f'{key} {value!r} is not a number') from None
        i += 1
    num_frames, frame_time = header['Frames:'], header['Frame Time:']
    if num_frames < 0:
        raise err(i - 1, f'Frames: {num_frames} is negative')
    if not (math.isfinite(frame_time) and frame_time > 0.0):
        raise err(i, f'Frame Time: {frame_time} must be a positive number of seconds')
    return num_frames, frame_time, i


def _frame_row(words: list[str], k: int, num_channels: int, lineno: int, err) -> np.ndarray:
    """Frame k's values from the words of its row, line `lineno`."""
    if len(words) != num_channels:
        raise err(lineno, f'frame {k}: expected {num_channels} values, found {len(words)}'
                  + (' (short row: truncated file?)' if len(words) < num_channels else ''))
    try:
        row = np.array(words, dtype=float)
    except ValueError:
        for col, word in enumerate(words):
            try:
                float(word)
            except ValueError:
                raise err(lineno, f'frame {k}, column {col}: cannot read {word!r} as a '
                          'number') from None
        raise
    if not np.all(np.isfinite(row)):
        col = int(np.flatnonzero(~np.isfinite(row))[0])
        raise err(lineno, f'frame {k}, column {col}: non-finite value {words[col]!r}')
    return row


def read_bvh(path: str | os.PathLike, *, units_to_m: float = CMU_UNITS_TO_M,
             skip_first: int = 1, skip_zero_frames: bool = True) -> BvhClip:
    """Read and validate a BVH file.

    Args:
        path: the .bvh file.
        units_to_m: metres per file length unit (CMU: 0.056444).
        skip_first: number of leading MOTION rows to drop (CMU frame 0 is a T-pose: 1).
        skip_zero_frames: also drop rows whose channels are all exactly zero (07_12 frame 1).

    Returns:
        a `BvhClip` with lengths in metres, angles in degrees, file axes.

    Raises:
        ClothInputError: missing or unreadable file, malformed HIERARCHY, unknown channel name,
            a garbled or non-finite number, fewer frame rows than `Frames:` declares, a short
            row, or no frame left after skipping. Messages name the file, the line and the
            problem.
    """
    path = os.fspath(path)
    lines = _bvh_lines(path, units_to_m, skip_first)
    tok = _Tokens(path, lines)
    names, parents, offsets, end_sites, channels = _parse_hierarchy(tok, units_to_m)
    if tok.motion_line is None:
        raise ClothInputError(f'{path}: line {len(lines)}: truncated file: no MOTION section')
    counts = [len(c) for c in channels]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    num_channels = int(sum(counts))
    rows, frame_time = _parse_motion(path, lines, tok.motion_line - 1, num_channels)

    # lengths to metres
    for j, chans in enumerate(channels):
        for c, name in enumerate(chans):
            if name in _POSITION_CHANNELS:
                rows[:, starts[j] + c] *= units_to_m

    keep = np.arange(rows.shape[0]) >= skip_first
    if skip_zero_frames:
        # the all-zero rows before the motion starts only: one dropped inside the clip would
        # pull every later frame a frame time earlier (the clip's times are evenly spaced)
        zero = ~np.any(rows != 0.0, axis=1)
        keep &= ~(zero & (np.cumsum(keep & ~zero) == 0))
    source = np.flatnonzero(keep)
    if source.size == 0:
        raise ClothInputError(f'{path}: no motion frames left after skipping (Frames: '
                              f'{rows.shape[0]}, skip_first={skip_first}, '
                              f'skip_zero_frames={skip_zero_frames})')
    return BvhClip(
        path=path,
        joint_names=names,
        parents=np.array(parents, dtype=np.int64),
        offsets=np.array(offsets, dtype=float).reshape(-1, 3),
        end_sites=np.array(end_sites, dtype=float).reshape(-1, 3),
        channels=channels,
        channel_start=starts,
        frames=np.ascontiguousarray(rows[source]),
        frame_time=float(frame_time),
        source_frames=source,
        units_to_m=float(units_to_m),
    )


def _bvh_lines(path: str, units_to_m: float, skip_first: int) -> list[str]:
    """The file's lines, once the options are checked and the file found and read as UTF-8
    (ClothInputError otherwise)."""
    if not (isinstance(units_to_m, (int, float)) and math.isfinite(units_to_m)
            and units_to_m > 0):
        raise ClothInputError(f'{path}: units_to_m must be a positive number, got {units_to_m!r}')
    if int(skip_first) != skip_first or skip_first < 0:
        raise ClothInputError(f'{path}: skip_first must be a non-negative integer, '
                              f'got {skip_first!r}')
    p = Path(path)
    if not p.is_file():
        raise ClothInputError(f'{path}: BVH file not found' if not p.exists()
                              else f'{path}: not a file')
    try:
        text = p.read_text(encoding='utf-8', errors='strict')
    except (OSError, UnicodeDecodeError) as exc:
        raise ClothInputError(f'{path}: cannot read BVH file: {exc}') from None
    return text.splitlines()


# --------------------------------------------------------------------------------------------
# Kinematics


def _axis_rotation(axis: str, degrees: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations about the X, Y or Z axis by `degrees` (F,) (right-handed)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    i = 'XYZ'.index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def euler_to_matrix(order: str, degrees: np.ndarray) -> np.ndarray:
    """Rotation matrices from BVH Euler angles.

    Args:
        order: axes in channel order, e.g. 'ZYX' for `Zrotation Yrotation Xrotation`.
        degrees: (..., len(order)) angles in degrees, in the same order.

    Returns:
        (..., 3, 3) R = R_order[0] @ R_order[1] @ ... (e.g. Rz @ Ry @ Rx for 'ZYX').
    """
    degrees = np.asarray(degrees, dtype=float)
    out = np.broadcast_to(np.eye(3), degrees.shape[:-1] + (3, 3)).copy()
    for n, axis in enumerate(order):
        out = out @ _axis_rotation(axis, degrees[..., n])
    return out


def _local_transforms(clip: BvhClip) -> tuple[np.ndarray, np.ndarray]:
    """(F, J, 3, 3) local rotations and (F, J, 3) local translations (metres, file axes)."""
    F, J = clip.num_frames, clip.num_joints
    rot = np.broadcast_to(np.eye(3), (F, J, 3, 3)).copy()
    trans = np.broadcast_to(clip.offsets, (F, J, 3)).copy()
    for j, chans in enumerate(clip.channels):
        start = clip.channel_start[j]
        order = ''.join(c[0] for c in chans if c in _ROTATION_CHANNELS)
        cols = [start + n for n, c in enumerate(chans) if c in _ROTATION_CHANNELS]
        if order:
            rot[:, j] = euler_to_matrix(order, clip.frames[:, cols])
        for n, c in enumerate(chans):
            if c in _POSITION_CHANNELS:
                trans[:, j, 'XYZ'.index(c[0])] += clip.frames[:, start + n]
    return rot, trans


def forward_kinematics(clip: BvhClip, *, ros: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """World rotation and position of every joint in every kept frame.

    Vectorised over frames: one numpy product per joint, no loop over frames.

    Args:
        clip: a parsed clip.
        ros: convert to ROS axes (z up, x = BVH +Z forward, y = BVH +X left); False keeps the
            file's axes.

    Returns:
        rotations (F, J, 3, 3): each joint's world rotation (maps joint-frame vectors to world);
        positions (F, J, 3): each joint's world position in metres.
    """
    local_rot, local_trans = _local_transforms(clip)
    world_rot = np.empty_like(local_rot)
    world_pos = np.empty_like(local_trans)
    for j, parent in enumerate(clip.parents):
        if parent < 0:
            world_rot[:, j] = local_rot[:, j]
            world_pos[:, j] = local_trans[:, j]
        else:
            world_rot[:, j] = world_rot[:, parent] @ local_rot[:, j]
            world_pos[:, j] = world_pos[:, parent] + np.einsum(
                'fab,fb->fa', world_rot[:, parent], local_trans[:, j])
    if ros:
        world_rot = BVH_TO_ROS @ world_rot @ BVH_TO_ROS.T
        world_pos = world_pos @ BVH_TO_ROS.T
    return world_rot, world_pos
