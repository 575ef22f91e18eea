"""Test-side shorthands for ``tracer.study.statistics`` at the suite's 1% family rate.

Every statistical test in this suite runs at a family-wise false-alarm rate of 1% (per test
function), split over its m comparisons with the Sidak correction, so that a correct tracer
fails a test function with probability at most 1% whatever m is; the seeds are fixed, so a
pass is reproducible. The definitions live in ``tracer.study.statistics``, whose argument order
is ``(alpha, m)``; the shorthands here take m first and ``alpha`` only by keyword, so that
``sidak(m)`` reads as "the level for m comparisons" and a swapped call cannot pass silently.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from tracer.study import statistics
from tracer.study.statistics import FAMILY_ALPHA

__all__ = ["FAMILY_ALPHA", "image_mean_and_se", "sidak", "t_test_mean", "z_critical"]


def sidak(m: int, *, alpha: float = FAMILY_ALPHA) -> float:
    """Per-comparison level for m independent comparisons: ``statistics.sidak(alpha, m)``."""
    return statistics.sidak(alpha, m)


def z_critical(m: int, *, alpha: float = FAMILY_ALPHA, sides: int = 2) -> float:
    """Normal critical value after the Sidak correction over m comparisons, two-sided (|z|
    above it rejects) or with ``sides=1`` one-sided (z above it rejects)."""
    return statistics.z_critical(alpha, m, sides)


def t_test_mean(samples: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Two-sided one-sample Student t-test p-values of the mean of ``samples`` (axis 0)."""
    return stats.ttest_1samp(samples, expected, axis=0).pvalue


def image_mean_and_se(film) -> tuple[np.ndarray, np.ndarray]:
    """Mean over pixels of a film's image per channel ``(3,)``, and its standard error ``(3,)``
    (``statistics.image_mean_and_se`` of the film's means and their variances)."""
    return statistics.image_mean_and_se(film.mean, film.variance_of_mean())
