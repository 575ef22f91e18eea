"""Mesh files and vertex normals, for every scene reader.

:func:`read_mesh_file` reads a mesh (PLY, OBJ and whatever else trimesh reads) with the vertex
normals the file holds, checked; a face of more than three corners (a quad, a polygon) becomes
a fan of triangles from its first corner, as Mitsuba 3's OBJ loader makes it
(src/shapes/obj.cpp: each corner after the third makes a triangle with the first and the one
before it; like Mitsuba, tracer takes polygons to be convex). :func:`angle_weighted_normals`
computes vertex normals where a file has none and a scene asks for smooth shading, as Mitsuba 3
does: each face adds its unit normal weighted by its angle at the vertex (Thürmer and Wüthrich
1998, "Computing vertex normals from polygonal facets", JGT 3(1); checked against Mitsuba 3.9's
``vertex_normals`` on a fan of unequal faces, where area and uniform weights differ).
"""

from __future__ import annotations

import io
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Coordinates beyond this magnitude are refused (the scene readers' MAX_COORDINATE).
MAX_COORDINATE = 1e15
# A vertex normal whose length is within this of 1 is unit already (float64 rounding of a
# normalization is ~1e-16).
UNIT_TOLERANCE = 1e-12

# An OBJ face line of four corners or more.
_OBJ_POLYGON = re.compile(r"^[ \t]*f(?:[ \t]+\S+){4,}", re.MULTILINE)


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file, the caller the key."""


@dataclass
class Mesh:
    """A triangle mesh as read.

    vertices : (V, 3) float64.   faces : (F, 3) int64 indices into vertices.
    normals : (V, 3) float64 unit vertex normals from the file (normalized unless unit already),
        or None if it has none.
    corner_uv : (F, 6) float64 texture coordinates (u, v) of each triangle's three corners as
        the file gives them, or None if it has none.
    attributes : a PLY file's other vertex and face properties by Mitsuba's names
        (``vertex_color``, ``face_weight``: :func:`ply_attributes`), each (F, 3, C) float64, its
        value at each triangle's three corners (a face's value at all three), C = 1, 3 or 4.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    attributes: dict[str, np.ndarray] = field(default_factory=dict)


def import_trimesh():
    """The trimesh module. Its first import runs optional imports inside ``except
    BaseException``, which would swallow a Ctrl-C or SIGTERM arriving then (the render went on
    and exited 0): signals are held during the import and raised right after it."""
    from .. import interrupts

    with interrupts.deferred() as arrived:
        import trimesh
    if arrived:
        raise KeyboardInterrupt
    return trimesh


def read_mesh_file(mesh_path: Path) -> Mesh:
    """The triangles (and vertex normals, if the file has them) of ``mesh_path``, with the
    file's vertices and winding exactly as written, its polygons made fans of triangles.
    Raises MeshError."""
    trimesh = import_trimesh()
    try:
        found = mesh_path.is_file()
    except OSError as exc:  # a name too long for the file system, and the like
        raise MeshError(f"cannot look up mesh {str(mesh_path)[:80]}...: {exc.strerror}") from None
    if not found:
        # A FIFO or a device would block or never end in trimesh's reader: refused, and named.
        there = mesh_path.exists()
        raise MeshError(f"mesh file is not a regular file (a FIFO, socket, device or folder): {mesh_path}"
                        if there else f"mesh file not found: {mesh_path}")
    try:
        # trimesh casts the file's numbers with numpy: a coordinate past float32 (1e39) prints
        # an overflow warning on stderr. The checks below refuse what it became, in one line.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            vertices, faces, normals, corner_uv, attributes = _load(trimesh, mesh_path)
    except MeshError:
        raise
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"cannot read mesh {mesh_path}: {exc}") from None
    mesh = checked(mesh_path, Mesh(vertices, faces, normals, corner_uv))
    for name, values in attributes.items():
        if not np.all(np.isfinite(values)):
            raise MeshError(f"{mesh_path} has a mesh attribute ({name}) that is not finite")
    mesh.attributes = attributes
    return mesh


