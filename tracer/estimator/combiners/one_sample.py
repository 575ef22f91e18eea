"""The ``one_sample`` combiner: one-sample MIS (Veach 1997, section 9.2.4). Each camera sample
takes the light technique with probability c_l = N / (N + M), else the direction technique,
divides by c p of the one it took, and weights with c_l p_l against c_d p_d (the counts are the
choice probabilities, ``tracer.estimator.counts``). A plug-in (``tracer.estimator.combiners``)."""

from __future__ import annotations

from ... import mis
from ...kernels import template
from ...plugins import Combiner, register
from .. import counts as taken

NAME = "one_sample"
PLUGIN = register(Combiner(NAME, module=__name__, rank=2, doc="one-sample MIS"))


@template
def counts(plan, tuned, sampler, state, pixel: int, sample: int):
    return taken.drawn(plan, tuned, sampler, state, pixel, sample, plan.c_light)


weight = mis.weight_of
