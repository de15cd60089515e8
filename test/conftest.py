"""Fixtures of the cloth_node tests (helpers in node_harness.py)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture
def ros_env(monkeypatch) -> dict[str, str]:
    """Environment for both ends: loopback discovery on this run's own domain."""
    from node_harness import DOMAIN_ID

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN_ID))
    return dict(os.environ, PYTHONUNBUFFERED="1")


@pytest.fixture
def listener(ros_env):
    """A Listener on the node's outputs in the root namespace."""
    from node_harness import Listener

    lis = Listener()
    yield lis
    lis.close()


@pytest.fixture(scope="module")
def walk_frames() -> list[tuple[float, np.ndarray]]:
    """The first MESSAGES (stamp s, poses (S, 7)) frames of the bundled walk bag."""
    from node_harness import MESSAGES

    from cloth_mg_ros.bags import bundled_bag, read_pose_frames

    return read_pose_frames(bundled_bag("walk"))[:MESSAGES]


@pytest.fixture
def short_bag(tmp_path, walk_frames) -> Path:
    """The first MESSAGES messages of the bundled walk bag."""
    from cloth_mg_ros.bags import write_pose_bag

    return write_pose_bag(tmp_path / "walk40", np.array([s for s, _ in walk_frames]),
                          np.stack([p for _, p in walk_frames]))
