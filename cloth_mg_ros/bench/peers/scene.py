"""The drape scene every peer receives (`DrapeSpec`, `build_spec`) and our material mapped
onto each peer's parameters.

The material is mapped onto each engine's parameters by matching the small-strain energy
(`peer_parameters`); where an engine's model has no counterpart the mapping is approximate
and says so in ``meta.notes``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cloth_mg_ros.bench.peers.options import DEFAULT_DT, DEFAULT_STEPS
from cloth_mg_ros.collision.colliders import PlaneCollider, SphereCollider
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.sheets import build_scene


@dataclass(frozen=True, eq=False)
class DrapeSpec:
    """The drape scene as every engine receives it. SI units, z up.

    rest: (n, 3) initial positions, m (the flat sheet; also its rest shape).
    faces: (t, 3) int64 triangles, counter-clockwise seen from +z.
    areas: (t,) rest triangle areas, m^2. mass: (n,) lumped particle masses, kg.
    edges: (e, 2) int64 mesh edges; edge_rest: (e,) their rest lengths, m.
    material: the `Material` (stretch, shear N/m; bend N m; density kg/m^2; damping s;
    air_drag 1/s). gravity: (3,) m/s^2. sphere_centre: (3,) m; sphere_radius m;
    sphere_friction, floor_friction (Coulomb coefficients, the floor is z = 0); thickness: contact
    distance, m. dt: step, s; steps: number of steps.
    """

    rest: np.ndarray
    faces: np.ndarray
    areas: np.ndarray
    mass: np.ndarray
    edges: np.ndarray
    edge_rest: np.ndarray
    material: object
    gravity: np.ndarray
    sphere_centre: np.ndarray
    sphere_radius: float
    sphere_friction: float
    floor_friction: float
    thickness: float
    dt: float
    steps: int
    particles_requested: int = 0
    scene: object = field(default=None, repr=False, compare=False)

    @property
    def n(self) -> int:
        return len(self.rest)

    @property
    def sphere_top(self) -> float:
        """Height of the sphere's top, m."""
        return float(self.sphere_centre[2] + self.sphere_radius)


def build_spec(particles: int, material: str = "cotton", dt: float = DEFAULT_DT,
               steps: int = DEFAULT_STEPS) -> DrapeSpec:
    """The drape scene of ``cloth-mg run --scene drape --particles N`` as plain arrays."""
    mat = get_material(material)
    scene = build_scene("drape", particles, mat)
    model = scene.model
    sphere = next(c for c in model.colliders if isinstance(c, SphereCollider))
    floor = next(c for c in model.colliders if isinstance(c, PlaneCollider))
    if not (np.allclose(floor.normal, [0.0, 0.0, 1.0]) and abs(floor.point[2]) < 1e-12):
        raise ClothInputError("bench peers: the drape floor is expected at z = 0, facing up")
    return DrapeSpec(
        rest=np.array(scene.state.x, dtype=np.float64), faces=np.array(model.mesh.faces),
        areas=np.array(model.mesh.face_areas), mass=np.array(model.mass),
        edges=np.array(model.mesh.edges), edge_rest=np.array(model.edge_rest), material=mat,
        gravity=np.array(model.gravity, dtype=np.float64),
        sphere_centre=np.array(sphere.centre), sphere_radius=float(sphere.radius),
        sphere_friction=float(sphere.friction), floor_friction=float(floor.friction),
        thickness=float(model.thickness), dt=float(dt), steps=int(steps),
        particles_requested=int(particles), scene=scene)


# -- mapping the material -----------------------------------------------------------------
def membrane_lame(material) -> tuple[float, float]:
    """Lamé parameters (mu, lambda), N/m, of the isotropic membrane closest to ours.

    At small strain our energy density is stretch/2 (e_uu^2 + e_vv^2) + shear/2 (e_uu +
    e_vv)^2 + 2 shear e_uv^2 (the four Baraff-Witkin measures, stretch on weft and warp, shear
    on the two diagonals). The isotropic mu (e_uu^2 + e_vv^2 + 2 e_uv^2) + lambda/2 (e_uu +
    e_vv)^2 matches it with mu = shear and lambda = stretch - shear, exactly when stretch = 2
    shear (silk, wool, cotton, denim); otherwise the weft/warp coupling differs.
    """
    mu = float(material.shear)
    return mu, max(float(material.stretch) - mu, 0.0)


def hinge_stiffness(rest: np.ndarray, hinges: np.ndarray, bend: float) -> np.ndarray:
    """Dihedral-angle stiffness per hinge, (k,) in N, for an energy k L theta^2 / 2.

    hinges: (k, 4) vertex indices [tip0, tip1, edge0, edge1] (Newton's edge_indices order; a
    tip of -1 marks a boundary edge, which gets 0). Our bending energy of a hinge is
    bend L^2 theta^2 / (2 (A0 + A1)) at small angles (L the edge, A0, A1 the rest areas of
    its two triangles), so k = bend L / (A0 + A1).
    """
    hinges = np.asarray(hinges, dtype=np.int64)
    inner = (hinges[:, 0] >= 0) & (hinges[:, 1] >= 0)
    h = np.where(hinges < 0, 0, hinges)
    e0, e1 = rest[h[:, 2]], rest[h[:, 3]]
    length = np.linalg.norm(e1 - e0, axis=1)
    a0 = 0.5 * np.linalg.norm(np.cross(e0 - rest[h[:, 0]], e1 - rest[h[:, 0]]), axis=1)
    a1 = 0.5 * np.linalg.norm(np.cross(e0 - rest[h[:, 1]], e1 - rest[h[:, 1]]), axis=1)
    out = np.zeros(len(hinges))
    ok = inner & (a0 + a1 > 0.0)
    out[ok] = bend * length[ok] / (a0[ok] + a1[ok])
    return out


