"""The clocks a timer scene ticks by (ros.session.LiveSession._run_timer): `WallClock`
(time.monotonic: wall time, the default) and `RosClock` (the node's ROS clock: /clock's time
under use_sim_time, so that a /clock that pauses pauses the cloth and one at half speed
halves the stepping).

Both answer `now` (s), `wait_until(t, stop)` (until the clock reads t s, or `stop`, a
threading.Event, is set: then False) and `next_tick(t, period)` (the tick after one due at t,
s: a period later, or now when late: no burst to catch up).
"""

from __future__ import annotations

import math
import threading
import time

from rclpy.clock import Clock, JumpThreshold
from rclpy.duration import Duration

__all__ = ["RosClock", "WallClock"]

# s of wall time: how often a wait on the ROS clock looks at `stop` (a /clock message wakes it
# at once).
POLL_S = 0.1


class WallClock:
    """Wall time (time.monotonic), s."""

    def now(self) -> float:
        return time.monotonic()

    def wait_until(self, t: float, stop: threading.Event) -> bool:
        delay = t - time.monotonic()
        return not (delay > 0.0 and stop.wait(delay))

    def next_tick(self, t: float, period: float) -> float:
        return max(t + period, time.monotonic())

    def wake(self) -> None:
        """(stop.wait wakes by itself.)"""

    def close(self) -> None:
        """(Nothing to release.)"""


class RosClock:
    """The node's ROS clock (an rclpy Clock of ROS time: /clock under use_sim_time), s. A
    wait wakes on each update of the clock (a jump callback, as rclpy's Clock.sleep_until);
    time that goes back (a looped bag, a restarted /clock) ends a wait at once and the ticks
    go on from the new time."""

    def __init__(self, clock: Clock) -> None:
        self._clock = clock
        self._event = threading.Event()
        self._latest = -math.inf  # s: the clock when a wait last ended
        threshold = JumpThreshold(min_forward=Duration(nanoseconds=1),
                                  min_backward=Duration(nanoseconds=-1), on_clock_change=True)
        self._handle = clock.create_jump_callback(threshold,
                                                  post_callback=lambda _: self._event.set())

    def now(self) -> float:
        return self._clock.now().nanoseconds * 1e-9

    def wait_until(self, t: float, stop: threading.Event) -> bool:
        while not stop.is_set():
            self._event.clear()
            now = self.now()
            if now >= t or now < self._latest:  # due, or the clock went back
                self._latest = now
                return True
            self._event.wait(POLL_S)
        return False

    def next_tick(self, t: float, period: float) -> float:
        now = self.now()
        return now + period if now < t else max(t + period, now)

    def wake(self) -> None:
        """End a wait now (it then looks at `stop`)."""
        self._event.set()

    def close(self) -> None:
        """Unregister the jump callback."""
        self._handle.unregister()
