"""How much of the time this process's threads wanted a core they waited for one: the
machine's contention as the node feels it, read from Linux's scheduler statistics.

A tick that takes longer can mean a harder step (the body moves faster, a coarse rung's
tighter tolerance) or a machine whose cores other work holds; the level of detail must tell
them apart (sim.detail.DetailController), and the tick's own time cannot. The kernel counts,
per thread, the time it ran on a core and the time it waited runnable on a run queue
(/proc/<pid>/task/<tid>/schedstat: run ns, wait ns, timeslices; CONFIG_SCHED_INFO, on in
Debian's kernels). Summed over the process's threads between two reads, wait / (run + wait)
is near 0 on an idle machine and about 1 - cores / runnable threads when other work holds
the cores (0.5 for two busy threads on two cores beside two hogs). Where the file is missing
(another OS, a kernel without it) the share is None and the caller does without it. Written
here rather than taken from psutil: psutil does not expose the run-queue wait, and it would be
a dependency for one file read.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["ContentionMeter"]

TASKS = Path("/proc/self/task")


def _process_times() -> tuple[int, int] | None:
    """(run ns, wait ns) summed over this process's threads, or None where unavailable."""
    run = wait = 0
    try:
        names = os.listdir(TASKS)
    except OSError:
        return None
    seen = False
    for name in names:
        try:
            fields = (TASKS / name / "schedstat").read_text().split()
        except OSError:
            continue  # a thread that ended between the listing and the read
        if len(fields) >= 2:
            run += int(fields[0])
            wait += int(fields[1])
            seen = True
    return (run, wait) if seen else None


class ContentionMeter:
    """The share of its threads' time the process waited for a core, between reads.

    `share()` returns wait / (run + wait) since the previous call (the first call: since the
    meter was made), or None where the scheduler statistics are unavailable or no thread ran
    in between. A read costs about 50 us (a file per thread)."""

    def __init__(self) -> None:
        self._last = _process_times()

    @property
    def available(self) -> bool:
        return self._last is not None

    def share(self) -> float | None:
        now = _process_times()
        last, self._last = self._last, now
        if now is None or last is None:
            return None
        # a thread that ended takes its counts with it: clamp the differences at zero
        run, wait = max(now[0] - last[0], 0), max(now[1] - last[1], 0)
        if run + wait <= 0:
            return None
        return wait / (run + wait)
