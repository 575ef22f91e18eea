"""The TOML scene reader: one TOML file (``docs/SCENE_FORMAT.md``) -> :class:`Scene`.

The reader is strict: an unknown key, a wrong type or length, a non-finite or out-of-range
number, a missing mesh or material, a degenerate camera or a resolution that cannot fit in
memory raises :class:`InputError` naming the file and the key. Material parameters are read as
each material type declares them (``tracer.materials``), so a new material needs no change
here.
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from .. import materials, sampler_choice, strategy
from ..camera import ORTHOGRAPHIC, PERSPECTIVE, PROJECTIONS, Camera
from ..errors import InputError
from ..inputfiles import read_regular_file
from ..record import MAX_SAMPLE_INDEX
from ..textures import BUMP_MAP, FILTERS, WRAPS, Perturbation, Texture, TextureTable, bind, tiltable
from ..textures.bitmap import read_texels
from . import keys
from .environment import Environment, rotation_problem
from .icosphere import unit_icosphere
from .mesh import Mesh, MeshError, angle_weighted_normals, read_mesh_file
from .model import Scene, Shape

# Film memory per pixel: count (int64), mean and M2 (3 float64 each), plus per-pass batch
# statistics and the float32 output image; used to refuse resolutions that cannot fit.
FILM_BYTES_PER_PIXEL = 8 + 6 * 8 + 6 * 8 + 6 * 4
MAX_SIDE = 1 << 15
# Validated in the precision the renderer uses. Embree holds coordinates in float32 and forms
# products of coordinate differences: magnitudes up to 1e15 keep those below float32's 3.4e38.
# The EXR holds the per-sample variance in float32, the square of a radiance: radiance and
# intensity up to 1e18 keep it finite.
MAX_COORDINATE = 1e15
MAX_RADIANCE = 1e18


MAX_SCENE_BYTES = 64 << 20  # far beyond any scene file (meshes live in their own files)
MAX_KEY_PARTS = 64  # dotted keys and table headers deeper than this are refused before parsing


def read_toml_file(path: str) -> dict[str, Any]:
    """The parsed TOML document of ``path``; unreadable, invalid or hostile files (nesting
    that exhausts the parser, integers past Python's digit limit, dotted keys thousands of
    parts deep, which tomllib parses in quadratic time) raise InputError quickly."""
    data = read_regular_file(path, MAX_SCENE_BYTES, "scene file")
    try:
        text = data.decode("utf-8")
        _refuse_deep_keys(text, path)
        return tomllib.loads(text)
    except RecursionError:
        raise InputError("not valid TOML: nested too deeply", path) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path) from None
    except UnicodeDecodeError:
        raise InputError("not valid TOML: not UTF-8 text", path) from None
    except ValueError as exc:  # Python's digit limit for integers, raised inside tomllib
        raise InputError(f"not valid TOML: {exc}", path) from None


def _refuse_deep_keys(text: str, path: str) -> None:
    """Refuse a key or table header with more than MAX_KEY_PARTS dotted parts (the part of a
    line before '=', or a [header]); values are not looked at."""
    for number, line in enumerate(text.splitlines(), start=1):
        head = line.split("=", 1)[0] if "=" in line else line
        if head.count(".") >= MAX_KEY_PARTS and (head.lstrip().startswith("[") or "=" in line):
            raise InputError(f"line {number}: a key of more than {MAX_KEY_PARTS} dotted parts", path)


def scene_from_document(doc: Any, path: str, base: Path, width: int | None = None,
                        height: int | None = None) -> Scene:
    """Validate a parsed scene document into a :class:`Scene`. ``path`` names it in messages,
    ``base`` is the folder mesh files are relative to; ``width``/``height`` override the
    camera's resolution."""
    top = _Reader(path, "", doc, keys.TOP)
    render = _read_render(_Reader(path, "render", top.raw("render", {}), keys.RENDER))
    camera = _read_camera(_Reader(path, "camera", top.raw("camera"), keys.CAMERA), width, height)
    geometry = _Geometry()
    table = _read_materials(path, top.raw("materials", {}), base, geometry.textures)
    shapes = top.raw("shapes", [])
    if not isinstance(shapes, list):
        top.fail("expected an array of tables ([[shapes]])", "shapes")
    for i, shape_table in enumerate(shapes):
        _read_shape(_Reader(path, f"shapes[{i}]", shape_table, keys.SHAPE), base, table.names, geometry)
    lights = top.raw("lights", [])
    if not isinstance(lights, list):
        top.fail("expected an array of tables ([[lights]])", "lights")
    point_position, point_intensity, spots, directionals = [], [], [], []
    for i, light_table in enumerate(lights):
        light = _Reader(path, f"lights[{i}]", light_table, keys.LIGHT)
        kind = light.string("type", tuple(keys.LIGHTS))
        light.expect(keys.LIGHTS[kind])
        if kind == "directional":
            directionals.append((_unit(light, "direction"),
                                 light.vec3("irradiance", nonnegative=True, hi=MAX_RADIANCE)))
            light.done()
            continue
        point_position.append(_position(light, "position"))
        point_intensity.append(light.vec3("intensity", nonnegative=True, hi=MAX_RADIANCE))
        spot = (np.array([0.0, 0.0, 1.0]), 180.0, 180.0)
        if kind == "spot":
            cutoff = float(light.number("cutoff_angle", 20.0, lo=0.0, hi=180.0, lo_open=True))
            beam = float(light.number("beam_width", 0.75 * cutoff, lo=0.0, hi=180.0))
            spot = (_unit(light, "direction"), cutoff, beam)
        spots.append(spot)
        light.done()
    environment = None
    if top.has("environment"):
        environment = _read_environment(
            _Reader(path, "environment", top.raw("environment"), keys.ENVIRONMENT), base)
    top.done()

    return geometry.scene(path, camera, table, point_position, point_intensity, render, environment,
                          spots=spots, directionals=directionals)


