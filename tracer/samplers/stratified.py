"""The ``stratified`` sampler: jittered strata, padded per pair of dimensions.

A render gives each replicate (``tracer.samplers``, "Replicates") N = ceil(spp / R) points, and
each pair of dimensions of those points is stratified on its own grid of ``nx x ny`` cells,
``nx = ceil(sqrt(N))``, ``ny = ceil(N / nx)``: point j of a replicate takes cell ``pi(j)`` of a
random permutation of the cells and a uniform position inside it. When N is a square the grid
is exactly N cells, one point each (classic jittered sampling); otherwise the grid has
``nx ny - N < nx`` more cells than points, and the points take N distinct cells chosen at
random (so an spp of 8 per replicate is a 3 x 3 grid with one cell left empty). "Padded":
every pair has its own permutation, keyed by a hash of (seed, pixel, replicate, pair), so the
pairs are decorrelated from each other, as in pbrt-v3's ``StratifiedSampler``.

The permutation is a keyed bijection of the integers below the next power of two, walked in
cycles until it lands below ``nx ny`` (cycle walking), then rotated by a uniform random offset:
the rotation keeps the cells distinct and makes each point's cell uniform (to within
``nx ny / 2^32``) whatever the bijection's quality, so every point is uniform and every
estimate unbiased, also when a render stops early and a pixel holds only some of its points.

The grid depends on the render's spp, so the points depend on (seed, pixel, sample index,
dimension) and on the render's first sample and spp; a resume adds a new stratified set per
replicate (keyed by its first index too), independent of the earlier one.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import jit, jit_called
from ..plugins import Sampler, register
from ..sampler_choice import REPLICATES
from .independent import GOLDEN_GAMMA, mix64
from .replicates import replicate_start

NAME = "stratified"
PLUGIN = register(Sampler(NAME, module=__name__, rank=1, replicates=REPLICATES,
                          doc="jittered strata per pair of dimensions, 8 replicates"))
_ONE_BELOW = 1.0 - 2.0**-53
_M32, _S32 = np.uint64(0xFFFFFFFF), np.uint64(32)
_TO_UNIT32 = 2.0**-32
_MUL = (np.uint64(0x2C1B3C6D), np.uint64(0x297A2D39))


def grid(points: int) -> tuple[int, int]:
    """``(nx, ny)``: the cells of the grid that stratifies ``points`` points per pair."""
    nx = math.isqrt(points - 1) + 1 if points > 1 else 1  # ceil(sqrt(points)), exactly
    return nx, max(1, -(-points // nx))


@jit
def permute(j: int, n: int, key: np.uint64) -> int:
    """Element j (0 <= j < n) of a random permutation of 0 .. n - 1 keyed by ``key``. (A j
    outside that range is taken modulo n: the walk below returns below n only from below n.)"""
    if n <= 1:
        return 0
    if j < 0 or j >= n:
        j %= n
    bits = 1
    while (1 << bits) < n:
        bits += 1
    mask = np.uint64((1 << bits) - 1)
    half = np.uint64(bits // 2 + 1)
    mul_a = (key >> np.uint64(32)) | np.uint64(1)
    mul_b = _MUL[0] ^ ((key >> np.uint64(16)) & np.uint64(0xFFFE))
    w = np.uint64(j)
    while True:  # every step is a bijection of 0 .. 2^bits - 1, so the walk returns below n
        w = (w ^ key) & mask
        w = (w * mul_a) & mask
        w ^= w >> half
        w = (w + (key >> np.uint64(24))) & mask
        w = (w * mul_b) & mask
        w ^= w >> np.uint64(1)
        w = (w * _MUL[1]) & mask
        w ^= w >> half
        if w < np.uint64(n):
            break
    # The rotation by a uniform offset (Lemire's multiply-shift: uniform to within n / 2^32,
    # without a division) makes each point's cell uniform whatever the bijection's quality.
    offset = ((mix64(key ^ np.uint64(0x5DEECE66D)) >> np.uint64(32)) * np.uint64(n)) >> np.uint64(32)
    cell = w + offset
    if cell >= np.uint64(n):
        cell -= np.uint64(n)
    return np.int64(cell)


@jit_called
def point_pair(key: np.uint64, j: int, dim: int, nx: int, ny: int):
    """Dimensions ``dim`` and ``dim + 1`` (``dim`` even) of point ``j`` of a replicate's
    stratified set (key ``key``): its cell of the pair's permutation, jittered uniformly."""
    pair = mix64(key + np.uint64(dim // 2 + 1) * GOLDEN_GAMMA)
    cell = permute(j, nx * ny, pair)
    jitter = mix64(pair + np.uint64(j) * GOLDEN_GAMMA)  # 32 random bits for each coordinate
    ux = (cell % nx + float(np.int64(jitter >> _S32)) * _TO_UNIT32) / nx
    uy = (cell // nx + float(np.int64(jitter & _M32)) * _TO_UNIT32) / ny
    return min(ux, _ONE_BELOW), min(uy, _ONE_BELOW)


@jit_called
def point(key: np.uint64, j: int, dim: int, nx: int, ny: int) -> float:
    """Dimension ``dim`` of point ``j`` of a replicate's stratified set (key ``key``)."""
    u = point_pair(key, j, dim - (dim & 1), nx, ny)
    return u[dim & 1]


# The sampler interface (``tracer.samplers``).


@jit
def start(sampler, pixel: int, sample: int):
    """The lane's state ``(key, index, 0)``: the key of its replicate's set of this render (its
    first point, ``first_sample``, keys it) and the sample's point index in that set."""
    key, index = replicate_start(sampler, pixel, sample)
    r = sample % sampler.replicates
    # The render's first point of replicate r: ceil((first_sample - r) / R), at least 0.
    first = max(0, (sampler.first_sample - r + sampler.replicates - 1) // sampler.replicates)
    key = mix64(key + np.uint64(first + 1) * GOLDEN_GAMMA)
    return key, index - first, 0


@jit
def uniform(sampler, state, dim: int) -> float:
    return point(state[0], state[1], dim, sampler.nx, sampler.ny)


@jit
def uniform_pair(sampler, state, dim: int):
    return point_pair(state[0], state[1], dim, sampler.nx, sampler.ny)
