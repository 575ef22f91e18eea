"""A scene's emitters by kind: what light techniques sample and light selections choose among.

Seven kinds (``KINDS``), each a record of arrays with one row per emitter candidate:

=========  ===========================================================  =========================
kind       candidates                                                   record
=========  ===========================================================  =========================
triangle   every emitting triangle of positive area (a quad's two       :class:`TriangleEmitters`
           triangles unless it is taken as a rectangle)
textured_  the triangles of shapes whose radiance is a bitmap or a      :class:`TexturedTriangle-
triangle   checkerboard, when the render's light sampling has a         Emitters`
           technique for them (``area``: ``triangle_texels``); else
           they are triangles (or rectangles) like the others
rectangle  emitting quads with perpendicular edges, when the render's    :class:`RectangleEmitters`
           light sampling has a technique for rectangles
sphere     emitting analytic spheres                                    :class:`SphereEmitters`
point      point lights (and spot lights) of positive intensity         :class:`PointEmitters`
direc-     directional lights of positive irradiance (delta lights at   :class:`DirectionalEmitters`
tional     infinity)
environ-   the scene's environment if it sends light: one candidate,    :class:`Environment-
ment       sampled by ``tracer.lights.environment`` (no technique)      Emitters`
=========  ===========================================================  =========================

Every record also says each candidate's flux (for the ``power`` selection), the shape it
belongs to (``owner``: shape index, -1 - i for point light i, -1 - P - j for directional light
j, -1 - P - D for the environment; for the ``uniform`` selection), its area (1 for the lights
without one), its bounds (for the light BVH: a box and a cone of emission directions) and the
scene primitives it covers (for the pdf of a direction that hits it). Directional lights and the
environment are lights at infinity (``Emitters.AT_INFINITY``): their box is the scene's, over
whose bounding sphere their flux is measured, and the light BVH keeps them out of its tree.

A textured emitter's triangle (or rectangle) takes as its emission the mean of its texture over
its own (u, v) footprint, integrated exactly (``tracer.lights.textured_area``), not the
texture's mean over [0, 1]^2: its flux, and so how often the ``power`` and ``bvh`` selections
choose it, follows the light it really sends, and the ``uniform`` selection splits a textured
shape among its candidates by that flux instead of their area.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from . import textured_area

KINDS = ("triangle", "textured_triangle", "rectangle", "sphere", "point", "directional", "environment")
# Smallest emitting triangle the light table takes: 1 / area must be finite in float32.
MIN_LIGHT_AREA = float(np.finfo(np.float32).tiny)
# A quad is sampled as a rectangle when its edges are perpendicular to this relative precision
# (|e1 . e2| <= RECTANGLE_TOLERANCE |e1| |e2|); other quads as two triangles.
RECTANGLE_TOLERANCE = 1e-6


@dataclass
class Emitters:
    """What every kind's record holds (K candidates).

    flux : (K,) pi area mean(Le) (4 pi mean(I) for a point light).   owner : (K,) int64 shape
    index (-1 - i for point light i).   area : (K,) (1 for a point light).
    lo, hi : (K, 3) bounding box.   axis : (K, 3) the normal of one-sided emitters (+z for the
    others).   cos_o : (K,) cos of the emission cone's spread: 1 (a normal's front hemisphere)
    or -1 (every direction).   prims : list of (K,) arrays of the scene primitives the
    candidate covers (triangles: one; a rectangle: two; a sphere: its primitive id).
    share : (K,) what the ``uniform`` selection splits a light among its candidates by: their
    flux for a textured emitter; None: ``area``.
    """

    flux: np.ndarray
    owner: np.ndarray
    area: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    axis: np.ndarray
    cos_o: np.ndarray
    prims: list
    share: np.ndarray | None = None
    # A light at infinity (directional, environment): no position, its box the scene's, and
    # kept out of the light BVH (``tracer.lights.selections.bvh``).
    AT_INFINITY: ClassVar[bool] = False

    def __len__(self) -> int:
        return len(self.flux)


@dataclass
class TriangleEmitters(Emitters):
    """corners (T, 3, 3), normal (T, 3) unit front normal, emission (T, 3)."""

    corners: np.ndarray = None  # type: ignore[assignment]
    normal: np.ndarray = None  # type: ignore[assignment]
    emission: np.ndarray = None  # type: ignore[assignment]


@dataclass
class TexturedTriangleEmitters(TriangleEmitters):
    """A :class:`TriangleEmitters` (emission: each triangle's mean radiance) and ``tables``, (T,)
    list of each triangle's distribution over its texels (``textured_area.TexelTable``)."""

    tables: list = None  # type: ignore[assignment]


@dataclass
class RectangleEmitters(Emitters):
    """frames (Q, 3, 3): corner, edge u, edge v (perpendicular); emission (Q, 3)."""

    frames: np.ndarray = None  # type: ignore[assignment]
    emission: np.ndarray = None  # type: ignore[assignment]


@dataclass
class SphereEmitters(Emitters):
    """spheres (S, 4) centre and radius; emission (S, 3) radiance leaving the outside."""

    spheres: np.ndarray = None  # type: ignore[assignment]
    emission: np.ndarray = None  # type: ignore[assignment]


@dataclass
class PointEmitters(Emitters):
    """position (P, 3); intensity (P, 3) in W/sr; spot_axis (P, 3), cutoff, beam (P,) radians
    (pi, pi: every way; ``Scene.point_cutoff``); images (P,) the image each projects, or None
    (``tracer.lights.projected_images``)."""

    position: np.ndarray = None  # type: ignore[assignment]
    intensity: np.ndarray = None  # type: ignore[assignment]
    spot_axis: np.ndarray = None  # type: ignore[assignment]
    cutoff: np.ndarray = None  # type: ignore[assignment]
    beam: np.ndarray = None  # type: ignore[assignment]
    images: list = None  # type: ignore[assignment]


@dataclass
class DirectionalEmitters(Emitters):
    """direction (D, 3) the light travels in; irradiance (D, 3) W/m^2."""

    AT_INFINITY = True
    direction: np.ndarray = None  # type: ignore[assignment]
    irradiance: np.ndarray = None  # type: ignore[assignment]


@dataclass
class EnvironmentEmitters(Emitters):
    """The environment (none or one), sampled by ``tracer.lights.environment``."""

    AT_INFINITY = True


def emitting_triangles(scene) -> np.ndarray:
    """Indices of the scene's emitting triangles that can be light candidates. Emission is >= 0,
    so a triangle with area and some positive channel has positive flux. The table holds 1 /
    area in float32: a triangle smaller than float32's smallest normal number (a sphere of
    radius 1e-20) would put inf there, so it is left out like a zero-area one (never
    light-sampled; a BSDF sample that hits it gets weight 1, consistently). A textured
    emitter's triangle whose footprint holds only black texels (its exact integral 0,
    ``textured_area.mean_radiance``) sends no light and is left out too: its flux of 0 would
    make the ``uniform`` selection's split 0 / 0."""
    tri = np.flatnonzero((scene.area >= MIN_LIGHT_AREA) & (scene.emission.max(axis=1, initial=0.0) > 0.0))
    if scene.textures.emitters:
        tri = tri[textured_area.mean_radiance(scene, tri).max(axis=1, initial=0.0) > 0.0]
    return tri


def rectangles(scene, tri: np.ndarray) -> RectangleEmitters:
    """The emitting quads among ``scene.shapes`` that are rectangles with both triangles in
    ``tri``, their corner, edge u, edge v taken from the quad's float32 vertices (o, o + e1,
    o + e1 + e2, o + e2), so that the rectangle sampled is the one Embree intersects
    (float32(o) + float32(e1) can differ from float32(o + e1): a light 0.00013 wide at x = 1000
    was 6% wider that way)."""
    in_table = set(tri.tolist())
    found, frames = [], []
    for index, shape in enumerate(scene.shapes):
        if shape.type != "quad" or shape.count != 2 or not shape.emissive:
            continue
        if shape.first not in in_table or shape.first + 1 not in in_table:
            continue
        first, second = scene.faces[shape.first], scene.faces[shape.first + 1]  # (0, 1, 2), (0, 2, 3)
        corner = scene.vertices[first[0]]
        e1 = scene.vertices[first[1]] - corner
        e2 = scene.vertices[second[2]] - corner
        if abs(np.dot(e1, e2)) <= RECTANGLE_TOLERANCE * np.linalg.norm(e1) * np.linalg.norm(e2):
            found.append(index)
            frames.append([corner, e1, e2])
    frames = np.array(frames, dtype=np.float64).reshape(-1, 3, 3)
    area = np.linalg.norm(np.cross(frames[:, 1], frames[:, 2]), axis=1)
    emission = np.array([scene.shapes[q].emission for q in found]).reshape(-1, 3)
    corners = frames[:, :1] + np.array([0.0, 1.0, 1.0, 0.0])[:, None] * frames[:, 1:2] \
        + np.array([0.0, 0.0, 1.0, 1.0])[:, None] * frames[:, 2:3]
    first_triangle = np.array([scene.shapes[q].first for q in found], dtype=np.int64)
    textured = np.array([q in scene.textures.emitters for q in found], dtype=bool)
    if textured.any():  # the area-weighted mean of its two triangles' means
        halves = np.stack([first_triangle[textured], first_triangle[textured] + 1], axis=1)
        mean = textured_area.mean_radiance(scene, halves.reshape(-1)).reshape(-1, 2, 3)
        weight = scene.area[halves]
        emission[textured] = (mean * weight[..., None]).sum(axis=1) / weight.sum(axis=1)[:, None]
    flux = np.pi * area * emission.mean(axis=1)
    return RectangleEmitters(flux, np.array(found, dtype=np.int64), area,
                             corners.min(axis=1), corners.max(axis=1),
                             scene.normal[first_triangle].reshape(-1, 3), np.ones(len(found)),
                             [first_triangle, first_triangle + 1], share=_share(textured, flux, area),
                             frames=frames, emission=emission)


def triangles(scene, tri: np.ndarray, emission: np.ndarray | None = None) -> TriangleEmitters:
    """The triangles ``tri`` as candidates; ``emission (T, 3)`` their mean radiance (default
    ``textured_area.mean_radiance``: the scene's constant, or a textured one's integral)."""
    corners = scene.vertices[scene.faces[tri]]
    emission = textured_area.mean_radiance(scene, tri) if emission is None else emission
    owner = scene.shape_of_triangle[tri].astype(np.int64)
    flux = np.pi * scene.area[tri] * emission.mean(axis=1)
    textured = np.isin(owner, list(scene.textures.emitters))
    return TriangleEmitters(flux, owner, scene.area[tri], corners.min(axis=1), corners.max(axis=1),
                            scene.normal[tri], np.ones(len(tri)), [tri.astype(np.int64)],
                            share=_share(textured, flux, scene.area[tri]), corners=corners,
                            normal=scene.normal[tri], emission=emission)


def _share(textured: np.ndarray, flux: np.ndarray, area: np.ndarray) -> np.ndarray | None:
    """``Emitters.share``: the flux of textured candidates, the area of the others (None if
    none is textured)."""
    return np.where(textured, flux, area) if textured.any() else None


def texel_sampled(scene, tri: np.ndarray) -> np.ndarray:
    """``(T,)`` bool: which of the emitting triangles ``tri`` are textured emitters that a
    ``textured_triangle`` technique can sample (``textured_area.sampled_by_texels``)."""
    return textured_area.sampled_by_texels(scene, tri)


def textured_triangles(scene, tri: np.ndarray) -> TexturedTriangleEmitters:
    """The textured triangles ``tri`` (:func:`texel_sampled`) with their distributions."""
    tables, mean = textured_area.texel_tables(scene, tri)
    return TexturedTriangleEmitters(**vars(triangles(scene, tri, mean)), tables=tables)


def spheres(scene) -> SphereEmitters:
    sph = np.flatnonzero((scene.sphere_emission.max(axis=1, initial=0.0) > 0.0)
                         & (4.0 * np.pi * scene.spheres[:, 3] ** 2 >= MIN_LIGHT_AREA))
    area = 4.0 * np.pi * scene.spheres[sph, 3] ** 2
    centre, radius = scene.spheres[sph, :3], scene.spheres[sph, 3:]
    axis = np.zeros((len(sph), 3))
    axis[:, 2] = 1.0
    return SphereEmitters(np.pi * area * scene.sphere_emission[sph].mean(axis=1),
                          scene.shape_of_sphere[sph].astype(np.int64), area, centre - radius, centre + radius,
                          axis, -np.ones(len(sph)), [scene.triangle_count + sph.astype(np.int64)],
                          spheres=scene.spheres[sph], emission=scene.sphere_emission[sph])


def spot_solid_angle(cutoff: float, beam: float) -> float:
    """The integral of a spot's falloff over the sphere, angles in radians (4 pi for a light that
    shines every way, cutoff pi): 2 pi times the integral over theta of falloff(theta)
    sin(theta), the falloff 1 within the beam width and (c - theta) / (c - b) from there to the
    cutoff c (Mitsuba's ``spot``). In closed form, since the integral of (c - theta) sin(theta)
    from b to c is (c - b) cos b + sin b - sin c."""
    if cutoff >= np.pi:
        return 4.0 * np.pi
    beam = min(beam, cutoff)
    inner = 2.0 * np.pi * (1.0 - np.cos(beam))
    if cutoff <= beam:
        return float(inner)
    ramp = ((cutoff - beam) * np.cos(beam) + np.sin(beam) - np.sin(cutoff)) / (cutoff - beam)
    return float(inner + 2.0 * np.pi * ramp)


def points(scene) -> PointEmitters:
    cones = np.array([spot_solid_angle(np.radians(c), np.radians(b))
                      for c, b in zip(scene.point_cutoff, scene.point_beam, strict=True)]).reshape(-1)
    flux = cones * scene.point_intensity.mean(axis=1)
    # A projected image scales the power by its mean: exactly for a projector, whose intensity
    # over its frustum integrates to mean(I) mean(image) times the image's area at distance 1;
    # for a textured spot, where the image's disk fills the cone, nearly (the selection's pmf
    # needs no more: any positive pmf is unbiased).
    for i, image in enumerate(scene.point_images):
        if image is not None:
            flux[i] = scene.point_intensity[i].mean() * image.mean() * (
                image.area if image.kind == "projector" else cones[i])
    lit = np.flatnonzero(flux > 0.0)
    position = scene.point_position[lit]
    axis = np.zeros((len(lit), 3))
    axis[:, 2] = 1.0
    return PointEmitters(flux[lit], (-1 - lit).astype(np.int64), np.ones(len(lit)), position, position, axis,
                         -np.ones(len(lit)), [], position=position, intensity=scene.point_intensity[lit],
                         spot_axis=scene.point_axis[lit], cutoff=np.radians(scene.point_cutoff[lit]),
                         beam=np.radians(scene.point_beam[lit]), images=[scene.point_images[i] for i in lit])


def directionals(scene) -> DirectionalEmitters:
    """Directional lights: flux pi r^2 mean(E) over the scene's bounding sphere (what a disk of
    the scene's size catches), box the scene's, emitting one way (cone axis: the direction the
    light travels, spread 0)."""
    irradiance = scene.directional_irradiance
    lit = np.flatnonzero(irradiance.max(axis=1, initial=0.0) > 0.0)
    lo, hi = scene_box(scene)
    radius = scene_radius(lo, hi)
    direction = scene.directional_direction[lit]
    return DirectionalEmitters(np.pi * radius * radius * irradiance[lit].mean(axis=1),
                               (-1 - len(scene.point_position) - lit).astype(np.int64), np.ones(len(lit)),
                               np.tile(lo, (len(lit), 1)), np.tile(hi, (len(lit), 1)), direction.reshape(-1, 3),
                               np.ones(len(lit)), [], direction=direction, irradiance=irradiance[lit])


def environment(scene) -> EnvironmentEmitters:
    """The scene's environment as one candidate (none without one, or if it is black). Its
    flux is ``tracer.lights.environment.flux`` over the scene's bounding sphere; its box is the
    scene's, emitting every way."""
    from . import environment as light

    env = scene.environment
    lo, hi = scene_box(scene)
    power = light.flux(env, scene_radius(lo, hi)) if env is not None else 0.0
    lit = 1 if power > 0.0 else 0
    axis = np.tile([0.0, 0.0, 1.0], (lit, 1))
    owner = -1 - len(scene.point_position) - len(scene.directional_irradiance)
    return EnvironmentEmitters(np.full(lit, power), np.full(lit, owner, dtype=np.int64), np.ones(lit),
                               np.tile(lo, (lit, 1)), np.tile(hi, (lit, 1)), axis, -np.ones(lit), [])


def scene_radius(lo: np.ndarray, hi: np.ndarray) -> float:
    """The radius of the bounding sphere of the box ``lo, hi`` (1 for an empty scene): what the
    flux of a light at infinity is measured over."""
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    return radius if radius > 0.0 else 1.0


def scene_box(scene) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (3,) the box around the scene's triangles, spheres and point lights (zeros
    for an empty scene)."""
    centre, radius = scene.spheres[:, :3], scene.spheres[:, 3:]
    points = np.concatenate([scene.vertices, scene.point_position, centre - radius, centre + radius])
    if not len(points):
        return np.zeros(3), np.zeros(3)
    return points.min(axis=0), points.max(axis=0)


@dataclass
class Candidates:
    """Every candidate of a render, kinds in the order of ``KINDS`` (the light table's rows):
    the fields of :class:`Emitters`, concatenated, that light selections read (``share``: the
    area where a record has none), and ``infinite`` (K,) bool, the lights at infinity
    (``Emitters.AT_INFINITY``: directional lights and the environment, the last candidates)."""

    flux: np.ndarray
    owner: np.ndarray
    area: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    axis: np.ndarray
    cos_o: np.ndarray
    share: np.ndarray
    infinite: np.ndarray

    @classmethod
    def of(cls, records: list[Emitters]) -> "Candidates":
        def cat(name: str, shape: tuple[int, ...]) -> np.ndarray:
            parts = [np.asarray(_field(r, name), dtype=np.float64).reshape((-1,) + shape) for r in records]
            return np.concatenate(parts) if parts else np.zeros((0,) + shape)

        infinite = np.concatenate([np.full(len(r), r.AT_INFINITY) for r in records] or [np.zeros(0, bool)])
        return cls(cat("flux", ()), cat("owner", ()).astype(np.int64), cat("area", ()), cat("lo", (3,)),
                   cat("hi", (3,)), cat("axis", (3,)), cat("cos_o", ()), cat("share", ()), infinite)


def _field(record: Emitters, name: str) -> np.ndarray:
    """A record's field; its ``share`` is its area where it has none."""
    value = getattr(record, name)
    return record.area if value is None and name == "share" else value
