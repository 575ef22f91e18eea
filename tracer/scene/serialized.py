"""Mitsuba's ``serialized`` mesh files (versions 3 and 4), read from their specification.

The format, as Mitsuba 3 documents it (src/shapes/serialized.cpp, "Format description"):
little endian throughout; each mesh is a 2-byte magic ``0x041C`` and a 2-byte version, then a
zlib stream holding

- ``uint32`` flags: 0x0001 vertex normals, 0x0002 texture coordinates, 0x0008 vertex colours,
  0x0010 face normals, 0x1000 single precision, 0x2000 double precision;
- version 4 only: the mesh's name, a NUL-terminated UTF-8 string;
- ``uint64`` vertex count V, ``uint64`` triangle count F;
- positions (V x 3), then normals (V x 3), texture coordinates (V x 2) and colours (V x 3)
  where the flags say so, as float32 or float64;
- indices (F x 3), ``uint32`` (Mitsuba 3 reads them so whatever V is).

A file may hold several meshes one after another; it then ends with the offset of each (uint64
in version 4, uint32 in version 3) and their count (uint32), which ``shape_index`` uses. Mitsuba
3.9's own version 5 (a packed vertex layout) is refused by name. Vertex colours are skipped, as
Mitsuba skips them. Mitsuba 3.9 ignores the face-normals flag of versions 3 and 4 (only the
scene's ``face_normals`` decides), and so does tracer.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from .mesh import Mesh, MeshError, checked

MAGIC = 0x041C
HAS_NORMALS, HAS_TEXCOORDS, HAS_COLORS = 0x0001, 0x0002, 0x0008
DOUBLE_PRECISION = 0x2000
# A mesh stream is inflated only up to what its counts need; more than this many vertices or
# triangles (in the tens of gigabytes) is taken for a corrupt header.
MAX_COUNT = 2**31


def read_serialized(path: Path, shape_index: int = 0) -> Mesh:
    """Mesh ``shape_index`` of the serialized file ``path``: positions, faces, vertex normals
    (None if the file has none) and its corners' texture coordinates (None if none), as written
    (the caller transforms them). Raises MeshError naming the file and what is wrong."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read mesh {path}: {exc.strerror}") from None
    if len(data) < 4:
        raise MeshError(f"{path} is not a Mitsuba serialized mesh (it has {len(data)} bytes)")
    start = _mesh_offset(path, data, shape_index)
    magic, version = struct.unpack_from("<HH", data, start)
    if magic != MAGIC:
        raise MeshError(f"{path} is not a Mitsuba serialized mesh (its mesh {shape_index} starts with "
                        f"0x{magic:04X}, not 0x{MAGIC:04X})")
    if version not in (3, 4):
        detail = " (Mitsuba 3.9's packed layout: re-export it as version 4 or PLY)" if version == 5 else ""
        raise MeshError(f"{path}: serialized mesh version {version} is not supported{detail}; "
                        "tracer reads versions 3 and 4")
    stream = _Inflated(path, data[start + 4:])
    flags = stream.unpack("<I")[0]
    if version == 4:
        stream.cstring()
    vertex_count, face_count = stream.unpack("<QQ")
    if vertex_count > MAX_COUNT or face_count > MAX_COUNT or face_count == 0:
        raise MeshError(f"{path}: mesh {shape_index} claims {vertex_count} vertices and {face_count} "
                        "triangles (a corrupt file?)")
    real = "<f8" if flags & DOUBLE_PRECISION else "<f4"
    vertices = stream.array(real, vertex_count * 3).reshape(-1, 3)
    normals = stream.array(real, vertex_count * 3).reshape(-1, 3) if flags & HAS_NORMALS else None
    uv = stream.array(real, vertex_count * 2).reshape(-1, 2) if flags & HAS_TEXCOORDS else None
    if flags & HAS_COLORS:
        stream.array(real, vertex_count * 3)
    faces = stream.array("<u4", face_count * 3).reshape(-1, 3).astype(np.int64)
    if faces.max() >= vertex_count:
        raise MeshError(f"{path} has a face index outside its {vertex_count} vertices")
    corner_uv = None if uv is None else uv[faces].reshape(-1, 6)
    return checked(path, Mesh(vertices, faces, normals, corner_uv))


def _mesh_offset(path: Path, data: bytes, shape_index: int) -> int:
    """Byte offset of mesh ``shape_index``: 0 for the first, else from the file's end table."""
    if shape_index == 0:
        return 0
    version = struct.unpack_from("<H", data, 2)[0]
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    if shape_index >= count:
        raise MeshError(f"{path}: shape_index {shape_index} is out of range (the file holds {count} "
                        f"mesh{'es' if count != 1 else ''}, 0 .. {count - 1})")
    width, code = (8, "<Q") if version >= 4 else (4, "<I")
    at = len(data) - 4 - width * (count - shape_index)
    if at < 0:
        raise MeshError(f"{path}: its table of meshes is cut short (a corrupt file?)")
    offset = struct.unpack_from(code, data, at)[0]
    if offset + 4 > len(data):
        raise MeshError(f"{path}: mesh {shape_index} starts at byte {offset}, past the file's end")
    return offset


class _Inflated:
    """The zlib stream of one mesh, inflated as it is read (never more than asked for)."""

    def __init__(self, path: Path, compressed: bytes):
        self.path = path
        self.inflater = zlib.decompressobj()
        self.compressed = compressed
        self.buffer = b""

    def read(self, size: int) -> bytes:
        while len(self.buffer) < size:
            if not self.compressed and not self.inflater.unconsumed_tail:
                raise MeshError(f"{self.path}: the mesh data ends early (a truncated file?)")
            try:
                pending = self.inflater.unconsumed_tail or self.compressed
                self.compressed = b""
                self.buffer += self.inflater.decompress(pending, max(size - len(self.buffer), 1 << 16))
            except zlib.error as exc:
                raise MeshError(f"{self.path}: its zlib stream is corrupt ({exc})") from None
            if self.inflater.eof and len(self.buffer) < size:
                raise MeshError(f"{self.path}: the mesh data ends early (a truncated file?)")
        out, self.buffer = self.buffer[:size], self.buffer[size:]
        return out

    def unpack(self, code: str) -> tuple:
        return struct.unpack(code, self.read(struct.calcsize(code)))

    def cstring(self) -> str:
        name = bytearray()
        while (byte := self.read(1)) != b"\0":
            name += byte
            if len(name) > 1 << 16:
                raise MeshError(f"{self.path}: the mesh's name has no end (a corrupt file?)")
        return name.decode("utf-8", "replace")

    def array(self, dtype: str, count: int) -> np.ndarray:
        size = np.dtype(dtype).itemsize * count
        return np.frombuffer(self.read(size), dtype=dtype).astype(
            np.int64 if dtype.startswith("<u") else np.float64)
