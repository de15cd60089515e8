"""Compression that buckles: a triangle's wrinkles finer than the mesh, by a tension-field
relaxation of the four-spring membrane (physics.stretch).

A fabric carries almost no in-plane compression: it wrinkles out of its plane at the load its
bending allows (Choi and Ko, "Stable but Responsive Cloth", SIGGRAPH 2002, carry compression
by a post-buckling curve for that reason). The finest wrinkle a mesh can show spans two
triangles, a half-wave of the triangle's size h = sqrt(2 A); a plate of bending stiffness B
(N m) buckles into it at sigma_b = pi^2 B / h^2 (N/m, the Euler load of a pinned span h),
and past buckling an elastica's force stays nearly constant. So a face may shorten along the
fabric's weft and warp (its rest frame's u and v) by wrinkle strains eta_u, eta_v in
[0, MAX_WRINKLE], each costing A sigma_b = pi^2 B / 2 (J per unit strain, the same for every
triangle size), which leave the springs the longer: the spring with rest direction r becomes
d' = F diag(1 + eta_u, 1 + eta_v) r, F = [d_u d_v]. The face's energy is

    E = min over eta of  sum_q A k_q / 2 (|d'_q| - l_q)^2 + A sigma_b (eta_u + eta_v).

Where the stress along a thread is above -sigma_b its eta is 0 and nothing changes: a strip in
tension keeps its measured moduli and its Poisson contraction (the crosswise spring is
compressed there while the crosswise stress is nil; capping springs one by one, as a spring
model would, undoes both). Past it the wrinkles take up the compression at the buckling
stress. E is continuous with a continuous gradient. The directions do not move with the cloth
and eta minimises (bounds included), so by the envelope theorem the forces are the springs'
forces with eta held: exact, and each spring is still a scalar function of one |d'|, which
keeps the block-symmetric Hessian.

The Hessian is the springs' at the wrinkled coefficients with eta held, not E's own (which has
no stiffness along a wrinkled thread): holding eta gives an energy that lies above E and
touches it where the step starts, so a step linearised on it never lands higher than it
predicts (a majorizer: the hanging sheet's energy never rises, and a sheet held 10 % short
settles). The price is that a step resists further compression as the taut membrane would,
and the wrinkles take it up at the next step's eta: compression relaxes over steps. A step
that used E's zero stiffness instead overshot springs that were back in tension within the
step and blew up on the held sheet.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# The measures' rest directions in the (u, v) rest frame: d_u, d_v, d_u + d_v, d_u - d_v.
R_U = (1.0, 0.0, 1.0, 1.0)
R_V = (0.0, 1.0, 1.0, -1.0)
# The most a thread may shorten by wrinkles finer than the mesh: past half its length the
# triangle has folded onto itself, which is the mesh's to show (resisted as tension again).
# Without a bound a slack face under its weight collapses towards zero height, where its
# springs' 1/|d| grows without limit.
MAX_WRINKLE = 0.5
_NEWTON_STEPS = 40


@njit(cache=True, nogil=True, inline="always")
def _columns(x, i0, i1, i2, coef):
    """F's columns d_u, d_v (each three scalars) of a face with coefficients coef (4, 3)."""
    u0 = coef[0, 0] * x[i0, 0] + coef[0, 1] * x[i1, 0] + coef[0, 2] * x[i2, 0]
    u1 = coef[0, 0] * x[i0, 1] + coef[0, 1] * x[i1, 1] + coef[0, 2] * x[i2, 1]
    u2 = coef[0, 0] * x[i0, 2] + coef[0, 1] * x[i1, 2] + coef[0, 2] * x[i2, 2]
    v0 = coef[1, 0] * x[i0, 0] + coef[1, 1] * x[i1, 0] + coef[1, 2] * x[i2, 0]
    v1 = coef[1, 0] * x[i0, 1] + coef[1, 1] * x[i1, 1] + coef[1, 2] * x[i2, 1]
    v2 = coef[1, 0] * x[i0, 2] + coef[1, 1] * x[i1, 2] + coef[1, 2] * x[i2, 2]
    return u0, u1, u2, v0, v1, v2