def _read_environment(r: "_Reader", base: Path) -> Environment:
    """``[environment]``: a constant ``radiance`` or a ``map`` with ``scale`` and ``to_world``."""
    if r.has("radiance") == r.has("map"):
        r.fail("give radiance (a constant environment) or map (an image file), one of them")
    if r.has("radiance"):
        environment = Environment.constant(r.vec3("radiance", nonnegative=True, hi=MAX_RADIANCE))
    else:
        file = r.string("map")
        scale = r.number("scale", 1.0, lo=0.0, hi=MAX_RADIANCE)
        texels = read_texels(base / file, False, r.path, f"{r.key}.map")
        if np.any(texels < 0.0):
            r.fail(f"the map {file} has negative texels (radiance is >= 0)", "map")
        if np.max(texels, initial=0.0) * scale > MAX_RADIANCE:
            r.fail(f"texels x scale exceed {MAX_RADIANCE:g}", "scale")
        to_world = _rows(r, "to_world", 3, 3, np.eye(3).tolist())
        problem = rotation_problem(to_world)
        if problem is not None:
            r.fail(problem, "to_world")
        environment = Environment(texels * np.float32(scale), to_world, kind="envmap", source=file,
                                  scale=scale, file=str(base / file))
    r.done()
    return environment


def _unit(r: "_Reader", name: str) -> np.ndarray:
    """A direction: normalized, unless within 1e-9 of unit length already (kept as written, so
    that a converted scene reads back to the very same bits)."""
    v = _position(r, name)
    length = float(np.linalg.norm(v))
    if not length > 0.0:
        r.fail("a direction must not be zero", name)
    return v if abs(length - 1.0) <= 1e-9 else v / length


def _position(r: "_Reader", name: str, default: Any = ...) -> np.ndarray:
    """A point or vector in scene units, within +-MAX_COORDINATE."""
    return r.vector(name, 3, default, lo=-MAX_COORDINATE, hi=MAX_COORDINATE)


def _float32(rows: list[np.ndarray]) -> np.ndarray:
    return np.asarray(rows, dtype=np.float32).reshape(-1, 3).astype(np.float64)


def check_resolution(width: int, height: int, where: str | None = None, key: str | None = None) -> None:
    """Refuse a resolution that is not positive or whose film cannot fit in memory."""
    if width < 1 or height < 1 or width > MAX_SIDE or height > MAX_SIDE:
        raise InputError(f"resolution {width}x{height} is out of range (1 to {MAX_SIDE} per side)",
                         where, key)
    need = width * height * FILM_BYTES_PER_PIXEL
    have = _physical_memory()
    if need > have // 2:
        raise InputError(
            f"resolution {width}x{height} needs {need / 2**30:.1f} GiB for the film, more than half "
            f"of this machine's {have / 2**30:.1f} GiB", where, key)


def _physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


