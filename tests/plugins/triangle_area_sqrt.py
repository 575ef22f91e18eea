"""A light technique plug-in: an emitting triangle sampled uniformly by area, with the classic
square-root map of the unit square to barycentrics (Osada et al. 2002, "Shape distributions",
eq. 1) instead of Heitz's (``triangle_area``): the same density, another map. It serves a light
sampling of its own name, ``area-sqrt``, for triangles (and so for quads, taken as two)."""

from __future__ import annotations

import math

from tracer.jit import jit
from tracer.lights.techniques import triangle_area
from tracer.plugins import LightTechnique, register

NAME = "triangle_area_sqrt"
PLUGIN = register(LightTechnique(NAME, code=101, module=__name__, dims=2, emitters=("triangle",),
                                 light_samplings=("area-sqrt",), width=triangle_area.WIDTH,
                                 doc="uniform by area, square-root barycentrics"))
rows = triangle_area.rows  # the same columns: vertices, normal, emission, 1 / area
V0, V1, V2, NORMAL, EMISSION, INV_AREA = (triangle_area.V0, triangle_area.V1, triangle_area.V2,
                                          triangle_area.NORMAL, triangle_area.EMISSION,
                                          triangle_area.INV_AREA)


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    s = math.sqrt(u0)
    b1, b2 = s * (1.0 - u1), s * u1  # the point v0 + b1 (v1 - v0) + b2 (v2 - v0)
    lx = rows[k, V0] + b1 * (rows[k, V1] - rows[k, V0]) + b2 * (rows[k, V2] - rows[k, V0]) - x[0]
    ly = (rows[k, V0 + 1] + b1 * (rows[k, V1 + 1] - rows[k, V0 + 1])
          + b2 * (rows[k, V2 + 1] - rows[k, V0 + 1]) - x[1])
    lz = (rows[k, V0 + 2] + b1 * (rows[k, V1 + 2] - rows[k, V0 + 2])
          + b2 * (rows[k, V2 + 2] - rows[k, V0 + 2]) - x[2])
    d2 = lx * lx + ly * ly + lz * lz
    d = math.sqrt(d2)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False
    wi = (lx / d, ly / d, lz / d)
    cos_light = -(rows[k, NORMAL] * wi[0] + rows[k, NORMAL + 1] * wi[1] + rows[k, NORMAL + 2] * wi[2])
    if cos_light <= 0.0:
        return wi, d, (0.0, 0.0, 0.0), 0.0, False
    le = (float(rows[k, EMISSION]), float(rows[k, EMISSION + 1]), float(rows[k, EMISSION + 2]))
    return wi, d, le, rows[k, INV_AREA] * d2 / cos_light, False


pdf = triangle_area.pdf  # the density is area sampling's: the map does not change it
