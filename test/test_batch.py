"""`cloth-mg batch` on an embedded Dask LocalCluster of two worker processes.

A tiny grid (two bags x two garments, ~300 particles, half a second of motion): every run
writes its folder and its manifest row; a second call skips them; a run on a bad bag becomes a
`failed` row with its error while the others finish; BVH clips become bags as tasks.
"""

from __future__ import annotations

import csv
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from cloth_mg_ros.apps.batch import (
    MANIFEST_COLUMNS,
    BatchGrid,
    messages_for,
    read_manifest,
    run_batch,
    validate_grid,
)
from cloth_mg_ros.apps.cluster import gather_all, run_tasks
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.io.bags import bundled_bag, read_pose_frames, write_pose_bag

REPO = Path(__file__).resolve().parent.parent
MOCAP = REPO / "test" / "data" / "mocap"
PARTICLES = 300
SECONDS = 0.5


@pytest.fixture
def client(dask_local):
    return dask_local


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> str:
    """The walking scene at a fixed tolerance: these tests are about the batch, and each bag
    and garment under tolerance auto would calibrate first (30-60 s each)."""
    text = (REPO / "config" / "walking.yaml").read_text()
    fixed, count = re.subn(r"(?m)^(\s*tolerance:)\s*auto\b", r"\1 0.001", text)
    assert count == 1
    path = tmp_path_factory.mktemp("scene") / "walking_fixed_tolerance.yaml"
    path.write_text(fixed)
    return str(path)


def _grid(**kw) -> BatchGrid:
    base = {"bags": ["walk", "run"], "garments": ["skirt", "dress"], "particles": [PARTICLES],
            "seconds": SECONDS}
    return BatchGrid(**(base | kw))


def _manifest(out: Path) -> list[dict]:
    with (out / "manifest.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def test_a_grid_runs_once_and_a_second_call_skips_it(client, tmp_path, scene):
    out = tmp_path / "batch"
    result = run_batch(_grid(mcap=True, scene=scene), out, client, log=lambda line: None,
                        progress=False)
    assert (result["ran"], result["skipped"], result["failed"]) == (4, 0, [])
    rows = _manifest(out)
    assert list(rows[0]) == list(MANIFEST_COLUMNS)
    assert [(r["bag"], r["garment"]) for r in rows] == [
        ("walk", "skirt"), ("walk", "dress"), ("run", "skirt"), ("run", "dress")]
    for row in rows:
        assert row["status"] == "ok" and row["error"] == "", row
        folder = out / row["output"]
        assert folder.is_dir() and not Path(str(folder) + ".partial").exists()
        with np.load(folder / "positions.npz") as data:
            k, n = int(row["ticks"]), int(row["particles_simulated"])
            assert data["positions"].shape == (k, n, 3)
            assert np.isfinite(data["positions"]).all()
        # The lead-in and half a second of motion, one tick per 30 Hz pose message.
        frames = read_pose_frames(bundled_bag(row["bag"]))
        assert k == messages_for(frames, SECONDS) == pytest.approx(30 + 15, abs=1)
        assert float(row["max_penetration_m"]) < 0.015
        assert abs(n - PARTICLES) < PARTICLES // 3
        from rosbags.rosbag2 import Reader

        with Reader(folder / "markers") as reader:  # --mcap: one Marker per tick
            assert reader.message_count == k
            assert {c.msgtype for c in reader.connections} == {"visualization_msgs/msg/Marker"}
    stamps = {p: (out / p / "summary.json").stat().st_mtime_ns for p in
              (r["output"] for r in rows)}

    again = run_batch(_grid(mcap=True, scene=scene), out, client, log=lambda line: None,
                       progress=False)
    assert (again["ran"], again["skipped"]) == (0, 4)
    assert _manifest(out) == rows
    assert {p: (out / p / "summary.json").stat().st_mtime_ns for p in stamps} == stamps

    # A finished run whose folder went missing runs again; the others stay.
    shutil.rmtree(out / rows[0]["output"])
    third = run_batch(_grid(mcap=True, scene=scene), out, client, log=lambda line: None,
                       progress=False)
    assert (third["ran"], third["skipped"]) == (1, 3)


def _bad_bag(path: Path) -> Path:
    """A valid rosbag2 bag whose poses do not fit the avatar (3 segments, not 16)."""
    stamps = np.arange(20) / 30.0
    poses = np.zeros((20, 3, 7))
    poses[..., 6] = 1.0
    return write_pose_bag(path, stamps, poses)


def test_a_failing_run_is_a_failed_row_and_the_others_finish(client, tmp_path, scene):
    bad = _bad_bag(tmp_path / "three_segments")
    out = tmp_path / "batch"
    grid = _grid(bags=["walk", str(bad)], garments=["skirt"], scene=scene)
    result = run_batch(grid, out, client, log=lambda line: None, progress=False)
    rows = {Path(r["bag"]).name: r for r in _manifest(out)}
    assert rows["walk"]["status"] == "ok"
    failed = rows["three_segments"]
    assert failed["status"] == "failed" and failed["output"] == ""
    assert "three_segments" in failed["error"] and "pose" in failed["error"], failed["error"]
    assert [Path(r["bag"]).name for r in result["failed"]] == ["three_segments"]
    assert not list(out.glob("three_segments*"))  # nothing half-written is left
    # A second call tries the failed run again, and only it.
    again = run_batch(grid, out, client, log=lambda line: None, progress=False)
    assert (again["ran"], again["skipped"]) == (1, 1)


def test_bvh_clips_become_bags_as_tasks(client, tmp_path, scene):
    clips = tmp_path / "clips"
    clips.mkdir()
    shutil.copy(MOCAP / "09_01.bvh", clips / "run_clip.bvh")
    out = tmp_path / "batch"
    grid = BatchGrid(bags=[], garments=["skirt"], particles=[PARTICLES], seconds=0.2,
                     scene=scene)
    result = run_batch(grid, out, client, bvh_dir=clips, log=lambda line: None,
                       progress=False)
    assert (out / "bags" / "run_clip" / "metadata.yaml").is_file()
    (row,) = result["rows"]
    assert row["status"] == "ok" and Path(row["bag"]).name == "run_clip"


def test_tasks_hand_back_errors_and_keep_order(client):
    done = {item: (result, error) for item, result, error in
            run_tasks(client, _inverse, [1, 0, 4], progress=False)}
    assert done[1] == (1.0, None) and done[4] == (0.25, None)
    assert done[0][0] is None and isinstance(done[0][1], ZeroDivisionError)
    assert gather_all(client, _inverse, [4, 2, 1], progress=False) == [0.25, 0.5, 1.0]
    with pytest.raises(ZeroDivisionError):
        gather_all(client, _inverse, [1, 0], progress=False)


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _listens(address: str) -> bool:
    """Whether something accepts connections at `address` ('tcp://HOST:PORT')."""
    import socket

    host, port = address.removeprefix("tcp://").rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=1.0):
            return True
    except OSError:
        return False