class _Reader:
    """Typed access to one TOML table that remembers which keys were used.

    ``key`` is the table's dotted name in messages (``shapes[2]``); ``done()`` refuses any key
    that was never asked for, as Nori's factory and pbrt's ReportUnused do.
    """

    def __init__(self, path: str, key: str, table: Any, section: keys.Section | None = None,
                 extra: tuple[str, ...] = ()):
        self.path = path
        self.key = key
        if not isinstance(table, dict):
            self.fail(f"expected a table, got {_kind(table)}")
        self.table = table
        self.used: set[str] = set()
        self.declared: tuple[str, ...] = ()
        self.expect(section, extra)

    def expect(self, section: keys.Section | None, extra: tuple[str, ...] = ()) -> None:
        """The keys this table may hold: ``section``'s (``tracer.scene.keys``) and ``extra``
        (a material's parameters). A shape's section is known once its ``type`` is read."""
        self.declared = (section.names() if section else ()) + tuple(extra)

    def _unknown(self) -> list[str]:
        return sorted(set(self.table) - set(self.declared))

    @staticmethod
    def _closest(name: str, candidates) -> str | None:
        """The candidate most like ``name`` (a typo's other half), or None."""
        match = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
        return match[0] if match else None

    def _full(self, name: str) -> str:
        return f"{self.key}.{name}" if self.key else name

    def fail(self, message: str, name: str | None = None) -> None:
        raise InputError(message, self.path, self._full(name) if name else (self.key or None))

    def has(self, name: str) -> bool:
        return name in self.table

    def raw(self, name: str, default: Any = ...) -> Any:
        # The reader may only read what tracer.scene.keys declares: the reference page is made
        # from those tables, so a key read here and not declared there would go undocumented.
        if self.declared and name not in self.declared:  # (a bare _Reader, as tests make, checks none)
            raise RuntimeError(f"the scene reader reads {self._full(name)!r}, which tracer.scene.keys "
                               f"does not declare")
        self.used.add(name)
        if name not in self.table:
            if default is ...:
                # A typo of a required key is missing under its own name and present, unknown,
                # under another: name the one the file has.
                typo = self._closest(name, self._unknown())
                hint = f" (the table has '{typo}', which is not a key: a typo?)" if typo else ""
                self.fail("missing required key" + hint, name)
            return default
        return self.table[name]

    def number(self, name: str, default: Any = ..., lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, integer: bool = False) -> Any:
        value = self.raw(name, default)
        if value is default and default is not ...:
            return value
        ok_type = isinstance(value, int) if integer else isinstance(value, (int, float))
        if isinstance(value, bool) or not ok_type:
            self.fail(f"expected {'an integer' if integer else 'a number'}, got {_kind(value)}", name)
        if not math.isfinite(value):
            self.fail(f"expected a finite number, got {value}", name)
        if lo is not None and (value < lo or (lo_open and value == lo)):
            self.fail(f"expected a number {'>' if lo_open else '>='} {lo}, got {value}", name)
        if hi is not None and value > hi:
            self.fail(f"expected a number <= {hi}, got {value}", name)
        return int(value) if integer else float(value)

    def vec3(self, name: str, default: Any = ..., nonnegative: bool = False,
             hi: float | None = None) -> np.ndarray:
        return self.vector(name, 3, default, lo=0.0 if nonnegative else None, hi=hi)

    def vector(self, name: str, size: int, default: Any = ..., lo: float | None = None,
               lo_open: bool = False, hi: float | None = None) -> np.ndarray:
        """A list of ``size`` finite numbers, each within [lo, hi] (lo excluded if lo_open)."""
        value = self.raw(name, default)
        if value is default and default is not ...:
            return np.asarray(value, dtype=np.float64)
        if (not isinstance(value, list) or len(value) != size
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)):
            self.fail(f"expected a list of {size} numbers, got {_short(value)}", name)
        arr = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            self.fail(f"expected finite numbers, got {value}", name)
        if lo is not None and (np.any(arr < lo) or (lo_open and np.any(arr == lo))):
            self.fail(f"expected numbers {'>' if lo_open else '>='} {lo:g}, got {value}", name)
        if hi is not None and np.any(arr > hi):
            self.fail(f"expected numbers <= {hi:g}, got {value}", name)
        return arr

    def string(self, name: str, choices: tuple[str, ...] | None = None, default: Any = ...) -> Any:
        value = self.raw(name, default)
        if value is default and default is not ...:
            return value
        if not isinstance(value, str):
            self.fail(f"expected a string, got {_kind(value)}", name)
        if choices is not None and value not in choices:
            self.fail(f"expected one of {', '.join(choices)}; got '{value}'", name)
        return value

    def boolean(self, name: str, default: Any = ...) -> Any:
        value = self.raw(name, default)
        if value is default and default is not ...:
            return value
        if not isinstance(value, bool):
            self.fail(f"expected true or false, got {_kind(value)}", name)
        return value

    def done(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            name = unknown[0]
            meant = self._closest(name, self.declared)
            self.fail(f"unknown key '{name}'" + (f" (did you mean '{meant}'?)" if meant else ""), name)


def _kind(value: Any) -> str:
    names = {bool: "a boolean", str: "a string", list: "a list", dict: "a table", int: "an integer",
             float: "a number"}
    return names.get(type(value), type(value).__name__)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) < 60 else text[:57] + "..."


