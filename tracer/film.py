"""The film: per-pixel running statistics, exact merges, and EXR/PNG files.

Per pixel the film holds the sample count, the running mean and Welford's M2 (sum of squared
deviations from the mean) in float64. Two films merge exactly with Chan et al.'s parallel
formula, so renders can be resumed, split across processes and summed into references.

EXR layout (``DESIGN.md``): channels ``R,G,B`` = pixel mean and ``variance.R/G/B`` = unbiased
variance of a single sample's estimate (the variance of the pixel value is that / spp),
float32, zip. If the counts differ between pixels (a render interrupted mid-pass), a seventh
channel ``samples`` holds each pixel's count and ``tracer:spp`` is the smallest count.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_write
from .errors import InputError
from .jit import jit

CHANNELS = ("R", "G", "B", "variance.R", "variance.G", "variance.B")
COUNT_CHANNEL = "samples"


@dataclass
class Film:
    """Running statistics of ``width * height`` pixels, row-major, row 0 at the top.

    count : (P,) int64 samples per pixel.   mean : (P, 3) float64.   m2 : (P, 3) float64.
    attributes : header values carried along (``tracer:strategy`` and the like).
    """

    width: int
    height: int
    count: np.ndarray = field(default=None)  # type: ignore[assignment]
    mean: np.ndarray = field(default=None)  # type: ignore[assignment]
    m2: np.ndarray = field(default=None)  # type: ignore[assignment]
    attributes: dict[str, Any] = field(default_factory=dict)

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

    def add_block(self, first_pixel: int, samples: np.ndarray) -> None:
        """Add ``samples (npix, k, 3)``: k samples for each of pixels first_pixel, ... ."""
        _add_block(self.count, self.mean, self.m2, first_pixel, samples)

    def merge(self, other: "Film") -> None:
        """Fold ``other`` (same resolution) into this film, pixel by pixel, exactly."""
        if (other.width, other.height) != (self.width, self.height):
            raise InputError(f"cannot merge a {other.width}x{other.height} film into a "
                             f"{self.width}x{self.height} one")
        _merge(self.count, self.mean, self.m2, other.count, other.mean, other.m2)

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

    # -----------------------------------------------------------------------------------------
    # Files

    def write_exr(self, path: str | os.PathLike[str], half: bool = False) -> None:
        """Write the EXR atomically (temporary file in the same folder, then rename).

        ``half`` stores the means as 16-bit floats (3 significant digits), for references whose
        own error is far below what they are compared with; variances stay 32-bit.
        """
        import OpenImageIO as oiio

        uniform = bool(np.all(self.count == self.count[0])) if len(self.count) else True
        names = list(CHANNELS) + ([] if uniform else [COUNT_CHANNEL])
        planes = [self.mean, self.variance()]
        if not uniform:
            planes.append(self.count[:, None].astype(np.float64))
        pixels = np.ascontiguousarray(np.concatenate(planes, axis=1), dtype=np.float32)
        pixels = pixels.reshape(self.height, self.width, -1)
        spec = oiio.ImageSpec(self.width, self.height, len(names), "half" if half else "float")
        spec.channelnames = tuple(names)
        if half:
            # Half floats only for the means: variances of bright, small emitters exceed the
            # half range (65504) and would read back as inf.
            spec.channelformats = (oiio.TypeDesc("half"),) * 3 + (oiio.TypeDesc("float"),) * (len(names) - 3)
        spec.attribute("compression", "zip")
        spec.attribute("tracer:spp", int(self.spp))
        for key, value in self.attributes.items():
            if key != "tracer:spp":
                spec.attribute(key, value)
        atomic_write(path, lambda tmp: _oiio_write(tmp, spec, pixels))

    def write_png(self, path: str | os.PathLike[str], exposure: float = 0.0) -> None:
        """An 8-bit sRGB preview: exposure (stops), then the sRGB transfer curve."""
        write_png(path, self.image(), exposure)

    @classmethod
    def read_exr(cls, path: str | os.PathLike[str]) -> "Film":
        """Read an EXR written by :meth:`write_exr`; channels are looked up by name."""
        import OpenImageIO as oiio

        path = str(path)
        if not os.path.isfile(path):
            raise InputError("no such file", path)
        inp = oiio.ImageInput.open(path)
        if inp is None:
            raise InputError(f"cannot read image: {oiio.geterror()}", path)
        try:
            spec = inp.spec()
            data = inp.read_image(0, 0, 0, spec.nchannels, "float")
        finally:
            inp.close()
        if data is None:
            raise InputError("cannot read image data", path)
        names = list(spec.channelnames)
        missing = [c for c in CHANNELS if c not in names]
        if missing:
            raise InputError(f"missing channel(s) {', '.join(missing)} (has {', '.join(names)})", path)
        data = np.asarray(data, dtype=np.float64).reshape(spec.height * spec.width, spec.nchannels)
        attributes = {a.name: a.value for a in spec.extra_attribs if a.name.startswith("tracer:")}
        spp = int(attributes.get("tracer:spp", 0))
        if COUNT_CHANNEL in names:
            count = np.rint(data[:, names.index(COUNT_CHANNEL)]).astype(np.int64)
        else:
            count = np.full(spec.height * spec.width, spp, dtype=np.int64)
        mean = np.ascontiguousarray(data[:, [names.index(c) for c in CHANNELS[:3]]])
        var = np.ascontiguousarray(data[:, [names.index(c) for c in CHANNELS[3:]]])
        m2 = var * np.maximum(count - 1, 0)[:, None]
        return cls(spec.width, spec.height, count, mean, m2, attributes)


def merge_renders(a: Film, b: Film) -> Film:
    """Merge render ``b`` into render ``a`` (both read from EXRs) after checking that they are
    renders of the same scene, resolution and strategy with independent random numbers."""
    for key in ("tracer:strategy", "tracer:heuristic", "tracer:light_samples", "tracer:bsdf_samples",
                "tracer:one_sample", "tracer:light_selection"):
        if a.attributes.get(key) != b.attributes.get(key):
            raise InputError(f"cannot merge renders with different {key}: "
                             f"{a.attributes.get(key)!r} and {b.attributes.get(key)!r}")
    scene_a, scene_b = a.attributes.get("tracer:scene"), b.attributes.get("tracer:scene")
    if scene_a and scene_b and Path(scene_a).name != Path(scene_b).name:
        raise InputError(f"cannot merge renders of different scenes: {scene_a} and {scene_b}")
    if a.attributes.get("tracer:seed") == b.attributes.get("tracer:seed"):
        range_a, range_b = sample_range(a), sample_range(b)
        if range_a[0] < range_b[1] and range_b[0] < range_a[1]:
            raise InputError(
                f"the two renders used the same seed and sample indices ({range_a[0]}-{range_a[1] - 1} "
                f"and {range_b[0]}-{range_b[1] - 1}): they hold the same samples, so merging them would "
                "count each twice; render one with another --seed")
    merged = Film(a.width, a.height, a.count.copy(), a.mean.copy(), a.m2.copy(), dict(a.attributes))
    merged.merge(b)
    (first_a, next_a), (first_b, next_b) = sample_range(a), sample_range(b)
    merged.attributes["tracer:first_sample"] = int(min(first_a, first_b))
    merged.attributes["tracer:next_sample"] = int(max(next_a, next_b))
    merged.attributes["tracer:seconds"] = float(a.attributes.get("tracer:seconds", 0.0)) + float(
        b.attributes.get("tracer:seconds", 0.0))
    return merged


def exr_is_half(path: str | os.PathLike[str]) -> bool:
    """Whether an EXR stores its means (R, G, B) as 16-bit floats (merges of half references stay half)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"cannot read image: {oiio.geterror()}", str(path))
    try:
        spec = inp.spec()
        formats = list(spec.channelformats) or [spec.format] * spec.nchannels
        return formats[list(spec.channelnames).index("R")] == oiio.HALF
    finally:
        inp.close()


