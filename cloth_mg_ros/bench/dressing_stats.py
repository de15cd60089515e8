"""`bench dressing`'s statistics over perturbed starts: the share of each outcome with its
95 % interval, and the spread of each figure.

A dressing run's outcome is one sample of a chaotic contact problem (a change of gravity by
one part in 10^12 flips it), so the benchmark runs each case from N starts a micrometre
apart and reports what those N samples say: for an outcome seen k times in N, the share
k / N and Wilson's score interval (Wilson 1927; scipy.stats.binomtest's proportion_ci,
method 'wilson'), which, unlike the normal approximation, stays inside [0, 1] and is not
empty at k = 0 or k = N (0 of 10: 0 to 0.28); for a figure (a peak force N, a dressed length
m), its median and its 10th and 90th percentiles over the starts.
"""

from __future__ import annotations

import numpy as np

OUTCOMES = ("good", "caught", "missed")  # apps.dressing_scene.summarise's outcomes
CONFIDENCE = 0.95
PERCENTILES = (10.0, 50.0, 90.0)


def proportion_interval(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """(low, high): Wilson's score interval for a share seen k times in n trials, at
    ``confidence`` (0.95: 95 %). Raises ValueError for k outside [0, n] or n < 1."""
    # imported here: scipy.stats loads in a few hundred ms, only when a bench summarises
    from scipy.stats import binomtest

    if not (isinstance(n, (int, np.integer)) and n >= 1 and 0 <= k <= n):
        raise ValueError(f"an interval needs 0 <= k <= n and n >= 1, got k={k}, n={n}")
    ci = binomtest(int(k), int(n)).proportion_ci(confidence, method="wilson")
    return float(ci.low), float(ci.high)


def outcome_shares(outcomes: list[str], confidence: float = CONFIDENCE) -> dict:
    """{outcome: {"count", "share", "low", "high"}} for every outcome of OUTCOMES (and any
    other seen), over ``outcomes`` (one per start); the shares sum to 1."""
    n = len(outcomes)
    names = list(OUTCOMES) + sorted(set(outcomes) - set(OUTCOMES))
    out = {}
    for name in names:
        k = sum(o == name for o in outcomes)
        low, high = proportion_interval(k, n, confidence)
        out[name] = {"count": k, "share": k / n, "low": low, "high": high}
    return out


def spread(values: list[float | None]) -> dict:
    """{"n", "median", "p10", "p90", "min", "max"} of ``values``: None entries (a force level
    a start never reached) are left out, "n" counts the rest; all None when none is left."""
    v = np.array([x for x in values if x is not None], dtype=np.float64)
    if not len(v):
        return {"n": 0, "median": None, "p10": None, "p90": None, "min": None, "max": None}
    p10, median, p90 = np.percentile(v, PERCENTILES)
    return {"n": len(v), "median": float(median), "p10": float(p10), "p90": float(p90),
            "min": float(v.min()), "max": float(v.max())}


# the figures whose spread a case reports: name -> how to read it from a run's summary
FIGURES = {
    "dressed_m": lambda s: s["dressed_m"],
    "peak_force_n": lambda s: s["peak_force_n"],
    "hand_n": lambda s: s["peak_body_n"]["hand"],
    "forearm_n": lambda s: s["peak_body_n"]["forearm"],
    "upper_arm_n": lambda s: s["peak_body_n"]["upper_arm"],
    "e_stop_travel_m": lambda s: s["e_stop_travel_m"],
    "upper_arm_ratio": lambda s: s["upper_arm_ratio"],
    "slip_m": lambda s: s["slip_m"],
    "edge_depth_m": lambda s: s["edge_depth_m"],
    "wall_s": lambda s: s["wall_s"],
}


def distribution(summaries: list[dict], confidence: float = CONFIDENCE) -> dict:
    """One case over its starts: {"starts": N, "outcomes": `outcome_shares`, "figures":
    {figure: `spread`}} from the runs' summaries (apps.dressing_scene.summarise), one per start."""
    if not summaries:
        raise ValueError("a distribution needs at least one start")
    return {"starts": len(summaries),
            "outcomes": outcome_shares([s["outcome"] for s in summaries], confidence),
            "figures": {name: spread([get(s) for s in summaries])
                        for name, get in FIGURES.items()}}


def share_text(entry: dict) -> str:
    """'0.70 [0.40, 0.89]': a share and its interval, from `outcome_shares`' entry."""
    return f"{entry['share']:.2f} [{entry['low']:.2f}, {entry['high']:.2f}]"


def spread_text(entry: dict, digits: int = 2) -> str:
    """'1.23 (0.98-1.50)': median (10th-90th percentile), '-' when nothing was measured."""
    if entry["median"] is None:
        return "-"
    f = f"{{:.{digits}f}}"
    return f"{f.format(entry['median'])} ({f.format(entry['p10'])}-{f.format(entry['p90'])})"
