"""Significance levels and tests shared by the statistical tests.

Every statistical test in this suite runs at a family-wise false-alarm rate of 1% (per test
function), split over its m comparisons with the Sidak correction
alpha_1 = 1 - (1 - alpha)^(1/m), so that a correct tracer fails a test function with
probability at most 1% whatever m is; the seeds are fixed, so a pass is reproducible.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

FAMILY_ALPHA = 0.01


def sidak(m: int, alpha: float = FAMILY_ALPHA) -> float:
    """Per-comparison significance level for m independent comparisons."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(m, 1))


def z_critical(m: int, alpha: float = FAMILY_ALPHA) -> float:
    """Two-sided normal critical value after the Sidak correction over m comparisons."""
    return float(stats.norm.isf(sidak(m, alpha) / 2.0))


def mean_and_se(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean and its standard error along axis 0."""
    n = samples.shape[0]
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(n)


def t_test_mean(samples: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Two-sided one-sample Student t-test p-values of the mean of ``samples`` (axis 0)."""
    return stats.ttest_1samp(samples, expected, axis=0).pvalue


def image_mean_and_se(film) -> tuple[np.ndarray, np.ndarray]:
    """Mean over pixels of a film's image per channel, and its standard error.

    Pixels are independent, so Var(mean) = sum_p Var(pixel_p) / P^2 with
    Var(pixel_p) = variance_p / count_p (the film's per-sample variance over its count).
    """
    p = len(film.count)
    var_pixel = film.variance() / np.maximum(film.count, 1)[:, None]
    return film.mean.mean(axis=0), np.sqrt(var_pixel.sum(axis=0)) / p
