"""The film: per-pixel running statistics of a render, and their exact merge.

Per pixel the film holds the sample count, the running mean and Welford's M2 (sum of squared
deviations from the mean) in float64. Two films of disjoint samples merge exactly with Chan,
Golub and LeVeque's parallel formula, so renders can be resumed, split across processes and
pooled into references.

Films of a sampler with replicates (``stratified``, ``sobol``: ``tracer.samplers``) also hold
each replicate's count and mean. Their samples are not independent within a pixel, so M2 / (n -
1) says little about the error of the mean; :meth:`Film.variance` is instead the *effective*
per-sample variance, n x the variance of the pixel mean estimated from the R independent
replicate means ``Y_r`` (counts ``n_r``, weights ``w_r = n_r / n``):

    Var(mean) ~= sum_r w_r^2 (Y_r - mean)^2 / (1 - sum_r w_r^2)

which is the usual unbiased ``s^2 / R`` of the replicate means when the counts are equal, so
that ``variance / count`` is the error of the pixel value for every sampler; with unequal
counts (an spp that is not a multiple of R, a pass cut short, pools of renders of fewer than R
spp) it is unbiased when a replicate's variance falls as 1 / n_r, and close otherwise (the
factor R' / (R' - 1) instead would be 22% low for counts 8, 1, ..., 1). Where one replicate
holds every sample (pools of 1-spp renders) there is nothing to compare: the per-sample
spread M2 / (n - 1) stands in, which for these samplers overstates the error rather than
hide it. Merges add replicate r of one film to replicate r of the other: both hold points of
replicate r's own randomization (the same sequence continued, or another seed's independent
one), and different replicates stay independent.

Files are elsewhere: ``tracer.imagefiles`` (the EXR contract and PNG previews).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .jit import jit
from .record import RenderRecord, check_mergeable, merged
from .sampler_choice import replicates_of


@dataclass
class Film:
    """Running statistics of ``width * height`` pixels, row-major, row 0 at the top.

    count : (P,) int64 samples per pixel.   mean : (P, 3) float64.   m2 : (P, 3) float64.
    record : how the samples were made (``tracer.record``), written to and read from the EXR
        header.
    replicates : R (``tracer.samplers.REPLICATES``) for samplers with replicates, else 0.
    rep_count : (P, R) int64 samples per replicate.   rep_mean : (P, R, 3) float64 their means.
        (None when ``replicates`` is 0.)
    learned : per-pixel maps ``(P,)`` of what the render learned between passes, by EXR channel
        name (``tracer.tuning.Learner.maps``): written for a user to see, never read back, and
        dropped by a merge (they describe one render).
    """

    width: int
    height: int
    count: np.ndarray = field(default=None)  # type: ignore[assignment]
    mean: np.ndarray = field(default=None)  # type: ignore[assignment]
    m2: np.ndarray = field(default=None)  # type: ignore[assignment]
    record: RenderRecord = field(default_factory=RenderRecord)
    replicates: int = 0
    rep_count: np.ndarray | None = None
    rep_mean: np.ndarray | None = None
    learned: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = self.width * self.height
        if self.count is None:
            self.count = np.zeros(n, dtype=np.int64)
            self.mean = np.zeros((n, 3))
            self.m2 = np.zeros((n, 3))
        if self.replicates and self.rep_count is None:
            self.rep_count = np.zeros((n, self.replicates), dtype=np.int64)
            self.rep_mean = np.zeros((n, self.replicates, 3))

    @property
    def spp(self) -> int:
        """Samples in every pixel (the smallest count if they differ)."""
        return int(self.count.min()) if len(self.count) else 0

    @property
    def uniform(self) -> bool:
        """Whether every pixel has the same sample count."""
        return bool(np.all(self.count == self.count[0])) if len(self.count) else True

    def add_block(self, first_pixel: int, samples: np.ndarray, first_sample: int = 0) -> None:
        """Add ``samples (npix, k, 3)``: samples ``first_sample .. first_sample + k - 1`` of each
        of pixels first_pixel, ... (the sample index says which replicate a sample belongs to)."""
        _add_block(self.count, self.mean, self.m2, first_pixel, samples)
        if self.replicates:
            _add_replicates(self.rep_count, self.rep_mean, first_pixel, first_sample, samples)

    def merge(self, other: "Film") -> None:
        """Fold ``other``'s statistics (same resolution and replicates) into this film, pixel by
        pixel, exactly. The records are not looked at: :func:`merge_renders` checks them."""
        if (other.width, other.height) != (self.width, self.height):
            raise InputError(f"cannot merge a {other.width}x{other.height} film into a "
                             f"{self.width}x{self.height} one")
        if other.replicates != self.replicates:
            raise InputError(f"cannot merge a film of {other.replicates} replicates into one of "
                             f"{self.replicates}: their error estimates would not combine")
        _merge(self.count, self.mean, self.m2, other.count, other.mean, other.m2)
        self.learned = {}
        if self.replicates:
            _merge_replicates(self.rep_count, self.rep_mean, other.rep_count, other.rep_mean)

    def copy(self) -> "Film":
        replicas = (self.rep_count.copy(), self.rep_mean.copy()) if self.replicates else (None, None)
        return Film(self.width, self.height, self.count.copy(), self.mean.copy(), self.m2.copy(),
                    dataclasses.replace(self.record), self.replicates, *replicas,
                    {name: plane.copy() for name, plane in self.learned.items()})

    def variance(self) -> np.ndarray:
        """(P, 3) variance of one sample's estimate, such that variance / count is the variance
        of the pixel value: for independent samples the unbiased sample variance; for a sampler
        with replicates the effective per-sample variance from the replicate means (module
        docstring). 0 where there are fewer than 2 samples (or replicates with samples)."""
        if self.replicates:
            return _replicate_variance(self.count, self.rep_count, self.rep_mean, self.m2)
        denom = np.maximum(self.count - 1, 1).astype(np.float64)[:, None]
        return np.where((self.count >= 2)[:, None], self.m2 / denom, 0.0)

    def variance_of_mean(self) -> np.ndarray:
        """(P, 3) variance of each pixel value (the mean): per-sample variance / count."""
        return self.variance() / np.maximum(self.count, 1)[:, None]

    def image(self) -> np.ndarray:
        """(H, W, 3) float64 pixel means."""
        return self.mean.reshape(self.height, self.width, 3)


def merge_renders(a: Film, b: Film, name_a: str = "the first render",
                  name_b: str = "the second render") -> Film:
    """A new film pooling renders ``a`` and ``b``, after checking that their records allow it
    (same scene and estimator, disjoint samples: ``tracer.record.check_mergeable``, whose
    message names them ``name_a`` and ``name_b``)."""
    if (a.width, a.height) != (b.width, b.height):
        raise InputError(f"cannot pool {name_a} ({a.width}x{a.height}) and {name_b} "
                         f"({b.width}x{b.height}): different resolutions")
    check_mergeable(a.record, b.record, name_a, name_b)
    for name, film in ((name_a, a), (name_b, b)):
        if film.replicates != replicates_of(film.record.sampler):
            raise InputError(f"cannot pool {name_a} and {name_b}: {name} ({film.record.sampler} sampler) "
                             "holds no replicate means (channels replicate0.R, ...), from which the error "
                             "of a pool is estimated")
    pooled = a.copy()
    pooled.merge(b)
    pooled.record = merged(a.record, b.record)
    return pooled


@jit
def _fold(count, mean, m2, pixel, n_b, mean_b, m2_b) -> None:
    """Fold the statistics ``(n_b, mean_b (3,), m2_b (3,))`` of a disjoint sample set into one
    pixel (Chan, Golub and LeVeque 1979)."""
    n_a = count[pixel]
    n = n_a + n_b
    if n == 0:
        return
    if n_a == 0:  # exactly the other's statistics (the formula would give inf x 0 for a huge mean)
        count[pixel] = n_b
        for c in range(3):
            mean[pixel, c] = mean_b[c]
            m2[pixel, c] = m2_b[c]
        return
    share = n_b / n
    for c in range(3):
        delta = mean_b[c] - mean[pixel, c]
        mean[pixel, c] += delta * share
        m2[pixel, c] += m2_b[c] + delta * delta * n_a * share
    count[pixel] = n


# Compiled code runs to its end before Python sees a Ctrl-C, so neither of these can leave a
# pixel half-merged.


@jit
def _merge(count, mean, m2, n_b, mean_b, m2_b) -> None:
    """Fold a whole film's ``(count, mean, m2)`` into another's."""
    for pixel in range(len(n_b)):
        _fold(count, mean, m2, pixel, n_b[pixel], mean_b[pixel], m2_b[pixel])


def _replicate_variance(count: np.ndarray, rep_count: np.ndarray, rep_mean: np.ndarray,
                        m2: np.ndarray) -> np.ndarray:
    """(P, 3) effective per-sample variance n x Var(mean) from replicate counts ``(P, R)`` and
    means ``(P, R, 3)`` (module docstring); where one replicate holds every sample, the
    per-sample spread ``m2 (P, 3)`` / (n - 1) instead."""
    n = np.maximum(count, 1).astype(np.float64)[:, None]
    w = rep_count / n  # (P, R)
    pooled = np.einsum("pr,prc->pc", w, rep_mean)
    spread = np.einsum("pr,prc->pc", w * w, (rep_mean - pooled[:, None, :]) ** 2)
    share = 1.0 - np.sum(w * w, axis=1)[:, None]  # 0 where one replicate holds every sample
    spread_of_samples = m2 / np.maximum(n - 1.0, 1.0) / n
    var_mean = np.where(share > 1e-12, spread / np.where(share > 1e-12, share, 1.0),
                        np.where(n >= 2, spread_of_samples, 0.0))
    return n * var_mean


@jit
def _add_replicates(rep_count, rep_mean, first, first_sample, samples) -> None:
    """Fold ``samples (npix, k, 3)`` (sample indices first_sample, ...) into the running means of
    their replicates (sample s belongs to replicate s % R)."""
    npix, k, _ = samples.shape
    replicates = rep_count.shape[1]
    for row in range(npix):
        pixel = first + row
        for j in range(k):
            r = (first_sample + j) % replicates
            rep_count[pixel, r] += 1
            share = 1.0 / rep_count[pixel, r]
            for c in range(3):
                rep_mean[pixel, r, c] += (samples[row, j, c] - rep_mean[pixel, r, c]) * share


@jit
def _merge_replicates(rep_count, rep_mean, n_b, mean_b) -> None:
    """Fold replicate r of another film into replicate r of this one, for every pixel and r."""
    for pixel in range(rep_count.shape[0]):
        for r in range(rep_count.shape[1]):
            n = rep_count[pixel, r] + n_b[pixel, r]
            if n == 0:
                continue
            share = n_b[pixel, r] / n
            for c in range(3):
                rep_mean[pixel, r, c] += (mean_b[pixel, r, c] - rep_mean[pixel, r, c]) * share
            rep_count[pixel, r] = n


@jit
def _add_block(count, mean, m2, first, samples) -> None:
    """Fold ``samples (npix, k, 3)`` into pixels first, first + 1, ...: each pixel's k samples
    are reduced to (k, mean, M2) by two passes, then folded in."""
    npix, k, _ = samples.shape
    mean_b = np.empty(3)
    m2_b = np.empty(3)
    for row in range(npix):
        for c in range(3):
            total = 0.0
            for j in range(k):
                total += samples[row, j, c]
            mean_b[c] = total / k
            sq = 0.0
            for j in range(k):
                dev = samples[row, j, c] - mean_b[c]
                sq += dev * dev
            m2_b[c] = sq
        _fold(count, mean, m2, first + row, k, mean_b, m2_b)
