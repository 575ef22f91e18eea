"""``plastic``: a diffuse base under a smooth dielectric coating, Mitsuba 3's model.

Light either reflects off the coating (a delta lobe, weight specular_reflectance x F) or enters
it, scatters diffusely in the base and leaves through the coating:

    f(wo, wi) = R' (1 - F(cos_o)) (1 - F(cos_i)) / (pi eta^2),   R' = R / (1 - Fdr_int)

with F the exact dielectric Fresnel term of eta = int_ior / ext_ior, R the diffuse reflectance
and Fdr_int the coating's diffuse reflectance seen from inside, which accounts for the light
that bounces between base and coating (``nonlinear``: R' = R / (1 - R Fdr_int), the
bounces' colour shift). Because eta^2 (1 - Fdr(1/eta)) = 1 - Fdr(eta), the albedo is exactly
specular x F(cos_o) + R (1 - F(cos_o)) in the linear model (tested). Fdr is integrated
exactly when the material is built (``microfacet.diffuse_fresnel_reflectance``; Mitsuba 3 uses
fits within ~0.1% of it).

Sampling (Mitsuba's lobe selection): the coating with probability proportional to
F(cos_o) x w_s, the base with (1 - F(cos_o)) (1 - w_s), where w_s = mean(specular) / (mean(diffuse)
+ mean(specular)); the base by the cosine warp. pdf and f of a given direction are the base's
(the coating is a delta lobe no other technique can hit).

=====================  =====  ===================================================
parameter              size   meaning
=====================  =====  ===================================================
diffuse_reflectance    3      base albedo per channel, in [0, 1] (default 0.5)
specular_reflectance   3      coating reflection scale, in [0, 1] (default 1)
int_ior, ext_ior       1, 1   indices inside the coating and outside (1.49, 1.000277)
nonlinear              1      true: account for the colour shift of internal bounces
=====================  =====  ===================================================
"""

from __future__ import annotations

import numpy as np

from .. import warp
from ..jit import jit, jit_called
from ..plugins import register
from . import microfacet
from .base import DELTA, DIFFUSE, MaterialType, Param, rgb

CODE = 5  # the dispatch code (``tracer.materials``)
# Indices of refraction in [MIN_IOR, MAX_IOR], so that eta = int_ior / ext_ior lies in [1e-4, 1e4]:
# every such coating renders finite (measured to 1e-5 .. 1e5); real ones lie in 1 .. 4, and an
# index near 0 divided by 0 (int_ior 1e-300: ZeroDivisionError) or overflowed (ext_ior 1e-300).
MIN_IOR, MAX_IOR = 0.01, 100.0
# Mitsuba 3's defaults: polypropylene inside, air outside.
COATING_PARAMS = (
    Param("diffuse_reflectance", 3, lo=0.0, hi=1.0, default=0.5, texture=True, doc="base albedo per channel"),
    Param("specular_reflectance", 3, lo=0.0, hi=1.0, default=1.0,
          texture=True, doc="coating reflection scale"),
    Param("int_ior", 1, lo=MIN_IOR, hi=MAX_IOR, default=1.49, doc="index inside the coating"),
    Param("ext_ior", 1, lo=MIN_IOR, hi=MAX_IOR, default=1.000277, doc="index outside"),
    Param("nonlinear", 1, default=False, boolean=True, doc="colour shift of internal bounces"),
)
COATING_DERIVED = (Param("eta", 1), Param("inv_eta2", 1), Param("specular_weight", 1), Param("fdr_int", 1))


def coating_constants(values: dict[str, object]) -> dict[str, object]:
    """eta, 1 / eta^2 and the lobe-selection weight w_s of a coating's parameters."""
    eta = float(values["int_ior"]) / float(values["ext_ior"])
    specular = float(np.mean(values["specular_reflectance"]))
    diffuse = float(np.mean(values["diffuse_reflectance"]))
    weight = specular / (specular + diffuse) if specular + diffuse > 0.0 else 0.5
    return {"eta": eta, "inv_eta2": 1.0 / (eta * eta), "specular_weight": weight}


