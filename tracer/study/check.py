"""Noise-level regression test: has a change made an estimator noisier, or biased?

A baseline file (JSON, format in the guide, docs/guide/noise-tests.md) lists entries ``{"scene",
"strategy", "heuristic", "spp", "seeds", "relmse", "variance", "image_means", ...}``. For each
entry the check renders the scene once per seed at a small resolution (the reference's
resolution divided by ``downsample``), each seed in ``REPLICATES_PER_SEED`` renders of
disjoint sample ranges (independent replicates), and runs four tests:

- **Noise** (one-sided exact Mann-Whitney U test per measure, relMSE and variance): the
  per-seed values of the new renders against the baseline's per-seed values. H0: both come
  from the same distribution, so every ordering of the pooled values is equally likely and the
  false-alarm rate is exact whatever the distribution, which matters because the relMSE of a
  heavy-tailed estimator is itself heavy-tailed (one firefly can double it). With n seeds a
  side the smallest p is 1 / C(2n, n) (7.8e-5 for 8): a regression is flagged when (nearly)
  every new seed is noisier than (nearly) every baseline seed, as doubling the variance does.
- **Image mean** (two-sided permutation test, ``statistics.permutation_p``): the replicate
  renders' image means against the baseline's, with Welch's statistic (the largest over the
  channels). Under H0 (an unchanged estimator) the 2r image means are exchangeable, so the
  false-alarm rate is exact whatever their distribution: heavy tails cannot make it liberal.
  The z-test of the pooled image against the reference used before could: for light sampling
  of a sharp GGX lobe the samples that raise the mean also raise the variance estimate, a
  render that misses them has both low, and z ran to -3 and below on unbiased renders. Whether
  the baseline itself is unbiased is tested against the reference when it is written (below).
- **Bias, per pixel** (Mitsuba 3's render test): z = (I - R) / sqrt(Var I + Var R) for every
  pixel and channel of the seeds' pooled image against the reference, two-sided, Sidak-
  corrected over the pixels at 1%; the entry fails if fewer than 99.75% of them pass.

Levels: the file's false-alarm rate is 1% (``FAMILY_ALPHA``), split with Sidak over 4 tests
per entry. A file whose level is below the smallest p-value a rank or permutation test can
reach with its seeds could never fail; it is refused, with the number of seeds it needs. The
pixel test's false-alarm rate under normal pixels is negligible (31 of 12288 pixel-channels
must fail at 8e-7 each); where pixels are not normal it is switched off (below).

**What --update (and --create) check before writing** (``gate``), so that every entry written
is unbiased as far as its renders can tell, and testable:

- pixels: the pixel test is kept where no pixel fails it in the baseline's pooled renders (a
  well-behaved entry has a failing pixel with probability about 1%, the per-pixel Sidak level)
  and switched off, with a note, where some do: there the estimator is heavy-tailed per pixel
  at its spp (most pixels see few light hits) and a normal z does not hold.
- image mean against the reference: a t-test of the replicates' image means against the
  reference's image mean and standard error (``statistics.t_against_reference``), at half the
  level; a failure refuses the entry as biased. The t-test needs the replicates' image means
  to be close to normal; that is checked by resampling the baseline's renders pixel by pixel
  (a bootstrap: pixels are independent, so a synthetic render draws each pixel's value from
  one of the replicates at random; Efron and Tibshirani 1993, An Introduction to the
  Bootstrap, ch. 6 and 12) and running the t-test on synthetic renders many times against the
  truth of that resampled world. An entry whose estimated false-alarm rate exceeds the level
  is refused as too heavy-tailed to confirm, naming the spp at which the same resampling
  (averaging k synthetic renders is one render at k times the spp) brings it within the
  level. That estimate comes from the renders at hand and rare events they missed make it low
  (the bootstrap of a heavy-tailed mean is known to be unreliable: Athreya 1987, Ann. Statist.
  15:724); --update checks again at the spp it named, and may then ask for more.

Renders are a deterministic function of their seeds (whatever the thread count): on the
machine that wrote the baseline, the unchanged tree with the baseline's seeds reproduces every
per-seed relMSE, variance and image mean exactly, so every rank test sees all ties (p ~ 0.5,
or 1 for the permutation test) and the pixel test repeats its share. Another machine's floating
point (another libm, vector instructions) may differ in the last digits; the tests hold either
way. With other seeds (``seed_offset``) a correct tree fails with probability <= 1% for the
whole file, over baselines and checks drawn afresh; against one fixed baseline the rate varies
with the draw that baseline was.

The reference image is box-downsampled by ``downsample``: a low-resolution pixel covers exactly
the block of reference pixels, so the block mean is its expected value, and the variance of
the block mean is the sum of the sub-pixel variances over (downsample^2)^2.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_text
from ..errors import InputError
from ..film import Film, merge_renders
from ..imagefiles import exr_is_half, read_exr, write_exr, write_png
from ..inputfiles import read_regular_file
from ..render_loop import RenderResult, RenderSettings, render_complete
from ..sampler_choice import DEFAULT_SAMPLER, SAMPLERS, replicates_of
from ..scene import Scene, load_scene, resolve_scene, shipped_scenes
from ..scene.shipped import shipped_names, shipped_scene_named
from ..strategy import (
    DEFAULT_LIGHT_SAMPLING,
    ENVIRONMENT_SAMPLINGS,
    HEURISTICS,
    LIGHT_SAMPLINGS,
    LIGHT_SELECTIONS,
    STRATEGIES,
    Strategy,
)
from . import metrics, statistics
from .reference import scene_for_reference
from .statistics import FAMILY_ALPHA

PIXEL_PASS_SHARE = 0.9975  # Mitsuba 3's share of pixels that must pass the z-test
TESTS_PER_ENTRY = 4  # relMSE, variance, pixels, image mean: the Sidak split of FAMILY_ALPHA
# Replicate renders per seed, of disjoint sample ranges (so independent), for the image-mean
# tests: for the same samples, 2n replicates give the permutation test C(4n, 2n) splits instead
# of C(2n, n) (6e8, not 12870, for n = 8) and the t-test at --update a critical value of 6.0
# instead of 9.7 at a 16-entry file's level.
REPLICATES_PER_SEED = 2
BASELINE_NAME = "tracer_baseline.json"  # the default baseline, in the current folder
# Most seeds an entry may have: 8 reach the levels of files of up to 32 entries, 12 of thousands;
# the exact Mann-Whitney test and --update's resampling grow costly beyond.
MAX_SEEDS = 64
# A baseline of a thousand entries of 64 seeds is under 10 MiB; a larger file is not a baseline.
MAX_BASELINE_BYTES = 64 << 20
# Largest spp factor --update looks for when an entry is too heavy-tailed for its t-test
# against the reference (64: 1024 spp for a 16-spp entry).
MAX_SPP_FACTOR = 64


@dataclass
class Entry:
    """One baseline entry. ``relmse``/``variance`` are means over ``seeds``; ``*_seeds`` the
    per-seed values the noise tests compare new renders with."""

    scene: str
    strategy: str
    spp: int
    seeds: list[int]
    heuristic: str = "power"
    light_samples: int = 1
    bsdf_samples: int = 1
    light_sampling: str = DEFAULT_LIGHT_SAMPLING
    light_selection: str = "power"
    environment_sampling: str = ENVIRONMENT_SAMPLINGS[0]
    sampler: str = DEFAULT_SAMPLER
    downsample: int = 4
    pixel_test: bool = True
    reference: str | None = None
    relmse: float | None = None
    variance: float | None = None
    relmse_seeds: list[float] | None = None
    variance_seeds: list[float] | None = None
    image_means: list[list[float]] | None = None
    note: str = ""

    @property
    def name(self) -> str:
        label = self.strategy if self.strategy != "mis" else f"mis-{self.heuristic}"
        if self.light_sampling != DEFAULT_LIGHT_SAMPLING:
            label += f"-{self.light_sampling}"
        if self.light_selection != "power":
            label += f"-{self.light_selection}-lights"
        if self.environment_sampling != ENVIRONMENT_SAMPLINGS[0]:
            label += f"-{self.environment_sampling}-environment"
        if self.sampler != DEFAULT_SAMPLER:
            label += f"-{self.sampler}"
        return f"{self.scene}/{label}"

    def strategy_object(self) -> Strategy:
        return Strategy.from_record(self)

    def reference_key(self) -> str:
        """The reference file, relative to the baseline's folder."""
        return self.reference or f"references/{self.scene}.exr"

    def to_json(self) -> dict[str, Any]:
        # The default light sampling, selection and sampler are left out, so that baselines of
        # tracer 0.2 stay as they were.
        return {k: v for k, v in self.__dict__.items() if v is not None and v != ""
                and not (k == "light_sampling" and v == DEFAULT_LIGHT_SAMPLING)
                and not (k == "light_selection" and v == "power")
                and not (k == "environment_sampling" and v == ENVIRONMENT_SAMPLINGS[0])
                and not (k == "sampler" and v == DEFAULT_SAMPLER)}


