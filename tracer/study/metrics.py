"""Noise and error measures, one definition everywhere (``docs/DESIGN.md``).

Images are ``(..., 3)`` float arrays of pixel means; the reference R is a high-spp MIS render.

- ``mse`` = mean over pixels and channels of (I - R)^2
- ``relmse`` = mean over pixels and channels of (I - R)^2 / (R^2 + 0.01)
- ``variance`` = mean over pixels and channels of the variance of the pixel value
  (the film's per-sample variance / spp): the error expected without a reference
- ``efficiency`` = 1 / (relmse x seconds): higher is better at equal time

The reference has noise of its own, and it adds to every measured error: for an image I and a
reference R rendered independently, E[(I - R)^2] = E[(I - mu)^2] + Var(R) per pixel (mu the true
value, I unbiased). ``mse`` and ``relmse`` therefore take the variance of each reference pixel
value (its per-sample variance / its count, which the reference EXR holds) and subtract it,
giving unbiased estimates of the image's own error; ``reference_relmse`` is the share removed.
A corrected value can come out at or below 0 when the image's error is below what the
reference can resolve: it is reported as measured, and its efficiency is then undefined.

Significance levels and z-tests are ``tracer.study.statistics``.
"""

from __future__ import annotations

import numpy as np

from ..film import Film

RELMSE_EPSILON = 0.01
# Efficiency-ratio maps average each pixel's squared error over a (2 r + 1)^2 window, r this.
EFFICIENCY_RADIUS = 3


def mse(image: np.ndarray, reference: np.ndarray, reference_variance: np.ndarray | None = None) -> float:
    """Mean over pixels and channels of (I - R)^2 - Var(R); ``image``, ``reference`` and
    ``reference_variance`` (variance of each reference pixel value; None: 0) of one shape."""
    error = (image - reference) ** 2
    if reference_variance is not None:
        error = error - reference_variance
    return float(np.mean(error))


def relative_squared_error(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per pixel and channel: (I - R)^2 / (R^2 + 0.01), same shape as the inputs."""
    return (image - reference) ** 2 / (reference**2 + RELMSE_EPSILON)


def relmse(image: np.ndarray, reference: np.ndarray, reference_variance: np.ndarray | None = None) -> float:
    """Mean over pixels and channels of :func:`relative_squared_error`, less
    Var(R) / (R^2 + 0.01) when ``reference_variance`` is given (see the module docstring)."""
    error = relative_squared_error(image, reference)
    if reference_variance is not None:
        error = error - reference_variance / (reference**2 + RELMSE_EPSILON)
    return float(np.mean(error))


def reference_relmse(reference: np.ndarray, reference_variance: np.ndarray) -> float:
    """The reference's own noise on the relMSE scale: mean of Var(R) / (R^2 + 0.01), what
    :func:`relmse` subtracts."""
    return float(np.mean(reference_variance / (reference**2 + RELMSE_EPSILON)))


def variance(film: Film) -> float:
    """Mean over pixels and channels of the variance of the pixel value."""
    return float(np.mean(film.variance_of_mean()))


def efficiency(relmse_value: float, seconds: float) -> float:
    """1 / (relMSE x seconds); NaN (undefined) when relMSE x seconds is not positive: an exact
    image, or an error below what the reference resolves. Reports show NaN as "n/a" and
    write it to JSON as null."""
    denom = relmse_value * seconds
    return float("nan") if not denom > 0.0 else 1.0 / denom


def box_blur(image: np.ndarray, radius: int) -> np.ndarray:
    """Mean over the (2 radius + 1)^2 window around each pixel of an ``(H, W, ...)`` array,
    the window clipped at the borders. Separable sums of shifted copies: no summed-area table,
    whose cancellation would turn exact zeros (unlit pixels) into round-off noise."""
    out = image.astype(np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        total = np.zeros_like(out)
        count = np.zeros(n)
        for shift in range(-radius, radius + 1):
            lo, hi = max(0, -shift), min(n, n - shift)  # destination rows that have a source
            if lo >= hi:
                continue
            dst = [slice(None)] * out.ndim
            src = [slice(None)] * out.ndim
            dst[axis] = slice(lo, hi)
            src[axis] = slice(lo + shift, hi + shift)
            total[tuple(dst)] += out[tuple(src)]
            count[lo:hi] += 1
        shape = [1] * out.ndim
        shape[axis] = n
        out = total / count.reshape(shape)
    return out


def efficiency_ratio_map(
    error_a: np.ndarray, seconds_a: float, error_b: np.ndarray, seconds_b: float,
    radius: int = EFFICIENCY_RADIUS
) -> np.ndarray:
    """Per-pixel log2 of efficiency(a) / efficiency(b), ``(H, W)``.

    ``error_*`` are ``(H, W, 3)`` squared errors against the reference; they are averaged over
    channels and a (2 radius + 1)^2 window before the ratio (one pixel's squared error is a
    single noisy draw). Positive: a reaches a given error sooner than b there. Pixels where
    both errors vanish (black background) are 0.
    """
    cost_a = box_blur(error_a.mean(axis=2), radius) * seconds_a
    cost_b = box_blur(error_b.mean(axis=2), radius) * seconds_b
    tiny = 1e-30
    ratio = np.log2((cost_b + tiny) / (cost_a + tiny))
    return np.where((cost_a <= tiny) & (cost_b <= tiny), 0.0, ratio)
