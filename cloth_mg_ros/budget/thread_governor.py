"""How many threads a live garment's steps should run on now: fewer than configured while
other work holds the cores.

The solver's threaded kernels meet at a barrier after every parallel sweep (hundreds per
step), and a barrier waits for its slowest thread. Once other work holds a core, one of the
garment's threads is off a core at most barriers, and the step waits a scheduler slice each
time. Measured on the 2-core AMD EPYC with a 7416-particle walking dress (medians of 20
ticks): beside one busy process, 142-165 ms a tick on one thread against 280-285 ms on two;
beside two, 240 ms against 460-520 ms, with single ticks of 2-5 s on two threads. On an idle
machine two threads are the faster (103 ms). The threads change how fast a step runs, never
what it computes: the sweeps' split into parts follows the configured count
(solvers.dissection), so the cloth is the same bit for bit on any number of running threads.

The rule reads the run-queue wait share of the process's threads (budget.contention): with
T busy threads of ours among R runnable on C cores, each gets C / R of a core, so the share
is 1 - C / R and the others number R - T = C / (1 - share) - T (the share less an idle
node's own, its baseline: its executor and DDS threads wait too). When that share is high the
governor runs min(configured, C - others) threads (at least one). A low share at fewer threads
than configured cannot tell how many others there are (the cores are not full), so the
governor tries the configured count again after a quiet spell (2 s), and waits twice as long
before the next try when a try meets the same load, up to 4 s: a try costs a tick or two at
half speed, and a longer wait would keep the node on fewer threads (and its level of detail
down, sim.detail) for that long after the load ends.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

__all__ = ["ThreadChange", "ThreadGovernor"]

# The node's own wait share on an idle machine (its executor and DDS threads wait too), its
# baseline: measured as it runs (the least median over a quiet_s window on every thread),
# never above BASELINE_CAP (more is other work), IDLE_SHARE until measured. On the 2-core AMD
# EPYC: 0.04-0.09 a tick on two threads at a 3 Hz stream, 0.08-0.22 at 10 Hz (shorter ticks,
# the other threads' share larger); on one thread beside two busy processes 0.36-0.56.
IDLE_SHARE = 0.05
BASELINE_CAP = 0.15
# A wait share this far above the baseline: other work holds cores; less, at fewer threads
# than configured: the cores may be free again.
BUSY_MARGIN = 0.15


@dataclass(frozen=True)
class ThreadChange:
    """A change of the running threads: the new count and why (for the log)."""

    threads: int
    reason: str

    def describe(self, configured: int) -> str:
        """The log line: 'solver threads: T of C (why)'."""
        return f"solver threads: {self.threads} of {configured} ({self.reason})"


class ThreadGovernor:
    """The running thread count of a live garment's steps (module docstring).

    configured: the threads asked for (>= 1); cores: the machine's (numba's count). Feed each
    tick to `observe`; it returns a ThreadChange when the count should change (the caller runs
    the next steps on `threads`). Times are the caller's monotonic clock, s."""

    def __init__(self, configured: int, cores: int, window_s: float = 1.0,
                 quiet_s: float = 2.0, hold_s: float = 10.0, backoff: float = 2.0,
                 max_wait_s: float = 4.0) -> None:
        if configured < 1 or cores < 1:
            raise ValueError(f"threads and cores must be >= 1, got {configured}, {cores}")
        self.configured = configured
        self.cores = cores
        self.threads = configured
        self.window_s = window_s  # the ticks that judge a count: the last this many seconds
        self.quiet_s = quiet_s  # quiet this long before trying more threads
        self.hold_s = hold_s  # a try that lasts this long held: the backoff starts over
        self.backoff = backoff
        self.max_wait_s = max_wait_s
        self.changes = 0
        self._wait_s = quiet_s
        self._since: float | None = None  # the last change (or the first tick)
        self._tried: float | None = None  # when the last try at more threads began
        self._ticks: deque = deque()  # (now_s, wait share) since the last change
        self.baseline = IDLE_SHARE  # the node's own wait share on an idle machine
        self._baseline_measured = False

    @property
    def probing(self) -> bool:
        """The next tick is a try's first: it tests whether the cores are free, and judges
        alone (a loaded machine drops back after one slow tick, not a window of them)."""
        return self._tried is not None and not self._ticks

    def observe(self, now_s: float, wait_share: float | None) -> ThreadChange | None:
        """Record one tick that ended at now_s with its wait share (0..1 since the last tick;
        None: unknown, which changes nothing) and return the change to make, if any."""
        if self._since is None:
            self._since = now_s
        if wait_share is None:
            return None
        if self._tried is not None and now_s - self._tried >= self.hold_s:
            self._wait_s, self._tried = self.quiet_s, None  # the last try held
        probe = self.probing
        self._ticks.append((now_s, min(max(wait_share, 0.0), 1.0)))
        horizon = max(self.window_s, self.quiet_s)
        while len(self._ticks) > 1 and self._ticks[0][0] < now_s - horizon:
            self._ticks.popleft()
        recent = [s for t, s in self._ticks if t >= now_s - self.window_s]
        # a tick longer than the window (a starved machine) judges alone
        share = sorted(recent)[len(recent) // 2] if recent else self._ticks[-1][1]
        quiet = sorted(s for t, s in self._ticks if t >= now_s - self.quiet_s)
        quiet_share = quiet[len(quiet) // 2]
        if (self.threads == self.configured and len(quiet) >= 3
                and now_s - self._since >= self.quiet_s):
            least = self.baseline if self._baseline_measured else BASELINE_CAP
            self.baseline, self._baseline_measured = min(least, quiet_share), True
        busy = self.baseline + BUSY_MARGIN
        if self.threads > 1 and share >= busy and (
                probe or len(recent) >= 2 or now_s - self._since >= self.window_s):
            drop = self._drop(now_s, share, "the threads")
            if drop is not None:
                return drop
        if (self.threads < self.configured and now_s - self._since >= self._wait_s
                and len(quiet) >= 2 and quiet_share < busy):
            self._tried = now_s
            return self._change(now_s, self.configured,
                                f"the threads waited {100 * quiet_share:.0f} % of their time "
                                f"for a core (median over {self.quiet_s:g} s; "
                                f"{100 * self.baseline:.0f} % on an idle machine)")
        return None

    def observe_step(self, now_s: float, wait_share: float | None) -> ThreadChange | None:
        """Between two steps of a tick, with the wait share since the last call: a step that
        waited past twice the busy margin drops the count at once, before the tick ends (the
        first tick of a load on two threads took 1.5-4.5 s at 7416 particles); the tick's own
        `observe` judges the rest."""
        if wait_share is None or self.threads <= 1:
            return None
        if wait_share < self.baseline + 2 * BUSY_MARGIN:
            return None
        return self._drop(now_s, wait_share, "a step's threads")

    def _drop(self, now_s: float, share: float, who: str) -> ThreadChange | None:
        """The change to the threads the other work leaves, judged by a wait share (the
        module docstring's count of others), if that is fewer than run now."""
        others = self.cores / max(1.0 - (share - self.baseline), 1e-3) - self.threads
        # a thread less for each 0.75 others or more: a noisy probe's 0.5 keeps them all
        fit = max(1, min(self.configured, math.ceil(self.cores - others - 0.25)))
        if fit >= self.threads:
            return None
        if self._tried is not None:  # the try met the load it left: wait longer
            self._wait_s = min(self._wait_s * self.backoff, self.max_wait_s)
            self._tried = None
        return self._change(now_s, fit, f"{who} waited {100 * share:.0f} % of their time for a "
                                        f"core: about {others:.1f} other busy threads on "
                                        f"{self.cores} cores")

    def _change(self, now_s: float, threads: int, reason: str) -> ThreadChange:
        self.threads = threads
        self.changes += 1
        self._since = now_s
        self._ticks.clear()
        return ThreadChange(threads, reason)
