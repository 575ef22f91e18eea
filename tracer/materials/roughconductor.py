"""``roughconductor``: a microfacet metal, GGX or Beckmann, with a conductor's Fresnel term.

f = reflectance F(wo.h; eta + i k) D(h) G1(wo) G1(wi) / (4 cos_o cos_i), separable Smith
masking, ``alpha`` used as given (not squared), sampled by the distribution's visible normals
(``microfacet``); the sample weight is reflectance F G1(wi). With the defaults eta = 0, k = 1
the Fresnel term is 1 (the first version's Fresnel-free GGX reflector, which scenes written
before eta, k and distribution existed still describe, with the same digest).

=============  =====  ========================================================
parameter      size   meaning
=============  =====  ========================================================
reflectance    3      scale per channel, in [0, 1] (Mitsuba's ``specular_reflectance``)
alpha          1      roughness, in (0, 10]
eta, k         3, 3   complex index of refraction per channel (``conductor``)
distribution   1      ``ggx`` (default) or ``beckmann``
alpha_v        1      roughness along the shading frame's t axis; 0 (default):
                      isotropic, ``alpha`` both ways. Otherwise ``alpha`` is
                      the roughness along s, Mitsuba's ``alpha_u``
=============  =====  ========================================================

Anisotropic roughness (``alpha_v`` > 0) depends on which way the surface's tangent points: the
material is then shaded in Mitsuba's frame, s along dp/du (``oriented``; the kernels build the
frame as ``tracer.textures.shading_frames`` does for normal maps) and evaluated by the
anisotropic functions of ``microfacet``. An isotropic row takes the isotropic functions, so
its values keep their bits.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..jit import jit
from ..plugins import register
from . import microfacet
from .base import GLOSSY, MaterialType, Param, mean3, rgb
from .conductor import ETA_PARAM, K_PARAM, fresnel_rgb

CODE = 2  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name=
    "roughconductor", code=CODE, lobes=GLOSSY, doc="microfacet metal (GGX or Beckmann), conductor Fresnel",
    params=(Param("reflectance", 3, lo=0.0, hi=1.0, texture=True, doc="scale per channel"),
            Param("alpha", 1, lo=microfacet.MIN_ALPHA, hi=microfacet.MAX_ALPHA,
                  texture=True, doc="roughness, used as given"),
            replace(ETA_PARAM, late=True), replace(K_PARAM, late=True),
            Param("distribution", 1, default="ggx", choices=microfacet.DISTRIBUTIONS, late=True,
                  doc="microfacet distribution"),
            Param("alpha_v", 1, lo=0.0, hi=microfacet.MAX_ALPHA, default=0.0, texture=True, late=True,
                  doc="roughness along the tangent t (alpha is then along s, dp/du); 0: isotropic")),
    oriented=lambda values: float(values["alpha_v"]) > 0.0))
REFLECTANCE, ALPHA, ETA, K = (TYPE.column(n) for n in ("reflectance", "alpha", "eta", "k"))
DISTRIBUTION, ALPHA_V = TYPE.column("distribution"), TYPE.column("alpha_v")


@jit
def _alpha_v(params, row) -> float:
    """The row's alpha_v, 0 for an isotropic row, else at least MIN_ALPHA (a texture's lookup
    is clamped into [0, MAX_ALPHA], the parameter's range, and may be smaller)."""
    alpha_v = params[row, ALPHA_V]
    return max(alpha_v, microfacet.MIN_ALPHA) if alpha_v > 0.0 else 0.0


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf): reflectance x Fresnel x the microfacet reflector, and the visible-normal pdf."""
    alpha, alpha_v, distribution = params[row, ALPHA], _alpha_v(params, row), int(params[row, DISTRIBUTION])
    if alpha_v > 0.0:
        value, p = microfacet.anisotropic_value_and_pdf(wo, wi, alpha, alpha_v, distribution)
    else:
        value, p = microfacet.reflection_value_and_pdf(wo, wi, alpha, distribution)
    if not value > 0.0:
        return (0.0, 0.0, 0.0), p
    f = fresnel_rgb(params, row, ETA, K, microfacet.wo_dot_half(wo, wi))
    r, g, b = rgb(params, row, REFLECTANCE)
    return (r * f[0] * value, g * f[1] * value, b * f[2] * value), p


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """wi = reflect(wo, h) with h from the visible normals; weight = reflectance F G1(wi)."""
    alpha, alpha_v, distribution = params[row, ALPHA], _alpha_v(params, row), int(params[row, DISTRIBUTION])
    if alpha_v > 0.0:
        wi, p, g1 = microfacet.sample_anisotropic_reflection(wo, alpha, alpha_v, distribution, u0, u1)
    else:
        wi, p, g1 = microfacet.sample_reflection(wo, alpha, distribution, u0, u1)
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    f = fresnel_rgb(params, row, ETA, K, microfacet.wo_dot_half(wo, wi))
    r, g, b = rgb(params, row, REFLECTANCE)
    return wi, (r * f[0] * g1, g * f[1] * g1, b * f[2] * g1), p, GLOSSY


@jit
def lobe(params, row, wo):
    """The lobe proxy of product sampling (``tracer.lights.environment_product``): glossy about
    the mirror direction, of the geometric mean of the two roughnesses, weighted by the mean
    reflectance (the Fresnel term left out: it changes the lobe's size, not its shape)."""
    alpha, alpha_v = params[row, ALPHA], _alpha_v(params, row)
    if alpha_v > 0.0:
        alpha = math.sqrt(alpha * alpha_v)
    return 0.0, mean3(params, row, REFLECTANCE), 0.0, alpha
