"""Image files: the render EXR contract and 8-bit PNG previews, through OpenImageIO.

The EXR (``docs/DESIGN.md``, "The render file"): channels ``R,G,B`` = pixel mean and
``variance.R/G/B`` = unbiased variance of a single sample's estimate (the variance of the
pixel value is that / spp), float32 (or half means for references), zip compression; the
header holds ``tracer:spp`` and the render record (``tracer.record``). If the counts differ
between pixels (a render interrupted mid-pass), a seventh channel ``samples`` holds each
pixel's count and ``tracer:spp`` is the smallest count. A 32-bit float counts exactly up to
2^24, so where a count exceeds that the count is two channels instead, ``samples.low`` (count
mod 2^24) and ``samples.high`` (count // 2^24), each exact: counts up to 2^48 a pixel (a
film past that with unequal counts is refused, nothing written). Channels are looked up by name
on read (EXR reorders them).

Reads check the header against itself and the pixels before anything trusts it: the header's
fields against their bounds (``tracer.record``), ``tracer:spp`` against the smallest count, and
pixels that hold no samples against their mean and variance (all 0), and fewer than two against
their variance (0); what a writer would never write is refused, with the pixel named.

Films of a sampler with replicates (``stratified``, ``sobol``) write their variance channels as
the effective per-sample variance (``tracer.film``: count x the variance of the pixel mean
estimated from independent replicates), so that ``variance / spp`` is the error of the pixel
value for every sampler, and add each replicate's mean and count as layers
``replicate<r>.R/G/B`` and ``replicate<r>.samples`` (float32), which merges and resumes pool
replicate by replicate.

A render that learned between passes (``tracer.tuning``) adds what it learned per pixel:
``allocation.light`` (adaptive allocation: the share of a camera sample's technique samples
that are light samples) and ``alpha.R/G/B`` (optimal MIS: the control variate's coefficient).
They are for looking at; reads ignore them.

An EXR that another renderer wrote (no ``tracer:spp`` in its header: :func:`is_tracer_exr`)
is read by :func:`read_external_exr` as what it holds: the RGB (or gray) pixel values of a
channel set or layer, and ``variance.*`` channels if present, taken in tracer's convention
(one sample's variance). Its sample count and scene are not known from the file.

Every write is atomic (``tracer.atomic``) and checked: an error from OpenImageIO, also at
close, raises ``InputError`` and leaves any existing file as it was.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .atomic import atomic_write
from .errors import InputError
from .film import Film
from .record import RenderRecord
from .sampler_choice import MAX_REPLICATE_COUNT, max_samples, replicates_of

CHANNELS = ("R", "G", "B", "variance.R", "variance.G", "variance.B")
COUNT_CHANNEL = "samples"
# Counts above FLOAT_EXACT (where float32 stops counting exactly) are written as two channels.
COUNT_LOW, COUNT_HIGH = "samples.low", "samples.high"
FLOAT_EXACT = 2**24
MAX_SPLIT_COUNT = FLOAT_EXACT * FLOAT_EXACT  # what the two channels hold (exclusive)
SPP_ATTRIBUTE = "tracer:spp"
REPLICATE_LAYER = "replicate{}"
VARIANCE_LAYER = "variance"
MOMENT_PREFIX = "m2_"  # Mitsuba 3's moment integrator: second moments (read_external_exr)
FLOAT32_MAX = 3.4028234e38
HALF_MAX = 65504.0  # the largest finite 16-bit float
MAX_COUNT = 2**53  # sample counts stay exact in float64


def write_exr(path: str | os.PathLike[str], film: Film, half: bool = False) -> None:
    """Write ``film`` and its record as a render EXR, atomically.

    ``half`` stores the means as 16-bit floats (3 significant digits), for references whose own
    error is far below what they are compared with; variances stay 32-bit. Means beyond the
    half range (65504, a visible bright emitter) would read back as inf: then the means are
    written as 32-bit floats instead, whatever ``half`` says.
    """
    import OpenImageIO as oiio

    half = half and bool(np.all(np.abs(film.mean) <= HALF_MAX))
    check_writable(film, str(path))
    names = list(CHANNELS)
    planes = [film.mean, film.variance()]
    if not film.uniform:
        if int(film.count.max()) <= FLOAT_EXACT:
            names.append(COUNT_CHANNEL)
            planes.append(film.count[:, None].astype(np.float64))
        else:
            names += [COUNT_LOW, COUNT_HIGH]
            planes += [(film.count % FLOAT_EXACT)[:, None].astype(np.float64),
                       (film.count // FLOAT_EXACT)[:, None].astype(np.float64)]
    if film.replicates:
        for r in range(film.replicates):
            names += [f"{REPLICATE_LAYER.format(r)}.{c}" for c in ("R", "G", "B", COUNT_CHANNEL)]
            planes += [film.rep_mean[:, r, :], film.rep_count[:, r, None].astype(np.float64)]
    for name, plane in film.learned.items():
        names.append(name)
        planes.append(plane[:, None])
    with np.errstate(over="ignore"):
        pixels = np.ascontiguousarray(np.concatenate(planes, axis=1), dtype=np.float32)
    bad = ~np.all(np.isfinite(pixels), axis=1)
    if bad.any():
        # A mean near float32's limit whose variance (its square) is not: never written as inf.
        channel = names[int(np.argmax(~np.isfinite(pixels[np.argmax(bad)])))]
        raise InputError(f"channel '{channel}' at {_pixel(bad, film.width)} exceeds what a 32-bit float "
                         "holds (3.4e38); nothing was written", str(path))
    pixels = pixels.reshape(film.height, film.width, -1)
    spec = oiio.ImageSpec(film.width, film.height, len(names), "half" if half else "float")
    spec.channelnames = tuple(names)
    if half:
        # Half floats only for the means: variances of bright, small emitters exceed the
        # half range (65504) and would read back as inf.
        spec.channelformats = (oiio.TypeDesc("half"),) * 3 + (oiio.TypeDesc("float"),) * (len(names) - 3)
    spec.attribute("compression", "zip")
    # EXR integer attributes are 32-bit: larger counts as decimal strings (read back by _sample_count).
    spp = int(film.spp)
    spec.attribute(SPP_ATTRIBUTE, spp if spp < 2**31 else str(spp))
    for key, value in film.record.attributes().items():
        spec.attribute(key, value)
    atomic_write(path, lambda tmp: _write(tmp, spec, pixels))


def check_writable(film: Film, where: str) -> None:
    """Raise InputError (nothing written) unless :func:`read_exr` would read back the file of
    ``film``: counts that the count channels hold exactly, a header that passes the reader's
    checks. A merge or a resume checks this before it writes, so that tracer never writes a
    file it then refuses."""
    most = int(film.count.max()) if len(film.count) else 0
    if most > MAX_COUNT:
        raise InputError(f"a pixel would hold {most} samples, more than the {MAX_COUNT} (2^53) a render "
                         "file counts exactly; nothing was written", where)
    if not film.uniform and most >= MAX_SPLIT_COUNT:
        raise InputError(f"a pixel would hold {most} samples while others hold fewer: unequal counts are "
                         f"stored exactly up to {MAX_SPLIT_COUNT - 1} (2^48 - 1); nothing was written", where)
    if film.replicates and film.rep_count.size and int(film.rep_count.max()) > MAX_REPLICATE_COUNT:
        raise InputError(f"a replicate holds {int(film.rep_count.max())} samples, more than the "
                         f"{MAX_REPLICATE_COUNT} a 32-bit float counts exactly; nothing was written", where)
    try:
        RenderRecord.from_attributes(film.record.attributes(), most)
    except InputError as exc:
        raise InputError(f"the render's record would not read back ({exc}); nothing was written", where) from None


def read_exr(path: str | os.PathLike[str]) -> Film:
    """Read a render EXR (written by :func:`write_exr`, or any EXR with its six channels) into a
    film whose record is the header's."""
    path = str(path)
    spec, _, data = _read_pixels(path)
    names = list(spec.channelnames)
    missing = [c for c in CHANNELS if c not in names]
    if missing:
        raise InputError(f"missing channel(s) {', '.join(missing)} (has {', '.join(names)})", path)
    attributes = _tracer_attributes(spec)
    spp = _sample_count(attributes.get(SPP_ATTRIBUTE, 0), path)
    count = _read_counts(names, data, spec.width, path)
    if count is None:
        count = np.full(spec.height * spec.width, spp, dtype=np.int64)
    elif SPP_ATTRIBUTE in attributes and len(count) and int(count.min()) != spp:
        raise InputError(f"header attribute {SPP_ATTRIBUTE} = {spp} is not the smallest count of the sample "
                         f"channels, {int(count.min())}", path)
    mean = np.ascontiguousarray(data[:, [names.index(c) for c in CHANNELS[:3]]])
    var = np.ascontiguousarray(data[:, [names.index(c) for c in CHANNELS[3:]]])
    for label, values, ok in (("mean (R, G, B)", mean, np.isfinite(mean)),
                              ("variance", var, np.isfinite(var) & (var >= 0.0))):
        bad = ~np.all(ok, axis=1)
        if bad.any():
            raise InputError(f"{label} is not a finite{' non-negative' if label == 'variance' else ''} "
                             f"number at {_pixel(bad, spec.width)}: {values[np.argmax(bad)].tolist()}", path)
    if SPP_ATTRIBUTE in attributes:
        # A tracer file: a pixel without samples has a zero mean and variance, one with a single
        # sample a zero variance. (A header edited to say fewer samples than the pixels hold
        # fails here, instead of a resume silently dropping them.)
        for label, bad in (("holds no samples but a mean or variance that is not 0",
                            (count == 0) & np.any((mean != 0.0) | (var != 0.0), axis=1)),
                           ("holds one sample but a variance that is not 0",
                            (count == 1) & np.any(var != 0.0, axis=1))):
            if bad.any():
                raise InputError(f"{_pixel(bad, spec.width)} {label} (by {SPP_ATTRIBUTE} = {spp} and the "
                                 "sample channels): the header does not describe these pixels", path)
    try:
        # A file that names no sample range holds samples 0 .. (its largest count) - 1.
        record = RenderRecord.from_attributes(attributes, int(count.max()) if len(count) else 0)
    except InputError as exc:
        raise InputError(str(exc), path) from None
    listed = sum(n - f for _, f, n in record.samples or ())
    if record.samples is not None and len(count) and int(count.max()) > listed:
        # More samples in a pixel than the ranges list (a merge by tracer 0.1 kept one seed): what
        # the file holds is unknown, so it may be read and compared with but not pooled.
        record.samples = None
    m2 = var * np.maximum(count - 1, 0)[:, None]
    limit = max_samples(record.sampler or "independent")
    if record.samples and max(n for _, _, n in record.samples) > limit:
        raise InputError(f"header attribute tracer:samples lists sample indices beyond the "
                         f"{limit} the {record.sampler} sampler draws", path)
    film = Film(spec.width, spec.height, count, mean, m2, record)
    _read_replicates(film, names, data, path, _means_are_half(spec))
    return film


