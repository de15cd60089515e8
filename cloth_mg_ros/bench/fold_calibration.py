"""What the two saw-teeth measures read on shapes whose answer is known.

A flat 1 m sheet on the sheet scenes' lattice (`mesh.generators.sheet_coarse`, 40 cells
across: 2.5 cm edges, rows along x, stacked along z, the sheet in the x-z plane) is given a
shape by moving its vertices along y, and both measures read it: the hinge measure of
`bench.hinge_zigzag` (triangles whose hinges bend both ways) and the vertex measure of
`bench.saw_teeth` (vertices whose mean curvature has the opposite sign of their neighbours').
Smooth shapes (cylinders, folds four or more edges wide) are folds and should read 0; an
accordion pleated at every row and random heights are saw teeth and should read near 1.
"""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.bench.hinge_zigzag import fold_figures
from cloth_mg_ros.bench.saw_teeth import saw_teeth_figures

SHEET_CELLS = 40  # across 1 m: 2.49 cm mean edge
FOLD_ANGLE = np.radians(30.0)  # a smooth fold's peak curvature times the mean edge, rad
CYLINDER_RADIUS = 0.10  # m
WAVES = (3, 4, 8, 16)  # a smooth fold's length, mean edges per wave
NOISE_SD = 0.12  # random heights' standard deviation, mean edges
PLEAT_ANGLE = np.radians(20.0)  # the accordion's slope between rows, rad


def _sheet():
    # imported here: the calibration is the only user of the sheet generator in bench
    from cloth_mg_ros.mesh.generators import sheet_coarse
    mesh = sheet_coarse(1.0, 1.0, SHEET_CELLS)
    rest = np.asarray(mesh.rest)
    edge = float(np.linalg.norm(rest[mesh.edges[:, 1]] - rest[mesh.edges[:, 0]], axis=1).mean())
    return mesh, rest, edge


def _cylinder(rest: np.ndarray, along: int) -> np.ndarray:
    """The sheet rolled onto a cylinder curving along axis ``along`` (lengths kept)."""
    x = rest.copy()
    u = rest[:, along]
    x[:, along] = CYLINDER_RADIUS * np.sin(u / CYLINDER_RADIUS)
    x[:, 1] = CYLINDER_RADIUS * (1.0 - np.cos(u / CYLINDER_RADIUS))
    return x


def calibration_shapes() -> tuple[object, list[tuple[str, bool, np.ndarray]]]:
    """(the sheet's MeshLevel, [(name, is_saw_teeth, positions (n, 3) m)])."""
    mesh, rest, edge = _sheet()
    shapes = [(f"cylinder r {100 * CYLINDER_RADIUS:.0f} cm, axis across the rows", False,
               _cylinder(rest, 0)),
              (f"cylinder r {100 * CYLINDER_RADIUS:.0f} cm, axis along the rows", False,
               _cylinder(rest, 2))]
    for m in WAVES:
        wave = 2.0 * np.pi / (m * edge)
        x = rest.copy()
        # amplitude a: peak curvature a wave^2 times the edge is FOLD_ANGLE; an odd phase
        # keeps the lattice off the sine's zeros
        x[:, 1] = FOLD_ANGLE / (edge * wave ** 2) * np.sin(wave * rest[:, 0] + 0.37)
        shapes.append((f"smooth folds {m} edges long, crests across the rows", False, x))
    rows = np.unique(np.round(rest[:, 2], 9))
    row_of = np.searchsorted(rows, np.round(rest[:, 2], 9))
    x = rest.copy()
    x[:, 1] = 0.5 * np.tan(PLEAT_ANGLE) * np.diff(rows).mean() * (-1.0) ** row_of
    shapes.append(("accordion pleated at every row", True, x))
    x = rest.copy()
    x[:, 1] = NOISE_SD * edge * np.random.default_rng(0).standard_normal(len(rest))
    shapes.append((f"random heights, s.d. {NOISE_SD:g} edge", True, x))
    return mesh, shapes


def calibration(threshold_deg: float) -> list[dict]:
    """Both measures on every calibration shape: [{"shape", "saw_teeth" (what it is),
    "zigzag_share", "bending_share" (hinge measure), "vertex_saw_share",
    "vertex_bending_share"}]."""
    mesh, shapes = calibration_shapes()
    out = []
    for name, saw, x in shapes:
        hinge = fold_figures(x, mesh, threshold_deg)
        vertex = saw_teeth_figures(x, mesh, threshold_deg)
        out.append({"shape": name, "saw_teeth": saw,
                    "zigzag_share": hinge["zigzag_share"],
                    "bending_share": hinge["bending_share"],
                    "vertex_saw_share": vertex["vertex_saw_share"],
                    "vertex_bending_share": vertex["vertex_bending_share"]})
    return out
