"""Image files as texture texels, through OpenImageIO (PNG, JPEG, EXR, HDR, TIFF, ...).

Values are made linear as Mitsuba 3's ``bitmap`` makes them (src/textures/bitmap.cpp): an
image of integer channels (8 or 16 bits, as PNG and JPEG store them) is sRGB-encoded and decoded
with the sRGB curve (IEC 61966-2-1), unless ``raw``; an image of float channels (EXR, HDR) is
linear already. One channel (grey) is used for all three; an alpha channel is dropped. Mitsuba
keeps 8-bit texels encoded and decodes each fetched texel before it interpolates; decoding
every texel once here gives the same values.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..errors import InputError

# More texels than this (about 1.5 GiB as float32 RGB) are refused before they are read.
MAX_TEXELS = 2**27


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB decoding curve on values in [0, 1]."""
    return np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)


def read_texels(path: Path, raw: bool, where: str, key: str | None = None) -> np.ndarray:
    """(H, W, 3) float32 linear texels of the image ``path``, row 0 its top. Raises InputError
    naming ``where`` and ``key`` (the scene file and key that name the image) for a file that
    cannot be used."""
    import OpenImageIO as oiio

    if not path.is_file():
        raise InputError(f"texture image not found: {path}", where, key)
    with _native_stderr_held() as held:
        try:
            return _decode(oiio, path, raw, where, key)
        except InputError:
            held.drop = True  # the error says it in one line: libpng's own lines are dropped
            raise


class _Held:
    """What C libraries wrote to stderr inside ``_native_stderr_held``: ``drop`` discards it."""

    drop = False


@contextlib.contextmanager
def _native_stderr_held():
    """Hold what C code (libpng prints "libpng error: ..." itself) writes to file descriptor 2,
    and write it out afterwards unless the caller set ``drop``: a refused image then gives the
    one line of its InputError, and a warning on an image that is read is still shown."""
    held = _Held()
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable stderr: nothing to hold
        yield held
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield held
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read()
            if text and not held.drop:
                sys.stderr.write(text.decode(errors="replace"))


def _decode(oiio, path: Path, raw: bool, where: str, key: str | None) -> np.ndarray:
    """``read_texels`` once the file exists, with its stderr held."""
    image = oiio.ImageInput.open(str(path))
    if image is None:
        reason = _first_line(oiio.geterror()) or "unknown format"
        raise InputError(f"cannot read texture image {path}: {reason}", where, key)
    try:
        spec = image.spec()
        width, height, channels = spec.width, spec.height, spec.nchannels
        if width <= 0 or height <= 0 or channels <= 0:
            raise InputError(f"texture image {path} has no pixels", where, key)
        if width * height > MAX_TEXELS:
            raise InputError(f"texture image {path} is {width}x{height}, more than {MAX_TEXELS} texels",
                             where, key)
        integer = spec.format.basetype in (oiio.UINT8, oiio.INT8, oiio.UINT16, oiio.INT16)
        pixels = image.read_image(0, 0, 0, channels, oiio.FLOAT)
        if pixels is None:
            reason = _first_line(image.geterror()) or "unknown error"
            raise InputError(f"cannot read texture image {path}: {reason}", where, key)
    finally:
        image.close()
    pixels = np.asarray(pixels, dtype=np.float64).reshape(height, width, channels)
    colour = pixels[..., :1].repeat(3, axis=2) if channels < 3 else pixels[..., :3]
    if not np.all(np.isfinite(colour)):
        raise InputError(f"texture image {path} has NaN or infinite texels", where, key)
    if integer and not raw:
        colour = srgb_to_linear(np.clip(colour, 0.0, 1.0))
    return np.ascontiguousarray(colour, dtype=np.float32)


def _first_line(text: str) -> str:
    """OpenImageIO's first line of an error (libpng repeats it in the lines after)."""
    return next((line.strip() for line in text.splitlines() if line.strip()), "")
