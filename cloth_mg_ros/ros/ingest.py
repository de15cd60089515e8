"""Pose ingestion for cloth_node: PoseArray bytes in, checked key poses out, nothing lost.

The subscription callback only decodes a message (`pose_array_from_cdr`, microseconds, no
Pose objects) and hands it to `PoseIngest.offer`, which checks it against the previous
accepted frame and appends it to a small buffer of key poses. The simulation thread takes
every buffered key at once (`take`) and advances the cloth through all of them in one tick.
A slow tick therefore coalesces the poses that arrived meanwhile instead of queueing them,
and no valid pose is ever dropped: each one is either a key of some tick, still waiting in the
buffer, or (only when `~/reset` discards a stream) counted as discarded.

Bad frames (FRAME_KINDS) are skipped on receipt, never reach the buffer, are logged once per
kind and counted (`FrameLog`). A teleport (a jump of more than a metre) is kept, marked: the
simulation re-anchors the garment there.

Stamps and time lines. The simulated time is the newest stamp the simulation thread has
taken. A frame stamped after it is used, also when it arrives out of order (best-effort
transport reorders): it is put in its place among the buffered keys. A frame stamped at or
before it, a stamp already received, or one more than MAX_REORDER_S before the newest
received is stale: skipped and counted, the cloth untouched.
A new time line (stamps that went back: `ros2 bag play --loop`, a restarted publisher) is
told from a stray stale message by what follows: when NEW_STREAM_KEYS consecutive frames
advance from the earlier stamp, with no frame of the live stream between them, they start a
new stream: the keys of the old one still buffered are simulated first, then the garment is
re-dressed on the new one (its first NEW_STREAM_KEYS frames are its first keys: none is
lost), as after `~/reset` (which, unlike a new time line, discards the buffered keys).

The counters (`PoseCounts`) are what `cloth/stats` and the node benchmark report:
received, used, coalesced, skipped, discarded, pending, restarts, and the lag between the
newest received stamp and the simulated time.
"""

from __future__ import annotations

import bisect
import math
import threading
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from cloth_mg_ros.io.messages.cdr import CdrReader
from cloth_mg_ros.motion.frames import FrameStatus, check_frame

__all__ = [
    "FRAME_KINDS",
    "FrameLog",
    "KeyPose",
    "PoseCounts",
    "PoseIngest",
    "pose_array_from_cdr",
    "verify_pose_array_layout",
]

SUMMARY_PERIOD_S = 10.0  # s between summaries of skipped pose frames (while they change)
# A new time line (stamps that went back: `ros2 bag play --loop`, a restarted publisher) is
# believed after this many consecutive frames advancing from the earlier stamp: one stale
# message (a late sample, a stray publisher, a clock hiccup) is skipped, the cloth kept. At
# 30 Hz the new stream's first poses wait 0.13 s for the verdict; none is lost.
NEW_STREAM_KEYS = 5
MAX_REORDER_S = 1.0  # s: transport reorders by milliseconds; a frame further back is stale
RECENT_KEYS = 16  # accepted frames remembered: an out-of-order frame's neighbours

#: What each kind of skipped (or repaired) pose frame means, for the log.
FRAME_KINDS = {
    "empty": "no poses",
    "wrong_count": "not one pose per avatar segment (with body_input joints: per joint of "
                   "`skeleton`)",
    "no_body": "joints from which the body cannot be placed: the pelvis's joints missing for "
               "longer than joint_hold, coincident joints (an untracked body), or a segment's "
               "before the stream's first whole body (later, a lost segment is only dropped "
               "from the collider)",
    "non_finite": "NaN or infinite values, or a zero quaternion",
    "stale": "a header stamp at or before the simulated time (late, duplicated, or of "
             "another time line): the cloth is untouched",
    "malformed": "bytes that do not decode as a PoseArray",
    "dress_failed": "the garment could not be dressed on this pose",
    "tick_failed": "the tick that took it failed (logged): the garment is re-dressed on the "
                   "next valid pose",
    "teleport": "a jump of more than a metre: the garment was carried along (re-anchored)",
    "wrong_frame": "a header frame_id other than the stream's (that of its first pose with "
                   "one): two frames make no one body path; ~/reset starts a stream in a new "
                   "frame",
}


# ------------------------------------------------------------------------------------------
# PoseArray bytes


