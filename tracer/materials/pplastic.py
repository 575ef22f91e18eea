"""``pplastic``: Mitsuba 3's polarized plastic, as it renders without polarization.

Mitsuba's ``pplastic`` (after Baek et al. 2018, "Simultaneous acquisition of polarimetric SVBRDF
and normals") adds a rough specular reflection and a diffuse term attenuated by a smooth
refraction in and out, instead of layering them as ``roughplastic`` does:

    f(wo, wi) = specular F(wo.h) D(h) G1(wo) G1(wi) / (4 cos_o cos_i)
              + diffuse (1 - F(cos_o)) (1 - F(cos_i)) / pi

with F the exact dielectric Fresnel term of eta = int_ior / ext_ior and D, G1 GGX or Beckmann
(``microfacet``). tracer renders intensity only, which is the (0, 0) entry of Mitsuba's Mueller
matrices, so these are the formulas of its unpolarized branch. The model is neither layered nor
energy conserving (the sum stays below 1: the specular term takes at most F, the diffuse one
at most 1 - F).

Sampling (Mitsuba's): the specular lobe by its visible normals with the fixed probability
w_s = mean(specular) / (mean(specular) + mean(diffuse)), else the cosine warp; pdf is the
mixture of both densities. A texture's mean stands in for it in w_s (``tracer.textures.bind``),
as Mitsuba takes the texture's mean.

=====================  =====  ===================================================
parameter              size   meaning
=====================  =====  ===================================================
diffuse_reflectance    3      diffuse scale per channel, in [0, 1] (default 0.5)
specular_reflectance   3      specular scale per channel, in [0, 1] (default 1)
int_ior, ext_ior       1, 1   indices inside and outside (polypropylene 1.49, air 1.000277)
alpha                  1      roughness, in (0, 10] (default 0.1)
distribution           1      ``beckmann`` (default, as Mitsuba) or ``ggx``
=====================  =====  ===================================================
"""

from __future__ import annotations

from .. import warp
from ..jit import jit_called
from ..plugins import register
from . import microfacet
from .base import DIFFUSE, GLOSSY, MaterialType, Param, rgb, weighted
from .plastic import COATING_PARAMS, coating_constants

CODE = 10  # the dispatch code (``tracer.materials``)


def _derive(values: dict[str, object]) -> dict[str, object]:
    """eta and w_s, as ``plastic`` derives them (Mitsuba's weight is the same ratio of means)."""
    constants = coating_constants(values)
    return {"eta": constants["eta"], "specular_weight": constants["specular_weight"]}


TYPE = register(MaterialType(module=__name__, rank=CODE, name=
    "pplastic", code=CODE, lobes=GLOSSY | DIFFUSE,
    doc="rough specular plus Fresnel-attenuated diffuse (Mitsuba)",
    params=tuple(p for p in COATING_PARAMS if p.name != "nonlinear") + (
        Param("alpha", 1, lo=microfacet.MIN_ALPHA, hi=microfacet.MAX_ALPHA, default=0.1, texture=True,
              doc="roughness, used as given"),
        Param("distribution", 1, default="beckmann", choices=microfacet.DISTRIBUTIONS,
              doc="microfacet distribution")),
    derived=(Param("eta", 1), Param("specular_weight", 1)),
    derive=_derive))
DIFFUSE_REFLECTANCE = TYPE.column("diffuse_reflectance")
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
ALPHA, DISTRIBUTION = TYPE.column("alpha"), TYPE.column("distribution")
ETA, SPECULAR_WEIGHT = TYPE.column("eta"), TYPE.column("specular_weight")


@jit_called
def eval_pdf(params, row, wo, wi):
    """(f, pdf): the specular and diffuse terms, and the lobe-mixture pdf; 0 unless both
    directions are above the surface."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    eta = params[row, ETA]
    value, pdf_specular = microfacet.reflection_value_and_pdf(wo, wi, params[row, ALPHA],
                                                              int(params[row, DISTRIBUTION]))
    specular = value * microfacet.fresnel_dielectric(microfacet.wo_dot_half(wo, wi), eta)
    diffuse = ((1.0 - microfacet.fresnel_dielectric(wo[2], eta))
               * (1.0 - microfacet.fresnel_dielectric(wi[2], eta)) * warp.INV_PI)
    s = rgb(params, row, SPECULAR_REFLECTANCE)
    d = rgb(params, row, DIFFUSE_REFLECTANCE)
    f = (s[0] * specular + d[0] * diffuse, s[1] * specular + d[1] * diffuse, s[2] * specular + d[2] * diffuse)
    w_s = params[row, SPECULAR_WEIGHT]
    return f, w_s * pdf_specular + (1.0 - w_s) * warp.cosine_hemisphere_pdf(wi[2])


@jit_called
def sample(params, row, wo, u_lobe, u0, u1):
    """A direction from the specular lobe's visible normals (probability w_s) or the cosine
    warp; weight f cos / pdf of the mixture."""
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0
    wi, flags = microfacet.reflection_or_cosine(wo, params[row, ALPHA], int(params[row, DISTRIBUTION]),
                                                params[row, SPECULAR_WEIGHT], u_lobe, u0, u1)
    f, p = eval_pdf(params, row, wo, wi)
    return weighted(wi, f, p, flags)
