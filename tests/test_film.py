"""The film's statistics and files: Welford/Chan merges and the EXR contract."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from tracer.errors import InputError
from tracer.film import Film
from tracer.imagefiles import CHANNELS, read_exr, write_exr, write_png
from tracer.record import RenderRecord


def _random_film(rng, width=5, height=3, k=7, offset=0.0) -> tuple[Film, np.ndarray]:
    samples = rng.normal(offset, 2.0, size=(width * height, k, 3))
    film = Film(width, height)
    film.add_block(0, samples)
    return film, samples


def test_merge_equals_pooled_statistics():
    """Merging films (in blocks of different sizes) gives the count, mean and unbiased variance
    of the pooled samples, to float64 rounding (1e-12 relative): Chan's formula is exact."""
    rng = np.random.default_rng(0)
    a, sa = _random_film(rng, k=32, offset=1.0)
    b, sb = _random_film(rng, k=32, offset=-3.0)
    c = Film(5, 3)
    c.add_block(0, sb[:, :5])
    c.add_block(0, sb[:, 5:])
    a.merge(c)
    pooled = np.concatenate([sa, sb], axis=1)
    assert np.all(a.count == 64)
    np.testing.assert_allclose(a.mean, pooled.mean(axis=1), rtol=1e-12)
    np.testing.assert_allclose(a.variance(), pooled.var(axis=1, ddof=1), rtol=1e-12)


def test_partial_blocks_track_per_pixel_counts():
    """Blocks that cover part of the image leave per-pixel counts that differ; spp reports the
    smallest, and the other pixels keep all their samples."""
    film = Film(4, 1)
    film.add_block(0, np.ones((4, 2, 3)))
    film.add_block(1, np.full((2, 3, 3), 2.0))
    assert film.count.tolist() == [2, 5, 5, 2]
    assert film.spp == 2
    np.testing.assert_allclose(film.mean[1], (2 * 1.0 + 3 * 2.0) / 5)


def test_exr_round_trip(tmp_path):
    """Write and read back: channel names, float32 values of mean and variance, the whole render
    record (every field, so a field the writer or reader forgot fails here)."""
    rng = np.random.default_rng(1)
    film, _ = _random_film(rng, width=6, height=4, k=9)
    film.record = RenderRecord(strategy="mis", heuristic="power", light_samples=2, bsdf_samples=3,
                               one_sample=True, light_selection="uniform", sampler="independent",
                               samples=((5, 4, 13), (2**40, 0, 9)), seconds=1.5, scene="x.toml",
                               scene_digest="0f" * 32, version="0.1")
    path = tmp_path / "out.exr"
    write_exr(path, film)

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    inp.close()
    assert tuple(spec.channelnames) == CHANNELS
    assert spec.format == oiio.FLOAT
    assert spec.getattribute("compression") == "zip"
    assert spec.getattribute("tracer:spp") == 9

    back = read_exr(path)
    assert (back.width, back.height) == (6, 4)
    assert np.all(back.count == 9)
    np.testing.assert_allclose(back.mean, film.mean.astype(np.float32), rtol=1e-7)
    np.testing.assert_allclose(back.variance(), film.variance().astype(np.float32), rtol=1e-6)
    assert back.record == film.record
    # No temporary files are left beside the output.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]


def test_exr_with_uneven_counts_keeps_them(tmp_path):
    """An interrupted render (uneven counts) writes a 'samples' channel and reads back exactly."""
    film = Film(3, 1)
    film.add_block(0, np.ones((3, 2, 3)))
    film.add_block(0, np.ones((1, 1, 3)))
    write_exr(tmp_path / "a.exr", film)
    back = read_exr(tmp_path / "a.exr")
    assert back.count.tolist() == [3, 2, 2]


def test_merge_refuses_other_resolution():
    with pytest.raises(InputError, match="cannot merge"):
        Film(2, 2).merge(Film(3, 2))


def test_png_preview(tmp_path):
    """The preview is 8-bit RGB of the film's size; 0.5 linear maps to sRGB 188."""
    film = Film(2, 2)
    film.add_block(0, np.full((4, 1, 3), 0.5))
    write_png(tmp_path / "p.png", film.image())
    buf = oiio.ImageBuf(str(tmp_path / "p.png"))
    assert (buf.spec().width, buf.spec().height, buf.spec().nchannels) == (2, 2, 3)
    assert buf.spec().format == oiio.UINT8
    assert round(buf.get_pixels(oiio.FLOAT)[0, 0, 0] * 255) == 188


def _write_raw_exr(path, mean, variance, attributes, count=None):
    """An EXR in the render layout written straight through OpenImageIO, so that tests can
    damage what tracer's own writer never would."""
    planes = [mean, variance] + ([count[:, None]] if count is not None else [])
    pixels = np.ascontiguousarray(np.concatenate(planes, axis=1), dtype=np.float32).reshape(1, len(mean), -1)
    names = list(CHANNELS) + (["samples"] if count is not None else [])
    spec = oiio.ImageSpec(len(mean), 1, len(names), "float")
    spec.channelnames = tuple(names)
    for key, value in attributes.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels)
    out.close()


