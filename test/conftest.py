"""Fixtures of the cloth_node tests (helpers in node_harness.py)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="session", autouse=True)
def cost_model_cache(tmp_path_factory):
    """One cost-model cache for the whole run, in its own folder: every test that starts a
    scene with particles or tolerance auto on the same settings (and its node and Dask worker
    processes, which inherit the environment) shares one calibration, as a machine's runs do,
    and none reads or fills the user's cache. Tests of the calibration itself set their own."""
    path = tmp_path_factory.mktemp("cost_model_cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CLOTH_MG_CACHE", str(path))
        yield path


@pytest.fixture(scope="session")
def walking_calibration(tmp_path_factory, cost_model_cache):
    """The walking scene's cost model (tolerance auto; its dress and fabric) at 2400
    particles on one thread, calibrated once in an empty cache of its own and shared by the
    calibration's tests: a namespace with options, material, model, cached (whether the
    first call found it cached: never) and cache (the folder; a test that looks it up again
    sets CLOTH_MG_CACHE to it). The model is also put in the run's cache (cost_model_cache),
    so that every scene on these settings (a node, a bench, in-process or not) starts from it
    instead of calibrating them again (30-45 s each); a test that needs it requests this
    fixture. One thread: on two cores shared with other work, two threads' kernels wait at
    every barrier for a descheduled peer (a calibration took 262 s instead of 35 s)."""
    import shutil
    from types import SimpleNamespace

    from cloth_mg_ros.budget.cost_model import cache_path, load_or_calibrate
    from cloth_mg_ros.config.scenes import load_scene
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.garment_sim import BodySimOptions

    path = tmp_path_factory.mktemp("calibration_cache")
    params = load_scene("walking")
    options = BodySimOptions.from_scene(params, particles=2400, threads=1)
    material = get_material(params.material)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CLOTH_MG_CACHE", str(path))
        model, cached = load_or_calibrate(options, material)
        entry = cache_path(options, "walk", material)
    shared = cost_model_cache / entry.name
    if not shared.exists():
        shutil.copyfile(entry, shared)
    return SimpleNamespace(options=options, material=material, model=model, cached=cached,
                           cache=path)


@pytest.fixture
def walking_one_thread(tmp_path, walking_calibration) -> Path:
    """The walking scene's params file on one thread (config/walking.yaml plus ``threads:
    1``), for a bench that runs the scene as given: its tolerance auto finds the run's
    calibration of these settings (walking_calibration; particles are not part of the key)
    instead of measuring its own (30 s)."""
    path = tmp_path / "walking_1_thread.yaml"
    repo = Path(__file__).resolve().parents[1]
    path.write_text((repo / "config" / "walking.yaml").read_text() + "    threads: 1\n")
    return path


@pytest.fixture(scope="session")
def dask_local():
    """An embedded Dask LocalCluster of two single-threaded workers, shared by the tests of
    `cloth-mg batch` and of the sweeps that run on it."""
    from cloth_mg_ros.apps.cluster import dask_client

    with dask_client(workers=2, log=lambda line: None) as client:
        yield client


@pytest.fixture
def ros_env(monkeypatch, request) -> dict[str, str]:
    """Environment for both ends: loopback discovery on a domain of this test's own (the test
    module's DOMAIN_ID where it has one, else a fresh one per test, so that a test never
    hears a node of another)."""
    from node_harness import next_domain_id

    domain = getattr(request.module, "DOMAIN_ID", None) or next_domain_id()
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
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

    from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames

    return read_pose_frames(bundled_bag("walk"))[:MESSAGES]


@pytest.fixture
def short_bag(tmp_path, walk_frames) -> Path:
    """The first MESSAGES messages of the bundled walk bag."""
    from cloth_mg_ros.io.bags import write_pose_bag

    return write_pose_bag(tmp_path / "walk40", np.array([s for s, _ in walk_frames]),
                          np.stack([p for _, p in walk_frames]))


@pytest.fixture(scope="session")
def contact_step():
    """A real step system with the sheet on the sphere (contacts on the diagonal): the drape's
    (1200 particles of cotton) past its landing; (scene, step). test_multigrid and
    test_packed_levels share it."""
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.sim.integrator import assemble_step
    from cloth_mg_ros.sim.sheets import build_scene
    from cloth_mg_ros.sim.simulator import Simulator
    from cloth_mg_ros.solvers import PCGSolver

    scene = build_scene("drape", 1200, get_material("cotton"))
    sim = Simulator(scene.model, scene.state, PCGSolver(tol=1e-6), dt=1 / 60)
    # the first state past the sheet's landing (0.15 s) whose next step has penalty contacts
    # (a sheet sliding over the sphere's curve predicts itself clear of it in some steps)
    for k in range(80):
        sim.step()
        step = assemble_step(scene.model, sim.state, sim.dt, "bdf2")
        if k >= 9 and len(step.contacts) >= 5:
            break
    assert len(step.contacts) >= 5
    return scene, step