def test_a_running_cluster_started_with_dasks_own_commands(tmp_path, capsys, scene):
    """`dask scheduler` and `dask worker` in their own processes; `cloth-mg batch
    --scheduler` sends the grid there."""
    import os
    import subprocess
    import sys
    import time

    dask = str(Path(sys.executable).parent / "dask")
    address = f"tcp://127.0.0.1:{_free_port()}"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port",
                               address.rsplit(":", 1)[1], "--no-dashboard"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        # the worker retries until the scheduler listens; the batch's client gives up after
        # 10 s, so it waits for that (the scheduler's start-up is dask's import: seconds, more
        # on a loaded machine)
        procs.append(subprocess.Popen([dask, "worker", address, "--nthreads", "1",
                                       "--nworkers", "1", "--no-dashboard"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 120.0
        while not _listens(address) and procs[0].poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        out = tmp_path / "batch"
        code = main(["batch", "--bags", "walk", "--garments", "skirt", "--particles",
                     str(PARTICLES), "--seconds", "0.2", "--scene", scene, "--out", str(out),
                     "--scheduler", address])
        assert code == 0, capsys.readouterr()
        captured = capsys.readouterr()
        assert f"scheduler {address}" in captured.err
        (row,) = _manifest(out)
        assert row["status"] == "ok" and (out / row["output"] / "positions.npz").is_file()
        assert "1 ok, 0 failed" in captured.out
    finally:
        for proc in reversed(procs):
            proc.terminate()
            proc.wait(timeout=30)


def test_an_unreachable_scheduler_is_named(tmp_path, capsys, monkeypatch):
    # nothing listens there: every attempt is refused at once, so the wait for an answer
    # (10 s in the CLI) only sets how long it tries again
    monkeypatch.setattr("cloth_mg_ros.apps.cluster.CONNECT_TIMEOUT_S", 1.0)
    address = f"tcp://127.0.0.1:{_free_port()}"
    code = main(["batch", "--bags", "walk", "--out", str(tmp_path / "b"), "--scheduler",
                 address])
    assert code == 2
    assert address in capsys.readouterr().err


def _inverse(x: int) -> float:
    return 1.0 / x


@pytest.mark.parametrize(("changes", "named"), [
    ({"garments": ["gown"]}, "gown"),
    ({"materials": ["velvet"]}, "velvet"),
    ({"solvers": ["magic"]}, "magic"),
    ({"particles": [5]}, "--particles"),
    ({"bags": ["no/such/bag"]}, "no/such/bag"),
    ({"seconds": -1.0}, "--seconds"),
    ({"garments": ["skirt", "skirt"]}, "twice"),
    # below a garment's smallest mesh (mesh.garments.design.MIN_PARTICLES: top 300), and a
    # scene file that is not there: before, they passed and every run failed on the workers
    ({"garments": ["dress", "top"], "particles": [300, 100]}, "--particles .* 300..200000"),
    ({"scene": "missing.yaml"}, "--scene: .*missing.yaml"),
])
def test_bad_grid_values_are_named_before_anything_runs(changes, named):
    with pytest.raises(ClothInputError, match=named):
        validate_grid(_grid(**changes))


def test_the_cli_refuses_a_bad_grid_before_starting_a_cluster(tmp_path, capsys):
    code = main(["batch", "--garments", "gown", "--out", str(tmp_path / "b")])
    assert code == 2
    assert "gown" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def test_the_cli_refuses_a_missing_scene_before_starting_a_cluster(tmp_path, capsys):
    code = main(["batch", "--scene", str(tmp_path / "missing.yaml"), "--out",
                 str(tmp_path / "b")])
    assert code == 2
    assert "--scene" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def test_the_cli_with_bvh_refuses_a_bad_grid_before_starting_a_cluster(tmp_path, capsys,
                                                                       monkeypatch):
    """--bvh: the clips' bags come later, the rest of the grid is checked at once."""
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster started before the grid was checked")

    monkeypatch.setattr("cloth_mg_ros.apps.cluster.dask_client", no_cluster)
    code = main(["batch", "--bvh", str(tmp_path), "--garments", "top", "--particles", "100",
                 "--out", str(tmp_path / "b")])
    assert code == 2
    assert "--particles" in capsys.readouterr().err


def test_a_manifest_from_something_else_is_refused(tmp_path):
    (tmp_path / "manifest.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ClothInputError, match="not a batch manifest"):
        read_manifest(tmp_path)
