"""Which light to sample: a discrete distribution over the emitter candidates.

- ``power`` (default): each candidate in proportion to the flux it emits, pi * area * mean(Le)
  for an emitting triangle and 4 pi * mean(I) for a point light, so bright lights get more
  samples;
- ``uniform``: each light (an emissive shape or a point light) equally likely, then a triangle
  of that shape in proportion to its area.

Candidates are drawn with Walker's alias method (O(1) per sample). The selection probability
is multiplied into the light pdf by ``tracer.lights``, where MIS needs it.
"""

from __future__ import annotations

import numpy as np

from ..jit import jit


def weights(selection: str, flux: np.ndarray, light: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Unnormalized selection weights of K candidates.

    flux : (K,) flux of each candidate.   light : (K,) the light (emissive shape or point light)
    each candidate belongs to.   area : (K,) area of each candidate (1 for point lights).
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
    keeps itself with probability prob[k] and otherwise gives its alias."""
    k = len(pmf)
    prob = np.ones(k)
    alias = np.arange(k)
    if k == 0:
        return prob, alias
    scaled = pmf * k
    small = [i for i in range(k) if scaled[i] < 1.0]
    large = [i for i in range(k) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        prob[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    # What remains is 1 up to rounding: keep those columns whole.
    for i in small + large:
        prob[i] = 1.0
    return prob, alias


@jit
def pick(alias_prob, alias, u_select: float) -> int:
    """A candidate index distributed by the pmf, by Walker's alias method: the integer part of
    u K picks a column, the fraction decides between the column and its alias."""
    count = len(alias)
    scaled = u_select * count
    column = min(int(scaled), count - 1)
    return column if scaled - column < alias_prob[column] else alias[column]