@dataclass
class Measurement:
    """Per-seed relMSE and variance, each seed's film, their pooled film and the downsampled
    reference."""

    relmse: np.ndarray
    variance: np.ndarray
    films: list[Film]
    pooled: Film
    reference_mean: np.ndarray  # (P, 3)
    reference_var: np.ndarray  # (P, 3) variance of the reference pixel value
    reference_sample_var: np.ndarray  # (P, 3) per-sample variance of the reference estimator
    scene: Scene
    seconds: float

    def replicate_image_means(self) -> np.ndarray:
        """(r, 3): each replicate render's image mean (REPLICATES_PER_SEED per seed)."""
        return np.array([f.mean.mean(axis=0) for f in self.films])

    def reference_image_mean(self) -> tuple[np.ndarray, np.ndarray]:
        """The reference's image mean per channel and its standard error, both (3,)."""
        return statistics.image_mean_and_se(self.reference_mean, self.reference_var)


@dataclass
class Verdict:
    """One row of the table: an entry's measure, the measured and baseline values, the test's
    p-value (or pass share) and whether it holds."""

    entry: str
    measure: str
    measured: float
    baseline: float
    p: float
    ok: bool

    @property
    def ratio(self) -> float:
        return self.measured / self.baseline if self.baseline else float("nan")


@dataclass
class CheckResult:
    """The verdicts, the measurements by entry name, and the folder each failing entry's maps
    were written to (``write_failures``), by entry name."""

    verdicts: list[Verdict] = field(default_factory=list)
    measurements: dict[str, Measurement] = field(default_factory=dict)
    failure_folders: dict[str, Path] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return all(v.ok for v in self.verdicts)


# ---------------------------------------------------------------------------------------------
# Baseline files


# The shipped scenes' baseline, in a source checkout of tracer (not in the installed package:
# its references are 3 MB of EXR that only the shipped scenes need).
CHECKOUT_BASELINE = Path("renders") / "noise_baseline.json"


def is_tracer_checkout(folder: Path) -> bool:
    """Whether ``folder`` is the root of a source checkout of tracer: its pyproject.toml names
    the project tracer, and it holds the shipped scenes' baseline."""
    import tomllib

    try:
        project = tomllib.loads((folder / "pyproject.toml").read_text(encoding="utf-8")).get("project", {})
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return isinstance(project, dict) and project.get("name") == "tracer" and \
        (folder / CHECKOUT_BASELINE).is_file()


def repository_baseline() -> Path | None:
    """``renders/noise_baseline.json`` of the source checkout this tracer runs from (an editable
    install, or the tests run in a clone), or None for an installed package (``pip install .``
    copies the package into site-packages, away from the clone's renders/)."""
    root = Path(__file__).resolve().parents[2]
    return root / CHECKOUT_BASELINE if is_tracer_checkout(root) else None


def checkout_baseline(folder: Path | None = None) -> Path | None:
    """``renders/noise_baseline.json`` of the source checkout of tracer that ``folder`` (default:
    the current folder) is in, it or a parent of it; None outside one. This is how a clone
    installed with a plain ``pip install .`` (the quick start) finds its baseline."""
    here = (folder or Path.cwd()).resolve()
    for candidate in (here, *here.parents):
        if is_tracer_checkout(candidate):
            return candidate / CHECKOUT_BASELINE
    return None