def sample_range(film: Film) -> tuple[int, int]:
    """(first, next) sample indices a render drew with its seed; files from before this
    attribute existed count as 0 .. spp."""
    first = int(film.attributes.get("tracer:first_sample", 0))
    return first, int(film.attributes.get("tracer:next_sample", first + film.spp))


def to_srgb8(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB ``(H, W, 3)`` -> 8-bit sRGB: exposure (stops), the sRGB curve, rounding."""
    x = np.clip(np.nan_to_num(image * 2.0**exposure, nan=0.0), 0.0, 1.0)
    # sRGB transfer function (IEC 61966-2-1).
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.rint(srgb * 255.0).astype(np.uint8)


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


def write_png(path: str | os.PathLike[str], image: np.ndarray, exposure: float = 0.0,
              srgb: bool = False) -> None:
    """Write ``image (H, W, 3)`` as an 8-bit PNG, atomically: linear RGB through
    :func:`to_srgb8`, or, with ``srgb``, values already display-encoded in [0, 1]."""
    import OpenImageIO as oiio

    if srgb:
        pixels = np.rint(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
    else:
        pixels = to_srgb8(image, exposure)
    pixels = np.ascontiguousarray(pixels)
    spec = oiio.ImageSpec(image.shape[1], image.shape[0], pixels.shape[2], "uint8")
    atomic_write(path, lambda tmp: _oiio_write(tmp, spec, pixels))


def _oiio_write(path: str, spec: Any, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(path)
    if out is None:
        raise InputError(f"cannot write images of this type: {oiio.geterror()}", path)
    ok = out.open(path, spec) and out.write_image(pixels)
    error = out.geterror()
    out.close()
    if not ok:
        raise InputError(f"cannot write: {error}", path)
