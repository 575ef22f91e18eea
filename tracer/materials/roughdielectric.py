"""``roughdielectric``: a rough interface between two indices, Walter et al.'s microfacet model
("Microfacet models for refraction through rough surfaces", EGSR 2007) as Mitsuba 3 writes it
(src/bsdfs/roughdielectric.cpp), GGX or Beckmann, isotropic.

Both lobes share one microfacet normal m, drawn from the normals visible from wo (Heitz 2018;
``microfacet``). With eta the relative index across the interface (the other side's over
wo's), F = F(wo . m; eta) the exact dielectric Fresnel term and G = G1(wo) G1(wi):

- reflection (wi.z > 0): m = normalize(wo + wi),
  f = specular_reflectance F D(m) G / (4 cos_o cos_i),
  pdf = D_wo(m) F / (4 wi . m);
- refraction (wi.z < 0): m = normalize(wo + eta wi), turned up,
  f = specular_transmittance (1 - F) D(m) G |wo . m| |wi . m| / (cos_o |cos_i| (wo . m + eta wi . m)^2),
  pdf = D_wo(m) (1 - F) eta^2 |wi . m| / (wo . m + eta wi . m)^2,

D_wo(m) = G1(wo) max(0, wo . m) D(m) / cos_o. The refracted radiance carries 1 / eta^2 (the
solid-angle compression across the interface, Mitsuba's radiance mode), which cancels the
eta^2 of Walter's Jacobian in f. Sampling picks reflection with probability F and refraction
with 1 - F, so a sample's weight f |cos_i| / pdf is its scale times G1(wi) (and 1 / eta^2 for
refraction). Each side of a microfacet must agree with the macro surface ((wo . m) cos_o > 0 and
(wi . m) cos_i > 0), as Mitsuba requires of its Smith terms.

Like ``dielectric`` it has an inside: a hit seen from behind the normal shades with the row of
the indices swapped (``MaterialType.behind``), so the materials always see wo.z > 0. It
transmits: light sampling reaches it from both sides of the surface (``MaterialType.transmits``).

=======================  =====  ===================================================
parameter                size   meaning
=======================  =====  ===================================================
specular_reflectance     3      reflection scale, in [0, 1] (default 1)
specular_transmittance   3      refraction scale, in [0, 1] (default 1)
int_ior, ext_ior         1, 1   indices inside and outside (bk7 1.5046, air 1.000277)
alpha                    1      roughness, used as given (default 0.1)
distribution             1      ``beckmann`` (default, as Mitsuba) or ``ggx``
=======================  =====  ===================================================
"""

from __future__ import annotations

import math

from ..jit import jit
from ..plugins import register
from . import microfacet
from .base import GLOSSY, MaterialType, Param, rgb
from .dielectric import DIELECTRIC_PARAMS, relative_eta, seen_from_inside

CODE = 9  # the dispatch code (``tracer.materials``)
TYPE = register(MaterialType(module=__name__, rank=CODE, name="roughdielectric", code=CODE, lobes=GLOSSY,
                    doc="rough glass: microfacet reflection and refraction (GGX or Beckmann)",
                    params=DIELECTRIC_PARAMS + (
                        Param("alpha", 1, lo=microfacet.MIN_ALPHA, hi=microfacet.MAX_ALPHA, default=0.1,
                              texture=True, doc="roughness, used as given (the same on both sides)"),
                        Param("distribution", 1, default="beckmann", choices=microfacet.DISTRIBUTIONS,
                              doc="microfacet distribution")),
                    derived=(Param("eta", 1),), derive=relative_eta, behind=seen_from_inside,
                    transmits=True))
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
SPECULAR_TRANSMITTANCE = TYPE.column("specular_transmittance")
ALPHA, DISTRIBUTION, ETA = TYPE.column("alpha"), TYPE.column("distribution"), TYPE.column("eta")

ZERO = (0.0, 0.0, 0.0)


