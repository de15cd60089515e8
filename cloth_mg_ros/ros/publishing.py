"""cloth_node's outputs: the cloth marker, the body's marker array (with the contact forces'
arrows), the garment as a point cloud and a mesh, the per-tick stats, the periodic
/diagnostics status and the wrenches (ros.wrenches); serialised from numpy and published
from the simulation thread (the /diagnostics status from the executor's).

rclpy publishers may be called from any thread; a publisher created with the Marker type
accepts either a Marker or `bytes` (exactly `bytes`: a bytearray raises TypeError), and
subscribers cannot tell the difference. Everything of one tick goes out in one frame: the
body poses' header.frame_id, or the `frame_id` parameter when that is empty.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.duration import Duration

from cloth_mg_ros.io.messages.markers import marker_triangle_list_bytes
from cloth_mg_ros.ros.geometry_out import mesh_bytes, pointcloud2_bytes
from cloth_mg_ros.ros.marker_array import (
    CLOTH_RGBA,
    delete_all_bytes,
    marker_array_bytes,
    strain_colours,
)

__all__ = ["STATUS_NAME", "ClothOutputs", "Publishers", "caption_text"]

STATUS_NAME = "cloth_node: solver"
CAPTION_LIFT = 0.25  # m: the caption floats this far above the cloth's highest particle


def caption_text(table: dict[str, str], message: str = "ok") -> str:
    """A status's figures in one line for the RViz caption: particles, ms per tick, solver
    iterations, lag (body scenes), and the message when it is not 'ok'."""
    parts = [f"{table.get('particles', '?')} particles",
             f"{float(table.get('step_ms', 0.0)):.0f} ms/tick",
             f"{table.get('solver', '?')} {table.get('iterations', 0)} it"]
    if "lag_ms" in table:
        parts.append(f"lag {float(table['lag_ms']):.0f} ms")
    if message and message != "ok":
        parts.append(message)
    return " | ".join(parts)


@dataclass
class Publishers:
    """The node's rclpy publishers: marker (Marker), markers (MarkerArray), stats and
    diagnostics (DiagnosticArray), points (PointCloud2), mesh (shape_msgs/Mesh)."""

    marker: object
    markers: object
    stats: object
    diagnostics: object
    points: object
    mesh: object


class ClothOutputs:
    """What goes out on the publishers (module docstring).

    frame_id: the frame when the poses name none; colour_by_strain: per-vertex strain colours
    on the cloth; with_velocity: the point cloud carries vx, vy, vz; node_name: the
    /diagnostics status's hardware_id (the node's fully qualified name).
    """

    def __init__(self, pubs: Publishers, frame_id: str, colour_by_strain: bool,
                 with_velocity: bool, node_name: str, lifetime_s: float = 0.0) -> None:
        self.pubs = pubs
        self.lifetime_s = lifetime_s
        self.frame_id = frame_id
        self.colour_by_strain = colour_by_strain
        self.with_velocity = with_velocity
        self.node_name = node_name
        self._lock = threading.Lock()
        self._latest: tuple[bytes, str, dict[str, str]] | None = None
        self._worst = DiagnosticStatus.OK
        self._drawn = 0  # vertices of the cloth last drawn (0: nothing on display)
        self._drawn_frame = frame_id  # the frame it was drawn in
        self._caption = ""  # the latest status in a line, drawn above the cloth
        self._arrows: set[int] = set()  # ids of the contact arrows on display
        #: The grippers' and contacts' WrenchStamped publishers (ros.wrenches), once made.
        self.wrenches = None

    def frame(self, frame_id: str) -> str:
        """The frame to publish in: the poses' frame, else the parameter's."""
        return frame_id or self.frame_id

    def cloth(self, model, x: np.ndarray, sec: int, nanosec: int, frame_id: str = "",
              v: np.ndarray | None = None, capsules=None, spheres=(), arrows=None) -> float:
        """Publish the garment at positions x (n, 3) m (velocities v (n, 3) m/s) of `model`
        (its mesh and rest edge lengths): the cloth marker, the body's marker array (capsules
        and spheres as in marker_array_bytes; arrows {id: (start, end)}: the contact forces'
        arrows, those drawn before and gone deleted), the point cloud and the mesh, stamped (sec,
        nanosec) in `frame(frame_id)`. When the cloth changed size since the last one (a
        re-dress), a DELETEALL goes first. The marker array carries a caption above the cloth:
        the latest status in a line (caption_text). Returns the time it took, ms."""
        t0 = time.perf_counter()
        frame = self.frame(frame_id)
        if self._drawn and self._drawn != len(x):
            self.clear(sec, nanosec, frame)
        arrows = arrows or {}
        gone = sorted(self._arrows - set(arrows))
        marker, array, points, mesh = self.cloth_messages(model, x, sec, nanosec, frame, v,
                                                          capsules, spheres, arrows, gone)
        p = self.pubs
        p.marker.publish(marker)
        p.markers.publish(array)
        p.points.publish(points)
        p.mesh.publish(mesh)
        self._drawn, self._drawn_frame = len(x), frame
        self._arrows = set(arrows)
        return 1e3 * (time.perf_counter() - t0)

    def cloth_messages(self, model, x: np.ndarray, sec: int, nanosec: int, frame: str,
                       v: np.ndarray | None = None, capsules=None, spheres=(), arrows=None,
                       deleted_arrows=()) -> tuple[bytes, bytes, bytes, bytes]:
        """The serialised cloth marker, marker array, point cloud and mesh of `cloth` (its
        arguments; deleted_arrows: arrow ids to delete), without publishing them (the
        warm-up builds them once)."""
        faces = model.mesh.faces
        colours = strain_colours(x, model.mesh.edges, model.edge_rest) if (
            self.colour_by_strain and model.edge_rest is not None) else None
        with self._lock:
            caption = self._caption
        above = (*x[:, :2].mean(axis=0), x[:, 2].max() + CAPTION_LIFT) if len(x) else (0, 0, 0)
        return (marker_triangle_list_bytes(x, faces, sec, nanosec, frame, "cloth", 0,
                                           CLOTH_RGBA, colours, lifetime_s=self.lifetime_s),
                marker_array_bytes(None, None, sec, nanosec, frame, capsules, spheres,
                                   caption=(above, caption) if caption else None,
                                   lifetime_s=self.lifetime_s, arrows=arrows,
                                   deleted_arrows=deleted_arrows),
                pointcloud2_bytes(x, sec, nanosec, frame, v if self.with_velocity else None),
                mesh_bytes(x, faces))

    def clear(self, sec: int, nanosec: int, frame_id: str = "") -> bool:
        """DELETEALL on both marker topics, in `frame_id` (default: the frame of the last
        drawing): displays drop the cloth and the body (nothing goes out when nothing was
        drawn since the last one). Returns whether it was published."""
        if not self._drawn:
            return False
        marker, array = delete_all_bytes(sec, nanosec, frame_id or self._drawn_frame)
        self.pubs.marker.publish(marker)
        self.pubs.markers.publish(array)
        self._drawn = 0
        self._arrows = set()
        return True

    def wait_for_acks(self, timeout_s: float) -> bool:
        """Wait up to timeout_s (in all) until every reliable reader of both marker topics
        acknowledged what was published (a DELETEALL at shutdown); whether they all did."""
        deadline = time.monotonic() + timeout_s
        ok = True
        for pub in (self.pubs.marker, self.pubs.markers):
            left = max(deadline - time.monotonic(), 0.0)
            ok = pub.wait_for_all_acked(Duration(nanoseconds=round(left * 1e9))) and ok
        return ok

    def status(self, stats, total_ms: float, finite: bool, sec: int, nanosec: int,
               values: dict[str, str], level: bytes = DiagnosticStatus.OK, note: str = "",
               frame_id: str = "") -> None:
        """Publish one DiagnosticArray on the stats topic: a status with the level, the message
        (note, and why the level rose), the tick's figures and `values`; keep it for the next
        /diagnostics status. stats: the tick's TickStats (a garment) or StepStats (a sheet's
        one step), None when the tick took no step (a dressing); total_ms: the tick's time."""
        notes = [note] if note else []
        if not finite:
            level, notes = DiagnosticStatus.ERROR, ["cloth positions became non-finite"]
        elif stats is not None and not stats.converged:
            level = max(level, DiagnosticStatus.WARN)
            notes.append(f"solve stopped at relative residual {stats.rel_residual:.3g} after "
                         f"{stats.iterations} iterations")
        dropped = stats.self_contact_dropped if stats is not None else 0
        if dropped and finite:  # the cloth may pass through itself where pairs were left out
            level = max(level, DiagnosticStatus.WARN)
            notes.append(f"{dropped} self-contact pairs dropped past the search's cap")
        table = {
            "solve_ms": f"{stats.solve_ms if stats else 0.0:.3f}",
            "step_ms": f"{total_ms:.3f}",
            "iterations": str(stats.iterations if stats else 0),
            "rel_residual": f"{stats.rel_residual if stats else 0.0:.3e}",
            "max_penetration_m": f"{stats.max_penetration if stats else 0.0:.3e}",
            "contacts": str(stats.contacts if stats else 0),
            "self_contact_dropped": str(dropped),
            **values,
        }
        message = "; ".join(notes) or "ok"
        with self._lock:
            self._latest = (level, message, table)
            self._worst = max(self._worst, level)
            self._caption = caption_text(table, message)
        out = self._array(level, message, table, sec, nanosec)
        out.header.frame_id = self.frame(frame_id)
        self.pubs.stats.publish(out)

    def diagnostics(self, sec: int, nanosec: int, waiting: str = "") -> None:
        """Publish the /diagnostics status: the latest tick's figures at the worst level seen
        since the last one (a warning between two statuses is not lost), or OK with `waiting`
        before the first tick."""
        with self._lock:
            latest, worst = self._latest, self._worst
            self._worst = DiagnosticStatus.OK
        if latest is None:
            level, message, table = DiagnosticStatus.OK, waiting or "waiting", {}
        else:
            level, message, table = max(worst, latest[0]), latest[1], latest[2]
        self.pubs.diagnostics.publish(self._array(level, message, table, sec, nanosec))

    def _array(self, level: bytes, message: str, table: dict[str, str], sec: int,
               nanosec: int) -> DiagnosticArray:
        status = DiagnosticStatus(level=level, name=STATUS_NAME, message=message,
                                  hardware_id=self.node_name,
                                  values=[KeyValue(key=k, value=v) for k, v in table.items()])
        out = DiagnosticArray(status=[status])
        out.header.stamp.sec, out.header.stamp.nanosec = sec, nanosec
        return out
