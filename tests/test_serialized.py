"""Mitsuba's serialized mesh format (tracer/scene/serialized.py), against files written here
from the format's specification, and its use from a Mitsuba XML scene.

The files are built byte by byte in this module (``serialized_file``) so that every flag,
both versions and both precisions are covered; the reader's agreement with Mitsuba 3.9.1 itself
was checked on mitsuba-data's matpreview.serialized (positions, faces and texture coordinates
identical, normals within 1.4e-7: Mitsuba renormalizes them in float32).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.scene.mesh import MeshError
from tracer.scene.serialized import read_serialized

TRIANGLE_PAIR = (np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]),
                 np.array([[0, 1, 2], [0, 2, 3]]))


def mesh_stream(vertices, faces, *, version=4, double=False, normals=None, uv=None, colors=None,
                name="mesh") -> bytes:
    """One mesh as the specification lays it out: header, then the zlib stream."""
    flags = (0x2000 if double else 0x1000) | (0x0001 if normals is not None else 0) | \
        (0x0002 if uv is not None else 0) | (0x0008 if colors is not None else 0)
    real = "<f8" if double else "<f4"
    body = struct.pack("<I", flags)
    if version == 4:
        body += name.encode() + b"\0"
    body += struct.pack("<QQ", len(vertices), len(faces))
    for block in (vertices, normals, uv, colors):
        if block is not None:
            body += np.asarray(block, dtype=real).tobytes()
    body += np.asarray(faces, dtype="<u4").tobytes()
    return struct.pack("<HH", 0x041C, version) + zlib.compress(body)


def serialized_file(streams: list[bytes], version: int = 4) -> bytes:
    """Meshes one after another, then the table of their offsets and their count."""
    offsets, data = [], b""
    for stream in streams:
        offsets.append(len(data))
        data += stream
    code = "<Q" if version == 4 else "<I"
    return data + b"".join(struct.pack(code, o) for o in offsets) + struct.pack("<I", len(streams))


@pytest.mark.parametrize("version", [3, 4])
@pytest.mark.parametrize("double", [False, True])
def test_every_block_and_every_mesh_of_a_file_reads_back(tmp_path, version, double):
    # Three meshes with different blocks each: the flags decide what follows the positions,
    # and shape_index finds each mesh through the end-of-file table.
    rng = np.random.default_rng(1)
    vertices, faces = TRIANGLE_PAIR
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    uv = rng.random((4, 2))
    colors = rng.random((4, 3))
    streams = [mesh_stream(vertices, faces, version=version, double=double),
               mesh_stream(vertices + 5.0, faces[::-1], version=version, double=double, normals=normals,
                           colors=colors),
               mesh_stream(vertices * 2.0, faces, version=version, double=double, uv=uv, normals=normals)]
    path = tmp_path / "three.serialized"
    path.write_bytes(serialized_file(streams, version))
    first, second, third = (read_serialized(path, i) for i in range(3))
    np.testing.assert_array_equal(first.vertices, vertices)
    assert first.normals is None and first.corner_uv is None
    np.testing.assert_array_equal(second.vertices, vertices + 5.0)
    np.testing.assert_array_equal(second.faces, faces[::-1])
    np.testing.assert_array_equal(second.normals, normals)
    assert second.corner_uv is None  # the colours in between were skipped, not taken for uv
    precision = 0.0 if double else 1e-7
    np.testing.assert_allclose(third.corner_uv, uv[faces].reshape(-1, 6), atol=precision)
    np.testing.assert_array_equal(third.vertices, vertices * 2.0)


@pytest.mark.parametrize("damage, message", [
    (lambda data: b"\x06\x00" + data[2:], "not a Mitsuba serialized mesh"),
    (lambda data: data[:2] + struct.pack("<H", 5) + data[4:], "version 5 is not supported"),
    (lambda data: data[:20], "ends early"),
    (lambda data: data[:4] + b"\x78\x9c" + b"\xff" * 30, "zlib stream is corrupt"),
    (lambda data: b"\x1c", "has 1 bytes"),
])
def test_broken_files_are_refused_naming_the_file(tmp_path, damage, message):
    path = tmp_path / "broken.serialized"
    path.write_bytes(damage(serialized_file([mesh_stream(*TRIANGLE_PAIR)])))
    with pytest.raises(MeshError, match=message) as caught:
        read_serialized(path)
    assert str(path) in str(caught.value)


def test_a_shape_index_past_the_last_mesh_is_refused(tmp_path):
    path = tmp_path / "one.serialized"
    path.write_bytes(serialized_file([mesh_stream(*TRIANGLE_PAIR)]))
    with pytest.raises(MeshError, match=r"shape_index 1 is out of range \(the file holds 1 mesh, 0 .. 0\)"):
        read_serialized(path, 1)


def test_a_face_index_past_the_vertices_is_refused(tmp_path):
    path = tmp_path / "bad.serialized"
    path.write_bytes(serialized_file([mesh_stream(TRIANGLE_PAIR[0], [[0, 1, 7]])]))
    with pytest.raises(MeshError, match="face index outside its 4 vertices"):
        read_serialized(path)


SCENE = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0.5, 0.5, 3" target="0.5, 0.5, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
  </sensor>
  <shape type="serialized">
    <string name="filename" value="{name}"/>
    <integer name="shape_index" value="{index}"/>
    <transform name="to_world"><translate x="1"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter>
  </shape>
</scene>
"""


def test_a_scene_takes_the_mesh_it_names_transformed(tmp_path):
    # The second mesh of the file, moved by to_world: its vertices in the scene are the file's
    # plus (1, 0, 0), and its normals (which the file has) shade it smoothly.
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    data = serialized_file([mesh_stream(*TRIANGLE_PAIR),
                            mesh_stream(TRIANGLE_PAIR[0] * 0.5, TRIANGLE_PAIR[1], normals=normals)])
    (tmp_path / "two.serialized").write_bytes(data)
    (tmp_path / "scene.xml").write_text(SCENE.format(name="two.serialized", index=1))
    scene = tracer.load_scene(tmp_path / "scene.xml")
    np.testing.assert_allclose(np.sort(scene.vertices, axis=0),
                               np.sort(TRIANGLE_PAIR[0] * 0.5 + [1.0, 0.0, 0.0], axis=0))
    assert len(scene.faces) == 2 and len(scene.corner_normals) == 2


def test_a_scene_with_a_broken_mesh_names_the_file_and_line(tmp_path):
    (tmp_path / "broken.serialized").write_bytes(b"\x1c\x04\x04\x00garbage")
    (tmp_path / "scene.xml").write_text(SCENE.format(name="broken.serialized", index=0))
    with pytest.raises(InputError, match="broken.serialized") as caught:
        tracer.load_scene(tmp_path / "scene.xml")
    assert "scene.xml:7" in str(caught.value)
