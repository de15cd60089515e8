"""The exact buckled strip: the first-mode elastica of a strip clamped level at both ends.

A strip of bending stiffness B (N m, per unit width), width W (m) and length L (m) between its
clamps, its ends brought together by a share S of L with gravity off, takes the inflectional
elastica's first clamped-clamped mode. With k the elliptic modulus, K(k) and E(k) the complete
elliptic integrals of the first and second kinds and lambda = 4 K / L (the clamps and the
midpoint at theta = 0, the inflections at L/4 and 3L/4):

    sin(theta(s) / 2) = k sn(lambda s, k)
    x(s) = (2 E(am(lambda s), k) - lambda s) / lambda,   z(s) = 2 k (1 - cn(lambda s, k)) / lambda

so S = 1 - x(L) / L = 2 (1 - E / K), the axial force P = B W lambda^2 = 16 K^2 B W / L^2
(4 pi^2 B W / L^2 at onset, k -> 0) and the midpoint's lift z(L/2) = k L / K (small S:
(2 L / pi) sqrt(S)). (Love, A Treatise on the Mathematical Theory of Elasticity, ch. XIX;
shared/REFERENCES.md, "Dynamics, friction and compression".)

scipy.special's ellipk / ellipe / ellipj / ellipeinc take the parameter m = k^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipj, ellipk

from cloth_mg_ros.errors import ClothInputError

# Largest modulus searched: S(k) rises monotonically from 0 at k = 0 to 2 at k = 1 (a strip
# folded flat); k = 1 - 1e-12 already gives S = 1.9999..., beyond any shortening below 1.
_K_MAX = 1.0 - 1e-12


def shortening_of(k: float) -> float:
    """S = 2 (1 - E(k) / K(k)): the end shortening, as a share of L, at modulus k in [0, 1)."""
    m = k * k
    return 2.0 * (1.0 - float(ellipe(m)) / float(ellipk(m)))


def modulus_of(shortening: float) -> float:
    """The modulus k in (0, 1) whose first mode shortens the strip by ``shortening`` (a share of
    L, 0 < S < 1), by Brent's method on S(k)."""
    if not (isinstance(shortening, (int, float)) and math.isfinite(shortening)
            and 0.0 < shortening < 1.0):
        raise ClothInputError(f"buckle: the shortening must be a share of L in (0, 1), got "
                              f"{shortening!r}")
    return float(brentq(lambda k: shortening_of(k) - shortening, 0.0, _K_MAX,
                        xtol=1e-15, rtol=1e-15))


def onset_force(bend: float, width: float, length: float) -> float:
    """4 pi^2 B W / L^2, N: the clamped-clamped strip's Euler load (B N m, W and L m)."""
    return 4.0 * math.pi ** 2 * bend * width / length ** 2


@dataclass(frozen=True)
class BuckledStrip:
    """The exact first mode at shortening S: modulus k, force_n P (N), lift_m (the midpoint's
    height above the clamps, m), and the strip's bend (N m), width and length (m)."""

    bend: float
    width: float
    length: float
    shortening: float
    k: float
    force_n: float
    lift_m: float

    def profile(self, samples: int = 201) -> np.ndarray:
        """(samples, 2) points (x, z) in m of the centre line from the left clamp (x along the
        chord, z up), evenly spaced in arc length."""
        m = self.k * self.k
        lam = 4.0 * float(ellipk(m)) / self.length
        u = lam * np.linspace(0.0, self.length, samples)
        _, cn, _, am = ellipj(u, m)
        x = (2.0 * ellipeinc(am, m) - u) / lam
        z = 2.0 * self.k * (1.0 - cn) / lam
        return np.stack([x, z], axis=1)


def buckled_strip(bend: float, width: float, length: float, shortening: float) -> BuckledStrip:
    """The exact first-mode elastica of a clamped-clamped strip shortened by ``shortening``
    (share of L, 0 < S < 1): bend B N m per unit width, width W m, length L m."""
    for name, value in (("bend", bend), ("width", width), ("length", length)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
            raise ClothInputError(f"buckle: --{name} must be a positive number, got {value!r}")
    k = modulus_of(shortening)
    big_k = float(ellipk(k * k))
    return BuckledStrip(float(bend), float(width), float(length), float(shortening), k,
                        16.0 * big_k ** 2 * bend * width / length ** 2,
                        k * length / big_k)
