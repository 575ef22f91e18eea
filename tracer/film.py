"""The film: per-pixel running statistics of a render, and their exact merge.

Per pixel the film holds the sample count, the running mean and Welford's M2 (sum of squared
deviations from the mean) in float64. Two films of disjoint samples merge exactly with Chan,
Golub and LeVeque's parallel formula, so renders can be resumed, split across processes and
pooled into references. Files are elsewhere: ``tracer.imagefiles`` (the EXR contract and
PNG previews).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .jit import jit
from .record import RenderRecord, check_mergeable, merged


@dataclass
class Film:
    """Running statistics of ``width * height`` pixels, row-major, row 0 at the top.

    count : (P,) int64 samples per pixel.   mean : (P, 3) float64.   m2 : (P, 3) float64.
    record : how the samples were made (``tracer.record``), written to and read from the EXR
        header.
    """

    width: int
    height: int
    count: np.ndarray = field(default=None)  # type: ignore[assignment]
    mean: np.ndarray = field(default=None)  # type: ignore[assignment]
    m2: np.ndarray = field(default=None)  # type: ignore[assignment]
    record: RenderRecord = field(default_factory=RenderRecord)

    def __post_init__(self) -> None:
        n = self.width * self.height
        if self.count is None:
            self.count = np.zeros(n, dtype=np.int64)
            self.mean = np.zeros((n, 3))
            self.m2 = np.zeros((n, 3))

    @property
    def spp(self) -> int:
        """Samples in every pixel (the smallest count if they differ)."""
        return int(self.count.min()) if len(self.count) else 0

    @property
    def uniform(self) -> bool:
        """Whether every pixel has the same sample count."""
        return bool(np.all(self.count == self.count[0])) if len(self.count) else True

    def add_block(self, first_pixel: int, samples: np.ndarray) -> None:
        """Add ``samples (npix, k, 3)``: k samples for each of pixels first_pixel, ... ."""
        _add_block(self.count, self.mean, self.m2, first_pixel, samples)

    def merge(self, other: "Film") -> None:
        """Fold ``other``'s statistics (same resolution) into this film, pixel by pixel, exactly.
        The records are not looked at: :func:`merge_renders` checks them."""
        if (other.width, other.height) != (self.width, self.height):
            raise InputError(f"cannot merge a {other.width}x{other.height} film into a "
                             f"{self.width}x{self.height} one")
        _merge(self.count, self.mean, self.m2, other.count, other.mean, other.m2)

    def copy(self) -> "Film":
        return Film(self.width, self.height, self.count.copy(), self.mean.copy(), self.m2.copy(),
                    dataclasses.replace(self.record))

    def variance(self) -> np.ndarray:
        """(P, 3) unbiased variance of one sample's estimate; 0 where count < 2."""
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
