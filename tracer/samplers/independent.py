"""The ``independent`` sampler: every number an independent uniform, by hashing.

u(seed, pixel, sample, dimension) is a counter-based hash: no state, no memory traffic, no
locking, and the same bits whatever the batch a lane falls in or the thread that runs it.

The generator is SplitMix64 (Steele, Lea and Flood 2014, "Fast splittable pseudorandom number
generators"): a Weyl sequence through a 64-bit finalizer that passes BigCrush. A lane's
stream starts at ``mix(mix(seed_key ^ pixel) + sample * gamma)``: ``mix`` is a bijection and
gamma is odd, so within a pixel distinct samples start distinct streams; dimension d is the
(d + 1)-th output of that stream.
"""

from __future__ import annotations

import numpy as np

from ..jit import jit
from ..plugins import Sampler, register

NAME = "independent"
PLUGIN = register(Sampler(NAME, module=__name__, rank=0, replicates=0,
                          doc="independent uniforms (SplitMix64)"))
GOLDEN_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@jit
def mix64(z: np.uint64) -> np.uint64:
    """SplitMix64's output function: a bijection of 64-bit integers with full avalanche."""
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@jit
def lane_key(seed_key: np.uint64, pixel: int, sample: int) -> np.uint64:
    """The key of the stream of the lane that takes sample ``sample`` of pixel ``pixel``."""
    return mix64(mix64(seed_key ^ np.uint64(pixel)) + np.uint64(sample) * GOLDEN_GAMMA)


@jit
def stream_uniform(key: np.uint64, dim: int) -> float:
    """Uniform in [0, 1): dimension ``dim`` of the stream of ``key``, with 53 random bits."""
    z = mix64(key + np.uint64(dim + 1) * GOLDEN_GAMMA)
    return float(np.int64(z >> _S11)) * _TO_UNIT  # signed: one instruction, exact below 2^53


# The sampler interface (``tracer.samplers``).


@jit
def start(sampler, pixel: int, sample: int):
    """The lane's state ``(key, sample, 0)``: the key of its own stream."""
    return lane_key(sampler.seed_key, pixel, sample), sample, 0


@jit
def uniform(sampler, state, dim: int) -> float:
    return stream_uniform(state[0], dim)


@jit
def uniform_pair(sampler, state, dim: int):
    return stream_uniform(state[0], dim), stream_uniform(state[0], dim + 1)
