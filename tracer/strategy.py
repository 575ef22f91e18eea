"""What a strategy is: the names users choose among and the sample counts behind them.

This module holds names and validation only (no numba), so that the command line can list the
choices in ``--help`` without compiling anything. The estimator that runs a strategy is
``tracer.estimator``; the heuristics themselves are ``tracer.mis``.

A strategy is a pair of sample counts per camera sample (Mitsuba's ``emitter_samples`` and
``bsdf_samples``) and the technique that draws the directions; for ``ris`` the counts are of
candidates, of which one is kept and shadow-tested (``tracer.estimator``):

=========  ==============  =================  ===============================
strategy   light samples   direction samples  direction technique
=========  ==============  =================  ===============================
uniform    0               M                  uniform hemisphere
cosine     0               M                  cosine-weighted hemisphere
bsdf       0               M                  the material's own sampling
light      N               0                  -
mis        N               M                  the material's, weighted by MIS
ris        N candidates    M candidates       the material's; one candidate kept
auto       one of light, bsdf and mis with these counts, the light sampling and selection
           that a pilot measures most efficient on the scene (``tracer.auto``)
=========  ==============  =================  ===============================
"""

from __future__ import annotations

from dataclasses import dataclass

STRATEGIES = ("uniform", "cosine", "bsdf", "light", "mis", "ris", "auto")
# What ``compare`` runs when no strategies are named: the five classic ones (``ris`` is asked for).
CLASSIC_STRATEGIES = STRATEGIES[:5]
HEURISTICS = ("balance", "power", "max", "optimal")
# The classic heuristics of Veach's thesis; ``optimal`` (``tracer.tuning``) learns its weights.
CLASSIC_HEURISTICS = HEURISTICS[:3]
# How the light and BSDF samples of mis are split (``tracer.tuning``): the counts given, or per
# pixel from what earlier passes measured.
ALLOCATIONS = ("fixed", "adaptive")
# Where ris's candidates come from (``Strategy.ris``): light samples only, or both techniques.
RIS_SOURCES = ("light", "light+bsdf")
DEFAULT_RIS_CANDIDATES = 16
# How a chosen light is sampled (``tracer.lights``: by area, by solid angle, or by solid angle
# warped toward the receiver's cosine) and chosen (``tracer.lights.selections``): the names come
# from the plug-ins' registry (``LIGHT_SAMPLINGS``, ``LIGHT_SELECTIONS``, looked up on first use).
DEFAULT_LIGHT_SAMPLING = "area"
DEFAULT_LIGHT_SELECTION = "power"
# How the environment is light-sampled (``tracer.lights.environment``), the default first.
ENVIRONMENT_SAMPLINGS = ("luminance", "uniform", "compensated", "product")
ENVIRONMENT_SAMPLING_DOCS = {
    "luminance": "cells in proportion to luminance x solid angle (2-D inversion of the map)",
    "uniform": "uniform on the sphere of directions, p = 1 / (4 pi)",
    "compensated": "luminance less the map's mean, clamped at 0 (Karlik et al. 2019); needs BSDF samples",
    "product": "luminance x the shading point's BSDF lobe, by a hierarchy of blocks (after Clarberg and "
               "Akenine-Moller 2008)",
}
DEFAULT_HEURISTIC = "power"

# One line each for help texts and the reference pages (``tracer.manual``; a test checks that
# every name has one).
STRATEGY_DOCS = {
    "uniform": "direction samples uniform over the hemisphere, pdf 1 / 2pi",
    "cosine": "direction samples by the cosine, pdf cos / pi",
    "bsdf": "direction samples from the material's own sampling (its lobes)",
    "light": "light samples: an emitter chosen by the light selection, a point or direction on it "
             "by the light sampling; sees delta lights",
    "mis": "light and BSDF samples combined with MIS weights (--heuristic), N light + M BSDF "
           "samples or one of the two at random (--one-sample)",
    "ris": "resampled importance sampling: M candidates weighed by their unshadowed contribution, "
           "one kept, one shadow ray",
    "auto": "the most efficient of light, bsdf and mis (each light sampling and selection) on the scene, "
            "by a pilot's relMSE x cost per sample; the render record says what it chose",
}
HEURISTIC_DOCS = {
    "balance": "w_i = n_i p_i / sum_k n_k p_k (Veach 1997)",
    "power": "w_i = (n_i p_i)^2 / sum_k (n_k p_k)^2, exponent 2 (Veach 1997)",
    "max": "w_i = 1 for the technique of largest n_i p_i, else 0 (Veach 1997)",
    "optimal": "balance plus a control variate whose coefficient each pixel learns between passes "
               "(Kondapaneni et al. 2019)",
}
ALLOCATION_DOCS = {
    "fixed": "every camera sample takes N light and M BSDF samples",
    "adaptive": "each pixel splits its N + M samples as earlier passes measured best (Sbert et al. 2016)",
}
RIS_SOURCE_DOCS = {
    "light": "every candidate is a light sample",
    "light+bsdf": "half the candidates are light samples and half BSDF samples, with MIS-weighted "
                  "candidate pdfs",
}


