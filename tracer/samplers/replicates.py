"""Where a lane of a sampler with replicates starts: its replicate's key and point index.

Sample ``s`` of a pixel belongs to replicate ``r = s % R`` as its point ``s // R``
(``tracer.samplers``, "Replicates"); each replicate of each pixel has its own key, so its
points are randomized independently of the other replicates'.
"""

from __future__ import annotations

from ..jit import jit
from .independent import lane_key


@jit
def replicate_start(sampler, pixel: int, sample: int):
    """``(key, index)``: the key of the replicate of sample ``sample`` of ``pixel`` and the
    sample's point index in it."""
    r = sample % sampler.replicates
    return lane_key(sampler.seed_key, pixel, r), sample // sampler.replicates
