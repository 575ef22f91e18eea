"""The samplers a render can choose, and what each keeps: names, replicates, index limits.

The samplers themselves are plug-ins (``tracer.samplers``, ``tracer.plugins``); this module
answers questions about them by name for the command line, scene files and render files. Its
constants are plain numbers (the sampler modules import them); the names come from the
registry when first asked for (``SAMPLERS``).
"""

from __future__ import annotations

DEFAULT_SAMPLER = "independent"
# Independently randomized replicates per pixel of the samplers that have them
# (``tracer.samplers``, "Replicates"): sample s belongs to replicate s % REPLICATES.
REPLICATES = 8
# A replicate's count is written as a float32 channel, exact up to 2^24 (134 M spp a pixel).
MAX_REPLICATE_COUNT = 2**24
# Sobol points are generated with 32-bit indices: a replicate holds at most 2^32 of them.
SOBOL_MAX_INDEX = 2**32
MAX_SAMPLE_INDEX = 2**53  # sample counts and indices stay exact in float64


def _registry():
    from . import plugins

    return plugins.registry("sampler")


def __getattr__(name: str):
    # PEP 562: SAMPLERS is the registry's names, looked up on first use (the sampler modules
    # import this module's constants, so it cannot import them while it is being imported).
    if name == "SAMPLERS":
        return tuple(_registry())
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def replicates_of(name: str | None) -> int:
    """The replicates of the sampler called ``name``: 0 for ``independent`` (and None, files
    from before samplers were named), ``REPLICATES`` for the others."""
    if name in (None, DEFAULT_SAMPLER):
        return 0
    plugin = _registry().get(name)
    return plugin.replicates if plugin is not None else REPLICATES


def max_samples(name: str) -> int:
    """One past the largest sample index the sampler ``name`` can draw in a pixel."""
    plugin = _registry().get(name)
    return plugin.max_samples if plugin is not None else MAX_SAMPLE_INDEX
