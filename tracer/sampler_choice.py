"""The samplers a render can choose, and what each keeps: names, replicates, index limits.

The samplers themselves are compiled code (``tracer.samplers``); this module only names them,
without importing numba, so that the command line, scene files and render files can check a
sampler's name at no start-up cost. The order of ``SAMPLERS`` gives each sampler its code in
the kernels.
"""

from __future__ import annotations

SAMPLERS = ("independent", "stratified", "sobol")
DEFAULT_SAMPLER = "independent"
# Independently randomized replicates per pixel of the samplers that have them
# (``tracer.samplers``, "Replicates"): sample s belongs to replicate s % REPLICATES.
REPLICATES = 8
# A replicate's count is written as a float32 channel, exact up to 2^24 (134 M spp a pixel).
MAX_REPLICATE_COUNT = 2**24
# Sobol points are generated with 32-bit indices: a replicate holds at most 2^32 of them.
SOBOL_MAX_INDEX = 2**32
MAX_SAMPLE_INDEX = 2**53  # sample counts and indices stay exact in float64


def replicates_of(name: str | None) -> int:
    """The replicates of the sampler called ``name``: 0 for ``independent`` (and None, files
    from before samplers were named), ``REPLICATES`` for the others."""
    return 0 if name in (None, DEFAULT_SAMPLER) else REPLICATES


def max_samples(name: str) -> int:
    """One past the largest sample index the sampler ``name`` can draw in a pixel."""
    return REPLICATES * SOBOL_MAX_INDEX if name == "sobol" else MAX_SAMPLE_INDEX