def _read_render(r: _Reader) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if r.has("spp"):
        # Sample indices stop at 2^53, where counts stay exact (tracer.record.MAX_SAMPLE_INDEX).
        out["spp"] = r.number("spp", lo=1, hi=MAX_SAMPLE_INDEX, integer=True)
    if r.has("strategy"):
        out["strategy"] = r.string("strategy", strategy.STRATEGIES)
    if r.has("light_sampling"):
        out["light_sampling"] = r.string("light_sampling", strategy.light_samplings())
    if r.has("sampler"):
        out["sampler"] = r.string("sampler", sampler_choice.SAMPLERS)
    r.done()
    return out


def _read_camera(r: _Reader, width: int | None, height: int | None) -> Camera:
    origin = _position(r, "origin")
    target = _position(r, "target")
    up = _position(r, "up", default=[0.0, 1.0, 0.0])
    projection = r.string("projection", choices=PROJECTIONS, default=PERSPECTIVE)
    lens = {}
    if projection == ORTHOGRAPHIC:
        for name in ("fov", "aperture_radius", "focus_distance"):
            if r.has(name):
                r.fail("an orthographic camera has no " + name, name)
        fov = 0.0
        lens["view_width"] = r.number("view_width", lo=0.0, lo_open=True, hi=MAX_COORDINATE)
    else:
        if r.has("view_width"):
            r.fail("view_width is the orthographic camera's: a perspective camera has a fov", "view_width")
        fov = r.number("fov", lo=0.0, lo_open=True, hi=179.0)
        lens["aperture_radius"] = r.number("aperture_radius", default=0.0, lo=0.0, hi=MAX_COORDINATE)
        if lens["aperture_radius"] > 0.0 or r.has("focus_distance"):
            lens["focus_distance"] = r.number("focus_distance", lo=0.0, lo_open=True, hi=MAX_COORDINATE)
    w = r.number("width", default=256, lo=1, hi=MAX_SIDE, integer=True)
    h = r.number("height", default=256, lo=1, hi=MAX_SIDE, integer=True)
    mirrored = r.boolean("mirrored", default=False)
    r.done()
    forward = target - origin
    if np.linalg.norm(forward) <= 1e-12 * max(1.0, float(np.linalg.norm(origin))):
        r.fail("degenerate camera: target equals origin", "target")
    if np.linalg.norm(up) == 0.0:
        r.fail("degenerate camera: up is the zero vector", "up")
    cos_up = abs(np.dot(forward, up)) / (np.linalg.norm(forward) * np.linalg.norm(up))
    if cos_up > 1.0 - 1e-9:
        r.fail("degenerate camera: up is parallel to the viewing direction", "up")
    # One side given: the other follows the file's aspect ratio (a --width alone must not squash
    # the frame into a sliver), rounded, at least one pixel.
    if width is not None and height is None:
        w, h = width, max(1, round(width * h / w))
    elif height is not None and width is None:
        w, h = max(1, round(height * w / h)), height
    elif width is not None:
        w, h = width, height
    check_resolution(w, h, r.path, "camera.width/height")
    return Camera(origin, target, up, fov, int(w), int(h), mirrored=bool(mirrored), projection=projection,
                  **{key: float(value) for key, value in lens.items()})


def _read_materials(path: str, table: Any, base: Path, textures: TextureTable) -> materials.MaterialTable:
    top = _Reader(path, "materials", table, extra=tuple(table) if isinstance(table, dict) else ())
    triples = []
    sides: list[bool] = []
    opacity: list[float] = []
    images: dict[tuple[str, bool], np.ndarray] = {}
    for row, name in enumerate(table, start=1):  # row 0 is the black material
        m = _Reader(path, f"materials.{name}", top.raw(name), keys.MATERIAL)
        kind = materials.TYPES[m.string("type", tuple(materials.TYPES))]
        if kind.composite:  # its parts are rows of their own, which this format cannot name yet
            m.fail(f"a {kind.name} is read from Mitsuba XML only (tracer's TOML has no nested materials "
                   "yet)", "type")
        given = tuple(p for p in kind.params if not p.internal)  # internal ones: set by readers only
        m.expect(keys.MATERIAL, tuple(p.name for p in given))
        values: dict[str, object] = {}
        for p in given:
            default = ... if p.default is None else p.default
            if p.texture and isinstance(m.raw(p.name, None), dict):
                values[p.name] = _read_texture(_Reader(path, f"materials.{name}.{p.name}", m.raw(p.name),
                                                       keys.TEXTURE), base, images)
            elif p.choices:
                values[p.name] = m.string(p.name, p.choices, default=default)
            elif p.boolean:
                values[p.name] = m.boolean(p.name, default=default)
            elif p.size == 1:
                values[p.name] = m.number(p.name, default=default, lo=p.lo, lo_open=p.lo_open, hi=p.hi)
            else:
                values[p.name] = m.vector(p.name, p.size, default=default, lo=p.lo, lo_open=p.lo_open,
                                          hi=p.hi)
        sides.append(m.boolean("twosided", default=True))
        if isinstance(m.raw("opacity", None), dict):
            opacity.append(textures.bind_opacity(row, _read_texture(
                _Reader(path, f"materials.{name}.opacity", m.raw("opacity"), keys.TEXTURE), base, images)))
        else:
            opacity.append(m.number("opacity", default=1.0, lo=0.0, hi=1.0))
        tilt = _read_perturbation(path, name, m, kind, base, images)
        if tilt is not None:
            textures.bind_perturbation(row, tilt)
        m.done()
        try:
            values = bind(textures, row, kind, values, path)
        except ValueError as exc:  # unreachable: only texture parameters read a table above
            m.fail(str(exc))
        triples.append((name, kind.name, values))
    top.done()
    try:
        return materials.table(triples, sides, opacity)
    except ValueError as exc:  # unreachable while the checks above hold each Param's range
        raise InputError(str(exc), path) from None


