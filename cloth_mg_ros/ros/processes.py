"""cloth_node as a child process on a ROS domain of its own, and this process's side of the graph.

Shared by `cloth-mg demo` (`cloth_mg_ros.ros.demo`) and `cloth-mg bench node`
(`cloth_mg_ros.bench.node_latency`):

- the ROS domain: `default_domain_id` (``1 + pid % 100``), `check_domain_id`,
  `claim_domain_id` (a domain no other process on the machine holds, by a file lock) and
  `open_ros_side`, which moves on to the next free domain when other nodes show up;
- the environment: `ros_environment` (ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
  in this process while a block runs), `child_env` (the same for a child process);
- `NodeProcess`: `python -m cloth_mg_ros.ros.node` as a subprocess, its output in a log file;
  `NodeError` with the log's last lines when it fails; `wait_for_node` until it subscribes;
- `RosSide`: an rclpy context, node and executor of this process on that domain;
- `interrupt_signals`: Ctrl-C and SIGTERM as KeyboardInterrupt while a block runs;
- cloth_node's names in the graph (`NODE_NAME`, `POSE_TOPIC`, `MARKER_TOPIC`, `STATS_TOPIC`).
"""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from cloth_mg_ros.environment import environ_set
from cloth_mg_ros.errors import ClothInputError

__all__ = [
    "MARKER_TOPIC",
    "NODE_NAME",
    "POSE_TOPIC",
    "STATS_TOPIC",
    "NodeError",
    "NodeProcess",
    "RosSide",
    "check_domain_id",
    "claim_domain_id",
    "child_env",
    "default_domain_id",
    "interrupt_signals",
    "kill_process",
    "node_command",
    "open_ros_side",
    "release_domain_id",
    "ros_environment",
    "run_node_job",
    "start_process",
    "stop_process",
    "wait_for_node",
]

POSE_TOPIC = "/avatar/body_poses"
MARKER_TOPIC = "/cloth/marker"
STATS_TOPIC = "/cloth/stats"
NODE_NAME = "cloth_node"
# node start: imports, warm-up, the first run's numba compile and, for a scene with
# `tolerance: auto` or `lod` and an empty cost-model cache, its calibration (26-50 s on a
# quiet 2-core machine, past 120 s on a loaded one): a deadline for failing, waited for by
# spinning, so a generous one costs a good start nothing
START_TIMEOUT_S = 600.0
STOP_TIMEOUT_S = 15.0  # SIGINT to exit, s
PROBE_S = 1.0  # look this long for other nodes on a ROS domain before using it, s
DOMAIN_TRIES = 10  # domains tried before using a busy one
TAIL_LINES = 25  # lines of the node's log shown when it fails


class NodeError(RuntimeError):
    """cloth_node failed: did not start, died, or did not exit cleanly (message: the log's
    last lines)."""


@contextmanager
def interrupt_signals() -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM raise KeyboardInterrupt in the main thread while the block
    runs, also when the process started with SIGINT ignored (in the background of a
    non-interactive shell); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame) -> None:
        raise KeyboardInterrupt

    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous_int)
        signal.signal(signal.SIGTERM, previous_term)


def run_node_job(job: Callable[[], object], stopped: str = "cloth_node stopped"
                 ) -> tuple[object, int]:
    """Run `job` (a command's work with cloth_node) under interrupt_signals: (its result, 0),
    or (None, 1) after printing a NodeError (the node did not start, died or did not exit
    cleanly), or (None, 130) after Ctrl-C or SIGTERM (`stopped`: what was stopped)."""
    try:
        with interrupt_signals():
            return job(), 0
    except NodeError as exc:
        print(f"cloth-mg: error: {exc}", file=sys.stderr)
        return None, 1
    except KeyboardInterrupt:
        print(f"interrupted ({stopped})", file=sys.stderr)
        return None, 130


def default_domain_id(pid: int | None = None) -> int:
    """A ROS domain id for this run: 1 + pid % 100 (1..100, clear of the default 0)."""
    return 1 + (os.getpid() if pid is None else pid) % 100


_CLAIMS: dict[int, object] = {}  # domain id -> its lock file, open while this process holds it


