"""``roughconductor``: a GGX (Trowbridge-Reitz) microfacet reflector with Fresnel = 1.

f = reflectance D(h) G1(wo) G1(wi) / (4 cos_o cos_i), separable Smith masking, ``alpha``
used as given (not squared). Sampled by the distribution of visible normals (Heitz 2018,
spherical-cap form of Dupuy and Benyoub 2023, ``tracer.warp``).

=============  =====  ================================================
parameter      size   meaning
=============  =====  ================================================
reflectance    3      scale per channel, in [0, 1] (the Fresnel term)
alpha          1      GGX roughness, in (0, 10]
=============  =====  ================================================
"""

from __future__ import annotations

from .. import warp
from ..jit import jit
from .base import GLOSSY, MaterialType, Param, rgb

CODE = 2  # the dispatch code (``tracer.materials``)
TYPE = MaterialType(
    "roughconductor", code=CODE, lobes=GLOSSY, doc="GGX microfacet reflector, Fresnel = 1",
    params=(Param("reflectance", 3, lo=0.0, hi=1.0, doc="scale per channel"),
            Param("alpha", 1, lo=0.0, lo_open=True, hi=10.0, doc="GGX roughness, used as given")))
REFLECTANCE = TYPE.column("reflectance")
ALPHA = TYPE.column("alpha")


@jit
def _cos2_half(wo, wi) -> float:
    """cos^2 of the half vector h = normalize(wo + wi), without the square root."""
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    return hz * hz / (hx * hx + hy * hy + hz * hz)


@jit
def ggx_value_and_pdf(wo, wi, alpha: float):
    """The scalar GGX BRDF with Fresnel = 1, D(h) G1(wo) G1(wi) / (4 cos_o cos_i), and the pdf
    of sampling wi = reflect(wo, h) with h ~ visible normals, D_wo(h) / (4 wo.h) =
    G1(wo) D(h) / (4 cos_o). With G1 = 2 cos / (cos + sigma) (``warp.ggx_sigma``) the cosines
    cancel: f = D / ((cos_o + sigma_o) (cos_i + sigma_i)) and pdf = D / (2 (cos_o + sigma_o)).
    Both are 0 unless wo and wi are above the surface (then wo.h > 0 holds)."""
    cos_o, cos_i = wo[2], wi[2]
    if cos_o <= 0.0 or cos_i <= 0.0:
        return 0.0, 0.0
    d = warp.ggx_d_cos2(_cos2_half(wo, wi), alpha)
    outgoing = cos_o + warp.ggx_sigma(cos_o, alpha)
    return d / (outgoing * (cos_i + warp.ggx_sigma(cos_i, alpha))), d / (2.0 * outgoing)


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf): reflectance times the scalar GGX BRDF, and the visible-normal pdf of wi."""
    value, p = ggx_value_and_pdf(wo, wi, params[row, ALPHA])
    r, g, b = rgb(params, row, REFLECTANCE)
    return (r * value, g * value, b * value), p


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """wi = reflect(wo, h) with h from the visible normals; weight = reflectance G1(wi)."""
    alpha = params[row, ALPHA]
    h = warp.ggx_visible_normal(wo, alpha, u0, u1)
    wo_dot_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    wi = (2.0 * wo_dot_h * h[0] - wo[0], 2.0 * wo_dot_h * h[1] - wo[1], 2.0 * wo_dot_h * h[2] - wo[2])
    if wi[2] <= 0.0 or wo_dot_h <= 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    # The pdf through the very function that evaluates it for other techniques' samples (from
    # h itself it differs in rounding, by 1e-3 at alpha = 1e-6: MIS weights would not sum to
    # one). With separable Smith G and visible-normal sampling, f cos / pdf is G1(wi).
    p = ggx_value_and_pdf(wo, wi, alpha)[1]
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    g1 = warp.ggx_g1(wi[2], alpha)
    r, g, b = rgb(params, row, REFLECTANCE)
    return wi, (r * g1, g * g1, b * g1), p, GLOSSY
