"""Sparse Cholesky of a block system through CHOLMOD (cvxopt), for the direct solver and the
multigrid's coarsest level.

CHOLMOD's supernodal factorisation with AMD ordering is several times faster than SciPy's
SuperLU on these matrices, both on whole systems (solvers.baselines.DirectSolver) and on a
garment's coarsest level, where it also beats a dense Cholesky (doc/design-measurements.md,
'Solvers and baselines' and 'The coarsest solve', has the figures).
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.physics.system import BlockSystem

_EYE3 = np.eye(3)


def cholmod_available() -> bool:
    """Whether cvxopt's CHOLMOD can be imported."""
    try:
        # imported here: cvxopt (CHOLMOD, a baseline) is optional
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def lower_triplets(system: BlockSystem, fixed: np.ndarray | None = None):
    """(values, rows, cols) of the lower triangle of S A S + (I - S), straight from the
    blocks (no sorting): 6 entries per diagonal block, 9 per pair block below the diagonal.
    fixed (n,) bool marks the particles S zeroes (None: none)."""
    n = system.n
    full = system.full_diagonal()
    offd = system.offd
    i, j = system.pairs[:, 0], system.pairs[:, 1]
    if fixed is not None and np.any(fixed):
        fixed = np.asarray(fixed, dtype=bool)
        full[fixed] = _EYE3
        keep = ~(fixed[i] | fixed[j])
        offd, i, j = offd[keep], i[keep], j[keep]
    la, lb = np.tril_indices(3)
    d_vals = full[:, la, lb].ravel()
    d_rows = (3 * np.arange(n)[:, None] + la[None, :]).ravel()
    d_cols = (3 * np.arange(n)[:, None] + lb[None, :]).ravel()
    a, c = np.divmod(np.arange(9), 3)  # entry (3j + a, 3i + c) = A_ji[a, c] = G_ij[c, a]
    p_vals = offd[:, c, a].ravel()
    p_rows = (3 * j[:, None] + a[None, :]).ravel()
    p_cols = (3 * i[:, None] + c[None, :]).ravel()
    return (np.concatenate([d_vals, p_vals]), np.concatenate([d_rows, p_rows]),
            np.concatenate([d_cols, p_cols]))


class SparseCholesky:
    """The CHOLMOD supernodal factor of S A S + (I - S) for a BlockSystem (n particles).

    symbolic: the symbolic analysis (ordering, supernodes) of an earlier SparseCholesky of a
    matrix with the same sparsity pattern (``.symbolic``), reused so that only the numeric
    factorisation runs: the multigrid's coarsest level keeps its pattern for the whole run,
    and its analysis cost about a third of each factorisation. The earlier factor's numbers
    are overwritten (its ``solve`` then answers for this matrix).

    pattern: ``.pattern`` of an earlier SparseCholesky of a system with the same pairs and
    pinned particles: its matrix is refilled in place (cvxopt's sorting of the triplets into
    columns cost a third of the multigrid's coarsest factorisation).

    Raises ImportError without cvxopt and ArithmeticError when the matrix is not positive
    definite. ``solve(rhs)`` takes and returns flat (3n,) arrays."""

    def __init__(self, system: BlockSystem, fixed: np.ndarray | None = None, symbolic=None,
                 pattern=None):
        # imported here: cvxopt (CHOLMOD, a baseline), loaded only when needed
        from cvxopt import cholmod, matrix, spmatrix

        vals, rows, cols = lower_triplets(system, fixed)
        size = 3 * system.n
        if pattern is not None and len(pattern[1]) == len(vals):
            A, where = pattern
            A.V = matrix(vals[where])
        else:
            # the triplets' places in cvxopt's column order: build it with their numbers as
            # values; a place two triplets share (a cloth-cloth spring on a bending pair:
            # cvxopt adds them) has no single number, and such a matrix is not kept
            A = spmatrix(matrix(np.arange(1.0, len(vals) + 1.0)), matrix(rows),
                         matrix(cols), (size, size))
            where = np.asarray(A.V, dtype=np.float64).ravel().astype(np.int64) - 1
            if len(where) == len(vals):
                A.V = matrix(vals[where])
            else:
                A = spmatrix(matrix(vals), matrix(rows), matrix(cols), (size, size))
                where = None
        self.pattern = None if where is None else (A, where)
        saved = dict(cholmod.options)
        cholmod.options["supernodal"] = 2
        try:
            self._factor = cholmod.symbolic(A, uplo="L") if symbolic is None else symbolic
            cholmod.numeric(A, self._factor)
        finally:
            cholmod.options.clear()
            cholmod.options.update(saved)

    @property
    def symbolic(self):
        """The factor object, for reuse on a matrix of the same pattern."""
        return self._factor

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        # imported here: cvxopt (CHOLMOD, a baseline), loaded only when needed
        from cvxopt import cholmod, matrix

        y = matrix(np.ascontiguousarray(rhs, dtype=np.float64).reshape(-1))
        cholmod.solve(self._factor, y)
        return np.array(y).reshape(-1)
