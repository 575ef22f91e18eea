"""Sampling an analytic sphere light by area (and the rows and helpers ``sphere_cone`` shares).

A sphere emits ``EMISSION`` from its outside. Seen from a point x at distance d_c from the
centre, it covers the cone of half-angle theta_max with sin(theta_max) = r / d_c.

- **Area** (``sample_area``): a point uniform on the whole sphere, p_A = 1 / (4 pi r^2), in
  solid angle p = d^2 / (4 pi r^2 |cos theta_light|). Points on the far half are not visible
  from x and give 0: about half the samples are wasted, and near the silhouette cos theta_light
  -> 0 makes 1 / p blow up. The baseline.
- **Cone** (``sample_cone``): a direction uniform in the subtended cone, p = 1 / (2 pi (1 -
  cos theta_max)), then the point where it meets the sphere (Shirley and Wang 1992's sphere
  cone sampling as pbrt-v4 formulates it, "Sampling Spheres", Physically Based Rendering 4th
  ed., sec. 6.2.4: cos theta uniform in [cos theta_max, 1], and the angle alpha at the centre
  between the sampled point and the direction to x from the law of cosines,
  cos alpha = sin^2 theta / sin theta_max + cos theta sqrt(1 - sin^2 theta / sin^2 theta_max)).
  For tiny or distant spheres 1 - cos theta_max cancels to nothing in float64; pbrt-v4 switches
  to the Taylor term sin^2 theta_max / 2 below sin^2 theta_max = sin^2 1.5 deg, which is off by
  a relative sin^2 theta_max / 4 (4e-5 at a sphere 1/40 of its distance across: measured as a
  4e-5 error in the pdf's integral). Here 1 - cos theta_max = sin^2 theta_max / (1 + cos
  theta_max) and, for t = 1 - cos theta, sin^2 theta = t (2 - t): exact identities with no
  cancellation at any size, so no branch is needed. From inside the sphere the cone is the
  whole sphere of directions: area sampling is used there (every point is then seen from the
  back and gives 0, as the sphere emits outward only).

This module is the ``sphere_area`` technique (``--light-sampling area``); ``sphere_cone.py`` the
cone. The selection probability is multiplied in by ``tracer.lights``. The pdfs of a direction
that hits the sphere are pure functions of (x, wi, dist), so MIS weights of BSDF samples match.

=========  =====  ================================
column     size   what
=========  =====  ================================
CENTER     3      centre (world)
RADIUS     1      radius
EMISSION   3      radiance leaving the outside
=========  =====  ================================
"""

from __future__ import annotations

import math

import numpy as np

from ...frame import add_scaled, dot, scale, sub
from ...jit import jit
from ...plugins import LightTechnique, register

NAME = "sphere_area"
CENTER, RADIUS, EMISSION = 0, 3, 4
WIDTH = 7
PLUGIN = register(LightTechnique(NAME, code=2, module=__name__, rank=2, dims=2, emitters=("sphere",),
                                 light_samplings=("area",), width=WIDTH, doc="a point uniform on the sphere"))


def rows(emitters) -> np.ndarray:
    """``(S, WIDTH)`` rows of S spheres (``emitters.SphereEmitters``)."""
    return sphere_rows(emitters.spheres, emitters.emission)


def sphere_rows(spheres: np.ndarray, emission: np.ndarray) -> np.ndarray:
    """``(S, WIDTH)`` rows of S spheres: ``spheres (S, 4)`` centre and radius, ``emission (S, 3)``."""
    out = np.zeros((len(spheres), WIDTH))
    out[:, CENTER:CENTER + 3] = spheres[:, :3]
    out[:, RADIUS] = spheres[:, 3]
    out[:, EMISSION:EMISSION + 3] = emission
    return out


@jit
def _center_radius(rows, k: int):
    return (float(rows[k, CENTER]), float(rows[k, CENTER + 1]), float(rows[k, CENTER + 2])), \
        float(rows[k, RADIUS])


@jit
def _emission(rows, k: int):
    return (float(rows[k, EMISSION]), float(rows[k, EMISSION + 1]), float(rows[k, EMISSION + 2]))


@jit
def _toward_point(rows, k: int, x, normal, pdf_area_to_solid: bool):
    """The sample for the sphere point with outward unit ``normal``: ``(wi, dist, le, pdf)``,
    with pdf the area pdf converted to solid angle if ``pdf_area_to_solid``, else 1 (the
    caller's)."""
    center, radius = _center_radius(rows, k)
    v = sub(add_scaled(center, radius, normal), x)
    d2 = dot(v, v)
    d = math.sqrt(d2)
    if not d > 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0
    wi = scale(1.0 / d, v)
    cos_light = -dot(normal, wi)
    if not cos_light > 0.0:  # the far side, not visible from x (or x inside the sphere)
        return wi, d, (0.0, 0.0, 0.0), 0.0
    pdf = d2 / (4.0 * math.pi * radius * radius * cos_light) if pdf_area_to_solid else 1.0
    return wi, d, _emission(rows, k), pdf


@jit
def sample_area(rows, k: int, x, u0: float, u1: float):
    """A point uniform by area on sphere ``k``: ``(wi, dist, le, pdf)`` in solid angle."""
    z = 1.0 - 2.0 * u0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u1
    return _toward_point(rows, k, x, (r * math.cos(phi), r * math.sin(phi), z), True)


@jit
def pdf_area(rows, k: int, x, wi, dist: float) -> float:
    """Solid-angle pdf of :func:`sample_area` for the direction ``wi`` from ``x`` that hits the
    sphere at distance ``dist``; 0 if the hit is seen from the inside."""
    center, radius = _center_radius(rows, k)
    n = sub(add_scaled(x, dist, wi), center)
    cos_light = -dot(n, wi) / radius
    if not cos_light > 0.0:
        return 0.0
    return dist * dist / (4.0 * math.pi * radius * radius * cos_light)


@jit
def sample(rows, k: int, x, n, u0: float, u1: float):
    """The technique's sample (``tracer.lights.techniques``): :func:`sample_area`."""
    wi, d, le, p = sample_area(rows, k, x, u0, u1)
    return wi, d, le, p, False


@jit
def pdf(rows, k: int, x, n, wi, dist: float) -> float:
    """The technique's pdf: :func:`pdf_area`."""
    return pdf_area(rows, k, x, wi, dist)
