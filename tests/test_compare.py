"""References, merges and strategy comparisons: exact statistics, metric formulas, files."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from test_cli import DARK

from tracer import render_loop
from tracer.cli import build_parser, main
from tracer.errors import InputError
from tracer.film import Film, merge_renders
from tracer.imagefiles import read_exr, write_exr
from tracer.render_loop import RenderResult, RenderSettings, render
from tracer.scene import load_scene
from tracer.strategy import CLASSIC_STRATEGIES, Strategy
from tracer.study import compare as compare_mod
from tracer.study import metrics
from tracer.study.compare import Comparison, fit_convergence, time_to_reach

from stats import FAMILY_ALPHA, z_critical

SCENES = Path(__file__).resolve().parent.parent / "tracer" / "scenes"


def test_metric_formulas_on_known_arrays():
    """mse, relmse, variance and efficiency by hand on 2 pixels."""
    reference = np.array([[1.0, 0.0, 2.0], [0.0, 0.0, 0.0]])
    image = np.array([[1.5, 0.1, 2.0], [0.0, -0.2, 0.0]])
    assert metrics.mse(image, reference) == pytest.approx((0.25 + 0.01 + 0.04) / 6)
    expected_rel = (0.25 / 1.01 + 0.01 / 0.01 + 0.04 / 0.01) / 6
    assert metrics.relmse(image, reference) == pytest.approx(expected_rel)
    film = Film(2, 1)
    film.add_block(0, np.array([[[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]], [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]]))
    # Pixel 0: sample variance 2, over 2 samples -> 1; pixel 1: 0. Mean over pixels and channels: 0.5.
    assert metrics.variance(film) == pytest.approx(0.5)
    assert metrics.efficiency(0.5, 4.0) == pytest.approx(0.5)
    assert np.isnan(metrics.efficiency(0.0, 1.0)) and np.isnan(metrics.efficiency(-1e-3, 1.0))


def test_efficiency_ratio_map_signs():
    """A strategy with 4x less squared error at equal time is 2 stops (log2 4) more efficient;
    twice the time halves that advantage; pixels with no error in either are 0."""
    err_a = np.full((6, 6, 3), 1.0)
    err_b = np.full((6, 6, 3), 4.0)
    err_a[:, :3] = err_b[:, :3] = 0.0
    ratio = metrics.efficiency_ratio_map(err_a, 1.0, err_b, 1.0, radius=0)
    assert np.allclose(ratio[:, 3:], 2.0) and np.allclose(ratio[:, :3], 0.0)
    assert np.allclose(metrics.efficiency_ratio_map(err_a, 2.0, err_b, 1.0, radius=0)[:, 3:], 1.0)


def test_convergence_fit_and_time_to_target():
    """On exact 1/spp data the fitted slope is -1 and the time to a target is read off the line."""
    points = [{"spp": s, "seconds": 0.1 * s, "relmse": 1.0 / s} for s in (1, 2, 4, 8, 16, 32)]
    slope, _ = fit_convergence(points, "spp")
    assert slope == pytest.approx(-1.0)
    seconds, extrapolated = time_to_reach(points, 0.1)
    assert seconds == pytest.approx(1.0) and not extrapolated
    seconds, extrapolated = time_to_reach(points, 0.01)
    assert seconds == pytest.approx(10.0) and extrapolated


def _scene():
    return load_scene(SCENES / "cornell.toml", 24, 16)


def test_merge_of_two_32_spp_renders_equals_the_pooled_samples():
    """Sample indices 0-31 and 32-63 merged hold exactly the samples of one 64-spp render (random
    numbers are keyed to seed, pixel and sample index), so count, mean and variance agree to
    float64 rounding, and the merged record spans samples 0-63; through EXR files and
    `tracer merge`, to float32."""
    scene = _scene()
    strategy = Strategy("mis")
    whole = render(scene, strategy, RenderSettings(spp=64, seed=3, threads=2)).film
    halves = [render(scene, strategy, RenderSettings(spp=32, seed=3, threads=2, first_sample=first)).film
              for first in (0, 32)]
    merged = merge_renders(*halves)
    assert np.all(merged.count == 64)
    np.testing.assert_allclose(merged.mean, whole.mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(merged.variance(), whole.variance(), rtol=1e-9, atol=1e-15)
    assert (merged.record.first_sample, merged.record.next_sample) == (0, 64)


def test_merge_command_and_its_refusals(tmp_path, capsys):
    """`tracer merge` adds spp and refuses renders that share random numbers or strategies differ."""
    scene = str(SCENES / "cornell.toml")
    common = ["--width", "12", "--height", "8", "--spp", "4", "--quiet"]
    assert main(["render", scene, "-o", str(tmp_path / "a.exr"), "--seed", "1", *common]) == 0
    assert main(["render", scene, "-o", str(tmp_path / "b.exr"), "--seed", "2", *common]) == 0
    assert main(["render", scene, "-o", str(tmp_path / "l.exr"), "--strategy", "light", *common]) == 0
    assert (
        main(["merge", str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), "-o", str(tmp_path / "ab.exr")]) == 0
    )
    a, b, ab = (read_exr(tmp_path / f"{n}.exr") for n in ("a", "b", "ab"))
    assert ab.spp == 8
    np.testing.assert_allclose(ab.mean, (a.mean + b.mean) / 2, rtol=1e-6, atol=1e-7)
    capsys.readouterr()
    assert (
        main(["merge", str(tmp_path / "a.exr"), str(tmp_path / "a.exr"), "-o", str(tmp_path / "x.exr")]) == 2
    )
    assert "both hold the same samples" in capsys.readouterr().err
    assert (
        main(["merge", str(tmp_path / "a.exr"), str(tmp_path / "l.exr"), "-o", str(tmp_path / "x.exr")]) == 2
    )
    assert "different tracer:strategy" in capsys.readouterr().err


def test_reference_resume_adds_fresh_samples(tmp_path):
    """--resume adds spp with new sample indices; the result equals merging the two parts."""
    scene = str(SCENES / "cornell.toml")
    out = tmp_path / "ref.exr"
    common = ["--width", "12", "--height", "8", "--spp", "4", "--quiet", "-o", str(out)]
    assert main(["reference", scene, *common]) == 0
    first = read_exr(out)
    assert main(["reference", scene, *common, "--resume"]) == 0
    both = read_exr(out)
    assert both.spp == 8
    assert (both.record.first_sample, both.record.next_sample) == (0, 8)
    assert not np.allclose(both.mean, first.mean)
    inp = oiio.ImageInput.open(str(out))
    formats = [str(f) for f in inp.spec().channelformats]
    inp.close()
    # References store the means as half floats, the variances as float (they overflow half).
    assert formats == ["half"] * 3 + ["float"] * 3


def test_equal_time_spends_the_budget(monkeypatch):
    """With a stand-in render whose every spp costs 0.1 s, equal-time mode ends within half a
    spp's time of the budget (the rule that keeps real runs within a few percent)."""

    def fake_render(scene, strategy, settings, film=None, progress=False, estimator=None, learner=None):
        film = film if film is not None else Film(2, 2)
        film.add_block(0, np.ones((4, settings.spp, 3)))
        return RenderResult(film, 0.1 * settings.spp, 4 * settings.spp, 0, False)

    monkeypatch.setattr(render_loop, "render", fake_render)
    reference = Film(2, 2)
    reference.add_block(0, np.ones((4, 1, 3)))
    scene = load_scene(SCENES / "cornell.toml", 2, 2)
    run = Comparison(scene, reference).equal_time(Strategy("light"), 5.0)
    assert abs(run.seconds - 5.0) <= 0.05 + 1e-9 and run.spp == 50


