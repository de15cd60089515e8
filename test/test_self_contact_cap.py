"""The self-contact pair search's per-particle cap: the pairs it leaves out are counted."""

from __future__ import annotations

import numpy as np

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