def _read_pixels(path: str, header_only: bool = False) -> tuple[Any, str, np.ndarray | None]:
    """The image's spec, its file format (OpenImageIO's name: ``openexr``, ``png`` ...) and its
    pixels as ``(P, C)`` float64, row-major (None with ``header_only``); InputError if there is
    no such file or OpenImageIO cannot read it."""
    import OpenImageIO as oiio

    if not os.path.isfile(path):
        raise InputError("no such file", path)
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise InputError(f"cannot read image: {_error_text(oiio)}", path)
    try:
        spec, file_format = inp.spec(), inp.format_name()
        if header_only:
            return spec, file_format, None
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
        error = _error_text(inp) if data is None else ""
    finally:
        inp.close()
    if data is None:
        raise InputError(f"cannot read image data{': ' + error if error else ''}", path)
    return spec, file_format, np.asarray(data, dtype=np.float64).reshape(spec.height * spec.width,
                                                                         spec.nchannels)


def _tracer_attributes(spec) -> dict[str, Any]:
    """The header's ``tracer:*`` attributes, by name."""
    return {a.name: a.value for a in spec.extra_attribs if a.name.startswith("tracer:")}


def _read_counts(names: list[str], data: np.ndarray, width: int, path: str) -> np.ndarray | None:
    """(P,) int64 per-pixel counts from the ``samples`` channel, or from ``samples.low`` and
    ``samples.high``; None if the file has neither (every pixel then holds ``tracer:spp``).
    Raises InputError where a count is not whole, or not exact in its 32-bit float."""
    if COUNT_CHANNEL in names:
        parts = [(COUNT_CHANNEL, data[:, names.index(COUNT_CHANNEL)], FLOAT_EXACT, 1)]
    elif COUNT_LOW in names or COUNT_HIGH in names:
        if not (COUNT_LOW in names and COUNT_HIGH in names):
            raise InputError(f"channels '{COUNT_LOW}' and '{COUNT_HIGH}' come together; one is missing", path)
        parts = [(COUNT_LOW, data[:, names.index(COUNT_LOW)], FLOAT_EXACT - 1, 1),
                 (COUNT_HIGH, data[:, names.index(COUNT_HIGH)], FLOAT_EXACT, FLOAT_EXACT)]
    else:
        return None
    count = np.zeros(len(data), dtype=np.int64)
    for name, values, most, scale in parts:
        # Above 2^24 a float32 channel no longer counts exactly (files of tracer <= 0.9 wrote such
        # counts rounded): refused rather than read as a count that may be off.
        bad = ~(np.isfinite(values) & (values >= 0) & (values <= most) & (values == np.rint(values)))
        if bad.any():
            raise InputError(f"channel '{name}' is not a sample count at {_pixel(bad, width)}: "
                             f"{values[np.argmax(bad)]} (a count is a whole number in 0 .. {most}, exact in "
                             "a 32-bit float)", path)
        count += values.astype(np.int64) * scale
    return count


