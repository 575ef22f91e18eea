"""The Mitsuba 3 XML scene reader: a subset of Mitsuba's scene format -> :class:`Scene`.

``docs/MITSUBA_XML.md`` lists what is read and what is refused. The document itself
(includes, defaults, ids, values) is :mod:`tracer.scene.mitsuba_document`; spectra become RGB
in :mod:`tracer.scene.spectrum`. This module reads the plugins: the sensor becomes tracer's
camera, shapes become triangles (rectangles as quads, spheres as analytic spheres), BSDFs
become rows of the material table (one-sided unless wrapped in ``twosided``, as in Mitsuba)
and emitters become emission and point lights, with Mitsuba 3.9.1's defaults, which were
checked against Mitsuba itself (``tests/test_mitsuba_xml.py`` holds the numbers). Like the
TOML reader it is strict: an unknown plugin or property, a texture, a value out of range or a
missing file raises :class:`InputError` naming the file, the line and the element.

What Mitsuba would do differently and tracer cannot (its integrator, pixel filter, sampler
type, film format, clipping planes) is read and told in one line through ``notify``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .. import materials
from ..camera import Camera
from ..errors import InputError, one_line, shown
from ..lights import projected_images
from ..lights.projected_images import HEADER_WIDTH, MAX_TABLE_FLOATS, ProjectedImage
from ..materials import blendbsdf, conductor, plastic, principled, principledthin
from ..record import MAX_SAMPLE_INDEX
from ..textures import FILTERS, LUMINANCE, WRAPS, Perturbation, Texture, bind, tiltable
from ..textures.bitmap import read_texels
from . import spectrum
from .environment import Environment, rotation_problem
from .mesh import MeshError, angle_weighted_normals, read_mesh_file
from .mitsuba_document import (
    OBJECT_TAGS,
    PROPERTY_TAGS,
    Document,
    Element,
    boolean,
    integer,
    number,
    numbers,
    read_document,
    transform_matrix,
    xyz,
)
from .mitsuba_upgrade import upgrade_document
from .model import Scene
from .serialized import read_serialized
from .toml_reader import MAX_COORDINATE, MAX_RADIANCE, MAX_SIDE, NO_UV, _Geometry, check_resolution

# Mitsuba 3.9.1's defaults (checked by loading scenes and reading them back with mi.traverse).
FILM_SIZE = (768, 576)
FOCAL_LENGTH_MM = 50.0  # a perspective sensor without fov or focal_length
FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)  # focal_length is a 35 mm film equivalent
# A projected image's frustum: tan(angle / 2) and its inverse stay in float32 and its corners'
# 1 / cos^3 finite (``projected_images.image_factor``).
MIN_PROJECTION_DEGREES = 1e-4
MAX_PROJECTOR_DEGREES = 179.0
MIN_ALPHA = 1e-4  # Mitsuba's microfacet distributions clamp alpha to at least this
# A disk is a fan of this many triangles: its area is (N/2) sin(2 pi/N) r^2, within 8e-5 of
# pi r^2 (the issue asks for 0.01%).
DISK_SEGMENTS = 288
# A cylinder is a tube of this many quads: each facet within 1 - cos(pi/N) = 6e-5 of the radius.
CYLINDER_SEGMENTS = 288
# A camera transform whose linear part M has an entry of M M^T - I beyond this scales or shears:
# Mitsuba 3.9.1's own test (Transform::has_scale in include/mitsuba/core/transform.h, which the
# perspective sensor's constructor applies, src/sensors/perspective.cpp), so tracer refuses what
# Mitsuba refuses and takes every camera it takes. A rotation printed to 6 significant digits is
# about 1e-6 from rigid, to 5 digits about 1e-5 (the 1e-5 tracer had refused those). Mitsuba casts
# rays along M d as given; tracer's camera is the rigid frame of M's forward and up columns, so
# the image centre is Mitsuba's and a ray elsewhere is off by about the deviation in radians: a
# pixel (9e-4 radians at 768 pixels across 40 degrees) at this limit, 1/1000 of one at 6 digits.
RIGID_TOLERANCE = 1e-3

_REFLECTANCES = ("reflectance", "diffuse_reflectance", "specular_reflectance")
_READ_BSDFS = frozenset({"diffuse", "conductor", "roughconductor", "plastic", "roughplastic", "pplastic",
                         "twosided", "dielectric", "thindielectric", "roughdielectric", "mask",
                         "normalmap", "bumpmap", "blendbsdf", "principled",
                         "principledthin"})
# BSDFs that wrap one other: a row of its own for the BSDF inside, carrying what they add.
_WRAPPERS = ("twosided", "mask", "normalmap", "bumpmap")
_DIELECTRICS = frozenset({"dielectric", "roughdielectric", "thindielectric"})
# Mitsuba 3.9.1's BSDF plugins (src/bsdfs/*.cpp): an unused declaration of one that tracer does
# not read is accepted unread (it changes no image); any other type is unknown to Mitsuba too.
_MITSUBA_BSDFS = _READ_BSDFS | _DIELECTRICS | frozenset({
    "blendbsdf", "bumpmap", "circular", "hair", "mask", "measured", "measured_polarized", "normalmap",
    "null", "polarizer", "pplastic", "principled", "principledthin", "retarder"})
_UNSUPPORTED_ANYWHERE = {
    "medium": "participating media are not supported (tracer renders surfaces in vacuum)",
    "phase": "participating media are not supported (tracer renders surfaces in vacuum)",
    "volume": "participating media are not supported (tracer renders surfaces in vacuum)",
}

def read_mitsuba_scene(path: str, width: int | None = None, height: int | None = None,
                       base: Path | None = None, notify: Callable[[str], None] | None = None,
                       parameters: dict[str, str] | None = None) -> Scene:
    """Read the Mitsuba 3 XML scene ``path``; ``width``/``height`` override the film's size,
    ``base`` the folder relative mesh files are looked for in (default: the scene's folder),
    ``parameters`` define the file's ``$name``s (Mitsuba's ``-D name=value``).
    A file of Mitsuba version 0.x or 1.x is first upgraded as Mitsuba 3 upgrades it
    (:mod:`tracer.scene.mitsuba_upgrade`), and that is told in one line. What the scene asks
    for and tracer does not do is passed to ``notify`` as one line."""
    document = read_document(path, base, parameters)
    upgrade = upgrade_document(document)
    reader = _SceneReader(document, width, height)
    scene = reader.read()
    if upgrade is not None and notify is not None:
        notify(one_line(upgrade.note(path)))
    if reader.notes and notify is not None:
        notify(one_line(f"{path}: tracer renders direct light with its own strategies and a box filter; "
                        f"not obeyed: {'; '.join(reader.notes)}"))
    return scene


class _Plugin:
    """Typed access to one object element's properties and nested objects, remembering what was
    read: ``done()`` refuses whatever was not (as the TOML reader refuses unknown keys)."""

    def __init__(self, document: Document, element: Element, notes: list[str]):
        self.document = document
        self.element = element
        self.notes = notes  # the reader's one line of what is not obeyed
        self.type = element.attrs.get("type", "")
        self.props: dict[str, Element] = {}
        self.objects: list[tuple[Element, Element]] = []  # (object, the element that names it)
        for child in element.children:
            if child.tag in PROPERTY_TAGS:
                name = child.attr("name")
                if name in self.props:
                    child.fail(f"property '{shown(name)}' is given twice (first at line "
                               f"{self.props[name].line})", element)
                self.props[name] = child
            elif child.tag == "ref":
                self.objects.append((document.resolve(child), child))
            elif child.tag in OBJECT_TAGS:
                self.objects.append((child, child))
            else:
                child.fail("unknown element", element)
        self.used: set[str] = set()
        self.taken: set[int] = set()

    def fail(self, message: str) -> None:
        self.element.fail(message)

    def has(self, name: str) -> bool:
        return name in self.props

    def prop(self, name: str, tags: tuple[str, ...]) -> Element | None:
        self.used.add(name)
        element = self.props.get(name)
        if element is not None and element.tag not in tags:
            element.fail(f"'{name}' is a {' or '.join(tags)}, not a {element.tag}", self.element)
        return element

    def _check(self, element: Element, value: float, lo: float | None, hi: float | None,
               lo_open: bool = False) -> None:
        name = element.attrs.get("name", "value")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            element.fail(f"{name}: expected a number {'>' if lo_open else '>='} {lo:g}, got {value:g}",
                         self.element)
        if hi is not None and value > hi:
            element.fail(f"{name}: expected a number <= {hi:g}, got {value:g}", self.element)

    def float(self, name: str, default: float, lo: float | None = None, hi: float | None = None,
              lo_open: bool = False) -> float:
        element = self.prop(name, ("float", "integer"))
        if element is None:
            return default
        value = number(element, element.attr("value"), name)
        self._check(element, value, lo, hi, lo_open)
        return value

    def integer(self, name: str, default: int, lo: int, hi: int) -> int:
        element = self.prop(name, ("integer",))
        if element is None:
            return default
        value = integer(element, element.attr("value"), name)
        self._check(element, value, lo, hi)
        return value

    def boolean(self, name: str, default: bool) -> bool:
        element = self.prop(name, ("boolean",))
        return default if element is None else boolean(element, element.attr("value"), name)

    def string(self, name: str, default: str | None) -> str | None:
        element = self.prop(name, ("string",))
        return default if element is None else element.attr("value")

    def point(self, name: str, default: np.ndarray | None) -> np.ndarray | None:
        element = self.prop(name, ("point", "vector"))
        if element is None:
            return default
        value = xyz(element, None, name)
        if np.max(np.abs(value)) > MAX_COORDINATE:
            element.fail(f"{name}: beyond the coordinate range +-{MAX_COORDINATE:g}", self.element)
        return value

    def color(self, name: str, default: float, kind: str, lo: float = 0.0,
              hi: float | None = None) -> np.ndarray:
        """An RGB colour from ``<rgb>``, ``<float>`` or ``<spectrum>``. ``kind``: "reflectance"
        (a spectrum under D65, clamped to [0, 1]), "emitter" (a spectrum as power, a constant
        spectrum equal-energy white) or "other" (under D65, clamped at 0)."""
        element = self.prop(name, ("rgb", "float", "integer", "spectrum"))
        if element is None:
            return np.full(3, float(default))
        if element.tag == "spectrum" and "filename" in element.attrs:
            element.fail("spectra from files are not supported (give value=\"wavelength:value, ...\")",
                         self.element)
        text = element.attr("value")
        if element.tag == "rgb":
            values = numbers(element, text, name)
            if len(values) not in (1, 3):
                element.fail(f"{name}: an RGB value has 1 or 3 numbers, not {len(values)}", self.element)
            rgb = np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)
        elif element.tag != "spectrum" or ":" not in text:
            value = number(element, text, name)
            rgb = (spectrum.constant_emitter_rgb(value) if element.tag == "spectrum" and kind == "emitter"
                   else np.full(3, value))
        else:
            rgb = self._tabulated(element, text, name, kind)
        for channel in rgb:
            self._check(element, float(channel), lo, hi)
        return rgb

    def _tabulated(self, element: Element, text: str, name: str, kind: str) -> np.ndarray:
        pairs = [token for token in text.replace(",", " ").split() if token]
        wavelengths, values = [], []
        for token in pairs:
            parts = token.split(":")
            if len(parts) != 2:
                element.fail(f"{name}: expected wavelength:value pairs, got '{shown(token)}'", self.element)
            wavelengths.append(number(element, parts[0], name))
            values.append(number(element, parts[1], name))
        if len(wavelengths) < 2:
            element.fail(f"{name}: a spectrum needs at least two wavelength:value pairs", self.element)
        if np.any(np.diff(wavelengths) <= 0.0) or wavelengths[0] <= 0.0:
            element.fail(f"{name}: wavelengths must be positive and increasing", self.element)
        rgb = spectrum.tabulated_rgb(np.array(wavelengths), np.array(values), emitter=kind == "emitter")
        clamped = np.clip(rgb, 0.0, 1.0 if kind == "reflectance" else None)
        if not np.array_equal(clamped, rgb):
            channels = ", ".join(f"{c:.4g}" for c in rgb)
            self.notes.append(f"{element.where}: {name}'s spectrum is ({channels}) in sRGB, clamped into "
                              "range as Mitsuba clamps it")
        return clamped

    def transform(self, name: str = "to_world") -> np.ndarray | None:
        element = self.prop(name, ("transform",))
        return None if element is None else transform_matrix(element)

    def nested(self, tag: str) -> list[tuple[Element, Element]]:
        """The nested objects (or references) of element ``tag``."""
        found = [(obj, written) for obj, written in self.objects if obj.tag == tag]
        self.taken.update(id(written) for _, written in found)
        return found

    def done(self) -> None:
        for name, element in self.props.items():
            if name not in self.used:
                element.fail(f"{shown(self.type)} has no property '{shown(name)}' that tracer reads",
                             self.element)
        for obj, written in self.objects:
            if id(written) not in self.taken:
                written.fail(f"a <{obj.tag}> is not expected inside <{self.element.tag} "
                             f"type=\"{shown(self.type)}\">", self.element)


class _SceneReader:
    def __init__(self, document: Document, width: int | None, height: int | None):
        self.document = document
        self.width, self.height = width, height
        self.notes: list[str] = []
        self.geometry = _Geometry()
        self.triples: list[tuple[str, str, dict[str, object]]] = []
        self.sides: list[bool] = []
        self.opacities: dict[int, object] = {}  # a masked row's opacity: a number or a Texture
        self.perturbations: dict[int, Perturbation] = {}  # a normal or bump map's row
        self.rows: dict[tuple[int, bool], int] = {}
        self.names: set[str] = set()
        self.emitter_owner: dict[int, Element] = {}
        self.positions: list[np.ndarray] = []
        self.intensities: list[np.ndarray] = []
        self.render: dict[str, Any] = {}
        self.default_row: int | None = None
        self.textures_read: dict[int, Texture] = {}  # by the id of the texture's element
        self.groups: dict[int, list[Element]] = {}  # a shapegroup's shapes, by its element's id
        self.images: dict[tuple[str, bool], np.ndarray] = {}  # texels by (file, raw)
        self.environment: Environment | None = None
        self.environment_element: Element | None = None
        self.spots: list[tuple[np.ndarray, float, float]] = []  # per point light: axis, cutoff, beam (deg)
        self.point_images: list[ProjectedImage | None] = []  # per point light: what it projects
        self.projected_floats = 0  # the light table's floats those images take (``projected_texture``)
        self.bsdfs_reading: set[int] = set()  # the BSDF elements being read (``material_parts``)
        self.directionals: list[tuple[np.ndarray, np.ndarray]] = []  # direction, irradiance

    def plugin(self, element: Element) -> _Plugin:
        return _Plugin(self.document, element, self.notes)

    def read(self) -> Scene:
        root = self.document.root
        _refuse_unsupported(root)
        sensors, declared_bsdfs, declared_emitters, declared_textures = [], [], [], []
        for child in root.children:
            if child.tag == "sensor":
                sensors.append(child)
            elif child.tag == "shape":
                self.shape(child)
            elif child.tag == "emitter":
                if child.attrs.get("type") == "area":
                    declared_emitters.append(child)
                elif child.attrs.get("type") in ("envmap", "constant"):  # the environment
                    self.environment_emitter(child)
                else:
                    self.point_emitter(child)
            elif child.tag == "bsdf":
                declared_bsdfs.append(child)
            elif child.tag == "integrator":
                self.integrator(child)
            elif child.tag == "sampler":
                self.notes.append(f"{child.where}: a <sampler> outside the <sensor> (Mitsuba ignores it too)")
            elif child.tag in ("film", "rfilter") and "id" in child.attrs:
                pass  # a declaration, read where a sensor refers to it
            elif child.tag == "texture":
                declared_textures.append(child)
            elif child.tag in PROPERTY_TAGS:
                child.fail("a property directly inside <scene> (properties belong inside an object)")
            elif child.tag == "ref":
                child.fail("a <ref> directly inside <scene> is not supported (declare the object here)")
            else:
                child.fail("not expected directly inside <scene>")
        # Declarations nothing refers to are still checked, as Mitsuba builds them too.
        used = {key[0] for key in self.rows}
        self.unused_bsdfs([element for element in declared_bsdfs if id(element) not in used])
        for element in declared_emitters:
            if id(element) not in self.emitter_owner:
                self.area_radiance(element)
        for element in declared_textures:  # checked as Mitsuba builds them, used or not
            self.texture(element, "reflectance")
        if not sensors:
            root.fail("no <sensor>: tracer needs a camera (a perspective sensor)")
        if len(sensors) > 1:
            self.notes.append(f"{sensors[1].where}: {len(sensors)} sensors, tracer uses the first")
        camera = self.camera(sensors[0])
        return self.scene(camera)

    # -- sensor -----------------------------------------------------------------------------

    def camera(self, element: Element) -> Camera:
        p = self.plugin(element)
        if p.type not in ("perspective", "thinlens", "orthographic"):
            p.fail(f"sensor '{shown(p.type)}' is not supported; tracer reads perspective, thinlens and "
                   "orthographic")
        width, height = FILM_SIZE
        films = p.nested("film")
        if len(films) > 1:
            films[1][1].fail("a sensor has one film", element)
        if films:
            width, height = self.film(*films[0])
        samplers = p.nested("sampler")
        if len(samplers) > 1:
            samplers[1][1].fail("a sensor has one sampler", element)
        if samplers:
            self.sampler(samplers[0][0])
        # Mitsuba's defaults (ProjectiveCamera, src/render/sensor.cpp). An orthographic ray starts
        # on the near plane, which tracer obeys; near and far planes of the others are noted.
        near_clip = p.float("near_clip", 1e-2, lo=0.0, lo_open=True)
        far_clip = p.float("far_clip", 1e4, lo=0.0, lo_open=True)
        for name in ("near_clip", "far_clip"):
            if p.has(name) and not (p.type == "orthographic" and name == "near_clip"):
                self.notes.append(f"{name} {p.float(name, 0.0):g}")
        for name in ("shutter_open", "shutter_close"):  # no motion in a tracer scene: no effect
            p.float(name, 0.0, lo=0.0)
        # Mitsuba's projective cameras read the focal distance (ProjectiveCamera in
        # src/render/sensor.cpp), by default the far plane; a pinhole's image does not depend on
        # it. (aperture_radius is the thin lens's, which requires it: Mitsuba refuses it
        # elsewhere too, as an unread property.)
        focus_distance = p.float("focus_distance", far_clip, lo=0.0, lo_open=True)
        aperture = 0.0
        if p.type == "thinlens":
            if not p.has("aperture_radius"):
                p.fail("a thinlens sensor needs aperture_radius (Mitsuba has no default)")
            aperture = p.float("aperture_radius", 0.0, lo=0.0, hi=MAX_COORDINATE)
            if focus_distance > MAX_COORDINATE:
                p.fail(f"focus_distance {focus_distance:g} is beyond the coordinate range "
                       f"+-{MAX_COORDINATE:g}")
        for name in ("principal_point_offset_x", "principal_point_offset_y"):
            if p.type != "orthographic" and p.float(name, 0.0) != 0.0:
                p.props[name].fail("an off-centre principal point is not supported", element)

        w, h = _resolution(width, height, self.width, self.height)
        check_resolution(w, h, element.where, "film width/height")
        matrix = p.transform()
        matrix = np.eye(4) if matrix is None else matrix
        if p.type == "orthographic":
            return self.orthographic(p, matrix, near_clip, int(w), int(h))
        tan_half = self.tan_half_vertical(p, w, h)
        fov = math.degrees(2.0 * math.atan(tan_half))
        if not 0.0 < fov <= 179.0:
            p.fail(f"the vertical field of view is {fov:.6g} degrees at {w}x{h}; tracer's camera takes up "
                   "to 179")
        linear = matrix[:3, :3]
        # A rigid rotation's entries lie in [-1, 1]; beyond 2 (1e308 overflowed the product with a
        # numpy warning) it is refused without forming M M^T.
        if np.max(np.abs(linear)) > 2.0 or np.max(np.abs(linear @ linear.T - np.eye(3))) > RIGID_TOLERANCE:
            p.props["to_world"].fail("the camera's to_world scales or shears (Mitsuba refuses scale factors "
                                     "in a camera's transform too): remove the scale", element)
        origin = matrix[:3, 3]
        if np.max(np.abs(origin)) > MAX_COORDINATE:
            p.fail(f"the camera is beyond the coordinate range +-{MAX_COORDINATE:g}")
        p.done()
        # Mitsuba's camera looks along its local +z with local +y up, and its local +x points to
        # the image's LEFT; tracer's image x runs along forward x up, which is -x exactly when
        # the transform keeps handedness (a mirror, det < 0, makes the image run the other way).
        mirrored = bool(np.linalg.det(linear) < 0.0)
        return Camera(origin.copy(), origin + linear[:, 2], linear[:, 1].copy(), fov, int(w), int(h),
                      mirrored=mirrored, aperture_radius=aperture, focus_distance=focus_distance)

    def orthographic(self, p: _Plugin, matrix: np.ndarray, near_clip: float, w: int, h: int) -> Camera:
        """Mitsuba's ``orthographic`` sensor (src/sensors/orthographic.cpp, and
        ``orthographic_projection`` in include/mitsuba/render/sensor.h): the film spans local
        x in [-1, 1] and y in [-1 / aspect, 1 / aspect] on the plane z = near_clip, mapped by
        ``to_world``, whose scale sets the film's size; rays run along local +z from there."""
        linear = matrix[:3, :3]
        if not np.all(np.isfinite(matrix)) or np.max(np.abs(linear)) > MAX_COORDINATE:
            p.props["to_world"].fail("the camera's to_world is beyond the coordinate range", p.element)
        lengths = np.linalg.norm(linear, axis=0)
        if np.min(lengths) <= 0.0 or np.max(lengths) / np.min(lengths) > 1e12:
            p.props["to_world"].fail("the camera's to_world scales one axis to zero or over 1e12 times "
                                     "another", p.element)
        axes = linear / lengths
        if np.max(np.abs(axes.T @ axes - np.eye(3))) > RIGID_TOLERANCE:
            p.props["to_world"].fail("the camera's to_world shears: tracer's orthographic camera takes a "
                                     "rotation and scale", p.element)
        if abs(lengths[0] - lengths[1]) > RIGID_TOLERANCE * lengths[0]:
            p.props["to_world"].fail(f"the camera's to_world scales x and y differently ({lengths[0]:g}, "
                                     f"{lengths[1]:g}): tracer's orthographic pixels are square", p.element)
        origin = matrix[:3, 3] + near_clip * linear[:, 2]
        if np.max(np.abs(origin)) > MAX_COORDINATE:
            p.fail(f"the camera is beyond the coordinate range +-{MAX_COORDINATE:g}")
        p.done()
        # Local +x is the image's left, as for the perspective sensor (``camera``).
        mirrored = bool(np.linalg.det(linear) < 0.0)
        return Camera(origin, origin + axes[:, 2], axes[:, 1].copy(), 0.0, w, h, mirrored=mirrored,
                      projection="orthographic", view_width=2.0 * float(lengths[0]))

    def tan_half_vertical(self, p: _Plugin, w: int, h: int) -> float:
        """tan(vertical fov / 2) from fov and fov_axis, or focal_length (a diagonal fov on
        35 mm film), at the film size w x h."""
        if p.has("fov") and p.has("focal_length"):
            p.fail("give fov or focal_length, not both")
        if p.has("focal_length"):
            element = p.prop("focal_length", ("string", "float", "integer"))
            text = element.attr("value").strip()
            millimetres = number(element, text[:-2] if text.endswith("mm") else text, "focal_length")
            p._check(element, millimetres, 0.0, None, lo_open=True)
            return FILM_DIAGONAL_MM / (2.0 * millimetres) * h / math.hypot(w, h)
        if not p.has("fov"):
            return FILM_DIAGONAL_MM / (2.0 * FOCAL_LENGTH_MM) * h / math.hypot(w, h)
        fov = p.float("fov", 0.0, lo=0.0, hi=180.0, lo_open=True)
        if fov >= 180.0:
            p.props["fov"].fail("fov: expected a number < 180", p.element)
        axis = (p.string("fov_axis", "x") or "x").lower()
        if axis not in ("x", "y", "diagonal", "smaller", "larger"):
            p.props["fov_axis"].fail(f"fov_axis: expected x, y, diagonal, smaller or larger; got "
                                     f"'{shown(axis)}'", p.element)
        if axis == "smaller":
            axis = "x" if w < h else "y"
        elif axis == "larger":
            axis = "x" if w > h else "y"
        tan_given = math.tan(math.radians(fov) / 2.0)
        return {"x": tan_given * h / w, "y": tan_given, "diagonal": tan_given * h / math.hypot(w, h)}[axis]

    def film(self, element: Element, written: Element) -> tuple[int, int]:
        p = self.plugin(element)
        if p.type != "hdrfilm":
            hint = " (Mitsuba 0.6's; Mitsuba 3 has none either)" if p.type == "ldrfilm" else ""
            p.fail(f"film '{shown(p.type)}' is not supported{hint}; tracer reads hdrfilm (and writes its own "
                   "EXR)")
        width = p.integer("width", FILM_SIZE[0], 1, MAX_SIDE)
        height = p.integer("height", FILM_SIZE[1], 1, MAX_SIDE)
        crop = {name: p.integer(name, default, 0, MAX_SIDE) for name, default in
                (("crop_offset_x", 0), ("crop_offset_y", 0), ("crop_width", width), ("crop_height", height))}
        if crop != {"crop_offset_x": 0, "crop_offset_y": 0, "crop_width": width, "crop_height": height}:
            p.fail("a crop window is not supported (tracer renders the whole film)")
        for name in ("pixel_format", "component_format", "file_format"):
            value = p.string(name, None)
            if value is not None:
                self.notes.append(f"film {name} \"{shown(value)}\"")
        for name in ("sample_border", "compensate"):
            if p.boolean(name, False):
                self.notes.append(f"film {name}")
        p.used.add("banner")  # Mitsuba 3 reads it, of any type, and writes no banner (hdrfilm.cpp)
        filters = p.nested("rfilter")
        for rfilter, _ in filters:
            f = self.plugin(rfilter)
            f.used.update(f.props)  # its parameters shape the filter tracer does not use
            f.done()
            if f.type != "box":
                self.notes.append(f"<rfilter type=\"{shown(f.type)}\">")
        p.done()
        return width, height

    def sampler(self, element: Element) -> None:
        p = self.plugin(element)
        if p.has("sample_count"):
            self.render["spp"] = p.integer("sample_count", 4, 1, MAX_SAMPLE_INDEX)
        if p.type != "independent":
            self.notes.append(f"<sampler type=\"{shown(p.type)}\"> (tracer uses its --sampler)")
        if p.has("seed"):
            seed = p.integer("seed", 0, -(2**63), 2**64)
            self.notes.append(f"sampler seed {seed} (tracer uses its --seed)")
        p.used.update(p.props)  # jitter, strength, ...: how Mitsuba's sampler places its points
        p.done()

    def integrator(self, element: Element) -> None:
        p = self.plugin(element)
        p.used.update(p.props)
        p.taken.update(id(written) for _, written in p.objects)
        # Mitsuba's direct integrator is what tracer renders (with its own strategies in place of
        # emitter_samples/bsdf_samples): nothing to tell. Any other is not obeyed, and said.
        if p.type != "direct":
            self.notes.append(f"<integrator type=\"{shown(p.type)}\">")

    # -- shapes ----------------------------------------------------------------------------

    def shape(self, element: Element, parent: np.ndarray | None = None) -> None:
        """Read the shape ``element`` into the geometry; ``parent``: the to_world of the instance
        it is read for (a shape of a ``shapegroup``), applied after its own."""
        p = self.plugin(element)
        kind = p.type
        if kind == "shapegroup":
            self.shape_group(p)
            return
        if kind == "instance":
            self.instance(p)
            return
        if kind not in ("obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk", "cylinder"):
            p.fail(f"shape '{shown(kind)}' is not supported; tracer reads obj, ply, serialized, rectangle, "
                   "cube, sphere, disk and cylinder, and instances of shapegroups of them")
        matrix = p.transform()
        matrix = np.eye(4) if matrix is None else matrix
        if parent is not None:
            matrix = parent @ matrix
            if p.nested("emitter"):
                p.fail("an emitter in a shapegroup (Mitsuba refuses it too: \"Instancing of emitters is not "
                       "supported\")")
        if np.max(np.abs(matrix)) > MAX_COORDINATE:
            p.props["to_world"].fail(f"numbers beyond +-{MAX_COORDINATE:g}", element)
        linear = matrix[:3, :3]
        det = float(np.linalg.det(linear))
        if not abs(det) > 0.0 or not math.isfinite(det):
            (p.props.get("to_world") or element).fail("the transform is singular (it flattens the shape)",
                                                      element)
        mirrored = det < 0.0
        flip = p.boolean("flip_normals", False)
        material, emission = self.shape_material(p)
        description = f"{kind} ({element.where})"
        if kind == "sphere":
            self.sphere(p, matrix, flip, mirrored, material, emission)
            return
        if kind in ("obj", "ply", "serialized"):
            self.mesh(p, matrix, flip, mirrored, material, emission)
            return
        if kind == "cylinder":
            self.cylinder(p, matrix, flip, mirrored, material, emission, description)
            return
        if kind == "rectangle":
            # Mitsuba's rectangle faces its to_world normal transform of +z: along the cross
            # product of the transformed edges, or against it when the transform mirrors.
            origin = _apply(matrix, np.array([[-1.0, -1.0, 0.0]]))[0]
            e1, e2 = linear @ np.array([2.0, 0.0, 0.0]), linear @ np.array([0.0, 2.0, 0.0])
            if mirrored != flip:
                e1, e2 = e2, e1
            corners = np.stack([origin, origin + e1, origin + e1 + e2, origin + e2])
            _check_range(p, corners)
            p.done()
            # Mitsuba's (u, v) on a rectangle: ((x + 1) / 2, (y + 1) / 2) of the local point.
            uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
            if mirrored != flip:
                uv = uv[:, ::-1]
            faces = np.array([[0, 1, 2], [0, 2, 3]])
            self.geometry.add("quad", {"origin": origin, "edge1": e1, "edge2": e2}, corners, faces, material,
                              emission, corner_uv=uv[faces].reshape(-1, 6))
            return
        local, faces = _unit_cube() if kind == "cube" else _unit_disk()
        corner_uv = _cube_uv(local, faces) if kind == "cube" else _disk_uv(local, faces)
        vertices = _apply(matrix, local)
        _check_range(p, vertices)
        if mirrored != flip:  # Mitsuba's cube and disk face along their normal transform
            faces = faces[:, ::-1]
            corner_uv = corner_uv.reshape(-1, 3, 2)[:, ::-1].reshape(-1, 6)
        p.done()
        self.geometry.add("mesh", {"file": description}, vertices, faces, material, emission,
                          corner_uv=corner_uv)

    def sphere(self, p: _Plugin, matrix: np.ndarray, flip: bool, mirrored: bool, material: int,
               emission: np.ndarray) -> None:
        center = p.point("center", np.zeros(3))
        radius = p.float("radius", 1.0, lo=0.0, lo_open=True, hi=MAX_COORDINATE)
        where = p.props.get("to_world") or p.element
        linear = matrix[:3, :3]
        gram = linear.T @ linear
        scale2 = float(np.mean(np.diag(gram)))
        if np.max(np.abs(gram - scale2 * np.eye(3))) > 1e-6 * scale2:
            where.fail("a sphere's to_world scales unevenly (an ellipsoid): tracer's spheres are round",
                       p.element)
        if mirrored or flip:
            (p.props.get("flip_normals") if flip else where).fail(
                "an inward-facing sphere (flip_normals, or a mirroring to_world, turns Mitsuba's sphere "
                "inside out) is not supported: tracer's spheres face outward", p.element)
        center = _apply(matrix, center[None])[0]
        radius = radius * math.sqrt(scale2)
        _check_range(p, center[None])
        if not radius <= MAX_COORDINATE or radius < 1e-6 * max(float(np.max(np.abs(center))), 1e-24):
            p.fail(f"radius {radius:g} is out of range (at most {MAX_COORDINATE:g}, and at least 1e-6 times "
                   "the largest centre coordinate, what float32 resolves there)")
        p.done()
        # Mitsuba's spherical (u, v) are taken in the sphere's own frame: to_world's rotation.
        frame = (linear / math.sqrt(scale2)).T
        self.geometry.add_sphere({"center": center, "radius": radius}, material, emission, frame)

    def shape_group(self, p: _Plugin) -> list[Element]:
        """The shapes of the ``shapegroup`` ``p`` (read once per instance, none on their own), as
        Mitsuba checks them: no nested groups or instances."""
        known = self.groups.get(id(p.element))
        if known is not None:
            return known
        shapes = []
        for shape, written in p.nested("shape"):
            if shape.attrs.get("type") in ("shapegroup", "instance"):
                written.fail("nested instancing is not supported (Mitsuba refuses it too)", p.element)
            shapes.append(shape)
        p.done()
        self.groups[id(p.element)] = shapes
        return shapes

    def instance(self, p: _Plugin) -> None:
        """Mitsuba's ``instance``: the shapes of its one ``shapegroup``, each under the instance's
        ``to_world`` after its own, added to the scene as shapes of their own (the geometry is
        copied: tracer has no instancing in its acceleration structure)."""
        groups = p.nested("shape")
        if len(groups) != 1 or groups[0][0].attrs.get("type") != "shapegroup":
            p.fail("an instance needs one reference to a shapegroup")
        matrix = p.transform()
        matrix = np.eye(4) if matrix is None else matrix
        p.done()
        for shape in self.shape_group(self.plugin(groups[0][0])):
            self.shape(shape, parent=matrix)

    def cylinder(self, p: _Plugin, matrix: np.ndarray, flip: bool, mirrored: bool, material: int,
                 emission: np.ndarray, description: str) -> None:
        """Mitsuba's ``cylinder``: the open tube of ``radius`` (1) from ``p0`` (0, 0, 0) to ``p1``
        (0, 0, 1), facing outward (inward with ``flip_normals``), as CYLINDER_SEGMENTS quads with
        smooth (radial) normals and Mitsuba's (u, v) = (φ / 2π, z) in the tube's frame, which is
        ``to_world`` times Mitsuba's ``to_frame`` of the axis (``_axis_frame``)."""
        radius = p.float("radius", 1.0, lo=0.0, lo_open=True, hi=MAX_COORDINATE)
        p0, p1 = p.point("p0", np.zeros(3)), p.point("p1", np.array([0.0, 0.0, 1.0]))
        length = float(np.linalg.norm(p1 - p0))
        if not length > 0.0:
            p.fail("p0 and p1 are the same point: the cylinder has no length")
        where = p.props.get("to_world") or p.element
        if mirrored:
            where.fail("a mirroring to_world turns Mitsuba's cylinder inside out: not supported (use "
                       "flip_normals)", p.element)
        frame = np.eye(4)
        frame[:3, :3] = _axis_frame((p1 - p0) / length) @ np.diag([radius, radius, length])
        frame[:3, 3] = p0
        tube = matrix @ frame
        across = tube[:3, :2]
        gram = across.T @ across
        if abs(gram[0, 1]) > 1e-6 * gram[0, 0] or abs(gram[0, 0] - gram[1, 1]) > 1e-6 * gram[0, 0]:
            where.fail("the cylinder's cross-section is not a circle (to_world scales or shears it "
                       "unevenly across its axis; Mitsuba warns of it too)", p.element)
        local, faces, normals, corner_uv = _unit_tube()
        vertices = _apply(tube, local)
        _check_range(p, vertices)
        world_normals = unit_rows(normals @ np.linalg.inv(tube[:3, :3]))  # the inverse transpose
        if flip:
            faces, world_normals = faces[:, ::-1], -world_normals
            corner_uv = corner_uv.reshape(-1, 3, 2)[:, ::-1].reshape(-1, 6)
        p.done()
        self.geometry.add("mesh", {"file": description}, vertices, faces, material, emission,
                          normals=world_normals, corner_uv=corner_uv)

    def mesh(self, p: _Plugin, matrix: np.ndarray, flip: bool, mirrored: bool, material: int,
             emission: np.ndarray) -> None:
        name = p.string("filename", None)
        if name is None:
            p.fail("missing property 'filename'")
        face_normals = p.boolean("face_normals", False)
        path = self.document.find_file(name)
        try:
            if p.type == "serialized":
                mesh = read_serialized(path, p.integer("shape_index", 0, 0, 2**31 - 1))
                flip_v = False
            else:
                # Mitsuba's OBJ loader turns v to 1 - v unless told not to; its PLY loader does not.
                flip_v = p.boolean("flip_tex_coords", p.type == "obj")
                mesh = read_mesh_file(path)
        except MeshError as exc:
            (p.props.get("filename") or p.element).fail(str(exc), p.element)
        vertices = _apply(matrix, mesh.vertices)
        _check_range(p, vertices)
        faces = mesh.faces
        file_normals = mesh.normals is not None and not face_normals
        # Mitsuba shades (and emits, and reflects one-sidedly) on the side of the shading normal.
        # The file's normals, transformed by the inverse transpose, point to the other side of
        # the transformed winding when the transform mirrors: the winding is turned then, so that
        # tracer's front side is Mitsuba's. flip_normals turns both.
        if flip != (mirrored and file_normals):
            faces = faces[:, ::-1]
        normals = None
        if file_normals:
            normals = mesh.normals @ np.linalg.inv(matrix[:3, :3])  # rows: (L^-T n)^T = n^T L^-1
            normals = -normals if flip else normals
        elif not face_normals:  # Mitsuba's own normals, computed after the transform
            normals = angle_weighted_normals(vertices, faces)
        if normals is not None:
            normals = unit_rows(normals)
        corner_uv = mesh.corner_uv
        if corner_uv is not None:
            if flip_v:
                corner_uv = corner_uv.copy()
                corner_uv[:, 1::2] = 1.0 - corner_uv[:, 1::2]
            if flip != (mirrored and file_normals):  # the corners were turned with the winding
                corner_uv = corner_uv.reshape(-1, 3, 2)[:, ::-1].reshape(-1, 6)
        elif flip != (mirrored and file_normals):
            # Without coordinates Mitsuba's (u, v) is the barycentrics of the file's corner order:
            # the turned corners carry them explicitly (the default would be of the turned order).
            corner_uv = np.tile(NO_UV.reshape(3, 2)[::-1].reshape(6), (len(faces), 1))
        attributes = mesh.attributes
        if flip != (mirrored and file_normals):
            attributes = {name: values[:, ::-1] for name, values in attributes.items()}
        p.done()
        self.geometry.add("mesh", {"file": str(path)}, vertices, faces, material, emission, normals,
                          corner_uv, attributes)

    def shape_material(self, p: _Plugin) -> tuple[int, np.ndarray]:
        """The material row and emission of a shape, from its bsdf and emitter (nested or
        referenced). Without a bsdf Mitsuba gives a shape a one-sided diffuse of reflectance
        0.5, and an emitting shape a black one (material row 0 here)."""
        bsdfs, emitters = p.nested("bsdf"), p.nested("emitter")
        if len(bsdfs) > 1:
            bsdfs[1][1].fail("a shape has one bsdf", p.element)
        if len(emitters) > 1:
            emitters[1][1].fail("a shape has one emitter", p.element)
        emission = np.zeros(3)
        if emitters:
            emitter, written = emitters[0]
            if emitter.attrs.get("type") != "area":
                written.fail(f"emitter '{shown(emitter.attrs.get('type', ''))}' inside a shape: a shape's "
                             "emitter is 'area'", p.element)
            owner = self.emitter_owner.setdefault(id(emitter), p.element)
            if owner is not p.element:
                written.fail(f"this area emitter already belongs to the shape at {owner.where} (an emitter "
                             "belongs to one shape)", p.element)
            emission = self.area_radiance(emitter)
        if bsdfs:
            material = self.material(*bsdfs[0])
            tilt = self.perturbations.get(material)
            if p.type == "disk" and tilt is not None and tilt.kind == "bumpmap":
                # Its fan's triangles carry the rim's dp/dv everywhere (Mitsuba's analytic disk
                # has 2π r there): a bump map's tilt would be off toward the centre.
                bsdfs[0][1].fail("a bumpmap on a disk is not supported (tracer's disk is a fan of "
                                 "triangles, whose dp/dv is not the disk's)", p.element)
            if emitters and material in self.opacities:
                bsdfs[0][1].fail("a mask on an emitting shape is not supported (tracer's emitters are "
                                 "opaque)", p.element)
        elif emitters:
            material = 0
        else:
            material = self.default_material()
        return material, emission

    def area_radiance(self, element: Element) -> "np.ndarray | Texture":
        """An ``area`` emitter's radiance: an RGB colour, or a texture (a bitmap, a checkerboard,
        a rawconstant) whose value at a point of the shape is the radiance leaving it there."""
        p = self.plugin(element)
        radiance = self.colour(p, "radiance", 1.0, "emitter", hi=MAX_RADIANCE)
        p.float("sampling_weight", 1.0, lo=0.0)  # how often Mitsuba samples it: not the image
        p.done()
        if isinstance(radiance, Texture):
            if radiance.kind == "mesh_attribute":
                element.fail("a mesh_attribute radiance is not supported (give a bitmap, a checkerboard or a "
                             "colour)")
            low, high = radiance.value_range()
            if low < 0.0:
                element.fail(f"the radiance texture has negative values ({low:.4g}; light is >= 0)")
            if not high <= MAX_RADIANCE:
                element.fail(f"the radiance texture's values reach {high:.4g}, beyond {MAX_RADIANCE:g}")
            return radiance
        # float32, as the TOML reader keeps emission (and the light table stores it)
        return radiance.astype(np.float32).astype(np.float64)

    # -- emitters ----------------------------------------------------------------------------

    def point_emitter(self, element: Element) -> None:
        """A ``point``, ``spot``, ``projector`` or ``directional`` emitter (delta lights)."""
        p = self.plugin(element)
        if p.type == "directional":
            self.directional_emitter(p)
            return
        if p.type not in ("point", "spot", "projector"):
            p.fail(f"emitter '{shown(p.type)}' is not supported; tracer reads point, spot, projector, "
                   "directional, envmap and constant emitters and area emitters on shapes")
        if p.type == "projector":
            self.projector(p)
            return
        intensity = p.color("intensity", 1.0, "emitter", hi=MAX_RADIANCE)
        position = p.point("position", None) if p.type == "point" else None
        matrix = p.transform()
        if position is not None and matrix is not None:
            p.fail("give position or to_world, not both")
        if position is None:
            position = np.zeros(3) if matrix is None else matrix[:3, 3]
            if np.max(np.abs(position)) > MAX_COORDINATE:
                p.fail(f"the position is beyond the coordinate range +-{MAX_COORDINATE:g}")
        axis, cutoff, beam = np.array([0.0, 0.0, 1.0]), 180.0, 180.0
        image = None
        if p.type == "spot":
            cutoff_degrees = p.float("cutoff_angle", 20.0, lo=0.0, hi=180.0, lo_open=True)
            beam_degrees = p.float("beam_width", 0.75 * cutoff_degrees, lo=0.0, hi=180.0)
            linear = np.eye(3) if matrix is None else matrix[:3, :3]
            problem = _similarity_problem(linear)
            if problem is not None:
                p.props["to_world"].fail(f"to_world of a spot light: {problem}", element)
            axis = linear[:, 2] / np.linalg.norm(linear[:, 2])
            cutoff, beam = cutoff_degrees, beam_degrees
            textures = [obj for obj, _ in p.objects if obj.tag == "texture"]
            if textures:
                if cutoff_degrees >= 90.0:
                    p.props["cutoff_angle"].fail("a textured spot's cutoff_angle must be below 90 degrees "
                                                 "(its image lies on a plane ahead of the light)", element)
                texture = self.projected_texture(p, "texture")
                _check_projected_radiance(p, texture, float(np.max(intensity)), "intensity x texels")
                if cutoff_degrees < MIN_PROJECTION_DEGREES:  # its 1 / tan(cutoff) overflows float32
                    p.props["cutoff_angle"].fail(f"a textured spot's cutoff_angle must be at least "
                                                 f"{MIN_PROJECTION_DEGREES:g} degrees", element)
                factor = projected_images.spot_factor(math.radians(cutoff_degrees))
                image = ProjectedImage("spot", _rotation_rows(linear), factor, factor, texture)
        p.float("sampling_weight", 1.0, lo=0.0)
        p.done()
        self.positions.append(position)
        self.intensities.append(intensity)
        self.spots.append((axis, cutoff, beam))
        self.point_images.append(image)

    def projected_texture(self, p: _Plugin, name: str) -> Texture:
        """The bitmap a light projects (``texture`` of a spot, ``irradiance`` of a projector)."""
        found = p.nested("texture")
        for _, written in found:
            if written.attr("name") != name:
                written.fail(f"a <texture> of this light must be named '{name}'")
        if len(found) > 1:
            found[1][1].fail(f"a second <texture> '{name}'")
        element = found[0][0]
        texture = self.texture(element, "emitter")
        if texture.kind != "bitmap":
            element.fail(f"a light projects a bitmap texture; this is '{texture.kind}'")
        if not np.array_equal(texture.to_uv, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])):
            element.fail("a light's projected image with a to_uv transform is not supported")
        if np.any(texture.pixels < 0.0):
            element.fail("a light's projected image has negative texels (light is >= 0)")
        height, width = texture.pixels.shape[:2]
        # The light table's float32 offsets are exact below 2^24 (``projected_images``); all the
        # images of a scene share that, so the running total is checked here, where a line is known.
        self.projected_floats += (1 + -(-3 * height * width // HEADER_WIDTH)) * HEADER_WIDTH
        if self.projected_floats > MAX_TABLE_FLOATS:
            element.fail(f"the lights' projected images hold {self.projected_floats:,} floats; tracer's "
                         f"light table holds {MAX_TABLE_FLOATS:,} (use smaller images)")
        return texture

    def projector(self, p: _Plugin) -> None:
        """Mitsuba's ``projector`` (src/emitters/projector.cpp): a point light at ``to_world``'s
        origin projecting ``irradiance`` (a bitmap or a constant) through a pinhole frustum of
        ``fov`` (parsed as a sensor's, on the image's aspect ratio), ``scale`` times;
        ``tracer.lights.projected_images``."""
        scale = p.float("scale", 1.0, lo=0.0, hi=MAX_RADIANCE)
        if any(obj.tag == "texture" for obj, _ in p.objects):
            texture = self.projected_texture(p, "irradiance")
        else:
            irradiance = p.color("irradiance", 1.0, "emitter", hi=MAX_RADIANCE)
            texture = _constant_texture(irradiance, p.element.where)
        height, width = texture.pixels.shape[:2]
        # Mitsuba's parse_fov at aspect W / H: fov_axis x by default; the frustum's horizontal
        # tangent from tracer's vertical one (tan_half_vertical, the camera's rule).
        tan_half_x = self.tan_half_vertical(p, width, height) * width / height
        fov_x = 2.0 * math.degrees(math.atan(tan_half_x))
        if not MIN_PROJECTION_DEGREES <= fov_x <= MAX_PROJECTOR_DEGREES:
            (p.props.get("fov") or p.props.get("focal_length") or p.element).fail(
                f"a projector's horizontal field of view must lie in [{MIN_PROJECTION_DEGREES:g}, "
                f"{MAX_PROJECTOR_DEGREES:g}] degrees; this is {fov_x:.10g}", p.element)
        matrix = p.transform()
        linear = np.eye(3) if matrix is None else matrix[:3, :3]
        problem = _similarity_problem(linear)
        if problem is not None:
            p.props["to_world"].fail(f"to_world of a projector: {problem}", p.element)
        position = np.zeros(3) if matrix is None else matrix[:3, 3]
        if np.max(np.abs(position)) > MAX_COORDINATE:
            p.fail(f"the position is beyond the coordinate range +-{MAX_COORDINATE:g}")
        p.float("sampling_weight", 1.0, lo=0.0)
        p.done()
        factor_u, factor_v, half_angle, area = projected_images.projector_frustum(tan_half_x, width / height)
        # A uniform scale s of to_world scales Mitsuba's intensity by s (its 1 / (z_local^2 cos)
        # with z_local = d cos / s and cos measured on the scaled axis).
        size = float(np.linalg.norm(linear[:, 2]))
        _check_projected_radiance(p, texture, math.pi * scale * size,
                                  "pi x scale x to_world's scale x texels")
        self.positions.append(position)
        self.intensities.append(np.full(3, math.pi * scale * size))
        self.spots.append((linear[:, 2] / size, math.degrees(half_angle), math.degrees(half_angle)))
        self.point_images.append(ProjectedImage("projector", _rotation_rows(linear), factor_u, factor_v,
                                                texture, area=area))

    def directional_emitter(self, p: _Plugin) -> None:
        """A ``directional`` emitter: irradiance arriving along ``direction`` (or to_world's +z)."""
        irradiance = p.color("irradiance", 1.0, "emitter", hi=MAX_RADIANCE)
        direction = p.point("direction", None)
        matrix = p.transform()
        if direction is not None and matrix is not None:
            p.fail("give direction or to_world, not both")
        if direction is None:
            direction = np.array([0.0, 0.0, 1.0]) if matrix is None else matrix[:3, 2]
        length = float(np.linalg.norm(direction))
        if not length > 0.0 or not math.isfinite(length):
            (p.props.get("direction") or p.props.get("to_world") or p.element).fail(
                "the light's direction is zero", p.element)
        p.float("sampling_weight", 1.0, lo=0.0)
        p.done()
        self.directionals.append((direction / length, irradiance))

    def environment_emitter(self, element: Element) -> None:
        """An ``envmap`` or ``constant`` emitter: the scene's environment (one, as in Mitsuba)."""
        p = self.plugin(element)
        if self.environment_element is not None:
            p.fail(f"a second environment emitter (the first is at {self.environment_element.where}); a "
                   "scene has one, as in Mitsuba")
        if p.type == "constant":
            if any(obj.tag == "texture" for obj, _ in p.objects):
                p.fail("a textured constant emitter is not supported (give its radiance as a colour)")
            radiance = p.color("radiance", 1.0, "emitter", hi=MAX_RADIANCE)
            environment = Environment.constant(radiance)
        else:
            name = p.string("filename", None)
            if name is None:
                p.fail("missing property 'filename' (tracer reads an envmap from an image file)")
            scale = p.float("scale", 1.0, lo=0.0, hi=MAX_RADIANCE)
            path = self.document.find_file(name)
            where = (p.props.get("filename") or element).where
            key = (str(path), False)
            if key not in self.images:
                self.images[key] = read_texels(path, False, where)
            texels = self.images[key]
            if np.any(texels < 0.0):
                p.props["filename"].fail(f"the environment map {path.name} has negative texels (radiance "
                                         "is >= 0)", element)
            if np.max(texels, initial=0.0) * scale > MAX_RADIANCE:
                p.fail(f"the environment's radiance exceeds {MAX_RADIANCE:g} (texels x scale)")
            matrix = p.transform()
            linear = np.eye(3) if matrix is None else matrix[:3, :3]
            problem = rotation_problem(linear)
            if problem is not None:
                p.props["to_world"].fail(f"to_world of an environment: {problem}", element)
            if p.has("mis_compensation"):
                if p.boolean("mis_compensation", False):
                    self.notes.append(f"{element.where}: mis_compensation (how Mitsuba samples the map; "
                                      "tracer samples it as --environment-sampling says: the image is "
                                      "the same)")
            environment = Environment(texels * np.float32(scale), linear, kind="envmap", source=name,
                                      scale=scale, file=str(path))
        p.float("sampling_weight", 1.0, lo=0.0)
        p.done()
        self.environment, self.environment_element = environment, element

    # -- materials ---------------------------------------------------------------------------

    def default_material(self) -> int:
        if self.default_row is None:
            self.default_row = self.add_material(self.unique("default"), "diffuse", {"reflectance": 0.5},
                                                 False)
        return self.default_row

    def unused_bsdfs(self, bsdfs: list[Element]) -> None:
        """Check BSDFs no shape uses, as Mitsuba checks them when it builds them: one that
        tracer reads is read (its values must be what Mitsuba takes), a twosided's one or two
        nested BSDFs each so (Mitsuba's twosided refuses a dielectric inside,
        src/bsdfs/twosided.cpp); another of Mitsuba's BSDFs is accepted unread, an unknown type
        refused. Depth first without recursion, as references may chain twosided BSDFs as long
        as the scene is; a reference cycle is refused, as Mitsuba refuses it (parser.cpp,
        ``check_cycles``)."""
        checked: set[int] = set()
        inside: set[int] = set()  # the twosided BSDFs whose nested ones are being checked
        # ("enter", a BSDF, the element naming it) and ("leave", a twosided, None), last first
        work: list[tuple[str, Element, Element | None]] = [("enter", b, b) for b in reversed(bsdfs)]
        while work:
            step, bsdf, written = work.pop()
            if step == "leave":
                inside.discard(id(bsdf))
                checked.add(id(bsdf))
                continue
            if id(bsdf) in inside:
                written.fail("a circular reference: this BSDF would be nested in itself")
            if id(bsdf) in checked:
                continue
            p = self.plugin(bsdf)
            if p.type not in _WRAPPERS:
                if p.type in _READ_BSDFS or p.type not in _MITSUBA_BSDFS:
                    self.bsdf_triple(p)
                checked.add(id(bsdf))
                continue
            nested = p.nested("bsdf")
            if p.type == "mask":
                self.mask_opacity(p)
                if len(nested) != 1:
                    p.fail(f"mask needs one nested bsdf, not {len(nested)}")
            elif p.type in ("normalmap", "bumpmap"):
                self.perturbation(p)
                if len(nested) != 1:
                    p.fail(f"{p.type} needs one nested bsdf, not {len(nested)}")
            elif not nested or len(nested) > 2:
                p.fail(f"twosided needs one or two nested BSDFs, not {len(nested)}")
            for inner, naming in nested:
                if p.type == "twosided" and inner.attrs.get("type") in _DIELECTRICS:
                    naming.fail("a dielectric inside a twosided (Mitsuba nests only BSDFs without "
                                "transmission)", bsdf)
            p.done()
            inside.add(id(bsdf))
            work.append(("leave", bsdf, None))
            work.extend(("enter", inner, naming) for inner, naming in reversed(nested))

    def material(self, bsdf: Element, written: Element) -> int:
        """The material row of the BSDF ``bsdf`` (one row per element, and per wrapping
        ``twosided``; ``written``: where the shape names it)."""
        key = (id(bsdf), bsdf.attrs.get("type") == "twosided")
        if key in self.rows:
            return self.rows[key]
        ident, inner, type_name, values, twosided, opacity, tilt = self.material_parts(bsdf)
        name = self.unique(ident or f"{inner.type}@{Path(inner.element.file).name}:{inner.element.line}")
        row = self.rows[key] = self.add_material(name, type_name, values, twosided)
        if opacity is not None:
            self.opacities[row] = opacity
        if tilt is not None:
            self.perturbations[row] = tilt
        return row

    def material_parts(self, bsdf: Element, sides: bool = False) -> tuple:
        """``(id, inner plugin, type name, values, twosided, opacity, perturbation)`` of the BSDF
        ``bsdf``: the first id on the way in, the innermost BSDF that tracer's type reads, its type
        and values, whether it reflects on both sides, a ``mask``'s opacity (a number or a
        texture; Mitsuba's default 0.5) or None, and a ``normalmap``'s or ``bumpmap``'s
        :class:`Perturbation` or None. ``sides``: a ``twosided`` wraps it.

        A ``mask`` becomes its nested BSDF's material with the mask's opacity
        (``MaterialTable.opacity``, ``tracer.estimator.cutouts``); a ``twosided`` may wrap a mask
        (Mitsuba nests it there: its pass-through is not a transmission lobe) and a mask a
        ``twosided``. Mitsuba's dielectrics shade both sides (an inside seen from behind: eta
        inverted)."""
        # A BSDF nested (through references) in itself would recurse without end: refused, as
        # Mitsuba refuses a reference cycle. Reading is depth first, so the ones being read are
        # the chain from the shape to here.
        if id(bsdf) in self.bsdfs_reading:
            bsdf.fail("a circular reference: this BSDF would be nested in itself")
        self.bsdfs_reading.add(id(bsdf))
        try:
            return self._material_parts(bsdf, sides)
        finally:
            self.bsdfs_reading.discard(id(bsdf))

    def _material_parts(self, bsdf: Element, sides: bool) -> tuple:
        """:meth:`material_parts`, once it is known not to be read already."""
        p = self.plugin(bsdf)
        ident = bsdf.attrs.get("id")
        if p.type == "mask":
            opacity = self.mask_opacity(p)
            nested = p.nested("bsdf")
            if len(nested) != 1:
                p.fail(f"mask needs one nested bsdf, not {len(nested)}")
            inner, naming = nested[0]
            if inner.attrs.get("type") == "mask":
                naming.fail("a mask inside a mask is not supported (give one mask the product of the "
                            "opacities)", bsdf)
            p.done()
            inner_id, plugin, type_name, values, twosided, _, tilt = self.material_parts(inner, sides)
            return ident or inner_id, plugin, type_name, values, twosided, opacity, tilt
        if p.type in ("normalmap", "bumpmap"):
            tilt = self.perturbation(p)
            nested = p.nested("bsdf")
            if len(nested) != 1:
                p.fail(f"{p.type} needs one nested bsdf, not {len(nested)}")
            inner, naming = nested[0]
            inside = inner.attrs.get("type")
            advice = {"twosided": f"put the twosided outside the {p.type}",
                      "mask": f"put the mask outside the {p.type}",
                      "normalmap": "give one map", "bumpmap": "give one map"}
            if inside in advice:
                # Mitsuba applies the map to every lobe below it (a mask's pass-through too) and
                # mirrors a twosided's back differently below a map than above it.
                naming.fail(f"a {inside} inside a {p.type} is not supported ({advice[inside]})", bsdf)
            p.done()
            inner_id, plugin, type_name, values, twosided, opacity, _ = self.material_parts(inner, sides)
            if not tiltable(materials.TYPES[type_name]):
                naming.fail(f"a {p.type} around {type_name} is not supported (tracer tilts the frame of "
                            "materials that only reflect)", bsdf)
            if p.type == "bumpmap" and "alpha_v" in values:
                # Mitsuba's bump frame takes its s from the untilted dp/du in mixed coordinates.
                naming.fail("a bumpmap around anisotropic roughness is not supported (give one alpha)", bsdf)
            return ident or inner_id, plugin, type_name, values, twosided, opacity, tilt
        if p.type == "twosided":
            nested = p.nested("bsdf")
            if not nested:
                p.fail("twosided needs one nested bsdf")
            if len(nested) > 1:
                nested[1][1].fail("two different BSDFs for the two sides are not supported (tracer's "
                                  "twosided material is one BSDF on both sides)", bsdf)
            if sides:
                p.fail("a twosided inside a twosided")
            if nested[0][0].attrs.get("type") == "twosided":
                nested[0][1].fail("a twosided inside a twosided", bsdf)
            p.done()
            inner_id, plugin, type_name, values, _, opacity, tilt = self.material_parts(nested[0][0], True)
            return ident or inner_id, plugin, type_name, values, True, opacity, tilt
        type_name, values = self.bsdf_triple(p)
        if type_name == "principled" and sides:
            if values["spec_trans"] is not None and not (isinstance(values["spec_trans"], float)
                                                         and values["spec_trans"] == 0.0):
                p.fail("a principled with spec_trans inside a twosided (Mitsuba nests only BSDFs without "
                       "transmission)")
            values["mirrored"] = True
        if type_name == "principled" and values["spec_trans"] is None:
            values["spec_trans"] = 0.0
        # Mitsuba's dielectrics and principled BSDF shade both sides (an interface: its inside).
        if type_name == "principledthin" and sides:
            p.fail("a principledthin inside a twosided (Mitsuba nests only BSDFs without transmission; "
                   "the thin BSDF is the same from both sides already)")
        both = sides or type_name in _DIELECTRICS or type_name in ("principled", "principledthin") \
            or bool(values.get("parts_twosided", False))
        return ident, p, type_name, values, both, None, None

    def blend(self, p: _Plugin) -> dict[str, object]:
        """A ``blendbsdf``'s weight (a number or a texture, required, as in Mitsuba) and its two
        parts, ``(type name, values)`` each, and whether they are two-sided: the values of
        ``add_material``, which lays out the rows (``tracer.materials.blendbsdf``)."""
        if not any(obj.tag == "texture" and written.attrs.get("name") == "weight" for obj, written in p.objects) \
                and not p.has("weight"):
            p.fail("missing property 'weight' (a number or a texture, as Mitsuba requires)")
        weight = self.textured(p, "weight", lambda: p.float("weight", 0.5, lo=0.0, hi=1.0), "other")
        nested = p.nested("bsdf")
        if len(nested) != 2:
            p.fail(f"blendbsdf needs two nested BSDFs, not {len(nested)}")
        parts, sides = [], []
        for inner, naming in nested:
            _, _, type_name, values, twosided, opacity, tilt = self.material_parts(inner)
            kind = materials.TYPES[type_name]
            if opacity is not None or tilt is not None:
                naming.fail("a mask, normalmap or bumpmap inside a blendbsdf is not supported (put it around "
                            "the blendbsdf)", p.element)
            if kind.composite:
                naming.fail("a blendbsdf inside a blendbsdf is not supported", p.element)
            if not tiltable(kind):
                naming.fail(f"a blendbsdf of {type_name} is not supported (tracer blends materials that only "
                            "reflect)", p.element)
            parts.append((type_name, values))
            sides.append(twosided)
        if sides[0] != sides[1]:
            nested[1][1].fail("a blendbsdf of a one-sided and a two-sided BSDF is not supported (wrap the "
                              "blendbsdf in the twosided)", p.element)
        return {"weight": weight, "parts": parts, "parts_twosided": sides[0]}

    def mask_opacity(self, p: _Plugin) -> object:
        """A ``mask``'s opacity: a texture, or a number in [0, 1] (a colour's luminance, as
        Mitsuba's ``eval_1`` reads one, clamped as its ``eval_opacity`` clamps)."""
        return self.textured(p, "opacity",
                             lambda: float(np.clip(p.color("opacity", 0.5, "other") @ LUMINANCE, 0.0, 1.0)),
                             "other")

    def perturbation(self, p: _Plugin) -> Perturbation:
        """A ``normalmap``'s or ``bumpmap``'s :class:`Perturbation`, read as Mitsuba 3.9.1 reads
        it: a normal map's ``normalmap`` texture (or a constant RGB); a bump map's one nested
        texture, whatever its name, and its ``scale``; both maps' ``flip_invalid_normals`` and
        ``use_shadowing_function`` (default true)."""
        if p.type == "normalmap":
            texture = self.textured(p, "normalmap", lambda: None, "other")
            if texture is None:
                if not p.has("normalmap"):
                    p.fail("missing property 'normalmap' (a texture or an rgb)")
                # An rgb is Mitsuba's srgb texture, which takes components in [0, 1] only.
                texture = _constant_texture(p.color("normalmap", 0.0, "other", lo=0.0, hi=1.0),
                                            p.props["normalmap"].where)
            scale = 1.0
        else:
            found = [(obj, written) for obj, written in p.objects if obj.tag == "texture"]
            if len(found) != 1:
                p.fail(f"bumpmap needs one nested texture (the height field), not {len(found)}")
            p.taken.add(id(found[0][1]))
            texture = self.texture(found[0][0], "other")
            if texture.kind != "bitmap":
                found[0][1].fail(f"a bumpmap's height field is a bitmap here, not a {texture.kind} "
                                 "(Mitsuba takes the gradient of bitmaps only)", p.element)
            scale = p.float("scale", 1.0, lo=-1e6, hi=1e6)
        return Perturbation(p.type, texture, scale, p.boolean("flip_invalid_normals", True),
                            p.boolean("use_shadowing_function", True))

    def texture(self, element: Element, kind: str) -> Texture:
        """The texture ``element`` (read once: references share it); ``kind`` as for colours."""
        known = self.textures_read.get(id(element))
        if known is not None:
            return known
        p = self.plugin(element)
        to_uv = p.transform("to_uv")
        if p.type == "checkerboard":
            texture = Texture("checkerboard", color0=p.color("color0", 0.4, kind),
                              color1=p.color("color1", 0.2, kind), source=element.where)
        elif p.type == "bitmap":
            name = p.string("filename", None)
            if name is None:
                p.fail("missing property 'filename'")
            raw = p.boolean("raw", False)
            filter_type = p.string("filter_type", "bilinear")
            wrap = p.string("wrap_mode", "repeat")
            for key, value, allowed in (("filter_type", filter_type, FILTERS), ("wrap_mode", wrap, WRAPS)):
                if value not in allowed:
                    p.props[key].fail(f"{key}: expected {' or '.join(allowed)}, got '{shown(value)}'",
                                      element)
            fmt = p.string("format", "auto")  # storage precision: the values are the same
            if fmt not in ("auto", "variant", "float16", "fp16", "uint8"):
                p.props["format"].fail("format: expected auto, variant, float16 or uint8, got "
                                       f"'{shown(fmt)}'", element)
            path = self.document.find_file(name)
            where = (p.props.get("filename") or element).where
            key = (str(path), raw)
            if key not in self.images:
                self.images[key] = read_texels(path, raw, where)
            texture = Texture("bitmap", pixels=self.images[key], filter=filter_type, wrap=wrap,
                              source=str(path), raw=raw)
        elif p.type == "mesh_attribute":
            name = p.string("name", None)
            if name is None:
                p.fail("missing property 'name' (the attribute: vertex_... or face_...)")
            if not (name.startswith("vertex_") or name.startswith("face_")):
                p.props["name"].fail(f"name: a mesh attribute's name starts with vertex_ or face_, got "
                                     f"'{shown(name)}'", element)
            if to_uv is not None:
                p.props["to_uv"].fail("a mesh_attribute texture has no to_uv (Mitsuba's has none)", element)
            # The attribute's values are checked finite when read; a scale keeps them within
            # what a float64 product of them can hold.
            scale = p.float("scale", 1.0, lo=-1e15, hi=1e15)
            texture = Texture("mesh_attribute", attribute=name, scale=scale, source=element.where)
        elif p.type == "rawconstant":
            # Mitsuba's rawconstant (src/spectra/rawconstant.cpp): one number or a 3-vector,
            # returned as it is in any colour mode (no spectral upsampling, no sRGB decoding).
            element_value = p.prop("value", ("float", "integer", "vector", "point"))
            if element_value is None:
                p.fail("missing property 'value'")
            if element_value.tag in ("vector", "point"):
                value = xyz(element_value, None, "value")
            else:
                value = np.full(3, number(element_value, element_value.attr("value"), "value"))
            if not np.all(np.isfinite(value)) or np.max(np.abs(value)) > MAX_RADIANCE:
                element_value.fail(f"value: expected finite numbers within +-{MAX_RADIANCE:g}", element)
            if to_uv is not None:
                p.props["to_uv"].fail("a rawconstant texture has no to_uv (it is the same everywhere)",
                                      element)
            texture = _constant_texture(value, element.where)
        else:
            p.fail(f"texture '{shown(p.type)}' is not supported; tracer reads bitmap, checkerboard, "
                   "mesh_attribute and rawconstant")
        if to_uv is not None:
            texture.to_uv = np.array([[to_uv[0, 0], to_uv[0, 1], to_uv[0, 3]],
                                      [to_uv[1, 0], to_uv[1, 1], to_uv[1, 3]]])
            if not np.all(np.isfinite(texture.to_uv)):
                p.props["to_uv"].fail("to_uv: numbers must be finite", element)
        p.done()
        self.textures_read[id(element)] = texture
        return texture

    def textured(self, p: _Plugin, name: str, read: Callable[[], object], kind: str) -> object:
        """The texture ``p`` gives for property ``name`` (nested, or referenced with that name),
        else what ``read`` reads (a constant)."""
        found = [(obj, written) for obj, written in p.objects
                 if obj.tag == "texture" and written.attrs.get("name") == name]
        if not found:
            return read()
        if p.has(name) or len(found) > 1:
            again = found[1][1] if len(found) > 1 else found[0][1]
            again.fail(f"property '{name}' is given twice", p.element)
        p.taken.add(id(found[0][1]))
        return self.texture(found[0][0], kind)

    def colour(self, p: _Plugin, name: str, default: float, kind: str, hi: float | None = None) -> object:
        """A colour property that may be a texture (``textured``)."""
        return self.textured(p, name, lambda: p.color(name, default, kind, hi=hi), kind)

    def bind_textures(self, row: int, type_name: str, values: dict[str, object]) -> dict[str, object]:
        """``values`` with each texture replaced by its mean, the texture bound to the parameter
        in the geometry's texture table (``tracer.textures.bind``)."""
        try:
            return bind(self.geometry.textures, row, materials.TYPES[type_name], values, self.document.path,
                        self.notes)
        except ValueError as exc:
            raise InputError(str(exc), self.document.path) from None

    def unique(self, name: str) -> str:
        candidate, i = name, 2
        while candidate in self.names or (candidate != name and candidate in self.document.ids):
            candidate, i = f"{name}-{i}", i + 1
        self.names.add(candidate)
        return candidate

    def add_material(self, name: str, type_name: str, values: dict[str, object], twosided: bool) -> int:
        """The row of a new material; a blend's two parts (``values["parts"]``) take the rows
        after it (``tracer.materials.blendbsdf.parts``)."""
        if "parts" in values:
            triples = blendbsdf.parts(name, values["weight"], *values["parts"])
        else:
            triples = [(name, type_name, values)]
        row = len(self.triples) + 1  # row 0 is the black material
        self.triples.extend(triples)
        self.sides.extend([twosided] * len(triples))
        return row

    def bsdf_triple(self, p: _Plugin) -> tuple[str, dict[str, object]]:
        """tracer's material type and parameters for the Mitsuba BSDF ``p`` (not twosided)."""
        kind = p.type
        if kind == "diffuse":
            values: dict[str, object] = {
                "reflectance": self.colour(p, "reflectance", 0.5, "reflectance", hi=1.0)}
        elif kind in ("conductor", "roughconductor"):
            eta, k = self.conductor_ior(p)
            values = {"reflectance": self.colour(p, "specular_reflectance", 1.0, "reflectance", hi=1.0),
                      "eta": eta, "k": k}
            if kind == "roughconductor":
                values.update(self.roughness(p, anisotropic=True))
        elif kind in ("plastic", "roughplastic"):
            values = {
                "diffuse_reflectance": self.colour(p, "diffuse_reflectance", 0.5, "reflectance", hi=1.0),
                "specular_reflectance": self.colour(p, "specular_reflectance", 1.0, "reflectance", hi=1.0),
                "int_ior": self.ior(p, "int_ior", "polypropylene"),
                "ext_ior": self.ior(p, "ext_ior", "air"),
                "nonlinear": p.boolean("nonlinear", False)}
            if kind == "roughplastic":
                values.update(self.roughness(p))
        elif kind == "pplastic":
            values = {
                "diffuse_reflectance": self.colour(p, "diffuse_reflectance", 0.5, "reflectance", hi=1.0),
                "specular_reflectance": self.colour(p, "specular_reflectance", 1.0, "reflectance", hi=1.0)}
            if p.has("eta"):
                # Mitsuba's pplastic alone takes the relative index directly.
                if p.has("int_ior") or p.has("ext_ior"):
                    p.fail("give eta or int_ior and ext_ior, not both")
                values.update(int_ior=self.ior(p, "eta", "polypropylene"), ext_ior=1.0)
            else:
                values.update(int_ior=self.ior(p, "int_ior", "polypropylene"),
                              ext_ior=self.ior(p, "ext_ior", "air"))
            values.update(self.roughness(p))
        elif kind == "blendbsdf":
            values = self.blend(p)
        elif kind in ("principled", "principledthin"):
            values = self.principled(p)
        elif kind in _DIELECTRICS:
            values = {
                "specular_reflectance": p.color("specular_reflectance", 1.0, "reflectance", hi=1.0),
                "specular_transmittance": p.color("specular_transmittance", 1.0, "reflectance", hi=1.0),
                "int_ior": self.ior(p, "int_ior", "bk7"),
                "ext_ior": self.ior(p, "ext_ior", "air")}
            if kind == "roughdielectric":
                values.update(self.roughness(p))
        else:
            p.fail(f"bsdf '{shown(kind)}' is not supported; tracer reads diffuse, conductor, roughconductor, "
                   "plastic, roughplastic, pplastic, dielectric, roughdielectric, thindielectric, twosided, "
                   "mask, normalmap, bumpmap, blendbsdf, principled and principledthin")
        p.done()
        return kind, values

    def principled(self, p: _Plugin) -> dict[str, object]:
        """The parameters of Mitsuba's ``principled`` or ``principledthin``
        (``tracer.materials.principled``, ``principledthin``): each a number or a texture (a
        colour gives its luminance, as Mitsuba's ``eval_1``), in [0, 1] (diff_trans in [0, 2]);
        principled's eta given or from ``specular`` (not both, as Mitsuba); its spec_trans None
        where not given (a twosided may wrap the BSDF then)."""
        thin = p.type == "principledthin"

        def one(name: str, default: float, hi: float = 1.0) -> object:
            return self.textured(p, name, lambda: float(p.color(name, default, "other", hi=hi) @ LUMINANCE),
                                 "other")

        kind = principledthin.TYPE if thin else principled.TYPE
        values: dict[str, object] = {"base_color": self.colour(p, "base_color", 0.5, "reflectance", hi=1.0)}
        for param in kind.params:
            if param.size == 1 and param.texture and param.name not in ("eta", "spec_trans"):
                values[param.name] = one(param.name, float(param.default), float(param.hi))
        given = p.has("spec_trans") or any(obj.tag == "texture" and written.attrs.get("name") == "spec_trans"
                                           for obj, written in p.objects)
        values["spec_trans"] = one("spec_trans", 0.0) if given or thin else None
        for name in (principledthin.RATES if thin else principled.RATES):
            values[name] = p.float(name, 1.0, lo=0.0, hi=principled.MAX_SAMPLING_RATE,
                                   lo_open=name == "main_specular_sampling_rate")
        if thin:
            values["eta"] = self.textured(p, "eta", lambda: p.float("eta", 1.5, lo=1.0, hi=plastic.MAX_IOR),
                                          "other")
            return values
        transmits = given and not (isinstance(values["spec_trans"], float) and values["spec_trans"] == 0.0)
        if p.has("eta") and p.has("specular"):
            p.fail("give eta or specular, not both (Mitsuba takes one)")
        if p.has("eta"):
            eta = p.float("eta", 1.5, lo=1.0, hi=plastic.MAX_IOR)
            values["eta"] = 1.001 if transmits and eta == 1.0 else eta  # Mitsuba's: eta 1 cannot refract
        else:
            specular = p.float("specular", 0.5, lo=0.0, hi=1.0)
            values["eta"] = principled.eta_of_specular(1e-3 if transmits and specular == 0.0 else specular)
        return values

    def conductor_ior(self, p: _Plugin) -> tuple[np.ndarray, np.ndarray]:
        """eta and k: from ``material`` (Mitsuba's named conductors; default "none", a perfect
        mirror: eta 0, k 1) or given (each defaulting to that mirror's)."""
        name = p.string("material", None)
        if name is not None and (p.has("eta") or p.has("k")):
            p.fail("give material or eta and k, not both")
        if name is None or name == "none":
            return (self.colour(p, "eta", 0.0, "other", hi=conductor.MAX_INDEX),
                    self.colour(p, "k", 1.0, "other", hi=conductor.MAX_INDEX))
        from ..materials.presets import CONDUCTORS

        if name not in CONDUCTORS:
            folded = name.lower()  # once: a 60 MB name folded for every preset took seconds
            close = [n for n in CONDUCTORS if n.lower() == folded]
            hint = f" (names are case-sensitive: '{close[0]}')" if close else ""
            p.props["material"].fail(f"unknown conductor material '{shown(name)}'{hint}; Mitsuba's names: "
                                     f"none, {', '.join(sorted(CONDUCTORS, key=str.lower))}", p.element)
        eta, k = CONDUCTORS[name]
        return np.array(eta, dtype=np.float64), np.array(k, dtype=np.float64)

    def ior(self, p: _Plugin, name: str, default: str) -> float:
        """A real index of refraction: a number, or a name of Mitsuba's table (any case)."""
        from ..materials.presets import IORS

        element = p.prop(name, ("float", "integer", "string"))
        if element is None:
            return IORS[default]
        text = element.attr("value")
        if element.tag == "string":
            key = text.strip().lower()
            if key not in IORS:
                element.fail(f"unknown IOR name '{shown(text)}' (Mitsuba's names: {', '.join(IORS)})",
                             p.element)
            return IORS[key]
        value = number(element, text, name)
        p._check(element, value, plastic.MIN_IOR, plastic.MAX_IOR)
        return value

    def roughness(self, p: _Plugin, anisotropic: bool = False) -> dict[str, object]:
        """distribution and alpha, and with ``anisotropic`` (a type with ``alpha_v``:
        roughconductor) alpha_v where alpha_u and alpha_v differ (alpha is then alpha_u);
        clamped to at least MIN_ALPHA as Mitsuba's distributions clamp them."""
        distribution = (p.string("distribution", "beckmann") or "").lower()
        if distribution not in ("beckmann", "ggx"):
            p.props["distribution"].fail("distribution: expected beckmann or ggx, got "
                                         f"'{shown(distribution)}'", p.element)
        def given(name: str) -> bool:
            return p.has(name) or any(obj.tag == "texture" and written.attrs.get("name") == name
                                      for obj, written in p.objects)

        alpha_v = None
        if given("alpha_u") or given("alpha_v"):
            if given("alpha"):
                p.fail("give alpha or alpha_u and alpha_v, not both")
            if not (given("alpha_u") and given("alpha_v")):
                p.fail("alpha_u and alpha_v go together")
            alpha = self.textured(p, "alpha_u", lambda: self.scalar(p, "alpha_u", 0.1), "other")
            alpha_v = self.textured(p, "alpha_v", lambda: self.scalar(p, "alpha_v", 0.1), "other")
            same = alpha is alpha_v or (not isinstance(alpha, Texture) and not isinstance(alpha_v, Texture)
                                        and alpha == alpha_v)
            if same:
                alpha_v = None
            elif not anisotropic:
                p.fail(f"anisotropic roughness (alpha_u and alpha_v) on {p.type} is not supported (tracer "
                       "reads it on roughconductor)")
        else:
            alpha = self.textured(p, "alpha", lambda: self.scalar(p, "alpha", 0.1), "other")
        if not p.boolean("sample_visible", True):
            self.notes.append(f"{p.element.where}: sample_visible false (tracer samples visible normals)")
        out: dict[str, object] = {"distribution": distribution, "alpha": _at_least(alpha, MIN_ALPHA)}
        if alpha_v is not None:
            out["alpha_v"] = _at_least(alpha_v, MIN_ALPHA)
        return out

    @staticmethod
    def scalar(p: _Plugin, name: str, default: float) -> float:
        """A roughness: a number, a constant spectrum or a grey RGB, in [0, 10]."""
        rgb = p.color(name, default, "other", hi=10.0)
        if not (rgb[0] == rgb[1] == rgb[2]):
            p.props[name].fail(f"{name}: a roughness per colour channel is not supported", p.element)
        return float(rgb[0])

    # -- the scene ---------------------------------------------------------------------------

    def scene(self, camera: Camera) -> Scene:
        g = self.geometry
        # Mesh attributes are read from the shapes that use them, all read by now.
        feeds: dict[int, tuple[Texture, set[int], bool]] = {}
        sizes = {(t.name, param.name): param.size for t in materials.TYPES.values() for param in t.params}
        sources = [(row, value, sizes.get((type_name, name)) == 1)
                   for row, (_, type_name, values) in enumerate(self.triples, start=1)
                   for name, value in values.items()]
        sources += [(row, value, True) for row, value in self.opacities.items()]
        for row, value, one_number in sources:
            if isinstance(value, Texture) and value.kind == "mesh_attribute":
                texture, rows, one = feeds.setdefault(id(value), (value, set(), False))
                rows.add(row)
                feeds[id(value)] = (texture, rows, one or one_number)
        for texture, rows, one_number in feeds.values():
            g.resolve_attribute(texture, rows, self.document.path)
            if one_number and texture.channels != 1:
                self.notes.append(f"{texture.source}: a one-number parameter reads the "
                                  f"{texture.channels}-channel mesh attribute '{texture.attribute}' as 0, "
                                  "as Mitsuba's eval_1 does")
        triples = [(name, type_name, self.bind_textures(row, type_name, values))
                   for row, (name, type_name, values) in enumerate(self.triples, start=1)]
        opacity = [g.textures.bind_opacity(row, self.opacities.get(row, 1.0))
                   for row in range(1, len(self.triples) + 1)]
        for row, tilt in self.perturbations.items():
            g.textures.bind_perturbation(row, tilt)
        try:
            table = materials.table(triples, self.sides, opacity)
        except ValueError as exc:  # the parameter ranges every reader is held to (Param.check)
            raise InputError(str(exc), self.document.path) from None
        return g.scene(self.document.path, camera, table, self.positions, self.intensities, self.render,
                       self.environment, spots=self.spots, directionals=self.directionals,
                       images=self.point_images)


def _at_least(value: "Texture | float", lo: float) -> "Texture | float":
    """A roughness clamped to at least ``lo``: a number, or a texture whose texels (colours) below
    it are raised to it. Mitsuba clamps the looked-up value; clamping the texels instead differs
    only where a bilinear lookup blends texels below ``lo`` with others (by less than ``lo``)."""
    if not isinstance(value, Texture):
        return max(value, lo)
    if value.kind == "mesh_attribute" or value.value_range()[0] >= lo:  # an attribute: read later
        return value
    if value.kind == "checkerboard":
        return dataclasses.replace(value, color0=np.maximum(value.color0, lo),
                                   color1=np.maximum(value.color1, lo))
    floor = np.asarray(lo, dtype=value.pixels.dtype)
    return dataclasses.replace(value, pixels=np.maximum(value.pixels, floor))


def _constant_texture(rgb: np.ndarray, where: str) -> Texture:
    """A constant as a texture: one texel, looked up nearest (its gradient is 0)."""
    return Texture("bitmap", pixels=np.asarray(rgb, dtype=np.float32).reshape(1, 1, 3), filter="nearest",
                   source=where, raw=True)


def _check_projected_radiance(p: _Plugin, texture: Texture, factor: float, what: str) -> None:
    """Refuse a projected image whose brightest texel times ``factor`` exceeds MAX_RADIANCE."""
    if not float(np.max(texture.pixels, initial=0.0)) * factor <= MAX_RADIANCE:
        p.fail(f"the light's {what} exceed {MAX_RADIANCE:g}")


def _rotation_rows(linear: np.ndarray) -> np.ndarray:
    """World to a light's frame: the rows are its transform's columns, normalized (the
    transform is a rotation times a uniform scale: ``_similarity_problem``)."""
    return (linear / np.linalg.norm(linear, axis=0)).T.copy()


def _similarity_problem(linear: np.ndarray) -> str | None:
    """Why the 3x3 ``linear`` is not a rotation times a uniform scale (to 1e-4), else None: a
    spot's cone is its +z axis and an angle, which another transform would distort."""
    if not np.all(np.isfinite(linear)):
        return "numbers must be finite"
    with np.errstate(over="ignore"):
        gram = linear.T @ linear
    scale = float(np.trace(gram)) / 3.0
    if not np.all(np.isfinite(gram)) or not math.isfinite(scale):
        return "its scale is beyond the number range"
    if not scale > 1e-200:  # squared: lengths below 1e-100, where the test below loses its digits
        return "its scale is zero or too small for the number range"
    if np.max(np.abs(gram / scale - np.eye(3))) > 1e-4:
        return "it must be a rotation and translation (a scale or shear would distort the cone)"
    return None


def _refuse_unsupported(root: Element) -> None:
    """Textures, media and spectrum plugins are refused wherever they are, used or not."""
    stack = [root]
    while stack:
        element = stack.pop()
        stack.extend(element.children)
        if element.tag in _UNSUPPORTED_ANYWHERE:
            element.fail(_UNSUPPORTED_ANYWHERE[element.tag])
        if element.tag == "spectrum" and "type" in element.attrs:
            element.fail("spectrum plugins are not supported (give value=\"...\")")
        if element.tag not in OBJECT_TAGS and element.tag not in PROPERTY_TAGS and element.tag not in (
                "ref", "translate", "scale", "rotate", "matrix", "lookat"):
            element.fail("unknown element")


def _resolution(width: int, height: int, want_width: int | None, want_height: int | None) -> tuple[int, int]:
    """The film size with the caller's overrides: one side given keeps the aspect ratio (as the
    TOML reader does), both replace it."""
    if want_width is not None and want_height is None:
        return want_width, max(1, round(want_width * height / width))
    if want_height is not None and want_width is None:
        return max(1, round(want_height * width / height)), want_height
    if want_width is not None:
        return want_width, want_height
    return width, height


def _apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _check_range(p: _Plugin, points: np.ndarray) -> None:
    if not np.all(np.isfinite(points)) or np.max(np.abs(points)) > MAX_COORDINATE:
        p.fail(f"the transformed shape leaves the coordinate range +-{MAX_COORDINATE:g}")


def unit_rows(normals: np.ndarray) -> np.ndarray:
    """``n / |n|`` per row, zero rows kept (the mesh reader keeps rows that are unit already, so
    these come back bit for bit from a PLY file that ``tracer convert`` writes)."""
    rows = np.asarray(normals, dtype=np.float64)
    length = np.linalg.norm(rows, axis=1)
    return rows / np.where(length > 0.0, length, 1.0)[:, None]


def _unit_cube() -> tuple[np.ndarray, np.ndarray]:
    """[-1, 1]^3 as 8 corners and 12 triangles wound outward (counter-clockwise from outside)."""
    vertices = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    faces = np.array([[0, 2, 3], [0, 3, 1],   # z = -1
                      [4, 5, 7], [4, 7, 6],   # z = +1
                      [0, 1, 5], [0, 5, 4],   # y = -1
                      [2, 6, 7], [2, 7, 3],   # y = +1
                      [0, 4, 6], [0, 6, 2],   # x = -1
                      [1, 3, 7], [1, 7, 5]])  # x = +1
    return vertices, faces


# Mitsuba's cube (src/shapes/cube.cpp): each face's (u, v) as affine functions of the local
# point, by the face's outward normal axis and sign: (axis, sign) -> the coefficients of
# (x, y, z, 1) giving u and of those giving v. Fitted (exactly: zero residual) to Mitsuba 3.9.1's
# own cube, its vertex positions and texture coordinates, face by face.
_CUBE_UV = {
    (1, -1.0): ([0.0, -0.25, 0.5, 0.25], [0.5, -0.25, 0.0, 0.25]),
    (1, 1.0): ([-0.5, 0.25, 0.0, 0.25], [0.0, 0.25, -0.5, 0.25]),
    (0, 1.0): ([0.25, 0.5, 0.0, 0.25], [0.25, 0.0, -0.5, 0.25]),
    (2, 1.0): ([0.0, 0.5, 0.25, 0.25], [0.5, 0.0, 0.25, 0.25]),
    (0, -1.0): ([-0.25, 0.5, 0.0, 0.25], [-0.25, 0.0, 0.5, 0.25]),
    (2, -1.0): ([0.0, -0.5, -0.25, 0.25], [0.5, 0.0, -0.25, 0.25]),
}


def _cube_uv(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 6) Mitsuba's cube texture coordinates at the corners of the unit cube's triangles."""
    out = np.zeros((len(faces), 6))
    for f, face in enumerate(faces):
        corners = vertices[face]
        axis = int(np.flatnonzero(np.all(corners == corners[0], axis=0))[0])
        u_row, v_row = (np.array(r) for r in _CUBE_UV[(axis, float(corners[0, axis]))])
        homogeneous = np.concatenate([corners, np.ones((3, 1))], axis=1)
        out[f] = np.stack([homogeneous @ u_row, homogeneous @ v_row], axis=1).ravel()
    return out


def _disk_uv(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 6) Mitsuba's disk texture coordinates (r, φ / 2π) at the fan's corners: the centre
    takes each triangle's middle angle, the rim corners their own (the last triangle's end at
    φ = 2π, not 0). Interpolated over a triangle, r is off by at most 1 - cos(π / 288), 6e-5, and
    φ / 2π by at most half a triangle's angle, 1/576 (near the centre)."""
    out = np.zeros((len(faces), 6))
    for f, face in enumerate(faces):
        angles = [math.atan2(vertices[i, 1], vertices[i, 0]) % (2.0 * math.pi) for i in face]
        rims = [k for k in range(3) if np.hypot(*vertices[face[k], :2]) > 0.5]
        if len(rims) == 2 and abs(angles[rims[1]] - angles[rims[0]]) > math.pi:
            for k in rims:  # the triangle across φ = 0: its corner at 0 is at 2π
                if angles[k] < math.pi:
                    angles[k] += 2.0 * math.pi
        middle = float(np.mean([angles[k] for k in rims])) if rims else 0.0
        for k, i in enumerate(face):
            radius = float(np.hypot(*vertices[i, :2]))
            out[f, 2 * k] = radius
            out[f, 2 * k + 1] = (angles[k] if radius > 0.5 else middle) / (2.0 * math.pi)
    return out


def _axis_frame(n: np.ndarray) -> np.ndarray:
    """(3, 3) columns (s, t, n): Mitsuba's ``Frame3f(n)`` (its ``coordinate_system``, Duff et al.
    2017, "Building an orthonormal basis, revisited"), the frame its cylinder is built in."""
    sign = math.copysign(1.0, float(n[2]))
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return np.stack([s, t, n], axis=1)


def _unit_tube() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The unit open tube (radius 1 about z, 0 <= z <= 1) as CYLINDER_SEGMENTS quads facing
    outward: vertices, faces, unit radial vertex normals and (F, 6) corner (u, v) = (φ / 2π, z),
    the seam's column duplicated at u = 1. A quad's flat facet lies within 1 - cos(π / N) of the
    tube (6e-5 of the radius); its interpolated normal within about that of the radial one."""
    n = CYLINDER_SEGMENTS
    angle = 2.0 * np.pi * np.arange(n + 1) / n
    ring = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    ring[n] = ring[0]  # the seam: the same point, u = 1
    bottom = np.concatenate([ring, np.zeros((n + 1, 1))], axis=1)
    top = np.concatenate([ring, np.ones((n + 1, 1))], axis=1)
    vertices = np.concatenate([bottom, top])
    normals = np.concatenate([bottom, bottom]) * [1.0, 1.0, 0.0]
    i = np.arange(n)
    faces = np.concatenate([np.stack([i, i + 1, n + 1 + i + 1], axis=1),
                            np.stack([i, n + 1 + i + 1, n + 1 + i], axis=1)])
    uv = np.concatenate([np.stack([angle / (2.0 * np.pi), np.zeros(n + 1)], axis=1),
                         np.stack([angle / (2.0 * np.pi), np.ones(n + 1)], axis=1)])
    return vertices, faces, normals, uv[faces].reshape(-1, 6)


def _unit_disk() -> tuple[np.ndarray, np.ndarray]:
    """The unit disk at z = 0 as a fan of DISK_SEGMENTS triangles facing +z."""
    angle = 2.0 * np.pi * np.arange(DISK_SEGMENTS) / DISK_SEGMENTS
    rim = np.stack([np.cos(angle), np.sin(angle), np.zeros(DISK_SEGMENTS)], axis=1)
    vertices = np.concatenate([np.zeros((1, 3)), rim])
    i = np.arange(DISK_SEGMENTS)
    faces = np.stack([np.zeros(DISK_SEGMENTS, dtype=np.int64), 1 + i, 1 + (i + 1) % DISK_SEGMENTS], axis=1)
    return vertices, faces
