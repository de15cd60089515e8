"""`cloth-mg bench profile`: the tick's parts and a tiny profiled run."""

from __future__ import annotations

import cProfile
import json
import pstats

import numpy as np
import pytest

from cloth_mg_ros.bench.profile_tick import part_of, split_parts
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.physics.system import BlockSystem
from cloth_mg_ros.sim.solve_tolerance import tolerance_at
from cloth_mg_ros.solvers.baselines import DirectSolver

# Benchmark tests: `colcon test` skips them (pytest.ini); `make test` runs them.
pytestmark = pytest.mark.bench


def test_functions_are_put_in_their_part():
    assert part_of("/x/cloth_mg_ros/solvers/smoothers.py", "packed_gauss_seidel") == "solve"
    # the step's system by module: assembly (split_parts moves what the solvers call)
    assert part_of("/x/cloth_mg_ros/physics/system.py", "bs_matvec") == "assembly"
    assert part_of("/x/cloth_mg_ros/physics/system.py", "bs_full_diagonal") == "assembly"
    assert part_of("/x/cloth_mg_ros/physics/stretch.py", "stretch_face_terms") == \
        "assembly"
    assert part_of("/x/cloth_mg_ros/collision/capsules.py", "query") == "collisions"
    assert part_of("/x/cloth_mg_ros/physics/strain_limit.py", "limit_strain") == "strain limit"
    assert part_of("~", "<built-in method cvxopt.cholmod.numeric>") == "solve"
    assert part_of("/x/cloth_mg_ros/sim/garment_sim.py", "push") == "other"


INTEGRATOR = ("/x/cloth_mg_ros/sim/integrator.py", 1, "step")
CG = ("/x/cloth_mg_ros/solvers/cg.py", 1, "solve")
MATVEC = ("/x/cloth_mg_ros/physics/system.py", 146, "matvec")
KERNEL = ("/x/cloth_mg_ros/physics/system.py", 20, "bs_matvec")
EMPTY = ("~", 0, "<built-in method numpy.empty_like>")


class _Profile:
    """A made-up profile (pstats' own layout: (cc, nc, tottime, cumtime, {caller: (cc, nc,
    tottime, cumtime)}), seconds): the integrator calls CG and BlockSystem.matvec, CG calls
    matvec too (2 s of its 3 s own time, 3 s of its 4.5 s inclusive); matvec calls the numba
    kernel and numpy's empty_like, which the integrator also calls."""

    def create_stats(self):
        self.stats = {
            INTEGRATOR: (1, 1, 5.0, 15.0, {}),
            CG: (1, 1, 4.0, 7.0, {INTEGRATOR: (1, 1, 4.0, 7.0)}),
            MATVEC: (30, 30, 3.0, 4.5, {CG: (20, 20, 2.0, 3.0), INTEGRATOR: (10, 10, 1.0, 1.5)}),
            KERNEL: (30, 30, 0.9, 0.9, {MATVEC: (30, 30, 0.9, 0.9)}),
            EMPTY: (40, 40, 1.0, 1.0, {MATVEC: (30, 30, 0.6, 0.6),
                                       INTEGRATOR: (10, 10, 0.4, 0.4)}),
        }


def test_solver_called_system_counts_as_solve():
    parts, rows = split_parts(pstats.Stats(_Profile()))
    split = {r["function"]: r["split"] for r in rows}
    # matvec: its own time from CG is solve; so are 2/3 of what it runs below it (the CG
    # calls' share of its inclusive time): the kernel's and empty_like's time from it
    assert split["physics/system.py:matvec"] == {"solve": 2.0, "assembly": 1.0}
    assert split["physics/system.py:bs_matvec"] == pytest.approx({"solve": 0.6,
                                                                   "assembly": 0.3})
    assert split["~:<built-in method numpy.empty_like>"] == pytest.approx(
        {"solve": 0.4, "other": 0.6})
    assert parts == pytest.approx({"solve": 7.0, "assembly": 6.3, "collisions": 0.0,
                                   "strain limit": 0.0, "other": 0.6})
    assert {r["function"]: r["part"] for r in rows}["physics/system.py:matvec"] == "solve"


def test_a_solvers_system_calls_count_as_solve():
    # a real profile: the direct solver (solvers/baselines.py) calls BlockSystem.matvec and
    # full_diagonal; this test module calls matvec too, which stays assembly
    n = 40
    pairs = np.array([[i, i + 1] for i in range(n - 1)], dtype=np.int64)
    system = BlockSystem(np.tile(np.eye(3), (n, 1, 1)), pairs,
                         np.tile(-np.eye(3), (n - 1, 1, 1)))
    solver, b = DirectSolver(backend="splu"), np.ones((n, 3))

    def ticks():
        for _ in range(20):
            solver.solve(system, b)
            system.matvec(b)

    ticks()  # numba and scipy loaded outside the profile
    prof = cProfile.Profile()
    prof.runcall(ticks)
    stats = pstats.Stats(prof)
    parts, rows = split_parts(stats)
    split = {r["function"]: r["split"] for r in rows}
    assert split["physics/system.py:matvec"].keys() == {"solve", "assembly"}
    assert split["physics/system.py:full_diagonal"].keys() == {"solve"}
    assert sum(parts.values()) == pytest.approx(stats.total_tt, rel=1e-9)


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
