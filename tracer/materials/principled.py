"""``principled``: Burley's principled BSDF as Mitsuba 3.9.1 writes it (src/bsdfs/principled.cpp).

Five lobes, weighted by the parameters (``principled_lobes`` holds the terms and their sources).
With brdf = (1 - metallic)(1 - spec_trans) and bsdf = (1 - metallic) spec_trans, seen from the
front:

- main specular reflection: anisotropic GGX, f = F_p D G / (4 cos_o cos_i) with F_p = (1 -
  metallic)(1 - spec_tint) F + metallic Schlick(base_color) + (1 - metallic) spec_tint
  Schlick(tint R0(eta)), F the exact dielectric Fresnel term of eta;
- specular transmission (Walter et al. 2007): sqrt(base_color) bsdf (1 - F) times the rough
  refraction of ``roughdielectric``, with the radiance's 1 / eta^2;
- clearcoat: GTR1, clearcoat / 4 times Schlick(0.04) D G (Mitsuba's form);
- diffuse: brdf base_color / pi times Burley's retro-reflective diffuse (flattened toward the
  fake subsurface by ``flatness``);
- sheen: sheen (1 - metallic) (1 - cos_d)^5, tinted by ``sheen_tint``.

Seen from behind (``inside``: a row of ``MaterialType.behind``) only the interface remains: the
relative index is 1 / eta, reflection is bsdf F D G / (4 cos_o cos_i) and transmission as above;
with spec_trans = 0 the back is black. Inside Mitsuba's ``twosided`` (allowed only without
spec_trans, as Mitsuba allows) the back is the front mirrored (``mirrored``).

Sampling is Mitsuba's: a lobe by the probabilities (front) main_specular_sampling_rate (1 -
bsdf (1 - F)) for reflection and main_specular_sampling_rate bsdf (1 - F) for transmission, with
F at the sampled visible normal, clearcoat_sampling_rate clearcoat / 4 for the clearcoat and
diffuse_reflectance_sampling_rate brdf for the cosine-weighted diffuse; (behind) F and 1 - F.
The two F-dependent probabilities sum to the rate, so the choice is consistent with the pdf,
which evaluates them at the pair's half vector (the sampled normal itself for those lobes). The
weight of a sample is f |cos_i| / pdf of the whole mixture.

Anisotropy makes the value depend on the tangent: a row with anisotropic > 0 is shaded in
Mitsuba's frame, s along dp/du (``oriented``).

================================  ====  =================================================
parameter                         size  meaning
================================  ====  =================================================
base_color                        3     in [0, 1] (default 0.5)
roughness                         1     in [0, 1] (default 0.5)
anisotropic, metallic, spec_tint  1     in [0, 1] (default 0)
sheen, sheen_tint                 1     in [0, 1] (default 0)
clearcoat, clearcoat_gloss        1     in [0, 1] (default 0)
spec_trans, flatness              1     in [0, 1] (default 0)
eta                               1     relative index, in [1, 100] (default 1.5: Mitsuba's
                                        specular 0.5); Mitsuba's specular s is eta =
                                        2 / (1 - sqrt(0.08 s)) - 1
main_specular_sampling_rate       1     > 0 (default 1)
clearcoat_sampling_rate           1     >= 0 (default 1)
diffuse_reflectance_sampling_rate 1     >= 0 (default 1)
================================  ====  =================================================
"""

from __future__ import annotations

import math

from .. import warp
from ..frame import add_scaled
from ..jit import jit
from ..plugins import register
from . import microfacet
from . import principled_lobes as lobes
from .base import DIFFUSE, GLOSSY, MaterialType, Param, rgb, weighted
from .plastic import MAX_IOR

CODE = 12  # the dispatch code (``tracer.materials``)
MAX_SAMPLING_RATE = 1e6
WHITE = (1.0, 1.0, 1.0)
RATES = ("main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate")


def _unit(name: str, default: float, doc: str) -> Param:
    return Param(name, 1, lo=0.0, hi=1.0, default=default, texture=True, doc=doc)


def _seen_from_behind(values: dict[str, object]) -> dict[str, object]:
    """The row a hit from behind shades with: the inside of the interface, or (inside Mitsuba's
    twosided) the front itself."""
    return values if values["mirrored"] else dict(values, inside=True)


