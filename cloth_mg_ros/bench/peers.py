"""`cloth-mg bench peers`: the drape scene in this solver, in Newton and in MuJoCo, side by side.

One scene, handed to every engine: the ``drape`` sheet of `scenes.build_scene` (a square sheet
of about ``particles`` particles, 1 m wide, released flat 10 cm above a sphere of radius
0.25 m centred 0.5 m above a floor), the same triangles, the same lumped masses (areal
density x one third of each adjacent rest triangle), gravity -9.81 m/s^2 along z, the sphere
and floor friction of the scene (0.3 and 0.5), a contact distance of the model's thickness
(5 mm) and the same step ``dt`` and duration (``steps`` x ``dt``). The engines:

* ``ours:mpcg``, ``ours:mg``: this project (BDF2, one linearised solve per step, tol 1e-4).
* ``newton:style3d``, ``newton:vbd``: Newton's SolverStyle3D (projective-dynamics Hessian
  with PCG) and SolverVBD (vertex block descent) on the Warp device ``cpu``, each step of
  ``dt`` split into the engine's substeps; the sphere and floor are static Newton shapes.
* ``mujoco:newton``, ``mujoco:cg``: a MuJoCo flex (``flexcomp type="direct"``, one slide-jointed
  body per particle) with the ``discrete`` integrator (implicit in position, so one step of
  ``dt`` is stable) and MuJoCo's own Newton or CG constraint solver.

The material is mapped onto each engine's parameters by matching the small-strain energy
(`peer_parameters`); where an engine's model has no counterpart the mapping is approximate
and says so in ``meta.notes``.

Per run (one engine, one size): ``ms_per_step``, the median wall time of one ``dt`` step
(substeps included) over the steps after the first ``WARMUP_STEPS``; ``first_step_ms`` and
``setup_s`` (model build) reported apart; each engine is first run for a few steps at
``WARMUP_PARTICLES`` particles so that JIT compilation (numba, Warp kernels) or loading its
cache stays out of the timings (``meta.warmup_s``). Sanity figures, read from the engine's
positions after every step (outside the timed region): ``finite``, ``mean_height_m``,
``sag_m`` (how far the final mean height is below the sphere's top), ``hang_m`` (how far the
lowest particle is below it), ``max_penetration_m`` and ``final_penetration_m`` (deepest any
particle went inside the sphere or below the floor, any step and at the end), ``max_stretch``
and ``peak_stretch`` (longest edge over its rest length at the end and at any step, with
``peak_stretch_step``), ``mass_kg`` (the engine's own masses summed) and ``draped`` (finite and
``sag_m`` > DRAPED_SAG). ``cpu_ms_per_step`` (median process CPU time of a step) and
``cpu_per_wall`` (how many cores the engine kept busy) tell contention on a shared machine
from an engine's own cost.

A missing engine package is not an error: its rows are recorded as skipped with the install
command in the reason. Set OPENBLAS_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import copy
import datetime as _dt
import math
import os
import platform
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cloth_mg_ros.errors import ClothInputError

# engine: its solvers, in the order the benchmark runs them.
ENGINES: dict[str, tuple[str, ...]] = {
    "ours": ("mpcg", "mg"),
    "newton": ("style3d", "vbd"),
    "mujoco": ("newton", "cg"),
}
ENGINE_MODULES = {"ours": (), "newton": ("warp", "newton"), "mujoco": ("mujoco",)}
INSTALL_HINT = "pip install -e .[peers]"
DEFAULT_PARTICLES = (1200, 2400, 4500)
DEFAULT_STEPS = 120
DEFAULT_DT = 1.0 / 60.0
DEFAULT_TOL = 1e-4  # relative residual of our solves, as in the other benchmarks
WARMUP_STEPS = 2  # first steps of every run left out of the median
WARMUP_PARTICLES = 300
DRAPED_SAG = 0.1  # m: a sheet lying flat on the sphere has sag ~0; a draped one ~0.2

# Per-engine settings, overridable with --set solver.key=value. Newton's are the ones its
# cloth examples use (example_cloth_hanging: VBD 10 substeps x 10 iterations, Style3D 2
# substeps x 10 iterations of 10 PCG iterations); MuJoCo's are its defaults.
DEFAULT_SETTINGS: dict[str, dict[str, float]] = {
    "ours:mpcg": {"tol": DEFAULT_TOL},
    "ours:mg": {"tol": DEFAULT_TOL},
    "newton:style3d": {"substeps": 2, "iterations": 10, "linear_iterations": 10,
                       "contact_ke": 1.0e4, "contact_kd": 10.0},
    "newton:vbd": {"substeps": 10, "iterations": 10, "contact_ke": 1.0e4, "contact_kd": 10.0},
    "mujoco:newton": {"substeps": 1, "iterations": 100, "tolerance": 1e-8},
    "mujoco:cg": {"substeps": 1, "iterations": 100, "tolerance": 1e-8},
}
INTEGER_SETTINGS = ("substeps", "iterations", "linear_iterations")


# -- the scene ----------------------------------------------------------------------------
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
    from cloth_mg_ros.collision.colliders import PlaneCollider, SphereCollider
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.scenes import build_scene

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
    beta = float(material.damping)
    exact_iso = math.isclose(material.stretch, 2.0 * material.shear, rel_tol=1e-9)
    iso_note = ("membrane: isotropic Lamé mu = shear, lambda = stretch - shear matches our "
                "small-strain energy exactly (stretch = 2 shear)" if exact_iso else
                f"membrane: stretch {material.stretch:g} != 2 x shear {material.shear:g}: the "
                "isotropic fit keeps the weft/warp and shear terms, not their coupling "
                "(approximate)")
    # Plane-stress Young's modulus x thickness and Poisson ratio of that membrane.
    nu = lam / (lam + 2.0 * mu)
    young_t = 4.0 * mu * (lam + mu) / (lam + 2.0 * mu)
    # Kirchhoff plate: D = E t^3 / (12 (1 - nu^2)) = bend, so t from E t and D.
    thickness = math.sqrt(12.0 * (1.0 - nu * nu) * material.bend / young_t) \
        if material.bend > 0.0 else 1e-4
    vbd = {
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
    style3d = {
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
    mujoco = {
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
    return {"vbd": vbd, "style3d": style3d, "mujoco": mujoco}


def mujoco_xml(spec: DrapeSpec, solver: str = "newton", substeps: int = 1,
               iterations: int = 100, tolerance: float = 1e-8) -> str:
    """MJCF of the drape scene: a floor, the sphere and a 2D flexcomp of spec's sheet.

    Contact: the flex radius is the contact distance; MuJoCo takes the larger friction of a
    pair, so the flex gets the sphere's (the smaller) and each geom its own. Self-collision
    is off, as in our drape scene. The flexcomp's total mass is spec's; the per-body masses
    are set after compiling (`_MujocoEngine`)."""
    params = peer_parameters(spec.material)["mujoco"]
    pts = " ".join(f"{v:.9g}" for v in spec.rest.ravel())
    els = " ".join(str(int(i)) for i in spec.faces.ravel())
    cx, cy, cz = (f"{v:.9g}" for v in spec.sphere_centre)
    gx, gy, gz = (f"{v:.9g}" for v in spec.gravity)
    mu_s, mu_f = spec.sphere_friction, spec.floor_friction
    mu_flex = min(mu_s, mu_f)
    solver_name = {"newton": "Newton", "cg": "CG"}[solver]
    return f"""<mujoco model="cloth_mg_ros drape">
  <option timestep="{spec.dt / substeps:.12g}" integrator="discrete" solver="{solver_name}"
          iterations="{int(iterations)}" tolerance="{tolerance:.6g}" gravity="{gx} {gy} {gz}"/>
  <worldbody>
    <geom name="floor" type="plane" size="3 3 0.1" friction="{mu_f:g} 0.005 0.0001"/>
    <geom name="sphere" type="sphere" size="{spec.sphere_radius:.9g}" pos="{cx} {cy} {cz}"
          friction="{mu_s:g} 0.005 0.0001"/>
    <flexcomp name="cloth" type="direct" dim="2" point="{pts}" element="{els}"
              mass="{float(spec.mass.sum()):.9g}" radius="{spec.thickness:.9g}">
      <contact condim="3" friction="{mu_flex:g} 0.005 0.0001" selfcollide="none"/>
      <elasticity young="{params['young']:.9g}" poisson="{params['poisson']:.9g}"
                  thickness="{params['thickness']:.9g}" damping="{params['damping']:.9g}"
                  elastic2d="{'both' if spec.material.bend > 0.0 else 'stretch'}"/>
      <edge equality="false"/>
    </flexcomp>
  </worldbody>