def _derive(values: dict[str, object]) -> dict[str, object]:
    out = coating_constants(values)
    out["fdr_int"] = microfacet.diffuse_fresnel_reflectance(1.0 / out["eta"])
    return out


TYPE = register(MaterialType(module=__name__, rank=CODE, name="plastic", code=CODE, lobes=DELTA | DIFFUSE,
                    doc="diffuse base under a smooth coating",
                    params=COATING_PARAMS, derived=COATING_DERIVED, derive=_derive))
DIFFUSE_REFLECTANCE = TYPE.column("diffuse_reflectance")
SPECULAR_REFLECTANCE = TYPE.column("specular_reflectance")
NONLINEAR, ETA, INV_ETA2 = TYPE.column("nonlinear"), TYPE.column("eta"), TYPE.column("inv_eta2")
SPECULAR_WEIGHT, FDR_INT = TYPE.column("specular_weight"), TYPE.column("fdr_int")


@jit
def base_albedo(params, row, diffuse_column: int, nonlinear_column: int, internal: float):
    """R' per channel: the base's reflectance with the bounces under the coating summed."""
    r = rgb(params, row, diffuse_column)
    if params[row, nonlinear_column] != 0.0:
        return r[0] / (1.0 - r[0] * internal), r[1] / (1.0 - r[1] * internal), r[2] / (1.0 - r[2] * internal)
    scale = 1.0 / (1.0 - internal)
    return r[0] * scale, r[1] * scale, r[2] * scale


@jit
def specular_probability(reflected: float, weight: float) -> float:
    """Probability of sampling the coating given the energy it reflects at wo and w_s."""
    specular, diffuse = reflected * weight, (1.0 - reflected) * (1.0 - weight)
    total = specular + diffuse
    return specular / total if total > 0.0 else 0.0


@jit_called
def eval_pdf(params, row, wo, wi):
    """(f, pdf) of the base: R' (1 - F_o)(1 - F_i) / (pi eta^2), and its selection probability
    times the cosine pdf."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    eta = params[row, ETA]
    f_o, f_i = microfacet.fresnel_dielectric(wo[2], eta), microfacet.fresnel_dielectric(wi[2], eta)
    albedo = base_albedo(params, row, DIFFUSE_REFLECTANCE, NONLINEAR, params[row, FDR_INT])
    c = (1.0 - f_o) * (1.0 - f_i) * params[row, INV_ETA2] * warp.INV_PI
    p = (1.0 - specular_probability(f_o, params[row, SPECULAR_WEIGHT])) * warp.cosine_hemisphere_pdf(wi[2])
    return (albedo[0] * c, albedo[1] * c, albedo[2] * c), p


@jit_called
def sample(params, row, wo, u_lobe, u0, u1):
    """The coating's mirror direction (delta) or a cosine-weighted direction into the base."""
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0
    f_o = microfacet.fresnel_dielectric(wo[2], params[row, ETA])
    p_specular = specular_probability(f_o, params[row, SPECULAR_WEIGHT])
    if u_lobe < p_specular:
        s = rgb(params, row, SPECULAR_REFLECTANCE)
        c = f_o / p_specular
        return (-wo[0], -wo[1], wo[2]), (s[0] * c, s[1] * c, s[2] * c), 0.0, DELTA
    wi = warp.cosine_hemisphere(u0, u1)
    f, p = eval_pdf(params, row, wo, wi)
    if not p > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    c = wi[2] / p
    return wi, (f[0] * c, f[1] * c, f[2] * c), p, DIFFUSE


@jit
def lobe(params, row, wo):
    """The lobe proxy of product sampling (``tracer.lights.environment_product``): the diffuse
    base alone (the smooth coating's delta lobe takes no light samples)."""
    return 1.0, 0.0, 0.0, 1.0