def pose_array_from_cdr(data: bytes | bytearray | memoryview
                        ) -> tuple[int, int, str, np.ndarray]:
    """Decode a serialised geometry_msgs/PoseArray without building Pose objects.

    Layout (plain little-endian CDR after the 4-byte encapsulation header): header.stamp
    (int32 sec, uint32 nanosec), header.frame_id (string), then a uint32 count and count
    poses of 7 float64 (position x, y, z, orientation x, y, z, w), 8-byte aligned.

    Returns (stamp sec, stamp nanosec, frame_id, poses (count, 7) float64, a fresh array).
    Raises ValueError for bytes that are not such a message.
    """
    r = CdrReader(data)
    sec, nanosec = r.unpack("iI", 4)
    frame_id = r.string()
    count = r.uint32()
    if count > r.remaining // 56 + 1:
        raise ValueError(f"PoseArray claims {count} poses in {r.remaining} bytes")
    poses = np.array(r.array(np.float64, 7 * count, 8), dtype=np.float64).reshape(count, 7)
    return sec, nanosec, frame_id, poses


def verify_pose_array_layout() -> None:
    """Check `pose_array_from_cdr` against rclpy's serialiser (frame ids of every length mod
    8, 0 to 2 poses); raises RuntimeError naming the first case that differs."""
    # imported here: ROS messages (the ROS side), loaded only when needed
    from geometry_msgs.msg import Pose, PoseArray

    # imported here: rclpy (the ROS side), loaded only when needed
    from rclpy.serialization import serialize_message

    for k in range(8):
        for n in range(3):
            msg = PoseArray()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 7 + k, 123 * n
            msg.header.frame_id = "f" * k
            vals = np.arange(7 * n, dtype=np.float64).reshape(n, 7) + 0.5
            for v in vals:
                p = Pose()
                p.position.x, p.position.y, p.position.z = (float(c) for c in v[:3])
                (p.orientation.x, p.orientation.y, p.orientation.z,
                 p.orientation.w) = (float(c) for c in v[3:])
                msg.poses.append(p)
            sec, nsec, frame, poses = pose_array_from_cdr(serialize_message(msg))
            if (sec, nsec, frame) != (7 + k, 123 * n, "f" * k) or not np.array_equal(poses,
                                                                                     vals):
                raise RuntimeError(f"geometry_msgs/PoseArray layout differs from the "
                                   f"hand-written one (frame_id length {k}, {n} poses)")


# ------------------------------------------------------------------------------------------
# Bookkeeping of skipped pose frames


class FrameLog:
    """Counts the pose frames skipped by kind (FRAME_KINDS); warns once per kind, then
    summarises. Thread-safe (the subscription and the simulation thread both note). segments:
    the poses a frame must hold, each one per `per` ('avatar segment', 'kinect32 joint')."""

    def __init__(self, logger, segments: int, per: str = "avatar segment") -> None:
        self.logger = logger
        self.segments = segments
        self.per = per
        self.counts: Counter = Counter()
        self.since_status: Counter = Counter()
        self._summarised: Counter = Counter()
        self._lock = threading.Lock()

    def note(self, kind: str, stamp: float) -> None:
        """Count one skipped (or re-anchored, kind 'teleport') frame with header stamp (s)."""
        with self._lock:
            first = not self.counts[kind]
            self.counts[kind] += 1
            self.since_status[kind] += 1
        if first:
            what = FRAME_KINDS.get(kind, kind)
            if kind == "wrong_count":
                what = f"not {self.segments} poses (one per {self.per})"
            verb = "re-anchored the garment at" if kind == "teleport" else "skipped"
            self.logger.warning(
                f"{verb} a body pose frame (stamp {stamp:.3f} s): {kind}: {what}; further "
                f"{kind} frames are counted and summarised every {SUMMARY_PERIOD_S:g} s and "
                f"at shutdown")

    def count(self, kind: str) -> int:
        """Frames of `kind` counted so far."""
        with self._lock:
            return self.counts[kind]

    def snapshot(self) -> Counter:
        """A copy of the counts by kind, taken under the lock (the subscription notes while
        the simulation thread reads)."""
        with self._lock:
            return self.counts.copy()

    @property
    def skipped(self) -> int:
        """Frames skipped (re-anchorings not counted: those frames were used)."""
        with self._lock:
            return sum(n for k, n in self.counts.items() if k != "teleport")

    def take_since_status(self) -> Counter:
        """The kinds counted since the last call (for one status message), then cleared."""
        with self._lock:
            out = self.since_status.copy()
            self.since_status.clear()
        return out

    def summary(self, received: int, used: int) -> str:
        """One line: 'pose frames: R received, U used (...); skipped S: kind n (meaning), ...'."""
        with self._lock:
            counts = self.counts.copy()
        line = f"pose frames: {received} received, {used} used"
        if counts["teleport"]:
            line += f" ({counts['teleport']} re-anchored after a teleport)"
        skipped = {k: n for k, n in sorted(counts.items()) if k != "teleport" and n}
        if skipped:
            parts = [f"skipped {n} frame{'s' if n > 1 else ''} with {k} "
                     f"({FRAME_KINDS.get(k, k)})" for k, n in skipped.items()]
            line += "; " + ", ".join(parts)
        return line

    def changed(self) -> bool:
        """Whether anything was skipped or re-anchored since the last periodic summary."""
        with self._lock:
            if self.counts == self._summarised:
                return False
            self._summarised = self.counts.copy()
            return True


