"""The camera of the scene contract (pinhole, thin lens, orthographic) and its primary rays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import samplers
from .jit import jit
from .kernels import UNBOUND, kernel
from .samplers import dimensions
from .warp import concentric_disk

PERSPECTIVE, ORTHOGRAPHIC = "perspective", "orthographic"
PROJECTIONS = (PERSPECTIVE, ORTHOGRAPHIC)


@dataclass
class Camera:
    """The camera: a pinhole or a thin lens (``perspective``), or a parallel projection
    (``orthographic``). Vectors are (3,) float64.

    fov : vertical field of view in degrees (``perspective``).
    mirrored : the image's x axis runs along -r instead of r (a camera whose transform has a
        negative determinant, as Mitsuba scenes with ``<scale x="-1"/>`` have).
    projection : ``perspective`` or ``orthographic``.
    view_width : ``orthographic``: the width of the film in world units (its height follows
        the aspect ratio); ``origin`` is the centre of the film, and rays start on it.
    aperture_radius : ``perspective``: the radius of a thin lens at ``origin`` in world units
        (0: a pinhole). Rays leave a uniform point of the lens toward the point of the plane
        ``focus_distance`` ahead (along forward) that the pinhole ray of the same film position
        meets: that plane is in focus (Mitsuba's ``thinlens``, src/sensors/thinlens.cpp).
    """

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    width: int
    height: int
    mirrored: bool = False
    projection: str = PERSPECTIVE
    view_width: float = 0.0
    aperture_radius: float = 0.0
    focus_distance: float = 1.0

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f, r, u): forward, right and up unit vectors, ``r = f x up`` (negated if
        ``mirrored``: the direction of the image's x axis), ``u = (f x up) x f``."""
        f = self.target - self.origin
        f = f / np.linalg.norm(f)
        r = np.cross(f, self.up)
        r = r / np.linalg.norm(r)
        return f, (-r if self.mirrored else r), np.cross(r, f)

    @property
    def thin_lens(self) -> bool:
        """Whether rays leave a lens of non-zero radius (and so draw a point on it)."""
        return self.projection == PERSPECTIVE and self.aperture_radius > 0.0

    @property
    def screen(self) -> tuple:
        """What the ray kernels need: orthographic (bool), width, height, the half height of the
        film (tan(fov / 2) at unit distance, or half the orthographic film's height in world
        units), f, r, u, origin, aperture radius, focus distance."""
        if self.projection == ORTHOGRAPHIC:
            half = 0.5 * float(self.view_width) * self.height / self.width
        else:
            half = float(np.tan(np.radians(self.fov) * 0.5))
        return ((self.projection == ORTHOGRAPHIC, self.width, self.height, half) + self.basis
                + (np.asarray(self.origin, dtype=np.float64), float(self.aperture_radius),
                   float(self.focus_distance)))

    def rays(self, pixel: np.ndarray, jitter: np.ndarray,
             lens: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through film positions (pixel x + jitter x, pixel y + jitter y).

        pixel : (n,) int64 row-major pixel index (row 0 at the top).
        jitter : (n, 2) in [0, 1)^2, the position inside the pixel (box filter).
        lens : (n, 2) in [0, 1)^2, the point of a thin lens (None: its centre).
        Returns origins (n, 3) and unit directions (n, 3), float64.
        """
        jitter = np.asarray(jitter, dtype=np.float64)
        lens = np.full_like(jitter, 0.5) if lens is None else np.asarray(lens, dtype=np.float64)
        return _rays(np.asarray(pixel), jitter, lens, *self.screen)

    def lane_rays(self, rays, sampler: samplers.SamplerParams, pixel: np.ndarray, sample: np.ndarray,
                  lens_dimension: int) -> tuple[np.ndarray, np.ndarray]:
        """The camera rays of lanes ``(pixel[i], sample[i])`` (``(n,)`` int64 each): the jitter
        inside the pixel is the sampler's camera dimensions (``samplers.dimensions``) and a thin
        lens's point the pair at ``lens_dimension``, drawn by ``rays``, the render's build of
        :func:`lane_camera_rays` (``tracer.kernels``). Returns origins and unit directions
        ``(n, 3)``, float32 as Embree takes them."""
        return rays(sampler, pixel, sample, lens_dimension, *self.screen)


@jit
def _ray(px: float, py: float, lens_u0: float, lens_u1: float, orthographic, width, height, half, f, r, u,
         origin, aperture, focus):
    """The ray through film position (px, py) in pixels (row 0 at the top): origin and unit
    direction, each an (x, y, z) tuple. Film x spans [-aspect, aspect] half, y spans [-1, 1]
    half; (lens_u0, lens_u1) in [0, 1)^2 picks the point of a thin lens (unused otherwise)."""
    sx = (2.0 * px / width - 1.0) * half * (width / height)
    sy = (1.0 - 2.0 * py / height) * half
    if orthographic:
        o = (origin[0] + sx * r[0] + sy * u[0], origin[1] + sx * r[1] + sy * u[1],
             origin[2] + sx * r[2] + sy * u[2])
        return o, (f[0], f[1], f[2])
    x, y, z = f[0] + sx * r[0] + sy * u[0], f[1] + sx * r[1] + sy * u[1], f[2] + sx * r[2] + sy * u[2]
    ox, oy, oz = origin[0], origin[1], origin[2]
    if aperture > 0.0:
        # The pinhole ray meets the plane in focus at t = focus (its forward component is 1);
        # the ray from the lens point aims there. The disk's x runs along -r, as Mitsuba's
        # camera-local x (the image's left), so that a lens sample lands where Mitsuba's does.
        a, b = concentric_disk(lens_u0, lens_u1)
        a, b = -a * aperture, b * aperture
        lx, ly, lz = a * r[0] + b * u[0], a * r[1] + b * u[1], a * r[2] + b * u[2]
        x, y, z = focus * x - lx, focus * y - ly, focus * z - lz
        ox, oy, oz = ox + lx, oy + ly, oz + lz
    inv = 1.0 / np.sqrt(x * x + y * y + z * z)
    return (ox, oy, oz), (x * inv, y * inv, z * inv)


@jit
def _rays(pixel, jitter, lens, orthographic, width, height, half, f, r, u, origin, aperture, focus):
    o = np.empty((len(pixel), 3))
    d = np.empty((len(pixel), 3))
    for i in range(len(pixel)):
        px, py = (pixel[i] % width) + jitter[i, 0], (pixel[i] // width) + jitter[i, 1]
        (o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]) = _ray(
            px, py, lens[i, 0], lens[i, 1], orthographic, width, height, half, f, r, u, origin, aperture,
            focus)
    return o, d


# The camera's rays draw on the sampler alone: one copy per sampler, whatever the scene.
@kernel(ignores=("materials", "light_techniques", "light_selection", "direction", "combiner", "light_samples",
                 "direction_samples", "learns"))
def lane_camera_rays(sampler, pixel, sample, lens_dimension, orthographic, width, height, half, f, r, u,
                     origin, aperture, focus):
    """Origins and unit directions ``(n, 3)`` float32 of the camera rays of lanes
    ``(pixel[i], sample[i])``: the jitter inside the pixel from the camera's dimensions, a thin
    lens's point (``aperture > 0``) from the pair at ``lens_dimension``."""
    o = np.empty((len(pixel), 3), dtype=np.float32)
    d = np.empty((len(pixel), 3), dtype=np.float32)
    for i in range(len(pixel)):
        p = pixel[i]
        state = dispatch.start(sampler, p, sample[i])
        jitter = dispatch.uniform_pair(sampler, state, dimensions.CAMERA_JITTER)
        lens = (0.5, 0.5)
        if aperture > 0.0:
            lens = dispatch.uniform_pair(sampler, state, lens_dimension)
        (o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]) = _ray(
            (p % width) + jitter[0], (p // width) + jitter[1], lens[0], lens[1], orthographic, width, height,
            half, f, r, u, origin, aperture, focus)
    return o, d


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
