"""Cloth materials: ten measured fabrics (`physics.fabrics`) and the paper's Table 2 set.

`MATERIALS` holds both. The measured fabrics (Wang, O'Brien and Ramamoorthi 2011) are what
scenes default to; the paper's five are kept, under their own names, because its Table 4
(solver time against stiffness) is reproduced with them. They are relative stiffnesses put
on an assumed SI scale, not fabrics. The paper gives only relative stiffness (stretch / shear /
bend): silk 3.0/1.5/0.03, wool 4/2/0.2, cotton 8/4/0.8, denim 10/5/2.5, leather 13/8/5. We keep
those ratios exactly and fix the units once:

* stretch and shear: 1 paper unit = ``STRETCH_UNIT`` = 1000 N/m (membrane stiffness, the
  energy per rest area is k/2 (|d| - l)^2 with d the dimensionless deformation gradient
  column). Cotton is then 8000 N/m: a 5 cm strip of woven cotton pulled 1 % carries 4 N,
  which is what tensile tests of plain-weave cotton show, and a hanging 1 m sheet stretches
  by about 0.025 % at the top. (A softer scale makes the systems easier to solve and the
  cloth rubbery; the solver comparisons would flatter every method.)
* bending: 1 paper unit = ``BEND_UNIT`` = 3e-5 N m (flexural rigidity). Cotton is then
  2.4e-5 N m, a bending length (B / (rho g))^(1/3) of about 2.3 cm, which is what woven
  cotton shows in the cantilever test; silk about 0.7 cm, leather about 4.3 cm.
* areal density: one value, 0.2 kg/m^2, for every material. The paper gives none, and a
  common density keeps stiffness the only difference between the materials, so Table 4's
  comparison (solver time against stiffness) is reproduced as the paper ran it.
* damping: stiffness-proportional (Rayleigh) damping ``damping`` seconds, D = damping * K =
  -damping * H (K = df/dx, H the energy's Hessian),
  plus mass-proportional air drag ``air_drag`` 1/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.bending_law import BendingLaw
from cloth_mg_ros.physics.fabrics import CURVATURE_CAP, MEASURED, WANG_2011, fabric_parameters

STRETCH_UNIT = 1000.0  # N/m per paper unit
BEND_UNIT = 3.0e-5  # N m per paper unit
DEFAULT_DENSITY = 0.2  # kg/m^2
DEFAULT_DAMPING = 2.0e-3  # s
DEFAULT_AIR_DRAG = 0.05  # 1/s

# name: (stretch, shear, bend) in the paper's relative units (Table 2).
PAPER_TABLE2: dict[str, tuple[float, float, float]] = {
    "silk": (3.0, 1.5, 0.03),
    "wool": (4.0, 2.0, 0.2),
    "cotton": (8.0, 4.0, 0.8),
    "denim": (10.0, 5.0, 2.5),
    "leather": (13.0, 8.0, 5.0),
}


@dataclass(frozen=True)
class Material:
    """Physical parameters of a fabric, SI units.

    - stretch: weft/warp membrane stiffness, N/m.
    - shear: stiffness of the two diagonal (shear) directions, N/m.
    - bend: flexural rigidity, N m.
    - density: areal density, kg/m^2.
    - damping: stiffness-proportional damping time, s (>= 0).
    - air_drag: mass-proportional drag rate, 1/s (>= 0).
    - stretch_warp: membrane stiffness along the warp (the material v axis), N/m; None: the
      same as ``stretch``, which is then the weft (u axis) stiffness.
    - kind: "measured" (a fabric measured in the lab) or "paper" (the paper's Table 2
      ratios).
    - use: what the fabric is used for; source: the citation its figures come from.
    - note: how the figures were derived from the source (what is averaged or adjusted).
    - bend_law: the bending by direction and curvature (physics.bending_law.BendingLaw) of a
      measured fabric, which the model then uses in place of ``bend``; None: one
      stiffness ``bend`` in every direction at every curvature.

    The membrane model's linearised small-strain law (`physics.stretch`: springs along u,
    v and the two diagonals) is sigma_uu = (k_u + k_s) e_uu + k_s e_vv, sigma_vv likewise,
    sigma_uv = k_s gamma (N/m), so a strip pulled along u with its sides free stretches by
    F / (W E_u), E_u = k_u + k_s k_v / (k_v + k_s): see `uniaxial_stiffness`.
    """

    name: str
    stretch: float
    shear: float
    bend: float
    density: float = DEFAULT_DENSITY
    damping: float = DEFAULT_DAMPING
    air_drag: float = DEFAULT_AIR_DRAG
    stretch_warp: float | None = None
    kind: str = "paper"
    use: str = ""
    source: str = ""
    note: str = ""
    bend_law: BendingLaw | None = None

    def __post_init__(self) -> None:
        if self.bend_law is not None and not isinstance(self.bend_law, BendingLaw):
            raise ClothInputError(f"material {self.name!r}: bend_law must be a BendingLaw, "
                                  f"got {self.bend_law!r}")
        if self.stretch_warp is not None and not (
                isinstance(self.stretch_warp, (int, float)) and math.isfinite(self.stretch_warp)
                and self.stretch_warp > 0.0):
            raise ClothInputError(f"material {self.name!r}: stretch_warp must be a positive "
                                  f"number, got {self.stretch_warp!r}")
        for field_name in ("stretch", "shear", "bend", "density", "damping", "air_drag"):
            value = getattr(self, field_name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ClothInputError(
                    f"material {self.name!r}: {field_name} must be a finite number, got {value!r}"
                )
            if value < 0.0:
                raise ClothInputError(
                    f"material {self.name!r}: {field_name} must not be negative, got {value!r}"
                )
        for field_name in ("stretch", "density"):
            if getattr(self, field_name) == 0.0:
                raise ClothInputError(
                    f"material {self.name!r}: {field_name} must be positive, got 0"
                )

    @property
    def stretch_v(self) -> float:
        """Spring stiffness along the warp (material v axis), N/m."""
        return self.stretch if self.stretch_warp is None else self.stretch_warp

    def direction_bend(self, direction: str) -> tuple[float, float]:
        """(k1 N m, k2 N m^2) of M = k1 kappa + k2 kappa^2 for a strip along ``direction``
        ("weft", "warp", "bias"): the bending law's, or (bend, 0) for one stiffness."""
        names = ("weft", "warp", "bias")
        if direction not in names:
            raise ClothInputError(f"direction must be one of {', '.join(names)}, "
                                  f"got {direction!r}")
        if self.bend_law is None:
            return self.bend, 0.0
        i = names.index(direction)
        return self.bend_law.k1[i], self.bend_law.k2[i]

    def bending_length(self, gravity: float = 9.81) -> float:
        """Cantilever bending length (B / (rho g))^(1/3), metres."""
        return (self.bend / (self.density * gravity)) ** (1.0 / 3.0)

    def axis_springs(self, axis: str = "weft") -> tuple[float, float, float]:
        """(along, across, shear) spring stiffnesses, N/m, for a pull along ``axis``
        ("weft": the material u axis, "warp": v)."""
        if axis not in ("weft", "warp"):
            raise ClothInputError(f"axis must be 'weft' or 'warp', got {axis!r}")
        if axis == "weft":
            return self.stretch, self.stretch_v, self.shear
        return self.stretch_v, self.stretch, self.shear

    def uniaxial_stiffness(self, axis: str = "weft") -> float:
        """Force per unit width per unit strain of a strip pulled along ``axis`` ("weft": u,
        "warp": v) with its sides free, N/m (see the class docstring)."""
        along, across, k_s = self.axis_springs(axis)
        return along + (k_s * across / (across + k_s) if across + k_s > 0.0 else 0.0)


