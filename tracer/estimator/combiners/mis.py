"""The ``mis`` combiner: multi-sample MIS (Veach 1997, section 9.2). Each technique's pdf is
scaled by its count before the heuristic compares them, w_l = h(N p_l, M p_d), and each sample
is divided by its own count; with adaptive allocation (``tracer.tuning``) each pixel's counts
are drawn from what earlier passes learned (``tracer.estimator.counts``). A plug-in
(``tracer.estimator.combiners``)."""

from __future__ import annotations

from ... import mis
from ...kernels import template
from ...plugins import Combiner, register
from .. import counts as taken

NAME = "mis"
PLUGIN = register(Combiner(NAME, module=__name__, rank=1, doc="multi-sample MIS"))


@template
def counts(plan, tuned, sampler, state, pixel: int, sample: int):
    if plan.adaptive:
        return taken.drawn(plan, tuned, sampler, state, pixel, sample, float(plan.n_light))
    return taken.fixed(plan)


weight = mis.weight_of
