"""The self-contact pair search's per-particle cap: the pairs it leaves out are counted."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_mg_ros.collision.self_contact import PAIRS_PER_PARTICLE, SelfContact


def _brute_force(x: np.ndarray, rest: np.ndarray, d0: float) -> set[tuple[int, int]]:
    """Every pair i < j closer than d0 now and at least 2 d0 apart at rest."""
    close = np.linalg.norm(x[:, None] - x[None], axis=2) < d0
    far = np.linalg.norm(rest[:, None] - rest[None], axis=2) >= 2.0 * d0
    i, j = np.nonzero(np.triu(close & far, k=1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


def test_pairs_past_the_cap_are_counted_not_lost_silently():
    """A crumpled clump (every particle within d0 of dozens of others that are far on the
    cloth) has more close pairs than the search keeps: what it keeps are true pairs, each
    once, and kept plus dropped is every close pair."""
    rng = np.random.default_rng(1)
    rest = rng.uniform(0.0, 10.0, (300, 3))
    x = rng.uniform(0.0, 0.04, (300, 3))
    sc = SelfContact(rest, 0.03)
    pairs = sc.pairs(x)
    expected = _brute_force(x, rest, 0.03)
    kept = {tuple(p) for p in pairs.tolist()}
    assert len(kept) == len(pairs) and kept <= expected
    assert len(expected) > PAIRS_PER_PARTICLE * len(x)  # more than the output can hold
    assert sc.dropped > 0
    assert len(pairs) + sc.dropped == len(expected)


def test_a_sparse_contact_drops_nothing():
    rng = np.random.default_rng(0)
    rest = rng.uniform(0.0, 1.0, (800, 3))
    x = rng.uniform(0.0, 0.2, (800, 3))
    sc = SelfContact(rest, 0.02)
    pairs = sc.pairs(x)
    assert sc.dropped == 0
    assert {tuple(p) for p in pairs.tolist()} == _brute_force(x, rest, 0.02)


def _capped_pairs(monkeypatch, dropped: int) -> None:
    """Every pair search reports `dropped` pairs left out past the cap (a real crumple that
    fills the cap takes a large garment and many steps): what is published is what is
    counted."""
    real = SelfContact.pairs

    def pairs(self, x):
        found = real(self, x)
        self.dropped = dropped
        return found

    monkeypatch.setattr(SelfContact, "pairs", pairs)


def test_the_pairs_a_tick_drops_reach_its_stats_and_the_runners_summary(tmp_path, monkeypatch):
    """Before, SelfContact.dropped was counted and read by nobody: a tick whose search hit
    the cap said nothing. Each step's StepStats carries it, a tick sums its steps', and the
    headless runner's summary.json has it per tick and in all."""
    from cloth_mg_ros.apps.runner import run_body_scene
    from cloth_mg_ros.config.scenes import load_scene

    _capped_pairs(monkeypatch, 7)
    params = load_scene("walking").replace(particles=300, tolerance=1e-4, lod=False,
                                           garment="skirt", self_contact=True, threads=1)
    summary = run_body_scene(params, tmp_path / "out", steps=3, n_frames=2, progress=False)
    ticks = summary["ticks"]
    assert ticks and all(t["self_contact_dropped"] == 7 * t["substeps"] for t in ticks)
    assert summary["self_contact_dropped"] == sum(t["self_contact_dropped"] for t in ticks)
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert written["self_contact_dropped"] == summary["self_contact_dropped"] > 0


def test_a_tick_that_drops_pairs_is_a_warning_on_stats_and_diagnostics():
    """cloth/stats carries self_contact_dropped on every status; a tick that dropped pairs
    is WARN there, with a note, and /diagnostics keeps the warning until its next status."""
    pytest.importorskip("diagnostic_msgs")
    from diagnostic_msgs.msg import DiagnosticStatus

    from cloth_mg_ros.ros.publishing import ClothOutputs, Publishers
    from cloth_mg_ros.sim.integrator import StepStats

    class Publisher:
        def __init__(self) -> None:
            self.sent = []

        def publish(self, message) -> None:
            self.sent.append(message)

    pubs = Publishers(*(Publisher() for _ in range(6)))
    out = ClothOutputs(pubs, "world", False, False, "/cloth_node")
    for dropped in (0, 12, 0):
        stats = StepStats(1.0, 1.0, 2.0, 5, 1e-6, True, 0.0, 0.0, 0, 0.0, 0.0,
                          self_contact_dropped=dropped)
        out.status(stats, 2.0, True, 1, 0, {"particles": "300"})
        if dropped:
            out.diagnostics(1, 0)
    statuses = [m.status[0] for m in pubs.stats.sent]
    values = [{kv.key: kv.value for kv in s.values} for s in statuses]
    assert [v["self_contact_dropped"] for v in values] == ["0", "12", "0"]
    assert [s.level for s in statuses] == [DiagnosticStatus.OK, DiagnosticStatus.WARN,
                                           DiagnosticStatus.OK]
    assert "12 self-contact pairs dropped" in statuses[1].message
    # the diagnostics status after the first two ticks is the worst of them: WARN
    assert pubs.diagnostics.sent[0].status[0].level == DiagnosticStatus.WARN
