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

from ...jit import jit
from ...plugins import LightTechnique, register

NAME = "point"
POSITION, INTENSITY = 0, 3
WIDTH = 6
# Every light sampling: a point light is sampled one way whatever the others are.
PLUGIN = register(LightTechnique(NAME, code=1, module=__name__, rank=1, dims=0, emitters=("point",),
                                 light_samplings=("*",), width=WIDTH, delta=True,
                                 doc="the direction to the point (a delta light)"))


def rows(emitters) -> np.ndarray:
    """``(P, WIDTH)`` rows of P point lights (``emitters.PointEmitters``: position, intensity)."""
    return np.concatenate([emitters.position, emitters.intensity], axis=1).reshape(-1, WIDTH)


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The direction from ``x`` to point light row ``k``: ``(wi, dist, le, 1, True)``, le = I /
    d^2; le and pdf 0 if the light is at x."""
    lx, ly, lz = rows[k, POSITION] - x[0], rows[k, POSITION + 1] - x[1], rows[k, POSITION + 2] - x[2]
    d = math.sqrt(lx * lx + ly * ly + lz * lz)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, True
    inv_d = 1.0 / d
    falloff = inv_d * inv_d
    le = (rows[k, INTENSITY] * falloff, rows[k, INTENSITY + 1] * falloff, rows[k, INTENSITY + 2] * falloff)
    return (lx * inv_d, ly * inv_d, lz * inv_d), d, le, 1.0, True


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """No ray finds a point light: 0."""
    return 0.0
