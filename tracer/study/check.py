"""Noise-level regression test: has a change made an estimator noisier, or biased?

A baseline file (JSON) lists entries ``{"scene", "strategy", "heuristic", "spp", "seeds",
"relmse", "variance", ...}``. For each entry the check renders the scene once per seed at a
small resolution (the reference's resolution divided by ``downsample``) and tests:

- **Noise** (one-sided exact Mann-Whitney U test per measure): the per-seed relMSE (and
  variance) of the new renders against the baseline's per-seed values. H0: both come from the
  same distribution, so every ordering of the pooled values is equally likely and the
  false-alarm rate is exact whatever the distribution, which matters because the relMSE of a
  heavy-tailed estimator is itself heavy-tailed (one firefly can double it). With 8 seeds a
  side the smallest p is 1 / C(16, 8) = 7.8e-5: a regression is flagged when (nearly) every
  new seed is noisier than (nearly) every baseline seed, as doubling the variance does. The
  level is Sidak-corrected for a 1% false-alarm rate over all noise tests of the file. An
  unchanged tree with the baseline's seeds reproduces the baseline exactly (all ties, p ~ 0.5);
  with other seeds (``seed_offset``) it fails with probability <= 1% for the whole file.
- **Bias, per pixel** (Mitsuba 3's render test): z = (I - R) / sqrt(Var I + Var R) for every
  pixel and channel of the seeds' pooled image against the reference, two-sided, Sidak-
  corrected over the pixels at 1%; the entry fails if fewer than 99.75% of them pass. Entries
  whose per-pixel distributions are too heavy-tailed at their spp for a normal z (many pixels
  with no light hit yet) set ``"pixel_test": false``.
- **Bias, image mean**: a two-sided z-test of the image mean against the reference's, Sidak-
  corrected at 1% over the entries.

The reference image is box-downsampled by ``downsample``: a low-resolution pixel covers exactly
the block of reference pixels, so the block mean is its expected value, and the variance of
the block mean is the sum of the sub-pixel variances over (downsample^2)^2.
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_text
from ..errors import InputError
from ..film import Film, merge_renders
from ..imagefiles import exr_is_half, read_exr, write_exr, write_png
from ..render_loop import RenderSettings, render_complete
from ..scene import Scene, default_scene_path
from ..strategy import HEURISTICS, STRATEGIES, Strategy
from . import metrics, statistics
from .compare import scene_for_reference
from .statistics import FAMILY_ALPHA

PIXEL_PASS_SHARE = 0.9975  # Mitsuba 3's share of pixels that must pass the z-test
DEFAULT_BASELINE = Path("renders") / "noise_baseline.json"


@dataclass
class Entry:
    """One baseline entry. ``relmse``/``variance`` are means over ``seeds``; ``*_seeds`` the
    per-seed values (the noise tolerance is derived from their spread)."""

    scene: str
    strategy: str
    spp: int
    seeds: list[int]
    heuristic: str = "power"
    light_samples: int = 1
    bsdf_samples: int = 1
    downsample: int = 4
    pixel_test: bool = True
    reference: str | None = None
    relmse: float | None = None
    variance: float | None = None
    relmse_seeds: list[float] | None = None
    variance_seeds: list[float] | None = None
    note: str = ""

    @property
    def name(self) -> str:
        label = self.strategy if self.strategy != "mis" else f"mis-{self.heuristic}"
        return f"{self.scene}/{label}"

    def strategy_object(self) -> Strategy:
        return Strategy(self.strategy, self.heuristic, self.light_samples, self.bsdf_samples)

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if v is not None and v != ""}


@dataclass
class Measurement:
    """Per-seed relMSE and variance, the pooled film of all seeds and the downsampled reference."""

    relmse: np.ndarray
    variance: np.ndarray
    pooled: Film
    reference_mean: np.ndarray  # (P, 3)
    reference_var: np.ndarray  # (P, 3) variance of the reference pixel value
    reference_sample_var: np.ndarray  # (P, 3) per-sample variance of the reference estimator
    scene: Scene
    seconds: float


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
    verdicts: list[Verdict] = field(default_factory=list)
    measurements: dict[str, Measurement] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return all(v.ok for v in self.verdicts)


# ---------------------------------------------------------------------------------------------
# Baseline files


def load_baseline(path: str | os.PathLike[str]) -> list[Entry]:
    """Read and validate a baseline file."""
    path = str(path)
    try:
        with open(path) as fh:
            doc = json.load(fh)
    except FileNotFoundError:
        raise InputError("no such baseline file (create one with --update)", path) from None
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


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            and value >= 0)


def _field_problem(name: str, value: Any, raw: dict[str, Any]) -> str | None:
    """What a baseline entry's field should be, if ``value`` is not that; None if it is."""
    if name in ("scene", "note"):
        return None if isinstance(value, str) and (value or name == "note") else "a non-empty string"
    if name == "strategy":
        return None if value in STRATEGIES else f"one of {', '.join(STRATEGIES)}"
    if name == "heuristic":
        return None if value in HEURISTICS else f"one of {', '.join(HEURISTICS)}"
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
        ok = isinstance(value, list) and value and all(_is_int(s, 0, 2**63) for s in value)
        distinct = ok and len(set(value)) == len(value)
        return None if distinct else "a non-empty list of distinct whole seeds >= 0"
    if name in ("relmse", "variance"):
        return None if value is None or _is_number(value) else "a finite number >= 0"
    if name in ("relmse_seeds", "variance_seeds"):
        seeds = raw.get("seeds")
        ok = isinstance(value, list) and all(_is_number(v) for v in value) and (
            not isinstance(seeds, list) or len(value) == len(seeds))
        return None if value is None or ok else "a list of finite numbers >= 0, one per seed"
    return None


