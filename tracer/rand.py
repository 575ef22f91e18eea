"""Counter-based uniform random numbers: u = hash(key, lane, dimension).

Every random number of a render is a pure function of a 64-bit batch ``key`` (drawn from the
batch's own generator, keyed by seed and batch position), the lane within the batch and the
dimension within the lane (``DESIGN.md``). So numbers need no state, no memory traffic and no
locking, and the same seed gives the same image whatever the number of threads.

The generator is SplitMix64 (Steele, Lea and Flood 2014, "Fast splittable pseudorandom number
generators"): a Weyl sequence through a 64-bit finalizer, which passes BigCrush. A lane's
stream starts from the finalizer applied to its key and lane index; dimension d is the
(d + 1)-th output of that stream.
"""

from __future__ import annotations

import numpy as np

from .jit import jit

GOLDEN_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_LANE_ODD = np.uint64(0xD1B54A32D192ED03)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@jit
def mix64(z: np.uint64) -> np.uint64:
    """SplitMix64's output function: a bijection of 64-bit integers with full avalanche."""
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@jit
def lane_stream(key: np.uint64, lane: int) -> np.uint64:
    """The start of lane ``lane``'s stream under batch ``key``."""
    return mix64(key ^ (np.uint64(lane) * _LANE_ODD))


@jit
def uniform(stream: np.uint64, dim: int) -> float:
    """Uniform in [0, 1): output ``dim`` of a lane's stream, with 53 random bits."""
    z = mix64(stream + np.uint64(dim + 1) * GOLDEN_GAMMA)
    return float(np.int64(z >> _S11)) * _TO_UNIT  # signed: one instruction, exact below 2^53


def batch_key(rng: np.random.Generator) -> np.uint64:
    """A 64-bit key drawn from a batch's generator."""
    return np.uint64(rng.integers(0, 2**64, dtype=np.uint64))
