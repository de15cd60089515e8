"""cloth_node's outputs: the cloth marker, the marker array with the body, and the
diagnostics of each tick, serialised from numpy and published from the simulation thread.

rclpy publishers may be called from any thread; a publisher created with the Marker type
accepts either a Marker or `bytes` (exactly `bytes`: a bytearray raises TypeError), and
subscribers cannot tell the difference.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from cloth_mg_ros.ros.marker_array import CLOTH_RGBA, marker_array_bytes, strain_colours
from cloth_mg_ros.ros.markers import marker_triangle_list_bytes

__all__ = ["STATUS_NAME", "ClothOutputs", "TickFigures"]

NODE_NAME = "cloth_node"
STATUS_NAME = "cloth_node: solver"


@dataclass
class TickFigures:
    """The figures a status reports: from a body scene's TickStats, a sheet's StepStats, or
    zero (dressing, re-anchoring). Times in ms, penetration in m."""

    total_ms: float = 0.0
    solve_ms: float = 0.0
    iterations: int = 0
    rel_residual: float = 0.0
    converged: bool = True
    max_penetration: float = 0.0
    contacts: int = 0

    @classmethod
    def from_stats(cls, stats, total_ms: float | None = None) -> TickFigures:
        """From a TickStats or StepStats (None: zero figures with total_ms)."""
        if stats is None:
            return cls(total_ms=total_ms or 0.0)
        return cls(stats.total_ms if total_ms is None else total_ms, stats.solve_ms,
                   stats.iterations, stats.rel_residual, stats.converged,
                   stats.max_penetration, stats.contacts)


class ClothOutputs:
    """The three publishers (marker, marker array, stats) and what goes out on them.

    marker_pub, markers_pub, stats_pub: rclpy publishers of Marker, MarkerArray and
    DiagnosticArray; frame_id: the frame of everything published; colour_by_strain: per-vertex
    strain colours on the cloth.
    """

    def __init__(self, marker_pub, markers_pub, stats_pub, frame_id: str,
                 colour_by_strain: bool) -> None:
        self.marker_pub = marker_pub
        self.markers_pub = markers_pub
        self.stats_pub = stats_pub
        self.frame_id = frame_id
        self.colour_by_strain = colour_by_strain

    def cloth(self, model, x: np.ndarray, sec: int, nanosec: int, capsules=None,
              spheres=()) -> float:
        """Publish the cloth marker and the marker array of positions x (n, 3) of `model`
        (its mesh and rest edge lengths), m, stamped (sec, nanosec); capsules and spheres as
        in marker_array_bytes. Returns the time it took, ms."""
        t0 = time.perf_counter()
        faces = model.mesh.faces
        colours = strain_colours(x, model.mesh.edges, model.edge_rest) if (
            self.colour_by_strain and model.edge_rest is not None) else None
        self.marker_pub.publish(marker_triangle_list_bytes(
            x, faces, sec, nanosec, self.frame_id, "cloth", 0, CLOTH_RGBA, colours))
        self.markers_pub.publish(marker_array_bytes(
            x, faces, sec, nanosec, self.frame_id, capsules, spheres,
            per_vertex_colours=colours))
        return 1e3 * (time.perf_counter() - t0)

    def status(self, figures: TickFigures, finite: bool, sec: int, nanosec: int,
               values: dict[str, str], level: bytes = DiagnosticStatus.OK,
               note: str = "") -> None:
        """Publish one DiagnosticArray: a status with the level, the message (note, and why
        the level rose) and the tick's figures plus `values`."""
        notes = [note] if note else []
        if not finite:
            level, notes = DiagnosticStatus.ERROR, ["cloth positions became non-finite"]
        elif not figures.converged:
            level = max(level, DiagnosticStatus.WARN)
            notes.append(f"solve stopped at relative residual {figures.rel_residual:.3g} after "
                         f"{figures.iterations} iterations")
        table = {
            "solve_ms": f"{figures.solve_ms:.3f}",
            "step_ms": f"{figures.total_ms:.3f}",
            "iterations": str(figures.iterations),
            "rel_residual": f"{figures.rel_residual:.3e}",
            "max_penetration_m": f"{figures.max_penetration:.3e}",
            "contacts": str(figures.contacts),
            **values,
        }
        status = DiagnosticStatus(level=level, name=STATUS_NAME,
                                  message="; ".join(notes) or "ok", hardware_id=NODE_NAME,
                                  values=[KeyValue(key=k, value=v) for k, v in table.items()])
        out = DiagnosticArray(status=[status])
        out.header.stamp.sec, out.header.stamp.nanosec = sec, nanosec
        out.header.frame_id = self.frame_id
        self.stats_pub.publish(out)
