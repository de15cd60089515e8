"""A body tracker's joints over time, before they place the body: missing joints held, jitter
filtered (`JointTrack`).

Trackers lose joints (occlusion: NaN, or a joint marked untracked) and jitter by millimetres. A
missing joint is held for up to `hold_s`: carried by its parent on the body's tree (a wrist by
its elbow, an ankle by its knee: `Skeleton.hold_parents`) at the offset it last had from it, so
that it goes where the body goes (held still in the world, a hidden wrist of a walker lagged
0.4 m behind within half a second, a hidden ankle stretched its foot's capsule over a metre).
The offset is not turned with the parent's bone: that helped a swinging arm and hurt a jumping
leg as much (the knee bends against the thigh), over the bundled clips. A joint without a
parent, or whose parent is lost (missing past `hold_s`) or was never seen, stays where it
was last seen; a parent that is itself held carries it from where it carries the parent
(parents are placed first: a hidden ear follows a hidden nose that follows a shoulder,
`HOLD_FALLBACK`). Past `hold_s` it stays
missing (NaN) and the segments that need it cannot be placed until it comes back. Jitter is
smoothed per joint and axis by the 1 Euro filter (Casiez, Roussel and Vogel, "1 Euro Filter: A
Simple Speed-based Low-pass Filter for Noisy Input in Interactive Systems", CHI 2012): a
first-order low-pass whose cut-off rises with the joint's speed, f_c = min_cutoff + beta
|dx/dt|, so a joint at rest is smoothed hard and a moving one follows with little lag; the
speed itself is low-passed at d_cutoff. Written here (a few lines of numpy over the joints)
rather than taken from a package: the filter must run vectorised over (J, 3) on the simulation
thread, hold state across ticks and skip the joints that are missing.

Units SI: m, s, Hz; beta in 1/m (Hz per m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = ["JointTrack", "TrackCounts"]


def _parents_first(parents: np.ndarray, joints: int) -> np.ndarray:
    """(J,) the joints in an order that puts each after its parent; ClothInputError for
    parents that are not (J,) indices or -1, or that form a cycle."""
    if parents.shape != (joints,) or np.any((parents < -1) | (parents >= joints)):
        raise ClothInputError(f"joint track: parents must be ({joints},) joint indices or -1, "
                              f"got {parents.tolist()}")
    depth = np.zeros(joints, dtype=np.int64)
    for j in range(joints):  # J is a few dozen: a walk up per joint is cheap and says a cycle
        k, steps = j, 0
        while parents[k] >= 0:
            k, steps = parents[k], steps + 1
            if steps > joints:
                raise ClothInputError(f"joint track: parents form a cycle through joint {j}: "
                                      f"{parents.tolist()}")
        depth[j] = steps
    return np.argsort(depth, kind="stable")


def _alpha(cutoff_hz: np.ndarray | float, dt: float) -> np.ndarray | float:
    """The smoothing factor of a first-order low-pass at cutoff_hz over a step of dt s."""
    tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz))
    return 1.0 / (1.0 + tau / dt)


@dataclass
class TrackCounts:
    """held: joint samples filled from a joint's last position (missing for up to hold_s);
    lost: joint samples missing for longer (their segments could not be placed)."""

    held: int = 0
    lost: int = 0


class JointTrack:
    """Hold and filter a stream of joint frames (module docstring).

    joints: J, the joints per frame; hold_s: how long a missing joint is held, s (0: never);
    min_cutoff: the filter's cut-off at rest, Hz (0: no filter); beta: how fast the cut-off
    rises with speed, 1/m; d_cutoff: the speed's own low-pass, Hz; parents: (J,) each
    joint's carrier while hidden (-1: none; acyclic), None: all held still.
    """

    def __init__(self, joints: int, hold_s: float = 0.5, min_cutoff: float = 0.0,
                 beta: float = 0.0, d_cutoff: float = 1.0,
                 parents: np.ndarray | None = None) -> None:
        for name, value in (("hold_s", hold_s), ("min_cutoff", min_cutoff), ("beta", beta),
                            ("d_cutoff", d_cutoff)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ClothInputError(f"joint track: {name} must be a number >= 0, got "
                                      f"{value!r}")
        if min_cutoff > 0.0 and d_cutoff <= 0.0:
            raise ClothInputError("joint track: d_cutoff must be > 0 when filtering")
        self.hold_s, self.min_cutoff, self.beta, self.d_cutoff = (
            hold_s, min_cutoff, beta, d_cutoff)
        self.parents = (np.full(joints, -1, dtype=np.int64) if parents is None
                        else np.asarray(parents, dtype=np.int64).reshape(-1))
        self.order = _parents_first(self.parents, joints)
        self.offset = np.full((joints, 3), np.nan)  # from its parent when last both seen, m
        self.last = np.full((joints, 3), np.nan)  # each joint's last seen (raw) position, m
        self.seen = np.full(joints, -math.inf)  # ... and its stamp, s
        self.smooth = np.full((joints, 3), np.nan)  # the filter's output, m
        self.speed = np.zeros((joints, 3))  # its filtered velocity, m/s
        self.stamp: float | None = None  # the last frame's stamp, s
        self.counts = TrackCounts()

    def reset(self) -> None:
        """Forget the stream (a new one starts: a reset, a looped bag); the counts go on."""
        counts = self.counts
        self.__init__(len(self.last), self.hold_s, self.min_cutoff, self.beta, self.d_cutoff,
                      self.parents)
        self.counts = counts

    def update(self, stamp: float, joints: np.ndarray) -> np.ndarray:
        """The frame at `stamp` (s) of joints (J, 3) m, NaN where a joint is missing, after
        holding and filtering: (J, 3) m, NaN where a joint has been missing longer than
        hold_s (or was never seen). Frames must come in increasing stamps."""
        x = np.array(joints, dtype=np.float64)
        if x.shape != self.last.shape:
            raise ClothInputError(f"joint track: a frame of shape {x.shape}, expected "
                                  f"{self.last.shape}")
        present = np.isfinite(x).all(axis=1)
        self.last[present], self.seen[present] = x[present], stamp
        self._remember(x, present)
        held = ~present & (stamp - self.seen <= self.hold_s)
        for j in self.order[held[self.order]]:  # a few joints; parents first
            x[j] = self._carried(j, x)
        self.counts.held += int(held.sum())
        self.counts.lost += int((~present & ~held).sum())
        out = self._filter(stamp, x) if self.min_cutoff > 0.0 else x
        self.stamp = stamp
        return out

    def _remember(self, x: np.ndarray, present: np.ndarray) -> None:
        """Each seen joint's offset from its seen parent."""
        has = self.parents >= 0
        both = present & has
        both[has] &= present[self.parents[has]]
        self.offset[both] = x[both] - x[self.parents[both]]

    def _carried(self, j: int, x: np.ndarray) -> np.ndarray:
        """Where hidden joint j is: on its parent at its last offset, else where it was last
        seen."""
        p = self.parents[j]
        if p >= 0 and np.isfinite(x[p]).all() and np.isfinite(self.offset[j]).all():
            return x[p] + self.offset[j]
        return self.last[j]

    def _filter(self, stamp: float, x: np.ndarray) -> np.ndarray:
        """The 1 Euro filter's step for every joint that is there; a joint there for the
        first time (or again after it was lost) starts from itself."""
        there = np.isfinite(x).all(axis=1)
        fresh = there & ~np.isfinite(self.smooth).all(axis=1)
        dt = stamp - self.stamp if self.stamp is not None else 0.0
        going = there & ~fresh & (dt > 0.0)
        if going.any():
            prev = self.smooth[going]
            velocity = (x[going] - prev) / dt
            a_d = _alpha(self.d_cutoff, dt)
            self.speed[going] = a_d * velocity + (1.0 - a_d) * self.speed[going]
            cutoff = self.min_cutoff + self.beta * np.abs(self.speed[going])
            a = _alpha(cutoff, dt)
            self.smooth[going] = a * x[going] + (1.0 - a) * prev
        self.smooth[fresh] = x[fresh]
        self.speed[fresh] = 0.0
        self.smooth[~there] = np.nan  # lost: it starts afresh when it comes back
        return self.smooth.copy()