def test_compare_writes_every_file_and_true_numbers(tmp_path):
    """End to end at 24x24: every promised file exists, index.html links only to files that
    exist, every run's EXR carries its render record, metrics.json is strict JSON, and
    MSE/relMSE in it match an independent computation from the EXRs (the reference's variance
    of the pixel value subtracted; as measured in *_uncorrected)."""
    scene = str(SCENES / "veach_mis.toml")
    ref = tmp_path / "ref.exr"
    assert (
        main(
            [
                "reference",
                scene,
                "-o",
                str(ref),
                "--width",
                "24",
                "--height",
                "24",
                "--spp",
                "64",
                "--quiet",
                "--float",
            ]
        )
        == 0
    )
    out = tmp_path / "cmp"
    assert (
        main(
            ["compare", scene, "--reference", str(ref), "--spp", "4", "--out", str(out), "--sweep", "--quiet"]
        )
        == 0
    )
    names = list(CLASSIC_STRATEGIES)  # what compare runs when no strategies are named
    for name in names:
        for suffix in (".exr", ".png", "_relerr.png", "_flip.png"):
            assert (out / f"{name}{suffix}").is_file(), name + suffix
        record = read_exr(out / f"{name}.exr").record
        # Seed 1: the reference holds seed 0's samples, which the comparison must not reuse.
        assert (record.strategy, record.seed, record.first_sample, record.next_sample) == (name, 1, 0, 4)
        assert record.heuristic == ("power" if name == "mis" else "none") and record.seconds > 0
        assert record.sampler and record.scene and record.version
    for file in (
        "grid.png",
        "convergence.png",
        "allocation.png",
        "metrics.json",
        "metrics.csv",
        "index.html",
        "efficiency_bsdf_vs_light.png",
        "efficiency_mis_vs_light.png",
    ):
        assert (out / file).is_file(), file

    page = (out / "index.html").read_text()
    links = re.findall(r'(?:src|href)="([^"]+)"', page)
    assert links and all(not link.startswith(("/", "http")) and (out / link).is_file() for link in links)

    doc = json.loads((out / "metrics.json").read_text(), parse_constant=_no_constants)
    assert doc["mode"]["kind"] == "equal-spp" and [r["strategy"] for r in doc["results"]] == names
    assert {"strategy", "heuristic", "spp", "seconds", "mse", "relmse", "variance", "efficiency"} <= set(
        doc["results"][0]
    )
    assert doc["sweep"] and {p["spp"] for p in doc["sweep"]} == {1, 2, 4}
    assert [(r["light_samples"], r["bsdf_samples"]) for r in doc["allocation"]] == list(
        compare_mod.ALLOCATIONS
    )

    def channels(path):
        buf = oiio.ImageBuf(str(path))
        names_ = list(buf.spec().channelnames)
        px = buf.get_pixels(oiio.FLOAT)
        return px[..., [names_.index(c) for c in "RGB"]].astype(np.float64)

    reference = channels(ref)
    buf = oiio.ImageBuf(str(ref))
    ref_names = list(buf.spec().channelnames)
    ref_var = buf.get_pixels(oiio.FLOAT)[..., [ref_names.index(f"variance.{c}") for c in "RGB"]] / 64.0
    noise = np.mean(ref_var / (reference**2 + 0.01))
    assert doc["reference_noise"]["relmse"] == pytest.approx(noise, rel=1e-5)
    for row in doc["results"]:
        image = channels(out / f"{row['strategy']}.exr")
        squared = (image - reference) ** 2
        assert row["mse_uncorrected"] == pytest.approx(np.mean(squared), rel=1e-5)
        assert row["mse"] == pytest.approx(np.mean(squared - ref_var), rel=1e-4, abs=1e-12)
        assert row["relmse_uncorrected"] == pytest.approx(np.mean(squared / (reference**2 + 0.01)), rel=1e-5)
        assert row["relmse"] == pytest.approx(np.mean((squared - ref_var) / (reference**2 + 0.01)),
                                              rel=1e-4, abs=1e-12)
        if row["relmse"] > 0:
            assert row["efficiency"] == pytest.approx(1.0 / (row["relmse"] * row["seconds"]), rel=1e-9)
        else:
            assert row["efficiency"] is None