def _read_replicates(film: Film, names: list[str], data: np.ndarray, path: str, half: bool) -> None:
    """Attach the replicate layers of a file whose sampler has replicates, checked against the
    rest of the file: every layer present; whole counts that add up to the pixel's count and
    that the listed sample ranges can hold (replicate r holds the indices s with s % R = r);
    finite means that pool to the pixel mean (to the precision of the stored means: ``half``);
    a variance they give that a 32-bit float holds. A file of such a sampler without them
    (another tool's) keeps its variance channel and cannot be pooled."""
    replicates = replicates_of(film.record.sampler)
    layers = [REPLICATE_LAYER.format(r) for r in range(replicates)]
    found = [n for n in names if n.startswith("replicate")]
    if not found:
        return
    wanted = [f"{layer}.{c}" for layer in layers for c in ("R", "G", "B", COUNT_CHANNEL)]
    if sorted(found) != sorted(wanted):
        raise InputError(f"replicate channels {', '.join(sorted(found)[:4])}... do not match the "
                         f"{replicates} replicates of the {film.record.sampler or 'independent'} sampler",
                         path)
    columns = [[names.index(f"{layer}.{c}") for c in ("R", "G", "B")] for layer in layers]
    rep_mean = np.ascontiguousarray(np.stack([data[:, col] for col in columns], axis=1))
    counts = np.stack([data[:, names.index(f"{layer}.{COUNT_CHANNEL}")] for layer in layers], axis=1)
    whole = np.all(np.isfinite(counts) & (counts >= 0) & (counts == np.rint(counts)), axis=1)
    bad = ~whole | (np.where(whole[:, None], counts, 0).sum(axis=1) != film.count)
    if bad.any():
        raise InputError(f"replicate counts are not whole numbers adding up to the pixel's sample count at "
                         f"{_pixel(bad, film.width)}", path)
    if film.record.samples is not None:
        # How many listed indices fall in each replicate: #{s in [first, next): s = r mod R}.
        room = [sum((n - 1 - r) // replicates - (f - 1 - r) // replicates for _, f, n in film.record.samples)
                for r in range(replicates)]
        bad = np.any(counts > np.array(room, dtype=np.float64), axis=1)
        if bad.any():
            raise InputError(f"replicate counts exceed what the sample ranges of tracer:samples hold in each "
                             f"replicate at {_pixel(bad, film.width)}", path)
    bad = ~np.all(np.isfinite(rep_mean), axis=(1, 2))
    if bad.any():
        raise InputError(f"a replicate mean is not a finite number at {_pixel(bad, film.width)}", path)
    weights = counts / np.maximum(film.count, 1)[:, None]
    pooled = np.einsum("pr,prc->pc", weights, rep_mean)
    scale = np.maximum(np.abs(film.mean), np.abs(rep_mean).max(axis=1))
    # Half or float32 rounding of the means, with room; below 2^-14 half floats are subnormal,
    # spaced 2^-24 apart whatever the value.
    tolerance = (2.0**-9 * scale + 2.0**-23) if half else (2.0**-20 * scale + 1e-37)
    bad = np.any(np.abs(pooled - film.mean) > tolerance, axis=1) & (film.count > 0)
    if bad.any():
        raise InputError(f"the replicate means do not pool to the pixel mean (R, G, B) at "
                         f"{_pixel(bad, film.width)}", path)
    film.replicates = replicates
    film.rep_count = counts.astype(np.int64)
    film.rep_mean = rep_mean
    variance = film.variance()
    bad = ~np.all(np.isfinite(variance) & (variance <= FLOAT32_MAX), axis=1)
    if bad.any():
        raise InputError(f"the replicate means give a variance beyond what a 32-bit float holds at "
                         f"{_pixel(bad, film.width)}", path)


def is_tracer_exr(path: str | os.PathLike[str]) -> bool:
    """Whether the file is a tracer render: its header holds ``tracer:spp`` (written by
    :func:`write_exr`, and by ``benchmarks/mitsuba_render.py``). Reads the header only;
    InputError if there is no such file or it cannot be read."""
    spec, _, _ = _read_pixels(str(path), header_only=True)
    return SPP_ATTRIBUTE in _tracer_attributes(spec)


@dataclass
class ExternalImage:
    """An image read from an EXR that another renderer wrote (Mitsuba 3, ...): its pixel
    values and, where the file has them, its variance channels. Nothing else is known of it.

    width, height : pixels.
    mean : (P, 3) float64 pixel values, row-major, row 0 at the top (a gray ``Y`` file: R = G = B).
    variance : (P, 3) float64 or None: the ``variance.*`` channels, read in tracer's convention
        as the variance of *one sample's* estimate (the pixel value's variance is this / spp;
        module docstring); None if the file has none.
    channels : the three channels ``mean`` was read from (``R, G, B``; ``beauty.R`` ...; ``Y``
        three times).
    variance_channels : likewise for ``variance``, or None.
    has_moments : whether the file has channels ``m2_*`` (Mitsuba 3's ``moment`` integrator),
        which are not read (see :func:`read_external_exr`).
    """

    width: int
    height: int
    mean: np.ndarray
    variance: np.ndarray | None
    channels: tuple[str, str, str]
    variance_channels: tuple[str, str, str] | None
    has_moments: bool


def read_external_exr(path: str | os.PathLike[str], layer: str | None = None) -> ExternalImage:
    """Read the RGB image of an EXR that is not a tracer render, and its variance channels.

    The colour is channels ``R, G, B`` or, for a gray image, ``Y`` (R = G = B), of ``layer``
    (channels ``LAYER.R`` ...) if one is named; otherwise the plain channels, or, when the file
    has none, its one RGB layer (several are refused, naming them). Names match in any case
    (``r``), exactly where two differ only in case. The variance is channels ``variance.R/G/B``
    (``variance.Y``; ``LAYER.variance.R`` ... for a layer), if present.

    Mitsuba 3 writes no variance channel of its own: its ``moment`` integrator adds channels
    ``m2_<name>.X/Y/Z``, the film's average of each sample's *square*, per CIE XYZ channel (raw
    second moments, not variances). m2 - mean^2 is one sample's variance of X, Y or Z, but an
    RGB variance needs the covariances between X, Y and Z, which it does not record: those
    channels are not read (``has_moments`` says they were there).

    InputError, naming the file: not an OpenEXR file, a crop of a larger frame, no colour
    channels (or a partial set), CIE XYZ instead of RGB, a partial variance set, or a value
    that is not finite (a variance that is negative) at some pixel.
    """
    path = str(path)
    spec, file_format, data = _read_pixels(path)
    if file_format != "openexr":
        raise InputError(f"is a {file_format} image, not an OpenEXR file (a reference holds linear "
                         "floats)", path)
    if (spec.x, spec.y, spec.width, spec.height) != (spec.full_x, spec.full_y, spec.full_width,
                                                     spec.full_height):
        raise InputError(f"holds a {spec.width}x{spec.height} crop of a {spec.full_width}x{spec.full_height} "
                         "frame (its data window is not its display window): a reference is a whole frame",
                         path)
    names = list(spec.channelnames)
    prefix = _colour_prefix(names, layer, path)
    colour = _colour_channels(names, prefix, path)
    if colour is None:
        raise InputError(f"no channels {prefix}R, {prefix}G, {prefix}B (nor a gray {prefix}Y) "
                         f"(has {', '.join(names)})", path)
    gray = colour[0] == colour[1]
    found = [_channel(names, f"{prefix}{VARIANCE_LAYER}.{c}", path) for c in ("Y" if gray else "RGB")]
    present = [name for name in found if name is not None]
    if present and len(present) != len(found):
        wanted = ", ".join(f"{prefix}{VARIANCE_LAYER}.{c}" for c in ("Y" if gray else "RGB"))
        raise InputError(f"has variance channel(s) {', '.join(present)} but not all of {wanted}", path)
    variance_channels = (tuple(present * 3) if gray else tuple(present)) if present else None
    mean = np.ascontiguousarray(data[:, [names.index(c) for c in colour]])
    bad = ~np.all(np.isfinite(mean), axis=1)
    if bad.any():
        raise InputError(f"{', '.join(dict.fromkeys(colour))} is not a finite number at "
                         f"{_pixel(bad, spec.width)}: {mean[np.argmax(bad)].tolist()}", path)
    variance = None
    if variance_channels is not None:
        variance = np.ascontiguousarray(data[:, [names.index(c) for c in variance_channels]])
        bad = ~np.all(np.isfinite(variance) & (variance >= 0.0), axis=1)
        if bad.any():
            raise InputError(f"{', '.join(dict.fromkeys(variance_channels))} is not a finite non-negative "
                             f"number at {_pixel(bad, spec.width)}: {variance[np.argmax(bad)].tolist()}",
                             path)
    return ExternalImage(spec.width, spec.height, mean, variance, colour, variance_channels,
                         any(name.startswith(MOMENT_PREFIX) for name in names))


def _channel(names: list[str], wanted: str, path: str) -> str | None:
    """The channel named ``wanted``, or else the one that differs from it only in case; None if
    there is none. InputError where several differ from it only in case."""
    if wanted in names:
        return wanted
    matches = [name for name in names if name.lower() == wanted.lower()]
    if len(matches) > 1:
        raise InputError(f"channels {', '.join(matches)} differ only in case: which is {wanted} is "
                         "not clear", path)
    return matches[0] if matches else None


def _colour_channels(names: list[str], prefix: str, path: str) -> tuple[str, str, str] | None:
    """The channels of the colour whose names start with ``prefix`` (``""`` or ``"LAYER."``):
    R, G, B, or a gray Y three times; None if there are neither. InputError for a partial
    R, G, B set, or X, Y, Z (CIE XYZ, which is not RGB)."""
    rgb = [_channel(names, prefix + c, path) for c in "RGB"]
    if all(rgb):
        return rgb[0], rgb[1], rgb[2]
    if any(rgb):
        missing = [prefix + c for c, name in zip("RGB", rgb, strict=True) if name is None]
        raise InputError(f"missing channel(s) {', '.join(missing)} (has {', '.join(names)})", path)
    x, y, z = (_channel(names, prefix + c, path) for c in "XYZ")
    if y and (x or z):
        raise InputError(f"holds CIE XYZ (channels {prefix}X, {prefix}Y, {prefix}Z), not RGB: write it as "
                         "RGB (Mitsuba: hdrfilm's pixel_format rgb)", path)
    return (y, y, y) if y else None


def _colour_prefix(names: list[str], layer: str | None, path: str) -> str:
    """Where the colour channels are: ``"LAYER."`` for a named layer, ``""`` for plain channels,
    else the file's one RGB layer (layers ``variance`` and ``LAYER.variance`` are variances, not
    colours). InputError for several RGB layers and none named."""
    if layer is not None:
        return f"{layer}."
    if _colour_channels(names, "", path) is not None:
        return ""
    components: dict[str, set[str]] = {}
    for name in names:
        head, dot, last = name.rpartition(".")
        if dot and last.upper() in ("R", "G", "B"):
            components.setdefault(head, set()).add(last.upper())
    layers = [head for head, found in components.items()
              if found == {"R", "G", "B"} and head.rpartition(".")[2].lower() != VARIANCE_LAYER]
    if len(layers) > 1:
        raise InputError(f"no plain R, G, B channels but {len(layers)} RGB layers ({', '.join(layers)}): "
                         "name the one to compare with (--reference-layer)", path)
    return f"{layers[0]}." if layers else ""


def _error_text(source) -> str:
    """OpenImageIO's pending error of ``source`` (the module or an image object), taken (so that
    OpenImageIO does not print it again at exit) and made one printable line: a damaged header
    can put bytes that are not UTF-8 into the message, which the binding fails to decode."""
    try:
        text = source.geterror()
    except UnicodeDecodeError:
        return "the file's header is damaged (its error message is not text)"
    return " ".join(str(text).split())


def _sample_count(value, path: str) -> int:
    """The header's ``tracer:spp`` as a count, or InputError naming it."""
    try:
        count = int(value)
    except (TypeError, ValueError, OverflowError):
        count = -1
    if isinstance(value, float) and value != count or not 0 <= count <= MAX_COUNT:
        raise InputError(f"header attribute {SPP_ATTRIBUTE} = {value!r} is not a sample count", path)
    return count


def _pixel(bad: np.ndarray, width: int) -> str:
    """``pixel (x, y)`` of the first true entry of a per-pixel mask, and how many there are."""
    first = int(np.argmax(bad))
    more = int(bad.sum()) - 1
    return f"pixel ({first % width}, {first // width})" + (f" and {more} more" if more else "")


def _means_are_half(spec) -> bool:
    import OpenImageIO as oiio

    formats = list(spec.channelformats) or [spec.format] * spec.nchannels
    return formats[list(spec.channelnames).index("R")] == oiio.HALF


def exr_is_half(path: str | os.PathLike[str]) -> bool:
    """Whether an EXR stores its means (R, G, B) as 16-bit floats (merges of half references stay half)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"cannot read image: {_error_text(oiio)}", str(path))
    try:
        return _means_are_half(inp.spec())
    finally:
        inp.close()


def to_srgb8(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB ``(H, W, 3)`` -> 8-bit sRGB: exposure (stops), the sRGB curve, rounding."""
    x = np.clip(np.nan_to_num(image * 2.0**exposure, nan=0.0), 0.0, 1.0)
    # sRGB transfer function (IEC 61966-2-1).
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.rint(srgb * 255.0).astype(np.uint8)


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
    atomic_write(path, lambda tmp: _write(tmp, spec, pixels))


def _write(path: str, spec: Any, pixels: np.ndarray) -> None:
    """Write ``pixels`` with ``spec`` to ``path``; any error, at open, write or close, raises."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(path)
    if out is None:
        raise InputError(f"cannot write images of this type: {_error_text(oiio)}", path)
    ok = out.open(path, spec) and out.write_image(pixels)
    error = _error_text(out)
    closed = out.close()
    if not ok:
        raise InputError(f"cannot write: {error}", path)
    if not closed:
        raise InputError(f"cannot write: {_error_text(out) or 'error while closing the file'}", path)
