"""The render record: how a film was made, as every render file states it in its header.

One record type for ``render``, ``reference``, ``compare`` and ``merge``: the EXR writer
(``tracer.imagefiles``) stores it as ``tracer:*`` header attributes and the reader gives it back, so
that a merge can tell whether two files hold the same estimator and disjoint samples. The
attribute names are spelled here and nowhere else (``docs/DESIGN.md``, "The render file").

Sample indices: a render with ``seed`` drew the samples ``first_sample .. next_sample - 1`` of
every pixel (random numbers are a function of seed, pixel, sample index and dimension), so two
renders with the same seed hold the same samples exactly where these ranges overlap.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import InputError

PREFIX = "tracer:"
# The fields that define the estimator: renders may be pooled only if all of them agree.
ESTIMATOR_FIELDS = ("strategy", "heuristic", "light_samples", "bsdf_samples", "one_sample",
                    "light_selection", "sampler")


@dataclass
class RenderRecord:
    """How a render was made. ``None`` where a file did not say (files of other tools).

    strategy, heuristic, light_samples, bsdf_samples, one_sample, light_selection : the
        estimator (``tracer.strategy.Strategy``; heuristic ``none`` unless the strategy is mis).
    sampler : the random-number sampler (``independent``).
    seed : the seed; first_sample, next_sample : the sample indices drawn with it.
    seconds : rendering wall time, summed over the runs pooled into the film.
    scene : the scene file's path.   version : tracer's version.
    """

    strategy: str | None = None
    heuristic: str | None = None
    light_samples: int | None = None
    bsdf_samples: int | None = None
    one_sample: bool | None = None
    light_selection: str | None = None
    sampler: str | None = None
    seed: int | None = None
    first_sample: int | None = None
    next_sample: int | None = None
    seconds: float | None = None
    scene: str | None = None
    version: str | None = None

    @classmethod
    def of_render(cls, strategy: Any, sampler: str, seed: int, first_sample: int, spp: int,
                  seconds: float, scene: str) -> "RenderRecord":
        """The record of a render of ``strategy`` (a ``Strategy``) that drew samples
        ``first_sample .. first_sample + spp - 1`` with ``seed``."""
        from . import __version__

        return cls(strategy=strategy.name,
                   heuristic=strategy.recorded_heuristic,
                   light_samples=int(strategy.light_count), bsdf_samples=int(strategy.direction_count),
                   one_sample=bool(strategy.one_sample), light_selection=strategy.light_selection,
                   sampler=sampler, seed=int(seed), first_sample=int(first_sample),
                   next_sample=int(first_sample + spp), seconds=float(seconds), scene=str(scene),
                   version=__version__)

    def attributes(self) -> dict[str, Any]:
        """The ``tracer:*`` header attributes (booleans as 0/1; fields that are None left out).
        EXR integer attributes are 32-bit: a whole number outside that range (a seed or sample
        index >= 2^31) is stored as its decimal string, which :meth:`from_attributes` reads back."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if isinstance(value, bool):
                value = int(value)
            elif isinstance(value, int) and not -2**31 <= value < 2**31:
                value = str(value)
            out[PREFIX + f.name] = value
        return out

    @classmethod
    def from_attributes(cls, attributes: dict[str, Any]) -> "RenderRecord":
        """The record in a header's ``tracer:*`` attributes; unknown ones are ignored."""
        kinds = {"light_samples": int, "bsdf_samples": int, "seed": int, "first_sample": int,
                 "next_sample": int, "one_sample": lambda v: bool(int(v)), "seconds": float}
        values = {}
        for f in dataclasses.fields(cls):
            if PREFIX + f.name in attributes:
                raw = attributes[PREFIX + f.name]
                try:
                    values[f.name] = kinds.get(f.name, str)(raw)
                except (TypeError, ValueError):
                    raise InputError(f"header attribute {PREFIX + f.name} = {raw!r} is not a valid "
                                     f"{f.name}") from None
        return cls(**values)

    def sample_range(self, spp: int) -> tuple[int, int]:
        """``(first, next)`` sample indices drawn with the seed; a file that does not say holds
        ``0 .. spp - 1``."""
        first = self.first_sample if self.first_sample is not None else 0
        return first, self.next_sample if self.next_sample is not None else first + spp


def check_mergeable(a: RenderRecord, spp_a: int, b: RenderRecord, spp_b: int) -> None:
    """Raise ``InputError`` unless renders ``a`` and ``b`` hold the same estimator on the same
    scene with disjoint samples, so that pooling them counts every sample once."""
    for name in ESTIMATOR_FIELDS:
        va, vb = getattr(a, name), getattr(b, name)
        if name == "sampler":  # files from before the sampler existed used the independent one
            va, vb = va or "independent", vb or "independent"
        if va != vb:
            raise InputError(f"cannot merge renders with different {PREFIX}{name}: {va!r} and {vb!r}")
    if a.scene and b.scene and Path(a.scene).name != Path(b.scene).name:
        raise InputError(f"cannot merge renders of different scenes: {a.scene} and {b.scene}")
    if a.seed == b.seed:
        (first_a, next_a), (first_b, next_b) = a.sample_range(spp_a), b.sample_range(spp_b)
        if first_a < next_b and first_b < next_a:
            raise InputError(
                f"the two renders used the same seed and sample indices ({first_a}-{next_a - 1} and "
                f"{first_b}-{next_b - 1}): they hold the same samples, so merging them would count "
                "each twice; render one with another --seed")


def merged(a: RenderRecord, spp_a: int, b: RenderRecord, spp_b: int) -> RenderRecord:
    """The record of the pool of ``a`` and ``b`` (checked with :func:`check_mergeable`): the
    sample range that spans both, the seconds summed."""
    (first_a, next_a), (first_b, next_b) = a.sample_range(spp_a), b.sample_range(spp_b)
    return dataclasses.replace(a, first_sample=min(first_a, first_b), next_sample=max(next_a, next_b),
                               seconds=(a.seconds or 0.0) + (b.seconds or 0.0))
