"""How fast poses arrive lately: the wall-clock period a live node's ticks must keep up with."""

from __future__ import annotations

import time
from collections import deque

ARRIVAL_WINDOW_S = 2.0  # s: the pose period the budget follows is measured over this long


class ArrivalRate:
    """The poses taken by the ticks of the last ``window_s`` seconds of wall-clock time."""

    def __init__(self, window_s: float = ARRIVAL_WINDOW_S) -> None:
        self.window_s = float(window_s)
        self._arrivals: deque = deque()  # (monotonic s, keys taken)

    def note(self, count: int, now: float | None = None) -> None:
        """A tick took ``count`` poses (0: none) at monotonic time ``now`` (None: now)."""
        now = time.monotonic() if now is None else now
        if count:
            self._arrivals.append((now, count))
        while self._arrivals and self._arrivals[0][0] < now - self.window_s:
            self._arrivals.popleft()

    def period(self) -> float | None:
        """Seconds per pose over the window (None: fewer than three takes, or no span)."""
        if len(self._arrivals) < 3:
            return None
        span = self._arrivals[-1][0] - self._arrivals[0][0]
        count = sum(c for _, c in list(self._arrivals)[1:])
        return span / count if span > 0.0 and count else None
