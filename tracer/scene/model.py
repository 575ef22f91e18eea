"""The scene model: what every scene reader produces and the renderer reads.

Two kinds of primitive. Triangles (quads split in two, meshes as read, spheres given
``subdivisions``) go into one Embree mesh, with per-triangle arrays for what shading needs.
Analytic spheres (a ``sphere`` without ``subdivisions``) are intersected exactly by tracer's
own compiled code (``tracer.geometry``). Primitive ids number the triangles 0 .. F - 1 and the
spheres F .. F + S - 1; the hit table has one row per primitive. Each shape keeps its record
as the file gave it (a sphere's centre and radius, a quad's corners), so that light techniques
that sample a shape as a whole (a rectangle, a sphere) can find it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .. import materials
from ..camera import Camera
from ..materials import MaterialTable
from ..textures import TextureTable
from .environment import Environment

# Offsets along the normal are this fraction of the scene's extent (see Scene.ray_epsilon).
RELATIVE_RAY_OFFSET = 1e-5


@dataclass
class Shape:
    """One shape of the scene as its file gave it.

    type : ``quad``, ``sphere`` or ``mesh``.
    first, count : its triangles are ``first .. first + count - 1`` of the scene's (count 0
        for an analytic sphere).
    sphere : the analytic sphere's row in the scene's sphere arrays, -1 if it has triangles.
    material : row in the material table (0: black).   emission : (3,) radiance from its front.
    record : what defines it: quad ``origin, edge1, edge2``; sphere ``center, radius,
        subdivisions``; mesh ``file``.
    """

    type: str
    first: int
    count: int
    material: int
    emission: np.ndarray
    record: dict[str, Any] = field(default_factory=dict)
    sphere: int = -1

    @property
    def emissive(self) -> bool:
        return bool(np.any(self.emission > 0.0))


@dataclass
class Scene:
    """A loaded scene: triangles with per-triangle arrays, shapes, materials, point lights, an
    environment, camera.

    vertices : (V, 3) float64 world positions, rounded to float32 (Embree's precision).
    faces : (F, 3) int32 vertex indices.
    material : (F,) int32 row of each triangle's material in ``materials`` (0: black).
    emission : (F, 3) float64 radiance leaving each triangle's front side (0: not emissive),
        rounded to float32.
    shape_of_triangle : (F,) int32 index into ``shapes``.
    shapes : the shapes, with their records.
    materials : the material table (``tracer.materials``).
    point_position, point_intensity : (P, 3) float64 (rounded to float32); intensity in W/sr.
    render_defaults : the file's ``[render]`` settings (``spp``, ``strategy``).
    spheres : (S, 4) float64 analytic spheres, centre and radius (rounded to float32, as the
        light table stores them).   sphere_material : (S,) int32.   sphere_emission : (S, 3)
        radiance leaving the outside.   shape_of_sphere : (S,) int32 index into ``shapes``.
    corner_normals : (F, 9) float64 unit vertex normals at each triangle's three corners, for
        smooth shading (a row of zeros: the triangle shades with its face normal); (0, 9) when
        every triangle is flat.
    textures : the scene's textures and the material parameters they feed (``tracer.textures``).
    corner_uv : (F, 6) float64 texture coordinates (u, v) at each triangle's corners, for
        textured materials; (0, 6) when nothing is textured.   sphere_frame : (S, 9) each
        analytic sphere's world-to-local rotation (rows), for its texture coordinates; (0, 9)
        when nothing is textured.
    environment : the light arriving from infinity (``tracer.scene.environment``), or None.
    point_axis : (P, 3) unit axis of each point light's cone (a spot light's); ``point_cutoff``,
        ``point_beam`` (P,) its cutoff and beam-width angles in degrees, Mitsuba's ``spot``
        (full intensity within the beam width, falling linearly in angle to 0 at the cutoff);
        180 and 180 for a light that shines every way (the default).
    point_images : (P,) list, the image each point light projects (a textured spot, a projector:
        ``tracer.lights.projected_images.ProjectedImage``) or None.
    directional_direction : (D, 3) the unit direction each directional light's light travels
        in; ``directional_irradiance`` (D, 3) its irradiance on a surface facing it, W/m^2.

    Derived on construction: ``v0, edge1, edge2, normal`` (F, 3), ``area`` (F,),
    ``hit_table`` (F + S, 16), ``ray_epsilon``.
    """

    path: str
    camera: Camera
    vertices: np.ndarray
    faces: np.ndarray
    material: np.ndarray
    emission: np.ndarray
    shape_of_triangle: np.ndarray
    shapes: list[Shape]
    materials: MaterialTable
    point_position: np.ndarray
    point_intensity: np.ndarray
    render_defaults: dict[str, Any] = field(default_factory=dict)
    spheres: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    sphere_material: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    sphere_emission: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shape_of_sphere: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    corner_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 9)))
    textures: TextureTable = field(default_factory=TextureTable)
    corner_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    sphere_frame: np.ndarray = field(default_factory=lambda: np.zeros((0, 9)))
    environment: Environment | None = None
    point_axis: np.ndarray | None = None
    point_cutoff: np.ndarray | None = None
    point_beam: np.ndarray | None = None
    point_images: list | None = None
    directional_direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    directional_irradiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        count = len(self.point_position)
        self.point_axis = (np.tile([0.0, 0.0, 1.0], (count, 1)) if self.point_axis is None
                           else np.asarray(self.point_axis, dtype=np.float64).reshape(-1, 3))
        self.point_cutoff = (np.full(count, 180.0) if self.point_cutoff is None
                             else np.asarray(self.point_cutoff, dtype=np.float64).reshape(-1))
        self.point_beam = (np.full(count, 180.0) if self.point_beam is None
                           else np.asarray(self.point_beam, dtype=np.float64).reshape(-1))
        self.point_images = [None] * count if self.point_images is None else list(self.point_images)
        if not len(self.point_axis) == len(self.point_cutoff) == len(self.point_beam) == len(self.point_images) \
                == count:
            raise ValueError("point_axis, point_cutoff, point_beam and point_images need one row per point "
                             "light")
        self.directional_direction = np.asarray(self.directional_direction, dtype=np.float64).reshape(-1, 3)
        self.directional_irradiance = np.asarray(self.directional_irradiance, dtype=np.float32).astype(
            np.float64).reshape(-1, 3)
        if len(self.directional_direction) != len(self.directional_irradiance):
            raise ValueError("directional_direction and directional_irradiance need one row per light")
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
        self.spheres = np.asarray(self.spheres, dtype=np.float32).astype(np.float64).reshape(-1, 4)
        self.corner_normals = np.ascontiguousarray(self.corner_normals, dtype=np.float64).reshape(-1, 9)
        if len(self.corner_normals) not in (0, len(self.faces)):
            raise ValueError("corner_normals needs one row per triangle, or none")
        self.corner_uv = np.ascontiguousarray(self.corner_uv, dtype=np.float64).reshape(-1, 6)
        self.sphere_frame = np.ascontiguousarray(self.sphere_frame, dtype=np.float64).reshape(-1, 9)
        if len(self.corner_uv) not in (0, len(self.faces)):
            raise ValueError("corner_uv needs one row per triangle, or none")
        if len(self.sphere_frame) not in (0, len(self.spheres)):
            raise ValueError("sphere_frame needs one row per sphere, or none")
        # What a hit needs, in one row per primitive so that a batch gathers it in one go:
        # triangles v0 (3), edge1 (3), edge2 (3), normal (3); spheres centre (3), radius (1),
        # zeros (5), and a zero normal, which marks the row as a sphere's; then for both
        # emission (3) and material row (1).
        triangles = np.concatenate([self.v0, self.edge1, self.edge2, self.normal, self.emission,
                                    self.material[:, None]], axis=1)
        spheres = np.zeros((len(self.spheres), 16))
        spheres[:, 0:4] = self.spheres
        spheres[:, 12:15] = self.sphere_emission
        spheres[:, 15] = self.sphere_material
        self.hit_table = np.ascontiguousarray(np.concatenate([triangles, spheres]))
        # float32 rounding in Embree scales with the magnitude of the coordinates a ray starts
        # from, which are the geometry's (hit points) and never the camera's (camera rays start
        # at the camera, with no offset): an offset proportional to the geometry's extent makes
        # a scene scaled by 1e-3 or 1e3 render the same image, wherever the camera is.
        center, radius = self.spheres[:, :3], self.spheres[:, 3:]
        points = np.concatenate([self.vertices, self.point_position, center - radius, center + radius])
        extent = 0.0
        if len(points):
            lo, hi = points.min(axis=0), points.max(axis=0)
            extent = max(float(np.max(np.abs(np.concatenate([lo, hi])))), float(np.linalg.norm(hi - lo)))
        self.ray_epsilon = RELATIVE_RAY_OFFSET * extent if extent > 0.0 else RELATIVE_RAY_OFFSET

    @property
    def name(self) -> str:
        return Path(self.path).stem

    @cached_property
    def digest(self) -> str:
        """SHA-256 (hex) of what the scene renders: the camera (not its resolution), the
        triangles with their materials and emission, the shapes they group into, the material
        table and the point lights, each at the precision the renderer holds it. Two files that
        render the same thing share it, wherever they live and whatever their comments say;
        the render record carries it, so that merges and comparisons refuse other scenes.
        Computed once (the scene's arrays are not meant to change after loading)."""
        digest = hashlib.sha256(b"tracer scene digest 1\0")

        def add(label: str, values, dtype: str) -> None:
            array = np.ascontiguousarray(values, dtype=dtype)  # fixed byte order: same on every machine
            digest.update(f"{label}{array.shape}\0".encode())
            digest.update(array.tobytes())

        cam = self.camera
        add("camera", np.concatenate([cam.origin, cam.target, cam.up, [cam.fov]]), "<f8")
        if cam.mirrored:  # only then, so that the digests of other scenes stay as they were
            digest.update(b"camera mirrored\0")
        if cam.projection != "perspective":  # likewise
            add(f"camera {cam.projection}", [cam.view_width], "<f8")
        if cam.thin_lens:
            add("camera lens", [cam.aperture_radius, cam.focus_distance], "<f8")
        add("vertices", self.vertices, "<f4")
        add("faces", self.faces, "<i8")
        add("material", self.material, "<i4")
        add("emission", self.emission, "<f4")
        add("shape_of_triangle", self.shape_of_triangle, "<i4")
        digest.update(("shapes " + ",".join(s.type for s in self.shapes) + "\0").encode())
        add("material_kinds", self.materials.kind, "<i1")
        add("material_params", self.materials.digest_params(materials.BY_CODE), "<f8")
        add("point_position", self.point_position, "<f4")
        add("point_intensity", self.point_intensity, "<f4")
        if len(self.spheres):  # only then, so that the digests of scenes without them stay as they were
            add("spheres", self.spheres, "<f4")
            add("sphere_material", self.sphere_material, "<i4")
            add("sphere_emission", self.sphere_emission, "<f4")
            add("shape_of_sphere", self.shape_of_sphere, "<i4")
        if len(self.corner_normals):  # smooth shading; likewise only when there is some
            add("corner_normals", self.corner_normals, "<f8")
        if not np.all(self.materials.twosided):
            add("material_twosided", self.materials.twosided, "<i1")
        if np.any(self.materials.opacity < 1.0):  # masks; likewise (a textured one: in the textures')
            add("material_opacity", self.materials.opacity, "<f8")
        if self.textures:  # likewise: scenes without textures keep their digests
            digest.update(self.textures.digest())
            add("corner_uv", self.corner_uv, "<f8")
            add("sphere_frame", self.sphere_frame, "<f8")
        if np.any(self.point_cutoff < 180.0):  # spot lights; likewise
            add("point_axis", self.point_axis, "<f8")
            add("point_cone", np.stack([self.point_cutoff, self.point_beam], axis=1), "<f8")
        for i, image in enumerate(self.point_images):  # projected images; likewise
            if image is not None:
                digest.update(f"point image {i}\0".encode() + image.digest())
        if len(self.directional_direction):  # likewise
            add("directional_direction", self.directional_direction, "<f8")
            add("directional_irradiance", self.directional_irradiance, "<f4")
        if self.environment is not None:  # likewise
            add("environment_texels", self.environment.texels, "<f4")
            add("environment_to_world", self.environment.to_world, "<f8")
        return digest.hexdigest()

    @property
    def has_lights(self) -> bool:
        """Whether anything emits: a shape with emission, a point or directional light, or an
        environment that is not black."""
        return (bool(np.any(self.emission > 0.0)) or bool(np.any(self.sphere_emission > 0.0))
                or bool(np.any(self.point_intensity > 0.0))
                or bool(np.any(self.directional_irradiance > 0.0))
                or (self.environment is not None and self.environment.emits))

    @property
    def triangle_count(self) -> int:
        """F: primitive ids below it are triangles, from it on analytic spheres."""
        return len(self.faces)

    @property
    def light_of_triangle(self) -> np.ndarray:
        """(F,) int32: the index of the emissive shape (area light) a triangle belongs to, in the
        order of the emissive shapes; -1 for triangles of shapes that do not emit."""
        emissive = np.array([s.emissive for s in self.shapes], dtype=bool)
        light = np.where(emissive, np.cumsum(emissive) - 1, -1).astype(np.int32)
        return light[self.shape_of_triangle] if len(self.shapes) else np.zeros(0, dtype=np.int32)
