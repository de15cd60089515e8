"""`cloth-mg bench fidelity`'s pieces at tiny sizes: every table fills and the charts draw."""

from __future__ import annotations

import math

import pytest

from cloth_mg_ros.bench.fidelity import (
    cantilever_rows,
    cusick_rows,
    fabric_names,
    resolution_chart,
    spearman,
    summarise_cusick,
    tensile_rows,
)
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.charts import cantilever_profiles_chart, drape_chart

pytestmark = pytest.mark.bench


def test_bench_fidelity_tables_and_charts(tmp_path):
    rows, profiles = cantilever_rows((4.0,), (("lattice", 45.0), ("garment", 0.0)), 400)
    assert len(rows) == 2 and all(r["settled"] for r in rows)
    assert all(r["tip_error_pct_of_overhang"] < 4.0 for r in rows)  # 400 particles: coarse
    assert profiles[0]["profile"][0] == [0.0, 0.0]
    tens = tensile_rows(("11oz-black-denim",), (("lattice", 0.0),))
    assert {r["axis"] for r in tens} == {"weft", "warp"}
    assert all(abs(r["error_pct"]) < 1.0 for r in tens)
    # the stiffest measured fabric and a soft one that comes to rest at 400 particles within
    # the drape's steps (gray-interlock, the softest, does not: it ran them all, 20-30 s)
    drape = cusick_rows(["royal-target", "ivory-rib-knit"], 1, particles=400)
    assert all(r["settled"] for r in drape)
    summary = summarise_cusick(drape)
    assert [s["material"] for s in summary] == ["royal-target", "ivory-rib-knit"]
    # The stiffer fabric (longer bending length) drapes less: a larger DC.
    assert summary[0]["bending_length_cm"] > summary[1]["bending_length_cm"]
    assert summary[0]["dc_mean"] > summary[1]["dc_mean"]
    assert math.isnan(spearman([1.0, 2.0], [1.0, 2.0]))  # too few points for a rank test
    assert spearman([1.0, 2.0, 3.0], [0.1, 0.5, 0.4]) == pytest.approx(0.5)
    for path in (cantilever_profiles_chart(tmp_path / "c.png", profiles),
                 drape_chart(tmp_path / "d.png", summary),
                 resolution_chart(tmp_path / "r.png", rows)):
        assert path.stat().st_size > 1000


def test_bench_fidelity_names_an_unknown_fabric():
    with pytest.raises(ClothInputError, match="tweed"):
        fabric_names("gray-interlock,tweed")
    assert len(fabric_names("measured")) == 10