def find_default_baseline() -> tuple[Path, str]:
    """The baseline ``tracer check`` uses without ``--baseline`` and why, in this order:
    ``./tracer_baseline.json`` if the current folder has one (a project's own baseline, made
    with ``--create``); the shipped scenes' baseline of the source checkout this tracer runs
    from (editable install); that of the source checkout the current folder is in (a clone
    installed with ``pip install .``); else InputError saying how to make one."""
    local = Path(BASELINE_NAME)
    if local.is_file():
        return local, "in the current folder"
    running = repository_baseline()
    if running is not None:
        return running, "the shipped scenes' baseline of the source checkout tracer runs from"
    here = checkout_baseline()
    if here is not None:
        return here, "the shipped scenes' baseline of the source checkout the current folder is in"
    raise InputError("no baseline here, and tracer is not run from or in a source checkout of tracer (an "
                     "installed tracer ships none): pass --baseline FILE, run tracer check in a clone of "
                     "tracer for its shipped scenes, or make one for your scenes with tracer check --create "
                     f"{BASELINE_NAME} --scenes A.toml,B.toml --strategies light,mis "
                     "(guide: Noise regression tests)", BASELINE_NAME)


def default_baseline() -> Path:
    """The baseline ``tracer check`` uses without ``--baseline`` (:func:`find_default_baseline`)."""
    return find_default_baseline()[0]


def load_baseline(path: str | os.PathLike[str]) -> list[Entry]:
    """Read and validate a baseline file."""
    path = str(path)
    data = read_regular_file(path, MAX_BASELINE_BYTES, "baseline file",
                             missing="no such baseline file (make one with tracer check --create)")
    try:
        doc = json.loads(data)
    except RecursionError:
        raise InputError("not a baseline: JSON nested too deeply", path) from None
    except (OSError, ValueError) as exc:
        # JSONDecodeError, text that is not UTF-8, integers past Python's digit limit: all ValueError.
        raise InputError(f"not a readable JSON baseline: {str(exc)[:200]}", path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("entries"), list):
        raise InputError('expected an object with a list "entries"', path)
    entries = []
    known = set(Entry.__dataclass_fields__)
    for i, raw in enumerate(doc["entries"]):
        key = f"entries[{i}]"
        if not isinstance(raw, dict):
            raise InputError("expected an object", path, key)
        unknown = sorted(set(raw) - known)
        if unknown:
            raise InputError(f"unknown key '{unknown[0]}'", path, f"{key}.{unknown[0]}")
        for name in ("scene", "strategy", "spp", "seeds"):
            if name not in raw:
                raise InputError("missing key", path, f"{key}.{name}")
        for name, value in raw.items():
            problem = _field_problem(name, value, raw)
            if problem:
                raise InputError(f"expected {problem}, got {value!r}"[:200], path, f"{key}.{name}")
        entry = Entry(**raw)
        try:
            entry.strategy_object()
        except ValueError as exc:
            raise InputError(str(exc), path, key) from None
        entries.append(entry)
    return entries


def _is_int(value: Any, lo: int, hi: int = 2**53) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi


# The largest number a baseline may hold: every one is measured from float32 render files
# (1e308 passed, and its square overflowed with a numpy warning when judged).
MAX_BASELINE_NUMBER = 3.4028234e38


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            and 0 <= value <= MAX_BASELINE_NUMBER)


def _field_problem(name: str, value: Any, raw: dict[str, Any]) -> str | None:
    """What a baseline entry's field should be, if ``value`` is not that; None if it is."""
    if name in ("scene", "note"):
        return None if isinstance(value, str) and (value or name == "note") else "a non-empty string"
    if name == "strategy":
        return None if value in STRATEGIES else f"one of {', '.join(STRATEGIES)}"
    if name == "heuristic":
        return None if value in HEURISTICS else f"one of {', '.join(HEURISTICS)}"
    if name == "light_sampling":
        return None if value in LIGHT_SAMPLINGS else f"one of {', '.join(LIGHT_SAMPLINGS)}"
    if name == "light_selection":
        return None if value in LIGHT_SELECTIONS else f"one of {', '.join(LIGHT_SELECTIONS)}"
    if name == "environment_sampling":
        return None if value in ENVIRONMENT_SAMPLINGS else f"one of {', '.join(ENVIRONMENT_SAMPLINGS)}"
    if name == "sampler":
        return None if value in SAMPLERS else f"one of {', '.join(SAMPLERS)}"
    if name == "spp":
        return None if _is_int(value, 1, 2**31) else "a whole number of samples >= 1"
    if name in ("light_samples", "bsdf_samples"):
        return None if _is_int(value, 0, 2**20) else "a whole number >= 0"
    if name == "downsample":
        return None if _is_int(value, 1, 2**15) else "a whole number >= 1"
    if name == "pixel_test":
        return None if isinstance(value, bool) else "true or false"
    if name == "reference":
        return None if value is None or (isinstance(value, str) and value) else "a file name"
    if name == "seeds":
        ok = (isinstance(value, list) and 0 < len(value) <= MAX_SEEDS
              and all(_is_int(s, 0, 2**63) for s in value))
        distinct = ok and len(set(value)) == len(value)
        return None if distinct else f"a list of 1 to {MAX_SEEDS} distinct whole seeds >= 0"
    if name in ("relmse", "variance"):
        return None if value is None or _is_number(value) else "a number in 0 .. 3.4e38"
    if name in ("relmse_seeds", "variance_seeds"):
        seeds = raw.get("seeds")
        ok = isinstance(value, list) and all(_is_number(v) for v in value) and (
            not isinstance(seeds, list) or len(value) == len(seeds))
        return None if value is None or ok else "a list of numbers in 0 .. 3.4e38, one per seed"
    if name == "image_means":  # their number is checked when judging: --update replaces stale ones
        ok = isinstance(value, list) and all(
            isinstance(v, list) and len(v) == 3 and all(_is_number(c) for c in v) for v in value)
        return None if value is None or ok else "a list of [r, g, b] image means, one per replicate render"
    return None


def save_baseline(path: str | os.PathLike[str], entries: list[Entry]) -> None:
    """Write the baseline atomically."""
    doc = {
        "about": "tracer check noise baseline (guide: Noise regression tests): per entry the scene (a "
        "shipped scene's name or a path relative to this file), strategy, spp, seeds and the reference "
        "(default references/<scene>.exr beside this file); relmse/variance are means over the seeds, "
        "*_seeds the per-seed values, image_means the image mean of each replicate render (seed 1's "
        "first half, its second half, seed 2's, ...). Re-measure with tracer check --update.",
        "entries": [e.to_json() for e in entries],
    }
    # One line per key, lists included: a readable file whose diffs show which values moved.
    def lines(entry: dict[str, Any]) -> str:
        return ",\n".join(f"      {json.dumps(k)}: {json.dumps(v)}" for k, v in entry.items())

    body = ",\n".join(f"    {{\n{lines(entry)}\n    }}" for entry in doc["entries"])
    write_text(path, f'{{\n  "about": {json.dumps(doc["about"])},\n  "entries": [\n{body}\n  ]\n}}\n')


