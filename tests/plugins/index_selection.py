"""A light selection plug-in: every emitter candidate equally likely, whatever its power or
shape (each triangle of a mesh counts once): the baseline that ``power`` and ``uniform``
improve on."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tracer.jit import jit
from tracer.plugins import LightSelection, register

NAME = "index"
PLUGIN = register(LightSelection(NAME, module=__name__, dims=1, doc="every candidate alike"))


class IndexTables(NamedTuple):
    pmf: np.ndarray  # (K,) 1 / K each


def tables(candidates) -> IndexTables:
    count = len(candidates.flux)
    return IndexTables(np.full(count, 1.0 / count) if count else np.zeros(0))


@jit
def choose(sel, x, n_receiver, u: float):
    count = len(sel.pmf)
    if count == 0:
        return -1, 0.0
    k = min(int(u * count), count - 1)
    return k, sel.pmf[k]


@jit
def pmf(sel, k: int, x, n_receiver) -> float:
    return sel.pmf[k]
