"""Faithful coarse bending vanishes on rigid and affine motions on every level.

The paper's wing correspondence assumes the face across a coarse edge is a 180-degree copy
of the parent; next to the sheet's half-triangle border columns and on irregular garment
meshes it is not, and the mapped stencils then charged a rigid rotation (review: 9e-05 J on
level 1 of an 8-cell sheet, fine level ~1e-18 J).
"""

from __future__ import annotations

import numpy as np
import pytest

from cloth_mg_ros.mesh.garments.body import standing_body
from cloth_mg_ros.mesh.garments.garment import make_garment
from cloth_mg_ros.mesh.generators import sheet_coarse
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy
from cloth_mg_ros.physics.bending import bending_terms
from cloth_mg_ros.physics.system import pair_difference_product
from cloth_mg_ros.solvers.coarsening import FaithfulCoarsening

BEND = 2.4e-5  # N m


def _energy(mesh, pair_values, e):
    """(1/2) e^T K e of scalar pair entries (m,) N/m on displacements e (n, 3) m, J."""
    blocks = pair_values[:, None, None] * np.eye(3)[None]
    out = np.zeros_like(e)
    pair_difference_product(mesh.pairs, blocks, e, out)
    return 0.5 * float(np.sum(e * out))


def _flat_wing(rest, wing):
    """A wing's four rest points laid flat about its edge, (4, 2) m."""
    p = rest[wing]
    x_hat = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
    flat = [(0.0, 0.0), (float(np.linalg.norm(p[1] - p[0])), 0.0)]
    for m, sign in ((2, 1.0), (3, -1.0)):
        r = p[m] - p[0]
        t = r @ x_hat
        flat.append((t, sign * np.linalg.norm(r - t * x_hat)))
    return np.array(flat)


@pytest.mark.parametrize("cells", [4, 8])
def test_coarse_bending_of_a_sheet_vanishes_on_affine_fields(cells):
    hier = MeshHierarchy.from_coarse(sheet_coarse(0.5, 0.5, cells_x=cells, plane="xz"), 2)
    fine = hier.levels[0]
    fc = FaithfulCoarsening(hier, bending_terms(fine, BEND), 3)
    for lvl in range(1, 3):
        mesh, bend = hier.levels[lvl], fc.maps[lvl - 1].coarse_bend
        rest = mesh.rest
        curved = np.zeros_like(rest)
        curved[:, 1] = 0.5 * rest[:, 0] ** 2  # a cylinder of curvature 1/m
        smooth = _energy(mesh, bend, curved)
        assert smooth > 0.0
        fields = {
            "e_y = x": np.stack([0 * rest[:, 0], rest[:, 0], 0 * rest[:, 0]], axis=1),
            "e_y = z": np.stack([0 * rest[:, 0], rest[:, 2], 0 * rest[:, 0]], axis=1),
            "rotation": np.cross([0.3, 0.5, 1.0], rest),
            "in-plane affine": rest @ np.array([[0.1, 0.0, 0.02], [0, 0, 0], [0.03, 0, -0.05]]).T,
        }
        for name, e in fields.items():
            assert abs(_energy(mesh, bend, e)) < 1e-9 * smooth, (lvl, name)
        # A smooth field costs on the coarse level about what it costs on the fine one.
        fine_curved = np.zeros_like(fine.rest)
        fine_curved[:, 1] = 0.5 * fine.rest[:, 0] ** 2
        fine_e = _energy(fine, bending_terms(fine, BEND).pair_values(fine), fine_curved)
        assert 0.7 * fine_e < smooth < 1.3 * fine_e, lvl


@pytest.mark.parametrize("name", ["skirt", "dress"])
def test_coarse_hinges_of_a_garment_vanish_on_their_flat_laid_affine_fields(name):
    """Garment stencils treat each curved rest wing as laid flat (physics.bending), so a
    rigid motion of the curved mesh is not free on any level; each coarse hinge must
    still annihilate the affine fields of its flat-laid wing."""
    hier = make_garment(name, standing_body(), 1200).hierarchy
    fc = FaithfulCoarsening(hier, bending_terms(hier.levels[0], BEND), len(hier.levels))
    assert fc.levels >= 2
    for lvl, mp in enumerate(fc.maps, start=1):
        mesh = hier.levels[lvl]
        for w in range(mesh.n_wings):
            q = mp.coarse_wing_hess[w]
            full = np.zeros((4, 4))
            full[[0, 0, 0, 1, 1, 2], [1, 2, 3, 2, 3, 3]] = q
            full += full.T
            full[np.diag_indices(4)] = -full.sum(axis=1)
            flat = _flat_wing(mesh.rest, mesh.wings[w])
            flat -= flat.mean(axis=0)
            resp = np.linalg.norm(full @ flat)
            assert resp <= 1e-8 * np.linalg.norm(full) * np.linalg.norm(flat), (lvl, w)
        # And the coarse level charges a rotation no more than its own discretisation does.
        rot = np.cross([0.3, 0.5, 1.0], mesh.rest)
        own = bending_terms(mesh, BEND).pair_values(mesh)
        assert _energy(mesh, mp.coarse_bend, rot) <= (1 + 1e-9) * _energy(mesh, own, rot)
