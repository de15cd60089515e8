"""Cloth meshes and the multigrid hierarchy: validated levels, midpoint subdivision, the
fine-to-coarse maps of the faithful coarsening, sheet generators and file loading.

levels[0] of a MeshHierarchy is the finest (PyAMG convention). Lengths in metres.
"""

from cloth_mg_ros.mesh.generators import (
    choose_sheet_resolution,
    sheet_coarse,
    sheet_counts,
    sheet_hierarchy,
    top_corner_vertices,
)
from cloth_mg_ros.mesh.hierarchy import MeshHierarchy, subdivided_counts
from cloth_mg_ros.mesh.io import choose_file_depth, hierarchy_from_file, load_coarse_mesh
from cloth_mg_ros.mesh.subdivision import subdivide
from cloth_mg_ros.mesh.topology import WING_PAIR_LOCAL, MeshLevel
from cloth_mg_ros.mesh.transfer import LevelTransfer

__all__ = [
    'WING_PAIR_LOCAL',
    'LevelTransfer',
    'MeshHierarchy',
    'MeshLevel',
    'choose_file_depth',
    'choose_sheet_resolution',
    'hierarchy_from_file',
    'load_coarse_mesh',
    'sheet_coarse',
    'sheet_counts',
    'sheet_hierarchy',
    'subdivide',
    'subdivided_counts',
    'top_corner_vertices',
]
