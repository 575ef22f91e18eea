"""BSDFs on batches: Lambertian diffuse, GGX rough conductor, ideal mirror.

All directions are in the local shading frame (z = normal flipped toward the viewer, so
``wo.z > 0``: materials are two-sided). ``wo`` points toward the viewer, ``wi`` toward the
light (pbrt's convention). ``eval`` returns f without the cosine; the estimator multiplies
|cos theta_i| where the rendering equation has it. Each lane carries its own material
parameters, so one batch may mix materials; work is split by kind with index arrays.

Measures: ``pdf`` is with respect to solid angle of ``wi``. A delta BSDF (the mirror) has
``eval = 0`` and ``pdf = 0`` for every direction (no other technique can hit its lobe) and
reports its samples with ``delta = True``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import warp

# Material kinds; ``NONE`` is the black material of shapes that name none.
NONE, DIFFUSE, ROUGH_CONDUCTOR, MIRROR = 0, 1, 2, 3
KIND_NAMES = {"diffuse": DIFFUSE, "roughconductor": ROUGH_CONDUCTOR, "mirror": MIRROR}


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
    """Per-lane material parameters. kind (n,) int8, reflectance (n, 3), alpha (n,) float64."""

    kind: np.ndarray
    reflectance: np.ndarray
    alpha: np.ndarray

    def take(self, idx: np.ndarray) -> "Bsdf":
        """The materials of lanes ``idx`` (or rows of a material table)."""
        return Bsdf(self.kind[idx], self.reflectance[idx], self.alpha[idx])

    def _lanes(self, kind: int) -> np.ndarray | slice | None:
        """The lanes of one kind: ``slice(None)`` when every lane is of it (no gather or scatter
        copies), None when none is, else their indices."""
        mask = self.kind == kind
        if mask.all():
            return slice(None)
        return np.flatnonzero(mask) if mask.any() else None

    @property
    def delta(self) -> np.ndarray:
        """(n,) bool: the lane's BSDF is a delta distribution."""
        return self.kind == MIRROR

    def eval(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """f(wo, wi) without the cosine, ``(n, 3)``; zero below the surface and for delta."""
        f = np.zeros((len(self.kind), 3))
        d = self._lanes(DIFFUSE)
        if d is not None:
            f[d] = self.reflectance[d] * (warp.INV_PI * (wi[d, 2] > 0.0))[:, None]
        r = self._lanes(ROUGH_CONDUCTOR)
        if r is not None:  # _ggx_value is 0 below the surface
            f[r] = self.reflectance[r] * _ggx_value(wo[r], wi[r], self.alpha[r])[:, None]
        return f

    def pdf(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` picks ``wi``, ``(n,)``; 0 for delta."""
        pdf = np.zeros(len(self.kind))
        d = self._lanes(DIFFUSE)
        if d is not None:
            pdf[d] = warp.pdf_cosine_hemisphere(wi[d])
        r = self._lanes(ROUGH_CONDUCTOR)
        if r is not None:
            pdf[r] = _ggx_pdf(wo[r], wi[r], self.alpha[r])
        return pdf

    def sample(self, u: np.ndarray, wo: np.ndarray) -> BsdfSample:
        """Importance-sample ``wi`` given ``wo``, with ``u (n, 2)`` in [0, 1)^2."""
        n = len(self.kind)
        wi = np.zeros((n, 3))
        weight = np.zeros((n, 3))
        pdf = np.zeros(n)

        d = self._lanes(DIFFUSE)
        if d is not None:
            wi[d] = warp.sample_cosine_hemisphere(u[d])
            pdf[d] = warp.pdf_cosine_hemisphere(wi[d])
            # f cos / pdf = (R / pi) cos / (cos / pi) = R, wherever the sample is above the surface.
            weight[d] = self.reflectance[d] * (pdf[d] > 0.0)[:, None]

        r = self._lanes(ROUGH_CONDUCTOR)
        if r is not None:
            wo_r, alpha = wo[r], self.alpha[r]
            h = warp.sample_ggx_visible_normal(u[r], wo_r, alpha)
            wi_r = warp.reflect(wo_r, h)
            wi[r] = wi_r
            pdf[r] = _ggx_pdf(wo_r, wi_r, alpha)
            # With separable Smith G and VNDF sampling, f cos / pdf reduces to R G1(wi).
            weight[r] = self.reflectance[r] * warp.ggx_g1(wi_r, alpha)[:, None]
            weight[r] *= (pdf[r] > 0.0)[:, None]

        m = self._lanes(MIRROR)
        if m is not None:
            wi[m] = wo[m] * np.array([-1.0, -1.0, 1.0])
            weight[m] = self.reflectance[m]
        return BsdfSample(wi=wi, weight=weight, pdf=pdf, delta=self.delta.copy())


def _ggx_value(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """D(h) G1(wo) G1(wi) / (4 cos_o cos_i): the GGX microfacet BRDF with Fresnel = 1."""
    h = wo + wi
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    cos_o, cos_i = wo[:, 2], wi[:, 2]
    value = warp.ggx_d(h, alpha) * warp.ggx_g1(wo, alpha) * warp.ggx_g1(wi, alpha)
    return np.where((cos_o > 0.0) & (cos_i > 0.0), value / (4.0 * cos_o * np.maximum(cos_i, 1e-300)), 0.0)


def _ggx_pdf(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """pdf of wi = reflect(wo, h) with h ~ visible normals: D_wo(h) / (4 wo.h)."""
    h = wo + wi
    norm = np.linalg.norm(h, axis=1, keepdims=True)
    h /= np.where(norm > 0.0, norm, 1.0)
    wo_dot_h = np.sum(wo * h, axis=1)
    valid = (wi[:, 2] > 0.0) & (wo_dot_h > 0.0)
    pdf_h = warp.pdf_ggx_visible_normal(h, wo, alpha)
    return np.where(valid, pdf_h / (4.0 * np.where(valid, wo_dot_h, 1.0)), 0.0)
