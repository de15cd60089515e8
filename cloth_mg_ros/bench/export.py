"""Export one step's linear system, with its exact solution and grid transfers, to one .npz.

`cloth-mg export-system --scene drape --particles N --material M --step K --out sys.npz`
runs the scene from rest with an accurate reference solver (the sparse direct solver when
available, else block-symmetric CG at 1e-8) and writes the system of step K (step 0 = the first
system of the run), so that another solver can be tried on exactly the matrices the
benchmarks use. `load_exported(path)` rebuilds the scipy matrices.

File format (``numpy.load(path)``; no pickles; format tag ``cloth_mg_ros.export/1``).
Unknowns are ordered particle-major: dof 3*i + a is particle i's velocity change along axis a
(x, y, z; z up), in m/s. n = particles.

    A_data, A_indices, A_indptr, A_shape   A, (3n, 3n) symmetric positive definite CSR
                                           (scipy.sparse.csr_matrix((A_data, A_indices,
                                           A_indptr), shape=A_shape)); kg.
    b          (3n,)   right-hand side, kg m/s.
    x          (3n,)   the direct solution (solver named in ``direct_solver``).
    x0         (3n,)   the initial guess the simulator gives every solver; its values on the
                       pinned dofs are prescribed.
    pinned     (k,)    int64 pinned particle indices (empty in the drape scene).
    pinned_dofs (3k,)  int64 their dofs. On these rows the equation is replaced by x = x0
                       (Baraff-Witkin filtering): solve A_ff x_f = b_f - A_fp x0_p on the free
                       dofs f. With no pins, A x = b.
    n_levels   ()      number of hierarchy levels L (level 0 the simulated mesh, finest).
    P{l}_data, P{l}_indices, P{l}_indptr, P{l}_shape   for l = 1 .. L-1: scalar linear
                       interpolation from level l (coarse, n_l vertices) to level l-1 (fine),
                       CSR of shape (n_{l-1}, n_l), rows summing to 1; n_0 = n. The operator on
                       the 3n unknowns is kron(P{l}, I3) (``scipy.sparse.kron(P, eye(3))``);
                       restriction is its transpose. The vertices of level l are the first n_l
                       vertices of level l-1.
    level_sizes (L,)   vertex count of each level.
    positions  (n, 3)  particle positions x_n at the step, m.
    velocities (n, 3)  velocities v_n, m/s.
    faces      (t, 3)  triangles of the simulated mesh (int64).
    contacts   ()      number of particles in contact in this system (penalties on A's diagonal
                       blocks).
    contact_index (c,) their indices.
    particles, step (int), dt, h_eff (float, s), material, scene, scheme, direct_solver,
    reference_solver, format, note (str).

The 3x3 block structure: A = B + sum over pairs (i, j) of the pair block G_ij placed at (i, j)
and (j, i), with -G_ij added to both diagonal blocks (paper Sec. 4.1); the BlockSystem in
`cloth_mg_ros.physics.system` holds it in that form.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from cloth_mg_ros.bench.step_systems import iter_systems, reference_solver, validate_record_args
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.sim.sheets import build_scene

FORMAT = "cloth_mg_ros.export/1"
EXACT_RESIDUAL = 1e-9  # a 'direct' answer worse than this is replaced by scipy spsolve's
NOTE = ("A x = b on free dofs (x = x0 on pinned_dofs); dof 3*i+a = particle i, axis a. "
        "P{l} is the scalar (n_{l-1}, n_l) interpolation from level l to level l-1; on the "
        "3n unknowns use kron(P{l}, I3).")


def filtered_direct_solve(A: sp.spmatrix, b: np.ndarray, x0: np.ndarray,
                          fixed_dofs: np.ndarray) -> np.ndarray:
    """x with x[fixed_dofs] = x0[fixed_dofs] and A_ff x_f = b_f - A_fp x0_p (scipy spsolve)."""
    A = sp.csr_matrix(A)
    n = A.shape[0]
    x = np.array(x0, dtype=np.float64).reshape(-1).copy()
    free = np.ones(n, dtype=bool)
    free[np.asarray(fixed_dofs, dtype=np.int64)] = False
    if not free.any():
        return x
    rhs = np.asarray(b, dtype=np.float64).reshape(-1)[free]
    if not free.all():
        rhs = rhs - A[free][:, ~free] @ x[~free]
    A_ff = A[free][:, free].tocsc()
    x[free] = spla.spsolve(A_ff, rhs)
    return x


def _csr_arrays(prefix: str, M: sp.spmatrix) -> dict[str, np.ndarray]:
    M = sp.csr_matrix(M)
    M.sort_indices()
    return {f"{prefix}_data": M.data, f"{prefix}_indices": M.indices.astype(np.int64),
            f"{prefix}_indptr": M.indptr.astype(np.int64),
            f"{prefix}_shape": np.array(M.shape, dtype=np.int64)}


def _csr_from(data: dict, prefix: str) -> sp.csr_matrix:
    shape = tuple(int(s) for s in data[f"{prefix}_shape"])
    return sp.csr_matrix((data[f"{prefix}_data"], data[f"{prefix}_indices"],
                          data[f"{prefix}_indptr"]), shape=shape)


def validate_export_args(scene: str, particles: int, material: str, step: int,
                         levels: int | None, dt: float, scheme: str):
    """Check every option before any work; returns the Material."""
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0:
        raise ClothInputError(f"--step must be an integer >= 0 (0 = the first system), "
                              f"got {step!r}")
    return validate_record_args(scene, particles, material, 1, dt, scheme, levels, 1e-8)


def export_system(scene: str, particles: int, material: str, step: int, out: str | Path,
                  levels: int | None = None, dt: float = 1.0 / 60.0, scheme: str = "bdf2",
                  reference_tol: float = 1e-8) -> dict:
    """Run ``scene`` to step ``step`` and write its system to ``out`` (.npz; see the module
    docstring). Returns a summary dict (path, particles, dofs, nnz, contacts, seconds, ...)."""
    mat = validate_export_args(scene, particles, material, step, levels, dt, scheme)
    out = Path(out)
    if out.suffix != ".npz":
        out = out.with_name(out.name + ".npz")
    t0 = time.perf_counter()
    sc = build_scene(scene, particles, mat, levels=levels)
    ref_name, solver = reference_solver(reference_tol)
    # the loop stops at `step`: its last values are the system exported below
    for k, st, dv, state in iter_systems(sc, dt, scheme, after_contact=False,  # noqa: B007
                                         solver=solver):
        if k == step:
            break
    n = sc.model.n
    A = st.system.to_csr()
    b = st.rhs.reshape(-1).astype(np.float64)
    x0 = st.x0.reshape(-1).astype(np.float64)
    pinned = np.flatnonzero(st.fixed).astype(np.int64)
    pinned_dofs = (3 * pinned[:, None] + np.arange(3)[None, :]).reshape(-1)
    free = np.ones(3 * n, dtype=bool)
    free[pinned_dofs] = False
    bn = float(np.linalg.norm(b[free])) or 1.0

    def rel_res(x):
        return float(np.linalg.norm((b - A @ x)[free])) / bn

    x, direct_name = dv.reshape(-1).copy(), "direct"
    if ref_name != "direct" or rel_res(x) > EXACT_RESIDUAL:
        x = filtered_direct_solve(A, b, x0, pinned_dofs)
        direct_name = "scipy.sparse.linalg.spsolve"
    hier = sc.hierarchy
    arrays: dict[str, np.ndarray] = {}
    arrays.update(_csr_arrays("A", A))
    for lvl, tr in enumerate(hier.transfers, start=1):
        arrays.update(_csr_arrays(f"P{lvl}", tr.prolongation()))
    arrays.update(
        b=b, x=x, x0=x0, pinned=pinned, pinned_dofs=pinned_dofs,
        n_levels=np.array(len(hier.levels)),
        level_sizes=np.array([lv.n_vertices for lv in hier.levels], dtype=np.int64),
        positions=state.x.copy(), velocities=state.v.copy(),
        faces=np.asarray(sc.model.mesh.faces, dtype=np.int64),
        contacts=np.array(len(st.contacts)),
        contact_index=np.asarray(st.contacts.index, dtype=np.int64),
        particles=np.array(n), step=np.array(step), dt=np.array(float(dt)),
        h_eff=np.array(float(st.h_eff)), material=np.array(mat.name), scene=np.array(scene),
        scheme=np.array(st.scheme), direct_solver=np.array(direct_name),
        reference_solver=np.array(ref_name), format=np.array(FORMAT), note=np.array(NOTE),
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out, **arrays)
    return {"path": str(out), "scene": scene, "particles": int(n), "dofs": int(3 * n),
            "nnz": int(A.nnz), "levels": len(hier.levels), "material": mat.name,
            "step": int(step), "contacts": len(st.contacts), "pinned": len(pinned),
            "direct_solver": direct_name, "rel_residual": rel_res(x),
            "seconds": time.perf_counter() - t0, "bytes": out.stat().st_size}


def load_exported(path: str | Path) -> dict:
    """Read a file written by `export_system`: returns a dict with ``A`` (scipy CSR),
    ``P`` (list of scalar CSR prolongations, P[0] = P1 from level 1 to level 0), the arrays
    (b, x, x0, pinned, pinned_dofs, positions, velocities, faces, level_sizes, contact_index)
    and the scalars as Python ints, floats and strs."""
    path = Path(path)
    if not path.is_file():
        raise ClothInputError(f"no exported system at {path}")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    if str(data.get("format", "")) != FORMAT:
        raise ClothInputError(f"{path}: not a cloth_mg_ros export (format "
                              f"{data.get('format')!r}, expected {FORMAT!r})")
    out: dict = {"A": _csr_from(data, "A")}
    n_levels = int(data["n_levels"])
    out["P"] = [_csr_from(data, f"P{lvl}") for lvl in range(1, n_levels)]
    for key in ("b", "x", "x0", "pinned", "pinned_dofs", "positions", "velocities", "faces",
                "level_sizes", "contact_index"):
        out[key] = data[key]
    for key in ("particles", "step", "contacts", "n_levels"):
        out[key] = int(data[key])
    for key in ("dt", "h_eff"):
        out[key] = float(data[key])
    for key in ("material", "scene", "scheme", "direct_solver", "reference_solver", "format",
                "note"):
        out[key] = str(data[key])
    return out
