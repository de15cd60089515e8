"""Strain limiting: a post-step correction that keeps mesh edges from stretching past a bound.

Woven cloth barely stretches, and a single linearised implicit step is only accurate for
moderate strains: cloth pinched between a body's solids can be pulled far past its elastic
range in one step, after which the next linearisation overshoots and the cloth gains energy
(Provot 1995 saw the same "super-elastic" effect). Edges longer than ``max_stretch`` times
their rest length are shortened back to that bound by a few Gauss-Seidel passes that move both
ends towards each other (a pinned end does not move). Like the contact projection, this is a
correction of positions, not motion: the integrator keeps it out of the BDF2 history.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _edge(x, i, j):
    """The vector from particle i to particle j of x (n, 3) and its length."""
    d0 = x[j, 0] - x[i, 0]
    d1 = x[j, 1] - x[i, 1]
    d2 = x[j, 2] - x[i, 2]
    return d0, d1, d2, np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, nogil=True)
def limit_strain(x, v, edges, rest_len, max_stretch, free, iterations, h_move, moved):
    """Shorten over-stretched edges of x (n, 3) in place; edges (e, 2), rest_len (e,) m,
    free (n,) weights, 1.0 movable, 0.0 pinned. The velocity v (n, 3) follows each move
    (v += dx / h_move, h_move s: an inelastic correction, x = ... + h_move v) and moved (n,)
    bool is set where a particle moved. Returns the largest stretch ratio found before."""
    worst = 0.0
    for it in range(iterations):
        changed = False
        for k in range(edges.shape[0]):
            i = edges[k, 0]
            j = edges[k, 1]
            d0, d1, d2, length = _edge(x, i, j)
            bound = max_stretch * rest_len[k]
            if it == 0 and length / rest_len[k] > worst:
                worst = length / rest_len[k]
            if length <= bound or length == 0.0:
                continue
            wi = free[i]
            wj = free[j]
            w = wi + wj
            if w == 0.0:
                continue
            excess = (length - bound) / (length * w)
            for a, da in ((0, d0), (1, d1), (2, d2)):
                x[i, a] += wi * excess * da
                x[j, a] -= wj * excess * da
                v[i, a] += wi * excess * da / h_move
                v[j, a] -= wj * excess * da / h_move
            moved[i] = moved[i] or wi > 0.0
            moved[j] = moved[j] or wj > 0.0
            changed = True
        if not changed:
            break
    return worst


@njit(cache=True, nogil=True)
def max_stretch_ratio(x, edges, rest_len):
    """The largest length / rest length of the edges (e, 2) of x (n, 3); rest_len (e,) m."""
    worst = 0.0
    for k in range(edges.shape[0]):
        r = _edge(x, edges[k, 0], edges[k, 1])[3] / rest_len[k]
        if r > worst:
            worst = r
    return worst
