"""What ``principled`` and ``principledthin`` share: Burley's lobes as Mitsuba 3.9.1 writes them.

Burley, "Physically Based Shading at Disney" (SIGGRAPH 2012 course notes) and "Extending the
Disney BRDF to a BSDF with Integrated Subsurface Scattering" (2015) define the lobes; Mitsuba's
``src/bsdfs/principledhelpers.h``, ``principled.cpp`` and ``principledthin.cpp`` fix the details
that the notes leave open, and tracer follows those (formulas read there, code our own):

- the Schlick weight (1 - cos)^5 and Schlick's Fresnel R0 + (1 - R0) w, where w is taken at the
  transmitted angle when the light passes into the optically thinner side (``schlick``);
- roughness to GGX alphas: alpha = roughness^2, stretched by the aspect sqrt(1 - 0.9
  anisotropic) (alpha_u = r^2 / aspect, alpha_v = r^2 aspect), at least 0.001 (``alphas``);
- the clearcoat's GTR1 distribution (Burley 2012, appendix B), sampled by its D cos (not by
  visible normals), with a separable Smith GGX masking of fixed roughness 0.25;
- the diffuse lobe with retro-reflection and Hanrahan-Krueger's "fake subsurface" flattening,
  and the sheen (``diffuse_and_sheen``); tints normalize the base colour by its luminance.

Directions are tracer's: ``wo`` toward the viewer, ``wi`` toward the light (Mitsuba's ``si.wi``
and ``wo``), local to the shading frame. Every function here is a term of f without the cosine
of wi (Mitsuba's ``eval`` includes it; tracer's materials do not).
"""

from __future__ import annotations

import math

from ..jit import jit
from . import microfacet

# Rec. 709 luminance of linear RGB, as Mitsuba's ``luminance`` (include/mitsuba/core/spectrum.h).
LUMINANCE_R, LUMINANCE_G, LUMINANCE_B = 0.212671, 0.715160, 0.072169
# Mitsuba's lower bound on the GGX alphas of the principled lobes (``calc_dist_params``).
MIN_PRINCIPLED_ALPHA = 0.001
# The clearcoat's masking roughness (fixed, Burley 2012) and GTR1 roughness at gloss 0 and 1.
CLEARCOAT_MASKING_ALPHA = 0.25
CLEARCOAT_ALPHA_ROUGH, CLEARCOAT_ALPHA_GLOSSY = 0.1, 0.001


@jit
def schlick_weight(cos: float) -> float:
    """(1 - cos)^5, with 1 - cos clamped into [0, 1]."""
    m = min(max(1.0 - cos, 0.0), 1.0)
    return m * m * m * m * m


@jit
def schlick(r0: float, cos_i: float, eta: float) -> float:
    """Schlick's Fresnel R0 + (1 - R0) (1 - cos)^5 of light meeting a microfacet at ``cos_i``
    (> 0 from the outside) of an interface of relative index ``eta``. cos is cos_i where the
    light enters the denser side and the transmitted angle's cosine where it enters the thinner
    (0 beyond the critical angle: Fresnel 1), as Mitsuba's ``calc_schlick``."""
    eta_it = eta if cos_i >= 0.0 else 1.0 / eta
    if eta_it > 1.0:
        w = schlick_weight(abs(cos_i))
    else:
        eta_ti = 1.0 / eta_it
        cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti))
        w = schlick_weight(cos_t)
    return w * (1.0 - r0) + r0


@jit
def r0_of_eta(eta: float) -> float:
    """The reflectance at normal incidence of relative index eta: ((eta - 1) / (eta + 1))^2."""
    q = (eta - 1.0) / (eta + 1.0)
    return q * q


@jit
def tint(base):
    """The base colour over its luminance (its hue at luminance 1); white for a black base."""
    lum = LUMINANCE_R * base[0] + LUMINANCE_G * base[1] + LUMINANCE_B * base[2]
    if not lum > 0.0:
        return 1.0, 1.0, 1.0
    return base[0] / lum, base[1] / lum, base[2] / lum


@jit
def alphas(anisotropic: float, roughness: float):
    """``(alpha_u, alpha_v)``: the GGX roughness along s and t of Burley's roughness and
    anisotropy (Mitsuba's ``calc_dist_params``)."""
    r2 = roughness * roughness
    aspect = math.sqrt(1.0 - 0.9 * anisotropic)
    return max(MIN_PRINCIPLED_ALPHA, r2 / aspect), max(MIN_PRINCIPLED_ALPHA, r2 * aspect)


@jit
def ggx_masking(v, m, alpha_u: float, alpha_v: float) -> float:
    """Smith's GGX G1 of direction ``v`` (either side) for microfacet ``m``: 0 where v sees the
    back of m ((v . m) v.z <= 0), as Mitsuba's ``smith_g1``."""
    if (v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] <= 0.0:
        return 0.0
    cos = abs(v[2])
    return microfacet.g1(cos, microfacet.projected_alpha(v, alpha_u, alpha_v), microfacet.GGX)


