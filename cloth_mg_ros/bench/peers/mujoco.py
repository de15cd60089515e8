"""``mujoco:newton``, ``mujoco:cg``: a MuJoCo flex (``flexcomp type="direct"``, one
slide-jointed body per particle) with the ``discrete`` integrator (implicit in position, so one
step of ``dt`` is stable) and MuJoCo's own Newton or CG constraint solver: the scene's MJCF,
its compilation (shared by both solvers of a size) and the engine.

`mujoco` is imported when it is needed, not here: it is optional (the peers extra).
"""

from __future__ import annotations

import copy
import time

import numpy as np

from cloth_mg_ros.bench.peers.scene import DrapeSpec, peer_parameters


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


# The last compiled MuJoCo drape model: (spec, substeps, MjModel, compile seconds). Compiling
# a 2D flex with bending grows steeply with its size (minutes at 4500 particles), so both
# MuJoCo solvers of one size share one compile and differ only in mjOption.
_MJ_COMPILED: dict = {}


def _compiled_mujoco(spec: DrapeSpec, substeps: int):
    """A fresh copy of spec's compiled MuJoCo model, its compile time (s) and whether it was
    reused from the previous run."""
    # imported here: mujoco (a peer engine), loaded only when needed
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
        # imported here: mujoco (a peer engine), loaded only when needed
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