def checked(mesh_path: Path, mesh: Mesh) -> Mesh:
    """``mesh`` with its normals made unit, once its arrays are checked: 3-D finite vertices in
    range, face indices among them, one finite nonzero normal (and uv pair) per used vertex.
    Raises MeshError naming ``mesh_path``."""
    vertices, faces, normals, corner_uv = mesh.vertices, mesh.faces, mesh.normals, mesh.corner_uv
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"{mesh_path} holds no faces (triangles or polygons)")
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"{mesh_path} holds no 3-D vertices")
    if not np.all(np.isfinite(vertices)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))[0])
        raise MeshError(f"{mesh_path} has a non-finite vertex (vertex {bad}: {vertices[bad].tolist()})")
    if np.max(np.abs(vertices)) > MAX_COORDINATE:
        bad = int(np.argmax(np.max(np.abs(vertices), axis=1)))
        raise MeshError(f"{mesh_path} has a vertex beyond the coordinate range +-{MAX_COORDINATE:g} "
                        f"(vertex {bad})")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"{mesh_path} has a face index outside its {len(vertices)} vertices")
    if normals is not None:
        if normals.shape != vertices.shape or not np.all(np.isfinite(normals)):
            raise MeshError(f"{mesh_path} has vertex normals that are not one finite 3-vector per vertex")
        length = np.linalg.norm(normals, axis=1)
        used = np.zeros(len(vertices), dtype=bool)
        used[faces.ravel()] = True
        if np.any(used & (length == 0.0)):
            bad = int(np.flatnonzero(used & (length == 0.0))[0])
            raise MeshError(f"{mesh_path} has a zero vertex normal (vertex {bad})")
        # Rows already unit to rounding are kept as written: normalizing them again moves about
        # one in three by an ulp, and a scene written out (tracer convert) and read back must
        # hold the very same normals.
        renormalize = np.abs(length - 1.0) > UNIT_TOLERANCE
        unit = normals / np.where(length > 0.0, length, 1.0)[:, None]
        normals = np.where(renormalize[:, None], unit, normals)
    if corner_uv is not None and (corner_uv.shape != (len(faces), 6) or not np.all(np.isfinite(corner_uv))):
        raise MeshError(f"{mesh_path} has texture coordinates that are not finite pairs, one per corner")
    return Mesh(vertices, faces, normals, corner_uv)


