"""Ten measured fabrics: Wang, O'Brien and Ramamoorthi, "Data-Driven Elastic Models for
Cloth: Modeling and Measurement", ACM TOG 30(4):71, 2011.

The figures below are facts quoted from the material files that paper published with the
ARCSim simulator (UC Berkeley; each file has ``density`` in kg/m^2, ``stretching`` whose
first row [C11, C12, C22, C33] is the zero-strain stiffness, and ``bending``, a 3 x 5 table
of ke by hinge direction and curvature). No file of theirs ships with this project.

How they become this model's SI parameters:

* Bending. ARCSim's hinge energy is ke l^2 theta^2 / (8 (A0 + A1)) (src/physics.cpp,
  ``bending_coeff``: ``double shape = sq(l)/(2*a); return ke*shape;`` and
  ``bending_energy``: ``return bending_coeff(edge, theta)*sq(theta - edge->theta_ideal)/4;``,
  with theta the angle between the face normals, src/geometry.cpp ``dihedral_angle``). On a
  strip bent to curvature kappa with hinges across it, theta = kappa h and A0 + A1 = l h, so
  the energy per area is ke kappa^2 / 8 against a plate's B kappa^2 / 2: the table holds 4 B,
  and B = ke / 4. (Feng et al. 2022 reproduce ARCSim with "modulus / 4" for the same reason.)
  The table's rows are by hinge direction in the cloth's (u, v) axes (src/dde.cpp
  ``bending_stiffness``): row 0 a hinge along u (the strip bends along v), row 1 at 45
  degrees, row 2 a hinge along v (the strip bends along u); its columns are curvatures 0,
  10, 20, 30 and 40 1/m (``alpha * 0.2`` with alpha = curv / 2: "samples are per 0.05
  cm^-1"), ARCSim interpolating linearly between them and holding the last beyond. Each
  entry is a secant stiffness: ARCSim's hinge force is -ke(theta) theta dtheta/dx / 2, so
  the moment is M = (ke / 4) kappa. `Material.bend` is the mean of the three rows' first
  column; `curvature_fit` fits each direction's M = k1 kappa + k2 kappa^2 (k1 the first
  column, k2 by least squares to the rest) and `curvature_law` gives the model's (k2 = r
  k1, one rate for the three) for physics.bending_law. The data do not all stiffen with
  curvature: of the ten fabrics, royal-target, pink-ribbon-brown and ivory-rib-knit rise
  1.2-1.8x by 20-30 1/m, the others stay level or fall, and eight of ten fall at 40 1/m.
* Stretch. ARCSim doubles each table entry (src/dde.cpp ``evaluate_stretching_sample``,
  ``real_elastic[i] *= 2``) and uses the Green-strain energy 1/2 k0 G00^2 + k1 G00 G11 +
  1/2 k2 G11^2 + k3 G01^2, so at small strain the moduli are k0 = 2 C11 along u,
  k2 = 2 C22 along v, k1 = 2 max(C12, 0) coupling and shear modulus mu = C33 (N/m). A strip
  pulled along u with free sides has E_u = k0 - k1^2 / k2 (E_v likewise).
* This model's membrane is four springs per triangle (u, v and two diagonals: the paper's
  block-symmetric stretch and shear), whose coupling equals its shear stiffness (Cauchy's
  relation of spring networks). `spring_constants` chooses k_u, k_v, k_s so that E_u, E_v
  match exactly and k_s = mu where it can; where the measured mu would make a spring
  negative, k_s is the largest value that keeps both E exact (noted per fabric).
* The data's u axis is taken as this model's weft axis (x of a flat sheet, "up" of a
  garment) and v as the warp; the source names neither.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.optimize import brentq

WANG_2011 = ("Wang, O'Brien, Ramamoorthi, Data-Driven Elastic Models for Cloth: Modeling and "
             "Measurement, ACM TOG 30(4):71, 2011 (ARCSim material files)")


CURVATURES = (0.0, 10.0, 20.0, 30.0, 40.0)  # 1/m: the bending table's columns
# The curvature law M = k1 kappa + k2 kappa^2 holds over the table's range; beyond it the
# moment goes on with the tangent at its end (ARCSim holds its last column there).
CURVATURE_CAP = CURVATURES[-1]
# Least tangent the law may reach, as a fraction of k1: the fits whose moment falls with
# curvature are clipped here so a fold never snaps through (module docstring).
MIN_TANGENT = 0.5


@dataclass(frozen=True)
class FabricRecord:
    """One measured fabric as published. density kg/m^2; bending: the 3 x 5 ke table, N m
    (rows: hinge along u, at 45 degrees, along v; columns: curvature `CURVATURES`);
    stretch [C11, C12, C22, C33] table row 0, N/m."""

    name: str
    use: str
    density: float
    bending: tuple[tuple[float, ...], ...]
    stretch: tuple[float, float, float, float]

    @property
    def ke(self) -> tuple[float, float, float]:
        """The curvature-0 column: (hinge along u, 45 deg, hinge along v), N m."""
        return tuple(row[0] for row in self.bending)

    @property
    def bend_directions(self) -> dict[str, float]:
        """B = ke / 4 at curvature 0 by the direction the strip runs (and bends) along, N m:
        weft (u; the table's row of hinges along v), warp (v) and bias."""
        along_v, bias, along_u = (k / 4.0 for k in self.ke)
        return {"weft": along_u, "warp": along_v, "bias": bias}

    @property
    def bend(self) -> float:
        """Mean of the three directions, N m."""
        return sum(self.ke) / 12.0

    def moments(self, direction: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(kappa 1/m, M N) of a strip along ``direction`` at the table's curvatures: ARCSim
        treats each entry as the secant stiffness there, M = (ke / 4) kappa."""
        row = {"warp": 0, "bias": 1, "weft": 2}[direction]
        return CURVATURES, tuple(k / 4.0 * c for k, c in zip(self.bending[row], CURVATURES,
                                                            strict=True))

    def curvature_fit(self, direction: str) -> tuple[float, float]:
        """(k1 N m, k2 N m^2) of M = k1 kappa + k2 kappa^2 (Feng et al. 2022's form) for a
        strip along ``direction``: k1 the curvature-0 stiffness, k2 the least-squares fit
        of the moments at 10-40 1/m above k1 kappa."""
        kappa, moment = self.moments(direction)
        k1 = self.bend_directions[direction]
        num = sum((m - k1 * c) * c * c for c, m in zip(kappa, moment, strict=True))
        return k1, num / sum(c ** 4 for c in kappa)

    @property
    def curvature_rate(self) -> float:
        """r (m) of the model's M = k1(phi) kappa (1 + r kappa): the three directions' k2
        summed over their k1 summed (the rise with curvature as a share of the stiffness,
        fitted to all three rows), clipped so the tangent k1 (1 + 2 r kappa) stays at least
        MIN_TANGENT k1 up to CURVATURE_CAP (a moment that fell with curvature would let a
        fold snap through)."""
        fits = [self.curvature_fit(d) for d in ("weft", "warp", "bias")]
        r = sum(f[1] for f in fits) / sum(f[0] for f in fits)
        return max(r, -(1.0 - MIN_TANGENT) / (2.0 * CURVATURE_CAP))

    def curvature_law(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """((k1 weft, warp, bias) N m, (k2 ...) N m^2) of the model: k1 the curvature-0
        column, k2 = r k1 (`curvature_rate`). One rate for the three directions: the rows'
        own fits scatter (pink-ribbon-brown's weft k2 is -0.01e-6, its warp's 0.90e-6 N m^2),
        and laws that rise at different rates make a bias strip twist under its own weight
        (its tip 8 % of l off the elastica at G = 8 with the rows' own k2, 3 % with one
        rate, 800 particles); `curvature_fit` gives each row's."""
        k1 = tuple(self.curvature_fit(d)[0] for d in ("weft", "warp", "bias"))
        r = self.curvature_rate
        return k1, tuple(r * k for k in k1)

    @property
    def moduli(self) -> tuple[float, float, float]:
        """(E_u, E_v, mu): uniaxial moduli with free sides and shear modulus, N/m."""
        c11, c12, c22, c33 = self.stretch
        k0, k2, k1 = 2.0 * c11, 2.0 * c22, 2.0 * max(c12, 0.0)
        return k0 - k1 * k1 / k2, k2 - k1 * k1 / k0, c33


def _table(*rows: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
    """A bending table given in 1e-6 N m, in N m."""
    return tuple(tuple(v * 1e-6 for v in row) for row in rows)


# Density, the bending table (1e-6 N m: rows hinge along u, 45 deg, along v; columns
# curvature 0, 10, 20, 30, 40 1/m) and stretching row 0 (N/m), quoted from the Wang et al.
# 2011 material files (the copy read: github.com/wxhaooo/lyra, materials/*.json).
MEASURED: tuple[FabricRecord, ...] = (
    FabricRecord("gray-interlock", "t-shirt", 0.187, _table(
        (23.191698, 32.932217, 34.406498, 39.014420, 23.382786),
        (24.749964, 18.651314, 16.370552, 25.095791, 8.860165),
        (14.267624, 7.052906, 14.515154, 24.665127, 19.383726)),
        (16.5938, -14.696, 34.4771, 36.8603)),
    FabricRecord("ivory-rib-knit", "underwear", 0.276, _table(
        (46.237591, 63.086697, 83.192772, 97.574425, 80.726685),
        (30.015930, 30.097424, 30.172081, 30.648300, 24.726685),
        (32.243889, 37.341282, 38.817448, 39.812527, 30.437820)),
        (42.871, -0.234556, 65.166, 83.1756)),
    FabricRecord("navy-sparkle-sweat", "sweater", 0.224, _table(
        (59.469658, 37.500004, 35.787308, 35.737106, 21.033506),
        (40.072277, 37.446949, 35.206612, 24.871773, 9.033506),
        (45.625023, 39.520981, 30.734119, 23.301662, 13.033506)),
        (12.4863, -19.8753, 3.27243, 17.6163)),
    FabricRecord("white-dots-on-blk", "tablecloth", 0.128, _table(
        (51.713814, 36.506981, 66.360748, 52.729267, 15.221714),
        (40.659470, 10.401686, 20.847820, 30.993469, 12.726685),
        (31.282822, 22.910311, 26.350384, 30.637762, 16.726685)),
        (2002.09, 0.345588, 2027.49, 19.189)),
    FabricRecord("11oz-black-denim", "jeans", 0.324, _table(
        (64.196457, 60.286175, 60.943428, 62.433697, 19.824701),
        (73.384567, 59.671982, 61.080757, 68.242569, 36.033474),
        (96.951576, 107.848228, 113.060738, 120.569740, 79.781021)),
        (205.352, 10.2341, 1013.89, 53.3872)),
    FabricRecord("camel-ponte-roma", "jacket", 0.284, _table(
        (36.348366, 49.585537, 45.744080, 47.413387, 20.726685),
        (33.013252, 29.744385, 35.103642, 34.041019, 14.439938),
        (37.157593, 34.107452, 33.229435, 34.685535, 10.439938)),
        (31.1462, -12.8027, 44.0287, 31.8964)),
    FabricRecord("royal-target", "pants", 0.220, _table(
        (125.409805, 167.284561, 215.412750, 215.090790, 223.861038),
        (107.997696, 120.583267, 144.141678, 140.606689, 153.048309),
        (125.409805, 167.284561, 215.412750, 215.090790, 227.861038)),
        (2016.55, 9.17051, 2034.98, 104.76)),
    FabricRecord("tango-red-jet-set", "jacket", 0.113, _table(
        (14.293814, 8.949391, 30.011126, 36.081490, 18.363136),
        (21.951700, 22.446325, 18.408735, 19.598495, 12.071854),
        (20.345654, 22.696880, 15.698071, 13.466827, 7.556618)),
        (43.0676, 54.3733, 171.425, 14.3147)),
    FabricRecord("white-swim-solid", "swimsuit", 0.204, _table(
        (60.237942, 56.357208, 69.698593, 55.305969, 34.705532),
        (58.803211, 63.121964, 61.379181, 47.971302, 19.383726),
        (51.018833, 50.741455, 50.570576, 50.006001, 24.556618)),
        (47.9712, 6.83452, 104.615, 60.7737)),
    FabricRecord("pink-ribbon-brown", "blanket", 0.228, _table(
        (117.070122, 202.682922, 298.615936, 244.588867, 238.437820),
        (87.509773, 36.396919, 103.628098, 91.630119, 97.175949),
        (59.774277, 59.260632, 64.199661, 55.017326, 59.221714)),
        (151.504, 106.028, 244.831, 30.2502)),
)


def _springs_for_shear(e_u: float, e_v: float, k_s: float) -> tuple[float, float]:
    """k_u, k_v with k_u + k_s k_v / (k_v + k_s) = e_u and likewise for v (fixed point:
    each map is a contraction for k_s > 0)."""
    k_u, k_v = e_u, e_v
    for _ in range(200):
        k_u = e_u - (k_s * k_v / (k_v + k_s) if k_v + k_s > 0.0 else 0.0)
        k_v = e_v - (k_s * k_u / (k_u + k_s) if k_u + k_s > 0.0 else 0.0)
    return k_u, k_v


def spring_constants(e_u: float, e_v: float, mu: float) -> tuple[float, float, float, bool]:
    """(k_u, k_v, k_s, shear_exact) of the four-spring membrane that gives the uniaxial
    moduli e_u, e_v (N/m) exactly and the shear modulus mu where it can (shear_exact), else
    the largest k_s that keeps k_u, k_v >= 0."""
    k_u, k_v = _springs_for_shear(e_u, e_v, mu)
    if min(k_u, k_v) >= 0.0:
        return k_u, k_v, mu, True

    def lowest(k_s: float) -> float:
        return min(_springs_for_shear(e_u, e_v, k_s))

    k_s = brentq(lowest, 0.0, mu, xtol=1e-9 * mu)
    k_s *= 1.0 - 1e-6  # stay on the feasible side
    k_u, k_v = _springs_for_shear(e_u, e_v, k_s)
    return max(k_u, 0.0), max(k_v, 0.0), k_s, False


def fabric_parameters(record: FabricRecord) -> dict:
    """The model parameters of one measured fabric (N/m, N m, kg/m^2) and a note saying
    what is averaged or adjusted."""
    e_u, e_v, mu = record.moduli
    k_u, k_v, k_s, exact = spring_constants(e_u, e_v, mu)
    bends = record.bend_directions
    spread = max(bends.values()) / min(bends.values())
    note = (f"bending {record.bend:.3g} N m is the mean of weft {bends['weft']:.3g}, "
            f"warp {bends['warp']:.3g}, bias {bends['bias']:.3g} (spread {spread:.2f}x), which "
            f"the bending law carries by direction with its curvature terms; "
            f"uniaxial E_u {e_u:.4g}, E_v {e_v:.4g} N/m exact")
    note += (f", shear {mu:.4g} N/m exact" if exact else
             f"; shear {k_s:.4g} N/m instead of the measured {mu:.4g} (the spring membrane "
             f"cannot have both moduli with a larger one)")
    if math.isclose(k_s, 0.0):
        note += "; no shear stiffness left"
    return {"stretch": k_u, "stretch_warp": k_v, "shear": k_s, "bend": record.bend,
            "density": record.density, "note": note}
