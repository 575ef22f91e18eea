"""Warps from the unit square to directions and points, each beside its pdf.

Every routine comes as a pair ``x(u0, u1, ...) -> value`` and ``x_pdf(value, ...) -> p``
(Nori's ``squareToX``/``squareToXPdf``, pbrt-v4's ``SampleX``/``XPDF``). A pdf is a pure
function of its arguments, so MIS may evaluate one technique's pdf on another's samples.

The per-lane functions take and return floats and ``(x, y, z)`` tuples and are compiled
(``tracer.jit``) for the estimator's kernels. Below them, array versions with the same
names prefixed ``sample_``/``pdf_`` run the very same compiled code over batches, for tests
and the primer: ``u`` is ``(n, 2)`` in [0, 1)^2, directions ``(n, 3)`` unit vectors, pdfs
``(n,)``, all float64, with respect to solid angle unless the name says area.

Directions live in a local frame whose z axis is the shading normal.
"""

from __future__ import annotations

import math

import numpy as np

from .jit import jit

INV_PI = 1.0 / math.pi
INV_2PI = 0.5 / math.pi


# ---------------------------------------------------------------------------------------------
# Per-lane warps


@jit
def uniform_hemisphere(u0: float, u1: float):
    """Uniform direction on the hemisphere z >= 0."""
    z = u0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u1
    return (r * math.cos(phi), r * math.sin(phi), z)


@jit
def uniform_hemisphere_pdf(z: float) -> float:
    """Solid-angle pdf of :func:`uniform_hemisphere` at a direction with cos(theta) = z."""
    return INV_2PI if z > 0.0 else 0.0


@jit
def cosine_hemisphere(u0: float, u1: float):
    """Cosine-weighted direction on z >= 0 (Malley's method: a uniform point on the unit disk,
    by the polar map r = sqrt(u0), lifted to the hemisphere)."""
    r = math.sqrt(u0)
    phi = 2.0 * math.pi * u1
    return (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - u0)))


@jit
def cosine_hemisphere_pdf(z: float) -> float:
    """Solid-angle pdf of :func:`cosine_hemisphere`: cos(theta) / pi where z > 0."""
    return max(z, 0.0) * INV_PI


@jit
def concentric_disk(u0: float, u1: float):
    """Uniform point (x, y) of the unit disk, Shirley and Chiu's concentric map ("A low
    distortion map between disk and square", 1997): squares around the centre go to rings, so
    strata of the square stay compact on the disk. pdf 1 / pi (area)."""
    a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r, phi = a, 0.25 * math.pi * (b / a)
    else:
        r, phi = b, 0.5 * math.pi - 0.25 * math.pi * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@jit
def triangle_barycentric(u0: float, u1: float):
    """Uniform barycentrics ``(b1, b2)``; the point is ``v0 + b1 (v1 - v0) + b2 (v2 - v0)``.
    Heitz's 2019 low-distortion square-to-triangle map: the smaller coordinate is offset to fold
    the square's two halves onto the triangle, so nearby ``u`` give nearby points."""
    if u1 > u0:
        return u0 * 0.5, u1 - u0 * 0.5
    return u0 - u1 * 0.5, u1 * 0.5


@jit
def ggx_sigma(cos: float, alpha: float) -> float:
    """cos(theta) sqrt(1 + alpha^2 tan^2 theta) = sqrt(alpha^2 + (1 - alpha^2) cos^2), the term
    through which Smith's GGX masking enters every formula here (Heitz 2014, JCGT 3(2), eq. 86:
    Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2)."""
    a2 = alpha * alpha
    return math.sqrt(a2 + (1.0 - a2) * cos * cos)


@jit
def ggx_g1(cos: float, alpha: float) -> float:
    """Smith masking G1 = 1 / (1 + Lambda) = 2 cos / (cos + sigma) of a direction with
    cos(theta) = ``cos``; 0 where cos <= 0."""
    return 2.0 * cos / (cos + ggx_sigma(cos, alpha)) if cos > 0.0 else 0.0


@jit
def ggx_d(cos_h: float, alpha: float) -> float:
    """GGX (Trowbridge-Reitz) normal distribution D(h) for cos(theta_h) = ``cos_h``:
    alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2), normalized so that the integral of D(h) cos(theta_h)
    over the hemisphere is 1 (Walter et al. 2007, eq. 33)."""
    return ggx_d_cos2(cos_h * cos_h, alpha) if cos_h > 0.0 else 0.0


@jit
def ggx_d_cos2(cos2_h: float, alpha: float) -> float:
    """:func:`ggx_d` from cos^2(theta_h), for a half vector known to point up."""
    a2 = alpha * alpha
    denom = cos2_h * (a2 - 1.0) + 1.0
    return a2 / (math.pi * denom * denom)


@jit
def ggx_visible_normal(wo, alpha: float, u0: float, u1: float):
    """A half vector h distributed as the GGX normals visible from local ``wo`` (wo.z > 0):
    density D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z in solid angle (Heitz 2018, JCGT 7(4)).

    Dupuy and Benyoub's spherical-cap form of Heitz's method (2023, "Sampling Visible GGX Normals
    with Spherical Caps", CGF 42(8)): in the stretched configuration, where the microsurface is a unit
    hemisphere, the visible normals are (a uniform point on the spherical cap z >= -v.z) + v,
    normalized, with v the stretched wo; unstretching gives h. Same distribution as Heitz's
    disk construction, with no basis to build.
    """
    return ggx_visible_normal_anisotropic(wo, alpha, alpha, u0, u1)