def light_samplings() -> tuple[str, ...]:
    """Every ``--light-sampling`` value: each name a light technique lists."""
    from .lights import light_samplings as offered

    return offered()


def light_selections() -> tuple[str, ...]:
    """Every ``--light-selection`` value: the registered light selections."""
    from . import plugins

    return plugins.names("light_selection")


def __getattr__(name: str):
    # PEP 562: the plug-in names are looked up when asked for, so importing this module (for
    # the command line's strategy names) loads no compiled code.
    if name == "LIGHT_SAMPLINGS":
        return light_samplings()
    if name == "LIGHT_SELECTIONS":
        return light_selections()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
# The most light or direction samples (ris: candidates) a camera sample may take: a render's
# buffers grow with the count, and a million already takes one lane per batch. The command line,
# the API and render files (``tracer.record``) are held to it alike.
MAX_SAMPLES_PER_CAMERA_SAMPLE = 1_000_000
# The direction technique of each strategy that takes direction samples.
DIRECTION_TECHNIQUE = {"uniform": "uniform", "cosine": "cosine", "bsdf": "bsdf", "mis": "bsdf", "ris": "bsdf"}


@dataclass(frozen=True)
class Strategy:
    """How to estimate direct light: a strategy name and its sample counts.

    name : one of ``STRATEGIES``.
    heuristic : the MIS heuristic (``balance``, ``power`` with beta = 2, ``max``, or ``optimal``:
        the balance heuristic plus a control variate whose coefficient each pixel learns from
        earlier passes, ``tracer.tuning``); used by ``mis``, and by ``ris`` (not ``optimal``) to
        weight candidates from two techniques.
    light_samples : light samples per camera sample; used by ``light`` and ``mis`` (``ris``:
        light candidates).
    bsdf_samples : direction samples per camera sample; used by ``uniform``, ``cosine``,
        ``bsdf`` and ``mis`` (``ris``: BSDF candidates).
    one_sample : one-sample MIS: each camera sample takes one technique, chosen with
        probability light_samples : bsdf_samples.
    light_selection : how the light to sample is chosen (``power``, ``uniform``, or ``bvh``: by a
        light BVH's importance at the shading point).
    light_sampling : how a point or direction on the chosen light is drawn (``area``,
        ``solid-angle``, ``solid-angle-cos``); used by ``light`` and ``mis`` (whose BSDF samples
        are weighted with its pdf).
    allocation : ``fixed`` (the counts above) or ``adaptive`` (mis only: each pixel splits the
        same number of samples between the techniques as earlier passes say is best,
        ``tracer.tuning``).
    environment_sampling : how a direction of the environment is drawn (``ENVIRONMENT_SAMPLINGS``:
        ``luminance``, ``uniform``, ``compensated``); used where light samples are. ``compensated``
        never samples the map's cells below its mean, so it needs BSDF samples to cover them: mis,
        or ris with BSDF candidates.

    Raises ``ValueError`` with a message naming the bad field.
    """

    name: str = "mis"
    heuristic: str = DEFAULT_HEURISTIC
    light_samples: int = 1
    bsdf_samples: int = 1
    one_sample: bool = False
    light_selection: str = DEFAULT_LIGHT_SELECTION
    light_sampling: str = DEFAULT_LIGHT_SAMPLING
    allocation: str = "fixed"
    environment_sampling: str = ENVIRONMENT_SAMPLINGS[0]

    def __post_init__(self) -> None:
        if self.name not in STRATEGIES:
            raise ValueError(f"unknown strategy {self.name!r}; expected one of {', '.join(STRATEGIES)}")
        if self.heuristic not in HEURISTICS:
            raise ValueError(f"unknown heuristic {self.heuristic!r}; expected one of {', '.join(HEURISTICS)}")
        if self.light_selection not in light_selections():
            raise ValueError(f"unknown light selection {self.light_selection!r}; "
                             f"expected one of {', '.join(light_selections())}")
        if self.light_sampling not in light_samplings():
            raise ValueError(f"unknown light sampling {self.light_sampling!r}; "
                             f"expected one of {', '.join(light_samplings())}")
        for field_name in ("light_samples", "bsdf_samples"):
            count = getattr(self, field_name)
            if isinstance(count, bool) or not isinstance(count, int) or not 0 <= count <= MAX_SAMPLES_PER_CAMERA_SAMPLE:
                raise ValueError(f"{field_name} must be a whole number in 0 .. {MAX_SAMPLES_PER_CAMERA_SAMPLE}, "
                                 f"got {count!r}")
        if self.light_count + self.direction_count == 0:
            raise ValueError(f"strategy {self.name!r} with these counts takes no samples")
        if self.name == "ris" and self.light_samples == 0:
            raise ValueError("ris needs light_samples >= 1 (light candidates)")
        if self.allocation not in ALLOCATIONS:
            raise ValueError(f"unknown allocation {self.allocation!r}; expected one of "
                             f"{', '.join(ALLOCATIONS)}")
        if self.allocation == "adaptive" and not (self.name == "mis" and self.light_samples
                                                  and self.bsdf_samples):
            raise ValueError("adaptive allocation splits samples between light and BSDF sampling: it needs "
                             "the mis strategy with light_samples >= 1 and bsdf_samples >= 1")
        if self.environment_sampling not in ENVIRONMENT_SAMPLINGS:
            raise ValueError(f"unknown environment sampling {self.environment_sampling!r}; expected one of "
                             f"{', '.join(ENVIRONMENT_SAMPLINGS)}")
        if self.environment_sampling == "compensated" and self.light_count and not (
                self.direction_technique == "bsdf" and self.direction_count):
            raise ValueError("compensated environment sampling leaves the map's cells below its mean to BSDF "
                             "samples: it needs mis, or ris with BSDF candidates (light sampling alone would "
                             "miss their light)")
        if self.name == "auto" and (self.light_sampling, self.light_selection, self.allocation, self.one_sample) \
                != (DEFAULT_LIGHT_SAMPLING, DEFAULT_LIGHT_SELECTION, "fixed", False):
            raise ValueError("auto chooses the light sampling and light selection itself, with fixed counts and "
                             "multi-sample MIS: give it none of --light-sampling, --light-selection, "
                             "--allocation, --one-sample")
        if self.name == "auto" and self.heuristic == "optimal":
            raise ValueError("auto chooses among fixed strategies: the optimal heuristic learns between passes "
                             "(use balance, power or max)")
        if self.name == "ris" and self.heuristic == "optimal" and self.bsdf_samples:
            raise ValueError("ris cannot use the optimal heuristic: its weights may be negative, and ris "
                             "resamples in proportion to them (use balance, power or max)")

    @classmethod
    def ris(cls, candidates: int = DEFAULT_RIS_CANDIDATES, sources: str = "light", **options) -> "Strategy":
        """``ris`` with ``candidates`` M per shading point: all light samples (``sources`` =
        ``light``), or M - M // 2 light and M // 2 BSDF samples (``light+bsdf``, M >= 2)."""
        if sources not in RIS_SOURCES:
            raise ValueError(f"unknown ris sources {sources!r}; expected one of {', '.join(RIS_SOURCES)}")
        if (isinstance(candidates, bool) or not isinstance(candidates, int)
                or not 1 <= candidates <= MAX_SAMPLES_PER_CAMERA_SAMPLE):
            raise ValueError(f"ris candidates must be a whole number in 1 .. {MAX_SAMPLES_PER_CAMERA_SAMPLE}, "
                             f"got {candidates!r}")
        if sources == "light+bsdf" and candidates < 2:
            raise ValueError("ris with light+bsdf candidates needs at least 2")
        bsdf = candidates // 2 if sources == "light+bsdf" else 0
        return cls("ris", light_samples=candidates - bsdf, bsdf_samples=bsdf, **options)

    @property
    def label(self) -> str:
        """A short description such as ``mis (power, 1 light + 1 bsdf)``."""
        if self.name == "auto":
            counts = "" if (self.light_samples, self.bsdf_samples) == (1, 1) else \
                f", {self.light_samples} light + {self.bsdf_samples} bsdf"
            return f"auto ({self.heuristic}{counts})" if self.heuristic != DEFAULT_HEURISTIC or counts else "auto"
        picked = {"uniform": ", lights picked uniformly", "bvh": ", lights picked by BVH"}
        selection = picked.get(self.light_selection, "") if self.light_count else ""
        if self.light_count and self.light_sampling != DEFAULT_LIGHT_SAMPLING:
            selection += f", {self.light_sampling} light sampling"
        if self.light_count and self.environment_sampling != ENVIRONMENT_SAMPLINGS[0]:
            selection += f", {self.environment_sampling} environment"
        if self.name == "mis":
            mode = "one-sample, " if self.one_sample else ""
            split = ", adaptive allocation" if self.adaptive else ""
            return (f"mis ({mode}{self.heuristic}, {self.light_samples} light + {self.bsdf_samples} bsdf"
                    f"{split}{selection})")
        if self.name == "ris":
            mix = f", {self.heuristic}" if self.bsdf_samples else ""
            sources = f"{self.light_samples} light + {self.bsdf_samples} bsdf" if self.bsdf_samples \
                else str(self.light_samples)
            return f"ris ({sources} candidates{mix}{selection})"
        count = self.light_count or self.direction_count
        parts = ([f"x{count}"] if count != 1 else []) + ([selection[2:]] if selection else [])
        return f"{self.name} ({', '.join(parts)})" if parts else self.name

    @property
    def slug(self) -> str:
        """This strategy's one name in files, table rows and curves: its name, then what differs
        from the defaults, ``mis``, ``mis_balance``, ``mis_l2_b1_one-sample``, ``ris_m16``,
        ``mis_optimal_adaptive``, ``light_x4_solid-angle_uniform-lights``. Equal slugs are equal
        strategies (``to_record``), so no two files or rows of a study share one."""
        count = self.light_count or self.direction_count
        if self.name == "ris":
            parts = [self.name, f"l{self.light_samples}_b{self.bsdf_samples}" if self.bsdf_samples
                     else f"m{self.light_samples}"]
        elif self.name in ("mis", "auto"):
            parts = [self.name] + ([] if (self.light_samples, self.bsdf_samples) == (1, 1)
                                   else [f"l{self.light_samples}_b{self.bsdf_samples}"])
            if self.one_sample:
                parts.append("one-sample")
        else:
            parts = [self.name] + ([f"x{count}"] if count != 1 else [])
        if self.recorded_heuristic not in ("none", DEFAULT_HEURISTIC):
            parts.append(self.heuristic)
        if self.adaptive:
            parts.append("adaptive")
        if self.light_count and self.light_sampling != DEFAULT_LIGHT_SAMPLING:
            parts.append(self.light_sampling)
        if self.light_count and self.light_selection != DEFAULT_LIGHT_SELECTION:
            parts.append(f"{self.light_selection}-lights")
        if self.light_count and self.environment_sampling != ENVIRONMENT_SAMPLINGS[0]:
            parts.append(f"{self.environment_sampling}-environment")
        return "_".join(parts)

    @classmethod
    def from_options(cls, name: str = "mis", *, heuristic: str | None = None,
                     light_samples: int | None = None, bsdf_samples: int | None = None,
                     one_sample: bool | None = None,
                     light_selection: str | None = None, light_sampling: str | None = None,
                     allocation: str | None = None, ris_candidates: int | None = None,
                     ris_sources: str | None = None, environment_sampling: str | None = None) -> "Strategy":
        """The strategy of the command line's, the API's and a check entry's options, None
        meaning the default (the field defaults of this class, ``DEFAULT_RIS_CANDIDATES``,
        ``RIS_SOURCES[0]``). ``ris`` takes its counts from ``ris_candidates`` and
        ``ris_sources``, the others from ``light_samples`` and ``bsdf_samples``. Raises
        ``ValueError`` naming the bad option."""
        given = {"heuristic": heuristic, "light_selection": light_selection, "light_sampling": light_sampling,
                 "environment_sampling": environment_sampling}
        given = {k: v for k, v in given.items() if v is not None}
        if name == "ris":
            return cls.ris(DEFAULT_RIS_CANDIDATES if ris_candidates is None else ris_candidates,
                           RIS_SOURCES[0] if ris_sources is None else ris_sources, **given)
        counts = {"light_samples": light_samples, "bsdf_samples": bsdf_samples, "one_sample": one_sample,
                  "allocation": allocation}
        return cls(name, **given, **{k: v for k, v in counts.items() if v is not None})

    def to_record(self) -> dict[str, object]:
        """The record's estimator fields (``tracer.record.ESTIMATOR_FIELDS`` but the sampler): the
        counts this strategy takes, and ``none`` for a heuristic or light sampling it does not use."""
        return {"strategy": self.name, "heuristic": self.recorded_heuristic,
                "light_samples": int(self.light_count), "bsdf_samples": int(self.direction_count),
                "one_sample": bool(self.one_sample),
                "light_selection": self.light_selection, "light_sampling": self.recorded_light_sampling,
                "allocation": self.allocation, "environment_sampling": self.recorded_environment_sampling}

    @classmethod
    def from_record(cls, record) -> "Strategy":
        """The strategy of a render record (``tracer.record.RenderRecord``, or a mapping of its
        fields), with the defaults where a file from an older tracer leaves a field out; a render
        of it pools with the recorded one (``record.check_mergeable``). Raises ``ValueError``."""
        def field(name: str):
            value = record.get(name) if isinstance(record, dict) else getattr(record, name, None)
            return None if value in (None, "none") else value

        if field("strategy") is None:
            raise ValueError("the record names no strategy")
        return cls(field("strategy"), **{name: field(name) for name in
                                         ("heuristic", "light_samples", "bsdf_samples", "one_sample",
                                          "light_selection", "light_sampling", "allocation",
                                          "environment_sampling")
                                         if field(name) is not None})

    @property
    def light_count(self) -> int:
        """Light samples per camera sample that this strategy takes (0 if it takes none)."""
        return self.light_samples if self.name in ("light", "mis", "ris", "auto") else 0

    @property
    def direction_count(self) -> int:
        """Direction samples per camera sample that this strategy takes (0 if it takes none)."""
        return self.bsdf_samples if self.name != "light" else 0

    @property
    def direction_technique(self) -> str | None:
        """``uniform``, ``cosine`` or ``bsdf``: how direction samples are drawn (None: none are)."""
        return DIRECTION_TECHNIQUE.get(self.name)

    @property
    def recorded_heuristic(self) -> str:
        """The heuristic as records and reports state it: ``none`` unless the strategy is mis."""
        return self.heuristic if self.name in ("mis", "auto") or (self.name == "ris" and self.bsdf_samples) \
            else "none"

    @property
    def recorded_light_sampling(self) -> str:
        """The light sampling as records state it: ``none`` unless the strategy takes light samples."""
        return self.light_sampling if self.light_count else "none"

    @property
    def recorded_environment_sampling(self) -> str:
        """The environment sampling as records state it: ``none`` unless the strategy takes light
        samples."""
        return self.environment_sampling if self.light_count else "none"

    @property
    def adaptive(self) -> bool:
        """Each pixel chooses its own split of light and BSDF samples (``tracer.tuning``)."""
        return self.allocation == "adaptive"

    @property
    def learns(self) -> bool:
        """Renders learn between passes (``tracer.tuning``), so that every pass depends on all
        the samples before it: they cannot be cut into independent tasks."""
        return self.learns_control_variate or self.adaptive

    @property
    def learns_control_variate(self) -> bool:
        """Optimal MIS with several samples per technique: the estimator adds a control variate
        whose coefficient is learned per pixel (``tracer.tuning``). With one-sample MIS the
        balance heuristic is already optimal, so there is nothing to learn."""
        return self.name == "mis" and self.heuristic == "optimal" and not self.one_sample_mis \
            and self.light_count > 0 and self.direction_count > 0

    @property
    def one_sample_mis(self) -> bool:
        """Each shading point takes one technique, chosen at random (both counts > 0)."""
        return self.one_sample and self.name != "ris" and self.light_count > 0 and self.direction_count > 0

    @property
    def samples_per_lane(self) -> int:
        """Shading rays one camera sample casts at most (light plus direction samples)."""
        if self.name == "ris":  # candidates cast no shadow rays: one for the kept one, one per BSDF candidate
            return 1 + self.direction_count
        return 1 if self.one_sample_mis else self.light_count + self.direction_count
