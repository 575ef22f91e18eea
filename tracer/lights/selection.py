"""Which light to sample: the discrete distributions of the ``power`` and ``uniform`` light
selections (``tracer.lights.selections``), drawn from Walker's alias table.

- ``power`` (default): each candidate in proportion to the flux it emits, pi * area * mean(Le)
  for an emitting triangle and 4 pi * mean(I) for a point light, so bright lights get more
  samples;
- ``uniform``: each light (an emissive shape or a point light) equally likely, then a triangle
  of that shape in proportion to its area (a textured emitter's: to its flux, the integral of its
  texture over the triangle, ``tracer.lights.textured_area``);
- ``bvh``: by a light BVH, in proportion to each candidate's importance at the shading point
  (``bvh.py``); its pmf depends on the point.

``power`` and ``uniform`` draw candidates with Walker's alias method (O(1) per sample). The
selection probability is multiplied into the light pdf by ``tracer.lights``, where MIS needs it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import jit


class AliasTables(NamedTuple):
    """Walker's table of a selection pmf over K candidates: ``alias_prob (K,)`` float64,
    ``alias (K,)`` int64, and ``pmf (K,)`` float64 the probabilities."""

    alias_prob: np.ndarray
    alias: np.ndarray
    pmf: np.ndarray


def alias_tables(selection: str, candidates) -> AliasTables:
    """The alias table of ``selection`` (``power`` or ``uniform``) over ``candidates``
    (``tracer.lights.emitters.Candidates``)."""
    weight = weights(selection, candidates.flux, candidates.owner, candidates.share)
    pmf = weight / weight.sum() if len(weight) else weight
    alias_prob, alias = alias_table(pmf)
    return AliasTables(alias_prob, alias, pmf)


@jit
def alias_choose(sel, x, n_receiver, u: float):
    """``(k, pmf_k)`` of an alias table's candidate for ``u`` (the point does not matter);
    ``(-1, 0.0)`` without candidates."""
    if len(sel.alias) == 0:
        return -1, 0.0
    k = pick(sel.alias_prob, sel.alias, u)
    return k, sel.pmf[k]


@jit
def alias_pmf(sel, k: int, x, n_receiver) -> float:
    return sel.pmf[k]


def weights(selection: str, flux: np.ndarray, light: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Unnormalized selection weights of K candidates.

    flux : (K,) flux of each candidate.   light : (K,) the light (emissive shape or point light)
    each candidate belongs to.   area : (K,) what ``uniform`` splits a light by: the area of each
    candidate (1 for point lights), a textured emitter's flux (``Emitters.share``).
    """
    if selection == "power":
        return np.asarray(flux, dtype=np.float64)
    if len(light) == 0:
        return np.zeros(0)
    _, light = np.unique(light, return_inverse=True)
    light_area = np.bincount(light, weights=area)
    return area / light_area[light] / (light.max() + 1)


def alias_table(pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Walker's alias table for ``pmf (K,)`` by Vose's stable construction (Vose 1991): column k
    keeps itself with probability prob[k] and otherwise gives its alias. Compiled: O(K) with
    no interpreter steps per candidate (100,000 emitters take milliseconds)."""
    return _vose(np.ascontiguousarray(pmf, dtype=np.float64))


@jit
def _vose(pmf):
    k = len(pmf)
    prob = np.ones(k)
    alias = np.arange(k)
    scaled = pmf * k
    # Two stacks of column indices, filled in index order and popped from the end: row 0 the
    # columns below 1 ("small"), row 1 the rest; height[r] the count in stack r.
    stacks = np.empty((2, k), dtype=np.int64)
    height = np.zeros(2, dtype=np.int64)
    for i in range(k):
        _push(stacks, height, 0 if scaled[i] < 1.0 else 1, i)
    while height[0] > 0 and height[1] > 0:
        height -= 1
        s, g = stacks[0, height[0]], stacks[1, height[1]]
        prob[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        _push(stacks, height, 0 if scaled[g] < 1.0 else 1, g)
    # What remains is 1 up to rounding: keep those columns whole (prob starts at 1).
    return prob, alias


@jit
def _push(stacks, height, which: int, column: int) -> None:
    stacks[which, height[which]] = column
    height[which] += 1


@jit
def pick(alias_prob, alias, u_select: float) -> int:
    """A candidate index distributed by the pmf, by Walker's alias method: the integer part of
    u K picks a column, the fraction decides between the column and its alias."""
    count = len(alias)
    scaled = u_select * count
    column = min(int(scaled), count - 1)
    return column if scaled - column < alias_prob[column] else alias[column]