# The corner coordinates of a triangle without texture coordinates: (u, v) is then (b1, b2).
NO_UV = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 1.0])
# A quad's texture coordinates at o, o + edge1, o + edge1 + edge2, o + edge2 (Mitsuba's rectangle).
QUAD_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


class _Geometry:
    """Accumulates shapes as triangle soups with per-triangle columns and shape records."""

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self.material: list[np.ndarray] = []
        self.emission: list[np.ndarray] = []
        self.shape: list[np.ndarray] = []
        self.shapes: list[Shape] = []
        self._count = 0
        self._triangles = 0
        self.spheres: list[list[float]] = []
        self.sphere_material: list[int] = []
        self.sphere_emission: list[np.ndarray] = []
        self.shape_of_sphere: list[int] = []
        self.corner_normals: list[np.ndarray] = []
        self.smooth = False
        self.corner_uv: list[np.ndarray] = []
        self.sphere_frames: list[np.ndarray] = []
        self.textures = TextureTable()
        self.attributes: list[dict[str, np.ndarray]] = []  # per shape: its mesh file's (mesh.Mesh)

    def _emission(self, emission: "np.ndarray | Texture") -> np.ndarray:
        """The constant emission (3,) of the shape added next: ``emission`` itself, or a
        radiance texture's mean, the texture bound to the shape (``TextureTable.bind_emission``),
        rounded to float32 as every table holds emission."""
        if isinstance(emission, Texture):
            emission = self.textures.bind_emission(len(self.shapes), emission)
        return np.asarray(emission, dtype=np.float32).astype(np.float64)

    def add(self, shape_type: str, record: dict[str, Any], vertices: np.ndarray, faces: np.ndarray,
            material: int, emission: "np.ndarray | Texture", normals: np.ndarray | None = None,
            corner_uv: np.ndarray | None = None, attributes: dict[str, np.ndarray] | None = None) -> None:
        """Add a shape's triangles; ``normals`` (V, 3) unit vertex normals for smooth shading
        (a zero normal shades its triangles flat), None for flat shading; ``corner_uv`` (F, 6)
        texture coordinates at each triangle's corners, None for none (a texture then sees the
        barycentrics, as in Mitsuba); ``attributes`` its mesh attributes by name, each (F, 3, C)
        at the corners (``mesh.Mesh.attributes``, corners in the order of ``faces``). ``emission``
        (3,) or a radiance texture (:meth:`_emission`)."""
        emission = self._emission(emission)
        n = len(faces)
        self.attributes.append(dict(attributes or {}))
        self.corner_uv.append(np.tile(NO_UV, (n, 1)) if corner_uv is None
                              else np.asarray(corner_uv, dtype=np.float64).reshape(n, 6))
        self.corner_normals.append(np.zeros((n, 9)) if normals is None
                                   else np.asarray(normals, dtype=np.float64)[faces].reshape(n, 9))
        self.smooth = self.smooth or normals is not None
        self._faces.append(faces.astype(np.int64) + self._count)
        self._vertices.append(vertices)
        self._count += len(vertices)
        self.material.append(np.full(n, material, dtype=np.int32))
        self.emission.append(np.tile(emission, (n, 1)))
        self.shape.append(np.full(n, len(self.shapes), dtype=np.int32))
        self.shapes.append(Shape(shape_type, self._triangles, n, material, emission, record))
        self._triangles += n

    def add_sphere(self, record: dict[str, Any], material: int, emission: "np.ndarray | Texture",
                   frame: np.ndarray | None = None) -> None:
        """Add an analytic sphere; ``frame`` (3, 3) its world-to-local rotation, for texture
        coordinates (None: the world's axes); ``emission`` as for :meth:`add`."""
        emission = self._emission(emission)
        self.sphere_frames.append(np.eye(3).ravel() if frame is None
                                  else np.asarray(frame, dtype=np.float64).ravel())
        self.spheres.append([*record["center"], record["radius"]])
        self.sphere_material.append(material)
        self.sphere_emission.append(emission)
        self.shape_of_sphere.append(len(self.shapes))
        self.attributes.append({})
        self.shapes.append(Shape("sphere", self._triangles, 0, material, emission, record,
                                 sphere=len(self.spheres) - 1))

    def resolve_attribute(self, texture: Texture, rows: set[int], path: str) -> None:
        """Fill the mesh-attribute texture ``texture`` (``Texture.resolve``) from the shapes'
        attributes of its name. Every shape of material rows ``rows`` (those it feeds) must have
        it, with the same number of channels, 1 or 3: InputError otherwise, naming the shape."""
        name, corners, present, channels = texture.attribute, None, np.zeros(self._triangles, bool), None
        for i, (shape, attributes) in enumerate(zip(self.shapes, self.attributes, strict=True)):
            values = attributes.get(name)
            where = f"shape {i + 1} ({shape.record.get('file') or shape.type})"
            if values is None:
                if shape.material in rows:
                    held = ", ".join(sorted(attributes)) or "none"
                    raise InputError(f"{where} has no mesh attribute '{name}', which its material's "
                                     f"mesh_attribute texture reads ({texture.source}; it has: {held})", path)
                continue
            if values.shape[2] not in (1, 3) or channels not in (None, values.shape[2]):
                raise InputError(f"{where}: mesh attribute '{name}' has {values.shape[2]} channels; a "
                                 "mesh_attribute texture reads 1 or 3 (Mitsuba reads 0 from others), the "
                                 "same in every shape", path)
            channels = values.shape[2]
            if corners is None:
                corners = np.zeros((self._triangles, 3, channels))
            corners[shape.first:shape.first + shape.count] = values
            present[shape.first:shape.first + shape.count] = True
        texture.resolve(np.zeros((self._triangles, 3, 1)) if corners is None else corners, present,
                        channels or 1)

    def scene(self, path: str, camera: Camera, table: materials.MaterialTable, point_position: list,
              point_intensity: list, render: dict[str, Any], environment: Environment | None = None,
              spots: list | None = None, directionals: list | None = None, images: list | None = None) -> Scene:
        """The scene of these shapes with the rest a reader read: every reader ends here.
        ``spots``: per point light ``(axis, cutoff, beam)`` (degrees; 180, 180: every way), or
        None for all omnidirectional; ``directionals``: ``(direction, irradiance)`` per light;
        ``images``: per point light the image it projects or None (None: no images)."""
        for i, shape in enumerate(self.shapes):
            cutout = table.opacity[shape.material] < 1.0 or shape.material in self.textures.cutouts
            if shape.emissive and cutout:
                raise InputError(f"shape {i + 1} emits, and its material '{table.names[shape.material]}' "
                                 "has an opacity (a mask): tracer's emitters are opaque", path)
        self.orient(path, table)
        omni = (np.array([0.0, 0.0, 1.0]), 180.0, 180.0)
        spots = spots if spots is not None else [omni] * len(point_position)
        directionals = directionals or []
        return Scene(
            path=path,
            camera=camera,
            vertices=self.vertices(),
            faces=self.faces(),
            material=self.column(self.material, np.int32),
            emission=self.column(self.emission, np.float64, (0, 3)),
            shape_of_triangle=self.column(self.shape, np.int32),
            shapes=self.shapes,
            materials=table,
            # float32, as the light table stores them, so that every table holds the same light.
            point_position=_float32(point_position),
            point_intensity=_float32(point_intensity),
            render_defaults=render,
            spheres=np.array(self.spheres, dtype=np.float64).reshape(-1, 4),
            sphere_material=np.array(self.sphere_material, dtype=np.int32),
            sphere_emission=np.array(self.sphere_emission, dtype=np.float64).reshape(-1, 3),
            shape_of_sphere=np.array(self.shape_of_sphere, dtype=np.int32),
            corner_normals=self.normals(),
            textures=self.textures,
            corner_uv=(np.concatenate(self.corner_uv) if self.textures and self.corner_uv
                       else np.zeros((0, 6))),
            sphere_frame=(np.array(self.sphere_frames).reshape(-1, 9) if self.textures else np.zeros((0, 9))),
            environment=environment,
            point_axis=np.array([s[0] for s in spots], dtype=np.float64).reshape(-1, 3),
            point_cutoff=np.array([s[1] for s in spots], dtype=np.float64),
            point_beam=np.array([s[2] for s in spots], dtype=np.float64),
            point_images=images,
            directional_direction=np.array([d[0] for d in directionals], dtype=np.float64).reshape(-1, 3),
            directional_irradiance=_float32([d[1] for d in directionals]).reshape(-1, 3),
        )

    def orient(self, path: str, table: materials.MaterialTable) -> None:
        """Mark the material rows whose value depends on the tangent (``MaterialType.oriented``:
        anisotropic roughness) to be shaded in Mitsuba's frame of dp/du (``TextureTable.frames``).
        Under a bump map that frame is not Mitsuba's (``tracer.textures.shading_frames``):
        refused."""
        types = materials.BY_CODE
        for row, code in enumerate(table.kind):
            kind = types[int(code)] if int(code) != materials.NONE else None
            if kind is None or kind.oriented is None or not kind.oriented(kind.values(table.params[row])):
                continue
            tilt = self.textures.perturbations.get(row)
            if tilt is not None and tilt[0] == BUMP_MAP:
                raise InputError(f"material '{table.names[row]}' ({kind.name}) has anisotropic roughness "
                                 "under a bump map, which tracer does not support (give one alpha)", path)
            if tilt is None:
                self.textures.frames.add(row)

    def vertices(self) -> np.ndarray:
        return np.concatenate(self._vertices) if self._vertices else np.zeros((0, 3))

    def normals(self) -> np.ndarray:
        """(F, 9) vertex normals of each triangle's corners (zeros: flat), or (0, 9) when no
        shape is smooth."""
        return np.concatenate(self.corner_normals) if self.smooth else np.zeros((0, 9))

    def faces(self) -> np.ndarray:
        return (np.concatenate(self._faces) if self._faces else np.zeros((0, 3))).astype(np.int32)

    @staticmethod
    def column(parts: list[np.ndarray], dtype: Any, empty_shape: tuple[int, ...] = (0,)) -> np.ndarray:
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(empty_shape, dtype=dtype)


