"""Tests of cloth_mg_ros.mesh: validation, sheet generation, subdivision hierarchy and the
fine-to-coarse maps of the faithful coarsening (conservation and consistency)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh import (
    WING_PAIR_LOCAL,
    MeshHierarchy,
    MeshLevel,
    choose_file_depth,
    choose_sheet_resolution,
    hierarchy_from_file,
    load_coarse_mesh,
    sheet_coarse,
    sheet_counts,
    sheet_hierarchy,
    top_corner_vertices,
)

TARGETS = [1200, 2400, 4500, 10000, 20000, 40000, 80000]


def _pyramid() -> MeshLevel:
    """Three faces around an apex: every wing's tip pair is also a (boundary) edge."""
    rest = [[0, 0, 1], [1, 0, 0], [-0.5, 0.8, 0], [-0.5, -0.8, 0]]
    return MeshLevel(np.array(rest, float), np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1]]))


def _jittered_sheet() -> MeshLevel:
    level = sheet_coarse(1.3, 0.7, cells_x=5, plane='xy')
    rng = np.random.default_rng(3)
    rest = level.rest + rng.uniform(-0.02, 0.02, level.rest.shape)
    return MeshLevel(rest, level.faces)


def _icosphere() -> MeshLevel:
    ico = trimesh.creation.icosphere(subdivisions=1, radius=0.3)
    return MeshLevel(ico.vertices, ico.faces)


COARSE_MESHES = {
    'sheet': lambda: sheet_coarse(1.0, 1.0, cells_x=6),
    'jittered': _jittered_sheet,
    'closed': _icosphere,
    'pyramid': _pyramid,
}


@pytest.fixture(scope='module', params=sorted(COARSE_MESHES))
def hierarchy(request) -> MeshHierarchy:
    return MeshHierarchy.from_coarse(COARSE_MESHES[request.param](), depth=2)


def _write(path, text: str):
    path.write_text(text)
    return path


# --- MeshLevel --------------------------------------------------------------------------------

def test_level_tables_on_a_square():
    rest = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    level = MeshLevel(rest, np.array([[0, 1, 2], [0, 2, 3]]))
    assert level.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert level.face_edges.tolist() == [[0, 3, 1], [1, 4, 2]]
    # Edge (0, 2) runs 0 -> 2 in face 1 (tip 3) and 2 -> 0 in face 0 (tip 1).
    assert level.wings.tolist() == [[0, 2, 3, 1]]
    assert level.wing_faces.tolist() == [[1, 0]]
    assert level.wing_edge.tolist() == [1]
    assert level.pairs.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    pairs = level.pairs
    for w, wing in enumerate(level.wings):
        for k, (i, j) in enumerate(WING_PAIR_LOCAL):
            assert sorted(pairs[level.wing_pairs[w, k]]) == sorted([wing[i], wing[j]])
    np.testing.assert_allclose(level.face_areas, [0.5, 0.5])
    np.testing.assert_allclose(level.vertex_areas, [1 / 3, 1 / 6, 1 / 3, 1 / 6])
    assert level.boundary_vertices.all()
    assert not level.rest.flags.writeable


def _arrays(obj) -> dict:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}


def test_tables_stay_read_only_through_copies_and_pickles(hierarchy):
    """numba compiles a kernel once per array kind, read-only apart from writable; numpy's
    deepcopy and unpickling give writable arrays, so a copied garment compiled every kernel
    again. A deepcopy shares the read-only tables; a pickle restores them read-only."""
    import copy
    import pickle

    import numba

    for original in (*hierarchy.levels, *hierarchy.transfers):
        tables = _arrays(original)
        assert tables and not any(a.flags.writeable for a in tables.values())
        for clone in (copy.deepcopy(original), pickle.loads(pickle.dumps(original))):
            assert type(clone) is type(original) and clone is not original
            assert _arrays(clone).keys() == tables.keys()
            for name, a in _arrays(clone).items():
                assert not a.flags.writeable, name
                assert numba.typeof(a) == numba.typeof(tables[name]), name
                np.testing.assert_array_equal(a, tables[name])
        deep = copy.deepcopy(original)
        assert all(getattr(deep, k) is a for k, a in tables.items())  # shared: never written
    copied = copy.deepcopy(hierarchy)
    assert copied.levels[0].faces is hierarchy.levels[0].faces
    assert copied.levels[0] is not hierarchy.levels[0]
    if hierarchy.transfers:  # its sparse matrices are copied, not shared
        t, u = hierarchy.transfers[0], copied.transfers[0]
        assert u.vertex_area_overlap is not t.vertex_area_overlap
        assert (u.vertex_area_overlap != t.vertex_area_overlap).nnz == 0


