"""Sampling an emitting rectangle (a quad whose edges are perpendicular) by the solid angle it
subtends, optionally warped toward the receiver's cosine: the ``spherical_rectangle`` technique
(``--light-sampling solid-angle``); ``spherical_rectangle_cos.py`` is the warped one, which
calls :func:`sample_warped` and :func:`pdf_warped`.

The point is drawn by Ureña, Fajardo and King's area-preserving map of the square onto the
spherical rectangle (2013, ``tracer.lights.spherical_rectangle``): its direction from x is uniform in
solid angle, p = 1 / Omega. With ``cos_warp`` the square is first warped by the bilinear
density whose corner values are |n . w_c| (clamped below at 0.01) for the rectangle's corner
directions w_c, placed at the corners of the square that the map sends to them; pbrt-v4
(Physically Based Rendering 4th ed., sec. 6.6.4, bilinear patches that are rectangles) does the
same, and its pdf for a given direction needs the inverse map.

Rectangles small for their distance from x (``tracer.lights.far_light``) and, as in pbrt-v4,
rectangles that subtend less than ``MIN_SOLID_ANGLE`` sr are sampled uniformly by area instead
(sample and pdf choose alike). Unlike pbrt-v4, nearly hemispherical ones (over
6.22 sr, a shading point close under a large light) are not: ``spherical_rectangle`` stays
accurate up to 2 pi (tested to 2 pi - 6e-12), while area sampling of such a light is hopeless
(a 2000 x 2000 light 1 above the floor: a 16-spp image mean 64% low with a tiny standard
error, the rare close samples that carry the integral not drawn).

=========  =======  ============================================
column     size     what
=========  =======  ============================================
CORNER     3        the quad's origin (world)
EDGE_U     3        first edge; the rectangle is corner + s edge_u + t edge_v, s, t in [0, 1]
EDGE_V     3        second edge, perpendicular to the first
NORMAL     3        unit front normal (edge_u x edge_v, normalized)
EMISSION   3        radiance leaving the front side
INV_AREA   1        1 / area
=========  =======  ============================================
"""

from __future__ import annotations

import math

import numpy as np

from ...frame import add_scaled, dot, scale, sub
from ...jit import jit, jit_called, opaque
from ...plugins import LightTechnique, register
from .. import bilinear
from .. import spherical_rectangle as urena
from ..far_light import far

NAME = "spherical_rectangle"
CORNER, EDGE_U, EDGE_V, NORMAL, EMISSION, INV_AREA = 0, 3, 6, 9, 12, 15
WIDTH = 16
PLUGIN = register(LightTechnique(NAME, code=6, module=__name__, rank=6, dims=2, emitters=("rectangle",),
                                 light_samplings=("solid-angle",), width=WIDTH,
                                 doc="uniform in the spherical rectangle (Urena et al. 2013)"))
MIN_SOLID_ANGLE = 1e-4


def rows(emitters) -> np.ndarray:
    """``(Q, WIDTH)`` rows of Q rectangles (``emitters.RectangleEmitters``)."""
    return rectangle_rows(emitters.frames, emitters.emission)


def rectangle_rows(frames: np.ndarray, emission: np.ndarray) -> np.ndarray:
    """``(Q, WIDTH)`` rows of Q rectangles: ``frames (Q, 3, 3)`` corner, edge u, edge v, and
    ``emission (Q, 3)``."""
    out = np.zeros((len(frames), WIDTH))
    cross = np.cross(frames[:, 1], frames[:, 2])
    area = np.linalg.norm(cross, axis=1)
    out[:, CORNER:CORNER + 9] = frames.reshape(len(frames), 9)
    out[:, NORMAL:NORMAL + 3] = cross / np.where(area > 0.0, area, 1.0)[:, None]
    out[:, EMISSION:EMISSION + 3] = emission
    out[:, INV_AREA] = 1.0 / np.where(area > 0.0, area, np.inf)
    return out


