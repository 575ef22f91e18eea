"""The ``sobol`` sampler: Owen-scrambled Sobol points, padded per pair of dimensions.

Each pair of dimensions ``(2 p, 2 p + 1)`` of a lane is a point of the first two dimensions of
Sobol's sequence, which form a (0, 2)-sequence in base 2: every aligned block of 2^m
consecutive points is a (0, m, 2)-net, one point in each elementary interval of area 2^-m.
"Padded" (pbrt-v4's ``PaddedSobolSampler``): every pair has its own randomization, drawn from a
hash of (seed, pixel, replicate, pair), so that pairs are decorrelated from each other:

- the *index* of the point is shuffled by a nested uniform scramble of its bits in which a bit
  flips according to the bits above it. Such a permutation maps every aligned block of 2^m
  indices onto another aligned block, so the first 2^m points a replicate takes are still a
  net, in an order (and a block) that differs from pair to pair;
- each coordinate is Owen-scrambled (nested uniform scrambling: a digit flips according to the
  digits before it), which keeps the net property and makes every point uniform on [0, 1).

Both scrambles use Burley's hash approximation of Owen scrambling (Burley 2020, "Practical
hash-based Owen scrambling", JCGT 9(4)): in bit-reversed order, adding a seed and XOR-ing with
products by even constants changes a bit only according to the bits below it (the digits above
it in the original order), so the map is a nested scramble; over a uniform 32-bit seed each
scrambled value is uniform, because for a fixed input the seed's bits reach the output through
a triangular, invertible map. The 32 digits so scrambled are followed by 21 further random
bits (from a product of the pair's hash and the index), as the infinitely many digits of a full
Owen scramble would be.

Replicates: sample ``s`` of a pixel is point ``s // R`` of replicate ``s % R`` (``R`` =
``tracer.samplers.REPLICATES``), each replicate an independently scrambled copy of the
sequence (``tracer.samplers``, "Replicates"). A render of samples ``0 .. n R - 1`` gives each
replicate the first n points of its sequence; a resume continues each replicate's sequence, so
a pixel that ends with 2^m points per replicate holds R scrambled nets whatever the number of
runs it took. Indices are 32-bit: a pixel takes at most R x 2^32 samples.
"""

from __future__ import annotations

import numpy as np

from ..jit import jit, jit_called
from ..plugins import Sampler, register
from ..sampler_choice import REPLICATES, SOBOL_MAX_INDEX
from .independent import GOLDEN_GAMMA, mix64
from .replicates import replicate_start

NAME = "sobol"
PLUGIN = register(Sampler(NAME, module=__name__, rank=2, replicates=REPLICATES,
                          max_samples=REPLICATES * SOBOL_MAX_INDEX,
                          doc="Owen-scrambled Sobol points per pair of dimensions, 8 replicates"))
_M32 = np.uint64(0xFFFFFFFF)
_BYTE = np.uint64(0xFF)
_S8, _S16, _S24 = np.uint64(8), np.uint64(16), np.uint64(24)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53
_S21, _S43, _S32 = np.uint64(21), np.uint64(43), np.uint64(32)
# Burley's (2020) constants for the Laine-Karras style permutation: all even, so that a
# product carries each bit only upward.
_LK = (np.uint64(0x6C50B47C), np.uint64(0xB82F1E52), np.uint64(0xC7AFE638), np.uint64(0x8D22F6E6))
_LOW21 = np.uint64((1 << 21) - 1)
_S22 = np.uint64(22)
_LOW_MIX = np.uint64(0xBF58476D1CE4E5B9)  # odd: its product carries the pair's and index's bits up


@jit
def reverse_bits32(x: np.uint64) -> np.uint64:
    """The low 32 bits of ``x`` in reverse order."""
    x = ((x >> np.uint64(1)) & np.uint64(0x55555555)) | ((x & np.uint64(0x55555555)) << np.uint64(1))
    x = ((x >> np.uint64(2)) & np.uint64(0x33333333)) | ((x & np.uint64(0x33333333)) << np.uint64(2))
    x = ((x >> np.uint64(4)) & np.uint64(0x0F0F0F0F)) | ((x & np.uint64(0x0F0F0F0F)) << np.uint64(4))
    x = ((x >> np.uint64(8)) & np.uint64(0x00FF00FF)) | ((x & np.uint64(0x00FF00FF)) << np.uint64(8))
    return ((x >> np.uint64(16)) & np.uint64(0xFFFF)) | ((x & np.uint64(0xFFFF)) << np.uint64(16))


@jit
def _lk_permutation(x: np.uint64, seed: np.uint64) -> np.uint64:
    """Burley's (2020) Laine-Karras style permutation of 32-bit integers: bit k of the result
    depends only on bits 0 .. k of ``x`` and of ``seed`` (the order in which a nested scramble
    works on bit-reversed digits)."""
    x = (x + seed) & _M32
    for c in _LK:
        x ^= (x * c) & _M32
    return x


