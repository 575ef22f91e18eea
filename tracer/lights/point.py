"""Point lights: a delta light of radiant intensity I (W/sr) at a position.

The sample is the direction to the light, with le = I / d^2 (the irradiance it gives is
le |cos theta_i|) and the ``delta`` flag: no other technique can produce it, so it takes MIS
weight 1, and its pdf is the selection probability alone.

=========  =====  ==================================
column     size   what
=========  =====  ==================================
POSITION   3      world position
INTENSITY  3      radiant intensity per channel, W/sr
=========  =====  ==================================
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import jit

NAME = "point"
POSITION, INTENSITY = 0, 3
WIDTH = 6


def rows(position: np.ndarray, intensity: np.ndarray) -> np.ndarray:
    """``(P, WIDTH)`` rows of P point lights: position (P, 3), intensity (P, 3)."""
    return np.concatenate([position, intensity], axis=1).reshape(-1, WIDTH)


@jit
def sample(rows, k: int, x):
    """The direction from ``x`` to point light row ``k``: ``(wi, dist, le)``, le = I / d^2;
    le 0 if the light is at x."""
    lx, ly, lz = rows[k, POSITION] - x[0], rows[k, POSITION + 1] - x[1], rows[k, POSITION + 2] - x[2]
    d = math.sqrt(lx * lx + ly * ly + lz * lz)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0)
    inv_d = 1.0 / d
    falloff = inv_d * inv_d
    le = (rows[k, INTENSITY] * falloff, rows[k, INTENSITY + 1] * falloff, rows[k, INTENSITY + 2] * falloff)
    return (lx * inv_d, ly * inv_d, lz * inv_d), d, le
