"""tracer against Mitsuba 3 on the Mitsuba XML verification scenes (tracer/scenes/mitsuba/).

Each scene is read by tracer's own Mitsuba reader (`tracer.load_scene("….xml")`) and rendered
with `mis` at the resolution of its stored Mitsuba 3.9.1 reference (tests/data/mitsuba_refs/,
made by `benchmarks/mitsuba_xml.py`: K independent `scalar_rgb` renders of the same file, so
the per-pixel mean comes with an estimated variance). The two renderers share nothing but the
XML file, so agreement checks the reader (shapes, transforms, camera, defaults, references),
the materials (conductor and roughconductor with Fresnel and Beckmann/GGX, plastic,
roughplastic, one- and two-sided) and smooth shading against an independent implementation.

The statistics live in benchmarks/mitsuba_xml.py (`compare`, whose docstring explains the
robust per-pixel standard error); each test here is at the suite's 1% family-wise rate
(tests/stats.py), so a correct tracer fails a test with probability at most 1%; the seeds are
fixed. tracer renders TRACER_SPP = 1024 spp per pixel (about 20 s for the five scenes);
Mitsuba's references hold 32 x 256 = 8192. The `slow` test renders 8192 spp (about 3 minutes),
which resolves biases confined to one object.
"""

from __future__ import annotations

import functools
import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from stats import FAMILY_ALPHA

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
mitsuba_xml = importlib.import_module("mitsuba_xml")  # one copy of the statistics

NAMES = sorted(p.stem for p in mitsuba_xml.REFS.glob("*.npz"))


def test_every_scene_has_a_reference():
    """Every XML scene shipped in tracer/scenes/mitsuba/ has a Mitsuba reference, so that none
    goes unchecked (parts/ holds included pieces, not scenes)."""
    assert NAMES == mitsuba_xml.scene_names()


# The slow test's tracer side: as many samples as Mitsuba's reference, so that the comparison
# resolves a local bias of a few per cent (the fast tests' 1024 spp leave 5-10% noise per pixel).
SLOW_SPP = 8192
SLOW_SEED = 16


@functools.cache
def rendered(name: str, spp: int = mitsuba_xml.TRACER_SPP, seed: int = mitsuba_xml.TRACER_SEED):
    """(reference, tracer image, comparison) for one scene, rendered once per test session."""
    ref = mitsuba_xml.load_reference(name)
    image = mitsuba_xml.render_tracer(name, ref, spp, seed)
    return ref, image, mitsuba_xml.compare(image.mean, image.variance, image.count, ref)


@pytest.mark.parametrize("name", NAMES)
def test_reference_is_current(name):
    """The reference was rendered from the scene file and the files it includes or loads as they
    are now (SHA-256), by Mitsuba 3.9.1: a stale reference would test nothing."""
    ref = mitsuba_xml.load_reference(name)
    path = mitsuba_xml.scene_path(name)
    assert ref.scene_sha256 == mitsuba_xml.sha256_file(path), f"{name}: regenerate the reference"
    assert ref.inputs_sha256 == mitsuba_xml.inputs_sha256(path), f"{name}: regenerate the reference"
    assert ref.mitsuba_version == "3.9.1"


@pytest.mark.parametrize("name", NAMES)
def test_image_mean(name):
    """The image mean per channel: tracer's and Mitsuba's differ by less than the normal critical
    value times the standard error of the difference (the summed per-pixel variances of both,
    over thousands of pixels an accurate estimate, and the mean of thousands of independent
    pixels is normal), with the Sidak correction over the 3 channels at the suite's 1%.
    This is the most sensitive test (relative standard errors of 0.1-0.3%): a small bias of
    a material, a light's power or the camera's framing that spreads over the image shows here."""
    ref, image, c = rendered(name)
    assert image.nonfinite == 0
    assert c.mean_p >= FAMILY_ALPHA, (
        f"{name}: image mean tracer {c.mean_tracer} vs Mitsuba {c.mean_mitsuba}, "
        f"z {c.mean_z.round(2)} (SE {c.mean_se}), family p {c.mean_p:.2e}")


