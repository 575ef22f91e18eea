"""How many light and direction samples a shading point takes, when a combiner draws them.

One-sample MIS and adaptive allocation (``tracer.tuning``) fix only the expected counts n̄_l and
n̄_d = N - n̄_l of a camera sample's N technique samples: the point takes floor(n̄_l) light
samples and one more with probability frac(n̄_l) (dimension ``TECHNIQUE_CHOICE``), and the rest
direction samples; every weight and division uses the expected counts, so that each camera
sample stays unbiased (E[count] / n̄ = 1).
"""

from __future__ import annotations

import math

from .. import tuning
from ..kernels import UNBOUND, template
from ..samplers import dimensions


@template
def drawn(plan, tuned, sampler, state, pixel: int, sample: int, own_light: float):
    """``(lights_here, dirs_here, own_light, own_dir)`` for the expected light count
    ``own_light``, or the pixel's learned one (adaptive allocation, once learned)."""
    if plan.adaptive and len(tuned.light_count):
        own_light = tuned.light_count[pixel, tuning.group_of(sample, tuned.replicates, tuned.groups)]
    own_dir = plan.total - own_light
    whole = math.floor(own_light)
    extra = dispatch.uniform(sampler, state, dimensions.TECHNIQUE_CHOICE) < own_light - whole
    lights_here = int(whole) + (1 if extra else 0)
    return lights_here, int(plan.total) - lights_here, own_light, own_dir


@template
def fixed(plan):
    """The strategy's own counts: ``(n_light, n_dir, n_light, n_dir)``."""
    return plan.n_light, plan.n_dir, float(plan.n_light), float(plan.n_dir)


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
