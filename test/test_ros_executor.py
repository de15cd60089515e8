"""ros.executor: a Ctrl-C that lands while an executor is being built is delivered once the
executor is whole (a half-built one printed a traceback into a stopped node's log)."""

from __future__ import annotations

import os
import signal

import pytest

pytest.importorskip("rclpy")

from node_harness import domain_id

from cloth_mg_ros.ros.executor import single_threaded_executor


def test_ctrl_c_while_an_executor_is_built_comes_once_it_is_whole(monkeypatch):
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    built: list = []
    build = SingleThreadedExecutor.__init__

    def interrupted(self, *args, **kwargs):  # Ctrl-C before the constructor's first line
        built.append(self)
        os.kill(os.getpid(), signal.SIGINT)
        build(self, *args, **kwargs)

    monkeypatch.setattr(SingleThreadedExecutor, "__init__", interrupted)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            single_threaded_executor(ctx)
    finally:
        signal.signal(signal.SIGINT, previous)
        monkeypatch.undo()
    try:
        assert len(built) == 1 and built[0]._sigint_gc is not None  # built whole
    finally:
        for executor in built:
            if getattr(executor, "_sigint_gc", None) is not None:
                executor.shutdown(timeout_sec=0.0)
        ctx.try_shutdown()
