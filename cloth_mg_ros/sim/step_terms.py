"""The per-particle terms of one implicit step (sim.integrator.assemble_step), a particle per
thread.

Each kernel computes what a numpy expression of the integrator did, in the same order of
operations, so the numbers are the same bit for bit. At 20K particles the expressions
made a dozen full (n, 3) temporaries per step on one thread, about 1 ms of a 35-40 ms tick;
a kernel writes each result once, on every core.
"""

from __future__ import annotations

from numba import njit, prange


@njit(cache=True, nogil=True, parallel=True)
def bdf2_combination(x, x_prev, v, h, out):
    """out (n, 3) = (x - x_prev) / 3 + h v: what K multiplies in a BDF2 step (m, with h the
    effective step in s)."""
    for i in prange(x.shape[0]):
        for a in range(3):
            out[i, a] = (x[i, a] - x_prev[i, a]) / 3.0 + h * v[i, a]


@njit(cache=True, nogil=True, parallel=True)
def step_forces(internal, applied, m, v, h_v, air_drag, damping, out):
    """out (n, 3) N = internal + applied - air_drag m v - damping H v: the elastic forces, the
    forces that do not depend on x, air drag (air_drag 1/s, m (n,) kg, v (n, 3) m/s) and
    stiffness-proportional damping (damping s, h_v (n, 3) = H v N/s)."""
    for i in prange(m.shape[0]):
        drag = air_drag * m[i]
        for a in range(3):
            f = internal[i, a] + applied[i, a] - drag * v[i, a]
            out[i, a] = f - damping * h_v[i, a]


@njit(cache=True, nogil=True, parallel=True)
def bdf2_rhs(m, v, v_prev, f, k_y, h, out):
    """out (n, 3) kg m/s = m (v - v_prev) / 3 + h (f + K y): a BDF2 step's right-hand side
    (h the effective step, s)."""
    for i in prange(m.shape[0]):
        for a in range(3):
            out[i, a] = (m[i] * (v[i, a] - v_prev[i, a])) / 3.0 + h * (f[i, a] + k_y[i, a])


@njit(cache=True, nogil=True, parallel=True)
def euler_rhs(f, k_y, h, out):
    """out (n, 3) kg m/s = h (f + h K y): an implicit Euler step's right-hand side."""
    for i in prange(f.shape[0]):
        for a in range(3):
            out[i, a] = h * (f[i, a] + h * k_y[i, a])


@njit(cache=True, nogil=True, parallel=True)
def mass_blocks(m, factor, out):
    """out (n, 3, 3) = m_i factor I: the lumped mass blocks, times (1 + h air_drag)."""
    for i in prange(m.shape[0]):
        d = m[i] * factor
        for a in range(3):
            for c in range(3):
                out[i, a, c] = d if a == c else 0.0