def test_face_pairs_and_edge_pairs_agree(hierarchy):
    for level in hierarchy.levels:
        ends = level.faces[:, [[0, 1], [1, 2], [2, 0]]]  # (t, 3, 2)
        np.testing.assert_array_equal(np.sort(ends, axis=2), level.edges[level.face_edges])
        np.testing.assert_array_equal(level.pairs[level.edge_pairs], level.edges)
        np.testing.assert_array_equal(level.face_pairs, level.edge_pairs[level.face_edges])
        tips = np.sort(level.wings[:, 2:], axis=1)
        np.testing.assert_array_equal(level.pairs[level.wing_pairs[:, 5]], tips)
        # c's face holds a -> b, d's face b -> a.
        a, b = level.wings[:, 0], level.wings[:, 1]
        fc = level.faces[level.wing_faces[:, 0]]
        k = np.argmax(fc == a[:, None], axis=1)
        assert (fc[np.arange(len(k)), (k + 1) % 3] == b).all()


@pytest.mark.parametrize('rest, faces, words', [
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 1, 0]], [[0, 1, 2], [1, 3, 2]],
     ['vertex 3', 'non-finite']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 4, 2]],
     ['face 1', 'index 4', 'out of range']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], [[0, 1, 2], [0, 1, 3]],
     ['face 1', 'degenerate']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 1, 3]],
     ['face 1', 'repeats a vertex']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 1]],
     [[0, 1, 2], [1, 3, 2], [1, 4, 2]], ['non-manifold edge (1, 2)', '3 faces']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 2, 3]],
     ['inconsistent orientation', 'faces [0, 1]', '(1, 2)']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], ['at least 2 faces', 'got 1']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 1]], ['faces [', 'duplicates']),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5]], [[0, 1, 2], [1, 3, 2]],
     ['vertex 4', 'not used']),
    # a long thin spike beside a square: 0.579 degrees at its tip, vertex 4 (its area is
    # the largest of the three: only its angle tells)
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [100, 0.5, 0]],
     [[0, 1, 2], [1, 3, 2], [1, 4, 3]],
     ['face 2', 'sliver', '0.579 deg at vertex 4', 'threshold 1 deg', 'rest area 49.5']),
])
def test_level_validation(rest, faces, words):
    with pytest.raises(ClothInputError) as info:
        MeshLevel(np.array(rest, float), np.array(faces), source='unit.obj')
    msg = str(info.value)
    assert 'unit.obj' in msg
    for word in words:
        assert word in msg


# --- sheets -----------------------------------------------------------------------------------

@pytest.mark.parametrize('target', TARGETS)
def test_sheet_sizes_near_targets(target):
    nx, ny, depth = choose_sheet_resolution(target)
    count = sheet_counts(nx, ny, depth)[0]
    assert abs(count / target - 1) < 0.10
    assert 1 <= depth <= 5 and min(nx, ny) >= 6
    if target <= 20000:
        h = sheet_hierarchy(target)
        assert h.finest.n_vertices == count and h.depth == depth
        assert h.coarsest.n_vertices == sheet_counts(nx, ny)[0]


def test_sheet_depth_grows_with_size():
    depths = [choose_sheet_resolution(t)[2] for t in (100, 1200, 20000, 80000)]
    assert depths == sorted(depths) and depths[0] < depths[-1]
    assert choose_sheet_resolution(80000, depth=2)[2] == 2


