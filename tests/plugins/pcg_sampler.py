"""A sampler plug-in: independent uniforms from another counter-based hash than SplitMix64, the
output permutation of O'Neill's PCG (2014, "PCG: a family of simple fast space-efficient
statistically good algorithms for random number generation", RXS M XS 64/64) applied to a Weyl
sequence keyed by (seed, pixel, sample, dimension)."""

from __future__ import annotations

import numpy as np

from tracer.jit import jit
from tracer.plugins import Sampler, register
from tracer.samplers.independent import GOLDEN_GAMMA, lane_key

NAME = "pcg"
PLUGIN = register(Sampler(NAME, module=__name__, replicates=0, doc="independent uniforms (PCG's output map)"))
_MULT = np.uint64(12605985483714917081)
_S5, _S22, _S43, _S59, _S11 = (np.uint64(v) for v in (5, 22, 43, 59, 11))


@jit
def _rxs_m_xs(state: np.uint64) -> np.uint64:
    word = ((state >> ((state >> _S59) + _S5)) ^ state) * _MULT
    return (word >> _S43) ^ word


@jit
def start(sampler, pixel: int, sample: int):
    return lane_key(sampler.seed_key, pixel, sample), sample, 0


@jit
def uniform(sampler, state, dim: int) -> float:
    z = _rxs_m_xs(state[0] + np.uint64(dim + 1) * GOLDEN_GAMMA)
    return float(np.int64(z >> _S11)) * (1.0 / 9007199254740992.0)


@jit
def uniform_pair(sampler, state, dim: int):
    return uniform(sampler, state, dim), uniform(sampler, state, dim + 1)
