"""The exact cantilever: the heavy elastica of a strip clamped level at a ledge.

A strip of bending stiffness B (N m, per unit width) and weight w = rho g (N/m^2) sticks
out level over a ledge by l (m). With s the arc length from the ledge, u = s / l and theta
the angle of the tangent below horizontal, the moment balance of the overhang is

    theta''(u) = -G (1 - u) cos(theta),    theta(0) = 0,  theta'(1) = 0,   G = w l^3 / B

(Peirce 1930; the ASTM D1388 cantilever test). theta'(0) = m is found by shooting; the
physical branch keeps theta within [0, pi/2] (other roots loop the strip around the ledge).
The standard's 41.5 degree chord is reached at G = 8.0042 (bending length (B / w)^(1/3) =
l / 2 to 0.02 %), with the tip 0.7243 l out and 0.6408 l down (shared/REFERENCES.md).

All lengths returned are in units of l unless named otherwise.

A moment that grows with curvature, M = k1 kappa + k2 kappa^2 up to kappa_c and with its
tangent there beyond (physics.bending_law), puts mu = M l / k1 = k + a k^2 (k = kappa l,
a = k2 / (k1 l)) in place of theta': mu' = -G (1 - u) cos(theta) with G = w l^3 / k1,
theta' = k(mu), mu(1) = 0, shot on mu(0) the same way (``growth`` a and ``cap`` kappa_c l).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from cloth_mg_ros.errors import ClothInputError

GRAVITY = 9.81  # m/s^2
_RTOL, _ATOL = 1e-11, 1e-12
ASTM_CHORD_DEG = 41.5  # ASTM D1388: the chord angle at which l = 2 c


@dataclass(frozen=True)
class Elastica:
    """The exact rest shape of a clamped heavy strip with parameter G = w l^3 / B.

    u: (k,) arc length / l from the ledge; x, z: (k,) position / l (x out from the ledge,
    z down from it, both >= 0); theta: (k,) tangent angle below horizontal, rad.
    root_curvature: theta'(0), curvature at the ledge times l.
    """

    gamma: float
    u: np.ndarray
    x: np.ndarray
    z: np.ndarray
    theta: np.ndarray
    root_curvature: float

    @property
    def tip_reach(self) -> float:
        """Horizontal distance of the tip from the ledge, in units of l."""
        return float(self.x[-1])

    @property
    def tip_drop(self) -> float:
        """Vertical drop of the tip below the ledge, in units of l."""
        return float(self.z[-1])

    @property
    def chord_angle_deg(self) -> float:
        """Angle of the ledge-to-tip chord below horizontal, degrees."""
        return math.degrees(math.atan2(self.tip_drop, self.tip_reach))

    @property
    def tip_angle_deg(self) -> float:
        """Angle of the tangent at the tip below horizontal, degrees."""
        return math.degrees(float(self.theta[-1]))

    def profile(self, overhang: float) -> np.ndarray:
        """(k, 2) points (reach, drop) in metres for an overhang of ``overhang`` m."""
        return np.stack([self.x, self.z], axis=1) * overhang


def _shoot(gamma: float, m: float, dense: bool = False, rtol: float = _RTOL):
    def rhs(u: float, y: np.ndarray) -> list[float]:
        th, k = y[0], y[1]
        return [k, -gamma * (1.0 - u) * math.cos(th), math.cos(th), math.sin(th)]

    return solve_ivp(rhs, (0.0, 1.0), [0.0, m, 0.0, 0.0], rtol=rtol, atol=_ATOL * rtol / _RTOL,
                     dense_output=dense)


def curvature_of_moment(mu: float, growth: float, cap: float) -> float:
    """k = kappa l of the dimensionless moment mu = M l / k1 (module docstring)."""
    sign, mu = (1.0, mu) if mu >= 0.0 else (-1.0, -mu)
    mu_cap = cap + growth * cap * cap
    if mu <= mu_cap:
        return sign * 2.0 * mu / (1.0 + math.sqrt(max(1.0 + 4.0 * growth * mu, 0.0)))
    return sign * (cap + (mu - mu_cap) / (1.0 + 2.0 * growth * cap))


def _shoot_law(gamma: float, m: float, growth: float, cap: float, dense: bool = False,
               rtol: float = _RTOL):
    def rhs(u: float, y: np.ndarray) -> list[float]:
        th, mu = y[0], y[1]
        return [curvature_of_moment(mu, growth, cap), -gamma * (1.0 - u) * math.cos(th),
                math.cos(th), math.sin(th)]

    return solve_ivp(rhs, (0.0, 1.0), [0.0, m, 0.0, 0.0], rtol=rtol, atol=_ATOL * rtol / _RTOL,
                     dense_output=dense)


@lru_cache(maxsize=256)
def elastica(gamma: float, samples: int = 201, growth: float = 0.0,
             cap: float = math.inf) -> Elastica:
    """The exact heavy elastica for G = ``gamma`` (> 0), sampled at ``samples`` points;
    growth and cap: a moment rising with curvature (module docstring), 0 and inf: M = B
    kappa.

    The root moment m (theta'(0) for a linear moment) lies in (0, G / 2] (the ledge carries
    at most the whole weight at arm l / 2); the end moment is scanned over that interval
    for a sign change and the root whose strip stays within [0, pi/2] is polished with
    Brent's method. root_curvature is theta'(0) l.
    """
    if not (isinstance(gamma, (int, float)) and math.isfinite(gamma) and gamma > 0.0):
        raise ClothInputError(f"elastica: G must be a positive number, got {gamma!r}")
    gamma = float(gamma)
    linear = growth == 0.0 and math.isinf(cap)
    if not linear and not (math.isfinite(growth) and cap > 0.0
                           and 1.0 + 2.0 * growth * min(cap, 1e300) > 0.0):
        raise ClothInputError(f"elastica: the moment law must keep a positive tangent, got "
                              f"growth {growth!r}, cap {cap!r}")

    def shoot(m: float, dense: bool = False, rtol: float = _RTOL):
        if linear:
            return _shoot(gamma, m, dense=dense, rtol=rtol)
        return _shoot_law(gamma, m, growth, cap, dense=dense, rtol=rtol)

    def end_curvature(m: float, rtol: float = _RTOL) -> float:
        return float(shoot(m, rtol=rtol).y[1, -1])

    # The physical root is the largest one (smaller roots loop the strip round): scan down
    # from G / 2 at a loose tolerance, then polish the first bracket found.
    grid = np.linspace(0.5 * gamma, 0.0, 41 + int(4 * math.sqrt(gamma)))
    prev_m, prev_f = grid[0], end_curvature(grid[0], 1e-6)
    for m_next in grid[1:]:
        f_next = end_curvature(m_next, 1e-6)
        if prev_f * f_next <= 0.0:
            m = brentq(end_curvature, m_next, prev_m, xtol=1e-14, rtol=1e-14)
            u = np.linspace(0.0, 1.0, samples)
            th, _, x, z = shoot(m, dense=True).sol(u)
            if th.min() >= -1e-9 and th.max() <= 0.5 * math.pi + 1e-9:
                root = float(m) if linear else curvature_of_moment(float(m), growth, cap)
                return Elastica(gamma, u, x, z, th, root)
        prev_m, prev_f = m_next, f_next
    raise ClothInputError(f"elastica: no physical solution found for G = {gamma}")


def gamma_of(bend: float, density: float, overhang: float, gravity: float = GRAVITY) -> float:
    """G = rho g l^3 / B for bending stiffness ``bend`` N m, areal density kg/m^2, overhang m."""
    return density * gravity * overhang ** 3 / bend


def gamma_at_chord(chord_deg: float = ASTM_CHORD_DEG) -> float:
    """The G at which the ledge-to-tip chord makes ``chord_deg`` degrees (0 < deg < 90)."""
    if not 0.0 < chord_deg < 90.0:
        raise ClothInputError(f"chord angle must be in (0, 90) degrees, got {chord_deg}")
    return brentq(lambda g: elastica(g).chord_angle_deg - chord_deg, 1e-2, 1e3, xtol=1e-10)