TYPE = register(MaterialType(
    module=__name__, rank=CODE, name="principled", code=CODE, lobes=GLOSSY | DIFFUSE,
    doc="Burley's principled BSDF (Mitsuba's): diffuse, sheen, clearcoat, metallic, rough transmission",
    params=(Param("base_color", 3, lo=0.0, hi=1.0, default=0.5, texture=True, doc="base colour"),
            _unit("roughness", 0.5, "Burley's roughness (alpha = roughness^2)"),
            _unit("anisotropic", 0.0, "anisotropy of the specular lobes (along s, dp/du)"),
            _unit("metallic", 0.0, "blend toward a metal tinted by base_color"),
            _unit("spec_tint", 0.0, "tint of the dielectric specular toward base_color"),
            _unit("sheen", 0.0, "sheen at grazing angles"),
            _unit("sheen_tint", 0.0, "tint of the sheen toward base_color"),
            _unit("clearcoat", 0.0, "weight of the clearcoat lobe"),
            _unit("clearcoat_gloss", 0.0, "glossiness of the clearcoat (GTR1 alpha 0.1 to 0.001)"),
            _unit("spec_trans", 0.0, "weight of the rough specular transmission"),
            _unit("flatness", 0.0, "blend of the diffuse toward the fake subsurface"),
            Param("eta", 1, lo=1.0, hi=MAX_IOR, default=1.5, doc="relative index of refraction"),
            Param("main_specular_sampling_rate", 1, lo=0.0, lo_open=True, hi=MAX_SAMPLING_RATE, default=1.0,
                  doc="weight of the specular lobes in lobe selection"),
            Param("clearcoat_sampling_rate", 1, lo=0.0, hi=MAX_SAMPLING_RATE, default=1.0,
                  doc="weight of the clearcoat in lobe selection"),
            Param("diffuse_reflectance_sampling_rate", 1, lo=0.0, hi=MAX_SAMPLING_RATE, default=1.0,
                  doc="weight of the diffuse lobe in lobe selection"),
            Param("inside", 1, default=False, boolean=True, internal=True,
                  doc="the row of the interface seen from behind (``behind``)"),
            Param("mirrored", 1, default=False, boolean=True, internal=True,
                  doc="inside Mitsuba's twosided: the back is the front mirrored")),
    behind=_seen_from_behind, transmits=True,
    oriented=lambda values: float(values["anisotropic"]) > 0.0))
(BASE_COLOR, ROUGHNESS, ANISOTROPIC, METALLIC, SPEC_TINT, SHEEN, SHEEN_TINT, CLEARCOAT, CLEARCOAT_GLOSS,
 SPEC_TRANS, FLATNESS, ETA, SPECULAR_RATE, CLEARCOAT_RATE, DIFFUSE_RATE, INSIDE) = (TYPE.column(n) for n in (
    "base_color", "roughness", "anisotropic", "metallic", "spec_tint", "sheen", "sheen_tint", "clearcoat",
    "clearcoat_gloss", "spec_trans", "flatness", "eta", "main_specular_sampling_rate",
    "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate", "inside"))


def eta_of_specular(specular: float) -> float:
    """Mitsuba's eta of Burley's ``specular`` s in [0, 1]: 2 / (1 - sqrt(0.08 s)) - 1 (R0 = 0.08 s
    at normal incidence)."""
    return 2.0 / (1.0 - math.sqrt(0.08 * specular)) - 1.0


@jit
def _lobe_probabilities(params, row, front: bool, fresnel: float):
    """``(specular reflection, specular transmission, clearcoat, diffuse)`` choice
    probabilities, summing to 1, for Fresnel term ``fresnel`` at the microfacet normal."""
    metallic, spec_trans = params[row, METALLIC], params[row, SPEC_TRANS]
    bsdf = (1.0 - metallic) * spec_trans
    if front:
        rate = params[row, SPECULAR_RATE]
        reflection = rate * (1.0 - bsdf * (1.0 - fresnel))
        transmission = rate * bsdf * (1.0 - fresnel)
        clearcoat = 0.25 * params[row, CLEARCOAT] * params[row, CLEARCOAT_RATE]
        diffuse = (1.0 - metallic) * (1.0 - spec_trans) * params[row, DIFFUSE_RATE]
    else:
        reflection, transmission, clearcoat, diffuse = fresnel, 1.0 - fresnel, 0.0, 0.0
    total = reflection + transmission + clearcoat + diffuse
    return reflection / total, transmission / total, clearcoat / total, diffuse / total