def _no_constants(name):
    raise AssertionError(f"metrics.json holds {name}, which is not JSON")


def test_compare_rejects_bad_input(tmp_path, capsys):
    scene = str(SCENES / "cornell.toml")
    assert main(["compare", scene, "--reference", str(tmp_path / "none.exr"), "--spp", "1"]) == 2
    assert "none.exr: no such file" in capsys.readouterr().err
    ref = tmp_path / "r.exr"
    assert (
        main(["reference", scene, "-o", str(ref), "--width", "8", "--height", "8", "--spp", "2", "--quiet"])
        == 0
    )
    assert main(["compare", scene, "--reference", str(ref), "--spp", "1", "--strategies", "mis,fast"]) == 2
    assert "unknown strategy 'fast'" in capsys.readouterr().err
    assert main(["compare", scene, "--reference", str(ref), "--spp", "1", "--crop", "4,4,8,8"]) == 2
    assert "leaves the 8x8 image" in capsys.readouterr().err


def test_compare_refuses_a_reference_of_another_scene_or_frame(tmp_path, capsys):
    """A reference of cornell given for veach_mis (same 16x16 size) is refused naming
    tracer:scene_digest (it was accepted: relMSE 13-95, exit 0); a cornell reference of another
    aspect ratio (16x8 for a square camera) is refused instead of rendering a squashed image;
    one of the same frame at another size is used, with a note."""
    cornell, veach = str(SCENES / "cornell.toml"), str(SCENES / "veach_mis.toml")
    for name, size in (("square", ("16", "16")), ("wide", ("16", "8"))):
        assert main(["reference", cornell, "-o", str(tmp_path / f"{name}.exr"), "--width", size[0],
                     "--height", size[1], "--spp", "2", "--quiet"]) == 0
    out = tmp_path / "cmp"
    common = ["--spp", "1", "--strategies", "light", "--out", str(out)]
    assert main(["compare", veach, "--reference", str(tmp_path / "square.exr"), *common, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "square.exr: tracer:scene_digest" in err and len(err.strip().splitlines()) == 1, err
    assert main(["compare", cornell, "--reference", str(tmp_path / "wide.exr"), *common, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "wide.exr: the reference is 16x8, the scene's camera 256x256" in err, err
    assert not out.exists()
    assert main(["compare", cornell, "--reference", str(tmp_path / "square.exr"), *common]) == 0
    assert "rendering at the reference's 16x16, not the scene's 256x256" in capsys.readouterr().err


def test_reference_noise_correction_is_unbiased():
    """Synthetic pixels with known truth mu: image I = mu + N(0, 0.2^2), reference R = mean of
    n = 4 draws of mu + N(0, 1), its variance of the mean estimated from those draws. The
    corrected MSE (mean of (I - R)^2 - s_R^2 / n) estimates E[(I - mu)^2] = 0.04 without bias,
    while the uncorrected one is 0.04 + 0.25. Compared with a z-test at 5 standard errors
    (the per-pixel terms are i.i.d. with finite variance, 200,000 of them: the mean is normal
    to far better than needed); the uncorrected value is 0.25 / SE ~ 200 SE away, so the test
    fails whenever the correction is missing."""
    rng = np.random.default_rng(7)
    pixels, n = 200_000, 4
    mu = rng.uniform(0.0, 2.0, size=(pixels, 3))
    image = mu + rng.normal(0.0, 0.2, size=mu.shape)
    draws = mu[None] + rng.normal(0.0, 1.0, size=(n,) + mu.shape)
    reference = draws.mean(axis=0)
    reference_variance = draws.var(axis=0, ddof=1) / n
    terms = (image - reference) ** 2 - reference_variance
    standard_error = terms.std(ddof=1) / np.sqrt(terms.size)
    corrected = metrics.mse(image, reference, reference_variance)
    assert corrected == pytest.approx(terms.mean())
    assert abs(corrected - 0.04) < 5 * standard_error
    assert abs(metrics.mse(image, reference) - 0.04) > 50 * standard_error


def test_undefined_numbers_are_null_in_json_and_n_a_in_tables(tmp_path, capsys):
    """A scene without lights: every image is exactly black, relMSE 0, efficiency undefined.
    metrics.json must stay strict JSON (null, not NaN or Infinity, which it held before), the
    CSV cell empty, and the table on stderr and in index.html say n/a."""
    scene = tmp_path / "dark.toml"
    scene.write_text(DARK)  # test_cli.GOOD with nothing emitting
    ref, out = tmp_path / "ref.exr", tmp_path / "cmp"
    assert main(["reference", str(scene), "-o", str(ref), "--spp", "2", "--quiet"]) == 0
    assert main(["compare", str(scene), "--reference", str(ref), "--spp", "1", "--strategies", "light,mis",
                 "--out", str(out), "--sweep"]) == 0
    assert re.search(r"light\s+1\s+\S+\s+0\s+n/a", capsys.readouterr().err)
    text = (out / "metrics.json").read_text()
    doc = json.loads(text, parse_constant=_no_constants)
    assert [r["efficiency"] for r in doc["results"]] == [None, None]
    assert all(r["relmse"] == 0.0 for r in doc["results"])
    header, first = (out / "metrics.csv").read_text().splitlines()[:2]
    assert first.split(",")[header.split(",").index("efficiency")] == ""
    assert "<td>n/a</td>" in (out / "index.html").read_text()


def test_an_interrupted_comparison_writes_no_results(tmp_path, monkeypatch, capsys):
    """Ctrl-C during an equal-time comparison (injected: the third render reports that it was
    interrupted, as render() does after a signal) stops it: exit 130, a line saying so, and no
    metrics or report written. Before, the interrupted chunk was counted and the comparison ran
    on to report an equal-time result."""
    scene = str(SCENES / "cornell.toml")
    ref, out = tmp_path / "ref.exr", tmp_path / "cmp"
    assert main(["reference", scene, "-o", str(ref), "--width", "8", "--height", "8", "--spp", "2",
                 "--quiet"]) == 0
    calls = []
    real_render = render_loop.render

    def render_interrupted_on_third_call(*args, **kwargs):
        result = real_render(*args, **kwargs)
        calls.append(1)
        if len(calls) == 3:
            result.interrupted = True
        return result

    monkeypatch.setattr(render_loop, "render", render_interrupted_on_third_call)
    capsys.readouterr()
    assert main(["compare", scene, "--reference", str(ref), "--time", "0.5", "--out", str(out),
                 "--quiet"]) == 130
    assert "interrupted: the comparison is incomplete, nothing written" in capsys.readouterr().err
    assert not out.exists() and len(calls) == 3


def test_compare_draws_samples_independent_of_the_reference(tmp_path, capsys):
    """The reference holds seed 0's samples 0-63; compare's renders must not reuse them (its mis
    run would be the reference's first N samples exactly, and the noise correction would then
    favour it by twice the reference's variance). By default compare picks seed 1; --seed 0 is
    refused with one line naming the reference and the seed."""
    scene = str(SCENES / "cornell.toml")
    ref, out = tmp_path / "ref.exr", tmp_path / "cmp"
    assert main(["reference", scene, "-o", str(ref), "--width", "8", "--height", "8", "--spp", "64",
                 "--quiet"]) == 0
    capsys.readouterr()
    assert main(["compare", scene, "--reference", str(ref), "--spp", "4", "--strategies", "mis",
                 "--out", str(out), "--quiet", "--seed", "0"]) == 2
    err = capsys.readouterr().err
    assert "ref.exr: --seed 0: the reference holds samples of seed 0" in err and len(err.splitlines()) == 1
    assert main(["compare", scene, "--reference", str(ref), "--spp", "4", "--strategies", "mis",
                 "--out", str(out), "--quiet"]) == 0
    assert read_exr(out / "mis.exr").record.samples == ((1, 0, 4),)
    reference = read_exr(ref)
    assert not np.array_equal(read_exr(out / "mis.exr").mean, reference.mean)


def test_compare_refuses_references_it_cannot_measure_with(tmp_path, capsys):
    """A reference with pixels of 0 samples (a first pass cut short) or only 1 (no variance) is
    refused: it used to be accepted (reference_spp 0, relMSE 82 where a good reference gives
    0.004). A 3x2 reference for a square camera is another frame (the aspect check allowed one
    pixel of slack per pixel of size: 3x2 passed). An output folder that cannot be made is
    refused before any rendering. Each: exit 2, one line."""
    scene = str(SCENES / "cornell.toml")
    good = tmp_path / "good.exr"
    assert main(["reference", scene, "-o", str(good), "--width", "8", "--height", "8", "--spp", "2",
                 "--quiet"]) == 0
    film = read_exr(good)
    holes = Film(8, 8)
    holes.add_block(0, np.ones((32, 2, 3)))  # half the pixels rendered
    holes.record = film.record
    write_exr(tmp_path / "holes.exr", holes)
    assert main(["reference", scene, "-o", str(tmp_path / "one.exr"), "--width", "8", "--height", "8",
                 "--spp", "1", "--quiet"]) == 0
    assert main(["reference", scene, "-o", str(tmp_path / "small.exr"), "--width", "3", "--height", "2",
                 "--spp", "2", "--quiet"]) == 0
    capsys.readouterr()
    for name, words in (("holes", "the reference has pixels with 0 sample(s)"),
                        ("one", "the reference has pixels with 1 sample(s)"),
                        ("small", "the reference is 3x2, the scene's camera 256x256")):
        assert main(["compare", scene, "--reference", str(tmp_path / f"{name}.exr"), "--spp", "1",
                     "--out", str(tmp_path / "cmp"), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert f"{name}.exr: {words}" in err and len(err.strip().splitlines()) == 1, err
    assert main(["compare", scene, "--reference", str(good), "--spp", "1", "--out", "/proc/tracer/x",
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "/proc/tracer/x: cannot write into this folder" in err and len(err.strip().splitlines()) == 1, err


def test_insets_fit_images_narrower_than_a_window():
    """A 1x8 image (a legal camera of width 1) gets inset windows inside it: the window size
    was at least 8 pixels whatever the image, and the outline then indexed past its edge."""
    from tracer.study.report import pick_insets

    reference = Film(1, 8)
    reference.add_block(0, np.ones((8, 2, 3)))
    run = compare_mod.Run(Strategy("mis"), reference.copy(), 1.0)
    for x, y, w, h in pick_insets([run, run], reference):
        assert 0 <= x and x + w <= 1 and 0 <= y and y + h <= 8 and w >= 1 and h >= 1


# ---------------------------------------------------------------------------------------------
# Sweeps over seeds, times to target, the CPU clock, the grid and the figure formats (issue 12)


def _synthetic_sweep(rng, draw, seeds: int, pixels: int, max_spp: int) -> compare_mod.SweepCurve:
    """A progressive sweep of ``seeds`` runs: per-sample values ``draw(rng, shape)`` (mean 1)
    in ``pixels`` pixels, and the squared error of the running means at spp 1, 2, 4, ...,
    averaged over the pixels; seconds = spp. Its expected relMSE is Var(sample) / spp."""
    spp = 2 ** np.arange(int(np.log2(max_spp)) + 1)
    samples = draw(rng, (seeds, pixels, max_spp))
    running = np.cumsum(samples, axis=2)[:, :, spp - 1] / spp
    relmse = ((running - 1.0) ** 2).mean(axis=1)
    return compare_mod.SweepCurve("synthetic", list(range(seeds)), spp,
                                  np.tile(spp.astype(float), (seeds, 1)), relmse)


def test_sweep_seeds_are_distinct_and_none_held_by_the_reference(capsys):
    """The sweep's seeds against a reference that holds seeds 0 and 2: by default the smallest
    three it does not hold (1, 3, 4); from --seed 3 that seed and the next free ones; --seed 2
    is refused. Fails if a sweep seed repeats or reuses the reference's random numbers (its
    errors would then be correlated with the reference's, and the correction would favour it)."""
    reference = Film(2, 2)
    reference.add_block(0, np.ones((4, 2, 3)))
    reference.record = dataclasses.replace(reference.record, samples=((0, 0, 64), (2, 0, 64)))
    assert compare_mod.independent_seeds(reference, None, 3, "ref.exr") == [1, 3, 4]
    assert compare_mod.independent_seeds(reference, 3, 3, "ref.exr") == [3, 4, 5]
    assert compare_mod.independent_seed(reference, None, "ref.exr") == 1
    with pytest.raises(InputError, match="the reference holds samples of seed 2"):
        compare_mod.independent_seeds(reference, 2, 3, "ref.exr")


def test_slope_interval_covers_minus_one_at_its_confidence():
    """Light-tailed sweeps (normal samples: 8 seeds of 32 pixels up to 64 spp), whose expected
    relMSE falls exactly as 1/spp: over 400 independent sweeps the jackknife interval of the
    fitted slope must hold -1 as often as its confidence says, within the binomial spread
    (a two-sided z-test at 1%). Fails if the interval is too narrow (a normal quantile for
    Student's t with 7 degrees of freedom covers about 91%; the seeds' spread without the
    jackknife's (S-1)/S x sum far less) or too wide."""
    rng = np.random.default_rng(12)
    repeats = 400

    def normal(rng, shape):
        return rng.normal(1.0, 1.0, shape)

    covered = 0
    for _ in range(repeats):
        fit = compare_mod.fit_sweep(_synthetic_sweep(rng, normal, 8, 32, 64), "spp")
        covered += fit.low <= -1.0 <= fit.high
    expected = repeats * compare_mod.CONFIDENCE
    spread = np.sqrt(repeats * compare_mod.CONFIDENCE * (1.0 - compare_mod.CONFIDENCE))
    assert abs(covered - expected) <= z_critical(1) * spread, (covered, expected)


def test_heavy_tailed_single_runs_fall_slower_than_their_expectation():
    """The chart's explanation, on a firefly estimator (a sample is 512 with probability 1/512,
    else 0: mean 1, relMSE expected exactly 511/spp): (a) single runs of 16 pixels fit slopes
    well above -1 on average (one-sided z-test on the mean of 2000 runs' slopes), because few
    of them draw a firefly at low spp; (b) the mean over those 2000 runs as seeds still falls
    as 1/spp (its 99% interval holds -1). Fails if the fit leaves out or mis-weights points so
    that single runs look like -1, or if the mean curve's slope or interval is wrong."""
    rng = np.random.default_rng(5)
    odds = 512

    def firefly(rng, shape):
        return (rng.integers(0, odds, shape) == 0) * float(odds)

    curve = _synthetic_sweep(rng, firefly, 2000, 16, 256)
    runs = np.arange(len(curve.seeds))
    single = np.array([compare_mod.fit_convergence(curve.mean_points(runs == i), "spp")[0] for i in runs])
    single = single[np.isfinite(single)]
    se = single.std(ddof=1) / np.sqrt(len(single))
    assert single.mean() > -1.0 + z_critical(1, sides=1) * se, (single.mean(), se)
    fit = compare_mod.fit_sweep(curve, "spp", confidence=1.0 - FAMILY_ALPHA)
    assert fit.low <= -1.0 <= fit.high, fit


def test_time_to_target_is_given_only_where_the_sweep_supports_it():
    """On sweeps of exact power laws (relMSE = c/spp, 0.01 s per spp; 4 seeds that differ by a
    constant factor, so that the mean curve is exact): a target inside the sweep is
    interpolated to the exact time, with an interval around it; one 2x beyond the sweep's end
    is extrapolated exactly along the fitted line at the last doubling's cost; one beyond
    EXTRAPOLATION_LIMIT x the longest time, a flat curve (slope 0) and a single seed give no
    time but a reason; a target the first point already meets is 'at most' that point's time.
    Fails if times are reported where the fit does not support them, or are off the line."""
    spp = 2 ** np.arange(9)
    per_spp, c = 0.01, 2.0
    factors = np.array([0.8, 1.0, 1.2, 1.0])[:, None]

    def curve(relmse, seeds=4):
        return compare_mod.SweepCurve("s", list(range(seeds)), spp, np.tile(per_spp * spp, (seeds, 1)),
                                      relmse[:seeds])

    power = curve(factors * c / spp)
    longest = per_spp * spp[-1]
    inside = compare_mod.time_to_target(power, c / 40.0)
    assert inside["how"] == "interpolated" and inside["seconds"] == pytest.approx(per_spp * 40.0)
    assert inside["low"] < inside["seconds"] < inside["high"]
    beyond = compare_mod.time_to_target(power, c / (2 * spp[-1]))
    assert beyond["how"] == "extrapolated" and beyond["seconds"] == pytest.approx(2 * longest)
    too_far = compare_mod.time_to_target(power, c / (2 * compare_mod.EXTRAPOLATION_LIMIT * spp[-1]))
    assert too_far["seconds"] is None and "beyond" in too_far["note"]
    flat = compare_mod.time_to_target(curve(factors * c + 0.0 * spp), c / 10.0)
    assert flat["seconds"] is None and "does not exclude 0" in flat["note"]
    alone = compare_mod.time_to_target(curve(factors * c / spp, seeds=1), c / (2 * spp[-1]))
    assert alone["seconds"] is None and "one seed" in alone["note"]
    first = compare_mod.time_to_target(power, 2.0 * c)
    assert first["how"] == "at most" and first["seconds"] == pytest.approx(per_spp)


def test_cpu_clock_budgets_process_time(monkeypatch):
    """With a stand-in render whose every spp takes 0.1 s of wall time and 0.2 s of process CPU
    time (two busy threads), an equal-time run on the CPU clock spends its budget in CPU
    seconds: half the spp of the wall clock, its wall seconds half its CPU seconds, and the
    warm-up sample that loads the kernels not charged. Fails if the clock is ignored (twice the
    spp) or the warm-up is counted (one spp fewer, or the CPU seconds off by its cost)."""
    wall_per_spp, cpu_per_spp, budget = 0.1, 0.2, 5.0
    cpu = [0.0]

    def fake_render(scene, strategy, settings, film=None, progress=False, estimator=None, learner=None):
        film = film if film is not None else Film(2, 2)
        film.add_block(0, np.ones((4, settings.spp, 3)))
        cpu[0] += cpu_per_spp * settings.spp
        return RenderResult(film, wall_per_spp * settings.spp, 4 * settings.spp, 0, False)

    monkeypatch.setattr(render_loop, "render", fake_render)
    monkeypatch.setattr(compare_mod.time, "process_time", lambda: cpu[0])
    reference = Film(2, 2)
    reference.add_block(0, np.ones((4, 1, 3)))
    scene = load_scene(SCENES / "cornell.toml", 2, 2)
    run = Comparison(scene, reference, clock="cpu").equal_time(Strategy("light"), budget)
    assert run.spp == round(budget / cpu_per_spp) and run.clock == "cpu"
    assert run.seconds == pytest.approx(run.spp * cpu_per_spp) == run.cpu_seconds
    assert run.wall_seconds == pytest.approx(run.spp * wall_per_spp)


def test_grid_labels_leave_the_reference_insets_visible(tmp_path):
    """An inset window in the reference's top-left corner, where the label band used to be
    drawn over the image (darkening the red outline to near black): the band now sits above
    the image, so the outline's top and left edges are pure red in grid.png, to 8-bit
    rounding, and the band holds no such outline. Fails if the band covers the image again."""
    from tracer.study.report import grid_image

    reference = Film(32, 32)
    reference.add_block(0, np.full((32 * 32, 2, 3), 0.25))
    run = compare_mod.Run(Strategy("mis"), reference.copy(), 1.0, measures={"relmse": 0.0})
    window = (0, 0, 8, 8)
    band = grid_image([run], reference, [window], 0.0, tmp_path / "grid.png")
    pixels = oiio.ImageBuf(str(tmp_path / "grid.png")).get_pixels(oiio.FLOAT)
    red = np.array([1.0, 0.2, 0.2])
    quantum = 0.5 / 255.0
    x, y, w, h = window
    np.testing.assert_allclose(pixels[band + y, x:x + w], np.broadcast_to(red, (w, 3)), atol=quantum)
    np.testing.assert_allclose(pixels[band + y:band + y + h, x], np.broadcast_to(red, (h, 3)), atol=quantum)
    assert not np.any(np.all(np.abs(pixels[:band, :reference.width] - red) <= quantum, axis=-1))


def test_compare_sweep_over_seeds_with_vector_figures_on_the_cpu_clock(tmp_path, capsys):
    """End to end at 8x8: --sweep --sweep-seeds 3 renders seeds 1-3 (the reference holds 0),
    each to the same spp; metrics.json holds slopes with intervals and times to target, the
    terminal and index.html show them; --figure-format pdf,svg adds vector copies of every
    chart and map beside PNGs written at PRINT_DPI; --clock cpu times the renders in CPU
    seconds. An unknown format is refused in one line. Fails if any of these is missing."""
    from tracer.study import report

    scene = str(SCENES / "cornell.toml")
    ref, out = tmp_path / "ref.exr", tmp_path / "cmp"
    assert main(["reference", scene, "-o", str(ref), "--width", "8", "--height", "8", "--spp", "16",
                 "--quiet"]) == 0
    capsys.readouterr()
    common = ["compare", scene, "--reference", str(ref), "--spp", "4", "--strategies", "mis",
              "--out", str(out)]
    assert main([*common, "--sweep", "--sweep-seeds", "3", "--figure-format", "pdf",
                 "--figure-format", "svg", "--clock", "cpu"]) == 0
    err = capsys.readouterr().err
    doc = json.loads((out / "metrics.json").read_text(), parse_constant=_no_constants)
    assert {p["seed"] for p in doc["sweep"]} == {1, 2, 3} and {p["strategy"] for p in doc["sweep"]} == {"mis"}
    assert all({p["spp"] for p in doc["sweep"] if p["seed"] == s} == {1, 2, 4} for s in (1, 2, 3))
    (slopes,) = doc["convergence"]
    assert slopes["strategy"] == "mis" and slopes["seeds"] == 3
    assert slopes["slope_spp_low"] <= slopes["slope_spp"] <= slopes["slope_spp_high"]
    assert [r["strategy"] for r in doc["time_to_target"]] == ["mis"]
    assert doc["mode"]["clock"] == "cpu"
    assert all(r["clock"] == "cpu" and r["seconds"] == r["cpu_seconds"] > 0 for r in doc["results"])
    assert "slope/spp [95%]" in err and "time to relMSE 0.01" in err
    page = (out / "index.html").read_text()
    assert "Convergence: slopes and time to relMSE" in page and 'href="convergence.pdf"' in page
    for stem in ("convergence", "allocation", "mis_relerr", "mis_flip"):
        assert (out / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-", stem
        assert b"<svg" in (out / f"{stem}.svg").read_bytes()[:2000], stem
        spec = oiio.ImageInput.open(str(out / f"{stem}.png"))
        assert spec.spec().get_float_attribute("XResolution") == pytest.approx(report.PRINT_DPI, rel=1e-3)
        spec.close()
    assert main([*common, "--figure-format", "pdf,eps", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--figure-format: unknown format 'eps'" in err and len(err.strip().splitlines()) == 1, err


def small_reference(tmp_path) -> tuple[str, Path]:
    """veach_mis and a 16 x 16, 16-spp reference of it in tmp_path."""
    scene = str(SCENES / "veach_mis.toml")
    ref = tmp_path / "ref.exr"
    assert main(["reference", scene, "-o", str(ref), "--width", "16", "--height", "16", "--spp", "16",
                 "--quiet"]) == 0
    return scene, ref


def test_compare_takes_a_list_of_light_samplings(tmp_path):
    """--light-sampling area,solid-angle compares each technique with every strategy that takes
    light samples (once for those that do not): files named by technique, records that say it,
    one metrics row each."""
    scene, ref = small_reference(tmp_path)
    out = tmp_path / "cmp"
    assert main(["compare", scene, "--reference", str(ref), "--spp", "2", "--out", str(out), "--quiet",
                 "--strategies", "light,bsdf", "--light-sampling", "area,solid-angle"]) == 0
    rows = {r["name"] for r in json.loads((out / "metrics.json").read_text())["results"]}
    assert rows == {"light", "light_solid-angle", "bsdf"}
    assert read_exr(out / "light_solid-angle.exr").record.light_sampling == "solid-angle"
    assert read_exr(out / "light.exr").record.light_sampling == "area"
    assert read_exr(out / "bsdf.exr").record.light_sampling == "none"
    # metrics.csv tells the runs apart too, by name and by light sampling.
    csv_rows = (out / "metrics.csv").read_text().splitlines()
    assert csv_rows[0].startswith("name,strategy,") and "light_sampling" in csv_rows[0]
    assert sorted(line.split(",")[0] for line in csv_rows[1:]) == ["bsdf", "light", "light_solid-angle"]
    # Where each technique wins: its efficiency map against the strategy's first technique.
    assert (out / "efficiency_light_solid-angle_vs_light.png").is_file()
    assert (out / "efficiency_bsdf_vs_light.png").is_file()


# CI budget: 130 s, nearly all of it compiling five builds (bvh and ris variants); the naming of
# swept dimensions is checked in every run by the heuristics and samplers tests.
@pytest.mark.slow
def test_compare_takes_light_selections_and_ris_settings(tmp_path):
    """--light-selection power,bvh and --ris-candidates 2,4 --ris-sources light,light+bsdf are
    dimensions: each strategy that takes light samples runs with each selection, ris with each
    candidate count and source; files and rows are named apart and the records say what ran."""
    scene, ref = small_reference(tmp_path)
    out = tmp_path / "cmp"
    assert main(["compare", scene, "--reference", str(ref), "--spp", "2", "--out", str(out), "--quiet",
                 "--strategies", "bsdf,mis,ris", "--light-selection", "power,bvh", "--ris-candidates", "2,4",
                 "--ris-sources", "light+bsdf"]) == 0
    rows = {r["name"]: r for r in json.loads((out / "metrics.json").read_text())["results"]}
    ris = {f"ris_{counts}{selection}" for counts in ("l1_b1", "l2_b2") for selection in ("", "_bvh-lights")}
    assert set(rows) == {"bsdf", "mis", "mis_bvh-lights"} | ris
    assert rows["ris_l2_b2_bvh-lights"]["light_selection"] == "bvh"
    assert (rows["ris_l2_b2"]["light_samples"], rows["ris_l2_b2"]["bsdf_samples"]) == (2, 2)
    assert rows["bsdf"]["light_selection"] == "none"
    record = read_exr(out / "ris_l2_b2_bvh-lights.exr").record
    assert (record.strategy, record.light_selection, record.light_samples, record.bsdf_samples) == \
        ("ris", "bvh", 2, 2)
    # Both sources in one list: every source with every count (names from Strategy.ris).
    args = build_parser().parse_args(["compare", scene, "--reference", str(ref), "--spp", "1",
                                      "--ris-sources", "light,light+bsdf", "--ris-candidates", "2,4"])
    assert (args.ris_sources, args.ris_candidates) == (["light", "light+bsdf"], [2, 4])
    assert main(["compare", scene, "--reference", str(ref), "--spp", "2", "--out", str(out), "--quiet",
                 "--strategies", "ris", "--ris-sources", "light+bsdf", "--ris-candidates", "1"]) == 2


def test_compare_takes_a_list_of_samplers(tmp_path):
    """--sampler independent,sobol renders every strategy with each sampler: files named by
    sampler, records that say it, a metrics row each with a sampler column, an efficiency map
    of each sampler against the strategy's first run, and sweep curves told apart by sampler."""
    scene, ref = small_reference(tmp_path)
    out = tmp_path / "cmp"
    assert main(["compare", scene, "--reference", str(ref), "--spp", "8", "--out", str(out), "--quiet",
                 "--strategies", "mis", "--sampler", "independent,sobol", "--sweep", "--sweep-seeds",
                 "2"]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    assert {(r["name"], r["sampler"]) for r in doc["results"]} == {("mis", "independent"),
                                                                   ("mis_sobol", "sobol")}
    assert read_exr(out / "mis_sobol.exr").record.sampler == "sobol"
    assert read_exr(out / "mis_sobol.exr").replicates == 8
    assert read_exr(out / "mis.exr").record.sampler == "independent"
    header = (out / "metrics.csv").read_text().splitlines()[0].split(",")
    assert "sampler" in header
    assert (out / "efficiency_mis_sobol_vs_mis.png").is_file()
    assert [r["strategy"] for r in doc["convergence"]] == ["mis", "mis_sobol"]


def test_slope_marks_tell_heavy_tails_from_faster_than_monte_carlo():
    """A sweep slope whose interval lies above -1 is marked as a heavy-tailed estimator (†);
    one whose interval lies below -1 falls faster than 1/spp, which stratified and QMC points
    can do (‡), and is not called heavy-tailed; one that holds -1 is not marked."""
    from tracer.study import report

    def row(slope, low, high):
        return {"slope_spp": slope, "slope_spp_low": low, "slope_spp_high": high,
                "holds_minus_one": bool(low <= -1.0 <= high)}

    heavy, fast, plain = row(-0.8, -0.9, -0.7), row(-1.3, -1.4, -1.2), row(-1.0, -1.1, -0.9)
    assert report.slope_text(heavy).endswith("†") and report.slope_text(fast).endswith("‡")
    assert report.slope_text(plain).endswith("]")
    assert report._slope_notes([fast]) == [report.FAST_NOTE]
    assert report._slope_notes([heavy, plain]) == [report.HEAVY_TAIL_NOTE]


def test_compare_takes_heuristics_and_allocations(tmp_path):
    """--heuristic power,optimal --allocation fixed,adaptive runs mis four times (named apart,
    with heuristic and allocation columns), ris with the classic heuristic, maps what the
    learning runs learned, and pairs each mis run against the power heuristic's in an
    efficiency map. Optimal MIS cannot weight ris (negative weights): asking only for it with
    ris is refused."""
    scene, ref = small_reference(tmp_path)
    out = tmp_path / "cmp"
    assert main(["compare", scene, "--reference", str(ref), "--spp", "48", "--out", str(out), "--quiet",
                 "--strategies", "mis,ris", "--ris-sources", "light+bsdf", "--ris-candidates", "2",
                 "--heuristic", "power,optimal", "--allocation", "fixed,adaptive"]) == 0
    rows = {r["name"]: r for r in json.loads((out / "metrics.json").read_text())["results"]}
    assert set(rows) == {"mis", "mis_adaptive", "mis_optimal", "mis_optimal_adaptive", "ris_l1_b1"}
    assert (rows["mis_optimal_adaptive"]["heuristic"], rows["mis_optimal_adaptive"]["allocation"]) == \
        ("optimal", "adaptive")
    assert rows["ris_l1_b1"]["heuristic"] == "power"
    assert read_exr(out / "mis_optimal_adaptive.exr").record.allocation == "adaptive"
    for name in ("mis_adaptive_allocation", "mis_optimal_alpha", "mis_optimal_adaptive_allocation",
                 "mis_optimal_adaptive_alpha", "efficiency_mis_optimal_adaptive_vs_mis"):
        assert (out / f"{name}.png").is_file(), name
    assert not (out / "mis_allocation.png").exists()
    assert main(["compare", scene, "--reference", str(ref), "--spp", "2", "--out", str(out), "--quiet",
                 "--strategies", "ris", "--ris-sources", "light+bsdf", "--heuristic", "optimal"]) == 2


def test_compare_says_each_stage_of_the_sweep_and_the_report(tmp_path, capsys):
    """The sweep and the report (its maps at 300 dpi) were silent for most of a run: each
    sweep line came only after every sweep was done, and nothing was said while the report
    was written. Now the sweep says its start and each strategy as it is done, and the report
    each stage as it starts, in order; --quiet says none of it."""
    scene = str(SCENES / "cornell.toml")
    ref = tmp_path / "ref.exr"
    assert main(["reference", scene, "-o", str(ref), "--width", "12", "--spp", "16", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["compare", scene, "--reference", str(ref), "--strategies", "light,mis", "--spp", "2",
                 "--sweep", "--sweep-seeds", "2", "--out", str(tmp_path / "cmp")]) == 0
    lines = [line.strip() for line in capsys.readouterr().err.splitlines()]
    stages = ["sweep: relMSE at spp 1, 2, 4, ... of 2 methods x 2 seeds", "sweep light:", "sweep mis",
              "report 1/2: light: EXR, PNG, error and FLIP maps",
              "report 2/2: mis: EXR, PNG, error and FLIP maps",
              "report: 1 efficiency-ratio map", "report: the viewer's data", "report: convergence chart",
              "report: allocation chart", "report: tables and index.html", "-> "]
    found = [next(i for i, line in enumerate(lines) if line.startswith(stage)) for stage in stages]
    assert found == sorted(found), lines
    assert main(["compare", scene, "--reference", str(ref), "--strategies", "light", "--spp", "2",
                 "--sweep", "--sweep-seeds", "2", "--out", str(tmp_path / "quiet"), "--quiet"]) == 0
    assert "report" not in capsys.readouterr().err


def test_report_maps_are_laid_out_as_tight_layout_and_drawn_once():
    """Figure.tight_layout leaves a placeholder layout engine, and savefig then draws the figure
    twice at 300 dpi (a map's image resampled twice); report.tight_layout lays it out the
    same way (the same subplot parameters) and leaves no engine, so savefig draws it once."""
    from tracer.study import report

    plt = report._pyplot()
    figures = []
    for _ in range(2):
        fig, ax = plt.subplots(figsize=(4.6, 3.8))
        im = ax.imshow(np.arange(12.0).reshape(3, 4))
        ax.set_title("a title", fontsize=9)
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="a label")
        figures.append(fig)
    figures[0].tight_layout()
    report.tight_layout(figures[1])
    params = [vars(f.subplotpars) for f in figures]
    assert params[0] == params[1]
    assert figures[0].get_layout_engine() is not None and figures[1].get_layout_engine() is None
    for fig in figures:
        plt.close(fig)