def _read_shape(r: _Reader, base: Path, material_names: list[str], geometry: _Geometry) -> None:
    shape_type = r.string("type", tuple(keys.SHAPES))
    r.expect(keys.SHAPES[shape_type])
    # Radiance is kept at float32 precision, as the EXR output and the light sampler's table
    # store it, so that every table holds the very same emission.
    emission = r.vec3("emission", default=[0.0, 0.0, 0.0], nonnegative=True, hi=MAX_RADIANCE)
    emission = emission.astype(np.float32).astype(np.float64)
    material = 0
    if r.has("material"):
        name = r.string("material")
        if name not in material_names[1:]:
            known = ", ".join(material_names[1:]) or "none defined"
            r.fail(f"unknown material '{name}' (known: {known})", "material")
        material = 1 + material_names[1:].index(name)  # row 0 is the black material

    if shape_type == "quad":
        o, e1, e2 = _position(r, "origin"), _position(r, "edge1"), _position(r, "edge2")
        if np.max(np.abs(np.stack([o + e1, o + e2, o + e1 + e2]))) > MAX_COORDINATE:
            r.fail(f"the quad's corners leave the coordinate range +-{MAX_COORDINATE:g}", "edge1")
        record: dict[str, Any] = {"origin": o, "edge1": e1, "edge2": e2}
        vertices = np.stack([o, o + e1, o + e1 + e2, o + e2])
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        corner_uv = _rows(r, "uv", 4, 2, QUAD_UV.tolist())[faces].reshape(-1, 6)
    elif shape_type == "sphere":
        center = _position(r, "center")
        radius = r.number("radius", lo=0.0, lo_open=True, hi=MAX_COORDINATE)
        # Smaller than float32 can resolve at the centre, the tessellation collapses.
        if radius < 1e-6 * max(float(np.max(np.abs(center))), 1e-24):
            r.fail(f"radius {radius:g} is below what float32 resolves at the centre "
                   f"(at least 1e-6 times the largest centre coordinate, and 1e-30)", "radius")
        if not r.has("subdivisions"):  # a true sphere, intersected exactly
            frame = _rows(r, "uv_frame", 3, 3, np.eye(3).tolist())
            if np.max(np.abs(frame @ frame.T - np.eye(3))) > 1e-6 or np.linalg.det(frame) < 0.0:
                r.fail("expected the rows of a rotation (orthonormal, right-handed)", "uv_frame")
            r.done()
            geometry.add_sphere({"center": center, "radius": radius}, material, emission, frame)
            return
        if r.has("uv_frame"):
            r.raw("uv_frame")
            r.fail("uv_frame is a true sphere's (an icosphere's texture coordinates are its triangles' "
                   "barycentrics)", "uv_frame")
        subdivisions = r.number("subdivisions", lo=0, hi=7, integer=True)
        record = {"center": center, "radius": radius, "subdivisions": subdivisions}
        vertices, faces = _icosphere(subdivisions, radius, center)
        corner_uv = None  # an icosphere's texture coordinates: the barycentrics
    else:
        file = r.string("file")
        shading = r.string("normals", ("face", "vertex"), default="face")
        record = {"file": str(base / file)}
        mesh = _read_mesh(r, base / file)
        vertices, faces, corner_uv = mesh.vertices, mesh.faces, mesh.corner_uv
        if r.boolean("flip_v", default=False) and corner_uv is not None:
            corner_uv = corner_uv.copy()
            corner_uv[:, 1::2] = 1.0 - corner_uv[:, 1::2]
        if shading == "vertex":  # the file's vertex normals, else Mitsuba's angle-weighted ones
            normals = mesh.normals if mesh.normals is not None else angle_weighted_normals(vertices, faces)
            r.done()
            geometry.add(shape_type, record, vertices, faces, material, emission, normals, corner_uv)
            return
    r.done()
    geometry.add(shape_type, record, vertices, faces, material, emission, corner_uv=corner_uv)


