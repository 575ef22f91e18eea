"""The scene model and its reader: one TOML file (``SCENE_FORMAT.md``) -> :class:`Scene`.

Everything becomes triangles (quads split in two, spheres tessellated, meshes read with
trimesh), so one Embree mesh holds the whole scene and per-triangle tables hold what shading
needs: material index, emitted radiance, light index. The reader is strict: an unknown key,
a wrong type or length, a non-finite or out-of-range number, a missing mesh or material, a
degenerate camera or a resolution that cannot fit in memory raises :class:`InputError`
naming the file and the key.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import bsdf
from .camera import Camera
from .errors import InputError

STRATEGIES = ("uniform", "cosine", "bsdf", "light", "mis")
# Film memory per pixel: count (int64), mean and M2 (3 float64 each), plus per-pass batch
# statistics and the float32 output image; used to refuse resolutions that cannot fit.
FILM_BYTES_PER_PIXEL = 8 + 6 * 8 + 6 * 8 + 6 * 4
MAX_SIDE = 1 << 15
FLOAT32_MAX = float(np.finfo(np.float32).max)  # the largest radiance a scene may give


def default_scene_path() -> Path:
    """The scene ``tracer render`` uses without an argument: ``veach_mis``, shipped in the package."""
    return Path(str(resources.files("tracer") / "scenes" / "veach_mis.toml"))


@dataclass
class Scene:
    """A loaded scene: triangles with per-triangle tables, materials, point lights, camera.

    vertices : (V, 3) float64 world positions, rounded to float32 (Embree's precision).
    faces : (F, 3) int32 vertex indices.
    material : (F,) int32 index into the material table (0 is the black material).
    emission : (F, 3) float64 radiance leaving each triangle's front side (0: not emissive);
        the scene file's values rounded to float32.
    light_of_triangle : (F,) int32, index of the area light (emissive shape) it belongs to, -1 if none.
    materials : ``Bsdf`` table with one row per material (row 0: black).
    point_position, point_intensity : (P, 3) float64; intensity in W/sr.
    """

    path: str
    camera: Camera
    vertices: np.ndarray
    faces: np.ndarray
    material: np.ndarray
    emission: np.ndarray
    light_of_triangle: np.ndarray
    materials: bsdf.Bsdf
    material_names: list[str]
    point_position: np.ndarray
    point_intensity: np.ndarray
    render_defaults: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Vertices at float32 precision, as Embree holds them: hit points, light samples and pdfs
        # then all use the very triangles Embree intersects.
        self.vertices = np.asarray(self.vertices, dtype=np.float32).astype(np.float64)
        tri = self.vertices[self.faces]
        self.v0 = tri[:, 0]
        self.edge1 = tri[:, 1] - tri[:, 0]
        self.edge2 = tri[:, 2] - tri[:, 0]
        cross = np.cross(self.edge1, self.edge2)
        length = np.linalg.norm(cross, axis=1)
        self.area = 0.5 * length
        # Zero-area triangles get a zero normal (and zero area): never sampled, shaded black.
        self.normal = cross / np.where(length > 0.0, length, 1.0)[:, None]
        # What a hit needs, in one row per triangle so that a batch gathers it in one go:
        # v0 (3), edge1 (3), edge2 (3), normal (3), emission (3), material index (1).
        self.hit_table = np.concatenate(
            [self.v0, self.edge1, self.edge2, self.normal, self.emission, self.material[:, None]], axis=1
        )
        lo = self.vertices.min(axis=0) if len(self.vertices) else np.zeros(3)
        hi = self.vertices.max(axis=0) if len(self.vertices) else np.zeros(3)
        extent = max(float(np.max(np.abs(np.concatenate([lo, hi, self.camera.origin])))),
                     float(np.linalg.norm(hi - lo)))
        if len(self.point_position):
            extent = max(extent, float(np.max(np.abs(self.point_position))))
        # float32 rounding in Embree scales with coordinate magnitude; an offset proportional to
        # the scene's size makes a scene scaled by 1e-3 or 1e3 render the same image.
        self.ray_epsilon = 1e-5 * extent if extent > 0.0 else 1e-5

    @property
    def name(self) -> str:
        return Path(self.path).stem


# ---------------------------------------------------------------------------------------------
# Reading and validation


class _Reader:
    """Typed access to one TOML table that remembers which keys were used.

    ``key`` is the table's dotted name in messages (``shapes[2]``); ``done()`` refuses any key
    that was never asked for, as Nori's factory and pbrt's ReportUnused do.
    """

    def __init__(self, path: str, key: str, table: Any):
        self.path = path
        self.key = key
        if not isinstance(table, dict):
            self.fail(f"expected a table, got {_kind(table)}")
        self.table = table
        self.used: set[str] = set()

    def _full(self, name: str) -> str:
        return f"{self.key}.{name}" if self.key else name

    def fail(self, message: str, name: str | None = None) -> None:
        raise InputError(message, self.path, self._full(name) if name else (self.key or None))

    def has(self, name: str) -> bool:
        return name in self.table

    def raw(self, name: str, default: Any = ...) -> Any:
        self.used.add(name)
        if name not in self.table:
            if default is ...:
                self.fail("missing required key", name)
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
        value = self.raw(name, default)
        if value is default and default is not ...:
            return np.asarray(value, dtype=np.float64)
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)):
            self.fail(f"expected a list of 3 numbers, got {_short(value)}", name)
        arr = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            self.fail(f"expected finite numbers, got {value}", name)
        if nonnegative and np.any(arr < 0.0):
            self.fail(f"expected numbers >= 0, got {value}", name)
        if hi is not None and np.any(arr > hi):
            self.fail(f"expected numbers <= {hi}, got {value}", name)
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

    def done(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            self.fail(f"unknown key '{unknown[0]}'", unknown[0])


def _kind(value: Any) -> str:
    names = {bool: "a boolean", str: "a string", list: "a list", dict: "a table", int: "an integer",
             float: "a number"}
    return names.get(type(value), type(value).__name__)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) < 60 else text[:57] + "..."


def load_scene(path: str | os.PathLike[str], width: int | None = None, height: int | None = None) -> Scene:
    """Read and validate a scene file; ``width``/``height`` override the camera's resolution."""
    path = str(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("no such scene file", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a scene file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path) from None
    except UnicodeDecodeError:
        raise InputError("not valid TOML: not UTF-8 text", path) from None

    top = _Reader(path, "", doc)
    render = _read_render(_Reader(path, "render", top.raw("render", {})))
    camera = _read_camera(_Reader(path, "camera", top.raw("camera")), width, height)
    materials, names = _read_materials(path, top.raw("materials", {}))
    geometry = _Geometry()
    shapes = top.raw("shapes", [])
    if not isinstance(shapes, list):
        top.fail("expected an array of tables ([[shapes]])", "shapes")
    for i, table in enumerate(shapes):
        _read_shape(_Reader(path, f"shapes[{i}]", table), names, geometry)
    lights = top.raw("lights", [])
    if not isinstance(lights, list):
        top.fail("expected an array of tables ([[lights]])", "lights")
    point_position, point_intensity = [], []
    for i, table in enumerate(lights):
        light = _Reader(path, f"lights[{i}]", table)
        light.string("type", ("point",))
        point_position.append(light.vec3("position"))
        point_intensity.append(light.vec3("intensity", nonnegative=True))
        light.done()
    top.done()

    return Scene(
        path=path,
        camera=camera,
        vertices=geometry.vertices(),
        faces=geometry.faces(),
        material=geometry.column(geometry.material, np.int32),
        emission=geometry.column(geometry.emission, np.float64, (0, 3)),
        light_of_triangle=geometry.column(geometry.light, np.int32),
        materials=materials,
        material_names=names,
        point_position=np.asarray(point_position, dtype=np.float64).reshape(-1, 3),
        point_intensity=np.asarray(point_intensity, dtype=np.float64).reshape(-1, 3),
        render_defaults=render,
    )


def _read_render(r: _Reader) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if r.has("spp"):
        out["spp"] = r.number("spp", lo=1, integer=True)
    if r.has("strategy"):
        out["strategy"] = r.string("strategy", STRATEGIES)
    r.done()
    return out


def _read_camera(r: _Reader, width: int | None, height: int | None) -> Camera:
    origin = r.vec3("origin")
    target = r.vec3("target")
    up = r.vec3("up", default=[0.0, 1.0, 0.0])
    fov = r.number("fov", lo=0.0, lo_open=True, hi=179.0)
    w = r.number("width", default=256, lo=1, hi=MAX_SIDE, integer=True)
    h = r.number("height", default=256, lo=1, hi=MAX_SIDE, integer=True)
    r.done()
    forward = target - origin
    if np.linalg.norm(forward) <= 1e-12 * max(1.0, float(np.linalg.norm(origin))):
        r.fail("degenerate camera: target equals origin", "target")
    if np.linalg.norm(up) == 0.0:
        r.fail("degenerate camera: up is the zero vector", "up")
    cos_up = abs(np.dot(forward, up)) / (np.linalg.norm(forward) * np.linalg.norm(up))
    if cos_up > 1.0 - 1e-9:
        r.fail("degenerate camera: up is parallel to the viewing direction", "up")
    w = w if width is None else width
    h = h if height is None else height
    check_resolution(w, h, r.path, "camera.width/height")
    return Camera(origin, target, up, fov, int(w), int(h))


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


def _read_materials(path: str, table: Any) -> tuple[bsdf.Bsdf, list[str]]:
    top = _Reader(path, "materials", table)
    names = ["(none)"]
    kind, reflectance, alpha = [bsdf.NONE], [np.zeros(3)], [1.0]
    for name in table:
        m = _Reader(path, f"materials.{name}", top.raw(name))
        type_name = m.string("type", tuple(bsdf.KIND_NAMES))
        kind.append(bsdf.KIND_NAMES[type_name])
        reflectance.append(m.vec3("reflectance", nonnegative=True, hi=1.0))
        alpha.append(m.number("alpha", lo=0.0, lo_open=True, hi=10.0)
                     if type_name == "roughconductor" else 1.0)
        m.done()
        names.append(name)
    top.done()
    table_bsdf = bsdf.Bsdf(np.asarray(kind, dtype=np.int8), np.asarray(reflectance),
                           np.asarray(alpha, dtype=np.float64))
    return table_bsdf, names


class _Geometry:
    """Accumulates shapes as triangle soups with per-triangle columns."""

    def __init__(self) -> None:
        self._vertices: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self.material: list[np.ndarray] = []
        self.emission: list[np.ndarray] = []
        self.light: list[np.ndarray] = []
        self._count = 0
        self.lights = 0

    def add(self, vertices: np.ndarray, faces: np.ndarray, material: int, emission: np.ndarray) -> None:
        n = len(faces)
        self._faces.append(faces.astype(np.int64) + self._count)
        self._vertices.append(vertices)
        self._count += len(vertices)
        self.material.append(np.full(n, material, dtype=np.int32))
        self.emission.append(np.tile(emission, (n, 1)))
        light = -1
        if np.any(emission > 0.0):
            light = self.lights
            self.lights += 1
        self.light.append(np.full(n, light, dtype=np.int32))

    def vertices(self) -> np.ndarray:
        return np.concatenate(self._vertices) if self._vertices else np.zeros((0, 3))

    def faces(self) -> np.ndarray:
        return (np.concatenate(self._faces) if self._faces else np.zeros((0, 3))).astype(np.int32)

    @staticmethod
    def column(parts: list[np.ndarray], dtype: Any, empty_shape: tuple[int, ...] = (0,)) -> np.ndarray:
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(empty_shape, dtype=dtype)


def _read_shape(r: _Reader, material_names: list[str], geometry: _Geometry) -> None:
    shape_type = r.string("type", ("quad", "mesh", "sphere"))
    # Radiance is kept at float32 precision, as the EXR output and the light sampler's table
    # store it, so that every table holds the very same emission.
    emission = r.vec3("emission", default=[0.0, 0.0, 0.0], nonnegative=True, hi=FLOAT32_MAX)
    emission = emission.astype(np.float32).astype(np.float64)
    material = 0
    if r.has("material"):
        name = r.string("material")
        if name not in material_names[1:]:
            known = ", ".join(material_names[1:]) or "none defined"
            r.fail(f"unknown material '{name}' (known: {known})", "material")
        material = material_names.index(name)

    if shape_type == "quad":
        o, e1, e2 = r.vec3("origin"), r.vec3("edge1"), r.vec3("edge2")
        vertices = np.stack([o, o + e1, o + e1 + e2, o + e2])
        faces = np.array([[0, 1, 2], [0, 2, 3]])
    elif shape_type == "sphere":
        center = r.vec3("center")
        radius = r.number("radius", lo=0.0, lo_open=True)
        subdivisions = r.number("subdivisions", default=3, lo=0, hi=7, integer=True)
        vertices, faces = _icosphere(subdivisions, radius, center)
    else:
        vertices, faces = _read_mesh(r, r.string("file"))
    r.done()
    geometry.add(vertices, faces, material, emission)


def _icosphere(subdivisions: int, radius: float, center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(mesh.vertices, dtype=np.float64) + center, np.asarray(mesh.faces)


def _read_mesh(r: _Reader, file: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh_path = Path(r.path).parent / file
    if not mesh_path.is_file():
        r.fail(f"mesh file not found: {mesh_path}", "file")
    try:
        # process=False keeps the file's faces and winding exactly as written.
        mesh = trimesh.load_mesh(str(mesh_path), process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        r.fail(f"cannot read mesh {mesh_path}: {exc}", "file")
    if not isinstance(mesh, trimesh.Trimesh):
        r.fail(f"{mesh_path} holds no triangle mesh", "file")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        r.fail(f"{mesh_path} holds no triangles", "file")
    if not np.all(np.isfinite(vertices)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))[0])
        r.fail(f"{mesh_path} has a non-finite vertex (vertex {bad}: {vertices[bad].tolist()})", "file")
    if faces.min() < 0 or faces.max() >= len(vertices):
        r.fail(f"{mesh_path} has a face index outside its {len(vertices)} vertices", "file")
    return vertices, faces
