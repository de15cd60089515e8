"""Shapes on a small grid whose fold answers are known: the fold measures' tests share them."""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.mesh.topology import MeshLevel


def grid(nx: int, ny: int, h: float) -> MeshLevel:
    """A flat nx x ny grid of spacing h m in the xy plane, two consistently oriented
    triangles per cell, diagonals alternating (no preferred direction)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    rest = np.stack([h * i.ravel(), h * j.ravel(), np.zeros(i.size)], axis=1)
    ci, cj = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    ci, cj = ci.ravel(), cj.ravel()
    v00, v10 = ci * ny + cj, (ci + 1) * ny + cj
    v01, v11 = v00 + 1, v10 + 1
    even = (ci + cj) % 2 == 0
    f1 = np.where(even[:, None], np.stack([v00, v10, v11], 1), np.stack([v00, v10, v01], 1))
    f2 = np.where(even[:, None], np.stack([v00, v11, v01], 1), np.stack([v10, v11, v01], 1))
    return MeshLevel(rest, np.concatenate([f1, f2]))


def cylinder(mesh: MeshLevel, radius: float) -> np.ndarray:
    """The grid rolled onto a cylinder of ``radius`` m about an axis along y (lengths kept)."""
    u, y = mesh.rest[:, 0], mesh.rest[:, 1]
    return np.stack([radius * np.sin(u / radius), y, radius * (1 - np.cos(u / radius))], axis=1)


def checkerboard(mesh: MeshLevel, amplitude: float) -> np.ndarray:
    """Saw teeth: the grid's vertices alternately raised and lowered, one vertex wide."""
    x = mesh.rest.copy()
    h = spacing(mesh)
    parity = np.round(x[:, 0] / h) + np.round(x[:, 1] / h)
    x[:, 2] = amplitude * (-1.0) ** parity
    return x


def spacing(mesh: MeshLevel) -> float:
    e = mesh.rest[mesh.edges[:, 1]] - mesh.rest[mesh.edges[:, 0]]
    return float(np.linalg.norm(e, axis=1).min())