@jit
def _principled_fresnel(params, row, base, fresnel: float, wo_h: float):
    """F_p of the main specular reflection from the front, per channel."""
    metallic, spec_tint, eta = params[row, METALLIC], params[row, SPEC_TINT], params[row, ETA]
    dielectric = (1.0 - metallic) * (1.0 - spec_tint) * fresnel
    c = lobes.tint(base)
    r0_tint = lobes.r0_of_eta(eta)
    tinted = (1.0 - metallic) * spec_tint

    def channel(k):
        return (dielectric + metallic * lobes.schlick(base[k], wo_h, eta)
                + tinted * lobes.schlick(c[k] * r0_tint, wo_h, eta))

    return channel(0), channel(1), channel(2)


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf) of the mixture: the lobes above for wi on either side, and the pdf of ``sample``."""
    cos_o, cos_i = wo[2], wi[2]
    if not cos_o > 0.0 or cos_i == 0.0:
        return (0.0, 0.0, 0.0), 0.0
    front = params[row, INSIDE] == 0.0
    metallic, spec_trans = params[row, METALLIC], params[row, SPEC_TRANS]
    bsdf = (1.0 - metallic) * spec_trans
    if not front and not bsdf > 0.0:  # the inside of an interface that transmits nothing
        return (0.0, 0.0, 0.0), 0.0
    brdf = (1.0 - metallic) * (1.0 - spec_trans)
    eta = params[row, ETA]
    eta_path = eta if front else 1.0 / eta
    reflects = cos_i > 0.0
    h, wo_h, wi_h = lobes.half_vector(wo, wi, eta_path)
    fresnel = microfacet.fresnel_dielectric(wo_h, eta_path)
    alpha_u, alpha_v = lobes.alphas(params[row, ANISOTROPIC], params[row, ROUGHNESS])
    microfacet_reflection = reflects and wo_h > 0.0 and wi_h > 0.0
    microfacet_refraction = not reflects and wo_h > 0.0 and wi_h < 0.0
    p_reflection, p_transmission, p_clearcoat, p_diffuse = _lobe_probabilities(params, row, front, fresnel)
    base = rgb(params, row, BASE_COLOR)
    f = (0.0, 0.0, 0.0)  # a tuple, rebound as lobes add to it: a list would be allocated per call
    pdf = 0.0
    if microfacet_reflection or microfacet_refraction:
        d = microfacet.d_anisotropic(h, alpha_u, alpha_v, microfacet.GGX)
        g = lobes.ggx_masking(wo, h, alpha_u, alpha_v) * lobes.ggx_masking(wi, h, alpha_u, alpha_v)
        visible = lobes.visible_normal_pdf(wo, h, alpha_u, alpha_v)
        if microfacet_reflection:
            jacobian = 1.0 / (4.0 * wi_h)
            pdf += p_reflection * visible * jacobian
            if fresnel > 0.0:
                common = d * g / (4.0 * cos_o * cos_i)
                if front:
                    f = add_scaled(f, common, _principled_fresnel(params, row, base, fresnel, wo_h))
                else:
                    f = add_scaled(f, bsdf * fresnel * common, WHITE)
            if front:
                clearcoat = params[row, CLEARCOAT]
                gloss = params[row, CLEARCOAT_GLOSS]
                if clearcoat > 0.0:
                    f = add_scaled(f, lobes.clearcoat_value(wo, wi, h, clearcoat, gloss, eta), WHITE)
                pdf += p_clearcoat * lobes.gtr1_d(h, lobes.clearcoat_alpha(gloss)) * h[2] * jacobian
        else:
            denom = wo_h + eta_path * wi_h
            jacobian = eta_path * eta_path * abs(wi_h) / (denom * denom)
            pdf += p_transmission * visible * jacobian
            if bsdf > 0.0 and fresnel < 1.0:
                # Walter's refraction with the radiance's 1 / eta_path^2: the eta_path^2 of
                # the Jacobian cancels.
                value = bsdf * abs((1.0 - fresnel) * d * g * wo_h * wi_h / (cos_o * denom * denom))
                value /= abs(cos_i)
                f = add_scaled(f, value, (math.sqrt(base[0]), math.sqrt(base[1]), math.sqrt(base[2])))
    if reflects and front:
        pdf += p_diffuse * warp.cosine_hemisphere_pdf(cos_i)
        if brdf > 0.0:
            roughness = params[row, ROUGHNESS]
            cos_d = wi_h
            shape = lobes.diffuse_shape(cos_o, cos_i, cos_d, roughness, params[row, FLATNESS])
            f = add_scaled(f, brdf * warp.INV_PI * shape, base)
            sheen = params[row, SHEEN]
            if sheen > 0.0 and metallic < 1.0:
                weight = sheen * (1.0 - metallic) * lobes.schlick_weight(abs(cos_d))
                f = add_scaled(f, weight, lobes.sheen_colour(base, params[row, SHEEN_TINT]))
    return f, pdf


@jit
def _refract(wo, m, wo_m: float, eta: float):
    """``(wi, ok)``: wo refracted through the microfacet m (wo . m = ``wo_m`` > 0) into the side
    of relative index ``eta``; ok False under total internal reflection."""
    sin2_t = (1.0 - wo_m * wo_m) / (eta * eta)
    if sin2_t >= 1.0:
        return (0.0, 0.0, -1.0), False
    cos_t = math.sqrt(1.0 - sin2_t)
    c = wo_m / eta - cos_t
    return (c * m[0] - wo[0] / eta, c * m[1] - wo[1] / eta, c * m[2] - wo[2] / eta), True


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """A lobe by Mitsuba's probabilities, then its direction: a visible GGX normal reflected or
    refracted, a GTR1 normal reflected, or the cosine warp; weight = f |cos_i| / pdf of the
    mixture. Invalid (weight 0) where the direction leaves its lobe's side or a microfacet
    disagrees with the surface, as Mitsuba filters."""
    nothing = ((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0)
    if not wo[2] > 0.0:
        return nothing
    front = params[row, INSIDE] == 0.0
    if not front and not (1.0 - params[row, METALLIC]) * params[row, SPEC_TRANS] > 0.0:
        return nothing
    eta = params[row, ETA]
    eta_path = eta if front else 1.0 / eta
    alpha_u, alpha_v = lobes.alphas(params[row, ANISOTROPIC], params[row, ROUGHNESS])
    m = warp.ggx_visible_normal_anisotropic(wo, alpha_u, alpha_v, u0, u1)
    wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    fresnel = microfacet.fresnel_dielectric(wo_m, eta_path)
    p_reflection, p_transmission, p_clearcoat, p_diffuse = _lobe_probabilities(params, row, front, fresnel)
    lobe = GLOSSY
    if u_lobe < p_diffuse:
        wi = warp.cosine_hemisphere(u0, u1)
        lobe = DIFFUSE
        if not wi[2] > 0.0:
            return nothing
    elif u_lobe < p_diffuse + p_clearcoat:
        m = lobes.gtr1_sample(lobes.clearcoat_alpha(params[row, CLEARCOAT_GLOSS]), u0, u1)
        wi = lobes.reflect(wo, m)
        wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
        if not (wi[2] > 0.0 and wo_m > 0.0 and wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2] > 0.0):
            return nothing
    elif u_lobe < p_diffuse + p_clearcoat + p_transmission:
        if not wo_m > 0.0:
            return nothing
        wi, ok = _refract(wo, m, wo_m, eta_path)
        if not (ok and wi[2] < 0.0 and wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2] < 0.0):
            return nothing
    else:
        wi = lobes.reflect(wo, m)
        if not (wi[2] > 0.0 and wo_m > 0.0 and wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2] > 0.0):
            return nothing
    f, pdf = eval_pdf(params, row, wo, wi)
    return weighted(wi, f, pdf, lobe)


@jit
def lobe(params, row, wo):
    """The lobe proxy of product sampling (``tracer.lights.environment_product``): the specular
    reflection and clearcoat as one glossy lobe of alpha = roughness^2, the diffuse lobe, and
    the transmission as a uniform part, in the proportion this material chooses them at wo
    (the Fresnel term at the normal standing in for the one at the sampled microfacet). Seen
    from behind, uniform."""
    if params[row, INSIDE] != 0.0 or wo[2] <= 0.0:
        return 0.0, 0.0, 1.0, 1.0
    fresnel = microfacet.fresnel_dielectric(wo[2], params[row, ETA])
    reflection, transmission, clearcoat, diffuse = _lobe_probabilities(params, row, True, fresnel)
    roughness = params[row, ROUGHNESS]
    return diffuse, reflection + clearcoat, transmission, max(roughness * roughness, 1e-4)
