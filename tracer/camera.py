"""The pinhole camera of the scene contract and its primary rays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
        px = (pixel % self.width) + jitter[:, 0]
        py = (pixel // self.width) + jitter[:, 1]
        tan_half = np.tan(np.radians(self.fov) * 0.5)
        sx = (2.0 * px / self.width - 1.0) * tan_half * (self.width / self.height)
        sy = (1.0 - 2.0 * py / self.height) * tan_half
        d = f + sx[:, None] * r + sy[:, None] * u
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.origin, d.shape), d
