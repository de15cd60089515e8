"""CDR bytes written from numpy must decode, with rclpy's own decoder, to the slow-built Marker.

Compares decoded messages, not bytes: rclpy's serialiser leaves stale memory in padding.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("visualization_msgs")

from rclpy.serialization import serialize_message
from visualization_msgs.msg import Marker

from cloth_mg_ros.io.messages.cdr import CdrReader, CdrWriter
from cloth_mg_ros.io.messages.markers import (
    TRIANGLE_LIST,
    marker_arrays_from_bytes,
    marker_triangle_list_bytes,
    triangle_corners,
)
from cloth_mg_ros.ros.message_reference import deserialize, marker_message, verify_layout


def grid_mesh(nx: int, ny: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A jittered nx-by-ny grid: positions (nx ny, 3) m, faces (2 (nx-1)(ny-1), 3)."""
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    pos = np.stack([i.ravel() / max(nx - 1, 1), j.ravel() / max(ny - 1, 1),
                    np.zeros(nx * ny)], axis=1)
    pos += 0.01 * rng.standard_normal(pos.shape)
    v = (i[:-1, :-1] * ny + j[:-1, :-1]).ravel()
    faces = np.concatenate([np.stack([v, v + ny, v + 1], axis=1),
                            np.stack([v + 1, v + ny, v + ny + 1], axis=1)])
    return pos, faces.astype(np.int64)