# ------------------------------------------------------------------------------------------
# The key-pose buffer


@dataclass(frozen=True)
class KeyPose:
    """One accepted pose frame: header stamp (sec, nanosec, and in s), frame_id, poses
    (S, 7) [x, y, z, qx, qy, qz, qw] in m, teleport: a jump of more than teleport_m from the
    previous accepted frame (the garment is re-anchored there); generation: the ingestion's
    reset count when it arrived (keys of an older generation belong to a discarded stream);
    dropped: (S,) bool, the segments a tracker's lost joints could not place (their poses
    held, carried by their parents: ros.body_input), None when every one is placed."""

    sec: int
    nanosec: int
    stamp: float
    frame_id: str
    poses: np.ndarray
    teleport: bool = False
    generation: int = 0
    dropped: np.ndarray | None = None


@dataclass
class PoseCounts:
    """Counters of the pose stream (see the module docstring). received: messages received;
    used: valid poses simulated to or coalesced into a tick (the dressing pose and re-anchoring
    teleports included); coalesced: used as a key inside a tick that ended at a newer one;
    skipped: bad frames; discarded: valid poses a reset threw away; pending: waiting in the
    buffer (or being checked on receipt); newest_stamp: the newest accepted stamp, s (nan
    before any); restarts: new time lines started by the stream itself (NEW_STREAM_KEYS).
    Every message received is at each snapshot one of used, skipped, discarded, pending, or
    in the simulation's hands (taken, not yet counted): `lost` is what is left over."""

    received: int = 0
    used: int = 0
    coalesced: int = 0
    skipped: int = 0
    discarded: int = 0
    pending: int = 0
    newest_stamp: float = float("nan")
    restarts: int = 0

    def lost(self, in_hand: int) -> int:
        """Messages received that none of the counts holds, given `in_hand` poses the
        simulation has taken and not yet counted (held while it measures, or in the tick
        under way). 0 unless a pose went missing: the node reports it as `dropped`."""
        return (self.received - self.used - self.skipped - self.discarded - self.pending
                - in_hand)


