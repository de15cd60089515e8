"""bench.traffic: the bytes an MG-preconditioned CG iteration moves, and a STREAM-like
bandwidth. Nothing here depends on the machine's speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cloth_mg_ros.bench.traffic import (
    first_guess_bytes,
    format_traffic,
    iteration_bytes,
    measure_traffic,
    stream_bandwidth,
    tick_bytes_estimate,
    time_iteration,
    working_set_bytes,
)
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.sheets import build_scene
from cloth_mg_ros.sim.simulator import Simulator
from cloth_mg_ros.solvers import make_solver


@pytest.fixture(scope="module")
def draped():
    """A sheet on the sphere after a few multigrid-solved steps: its solver's packed levels
    hold a real step's hierarchy (contacts, pinned rows, 3 levels)."""
    scene = build_scene("drape", 1200, get_material("cotton"))
    solver = make_solver("mpcg", tol=1e-6, hierarchy=scene.hierarchy,
                         bending=scene.model.bending, levels=3, threads=2)
    sim = Simulator(scene.model, scene.state, solver, dt=1 / 60)
    for _ in range(5):
        sim.step()
    assert solver._packed is not None and solver._packed.n_levels == 3
    return sim


def _level_slots(kind, lvl: int) -> int:
    """A level's slots of one set, from its own adjacency (not the row starts and stops)."""
    return len(kind.local[lvl][1])


def test_sweep_slot_bytes_are_the_levels_slots_exactly(draped):
    pk = draped.solver._packed
    it = iteration_bytes(pk)
    assert [lv["level"] for lv in it["levels"]] == list(range(pk.n_levels - 1))
    for lv in it["levels"]:
        lvl = lv["level"]
        full = _level_slots(pk.full, lvl) * (pk.full.nbr.itemsize + pk.full.values[0].nbytes)
        scal = _level_slots(pk.scal, lvl) * (pk.scal.nbr.itemsize + pk.scal.values.itemsize)
        assert pk.full.values.shape[1] == 6 and pk.scal.values.ndim == 1
        assert lv["terms"]["up_slots"] == full + scal
        assert lv["slots"] == _level_slots(pk.full, lvl) + _level_slots(pk.scal, lvl)
        # every slot's neighbour vector, 3 float64
        assert lv["terms"]["up_gather"] == lv["slots"] * 3 * pk.x.itemsize


def test_each_half_cycle_reads_every_slot_once(draped):
    """The first sweep reads the earlier neighbours' slots and its residual the later ones':
    together every slot once, as the backward sweep; only the finest level's backward sweep
    forms the outer CG's product (diag6 read, w written)."""
    pk = draped.solver._packed
    it = iteration_bytes(pk)
    for lv in it["levels"]:
        t = lv["terms"]
        assert 0 < lv["earlier_slots"] < lv["slots"]
        assert t["down_slots"] == t["up_slots"] and t["down_gather"] == t["up_gather"]
        n = lv["rows"]
        assert t["up_product"] == (n * (6 + 3) * 8 if lv["level"] == 0 else 0)


