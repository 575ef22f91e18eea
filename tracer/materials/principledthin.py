"""``principledthin``: Burley's thin-surface BSDF as Mitsuba 3.9.1 writes it
(src/bsdfs/principledthin.cpp): a sheet with no inside, the same from both sides.

Four lobes (``principled_lobes`` holds the shared terms and their sources); diff_trans is given
in [0, 2] and used halved, t = diff_trans / 2:

- specular reflection: GGX of the roughness, spec_trans F_thin D G / (4 cos_o cos_i), F_thin the
  dielectric Fresnel term of eta blended by spec_tint toward Schlick's of the tinted R0(eta);
- specular transmission straight through the sheet: wi is the reflected direction mirrored below,
  with GGX of the roughness scaled by (0.65 eta - 0.35) (Burley 2015's thin-surface
  approximation), spec_trans base_color (1 - F) D G / (4 cos_o |cos_i|);
- diffuse reflection: (1 - spec_trans)(1 - t) base_color / pi times Burley's diffuse, plus the
  sheen (1 - spec_trans)(1 - t) sheen (1 - cos_d)^5, tinted;
- diffuse transmission: (1 - spec_trans) t base_color / pi.

Sampling is Mitsuba's, by the probabilities spec_trans r_sr / 2, spec_trans r_st / 2, r_dr (1 -
spec_trans)(1 - t) and r_dt (1 - spec_trans) t (the four ``..._sampling_rate`` parameters r);
the weight is f |cos_i| / pdf of the mixture. Anisotropy is along s, dp/du (``oriented``).

====================================  ====  ============================================
parameter                             size  meaning
====================================  ====  ============================================
base_color                            3     in [0, 1] (default 0.5)
roughness                             1     in [0, 1] (default 0.5)
anisotropic, spec_trans, spec_tint    1     in [0, 1] (default 0)
sheen, sheen_tint, flatness           1     in [0, 1] (default 0)
diff_trans                            1     in [0, 2] (default 0)
eta                                   1     index of the sheet, in [1, 100] (default 1.5)
specular_reflectance_sampling_rate    1     >= 0 (default 1); likewise
specular_transmittance_sampling_rate        ``diffuse_reflectance_sampling_rate``
                                            and ``diffuse_transmittance_sampling_rate``
====================================  ====  ============================================
"""

from __future__ import annotations

from .. import warp
from ..frame import add_scaled
from ..jit import jit
from ..plugins import register
from . import microfacet
from . import principled_lobes as lobes
from .base import DIFFUSE, GLOSSY, MaterialType, Param, rgb, weighted
from .plastic import MAX_IOR
from .principled import MAX_SAMPLING_RATE, WHITE

CODE = 13  # the dispatch code (``tracer.materials``)
RATES = ("specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
         "diffuse_reflectance_sampling_rate", "diffuse_transmittance_sampling_rate")


def _unit(name: str, doc: str, default: float = 0.0) -> Param:
    return Param(name, 1, lo=0.0, hi=1.0, default=default, texture=True, doc=doc)


TYPE = register(MaterialType(
    module=__name__, rank=CODE, name="principledthin", code=CODE, lobes=GLOSSY | DIFFUSE,
    doc="Burley's thin principled BSDF (Mitsuba's): a sheet that reflects and transmits",
    params=(Param("base_color", 3, lo=0.0, hi=1.0, default=0.5, texture=True, doc="base colour"),
            _unit("roughness", "Burley's roughness (alpha = roughness^2)", 0.5),
            _unit("anisotropic", "anisotropy of the specular lobes (along s, dp/du)"),
            _unit("spec_trans", "weight of the specular lobes (reflection and transmission)"),
            _unit("spec_tint", "tint of the specular reflection toward base_color"),
            _unit("sheen", "sheen at grazing angles"),
            _unit("sheen_tint", "tint of the sheen toward base_color"),
            _unit("flatness", "blend of the diffuse toward the fake subsurface"),
            Param("diff_trans", 1, lo=0.0, hi=2.0, default=0.0, texture=True,
                  doc="diffuse transmission, 0 to 2 (halved: the fraction of the diffuse transmitted)"),
            Param("eta", 1, lo=1.0, hi=MAX_IOR, default=1.5, texture=True, doc="index of the sheet"),
            *(Param(name, 1, lo=0.0, hi=MAX_SAMPLING_RATE, default=1.0, doc="weight in lobe selection")
              for name in RATES)),
    transmits=True, oriented=lambda values: float(values["anisotropic"]) > 0.0))