def _read_perturbation(path: str, name: str, m: _Reader, kind, base: Path,
                       images: dict[tuple[str, bool], np.ndarray]) -> Perturbation | None:
    """Material ``name``'s ``normal_map`` or ``bump_map`` (``keys.MATERIAL``) as a
    :class:`Perturbation`, or None without either."""
    given = [key for key in ("normal_map", "bump_map") if m.has(key)]
    if not given:
        for key in ("bump_scale", "flip_invalid_normals", "use_shadowing_function"):
            if m.has(key):
                m.fail("needs a normal_map or a bump_map", key)
        return None
    if len(given) == 2:
        m.fail("give a normal_map or a bump_map, not both", "bump_map")
    key = given[0]
    if not tiltable(kind):
        m.fail(f"a {key} on {kind.name} is not supported (tracer tilts the frame of materials that only "
               "reflect)", key)
    table = m.raw(key)
    if not isinstance(table, dict):
        m.fail(f"expected a texture table, got {_kind(table)}", key)
    texture = _read_texture(_Reader(path, f"materials.{name}.{key}", table, keys.TEXTURE), base, images)
    if key == "bump_map" and (texture.kind != "bitmap" or texture.filter != "bilinear"):
        m.fail("a bump map is a bilinear bitmap (its gradient is that of the bilinear lookup)", key)
    scale = m.number("bump_scale", default=1.0, lo=-1e6, hi=1e6) if key == "bump_map" else 1.0
    if key == "normal_map" and m.has("bump_scale"):
        m.fail("bump_scale belongs to a bump_map", "bump_scale")
    return Perturbation("normalmap" if key == "normal_map" else "bumpmap", texture, scale,
                        m.boolean("flip_invalid_normals", default=True),
                        m.boolean("use_shadowing_function", default=True))


