"""The environment's light-sampling techniques (``environment_sampling``: ``luminance``,
``uniform``, ``compensated``; tracer/lights/environment.py): each sampler against its own pdf,
what each pdf is, which strategies may take them, how records keep them apart, and that MIS
estimates the same image with each.

The ``luminance`` sampler's own tests (lookup, cells, χ²) are in tests/test_environment.py.
Seeds are fixed; every statistical test is at the suite's 1% family-wise rate (tests/stats.py),
Šidák-corrected over what it compares.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from test_environment import SKY_SCENE, _map, _pdf, _sample

import tracer
from tracer.errors import InputError
from tracer.lights import environment as light
from tracer.record import RenderRecord, check_mergeable
from tracer.scene import shipped_folder
from tracer.strategy import Strategy

import chi2
from stats import z_critical

OTHERS = ("uniform", "compensated")


@pytest.mark.parametrize("sampling", OTHERS)
def test_samples_follow_the_pdf(sampling):
    """χ² of 400,000 samples on the whole sphere in equal-area bins that do not align with the
    map's cells, against the technique's pdf integrated per bin by cubature; each sample's pdf
    is the pdf function's at its direction (but where rounding puts it across a cell edge). Two
    tests, Šidák at the suite's rate."""
    table = light.table(_map(), 0, sampling)
    u = np.random.default_rng([41, OTHERS.index(sampling)]).random((400_000, 2))
    wi, _, p = _sample(table, u)
    assert np.all(p > 0.0)
    assert np.isclose(_pdf(table, wi), p, rtol=1e-12).mean() > 0.999
    domain = chi2.spherical_domain((0.0, 1.0, 0.0), np.pi, polar="z")
    result = chi2.goodness_of_fit(wi, lambda w: _pdf(table, np.ascontiguousarray(w)), domain, (24, 48),
                                  chi2.sidak(len(OTHERS)), mass=1.0, name=f"{sampling} sampler")
    assert result.passed, result.report()


def test_the_pdfs_are_what_the_techniques_say():
    """uniform: 1 / (4 pi) on every cell. compensated: positive exactly on the cells whose mean
    luminance (of their four texels) is above the map's solid-angle mean, proportional there to
    the excess, and normalized; a constant map, with no cell above its mean, keeps the luminance
    distribution (itself uniform then). Deterministic up to rounding."""
    env = _map()
    uniform = light.table(env, 0, "uniform")
    np.testing.assert_allclose(uniform.cell_pdf, 1.0 / (4.0 * np.pi), rtol=1e-12)
    weight, solid_angle = light.cell_weights(env.texels.astype(np.float64) @ light.LUMINANCE)
    mean_cell = weight / solid_angle
    mean = weight.sum() / (4.0 * np.pi)
    compensated = light.table(env, 0, "compensated")
    above = mean_cell > mean
    assert 0 < above.sum() < above.size
    np.testing.assert_array_equal(compensated.cell_pdf > 0.0, above)
    excess = (mean_cell - mean)[above]
    ratio = compensated.cell_pdf[above] / excess
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-9)
    assert float((compensated.cell_pdf * solid_angle).sum()) == pytest.approx(1.0, rel=1e-12)
    flat = type(env)(np.full((9, 16, 3), 0.7, dtype=np.float32), np.eye(3))
    np.testing.assert_allclose(light.table(flat, 0, "compensated").cell_pdf, 1.0 / (4.0 * np.pi), rtol=1e-9)
    with pytest.raises(ValueError, match="unknown environment sampling"):
        light.table(env, 0, "importance")


def test_strategies_that_may_take_compensation():
    """Compensation leaves the dim cells to BSDF samples: mis (one-sample too: it draws BSDF
    samples) and ris with BSDF candidates take it; light sampling alone and ris of light
    candidates only are told why not. A strategy without light samples records none, whatever
    is asked."""
    for ok in (Strategy("mis", environment_sampling="compensated"),
               Strategy("mis", one_sample=True, environment_sampling="compensated"),
               Strategy.ris(8, "light+bsdf", environment_sampling="compensated")):
        assert ok.to_record()["environment_sampling"] == "compensated"
        assert "compensated-environment" in ok.slug and "compensated environment" in ok.label
    for bad in (dict(name="light"), dict(name="ris", light_samples=8, bsdf_samples=0)):
        with pytest.raises(ValueError, match="needs mis, or ris with BSDF candidates"):
            Strategy(**bad, environment_sampling="compensated")
    assert Strategy("bsdf", environment_sampling="uniform").to_record()["environment_sampling"] == "none"
    assert Strategy("light", environment_sampling="uniform").slug == "light_uniform-environment"
    assert Strategy("mis").slug == "mis"  # the default leaves names as they were


def test_records_keep_environment_samplings_apart(tmp_path):
    """Renders by different environment samplings never pool (they are different estimators of
    one image, with different noise); a file from before the field existed holds luminance
    sampling if it took light samples. The record survives an EXR header."""
    scene = tracer.load_scene("cornell")
    a = RenderRecord.of_render(Strategy("mis"), "independent", 1, 0, 4, 1.0, scene)
    uniform = Strategy("mis", environment_sampling="uniform")
    b = RenderRecord.of_render(uniform, "independent", 2, 0, 4, 1.0, scene)
    with pytest.raises(InputError, match="environment_sampling"):
        check_mergeable(a, b)
    old = RenderRecord(**{**a.__dict__, "environment_sampling": None, "samples": ((3, 0, 4),)})
    check_mergeable(a, old)  # an old file: luminance
    back = RenderRecord.from_attributes(b.attributes())
    assert back.environment_sampling == "uniform" and Strategy.from_record(back) == Strategy(
        "mis", environment_sampling="uniform")
    with pytest.raises(InputError, match="environment_sampling"):
        RenderRecord.from_attributes({**b.attributes(), "tracer:environment_sampling": "importance"})


def test_mis_estimates_the_same_image_with_each_environment_sampling(tmp_path):
    """Under the shipped sky map (a hot sun, turned and scaled) with an area light, over diffuse
    and rough-conductor surfaces, MIS with uniform and with compensated environment sampling
    estimates the image that MIS with luminance sampling does: the image means per channel
    differ by less than z standard errors of their difference (Šidák over 2 techniques x 3
    channels; the standard error from per-pixel variances summed over independent pixels; the
    channels tested apart, never summed). Compensation is unbiased only because BSDF samples
    cover the cells it never light-samples; a bias there would show here."""
    shutil.copy(shipped_folder() / "mitsuba" / "textures" / "sky.exr", tmp_path / "sky.exr")
    (tmp_path / "sky.toml").write_text(SKY_SCENE)
    scene = tracer.load_scene(str(tmp_path / "sky.toml"))
    estimates = {}
    for seed, sampling in enumerate(("luminance", *OTHERS)):
        image = tracer.render(scene, "mis", spp=128, seed=20 + seed, environment_sampling=sampling)
        pixels = image.mean.reshape(-1, 3).astype(np.float64)
        var_of_mean = (image.variance.reshape(-1, 3) / image.count.reshape(-1, 1)).astype(np.float64)
        estimates[sampling] = (pixels.mean(axis=0), np.sqrt(var_of_mean.sum(axis=0)) / len(pixels))
    mean0, error0 = estimates["luminance"]
    for sampling in OTHERS:
        mean, error = estimates[sampling]
        z = (mean - mean0) / np.hypot(error, error0)
        assert np.all(np.abs(z) < z_critical(2 * 3)), (sampling, z)