GOOD_MEAN, GOOD_VAR = np.ones((4, 3)), np.full((4, 3), 0.5)
DAMAGED = {
    "NaN mean": (np.where(np.arange(12).reshape(4, 3) == 7, np.nan, 1.0), GOOD_VAR, {"tracer:spp": 4}, None,
                 "mean (R, G, B) is not a finite number at pixel (2, 0)"),
    "negative variance": (GOOD_MEAN, -GOOD_VAR, {"tracer:spp": 4}, None,
                          "variance is not a finite non-negative"),
    "negative spp": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": -5}, None, "tracer:spp = -5 is not a sample count"),
    "string spp": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": "many"}, None, "tracer:spp = 'many'"),
    "string seed": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:seed": "abc"}, None, "tracer:seed"),
    "NaN samples channel": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4}, np.array([4.0, np.nan, 4.0, 4.0]),
                            "channel 'samples' is not a sample count at pixel (1, 0)"),
    "sample ranges not ranges": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:samples": "1:0-3;2"}, None,
                                 "tracer:samples = '1:0-3;2' is not a valid samples"),
    "sample ranges that overlap": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:samples": "1:0-3,1:2-5"},
                                   None, "seed 1: sample indices 0-3 and 2-5 overlap"),
    "sample ranges against the seed": (GOOD_MEAN, GOOD_VAR,
                                       {"tracer:spp": 4, "tracer:samples": "1:0-3", "tracer:seed": 2}, None,
                                       "tracer:samples (1:0-3) and tracer:seed/first_sample/next_sample"),
    "next before first": (GOOD_MEAN, GOOD_VAR,
                          {"tracer:spp": 4, "tracer:seed": 1, "tracer:first_sample": 9,
                           "tracer:next_sample": 3},
                          None, "are not a seed and a sample range"),
    "scene digest not a digest": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:scene_digest": "abc"}, None,
                                  "tracer:scene_digest = 'abc'"),
    "huge samples channel": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4}, np.array([4.0, 1e30, 4.0, 4.0]),
                             "channel 'samples' is not a sample count"),
    # Issue 38.2: a float32 channel counts exactly only up to 2^24 (16777217 is not a float32).
    "samples channel past float32's exact counts": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4},
                                                    np.array([4.0, 16777218.0, 4.0, 4.0]),
                                                    "channel 'samples' is not a sample count"),
    # Issue 38.4: a header held to the bounds of the command line, and cross-checked.
    "light samples past the command line's bound": (GOOD_MEAN, GOOD_VAR,
                                                    {"tracer:spp": 4, "tracer:light_samples": 2147483647},
                                                    None, "tracer:light_samples = 2147483647"),
    "bsdf samples past the bound": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:bsdf_samples": "1000001"},
                                    None, "tracer:bsdf_samples"),
    "seconds not finite": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:seconds": float("nan")}, None,
                           "tracer:seconds"),
    "one_sample not a flag": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 4, "tracer:one_sample": 7}, None,
                              "tracer:one_sample"),
    "spp 0 over pixels with samples": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 0, "tracer:samples": "0:0-7"}, None,
                                       "pixel (0, 0) and 3 more holds no samples but a mean"),
    "one sample with a variance": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 1}, None,
                                   "holds one sample but a variance"),
    "spp not the smallest count": (GOOD_MEAN, GOOD_VAR, {"tracer:spp": 2}, np.array([4.0, 5.0, 4.0, 4.0]),
                                   "tracer:spp = 2 is not the smallest count of the sample channels, 4"),
}


@pytest.mark.parametrize("case", sorted(DAMAGED))
def test_damaged_render_files_are_refused_with_one_line(case, tmp_path):
    """Every damaged field of a render EXR is refused on read with a message naming the file,
    the field and (for pixel data) the first bad pixel, instead of NaN results or a traceback."""
    mean, variance, attributes, count, words = DAMAGED[case]
    path = tmp_path / "damaged.exr"
    _write_raw_exr(path, mean, variance, attributes, count)
    with pytest.raises(InputError) as info:
        read_exr(path)
    assert words in str(info.value) and "damaged.exr" in str(info.value), str(info.value)


def test_half_reference_of_a_bright_emitter_stays_finite(tmp_path):
    """Means beyond the half-float range (65504: a visible emitter of radiance 1e5) are written
    as 32-bit floats even when half is asked for, so they read back finite and exact."""
    film = Film(2, 1)
    film.add_block(0, np.array([[[1e5, 2.0, 3.0]], [[0.5, 0.5, 0.5]]]))
    write_exr(tmp_path / "ref.exr", film, half=True)
    back = read_exr(tmp_path / "ref.exr")
    assert np.all(np.isfinite(back.mean)) and back.mean[0, 0] == 1e5


