"""Directional lights: a delta light at infinity, irradiance E (W/m^2) arriving along one
direction (Mitsuba's ``directional``: its light travels along to_world's +z, or ``direction``).

The sample is the direction toward the light, wi = -direction, at distance inf (the shadow ray
runs to infinity), with le = E (the irradiance it gives a surface is E |cos theta_i|) and the
``delta`` flag: no other technique can produce it, so it takes MIS weight 1, and its pdf is the
selection probability alone.

===========  =====  ==========================================
column       size   what
===========  =====  ==========================================
TOWARD       3      unit direction toward the light (-direction)
IRRADIANCE   3      irradiance per channel, W/m^2
===========  =====  ==========================================
"""

from __future__ import annotations

import math

import numpy as np

from ...jit import jit
from ...plugins import LightTechnique, register

NAME = "directional"
TOWARD, IRRADIANCE = 0, 3
WIDTH = 6
# Every light sampling: a directional light is sampled one way whatever the others are.
PLUGIN = register(LightTechnique(NAME, code=8, module=__name__, rank=8, dims=0, emitters=("directional",),
                                 light_samplings=("*",), width=WIDTH, delta=True,
                                 doc="the direction toward a light at infinity (a delta light)"))


def rows(emitters) -> np.ndarray:
    """``(D, WIDTH)`` rows of D directional lights (``emitters.DirectionalEmitters``)."""
    return np.concatenate([-np.asarray(emitters.direction), emitters.irradiance], axis=1).reshape(-1, WIDTH)


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """``(wi, inf, E, 1, True)``: toward the light, at infinity."""
    return ((rows[k, TOWARD], rows[k, TOWARD + 1], rows[k, TOWARD + 2]), math.inf,
            (rows[k, IRRADIANCE], rows[k, IRRADIANCE + 1], rows[k, IRRADIANCE + 2]), 1.0, True)


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """No ray finds a directional light: 0."""
    return 0.0
