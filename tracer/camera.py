"""The pinhole camera of the scene contract and its primary rays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import samplers
from .jit import jit
from .kernels import UNBOUND, kernel
from .samplers import dimensions


@dataclass
class Camera:
    """Pinhole camera. Vectors are (3,) float64; ``fov`` is the vertical field of view in degrees.
    ``mirrored``: the image's x axis runs along -r instead of r (a camera whose transform has a
    negative determinant, as Mitsuba scenes with ``<scale x="-1"/>`` have)."""

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    width: int
    height: int
    mirrored: bool = False
    _origins: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

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
    def screen(self) -> tuple:
        """What the ray kernels need: width, height, tan(fov / 2), f, r, u."""
        return (self.width, self.height, float(np.tan(np.radians(self.fov) * 0.5))) + self.basis

    def rays(self, pixel: np.ndarray, jitter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through film positions (pixel x + jitter x, pixel y + jitter y).

        pixel : (n,) int64 row-major pixel index (row 0 at the top).
        jitter : (n, 2) in [0, 1)^2, the position inside the pixel (box filter).
        Returns origins (n, 3) and unit directions (n, 3), float64.
        """
        d = _directions(np.asarray(pixel), np.asarray(jitter, dtype=np.float64), *self.screen)
        return np.broadcast_to(self.origin, d.shape), d

    def lane_rays(self, directions, sampler: samplers.SamplerParams, pixel: np.ndarray,
                  sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera rays of lanes ``(pixel[i], sample[i])`` (``(n,)`` int64 each): the jitter
        inside the pixel is the sampler's camera dimensions (``samplers.dimensions``), drawn by
        ``directions``, the render's build of :func:`lane_directions` (``tracer.kernels``).
        Returns origins and unit directions ``(n, 3)``, float32 as Embree takes them."""
        d = directions(sampler, pixel, sample, *self.screen)
        # One contiguous array of the origin (Embree wants contiguous rows), grown to the
        # largest batch and shared by the render threads: each keeps its own reference, so a
        # race between two of them costs at most an extra allocation.
        origins = self._origins
        # Recomputed from the current fields every time (a notebook may move the camera between
        # renders); only the tiled origin is kept, and checked against the current origin.
        here = self.origin.astype(np.float32)
        if origins is None or len(origins) < len(d) or not np.array_equal(origins[:1], here[None]):
            origins = self._origins = np.tile(here, (len(d), 1))
        return origins[: len(d)], d


@jit
def _direction(px: float, py: float, width, height, tan_half, f, r, u):
    """Unit direction through film position (px, py) in pixels; screen x spans
    [-aspect, aspect] tan_half, y spans [-1, 1] tan_half, row 0 at the top."""
    sx = (2.0 * px / width - 1.0) * tan_half * (width / height)
    sy = (1.0 - 2.0 * py / height) * tan_half
    x, y, z = f[0] + sx * r[0] + sy * u[0], f[1] + sx * r[1] + sy * u[1], f[2] + sx * r[2] + sy * u[2]
    inv = 1.0 / np.sqrt(x * x + y * y + z * z)
    return x * inv, y * inv, z * inv


@jit
def _directions(pixel, jitter, width, height, tan_half, f, r, u) -> np.ndarray:
    d = np.empty((len(pixel), 3))
    for i in range(len(pixel)):
        px, py = (pixel[i] % width) + jitter[i, 0], (pixel[i] // width) + jitter[i, 1]
        d[i, 0], d[i, 1], d[i, 2] = _direction(px, py, width, height, tan_half, f, r, u)
    return d


# The camera's jitter draws on the sampler alone: one copy per sampler, whatever the scene.
@kernel(ignores=("materials", "light_techniques", "light_selection", "direction", "combiner", "light_samples",
                 "direction_samples", "learns"))
def lane_directions(sampler, pixel, sample, width, height, tan_half, f, r, u) -> np.ndarray:
    """``(n, 3)`` float32 unit directions of the camera rays of lanes ``(pixel[i], sample[i])``."""
    d = np.empty((len(pixel), 3), dtype=np.float32)
    for i in range(len(pixel)):
        p = pixel[i]
        state = dispatch.start(sampler, p, sample[i])
        jitter = dispatch.uniform_pair(sampler, state, dimensions.CAMERA_JITTER)
        d[i, 0], d[i, 1], d[i, 2] = _direction((p % width) + jitter[0], (p // width) + jitter[1],
                                               width, height, tan_half, f, r, u)
    return d


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
