"""`single_threaded_executor`: rclpy's SingleThreadedExecutor built whole even when Ctrl-C
lands while it is being built.

Why: this project's processes turn Ctrl-C and SIGTERM into a KeyboardInterrupt (rclpy's own
signal handlers off, so the context stays valid for the node's last words). One raised
inside the executor's constructor leaves a half-built object whose ``__del__`` (rclpy 7.1)
reads an attribute the constructor never reached and prints "Exception ignored ...
AttributeError: 'SingleThreadedExecutor' object has no attribute '_sigint_gc'" with a
traceback into the node's log (seen once in a fresh-clone test run: a node stopped right
after it started). The two signals' Python handlers are swapped for one that notes them while
it is built, and the signals are raised again once it exists. (Blocking them in the main
thread does not do: a signal sent to the process goes to any thread that does not block it,
a DDS or I/O thread, and Python then runs the handler in the main thread all the same.)
"""

from __future__ import annotations

import signal
import threading

HELD_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


def single_threaded_executor(context):
    """A rclpy SingleThreadedExecutor on ``context``, built with SIGINT and SIGTERM held
    back (raised again, as a KeyboardInterrupt where they are one, once it exists). Off the
    main thread, where Python runs no signal handler, or where a handler was not installed
    from Python (it could not be put back), it is built as is."""
    # imported here: rclpy loads only where a ROS process needs it
    from rclpy.executors import SingleThreadedExecutor

    if threading.current_thread() is not threading.main_thread():
        return SingleThreadedExecutor(context=context)
    previous = {s: signal.getsignal(s) for s in HELD_SIGNALS}
    if any(h is None for h in previous.values()):
        return SingleThreadedExecutor(context=context)
    noted: list[int] = []
    for s in HELD_SIGNALS:
        signal.signal(s, lambda signum, frame: noted.append(signum))
    try:
        executor = SingleThreadedExecutor(context=context)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    for signum in dict.fromkeys(noted):
        signal.raise_signal(signum)
    return executor