@pytest.mark.parametrize("name", NAMES)
def test_pixels_sidak(name):
    """The worst pixel: every pixel-channel's difference, over the robust standard error of
    `mitsuba_xml.compare` (the larger of the two renderers' per-sample variance estimates for
    both sides, conservative where they differ and proof against one side having missed a rare
    bright event), is tested with Student's t at the degrees of freedom of that estimate, and
    the smallest p-value is Sidak-corrected over all m tested pixel-channels: at most a 1%
    false alarm if tracer is right. Catches a local error (a misplaced shape, a wrong normal,
    a light seen from the wrong side) that the image mean dilutes."""
    ref, image, c = rendered(name)
    r, col, ch = c.worst
    assert c.sidak_p >= FAMILY_ALPHA, (
        f"{name}: pixel (row {r}, column {col}, channel {ch}): tracer {image.mean[c.worst]:.6g}, "
        f"Mitsuba {ref.mean[c.worst]:.6g}, z {c.z[c.worst]:+.2f}; family p {c.sidak_p:.2e} over "
        f"{c.chi2_m} pixel-channels")


@pytest.mark.parametrize("name", NAMES)
def test_pixels_chi_square(name):
    """Many small differences: the per-pixel t p-values of `test_pixels_sidak`, as normal scores
    squared, are chi-square(1) each and independent across pixel-channels (both renderers draw
    every pixel's samples independently), so their sum is chi-square(m) if tracer is right (with
    the conservative standard error it is smaller); the upper tail p must be at least 1%.
    Catches a bias of a few per cent of the noise over a whole region, say one material's
    highlight, that no single pixel shows."""
    ref, image, c = rendered(name)
    assert c.chi2_p >= FAMILY_ALPHA, (
        f"{name}: sum of squared pixel scores {c.chi2:.1f} over {c.chi2_m} pixel-channels "
        f"({c.chi2 / c.chi2_m:.3f} each), p {c.chi2_p:.2e}")


@pytest.mark.parametrize("name", NAMES)
def test_blocks_sidak(name):
    """8 x 8 blocks: each block's mean difference per channel over its standard error (the
    summed variances of the block's independent pixel means, both renderers; channels tested
    one by one, since a pixel's channels are not independent), normal p, Sidak over blocks and
    channels at the suite's 1%. Between the worst pixel and the image mean: catches a bias over
    one object or one texture region that single pixels are too noisy to show."""
    ref, image, c = rendered(name)
    variance_of_mean = image.variance / np.maximum(image.count, 1)[..., None]
    family_p, worst = mitsuba_xml.block_test(image.mean, variance_of_mean, ref)
    assert family_p >= FAMILY_ALPHA, f"{name}: block at (row, column, channel, z) {worst}, family p {family_p:.2e}"


@pytest.mark.parametrize("name", NAMES)
def test_exact_pixels(name):
    """Pixel-channels where both renderers report zero variance (background, a light's interior
    seen directly, points no light reaches) are deterministic in both: they must agree to float32
    rounding (relative 1e-4: Mitsuba sums 256 float32 samples per render), so a wrong
    emitted radiance or a black-versus-lit mistake shows without any statistics."""
    ref, image, c = rendered(name)
    bad = np.argwhere(c.exact_bad)
    assert len(bad) == 0, (
        f"{name}: {len(bad)} of {int(c.exact.sum())} zero-variance pixel-channels differ, first "
        f"{tuple(bad[0])}: tracer {image.mean[tuple(bad[0])]:.6g}, Mitsuba {ref.mean[tuple(bad[0])]:.6g}")


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_pixels_at_reference_spp(name):
    """`test_pixels_sidak` and `test_pixels_chi_square` with tracer at SLOW_SPP = 8192 spp, as
    many samples as Mitsuba's reference, so that a bias confined to one object (a material's
    grazing-angle term on a small sphere, one face of a box) stands out of the noise: at 1024 spp
    a 5% bias on 100 pixels is invisible. The two tests' bounds hold as there (Sidak over the m
    pixel-channels, chi-square(m) upper tail), each at the suite's 1%, Bonferroni-split in two
    (0.5% each) as they share this render; about 30 s of rendering a scene."""
    ref, image, c = rendered(name, SLOW_SPP, SLOW_SEED)
    r, col, ch = c.worst
    assert c.sidak_p >= FAMILY_ALPHA / 2, (
        f"{name}: pixel (row {r}, column {col}, channel {ch}): tracer {image.mean[c.worst]:.6g}, "
        f"Mitsuba {ref.mean[c.worst]:.6g}, z {c.z[c.worst]:+.2f}; family p {c.sidak_p:.2e} over "
        f"{c.chi2_m} pixel-channels")
    assert c.chi2_p >= FAMILY_ALPHA / 2, (
        f"{name}: sum of squared pixel scores {c.chi2:.1f} over {c.chi2_m} pixel-channels, "
        f"p {c.chi2_p:.2e}")
