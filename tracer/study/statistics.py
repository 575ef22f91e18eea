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

For ``check``: a t-test of independent replicates against a reference that has its own
standard error (``t_against_reference``), the smallest p-value of an exact Mann-Whitney test
(``mann_whitney_smallest_p``), and a permutation test of two samples' means whose false-alarm
rate is exact whatever their distribution (``permutation_p``).

scipy is imported inside the functions that need it, so importing this module stays cheap.
"""

from __future__ import annotations

import math

import numpy as np

FAMILY_ALPHA = 0.01


def sidak(alpha: float, m: int) -> float:
    """Per-comparison level for ``m`` independent comparisons at family-wise rate ``alpha``:
    1 - (1 - alpha)^(1/m). m < 1 counts as one comparison."""
    # expm1/log1p keep the digits for small alpha, where 1 - (1 - alpha)^(1/m) cancels.
    return float(-np.expm1(np.log1p(-alpha) / max(int(m), 1)))


def sidak_family(p, m: int):
    """The family-wise p-value of the smallest of ``m`` independent p-values when it is ``p``:
    1 - (1 - p)^m (the inverse of :func:`sidak`). Rejecting when it is below alpha is the same
    as rejecting when ``p < sidak(alpha, m)``. ``p`` a number (a float back) or an array (an
    array of its shape back)."""
    p = np.clip(np.asarray(p, dtype=np.float64), 0.0, 1.0)
    # np.where evaluates both sides: cap p below 1 so that log1p stays finite where p = 1 (-> 1).
    below_one = np.minimum(p, np.nextafter(1.0, 0.0))
    family = np.where(p >= 1.0, 1.0, -np.expm1(max(int(m), 1) * np.log1p(-below_one)))
    return float(family) if family.ndim == 0 else family


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


def t_against_reference(
    replicates: np.ndarray, ref_mean: np.ndarray, ref_se: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A t-test of the mean of n independent replicates against a reference value that
    carries its own standard error: ``(t, two-sided p)``, each of shape ``(..., k)``.

    replicates : (..., n, k) values, n >= 2 (e.g. n seeds' image means, k channels).
    ref_mean, ref_se : broadcastable to (..., k): the reference's value and standard error,
        independent of the replicates.

    t = (x̄ - R) / sqrt(s²/n + se_R²), s² the replicates' unbiased variance, referred to
    Student's t with n - 1 degrees of freedom. Welch's test (Welch 1947, Biometrika 34:28)
    would use the Welch-Satterthwaite degrees of freedom (s²/n + se_R²)² / ((s²/n)² / (n - 1)),
    more than n - 1; at the small levels a Sidak correction asks for (1e-5) that approximation
    was measured 3 times too liberal with se_R a tenth of the image's standard error. n - 1 is
    conservative: with W = s²/(σ²) the statistic is N(0, a + b) / sqrt(a W + b) (a = σ²/n,
    b = se_R²), and for W < 1, the small variance estimates that make the tail, sqrt((a W + b)
    / (a + b)) > sqrt(W), so its tail is lighter than t's with n - 1 degrees of freedom.
    Only the replicates' spread estimates their variance, so the test needs their means, not
    each sample, to be close to normal. With no spread on either side t is 0 for means equal
    to 1e-12 (relative) and infinite otherwise.
    """
    from scipy import stats

    x = np.asarray(replicates, dtype=np.float64)
    n = x.shape[-2]
    if n < 2:
        raise ValueError(f"a t-test needs at least 2 replicates, got {n}")
    mean = x.mean(axis=-2)
    total = x.var(axis=-2, ddof=1) / n + np.asarray(ref_se, dtype=np.float64) ** 2
    diff = mean - np.asarray(ref_mean, dtype=np.float64)
    scale = np.maximum(np.abs(mean), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(total > 0, diff / np.sqrt(np.where(total > 0, total, 1.0)),
                     np.where(np.abs(diff) <= 1e-12 * scale, 0.0, np.inf * np.sign(diff)))
    return t, 2.0 * stats.t.sf(np.abs(t), n - 1)


def mann_whitney_smallest_p(n1: int, n2: int) -> float:
    """The smallest one-sided p-value an exact Mann-Whitney U test of n1 against n2 values can
    give: 1 / C(n1 + n2, n1), the probability of the single most extreme ordering (every value
    of one sample above every value of the other) when all orderings are equally likely. A
    level below it can never be reached: such a test cannot fail."""
    return 1.0 / math.comb(int(n1) + int(n2), int(n1))


def studentized_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """max over the last axis of |mean a - mean b| / sqrt(var a / n_a + var b / n_b), for
    samples ``a (..., n_a, k)`` and ``b (..., n_b, k)``: Welch's statistic, channel by channel,
    its largest. 0 where both means agree and neither sample spreads, infinite where they
    differ without spread."""
    with np.errstate(all="ignore"):  # values near the float limit give inf or nan, which reach nothing
        diff = np.abs(a.mean(axis=-2) - b.mean(axis=-2))
        scale = np.sqrt(a.var(axis=-2, ddof=1) / a.shape[-2] + b.var(axis=-2, ddof=1) / b.shape[-2])
        tiny = 1e-12 * np.maximum(np.abs(a.mean(axis=-2)), np.abs(b.mean(axis=-2)))
        t = np.where(scale > 0, diff / np.where(scale > 0, scale, 1.0), np.where(diff <= tiny, 0.0, np.inf))
    return t.max(axis=-1)


def permutation_p(a: np.ndarray, b: np.ndarray, level: float, rng: np.random.Generator,
                  exceedances: int = 10) -> float:
    """Two-sided p-value of a permutation test that samples ``a (n_a, k)`` and ``b (n_b, k)``
    have the same means, with :func:`studentized_difference` as the statistic.

    Under H0 that all n_a + n_b rows are exchangeable (independent draws of one distribution)
    every split of the pooled rows is equally likely, so the p-value is exact whatever the
    distribution: heavy tails do not make it liberal (Fisher 1935; Pitman 1937). The studentized
    statistic keeps it asymptotically valid for equal means when the spreads differ (Janssen
    1997, Statist. Probab. Lett. 36:9; Chung and Romano 2013, Ann. Statist. 41:484); the
    maximum over the k columns makes one test of all of them, exact for their correlation
    (Westfall and Young 1993). Random splits are drawn until ``exceedances`` of them reach the
    observed statistic, p = exceedances / splits drawn (Besag and Clifford 1991, Biometrika
    78:301), or until 10 / ``level`` splits, p = (reached + 1) / (drawn + 1): both are valid
    p-values (P(p <= x) <= x), the second one resolving ``level`` to a tenth. Ties count as
    reaching it, so equal samples give p = 1.
    """
    x = np.concatenate([a, b])
    n_a, total = len(a), len(a) + len(b)
    observed = float(studentized_difference(a, b))
    threshold = observed * (1.0 - 1e-12)
    limit = int(math.ceil(10.0 / level))
    drawn, reached, batch = 0, 0, 64
    while drawn < limit:
        size = min(batch, limit - drawn)
        order = np.argsort(rng.random((size, total)), axis=1)
        t = studentized_difference(x[order[:, :n_a]], x[order[:, n_a:]])
        hits = np.cumsum(t >= threshold)
        if reached + hits[-1] >= exceedances:  # stop at the split that makes `exceedances`
            stop = int(np.argmax(reached + hits >= exceedances)) + 1
            return exceedances / (drawn + stop)
        reached += int(hits[-1])
        drawn += size
        batch = min(batch * 2, 2**16)
    return (reached + 1) / (drawn + 1)