</mujoco>
"""


# -- engines ------------------------------------------------------------------------------
class _OursEngine:
    """This project's simulator, stepping with assemble / solve / finish (the per-step energy
    diagnostics of `Simulator.step` are left out, as they are for the peers)."""

    def __init__(self, spec: DrapeSpec, solver: str, settings: dict):
        from cloth_mg_ros.physics.integrator import Simulator
        from cloth_mg_ros.physics.model import ClothState
        from cloth_mg_ros.solvers import make_solver

        scene = spec.scene
        lin = make_solver(solver, tol=float(settings["tol"]), hierarchy=scene.hierarchy,
                          wing_hess=scene.model.wing_hess)
        self.sim = Simulator(scene.model, ClothState.at_rest(spec.rest), lin, dt=spec.dt,
                             scheme="bdf2")
        self.mass_kg = float(scene.model.mass.sum())
        self.iterations: list[int] = []

    def step(self) -> None:
        from cloth_mg_ros.physics.integrator import assemble_step, finish_step

        sim = self.sim
        system = assemble_step(sim.model, sim.state, sim.dt, sim.scheme)
        result = sim.solver.solve(system.system, system.rhs, system.x0, system.fixed)
        sim.state, _, _ = finish_step(sim.model, sim.state, system, result.x, sim.dt)
        self.iterations.append(int(result.iterations))

    def positions(self) -> np.ndarray:
        return self.sim.state.x


class _NewtonEngine:
    """Newton (Warp, device "cpu"): the sheet as a cloth mesh, the sphere and the floor as
    static shapes, SolverStyle3D or SolverVBD, ``substeps`` solver steps per ``dt``."""

    def __init__(self, spec: DrapeSpec, solver: str, settings: dict):
        import warp as wp

        # Warp's per-module "load ... took" lines would flood the benchmark's output.
        wp.config.log_level = getattr(wp, "LOG_WARNING", 30)
        wp.init()
        import newton
        from newton.solvers import style3d

        self.wp, self.solver_name = wp, solver
        params = peer_parameters(spec.material)
        mat = spec.material
        builder = newton.ModelBuilder(up_axis=newton.Axis.Z,
                                      gravity=tuple(float(g) for g in spec.gravity))
        if solver == "style3d":
            newton.solvers.SolverStyle3D.register_custom_attributes(builder)
        # Newton mixes the particle and shape sides of a contact: stiffness by their mean
        # (VBD) or the particle side alone (Style3D), friction by the geometric mean. Both
        # sides get the same stiffness and the particle side friction 1, so each shape's
        # friction is the square of the scene's.
        ke, kd = float(settings["contact_ke"]), float(settings["contact_kd"])
        sphere_cfg = builder.default_shape_cfg.copy()
        sphere_cfg.ke, sphere_cfg.kd, sphere_cfg.mu = ke, kd, spec.sphere_friction ** 2
        builder.add_shape_sphere(
            -1, xform=wp.transform(wp.vec3(*spec.sphere_centre.tolist()), wp.quat_identity()),
            radius=spec.sphere_radius, cfg=sphere_cfg)
        floor_cfg = builder.default_shape_cfg.copy()
        floor_cfg.ke, floor_cfg.kd, floor_cfg.mu = ke, kd, spec.floor_friction ** 2
        builder.add_ground_plane(cfg=floor_cfg)
        common = {"pos": wp.vec3(0.0, 0.0, 0.0), "rot": wp.quat_identity(),
                      "vel": wp.vec3(0.0, 0.0, 0.0), "vertices": spec.rest.tolist(),
                      "indices": spec.faces.ravel().tolist(), "density": float(mat.density),
                      "particle_radius": spec.thickness}
        if solver == "style3d":
            p = params["style3d"]
            builder.default_edge_ke = p["edge_ke"]  # isotropic: no edge_aniso_ke
            style3d.add_cloth_mesh(builder, **common, tri_aniso_ke=wp.vec3(*p["tri_aniso_ke"]),
                                   panel_verts=spec.rest[:, :2].tolist())
        else:
            p = params["vbd"]
            builder.add_cloth_mesh(**common, scale=1.0, tri_ke=p["tri_ke"], tri_ka=p["tri_ka"],
                                   tri_kd=p["tri_kd"], edge_ke=0.0, edge_kd=0.0)
            builder.color(include_bending=True)
        model = builder.finalize(device="cpu")
        if model.particle_count != spec.n:
            raise RuntimeError(f"Newton built {model.particle_count} particles, expected {spec.n}")
        model.soft_contact_ke, model.soft_contact_kd, model.soft_contact_mu = ke, kd, 1.0
        if solver == "vbd":
            # Per-hinge bending stiffness (Newton's edge_ke is one value per mesh).
            k = hinge_stiffness(spec.rest, model.edge_indices.numpy(), float(mat.bend))
            props = model.edge_bending_properties.numpy()
            props[:, 0], props[:, 1] = k, float(mat.damping) * k
            model.edge_bending_properties.assign(props)
            self.solver = newton.solvers.SolverVBD(model, iterations=int(settings["iterations"]))
        else:
            cfg = newton.solvers.SolverStyle3D.Config(
                iterations=int(settings["iterations"]),
                linear_iterations=int(settings["linear_iterations"]))
            self.solver = newton.solvers.SolverStyle3D(model, config=cfg)
        self.model = model
        self.state0, self.state1 = model.state(), model.state()
        self.control = model.control()
        self.pipeline = newton.CollisionPipeline(model)
        self.contacts = self.pipeline.contacts()
        self.substeps = int(settings["substeps"])
        self.h = spec.dt / self.substeps
        self.mass_kg = float(model.particle_mass.numpy().astype(np.float64).sum())

    def step(self) -> None:
        for _ in range(self.substeps):
            self.state0.clear_forces()
            self.pipeline.collide(self.state0, self.contacts)
            self.solver.step(self.state0, self.state1, self.control, self.contacts, self.h)
            self.state0, self.state1 = self.state1, self.state0
        self.wp.synchronize()

    def positions(self) -> np.ndarray:
        return self.state0.particle_q.numpy().astype(np.float64)


# The last compiled MuJoCo drape model: (spec, substeps, MjModel, compile seconds). Compiling
# a 2D flex with bending grows steeply with its size (minutes at 4500 particles), so both
# MuJoCo solvers of one size share one compile and differ only in mjOption.
_MJ_COMPILED: dict = {}


def _compiled_mujoco(spec: DrapeSpec, substeps: int):
    """A fresh copy of spec's compiled MuJoCo model, its compile time (s) and whether it was
    reused from the previous run."""
    import mujoco

    hit = _MJ_COMPILED.get("last")
    if hit is not None and hit[0] is spec and hit[1] == substeps:
        return copy.copy(hit[2]), hit[3], True
    t0 = time.perf_counter()
    mjspec = mujoco.MjSpec.from_string(mujoco_xml(spec, "newton", substeps))
    # flexcomp gives every point's body the same mass; set our lumped masses before compiling
    # (after it, mj_setConst would have to redo the flex's costly constants).
    bodies = {b.name: b for b in mjspec.bodies}
    for i, mass in enumerate(spec.mass):
        bodies[f"cloth_{i}"].mass = float(mass)
    model = mjspec.compile()
    seconds = time.perf_counter() - t0
    _MJ_COMPILED["last"] = (spec, substeps, model, seconds)
    return copy.copy(model), seconds, False


class _MujocoEngine:
    """MuJoCo: `mujoco_xml`'s flex, body masses set to ours, air drag as slide-joint damping,
    ``substeps`` mj_step calls per ``dt``."""

    def __init__(self, spec: DrapeSpec, solver: str, settings: dict):
        import mujoco

        self.mj = mujoco
        self.substeps = int(settings["substeps"])
        m, compile_s, reused = _compiled_mujoco(spec, self.substeps)
        m.opt.solver = {"newton": mujoco.mjtSolver.mjSOL_NEWTON,
                        "cg": mujoco.mjtSolver.mjSOL_CG}[solver]
        m.opt.iterations = int(settings["iterations"])
        m.opt.tolerance = float(settings["tolerance"])
        self.extra = {"compile_s": compile_s, "compile_reused": reused}
        start, count = int(m.flex_vertadr[0]), int(m.flex_vertnum[0])
        if count != spec.n:
            raise RuntimeError(f"MuJoCo built {count} flex vertices, expected {spec.n}")
        bodies = m.flex_vertbodyid[start:start + count]
        if np.any(m.body_dofnum[bodies] != 3):
            raise RuntimeError("MuJoCo flexcomp bodies are expected to have 3 slide joints")
        if not np.allclose(m.body_mass[bodies], spec.mass, rtol=1e-9, atol=0.0):
            raise RuntimeError("MuJoCo flex bodies do not carry the lumped particle masses")
        # Joint damping is a plain parameter (no derived constants): air drag after compiling.
        dofs = m.body_dofadr[bodies][:, None] + np.arange(3)[None, :]
        m.dof_damping[dofs.ravel()] = np.repeat(spec.material.air_drag * spec.mass, 3)
        d = mujoco.MjData(m)
        # Particle i's position is its body's rest point plus its three slide joints
        # (world x, y, z); checked once against MuJoCo's own vertex positions.
        self.qadr = m.jnt_qposadr[m.body_jntadr[bodies]][:, None] + np.arange(3)[None, :]
        self.origin = np.array(m.body_pos[bodies], dtype=np.float64)
        mujoco.mj_forward(m, d)
        if not np.allclose(self.positions_of(d), d.flexvert_xpos[start:start + count],
                           atol=1e-9):
            raise RuntimeError("MuJoCo flex vertices do not follow their slide joints")
        self.m, self.d = m, d
        self.mass_kg = float(m.body_mass[bodies].sum())

    def positions_of(self, d) -> np.ndarray:
        return self.origin + d.qpos[self.qadr]

    def step(self) -> None:
        for _ in range(self.substeps):
            self.mj.mj_step(self.m, self.d)

    def positions(self) -> np.ndarray:
        return self.positions_of(self.d)


ENGINE_CLASSES = {"ours": _OursEngine, "newton": _NewtonEngine, "mujoco": _MujocoEngine}


# -- options ------------------------------------------------------------------------------
def parse_engines(text: str | list) -> list[str]:
    """'ours,newton:vbd' -> ['ours:mpcg', 'ours:mg', 'newton:vbd']; 'all' -> every one.

    ClothInputError names an unknown engine or solver, or one listed twice."""
    items = text if isinstance(text, (list, tuple)) else str(text).split(",")
    out: list[str] = []
    for raw in items:
        item = str(raw).strip().lower()
        if not item:
            continue
        if item == "all":
            out += [f"{e}:{s}" for e, ss in ENGINES.items() for s in ss]
            continue
        engine, _, solver = item.partition(":")
        if engine not in ENGINES:
            raise ClothInputError(f"--engines: unknown engine {engine!r} (choose from "
                                  f"{', '.join(ENGINES)}, or engine:solver, or all)")
        if solver and solver not in ENGINES[engine]:
            raise ClothInputError(f"--engines: {engine} has no solver {solver!r} (choose from "
                                  f"{', '.join(ENGINES[engine])})")
        out += [f"{engine}:{s}" for s in ((solver,) if solver else ENGINES[engine])]
    if not out:
        raise ClothInputError("--engines must list at least one engine")
    dupes = sorted({e for e in out if out.count(e) > 1})
    if dupes:
        raise ClothInputError(f"--engines lists {', '.join(dupes)} twice")
    return out


def parse_settings(items: list[str] | None) -> dict[str, dict[str, float]]:
    """--set values 'newton:vbd.iterations=20' -> {'newton:vbd': {'iterations': 20}}.

    ClothInputError names an unknown run or key, or a value that is not a positive number
    (a positive integer for substeps and iterations)."""
    out: dict[str, dict[str, float]] = {}
    for item in items or []:
        key, eq, value = str(item).partition("=")
        label, dot, name = key.strip().lower().rpartition(".")
        if not eq or not dot:
            raise ClothInputError(f"--set {item!r}: expected ENGINE:SOLVER.KEY=VALUE, e.g. "
                                  f"newton:vbd.iterations=20")
        if label not in DEFAULT_SETTINGS:
            raise ClothInputError(f"--set {item!r}: unknown run {label!r} (choose from "
                                  f"{', '.join(DEFAULT_SETTINGS)})")
        if name not in DEFAULT_SETTINGS[label]:
            raise ClothInputError(f"--set {item!r}: {label} has no setting {name!r} (it has "
                                  f"{', '.join(DEFAULT_SETTINGS[label])})")
        try:
            number = float(value)
        except ValueError:
            raise ClothInputError(f"--set {item!r}: {value!r} is not a number") from None
        if not (math.isfinite(number) and number > 0.0):
            raise ClothInputError(f"--set {item!r}: the value must be positive")
        if name in INTEGER_SETTINGS:
            if number != int(number):
                raise ClothInputError(f"--set {item!r}: {name} must be a whole number")
            number = int(number)
        out.setdefault(label, {})[name] = number
    return out


def validate_peers_args(particles: list, engines: list, steps: int, dt: float,
                        material: str) -> None:
    """Check every option before any work; one ClothInputError lists all the problems."""
    from cloth_mg_ros.mesh.generators import MIN_PARTICLES
    from cloth_mg_ros.physics.materials import MATERIALS

    problems = []
    if not particles:
        problems.append("--particles must list at least one count")
    for p in particles:
        if isinstance(p, bool) or not isinstance(p, (int, np.integer)) or p < MIN_PARTICLES:
            problems.append(f"--particles must be integers >= {MIN_PARTICLES}, got {p!r}")
    if len(set(particles)) != len(particles):
        problems.append(f"--particles lists a count twice: {particles}")
    known = {f"{e}:{s}" for e, ss in ENGINES.items() for s in ss}
    bad = [e for e in engines if e not in known]
    if bad or not engines:
        problems.append(f"--engines: unknown {', '.join(map(repr, bad)) or 'empty list'}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps <= WARMUP_STEPS:
        problems.append(f"--steps must be an integer > {WARMUP_STEPS} (the first "
                        f"{WARMUP_STEPS} are not timed), got {steps!r}")
    if not (isinstance(dt, (int, float)) and not isinstance(dt, bool) and math.isfinite(dt)
            and 0.0 < dt <= 0.1):
        problems.append(f"--dt must be a step in (0, 0.1] seconds, got {dt!r}")
    if str(material).strip().lower() not in MATERIALS:
        problems.append(f"unknown material {material!r} (choose from {', '.join(MATERIALS)})")
    if problems:
        raise ClothInputError("bench peers: " + "; ".join(problems))


# -- running ------------------------------------------------------------------------------
def missing_modules(engine: str) -> list[str]:
    """The Python modules ``engine`` needs that cannot be found (not imported here)."""
    import importlib.util

    return [m for m in ENGINE_MODULES[engine] if importlib.util.find_spec(m) is None]


def _sanity(spec: DrapeSpec, x: np.ndarray) -> tuple[float, float]:
    """(deepest penetration into the sphere or below the floor, m >= 0; longest edge over its
    rest length) of positions x (n, 3)."""
    inside = spec.sphere_radius - np.linalg.norm(x - spec.sphere_centre, axis=1)
    depth = max(float(np.max(inside, initial=0.0)), float(np.max(-x[:, 2], initial=0.0)), 0.0)
    e = spec.edges
    stretch = float(np.max(np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1) / spec.edge_rest))
    return depth, stretch


def run_engine(spec: DrapeSpec, label: str, settings: dict | None = None) -> dict:
    """Build ``label`` ('engine:solver') on spec's scene, step it spec.steps times, time every
    step and return the run's row (see the module docstring)."""
    engine, solver = label.split(":")
    conf = dict(DEFAULT_SETTINGS[label], **(settings or {}))
    t0 = time.perf_counter()
    eng = ENGINE_CLASSES[engine](spec, solver, conf)
    setup_s = time.perf_counter() - t0
    times: list[float] = []
    cpu: list[float] = []
    depth, peak, peak_step, nan_at = 0.0, 1.0, 0, None
    x = eng.positions()
    for k in range(spec.steps):
        cs, ts = time.process_time(), time.perf_counter()
        eng.step()
        times.append(time.perf_counter() - ts)
        cpu.append(time.process_time() - cs)
        x = np.asarray(eng.positions(), dtype=np.float64)
        if not np.all(np.isfinite(x)):
            nan_at = k + 1
            break
        d, s = _sanity(spec, x)
        depth = max(depth, d)
        if s > peak:
            peak, peak_step = s, k + 1
    finite = nan_at is None
    timed = times[WARMUP_STEPS:] if len(times) > WARMUP_STEPS else times
    row = {
        "engine": engine, "solver": solver, "label": label, "particles": spec.n,
        "particles_requested": spec.particles_requested, "dt": spec.dt,
        "steps": len(times), "timed_steps": len(timed),
        "ms_per_step": 1e3 * float(np.median(timed)),
        "ms_per_step_p90": 1e3 * float(np.percentile(timed, 90)),
        # CPU time of the process per step: less sensitive than wall time to other load on a
        # shared machine, for engines that run on one thread.
        "cpu_ms_per_step": 1e3 * float(np.median(cpu[WARMUP_STEPS:] or cpu)),
        "first_step_ms": 1e3 * times[0], "setup_s": setup_s,
        # CPU seconds of all the process's threads per wall second: how many cores it used.
        "cpu_per_wall": float(sum(cpu[WARMUP_STEPS:]) / max(sum(times[WARMUP_STEPS:]), 1e-12))
        if len(times) > WARMUP_STEPS else None,
        "substeps": int(conf.get("substeps", 1)), "settings": conf,
        "finite": finite, "nan_at_step": nan_at, "mass_kg": eng.mass_kg,
        "area_m2": float(spec.areas.sum()), "skipped": False, "skip_reason": None,
    }
    if finite:
        final_depth, final_stretch = _sanity(spec, x)
        mean_h = float(np.mean(x[:, 2]))
        row.update(mean_height_m=mean_h, sag_m=spec.sphere_top - mean_h,
                   hang_m=spec.sphere_top - float(np.min(x[:, 2])),
                   max_penetration_m=depth, final_penetration_m=final_depth,
                   max_stretch=final_stretch, peak_stretch=peak, peak_stretch_step=peak_step)
    else:
        row.update(mean_height_m=None, sag_m=None, hang_m=None, max_penetration_m=None,
                   final_penetration_m=None, max_stretch=None, peak_stretch=None,
                   peak_stretch_step=None)
    row["draped"] = bool(finite and row["sag_m"] > DRAPED_SAG)
    if engine == "ours":
        row["iterations"] = float(np.median(eng.iterations))
    row.update(getattr(eng, "extra", {}))
    return row


