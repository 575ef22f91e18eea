"""The keys of the TOML scene format, table by table: what the reader accepts and the reference
page lists (``tracer.manual``).

The reader (``tracer.scene.toml_reader``) reads each table through a ``Section`` of this
module: asking for a key the section does not declare is a programming error, and a key in
the file that the section does not declare is refused with the closest declared one named. So
the documentation cannot list a key the reader refuses, nor miss one it reads. Material
parameters are declared by each material's module (``tracer.materials``), not here.

``type`` and ``default`` are text for people; the checks themselves (ranges, lengths) are in
the reader, and docs/SCENE_FORMAT.md explains the conventions behind them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Key:
    """One key of a table: its name, its type and default as the reference states them, and
    its meaning."""

    name: str
    type: str
    default: str
    doc: str


@dataclass(frozen=True)
class Section:
    """The keys one table of a scene may hold. ``header`` is how a scene file writes the table,
    ``doc`` one sentence on what it is for."""

    header: str
    doc: str
    keys: tuple[Key, ...]

    def names(self) -> tuple[str, ...]:
        return tuple(k.name for k in self.keys)


REQUIRED = "required"
VEC3 = "3 numbers"

TOP = Section("top level", "The tables of a scene file.", (
    Key("render", "table", "none", "defaults for `tracer render`"),
    Key("camera", "table", REQUIRED, "the pinhole camera"),
    Key("materials", "table of tables", "none", "`[materials.NAME]`, one table per material"),
    Key("shapes", "array of tables", "none", "`[[shapes]]`: geometry, optionally emitting"),
    Key("lights", "array of tables", "none", "`[[lights]]`: point, spot and directional lights"),
    Key("environment", "table", "none", "`[environment]`: light from every direction at infinity"),
))

RENDER = Section("[render]", "Defaults of `tracer render`; its flags win. `reference`, `compare` and "
                 "`tracer.render` take `light_sampling` and `sampler` from here when not given.", (
    Key("spp", "integer >= 1", "64", "samples per pixel"),
    Key("strategy", "string", "mis", "a strategy name (see the plug-in page)"),
    Key("light_sampling", "string", "area", "how a chosen light is sampled: area, solid-angle, "
        "solid-angle-cos"),
    Key("sampler", "string", "independent", "where the random numbers come from: a sampler name"),
))

CAMERA = Section("[camera]", "The camera: a pinhole, a thin lens or an orthographic projection; a "
                 "pixel is the plain mean of its samples (a box filter).", (
    Key("origin", VEC3, REQUIRED, "eye position (orthographic: the centre of the film, where rays "
        "start)"),
    Key("target", VEC3, REQUIRED, "a point the camera looks at; must differ from origin"),
    Key("up", VEC3, "[0, 1, 0]", "not zero, not parallel to target - origin"),
    Key("projection", "string", "\"perspective\"", "perspective or orthographic (parallel rays "
        "along target - origin)"),
    Key("fov", "number in (0, 179]", "required (perspective)", "vertical field of view in degrees; "
        "perspective only"),
    Key("view_width", "number > 0", "required (orthographic)", "the width of an orthographic film in "
        "scene units; its height follows the aspect ratio"),
    Key("aperture_radius", "number >= 0", "0", "perspective: the radius of a thin lens in scene units "
        "(0: a pinhole); depth of field"),
    Key("focus_distance", "number > 0", "required with a lens", "the distance along the view to the "
        "plane in focus"),
    Key("width", "integer 1 .. 32768", "256", "pixels; --width replaces it"),
    Key("height", "integer 1 .. 32768", "256", "pixels; --height replaces it"),
    Key("mirrored", "boolean", "false", "the image's x axis runs the other way (a Mitsuba sensor "
        "whose transform has a negative determinant)"),
))

MATERIAL = Section("[materials.NAME]", "One material; NAME is any TOML key, which shapes refer to. "
                   "The other keys are the type's parameters (plug-in page).", (
    Key("type", "string", REQUIRED, "a material type: diffuse, mirror, conductor, ... (plug-in page)"),
    Key("twosided", "boolean", "true", "reflects on both sides; false: black seen from behind"),
    Key("opacity", "number in [0, 1] or a texture", "1", "the fraction of light the surface stops "
        "(Mitsuba's mask): a hit is passed through with probability 1 - opacity, a shadow ray "
        "carries that fraction on; not on an emitting shape"),
    Key("normal_map", "a texture", "none", "the normal, 2 rgb - 1, in the shading frame whose x "
        "axis is dp/du (Mitsuba's normalmap; usually a raw bitmap); not on a type that transmits"),
    Key("bump_map", "a texture (a bilinear bitmap)", "none", "a height field whose gradient tilts "
        "the shading frame (Mitsuba's bumpmap); not with normal_map"),
    Key("bump_scale", "number", "1", "the bump map's gradient factor"),
    Key("flip_invalid_normals", "boolean", "true", "with a map: a tilted normal facing away from "
        "the viewer is mirrored about the shading normal"),
    Key("use_shadowing_function", "boolean", "true", "with a map: the bump-terminator shadowing "
        "term (Estevez et al. 2019)"),
))

TEXTURE = Section("a material parameter's texture", "Any parameter the plug-in page marks "
                  "`texture` may be an inline table instead of a value: `reflectance = { texture = "
                  "\"bitmap\", file = \"wood.png\" }`. Coordinates (u, v) are Mitsuba's (SCENE_FORMAT.md).", (
    Key("texture", "string", REQUIRED, "checkerboard or bitmap"),
    Key("color0", "number or 3 numbers", "0.4", "checkerboard: where the fractional parts of u and v are "
        "both above 1/2 or both not (a one-number parameter swaps the colours, as Mitsuba does)"),
    Key("color1", "number or 3 numbers", "0.2", "checkerboard: elsewhere"),
    Key("file", "string", REQUIRED + " (bitmap)", "bitmap: an image OpenImageIO reads, relative to the "
        "scene file; 8- and 16-bit images are sRGB-decoded unless raw, float images are linear"),
    Key("raw", "boolean", "false", "bitmap: take integer images' values as they are"),
    Key("filter", "string", "bilinear", "bitmap: bilinear or nearest"),
    Key("wrap", "string", "repeat", "bitmap: repeat, mirror or clamp beyond [0, 1]"),
    Key("to_uv", "2 rows of 3 numbers", "[[1, 0, 0], [0, 1, 0]]", "(u, v) -> (a u + b v + c, d u + e v + f) "
        "before the lookup"),
))

_SHAPE_COMMON = (
    Key("type", "string", REQUIRED, "quad, sphere or mesh"),
    Key("material", "string", "none (black)", "the NAME of a [materials.NAME] table"),
    Key("emission", VEC3 + " >= 0, <= 1e18", "[0, 0, 0]", "radiance leaving the front side: an "
        "area light"),
)

QUAD = Section("[[shapes]] type = \"quad\"", "A parallelogram of two triangles; front = "
               "normalize(edge1 x edge2).", _SHAPE_COMMON + (
    Key("origin", VEC3, REQUIRED, "corner o"),
    Key("edge1", VEC3, REQUIRED, "the corners are o, o + edge1, o + edge1 + edge2, o + edge2"),
    Key("edge2", VEC3, REQUIRED, "see edge1"),
    Key("uv", "4 pairs of numbers", "[[0, 0], [1, 0], [1, 1], [0, 1]]", "texture coordinates at the "
        "corners o, o + edge1, o + edge1 + edge2, o + edge2"),
))

SPHERE = Section("[[shapes]] type = \"sphere\"", "A true sphere, intersected exactly, emitting from "
                 "its outside; with subdivisions, an icosphere mesh.", _SHAPE_COMMON + (
    Key("center", VEC3, REQUIRED, "centre"),
    Key("radius", "number > 0", REQUIRED, "at least 1e-6 times the largest centre coordinate"),
    Key("subdivisions", "integer 0 .. 7", "none (a true sphere)", "an icosphere of 20 * 4^s "
        "triangles instead"),
    Key("uv_frame", "3 rows of 3 numbers", "the world's axes", "a true sphere's texture frame: the "
        "rows are its local x, y, z axes in world coordinates (u = φ/2π about z from x, v = θ/π)"),
))

MESH = Section("[[shapes]] type = \"mesh\"", "A triangle mesh file read by trimesh (.ply, .obj, "
               ".stl, .glb, ...).", _SHAPE_COMMON + (
    Key("file", "string", REQUIRED, "the mesh file, relative to the scene file's folder"),
    Key("normals", "string", "face", "face: flat shading with each triangle's normal; vertex: "
        "the file's vertex normals (or angle-weighted ones) interpolated"),
    Key("flip_v", "boolean", "false", "turn the file's texture coordinate v into 1 - v (what Mitsuba "
        "does to OBJ files by default)"),
))

POINT_LIGHT = Section("[[lights]] type = \"point\"", "A point light: a delta light, seen by light "
                      "sampling only.", (
    Key("type", "string", REQUIRED, "point"),
    Key("position", VEC3, REQUIRED, "world position"),
    Key("intensity", VEC3 + " >= 0, <= 1e18", REQUIRED, "radiant intensity, W/sr per channel"),
))

SPOT_LIGHT = Section("[[lights]] type = \"spot\"", "A spot light (Mitsuba's `spot`): a point light shining "
                     "within a cone, full within the beam width and falling linearly in angle to 0 at the "
                     "cutoff.", (
    Key("type", "string", REQUIRED, "spot"),
    Key("position", VEC3, REQUIRED, "world position"),
    Key("intensity", VEC3 + " >= 0, <= 1e18", REQUIRED, "radiant intensity on the axis, W/sr per channel"),
    Key("direction", VEC3, REQUIRED, "the axis the light shines along (not zero)"),
    Key("cutoff_angle", "degrees in (0, 180]", "20", "where the light ends"),
    Key("beam_width", "degrees in [0, 180]", "3/4 of cutoff_angle", "where the falloff starts"),
))

DIRECTIONAL_LIGHT = Section("[[lights]] type = \"directional\"", "A directional light: parallel light "
                            "arriving from infinity (the sun), seen by light sampling only.", (
    Key("type", "string", REQUIRED, "directional"),
    Key("direction", VEC3, REQUIRED, "the direction the light travels in (not zero)"),
    Key("irradiance", VEC3 + " >= 0, <= 1e18", REQUIRED, "irradiance on a surface facing the light, W/m² "
        "per channel"),
))
LIGHTS = {"point": POINT_LIGHT, "spot": SPOT_LIGHT, "directional": DIRECTIONAL_LIGHT}
# A light's table before its type is read.
LIGHT = Section("[[lights]]", "Keys of every light.", (Key("type", "string", REQUIRED, ", ".join(LIGHTS)),))

ENVIRONMENT = Section("[environment]", "Light arriving from every direction at infinity: a constant "
                      "`radiance` or a latitude-longitude `map` in Mitsuba 3's orientation (see the scene "
                      "format's environment section); one per scene.", (
    Key("radiance", VEC3 + " >= 0, <= 1e18", "none", "a constant environment's radiance (give this or map)"),
    Key("map", "string", "none", "an image file (EXR, HDR, PNG, ...) relative to the scene file; 8-bit "
        "images are sRGB-decoded"),
    Key("scale", "number >= 0", "1", "multiplies the map's texels"),
    Key("to_world", "3 lists of 3 numbers", "identity", "the rotation (or mirror) from the map's frame to "
        "the world, by rows"),
))

# A shape's table before its type is read (the keys every type has).
SHAPE = Section("[[shapes]]", "Keys of every shape.", _SHAPE_COMMON)
SHAPES = {"quad": QUAD, "sphere": SPHERE, "mesh": MESH}
# Every section, in the order the reference lists them.
SECTIONS = (TOP, RENDER, CAMERA, MATERIAL, TEXTURE, QUAD, SPHERE, MESH, POINT_LIGHT, SPOT_LIGHT,
            DIRECTIONAL_LIGHT, ENVIRONMENT)