@jit
def _refraction_half(wo, wi, eta: float):
    """m = normalize(wo + eta wi), turned to the upper side; (0, 0, 0) if wo + eta wi is 0."""
    hx, hy, hz = wo[0] + eta * wi[0], wo[1] + eta * wi[1], wo[2] + eta * wi[2]
    length = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not length > 0.0:
        return ZERO
    inv = (1.0 if hz >= 0.0 else -1.0) / length
    return hx * inv, hy * inv, hz * inv


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf) of either lobe (module docstring); 0 where the sides disagree."""
    cos_o, cos_i = wo[2], wi[2]
    if cos_o <= 0.0 or cos_i == 0.0:
        return ZERO, 0.0
    alpha, distribution, eta = params[row, ALPHA], int(params[row, DISTRIBUTION]), params[row, ETA]
    if cos_i > 0.0:
        value, p = microfacet.reflection_value_and_pdf(wo, wi, alpha, distribution)
        fresnel = microfacet.fresnel_dielectric(microfacet.wo_dot_half(wo, wi), eta)
        if not value > 0.0:
            return ZERO, p * fresnel
        r, g, b = rgb(params, row, SPECULAR_REFLECTANCE)
        scale = fresnel * value
        return (r * scale, g * scale, b * scale), p * fresnel
    m = _refraction_half(wo, wi, eta)
    wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    wi_m = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2]
    if not (wo_m > 0.0 and wi_m < 0.0):
        return ZERO, 0.0
    d = microfacet.d_cos2(m[2] * m[2], alpha, distribution)
    g1_o = microfacet.g1(cos_o, alpha, distribution)
    transmitted = 1.0 - microfacet.fresnel_dielectric(wo_m, eta)
    denominator = wo_m + eta * wi_m
    denominator *= denominator
    if not (denominator > 0.0 and transmitted > 0.0):
        return ZERO, 0.0
    p = g1_o * wo_m * d / cos_o * transmitted * eta * eta * -wi_m / denominator
    value = transmitted * d * g1_o * microfacet.g1(-cos_i, alpha, distribution) * wo_m * -wi_m \
        / (cos_o * -cos_i * denominator)
    t = rgb(params, row, SPECULAR_TRANSMITTANCE)
    return (t[0] * value, t[1] * value, t[2] * value), p


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """m from the visible normals; reflection with probability F(wo . m), else refraction."""
    alpha, distribution, eta = params[row, ALPHA], int(params[row, DISTRIBUTION]), params[row, ETA]
    m = microfacet.visible_normal(wo, alpha, distribution, u0, u1)
    wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    if not wo_m > 0.0:
        return (0.0, 0.0, 1.0), ZERO, 0.0, 0
    fresnel = microfacet.fresnel_dielectric(wo_m, eta)
    if u_lobe < fresnel:
        wi = (2.0 * wo_m * m[0] - wo[0], 2.0 * wo_m * m[1] - wo[1], 2.0 * wo_m * m[2] - wo[2])
        if wi[2] <= 0.0:
            return wi, ZERO, 0.0, 0
        scale = microfacet.g1(wi[2], alpha, distribution)
        weight = rgb(params, row, SPECULAR_REFLECTANCE)
    else:
        # Snell across m: F < 1 here, so the root is real.
        inv_eta = 1.0 / eta
        cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - wo_m * wo_m) * inv_eta * inv_eta))
        along = wo_m * inv_eta - cos_t
        wi = (along * m[0] - inv_eta * wo[0], along * m[1] - inv_eta * wo[1], along * m[2] - inv_eta * wo[2])
        if wi[2] >= 0.0:
            return wi, ZERO, 0.0, 0
        scale = microfacet.g1(-wi[2], alpha, distribution) * inv_eta * inv_eta
        weight = rgb(params, row, SPECULAR_TRANSMITTANCE)
    # The pdf through eval_pdf, the very function other techniques' samples are weighed with.
    p = eval_pdf(params, row, wo, wi)[1]
    if not p > 0.0:
        return wi, ZERO, 0.0, 0
    return wi, (weight[0] * scale, weight[1] * scale, weight[2] * scale), p, GLOSSY