def skipped_row(label: str, spec_n: int | None, requested: int, reason: str) -> dict:
    """A row for a run that did not happen (missing package, failure)."""
    engine, solver = label.split(":")
    return {"engine": engine, "solver": solver, "label": label, "particles": spec_n,
            "particles_requested": requested, "ms_per_step": None, "skipped": True,
            "skip_reason": reason, "finite": None, "draped": False}


def warm_up(labels: list[str], material: str, dt: float, settings: dict,
            unavailable: dict[str, str], log) -> dict[str, float]:
    """A few steps of every run at WARMUP_PARTICLES, so that JIT compilation (numba, Warp
    kernels) and loading its caches stay out of the timings. Returns {label: seconds};
    runs that fail here are added to ``unavailable`` with the reason."""
    spec = build_spec(WARMUP_PARTICLES, material, dt, WARMUP_STEPS + 1)
    out = {}
    for label in labels:
        if label in unavailable:
            continue
        t0 = time.perf_counter()
        try:
            run_engine(spec, label, settings.get(label))
        except Exception as exc:  # noqa: BLE001 - a peer's failure must not end the benchmark
            unavailable[label] = f"failed in warm-up: {type(exc).__name__}: {exc}"
            log(traceback.format_exc())
            continue
        out[label] = time.perf_counter() - t0
        log(f"warm-up {label}: {out[label]:.1f} s (JIT compilation or cache loading)")
    return out


