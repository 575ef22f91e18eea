"""Warps from the unit square to directions and points, each beside its pdf.

Every routine comes as a pair ``sample_x(u, ...) -> values`` and ``pdf_x(values, ...) -> p``
(Nori's ``squareToX``/``squareToXPdf``, pbrt-v4's ``SampleX``/``XPDF``). A pdf is a pure
function of its arguments, so MIS may evaluate one technique's pdf on another's samples.

Directions live in a local frame whose z axis is the shading normal. Arrays are float64:
``u`` is ``(n, 2)`` in [0, 1)^2, directions are ``(n, 3)`` unit vectors, pdfs are ``(n,)``
with respect to solid angle unless the name says area.
"""

from __future__ import annotations

import numpy as np

INV_PI = 1.0 / np.pi
INV_2PI = 0.5 / np.pi


def sample_uniform_hemisphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the hemisphere z >= 0. ``u (n, 2)`` -> ``(n, 3)``."""
    z = u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def pdf_uniform_hemisphere(w: np.ndarray) -> np.ndarray:
    """Solid-angle pdf of :func:`sample_uniform_hemisphere`: 1/(2 pi) where z > 0."""
    return np.where(w[:, 2] > 0.0, INV_2PI, 0.0)


def sample_cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on z >= 0 (Malley's method: a uniform point on the unit disk,
    by the polar map r = sqrt(u0), lifted to the hemisphere). ``(n, 2)`` -> ``(n, 3)``."""
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    out = np.empty((len(u), 3))
    out[:, 0] = r * np.cos(phi)
    out[:, 1] = r * np.sin(phi)
    out[:, 2] = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
    return out


def pdf_cosine_hemisphere(w: np.ndarray) -> np.ndarray:
    """Solid-angle pdf of :func:`sample_cosine_hemisphere`: cos(theta)/pi where z > 0."""
    return np.maximum(w[:, 2], 0.0) * INV_PI


def sample_triangle_barycentric(u: np.ndarray) -> np.ndarray:
    """Uniform barycentrics ``(b1, b2)`` on a triangle, ``(n, 2)``; the point is
    ``v0 + b1 (v1 - v0) + b2 (v2 - v0)``. Uses Heitz's 2019 low-distortion square-to-triangle
    map, so nearby ``u`` give nearby points (area pdf = 1 / area)."""
    u0 = u[:, 0]
    u1 = u[:, 1]
    lower = u1 > u0
    # Offset the smaller coordinate: fold the square's two halves onto the triangle.
    half = np.where(lower, u0, u1) * 0.5
    b1 = np.where(lower, u0 * 0.5, u0 - half)
    b2 = np.where(lower, u1 - half, u1 * 0.5)
    return np.stack([b1, b2], axis=1)


def _ggx_lambda_tan2(alpha: np.ndarray, cos2: np.ndarray) -> np.ndarray:
    """Smith's Lambda for GGX from cos^2(theta): (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    tan2 = np.maximum(1.0 - cos2, 0.0) / np.maximum(cos2, 1e-300)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def ggx_g1(w: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith masking G1(w) for GGX, ``w (n, 3)`` local, ``alpha (n,)``; 0 where w.z <= 0."""
    cos = w[:, 2]
    g1 = 1.0 / (1.0 + _ggx_lambda_tan2(alpha, cos * cos))
    return np.where(cos > 0.0, g1, 0.0)


def ggx_d(h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """GGX (Trowbridge-Reitz) normal distribution D(h), ``h (n, 3)`` local unit half vectors.

    D = alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2), normalized so that the integral of
    D(h) cos(theta_h) over the hemisphere is 1 (Walter et al. 2007, eq. 33).
    """
    cos2 = h[:, 2] * h[:, 2]
    a2 = alpha * alpha
    denom = cos2 * (a2 - 1.0) + 1.0
    return np.where(h[:, 2] > 0.0, a2 / (np.pi * denom * denom), 0.0)


def sample_ggx_visible_normal(u: np.ndarray, wo: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Half vectors h distributed as the GGX normals visible from ``wo`` (Heitz 2018, JCGT 7(4)).

    ``wo (n, 3)`` local with wo.z > 0, ``alpha (n,)``. Returns ``(n, 3)`` unit h with density
    D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z with respect to solid angle of h.
    """
    # Stretch wo to the configuration where the microsurface is a unit hemisphere.
    vh = np.stack([alpha * wo[:, 0], alpha * wo[:, 1], wo[:, 2]], axis=1)
    vh /= np.linalg.norm(vh, axis=1, keepdims=True)
    # Orthonormal basis (vh, t1, t2); t1 is perpendicular to vh in the xy-plane.
    len2 = vh[:, 0] ** 2 + vh[:, 1] ** 2
    inv_len = np.where(len2 > 0.0, 1.0 / np.sqrt(np.maximum(len2, 1e-300)), 0.0)
    t1 = np.stack(
        [np.where(len2 > 0.0, -vh[:, 1] * inv_len, 1.0), np.where(len2 > 0.0, vh[:, 0] * inv_len, 0.0),
         np.zeros_like(len2)],
        axis=1,
    )
    t2 = np.cross(vh, t1)
    # Uniform point on the disk, then squash its upper half into the projected visible area.
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * vh
    # Unstretch back to the ellipsoid configuration.
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def pdf_ggx_visible_normal(h: np.ndarray, wo: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Solid-angle density of h under :func:`sample_ggx_visible_normal`."""
    cos_o = wo[:, 2]
    dot = np.maximum(np.sum(wo * h, axis=1), 0.0)
    safe_cos = np.where(cos_o > 0.0, cos_o, 1.0)
    return np.where(cos_o > 0.0, ggx_g1(wo, alpha) * dot * ggx_d(h, alpha) / safe_cos, 0.0)


def reflect(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror ``w (n, 3)`` about unit normals ``n (n, 3)`` (or the local z axis if n is (3,))."""
    return 2.0 * np.sum(w * n, axis=-1, keepdims=True) * n - w