@jit
def _frame(rows, k: int):
    corner = (float(rows[k, CORNER]), float(rows[k, CORNER + 1]), float(rows[k, CORNER + 2]))
    eu = (float(rows[k, EDGE_U]), float(rows[k, EDGE_U + 1]), float(rows[k, EDGE_U + 2]))
    ev = (float(rows[k, EDGE_V]), float(rows[k, EDGE_V + 1]), float(rows[k, EDGE_V + 2]))
    normal = (float(rows[k, NORMAL]), float(rows[k, NORMAL + 1]), float(rows[k, NORMAL + 2]))
    return corner, eu, ev, normal


@jit
def _by_area(x, corner, eu, ev):
    """Whether the rectangle is sampled by area from ``x``: far for its size
    (``tracer.lights.far_light``), else subtending under ``MIN_SOLID_ANGLE``; returns
    ``(by_area, omega)``, omega computed only where the first test does not decide."""
    centre = add_scaled(add_scaled(corner, 0.5, eu), 0.5, ev)
    if far(x, centre, 0.25 * (dot(eu, eu) + dot(ev, ev))):
        return True, 0.0
    omega = urena.solid_angle(x, corner, eu, ev)
    return not omega > MIN_SOLID_ANGLE, omega


@jit
def _corner_weights(n, x, corner, eu, ev):
    """The bilinear weights (w00, w10, w01, w11): the square's corner (s, t) is the rectangle's
    corner + s edge_u + t edge_v."""
    return (bilinear.cos_weight(n, x, corner), bilinear.cos_weight(n, x, add_scaled(corner, 1.0, eu)),
            bilinear.cos_weight(n, x, add_scaled(corner, 1.0, ev)),
            bilinear.cos_weight(n, x, add_scaled(add_scaled(corner, 1.0, eu), 1.0, ev)))


@jit
def _toward(rows, k: int, x, point, normal, pdf: float):
    """``(wi, dist, le, pdf)`` for the sampled ``point``; 0 from the back side."""
    v = sub(point, x)
    d = math.sqrt(dot(v, v))
    if not (d > 0.0 and pdf > 0.0):
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0
    wi = scale(1.0 / d, v)
    if not -dot(normal, wi) > 0.0:
        return wi, d, (0.0, 0.0, 0.0), 0.0
    le = (float(rows[k, EMISSION]), float(rows[k, EMISSION + 1]), float(rows[k, EMISSION + 2]))
    return wi, d, le, pdf


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
    """A point on rectangle row ``k`` seen from ``x`` (normal ``n``): ``(wi, dist, le, pdf)``
    with pdf in solid angle; 0 for the back side."""
    corner, eu, ev, normal = _frame(rows, k)
    by_area, omega = _by_area(x, corner, eu, ev)
    if by_area:
        point = add_scaled(add_scaled(corner, u0, eu), u1, ev)
        wi, d, le, _ = _toward(rows, k, x, point, normal, 1.0)
        cos_light = -dot(normal, wi)
        return wi, d, le, (rows[k, INV_AREA] * d * d / cos_light if cos_light > 0.0 and d > 0.0 else 0.0)
    warp_pdf = 1.0
    if cos_warp:
        w00, w10, w01, w11 = _corner_weights(n, x, corner, eu, ev)
        u0, u1 = bilinear.sample(u0, u1, w00, w10, w01, w11)
        warp_pdf = bilinear.pdf(u0, u1, w00, w10, w01, w11)
    point, pdf = urena.sample_given(x, corner, eu, ev, omega, u0, u1, False)
    return _toward(rows, k, x, point, normal, pdf * warp_pdf)


@jit_called
def pdf_warped(rows, k: int, x, n, cos_warp: bool, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample_warped` picks the direction ``wi`` from ``x`` (normal
    ``n``) that hits rectangle row ``k`` at distance ``dist``; 0 from the back side."""
    corner, eu, ev, normal = _frame(rows, k)
    cos_light = -dot(normal, wi)
    if not cos_light > 0.0:
        return 0.0
    by_area, omega = _by_area(x, corner, eu, ev)
    if by_area:
        return rows[k, INV_AREA] * dist * dist / cos_light
    if not cos_warp:
        return 1.0 / omega
    u0, u1 = urena.invert(x, corner, eu, ev, add_scaled(x, dist, wi))
    w00, w10, w01, w11 = _corner_weights(n, x, corner, eu, ev)
    return bilinear.pdf(u0, u1, w00, w10, w01, w11) / omega
