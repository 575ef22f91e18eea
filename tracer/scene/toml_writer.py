"""Write any :class:`Scene` as tracer's TOML scene format (``tracer convert``).

The TOML file renders exactly what the scene renders: loading it gives a scene with the same
``digest``. Every number is written as the shortest text that reads back as the same float64
(Python's ``repr``), quads, spheres and the camera from the values the scene was built from
(the shape records), materials parameter by parameter from the material table, and every
triangle shape other than a quad (meshes, Mitsuba cubes and disks, icospheres read as meshes)
as a binary PLY file beside the TOML: its vertex block of the scene, float32 as the scene holds
them, with the vertex normals in float64 (``nx ny nz``) for a smoothly shaded shape, which the
TOML names with ``normals = "vertex"``.

No TOML library writes here: the format needs tables, arrays of tables, strings, booleans and
numbers only, and a small writer that quotes strings and keys itself keeps tracer free of a
dependency for it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .. import __version__, materials
from ..atomic import atomic_write_many, bytes_writer, text_writer
from ..camera import ORTHOGRAPHIC
from ..errors import InputError
from ..textures import BUMP_MAP, NORMAL_MAP
from .icosphere import unit_icosphere
from .model import Scene, Shape

# How the refusal names a perturbation kind.
_MAPS = {NORMAL_MAP: "normal map", BUMP_MAP: "bump map"}
_BARE_KEY = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")


def write_scene(scene: Scene, path: str | os.PathLike[str], source: str | None = None) -> list[Path]:
    """Write ``scene`` as the TOML file ``path`` and its meshes as PLY files beside it, all
    atomically and together (``atomic.atomic_write_many``: the TOML renamed last). Returns the
    files written. ``source`` is named in the TOML's first comment.

    A mesh file is ``STEM_shapeN.ply``, or, where that name is taken by a file this must not
    replace, ``STEM_shapeN_2.ply``, ``_3``, ...: a file replaced must be a PLY that tracer wrote
    (an earlier conversion's) and must not be one the scene itself reads (``_inputs``), so that
    converting never overwrites an input or a user's own file. Raises InputError if the scene
    cannot be written as TOML."""
    if scene.textures.textured:
        # The TOML format has no textures yet: writing their means would render another image.
        names = sorted({b.param for b in scene.textures.bindings}
                       | ({"opacity"} if scene.textures.cutouts else set())
                       | {_MAPS[kind] for kind, *_ in scene.textures.perturbations.values()}
                       | ({"radiance"} if scene.textures.emitters else set()))
        raise InputError(f"the scene has textures ({', '.join(names)}), which tracer's TOML format does not "
                         "hold yet: render the XML scene itself", str(scene.path))
    environment_map = None
    if scene.environment is not None and scene.environment.kind != "constant":
        # The TOML refers to the map's image file, which must be where the scene found it; a map
        # of unknown origin would need its texels written beside the TOML: refused, never lost.
        if not scene.environment.file or not Path(scene.environment.file).is_file():
            raise InputError("the scene has an environment map whose image file is not known or not "
                             "there, which tracer convert does not write yet: render the scene itself",
                             str(scene.path))
        environment_map = _relative_to(Path(scene.environment.file), Path(path).parent)
    projecting = [image.kind for image in scene.point_images if image is not None]
    if projecting:
        raise InputError(f"the scene has lights that project images ({', '.join(sorted(set(projecting)))}), "
                         "which tracer's TOML format does not hold yet: render the XML scene itself",
                         str(scene.path))
    target = Path(path)
    inputs = _inputs(scene)
    taken: set[Path] = set()

    def mesh_name(i: int) -> str:
        base, number = f"{target.stem}_shape{i}", 1
        while True:
            name = f"{base}.ply" if number == 1 else f"{base}_{number}.ply"
            candidate = target.parent / name
            if candidate not in taken and _replaceable(candidate, inputs):
                taken.add(candidate)
                return name
            number += 1

    text, meshes = scene_to_toml(scene, mesh_name, source, environment_map)
    files = [(target.parent / name, bytes_writer(data)) for name, data in meshes]
    files.append((target, text_writer(text)))
    atomic_write_many(files)
    return [file for file, _ in files]


def _relative_to(file: Path, folder: Path) -> str:
    """``file`` as a TOML in ``folder`` names it: relative where it can be, else absolute."""
    try:
        return os.path.relpath(file.resolve(), folder.resolve())
    except (OSError, ValueError):  # another drive, or a path that cannot be resolved
        return str(file.resolve())


def _inputs(scene: Scene) -> set[Path]:
    """The files the scene was read from, resolved: the scene file and its shapes' mesh files."""
    files = [scene.path] + [s.record["file"] for s in scene.shapes if isinstance(s.record.get("file"), str)]
    resolved = set()
    for file in files:
        try:
            resolved.add(Path(file).resolve())
        except (OSError, RuntimeError):
            continue
    return resolved


# The comment every PLY that tracer writes carries in its header (``_ply``).
WRITTEN_BY_TRACER = b"comment written by tracer"


def _replaceable(candidate: Path, inputs: set[Path]) -> bool:
    """Whether a mesh may be written at ``candidate``: nothing is there, or a PLY that tracer
    wrote and that the scene does not read."""
    try:
        if not candidate.exists() and not candidate.is_symlink():
            return True
        if candidate.resolve() in inputs or not candidate.is_file() or candidate.is_symlink():
            return False
        with open(candidate, "rb") as fh:
            head = fh.read(256)
    except OSError:
        return False
    return head.startswith(b"ply\n") and WRITTEN_BY_TRACER + b"\n" in head


def scene_to_toml(scene: Scene, mesh_name, source: str | None = None,
                  environment_map: str | None = None) -> tuple[str, list[tuple[str, bytes]]]:
    """The TOML text of ``scene`` and its PLY files as ``(file name, bytes)``; ``mesh_name(i)``
    names the PLY file of shape i (relative to the TOML's folder), ``environment_map`` the image
    file of its environment map (relative to that folder, or absolute), if it has one."""
    origin = f" from {_one_line(source)}" if source else ""
    lines = [f"# tracer scene written by tracer {__version__}{origin}",
             "# (docs/SCENE_FORMAT.md; every number reads back as the same float64)", ""]
    if scene.render_defaults:
        lines.append("[render]")
        for key in ("spp", "strategy", "light_sampling", "sampler"):
            if key in scene.render_defaults:
                lines.append(f"{key} = {_value(scene.render_defaults[key])}")
        lines.append("")
    cam = scene.camera
    lines += ["[camera]", f"origin = {_value(cam.origin)}", f"target = {_value(cam.target)}",
              f"up = {_value(cam.up)}"]
    if cam.projection == ORTHOGRAPHIC:
        lines += [f"projection = {_value(cam.projection)}", f"view_width = {_value(float(cam.view_width))}"]
    else:
        lines.append(f"fov = {_value(float(cam.fov))}")
        if cam.thin_lens:
            lines += [f"aperture_radius = {_value(float(cam.aperture_radius))}",
                      f"focus_distance = {_value(float(cam.focus_distance))}"]
    lines += [f"width = {int(cam.width)}", f"height = {int(cam.height)}"]
    if cam.mirrored:
        lines.append("mirrored = true")
    lines.append("")
    names = scene.materials.names
    if len(set(names[1:])) != len(names) - 1:
        raise InputError("two materials share a name: the TOML format names each once", scene.path)
    for row in range(1, len(names)):
        lines += _material(scene, row)
    meshes: list[tuple[str, bytes]] = []
    blocks = _vertex_blocks(scene)
    for i, shape in enumerate(scene.shapes):
        lines += ["[[shapes]]"]
        if shape.type == "quad":
            rec = shape.record
            lines += ["type = \"quad\"", f"origin = {_value(rec['origin'])}",
                      f"edge1 = {_value(rec['edge1'])}", f"edge2 = {_value(rec['edge2'])}"]
        elif shape.type == "sphere" and shape.sphere >= 0:
            lines += ["type = \"sphere\"", f"center = {_value(shape.record['center'])}",
                      f"radius = {_value(float(shape.record['radius']))}"]
        elif shape.type == "sphere":
            lines += ["type = \"sphere\"", f"center = {_value(shape.record['center'])}",
                      f"radius = {_value(float(shape.record['radius']))}",
                      f"subdivisions = {int(shape.record['subdivisions'])}"]
        else:
            name = mesh_name(i)
            data, smooth = _ply(scene, i, shape, *blocks[i])
            meshes.append((name, data))
            lines += ["type = \"mesh\"", f"file = {_string(name)}"]
            if smooth:
                lines.append("normals = \"vertex\"")
        if shape.material:
            lines.append(f"material = {_string(names[shape.material])}")
        if np.any(shape.emission):
            lines.append(f"emission = {_value(shape.emission)}")
        lines.append("")
    for i, (position, intensity) in enumerate(zip(scene.point_position, scene.point_intensity, strict=True)):
        if scene.point_cutoff[i] >= 180.0:
            lines += ["[[lights]]", "type = \"point\"", f"position = {_value(position)}",
                      f"intensity = {_value(intensity)}", ""]
            continue
        lines += ["[[lights]]", "type = \"spot\"", f"position = {_value(position)}",
                  f"intensity = {_value(intensity)}", f"direction = {_value(scene.point_axis[i])}",
                  f"cutoff_angle = {_value(float(scene.point_cutoff[i]))}",
                  f"beam_width = {_value(float(scene.point_beam[i]))}", ""]
    for direction, irradiance in zip(scene.directional_direction, scene.directional_irradiance, strict=True):
        lines += ["[[lights]]", "type = \"directional\"", f"direction = {_value(direction)}",
                  f"irradiance = {_value(irradiance)}", ""]
    environment = scene.environment
    if environment is not None and environment.kind == "constant":
        lines += ["[environment]", f"radiance = {_value(environment.radiance)}", ""]
    elif environment is not None:
        if environment_map is None:
            raise ValueError("a scene with an environment map needs the map's file (environment_map)")
        rows = ", ".join(_value(row) for row in np.asarray(environment.to_world, dtype=np.float64))
        lines += ["[environment]", f"map = {_string(environment_map)}",
                  f"scale = {_value(float(environment.scale))}", f"to_world = [{rows}]", ""]
    return "\n".join(lines), meshes


def _material(scene: Scene, row: int) -> list[str]:
    table = scene.materials
    kind = materials.BY_CODE[int(table.kind[row])]
    out = [f"[materials.{_key(table.names[row])}]", f"type = {_string(kind.name)}"]
    if any(p.internal and p.boolean and table.params[row, kind.column(p.name)] != 0.0
           for p in kind.params):
        # A principled inside Mitsuba's twosided, whose back mirrors its front: TOML has no key for it.
        raise InputError(f"material '{table.names[row]}' is a {kind.name} inside Mitsuba's twosided, which "
                         "tracer's TOML format does not hold yet: render the XML scene itself",
                         str(scene.path))
    for p in kind.params:
        if p.internal:  # set by the readers, never written by a scene
            continue
        column = kind.column(p.name)
        values = table.params[row, column: column + p.size]
        if p.choices:
            value: object = p.choices[int(values[0])]
        elif p.boolean:
            value = bool(values[0])
        elif p.size == 1:
            value = float(values[0])
        else:
            value = values
        out.append(f"{p.name} = {_value(value)}")
    if not table.twosided[row]:
        out.append("twosided = false")
    if table.opacity[row] < 1.0:
        out.append(f"opacity = {_value(float(table.opacity[row]))}")
    return out + [""]


def _vertex_blocks(scene: Scene) -> dict[int, tuple[int, int]]:
    """Each triangle shape's range of ``scene.vertices``: readers add a shape's vertices as one
    block, in shape order. Quads and icospheres have blocks of known size, found by their
    faces; a mesh's block runs from the end of the one before to the start of the next (its
    unused vertices included, so that the TOML gives back the very vertex array)."""
    order = [i for i, s in enumerate(scene.shapes) if s.count > 0]
    fixed: dict[int, tuple[int, int]] = {}
    for i in order:
        s = scene.shapes[i]
        faces = scene.faces[s.first: s.first + s.count]
        if s.type == "quad":
            fixed[i] = (int(faces[0, 0]), int(faces[0, 0]) + 4)
        elif s.type == "sphere":
            start = int(faces.min())
            fixed[i] = (start, start + len(unit_icosphere(int(s.record["subdivisions"]))[0]))
    blocks: dict[int, tuple[int, int]] = {}
    position = 0
    for k, i in enumerate(order):
        if i in fixed:
            start, end = fixed[i]
        else:
            start = position
            following = order[k + 1] if k + 1 < len(order) else None
            if following is None:
                end = len(scene.vertices)
            elif following in fixed:
                end = fixed[following][0]
            else:
                s = scene.shapes[i]
                end = int(scene.faces[s.first: s.first + s.count].max()) + 1
        s = scene.shapes[i]
        faces = scene.faces[s.first: s.first + s.count]
        if start != position or faces.min() < start or faces.max() >= end:
            raise InputError(f"shape {i}'s vertices are not one block of the scene's vertex array: it cannot "
                             "be written as TOML", scene.path)
        blocks[i] = (start, end)
        position = end
    return blocks


def _ply(scene: Scene, index: int, shape: Shape, start: int, end: int) -> tuple[bytes, bool]:
    """A binary little-endian PLY of the shape's vertex block and triangles, with float64
    vertex normals when the shape is shaded smoothly; and whether it is."""
    vertices = scene.vertices[start:end]
    faces = scene.faces[shape.first: shape.first + shape.count].astype(np.int64) - start
    corners = (scene.corner_normals[shape.first: shape.first + shape.count]
               if len(scene.corner_normals) else np.zeros((0, 9)))
    smooth = bool(len(corners)) and bool(np.any(corners))
    normals = None
    if smooth:
        corners = corners.reshape(-1, 3, 3)
        normals = np.zeros((len(vertices), 3))
        normals[faces.ravel()] = corners.reshape(-1, 3)
        used = np.zeros(len(vertices), dtype=bool)
        used[faces.ravel()] = True
        if not np.array_equal(normals[faces], corners) or np.any(used & ~np.any(normals, axis=1)):
            raise InputError(f"shape {index} has corners of one vertex with different normals, or a vertex "
                             "without one: its shading cannot be written as a PLY file", scene.path)
    header = ["ply", "format binary_little_endian 1.0", WRITTEN_BY_TRACER.decode("ascii"),
              f"element vertex {len(vertices)}", "property float x", "property float y", "property float z"]
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        header += ["property double nx", "property double ny", "property double nz"]
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    vertex_rows = np.zeros(len(vertices), dtype=fields)
    for axis, name in enumerate("xyz"):
        vertex_rows[name] = vertices[:, axis]
        if normals is not None:
            vertex_rows["n" + name] = normals[:, axis]
    face_rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rows["n"] = 3
    face_rows["i"] = faces
    return ("\n".join(header) + "\n").encode("ascii") + vertex_rows.tobytes() + face_rows.tobytes(), smooth


def _value(value: object) -> str:
    """A TOML value: a string, a boolean, an integer, a float (shortest exact text) or an
    array of floats."""
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(f"TOML scenes hold finite numbers, not {number}")
        return repr(number)
    return "[" + ", ".join(_value(float(v)) for v in np.asarray(value, dtype=np.float64).ravel()) + "]"


_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped."""
    out = []
    for c in text:
        if c in _ESCAPES:
            out.append(_ESCAPES[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04X}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _key(name: str) -> str:
    """A TOML key: bare when it can be, else quoted."""
    return name if name and set(name) <= _BARE_KEY else _string(name)


def _one_line(text: str) -> str:
    return "".join(c if c.isprintable() else "?" for c in text)
