"""Microfacet distributions (GGX and Beckmann), Fresnel terms and the math of the rough materials.

Both distributions are isotropic or, for ``roughconductor``, anisotropic (the section of that
name), with Smith's separable masking-shadowing
G(wo, wi) = G1(wo) G1(wi), and are sampled by their visible normals: h has the solid-angle
density D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z (Heitz 2018, "Sampling the GGX distribution of
visible normals", JCGT 7(4)), so wi = reflect(wo, h) has pdf D_wo(h) / (4 wo.h) = G1(wo) D(h) /
(4 wo.z) and the sample weight f cos / pdf of a reflector is F G1(wi).

- GGX: ``tracer.warp`` (D, G1 and the spherical-cap sampler).
- Beckmann: D(h) = exp(-tan^2 theta_h / alpha^2) / (pi alpha^2 cos^4 theta_h); Smith's
  Lambda = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2 with a = 1 / (alpha tan theta), exact (Mitsuba
  3 uses Walter et al.'s rational fit of G1 instead, which differs by up to ~0.3%); visible normals
  by Heitz and d'Eon's slope method (2014, "Importance sampling microfacet-based BSDFs using the
  distribution of visible normals", CGF 33(4)): in the configuration stretched to alpha = 1 the
  visible slopes separate; the one along wo is found by inverting its CDF (closed form in erf)
  with safeguarded Newton steps, the other is a Gaussian drawn by an inverse error function.

Fresnel terms are the exact unpolarized ones: a dielectric interface of relative index eta
(transmitted over incident side), and a conductor of complex index eta + i k (Born and Wolf;
pbrt-v4 sec. 9.3 writes both out). ``eta = 0, k = 1`` reflects everything (F = 1 exactly), which
is Mitsuba's ``material="none"``.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from .. import warp
from ..jit import jit, jit_called
from .base import DIFFUSE, GLOSSY

GGX, BECKMANN = 0, 1
# The roughness a scene may give. Down to MIN_ALPHA every value, weight and pdf of both
# distributions is finite (measured at grazing, normal and random directions: GGX's stop being
# finite below 1e-8), a margin of 100; Mitsuba clamps at 1e-4 (the XML reader does too).
MIN_ALPHA, MAX_ALPHA = 1e-6, 10.0
DISTRIBUTIONS = ("ggx", "beckmann")
SQRT_PI = math.sqrt(math.pi)


# ---------------------------------------------------------------------------------------------
# Fresnel


@jit
def fresnel_dielectric(cos_i: float, eta: float) -> float:
    """Unpolarized reflectance of light arriving at cos_i (> 0: from the outside) on an interface
    whose inside has relative index ``eta``; 1 under total internal reflection."""
    if cos_i < 0.0:  # from the inside: the interface seen the other way round
        eta, cos_i = 1.0 / eta, -cos_i
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin2_t)
    r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return 0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)


@jit_called
def fresnel_conductor(cos_i: float, eta: float, k: float) -> float:
    """Unpolarized reflectance of a conductor of complex relative index n = eta + i k at cos_i.

    Written with w = n cos_t = sqrt(n^2 - sin^2 theta_i) (the principal root: Re w >= 0, the
    wave that enters), so that no step divides by n: r_s = (cos_i - w) / (cos_i + w) and
    r_p = (n^2 cos_i - w) / (n^2 cos_i + w), the usual forms (pbrt-v4 sec. 9.3) multiplied
    through by n. The textbook form divided by n^2 and failed at eta = k = 0 (complex division
    by zero); this one gives F -> 1 there, its limit, and agrees with it to 1e-14 elsewhere."""
    cos_i = min(max(cos_i, 0.0), 1.0)
    n2 = complex(eta, k) * complex(eta, k)
    w = cmath.sqrt(n2 - (1.0 - cos_i * cos_i))
    # |a / b|^2 as |a|^2 / |b|^2: for eta = 0, k = 1 both are the same sums of squares, so F = 1.
    a, b = n2 * cos_i - w, n2 * cos_i + w
    c, d = cos_i - w, cos_i + w
    b2, d2 = b.real * b.real + b.imag * b.imag, d.real * d.real + d.imag * d.imag
    # b = 0 or d = 0 only where n = 0 meets cos_i = 1 (or cos_i = 0): the limit there is 1.
    parallel = (a.real * a.real + a.imag * a.imag) / b2 if b2 > 0.0 else 1.0
    perpendicular = (c.real * c.real + c.imag * c.imag) / d2 if d2 > 0.0 else 1.0
    return 0.5 * (parallel + perpendicular)


def diffuse_fresnel_reflectance(eta: float, nodes: int = 400) -> float:
    """Fdr(eta) = 2 integral_0^1 F(mu, eta) mu dmu, the reflectance of the interface for light
    arriving uniformly over the hemisphere (cosine-weighted), by Gauss-Legendre quadrature above
    the critical cosine mu_c (below it F = 1), in s with mu = mu_c + (1 - mu_c) s^2, which
    removes F's square-root singularity at mu_c. Accurate to ~1e-13; Mitsuba 3 uses
    polynomial fits (Egan and Hilgeman 1973; d'Eon and Irving 2011) within ~0.1% of it."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    critical = math.sqrt(max(0.0, 1.0 - eta * eta)) if eta < 1.0 else 0.0
    s = 0.5 * (x + 1.0)
    mu = critical + (1.0 - critical) * s * s
    values = fresnel_dielectric_array(mu, float(eta))
    jacobian = 2.0 * (1.0 - critical) * s * 0.5  # dmu/ds times ds/dx
    return critical * critical + 2.0 * float(np.sum(w * values * mu * jacobian))


# ---------------------------------------------------------------------------------------------
# Distributions


@jit_called
def erfinv(y: float) -> float:
    """The inverse error function on (-1, 1): a rational first guess (Giles 2012, "Approximating
    the erfinv function", GPU Computing Gems; single precision, and coarser beyond
    1 - |y| = 1e-7) refined by Newton steps (on erf, or on erfc near +-1) to double precision;
    +-inf at +-1."""
    if y <= -1.0:
        return -math.inf
    if y >= 1.0:
        return math.inf
    w = -math.log((1.0 - y) * (1.0 + y))
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        for c in (3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087, -0.00125372503,
                  -0.00417768164, 0.246640727, 1.50140941):
            p = c + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        for c in (0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773, -0.0076224613,
                  0.00943887047, 1.00167406, 2.83297682):
            p = c + p * w
    x = abs(p * y)
    a = abs(y)
    for _ in range(12):  # Newton: erf'(x) = 2 exp(-x^2) / sqrt(pi); two steps but in the far tail
        slope = 2.0 / SQRT_PI * math.exp(-x * x)
        if not slope > 0.0:
            break
        # Near |y| = 1 on erfc(x) = 1 - |y| (exact in floating point there), whose relative
        # precision erf(x) = |y| lacks.
        step = ((math.erf(x) - a) if a < 0.5 else (1.0 - a) - math.erfc(x)) / slope
        x -= step
        if abs(step) <= 1e-15 * x:
            break
    return math.copysign(x, y)


@jit
def beckmann_d_cos2(cos2_h: float, alpha: float) -> float:
    """Beckmann D(h) from cos^2(theta_h) > 0."""
    a2 = alpha * alpha
    tan2 = (1.0 - cos2_h) / cos2_h
    return math.exp(-tan2 / a2) / (math.pi * a2 * cos2_h * cos2_h)


@jit_called
def beckmann_lambda(cos: float, alpha: float) -> float:
    """Smith's Lambda of Beckmann for a direction with cos(theta) = ``cos`` in (0, 1]."""
    sin = math.sqrt(max(0.0, 1.0 - cos * cos))
    if sin == 0.0:
        return 0.0
    a = cos / (alpha * sin)
    if a > 26.0:  # erfc and exp(-a^2) underflow together; Lambda < 1e-295
        return 0.0
    return 0.5 * (math.exp(-a * a) / (a * SQRT_PI) - math.erfc(a))


@jit
def d_cos2(cos2_h: float, alpha: float, distribution: int) -> float:
    """D(h) of either distribution from cos^2(theta_h), for h above the surface."""
    if distribution == BECKMANN:
        return beckmann_d_cos2(cos2_h, alpha)
    return warp.ggx_d_cos2(cos2_h, alpha)


@jit
def g1(cos: float, alpha: float, distribution: int) -> float:
    """Smith's masking G1 of a direction with cos(theta) = ``cos``; 0 where cos <= 0."""
    if cos <= 0.0:
        return 0.0
    if distribution == BECKMANN:
        return 1.0 / (1.0 + beckmann_lambda(cos, alpha))
    return warp.ggx_g1(cos, alpha)


# Half the spacing of a sampler's numbers: samplers give u in [0, 1) in steps of 2^-53.
HALF_STEP = 2.0**-54


@jit
def open_unit(u: float) -> float:
    """u in [0, 1) moved into (0, 1): 0 becomes HALF_STEP. A Gaussian drawn by erfinv(2u - 1)
    is then finite (about -5.9 sigma at most) where u = 0 gave -inf and a NaN normal; u = 0 has
    probability 2^-53, so the shift changes no distribution measurably."""
    return max(u, HALF_STEP)


@jit
def _beckmann_slope_cdf(t: float, tan_theta: float, erf_cot: float, exp_cot: float) -> float:
    """Unnormalized CDF of the visible slope t (along the stretched wo, alpha = 1), whose density
    is (1 + t tan theta) exp(-t^2) / sqrt(pi) on t > -cot theta."""
    return 0.5 * (math.erf(t) + erf_cot) + tan_theta / (2.0 * SQRT_PI) * (exp_cot - math.exp(-t * t))


@jit
def beckmann_visible_normal(wo, alpha: float, u0: float, u1: float):
    """A half vector h distributed as the Beckmann normals visible from local ``wo`` (wo.z > 0)."""
    return beckmann_visible_normal_anisotropic(wo, alpha, alpha, u0, u1)


@jit_called
def beckmann_visible_normal_anisotropic(wo, alpha_x: float, alpha_y: float, u0: float, u1: float):
    """:func:`beckmann_visible_normal` of roughness ``alpha_x`` along local x and ``alpha_y``
    along y: the slopes are stretched by (alpha_x, alpha_y)."""
    # Stretch wo to the alpha = 1 configuration.
    vx, vy, vz = alpha_x * wo[0], alpha_y * wo[1], wo[2]
    length = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / length, vy / length, vz / length
    sin_theta = math.sqrt(vx * vx + vy * vy)
    # Slope t along wo's azimuth (m = normalize(t, ., 1) leans toward wo for t > 0).
    if sin_theta < 1e-12:
        t = erfinv(2.0 * open_unit(u0) - 1.0)
        cos_phi, sin_phi = 1.0, 0.0
    else:
        cos_phi, sin_phi = vx / sin_theta, vy / sin_theta
        tan_theta = sin_theta / vz
        cot_theta = vz / sin_theta
        erf_cot, exp_cot = math.erf(cot_theta), math.exp(-cot_theta * cot_theta)
        target = u0 * _beckmann_slope_cdf(math.inf, tan_theta, erf_cot, exp_cot)
        lo, hi = max(-cot_theta, -9.0), 9.0
        t = 0.0 if lo < 0.0 else 0.5 * (lo + hi)
        for _ in range(100):
            value = _beckmann_slope_cdf(t, tan_theta, erf_cot, exp_cot) - target
            if value > 0.0:
                hi = t
            else:
                lo = t
            density = (1.0 + t * tan_theta) * math.exp(-t * t) / SQRT_PI
            step = value / density if density > 0.0 else math.inf
            new = t - step
            if not (lo < new < hi):  # Newton left the bracket: bisect
                new = 0.5 * (lo + hi)
            if abs(new - t) <= 1e-14 * (1.0 + abs(t)) or hi - lo <= 1e-14 * (1.0 + abs(t)):
                t = new
                break
            t = new
    s = erfinv(2.0 * open_unit(u1) - 1.0)
    # Rotate to wo's azimuth, unstretch the slopes, and form the normal.
    mx = alpha_x * (cos_phi * t - sin_phi * s)
    my = alpha_y * (sin_phi * t + cos_phi * s)
    inv = 1.0 / math.sqrt(mx * mx + my * my + 1.0)
    return (mx * inv, my * inv, inv)


@jit
def visible_normal(wo, alpha: float, distribution: int, u0: float, u1: float):
    """A half vector from the visible normals of either distribution."""
    if distribution == BECKMANN:
        return beckmann_visible_normal(wo, alpha, u0, u1)
    return warp.ggx_visible_normal(wo, alpha, u0, u1)


@jit
def half_cos2(wo, wi) -> float:
    """cos^2 of the half vector h = normalize(wo + wi), without the square root."""
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    return hz * hz / (hx * hx + hy * hy + hz * hz)


@jit
def wo_dot_half(wo, wi) -> float:
    """wo . h for h = normalize(wo + wi) (= wi . h): the cosine the Fresnel term takes."""
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    length = math.sqrt(hx * hx + hy * hy + hz * hz)
    return (wo[0] * hx + wo[1] * hy + wo[2] * hz) / length if length > 0.0 else 0.0


@jit
def reflection_value_and_pdf(wo, wi, alpha: float, distribution: int):
    """``(D G1(wo) G1(wi) / (4 cos_o cos_i), G1(wo) D / (4 cos_o))``: the microfacet reflector
    without Fresnel, and the pdf of wi = reflect(wo, h) with h from the visible normals. Both 0
    unless wo and wi are above the surface. GGX takes the sigma form of ``warp`` (the cosines
    cancel: f = D / ((cos_o + sigma_o)(cos_i + sigma_i)), pdf = D / (2 (cos_o + sigma_o)))."""
    cos_o, cos_i = wo[2], wi[2]
    if cos_o <= 0.0 or cos_i <= 0.0:
        return 0.0, 0.0
    d = d_cos2(half_cos2(wo, wi), alpha, distribution)
    if distribution == BECKMANN:
        g1_o = 1.0 / (1.0 + beckmann_lambda(cos_o, alpha))
        g1_i = 1.0 / (1.0 + beckmann_lambda(cos_i, alpha))
        p = g1_o * d / (4.0 * cos_o)
        return p * g1_i / cos_i, p
    outgoing = cos_o + warp.ggx_sigma(cos_o, alpha)
    return d / (outgoing * (cos_i + warp.ggx_sigma(cos_i, alpha))), d / (2.0 * outgoing)


@jit
def sample_reflection(wo, alpha: float, distribution: int, u0: float, u1: float):
    """``(wi, pdf, g1_i)``: wi = reflect(wo, h) with h from the visible normals, its pdf (through
    :func:`reflection_value_and_pdf`, the very function other techniques' samples are weighted
    with, so MIS weights sum to one) and G1(wi); pdf 0 if wi falls below the surface."""
    h = visible_normal(wo, alpha, distribution, u0, u1)
    wo_dot_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    wi = (2.0 * wo_dot_h * h[0] - wo[0], 2.0 * wo_dot_h * h[1] - wo[1], 2.0 * wo_dot_h * h[2] - wo[2])
    if wi[2] <= 0.0 or wo_dot_h <= 0.0:
        return wi, 0.0, 0.0
    p = reflection_value_and_pdf(wo, wi, alpha, distribution)[1]
    if not p > 0.0:
        return wi, 0.0, 0.0
    return wi, p, g1(wi[2], alpha, distribution)


# ---------------------------------------------------------------------------------------------
# Anisotropic roughness: alpha_x along the shading frame's s (local x), alpha_y along t (y)
#
# Heitz 2014 ("Understanding the masking-shadowing function in microfacet-based BRDFs", JCGT
# 3(2), sec. 5.3): stretching the microsurface by (alpha_x, alpha_y) maps it to the isotropic
# alpha = 1 one, so D has the slope term (h_x / alpha_x)^2 + (h_y / alpha_y)^2 in place of
# tan^2 / alpha^2, and a direction's Lambda is the isotropic one at its projected roughness
# (``projected_alpha``). Mitsuba 3.9.1 (include/mitsuba/render/microfacet.h) writes D, G1 and
# the visible-normal warp the same way.


@jit
def projected_alpha(w, alpha_x: float, alpha_y: float) -> float:
    """The roughness the direction ``w`` (local, unit) sees: sqrt(alpha_x^2 cos^2 phi +
    alpha_y^2 sin^2 phi); alpha_x along the normal itself, where phi has no meaning and Lambda
    is 0 whatever it is."""
    sin2 = w[0] * w[0] + w[1] * w[1]
    if not sin2 > 0.0:
        return alpha_x
    return math.sqrt((alpha_x * alpha_x * w[0] * w[0] + alpha_y * alpha_y * w[1] * w[1]) / sin2)


@jit
def d_anisotropic(h, alpha_x: float, alpha_y: float, distribution: int) -> float:
    """D(h) of either distribution for a unit half vector h above the surface."""
    x2 = (h[0] / alpha_x) * (h[0] / alpha_x)
    y2 = (h[1] / alpha_y) * (h[1] / alpha_y)
    z2 = h[2] * h[2]
    if distribution == BECKMANN:
        return math.exp(-(x2 + y2) / z2) / (math.pi * alpha_x * alpha_y * z2 * z2)
    denom = x2 + y2 + z2
    return 1.0 / (math.pi * alpha_x * alpha_y * denom * denom)


@jit
def anisotropic_value_and_pdf(wo, wi, alpha_x: float, alpha_y: float, distribution: int):
    """:func:`reflection_value_and_pdf` of the anisotropic distribution: ``(D G1(wo) G1(wi) /
    (4 cos_o cos_i), G1(wo) D / (4 cos_o))``, both 0 unless wo and wi are above the surface."""
    cos_o, cos_i = wo[2], wi[2]
    if cos_o <= 0.0 or cos_i <= 0.0:
        return 0.0, 0.0
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    length = math.sqrt(hx * hx + hy * hy + hz * hz)
    d = d_anisotropic((hx / length, hy / length, hz / length), alpha_x, alpha_y, distribution)
    g1_o = g1(cos_o, projected_alpha(wo, alpha_x, alpha_y), distribution)
    g1_i = g1(cos_i, projected_alpha(wi, alpha_x, alpha_y), distribution)
    p = g1_o * d / (4.0 * cos_o)
    return p * g1_i / cos_i, p


@jit
def sample_anisotropic_reflection(wo, alpha_x: float, alpha_y: float, distribution: int, u0: float,
                                  u1: float):
    """:func:`sample_reflection` of the anisotropic distribution: ``(wi, pdf, g1_i)``."""
    if distribution == BECKMANN:
        h = beckmann_visible_normal_anisotropic(wo, alpha_x, alpha_y, u0, u1)
    else:
        h = warp.ggx_visible_normal_anisotropic(wo, alpha_x, alpha_y, u0, u1)
    wo_dot_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    wi = (2.0 * wo_dot_h * h[0] - wo[0], 2.0 * wo_dot_h * h[1] - wo[1], 2.0 * wo_dot_h * h[2] - wo[2])
    if wi[2] <= 0.0 or wo_dot_h <= 0.0:
        return wi, 0.0, 0.0
    p = anisotropic_value_and_pdf(wo, wi, alpha_x, alpha_y, distribution)[1]
    if not p > 0.0:
        return wi, 0.0, 0.0
    return wi, p, g1(wi[2], projected_alpha(wi, alpha_x, alpha_y), distribution)


@jit
def reflection_or_cosine(wo, alpha: float, distribution: int, p_reflection: float, u_lobe: float, u0: float,
                         u1: float):
    """``(wi, lobe)``: the direction of a two-lobe material (``roughplastic``, ``pplastic``),
    which weights it by the pdf of its mixture. With probability ``p_reflection`` wi reflects
    about a visible normal (lobe ``GLOSSY``), else it comes from the cosine warp (``DIFFUSE``);
    lobe 0 where the reflection falls below the surface."""
    if u_lobe < p_reflection:
        wi, pdf_reflection, _ = sample_reflection(wo, alpha, distribution, u0, u1)
        return wi, (GLOSSY if pdf_reflection > 0.0 else 0)
    return warp.cosine_hemisphere(u0, u1), DIFFUSE


# ---------------------------------------------------------------------------------------------
# Batch versions (tests, tables)


@jit
def sample_visible_normals(u: np.ndarray, wo: np.ndarray, alpha: np.ndarray, distribution: int) -> np.ndarray:
    """``u (n, 2)``, local ``wo (n, 3)`` (wo.z > 0), ``alpha (n,)`` -> unit h ``(n, 3)``."""
    out = np.empty((len(u), 3))
    for i in range(len(u)):
        out[i, 0], out[i, 1], out[i, 2] = visible_normal((wo[i, 0], wo[i, 1], wo[i, 2]), alpha[i],
                                                         distribution, u[i, 0], u[i, 1])
    return out


@jit
def visible_normal_pdf(h: np.ndarray, wo: np.ndarray, alpha: np.ndarray, distribution: int) -> np.ndarray:
    """``(n,)`` density G1(wo) max(0, wo.h) D(h) / wo.z of half vectors ``h (n, 3)``."""
    out = np.empty(len(h))
    for i in range(len(h)):
        cos_h = h[i, 2]
        dot_oh = wo[i, 0] * h[i, 0] + wo[i, 1] * h[i, 1] + wo[i, 2] * h[i, 2]
        if cos_h <= 0.0 or dot_oh <= 0.0 or wo[i, 2] <= 0.0:
            out[i] = 0.0
            continue
        out[i] = (g1(wo[i, 2], alpha[i], distribution) * dot_oh
                  * d_cos2(cos_h * cos_h, alpha[i], distribution) / wo[i, 2])
    return out


@jit
def dielectric_albedo(cos_o: float, alpha: float, distribution: int, eta: float, nodes: int,
                      transmitted: bool) -> float:
    """The energy a rough dielectric interface of relative index ``eta`` reflects (R) or, with
    ``transmitted``, lets through toward the inside (T), for light arriving at cos_o, as Mitsuba
    3 defines both for its rough plastic: expectations over h from the visible normals of
    F(wo.h) G1(wi), wi the reflection of wo about h, and of (1 - F(wo.h)) G1(wt), wt its
    refraction (masked when it leaves on the wrong side of h), so that T < 1 - R: the refracted
    light is shadowed too. By a midpoint rule of ``nodes`` x ``nodes`` points on the sampler's
    unit square (both integrands vanish with G1 at the horizon: the rule converges as
    1 / nodes^2)."""
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    wo = (sin_o, 0.0, cos_o)
    total = 0.0
    for a in range(nodes):
        for b in range(nodes):
            h = visible_normal(wo, alpha, distribution, (a + 0.5) / nodes, (b + 0.5) / nodes)
            cos_i = wo[0] * h[0] + wo[2] * h[2]
            if cos_i <= 0.0:
                continue
            if not transmitted:
                wi_z = 2.0 * cos_i * h[2] - cos_o
                if wi_z > 0.0:
                    total += fresnel_dielectric(cos_i, eta) * g1(wi_z, alpha, distribution)
                continue
            cos2_t = 1.0 - (1.0 - cos_i * cos_i) / (eta * eta)
            if cos2_t <= 0.0:  # total internal reflection: nothing passes
                continue
            # wt = -wo / eta + (cos_i / eta - cos_t) h, the refracted direction (below).
            k = cos_i / eta - math.sqrt(cos2_t)
            wt_z = -wo[2] / eta + k * h[2]
            wt_dot_h = -cos_i / eta + k
            if wt_z >= 0.0 or wt_dot_h >= 0.0:
                continue
            total += (1.0 - fresnel_dielectric(cos_i, eta)) * g1(-wt_z, alpha, distribution)
    return total / (nodes * nodes)


@jit
def fresnel_conductor_array(cos: np.ndarray, eta: float, k: float) -> np.ndarray:
    """(n,) :func:`fresnel_conductor` at each cosine (tests)."""
    out = np.empty(len(cos))
    for i in range(len(cos)):
        out[i] = fresnel_conductor(cos[i], eta, k)
    return out


@jit
def fresnel_dielectric_array(cos: np.ndarray, eta: float) -> np.ndarray:
    """(n,) :func:`fresnel_dielectric` at each cosine (tests)."""
    out = np.empty(len(cos))
    for i in range(len(cos)):
        out[i] = fresnel_dielectric(cos[i], eta)
    return out
