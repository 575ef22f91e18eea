"""The render record: how a film was made, as every render file states it in its header.

One record type for ``render``, ``reference``, ``compare`` and ``merge``: the EXR writer
(``tracer.imagefiles``) stores it as ``tracer:*`` header attributes and the reader gives it back, so
that a merge can tell whether two files hold the same estimator, the same scene and disjoint
samples. The attribute names are spelled here and nowhere else (``docs/DESIGN.md``, "The render
file").

Samples: random numbers are a function of (seed, pixel, sample index, dimension) (for the
``stratified`` sampler also of how the range was split into runs, which size its grids), so a
render with ``seed`` that drew sample indices ``first .. next - 1`` of every pixel holds exactly
the samples ``(seed, first, next)``. A film's record keeps the *set* of such ranges it was made from,
carried through every merge and resume (``tracer:samples``), so two files hold a sample in
common exactly when two of their ranges share a seed and overlap. A render interrupted in the
middle of a pass holds, in each pixel, a prefix of its range: the range still names every index
it may hold, and a resume starts after it.

Scene: ``scene_digest`` is a digest of what the scene renders (``Scene.digest``: geometry,
materials, emission, lights, camera; not the file's path, comments or resolution), so two files
of one scene file merge wherever they were rendered and two different files of the same name
do not.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import InputError, shown
from .strategy import MAX_SAMPLES_PER_CAMERA_SAMPLE

PREFIX = "tracer:"
# The fields that define the estimator: renders may be pooled only if all of them agree.
ESTIMATOR_FIELDS = ("strategy", "heuristic", "light_samples", "bsdf_samples", "one_sample",
                    "light_selection", "light_sampling", "allocation", "environment_sampling", "sampler")
MAX_SEED = 2**64 - 1
MAX_SAMPLE_INDEX = 2**53  # sample counts stay exact in float64
# (seed, first, next): samples first .. next - 1 of every pixel, drawn with seed.
SampleRange = tuple[int, int, int]
_RANGE = re.compile(r"(\d{1,20}):(\d{1,16})-(\d{1,16})")
_DIGEST = re.compile(r"[0-9a-f]{64}")


def canonical_ranges(ranges) -> tuple[SampleRange, ...]:
    """Sorted by (seed, first), empty ranges dropped, ranges of one seed that touch joined into
    one. Raises ValueError if two ranges of one seed overlap (they would hold the same samples)."""
    out: list[list[int]] = []
    for seed, first, nxt in sorted((int(a), int(b), int(c)) for a, b, c in ranges if int(c) > int(b)):
        if out and out[-1][0] == seed and first < out[-1][2]:
            raise ValueError(f"seed {seed}: sample indices {out[-1][1]}-{out[-1][2] - 1} and "
                             f"{first}-{nxt - 1} overlap")
        if out and out[-1][0] == seed and first == out[-1][2]:
            out[-1][2] = nxt
        else:
            out.append([seed, first, nxt])
    return tuple((a, b, c) for a, b, c in out)


def format_ranges(ranges: tuple[SampleRange, ...]) -> str:
    """``seed:first-last`` items (``last`` inclusive, as people read ranges), comma-separated."""
    return ",".join(f"{seed}:{first}-{nxt - 1}" for seed, first, nxt in ranges)


def parse_ranges(text: str) -> tuple[SampleRange, ...]:
    """The inverse of :func:`format_ranges`, checked: ValueError on anything else."""
    ranges = []
    for item in str(text).split(","):
        match = _RANGE.fullmatch(item.strip())
        if not match:
            raise ValueError(f"{item.strip()!r} is not seed:first-last")
        seed, first, last = (int(g) for g in match.groups())
        if seed > MAX_SEED or not first <= last < MAX_SAMPLE_INDEX:
            raise ValueError(f"{item.strip()!r} is out of range")
        ranges.append((seed, first, last + 1))
    return canonical_ranges(ranges)


@dataclass
class RenderRecord:
    """How a render was made. ``None`` where a file did not say (files of other tools).

    strategy, heuristic, light_samples, bsdf_samples, one_sample, light_selection,
        light_sampling, allocation, environment_sampling : the estimator
        (``tracer.strategy.Strategy``; heuristic ``none`` unless the strategy is mis,
        light_sampling and environment_sampling ``none`` unless it takes light samples).
    sampler : the random-number sampler (``independent``).
    samples : the sample ranges ``(seed, first, next)`` the film holds (``canonical_ranges``).
    seconds : rendering wall time, summed over the runs pooled into the film.
    scene : the scene file's path (informative only).   scene_digest : ``Scene.digest``.
    version : tracer's version.
    auto : for a render of ``--strategy auto``, what its pilot measured (``tracer.auto.Choice.
        summary``: each candidate's efficiency relative to the strategy above, which it chose);
        None otherwise. Informative: renders pool by the strategy they ran.
    light_selection_ran : the selection the kernels ran where it differs from
        ``light_selection`` (``bvh`` on one leaf and no lights at infinity runs ``power``, which
        has the same probabilities: ``tracer.lights.build_tables``); None otherwise.
        Informative: it follows from the scene and the selection.
    """

    strategy: str | None = None
    heuristic: str | None = None
    light_samples: int | None = None
    bsdf_samples: int | None = None
    one_sample: bool | None = None
    light_selection: str | None = None
    light_sampling: str | None = None
    allocation: str | None = None
    environment_sampling: str | None = None
    sampler: str | None = None
    samples: tuple[SampleRange, ...] | None = None
    seconds: float | None = None
    scene: str | None = None
    scene_digest: str | None = None
    version: str | None = None
    auto: str | None = None
    light_selection_ran: str | None = None

    @classmethod
    def of_render(cls, strategy: Any, sampler: str, seed: int, first_sample: int, spp: int,
                  seconds: float, scene: Any) -> "RenderRecord":
        """The record of a render of ``strategy`` (a ``Strategy``) on ``scene`` (a ``Scene``)
        that drew samples ``first_sample .. first_sample + spp - 1`` with ``seed``."""
        from . import __version__

        return cls(**strategy.to_record(), sampler=sampler,
                   samples=((int(seed), int(first_sample), int(first_sample + spp)),),
                   seconds=float(seconds), scene=str(scene.path), scene_digest=scene.digest,
                   version=__version__)

    @property
    def seed(self) -> int | None:
        """The seed, if the film was made with one only."""
        seeds = {r[0] for r in self.samples or ()}
        return seeds.pop() if len(seeds) == 1 else None

    @property
    def first_sample(self) -> int | None:
        """The first sample index, if the film holds one range only."""
        return self.samples[0][1] if self.samples and len(self.samples) == 1 else None

    @property
    def next_sample(self) -> int | None:
        """One past the last sample index, if the film holds one range only."""
        return self.samples[0][2] if self.samples and len(self.samples) == 1 else None

    def fresh_start(self, seed: int) -> int:
        """The first sample index of ``seed`` above every one the film holds: where samples
        that the film does not hold yet begin."""
        return max((nxt for s, _, nxt in self.samples or () if s == seed), default=0)

    def attributes(self) -> dict[str, Any]:
        """The ``tracer:*`` header attributes (booleans as 0/1; fields that are None left out).
        ``samples`` is written as ``tracer:samples`` (:func:`format_ranges`) and, when it is
        one range, also as ``tracer:seed``, ``tracer:first_sample`` and ``tracer:next_sample``
        for readers that look for those. EXR integer attributes are 32-bit: a whole number
        outside that range (a seed or sample index >= 2^31) is stored as its decimal string,
        which :meth:`from_attributes` reads back."""
        out: dict[str, Any] = {}
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if self.samples:
            values["samples"] = format_ranges(self.samples)
            if len(self.samples) == 1:
                values.update(seed=self.seed, first_sample=self.first_sample, next_sample=self.next_sample)
        for name, value in values.items():
            if value is None:
                continue
            if isinstance(value, bool):
                value = int(value)
            elif isinstance(value, int) and not -2**31 <= value < 2**31:
                value = str(value)
            out[PREFIX + name] = value
        return out

    @classmethod
    def from_attributes(cls, attributes: dict[str, Any], spp: int = 0) -> "RenderRecord":
        """The record in a header's ``tracer:*`` attributes; unknown ones are ignored. A file
        without ``tracer:samples`` (older tracer, other tools) holds one range: its
        ``tracer:seed`` from ``tracer:first_sample`` (default 0) to ``tracer:next_sample``
        (default first + ``spp``); without a seed its samples are unknown (None)."""
        kinds = {"light_samples": _per_camera_sample, "bsdf_samples": _per_camera_sample, "seed": _whole,
                 "first_sample": _whole, "next_sample": _whole, "one_sample": _flag, "seconds": _seconds,
                 "samples": parse_ranges, "scene_digest": _digest}
        values: dict[str, Any] = {}
        for name in [f.name for f in dataclasses.fields(cls)] + ["seed", "first_sample", "next_sample"]:
            if PREFIX + name in attributes:
                raw = attributes[PREFIX + name]
                try:
                    values[name] = kinds.get(name, str)(raw)
                except (TypeError, ValueError, OverflowError) as exc:
                    raise InputError(f"header attribute {PREFIX + name} = {shown(repr(raw))} is not a valid "
                                     f"{name}: {exc}") from None
        for name, allowed in _names().items():
            if name in values and values[name] not in allowed:
                raise InputError(f"header attribute {PREFIX}{name} = {shown(repr(values[name]))} is not one "
                                 f"of {', '.join(allowed)}")
        seed, first, nxt = (values.pop(k, None) for k in ("seed", "first_sample", "next_sample"))
        one = None
        if seed is not None:
            first = 0 if first is None else first
            nxt = first + spp if nxt is None else nxt
            if not (0 <= seed <= MAX_SEED and 0 <= first <= nxt <= MAX_SAMPLE_INDEX):
                raise InputError(f"header attributes {PREFIX}seed, first_sample, next_sample = {seed}, "
                                 f"{first}, {nxt} are not a seed and a sample range")
            one = ((seed, first, nxt),) if nxt > first else ()
        if "samples" not in values:
            values["samples"] = one
        elif one is not None and one != values["samples"]:
            raise InputError(f"header attributes {PREFIX}samples ({format_ranges(values['samples'])}) and "
                             f"{PREFIX}seed/first_sample/next_sample ({format_ranges(one)}) disagree")
        return cls(**values)


def _names() -> dict[str, tuple[str, ...]]:
    """The values a header's named fields may take where tracer acts on them: a resume renders
    with the file's sampler. (The strategy and heuristic are only compared and shown, and other
    tools name theirs as they like: the Mitsuba cross-check writes ``mitsuba-direct``.)"""
    from .sampler_choice import SAMPLERS
    from .strategy import ALLOCATIONS, ENVIRONMENT_SAMPLINGS, LIGHT_SAMPLINGS

    return {"sampler": SAMPLERS, "light_sampling": (*LIGHT_SAMPLINGS, "none"), "allocation": ALLOCATIONS,
            "environment_sampling": (*ENVIRONMENT_SAMPLINGS, "none")}


def _old_light_sampling(record: RenderRecord) -> str:
    """What a file written before ``tracer:light_sampling`` existed (tracer <= 0.2) did."""
    return "area" if record.light_samples else "none"


def _old_environment_sampling(record: RenderRecord) -> str:
    """What a file written before ``tracer:environment_sampling`` existed (tracer <= 0.9) did."""
    return "luminance" if record.light_samples else "none"


def _whole(value: Any) -> int:
    """A whole number from an attribute (an int, or the decimal string of a big one)."""
    if isinstance(value, float) or isinstance(value, str) and not re.fullmatch(r"-?\d{1,20}", value.strip()):
        raise ValueError("not a whole number")
    return int(value)


def _per_camera_sample(value: Any) -> int:
    """A light or BSDF sample count from a header, held to the bounds the command line has (a
    resume renders with it: 2^31 light samples allocated 24 GiB and died)."""
    count = _whole(value)
    if not 0 <= count <= MAX_SAMPLES_PER_CAMERA_SAMPLE:
        raise ValueError(f"not in 0 .. {MAX_SAMPLES_PER_CAMERA_SAMPLE}")
    return count


def _flag(value: Any) -> bool:
    flag = _whole(value)
    if flag not in (0, 1):
        raise ValueError("not 0 or 1")
    return bool(flag)


def _seconds(value: Any) -> float:
    seconds = float(value)
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise ValueError("not a finite number >= 0")
    return seconds


def _digest(value: Any) -> str:
    if not isinstance(value, str) or not _DIGEST.fullmatch(value):
        raise ValueError("not a SHA-256 hex digest")
    return value


def check_mergeable(a: RenderRecord, b: RenderRecord, name_a: str = "the first render",
                    name_b: str = "the second render") -> None:
    """Raise ``InputError`` unless renders ``a`` and ``b`` hold the same estimator on the same
    scene with disjoint samples, so that pooling them counts every sample once. The message
    names both (``name_a``, ``name_b``: file names where there are files) and the field."""
    for name in ESTIMATOR_FIELDS:
        va, vb = getattr(a, name), getattr(b, name)
        if name == "sampler":  # files from before the sampler existed used the independent one
            va, vb = va or "independent", vb or "independent"
        if name == "light_sampling":  # files from before it existed sampled lights by area
            va, vb = va or _old_light_sampling(a), vb or _old_light_sampling(b)
        if name == "allocation":  # files from before it existed (tracer <= 0.6) had fixed counts
            va, vb = va or "fixed", vb or "fixed"
        if name == "environment_sampling":  # files from before it existed (tracer <= 0.9) by luminance
            va, vb = va or _old_environment_sampling(a), vb or _old_environment_sampling(b)
        if va != vb:
            raise InputError(f"cannot pool {name_a} and {name_b}: different {PREFIX}{name} "
                             f"({va!r} and {vb!r})")
    if a.scene_digest and b.scene_digest:
        if a.scene_digest != b.scene_digest:
            raise InputError(f"cannot pool {name_a} and {name_b}: different {PREFIX}scene_digest (scenes "
                             f"{a.scene} and {b.scene} differ in content)")
    else:
        # Files from before the digest existed: the scene file names are all there is.
        for name, record in ((name_a, a), (name_b, b)):
            if not record.scene:
                raise InputError(f"cannot pool {name_a} and {name_b}: {name} does not say which scene it "
                                 f"is of (no {PREFIX}scene_digest or {PREFIX}scene)")
        if Path(a.scene).name != Path(b.scene).name:
            raise InputError(f"cannot pool {name_a} and {name_b}: different {PREFIX}scene "
                             f"({a.scene} and {b.scene})")
    for name, record in ((name_a, a), (name_b, b)):
        if record.samples is None:
            raise InputError(f"cannot pool {name_a} and {name_b}: {name} does not say which samples it "
                             f"holds (no {PREFIX}samples or {PREFIX}seed, or fewer listed than its pixels "
                             "hold, as in merges made by tracer 0.1)")
    try:
        canonical_ranges(a.samples + b.samples)
    except ValueError as exc:
        raise InputError(f"cannot pool {name_a} and {name_b}: both hold the same samples ({exc}), which "
                         "would be counted twice; render one with another --seed") from None


def merged(a: RenderRecord, b: RenderRecord) -> RenderRecord:
    """The record of the pool of ``a`` and ``b`` (checked with :func:`check_mergeable`): the
    union of their sample ranges, the seconds summed."""
    return dataclasses.replace(a, samples=canonical_ranges(a.samples + b.samples),
                               seconds=(a.seconds or 0.0) + (b.seconds or 0.0),
                               # A file without a digest was matched by scene name only; the
                               # digest that is known stays, so that later pools still check it.
                               scene_digest=a.scene_digest or b.scene_digest,
                               # Informative: kept where both say the same (files from before
                               # the field existed say nothing).
                               light_selection_ran=a.light_selection_ran
                               if a.light_selection_ran == b.light_selection_ran else None)
