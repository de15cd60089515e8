"""The cantilever scene (ASTM D1388 / Peirce): a strip clamped level at a ledge, settled.

The strip lies along +x; its part on the ledge (x <= 0, ``LEDGE_FRACTION`` of the overhang)
is held, the overhang x in (0, l] hangs under gravity (-z) until it is at rest
(`fidelity.settle`). The tip is the mean of the free end's particles; reach and drop are
measured from the ledge edge (x = 0, z = 0) and compared with the exact heavy elastica for
G = rho g l^3 / B (`fidelity.elastica`).

A measured fabric (a material with a bending law) is cut along its weft, warp or bias
(``direction``: the fabric's axes are turned so that direction runs along the strip); the
exact answer is then the elastica with that direction's moment law M = k1 kappa + k2
kappa^2 (B = k1, and the law's k2 and range: `CantileverSpec.bend_k2`, ``curvature_cap``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.elastica import GRAVITY, elastica, gamma_of
from cloth_mg_ros.fidelity.settle import SettleResult, settle_specimen
from cloth_mg_ros.fidelity.strips import MESH_KINDS, strip_hierarchy
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.materials import Material
from cloth_mg_ros.sim.model import ClothModel, ClothState, build_model

LEDGE_FRACTION = 0.15  # held length on the ledge, as a fraction of the overhang
DEFAULT_WIDTH = 0.025  # m: the ASTM D1388 specimen is 25 mm wide
DEFAULT_PARTICLES = 3000
# ASTM D1388 tests a 25 x 200 mm strip; stretch plays no part in the elastica, so the strip
# gets a stiff woven membrane (the ASTM test assumes an inextensible strip).
CANTILEVER_STRETCH = 8000.0  # N/m
CANTILEVER_SHEAR = 4000.0  # N/m
DIRECTIONS = ("weft", "warp", "bias")
# The fabric's weft (u) axis in the strip's plane for a strip cut along each direction
# (the strip runs along +x; the warp v = z x u).
WEFT_OF_DIRECTION = {"weft": (1.0, 0.0, 0.0), "warp": (0.0, -1.0, 0.0),
                     "bias": (math.sqrt(0.5), -math.sqrt(0.5), 0.0)}


@dataclass(frozen=True)
class CantileverSpec:
    """A cantilever test: bend B (N m), density rho (kg/m^2), overhang l (m), width (m),
    mesh kind and orientation (degrees between the lattice's edges and the strip), particles;
    direction: the fabric's axis along the strip; bend_k2 (N m^2) and curvature_cap (1/m):
    the moment law M = bend kappa + bend_k2 kappa^2 up to the cap of a material with a
    bending law (0 and inf: M = B kappa)."""

    bend: float
    density: float
    overhang: float
    width: float = DEFAULT_WIDTH
    orientation: float = 0.0
    mesh: str = "lattice"
    particles: int = DEFAULT_PARTICLES
    seed: int = 0
    direction: str = "weft"
    bend_k2: float = 0.0
    curvature_cap: float = math.inf

    def __post_init__(self) -> None:
        if self.direction not in DIRECTIONS:
            raise ClothInputError(f"cantilever: --direction must be one of "
                                  f"{', '.join(DIRECTIONS)}, got {self.direction!r}")
        if not (math.isfinite(self.bend_k2) and self.curvature_cap > 0.0):
            raise ClothInputError(f"cantilever: the moment law needs a finite k2 and a "
                                  f"positive cap, got {self.bend_k2!r}, {self.curvature_cap!r}")
        for name in ("bend", "density", "overhang", "width"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ClothInputError(f"cantilever: --{name} must be a positive number, "
                                      f"got {value!r}")
        if not math.isfinite(self.orientation):
            raise ClothInputError(f"cantilever: --orientation must be finite, got "
                                  f"{self.orientation!r}")
        if self.mesh not in MESH_KINDS:
            raise ClothInputError(f"cantilever: --mesh must be one of {', '.join(MESH_KINDS)}, "
                                  f"got {self.mesh!r}")

    @property
    def gamma(self) -> float:
        return gamma_of(self.bend, self.density, self.overhang)

    def exact(self):
        """The exact elastica (`fidelity.elastica.Elastica`) of this strip's moment law."""
        if self.bend_k2 == 0.0:
            return elastica(self.gamma)
        return elastica(self.gamma, growth=self.bend_k2 / (self.bend * self.overhang),
                        cap=self.curvature_cap * self.overhang)

    @classmethod
    def of_material(cls, material: Material, direction: str, overhang: float,
                    **kwargs) -> CantileverSpec:
        """The spec of a strip of ``material`` cut along ``direction``: its bend and moment
        law that direction's (`Material.direction_bend`), its density the material's."""
        k1, k2 = material.direction_bend(direction)
        cap = material.bend_law.cap if material.bend_law is not None else math.inf
        return cls(k1, material.density, overhang, direction=direction, bend_k2=k2,
                   curvature_cap=cap, **kwargs)


@dataclass
class CantileverScene:
    """The built scene: hierarchy, model, initial state, and the free end's particles."""

    spec: CantileverSpec
    hierarchy: MeshHierarchy
    model: ClothModel
    state: ClothState
    tip: np.ndarray


def build_cantilever(spec: CantileverSpec, material: Material | None = None
                     ) -> CantileverScene:
    """The strip of ``spec``, with ``material``'s stretch, shear and damping (default: a stiff
    woven membrane) and the spec's density; its bend the spec's, or, for a material with a
    bending law, that law with the fabric's ``spec.direction`` along the strip."""
    base = material or Material("cantilever", CANTILEVER_STRETCH, CANTILEVER_SHEAR, spec.bend)
    if base.bend_law is not None:
        mat = replace(base, density=float(spec.density),
                      name=f"{base.name} ({spec.direction}, rho {spec.density:.3g} kg/m^2)")
    else:
        mat = replace(base, bend=float(spec.bend), density=float(spec.density),
                      name=f"{base.name} (B {spec.bend:.3g} N m, rho {spec.density:.3g} "
                           f"kg/m^2)")
    ledge = LEDGE_FRACTION * spec.overhang
    hier = strip_hierarchy(spec.mesh, -ledge, spec.overhang, spec.width, spec.particles,
                           spec.orientation, cuts=(0.0,), seed=spec.seed)
    rest = np.array(hier.finest.rest)
    eps = 1e-9 * spec.overhang
    held = np.flatnonzero(rest[:, 0] <= eps)
    tip = np.flatnonzero(rest[:, 0] >= spec.overhang - eps)
    model = build_model(hier.finest, mat, pinned=held, gravity=np.array([0.0, 0.0, -GRAVITY]),
                        weft=np.array(WEFT_OF_DIRECTION[spec.direction]), bending="law")
    return CantileverScene(spec, hier, model, ClothState.at_rest(rest), tip)


def natural_period(spec: CantileverSpec) -> float:
    """First bending period of the overhang as a linear cantilever, s (Euler-Bernoulli:
    omega_1 = 1.8751^2 sqrt(B / (rho l^4)))."""
    omega = 1.8751 ** 2 * math.sqrt(spec.bend / (spec.density * spec.overhang ** 4))
    return 2.0 * math.pi / omega


def settle_cantilever(scene: CantileverScene, solver_name: str = "direct",
                      tol: float = 1e-6, max_steps: int = 3000, on_step=None) -> SettleResult:
    """Settle the strip with implicit Euler steps of an eighth of its natural period and
    air drag at about its natural frequency (the test reads a rest shape, not a motion).
    The rest shape is the fixed point of the steps whatever solves them; the default is
    the direct one because a strip this slender with steps this long makes the multigrid
    solves slow (the speed benchmarks are elsewhere)."""
    return settle_specimen(scene.model, scene.state, scene.hierarchy,
                           natural_period(scene.spec), scene.spec.overhang, solver_name, tol,
                           max_steps, on_step=on_step)


def measure(scene: CantileverScene, state: ClothState) -> dict:
    """The summary's "cantilever" block for a settled ``state`` (lengths m, angles degrees):
    the tip (mean of the free end) against the exact elastica, errors in % of l."""
    spec = scene.spec
    x = state.x
    tip = x[scene.tip].mean(axis=0)
    reach, drop = float(tip[0]), float(-tip[2])
    # Tip tangent: the free end's direction from the particles one spacing behind it.
    rest = scene.model.mesh.rest
    spacing = float(np.median(scene.model.edge_rest))
    near = np.flatnonzero(np.abs(rest[:, 0] - (spec.overhang - 2.0 * spacing)) < 0.75 * spacing)
    back = x[near].mean(axis=0) if len(near) else tip
    tangent = tip - back
    exact = spec.exact()
    err = math.hypot(reach - exact.tip_reach * spec.overhang, drop - exact.tip_drop * spec.overhang)
    return {
        "overhang_m": spec.overhang, "bend_nm": spec.bend, "density_kgm2": spec.density,
        "width_m": spec.width, "orientation_deg": spec.orientation, "mesh": spec.mesh,
        "direction": spec.direction, "bend_k2_nm2": spec.bend_k2,
        "particles": int(scene.model.n), "gamma": spec.gamma,
        "tip_reach_m": reach, "tip_drop_m": drop,
        "chord_angle_deg": math.degrees(math.atan2(drop, reach)),
        "tip_angle_deg": math.degrees(math.atan2(-tangent[2], tangent[0])),
        "exact": {"tip_reach_m": exact.tip_reach * spec.overhang,
                  "tip_drop_m": exact.tip_drop * spec.overhang,
                  "chord_angle_deg": exact.chord_angle_deg,
                  "tip_angle_deg": exact.tip_angle_deg},
        "tip_error_pct_of_overhang": 100.0 * err / spec.overhang,
    }


def centre_profile(scene: CantileverScene, state: ClothState, bins: int = 40) -> np.ndarray:
    """(k, 2) the overhang's centre line (reach, drop) in m: particle positions averaged in
    bins of rest x, for charts against the exact curve."""
    rest = scene.model.mesh.rest
    over = rest[:, 0] >= 0.0
    edges = np.linspace(0.0, scene.spec.overhang, bins + 1)
    idx = np.clip(np.digitize(rest[over, 0], edges) - 1, 0, bins - 1)
    x = state.x[over]
    out = np.zeros((bins, 2))
    count = np.bincount(idx, minlength=bins)
    out[:, 0] = np.bincount(idx, x[:, 0], minlength=bins)
    out[:, 1] = -np.bincount(idx, x[:, 2], minlength=bins)
    keep = count > 0
    return np.concatenate([[[0.0, 0.0]], out[keep] / count[keep, None]])


def run_cantilever(spec: CantileverSpec, material: Material | None = None,
                   solver_name: str = "direct", tol: float = 1e-6
                   ) -> tuple[dict, CantileverScene, SettleResult]:
    """Build, settle and measure one cantilever; the block also carries the settle's figures."""
    scene = build_cantilever(spec, material)
    result = settle_cantilever(scene, solver_name, tol)
    block = measure(scene, result.state)
    block["settled"] = bool(result.settled)
    block["settle"] = result.as_dict()
    return block, scene, result