PAPER_SOURCE = ("the paper's Table 2 relative stiffnesses on an assumed SI scale "
                "(1000 N/m and 3e-5 N m per unit, 0.2 kg/m^2): not a measured fabric")

PAPER_MATERIALS: dict[str, Material] = {
    name: Material(name, s * STRETCH_UNIT, h * STRETCH_UNIT, b * BEND_UNIT, kind="paper",
                   use="paper Table 4 reproduction", source=PAPER_SOURCE)
    for name, (s, h, b) in PAPER_TABLE2.items()
}


MEASURED_MATERIALS: dict[str, Material] = {
    rec.name: Material(rec.name, kind="measured", use=rec.use, source=WANG_2011,
                       bend_law=BendingLaw(*rec.curvature_law(), cap=CURVATURE_CAP),
                       **fabric_parameters(rec))
    for rec in MEASURED
}


MATERIALS: dict[str, Material] = {**MEASURED_MATERIALS, **PAPER_MATERIALS}


def get_material(name: str, **overrides: float | None) -> Material:
    """Look up a material by name and apply optional overrides (``stretch=...`` etc.).

    Raises ClothInputError naming the unknown material and the known ones, or the field
    whose override is not physical. A ``bend`` override makes the material one stiffness in
    every direction (its bending law, if any, is dropped).
    """
    key = str(name).strip().lower()
    if key not in MATERIALS:
        known = ", ".join(MATERIALS)
        raise ClothInputError(f"unknown material {name!r}; known materials: {known}")
    changes: dict = {k: float(v) for k, v in overrides.items() if v is not None}
    if "bend" in changes:
        changes["bend_law"] = None
    return replace(MATERIALS[key], **changes) if changes else MATERIALS[key]
