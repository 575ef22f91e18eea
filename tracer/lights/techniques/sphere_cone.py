"""Sampling an analytic sphere light by the cone of directions it subtends (``sphere_area.py``
says why, and holds the rows and the helpers this shares).

A direction uniform in the cone of half-angle theta_max, sin(theta_max) = r / d_c, p = 1 / (2 pi
(1 - cos theta_max)), then the point where it meets the sphere; from inside the sphere, area
sampling. A plug-in (``tracer.lights.techniques``): spheres under ``--light-sampling
solid-angle`` and ``solid-angle-cos`` (the cosine warp does not apply to spheres, as in pbrt-v4).
"""

from __future__ import annotations

import math

from ...frame import basis, dot, scale, sub
from ...jit import jit
from ...plugins import LightTechnique, register
from . import sphere_area
from .sphere_area import WIDTH, _center_radius, _toward_point, pdf_area, sample_area

NAME = "sphere_cone"
PLUGIN = register(LightTechnique(NAME, code=3, module=__name__, rank=3, dims=2, emitters=("sphere",),
                                 light_samplings=("solid-angle", "solid-angle-cos"), width=WIDTH,
                                 doc="a direction uniform in the subtended cone"))


def rows(emitters):
    """The rows of ``sphere_area`` (centre, radius, emission)."""
    return sphere_area.rows(emitters)


@jit
def _cone(rows, k: int, x):
    """``(inside, sin2_max, one_minus_cos_max, axis, dist_center)`` of the cone sphere ``k``
    subtends from ``x``; axis is the unit direction to the centre."""
    center, radius = _center_radius(rows, k)
    to_center = sub(center, x)
    dc = math.sqrt(dot(to_center, to_center))
    if not dc > radius:
        return True, 1.0, 2.0, (0.0, 0.0, 1.0), dc
    sin_max = radius / dc
    sin2_max = sin_max * sin_max
    one_minus_cos_max = sin2_max / (1.0 + math.sqrt(max(0.0, 1.0 - sin2_max)))
    return False, sin2_max, one_minus_cos_max, scale(1.0 / dc, to_center), dc


@jit
def sample_cone(rows, k: int, x, u0: float, u1: float):
    """A direction uniform in the cone sphere ``k`` subtends from ``x`` (area sampling from
    inside): ``(wi, dist, le, pdf)``."""
    inside, sin2_max, one_minus_cos_max, axis, _ = _cone(rows, k, x)
    if inside:
        return sample_area(rows, k, x, u0, u1)
    one_minus_cos = one_minus_cos_max * u0  # cos theta uniform in [cos theta_max, 1]
    cos = 1.0 - one_minus_cos
    sin2 = min(one_minus_cos * (2.0 - one_minus_cos), sin2_max)
    # alpha: the angle at the centre between the sampled point and the direction back to x.
    sin_max = math.sqrt(sin2_max)
    cos_alpha = sin2 / sin_max + cos * math.sqrt(max(0.0, 1.0 - sin2 / sin2_max))
    sin_alpha = math.sqrt(max(0.0, 1.0 - cos_alpha * cos_alpha))
    phi = 2.0 * math.pi * u1
    s, t = basis(axis)
    a, b = sin_alpha * math.cos(phi), sin_alpha * math.sin(phi)
    normal = (a * s[0] + b * t[0] - cos_alpha * axis[0], a * s[1] + b * t[1] - cos_alpha * axis[1],
              a * s[2] + b * t[2] - cos_alpha * axis[2])
    wi, dist, le, pdf = _toward_point(rows, k, x, normal, False)
    # Points at the very silhouette can round to the far side; the density is the cone's.
    return wi, dist, le, (1.0 / (2.0 * math.pi * one_minus_cos_max) if pdf > 0.0 else 0.0)


@jit
def pdf_cone(rows, k: int, x, wi, dist: float) -> float:
    """Solid-angle pdf of :func:`sample_cone` for the direction ``wi`` from ``x`` that hits the
    sphere at distance ``dist``: constant over the cone (area sampling's from inside)."""
    inside, _, one_minus_cos_max, _, _ = _cone(rows, k, x)
    if inside:
        return pdf_area(rows, k, x, wi, dist)
    return 1.0 / (2.0 * math.pi * one_minus_cos_max)


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The technique's sample (``tracer.lights.techniques``): :func:`sample_cone`."""
    wi, d, le, p = sample_cone(rows, k, x, u0, u1)
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """The technique's pdf: :func:`pdf_cone`."""
    return pdf_cone(rows, k, x, wi, dist)