def save_baseline(path: str | os.PathLike[str], entries: list[Entry]) -> None:
    """Write the baseline atomically."""
    doc = {
        "about": "tracer check noise baseline: relmse/variance are means over the seeds, *_seeds the "
        "per-seed values; regenerate with `tracer check --update`.",
        "entries": [e.to_json() for e in entries],
    }
    write_text(path, json.dumps(doc, indent=2) + "\n")


# ---------------------------------------------------------------------------------------------
# Measuring


def scene_path(entry: Entry, base: Path) -> Path:
    """A shipped scene by name (beside the default scene), else a path relative to the baseline
    file's folder."""
    shipped = default_scene_path().parent / f"{entry.scene}.toml"
    return shipped if shipped.is_file() else base / entry.scene


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


def measure(entry: Entry, base: Path, seed_offset: int = 0, threads: int = 2) -> Measurement:
    """Render the entry once per seed and measure it against its reference."""
    ref_path = base / (entry.reference or f"references/{entry.scene}.exr")
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
    pooled: Film | None = None
    relmse, variance, seconds = [], [], 0.0
    for seed in entry.seeds:
        result = render_complete(
            scene, strategy, RenderSettings(spp=entry.spp, seed=seed + seed_offset, threads=threads)
        )
        relmse.append(metrics.relmse(result.film.mean, ref_mean))
        variance.append(metrics.variance(result.film))
        # Distinct seeds: the pool's record lists each seed's range (record.merged).
        pooled = result.film if pooled is None else merge_renders(pooled, result.film)
        seconds += result.seconds
    return Measurement(
        np.array(relmse), np.array(variance), pooled, ref_mean, ref_var, ref_sample_var, scene, seconds
    )


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


def image_mean_pvalue(m: Measurement) -> tuple[float, float]:
    """(z, two-sided p) of the image mean against the reference's, for the channel with the
    largest |z|, p Sidak-combined over the 3 channels (``statistics``: channels are tested
    apart because their errors are almost perfectly correlated)."""
    z = statistics.image_mean_z(m.pooled.mean, image_variance(m), m.reference_mean, m.reference_var)
    return statistics.worst_channel(z), statistics.worst_channel_p(z)


def judge(entries: list[Entry], measurements: dict[str, Measurement]) -> list[Verdict]:
    """The verdicts of every entry, with the Sidak levels of the whole file."""
    noise_level = statistics.sidak(FAMILY_ALPHA, 2 * len(entries))
    mean_level = statistics.sidak(FAMILY_ALPHA, len(entries))
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
            verdicts.append(Verdict(e.name, measure_name, float(np.mean(values)), base, p, p >= noise_level))
        if e.pixel_test:
            pvalues = pixel_pvalues(m)
            share = float(np.mean(pvalues > statistics.sidak(FAMILY_ALPHA, pvalues.size)))
            verdicts.append(
                Verdict(e.name, "pixels passing", share, PIXEL_PASS_SHARE, share, share >= PIXEL_PASS_SHARE)
            )
        z, p = image_mean_pvalue(m)
        verdicts.append(Verdict(e.name, "image mean z", z, 0.0, p, p >= mean_level))
    return verdicts


def run_check(
    baseline: str | os.PathLike[str],
    update: bool = False,
    out: Path | None = None,
    seed_offset: int = 0,
    threads: int = 2,
    stream=sys.stderr,
    entries: list[Entry] | None = None,
) -> CheckResult:
    """Measure every entry; with ``update`` rewrite the baseline, else judge against it.

    On failure, the failing entries' image, reference, error and p-value maps go to ``out``.
    """
    baseline = Path(baseline)
    entries = entries if entries is not None else load_baseline(baseline)
    if not update:  # what judging needs, before any rendering
        for i, e in enumerate(entries):
            for name in ("relmse", "variance"):
                if getattr(e, name) is None or not getattr(e, f"{name}_seeds"):
                    raise InputError(f"no {name} and {name}_seeds to judge against; run tracer check "
                                     "--update", str(baseline), f"entries[{i}]")
    base = baseline.parent
    result = CheckResult()
    for e in entries:
        m = measure(e, base, seed_offset, threads)
        result.measurements[e.name] = m
        if stream is not None:
            print(
                f"  measured {e.name}: {len(e.seeds)} seeds x {e.spp} spp at "
                f"{m.scene.camera.width}x{m.scene.camera.height}, {m.seconds:.1f} s",
                file=stream,
            )
    if update:
        for e in entries:
            m = result.measurements[e.name]
            e.relmse, e.variance = float(np.mean(m.relmse)), float(np.mean(m.variance))
            e.relmse_seeds = [float(x) for x in m.relmse]
            e.variance_seeds = [float(x) for x in m.variance]
        save_baseline(baseline, entries)
        return result
    result.verdicts = judge(entries, result.measurements)
    if not result.ok and out is not None:
        write_failures(out, entries, result)
    return result


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


def write_failures(out: Path, entries: list[Entry], result: CheckResult) -> None:
    """For each failing entry: image.exr, reference.exr, error.png and pvalue.png in out/ENTRY/."""
    from .report import save_map

    failing = {v.entry for v in result.verdicts if not v.ok}
    for e in entries:
        if e.name not in failing:
            continue
        m = result.measurements[e.name]
        folder = out / e.name.replace("/", "_")
        folder.mkdir(parents=True, exist_ok=True)
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
