"""Linear solvers for the implicit cloth system A dv = b."""

from __future__ import annotations

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.solvers.cg import PCGSolver, SolveResult

__all__ = ["SOLVERS", "PCGSolver", "SolveResult", "make_solver"]

SOLVERS = ("pcg",)


def make_solver(name: str, tol: float = 1e-4, maxiter: int = 10000):
    """A solver by name, with relative tolerance ``tol`` and iteration cap ``maxiter``."""
    if name == "pcg":
        return PCGSolver(tol=tol, maxiter=maxiter)
    raise ClothInputError(f"unknown solver {name!r}; choose one of {', '.join(SOLVERS)}")
