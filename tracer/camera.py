"""The pinhole camera of the scene contract and its primary rays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .jit import jit


@dataclass
class Camera:
    """Pinhole camera. Vectors are (3,) float64; ``fov`` is the vertical field of view in degrees."""

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    width: int
    height: int

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f, r, u): forward, right and up unit vectors, ``r = f x up``, ``u = r x f``."""
        f = self.target - self.origin
        f = f / np.linalg.norm(f)
        r = np.cross(f, self.up)
        r = r / np.linalg.norm(r)
        return f, r, np.cross(r, f)

    def rays(self, pixel: np.ndarray, jitter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through film positions (pixel x + jitter x, pixel y + jitter y).

        pixel : (n,) int64 row-major pixel index (row 0 at the top).
        jitter : (n, 2) in [0, 1)^2, the position inside the pixel (box filter).
        Returns origins (n, 3) and unit directions (n, 3), float64.
        """
        f, r, u = self.basis
        tan_half = float(np.tan(np.radians(self.fov) * 0.5))
        d = _directions(np.asarray(pixel), np.asarray(jitter, dtype=np.float64), self.width, self.height,
                        tan_half, f, r, u)
        return np.broadcast_to(self.origin, d.shape), d


@jit
def _directions(pixel, jitter, width, height, tan_half, f, r, u) -> np.ndarray:
    """Unit directions through film positions; screen x spans [-aspect, aspect] tan_half."""
    d = np.empty((len(pixel), 3))
    aspect = width / height
    for i in range(len(pixel)):
        sx = (2.0 * ((pixel[i] % width) + jitter[i, 0]) / width - 1.0) * tan_half * aspect
        sy = (1.0 - 2.0 * ((pixel[i] // width) + jitter[i, 1]) / height) * tan_half
        x, y, z = f[0] + sx * r[0] + sy * u[0], f[1] + sx * r[1] + sy * u[1], f[2] + sx * r[2] + sy * u[2]
        inv = 1.0 / np.sqrt(x * x + y * y + z * z)
        d[i, 0], d[i, 1], d[i, 2] = x * inv, y * inv, z * inv
    return d