def _load(trimesh, mesh_path: Path) -> tuple:
    """Vertices, faces, file normals (or None), corner texture coordinates (or None) and a PLY
    file's attributes (``Mesh.attributes``; empty for other formats).
    trimesh's ``load_mesh`` drops the normals a
    file holds (its cache is reset after loading), so PLY and OBJ go through trimesh's
    format readers, whose output keeps them; other formats have none we read."""
    suffix = mesh_path.suffix.lower()
    text = None
    if suffix == ".ply":
        with open(mesh_path, "rb") as fh:
            parts = [trimesh.exchange.ply.load_ply(fh)]
    elif suffix == ".obj":
        with open(mesh_path, "r", encoding="utf-8", errors="replace") as fh:
            text = _fan_triangulated_obj(fh.read())
        loaded = trimesh.exchange.obj.load_obj(io.StringIO(text), maintain_order=True)
        parts = list(loaded.get("geometry", {}).values()) if "geometry" in loaded else [loaded]
    else:
        mesh = trimesh.load_mesh(str(mesh_path), process=False)
        if not isinstance(mesh, trimesh.Trimesh):
            raise MeshError(f"{mesh_path} holds no triangle mesh")
        return (np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), None,
                None, {})
    if not parts:
        raise MeshError(f"{mesh_path} holds no triangle mesh")
    vertices, faces, normals, corner_uv, offset = [], [], [], [], 0
    attributes: dict[str, np.ndarray] = {}
    for part in parts:
        v = np.asarray(part.get("vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
        f = np.asarray(part.get("faces", np.zeros((0, 3))), dtype=np.int64)
        f = f.reshape(-1, f.shape[-1] if f.ndim == 2 else 3)
        if suffix == ".ply":  # one part
            attributes = ply_attributes(part.get("metadata", {}).get("_ply_raw", {}), f, mesh_path)
        f = fan_triangles(f)
        n = part.get("vertex_normals")
        uv = getattr(part.get("visual"), "uv", None)
        vertices.append(v)
        faces.append(f + offset)
        normals.append(None if n is None else np.asarray(n, dtype=np.float64).reshape(-1, 3))
        corner_uv.append(None if uv is None or len(uv) != len(v)
                         else np.asarray(uv, dtype=np.float64)[f].reshape(-1, 6))
        offset += len(v)
    all_normals = None if any(n is None for n in normals) else np.concatenate(normals)
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    if text is not None:  # an OBJ's coordinates belong to its face corners: read from its text
        uv = _obj_corner_uv(text, vertices[faces], mesh_path)
        if all_normals is None:  # trimesh dropped them (``_obj_corner_normals``)
            corner_normals = _obj_corner_normals(text, vertices[faces], mesh_path)
            if corner_normals is not None:  # a vertex per corner, each with its own normal
                vertices = vertices[faces].reshape(-1, 3)
                faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
                all_normals = corner_normals.reshape(-1, 3)
    else:
        uv = None if any(c is None for c in corner_uv) else np.concatenate(corner_uv)
    return vertices, faces, all_normals, uv, attributes


# Mitsuba's PLY reader (src/shapes/ply.h, find_other_fields) keeps these as the vertex and face
# themselves; every other property is an attribute.
_PLY_RESERVED = {"vertex": {"x", "y", "z", "nx", "ny", "nz", "u", "v", "s", "t", "texture_u", "texture_v"},
                 "face": {"vertex_indices", "vertex_index"}}
# The postfix categories of a multi-field attribute: {prefix}_x, _y, _z, _w; _r, _g, _b, _a;
# _0 .. _3; _1 .. _4 (Mitsuba's ``postfixes``; the colour category names it {prefix}_color).
_POSTFIXES = ("xyzw", "rgba", "0123", "1234")


def _ply_groups(names: list[str]) -> list[tuple[str, list[str]]]:
    """``(attribute name without the element's prefix, its fields)`` of a PLY element's
    property names, grouped as Mitsuba 3.9.1 groups them: r, g, b (and a) or red, green, blue
    (and alpha) make ``color``; then consecutive ``{prefix}_{postfix}`` fields of one postfix
    category, starting from its first letter, make ``{prefix}`` (``{prefix}_color`` for r, g,
    b, a), kept only with 1 or 3 fields. Fields Mitsuba ignores (no one-letter postfix, a broken
    sequence, a prefix seen before) are left out, as it leaves them out."""
    groups: list[tuple[str, list[str]]] = []
    present = set(names)
    colour = next((c for c in (("r", "g", "b", "a"), ("red", "green", "blue", "alpha"))
                   if set(c[:3]) <= present), None)
    if colour is not None:
        groups.append(("color", [c for c in colour if c in present]))
    taken = set(colour or ())
    seen: set[str] = set()
    prefix, category, fields = None, -1, []

    def flush() -> None:
        if prefix is not None and len(fields) in (1, 3):
            groups.append((prefix + ("_color" if category == 1 else ""), list(fields)))
            seen.add(prefix)

    for name in names:
        if name in taken:
            continue
        head, _, postfix = name.rpartition("_")
        if not head or len(postfix) != 1:
            flush()
            prefix, fields = None, []
            continue
        if prefix is not None and head == prefix:
            if len(fields) < 4 and postfix == _POSTFIXES[category][len(fields)]:
                fields.append(name)
            else:  # a broken sequence: Mitsuba drops the whole attribute, and the prefix after it
                seen.add(prefix)
                prefix, fields = None, []
            continue
        flush()
        prefix, fields = None, []
        starts = [i for i, letters in enumerate(_POSTFIXES) if letters[0] == postfix]
        if head in seen or not starts:
            continue
        prefix, category, fields = head, starts[0], [name]
    flush()
    return groups


def ply_attributes(raw: dict, faces: np.ndarray, mesh_path: Path) -> dict[str, np.ndarray]:
    """A PLY file's attributes at the corners of its triangles (``Mesh.attributes``), from
    trimesh's raw elements ``raw`` and the file's faces ``faces`` (F, k) before the fan
    triangulation: ``vertex_NAME`` interpolated between corners, ``face_NAME`` constant on each
    face (on each triangle of its fan). Values are taken as written (Mitsuba does not scale
    integer colours into [0, 1] either)."""
    out: dict[str, np.ndarray] = {}
    triangles = fan_triangles(faces)
    per_face = max(faces.shape[1] - 2, 1)
    for element in ("vertex", "face"):
        data = raw.get(element, {}).get("data")
        # trimesh gives a binary file's element as a structured array, an ASCII file's as a
        # dict of (N, 1) columns, both in the header's order.
        if isinstance(data, dict):
            columns = {n: np.asarray(c) for n, c in data.items()}
        elif data is not None and data.dtype.names is not None:
            columns = {n: data[n] for n in data.dtype.names if data.dtype[n].names is None}
        else:
            continue
        names = [n for n, c in columns.items() if n not in _PLY_RESERVED[element]
                 and c.ndim <= 2 and c.size == len(c) and c.dtype.kind in "fiu"]
        for name, fields in _ply_groups(names):
            values = np.stack([np.asarray(columns[f], dtype=np.float64).reshape(-1) for f in fields], axis=1)
            if element == "vertex":
                out[f"vertex_{name}"] = values[triangles]  # (F, 3 corners, C)
            else:
                if len(values) * per_face != len(triangles):
                    raise MeshError(f"{mesh_path}: face attributes need faces of one size (its faces have "
                                    "several)")
                per_triangle = np.repeat(values, per_face, axis=0)
                out[f"face_{name}"] = np.repeat(per_triangle[:, None, :], 3, axis=1)
    return out


def fan_triangles(faces: np.ndarray) -> np.ndarray:
    """(F, k) faces of k >= 3 corners -> (F (k - 2), 3) triangles: each face's fan (c0, c1, c2),
    (c0, c2, c3), ..., the faces in order. Faces of fewer corners are returned as they are.
    (trimesh gives a PLY file's faces so when they all have k corners; faces of mixed sizes it
    splits itself, into the same triangles, grouped by size.)"""
    corners = faces.shape[1]
    if corners <= 3:
        return faces
    second = np.arange(1, corners - 1)
    first = np.broadcast_to(faces[:, :1], (len(faces), corners - 2))
    return np.stack([first, faces[:, second], faces[:, second + 1]], axis=2).reshape(-1, 3)


def _fan_triangulated_obj(text: str) -> str:
    """An OBJ file's text with each face line of k > 3 corners made k - 2 triangle lines, the fan
    :func:`fan_triangles` makes. Done on the text, before trimesh reads it: trimesh keeps the
    normals of triangles but drops a file's normals when all its faces have the same number of
    corners above three, and they cannot be put back afterwards: an OBJ vertex is a triple
    (position, texture coordinate, normal) that only the face lines spell out."""
    if not _OBJ_POLYGON.search(text):
        return text
    lines = text.split("\n")
    for i, line in enumerate(lines):
        tokens = line.split()
        if len(tokens) > 4 and tokens[0] == "f":
            first = tokens[1]
            lines[i] = "\n".join(f"f {first} {a} {b}" for a, b in zip(tokens[2:-1], tokens[3:], strict=True))
    return "\n".join(lines)


def _obj_corner_uv(text: str, corners: np.ndarray, mesh_path: Path) -> np.ndarray | None:
    """(F, 6) texture coordinates of an OBJ's triangle corners, or None if it has none: each
    face corner's ``vt`` index, read from the text, since trimesh keeps one coordinate per
    vertex and an OBJ vertex may have several (a seam). A corner without one gets (0, 0)."""
    return _obj_corner_values(text, corners, mesh_path, "vt", 1, "texture coordinate", (0.0, 0.0))


def _obj_corner_normals(text: str, corners: np.ndarray, mesh_path: Path) -> np.ndarray | None:
    """(F, 9) normals of an OBJ's triangle corners by their ``vn`` indices, read from the text,
    or None unless every corner has one: for the files whose normals trimesh drops (it does when
    a vertex is referenced by no face, a valid OBJ)."""
    return _obj_corner_values(text, corners, mesh_path, "vn", 2, "normal", None)


def _obj_corner_values(text: str, corners: np.ndarray, mesh_path: Path, tag: str, field: int, what: str,
                       missing: tuple | None) -> np.ndarray | None:
    """The ``tag`` values (``vt``: 2 numbers, ``vn``: 3) of an OBJ's triangle corners as (F, 3 k),
    by each face corner's index in slash-separated ``field`` (1-based, or negative: counted back
    from the latest), or None if the file has none. A corner without one gets ``missing``, or
    with ``missing`` None the result is None. The faces are those trimesh read, in order:
    checked against ``corners`` (F, 3, 3), their positions."""
    if not re.search(rf"^[ \t]*{tag}[ \t]", text, re.MULTILINE):
        return None  # none in the file: no need to read the faces again
    size = 2 if tag == "vt" else 3
    positions: list[list[float]] = []
    values: list[list[float]] = []
    position_index: list[int] = []
    value_index: list[int] = []
    for line in text.split("\n"):
        tokens = line.split()
        if not tokens:
            continue
        if tokens[0] == "v" and len(tokens) >= 4:
            positions.append([float(t) for t in tokens[1:4]])
        elif tokens[0] == tag and len(tokens) >= size + 1:
            values.append([float(t) for t in tokens[1:size + 1]])
        elif tokens[0] == "f" and len(tokens) == 4:
            for corner in tokens[1:]:
                fields = corner.split("/")
                p = int(fields[0])
                k = int(fields[field]) if len(fields) > field and fields[field] else 0
                position_index.append(p - 1 if p > 0 else len(positions) + p)
                value_index.append(-1 if k == 0 else (k - 1 if k > 0 else len(values) + k))
    if not values or not value_index:
        return None
    ours = np.asarray(positions, dtype=np.float64)[np.asarray(position_index)].reshape(-1, 3, 3)
    if ours.shape != corners.shape or not np.array_equal(ours, corners):
        raise MeshError(f"{mesh_path}: its {what}s could not be matched to its faces (convert it to PLY)")
    index = np.asarray(value_index)
    if index.max() >= len(values) or index.min() < -1:
        raise MeshError(f"{mesh_path} has a face corner whose {what} index is out of range")
    if missing is None and index.min() < 0:
        return None
    table = np.concatenate([np.asarray(values, dtype=np.float64), np.zeros((1, size))])
    if missing is not None:
        table[-1] = missing
    return table[index].reshape(-1, 3 * size)


def angle_weighted_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals: the sum over a vertex's faces of each face's unit normal
    times the face's angle at that vertex, normalized. Zero-area faces add nothing; a vertex
    with nothing added gets a zero normal (its triangles then shade flat)."""
    tri = vertices[faces]  # (F, 3 corners, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(cross, axis=1)
    unit = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0.0)
    out = np.zeros_like(vertices, dtype=np.float64)
    for corner in range(3):
        e1 = tri[:, (corner + 1) % 3] - tri[:, corner]
        e2 = tri[:, (corner + 2) % 3] - tri[:, corner]
        norms = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
        cos = np.divide(np.einsum("ij,ij->i", e1, e2), norms, out=np.zeros(len(faces)), where=norms > 0.0)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        np.add.at(out, faces[:, corner], unit * angle[:, None])
    norm = np.linalg.norm(out, axis=1)
    return np.divide(out, norm[:, None], out=np.zeros_like(out), where=norm[:, None] > 0.0)