def test_damaged_header_bytes_give_one_line_not_a_traceback(tmp_path):
    """Bytes of a good render's header overwritten (with text and with 0xff, at offsets across
    the header): each read either succeeds with finite data or raises InputError naming the
    file in one line. OpenImageIO's messages could span lines, and 0xff in an attribute made
    them undecodable (a UnicodeDecodeError traceback), before its errors were read through one
    guarded helper."""
    rng = np.random.default_rng(2)
    film, _ = _random_film(rng, width=5, height=3, k=4)
    good = tmp_path / "good.exr"
    write_exr(good, film)
    data = good.read_bytes()
    outcomes = {"read": 0, "refused": 0}
    for offset in range(8, 400, 16):
        for fill in (b"x", b"\xff"):
            damaged = tmp_path / "damaged.exr"
            damaged.write_bytes(data[:offset] + fill * 40 + data[offset + 40:])
            try:
                back = read_exr(damaged)
            except InputError as exc:
                assert str(exc).startswith(str(damaged)) and "\n" not in str(exc)
                outcomes["refused"] += 1
            else:
                assert np.all(np.isfinite(back.mean)) and np.all(np.isfinite(back.variance()))
                outcomes["read"] += 1
    assert outcomes["refused"] > 0


def test_counts_past_32_bits_round_trip(tmp_path):
    """tracer:spp of a pool past 2^31 samples (EXR integer attributes are 32-bit: writing it
    raised std::bad_cast) is stored so that it reads back exactly."""
    film = Film(2, 1, np.array([2**31 + 5, 2**31 + 5]), np.ones((2, 3)), np.ones((2, 3)))
    write_exr(tmp_path / "big.exr", film)
    assert read_exr(tmp_path / "big.exr").spp == 2**31 + 5


def test_values_past_float32_are_refused_not_written_as_inf(tmp_path):
    """A mean of 1e20 is a float32 number, its variance (about its square) is not: the write is
    refused with one line naming the channel and pixel, and no file appears (it used to be
    written with inf variances, exit 0)."""
    film = Film(2, 1)
    film.add_block(0, np.array([[[1.0, 1.0, 1.0], [3.0, 1.0, 1.0]], [[1e20, 0.0, 0.0], [-1e20, 0.0, 0.0]]]))
    with pytest.raises(InputError, match=r"channel 'variance.R' at pixel \(1, 0\) exceeds"):
        write_exr(tmp_path / "r.exr", film)
    assert list(tmp_path.iterdir()) == []


def test_counts_past_float32_are_stored_exactly(tmp_path):
    """Issue 38.2: a pool of a 2^24-spp film and one whose pixels hold 7 or 8 samples has counts
    2^24 + 7 and 2^24 + 8, which a float32 channel rounds to the same number (the merge wrote
    16777224 in every pixel and tracer:spp 16777223). They are written as two exact channels and
    read back exactly, as is every count below 2^48."""
    counts = np.array([2**24 + 7, 2**24 + 8, 2**47 + 3, 5])
    film = Film(4, 1, counts, np.ones((4, 3)), np.ones((4, 3)))
    write_exr(tmp_path / "big.exr", film)
    back = read_exr(tmp_path / "big.exr")
    assert back.count.tolist() == counts.tolist() and back.spp == 5
    inp = oiio.ImageInput.open(str(tmp_path / "big.exr"))
    assert {"samples.low", "samples.high"} <= set(inp.spec().channelnames)
    inp.close()


def test_unequal_counts_past_what_the_file_holds_are_refused_before_writing(tmp_path):
    """Past 2^48 unequal counts are not written (nothing appears), with one line that says so."""
    film = Film(2, 1, np.array([2**48, 3]), np.ones((2, 3)), np.ones((2, 3)))
    with pytest.raises(InputError, match="unequal counts are stored exactly up to"):
        write_exr(tmp_path / "r.exr", film)
    assert list(tmp_path.iterdir()) == []


def test_a_pool_past_2_to_the_53_is_refused_before_writing(tmp_path):
    """Issue 38.3: merging two files of 2^53 - 1 spp (other seeds) made a file whose tracer:spp,
    2^54 - 2, tracer then refused to read. The writer now checks everything the reader checks
    before writing: the pool is refused with one line and no file appears."""
    from tracer.film import merge_renders

    def film(seed):
        f = Film(1, 1, np.array([2**53 - 1]), np.ones((1, 3)), np.ones((1, 3)))
        f.record = RenderRecord(strategy="mis", heuristic="power", light_samples=1, bsdf_samples=1,
                                one_sample=False, light_selection="power", light_sampling="area",
                                sampler="independent", samples=((seed, 0, 2**53 - 1),),
                                scene="x.toml", scene_digest="0f" * 32)
        return f

    for path in ("a.exr", "b.exr"):
        write_exr(tmp_path / path, film(len(path) + ord(path[0])))
        assert read_exr(tmp_path / path).spp == 2**53 - 1
    pooled = merge_renders(read_exr(tmp_path / "a.exr"), read_exr(tmp_path / "b.exr"))
    with pytest.raises(InputError, match="more than the 9007199254740992"):
        write_exr(tmp_path / "pool.exr", pooled)
    assert not (tmp_path / "pool.exr").exists()