def peer_parameters(material) -> dict:
    """Each peer's material parameters for ``material`` (SI), with how exact each is.

    Returns {"vbd": {...}, "style3d": {...}, "mujoco": {...}}; every entry holds the values
    handed to the engine and a "notes" list naming what is approximate.
    """
    mu, lam = membrane_lame(material)
    exact_iso = math.isclose(material.stretch, 2.0 * material.shear, rel_tol=1e-9)
    iso_note = ("membrane: isotropic Lamé mu = shear, lambda = stretch - shear matches our "
                "small-strain energy exactly (stretch = 2 shear)" if exact_iso else
                f"membrane: stretch {material.stretch:g} != 2 x shear {material.shear:g}: the "
                "isotropic fit keeps the weft/warp and shear terms, not their coupling "
                "(approximate)")
    # Plane-stress Young's modulus x thickness and Poisson ratio of that membrane.
    nu = lam / (lam + 2.0 * mu)
    young_t = 4.0 * mu * (lam + mu) / (lam + 2.0 * mu)
    return {"vbd": _vbd_parameters(material, mu, lam, iso_note),
            "style3d": _style3d_parameters(material, nu),
            "mujoco": _mujoco_parameters(material, nu, young_t, iso_note)}


def _vbd_parameters(material, mu: float, lam: float, iso_note: str) -> dict:
    """Newton VBD's membrane (Lamé mu, lambda), hinge bending and damping, with notes."""
    beta = float(material.damping)
    return {
        "tri_ke": mu, "tri_ka": lam, "tri_kd": beta * mu / 2.0,
        "edge_ke": "bend L / (A0 + A1) per hinge", "edge_kd": "damping x edge_ke",
        "notes": [
            iso_note + "; VBD's stable Neo-Hookean membrane (tri_ke = mu, tri_ka = lambda) "
            "agrees with it at small strain, not at large",
            ("bending: VBD's dihedral-angle hinge k L theta^2 / 2 with k = bend L / (A0 + A1) per "
            "hinge equals our quadratic bending at small angles"),
            (f"damping: VBD damps the rate of the metric F^T F: tri_kd = damping x mu / 2 = "
            f"{beta * mu / 2.0:g} N s/m matches our Rayleigh damping's shear part, not its "
            "area part (approximate); hinge damping = damping x k"),
            f"air drag {material.air_drag:g} 1/s: no per-particle linear drag in VBD (omitted)",
        ],
    }


def _style3d_parameters(material, nu: float) -> dict:
    """Newton Style3D's Baraff-Witkin stiffnesses and Bergou bending, with notes (nu: our
    membrane's Poisson ratio, which Style3D's lacks)."""
    return {
        "tri_aniso_ke": (material.stretch + material.shear, material.stretch + material.shear,
                         material.shear),
        "edge_ke": material.bend / 3.0,
        "notes": [
            ("membrane: Style3D's Baraff-Witkin weft/warp/shear energy with ku = kv = stretch + "
            "shear (the weft and warp diagonal of our small-strain energy) and ks = shear; it "
            f"has no weft-warp coupling (its Poisson ratio is 0, ours {nu:.2f}): approximate"),
            ("bending: Style3D's Bergou quadratic model with the 3 / (A0 + A1) normalisation, "
            "edge_ke = bend / 3, equals ours exactly"),
            ("damping: Style3D has no elastic damping parameter; it scales velocities by 0.998 "
            "per substep and its implicit Euler damps numerically (our Rayleigh damping and "
            "air drag are not mapped)"),
        ],
    }


def _mujoco_parameters(material, nu: float, young_t: float, iso_note: str) -> dict:
    """MuJoCo flex's Young's modulus, Poisson ratio and shell thickness (from the membrane's
    E t and our bending stiffness), and damping, with notes."""
    beta = float(material.damping)
    # Kirchhoff plate: D = E t^3 / (12 (1 - nu^2)) = bend, so t from E t and D.
    thickness = math.sqrt(12.0 * (1.0 - nu * nu) * material.bend / young_t) \
        if material.bend > 0.0 else 1e-4
    return {
        "young": young_t / thickness, "poisson": nu, "thickness": thickness, "damping": beta,
        "notes": [
            iso_note + "; MuJoCo's 2D flex StVK membrane (Green strain, plane stress) with "
            f"E t = {young_t:g} N/m and Poisson {nu:.3f} agrees with it at small strain",
            (f"bending: E t^3 / (12 (1 - nu^2)) = bend with shell thickness {thickness:.4g} m "
            f"(E = {young_t / thickness:.4g} Pa); MuJoCo's hinge model is normalised to the "
            "Kirchhoff plate energy, as ours: equal at small angles"),
            (f"damping: Rayleigh, elasticity damping = {beta:g} s as ours; air drag "
            f"{material.air_drag:g} 1/s as slide-joint damping air_drag x particle mass"),
            ("masses: flexcomp spreads mass evenly; each point's body gets our lumped mass "
            "before compiling (mjSpec)"),
        ],
    }
