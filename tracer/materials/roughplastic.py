"""``roughplastic``: a diffuse base under a rough dielectric coating, Mitsuba 3's model.

    f(wo, wi) = specular F(wo.h) D(h) G1(wo) G1(wi) / (4 cos_o cos_i)
              + R' T(cos_o) T(cos_i) / (pi eta^2)

The coating is a microfacet reflector (GGX or Beckmann, ``microfacet``) with the exact
dielectric Fresnel term of eta = int_ior / ext_ior. T(mu) is the energy the rough coating lets
through at incidence cos = mu, as Mitsuba 3 defines it: (1 - F) times the masking G1 of the
refracted direction, averaged over the visible normals (so T < 1 - R_c, R_c the coating's
directional albedo). R' = R / (1 - R_int) (``nonlinear``: R / (1 - R R_int)) with R_int
= 2 integral R_c(mu; 1/eta) mu dmu the coating's diffuse reflectance from inside, estimated as
Mitsuba does, by twice the mean of R_c mu over the table's nodes. As in Mitsuba, T is a table
of TABLE_SIZE values at mu = j / (TABLE_SIZE - 1) (mu = 1e-6 for j = 0), read by linear
interpolation; tracer integrates each entry with a QUADRATURE x QUADRATURE midpoint rule over
the visible-normal sampler's square (the integrands vanish with G1 at the horizon, so the rule
converges as 1 / n^2). The model is Mitsuba's, not energy-exact: T + R_c < 1.

Sampling (Mitsuba's lobe selection): the coating with probability proportional to
(1 - T(cos_o)) w_s, the base with T(cos_o) (1 - w_s) (w_s as ``plastic``); the coating by its
visible normals, the base by the cosine warp; pdf is the mixture of both densities.

=====================  =====  ===================================================
parameter              size   meaning
=====================  =====  ===================================================
(plastic's)                   diffuse_reflectance, specular_reflectance, int_ior, ext_ior,
                              nonlinear, with the same defaults
alpha                  1      coating roughness, in (0, 10] (default 0.1)
distribution           1      ``beckmann`` (default, as Mitsuba) or ``ggx``
=====================  =====  ===================================================
"""

from __future__ import annotations

import numpy as np

from .. import warp
from ..jit import jit, jit_called
from ..plugins import register
from . import microfacet
from .base import DIFFUSE, GLOSSY, MaterialType, Param, rgb, weighted
from .plastic import COATING_PARAMS, base_albedo, coating_constants, specular_probability

CODE = 6  # the dispatch code (``tracer.materials``)
TABLE_SIZE = 64
QUADRATURE = 64
_NODES = np.linspace(0.0, 1.0, TABLE_SIZE)


def _derive(values: dict[str, object]) -> dict[str, object]:
    out = coating_constants(values)
    alpha, distribution = float(values["alpha"]), int(values["distribution"])
    mu = np.maximum(_NODES, 1e-6)
    eta = out["eta"]
    out["transmittance"] = [microfacet.dielectric_albedo(m, alpha, distribution, eta, QUADRATURE, True)
                            for m in mu]
    inside = np.array([microfacet.dielectric_albedo(m, alpha, distribution, 1.0 / eta, QUADRATURE, False)
                       for m in mu])
    # Mitsuba's estimate of 2 integral R mu dmu: twice the mean over the table's nodes.
    out["internal_reflectance"] = float(2.0 * np.mean(inside * mu))
    return out


TYPE = register(MaterialType(module=__name__, rank=CODE, name=
    "roughplastic", code=CODE, lobes=GLOSSY | DIFFUSE, doc="diffuse base under a rough coating",
    params=COATING_PARAMS + (
        Param("alpha", 1, lo=microfacet.MIN_ALPHA, hi=microfacet.MAX_ALPHA, default=0.1, doc="coating roughness"),
        Param("distribution", 1, default="beckmann", choices=microfacet.DISTRIBUTIONS,
              doc="microfacet distribution")),
    derived=(Param("eta", 1), Param("inv_eta2", 1), Param("specular_weight", 1),
             Param("internal_reflectance", 1), Param("transmittance", TABLE_SIZE)),
    derive=_derive))
DIFFUSE_REFLECTANCE = TYPE.column("diffuse_reflectance")
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
NONLINEAR, ALPHA, DISTRIBUTION = TYPE.column("nonlinear"), TYPE.column("alpha"), TYPE.column("distribution")
ETA, INV_ETA2, SPECULAR_WEIGHT = TYPE.column("eta"), TYPE.column("inv_eta2"), TYPE.column("specular_weight")
INTERNAL, TRANSMITTANCE = TYPE.column("internal_reflectance"), TYPE.column("transmittance")


@jit
def transmittance(params, row, mu: float) -> float:
    """T(mu) by linear interpolation in the material's table."""
    x = min(max(mu, 0.0), 1.0) * (TABLE_SIZE - 1)
    i = min(int(x), TABLE_SIZE - 2)
    t = x - i
    return (1.0 - t) * params[row, TRANSMITTANCE + i] + t * params[row, TRANSMITTANCE + i + 1]


@jit_called
def eval_pdf(params, row, wo, wi):
    """(f, pdf): coating plus base, and the lobe-mixture pdf."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    alpha, distribution = params[row, ALPHA], int(params[row, DISTRIBUTION])
    value, pdf_coating = microfacet.reflection_value_and_pdf(wo, wi, alpha, distribution)
    coating = value * microfacet.fresnel_dielectric(microfacet.wo_dot_half(wo, wi), params[row, ETA])
    t_o, t_i = transmittance(params, row, wo[2]), transmittance(params, row, wi[2])
    albedo = base_albedo(params, row, DIFFUSE_REFLECTANCE, NONLINEAR, params[row, INTERNAL])
    base = t_o * t_i * params[row, INV_ETA2] * warp.INV_PI
    s = rgb(params, row, SPECULAR_REFLECTANCE)
    f = (s[0] * coating + albedo[0] * base, s[1] * coating + albedo[1] * base,
         s[2] * coating + albedo[2] * base)
    p_coating = specular_probability(1.0 - t_o, params[row, SPECULAR_WEIGHT])
    return f, p_coating * pdf_coating + (1.0 - p_coating) * warp.cosine_hemisphere_pdf(wi[2])


@jit_called
def sample(params, row, wo, u_lobe, u0, u1):
    """A direction from the coating's visible normals or the cosine warp; weight f cos / pdf of
    the mixture."""
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0
    p_coating = specular_probability(1.0 - transmittance(params, row, wo[2]), params[row, SPECULAR_WEIGHT])
    wi, flags = microfacet.reflection_or_cosine(wo, params[row, ALPHA], int(params[row, DISTRIBUTION]),
                                                p_coating, u_lobe, u0, u1)
    f, p = eval_pdf(params, row, wo, wi)
    return weighted(wi, f, p, flags)


@jit
def lobe(params, row, wo):
    """The lobe proxy of product sampling (``tracer.lights.environment_product``): the coating's
    glossy lobe and the diffuse base, in the proportion this material samples them at wo."""
    if wo[2] <= 0.0:
        return 0.0, 0.0, 0.0, 1.0
    p_coating = specular_probability(1.0 - transmittance(params, row, wo[2]), params[row, SPECULAR_WEIGHT])
    return 1.0 - p_coating, p_coating, 0.0, params[row, ALPHA]
