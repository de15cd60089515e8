"""The multigrid mesh hierarchy: repeated 1-to-4 midpoint subdivision of a coarse mesh.

levels[0] is the FINEST level (the simulated cloth), levels[-1] the coarsest, as in PyAMG.
transfers[l] links levels[l] (fine) to levels[l+1] (coarse). Because every subdivision keeps
the coarse vertices first with their indices, a vertex index of any coarser level names the
same material point on every finer level (handy for pins: a corner is the same index
throughout).
"""

from __future__ import annotations

from dataclasses import dataclass

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.subdivision import subdivide
from cloth_mg_ros.mesh.topology import MeshLevel
from cloth_mg_ros.mesh.transfer import LevelTransfer

__all__ = ['MAX_DEPTH', 'MeshHierarchy', 'subdivided_counts']

# 4^8 = 65536 times the coarse face count: more is never sensible for a cloth.
MAX_DEPTH = 8


def subdivided_counts(n_vertices: int, n_edges: int, n_faces: int, depth: int
                      ) -> tuple[int, int, int]:
    """(vertices, edges, faces) after `depth` midpoint subdivisions, without building them.

    Each subdivision adds one vertex per edge, splits each edge in two and adds three interior
    edges per face, and splits each face into four.
    """
    n, e, t = n_vertices, n_edges, n_faces
    for _ in range(depth):
        n, e, t = n + e, 2 * e + 3 * t, 4 * t
    return n, e, t


@dataclass(eq=False)
class MeshHierarchy:
    """Levels finest-first and the transfers between consecutive levels.

    Attributes:
        levels: list of MeshLevel, levels[0] finest, len = depth + 1.
        transfers: list of LevelTransfer, transfers[l] from levels[l] to levels[l+1],
            len = depth.
    """

    levels: list[MeshLevel]
    transfers: list[LevelTransfer]

    @classmethod
    def from_coarse(cls, coarse: MeshLevel, depth: int) -> MeshHierarchy:
        """Subdivide `coarse` `depth` times (depth = number of subdivisions, >= 0)."""
        if isinstance(depth, bool) or not isinstance(depth, int) or not 0 <= depth <= MAX_DEPTH:
            raise ClothInputError(
                f'hierarchy depth must be an integer in [0, {MAX_DEPTH}], got {depth!r}')
        levels = [coarse]
        transfers: list[LevelTransfer] = []
        for _ in range(depth):
            fine, transfer = subdivide(levels[0])
            levels.insert(0, fine)
            transfers.insert(0, transfer)
        return cls(levels=levels, transfers=transfers)

    @property
    def finest(self) -> MeshLevel:
        """levels[0], the simulated mesh."""
        return self.levels[0]

    @property
    def coarsest(self) -> MeshLevel:
        """levels[-1], the mesh the hierarchy was built from."""
        return self.levels[-1]

    @property
    def depth(self) -> int:
        """Number of subdivisions (len(levels) - 1)."""
        return len(self.levels) - 1

    def __len__(self) -> int:
        return len(self.levels)
