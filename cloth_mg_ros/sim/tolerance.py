"""The relative residual each level's linear solve goes to: a number, or ``auto`` with the
tolerances the cost model's calibration measured per garment size (budget.tolerance measures
them; this module only reads them, so that the simulation does not depend on the budget layer).
"""

from __future__ import annotations

import math

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = ["AUTO", "describe", "tolerance_at"]

AUTO = "auto"  # tolerance: auto (and particles: auto; config.schema checks the values)


def tolerance_at(points: list[tuple[int, float]] | tuple, particles: float,
                 rung: int = 0) -> float:
    """The tolerance for a garment level of `particles` from measured (particles, tolerance)
    points (the calibration garment's levels; the one with the most particles its finest):
    log tolerance interpolated linearly in log particles between them, the nearest point's
    beyond them (a larger mesh is not assumed to allow more than was measured).

    A coarser level of detail (`rung` >= 1) takes at most the tolerance measured at the
    calibration's coarser levels, whatever its size: it starts from a state restricted from
    a finer one, whose fine folds its solves cannot follow, as the calibration's coarse
    level did. (By size alone, a 20K dress's 5034- and 1283-particle levels took the
    2394-particle finest level's 3e-3 and 2.5e-3, and their solver error per message was 0.155
    and 0.149 of the step's on the walk, bench pareto, against 0.081 at its finest.)"""
    if not points:
        raise ClothInputError("tolerance auto has no measured tolerances (the cost model's "
                              "calibration measures them)")
    pts = sorted((float(n), float(t)) for n, t in points)
    cap = min(t for _, t in pts[:-1]) if rung >= 1 and len(pts) > 1 else math.inf
    if particles <= pts[0][0] or len({t for _, t in pts}) == 1:
        tol = pts[0][1]  # exactly as measured (a run repeated with it gets the same bits)
    elif particles >= pts[-1][0]:
        tol = pts[-1][1]
    else:
        n = np.log([p[0] for p in pts])
        t = np.log([p[1] for p in pts])
        tol = float(math.exp(np.interp(math.log(max(float(particles), 1.0)), n, t)))
    return min(tol, cap)


def describe(tolerance: float | str, tolerances=()) -> str:
    """A tolerance setting for a log line: '0.0001', or 'auto (0.01 at 2394 particles, ...)'."""
    if tolerance != AUTO:
        return f"{float(tolerance):g}"
    return "auto (" + ", ".join(f"{t:g} at {n} particles" for n, t in tolerances) + ")"