(BASE_COLOR, ROUGHNESS, ANISOTROPIC, SPEC_TRANS, SPEC_TINT, SHEEN, SHEEN_TINT, FLATNESS, DIFF_TRANS,
 ETA) = (TYPE.column(n) for n in ("base_color", "roughness", "anisotropic", "spec_trans", "spec_tint",
                                  "sheen", "sheen_tint", "flatness", "diff_trans", "eta"))
RATE_SR, RATE_ST, RATE_DR, RATE_DT = (TYPE.column(n) for n in RATES)


@jit
def _lobe_probabilities(params, row):
    """``(specular reflection, specular transmission, diffuse reflection, diffuse
    transmission)`` choice probabilities, summing to 1 (all 0 if every rate is 0)."""
    spec_trans, t = params[row, SPEC_TRANS], 0.5 * params[row, DIFF_TRANS]
    reflection = 0.5 * spec_trans * params[row, RATE_SR]
    transmission = 0.5 * spec_trans * params[row, RATE_ST]
    diffuse = params[row, RATE_DR] * (1.0 - spec_trans) * (1.0 - t)
    diffuse_transmission = params[row, RATE_DT] * (1.0 - spec_trans) * t
    total = reflection + transmission + diffuse + diffuse_transmission
    if not total > 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return reflection / total, transmission / total, diffuse / total, diffuse_transmission / total


@jit
def _transmission_alphas(params, row):
    """The GGX alphas of the transmission: of the roughness scaled by 0.65 eta - 0.35."""
    scaled = (0.65 * params[row, ETA] - 0.35) * params[row, ROUGHNESS]
    return lobes.alphas(params[row, ANISOTROPIC], scaled)