def test_totals_add_up(draped):
    pk = draped.solver._packed
    it = iteration_bytes(pk)
    for lv in it["levels"]:
        t = lv["terms"]
        assert lv["down"] == (t["load"] + t["down_rows"] + t["down_slots"] + t["down_gather"]
                              + t["restrict"])
        assert lv["up"] == (t["prolong"] + t["up_rows"] + t["up_slots"] + t["up_gather"]
                            + t["up_product"])
        assert (t["load"] > 0) == (lv["level"] == 0)
    down_up = sum(lv["down"] + lv["up"] for lv in it["levels"])
    assert it["vcycle"] == down_up + it["coarse"] + it["take"]
    assert it["iteration"] == it["vcycle"] + it["outer"]
    assert it["coarse"] == 2 * 3 * 8 * int(pk.voff[-1] - pk.voff[-2])
    # no product pass per iteration: p, q, z, w and x, r only (12 finest vectors' rows)
    assert it["outer"] == 12 * 3 * 8 * int(pk.voff[1]) < it["product"]
    g = it["gathers"]
    assert g["down"] == sum(lv["terms"]["down_gather"] for lv in it["levels"])
    assert g["up"] == sum(lv["terms"]["up_gather"] for lv in it["levels"])
    assert g["iteration"] == g["down"] + g["up"] < it["iteration"]
    assert pk.last_guess == "rigid"  # a simulator's step carries the rotations' terms
    pk.last_guess = "translation"  # the translations' guess first
    tick = tick_bytes_estimate(pk, iterations=10.0, solves=2.0)
    first = first_guess_bytes(pk)
    assert tick["first_guess"] == first["total"] == first["residual"] + first["guess"]
    assert tick["per_solve"] == tick["packing"] + first["total"] + 10 * it["iteration"]
    assert tick["per_tick"] == 2 * tick["per_solve"]
    assert tick["per_solve_min"] == pytest.approx(
        tick["per_solve"] - first["gathers"] - 10 * g["iteration"])
    # the first residual gathers only where the pins reach (nowhere on this unpinned sheet)
    share = np.count_nonzero(pk.touched) / pk.voff[1]
    assert first["gathers"] == pytest.approx(share * g["product"]) and share < 1.0
    # after a rigid first guess the residual is taken anew over every row: a whole product
    pk.last_guess = "rigid"
    rigid = first_guess_bytes(pk)
    assert rigid["residual"] == first["residual"] and rigid["guess"] > it["product"]
    assert rigid["gathers"] == pytest.approx(first["gathers"] + g["product"])
    # every array of the levels once, plus five finest vectors
    assert working_set_bytes(pk) > pk.full.values.nbytes + 5 * pk.voff[1] * 24


def test_stream_bandwidth_is_positive_and_finite():
    res = stream_bandwidth(1, mb=8, repeats=2)
    assert res["threads"] == 1
    for key in ("triad_gbs", "copy_gbs"):
        assert math.isfinite(res[key]) and res[key] > 0.0


def test_timed_kernels_and_the_report(draped):
    pk = draped.solver._packed
    ms = time_iteration(pk, repeats=2)
    assert ms["coarse"] == 0.0 and all(math.isfinite(v) and v >= 0.0 for v in ms.values())
    assert ms["iteration"] == pytest.approx(ms["down"] + ms["up"] + ms["outer"])
    run = {"iterations": 8.0, "substeps": 1.0, "ms_per_solve": 5.0, "ms_per_tick": 10.0}
    traffic = measure_traffic(draped, run, threads=1, repeats=2, stream_mb=8)
    parts = [r["part"] for r in traffic["rows"]]
    assert "V-cycle" in parts and "CG iteration" in parts and parts[-1].startswith("tick")
    assert traffic["rows"][-1]["mb"] == pytest.approx(
        traffic["tick_bytes"]["per_tick"] / 1e6)
    assert all(r["mb_min"] <= r["mb"] for r in traffic["rows"])
    assert np.isfinite(traffic["triad_gbs"]) and "of triad" in format_traffic(traffic)
    # the solve's and the tick's bytes over their whole wall time (set-up, coarsening,
    # assembly uncounted): rates labelled as such, not set against the triad
    solve, tick = traffic["rows"][-2:]
    assert (solve["timed"], tick["timed"]) == ("solve wall", "tick wall")
    assert solve["ms"] == run["ms_per_solve"] and tick["ms"] == run["ms_per_tick"]
    assert solve["of_triad"] is None and tick["of_triad"] is None
    assert all(r["timed"] == "kernels" and r["of_triad"] > 0.0 for r in traffic["rows"][:-2])
    table = format_traffic(traffic).splitlines()
    for row in table:
        if row.lstrip().startswith(("solve:", "tick:")):
            assert "%" not in row and row.rstrip().endswith("-")
    assert any("wall time" in line for line in table)


def test_no_packed_levels_no_report(draped):
    class Plain:
        solver = object()

    assert measure_traffic(Plain(), {}, threads=1) is None
