"""The packed path's first residual, as a solve's first step forms it: shared by the packed
levels' and the first guess's tests."""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.solvers.packed_kernels import residual_rows, touched_rows


def first_residual(pk, moved: np.ndarray, b: np.ndarray) -> tuple:
    """From the guess `moved` (n, 3) (the pins where they go) and right-hand side b (n, 3), in
    the PackedLevels `pk`'s row order: the guess x, the rows the pins' moves touch (uint8),
    the residual S (b - A x) on them, and b."""
    n = len(moved)
    x = pk.to_rows(moved)
    touched = np.empty(n, dtype=np.uint8)
    touched_rows(n, pk.slots, pk.free[:n], x, touched)
    r = np.empty_like(x)
    rows_b = pk.to_rows(b)
    residual_rows(pk.fine_chunks, pk.slots, pk.diag6, pk.free, rows_b, x, r, touched)
    return x, touched, r, rows_b
