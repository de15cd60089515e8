"""Plain CDR (XCDR1, little endian) writing and reading, for building ROS 2 messages from numpy.

Why: rclpy 7.1.6 (Jazzy) publishes pre-serialised bytes (`publisher.publish(data: bytes)`)
and hands raw bytes to `create_subscription(..., raw=True)` callbacks. Writing a large
message's arrays straight from numpy into those bytes avoids building one Python object per
point (doc/architecture.md has what each costs).

What rmw_fastrtps_cpp puts on the wire, measured against `rclpy.serialization.serialize_message`
for visualization_msgs/Marker (see test/test_ros_cdr.py):

- a 4-byte encapsulation header ``00 01 00 00`` (CDR_LE: plain CDR, little endian; no XCDR2
  member headers, so float64 keeps its 8-byte alignment);
- every primitive is aligned to its own size (at most 8), counted from the first byte after
  the encapsulation header, not from the start of the buffer;
- a string is a uint32 length that counts the terminating NUL, then the UTF-8 bytes and the
  NUL; a sequence is a uint32 element count, then the elements. An empty sequence gets no
  alignment padding after its count (padding belongs to the first element, so there is none);
- the buffer ends right after the last member (no trailing padding).

Surprises met on the way, worth knowing elsewhere:

- The padding bytes in `serialize_message` output are not zeroed (they hold stale memory), so
  two serialisations of the same message may differ: compare decoded messages, never bytes.
  This writer zeroes its padding.
- `Publisher.publish` accepts only `bytes` as a raw message (an `isinstance(msg, bytes)` test):
  a `bytearray` or `memoryview` raises TypeError. `CdrWriter.getvalue` returns `bytes`.
- `bytes.join` takes any buffer, numpy arrays included, so a C-contiguous array is copied once,
  straight into the message (no `tobytes` copy first).

Nothing here imports rclpy: the writer and reader are plain Python and numpy, so bag tools
and viewers can use them without a ROS installation (rclpy's decoder, the reference the
tests check them against, is ros.message_reference's `deserialize`).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

__all__ = [
    "CDR_LE_HEADER",
    "CdrReader",
    "CdrWriter",
]

#: Encapsulation header of plain little-endian CDR, as rmw_fastrtps_cpp writes it.
CDR_LE_HEADER = b"\x00\x01\x00\x00"

_ZEROS = bytes(8)


class CdrWriter:
    """Appends CDR-encoded members to a message; `getvalue()` joins them into one `bytes`.

    Pieces are kept in a list and joined once at the end, so a large numpy array added with
    `array` is copied exactly once. Offsets and alignment count from the first byte after the
    encapsulation header.
    """

    __slots__ = ("_parts", "_pos")

    def __init__(self) -> None:
        self._parts: list[Any] = [CDR_LE_HEADER]
        self._pos = 0  # payload offset (bytes after the encapsulation header)

    @property
    def offset(self) -> int:
        """Current payload offset in bytes (the encapsulation header not counted)."""
        return self._pos

    def align(self, size: int) -> None:
        """Pad with zero bytes up to a multiple of `size` (1, 2, 4 or 8)."""
        pad = -self._pos % size
        if pad:
            self._parts.append(_ZEROS[:pad])
            self._pos += pad

    def pack(self, fmt: str, *values: Any, align: int) -> None:
        """Align to `align` bytes, then append `struct.pack('<' + fmt, *values)`.

        The caller guarantees that `fmt` needs no inner padding at this alignment (for
        example 'dddd' at 8, 'iiI' at 4); `struct`'s '<' mode never inserts any.
        """
        self.align(align)
        data = struct.pack("<" + fmt, *values)
        self._parts.append(data)
        self._pos += len(data)

    def uint32(self, value: int) -> None:
        """One uint32 (4-byte aligned)."""
        self.pack("I", value, align=4)

    def boolean(self, value: bool) -> None:
        """One bool as a single byte 0 or 1."""
        self._parts.append(b"\x01" if value else b"\x00")
        self._pos += 1

    def string(self, value: str) -> None:
        """A string: uint32 length (including the NUL), UTF-8 bytes, NUL."""
        data = value.encode("utf-8") + b"\x00"
        self.uint32(len(data))
        self._parts.append(data)
        self._pos += len(data)

    def array(self, values: np.ndarray, align: int) -> None:
        """Append the raw bytes of a numpy array (little-endian, any shape), aligned first.

        The array is made C-contiguous little-endian if it is not; the join in `getvalue`
        copies it into the message. Nothing is aligned for an empty array (CDR puts padding
        before the first element only).
        """
        arr = np.ascontiguousarray(values)
        if arr.dtype.byteorder == ">":
            arr = arr.astype(arr.dtype.newbyteorder("<"))
        if arr.nbytes == 0:
            return
        self.align(align)
        self._parts.append(arr.reshape(-1).view(np.uint8))
        self._pos += arr.nbytes

    def getvalue(self) -> bytes:
        """The whole message as `bytes`, encapsulation header first (what `publish` takes)."""
        return b"".join(self._parts)


class CdrReader:
    """Reads CDR members from serialised bytes (with the 4-byte encapsulation header).

    Only little-endian plain CDR is accepted; it is what rmw_fastrtps_cpp writes.
    """

    __slots__ = ("_buf", "_pos")

    def __init__(self, data: bytes | bytearray | memoryview) -> None:
        buf = memoryview(data).cast("B")
        if len(buf) < 4 or bytes(buf[:2]) != CDR_LE_HEADER[:2]:
            head = bytes(buf[:4]).hex()
            raise ValueError(f"not little-endian plain CDR: encapsulation header {head!r}")
        self._buf = buf
        self._pos = 4  # buffer offset; alignment counts from 4

    @property
    def remaining(self) -> int:
        """Bytes left after the current position."""
        return len(self._buf) - self._pos

    def align(self, size: int) -> None:
        """Skip padding up to a multiple of `size` (payload offsets)."""
        self._pos += -(self._pos - 4) % size

    def unpack(self, fmt: str, align: int) -> tuple:
        """Align, then read `struct.unpack('<' + fmt)`."""
        self.align(align)
        fmt = "<" + fmt
        size = struct.calcsize(fmt)
        if self._pos + size > len(self._buf):
            raise ValueError(f"CDR data ends at byte {len(self._buf)}, wanted {self._pos + size}")
        values = struct.unpack_from(fmt, self._buf, self._pos)
        self._pos += size
        return values

    def uint32(self) -> int:
        """One uint32."""
        return self.unpack("I", 4)[0]

    def string(self) -> str:
        """A string (length including the NUL, bytes, NUL)."""
        n = self.uint32()
        if n == 0 or self._pos + n > len(self._buf):
            raise ValueError(f"bad CDR string length {n} at byte {self._pos - 4}")
        data = bytes(self._buf[self._pos:self._pos + n - 1])
        self._pos += n
        return data.decode("utf-8")

    def array(self, dtype: np.dtype | str, count: int, align: int) -> np.ndarray:
        """`count` elements of little-endian `dtype`, as a read-only view into the data."""
        dt = np.dtype(dtype).newbyteorder("<")
        if count == 0:
            return np.empty(0, dtype=dt)
        self.align(align)
        end = self._pos + count * dt.itemsize
        if end > len(self._buf):
            raise ValueError(f"CDR data ends at byte {len(self._buf)}, wanted {end}")
        out = np.frombuffer(self._buf, dtype=dt, count=count, offset=self._pos)
        self._pos = end
        return out