# ---------------------------------------------------------------------------------------------
# Levels


def test_level(entries: int) -> float:
    """The level of each test: ``FAMILY_ALPHA`` split with Sidak over 4 tests per entry."""
    return statistics.sidak(FAMILY_ALPHA, TESTS_PER_ENTRY * max(entries, 1))


def smallest_p(seeds: int, spp: int, sampler: str = DEFAULT_SAMPLER) -> float:
    """The smallest p-value the entry's rank and permutation tests can reach with ``seeds``:
    1 / C(2n, n) for the one-sided Mann-Whitney tests of n seeds a side, 2 / C(2r, r) for
    the two-sided permutation test of r replicates a side (a split and its mirror tie)."""
    r = seeds * replicates_per_seed(spp, sampler)
    return max(statistics.mann_whitney_smallest_p(seeds, seeds), 2 * statistics.mann_whitney_smallest_p(r, r))


def seeds_needed(level: float, spp: int, sampler: str = DEFAULT_SAMPLER) -> int:
    """The fewest seeds with which every test of an entry can reach ``level``."""
    n = 2
    while smallest_p(n, spp, sampler) >= level:
        n += 1
    return n


def check_seeds(entries: list[Entry], where: str) -> None:
    """Refuse entries whose rank tests could never fail: with n seeds a side the smallest
    p-value is 1 / C(2n, n), and a file of many entries asks for a smaller level."""
    level = test_level(len(entries))
    for i, e in enumerate(entries):
        n = len(e.seeds)
        smallest = smallest_p(n, e.spp, e.sampler)
        if smallest >= level:
            raise InputError(f"{n} seed(s): the rank tests' smallest p-value, {smallest:.2g}, cannot go "
                             f"below their level {level:.2g} ({len(entries)} entries), so they could never "
                             f"fail; use at least {seeds_needed(level, e.spp, e.sampler)} seeds", where,
                             f"entries[{i}].seeds")


# ---------------------------------------------------------------------------------------------
# Measuring


def scene_path(entry: Entry, base: Path) -> Path:
    """The entry's scene: a file relative to the baseline file's folder if there is one, else a
    shipped scene by name (``tracer.scene.shipped``: a file wins over a name, as for every
    command), else that file (which the reader then says is missing). Unlike a command's
    argument, an entry is never looked up in the current folder."""
    beside = base / entry.scene
    if os.path.lexists(beside):
        return beside
    return shipped_scene_named(entry.scene) or beside


def downsampled_reference(reference: Film, factor: int, half: bool) -> tuple[np.ndarray, ...]:
    """The reference at 1/factor resolution: block means ``(P', 3)``, the variance of each block
    mean, and the per-sample variance of a low-resolution pixel's estimate.

    A low-resolution sample falls uniformly in the block, so its variance is the mean of the
    sub-pixels' per-sample variances plus the variance of their means (total variance). A
    half-float reference adds its rounding, at most 2^-11 relative, as one more standard deviation.
    """
    w, h = reference.width // factor, reference.height // factor

    def blocks(a: np.ndarray) -> np.ndarray:
        return a.reshape(h, factor, w, factor, 3)

    mean = blocks(reference.mean).mean(axis=(1, 3))
    per_sample = blocks(reference.variance())
    var_mean = (per_sample / np.maximum(reference.count, 1).reshape(h, factor, w, factor, 1)).sum(axis=(1, 3))
    var_mean /= float(factor**4)
    if half:
        var_mean += (np.abs(mean) * 2.0**-11) ** 2
    var_sample = per_sample.mean(axis=(1, 3)) + blocks(reference.mean).var(axis=(1, 3))
    return mean.reshape(-1, 3), var_mean.reshape(-1, 3), var_sample.reshape(-1, 3)


@dataclass
class _Setup:
    """What measuring an entry needs besides its renders (``render_jobs``, ``measured``)."""

    entry: Entry
    scene: Scene
    ref_mean: np.ndarray
    ref_var: np.ndarray
    ref_sample_var: np.ndarray
    parts: int