@jit
def nested_scramble(x: np.uint64, seed: np.uint64) -> np.uint64:
    """A nested uniform scramble of the 32-bit ``x`` keyed by the 32-bit ``seed``: bit k of the
    result is bit k of ``x`` flipped according to bits k + 1 .. 31 of ``x`` (and the seed)."""
    return reverse_bits32(_lk_permutation(reverse_bits32(x), seed))


def _second_axis_tables() -> np.ndarray:
    """(4, 256) uint64: the XOR of the direction numbers of Sobol's second dimension selected by
    each value of each byte of an index, each bit-reversed (the order the scramble works in:
    one reversal fewer per point; reversal is linear over XOR). The direction numbers are
    v_1 = 1/2 and v_k = v_{k-1} xor v_{k-1} / 2 (the primitive polynomial x + 1: the generator
    matrix is Pascal's triangle mod 2); the point is linear in the index's bits over GF(2), so
    it is the XOR of four table entries, one per byte (the shuffled indices use all 32 bits,
    where a loop over bits takes 32 steps)."""
    directions = [0x80000000]
    for _ in range(31):
        directions.append(directions[-1] ^ (directions[-1] >> 1))
    directions = [int(f"{v:032b}"[::-1], 2) for v in directions]
    tables = np.zeros((4, 256), dtype=np.uint64)
    for byte in range(4):
        for value in range(256):
            bits = 0
            for k in range(8):
                if value >> k & 1:
                    bits ^= directions[8 * byte + k]
            tables[byte, value] = bits
    return tables


_SECOND_AXIS_REVERSED = _second_axis_tables()


@jit
def _xor_of_bytes(table: np.ndarray, index: np.uint64) -> np.uint64:
    return (table[0, index & _BYTE] ^ table[1, (index >> _S8) & _BYTE]
            ^ table[2, (index >> _S16) & _BYTE] ^ table[3, (index >> _S24) & _BYTE])


@jit
def _pair_point(key: np.uint64, index: int, dim: int, both: bool):
    """The scrambled 32-bit coordinates of the pair that holds ``dim`` (the second only if
    ``both``, else 0) and 64 random bits for the low digits.

    The pair's 64-bit hash gives the index shuffle its seed (low 32 bits) and the first
    coordinate's scramble (high 32 bits); the high half of its product with an odd constant
    the second coordinate's; the low digits come from a product of the pair's hash and the
    index (digits below 2^-32 need no more)."""
    pair = mix64(key + np.uint64(dim // 2 + 1) * GOLDEN_GAMMA)
    shuffled = nested_scramble(np.uint64(index), pair & _M32)
    # Axis 0 is the bit reversal of the index, so its scramble reverse(lk(reverse(.))) is lk(.) reversed.
    x = reverse_bits32(_lk_permutation(shuffled, pair >> _S32))
    y = np.uint64(0)
    if both:
        y = reverse_bits32(_lk_permutation(_xor_of_bytes(_SECOND_AXIS_REVERSED, shuffled),
                                           (pair * GOLDEN_GAMMA) >> _S32))
    low = (pair ^ (np.uint64(index) * GOLDEN_GAMMA)) * _LOW_MIX
    return x, y, low


@jit_called
def point_pair(key: np.uint64, index: int, dim: int):
    """Dimensions ``dim`` and ``dim + 1`` (``dim`` even: a pair) of point ``index`` of the
    replicate whose key is ``key``: a point of [0, 1)^2."""
    x, y, low = _pair_point(key, index, dim, True)
    return (float(np.int64((x << _S21) | (low >> _S43))) * _TO_UNIT,
            float(np.int64((y << _S21) | ((low >> _S22) & _LOW21))) * _TO_UNIT)


@jit_called
def point(key: np.uint64, index: int, dim: int) -> float:
    """Dimension ``dim`` of point ``index`` of the replicate whose key is ``key``: in [0, 1)
    (the pair's other coordinate is not computed when ``dim`` is its first)."""
    if dim & 1:
        return point_pair(key, index, dim - 1)[1]
    x, _, low = _pair_point(key, index, dim, False)
    return float(np.int64((x << _S21) | (low >> _S43))) * _TO_UNIT


# The sampler interface (``tracer.samplers``).


@jit
def start(sampler, pixel: int, sample: int):
    """The lane's state ``(key, index, 0)``: its replicate's key and its point index there."""
    key, index = replicate_start(sampler, pixel, sample)
    return key, index, 0


@jit
def uniform(sampler, state, dim: int) -> float:
    return point(state[0], state[1], dim)


@jit
def uniform_pair(sampler, state, dim: int):
    return point_pair(state[0], state[1], dim)