def random_mesh(n: int, t: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """n random positions (m) and t random triangles over them."""
    return rng.uniform(-2.0, 2.0, (n, 3)), rng.integers(0, n, (t, 3))


def test_layout_matches_installed_marker():
    verify_layout()


@pytest.mark.parametrize("n_tri", [0, 1, 2, 7, 64])
@pytest.mark.parametrize("with_colours", [False, True])
def test_decodes_to_slow_marker(n_tri, with_colours):
    rng = np.random.default_rng(n_tri)
    pos, faces = random_mesh(20, n_tri, rng)
    colours = rng.uniform(0.0, 1.0, (20, 4)) if with_colours else None
    # Every frame_id and ns length mod 8 moves the float64 pose and points by 4 bytes or not.
    for k in range(10):
        kwargs = {"stamp_sec": 1_700_000_000 + k, "stamp_nanosec": 999_999_999 - k,
                  "frame_id": "map/" * (k // 4) + "w" * (k % 4), "ns": "c" * (9 - k),
                  "marker_id": -k, "colour": (0.1, 0.2, 0.3, 0.5 + 0.05 * k),
                  "per_vertex_colours": colours}
        data = marker_triangle_list_bytes(pos, faces, **kwargs)
        assert isinstance(data, bytes)
        ref = marker_message(pos, faces, **kwargs)
        got = deserialize(data, Marker)
        assert got == ref, f"frame_id {kwargs['frame_id']!r}"
        assert len(data) == len(serialize_message(ref))
        assert got.type == Marker.TRIANGLE_LIST == TRIANGLE_LIST
        assert len(got.points) == 3 * n_tri
        assert len(got.colors) == (3 * n_tri if with_colours else 0)


def test_points_are_triangle_corners_bit_for_bit():
    rng = np.random.default_rng(1)
    pos, faces = grid_mesh(9, 7, rng)
    got = deserialize(marker_triangle_list_bytes(pos, faces), Marker)
    pts = np.array([[p.x, p.y, p.z] for p in got.points])
    np.testing.assert_array_equal(pts, pos[faces].reshape(-1, 3))
    np.testing.assert_array_equal(triangle_corners(pos, faces), pos[faces].reshape(-1, 3))


def test_non_ascii_frame_id_and_float32_positions():
    rng = np.random.default_rng(2)
    pos, faces = random_mesh(5, 3, rng)
    pos32 = pos.astype(np.float32)
    kwargs = {"frame_id": "wörld_ß", "ns": "тк"}
    got = deserialize(marker_triangle_list_bytes(pos32, faces.astype(np.int32), **kwargs),
                      Marker)
    assert got == marker_message(pos32.astype(np.float64), faces, **kwargs)


def test_reader_reads_rclpy_bytes():
    """The numpy reader agrees with what rclpy itself serialised (padding with stale bytes)."""
    rng = np.random.default_rng(3)
    pos, faces = random_mesh(11, 6, rng)
    colours = rng.uniform(0.0, 1.0, (11, 4)).astype(np.float32)
    for k in range(9):
        ref = marker_message(pos, faces, stamp_sec=5, stamp_nanosec=6, frame_id="f" * k,
                             ns="ns", marker_id=3, per_vertex_colours=colours if k % 2 else None)
        view = marker_arrays_from_bytes(serialize_message(ref))
        assert (view.stamp_sec, view.stamp_nanosec, view.frame_id, view.ns) == (5, 6, "f" * k,
                                                                                "ns")
        assert (view.marker_id, view.marker_type, view.action) == (3, TRIANGLE_LIST, 0)
        assert view.pose == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0) and view.scale == (1.0,) * 3
        np.testing.assert_array_equal(view.points, pos[faces].reshape(-1, 3))
        if k % 2:
            np.testing.assert_array_equal(view.colors, colours[faces].reshape(-1, 4))
        else:
            assert view.colors.shape == (0, 4)


def test_writer_reader_round_trip_alignment():
    w = CdrWriter()
    w.boolean(True)
    w.array(np.array([1.5, -2.0]), align=8)  # 7 bytes of padding after the bool
    w.string("ab")
    w.array(np.array([], dtype=np.float64), align=8)  # empty: no padding
    w.uint32(7)
    data = w.getvalue()
    assert data[:4] == b"\x00\x01\x00\x00"
    assert len(data) == 4 + 1 + 7 + 16 + 4 + 3 + 1 + 4
    r = CdrReader(data)
    assert r.unpack("?", 1) == (True,)
    np.testing.assert_array_equal(r.array(np.float64, 2, 8), [1.5, -2.0])
    assert r.string() == "ab"
    assert r.array(np.float64, 0, 8).size == 0
    assert r.uint32() == 7 and r.remaining == 0


@pytest.mark.parametrize("bad", [
    {"positions": np.zeros((4, 2)), "faces": np.zeros((1, 3), dtype=int)},
    {"positions": np.zeros((4, 3)), "faces": np.array([[0, 1, 4]])},
    {"positions": np.zeros((4, 3)), "faces": np.array([[0, -1, 2]])},
    {"positions": np.zeros((4, 3)), "faces": np.zeros((1, 3))},
    {"positions": np.zeros((4, 3)), "faces": np.zeros((1, 3), dtype=int),
     "per_vertex_colours": np.zeros((3, 4))},
    {"positions": np.zeros((4, 3)), "faces": np.zeros((1, 3), dtype=int), "colour": (1.0, 0.0)},
])
def test_bad_input_is_rejected(bad):
    with pytest.raises(ValueError):
        marker_triangle_list_bytes(**bad)


def test_reader_rejects_big_endian_and_truncated_data():
    with pytest.raises(ValueError, match="little-endian"):
        CdrReader(b"\x00\x00\x00\x00")
    data = marker_triangle_list_bytes(np.zeros((3, 3)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="ends"):
        marker_arrays_from_bytes(data[:120])


def test_a_20k_particle_marker_reads_back_and_its_time_is_printed():
    """A 20K-particle cloth (~40K triangles) serialised reads back to the same points; the
    time it takes is printed, not asserted (a test never fails because the machine was
    slow: `cloth-mg bench` has the speeds)."""
    rng = np.random.default_rng(4)
    pos, faces = grid_mesh(100, 200, rng)
    colours = rng.uniform(0.0, 1.0, (len(pos), 4)).astype(np.float32)
    for label, cols in (("", None), (" with per-vertex colours", colours)):
        times = []
        for _ in range(20):
            t0 = time.perf_counter()
            data = marker_triangle_list_bytes(pos, faces, 1, 2, "world",
                                              per_vertex_colours=cols)
            times.append(time.perf_counter() - t0)
        view = marker_arrays_from_bytes(data)
        np.testing.assert_array_equal(view.points, pos[faces].reshape(-1, 3))
        print(f"\nMarker of {len(pos)} particles, {len(faces)} triangles, {len(view.points)} "
              f"points{label}: {len(data) / 1e6:.2f} MB in {1e3 * np.median(times):.2f} ms "
              f"(median of 20, min {1e3 * min(times):.2f} ms)")
