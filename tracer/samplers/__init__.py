"""Samplers: where every random number of a render comes from.

Interface: a random number is ``u(seed, pixel, sample index, dimension)`` in [0, 1). A
kernel starts a lane with ``start(sampler, pixel, sample)``, which returns the lane's state
``(hash, pixel, sample)`` (each sampler uses what it needs: the independent one the hash, a
Sobol sampler the indices), and draws dimension d with ``uniform(sampler, state, d)``; which
dimension feeds which decision is ``tracer.samplers.dimensions``. Because numbers depend on
(pixel, sample) and not on the batch a lane runs in, the same seed gives the same image bit
for bit at any batch size and thread count.

A sampler reaches compiled code as a :class:`SamplerParams` (its code and what it was seeded
with). Adding a sampler: a module here with ``NAME``, ``start(...)`` and ``uniform(...)``, a
code in ``SAMPLERS``, and a branch in :func:`start` and :func:`uniform`.

=============  ====  ==========================================================
name           code  what
=============  ====  ==========================================================
independent    0     counter-based hash (SplitMix64): independent uniforms
=============  ====  ==========================================================
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import jit
from . import dimensions, independent

SAMPLERS = (independent.NAME,)  # the code of a sampler is its index here
INDEPENDENT = 0


class SamplerParams(NamedTuple):
    """A sampler as the kernels read it.

    code : index into ``SAMPLERS``.   seed_key : 64-bit key derived from the render's seed.
    """

    code: int
    seed_key: np.uint64


def seed_key(seed: int) -> np.uint64:
    """A well-mixed 64-bit key of any non-negative integer seed (numpy's SeedSequence, so that
    nearby seeds give unrelated keys)."""
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    return np.random.SeedSequence(seed).generate_state(1, dtype=np.uint64)[0]


def make(name: str, seed: int) -> SamplerParams:
    """The sampler called ``name`` (one of ``SAMPLERS``) seeded with ``seed``."""
    if name not in SAMPLERS:
        raise ValueError(f"unknown sampler {name!r}; expected one of {', '.join(SAMPLERS)}")
    return SamplerParams(SAMPLERS.index(name), seed_key(seed))


@jit
def start(sampler: SamplerParams, pixel: int, sample: int):
    """The state ``(hash, pixel, sample)`` of the lane that takes sample ``sample`` of pixel
    ``pixel``."""
    return independent.start(sampler.seed_key, pixel, sample), pixel, sample


@jit
def uniform(sampler: SamplerParams, state, dim: int) -> float:
    """Dimension ``dim`` of a lane whose state is ``state``: uniform in [0, 1)."""
    return independent.uniform(state[0], dim)


@jit
def _uniform_lanes(sampler, pixel, sample, dims, out):
    for i in range(len(pixel)):
        state = start(sampler, pixel[i], sample[i])
        for j in range(len(dims)):
            out[i, j] = uniform(sampler, state, dims[j])


def uniforms(sampler: SamplerParams, pixel: np.ndarray, sample: np.ndarray, dims) -> np.ndarray:
    """``(n, len(dims))`` float64: the numbers of lanes ``(pixel[i], sample[i])`` in dimensions
    ``dims``, exactly as the kernels draw them (for tests and tools)."""
    pixel = np.asarray(pixel, dtype=np.int64)
    out = np.empty((len(pixel), len(dims)))
    _uniform_lanes(sampler, pixel, np.broadcast_to(np.asarray(sample, dtype=np.int64), pixel.shape),
                   np.asarray(dims, dtype=np.int64), out)
    return out


__all__ = ["SAMPLERS", "SamplerParams", "dimensions", "make", "seed_key", "start", "uniform", "uniforms"]
