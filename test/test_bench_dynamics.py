"""`cloth-mg bench dynamics --quick`: the swing per scheme and step against the exact chain,
and the walking dress's kinetic energy per scheme."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_mg_ros.bench.dynamics import (
    QUICK_STEPS_PER_S,
    QUICK_WALK_MESSAGES,
    WALK_LEAD_IN_S,
    variants,
)
from cloth_mg_ros.cli.main import main
from cloth_mg_ros.fidelity.swing import chain_frequency


def test_quick_bench_charts_every_scheme_against_the_chain(tmp_path, capsys):
    out, png = tmp_path / "dynamics.json", tmp_path / "dynamics.png"
    assert main(["bench", "dynamics", "--quick", "--json", str(out), "--png", str(png)]) == 0
    assert "swing against the exact chain" in capsys.readouterr().out
    result = json.loads(out.read_text())
    assert png.stat().st_size > 0
    assert result["meta"]["quick"] is True
    assert result["meta"]["swing"]["exact_frequency_hz"] == pytest.approx(chain_frequency(0.5))
    labels = [(scheme, radius) for scheme, radius in variants()]
    rows = {(r["scheme"], r["spectral_radius"], r["steps_per_s"]): r for r in result["swing"]}
    assert set(rows) == {(s, r, n) for s, r in labels for n in QUICK_STEPS_PER_S}
    for (scheme, radius, rate), row in rows.items():
        # every scheme, stable or not, is reported; a stable one is within 2 % of the chain
        if not row["stable"]:
            assert scheme == "genalpha" and radius == 1.0, row
            continue
        for part in ("with_fabric", "integrator_only"):
            assert abs(row[part]["frequency_error_pct"]) < 2.0, (scheme, rate, part)
            assert row[part]["cost_s_per_simulated_s"] > 0.0
        # the fabric's damping only adds to the integrator's
        assert row["with_fabric"]["damping_ratio"] > row["integrator_only"]["damping_ratio"]
    for rate in QUICK_STEPS_PER_S:
        euler = rows[("euler", None, rate)]["integrator_only"]["damping_ratio"]
        bdf2 = rows[("bdf2", None, rate)]["integrator_only"]["damping_ratio"]
        genalpha = rows[("genalpha", labels[2][1], rate)]["integrator_only"]["damping_ratio"]
        # implicit Euler's omega h / 2 (0.044 at 1/60 s) against the second-order schemes'
        assert bdf2 < euler / 5.0 and genalpha < euler / 5.0
    # halving the step halves Euler's damping (first order)
    zeta = [rows[("euler", None, r)]["integrator_only"]["damping_ratio"]
            for r in QUICK_STEPS_PER_S]
    assert zeta[1] / zeta[0] == pytest.approx(0.5, abs=0.06)
    walk = result["walking"]
    assert [(w["scheme"], w["spectral_radius"]) for w in walk] == labels
    for w in walk:
        assert w["stable"], w
        assert len(w["kinetic_j"]) == QUICK_WALK_MESSAGES
        # the figures are the run's: its mean and peak past the lead-in, from the tick series
        ke, t = np.array(w["kinetic_j"]), np.array(w["time_s"])
        stride = ke[t >= WALK_LEAD_IN_S] if np.any(t >= WALK_LEAD_IN_S) else ke
        assert np.all(np.isfinite(ke)) and stride.min() >= 0.0 and stride.max() > 0.0
        assert w["peak_kinetic_j"] == stride.max()
        assert w["mean_kinetic_j"] == pytest.approx(stride.mean(), rel=1e-12)
    # each scheme's own run, not one run reported under every label
    assert len({tuple(w["kinetic_j"]) for w in walk}) == len(walk)