@jit
def eval_pdf(params, row, wo, wi):
    """(f, pdf) of the mixture for wi on either side, and the pdf of ``sample``."""
    cos_o, cos_i = wo[2], wi[2]
    if not cos_o > 0.0 or cos_i == 0.0:
        return (0.0, 0.0, 0.0), 0.0
    reflects = cos_i > 0.0
    spec_trans, t = params[row, SPEC_TRANS], 0.5 * params[row, DIFF_TRANS]
    eta = params[row, ETA]
    base = rgb(params, row, BASE_COLOR)
    # The half vector of wo and wi mirrored above: a transmission is a reflection sent through.
    h, wo_h, wi_r_h = lobes.half_vector(wo, (wi[0], wi[1], abs(wi[2])), 1.0)
    wi_h = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]
    p_reflection, p_transmission, p_diffuse, p_diffuse_transmission = _lobe_probabilities(params, row)
    f = (0.0, 0.0, 0.0)  # a tuple, rebound as lobes add to it: a list would be allocated per call
    pdf = 0.0
    if spec_trans > 0.0 and wo_h > 0.0 and ((reflects and wi_h > 0.0) or (not reflects and wi_h < 0.0)):
        fresnel = microfacet.fresnel_dielectric(wo_h, eta)
        jacobian = 1.0 / (4.0 * abs(wi_r_h))
        if reflects:
            alpha_u, alpha_v = lobes.alphas(params[row, ANISOTROPIC], params[row, ROUGHNESS])
        else:
            alpha_u, alpha_v = _transmission_alphas(params, row)
        d = microfacet.d_anisotropic(h, alpha_u, alpha_v, microfacet.GGX)
        g = lobes.ggx_masking(wo, h, alpha_u, alpha_v) * lobes.ggx_masking(wi, h, alpha_u, alpha_v)
        common = spec_trans * d * g / (4.0 * cos_o * abs(cos_i))
        visible = lobes.visible_normal_pdf(wo, h, alpha_u, alpha_v) * jacobian
        if reflects:
            pdf += p_reflection * visible
            spec_tint = params[row, SPEC_TINT]
            f = add_scaled(f, fresnel * (1.0 - spec_tint) * common, WHITE)
            if spec_tint > 0.0:
                c = lobes.tint(base)
                r0 = lobes.r0_of_eta(eta)
                f = add_scaled(f, spec_tint * common, (lobes.schlick(c[0] * r0, wo_h, eta),
                                                       lobes.schlick(c[1] * r0, wo_h, eta),
                                                       lobes.schlick(c[2] * r0, wo_h, eta)))
        else:
            pdf += p_transmission * visible
            f = add_scaled(f, (1.0 - fresnel) * common, base)
    if reflects:
        pdf += p_diffuse * warp.cosine_hemisphere_pdf(cos_i)
        if spec_trans < 1.0 and t < 1.0:
            weight = (1.0 - spec_trans) * (1.0 - t)
            shape = lobes.diffuse_shape(cos_o, cos_i, wi_h, params[row, ROUGHNESS], params[row, FLATNESS])
            f = add_scaled(f, weight * warp.INV_PI * shape, base)
            sheen = params[row, SHEEN]
            if sheen > 0.0:
                s = weight * sheen * lobes.schlick_weight(abs(wi_h))
                f = add_scaled(f, s, lobes.sheen_colour(base, params[row, SHEEN_TINT]))
    else:
        pdf += p_diffuse_transmission * warp.cosine_hemisphere_pdf(-cos_i)
        if spec_trans < 1.0 and t > 0.0:
            f = add_scaled(f, (1.0 - spec_trans) * t * warp.INV_PI, base)
    return f, pdf


@jit
def sample(params, row, wo, u_lobe, u0, u1):
    """A lobe by Mitsuba's probabilities, then its direction: a visible GGX normal reflected (and
    for the transmission, mirrored below), or the cosine warp above or below; weight = f |cos_i|
    / pdf of the mixture. Invalid where a microfacet disagrees with the surface."""
    nothing = ((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0)
    if not wo[2] > 0.0:
        return nothing
    p_reflection, p_transmission, p_diffuse, p_diffuse_transmission = _lobe_probabilities(params, row)
    lobe = GLOSSY
    if u_lobe < p_reflection + p_transmission:
        through = u_lobe >= p_reflection
        if through:
            alpha_u, alpha_v = _transmission_alphas(params, row)
        else:
            alpha_u, alpha_v = lobes.alphas(params[row, ANISOTROPIC], params[row, ROUGHNESS])
        m = warp.ggx_visible_normal_anisotropic(wo, alpha_u, alpha_v, u0, u1)
        wi = lobes.reflect(wo, m)
        if through:
            wi = (wi[0], wi[1], -wi[2])
        wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
        wi_m = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2]
        if not wo_m > 0.0 or (through and not (wi[2] < 0.0 and wi_m < 0.0)) \
                or (not through and not (wi[2] > 0.0 and wi_m > 0.0)):
            return nothing
    elif u_lobe < p_reflection + p_transmission + p_diffuse:
        wi = warp.cosine_hemisphere(u0, u1)
        lobe = DIFFUSE
    elif p_diffuse_transmission > 0.0:
        up = warp.cosine_hemisphere(u0, u1)
        wi = (up[0], up[1], -up[2])
        lobe = DIFFUSE
    else:
        return nothing
    f, pdf = eval_pdf(params, row, wo, wi)
    return weighted(wi, f, pdf, lobe)