@jit
def ggx_visible_normal_anisotropic(wo, alpha_x: float, alpha_y: float, u0: float, u1: float):
    """:func:`ggx_visible_normal` of the anisotropic GGX of roughness ``alpha_x`` along local x
    and ``alpha_y`` along y: the stretch is (alpha_x, alpha_y, 1) (Heitz 2018 works in it)."""
    # Stretch wo.
    vx, vy, vz = alpha_x * wo[0], alpha_y * wo[1], wo[2]
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx * inv, vy * inv, vz * inv
    # Uniform point on the cap of the unit sphere above z = -vz.
    phi = 2.0 * math.pi * u0
    z = (1.0 - u1) * (1.0 + vz) - vz
    sin_theta = math.sqrt(max(0.0, 1.0 - z * z))
    # Visible normal in the stretched configuration, then unstretched and normalized.
    hx = alpha_x * (sin_theta * math.cos(phi) + vx)
    hy = alpha_y * (sin_theta * math.sin(phi) + vy)
    hz = max(z + vz, 0.0)
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    return (hx * inv, hy * inv, hz * inv)


@jit
def ggx_visible_normal_pdf(h, wo, alpha: float) -> float:
    """Solid-angle density of h under :func:`ggx_visible_normal`."""
    if wo[2] <= 0.0:
        return 0.0
    wo_dot_h = max(wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2], 0.0)
    return ggx_g1(wo[2], alpha) * wo_dot_h * ggx_d(h[2], alpha) / wo[2]


# ---------------------------------------------------------------------------------------------
# The same warps over arrays (tests, primer)


def sample_uniform_hemisphere(u: np.ndarray) -> np.ndarray:
    """``u (n, 2)`` -> uniform directions ``(n, 3)``."""
    return _hemisphere_lanes(False, u)


def pdf_uniform_hemisphere(w: np.ndarray) -> np.ndarray:
    """``w (n, 3)`` -> ``(n,)`` pdf of :func:`sample_uniform_hemisphere`."""
    return _hemisphere_pdf_lanes(False, w)


def sample_cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """``u (n, 2)`` -> cosine-weighted directions ``(n, 3)``."""
    return _hemisphere_lanes(True, u)


def pdf_cosine_hemisphere(w: np.ndarray) -> np.ndarray:
    """``w (n, 3)`` -> ``(n,)`` pdf of :func:`sample_cosine_hemisphere`."""
    return _hemisphere_pdf_lanes(True, w)


@jit
def _hemisphere_lanes(cosine: bool, u: np.ndarray) -> np.ndarray:
    out = np.empty((len(u), 3))
    for i in range(len(u)):
        w = cosine_hemisphere(u[i, 0], u[i, 1]) if cosine else uniform_hemisphere(u[i, 0], u[i, 1])
        out[i, 0], out[i, 1], out[i, 2] = w
    return out


@jit
def _hemisphere_pdf_lanes(cosine: bool, w: np.ndarray) -> np.ndarray:
    out = np.empty(len(w))
    for i in range(len(w)):
        out[i] = cosine_hemisphere_pdf(w[i, 2]) if cosine else uniform_hemisphere_pdf(w[i, 2])
    return out


@jit
def sample_triangle_barycentric(u: np.ndarray) -> np.ndarray:
    """``u (n, 2)`` -> uniform barycentrics ``(n, 2)`` (area pdf = 1 / area)."""
    out = np.empty((len(u), 2))
    for i in range(len(u)):
        out[i, 0], out[i, 1] = triangle_barycentric(u[i, 0], u[i, 1])
    return out


@jit
def sample_concentric_disk(u: np.ndarray) -> np.ndarray:
    """``u (n, 2)`` -> uniform points of the unit disk ``(n, 2)`` (area pdf = 1 / pi)."""
    out = np.empty((len(u), 2))
    for i in range(len(u)):
        out[i, 0], out[i, 1] = concentric_disk(u[i, 0], u[i, 1])
    return out


@jit
def sample_ggx_visible_normal(u: np.ndarray, wo: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``u (n, 2)``, local ``wo (n, 3)`` with wo.z > 0, ``alpha (n,)`` -> unit h ``(n, 3)``."""
    out = np.empty((len(u), 3))
    for i in range(len(u)):
        out[i, 0], out[i, 1], out[i, 2] = ggx_visible_normal(
            (wo[i, 0], wo[i, 1], wo[i, 2]), alpha[i], u[i, 0], u[i, 1])
    return out


@jit
def pdf_ggx_visible_normal(h: np.ndarray, wo: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``(n,)`` density of half vectors ``h (n, 3)`` under :func:`sample_ggx_visible_normal`."""
    out = np.empty(len(h))
    for i in range(len(h)):
        out[i] = ggx_visible_normal_pdf((h[i, 0], h[i, 1], h[i, 2]), (wo[i, 0], wo[i, 1], wo[i, 2]),
                                        alpha[i])
    return out


@jit
def ggx_g1_array(w: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``(n,)`` G1(w) of unit directions ``w (n, 3)``, ``alpha (n,)``."""
    out = np.empty(len(w))
    for i in range(len(w)):
        out[i] = ggx_g1(w[i, 2], alpha[i])
    return out