@jit
def visible_normal_pdf(wo, m, alpha_u: float, alpha_v: float) -> float:
    """The density of microfacet normal ``m`` (m.z > 0) among the GGX normals visible from
    ``wo`` (wo.z > 0): G1(wo, m) |wo . m| D(m) / wo.z (Heitz 2018)."""
    if not m[2] > 0.0:
        return 0.0
    d = microfacet.d_anisotropic(m, alpha_u, alpha_v, microfacet.GGX)
    wo_m = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    return ggx_masking(wo, m, alpha_u, alpha_v) * abs(wo_m) * d / wo[2]


@jit
def gtr1_d(m, alpha: float) -> float:
    """Burley's GTR1 distribution (gamma = 1) of roughness ``alpha`` < 1: (alpha^2 - 1) /
    (pi ln(alpha^2) (1 + (alpha^2 - 1) cos^2 theta_m)), 0 for m below the surface."""
    if not m[2] > 0.0:
        return 0.0
    a2 = alpha * alpha
    return (a2 - 1.0) / (math.pi * math.log(a2) * (1.0 + (a2 - 1.0) * m[2] * m[2]))


@jit
def gtr1_sample(alpha: float, u0: float, u1: float):
    """A normal with density D(m) cos theta_m under GTR1: cos^2 theta = (1 - alpha^(2 (1 - u1)))
    / (1 - alpha^2), phi = 2 pi u0 (the inversion of Burley 2012, eq. 5)."""
    a2 = alpha * alpha
    cos2 = (1.0 - a2 ** (1.0 - u1)) / (1.0 - a2)
    cos = math.sqrt(max(0.0, cos2))
    sin = math.sqrt(max(0.0, 1.0 - cos2))
    phi = 2.0 * math.pi * u0
    return sin * math.cos(phi), sin * math.sin(phi), cos


@jit
def clearcoat_alpha(gloss: float) -> float:
    """The clearcoat's GTR1 roughness: 0.1 at gloss 0 down to 0.001 at gloss 1, linearly."""
    return CLEARCOAT_ALPHA_ROUGH * (1.0 - gloss) + CLEARCOAT_ALPHA_GLOSSY * gloss


@jit
def clearcoat_value(wo, wi, h, clearcoat: float, gloss: float, eta: float) -> float:
    """The clearcoat term of f (both directions above, h their half vector): clearcoat / 4 times
    Schlick's Fresnel of R0 = 0.04, GTR1 D and the fixed-roughness masking, as Mitsuba writes it
    (with no 1 / (4 cos_o cos_i): Mitsuba's clearcoat omits it, and tracer matches Mitsuba)."""
    wo_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    a = CLEARCOAT_MASKING_ALPHA
    g = ggx_masking(wi, h, a, a) * ggx_masking(wo, h, a, a)
    return 0.25 * clearcoat * schlick(0.04, wo_h, eta) * gtr1_d(h, clearcoat_alpha(gloss)) * g


@jit
def diffuse_shape(cos_o: float, cos_i: float, cos_d: float, roughness: float, flatness: float) -> float:
    """Burley's diffuse factor (times base / pi gives f): the Fresnel-shaped diffuse (1 - F_o /
    2)(1 - F_i / 2) plus retro-reflection R_r (F_o + F_i + F_o F_i (R_r - 1)), R_r = 2 roughness
    cos_d^2, blended toward the fake subsurface 1.25 (F_ss (1 / (cos_o + cos_i) - 1/2) + 1/2) by
    ``flatness``. cos_d: the half vector against the light direction."""
    f_view, f_light = schlick_weight(cos_o), schlick_weight(cos_i)
    diffuse = (1.0 - 0.5 * f_view) * (1.0 - 0.5 * f_light)
    rr = 2.0 * roughness * cos_d * cos_d
    retro = rr * (f_light + f_view + f_light * f_view * (rr - 1.0))
    if flatness == 0.0:
        return diffuse + retro
    fss90 = 0.5 * rr
    fss = (1.0 + (fss90 - 1.0) * f_light) * (1.0 + (fss90 - 1.0) * f_view)
    subsurface = 1.25 * (fss * (1.0 / (cos_i + cos_o) - 0.5) + 0.5)
    return (diffuse + retro) * (1.0 - flatness) + subsurface * flatness


@jit
def sheen_colour(base, sheen_tint: float):
    """The sheen's colour: white tinted toward the base colour's hue by ``sheen_tint``."""
    c = tint(base)
    return (1.0 + (c[0] - 1.0) * sheen_tint, 1.0 + (c[1] - 1.0) * sheen_tint,
            1.0 + (c[2] - 1.0) * sheen_tint)


@jit
def half_vector(wo, wi, eta_path: float):
    """The microfacet normal of a pair: normalize(wo + wi) for a reflection, normalize(wo + eta
    wi) for a refraction (wi below), turned to the upper side; and ``(wo . h, wi . h)``."""
    k = 1.0 if wi[2] > 0.0 else eta_path
    hx, hy, hz = wo[0] + k * wi[0], wo[1] + k * wi[1], wo[2] + k * wi[2]
    length = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not length > 0.0:
        return (0.0, 0.0, 1.0), 0.0, 0.0
    sign = 1.0 if hz >= 0.0 else -1.0
    h = (sign * hx / length, sign * hy / length, sign * hz / length)
    return (h, wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2], wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2])


@jit
def reflect(wo, m):
    """wo mirrored about the unit normal m."""
    c = 2.0 * (wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2])
    return c * m[0] - wo[0], c * m[1] - wo[1], c * m[2] - wo[2]
