"""A closed triangle mesh as a rigid cloth collider (a chair, a mannequin scan, a body mesh).

`MeshCollider` holds what never changes (the mesh in its own, local frame, scaled to metres,
its search structures, the friction); where the body is lives in a `RigidPose` value
(world = R @ local + t, now and at the previous pose). ``collider.at(pose)`` is the body at a
pose, a `PosedMesh`, which follows the collider protocol of `colliders.py` (a ``friction``
attribute and ``query(x, margin, x_prev=None) -> Contacts``), so `collide`, `project_contacts`
and `penetration` use it unchanged; a simulation keeps the pose in its State
(sim.model.ClothState.bodies). The particles are transformed into the local frame, never the
mesh into the world.

Inside and outside. The mesh must be closed (every edge shared by exactly two faces) and
consistently oriented (trimesh checks both); it is turned outward if its volume comes out
negative. The sign of a particle's distance is that of (p - c) . N, with c the closest
surface point and N the angle-weighted pseudonormal of the feature c lies on (the face normal
inside a face, the mean of the two face normals on an edge, the angle-weighted vertex normal
at a vertex): exact for such meshes (Baerentzen and Aanaes 2005), with no ray casting. The
contact normal is the face normal where c lies inside a face; on an edge or at a vertex it is
the direction from c to the particle (for a particle inside: from the particle to c), i.e.
the gradient of the distance, pointing out of the body either way.

Closest points. trimesh's `trimesh.proximity` (ProximityQuery, closest_point, signed_distance,
and `contains`) needs the optional ``rtree`` package, which is not a dependency of this
project, and loops in Python over the query points. So trimesh loads, checks and describes the
mesh (normals, unique edges, face angles), and the searches run on a bounding-volume hierarchy
over the triangles in numba (like the capsule collider), with Ericson's point-triangle test;
the tests check it against trimesh's exact `trimesh.triangles.closest_point`. Those numba
kernels (BVH, closest points, segment crossings, culling) live in `mesh_kernels.py`; this
module holds the collider class, the loading and checking of its mesh, and the benchmark.

Culling. A query first takes every particle into the local frame and drops those outside the
mesh's local bounding box grown by the margin, in one compiled pass. A voxel grid over the box
(built once) stores for each voxel a lower bound on the distance from any of its points to the
surface and, where the surface cannot cross the voxel, which side it is on; the particles in the box
whose voxel is outside and farther than the margin are dropped in the same pass, and so are the
paths (with x_prev) that stay away from the surface, so only the particles near the surface (and any
deep inside) reach the exact search.

Tunnelling. With ``x_prev`` (positions at the previous pose) the straight path of each particle
relative to the body, from x_prev in the previous pose's local frame to x in the current one,
is tested against the triangles (first crossing along the path). A particle whose path enters
the surface (it was outside) and whose nearest way out now points away from the side it came
in (nearest outward normal . entry face normal < -0.2: it went past the middle of a thin part,
or right through it and out of the far side) is sent back out through the face it entered:
normal = that face's outward normal, distance = how far it is past that face's plane (<= 0),
whether it is inside now or not. A particle that entered but whose nearest way out is on its
own side (it slid around a convex edge, or just touched down) keeps the nearest-surface
contact, so nothing is pushed sideways.

Cost: ``python -m cloth_mg_ros.collision.mesh_collider`` measures a query and the building
of the collider; doc/command-line.md has the figures of a 2-core machine.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import trimesh

from cloth_mg_ros.collision.colliders import Contacts
from cloth_mg_ros.collision.mesh_kernels import (
    _FEATURES,
    _NEAR,
    _PATH,
    closest_kernel,
    segment_kernel,
    select_kernel,
    triangle_bvh,
)
from cloth_mg_ros.errors import ClothInputError

__all__ = ["MeshCollider", "PosedMesh", "RigidPose"]

# Voxels in the culling grid (about; fewer for flat meshes).
_GRID_VOXELS = 32_768
# A tunnelled particle is sent back when its nearest outward normal . entry normal < this.
_FLIP_COS = -0.2


class RigidPose(NamedTuple):
    """Where a rigid body is: world = rotation @ local + translation, rotation (3, 3) and
    translation (3,) m now and (the ``_prev`` ones) at the previous pose, dt s between them
    (None: no previous pose, zero velocity and no tunnelling test across it). A value: moving
    makes a new one."""

    rotation: np.ndarray
    translation: np.ndarray
    rotation_prev: np.ndarray
    translation_prev: np.ndarray
    dt: float | None


class MeshCollider:
    """A rigid closed triangle mesh as a cloth collider.

    mesh: a trimesh.Trimesh or the path of a mesh file trimesh reads (obj, stl, ply, off,
    glb, ...), in the body's local frame; scale: multiplies its coordinates into metres;
    friction: Coulomb coefficient (>= 0). The mesh must be closed and consistently oriented
    (watertight) and free of zero-area faces: ClothInputError names the source and the problem
    otherwise.

    Its pose is a `RigidPose`, at the identity (world = local) with zero velocity at rest
    (`rest_pose`); ``moved(pose, R, t, dt)`` gives the pose after a move and ``at(pose)`` the
    body at a pose, whose ``query(x, margin, x_prev)`` returns the contacts there.
    Attributes: friction; mesh (the local, scaled trimesh.Trimesh: do not modify it); source
    (the file path or a description).
    """

    def __init__(self, mesh: trimesh.Trimesh | str | Path, friction: float = 0.5,
                 scale: float = 1.0):
        self.source, tm = _load(mesh)
        if not (isinstance(scale, (int, float, np.integer, np.floating)) and np.isfinite(scale)
                and scale > 0.0):
            raise ClothInputError(f"mesh collider {self.source}: scale must be a positive "
                                  f"number, got {scale!r}")
        if not (isinstance(friction, (int, float, np.integer, np.floating))
                and np.isfinite(friction) and friction >= 0.0):
            raise ClothInputError(f"mesh collider {self.source}: friction must be >= 0, got "
                                  f"{friction!r}")
        self.friction = float(friction)
        if scale != 1.0:
            tm.apply_scale(float(scale))
        _validate(tm, self.source)
        self.mesh = tm
        self._build()

    # ---------------------------------------------------------------- pose

    def rest_pose(self) -> RigidPose:
        """At the identity (world = local), with zero velocity."""
        return RigidPose(np.eye(3), np.zeros(3), np.eye(3), np.zeros(3), None)

    def at(self, pose: RigidPose | None = None) -> PosedMesh:
        """The body at ``pose`` (None: `rest_pose`), for queries."""
        return PosedMesh(self, self.rest_pose() if pose is None else pose)

    def moved(self, pose: RigidPose | None, rotation: np.ndarray, translation: np.ndarray,
              dt: float | None = None) -> RigidPose:
        """The pose after moving from ``pose`` to world = rotation @ local + translation;
        rotation (3, 3) proper orthonormal, translation (3,) m. dt (s): time since ``pose``;
        the surface velocity of a contact is then its body point's displacement / dt. None: a
        jump (the previous pose is forgotten: zero velocity and no tunnelling test across it;
        ``pose`` may then be None)."""
        r = np.ascontiguousarray(rotation, dtype=np.float64)
        t = np.ascontiguousarray(translation, dtype=np.float64).reshape(-1)
        if r.shape != (3, 3) or not np.isfinite(r).all():
            raise ClothInputError(f"mesh collider {self.source}: rotation must be a finite "
                                  f"(3, 3) matrix, got shape {r.shape}")
        if np.abs(r.T @ r - np.eye(3)).max() > 1e-6 or np.linalg.det(r) <= 0.0:
            raise ClothInputError(f"mesh collider {self.source}: rotation must be orthonormal "
                                  f"with determinant +1, got {r.tolist()}")
        if t.shape != (3,) or not np.isfinite(t).all():
            raise ClothInputError(f"mesh collider {self.source}: translation must be 3 finite "
                                  f"numbers, got {t.tolist()}")
        if dt is None:
            return RigidPose(r, t, r, t, None)
        if not (isinstance(dt, (int, float, np.integer, np.floating)) and np.isfinite(dt)
                and dt > 0.0):
            raise ClothInputError(f"mesh collider {self.source}: dt must be a positive "
                                  f"number of seconds, got {dt!r}")
        return RigidPose(r, t, pose.rotation, pose.translation, float(dt))

    # ---------------------------------------------------------------- queries

    def query_at(self, pose: RigidPose, x: np.ndarray, margin: float,
                 x_prev: np.ndarray | None = None) -> Contacts:
        """Particles of x (n, 3) m within ``margin`` m of the surface or inside the body at
        ``pose``.

        Returns Contacts sorted by particle index: signed distance (m, negative inside),
        outward unit normal (world), velocity (m/s) of the body point in contact. x_prev
        (n, 3): the particles at the previous pose, for the tunnelling test (module doc);
        None: nearest-surface contacts only.
        """
        x = self._points(x, "x")
        margin = float(margin)
        use_prev = x_prev is not None
        if use_prev:
            xp = self._points(x_prev, "x_prev")
            if xp.shape != x.shape:
                raise ClothInputError(f"mesh collider {self.source}: x_prev must be "
                                      f"{x.shape}, got {xp.shape}")
        else:
            xp = x
        # One pass over all particles: local frame, box and voxel culling (module doc).
        n = len(x)
        idx = np.empty(n, np.int64)
        flag = np.empty(n, np.int8)
        xl = np.empty((n, 3))
        xpl = np.empty((n, 3))
        m = select_kernel(np.ascontiguousarray(x), np.ascontiguousarray(xp), use_prev,
                           pose.rotation, pose.translation, pose.rotation_prev,
                           pose.translation_prev, self._lo, self._hi, margin, self._origin,
                           self._pitch, self._grid_shape, self._vox_side, self._vox_lb,
                           idx, flag, xl, xpl)
        idx, flag, xl, xpl = idx[:m], flag[:m], xl[:m], xpl[:m]
        exact = (flag & _NEAR) != 0
        entered = np.zeros(0, np.int64)
        if use_prev:
            path = np.flatnonzero((flag & _PATH) != 0)
            entered, hit_t, hit_face = self._entries(xpl[path], xl[path])
            entered = path[entered]
            exact[entered] = True
        # Exact closest points: the particles near the surface and all that entered the body.
        rows = np.flatnonzero(exact)
        c, dist, nrm = self._closest(xl[rows])
        keep = dist < margin
        if len(entered):
            pos = np.searchsorted(rows, entered)
            n_in = self._face_normals[hit_face]
            back = np.einsum("ij,ij->i", nrm[pos], n_in) < _FLIP_COS
            pos, n_in, hit_t = pos[back], n_in[back], hit_t[back]
            a, b = xpl[rows[pos]], xl[rows[pos]]
            hit = a + hit_t[:, None] * (b - a)
            c[pos], nrm[pos] = hit, n_in
            dist[pos] = np.minimum(np.einsum("ij,ij->i", b - hit, n_in), 0.0)
            keep[pos] = True
        return Contacts(idx[rows[keep]], nrm[keep] @ pose.rotation.T, dist[keep],
                        _surface_velocity(pose, c[keep]))

    def signed_distance_at(self, pose: RigidPose, x: np.ndarray) -> np.ndarray:
        """Signed distance (n,) m of world points x (n, 3) to the surface at ``pose``,
        negative inside (exact for every point: no culling)."""
        x = self._points(x, "x")
        _, dist, _ = self._closest((x - pose.translation) @ pose.rotation)
        return dist

    # ---------------------------------------------------------------- internals

    def _points(self, x: np.ndarray, name: str) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ClothInputError(f"mesh collider {self.source}: {name} must be (n, 3), got "
                                  f"shape {x.shape}")
        return x

    def _build(self) -> None:
        """Triangles, pseudonormals, the BVH and the voxel grid, all in the local frame."""
        tm = self.mesh
        tri = np.ascontiguousarray(tm.triangles, dtype=np.float64)  # (f, 3, 3)
        self._tri = tri
        self._face_normals = np.ascontiguousarray(tm.face_normals, dtype=np.float64)
        faces = np.asarray(tm.faces, dtype=np.int64)
        face_edges = np.asarray(tm.faces_unique_edges, dtype=np.int64)  # edge j: v_j -> v_j+1
        edge_n = np.zeros((len(tm.edges_unique), 3))
        np.add.at(edge_n, face_edges.ravel(), np.repeat(self._face_normals, 3, axis=0))
        vert_n = np.zeros((len(tm.vertices), 3))
        weights = np.asarray(tm.face_angles)[:, :, None] * self._face_normals[:, None, :]
        np.add.at(vert_n, faces.ravel(), weights.reshape(-1, 3))
        # Pseudonormal of every (face, feature): (f, 7, 3).
        pseudo = np.empty((len(faces), _FEATURES, 3))
        pseudo[:, 0] = self._face_normals
        pseudo[:, 1:4] = _unit(edge_n)[face_edges]
        pseudo[:, 4:7] = _unit(vert_n)[faces]
        self._pseudo = pseudo
        self._lo = np.asarray(tm.bounds[0], dtype=np.float64)
        self._hi = np.asarray(tm.bounds[1], dtype=np.float64)
        self._bvh = triangle_bvh(tri)
        self._tiny = 1e-9 * max(1.0, float(np.abs(tri).max()))
        self._build_grid()

    def _build_grid(self) -> None:
        """Voxel grid over the box (one voxel of padding): per voxel a lower bound on the
        distance from any of its points to the surface (m), and its side (+1 outside, -1
        inside, 0 where the surface may cross it)."""
        ext = np.maximum(self._hi - self._lo, 1e-6 * float(np.max(self._hi - self._lo)))
        pitch = float(np.cbrt(np.prod(ext) / _GRID_VOXELS))
        pitch = min(max(pitch, float(ext.max()) / 256.0), float(ext.max()) / 4.0)
        self._pitch = pitch
        self._origin = self._lo - pitch
        shape = np.ceil(ext / pitch).astype(np.int64) + 2
        self._grid_shape = shape
        ii = np.indices(tuple(shape)).reshape(3, -1).T
        _, dist, _ = self._closest(self._origin + (ii + 0.5) * pitch)
        lb = np.abs(dist) - 0.5 * np.sqrt(3.0) * pitch
        self._vox_lb = np.maximum(lb, 0.0)
        self._vox_side = np.where(lb > 0.0, np.sign(dist), 0).astype(np.int8)

    def _closest(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points of local points p (m, 3): (c (m, 3), signed distance (m,)
        m, outward unit normal (m, 3)), all local."""
        m = len(p)
        c = np.empty((m, 3))
        face = np.empty(m, np.int64)
        feat = np.empty(m, np.int64)
        closest_kernel(np.ascontiguousarray(p), self._tri, *self._bvh, c, face, feat)
        pseudo = self._pseudo[face, feat]
        rel = p - c
        length = np.sqrt(np.einsum("ij,ij->i", rel, rel))
        sign = np.where(np.einsum("ij,ij->i", rel, pseudo) < 0.0, -1.0, 1.0)
        # Inside a face the distance gradient is the face normal; on an edge or at a vertex
        # it is c -> p (flipped inside); too close to the surface to tell: the pseudonormal.
        grad = (feat > 0) & (length > self._tiny)
        normal = np.where(grad[:, None],
                          sign[:, None] * rel / np.maximum(length, self._tiny)[:, None], pseudo)
        return c, sign * length, normal

    def _entries(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                np.ndarray]:
        """Paths a -> b (k, 3) (local) that enter the body at their first crossing: (their
        rows (j,), path parameter t in [0, 1] of that crossing (j,), face crossed (j,))."""
        t = np.empty(len(a))
        face = np.empty(len(a), np.int64)
        segment_kernel(np.ascontiguousarray(a), np.ascontiguousarray(b), self._tri,
                        *self._bvh, t, face)
        hit = np.flatnonzero(face >= 0)
        d = b[hit] - a[hit]
        entering = np.einsum("ij,ij->i", d, self._face_normals[face[hit]]) < 0.0
        hit = hit[entering]
        return hit, t[hit], face[hit]