def claim_domain_id(first: int, count: int, start: int | None = None) -> int:
    """A ROS domain id in first..first + count - 1 that no other process on this machine
    holds, claimed for this process: an exclusive lock (flock) on a file in the temp
    directory, released by `release_domain_id` or when the process exits, however it exits.
    Tried from `start` (default: first + pid % count) upwards, wrapping round; ids this
    process holds already are skipped. Two test suites on one machine shared a domain once
    and a listener heard the other suite's node (its marker stamps among its own).

    Raises:
        ClothInputError: every id of the range is held.
    """
    start = first + os.getpid() % count if start is None else start
    for k in range(count):
        domain = check_domain_id(first + (start - first + k) % count)
        if domain in _CLAIMS:
            continue
        # not inherited by child processes (PEP 446): the claim ends with this process
        lock = open(Path(tempfile.gettempdir()) / f"cloth_mg_ros_domain_{domain}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _CLAIMS[domain] = lock
        return domain
    raise ClothInputError(f"every ROS domain id in {first}..{first + count - 1} is held by "
                          f"other processes on this machine")


def release_domain_id(domain: int) -> None:
    """Give back a domain `claim_domain_id` gave this process (none: nothing)."""
    lock = _CLAIMS.pop(domain, None)
    if lock is not None:
        lock.close()  # closing the file drops the lock


def check_domain_id(domain_id: int) -> int:
    """`domain_id` if it is a usable ROS domain id (0..232 with Fast DDS); else
    ClothInputError."""
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not (
            0 <= domain_id <= 232):
        raise ClothInputError(f"--domain-id must be an integer in 0..232, got {domain_id!r}")
    return domain_id


@contextmanager
def ros_environment(domain_id: int) -> Iterator[dict[str, str]]:
    """Set ROS_DOMAIN_ID=domain_id and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST in this
    process until the block ends (the previous values come back); yields the environment for
    child processes (`child_env`)."""
    with environ_set({"ROS_DOMAIN_ID": str(domain_id),
                      "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}):
        yield child_env(domain_id)


def child_env(domain_id: int) -> dict[str, str]:
    """Environment of a child process: ours with ROS_DOMAIN_ID=domain_id,
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and PYTHONUNBUFFERED=1 (its log arrives whole)."""
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
                ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")


class NodeProcess:
    """cloth_node as a subprocess: stdout and stderr into `log_path`.

    Args:
        params_file: a cloth_node params file (config/<scene>.yaml).
        params: further `name:=value` parameters (`-p`), after the file (they win).
        env: the child's environment (`child_env`).
        log_path: where its output goes (created or truncated).
    """

    def __init__(self, params_file: str | os.PathLike | None, params: Sequence[str],
                 env: dict[str, str], log_path: str | os.PathLike) -> None:
        self.log_path = Path(log_path)
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self.command = node_command(params, params_file)
        self.proc = start_process(self.command, env, self.log_path)

    def tail(self, lines: int = TAIL_LINES) -> str:
        """The last `lines` lines of the node's log, indented."""
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return "    (no log)"
        kept = text.rstrip().splitlines()[-lines:]
        return "\n".join(f"    {line}" for line in kept) or "    (the log is empty)"

    def check_alive(self, doing: str) -> None:
        """NodeError with the log's tail if the node has exited (`doing`: what was awaited)."""
        code = self.proc.poll()
        if code is not None:
            how = " (stopped by Ctrl-C or a signal?)" if code in (0, -2, -15) else ""
            raise NodeError(f"cloth_node exited with status {code} {doing}{how}; the last "
                            f"lines of its log ({self.log_path}):\n{self.tail()}")

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """SIGINT (Ctrl-C), then wait up to `timeout_s` s; killed after that (status -9).
        Returns the exit status (0: a clean shutdown)."""
        return stop_process(self.proc, timeout_s)

    def kill(self) -> None:
        """Kill the node if it still runs (cleanup after an error)."""
        kill_process(self.proc)


def node_command(params: Sequence[str] = (), params_file: str | os.PathLike | None = None
                 ) -> list[str]:
    """`python -m cloth_mg_ros.ros.node --ros-args [--params-file F] -p NAME:=VALUE ...`: the
    params file first, then each of `params` (they win)."""
    command = [sys.executable, "-m", "cloth_mg_ros.ros.node", "--ros-args"]
    if params_file is not None:
        command += ["--params-file", str(params_file)]
    for p in params:
        command += ["-p", p]
    return command


def start_process(command: Sequence[str], env: dict[str, str], log_path: str | os.PathLike,
                  cwd: str | os.PathLike | None = None) -> subprocess.Popen:
    """`command` as a child process with no input, its stdout and stderr into `log_path`
    (created or truncated)."""
    with open(log_path, "w") as log:
        return subprocess.Popen(list(command), env=env, cwd=cwd, stdin=subprocess.DEVNULL,
                                stdout=log, stderr=subprocess.STDOUT)


def stop_process(proc: subprocess.Popen, timeout_s: float = STOP_TIMEOUT_S) -> int:
    """SIGINT (Ctrl-C) to a child that still runs, then wait up to `timeout_s` s; killed after
    that (status -9). Returns the exit status."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            kill_process(proc)
    return int(proc.returncode)


def kill_process(proc: subprocess.Popen) -> None:
    """Kill a child that still runs and reap it."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()


class RosSide:
    """This process's side of the graph: an rclpy context on `domain_id` with localhost
    discovery (`ros_environment` while it initialises; no signal handlers: Ctrl-C stays a
    KeyboardInterrupt), one node and an executor spun by `spin_until`."""

    def __init__(self, domain_id: int, node_name: str) -> None:
        # imported here: rclpy (the ROS side), loaded only when needed
        import rclpy
        from rclpy.context import Context
        from rclpy.signals import SignalHandlerOptions

        from cloth_mg_ros.ros.executor import single_threaded_executor

        self.domain_id = domain_id
        self.ctx = Context()
        with ros_environment(domain_id):
            rclpy.init(context=self.ctx, domain_id=domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
            self.node = rclpy.create_node(node_name, context=self.ctx)
        self.executor = single_threaded_executor(self.ctx)
        self.executor.add_node(self.node)

    def other_nodes(self) -> list[str]:
        """Names of the nodes in the graph that are not this process's (call it before
        adding nodes): 'a node' for each other /rosout publisher not yet known by name."""
        names = sorted(name for name, _ in self.node.get_node_names_and_namespaces()
                       if name != self.node.get_name())
        unnamed = self.node.count_publishers("/rosout") - 1 - len(names)
        return names + ["a node"] * max(unnamed, 0)

    def spin_until(self, done: Callable[[], bool], timeout_s: float,
                   node: NodeProcess | None = None, doing: str = "") -> bool:
        """Spin until done() (True) or `timeout_s` s (False); NodeError if `node` exits."""
        deadline = time.monotonic() + timeout_s
        while not done():
            if node is not None:
                node.check_alive(doing)
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def has_endpoint(self, topic: str, node_name: str, subscription: bool) -> bool:
        """Whether node `node_name` has a subscription (or publisher) on `topic` in the
        graph."""
        get = (self.node.get_subscriptions_info_by_topic if subscription
               else self.node.get_publishers_info_by_topic)
        return any(i.node_name == node_name for i in get(topic))

    def close(self) -> None:
        # imported here: rclpy (the ROS side), loaded only when needed
        import rclpy

        self.executor.shutdown(timeout_sec=0.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def open_ros_side(domain_id: int | None, node_name: str, log: Callable[[str], None] = print,
                  probe_s: float = PROBE_S, tries: int = DOMAIN_TRIES) -> RosSide:
    """A RosSide on a ROS domain nobody else uses, before the node is started on it.

    domain_id None: the first of 1..100 from `default_domain_id()` on that no other process
    on the machine has claimed (`claim_domain_id`: a test suite beside it claims its own), or,
    when other nodes show up there within `probe_s` seconds, the next such one (up to `tries`
    domains; then the last one, with a warning). An explicit domain_id is used as given (a
    warning if it is busy)."""
    explicit = domain_id is not None
    domain = check_domain_id(domain_id) if explicit else default_domain_id() - 1
    tries = 1 if explicit else max(1, tries)
    for k in range(tries):
        if not explicit:  # busy ones stay claimed, so the next claim moves past them
            domain = claim_domain_id(1, 100, domain + 1)
        side = RosSide(domain, node_name)
        side.spin_until(lambda s=side: bool(s.other_nodes()), probe_s)
        others = side.other_nodes()
        if not others:
            return side
        if k < tries - 1:
            side.close()
            log(f"ROS domain {domain} is in use ({', '.join(others)}); trying the next")
            continue
        log(f"warning: ROS domain {domain} is in use ({', '.join(others)}); their messages "
            f"may mix with ours (choose a free one with --domain-id)")
        return side
    raise AssertionError("unreachable")


def wait_for_node(side: RosSide, node: NodeProcess, topic: str = POSE_TOPIC,
                  timeout_s: float = START_TIMEOUT_S,
                  also: Callable[[], bool] = lambda: True) -> float:
    """Spin until cloth_node subscribes to `topic` (it does after its warm-up, the last
    step of its start-up) and also() holds; returns the seconds waited. NodeError if the node
    exits or `timeout_s` passes."""
    t0 = time.monotonic()
    ok = side.spin_until(lambda: side.has_endpoint(topic, NODE_NAME, True) and also(),
                         timeout_s, node, "during start-up")
    if not ok:
        raise NodeError(f"cloth_node did not subscribe to {topic} within {timeout_s:g} s; the "
                        f"last lines of its log ({node.log_path}):\n{node.tail()}")
    return time.monotonic() - t0
