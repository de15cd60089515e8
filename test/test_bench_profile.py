"""`cloth-mg bench profile`: the tick's parts and a tiny profiled run."""

from __future__ import annotations

import json

import pytest

from cloth_mg_ros.bench.profile_tick import part_of
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.sim.solve_tolerance import tolerance_at

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench


def test_functions_are_put_in_their_part():
    assert part_of("/x/cloth_mg_ros/solvers/smoothers.py", "packed_gauss_seidel") == "solve"
    assert part_of("/x/cloth_mg_ros/physics/system.py", "bs_matvec") == "solve"
    assert part_of("/x/cloth_mg_ros/physics/system.py", "bs_full_diagonal") == "assembly"
    assert part_of("/x/cloth_mg_ros/physics/stretch.py", "stretch_face_terms") == \
        "assembly"
    assert part_of("/x/cloth_mg_ros/collision/capsules.py", "query") == "collisions"
    assert part_of("/x/cloth_mg_ros/physics/strain_limit.py", "limit_strain") == "strain limit"
    assert part_of("~", "<built-in method cvxopt.cholmod.numeric>") == "solve"
    assert part_of("/x/cloth_mg_ros/sim/garment_sim.py", "push") == "other"


def test_profile_cli(tmp_path, capsys):
    out = tmp_path / "prof.json"
    assert main(["bench", "profile", "--particles", "600", "--ticks", "2",
                 "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["ticks"] == 2 and result["solver"] == "mpcg"
    parts = result["parts"]
    assert parts["solve"] > 0.0 and parts["assembly"] > 0.0 and parts["collisions"] > 0.0
    assert sum(parts.values()) == pytest.approx(result["profiled_ms_per_tick"], rel=1e-6)
    assert result["top"][0]["ms_per_tick"] >= result["top"][-1]["ms_per_tick"]
    assert "share" in capsys.readouterr().out
    assert main(["bench", "profile", "--solver", "nope"]) == 2


def test_profile_at_tolerance_auto(tmp_path, capsys, walking_calibration):
    # the walking scene's fabric on one thread: walking_calibration's cost model (the run's
    # cache), not a calibration of its own
    out = tmp_path / "prof.json"
    assert main(["bench", "profile", "--particles", "600", "--ticks", "2", "--tol", "auto",
                 "--material", "white-dots-on-blk", "--threads", "1", "--json",
                 str(out)]) == 0
    result = json.loads(out.read_text())
    points = [tuple(p) for p in result["tolerances"]]
    assert result["tol_setting"] == "auto" and len(points) == 2
    assert result["tol"] == tolerance_at(points, result["particles"])
    assert "tolerance auto (" in capsys.readouterr().out
    assert main(["bench", "profile", "--tol", "loose"]) == 2