def test_sheet_geometry():
    level = sheet_coarse(2.0, 1.0, cells_x=10, plane='xy', centre=(1.0, 2.0, 3.0))
    lo, hi = level.rest.min(axis=0), level.rest.max(axis=0)
    np.testing.assert_allclose(lo, [0.0, 1.5, 3.0], atol=1e-12)
    np.testing.assert_allclose(hi, [2.0, 2.5, 3.0], atol=1e-12)
    np.testing.assert_allclose(level.face_areas.sum(), 2.0, rtol=1e-12)
    p = level.rest[level.faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (normal[:, 2] > 0).all()
    # Interior triangles (not touching the side borders) are near-equilateral.
    lengths = np.linalg.norm(p - p[:, [1, 2, 0]], axis=2)
    side = np.isclose(p[..., 0], 0.0).any(axis=1) | np.isclose(p[..., 0], 2.0).any(axis=1)
    ratio = lengths[~side].max(axis=1) / lengths[~side].min(axis=1)
    assert ratio.max() < 1.1
    # Vertical sheet: height along z, the top corners are exact vertices.
    hang = sheet_coarse(1.0, 1.0, cells_x=6, plane='xz')
    left, right = top_corner_vertices(hang, plane='xz')
    np.testing.assert_allclose(hang.rest[left], [-0.5, 0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(hang.rest[right], [0.5, 0.0, 0.5], atol=1e-12)
    fine = MeshHierarchy.from_coarse(hang, 2).finest
    np.testing.assert_array_equal(top_corner_vertices(fine), [left, right])


@pytest.mark.parametrize('kwargs, words', [
    ({'n_particles': 10}, ['n_particles', '10']),
    ({'n_particles': 200, 'depth': 4}, ['n_particles=200', 'too small for depth=4']),
    ({'n_particles': 1000, 'width': -1.0}, ['width', '-1.0']),
    ({'n_particles': 1000, 'plane': 'yz'}, ['plane', 'yz']),
])
def test_sheet_bad_arguments(kwargs, words):
    with pytest.raises(ClothInputError) as info:
        sheet_hierarchy(**kwargs)
    for word in words:
        assert word in str(info.value)


# --- hierarchy and transfers ------------------------------------------------------------------

def test_vertex_numbering_and_prolongation(hierarchy):
    for fine, coarse, tr in zip(hierarchy.levels, hierarchy.levels[1:], hierarchy.transfers,
                                strict=False):
        n_c = coarse.n_vertices
        assert fine.n_vertices == n_c + coarse.n_edges == tr.n_fine
        np.testing.assert_array_equal(fine.rest[:n_c], coarse.rest)
        np.testing.assert_array_equal(tr.parents[n_c:], coarse.edges)
        p = tr.prolongation()
        assert p.shape == (fine.n_vertices, n_c)
        np.testing.assert_allclose(np.asarray(p.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-15)
        # Linear interpolation reproduces the fine rest positions (flat midpoints).
        np.testing.assert_allclose(p @ coarse.rest, fine.rest, atol=1e-15)
        assert abs(tr.restriction() - p.T).max() == 0


def test_area_conservation(hierarchy):
    total = hierarchy.coarsest.face_areas.sum()
    for level in hierarchy.levels:
        np.testing.assert_allclose(level.face_areas.sum(), total, rtol=1e-12)
        np.testing.assert_allclose(level.vertex_areas.sum(), total, rtol=1e-12)
    for fine, coarse, tr in zip(hierarchy.levels, hierarchy.levels[1:], hierarchy.transfers,
                                strict=False):
        np.testing.assert_allclose(tr.vertex_area_overlap @ fine.vertex_areas,
                                   coarse.vertex_areas, rtol=1e-12)
        quarter = np.broadcast_to(0.25 * coarse.face_areas[:, None], tr.children.shape)
        np.testing.assert_allclose(fine.face_areas[tr.children], quarter, rtol=1e-12)
        np.testing.assert_allclose(tr.face_area_ratio, 0.25, rtol=1e-12)
        w = tr.vertex_area_overlap
        assert w.shape == (coarse.n_vertices, fine.n_vertices)
        np.testing.assert_allclose(np.asarray(w.sum(axis=0)).ravel(), 1.0)


def test_children_are_copies_of_their_parent(hierarchy):
    for fine, coarse, tr in zip(hierarchy.levels, hierarchy.levels[1:], hierarchy.transfers,
                                strict=False):
        child = fine.rest[fine.faces[tr.children]]            # (t_c, 4, 3, 3)
        image = coarse.rest[tr.child_vertex_map]             # (t_c, 4, 3, 3)
        child_sides = child[:, :, [1, 2, 0]] - child
        image_sides = image[:, :, [1, 2, 0]] - image
        scale = np.array([0.5, 0.5, 0.5, -0.5])[None, :, None, None]
        np.testing.assert_allclose(child_sides, scale * image_sides, atol=1e-14)
        np.testing.assert_array_equal(tr.children[:, 0], 4 * np.arange(coarse.n_faces))


def test_face_pair_map_is_consistent(hierarchy):
    for fine, coarse, tr in zip(hierarchy.levels, hierarchy.levels[1:], hierarchy.transfers,
                                strict=False):
        cvm = tr.child_vertex_map.reshape(-1, 3)
        looked_up = coarse.pair_index(cvm, cvm[:, [1, 2, 0]])
        np.testing.assert_array_equal(tr.face_pair_map, looked_up)
        # Each fine edge maps to exactly one coarse pair, from both of its faces.
        per_edge = np.full(fine.n_edges, -1)
        per_edge[fine.face_edges.ravel()] = tr.face_pair_map.ravel()
        np.testing.assert_array_equal(per_edge[fine.face_edges], tr.face_pair_map)
        np.testing.assert_array_equal(tr.pair_map[fine.edge_pairs], per_edge)
        # Every coarse face side receives its two halves from each side and the parallel
        # interior edge (two face sides) of each adjacent face: 4 face sides per adjacent face.
        hits = np.bincount(tr.face_pair_map.ravel(), minlength=coarse.n_pairs)
        np.testing.assert_array_equal(hits[coarse.edge_pairs], 4 * coarse.edge_face_count)


def test_wing_maps(hierarchy):
    for fine, coarse, tr in zip(hierarchy.levels, hierarchy.levels[1:], hierarchy.transfers,
                                strict=False):
        counts = np.bincount(tr.wing_map[tr.wing_map >= 0], minlength=coarse.n_wings)
        np.testing.assert_array_equal(counts, 4)
        # Unmapped fine wings: the interior edges parallel to a coarse boundary edge.
        n_boundary = int((coarse.edge_face_count == 1).sum())
        assert int((tr.wing_map < 0).sum()) == n_boundary
        ok = tr.wing_map >= 0
        target = coarse.wings[tr.wing_map[ok]]
        mapped = tr.wing_vertex_map[ok]
        np.testing.assert_array_equal(np.sort(mapped[:, :2], axis=1), target[:, :2])
        np.testing.assert_array_equal(np.sort(mapped[:, 2:], axis=1),
                                      np.sort(target[:, 2:], axis=1))
        assert (tr.wing_vertex_map[~ok] == -1).all() and (tr.wing_pair_map[~ok] == -1).all()
        # The six mapped pairs are the coarse wing's six pairs; tips onto tips.
        np.testing.assert_array_equal(np.sort(tr.wing_pair_map[ok], axis=1),
                                      np.sort(coarse.wing_pairs[tr.wing_map[ok]], axis=1))
        np.testing.assert_array_equal(tr.wing_pair_map[ok, 5],
                                      coarse.wing_pairs[tr.wing_map[ok], 5])
        # Fine wing area over coarse wing area: 1/4 where the coarse wing's faces are equal.
        fine_area = fine.face_areas[fine.wing_faces[ok]].sum(axis=1)
        coarse_faces = coarse.face_areas[coarse.wing_faces[tr.wing_map[ok]]]
        np.testing.assert_allclose(tr.wing_area_ratio[ok], fine_area / coarse_faces.sum(axis=1))
        equal = np.isclose(coarse_faces[:, 0], coarse_faces[:, 1], rtol=1e-12)
        np.testing.assert_allclose(tr.wing_area_ratio[ok][equal], 0.25, rtol=1e-12)
        assert (tr.wing_area_ratio[~ok] == 0).all()
        # Pure tip pairs map through their wing.
        tip_only = np.setdiff1d(fine.wing_pairs[ok, 5], fine.edge_pairs)
        assert (tr.pair_map[tip_only] >= 0).all()


def test_wing_correspondence_on_a_square():
    # Coarse faces (0,1,2), (0,2,3); midpoints m01=4, m02=5, m03=6, m12=7, m23=8.
    rest = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    h = MeshHierarchy.from_coarse(MeshLevel(rest, np.array([[0, 1, 2], [0, 2, 3]])), 1)
    fine, tr = h.finest, h.transfers[0]
    got = {}
    for wing, vmap in zip(fine.wings[tr.wing_map == 0], tr.wing_vertex_map[tr.wing_map == 0],
                          strict=True):
        got[tuple(wing[:2])] = dict(zip(wing.tolist(), vmap.tolist(), strict=True))
    assert got == {
        (0, 5): {0: 0, 5: 2, 4: 1, 6: 3},   # halves of coarse edge (0, 2)
        (2, 5): {2: 2, 5: 0, 7: 1, 8: 3},
        (4, 7): {4: 0, 7: 2, 1: 1, 5: 3},   # parallel to (0, 2) in face (0,1,2): m02 -> 3
        (6, 8): {6: 0, 8: 2, 3: 3, 5: 1},   # parallel to (0, 2) in face (0,2,3): m02 -> 1
    }
    assert (tr.wing_map >= 0).sum() == 4


def test_depth_zero_and_bad_depth():
    coarse = sheet_coarse(cells_x=4)
    h = MeshHierarchy.from_coarse(coarse, 0)
    assert len(h) == 1 and h.finest is coarse and h.transfers == []
    with pytest.raises(ClothInputError, match='depth'):
        MeshHierarchy.from_coarse(coarse, -1)


# --- files ------------------------------------------------------------------------------------

def test_load_exported_obj_and_build(tmp_path):
    sheet = sheet_coarse(1.0, 0.8, cells_x=5, plane='xy')
    path = tmp_path / 'sheet.obj'
    trimesh.Trimesh(sheet.rest, sheet.faces, process=False).export(path)
    level = load_coarse_mesh(path)
    np.testing.assert_allclose(level.rest, sheet.rest, atol=1e-6)
    np.testing.assert_array_equal(level.faces, sheet.faces)
    assert str(path) in level.source
    h = hierarchy_from_file(path, n_particles=500)
    assert h.depth == choose_file_depth(level, 500) == 2
    assert h.finest.n_vertices == 483  # 39 -> 132 -> 483
    assert choose_file_depth(level, 1500) == 3
    assert hierarchy_from_file(path, depth=1).depth == 1


@pytest.mark.parametrize('suffix', ['stl', 'ply', 'off'])
def test_load_other_formats(tmp_path, suffix):
    # STL is a triangle soup: coincident vertices must be merged back into a sheet.
    sheet = sheet_coarse(1.0, 1.0, cells_x=3, plane='xy')
    path = tmp_path / f'sheet.{suffix}'
    trimesh.Trimesh(sheet.rest, sheet.faces, process=False).export(path)
    level = load_coarse_mesh(path)
    assert level.n_vertices == sheet.n_vertices and level.n_faces == sheet.n_faces
    assert level.n_wings == sheet.n_wings
    np.testing.assert_allclose(level.face_areas.sum(), 1.0, rtol=1e-6)


SQUARE = 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n'


@pytest.mark.parametrize('name, text, words', [
    ('garbage.obj', 'this is not a mesh\n@@@ ### 1 2\n', ['no triangles']),
    ('nan.obj', SQUARE.replace('v 1 1 0', 'v nan 1 0') + 'f 1 2 3\nf 2 4 3\n',
     ['vertex 3', 'non-finite']),
    ('flat.obj', 'v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n',
     ['face 0', 'degenerate', 'area 0']),
    ('fin.obj', SQUARE + 'v 0.5 0.5 1\nf 1 2 3\nf 2 4 3\nf 2 5 3\n',
     ['non-manifold edge', '3 faces']),
    ('empty.obj', '', ['no triangles']),
    # a needle on the square's lower edge: 0.115 degrees at two corners, 179.8 at the third;
    # its area (5e-4 m^2, 1.5e-3 of the mean) passed the degenerate-area check
    ('needle.obj', SQUARE + 'v 0.5 -0.001 0\nf 1 2 3\nf 2 4 3\nf 1 5 2\n',
     ['face 2', 'sliver', 'smallest rest angle 0.115 deg', 'threshold 1 deg']),
])
def test_bad_files(tmp_path, name, text, words):
    path = _write(tmp_path / name, text)
    with pytest.raises(ClothInputError) as info:
        load_coarse_mesh(path)
    msg = str(info.value)
    assert str(path) in msg
    for word in words:
        assert word in msg


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(ClothInputError, match='not found') as info:
        load_coarse_mesh(tmp_path / 'nope.obj')
    assert 'nope.obj' in str(info.value)
    bad = tmp_path / 'mesh.xyz123'
    bad.write_bytes(b'\x00\x01\x02')
    with pytest.raises(ClothInputError, match='cannot read mesh file') as info:
        load_coarse_mesh(bad)
    assert 'mesh.xyz123' in str(info.value)


def test_file_n_particles_too_small(tmp_path):
    path = _write(tmp_path / 'square.obj', SQUARE + 'f 1 2 3\nf 2 4 3\n')
    with pytest.raises(ClothInputError) as info:
        hierarchy_from_file(path, n_particles=1)
    assert 'n_particles=1' in str(info.value) and 'square.obj' in str(info.value)
    assert hierarchy_from_file(path, n_particles=90).finest.n_vertices == 81