def _read_texture(r: _Reader, base: Path, images: dict[tuple[str, bool], np.ndarray]) -> Texture:
    """A material parameter's texture table (``keys.TEXTURE``); ``images`` holds the texels
    already read, by (file, raw)."""
    kind = r.string("texture", ("checkerboard", "bitmap"))
    to_uv = _rows(r, "to_uv", 2, 3, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    if kind == "checkerboard":
        def colour(name: str, default: float) -> np.ndarray:
            value = r.raw(name, default)
            return (np.full(3, r.number(name, default)) if not isinstance(value, list)
                    else r.vector(name, 3))
        texture = Texture("checkerboard", to_uv=to_uv, color0=colour("color0", 0.4),
                          color1=colour("color1", 0.2), source=r.key)
    else:
        file = r.string("file")
        raw = r.boolean("raw", default=False)
        key = (str(base / file), raw)
        if key not in images:  # one read of a file however many materials use it
            images[key] = read_texels(base / file, raw, r.path, f"{r.key}.file")
        pixels = images[key]
        texture = Texture("bitmap", to_uv=to_uv, pixels=pixels,
                          filter=r.string("filter", FILTERS, default="bilinear"),
                          wrap=r.string("wrap", WRAPS, default="repeat"), source=str(base / file), raw=raw)
    r.done()
    return texture


def _rows(r: _Reader, name: str, count: int, size: int, default: Any) -> np.ndarray:
    """``count`` rows of ``size`` finite numbers (a nested list)."""
    value = r.raw(name, default)
    if (not isinstance(value, list) or len(value) != count
            or any(not isinstance(row, list) or len(row) != size
                   or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in row)
                   for row in value)):
        r.fail(f"expected {count} lists of {size} numbers, got {_short(value)}", name)
    rows = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(rows)) or np.max(np.abs(rows)) > MAX_COORDINATE:
        r.fail(f"expected finite numbers within +-{MAX_COORDINATE:g}", name)
    return rows


def _icosphere(subdivisions: int, radius: float, center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # A unit sphere scaled here: projecting onto a tiny radius directly gives NaN vertices for
    # radii below about 1e-16.
    vertices, faces = unit_icosphere(subdivisions)
    return vertices * radius + center, faces


def _read_mesh(r: _Reader, mesh_path: Path) -> Mesh:
    try:
        return read_mesh_file(mesh_path)
    except MeshError as exc:
        r.fail(str(exc), "file")