class PoseIngest:
    """The thread-safe buffer between the subscription and the simulation thread.

    segments: poses per frame (the avatar's segments, or the skeleton's joints with joints);
    teleport_m: a larger jump between two accepted frames is a teleport (of a segment's or a
    joint's position); frames: the FrameLog noting skipped frames; joints: the poses are a
    body tracker's joint positions (body_input joints: their orientations are ignored, set to
    the identity on receipt); on_restart:
    called as on_restart(previous stamp, new stamp) (s) when a new time line has started
    (NEW_STREAM_KEYS poses went on from an earlier stamp; see the module docstring).
    """

    def __init__(self, segments: int, teleport_m: float, frames: FrameLog,
                 on_restart=None, joints: bool = False) -> None:
        self.segments = segments
        self.joints = joints
        self.teleport_m = teleport_m
        self.frames = frames
        self.on_restart = on_restart
        self._cond = threading.Condition()
        self._keys: list[KeyPose] = []  # by stamp: older generations first, then the live one
        # The live stream's latest accepted frames, by stamp (taken ones too): an
        # out-of-order frame's predecessor for the teleport check, and duplicates.
        self._recent: list[KeyPose] = []
        self._taken_to = -math.inf  # the newest stamp taken by the simulation (live stream)
        self._candidates: list[KeyPose] = []  # stale frames that may start a new time line
        self._generation = 0
        self._live_from = 0
        self._frame_id = ""  # the stream's frame: its first pose's with one ("": none yet)
        self._counts = PoseCounts()
        # Messages counted as received whose fate (skipped, buffered, a candidate) is not yet
        # counted: a snapshot counts them as pending, so that its counts always add up.
        self._checking = 0

    # -- the subscription side ----------------------------------------------------------
    def offer(self, data: bytes) -> FrameStatus | None:
        """Decode and check one PoseArray message (raw CDR bytes); keep it as a key pose if
        it is valid and still ahead of the simulated time. Returns its FrameStatus (None for
        undecodable bytes; STALE for a frame at or before the simulated time, also while it
        waits to see whether a new time line follows it)."""
        with self._cond:
            self._counts.received += 1
            self._checking += 1
        try:
            sec, nanosec, frame_id, poses = pose_array_from_cdr(data)
        except ValueError:
            self._skip("malformed", float("nan"), checked=True)
            return None
        return self._offer(sec, nanosec, frame_id, poses)

    def offer_frame(self, sec: int, nanosec: int, frame_id: str, poses: np.ndarray
                    ) -> FrameStatus:
        """`offer` for a frame decoded elsewhere (body_input kinect_markers: a MarkerArray's
        joints): stamp sec, nanosec; poses (S, 7) [x, y, z, qx, qy, qz, qw], NaN for a
        missing joint."""
        with self._cond:
            self._counts.received += 1
            self._checking += 1
        return self._offer(sec, nanosec, frame_id, np.array(poses, dtype=np.float64))

    def _offer(self, sec: int, nanosec: int, frame_id: str, poses: np.ndarray
               ) -> FrameStatus:
        stamp = sec + 1e-9 * nanosec
        with self._cond:
            status = FrameStatus.OK
            if frame_id and self._frame_id and frame_id != self._frame_id:
                status = FrameStatus.WRONG_FRAME
        if status == FrameStatus.OK:
            status = self._check(stamp, poses)
        if status != FrameStatus.OK:
            self._skip(status.value, stamp, checked=True)
            return status
        restarted = None
        with self._cond:
            self._checking -= 1  # buffered or a candidate, both pending
            key = KeyPose(sec, nanosec, stamp, frame_id, poses, generation=self._generation)
            if self._is_ahead(stamp):
                stale = self._drop_candidates()
                status = self._accept(key)
            else:
                stale = []
                if self._candidates and stamp <= self._candidates[-1].stamp:
                    stale = self._drop_candidates()  # not going on from the earlier stamp
                self._candidates.append(key)
                status = FrameStatus.STALE
                if len(self._candidates) >= NEW_STREAM_KEYS:
                    restarted = (self.newest_live_stamp(), self._candidates[0].stamp)
                    self._restart(keep=True)  # the old stream's buffered keys still get simulated
                    candidates, self._candidates = self._candidates, []
                    for k in candidates:
                        self._accept(replace(k, generation=self._generation))
                    self._counts.restarts += 1
                    status = FrameStatus.OK
        for k in stale:
            self.frames.note("stale", k.stamp)  # counted by _drop_candidates
        if restarted is not None and self.on_restart is not None:
            self.on_restart(*restarted)
        return status

    def _check(self, stamp: float, poses: np.ndarray, before: np.ndarray | None = None
               ) -> FrameStatus:
        """check_frame's verdict on a frame (before: the previous one's poses, for the
        teleport). Joints (body_input joints) are positions: their orientations are set to
        the identity here, a missing joint (NaN) is allowed while one is there (the body
        scene holds it: motion.joint_track), and a teleport is a jump of a joint seen in both
        frames."""
        if not self.joints or poses.ndim != 2 or poses.shape[1] != 7:
            return check_frame(None, stamp, poses, self.segments, before,
                               teleport_m=self.teleport_m)
        poses[:, 3:] = (0.0, 0.0, 0.0, 1.0)  # whatever was sent
        seen = np.isfinite(poses[:, :3]).all(axis=1)
        if poses.shape[0] == self.segments and not seen.any():
            return FrameStatus.NON_FINITE
        filled = poses.copy()
        filled[~seen] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # a missing joint: checked later
        status = check_frame(None, stamp, filled, self.segments)
        if status != FrameStatus.OK or before is None:
            return status
        both = seen & np.isfinite(before[:, :3]).all(axis=1)
        jump = np.linalg.norm(poses[both, :3] - before[both, :3], axis=1)
        return FrameStatus.TELEPORT if jump.size and jump.max() > self.teleport_m else status

    def _is_ahead(self, stamp: float) -> bool:
        """Whether a frame stamped `stamp` can still be used on the live stream (lock held):
        after the simulated time, not a stamp already received, and not further back than
        MAX_REORDER_S from the newest (a time line that went back, not transport)."""
        return (stamp > self._taken_to and stamp > self.newest_live_stamp() - MAX_REORDER_S
                and not any(k.stamp == stamp for k in self._recent))

    def _accept(self, key: KeyPose) -> FrameStatus:
        """Buffer a valid frame of the live stream in stamp order, marked when it jumped more
        than teleport_m from the frame before it in time (with the lock held)."""
        stamps = [k.stamp for k in self._recent]
        at = bisect.bisect(stamps, key.stamp)
        before = self._recent[at - 1] if at else None
        status = self._check(key.stamp, key.poses, None if before is None else before.poses)
        key = replace(key, teleport=status == FrameStatus.TELEPORT)
        self._frame_id = self._frame_id or key.frame_id
        self._recent.insert(at, key)
        del self._recent[:-RECENT_KEYS]
        at_keys = bisect.bisect([k.stamp if k.generation == key.generation else -math.inf
                                 for k in self._keys], key.stamp)
        self._keys.insert(at_keys, key)
        self._counts.newest_stamp = self.newest_live_stamp()
        self._cond.notify_all()
        return status

    def newest_live_stamp(self) -> float:
        """The newest stamp accepted on the live stream, s (-inf before any; lock held)."""
        return self._recent[-1].stamp if self._recent else -math.inf

    def _drop_candidates(self) -> list[KeyPose]:
        """Give up the frames that might have started a new time line (lock held): they were
        stale after all. Counted as skipped here, with the lock held, so that no snapshot
        sees them gone from pending and not yet skipped; returns them for the caller to note
        in the FrameLog outside the lock."""
        dropped, self._candidates = self._candidates, []
        self._counts.skipped += len(dropped)
        return dropped

    def _skip(self, kind: str, stamp: float, checked: bool = False) -> None:
        """Count and note a skipped frame; checked: one being checked on receipt (no longer
        pending)."""
        with self._cond:
            self._counts.skipped += 1
            self._checking -= checked
        self.frames.note(kind, stamp)

    # -- the simulation side ------------------------------------------------------------
    def take(self, timeout: float | None = None) -> list[KeyPose]:
        """Every buffered key pose (oldest first), waiting up to `timeout` s for one (None:
        return at once). The buffer is empty afterwards."""
        with self._cond:
            if not self._keys and timeout:
                self._cond.wait(timeout)
            keys, self._keys = self._keys, []
            for k in keys:
                if k.generation == self._generation:
                    self._taken_to = max(self._taken_to, k.stamp)
            return keys

    def wake(self) -> None:
        """Wake a `take` that is waiting (shutdown, a reset, a parameter change)."""
        with self._cond:
            self._cond.notify_all()

    def used(self, keys: int, coalesced: int = 0) -> None:
        """Count keys that a tick consumed, of which `coalesced` were not its newest."""
        with self._cond:
            self._counts.used += keys
            self._counts.coalesced += coalesced

    def skip_taken(self, kind: str, stamp: float) -> None:
        """A key the simulation took but cannot use (kind of FRAME_KINDS): counted as
        skipped, no longer as taken."""
        self._skip(kind, stamp)

    def discard(self, keys: int) -> None:
        """Count keys of a discarded stream (taken before a reset, never simulated)."""
        with self._cond:
            self._counts.discarded += keys

    def reset(self) -> None:
        """Start a new stream: forget the last accepted frame (the stamps may start over, the
        frame_id may change) and discard the buffered keys; keys of the old stream still in a
        consumer's hands carry an older generation."""
        with self._cond:
            self._restart(keep=False)
            self._live_from = self._generation
            self._frame_id = ""

    def _restart(self, keep: bool) -> None:
        """A new stream (generation), with the lock held; keep: leave the buffered keys of
        the old one to be simulated (a looped bag), else discard them (~/reset)."""
        if not keep:
            self._counts.discarded += len(self._keys) + len(self._candidates)
            self._keys, self._candidates = [], []
        self._recent = []
        self._taken_to = -math.inf
        self._generation += 1
        self._cond.notify_all()

    @property
    def generation(self) -> int:
        """The stream new keys belong to (0 at start, +1 at each reset or restart)."""
        with self._cond:
            return self._generation

    @property
    def live_from(self) -> int:
        """The oldest generation still to be simulated: keys of older ones were taken
        before a ~/reset discarded their stream."""
        with self._cond:
            return self._live_from

    def close(self) -> None:
        """At shutdown: frames still waiting to see whether a new time line followed them
        were stale."""
        with self._cond:
            stale = self._drop_candidates()
        for k in stale:
            self.frames.note("stale", k.stamp)  # counted by _drop_candidates

    def counts(self) -> PoseCounts:
        """A snapshot of the counters (pending: keys in the buffer now, stale frames waiting
        to see whether a new time line follows them, and messages being checked)."""
        with self._cond:
            snap = PoseCounts(**vars(self._counts))
            snap.pending = len(self._keys) + len(self._candidates) + self._checking
            return snap
