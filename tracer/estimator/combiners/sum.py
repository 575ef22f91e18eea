"""The ``sum`` combiner: one technique alone (a strategy with only light or only direction
samples), each sample divided by its count, weight 1. A plug-in (``tracer.estimator.combiners``)."""

from __future__ import annotations

from ...jit import jit
from ...kernels import template
from ...plugins import Combiner, register
from .. import counts as taken

NAME = "sum"
PLUGIN = register(Combiner(NAME, module=__name__, rank=0, doc="one technique, each sample weight 1"))


@template
def counts(plan, tuned, sampler, state, pixel: int, sample: int):
    return taken.fixed(plan)


@jit
def weight(heuristic: int, mine: float, other: float) -> float:
    return 1.0
