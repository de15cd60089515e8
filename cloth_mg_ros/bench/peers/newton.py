"""``newton:style3d``, ``newton:vbd``: Newton's SolverStyle3D (projective-dynamics Hessian
with PCG) and SolverVBD (vertex block descent) on the Warp device ``cpu``, each step of ``dt``
split into the engine's substeps; the sphere and floor are static Newton shapes.

`warp` and `newton` are imported when an engine is built, not here: they are optional (the
peers extra) and slow to import.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.bench.peers.scene import DrapeSpec, hinge_stiffness, peer_parameters


class _NewtonEngine:
    """Newton (Warp, device "cpu"): the sheet as a cloth mesh, the sphere and the floor as
    static shapes, SolverStyle3D or SolverVBD, ``substeps`` solver steps per ``dt``."""

    def __init__(self, spec: DrapeSpec, solver: str, settings: dict):
        # imported here: warp (a peer engine), loaded only when needed
        import warp as wp

        # Warp's per-module "load ... took" lines would flood the benchmark's output.
        wp.config.log_level = getattr(wp, "LOG_WARNING", 30)
        wp.init()
        # imported here: newton (a peer engine), loaded only when needed
        import newton

        self.wp, self.solver_name = wp, solver
        builder = newton.ModelBuilder(up_axis=newton.Axis.Z,
                                      gravity=tuple(float(g) for g in spec.gravity))
        if solver == "style3d":
            newton.solvers.SolverStyle3D.register_custom_attributes(builder)
        ke, kd = float(settings["contact_ke"]), float(settings["contact_kd"])
        _add_sphere_and_floor(wp, builder, spec, ke, kd)
        _add_sheet(wp, builder, spec, solver)
        model = builder.finalize(device="cpu")
        if model.particle_count != spec.n:
            raise RuntimeError(f"Newton built {model.particle_count} particles, expected {spec.n}")
        model.soft_contact_ke, model.soft_contact_kd, model.soft_contact_mu = ke, kd, 1.0
        self.solver = _make_solver(newton, model, spec, solver, settings)
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


def _add_sphere_and_floor(wp, builder, spec: DrapeSpec, ke: float, kd: float) -> None:
    """The sphere and the ground plane as static shapes of contact stiffness ke, damping kd.

    Newton mixes the particle and shape sides of a contact: stiffness by their mean (VBD) or
    the particle side alone (Style3D), friction by the geometric mean. Both sides get the
    same stiffness and the particle side friction 1, so each shape's friction is the square
    of the scene's."""
    sphere_cfg = builder.default_shape_cfg.copy()
    sphere_cfg.ke, sphere_cfg.kd, sphere_cfg.mu = ke, kd, spec.sphere_friction ** 2
    builder.add_shape_sphere(
        -1, xform=wp.transform(wp.vec3(*spec.sphere_centre.tolist()), wp.quat_identity()),
        radius=spec.sphere_radius, cfg=sphere_cfg)
    floor_cfg = builder.default_shape_cfg.copy()
    floor_cfg.ke, floor_cfg.kd, floor_cfg.mu = ke, kd, spec.floor_friction ** 2
    builder.add_ground_plane(cfg=floor_cfg)


def _add_sheet(wp, builder, spec: DrapeSpec, solver: str) -> None:
    """The sheet as a cloth mesh with the solver's material parameters (`peer_parameters`)."""
    # imported here: newton (a peer engine), loaded only when needed
    from newton.solvers import style3d

    params = peer_parameters(spec.material)
    mat = spec.material
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


def _make_solver(newton, model, spec: DrapeSpec, solver: str, settings: dict):
    """SolverVBD (with our bending per hinge) or SolverStyle3D on the finalised model."""
    if solver == "vbd":
        # Per-hinge bending stiffness (Newton's edge_ke is one value per mesh).
        mat = spec.material
        k = hinge_stiffness(spec.rest, model.edge_indices.numpy(), float(mat.bend))
        props = model.edge_bending_properties.numpy()
        props[:, 0], props[:, 1] = k, float(mat.damping) * k
        model.edge_bending_properties.assign(props)
        return newton.solvers.SolverVBD(model, iterations=int(settings["iterations"]))
    cfg = newton.solvers.SolverStyle3D.Config(
        iterations=int(settings["iterations"]),
        linear_iterations=int(settings["linear_iterations"]))
    return newton.solvers.SolverStyle3D(model, config=cfg)
