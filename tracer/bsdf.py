"""BSDFs: Lambertian diffuse, GGX rough conductor, ideal mirror.

All directions are in the local shading frame (z = normal flipped toward the viewer, so
``wo.z > 0``: materials are two-sided). ``wo`` points toward the viewer, ``wi`` toward the
light (pbrt's convention). Every material's f is its RGB reflectance times a scalar
*shape* that depends on the directions alone, so the per-lane functions work with the shape
and the caller multiplies the reflectance in. ``shape`` is f without the cosine; the
estimator multiplies |cos theta_i| where the rendering equation has it.

Measures: ``pdf`` is with respect to solid angle of ``wi``. A delta BSDF (the mirror) has
shape 0 and pdf 0 for every direction (no other technique can hit its lobe) and reports its
samples with ``delta = True``.

The per-lane functions are compiled (``tracer.jit``) for the estimator's kernels; the
``Bsdf`` class runs the same code over batches with per-lane materials (tests, tools).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import warp
from .jit import jit

# Material kinds; ``NONE`` is the black material of shapes that name none.
NONE, DIFFUSE, ROUGH_CONDUCTOR, MIRROR = 0, 1, 2, 3
KIND_NAMES = {"diffuse": DIFFUSE, "roughconductor": ROUGH_CONDUCTOR, "mirror": MIRROR}


# ---------------------------------------------------------------------------------------------
# Per-lane functions


@jit
def _cos2_half(wo, wi) -> float:
    """cos^2 of the half vector h = normalize(wo + wi), without the square root."""
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    return hz * hz / (hx * hx + hy * hy + hz * hz)


@jit
def ggx_value_and_pdf(wo, wi, alpha: float):
    """The GGX microfacet BRDF with Fresnel = 1, f = D(h) G1(wo) G1(wi) / (4 cos_o cos_i), and the
    pdf of sampling wi = reflect(wo, h) with h ~ visible normals, D_wo(h) / (4 wo.h) =
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
def shape_and_pdf(kind: int, alpha: float, wo, wi):
    """``(shape, pdf)``: f(wo, wi) / reflectance without the cosine (0 below the surface and for
    delta), and the solid-angle pdf with which :func:`sample` picks ``wi`` (0 for delta).
    Together because MIS needs both and they share most of their work."""
    if kind == DIFFUSE:
        return (warp.INV_PI if wi[2] > 0.0 else 0.0), warp.cosine_hemisphere_pdf(wi[2])
    if kind == ROUGH_CONDUCTOR:
        return ggx_value_and_pdf(wo, wi, alpha)
    return 0.0, 0.0


@jit
def shape(kind: int, alpha: float, wo, wi) -> float:
    """f(wo, wi) / reflectance, without the cosine (see :func:`shape_and_pdf`)."""
    return shape_and_pdf(kind, alpha, wo, wi)[0]


@jit
def pdf(kind: int, alpha: float, wo, wi) -> float:
    """Solid-angle pdf with which :func:`sample` picks ``wi`` (see :func:`shape_and_pdf`)."""
    return shape_and_pdf(kind, alpha, wo, wi)[1]


@jit
def sample(kind: int, alpha: float, wo, u0: float, u1: float):
    """Importance-sample ``wi`` given ``wo``. Returns ``(wi, weight, pdf, delta)``: weight is
    shape |cos theta_i| / pdf (1 for a delta sample; 0 if the sample is invalid)."""
    if kind == DIFFUSE:
        wi = warp.cosine_hemisphere(u0, u1)
        p = warp.cosine_hemisphere_pdf(wi[2])
        # shape cos / pdf = (1 / pi) cos / (cos / pi) = 1 wherever the sample is above the surface.
        return wi, (1.0 if p > 0.0 else 0.0), p, False
    if kind == ROUGH_CONDUCTOR:
        h = warp.ggx_visible_normal(wo, alpha, u0, u1)
        wo_dot_h = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        wi = (2.0 * wo_dot_h * h[0] - wo[0], 2.0 * wo_dot_h * h[1] - wo[1], 2.0 * wo_dot_h * h[2] - wo[2])
        if wi[2] <= 0.0 or wo_dot_h <= 0.0:
            return wi, 0.0, 0.0, False
        # The pdf through the very function that evaluates it for other techniques' samples (from
        # h itself it differs in rounding, by 1e-3 at alpha = 1e-6: MIS weights would not sum to
        # one). With separable Smith G and visible-normal sampling, shape cos / pdf is G1(wi).
        p = ggx_value_and_pdf(wo, wi, alpha)[1]
        return wi, (warp.ggx_g1(wi[2], alpha) if p > 0.0 else 0.0), p, False
    if kind == MIRROR:
        return (-wo[0], -wo[1], wo[2]), 1.0, 0.0, True
    return (0.0, 0.0, 1.0), 0.0, 0.0, False


# ---------------------------------------------------------------------------------------------
# Batches


@dataclass
class BsdfSample:
    """Result of :meth:`Bsdf.sample`; every field has one row per lane.

    wi : (n, 3) local unit direction toward the light.
    weight : (n, 3) f |cos theta_i| / pdf, or the reflectance for a delta sample; 0 if invalid.
    pdf : (n,) solid-angle pdf of ``wi``; 0 for delta samples and invalid ones.
    delta : (n,) bool, the sample came from a delta lobe.
    """

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray


@dataclass
class Bsdf:
    """Per-lane material parameters (or a scene's material table, one row per material).
    kind (n,) int8, reflectance (n, 3), alpha (n,) float64."""

    kind: np.ndarray
    reflectance: np.ndarray
    alpha: np.ndarray

    def take(self, idx: np.ndarray) -> "Bsdf":
        """The materials of lanes ``idx`` (or rows of a material table)."""
        return Bsdf(self.kind[idx], self.reflectance[idx], self.alpha[idx])

    @property
    def delta(self) -> np.ndarray:
        """(n,) bool: the lane's BSDF is a delta distribution."""
        return self.kind == MIRROR

    def eval(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """f(wo, wi) without the cosine, ``(n, 3)``; zero below the surface and for delta."""
        return self.reflectance * _shape_or_pdf(0, self.kind, self.alpha, wo, wi)[:, None]

    def pdf(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` picks ``wi``, ``(n,)``; 0 for delta."""
        return _shape_or_pdf(1, self.kind, self.alpha, wo, wi)

    def sample(self, u: np.ndarray, wo: np.ndarray) -> BsdfSample:
        """Importance-sample ``wi`` given ``wo (n, 3)``, with ``u (n, 2)`` in [0, 1)^2."""
        wi, weight, p, delta = _sample_lanes(self.kind, self.alpha, wo, u)
        return BsdfSample(wi, self.reflectance * weight[:, None], p, delta)


@jit
def _shape_or_pdf(which: int, kind, alpha, wo, wi) -> np.ndarray:
    out = np.empty(len(kind))
    for i in range(len(kind)):
        o, w = (wo[i, 0], wo[i, 1], wo[i, 2]), (wi[i, 0], wi[i, 1], wi[i, 2])
        out[i] = shape(kind[i], alpha[i], o, w) if which == 0 else pdf(kind[i], alpha[i], o, w)
    return out


@jit
def _sample_lanes(kind, alpha, wo, u):
    n = len(kind)
    wi, weight, p, delta = np.empty((n, 3)), np.empty(n), np.empty(n), np.empty(n, dtype=np.bool_)
    for i in range(n):
        w, weight[i], p[i], delta[i] = sample(kind[i], alpha[i], (wo[i, 0], wo[i, 1], wo[i, 2]),
                                             u[i, 0], u[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
    return wi, weight, p, delta
