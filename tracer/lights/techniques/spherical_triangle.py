"""Sampling an emitting triangle by the solid angle it subtends, optionally warped toward the
receiver's cosine.

The direction is uniform over the spherical triangle that the light projects onto the unit
sphere around x (Arvo 1995, ``tracer.lights.spherical_triangle``), p = 1 / Omega, which removes the d^2 and
1 / cos theta_light variation of area sampling (``triangle_area.py`` here). The point is where the
direction meets the triangle's plane.

With ``cos_warp`` the square (u0, u1) is first warped by the bilinear density whose corner
values are |n . w_v| (clamped below at 0.01) for the triangle's vertex directions w_v, placed at
the corners of the square that Arvo's map sends to those vertices (``bilinear.py``). The
product of the two densities approximates p proportional to |cos theta_i|, the receiver's
factor of the integrand; for a diffuse receiver under an unoccluded light that is nearly
zero-variance. pbrt-v4 (Pharr, Jakob and Humphreys, Physically Based Rendering 4th ed., sec.
6.5.4, "Triangle sampling") uses the same warp; its pdf for a given direction needs the
inverse of Arvo's map (``tracer.lights.spherical_triangle.invert``).

Triangles small for their distance from x (``tracer.lights.far_light``) and, as pbrt-v4 does,
triangles that subtend less than ``MIN_SOLID_ANGLE`` sr are sampled by area instead; sample
and pdf make the same choice from x, so the pair stays consistent. Below 3e-4
sr the d^2 / cos theta_light factor varies little over the triangle, so area sampling is
already close to uniform in solid angle and cheaper (no trigonometry; tracer's
spherical-triangle code itself stays accurate far below, to 1e-15 sr). Unlike pbrt-v4,
triangles over 6.22 sr (x close to a large triangle) keep spherical sampling: Arvo's
construction loses only a few digits near a hemisphere (2.5e-13 at 2 pi - 0.02), while area
sampling misses the close part of the light that carries the integral.

The row is ``triangle_area``'s (vertices, normal, emission, 1 / area). This module is the
``spherical_triangle`` technique (``--light-sampling solid-angle``); ``spherical_triangle_cos.py``
the warped one (``solid-angle-cos``), which calls :func:`sample_warped` and :func:`pdf_warped`.
"""

from __future__ import annotations

from ...frame import dot, sub
from ...jit import jit, jit_called, opaque
from ...plugins import LightTechnique, register
from .. import bilinear
from .. import spherical_triangle as arvo
from ..far_light import far
from . import triangle_area
from .triangle_area import EMISSION, NORMAL, V0, V1, V2, WIDTH

NAME = "spherical_triangle"
PLUGIN = register(LightTechnique(NAME, code=4, module=__name__, rank=4, dims=2, emitters=("triangle",),
                                 light_samplings=("solid-angle",), width=WIDTH,
                                 doc="uniform in the spherical triangle (Arvo 1995)"))
MIN_SOLID_ANGLE = 3e-4
rows = triangle_area.rows


@jit
def _vertices(rows, k: int):
    a = (float(rows[k, V0]), float(rows[k, V0 + 1]), float(rows[k, V0 + 2]))
    b = (float(rows[k, V1]), float(rows[k, V1 + 1]), float(rows[k, V1 + 2]))
    c = (float(rows[k, V2]), float(rows[k, V2 + 1]), float(rows[k, V2 + 2]))
    return a, b, c


@jit
def _by_area(x, a, b, c):
    """``(by_area, omega)``: whether the triangle is sampled by area from ``x``, far for its
    size (``tracer.lights.far_light``: radius about the centroid) or subtending under
    ``MIN_SOLID_ANGLE``; omega computed only where the first test does not decide."""
    centre = ((a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0)
    ra, rb, rc = sub(a, centre), sub(b, centre), sub(c, centre)
    if far(x, centre, max(dot(ra, ra), dot(rb, rb), dot(rc, rc))):
        return True, 0.0
    omega = arvo.solid_angle(x, a, b, c)
    return not omega > MIN_SOLID_ANGLE, omega


@jit
def _corner_weights(n, x, a, b, c):
    """The bilinear weights (w00, w10, w01, w11) at the corners of the square, which Arvo's map
    sends to the vertices (b, b, a, c): u1 = 0 is vertex b whatever u0, and u1 = 1 runs from a
    (u0 = 0) to c (u0 = 1)."""
    wa, wb, wc = bilinear.cos_weight(n, x, a), bilinear.cos_weight(n, x, b), bilinear.cos_weight(n, x, c)
    return wb, wb, wa, wc


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The technique's sample (``tracer.lights.techniques``), without the warp."""
    wi, d, le, p = sample_warped(rows, k, x, n, opaque(False), u0, u1)
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """The technique's pdf, without the warp."""
    return pdf_warped(rows, k, x, n, opaque(False), wi, dist)


@jit_called
def sample_warped(rows, k: int, x, n, cos_warp: bool, u0: float, u1: float):
    """A direction toward triangle row ``k`` from ``x`` (normal ``n``): ``(wi, dist, le, pdf)``
    with pdf in solid angle; pdf 0 (and le 0) for the back side or a degenerate triangle."""
    a, b, c = _vertices(rows, k)
    by_area, omega = _by_area(x, a, b, c)
    if by_area:
        return triangle_area.sample_point(rows, k, x, u0, u1)
    warp_pdf = 1.0
    if cos_warp:
        w00, w10, w01, w11 = _corner_weights(n, x, a, b, c)
        u0, u1 = bilinear.sample(u0, u1, w00, w10, w01, w11)
        warp_pdf = bilinear.pdf(u0, u1, w00, w10, w01, w11)
    wi, pdf = arvo.sample(x, a, b, c, u0, u1)
    normal = (float(rows[k, NORMAL]), float(rows[k, NORMAL + 1]), float(rows[k, NORMAL + 2]))
    cos_light = -dot(normal, wi)
    if not (pdf > 0.0 and cos_light > 0.0):  # front side only
        return wi, 0.0, (0.0, 0.0, 0.0), 0.0
    dist = dot(sub(a, x), normal) / -cos_light  # where the direction meets the triangle's plane
    le = (float(rows[k, EMISSION]), float(rows[k, EMISSION + 1]), float(rows[k, EMISSION + 2]))
    return wi, dist, le, pdf * warp_pdf


@jit_called
def pdf_warped(rows, k: int, x, n, cos_warp: bool, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample_warped` picks the direction ``wi`` from ``x`` (normal
    ``n``) that hits triangle row ``k`` at distance ``dist``; 0 from the back side."""
    normal = (float(rows[k, NORMAL]), float(rows[k, NORMAL + 1]), float(rows[k, NORMAL + 2]))
    if not -dot(normal, wi) > 0.0:
        return 0.0
    a, b, c = _vertices(rows, k)
    by_area, omega = _by_area(x, a, b, c)
    if by_area:
        return triangle_area.pdf_point(rows, k, x, wi, dist)
    if not cos_warp:
        return 1.0 / omega
    u0, u1 = arvo.invert(x, a, b, c, wi)
    w00, w10, w01, w11 = _corner_weights(n, x, a, b, c)
    return bilinear.pdf(u0, u1, w00, w10, w01, w11) / omega
