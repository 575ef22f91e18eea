"""Significance levels and the image-mean z-test, one definition for every study tool and test.

Every statistical check here runs at a family-wise false-alarm rate ``alpha`` (1% unless said)
split over its m comparisons with the Sidak correction: each comparison runs at

    alpha_1 = 1 - (1 - alpha)^(1/m),

so that m independent comparisons of a correct tracer all pass with probability 1 - alpha.
The argument order is always ``(alpha, m)``.

The image-mean test compares the mean over pixels of an image with a reference's, channel by
channel. Pixels are independent, so the variance of the image mean is the sum of the pixel
variances over P^2. Channels are kept apart because one sample's R, G and B errors are almost
perfectly correlated: pooling them as independent would understate the standard error by up to
sqrt(3). Used by ``check`` and ``stability`` and by the tests (``tests/stats.py``).

scipy is imported inside the functions that need it, so importing this module stays cheap.
"""

from __future__ import annotations

import numpy as np

FAMILY_ALPHA = 0.01


def sidak(alpha: float, m: int) -> float:
    """Per-comparison level for ``m`` independent comparisons at family-wise rate ``alpha``:
    1 - (1 - alpha)^(1/m). m < 1 counts as one comparison."""
    # expm1/log1p keep the digits for small alpha, where 1 - (1 - alpha)^(1/m) cancels.
    return float(-np.expm1(np.log1p(-alpha) / max(int(m), 1)))


def sidak_family(p: float, m: int) -> float:
    """The family-wise p-value of the smallest of ``m`` independent p-values when it is ``p``:
    1 - (1 - p)^m (the inverse of :func:`sidak`). Rejecting when it is below alpha is the same
    as rejecting when ``p < sidak(alpha, m)``."""
    p = min(max(float(p), 0.0), 1.0)
    if p >= 1.0:
        return 1.0
    return float(-np.expm1(max(int(m), 1) * np.log1p(-p)))


def z_critical(alpha: float, m: int = 1, sides: int = 2) -> float:
    """The normal critical value for ``m`` comparisons at family-wise rate ``alpha`` after
    Sidak: |z| above it (``sides=2``) or z above it (``sides=1``) rejects."""
    from scipy import stats

    if sides not in (1, 2):
        raise ValueError(f"sides must be 1 or 2, got {sides!r}")
    return float(stats.norm.isf(sidak(alpha, m) / sides))


def two_sided_p(z: np.ndarray | float) -> np.ndarray:
    """Two-sided normal p-values 2 P(Z > |z|), elementwise (1 at z = 0, 0 at infinite z)."""
    from scipy import stats

    return 2.0 * stats.norm.sf(np.abs(z))


def image_mean_and_se(mean: np.ndarray, var_of_mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image mean per channel and its standard error, both ``(3,)``.

    mean : (P, 3) pixel means.   var_of_mean : (P, 3) variance of each pixel mean (a film's
    per-sample variance over its count, ``Film.variance_of_mean``).
    """
    p = len(mean)
    return mean.mean(axis=0), np.sqrt(var_of_mean.sum(axis=0)) / p


def image_mean_z(
    mean: np.ndarray, var_of_mean: np.ndarray, ref_mean: np.ndarray, ref_var_of_mean: np.ndarray
) -> np.ndarray:
    """Per-channel z-scores ``(3,)`` of an image mean against a reference's.

    All inputs are ``(P, 3)``: pixel means and the variances of the pixel means, of the image
    and of the reference (same P). Where both variances vanish, z is 0 for means within
    1e-12 of each other and infinite otherwise.
    """
    m, se = image_mean_and_se(mean, var_of_mean)
    ref_m, ref_se = image_mean_and_se(ref_mean, ref_var_of_mean)
    diff = m - ref_m
    sd = np.hypot(se, ref_se)
    return np.where(sd > 0, diff / np.where(sd > 0, sd, 1.0), np.where(np.abs(diff) < 1e-12, 0.0, np.inf))


def worst_channel(z: np.ndarray) -> float:
    """The z of the channel with the largest |z| (its sign kept)."""
    return float(z[int(np.argmax(np.abs(z)))])


def worst_channel_p(z: np.ndarray) -> float:
    """The two-sided p-value of the worst channel of ``z (3,)``, Sidak-combined over the
    channels: the family p-value of the three per-channel tests."""
    return sidak_family(float(two_sided_p(worst_channel(z))), len(z))
