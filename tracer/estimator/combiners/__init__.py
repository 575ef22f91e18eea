"""Combiners: how a shading point's light and direction samples add up, one module each.

Each module is a plug-in (``tracer.plugins.Combiner``) that defines, compiled per lane
(templates, ``tracer.kernels``):

- ``counts(plan, tuned, sampler, state, pixel, sample) -> (lights, dirs, own_light, own_dir)``:
  how many samples of each technique the shading point takes, and their expected counts,
  which divide each sample's contribution (``tracer.estimator.counts``);
- ``weight(heuristic, mine, other) -> float``: the weight of a sample whose own count-scaled
  pdf is ``mine`` against the other technique's ``other`` (``tracer.mis``).

==========  ==========================================================================
combiner    module
==========  ==========================================================================
sum         ``sum.py``: one technique alone (light or direction samples), weight 1
mis         ``mis.py``: multi-sample MIS (Veach 1997, 9.2), fixed or adaptive counts
one_sample  ``one_sample.py``: one technique per camera sample (Veach 1997, 9.2.4)
ris         ``ris.py``: resampled importance sampling, one candidate kept (Talbot et al. 2005)
==========  ==========================================================================
"""