def render_jobs(entry: Entry, base: Path, seed_offset: int = 0,
                threads: int = 2) -> tuple[_Setup, list[tuple[Scene, Strategy, RenderSettings]]]:
    """The renders ``(scene, strategy, settings)`` that measure ``entry``: per seed, ``parts``
    renders of consecutive sample indices (``replicates_per_seed``), and what ``measured`` needs."""
    ref_path = base / entry.reference_key()
    reference = read_exr(ref_path)
    f = entry.downsample
    if f < 1 or reference.width % f or reference.height % f:
        raise InputError(
            f"reference {reference.width}x{reference.height} is not divisible by downsample {f}",
            str(ref_path),
        )
    scene = scene_for_reference(scene_path(entry, base), ref_path, reference, f, quiet=True)
    # Renders that drew the reference's own random numbers would share its noise.
    reference_seeds = {s for s, _, _ in reference.record.samples or ()}
    shared = sorted({seed + seed_offset for seed in entry.seeds} & reference_seeds)
    if shared:
        raise InputError(f"seed(s) {shared} (with --seed-offset {seed_offset}) are the reference's own: "
                         "the renders would share its samples", str(ref_path))
    ref_mean, ref_var, ref_sample_var = downsampled_reference(reference, f, exr_is_half(ref_path))
    strategy = entry.strategy_object()
    parts = replicates_per_seed(entry.spp, entry.sampler)
    # Sample indices j spp/parts, ...: together the seed's spp samples.
    jobs = [(scene, strategy, RenderSettings(spp=entry.spp // parts, seed=seed + seed_offset,
                                             first_sample=j * (entry.spp // parts), threads=threads,
                                             sampler=entry.sampler))
            for seed in entry.seeds for j in range(parts)]
    return _Setup(entry, scene, ref_mean, ref_var, ref_sample_var, parts), jobs


def measured(setup: _Setup, results: list[RenderResult]) -> Measurement:
    """The measurement of an entry from the results of its ``render_jobs``, in their order."""
    films: list[Film] = []
    pooled: Film | None = None
    relmse, variance = [], []
    for i in range(0, len(results), setup.parts):
        film: Film | None = None
        for result in results[i:i + setup.parts]:
            films.append(result.film)
            film = result.film if film is None else merge_renders(film, result.film)
        relmse.append(metrics.relmse(film.mean, setup.ref_mean))
        variance.append(metrics.variance(film))
        # Distinct seeds: the pool's record lists each seed's range (record.merged).
        pooled = film if pooled is None else merge_renders(pooled, film)
    return Measurement(np.array(relmse), np.array(variance), films, pooled, setup.ref_mean, setup.ref_var,
                       setup.ref_sample_var, setup.scene, sum(r.seconds for r in results))


def measure(entry: Entry, base: Path, seed_offset: int = 0, threads: int = 2) -> Measurement:
    """Render the entry once per seed and measure it against its reference."""
    setup, jobs = render_jobs(entry, base, seed_offset, threads)
    return measured(setup, [render_complete(*job) for job in jobs])


def replicates_per_seed(spp: int, sampler: str = DEFAULT_SAMPLER) -> int:
    """Independent renders per seed for the image-mean test: ``REPLICATES_PER_SEED`` parts of
    the seed's samples when spp divides evenly (equal parts, equally distributed), else 1.
    Also 1 for the samplers with replicates: the parts of one Sobol seed would continue the same
    scrambled sequences and not be independent, and a stratified part would stratify half as
    many points per replicate as the render it stands for (at 16 spp, none)."""
    if replicates_of(sampler):
        return 1
    return REPLICATES_PER_SEED if spp % REPLICATES_PER_SEED == 0 else 1


# ---------------------------------------------------------------------------------------------
# Judging


def noise_test(values: np.ndarray, baseline: list[float]) -> float:
    """One-sided exact Mann-Whitney U p-value that ``values`` tend to exceed the baseline's
    per-seed values (see the module docstring)."""
    from scipy import stats

    return float(stats.mannwhitneyu(values, baseline, alternative="greater", method="exact").pvalue)


def image_variance(m: Measurement) -> np.ndarray:
    """(P, 3) variance of the pooled image's pixel values. The per-sample variance is the larger
    of the image's own estimate and the reference's: with few samples a pixel that the light
    (or the camera's jitter, for a sub-pixel emitter) rarely reaches has too few hits to
    estimate its own variance (often 0), and the reference's (MIS, thousands of samples per
    pixel) is a floor of the right size there; Mitsuba 3's render tests use it alone."""
    per_sample = np.maximum(m.pooled.variance(), m.reference_sample_var)
    return per_sample / np.maximum(m.pooled.count, 1)[:, None]  # as Film.variance_of_mean, floored


def pixel_pvalues(m: Measurement) -> np.ndarray:
    """Two-sided per-pixel-channel p-values of the pooled image against the reference, (P, 3)."""
    diff = m.pooled.mean - m.reference_mean
    sd = np.sqrt(image_variance(m) + m.reference_var)
    scale = np.maximum(np.abs(m.reference_mean), 1e-6)
    # Both estimates exact (no spread): equal to float precision passes, anything else fails.
    z = np.where(
        sd > 0.0,
        np.abs(diff) / np.where(sd > 0.0, sd, 1.0),
        np.where(np.abs(diff) <= 1e-5 * scale, 0.0, np.inf),
    )
    return statistics.two_sided_p(z)


def pixel_level(pvalues: np.ndarray) -> float:
    """The per-pixel-channel level: 1% Sidak-corrected over the pixels and channels."""
    return statistics.sidak(FAMILY_ALPHA, pvalues.size)


def mean_test(replicates: np.ndarray, ref_mean: np.ndarray, ref_se: np.ndarray) -> tuple[Any, Any]:
    """--update's test of the image mean against the reference: ``replicates (..., r, 3)``
    (the replicate renders' image means) against the reference's image mean and standard
    error ``(3,)``: (t of the channel with the smallest p, the Sidak family p-value over the 3
    channels), each of shape (...). A t-test per channel (``statistics.t_against_reference``);
    channels apart, as their errors are almost perfectly correlated."""
    t, p = statistics.t_against_reference(replicates, ref_mean, ref_se)
    worst = np.argmin(p, axis=-1)[..., None]
    p_min = np.take_along_axis(p, worst, axis=-1)[..., 0]
    return np.take_along_axis(t, worst, axis=-1)[..., 0], statistics.sidak_family(p_min, p.shape[-1])


def judge(entries: list[Entry], measurements: dict[str, Measurement]) -> list[Verdict]:
    """The verdicts of every entry, with the Sidak levels of the whole file."""
    level = test_level(len(entries))
    verdicts = []
    for e in entries:
        m = measurements[e.name]
        for measure_name, values, base, per_seed in (
            ("relmse", m.relmse, e.relmse, e.relmse_seeds),
            ("variance", m.variance, e.variance, e.variance_seeds),
        ):
            if base is None or not per_seed:
                raise InputError(f"{e.name}: the baseline has no {measure_name}; run tracer check --update")
            p = noise_test(values, per_seed)
            verdicts.append(Verdict(e.name, measure_name, float(np.mean(values)), base, p, p >= level))
        if e.pixel_test:
            pvalues = pixel_pvalues(m)
            share = float(np.mean(pvalues > pixel_level(pvalues)))
            verdicts.append(
                Verdict(e.name, "pixels passing", share, PIXEL_PASS_SHARE, share, share >= PIXEL_PASS_SHARE)
            )
        if not e.image_means:
            raise InputError(f"{e.name}: the baseline has no image_means; run tracer check --update")
        base_means, means = np.array(e.image_means), m.replicate_image_means()
        if base_means.shape != means.shape:
            raise InputError(f"{e.name}: the baseline has {len(base_means)} image means, the check "
                             f"{len(means)} renders; run tracer check --update")
        rng = np.random.default_rng(zlib.crc32(e.name.encode()))  # the same splits every run
        p = statistics.permutation_p(means, base_means, level, rng)
        verdicts.append(Verdict(e.name, "image mean", float(means.mean()), float(base_means.mean()), p,
                                p >= level))
    return verdicts


# ---------------------------------------------------------------------------------------------
# What --update checks before it writes an entry


def failing_pixels(m: Measurement) -> int:
    """Pixels of the pooled render with a channel failing the per-pixel test."""
    pvalues = pixel_pvalues(m)
    return int(np.sum((pvalues <= pixel_level(pvalues)).any(axis=1)))


def _synthetic_image_means(seed_means: np.ndarray, count: int, factor: int,
                           rng: np.random.Generator) -> np.ndarray:
    """(count, 3) image means of synthetic renders at ``factor`` times the seeds' spp: each
    pixel's value is the mean of ``factor`` draws from the n seeds' values of that pixel,
    independently per pixel (``seed_means (n, P, 3)``)."""
    n, pixels, _ = seed_means.shape
    columns = np.arange(pixels)
    rows = max(1, 2**20 // (pixels * (1 if factor == 1 else n)))  # bound the memory of one chunk
    out = []
    for start in range(0, count, rows):
        size = min(rows, count - start)
        if factor == 1:
            values = seed_means[rng.integers(0, n, size=(size, pixels)), columns]
        else:
            weights = rng.multinomial(factor, np.full(n, 1.0 / n), size=(size, pixels)) / factor
            values = np.einsum("rpn,npc->rpc", weights, seed_means)
        out.append(values.mean(axis=1))
    return np.concatenate(out)


def _distinct_draws(rng: np.random.Generator, pool: int, size: int, n: int) -> np.ndarray:
    """(size, n) indices into a pool, distinct within each row (a row is n independent renders:
    drawing one twice would make the n values less spread than n renders are)."""
    idx = rng.integers(0, pool, size=(size, n))
    while True:
        ordered = np.sort(idx, axis=1)
        again = np.flatnonzero((np.diff(ordered, axis=1) == 0).any(axis=1))
        if not len(again):
            return idx
        idx[again] = rng.integers(0, pool, size=(len(again), n))


def mean_test_false_alarms(m: Measurement, level: float, factor: int = 1, seed: int = 0) -> float:
    """The image-mean test's false-alarm rate at ``factor`` times the entry's spp, estimated by
    the bootstrap of the module docstring.

    A pool of synthetic renders (``_synthetic_image_means``); the resampled world's truth is
    the mean of the n seeds' images, its reference that truth plus a normal error of the
    reference's standard error; each trial takes n distinct renders of the pool and runs
    :func:`mean_test` at ``level / 2``, as the gate does. Enough trials that a rate of
    ``level`` means about 50 rejections (relative error 14%; a well-behaved
    entry, at level / 2 or below, makes 25 or fewer)."""
    rng = np.random.default_rng(seed)
    seed_means = np.stack([f.mean for f in m.films])
    n, pixels, _ = seed_means.shape
    pool_size = int(np.clip(2**24 // (pixels * (1 if factor == 1 else n)), 64 * n, 4096))
    pool = _synthetic_image_means(seed_means, pool_size, factor, rng)
    truth = seed_means.mean(axis=(0, 1))
    _, ref_se = m.reference_image_mean()
    trials = int(min(1_000_000, math.ceil(50.0 / level)))
    rejected, chunk = 0, max(1, 2**19 // n)
    for start in range(0, trials, chunk):
        size = min(chunk, trials - start)
        sample = pool[_distinct_draws(rng, pool_size, size, n)]
        reference = truth + ref_se * rng.standard_normal((size, 3))
        _, p = mean_test(sample, reference, ref_se)
        rejected += int(np.sum(p < level / 2))
    return rejected / trials


class HeavyTailed(InputError):
    """Entries too heavy-tailed for the image-mean test at their spp. ``needs`` maps each
    refused entry's name to the spp that brings it within its level, or None if even
    ``MAX_SPP_FACTOR`` times its spp does not."""

    def __init__(self, message: str, where: str, key: str, needs: dict[str, int | None]):
        super().__init__(message, where, key)
        self.needs = needs


def gate(entries: list[Entry], measurements: dict[str, Measurement], where: str, stream=None) -> None:
    """What ``--update`` and ``--create`` check before writing (module docstring): set each
    entry's ``pixel_test`` from its failing pixels; refuse (InputError naming the first
    refused entry's spp key) an entry whose image mean differs from the reference's, and raise
    :class:`HeavyTailed` (with the spp each needs) if some entry's image mean is too heavy-
    tailed for that t-test to tell."""
    level = test_level(len(entries))
    refused: list[tuple[int, str]] = []
    needs: dict[str, int | None] = {}
    for i, e in enumerate(entries):
        m = measurements[e.name]
        failing = failing_pixels(m)
        e.pixel_test = failing == 0
        if e.note.startswith("pixel test off") or not e.note:
            e.note = "" if e.pixel_test else (
                f"pixel test off: {failing} of {len(m.pooled.count)} pixels failed it in the renders of the "
                f"baseline (heavy-tailed per pixel at {e.spp} spp: most pixels see few light hits)")
        if not e.pixel_test and stream is not None:
            print(f"  {e.name}: {e.note}", file=stream)
        seed = zlib.crc32(f"{e.name} {e.spp} {e.seeds}".encode())  # reproducible per entry
        rate = mean_test_false_alarms(m, level, 1, seed)
        if rate > level:
            factors = [2**j for j in range(1, int(math.log2(MAX_SPP_FACTOR)) + 1)]
            enough = next((k for k in factors if mean_test_false_alarms(m, level, k, seed) <= level), None)
            needs[e.name] = enough * e.spp if enough else None
            need = f"spp >= {enough * e.spp}" if enough else f"more than {MAX_SPP_FACTOR * e.spp} spp"
            refused.append((i, f"{e.name} at {e.spp} spp: resampling its renders, the t-test against the "
                            f"reference would raise false alarms {rate:.2%} of the time, against {level:.3%} "
                            f"allowed; it needs {need}"))
            continue
        t, p = mean_test(m.replicate_image_means(), *m.reference_image_mean())
        if p < level / 2:
            raise InputError(f"{e.name}: its image mean differs from the reference's (t = {float(t):.3g}, "
                             f"p = {float(p):.2g} < {level / 2:.2g}): the estimator is biased, or the "
                             "reference is of another version of the scene; nothing written", where,
                             f"entries[{i}]")
    if refused:
        details = "; ".join(text for _, text in refused)
        raise HeavyTailed(f"too heavy-tailed to confirm unbiased: {details}; raise the spp (--update checks "
                          "again there) or leave the entry out; nothing written", where,
                          f"entries[{refused[0][0]}].spp", needs)


# ---------------------------------------------------------------------------------------------
# Running


def run_check(
    baseline: str | os.PathLike[str],
    update: bool = False,
    out: Path | None = None,
    seed_offset: int = 0,
    threads: int = 2,
    stream=sys.stderr,
    entries: list[Entry] | None = None,
    client=None,
) -> CheckResult:
    """Measure every entry; with ``update`` check and rewrite the baseline, else judge
    against it.

    On failure, the failing entries' image, reference, error and p-value maps go to ``out``.
    With a Dask ``client`` (``tracer.cluster``) each entry's seeds render as tasks.
    """
    baseline = Path(baseline)
    entries = entries if entries is not None else load_baseline(baseline)
    check_seeds(entries, str(baseline))
    if not update:  # what judging needs, before any rendering
        for i, e in enumerate(entries):
            for name in ("relmse", "variance"):
                if getattr(e, name) is None or not getattr(e, f"{name}_seeds"):
                    raise InputError(f"no {name} and {name}_seeds to judge against; run tracer check "
                                     "--update", str(baseline), f"entries[{i}]")
            if not e.image_means:
                raise InputError("no image_means to judge against; run tracer check --update", str(baseline),
                                 f"entries[{i}]")
    result = CheckResult()
    _measure_all(entries, baseline.parent, seed_offset, threads, stream, result, client)
    if update:
        _write_update(baseline, entries, result, stream)
        return result
    result.verdicts = judge(entries, result.measurements)
    if not result.ok and out is not None:
        result.failure_folders = write_failures(out, entries, result)
    return result


def _measure_all(entries, base: Path, seed_offset: int, threads: int, stream, result: CheckResult,
                 client=None) -> None:
    """Measure every entry: here one render after the other, or with a Dask ``client`` every
    entry's renders at once, as tasks (``tracer.cluster``)."""
    if client is not None:
        from ..cluster import map_tasks, render_whole

        prepared = [render_jobs(e, base, seed_offset, threads) for e in entries]
        results = map_tasks(client, render_whole, [job for _, jobs in prepared for job in jobs],
                            progress=stream is not None)
        done = 0
        for setup, jobs in prepared:
            result.measurements[setup.entry.name] = measured(setup, results[done:done + len(jobs)])
            done += len(jobs)
    for e in entries:
        if client is None:
            result.measurements[e.name] = measure(e, base, seed_offset, threads)
        m = result.measurements[e.name]
        if stream is not None:
            print(
                f"  measured {e.name}: {len(e.seeds)} seeds x {e.spp} spp at "
                f"{m.scene.camera.width}x{m.scene.camera.height}, {m.seconds:.1f} s",
                file=stream,
            )


def _write_update(baseline: Path, entries: list[Entry], result: CheckResult, stream) -> None:
    gate(entries, result.measurements, str(baseline), stream)
    for e in entries:
        m = result.measurements[e.name]
        e.relmse, e.variance = float(np.mean(m.relmse)), float(np.mean(m.variance))
        e.relmse_seeds = [float(x) for x in m.relmse]
        e.variance_seeds = [float(x) for x in m.variance]
        e.image_means = [[float(c) for c in row] for row in m.replicate_image_means()]
    save_baseline(baseline, entries)


def parse_strategies(text: str) -> list[tuple[str, str]]:
    """``light,mis,mis-balance`` -> [(strategy, heuristic)]: a strategy name, or mis-HEURISTIC."""
    out = []
    for label in text.split(","):
        name, _, heuristic = label.strip().partition("-")
        if name not in STRATEGIES or (heuristic and (name != "mis" or heuristic not in HEURISTICS)):
            raise InputError(f"unknown strategy '{label.strip()[:40]}': expected {', '.join(STRATEGIES)} or "
                             f"mis-HEURISTIC ({', '.join(HEURISTICS)})", "--strategies")
        if (name, heuristic or "power") not in out:
            out.append((name, heuristic or "power"))
    return out


def reference_size(scene: Scene, size: int) -> tuple[int, int]:
    """The scene's frame with its longer side ``size`` pixels (the aspect ratio kept to within
    one pixel's rounding, as ``reference.scene_for_reference`` asks)."""
    w, h = scene.camera.width, scene.camera.height
    if w >= h:
        return size, max(1, round(size * h / w))
    return max(1, round(size * w / h)), size


def create_baseline(
    path: str | os.PathLike[str],
    scenes: list[str],
    strategies: list[tuple[str, str]],
    spp: int = 16,
    seeds: int = 8,
    reference_spp: int = 1024,
    size: int = 64,
    threads: int = 2,
    stream=sys.stderr,
    sampler: str = DEFAULT_SAMPLER,
    client=None,
) -> CheckResult:
    """Write a new baseline at ``path`` for every scene x strategy, with MIS references (the
    entries' renders as Dask tasks with a ``client``; the references here).

    Each scene's reference is rendered at ``size`` pixels on its longer side (the check's
    resolution, so ``downsample`` is 1) with ``reference_spp`` MIS samples of seed 0 and saved as
    ``references/<scene file name>.exr`` beside the baseline (an existing one of the same scene
    and size is reused, so a refused run can be repeated cheaply); entries use seeds 1..n.
    Then everything ``--update`` does: measure, check (``gate``), write."""
    path = Path(path)
    if path.exists():
        raise InputError("exists: --create writes a new baseline (re-measure an existing one with --update)",
                         str(path))
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError("the baseline's folder does not exist", str(folder))
    prepared = []  # (scene key, scene file, reference key)
    used_names: set[str] = set()
    for text in scenes:
        key, file, name = baseline_scene(text.strip(), folder)
        if key in (k for k, _, _ in prepared):
            continue
        unique, i = name, 2
        while unique in used_names:
            unique, i = f"{name}-{i}", i + 1
        used_names.add(unique)
        prepared.append((key, file, f"references/{unique}.exr"))
    entries = [Entry(scene=key, strategy=name, heuristic=heuristic, spp=spp, seeds=list(range(1, seeds + 1)),
                     downsample=1, reference=ref, sampler=sampler)
               for key, _, ref in prepared for name, heuristic in strategies]
    for e in entries:
        try:
            e.strategy_object()
        except ValueError as exc:
            raise InputError(str(exc), "--strategies") from None
    level = test_level(len(entries))
    if smallest_p(seeds, spp, sampler) >= level:
        raise InputError(f"{seeds} seeds are too few for the rank tests of {len(entries)} entries (they "
                         f"could never fail): use at least {seeds_needed(level, spp, sampler)}", "--seeds")
    if reference_spp < 2:
        raise InputError("a reference needs at least 2 samples per pixel (its variance is used)",
                         "--reference-spp")
    (folder / "references").mkdir(exist_ok=True)
    for _, file, ref in prepared:
        make_reference(file, folder / ref, size, reference_spp, threads, stream)
    result = CheckResult()
    _measure_all(entries, folder, 0, threads, stream, result, client)
    _write_update(path, entries, result, stream)
    return result


def baseline_scene(text: str, folder: Path) -> tuple[str, Path, str]:
    """A ``--scenes`` item as (the entry's ``scene`` key, the scene file, the name of its
    reference file): a scene file is keyed by its path relative to the baseline's ``folder``
    (absolute if there is none) and its reference by its file name; a shipped scene by its name
    (``tracer.scene.shipped``), wherever the baseline is, and its reference by that name with
    "_" for "/" (``mitsuba/veach_mis``: ``mitsuba_veach_mis``). InputError for neither."""
    try:
        file = resolve_scene(text)
    except InputError as exc:
        raise InputError(str(exc), "--scenes") from None
    shipped = {s.path.resolve(): s.name for s in shipped_scenes()}
    if Path(text).exists() or file.resolve() not in shipped:
        rel = os.path.relpath(file.resolve(), folder.resolve())
        return (rel if not os.path.isabs(rel) else str(file.resolve())), file, file.name
    name = shipped[file.resolve()]
    # references/NAME.exr, as Entry.reference_key names a shipped scene's reference by default.
    return name, file, name.replace("/", "_")


def make_reference(scene_file: Path, ref_path: Path, size: int, spp: int, threads: int, stream) -> None:
    """Render (or reuse) one scene's MIS reference for --create."""
    scene = load_scene(scene_file)
    width, height = reference_size(scene, size)
    if ref_path.exists():
        old = read_exr(ref_path)
        scene_for_reference(scene_file, ref_path, old, 1, quiet=True)  # same scene, else InputError
        if (old.width, old.height) != (width, height):
            raise InputError(f"a reference of {old.width}x{old.height} exists here, not {width}x{height} "
                             "(--size): remove it or pass its size", str(ref_path))
        if stream is not None:
            print(f"  reusing {ref_path} ({old.spp} spp)", file=stream)
        return
    scene = load_scene(scene_file, width, height)
    result = render_complete(scene, Strategy("mis"), RenderSettings(spp=spp, seed=0, threads=threads))
    write_exr(ref_path, result.film)
    if stream is not None:
        print(f"  reference {ref_path}: {width}x{height}, {spp} spp MIS, {result.seconds:.1f} s", file=stream)


def format_table(verdicts: list[Verdict]) -> str:
    """The table of verdicts as aligned text."""
    width = max([len(v.entry) for v in verdicts] + [5])
    lines = [
        f"{'entry':<{width}}  {'measure':<15} {'measured':>11} {'baseline':>11} {'ratio':>7} "
        f"{'p':>9}  verdict"
    ]
    for v in verdicts:
        ratio = f"{v.ratio:7.3f}" if np.isfinite(v.ratio) else "      -"
        lines.append(
            f"{v.entry:<{width}}  {v.measure:<15} {v.measured:>11.5g} {v.baseline:>11.5g} {ratio} "
            f"{v.p:>9.2g}  {'ok' if v.ok else 'FAIL'}"
        )
    return "\n".join(lines)


def failure_folder_names(entries: list[Entry]) -> dict[str, str]:
    """The folder name of each entry's failure maps, by entry name: the scene's stem (a shipped
    Mitsuba scene's name with "_" for "/") and the strategy's slug, as ``tracer render`` names
    its output (``room_mis``, ``cornell_light_sobol``, ``mitsuba_veach_mis_mis_balance``), in
    letters, digits, ``.``, ``_`` and ``-`` only, never starting with a dot (``../room.toml``
    made a hidden ``.._room.toml_mis-power``), and unique over the whole baseline (``-2``,
    ``-3``, ... in entry order), so that an entry's folder does not depend on which others fail."""
    shipped = set(shipped_names())
    names: dict[str, str] = {}
    used: set[str] = set()
    for e in entries:
        scene = e.scene.replace("/", "_") if e.scene in shipped else Path(e.scene).stem
        sampler = f"_{e.sampler}" if e.sampler != DEFAULT_SAMPLER else ""
        text = f"{scene}_{e.strategy_object().slug}{sampler}"
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", text).lstrip("._-")[:120] or "entry"
        unique, i = base, 2
        while unique in used:
            unique, i = f"{base}-{i}", i + 1
        used.add(unique)
        names[e.name] = unique
    return names


def write_failures(out: Path, entries: list[Entry], result: CheckResult) -> dict[str, Path]:
    """For each failing entry: image.exr, reference.exr, error.png and pvalue.png in a folder
    of ``out`` named by :func:`failure_folder_names`; returns those folders by entry name."""
    from .report import save_map

    failing = {v.entry for v in result.verdicts if not v.ok}
    folder_names = failure_folder_names(entries)
    written: dict[str, Path] = {}
    for e in entries:
        if e.name not in failing:
            continue
        m = result.measurements[e.name]
        folder = out / folder_names[e.name]
        folder.mkdir(parents=True, exist_ok=True)
        written[e.name] = folder
        reference = Film(
            m.pooled.width,
            m.pooled.height,
            np.full(len(m.pooled.count), 1, dtype=np.int64),
            m.reference_mean.copy(),
            np.zeros_like(m.reference_mean),
        )
        for name, film in (("image", m.pooled), ("reference", reference)):
            write_exr(folder / f"{name}.exr", film)
            write_png(folder / f"{name}.png", film.image())
        shape = (m.pooled.height, m.pooled.width)
        rel = metrics.relative_squared_error(m.pooled.mean, m.reference_mean).mean(axis=1).reshape(shape)
        save_map(
            np.log10(rel + 1e-12),
            folder / "error.png",
            f"{e.name}: relative squared error",
            "log10 (I-R)² / (R²+0.01)",
            vmin=-6.0,
            vmax=1.0,
        )
        pvalues = pixel_pvalues(m).min(axis=1).reshape(shape)
        save_map(
            np.log10(np.maximum(pvalues, 1e-12)),
            folder / "pvalue.png",
            f"{e.name}: per-pixel p-value (min over RGB)",
            "log10 p",
            cmap="viridis_r",
            vmin=-12.0,
            vmax=0.0,
        )
    return written
