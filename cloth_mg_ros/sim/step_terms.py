"""The per-particle terms of one implicit step (sim.integrator.assemble_step), a particle per
thread.

At 20K particles the numpy expressions these replace made a dozen full (n, 3) temporaries
per step on one thread, about 1 ms of a 35-40 ms tick; a kernel writes each result once, on
every core.
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
def elastic_combination(v, y, damping, s, out):
    """out (n, 3) = damping v + s y: what the mesh's elastic Hessian multiplies in the
    right-hand side (damping s; s = 1 for BDF2, h for implicit Euler, whose K y is scaled
    by h once more)."""
    for i in prange(v.shape[0]):
        for a in range(3):
            out[i, a] = damping * v[i, a] + s * y[i, a]


@njit(cache=True, nogil=True, parallel=True)
def step_forces(internal, gravity, external, m, v, air_drag, out):
    """out (n, 3) N = internal + m gravity + external - air_drag m v: the elastic forces, the
    forces that do not depend on x (ClothModel.applied_forces' sum: gravity (3,) m/s^2 and
    external (n, 3) N, or (0, 3) for none) and air drag (air_drag 1/s, m (n,) kg, v (n, 3)
    m/s), formed here rather than from an (n, 3) array of the applied forces made each step
    (0.17 ms at 20K particles). The damping force is in the right-hand side's elastic
    product (`elastic_combination`)."""
    loaded = external.shape[0] > 0
    for i in prange(m.shape[0]):
        drag = air_drag * m[i]
        for a in range(3):
            applied = m[i] * gravity[a]
            if loaded:
                applied = applied + external[i, a]
            out[i, a] = internal[i, a] + applied - drag * v[i, a]


@njit(cache=True, nogil=True, parallel=True)
def bdf2_rhs(m, v, v_prev, f, h_z, k_rest, h, out):
    """out (n, 3) kg m/s = m (v - v_prev) / 3 + h (f - H z + k_rest): a BDF2 step's
    right-hand side, with f the forces but damping, H z the elastic product
    (`elastic_combination`, s = 1) and k_rest the rest of K y (h the effective step, s)."""
    for i in prange(m.shape[0]):
        for a in range(3):
            out[i, a] = ((m[i] * (v[i, a] - v_prev[i, a])) / 3.0
                         + h * (f[i, a] - h_z[i, a] + k_rest[i, a]))


@njit(cache=True, nogil=True, parallel=True)
def euler_rhs(f, h_z, k_rest, h, out):
    """out (n, 3) kg m/s = h (f - H z + h k_rest): an implicit Euler step's right-hand side
    (H z with s = h, `elastic_combination`)."""
    for i in prange(f.shape[0]):
        for a in range(3):
            out[i, a] = h * (f[i, a] - h_z[i, a] + h * k_rest[i, a])


@njit(cache=True, nogil=True, parallel=True)
def mass_blocks(m, factor, out):
    """out (n, 3, 3) = m_i factor I: the lumped mass blocks, times (1 + h air_drag)."""
    for i in prange(m.shape[0]):
        d = m[i] * factor
        for a in range(3):
            for c in range(3):
                out[i, a, c] = d if a == c else 0.0


@njit(cache=True, nogil=True, parallel=True)
def bdf2_update(x, x_prev, v, dv, h, x_out, v_out):
    """v_out = v + dv, x_out = (4 x - x_prev) / 3 + h v_out (n, 3): a BDF2 step's new
    velocities (m/s) and positions (m) from its solution dv, h the effective step (s); the
    same operations as numpy's on whole arrays, without their four temporaries."""
    for i in prange(x.shape[0]):
        for a in range(3):
            vn = v[i, a] + dv[i, a]
            v_out[i, a] = vn
            x_out[i, a] = (4.0 * x[i, a] - x_prev[i, a]) / 3.0 + h * vn



@njit(cache=True, nogil=True, parallel=True)
def genalpha_combination(v, a, h, c, out):
    """out (n, 3) m = h v + c a: the Newmark displacement of a generalised-alpha step before
    its solution (h the step in s, c = h^2 (1/2 - beta/gamma) in s^2, a (n, 3) m/s^2 the
    acceleration history); what K multiplies in its right-hand side."""
    for i in prange(v.shape[0]):
        for j in range(3):
            out[i, j] = h * v[i, j] + c * a[i, j]


@njit(cache=True, nogil=True, parallel=True)
def genalpha_rhs(m, a, f, h_z, k_rest, s, k_share, c_m, out):
    """out (n, 3) kg m/s = s (f - H z + k_share k_rest) + c_m m a: a generalised-alpha step's
    right-hand side (sim.schemes.GenAlpha: s, k_share = 1 - alpha_f and c_m in s), with f
    the forces but damping, H z the elastic product (`elastic_combination`, s = k_share) and
    k_rest the rest of K y."""
    for i in prange(m.shape[0]):
        for j in range(3):
            out[i, j] = (s * (f[i, j] - h_z[i, j] + k_share * k_rest[i, j])
                         + c_m * m[i] * a[i, j])


@njit(cache=True, nogil=True, parallel=True)
def genalpha_update(x, v, a, dv, h, c, h_dv, gamma, x_out, v_out, a_out):
    """A generalised-alpha step's Newmark update from its solution dv (n, 3) m/s:
    v_out = v + dv, x_out = x + h v + c a + h_dv dv, a_out = (dv - h (1 - gamma) a) /
    (gamma h) (m/s, m, m/s^2; h in s, c in s^2, h_dv = h beta / gamma in s)."""
    for i in prange(x.shape[0]):
        for j in range(3):
            d = dv[i, j]
            v_out[i, j] = v[i, j] + d
            x_out[i, j] = x[i, j] + h * v[i, j] + c * a[i, j] + h_dv * d
            a_out[i, j] = (d - h * (1.0 - gamma) * a[i, j]) / (gamma * h)
