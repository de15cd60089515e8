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
  The first column (curvature 0) is the small-curvature stiffness. Its rows are by hinge
  direction in the cloth's (u, v) axes (src/dde.cpp ``bending_stiffness``): row 0 a hinge
  along u (the strip bends along v), row 1 at 45 degrees, row 2 a hinge along v (the strip
  bends along u). This model has one bending stiffness: B is the mean of the three rows,
  and the per-direction values are kept for reference.
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


@dataclass(frozen=True)
class FabricRecord:
    """One measured fabric as published. density kg/m^2; ke (hinge along u, 45 deg, hinge
    along v) at zero curvature, N m (4 B); stretch [C11, C12, C22, C33] table row 0, N/m."""

    name: str
    use: str
    density: float
    ke: tuple[float, float, float]
    stretch: tuple[float, float, float, float]

    @property
    def bend_directions(self) -> dict[str, float]:
        """B = ke / 4 by the direction the strip bends along, N m."""
        along_v, bias, along_u = (k / 4.0 for k in self.ke)
        return {"along_u": along_u, "bias": bias, "along_v": along_v}

    @property
    def bend(self) -> float:
        """Mean of the three directions, N m."""
        return sum(self.ke) / 12.0

    @property
    def moduli(self) -> tuple[float, float, float]:
        """(E_u, E_v, mu): uniaxial moduli with free sides and shear modulus, N/m."""
        c11, c12, c22, c33 = self.stretch
        k0, k2, k1 = 2.0 * c11, 2.0 * c22, 2.0 * max(c12, 0.0)
        return k0 - k1 * k1 / k2, k2 - k1 * k1 / k0, c33


# Density, ke (1e-6 N m: hinge along u, 45 deg, along v, curvature-0 column) and stretching
# row 0 (N/m), quoted from the Wang et al. 2011 material files.
MEASURED: tuple[FabricRecord, ...] = (
    FabricRecord("gray-interlock", "t-shirt", 0.187, (23.19e-6, 24.75e-6, 14.27e-6),
                 (16.5938, -14.696, 34.4771, 36.8603)),
    FabricRecord("ivory-rib-knit", "underwear", 0.276, (46.24e-6, 30.02e-6, 32.24e-6),
                 (42.871, -0.234556, 65.166, 83.1756)),
    FabricRecord("navy-sparkle-sweat", "sweater", 0.224, (59.47e-6, 40.07e-6, 45.63e-6),
                 (12.4863, -19.8753, 3.27243, 17.6163)),
    FabricRecord("white-dots-on-blk", "tablecloth", 0.128, (51.71e-6, 40.66e-6, 31.28e-6),
                 (2002.09, 0.345588, 2027.49, 19.189)),
    FabricRecord("11oz-black-denim", "jeans", 0.324, (64.20e-6, 73.38e-6, 96.95e-6),
                 (205.352, 10.2341, 1013.89, 53.3872)),
    FabricRecord("camel-ponte-roma", "jacket", 0.284, (36.35e-6, 33.01e-6, 37.16e-6),
                 (31.1462, -12.8027, 44.0287, 31.8964)),
    FabricRecord("royal-target", "pants", 0.220, (125.41e-6, 108.00e-6, 125.41e-6),
                 (2016.55, 9.17051, 2034.98, 104.76)),
    FabricRecord("tango-red-jet-set", "jacket", 0.113, (14.29e-6, 21.95e-6, 20.35e-6),
                 (43.0676, 54.3733, 171.425, 14.3147)),
    FabricRecord("white-swim-solid", "swimsuit", 0.204, (60.24e-6, 58.80e-6, 51.02e-6),
                 (47.9712, 6.83452, 104.615, 60.7737)),
    FabricRecord("pink-ribbon-brown", "blanket", 0.228, (117.07e-6, 87.51e-6, 59.77e-6),
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
    note = (f"bending {record.bend:.3g} N m is the mean of along-u {bends['along_u']:.3g}, "
            f"bias {bends['bias']:.3g}, along-v {bends['along_v']:.3g} (spread {spread:.2f}x); "
            f"uniaxial E_u {e_u:.4g}, E_v {e_v:.4g} N/m exact")
    note += (f", shear {mu:.4g} N/m exact" if exact else
             f"; shear {k_s:.4g} N/m instead of the measured {mu:.4g} (the spring membrane "
             f"cannot have both moduli with a larger one)")
    if math.isclose(k_s, 0.0):
        note += "; no shear stiffness left"
    return {"stretch": k_u, "stretch_warp": k_v, "shear": k_s, "bend": record.bend,
            "density": record.density, "note": note}
