"""`single_threaded_executor`: rclpy's SingleThreadedExecutor built whole even when Ctrl-C
lands while it is being built.

Why: this project's processes turn Ctrl-C and SIGTERM into a KeyboardInterrupt (rclpy's own
signal handlers off, so the context stays valid for the node's last words). One raised
inside the executor's constructor leaves a half-built object whose ``__del__`` (rclpy 7.1)
reads an attribute the constructor never reached and prints "Exception ignored ...
AttributeError: 'SingleThreadedExecutor' object has no attribute '_sigint_gc'" with a
traceback into the node's log (seen once in a fresh-clone test run: a node stopped right
after it started). Holding the two signals back while it is built delivers them just after.
"""

from __future__ import annotations

import signal
import threading

HELD_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


def single_threaded_executor(context):
    """A rclpy SingleThreadedExecutor on ``context``, built with SIGINT and SIGTERM held
    back in this thread (delivered, as a KeyboardInterrupt where they are one, once it
    exists). Off the main thread, where Python runs no signal handler, it is built as is."""
    # imported here: rclpy loads only where a ROS process needs it
    from rclpy.executors import SingleThreadedExecutor

    if threading.current_thread() is not threading.main_thread():
        return SingleThreadedExecutor(context=context)
    held = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    try:
        executor = SingleThreadedExecutor(context=context)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    return executor
