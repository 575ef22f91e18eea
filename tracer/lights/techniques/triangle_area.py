"""Area sampling of an emitting triangle: a point uniform by area, the pdf in solid angle.

For a point y uniform on triangle t seen from x, p_w = d^2 / (area |cos theta_light|): the area
density 1 / area times the Jacobian d^2 / |cos theta_light| of the change from area to solid
angle (pbrt-v4, "Sampling Shapes"); emitters shine from their front side only. The selection
probability is not included here (``tracer.lights`` multiplies it in). A plug-in
(``tracer.lights.techniques``): emitting triangles under ``--light-sampling area``.

A candidate's row in the light table (float32, as the scene holds vertices and emission, so
that sampled points lie on the very triangles Embree intersects):

=========  =======  ============================================
column     size     what
=========  =======  ============================================
V0         3        first vertex (world)
V1, V2     3, 3     the other vertices
NORMAL     3        unit front normal
EMISSION   3        radiance leaving the front side
INV_AREA   1        1 / area
=========  =======  ============================================
"""

from __future__ import annotations

import math

import numpy as np

from ... import warp
from ...jit import jit
from ...plugins import LightTechnique, register

NAME = "triangle_area"
V0, V1, V2, NORMAL, EMISSION, INV_AREA = 0, 3, 6, 9, 12, 15
WIDTH = 16
PLUGIN = register(LightTechnique(NAME, code=0, module=__name__, rank=0, dims=2, emitters=("triangle",),
                                 light_samplings=("area",), width=WIDTH, doc="a point uniform by area"))


def rows(emitters) -> np.ndarray:
    """``(T, WIDTH)`` rows of T triangles (``emitters.TriangleEmitters``)."""
    return triangle_rows(emitters.corners, emitters.normal, emitters.emission, emitters.area)


def triangle_rows(corners: np.ndarray, normal: np.ndarray, emission: np.ndarray,
                  area: np.ndarray) -> np.ndarray:
    """``(T, WIDTH)`` rows of T triangles: corners (T, 3, 3), normal (T, 3), emission (T, 3),
    area (T,) > 0."""
    out = np.zeros((len(area), WIDTH))
    out[:, V0:V0 + 9] = corners.reshape(len(area), 9)
    out[:, NORMAL:NORMAL + 3] = normal
    out[:, EMISSION:EMISSION + 3] = emission
    out[:, INV_AREA] = 1.0 / area
    return out


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The technique's sample (``tracer.lights.techniques``): :func:`sample_point`, not a delta."""
    wi, d, le, p = sample_point(rows, k, x, u0, u1)
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """The technique's pdf (``tracer.lights.techniques``): :func:`pdf_point`."""
    return pdf_point(rows, k, x, wi, dist)


@jit
def sample_point(rows, k: int, x, u0: float, u1: float):
    """A point on triangle row ``k`` seen from ``x``: ``(wi, dist, le, pdf)`` with le the
    radiance arriving along wi and pdf in solid angle; pdf 0 (and le 0) if the point is on the
    back side or at x."""
    b1, b2 = warp.triangle_barycentric(u0, u1)
    v0 = (float(rows[k, V0]), float(rows[k, V0 + 1]), float(rows[k, V0 + 2]))
    lx = v0[0] + b1 * (rows[k, V1] - v0[0]) + b2 * (rows[k, V2] - v0[0]) - x[0]
    ly = v0[1] + b1 * (rows[k, V1 + 1] - v0[1]) + b2 * (rows[k, V2 + 1] - v0[1]) - x[1]
    lz = v0[2] + b1 * (rows[k, V1 + 2] - v0[2]) + b2 * (rows[k, V2 + 2] - v0[2]) - x[2]
    d2 = lx * lx + ly * ly + lz * lz
    d = math.sqrt(d2)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0
    inv_d = 1.0 / d
    wi = (lx * inv_d, ly * inv_d, lz * inv_d)
    cos_light = -(rows[k, NORMAL] * wi[0] + rows[k, NORMAL + 1] * wi[1] + rows[k, NORMAL + 2] * wi[2])
    if cos_light <= 0.0:  # front side only
        return wi, d, (0.0, 0.0, 0.0), 0.0
    le = (float(rows[k, EMISSION]), float(rows[k, EMISSION + 1]), float(rows[k, EMISSION + 2]))
    return wi, d, le, rows[k, INV_AREA] * d2 / cos_light


@jit
def pdf_point(rows, k: int, x, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample_point` picks the direction ``wi`` from ``x`` that hits
    triangle row ``k`` at distance ``dist``; 0 from the back side."""
    cos_light = -(rows[k, NORMAL] * wi[0] + rows[k, NORMAL + 1] * wi[1] + rows[k, NORMAL + 2] * wi[2])
    if cos_light <= 0.0:
        return 0.0
    return rows[k, INV_AREA] * dist * dist / cos_light
