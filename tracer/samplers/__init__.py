"""Samplers: where every random number of a render comes from.

Interface (each sampler is a plug-in module here, ``tracer.plugins``): a random number is
``u(seed, pixel, sample index, dimension)`` in [0, 1). A kernel starts a lane with
``dispatch.start(sampler, pixel, sample)``, which returns the lane's state ``(key, index,
spare)`` (a 64-bit key and the point index the sampler works with), and draws dimension d with
``dispatch.uniform(sampler, state, d)`` (a pair, d even, with ``uniform_pair``), bound to the
render's sampler (``tracer.kernels``); which dimension feeds which decision is
``tracer.samplers.dimensions``. Because numbers depend on
(pixel, sample) and not on the batch a lane runs in, the same seed gives the same image bit
for bit at any batch size and thread count.

A sampler reaches compiled code as a :class:`SamplerParams` (its code, what it was seeded
with, and for ``stratified`` the render's grid). Adding a sampler: one module here that
registers a ``plugins.Sampler`` (its name, replicates and index limit) and defines ``start``,
``uniform`` and ``uniform_pair``; nothing else to edit.

=============  ====  ==========  ===============================================================
name           code  replicates  what
=============  ====  ==========  ===============================================================
independent    0     none        counter-based hash (SplitMix64): independent uniforms
stratified     1     8           jittered strata per pair of dimensions (``stratified.py``)
sobol          2     8           Owen-scrambled Sobol points per pair of dimensions (``sobol.py``)
=============  ====  ==========  ===============================================================

Replicates: samples of one pixel drawn by a stratified or Sobol sampler are not independent
(that is the point: they avoid each other), so the spread of the samples says little about the
error of their mean. These samplers therefore split each pixel's samples into ``REPLICATES``
independently randomized sets: sample ``s`` belongs to replicate ``s % R`` as its point
``s // R``. The film keeps each replicate's count and mean, and the error of the pixel value is
estimated from how the replicate means scatter (``tracer.film``). Eight replicates: enough
degrees of freedom (7) for the pooled z-tests of ``check`` and ``stability``, while each
replicate keeps 1/8 of the samples to form its net (a replicate of n points instead of 8 n
costs QMC a factor 8^(a - 1) in variance where its error falls as n^-a).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import plugins
from ..jit import jit
from ..kernels import UNBOUND, kernel
from ..sampler_choice import DEFAULT_SAMPLER, REPLICATES, max_samples, replicates_of
from . import dimensions, stratified

SAMPLERS = plugins.names("sampler")


class SamplerParams(NamedTuple):
    """A sampler as the kernels read it.

    code : index into ``SAMPLERS``.   seed_key : 64-bit key derived from the render's seed.
    replicates : R, or 0 for the independent sampler.
    first_sample : the render's first sample index (``stratified``: where its sets begin).
    nx, ny : ``stratified``'s grid per pair of dimensions (1, 1 for the others).
    """

    code: int
    seed_key: np.uint64
    replicates: int
    first_sample: int
    nx: int
    ny: int


def seed_key(seed: int) -> np.uint64:
    """A well-mixed 64-bit key of any non-negative integer seed (numpy's SeedSequence, so that
    nearby seeds give unrelated keys)."""
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    return np.random.SeedSequence(seed).generate_state(1, dtype=np.uint64)[0]


def make(name: str, seed: int, first_sample: int = 0, spp: int = 1) -> SamplerParams:
    """The sampler called ``name`` (one of ``SAMPLERS``) seeded with ``seed``, for a render of
    sample indices ``first_sample .. first_sample + spp - 1``."""
    plugin = plugins.get("sampler", name)
    replicates = plugin.replicates
    nx, ny = stratified.grid(-(-spp // replicates)) if name == stratified.NAME else (1, 1)
    return SamplerParams(plugins.names("sampler").index(name), seed_key(seed), replicates, int(first_sample),
                         nx, ny)


def name_of(sampler: SamplerParams) -> str:
    """The name of the sampler ``sampler`` was made of (its code is its place in the registry)."""
    return plugins.names("sampler")[sampler.code]


ONE_BELOW = 1.0 - 2.0 ** -53  # the largest float64 below 1


@jit
def reuse(u: float, p: float, took: bool) -> float:
    """A uniform ``u`` in [0, 1) that has decided a choice of probability ``p`` (taken when
    u < p), rescaled to a fresh uniform in [0, 1) for the next decision: u / p if taken, else
    (u - p) / (1 - p). Each decision spends log2 of its inverse probability of float64's 53 bits
    (the light BVH's descent and ris's reservoir use it, one dimension for many decisions)."""
    if took:
        return min(u / p, ONE_BELOW)
    return min((u - p) / (1.0 - p), ONE_BELOW)


@kernel
def _uniform_lanes(sampler, pixel, sample, dims, out):
    for i in range(len(pixel)):
        state = dispatch.start(sampler, pixel[i], sample[i])
        for j in range(len(dims)):
            out[i, j] = dispatch.uniform(sampler, state, dims[j])


def uniforms(sampler: SamplerParams, pixel: np.ndarray, sample: np.ndarray, dims) -> np.ndarray:
    """``(n, len(dims))`` float64: the numbers of lanes ``(pixel[i], sample[i])`` in dimensions
    ``dims``, exactly as the kernels draw them (for tests and tools)."""
    from ..kernels import FeatureSet, build

    features = FeatureSet((), (), "power", name_of(sampler), None, "sum", False, False, False)
    pixel = np.asarray(pixel, dtype=np.int64)
    out = np.empty((len(pixel), len(dims)))
    build(features).function(_uniform_lanes)(
        sampler, pixel, np.broadcast_to(np.asarray(sample, dtype=np.int64), pixel.shape),
        np.asarray(dims, dtype=np.int64), out)
    return out


dispatch = UNBOUND  # bound per build (``tracer.kernels``)

__all__ = ["DEFAULT_SAMPLER", "REPLICATES", "SAMPLERS", "SamplerParams", "dimensions", "make", "max_samples",
           "name_of", "replicates_of", "reuse", "seed_key", "uniforms"]