@njit(cache=True, nogil=True, inline="always")
def _gradient(f, eu, ev, stiff, rest_len):
    """(dE_el/d eta_u, dE_el/d eta_v, and the 2x2 second derivatives h_uu, h_uv, h_vv) of a
    face at wrinkle strains (eu, ev); f = F's columns d_u, d_v (6 scalars)."""
    uu = f[0] * f[0] + f[1] * f[1] + f[2] * f[2]
    uv = f[0] * f[3] + f[1] * f[4] + f[2] * f[5]
    vv = f[3] * f[3] + f[4] * f[4] + f[5] * f[5]
    gu = gv = huu = huv = hvv = 0.0
    for q in range(4):
        su = (1.0 + eu) * R_U[q]
        sv = (1.0 + ev) * R_V[q]
        d0 = su * f[0] + sv * f[3]
        d1 = su * f[1] + sv * f[4]
        d2 = su * f[2] + sv * f[5]
        dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dn < 1e-12:
            continue
        lr = rest_len[q]
        g = stiff[q] * (dn - lr) / dn
        du = R_U[q] * (d0 * f[0] + d1 * f[1] + d2 * f[2])  # d|d'|/d eta_u times |d'|
        dv = R_V[q] * (d0 * f[3] + d1 * f[4] + d2 * f[5])
        gu += g * du
        gv += g * dv
        w = stiff[q] * lr / (dn * dn * dn)
        huu += w * du * du + g * R_U[q] * R_U[q] * uu
        huv += w * du * dv + g * R_U[q] * R_V[q] * uv
        hvv += w * dv * dv + g * R_V[q] * R_V[q] * vv
    return gu, gv, huu, huv, hvv


@njit(cache=True, nogil=True, inline="always")
def relax(x, i0, i1, i2, coef, stiff, rest_len, cap):
    """A face's wrinkles (module docstring): (eta_u, eta_v) in [0, MAX_WRINKLE], the wrinkle
    strains along the fabric's weft and warp that minimise its energy (0, 0 where it is taut
    or the caps are off: cap inf). coef (4, 3), stiff (4,), cap (2,) of the face; rest_len
    (4,).

    A small bound-constrained problem, solved by Newton's method on the free variables with
    a projection onto the bounds: its minimum is where E's slope in each eta is -cap, or
    eta at a bound with the slope pointing out of the box. The bounds do not move with the
    cloth, so the forces need no term for them either."""
    if not cap[0] < np.inf:
        return 0.0, 0.0
    f = _columns(x, i0, i1, i2, coef)
    cu = cap[0]
    cv = cap[1]
    gu, gv, huu, huv, hvv = _gradient(f, 0.0, 0.0, stiff, rest_len)
    if gu + cu >= 0.0 and gv + cv >= 0.0:
        return 0.0, 0.0  # no thread direction compressed past its buckling stress
    eu = ev = 0.0
    scale = cu + cv + abs(gu) + abs(gv)
    for _ in range(_NEWTON_STEPS):
        ru = gu + cu
        rv = gv + cv
        free_u = (eu > 0.0 or ru < 0.0) and (eu < MAX_WRINKLE or ru > 0.0)
        free_v = (ev > 0.0 or rv < 0.0) and (ev < MAX_WRINKLE or rv > 0.0)
        if ((not free_u or abs(ru) <= 1e-13 * scale)
                and (not free_v or abs(rv) <= 1e-13 * scale)):
            break
        # Newton on the free variables (a diagonal fallback where the 2x2 is not positive)
        su = sv = 0.0
        det = huu * hvv - huv * huv
        if free_u and free_v and huu > 0.0 and det > 0.0:
            su = -(hvv * ru - huv * rv) / det
            sv = -(huu * rv - huv * ru) / det
        else:
            if free_u:
                su = -ru / huu if huu > 0.0 else -ru / scale
            if free_v:
                sv = -rv / hvv if hvv > 0.0 else -rv / scale
        nu_ = min(max(eu + su, 0.0), MAX_WRINKLE)
        nv_ = min(max(ev + sv, 0.0), MAX_WRINKLE)
        gu, gv, huu, huv, hvv = _gradient(f, nu_, nv_, stiff, rest_len)
        eu, ev = nu_, nv_
    return eu, ev


@njit(cache=True, nogil=True, inline="always")
def measure_coefficients(coef, q, eu, ev):
    """Measure q's vertex coefficients (c0, c1, c2) with the face's wrinkles:
    (1 + eta_u) r_u c_u + (1 + eta_v) r_v c_v."""
    su = (1.0 + eu) * R_U[q]
    sv = (1.0 + ev) * R_V[q]
    return (su * coef[0, 0] + sv * coef[1, 0], su * coef[0, 1] + sv * coef[1, 1],
            su * coef[0, 2] + sv * coef[1, 2])
