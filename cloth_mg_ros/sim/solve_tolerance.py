"""The relative residual each level's linear solve goes to: a number, or ``auto`` with the
tolerances the cost model's calibration measured per garment size (budget.tolerance_rule measures
them; this module only reads them, so that the simulation does not depend on the budget layer).
"""

from __future__ import annotations

from cloth_mg_ros.errors import ClothInputError

__all__ = ["AUTO", "describe", "tolerance_at"]

AUTO = "auto"  # tolerance: auto (and particles: auto; config.schema checks the values)


# How the tolerance a level needs falls with its size: tol ~ n^-SIZE_EXPONENT above the size
# measured. On the walk (bench pareto, every message) the rule's ratio grows as tol^0.46-0.58
# and, at one tolerance, with the level's particles: 0.071, 0.100 and 0.081 at 2394, 9964 and
# 19940 particles (finest levels, 3e-3), 0.055 and 0.108 at 615 and 2526 (the level below the
# finest, 1e-3); n^0.25 at the finest over the tolerance's 0.5 gives 0.5. By particle count
# alone a 10K dress took 3e-3 and 1e-3 and left 0.100 and 0.108.
SIZE_EXPONENT = 0.5


def tolerance_at(points: list[tuple[int, float]] | tuple, particles: float,
                 rung: int = 0) -> float:
    """The tolerance for level of detail `rung` (0: a garment's finest) of `particles` from
    the calibration's measured (particles, tolerance) points (the one with the most particles
    its garment's finest level, the others the levels below it).

    A garment's finest level takes the calibration's finest point; a coarser level of detail
    (`rung` >= 1) the tightest of the calibration's coarser points: it starts from a state
    restricted from a finer one, whose folds its solves cannot follow, as the calibration's
    coarse level did (by particle count, a 20K dress's 5034- and 1283-particle levels took
    3e-3 and 2.5e-3 and left 0.155 and 0.149 of the step's error, against 0.081 at its finest).
    Above the point's particles the tolerance falls as (n_point / particles)^SIZE_EXPONENT;
    below them it stays (a smaller mesh is not assumed to allow more than was measured)."""
    if not points:
        raise ClothInputError("tolerance auto has no measured tolerances (the cost model's "
                              "calibration measures them)")
    pts = sorted((float(n), float(t)) for n, t in points)
    n0, t0 = pts[-1] if rung == 0 or len(pts) == 1 else min(pts[:-1], key=lambda p: p[1])
    if particles <= n0:
        return t0  # exactly as measured (a run repeated with it gets the same bits)
    return float(t0 * (n0 / float(particles)) ** SIZE_EXPONENT)


def describe(tolerance: float | str, tolerances=()) -> str:
    """A tolerance setting for a log line: '0.0001', or 'auto (0.01 at 2394 particles, ...)'."""
    if tolerance != AUTO:
        return f"{float(tolerance):g}"
    return "auto (" + ", ".join(f"{t:g} at {n} particles" for n, t in tolerances) + ")"
