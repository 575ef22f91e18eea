"""Textures: material parameters that vary over a surface, with its (u, v) coordinates or its
mesh's corners.

Three kinds, as Mitsuba 3 defines them (src/textures/checkerboard.cpp, bitmap.cpp,
mesh_attribute.cpp):

- ``checkerboard``: ``color0`` where the fractional parts of u and v are both above or both
  at most 1/2, ``color1`` elsewhere (Mitsuba's one-channel lookup swaps the two: tracer does
  the same for a one-number parameter such as a roughness);
- ``bitmap``: an image (``tracer.textures.bitmap``) looked up nearest or bilinearly, its
  texel (i, j) centred at ((i + 1/2) / W, (j + 1/2) / H) with row 0 the image's top, beyond
  [0, 1] repeated, mirrored or clamped; a one-number parameter takes the RGB value's
  luminance, as Mitsuba's ``eval_1`` does.

- ``mesh_attribute``: a value a mesh file gives its vertices or faces (Mitsuba's
  src/textures/mesh_attribute.cpp, read from PLY files by ``tracer.scene.mesh``): a vertex
  attribute interpolated between the hit triangle's corners by the hit's barycentrics, a face
  attribute constant on the face; times ``scale``. As in Mitsuba, a one-channel attribute
  feeds a colour as grey, and a one-number parameter reads a three-channel one as 0
  (``eval_1`` of an attribute with another number of channels is 0).

A texture may also perturb a material's shading frame (:class:`Perturbation`, Mitsuba's
``normalmap`` and ``bumpmap`` BSDFs around the material; ``tracer.textures.shading_frames``).

The first two first map (u, v) by ``to_uv``, a 2 x 3 affine matrix (Mitsuba reads a 4 x 4 transform and
keeps its upper-left 2 x 2 block and the first two entries of its last column).

A scene's :class:`TextureTable` holds its textures and which material parameter each feeds
(:class:`Binding`). The material table holds, in a textured parameter's columns, the texture's
mean: what a material's derived constants are computed from, as Mitsuba computes, e.g., the
plastic's lobe-selection weight from its textures' means. During shading the kernels overwrite
those columns with the texture's value at the hit (``tracer.textures.lookup``). Only
parameters whose type marks them ``texture=True`` may be textured: those that no derived
column depends on except through a mean.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

CHECKERBOARD, BITMAP, MESH_ATTRIBUTE = 1, 2, 3
KINDS = {"checkerboard": CHECKERBOARD, "bitmap": BITMAP, "mesh_attribute": MESH_ATTRIBUTE}
NEAREST, BILINEAR = 0, 1
FILTERS = ("nearest", "bilinear")
REPEAT, MIRROR, CLAMP = 0, 1, 2
WRAPS = ("repeat", "mirror", "clamp")

# Columns of a texture's row in ``Textures.info`` (float64).
KIND, TO_UV, FILTER, WRAP, WIDTH, HEIGHT, OFFSET, COLOR0, COLOR1 = 0, 1, 7, 8, 9, 10, 11, 12, 15
INFO_WIDTH = 18
# Columns of a material row's perturbation in ``Textures.perturb`` (float64): its kind (0 none,
# NORMAL_MAP, BUMP_MAP, or FRAME: no tilt, but shaded in Mitsuba's frame of dp/du, for a material
# whose value depends on the tangent: ``MaterialType.oriented``), its texture, a bump map's
# scale, and Mitsuba's two switches.
PERTURB_KIND, PERTURB_TEXTURE, PERTURB_SCALE, PERTURB_FLIP, PERTURB_SHADOWING = 0, 1, 2, 3, 4
PERTURB_WIDTH = 5
NORMAL_MAP, BUMP_MAP, FRAME = 1, 2, 3
PERTURBATIONS = {"normalmap": NORMAL_MAP, "bumpmap": BUMP_MAP}
# Rec. 709 luminance, as Mitsuba's ``luminance`` (include/mitsuba/core/spectrum.h).
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


@dataclass
class Texture:
    """One texture.

    kind : ``checkerboard`` or ``bitmap``.   to_uv : (2, 3) affine map of (u, v, 1).
    color0, color1 : (3,) a checkerboard's colours.
    pixels : (H, W, 3) float32 linear values of a bitmap, row 0 the image's top.
    filter, wrap : a bitmap's lookup (``FILTERS``, ``WRAPS``).
    source : where it came from (a file, an element), for messages and the TOML writer.
    attribute, scale : a mesh attribute's name (``vertex_color``) and factor. Its ``pixels``
        are (F, 9) float32, the (scaled) value at the three corners of every triangle of the
        scene as RGB (a one-channel attribute repeated), filled in once the shapes are read
        (:meth:`resolve`); ``channels`` the attribute's, ``present`` (F,) which triangles'
        shapes have it.
    """

    kind: str
    to_uv: np.ndarray = field(default_factory=lambda: np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
    color0: np.ndarray = field(default_factory=lambda: np.full(3, 0.4))
    color1: np.ndarray = field(default_factory=lambda: np.full(3, 0.2))
    pixels: np.ndarray | None = None
    filter: str = "bilinear"
    wrap: str = "repeat"
    source: str = ""
    raw: bool = False
    attribute: str = ""
    scale: float = 1.0
    channels: int = 3
    present: np.ndarray | None = None

    def resolve(self, corners: np.ndarray, present: np.ndarray, channels: int) -> None:
        """A mesh attribute's values: ``corners`` (F, 3, C) at every scene triangle's corners
        (zeros where ``present`` (F,) is False: shapes without it), C = ``channels``."""
        rgb = np.repeat(corners, 3, axis=2) if channels == 1 else corners
        self.pixels = np.ascontiguousarray((rgb * self.scale).reshape(-1, 9), dtype=np.float32)
        self.present, self.channels = np.asarray(present, dtype=bool), channels

    def _attribute_values(self, channels: int) -> np.ndarray:
        """A mesh attribute's corner values on the triangles that have it, as ``channels``
        numbers per corner (a one-number lookup of a three-channel attribute is 0, Mitsuba's)."""
        values = self.pixels[self.present].reshape(-1, 3).astype(np.float64)
        if channels == 1:
            return values[:, :1] if self.channels == 1 else np.zeros((max(len(values), 1), 1))
        return values if len(values) else np.zeros((1, 3))

    def mean(self, channels: int) -> np.ndarray:
        """The texture's mean over [0, 1]² as ``channels`` (1 or 3) numbers: what derived
        material constants use. A bitmap's one-number mean is its luminance's, as Mitsuba's; a
        mesh attribute's mean is over its triangles' corners."""
        if self.kind == "mesh_attribute":
            return self._attribute_values(channels).mean(axis=0)
        if self.kind == "checkerboard":
            rgb = 0.5 * (self.color0 + self.color1)
        else:
            rgb = self.pixels.reshape(-1, 3).astype(np.float64).mean(axis=0)
        return rgb if channels == 3 else np.array([float(rgb @ LUMINANCE) if self.kind == "bitmap"
                                                   else float(np.mean(rgb))])

    def value_range(self) -> tuple[float, float]:
        """The smallest and largest value any lookup can give (bilinear and barycentric weights
        are convex)."""
        if self.kind == "mesh_attribute":
            values = self._attribute_values(3)
        else:
            values = (np.concatenate([self.color0, self.color1]) if self.kind == "checkerboard"
                      else self.pixels)
        return float(np.min(values)), float(np.max(values))


@dataclass(frozen=True)
class Perturbation:
    """A texture that perturbs a material's shading frame, as Mitsuba 3.9.1's ``normalmap`` and
    ``bumpmap`` BSDFs do around the BSDF they wrap (src/bsdfs/normalmap.cpp, bumpmap.cpp).

    kind : ``normalmap`` (the texture's RGB is the normal, 2 rgb - 1, in the shading frame whose
        s axis is dp/du) or ``bumpmap`` (the texture is a height field: its gradient, times
        ``scale``, tilts dp/du and dp/dv).
    flip_invalid : a normal facing away from the viewer is mirrored about the shading normal
        (Mitsuba's ``flip_invalid_normals``).   shadowing : the BSDF is multiplied by Estevez
        et al.'s bump-terminator shadowing (Mitsuba's ``use_shadowing_function``).
    """

    kind: str
    texture: Texture
    scale: float = 1.0
    flip_invalid: bool = True
    shadowing: bool = True


# tracer's material types with a delta transmission (``MaterialType.transmits`` marks those
# whose transmission has a density).
_DELTA_TRANSMITTERS = frozenset({"dielectric", "thindielectric"})


def tiltable(kind) -> bool:
    """Whether a normal or bump map may wrap material type ``kind`` (a ``MaterialType``): one
    that only reflects. tracer's tilted frame masks and shadows reflected samples only."""
    return not (getattr(kind, "transmits", False) or kind.name in _DELTA_TRANSMITTERS)


@dataclass(frozen=True)
class Binding:
    """Texture ``texture`` feeds parameter ``param`` (``size`` columns from ``column``) of the
    material in row ``material``; lookups are clamped into [lo, hi], the parameter's range."""

    material: int
    param: str
    column: int
    size: int
    texture: int
    lo: float
    hi: float


class Textures(NamedTuple):
    """The textures as the kernels read them.

    info : (T, INFO_WIDTH) float64, a row per texture (columns ``KIND`` ...).
    pixels : (N,) float32, every bitmap's texels one after another (RGB, row by row).
    bindings : (B, 5) float64 rows (column, size, texture, lo, hi), grouped by material.
    first_binding : (K + 1,) int64: material k's bindings are rows first_binding[k] ..
        first_binding[k + 1] - 1.
    opacity : (K,) int64 per material row, the texture that gives its opacity
        (``MaterialTable.opacity``), -1 where it is a constant.
    perturb : (K, PERTURB_WIDTH) float64 per material row, its normal or bump map (columns
        ``PERTURB_KIND`` ...; kind 0: none).
    corner_uv : (F, 6) float64 (u, v) at each triangle's three corners, or (0, 6).
    sphere_frame : (S, 9) float64 rows of each analytic sphere's world-to-local rotation, for
        Mitsuba's spherical (u, v), or (0, 9).
    span : (K,) int64 per material row, the rows its material takes (``MaterialType.rows``: a
        blend's parts follow it), whose textures a hit on it reads together.
    emission : (F + S,) int64 per primitive, the texture that gives its emitted radiance
        (``TextureTable.emitters``), -1 where it is the constant of the hit table; (0,) when no
        emitter is textured.
    """

    info: np.ndarray
    pixels: np.ndarray
    bindings: np.ndarray
    first_binding: np.ndarray
    opacity: np.ndarray
    corner_uv: np.ndarray
    sphere_frame: np.ndarray
    perturb: np.ndarray
    span: np.ndarray
    emission: np.ndarray


@dataclass
class TextureTable:
    """A scene's textures and what they feed: material parameters (``bindings``), the
    opacity of material rows (``cutouts``: row -> texture index) and their shading frames
    (``perturbations``: row -> (kind code, texture index, scale, flip_invalid, shadowing)), and
    the rows shaded in Mitsuba's frame of dp/du without a map (``frames``: anisotropic
    materials, ``MaterialType.oriented``), and the emitting shapes whose radiance a texture
    gives (``emitters``: shape index -> texture index; Mitsuba's ``area`` emitter with a
    ``radiance`` texture). A textured emitter's constant emission, in the scene's arrays, is the
    texture's mean: what the light selection weighs it by."""

    textures: list[Texture] = field(default_factory=list)
    bindings: list[Binding] = field(default_factory=list)
    cutouts: dict[int, int] = field(default_factory=dict)
    perturbations: dict[int, tuple[int, int, float, bool, bool]] = field(default_factory=dict)
    frames: set[int] = field(default_factory=set)
    emitters: dict[int, int] = field(default_factory=dict)

    def __bool__(self) -> bool:
        """Whether anything reads texture coordinates (then the scene keeps them)."""
        return bool(self.bindings or self.cutouts or self.perturbations or self.frames or self.emitters)

    @property
    def textured(self) -> bool:
        """Whether any texture is used (``frames`` alone use none: a TOML file holds them)."""
        return bool(self.bindings or self.cutouts or self.perturbations or self.emitters)

    @property
    def shading(self) -> bool:
        """Whether a lookup happens during shading (a bound parameter, a perturbed frame or a
        textured emitter): what the kernels' ``TEXTURES`` switch is for. Opacity alone is read
        by the cutouts."""
        return bool(self.bindings or self.perturbations or self.frames or self.emitters)

    def add(self, texture: Texture) -> int:
        """The index of ``texture`` in the table, added unless it is there (the same object)."""
        index = next((i for i, t in enumerate(self.textures) if t is texture), None)
        if index is None:
            self.textures.append(texture)
            index = len(self.textures) - 1
        return index

    def bind_opacity(self, row: int, opacity: "Texture | float") -> float:
        """Material ``row``'s opacity (Mitsuba's ``mask``): a number in [0, 1], returned as it
        is, or a texture, bound to the row here and returned as its mean (clamped into [0, 1]:
        lookups are clamped, as Mitsuba clamps them)."""
        if not isinstance(opacity, Texture):
            return float(opacity)
        self.cutouts[row] = self.add(opacity)
        return float(np.clip(opacity.mean(1)[0], 0.0, 1.0))

    def bind_perturbation(self, row: int, perturbation: Perturbation) -> None:
        """Material ``row``'s shading frame is perturbed by ``perturbation``."""
        p = perturbation
        self.perturbations[row] = (PERTURBATIONS[p.kind], self.add(p.texture), float(p.scale),
                                   bool(p.flip_invalid), bool(p.shadowing))

    def bind_emission(self, shape: int, texture: Texture) -> np.ndarray:
        """Shape ``shape`` emits the radiance ``texture`` gives (>= 0 everywhere); returns its
        mean RGB (3,), the shape's constant emission."""
        self.emitters[shape] = self.add(texture)
        return np.maximum(texture.mean(3), 0.0)

    def emission_by_primitive(self, shape_of_triangle: np.ndarray, shape_of_sphere: np.ndarray) -> np.ndarray:
        """``Textures.emission``: (F + S,) int64 the texture of each primitive's emission (-1:
        none), primitives ordered as the hit table (triangles, then spheres); (0,) when no
        emitter is textured."""
        if not self.emitters:
            return np.zeros(0, dtype=np.int64)
        shapes = np.concatenate([shape_of_triangle, shape_of_sphere]).astype(np.int64)
        by_shape = np.full(max(int(shapes.max(initial=-1)), max(self.emitters)) + 1, -1, dtype=np.int64)
        for shape, texture in self.emitters.items():
            by_shape[shape] = texture
        return by_shape[shapes]

    def arrays(self, material_count: int, corner_uv: np.ndarray, sphere_frame: np.ndarray,
               copies: dict[int, int] | None = None, span: np.ndarray | None = None,
               emission: np.ndarray | None = None) -> Textures:
        """The kernels' arrays (``Textures``) for a table of ``material_count`` materials.
        ``copies``: row -> the row whose bindings it takes too (a two-sided type's inside row,
        ``MaterialTable.shading``, reads the textures of its outside). ``span``: the rows each
        row's material takes (default 1 each). ``emission``: ``Textures.emission``
        (:meth:`emission_by_primitive`; default none)."""
        info = np.zeros((len(self.textures), INFO_WIDTH))
        pools, offset = [], 0
        for row, t in zip(info, self.textures, strict=True):
            row[KIND] = KINDS[t.kind]
            row[TO_UV:TO_UV + 6] = t.to_uv.ravel()
            if t.kind == "checkerboard":
                row[COLOR0:COLOR0 + 3], row[COLOR1:COLOR1 + 3] = t.color0, t.color1
                continue
            if t.kind == "mesh_attribute":  # (F, 9) corner values; WIDTH holds the channels
                row[WIDTH], row[OFFSET] = t.channels, offset
                pools.append(t.pixels.ravel())
                offset += pools[-1].size
                continue
            height, width, _ = t.pixels.shape
            row[FILTER], row[WRAP] = FILTERS.index(t.filter), WRAPS.index(t.wrap)
            row[WIDTH], row[HEIGHT], row[OFFSET] = width, height, offset
            pools.append(np.ascontiguousarray(t.pixels, dtype=np.float32).ravel())
            offset += pools[-1].size
        copied = [dataclasses.replace(b, material=row) for row, source in (copies or {}).items()
                  for b in self.bindings if b.material == source]
        ordered = sorted(self.bindings + copied, key=lambda b: b.material)
        bindings = np.array([[b.column, b.size, b.texture, b.lo, b.hi] for b in ordered],
                            dtype=np.float64).reshape(-1, 5)
        counts = np.bincount([b.material for b in ordered], minlength=material_count)
        first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        pixels = np.concatenate(pools) if pools else np.zeros(0, dtype=np.float32)
        opacity = np.full(material_count, -1, dtype=np.int64)
        for row, texture in self.cutouts.items():
            opacity[row] = texture
        perturb = np.zeros((material_count, PERTURB_WIDTH))
        for row in self.frames:
            perturb[row, PERTURB_KIND] = FRAME
        for row, values in self.perturbations.items():
            perturb[row] = values
        span = np.ones(material_count, dtype=np.int64) if span is None else np.asarray(span, dtype=np.int64)
        emission = np.zeros(0, dtype=np.int64) if emission is None else np.asarray(emission, dtype=np.int64)
        return Textures(info, pixels, bindings, first, opacity,
                        np.ascontiguousarray(corner_uv, dtype=np.float64),
                        np.ascontiguousarray(sphere_frame, dtype=np.float64), perturb, span,
                        np.ascontiguousarray(emission))

    def digest(self) -> bytes:
        """SHA-256 of everything a render reads of the table (scene digests include it)."""
        h = hashlib.sha256(b"tracer textures 1\0")
        for t in self.textures:
            h.update(f"{t.kind} {t.filter} {t.wrap}\0".encode())
            h.update(np.ascontiguousarray(t.to_uv, dtype="<f8").tobytes())
            if t.kind == "checkerboard":
                h.update(np.concatenate([t.color0, t.color1]).astype("<f8").tobytes())
            else:
                if t.kind == "mesh_attribute":
                    h.update(f"{t.channels}\0".encode())
                h.update(f"{t.pixels.shape}\0".encode())
                h.update(np.ascontiguousarray(t.pixels, dtype="<f4").tobytes())
        for b in self.bindings:
            h.update(f"{b.material} {b.param} {b.column} {b.size} {b.texture} {b.lo!r} {b.hi!r}\0".encode())
        for row, texture in sorted(self.cutouts.items()):  # none in scenes digested before masks
            h.update(f"opacity {row} {texture}\0".encode())
        for row, values in sorted(self.perturbations.items()):  # none before normal maps
            h.update(f"perturb {row} {values!r}\0".encode())
        for row in sorted(self.frames):  # none before anisotropic roughness
            h.update(f"frame {row}\0".encode())
        for shape, texture in sorted(self.emitters.items()):  # none before textured emitters
            h.update(f"emits {shape} {texture}\0".encode())
        return h.digest()


def bind(table: TextureTable, row: int, kind, values: dict[str, object], where: str,
         notes: list[str] | None = None) -> dict[str, object]:
    """``values`` of material ``row`` (type ``kind``, a ``MaterialType``) with each texture
    replaced by its mean clamped into the parameter's range, the texture bound to the parameter
    in ``table``. A texture's values beyond the range are told in ``notes`` (lookups are clamped).
    Raises ValueError for a parameter the type reads no texture for; ``where`` names the scene."""
    out = dict(values)
    for param in kind.params:
        texture = values.get(param.name)
        if not isinstance(texture, Texture):
            continue
        if not param.texture:
            raise ValueError(f"{kind.name}'s {param.name} cannot be a texture ({texture.source or where})")
        lo = -math.inf if param.lo is None else param.lo
        hi = math.inf if param.hi is None else param.hi
        low, high = texture.value_range()
        if (low < lo or high > hi) and notes is not None:
            notes.append(f"{texture.source or where}: the texture's values ({low:.4g} .. {high:.4g}) are "
                         f"clamped into {param.name}'s range ({lo:g} .. {hi:g})")
        index = table.add(texture)
        table.bindings.append(Binding(row, param.name, kind.column(param.name), param.size, index, lo, hi))
        mean = np.clip(texture.mean(param.size), lo, hi)
        out[param.name] = float(mean[0]) if param.size == 1 else mean
    return out


def empty_arrays(material_count: int) -> Textures:
    """The arrays of a scene without textures."""
    return TextureTable().arrays(material_count, np.zeros((0, 6)), np.zeros((0, 9)))
