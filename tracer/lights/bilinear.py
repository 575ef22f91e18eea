"""The bilinear warp of the unit square: points (s0, s1) in [0, 1]^2 with a density that
interpolates four positive corner weights, the map from uniform (u0, u1), and its inverse.

pbrt-v4 (Pharr, Jakob and Humphreys, "Physically Based Rendering", 4th ed., 2023; its functions
SampleLinear / SampleBilinear / InvertBilinearSample) warps a triangle or quad light's sample
square with it before the spherical sampling, so that the samples follow, approximately, the
receiver's cosine over the light (the weights are that cosine toward the light's corners). With weights
w00, w10, w01, w11 at the corners (s0, s1) = (0, 0), (1, 0), (0, 1), (1, 1) the density is

    p(s0, s1) = 4 ((1-s0)(1-s1) w00 + s0 (1-s1) w10 + (1-s0) s1 w01 + s0 s1 w11) / (w00+w10+w01+w11)

(the bilinear interpolant over its mean, which is the mean of the four weights). It is sampled
by inversion of the marginal of s1 and then of the conditional of s0 given s1; both are linear
densities on [0, 1]:

    s1 ~ linear(a = w00 + w10, b = w01 + w11) by u1,
    s0 ~ linear(a = lerp(s1, w00, w01), b = lerp(s1, w10, w11)) by u0,

where linear(a, b) has density f(x) = 2 ((1-x) a + x b) / (a + b) and distribution function
F(x) = x ((2-x) a + x b) / (a + b). Solving F(x) = u by the quadratic formula,
x = (sqrt(a^2 + u (b^2 - a^2)) - a) / (b - a), cancels catastrophically as b -> a (a difference
of nearly equal numbers over a small one, 0/0 at b = a); multiplying by the conjugate gives the
form used here,

    x = u (a + b) / (a + sqrt((1-u) a^2 + u b^2)),

whose terms are all positive, which tends smoothly to x = u at b = a, and which is returned as
exactly u when a == b. F itself is a sum of positive terms, so the inverse map needs no care.
Weights are rescaled by the larger of a and b first, so neither a^2 nor b^2 can overflow or
underflow.

Arguments are floats; weights must be > 0 (finite). ``sample`` maps [0, 1]^2 onto [0, 1]^2,
``pdf`` is with respect to area on the square (0 outside it), ``invert`` is the inverse of
``sample`` clamped to [0, 1]^2. Array versions for tests: ``sample_lanes``, ``pdf_lanes``,
``invert_lanes``, with ``u`` or ``s`` of shape (n, 2) and ``w = (w00, w10, w01, w11)`` of shape (4,).
"""

from __future__ import annotations

import math

import numpy as np

from ..frame import dot, sub
from ..jit import jit

MIN_COS_WEIGHT = 0.01  # keeps the warp's density positive where the receiver's cosine is 0


@jit
def cos_weight(n, x, corner) -> float:
    """The warp's weight at a light's corner: |n . w| for the unit direction w from the
    receiver at ``x`` (normal ``n``) to ``corner``, at least MIN_COS_WEIGHT (pbrt-v4's choice)."""
    w = sub(corner, x)
    length = math.sqrt(dot(w, w))
    return max(MIN_COS_WEIGHT, abs(dot(n, w)) / length) if length > 0.0 else MIN_COS_WEIGHT


@jit
def _lerp(t: float, a: float, b: float) -> float:
    """a + t (b - a): exactly a when a == b."""
    return a + t * (b - a)


@jit
def linear_sample(u: float, a: float, b: float) -> float:
    """x in [0, 1] with density 2 ((1-x) a + x b) / (a + b) (a, b > 0), by inversion of u."""
    if a == b:
        return u
    scale = 1.0 / max(a, b)
    a, b = a * scale, b * scale
    x = u * (a + b) / (a + math.sqrt((1.0 - u) * a * a + u * b * b))
    return min(max(x, 0.0), 1.0)


@jit
def linear_pdf(x: float, a: float, b: float) -> float:
    """Density of :func:`linear_sample` at x; 0 outside [0, 1]."""
    if x < 0.0 or x > 1.0:
        return 0.0
    return 2.0 * ((1.0 - x) * a + x * b) / (a + b)


@jit
def linear_invert(x: float, a: float, b: float) -> float:
    """The u that :func:`linear_sample` maps to x: F(x) = x ((2-x) a + x b) / (a + b)."""
    if a == b:
        return min(max(x, 0.0), 1.0)
    u = x * ((2.0 - x) * a + x * b) / (a + b)
    return min(max(u, 0.0), 1.0)


@jit
def sample(u0: float, u1: float, w00: float, w10: float, w01: float, w11: float):
    """(s0, s1) with the bilinear density of the corner weights: u1 picks s1 (marginal), u0
    picks s0 given s1."""
    s1 = linear_sample(u1, w00 + w10, w01 + w11)
    s0 = linear_sample(u0, _lerp(s1, w00, w01), _lerp(s1, w10, w11))
    return s0, s1


@jit
def pdf(s0: float, s1: float, w00: float, w10: float, w01: float, w11: float) -> float:
    """Density of :func:`sample` at (s0, s1), with respect to area; 0 outside [0, 1]^2."""
    if s0 < 0.0 or s0 > 1.0 or s1 < 0.0 or s1 > 1.0:
        return 0.0
    # Nested lerps, as the sampling uses them: with equal weights the density is exactly 1.
    bilerp = _lerp(s1, _lerp(s0, w00, w10), _lerp(s0, w01, w11))
    return 4.0 * bilerp / ((w00 + w10) + (w01 + w11))


@jit
def invert(s0: float, s1: float, w00: float, w10: float, w01: float, w11: float):
    """The (u0, u1) in [0, 1]^2 that :func:`sample` maps to (s0, s1)."""
    u1 = linear_invert(s1, w00 + w10, w01 + w11)
    u0 = linear_invert(s0, _lerp(s1, w00, w01), _lerp(s1, w10, w11))
    return u0, u1


# ---------------------------------------------------------------------------------------------
# Over arrays (tests, tools)


@jit
def sample_lanes(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``u (n, 2)``, weights ``w (4,)`` = (w00, w10, w01, w11) -> ``s (n, 2)``."""
    out = np.empty((len(u), 2))
    for i in range(len(u)):
        out[i, 0], out[i, 1] = sample(u[i, 0], u[i, 1], w[0], w[1], w[2], w[3])
    return out


@jit
def pdf_lanes(s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``s (n, 2)``, weights ``w (4,)`` -> ``(n,)`` densities."""
    out = np.empty(len(s))
    for i in range(len(s)):
        out[i] = pdf(s[i, 0], s[i, 1], w[0], w[1], w[2], w[3])
    return out


@jit
def invert_lanes(s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``s (n, 2)``, weights ``w (4,)`` -> ``u (n, 2)``."""
    out = np.empty((len(s), 2))
    for i in range(len(s)):
        out[i, 0], out[i, 1] = invert(s[i, 0], s[i, 1], w[0], w[1], w[2], w[3])
    return out