def _versions() -> dict:
    import importlib.metadata as md

    out = {}
    for pkg in ("numpy", "scipy", "numba", "warp-lang", "newton", "mujoco"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


def _meta(particles, labels, steps, dt, material, settings) -> dict:
    from cloth_mg_ros.bench.solvers import _machine
    from cloth_mg_ros.physics.materials import get_material
    from cloth_mg_ros.scenes import DRAPE_SPHERE

    try:
        load = os.getloadavg()
    except OSError:
        load = None
    mat = get_material(material)
    params = peer_parameters(mat)
    conf = {label: dict(DEFAULT_SETTINGS[label], **settings.get(label, {})) for label in labels}
    notes = [
        ("ms_per_step: one step of dt (all of an engine's substeps), median over the steps after "
        f"the first {WARMUP_STEPS}; cpu_per_wall (process CPU time over wall time in the timed "
        "steps) shows how many cores each engine kept busy"),
        ("ours: BDF2, one linearised implicit solve per step (tol 1e-4), penalty contacts then "
        "projection with Coulomb friction; timings leave out the per-step energy diagnostics"),
        ("newton: settings of Newton's cloth examples (VBD 10 substeps x 10 iterations; Style3D "
        "2 substeps x 10 nonlinear x 10 PCG iterations); contacts: penalty "
        f"{DEFAULT_SETTINGS['newton:vbd']['contact_ke']:g} N/m (ours projects particles out "
        "instead); self-contact off as in ours"),
        ("mujoco: discrete integrator (implicit in position; the flex's elasticity enters the "
        "solver's metric), one step per dt, soft-constraint contacts of the flex radius; "
        "compiling a 2D flex with bending grows steeply with its size (compile_s per row), so "
        "both MuJoCo solvers of a size share one compile (setup, not timed)"),
        ("walking garment: not run. A like-for-like run needs the dress's sewn particles to "
        "follow the body and its 16 capsules to move every substep: Newton could do it "
        "(kinematic capsule bodies posed each substep, zero-mass sewn particles moved by hand) "
        "but it is not implemented here; MuJoCo cannot attach flex vertices with elasticity "
        "to mocap bodies (its documentation), so the avatar would have to become an actuated "
        "articulated body tracking the poses, a different problem from ours"),
    ]
    for key in ("vbd", "style3d", "mujoco"):
        notes += [f"{key}: {n}" for n in params[key]["notes"]]
    return {
        "machine": _machine(), "cpus": os.cpu_count(), "platform": platform.platform(),
        "python": sys.version.split()[0], "versions": _versions(),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "scene": "drape", "material": mat.name, "particles_requested": list(particles),
        "engines": list(labels), "steps": steps, "dt": dt, "duration_s": steps * dt,
        "warmup_steps": WARMUP_STEPS, "warmup_particles": WARMUP_PARTICLES,
        "draped_sag_m": DRAPED_SAG, "settings": conf,
        "sphere_top_m": float(DRAPE_SPHERE[0][2] + DRAPE_SPHERE[1]),
        "sphere": {"centre_m": DRAPE_SPHERE[0].tolist(), "radius_m": DRAPE_SPHERE[1]},
        "parameters": {k: {kk: vv for kk, vv in v.items() if kk != "notes"}
                       for k, v in params.items()},
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS", "unset"),
        "loadavg_start": load, "notes": notes,
    }


def bench_peers(particles: list[int] | tuple = DEFAULT_PARTICLES, engines: list[str] | str = "all",
                steps: int = DEFAULT_STEPS, dt: float = DEFAULT_DT, material: str = "cotton",
                settings: dict | None = None, log=None) -> dict:
    """Run the benchmark; returns {"runs": [...], "meta": {...}}.

    engines: labels 'engine:solver' or engine names (see `parse_engines`); settings:
    {label: {key: value}} overriding DEFAULT_SETTINGS; log: a callable taking one line of
    progress (default: print to stderr)."""
    labels = parse_engines(engines)
    material = str(material).strip().lower()
    particles = list(particles)
    validate_peers_args(particles, labels, steps, dt, material)
    settings = settings or {}
    for label, conf in settings.items():
        if label not in DEFAULT_SETTINGS or any(k not in DEFAULT_SETTINGS[label] for k in conf):
            raise ClothInputError(f"bench peers: unknown setting(s) for {label!r}: {conf}")
    if log is None:
        def log(line):
            print(line, file=sys.stderr, flush=True)
    meta = _meta(particles, labels, steps, dt, material, settings)
    t_start = time.perf_counter()
    unavailable: dict[str, str] = {}
    for label in labels:
        engine = label.split(":")[0]
        missing = missing_modules(engine)
        if missing:
            unavailable[label] = (f"{', '.join(missing)} not installed ({INSTALL_HINT} installs "
                                  f"the peers extra)")
            log(f"{label}: skipped: {unavailable[label]}")
    meta["warmup_s"] = warm_up(labels, material, dt, settings, unavailable, log)
    runs = []
    for n in particles:
        spec = build_spec(n, material, dt, steps)
        log(f"{spec.n} particles ({spec.steps} steps of {spec.dt:.4g} s)")
        for label in labels:
            if label in unavailable:
                runs.append(skipped_row(label, spec.n, n, unavailable[label]))
                continue
            try:
                row = run_engine(spec, label, settings.get(label))
            except Exception as exc:  # noqa: BLE001 - one failing peer must not end the run
                log(traceback.format_exc())
                row = skipped_row(label, spec.n, n, f"failed: {type(exc).__name__}: {exc}")
            runs.append(row)
            log("  " + _progress_line(row))
    meta["wall_s"] = time.perf_counter() - t_start
    meta["unavailable"] = unavailable
    return {"runs": runs, "meta": meta}


# -- reporting ----------------------------------------------------------------------------
def _progress_line(row: dict) -> str:
    if row["skipped"]:
        return f"{row['label']:15s} skipped: {row['skip_reason']}"
    if not row["finite"]:
        return (f"{row['label']:15s} {row['ms_per_step']:9.1f} ms/step  NaN at step "
                f"{row['nan_at_step']}")
    return (f"{row['label']:15s} {row['ms_per_step']:9.1f} ms/step  sag {row['sag_m']:.3f} m  "
            f"hang {row['hang_m']:.3f} m  penetration {1e3 * row['max_penetration_m']:.2f} mm  "
            f"stretch {100 * (row['max_stretch'] - 1):.2f} % (peak "
            f"{100 * (row['peak_stretch'] - 1):.2f} %)")


def _cores(row: dict) -> str:
    return "-" if row.get("cpu_per_wall") is None else f"{row['cpu_per_wall']:.2f}"


def format_peers_report(result: dict) -> str:
    """The table printed by the CLI: ms per step per run and size, then every run's sanity
    figures, then the notes on the mapping."""
    from cloth_mg_ros.text_table import text_table

    runs, meta = result["runs"], result["meta"]
    labels = list(dict.fromkeys(r["label"] for r in runs))
    sizes = sorted({r["particles"] for r in runs if r["particles"] is not None})
    find = {(r["particles"], r["label"]): r for r in runs}
    head = (f"bench peers: drape ({meta['material']}), {meta['steps']} steps of "
            f"{meta['dt']:.4g} s, OPENBLAS_NUM_THREADS={meta['OPENBLAS_NUM_THREADS']}, "
            f"{meta['machine']}")
    lines = [head, ("ms per step of dt (median; substeps included); * = did not drape "
             f"(final mean height less than {meta['draped_sag_m']:g} m below the sphere's top), "
             "NaN = blew up, skip = not run")]

    def cell(r):
        if r is None:
            return "-"
        if r["skipped"]:
            return "skip"
        txt = f"{r['ms_per_step']:.1f}"
        if not r["finite"]:
            return txt + " NaN"
        return txt if r["draped"] else txt + " *"

    header = ["engine:solver (substeps)"] + [str(n) for n in sizes]
    rows = []
    for label in labels:
        some = next((r for r in runs if r["label"] == label and not r["skipped"]), None)
        sub = f" (x{some['substeps']})" if some and some.get("substeps", 1) > 1 else ""
        rows.append([label + sub] + [cell(find.get((n, label))) for n in sizes])
    lines += ["", text_table(header, rows), "", (
        "per run: cpu ms = the process's CPU time per step (median), cores = CPU over wall time, "
        "first ms = the first step, setup s = building the model (MuJoCo: compiling, once per "
        f"size for both its solvers); sphere top at {meta['sphere_top_m']:.2f} m: sag = how far "
        "the final mean height is below it, hang = the lowest particle; pen. = deepest inside "
        "the sphere or below the floor (any step / at the end); stretch = longest edge over its "
        "rest length at the end, and its peak with the step it happened")]
    header = ["run", "particles", "ms/step", "cpu ms", "cores", "first ms", "setup s",
              "mean z m", "sag m", "hang m", "pen. max/end mm", "stretch %", "peak % @step",
              "mass kg"]
    rows = []
    for r in runs:
        if r["skipped"]:
            rows.append([r["label"], str(r["particles"]), "skip"] + [""] * 11)
            continue
        timing = [f"{r['ms_per_step']:.1f}", f"{r['cpu_ms_per_step']:.1f}", _cores(r),
                  f"{r['first_step_ms']:.0f}", f"{r['setup_s']:.1f}"]
        if not r["finite"]:
            rows.append([r["label"], str(r["particles"])] + timing
                        + [f"NaN@{r['nan_at_step']}"] + [""] * 5 + [f"{r['mass_kg']:.4f}"])
            continue
        rows.append([r["label"], str(r["particles"])] + timing + [
            f"{r['mean_height_m']:.3f}", f"{r['sag_m']:.3f}", f"{r['hang_m']:.3f}",
            f"{1e3 * r['max_penetration_m']:.1f}/{1e3 * r['final_penetration_m']:.1f}",
            f"{100 * (r['max_stretch'] - 1):.2f}",
            f"{100 * (r['peak_stretch'] - 1):.1f} @{r['peak_stretch_step']}",
            f"{r['mass_kg']:.4f}"])
    lines.append(text_table(header, rows))
    skipped = {r["label"]: r["skip_reason"] for r in runs if r["skipped"]}
    for label, why in skipped.items():
        lines.append(f"skipped {label}: {why}")
    if meta.get("warmup_s"):
        lines.append("warm-up (JIT compile or cache load, not timed): " + ", ".join(
            f"{k} {v:.1f} s" for k, v in meta["warmup_s"].items()))
    lines += ["", "notes:"] + [f"- {n}" for n in meta["notes"]]
    return "\n".join(lines)


def plot_peers(result: dict, png: str | Path) -> Path:
    """ms per step against particles, log-log, one line per engine:solver (open markers: did
    not drape; crosses: NaN). Returns the written path."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from cloth_mg_ros.bench.charts import save_chart

    meta = result["meta"]
    runs = [r for r in result["runs"] if not r["skipped"]]
    labels = list(dict.fromkeys(r["label"] for r in result["runs"]))
    fig, ax = plt.subplots(figsize=(10, 5.5))
    for i, label in enumerate(labels):
        rs = sorted((r for r in runs if r["label"] == label), key=lambda r: r["particles"])
        if not rs:
            continue
        colour = plt.cm.tab10(i % 10)
        style = "-" if label.startswith("ours") else "--"
        sub = rs[0].get("substeps", 1)
        name = label + (f" (x{sub} substeps)" if sub > 1 else "")
        ax.plot([r["particles"] for r in rs], [r["ms_per_step"] for r in rs], style,
                color=colour, marker="o", label=name)
        for r in rs:
            if not r["finite"]:
                ax.plot(r["particles"], r["ms_per_step"], "x", color="red", ms=12, mew=2.5)
            elif not r["draped"]:
                ax.plot(r["particles"], r["ms_per_step"], "o", ms=13, mfc="none", mec="grey",
                        mew=1.5)
    ax.plot([], [], "o", ms=13, mfc="none", mec="grey", linestyle="none",
            label=f"did not drape (sag < {meta['draped_sag_m']:g} m)")
    ax.plot([], [], "x", color="red", mew=2.5, linestyle="none", label="NaN")
    ax.set_xscale("log")
    ax.set_yscale("log")
    sizes = sorted({r["particles"] for r in runs})
    if sizes:
        ax.set_xticks(sizes, [str(n) for n in sizes])
        ax.minorticks_off()
    ax.set_xlabel("particles")
    ax.set_ylabel(f"ms per step of {meta['dt']:.4g} s (median)")
    ax.set_title(f"drape, {meta['material']}, {meta['steps']} steps: this solver vs Newton (CPU) "
                 f"and MuJoCo flex", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return save_chart(fig, png)


# -- command line -------------------------------------------------------------------------
def add_cli(bsub: argparse._SubParsersAction) -> None:
    """Register `cloth-mg bench peers` on the bench sub-parsers."""
    p = bsub.add_parser("peers", help="the drape scene in this solver, Newton (Style3D, VBD; "
                        "CPU) and MuJoCo flex, timed side by side (needs the peers extra)")
    p.add_argument("--particles", default=",".join(map(str, DEFAULT_PARTICLES)),
                   help="comma-separated particle counts (default 1200,2400,4500)")
    p.add_argument("--engines", default="all",
                   help="comma-separated engines or engine:solver: ours (mpcg, mg), newton "
                        "(style3d, vbd), mujoco (newton, cg); default all")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS,
                   help=f"steps per run (default {DEFAULT_STEPS}; the first {WARMUP_STEPS} "
                        "are not timed)")
    p.add_argument("--dt", type=float, default=DEFAULT_DT, help="step, s (default 1/60)")
    p.add_argument("--material", default="cotton", help="material (default cotton)")
    p.add_argument("--set", action="append", default=None, metavar="RUN.KEY=VALUE",
                   help="override a run's setting, e.g. newton:vbd.iterations=20 "
                        "(repeatable; keys: substeps, iterations, linear_iterations, "
                        "contact_ke, contact_kd, tolerance, tol)")
    p.add_argument("--json", default="out/bench_peers.json", help="JSON output file")
    p.add_argument("--png", default="out/bench_peers.png", help="chart output file")
    p.set_defaults(bench_func=cmd_bench_peers)


def cmd_bench_peers(args: argparse.Namespace) -> int:
    """`cloth-mg bench peers`: run, print the table, write the JSON and the PNG."""
    import json

    from cloth_mg_ros.bench.solvers import parse_list

    particles = parse_list(args.particles, "particles", int)
    labels = parse_engines(args.engines)
    settings = parse_settings(args.set)
    validate_peers_args(particles, labels, args.steps, args.dt, args.material)
    result = bench_peers(particles, labels, args.steps, args.dt, args.material, settings)
    print(format_peers_report(result))
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(result, indent=1))
    png = plot_peers(result, args.png)
    print(f"wrote {args.json} and {png}")
    return 0
