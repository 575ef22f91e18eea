"""What a strategy is: the names users choose among and the sample counts behind them.

This module holds names and validation only (no numba), so that the command line can list the
choices in ``--help`` without compiling anything. The estimator that runs a strategy is
``tracer.estimators``; the heuristics themselves are ``tracer.mis``.

A strategy is a pair of sample counts per camera sample (Mitsuba's ``emitter_samples`` and
``bsdf_samples``) and the technique that draws the directions; for ``ris`` the counts are of
candidates, of which one is kept and shadow-tested (``tracer.estimators``):

=========  ==============  =================  ===============================
strategy   light samples   direction samples  direction technique
=========  ==============  =================  ===============================
uniform    0               M                  uniform hemisphere
cosine     0               M                  cosine-weighted hemisphere
bsdf       0               M                  the material's own sampling
light      N               0                  -
mis        N               M                  the material's, weighted by MIS
ris        N candidates    M candidates       the material's; one candidate kept
=========  ==============  =================  ===============================
"""

from __future__ import annotations

from dataclasses import dataclass

STRATEGIES = ("uniform", "cosine", "bsdf", "light", "mis", "ris")
# What ``compare`` runs when no strategies are named: the five classic ones (``ris`` is asked for).
CLASSIC_STRATEGIES = STRATEGIES[:5]
HEURISTICS = ("balance", "power", "max", "optimal")
# The classic heuristics of Veach's thesis; ``optimal`` (``tracer.tuning``) learns its weights.
CLASSIC_HEURISTICS = HEURISTICS[:3]
# How the light and BSDF samples of mis are split (``tracer.tuning``): the counts given, or per
# pixel from what earlier passes measured.
ALLOCATIONS = ("fixed", "adaptive")
LIGHT_SELECTIONS = ("power", "uniform", "bvh")
# Where ris's candidates come from (``Strategy.ris``): light samples only, or both techniques.
RIS_SOURCES = ("light", "light+bsdf")
DEFAULT_RIS_CANDIDATES = 16
# How a chosen light is sampled (``tracer.lights``): by area, by solid angle, or by solid angle
# warped toward the receiver's cosine.
LIGHT_SAMPLINGS = ("area", "solid-angle", "solid-angle-cos")
DEFAULT_LIGHT_SAMPLING = "area"
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

    Raises ``ValueError`` with a message naming the bad field.
    """

    name: str = "mis"
    heuristic: str = "power"
    light_samples: int = 1
    bsdf_samples: int = 1
    one_sample: bool = False
    light_selection: str = "power"
    light_sampling: str = DEFAULT_LIGHT_SAMPLING
    allocation: str = "fixed"

    def __post_init__(self) -> None:
        if self.name not in STRATEGIES:
            raise ValueError(f"unknown strategy {self.name!r}; expected one of {', '.join(STRATEGIES)}")
        if self.heuristic not in HEURISTICS:
            raise ValueError(f"unknown heuristic {self.heuristic!r}; expected one of {', '.join(HEURISTICS)}")
        if self.light_selection not in LIGHT_SELECTIONS:
            raise ValueError(f"unknown light selection {self.light_selection!r}; "
                             f"expected one of {', '.join(LIGHT_SELECTIONS)}")
        if self.light_sampling not in LIGHT_SAMPLINGS:
            raise ValueError(f"unknown light sampling {self.light_sampling!r}; "
                             f"expected one of {', '.join(LIGHT_SAMPLINGS)}")
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
        picked = {"uniform": ", lights picked uniformly", "bvh": ", lights picked by BVH"}
        selection = picked.get(self.light_selection, "") if self.light_count else ""
        if self.light_count and self.light_sampling != DEFAULT_LIGHT_SAMPLING:
            selection += f", {self.light_sampling} light sampling"
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
    def file_stem(self) -> str:
        """A file-name part that tells this strategy's settings apart from the defaults':
        ``mis``, ``mis_balance``, ``mis_l2_b1_one-sample``, ``light_x4_uniform-lights``."""
        parts = [self.name]
        if self.name == "mis":
            if self.heuristic != "power":
                parts.append(self.heuristic)
            if (self.light_samples, self.bsdf_samples) != (1, 1):
                parts.append(f"l{self.light_samples}_b{self.bsdf_samples}")
            if self.one_sample:
                parts.append("one-sample")
            if self.adaptive:
                parts.append("adaptive")
        elif self.name == "ris":
            parts.append(f"l{self.light_samples}_b{self.bsdf_samples}" if self.bsdf_samples
                         else f"m{self.light_samples}")
            if self.bsdf_samples and self.heuristic != "power":
                parts.append(self.heuristic)
        elif (self.light_count or self.direction_count) != 1:
            parts.append(f"x{self.light_count or self.direction_count}")
        if self.light_count and self.light_selection != "power":
            parts.append(f"{self.light_selection}-lights")
        if self.light_count and self.light_sampling != DEFAULT_LIGHT_SAMPLING:
            parts.append(self.light_sampling)
        return "_".join(parts)

    @property
    def light_count(self) -> int:
        """Light samples per camera sample that this strategy takes (0 if it takes none)."""
        return self.light_samples if self.name in ("light", "mis", "ris") else 0

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
        return self.heuristic if self.name == "mis" or (self.name == "ris" and self.bsdf_samples) else "none"

    @property
    def recorded_light_sampling(self) -> str:
        """The light sampling as records state it: ``none`` unless the strategy takes light samples."""
        return self.light_sampling if self.light_count else "none"

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