# -------------------------------------------------------------------- helpers


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of v (k, 3) scaled to unit length (zero rows stay zero)."""
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0.0)


class PosedMesh:
    """A mesh body at a pose: `MeshCollider` ``collider`` and `RigidPose` ``pose``.

    ``query`` finds contacts at the pose (`MeshCollider.query_at`); ``set_pose(R, t, dt)``
    replaces the pose by the one after a move (``collider.moved``), for a body moved by hand
    outside a simulation."""

    def __init__(self, collider: MeshCollider, pose: RigidPose):
        self.collider, self.pose = collider, pose

    @property
    def friction(self) -> float:
        return self.collider.friction

    @property
    def rotation(self) -> np.ndarray:
        return self.pose.rotation

    @property
    def translation(self) -> np.ndarray:
        return self.pose.translation

    def set_pose(self, rotation: np.ndarray, translation: np.ndarray,
                 dt: float | None = None) -> None:
        """Move the body (`MeshCollider.moved`)."""
        self.pose = self.collider.moved(self.pose, rotation, translation, dt)

    def query(self, x: np.ndarray, margin: float, x_prev: np.ndarray | None = None) -> Contacts:
        """`MeshCollider.query_at` at this pose."""
        return self.collider.query_at(self.pose, x, margin, x_prev)

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """`MeshCollider.signed_distance_at` at this pose."""
        return self.collider.signed_distance_at(self.pose, x)


def _surface_velocity(pose: RigidPose, c: np.ndarray) -> np.ndarray:
    """World velocity (k, 3) m/s of the body points at local positions c (k, 3)."""
    if pose.dt is None:
        return np.zeros_like(c)
    now = c @ pose.rotation.T + pose.translation
    before = c @ pose.rotation_prev.T + pose.translation_prev
    return (now - before) / pose.dt


def _load(mesh: trimesh.Trimesh | str | Path) -> tuple[str, trimesh.Trimesh]:
    """(source description, a private copy of the mesh with coincident vertices merged)."""
    if isinstance(mesh, trimesh.Trimesh):
        source = f"<trimesh.Trimesh, {len(mesh.faces)} faces>"
        tm = mesh.copy()
    elif isinstance(mesh, (str, Path)):
        p = Path(mesh)
        source = str(p)
        if not p.exists():
            raise ClothInputError(f"mesh collider file not found: {p}")
        if not p.is_file():
            raise ClothInputError(f"mesh collider path is not a file: {p}")
        try:
            tm = trimesh.load(str(p), force="mesh")
        except Exception as exc:  # noqa: BLE001 - trimesh raises many types on bad input
            raise ClothInputError(
                f"cannot read mesh collider file {p}: {type(exc).__name__}: {exc}") from None
        if not isinstance(tm, trimesh.Trimesh):
            raise ClothInputError(f"mesh collider file {p} holds no triangle mesh "
                                  f"(trimesh read a {type(tm).__name__})")
    else:
        raise ClothInputError(f"mesh collider: expected a trimesh.Trimesh or a file path, got "
                              f"{type(mesh).__name__}")
    v = np.asarray(tm.vertices)
    if len(tm.faces) == 0 or len(v) == 0:
        raise ClothInputError(f"mesh collider {source} is empty ({len(v)} vertices, "
                              f"{len(tm.faces)} faces)")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ClothInputError(f"mesh collider {source}: vertex {i} has a non-finite "
                              f"coordinate {v[i].tolist()}")
    tm.merge_vertices()
    tm.remove_unreferenced_vertices()
    return source, tm


def _validate(tm: trimesh.Trimesh, source: str) -> None:
    """Raise ClothInputError unless tm is closed, consistently oriented and non-degenerate;
    turn it outward (in place) if its volume is negative."""
    tri = tm.triangles
    diag = float(np.linalg.norm(tm.extents))
    if not diag > 0.0:
        raise ClothInputError(f"mesh collider {source} is degenerate: all vertices coincide")
    areas = tm.area_faces
    bad = np.flatnonzero(areas <= 1e-12 * diag * diag)
    if len(bad):
        raise ClothInputError(
            f"mesh collider {source} has {len(bad)} degenerate (zero-area) faces, the first "
            f"is face {int(bad[0])} with vertices {tri[bad[0]].tolist()}; remove them (e.g. "
            f"mesh.update_faces(mesh.nondegenerate_faces()) and re-close the mesh)")
    _, counts = np.unique(tm.edges_sorted, axis=0, return_counts=True)
    open_edges = int(np.sum(counts == 1))
    multi_edges = int(np.sum(counts > 2))
    if open_edges or multi_edges:
        raise ClothInputError(
            f"mesh collider {source} is not watertight: {open_edges} boundary edges and "
            f"{multi_edges} edges shared by more than two faces; inside and outside are "
            f"undefined (close the holes, e.g. trimesh.repair.fill_holes, or use a closed "
            f"scan)")
    if not tm.is_winding_consistent:
        raise ClothInputError(
            f"mesh collider {source} is not consistently oriented (neighbouring faces wind "
            f"in opposite directions); fix it, e.g. trimesh.repair.fix_winding")
    volume = float(tm.volume)
    if not abs(volume) > 1e-12 * diag ** 3:
        raise ClothInputError(f"mesh collider {source} is degenerate: it encloses no volume "
                              f"({volume} m^3)")
    if volume < 0.0:
        tm.invert()



def _benchmark() -> None:
    """Time queries of 20K particles against a 5,120-face icosphere (module doc)."""
    rng = np.random.default_rng(0)
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    MeshCollider(mesh)  # compile (or load the cached kernels)
    t0 = time.perf_counter()
    col = MeshCollider(mesh).at()
    build = time.perf_counter() - t0
    n, near = 20_000, 2_000
    d = rng.normal(size=(near, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x_near = d * (0.3 + rng.uniform(-0.02, 0.02, near))[:, None]
    far = rng.uniform(-3.0, 3.0, (4 * n, 3))
    far = far[np.linalg.norm(far, axis=1) > 0.4][: n - near]
    x = np.concatenate([x_near, far])
    x_prev = x + rng.normal(scale=0.003, size=x.shape)
    outside = rng.uniform(1.0, 3.0, (n, 3))

    def best_ms(fn, reps=30):
        times = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return 1e3 * min(times), 1e3 * float(np.median(times))

    print(f"build: {1e3 * build:.0f} ms for {len(col.collider.mesh.faces)} faces; "
          f"{len(col.query(x, 0.005))} contacts of {len(x)} particles at margin 5 mm")
    for name, fn in [("query", lambda: col.query(x, 0.005)),
                     ("query with x_prev", lambda: col.query(x, 0.005, x_prev)),
                     ("all 20K outside the box", lambda: col.query(outside, 0.005))]:
        lo, med = best_ms(fn)
        print(f"{name}: best {lo:.2f} ms, median {med:.2f} ms")


if __name__ == "__main__":
    _benchmark()
