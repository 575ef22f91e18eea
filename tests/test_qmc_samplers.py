"""The stratified and Sobol samplers and their replicates: the points (uniform, nets, strata,
pairs decorrelated), the bits (the same at any thread count and batch size), the honesty of the
variance channel they feed (against a reference and seed against seed), and the replicate
statistics through resumes, merges and EXR files.

Independence. Within one (pixel, replicate) the points of a QMC sampler avoid each other on
purpose, so they are not independent samples of anything; each (pixel, replicate) is one
independent randomization (a hash of the seed, the pixel and the replicate), so the tests below
draw at most one statistic from each and pool those over many pixels and replicates.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import OpenImageIO as oiio
import pytest
from scipy import stats

from tracer import samplers
from tracer.errors import InputError
from tracer.film import merge_renders
from tracer.imagefiles import read_exr, write_exr
from tracer.render_loop import DEFAULT_BATCH_LANES, RenderSettings, render
from tracer.samplers import stratified
from tracer.scene import load_scene
from tracer.strategy import Strategy

from stats import sidak, z_critical

SAMPLERS = ("independent", "stratified", "sobol")
QMC = ("stratified", "sobol")
R = samplers.REPLICATES


def lit_floor(width: int, height: int) -> dict:
    """A grey floor lit by a square light 1.5 above it, with a square occluder between them (a
    soft shadow: the light is partly visible from the penumbra), seen from below the light's
    height so that every pixel sees the floor or the occluder's top. One light and one grey
    material: the three channels of every sample are proportional."""
    grey = "grey"
    return {
        "camera": {"origin": [0.0, 1.2, 2.2], "target": [0.0, 0.0, 0.0], "fov": 40.0,
                   "width": width, "height": height},
        "materials": {grey: {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [
            {"type": "quad", "origin": [-5.0, 0.0, -5.0], "edge1": [0.0, 0.0, 10.0],
             "edge2": [10.0, 0.0, 0.0], "material": grey},
            {"type": "quad", "origin": [-0.3, 0.6, -0.3], "edge1": [0.6, 0.0, 0.0],
             "edge2": [0.0, 0.0, 0.6], "material": grey},
            {"type": "quad", "origin": [-0.5, 1.5, -0.5], "edge1": [1.0, 0.0, 0.0],  # faces down
             "edge2": [0.0, 0.0, 1.0], "emission": [4.0, 4.0, 4.0]},
        ],
    }


def render_film(scene, sampler: str, spp: int, seed: int, first_sample: int = 0, film=None,
                threads: int = 2, batch_lanes: int = DEFAULT_BATCH_LANES, strategy: str = "mis"):
    """The film of a whole MIS render (``tracer.render_loop.render``)."""
    settings = RenderSettings(spp=spp, seed=seed, threads=threads, first_sample=first_sample,
                              batch_lanes=batch_lanes, sampler=sampler)
    result = render(scene, Strategy(strategy), settings, film=film)
    assert not result.interrupted
    return result.film


# ---------------------------------------------------------------------------------------------
# The points

KEY_PIXELS = 8192  # x R replicates = 65,536 independent randomizations per sampler
GRID = 16
WITHIN_PAIR = ((0, 1), (4, 5), (8, 9))
CROSS_PAIR = ((0, 4), (1, 6), (5, 8))


def _keys() -> tuple[np.ndarray, np.ndarray]:
    """(pixel, replicate) of every key, ``(KEY_PIXELS * R,)`` each."""
    return np.repeat(np.arange(KEY_PIXELS), R), np.tile(np.arange(R), KEY_PIXELS)


def test_points_are_uniform_on_2d_projections():
    """One point from each of 65,536 (pixel, replicate) keys (for ``independent``, sample
    r + 8 i of the pixel; for the others point i of replicate r, i = (3 pixel + r) mod 8 so that
    every point index of a 64-spp render is covered): the keys are independently randomized, so
    the points are independent and the 16 x 16 cell counts of a 2-D projection are multinomial
    with equal probabilities if every point is uniform on it. Pearson's chi-square (255 dof,
    256 expected per cell) on the within-pair projections (0, 1), (4, 5), (8, 9), where each
    point of a scrambled net or jittered stratum is uniform, and on the cross-pair projections
    (0, 4), (1, 6), (5, 8), where a point's coordinates in two pairs must be independent (pairs
    randomized from a hash that forgot the pair would put (0, 4) on the diagonal; that the
    points of one replicate are decorrelated across pairs is the next test); Sidak over 3
    samplers x 6 projections. The 64-spp stratified grid is 3 x 3 for 8 points, one cell left
    empty: uniformity there rests on the random rotation of the cells."""
    pixel, replicate = _keys()
    index = (3 * pixel + replicate) % 8
    dims = sorted({d for pair in WITHIN_PAIR + CROSS_PAIR for d in pair})
    level = sidak(len(SAMPLERS) * (len(WITHIN_PAIR) + len(CROSS_PAIR)))
    failures = []
    for name in SAMPLERS:
        u = samplers.uniforms(samplers.make(name, 2024, 0, 64), pixel, replicate + R * index, dims)
        assert np.all((u >= 0.0) & (u < 1.0))
        for a, b in WITHIN_PAIR + CROSS_PAIR:
            ia, ib = ((u[:, dims.index(d)] * GRID).astype(np.int64) for d in (a, b))
            cells = ia * GRID + ib
            counts = np.bincount(cells, minlength=GRID * GRID)
            p = stats.chisquare(counts).pvalue
            if p < level:
                failures.append(f"{name} dims ({a}, {b}): chi2 p = {p:.3g} < {level:.3g}; "
                                f"counts {counts.min()} .. {counts.max()} (expected {len(u) // GRID**2})")
    assert not failures, "\n".join(failures)


def _common_prefix(u: np.ndarray, v: np.ndarray, levels: int = 3) -> np.ndarray:
    """How many of the first ``levels`` binary digits of u and v agree before the first that
    differs: 0 .. levels."""
    agree = np.stack([np.floor(u * 2**k) == np.floor(v * 2**k) for k in range(1, levels + 1)])
    return np.cumprod(agree, axis=0).sum(axis=0)


def test_pairs_are_decorrelated_within_a_replicate():
    """Padding, inside a replicate. For points i = 0 and j = 8 of each of 65,536 keys, L_d is
    the number of leading binary digits that u_d(i) and u_d(j) share (capped at 3), and the
    test is on the 4 x 4 table of (L_p, L_q) for the first dimensions of pairs 0, 2, 4
    (dims 0, 4, 8), one table entry per key (independent keys: a multinomial table).

    Sobol: i and j first differ in bit 3, so the nested shuffle of the index (a bit flips with
    the bits above it) makes their shuffled low 3 bits independent uniform and the x digits are
    those bits reversed; the coordinate's Owen scramble keeps shared prefixes. So L is 0, 1, 2,
    3 with probabilities 1/2, 1/4, 1/8, 1/8 in every pair, independently across pairs (separate
    hashes): a goodness-of-fit chi-square (15 dof). The same law holds for independent uniforms
    (the ``independent`` sampler). Without the index shuffle both pairs would share the index's
    own digits (L = 3 always). Stratified (16 points, a 4 x 4 grid): L's law depends on the
    cell permutation, so the test is the chi-square of independence of L_p and L_q (9 dof),
    which pairs permuted with one key would fail. Sidak over 3 samplers x 3 pairs of pairs."""
    pixel, replicate = _keys()
    dims = [0, 4, 8]
    law = np.array([0.5, 0.25, 0.125, 0.125])
    level = sidak(len(SAMPLERS) * 3)
    failures = []
    for name in SAMPLERS:
        sampler = samplers.make(name, 77, 0, 128)
        ui = samplers.uniforms(sampler, pixel, replicate, dims)
        uj = samplers.uniforms(sampler, pixel, replicate + 8 * R, dims)
        prefix = [_common_prefix(ui[:, k], uj[:, k]) for k in range(len(dims))]
        for p, q in ((0, 1), (0, 2), (1, 2)):
            table = np.zeros((4, 4))
            np.add.at(table, (prefix[p], prefix[q]), 1.0)
            if name == "stratified":
                pvalue = stats.chi2_contingency(table, correction=False).pvalue
            else:
                pvalue = stats.chisquare(table.ravel(), np.outer(law, law).ravel() * table.sum()).pvalue
            if pvalue < level:
                failures.append(f"{name} dims {dims[p]}, {dims[q]}: p = {pvalue:.3g} < {level:.3g}\n{table}")
    assert not failures, "\n".join(failures)


def test_sobol_points_are_nets():
    """For 4 pixels x 3 replicates x 4 pairs (dims (0, 1), (2, 3), (4, 5), (10, 11)) and m = 0
    .. 8, the replicate's points with indices in the aligned block [b 2^m, (b + 1) 2^m) (sample
    indices r + 8 i) for b = 0 (a render's first 2^m points), b = 1 (what a resume to 2^(m+1)
    adds) and b = 3 put exactly one point in every elementary interval
    [a/2^k, (a+1)/2^k) x [c/2^(m-k), (c+1)/2^(m-k)), k = 0 .. m: a (0, m, 2)-net. Exact."""
    sampler = samplers.make("sobol", 11)
    pairs = (0, 1, 2, 5)
    dims = [d for p in pairs for d in (2 * p, 2 * p + 1)]
    index = np.arange(1024)
    failures = []
    checked = 0
    for pixel in (0, 1, 4095, 123457):
        for r in (0, 3, 7):
            u = samplers.uniforms(sampler, np.full(len(index), pixel), r + R * index, dims)
            for k_pair, pair in enumerate(pairs):
                x, y = u[:, 2 * k_pair], u[:, 2 * k_pair + 1]
                for m in range(9):
                    for b in (0, 1, 3):
                        block = slice(b << m, (b + 1) << m)
                        for k in range(m + 1):
                            cells = ((x[block] * 2**k).astype(np.int64) << (m - k)) + (
                                y[block] * 2 ** (m - k)).astype(np.int64)
                            checked += 1
                            if len(np.unique(cells)) != 1 << m:
                                failures.append(f"pixel {pixel} replicate {r} pair {pair} m={m} block {b} "
                                                f"k={k}: {len(np.unique(cells))} of {1 << m} intervals hit")
    assert checked == 4 * 3 * 4 * 3 * sum(m + 1 for m in range(9))
    assert not failures, "\n".join(failures[:10])


STRATIFIED_CASES = [(spp, first) for spp in (8, 32, 64, 72, 128, 200, 61) for first in (0, 64, 13)]


@pytest.mark.parametrize("spp, first_sample", STRATIFIED_CASES)
def test_stratified_points_take_distinct_cells(spp, first_sample):
    """A stratified render of ``spp`` samples from ``first_sample`` (0, a resume at 64, or an
    index that is not a multiple of R) gives each replicate N = ceil(spp / 8) points or fewer
    (spp = 61: 7 or 8), and in each of the pairs (0, 1), (4, 5), (8, 9) they fall in distinct
    cells of the grid ``stratified.grid(N)``, which has at least N and fewer than N + nx cells;
    when spp = 8 N with N a perfect square (1, 4, 9, 16, 25) every cell holds exactly one point.
    Exact, for 3 pixels and every replicate."""
    n = -(-spp // R)
    nx, ny = stratified.grid(n)
    assert n <= nx * ny < n + nx
    square = spp == R * n and math.isqrt(n) ** 2 == n
    if square:
        assert nx == ny == math.isqrt(n)
    sampler = samplers.make("stratified", 5, first_sample, spp)
    sample = np.arange(first_sample, first_sample + spp)
    pairs = ((0, 1), (4, 5), (8, 9))
    for pixel in (0, 77, 4095):
        u = samplers.uniforms(sampler, np.full(spp, pixel), sample, [d for p in pairs for d in p])
        for r in range(R):
            mine = sample % R == r
            assert mine.sum() in ((n,) if spp == R * n else (n - 1, n))
            for k in range(len(pairs)):
                column = (u[mine, 2 * k] * nx).astype(np.int64)
                cells = column + nx * (u[mine, 2 * k + 1] * ny).astype(np.int64)
                assert len(np.unique(cells)) == mine.sum(), (pixel, r, pairs[k], np.sort(cells))
                if square:
                    assert np.array_equal(np.sort(cells), np.arange(nx * ny)), (pixel, r, pairs[k])


# ---------------------------------------------------------------------------------------------
# The bits


def _film_arrays(film) -> dict[str, np.ndarray]:
    arrays = {"count": film.count, "mean": film.mean, "m2": film.m2}
    if film.replicates:
        arrays |= {"rep_count": film.rep_count, "rep_mean": film.rep_mean}
    return arrays


def test_same_seed_gives_the_same_bits_at_any_threads_and_batch_size():
    """For each sampler, a 48 x 40 MIS render of 40 spp (passes of 17, 17 and 6 samples, so
    replicates get 5 samples each and passes cut through them) with seed 5 at threads 1 and 2
    and batch lanes 2^15, 333 and 1000: count, mean, M2 and the replicate counts and means are
    bit-identical, because every number is a function of (seed, pixel, sample, dimension) and
    batches are folded in a fixed order."""
    scene = load_scene(lit_floor(48, 40))
    for name in SAMPLERS:
        runs = [render_film(scene, name, 40, 5, threads=t, batch_lanes=b)
                for t, b in ((1, DEFAULT_BATCH_LANES), (2, DEFAULT_BATCH_LANES), (2, 333), (1, 1000))]
        assert runs[0].replicates == samplers.replicates_of(name)
        assert np.all(runs[0].count == 40)
        if runs[0].replicates:
            assert np.all(runs[0].rep_count == 5)
        base = _film_arrays(runs[0])
        for run in runs[1:]:
            for key, values in _film_arrays(run).items():
                assert np.array_equal(values, base[key]), f"{name}: {key} differs"


# ---------------------------------------------------------------------------------------------
# The variance channel: is variance / spp the error of the pixel value?

COVERAGE_SIZE = 64
COVERAGE_SPP = 64
REFERENCE_SPP = 2048
COVERAGE_SEEDS = {"independent": (1, 2), "stratified": (3, 4), "sobol": (5, 6)}
CHANNEL = 0  # the channels are proportional (``lit_floor``): one carries all there is


@pytest.fixture(scope="module")
def coverage(computed_once):
    """Renders of ``lit_floor`` at 64 x 64: an independent reference (2048 spp, seed 100), an
    independent 64-spp pilot (seed 99) whose variances weight the pixels, and two 64-spp
    renders (two seeds) of each sampler."""

    def compute(_folder):
        scene = load_scene(lit_floor(COVERAGE_SIZE, COVERAGE_SIZE))
        reference = render_film(scene, "independent", REFERENCE_SPP, 100)
        pilot = render_film(scene, "independent", COVERAGE_SPP, 99)
        films = {name: [render_film(scene, name, COVERAGE_SPP, seed) for seed in seeds]
                 for name, seeds in COVERAGE_SEEDS.items()}
        return reference, pilot, films

    return computed_once("qmc-coverage", compute)


def _against_reference(film, reference, pilot, variance_of_mean) -> tuple[float, float, float]:
    """(z, weighted ratio sum w d^2 / sum w v, its standard error) of d = pixel - reference and
    v = variance_of_mean + the reference's, weights w = 1 / the pilot's variance of the mean
    (0 where the pilot's is 0), for ``test_variance_channel_covers_the_error``."""
    d = film.mean[:, CHANNEL] - reference.mean[:, CHANNEL]
    v = variance_of_mean + reference.variance_of_mean()[:, CHANNEL]
    pilot_v = pilot.variance_of_mean()[:, CHANNEL]
    w = np.where(pilot_v > 0, 1.0 / np.where(pilot_v > 0, pilot_v, 1.0), 0.0)
    x = w * (d * d - v)
    se = math.sqrt(float(np.sum(x * x)))
    z = float(np.sum(x)) / se
    wv = float(np.sum(w * v))
    return z, float(np.sum(w * d * d)) / wv, se / wv


def test_variance_channel_covers_the_error(coverage):
    """Against the reference, d = pixel - reference has E[d^2] = Var(pixel) + Var(reference)
    (both unbiased, independent), and v = variance / spp + the reference's variance_of_mean has
    the same expectation when the variance channel is honest: for ``independent`` M2 / (n - 1)
    is unbiased, for the others the replicate formula is (8 i.i.d. replicate means, equal
    counts). No normality is needed. Pixels are independent (each has its own randomization),
    so x_p = w_p (d_p^2 - v_p), with weights w_p = 1 / (variance of the mean of an independent
    pilot render, independent of both images, so E[x_p] = 0 still), sums to a
    mean-zero total with standard error sqrt(sum x_p^2) (the weights even out the bright
    pixels, which would otherwise dominate: about 1.6 x smaller errors here). So
    sum w d^2 / sum w v = 1 within z_critical(3) standard errors, Sidak over the 3 samplers
    (they share the reference; Sidak holds for correlated two-sided normal tests). Pixels with
    v = 0 add exactly 0 to both sums (black everywhere in both renders)."""
    reference, pilot, films = coverage
    bound = z_critical(len(SAMPLERS))
    report = []
    for name in SAMPLERS:
        film = films[name][0]
        z, ratio, se = _against_reference(film, reference, pilot, film.variance_of_mean()[:, CHANNEL])
        report.append((name, z, ratio, se))
    assert all(abs(z) < bound for _, z, _, _ in report), "\n".join(
        f"{n}: weighted mean(d^2) / mean(v) = {r:.3f} +- {s:.3f}, z = {z:.2f} (bound {bound:.2f})"
        for n, z, r, s in report)


def test_naive_variance_overstates_qmc_error(coverage):
    """The same statistic as ``test_variance_channel_covers_the_error`` with the naive
    per-sample variance M2 / (n - 1) of the stratified and Sobol films in place of the replicate
    one: their samples avoid each other, so the pixel's error is smaller than the samples'
    spread says, and sum w d^2 / sum w v_naive falls below 1 by more than z_critical(2,
    sides=1) standard errors (one-sided, Sidak over the 2 samplers). This is why replicates
    exist, and it shows that the honesty test fails for a variance that is off by the factor
    QMC gains here (about 2)."""
    reference, pilot, films = coverage
    bound = z_critical(len(QMC), sides=1)
    for name in QMC:
        film = films[name][0]
        naive = film.m2[:, CHANNEL] / np.maximum(film.count - 1, 1) / np.maximum(film.count, 1)
        z, ratio, se = _against_reference(film, reference, pilot, naive)
        assert z < -bound, f"{name}: naive ratio {ratio:.3f} +- {se:.3f}, z = {z:.2f}, bound -{bound:.2f}"


def test_seed_to_seed_scatter_matches_variance_channel(coverage):
    """Two renders of one sampler with different seeds: z = d / sqrt(v), d = the difference of
    their pixel values and v = the sum of their variance_of_mean. Each pixel's N i.i.d. units
    (the 2 x 8 replicate means, nu = 2 (8 - 1) = 14; for ``independent`` the 2 x 64 samples,
    nu = 126; N = nu + 2) are exchangeable, so every split of them into two halves is equally
    likely to be the one the seeds made, and the between-halves share of their sum of squares,
    Q = d^2 / (d^2 + nu v) = z^2 / (z^2 + nu), has E[Q] = 1 / (N - 1) = 1 / (nu + 1) exactly,
    for any distribution of the units (randomization theory: E[d^2] = S^2 (2/(N/2)) with S^2 the
    units' variance). Q is bounded, and pixels are independent: mean((nu + 1) Q) = 1 within
    z_critical(3) standard errors of the pixel-to-pixel spread, Sidak over the 3 samplers.
    This is the per-pixel spread of z: under normal units z ~ t_nu, whose SD sqrt(nu / (nu - 2))
    (1.080 and 1.008) the message shows beside the measured one, but the test does not rely on
    it (replicate means of 8 points are not normal in general). The film's variance enters
    through v, so a variance off by a factor, or taken from the wrong pixel, fails."""
    _, _, films = coverage
    bound = z_critical(len(SAMPLERS))
    report = []
    for name in SAMPLERS:
        a, b = films[name]
        assert np.all(a.count == COVERAGE_SPP) and np.all(b.count == COVERAGE_SPP)
        nu = 2 * (R - 1) if a.replicates else 2 * (COVERAGE_SPP - 1)
        if a.replicates:
            assert np.all(a.rep_count == COVERAGE_SPP // R) and np.all(b.rep_count == COVERAGE_SPP // R)
        d = a.mean[:, CHANNEL] - b.mean[:, CHANNEL]
        v = a.variance_of_mean()[:, CHANNEL] + b.variance_of_mean()[:, CHANNEL]
        total = d * d + nu * v  # 0 only where all N units are equal (the selection is symmetric in them)
        used = total > 0
        q = (nu + 1) * d[used] ** 2 / total[used]
        z = float((np.mean(q) - 1.0) / (np.std(q, ddof=1) / math.sqrt(used.sum())))
        sd_z = math.sqrt(float(np.mean(d[used] ** 2 / v[used]))) if np.all(v[used] > 0) else math.inf
        report.append((name, z, float(np.mean(q)), sd_z, math.sqrt(nu / (nu - 2)), int(used.sum())))
    assert all(abs(z) < bound for _, z, *_ in report), "\n".join(
        f"{n}: mean((nu+1) Q) = {m:.4f}, z = {z:.2f} (bound {bound:.2f}); SD of z {s:.4f} "
        f"(normal theory {t:.4f}); {p} pixels" for n, z, m, s, t, p in report)


# ---------------------------------------------------------------------------------------------
# Replicates through resumes, merges and files


@pytest.fixture(scope="module")
def small_scene():
    return load_scene(lit_floor(16, 16))


def _close(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to float64 rounding of means of at most a few hundred O(1) samples."""
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14 * max(1.0, float(np.abs(b).max())))


@pytest.mark.parametrize("split", [64, 60])
def test_sobol_resume_equals_one_render(small_scene, split):
    """Sobol points depend only on (seed, pixel, sample index, dimension): samples 0 .. split - 1
    resumed with split .. 127 (RenderSettings(first_sample=split), film=...) hold the same
    counts and replicate counts as one render of 0 .. 127 and the same means, replicate means
    and variances to float64 rounding (16 x 16: one pass of 128 against two passes, so the
    means are folded differently). split = 60 cuts replicates unevenly (8 and 7 samples)."""
    whole = render_film(small_scene, "sobol", 128, 7)
    part = render_film(small_scene, "sobol", split, 7)
    if split % R:
        assert sorted(set(part.rep_count[0].tolist())) == [split // R, split // R + 1]
    resumed = render_film(small_scene, "sobol", 128 - split, 7, first_sample=split, film=part)
    assert np.array_equal(resumed.count, whole.count) and np.all(whole.count == 128)
    assert np.array_equal(resumed.rep_count, whole.rep_count) and np.all(whole.rep_count == 128 // R)
    _close(resumed.mean, whole.mean)
    _close(resumed.rep_mean, whole.rep_mean)
    _close(resumed.variance(), whole.variance())
    assert resumed.record.samples == whole.record.samples == ((7, 0, 128),)


@pytest.mark.parametrize("split", [64, 60])
def test_stratified_resume_and_seed_pool_keep_replicate_counts(small_scene, split):
    """Stratified: a render of samples 0 .. split - 1 resumed with split .. 127 holds exactly
    128 samples in every pixel and 16 in every replicate; what the resume added is a new
    stratified set, the same as a standalone render of split .. 127, so the resumed film equals
    merge_renders of the two standalone films (to float64 rounding). Pooling two seeds with
    merge_renders sums the replicate counts (8 + 8) and averages the replicate means."""
    first = render_film(small_scene, "stratified", split, 7)
    resumed = render_film(small_scene, "stratified", 128 - split, 7, first_sample=split, film=first.copy())
    assert np.all(resumed.count == 128) and np.all(resumed.rep_count == 128 // R)
    second = render_film(small_scene, "stratified", 128 - split, 7, first_sample=split)
    pooled = merge_renders(first, second)
    assert np.array_equal(pooled.rep_count, resumed.rep_count)
    _close(resumed.mean, pooled.mean)
    _close(resumed.rep_mean, pooled.rep_mean)

    a = render_film(small_scene, "stratified", 64, 7)
    b = render_film(small_scene, "stratified", 64, 8)
    both = merge_renders(a, b)
    assert np.all(both.count == 128) and np.all(both.rep_count == 2 * (64 // R))
    _close(both.rep_mean, (a.rep_mean + b.rep_mean) / 2)
    _close(both.mean, (a.mean + b.mean) / 2)


def _variance_rounding_bound(film) -> np.ndarray:
    """(P, 3) bound on the change of ``film.variance()`` when its replicate means are rounded to
    float32 (relative error <= 2^-24 each): each deviation e_r = Y_r - sum_s w_s Y_s moves by at
    most eps = 2 x 2^-24 max_r |Y_r|, so n R'/(R' - 1) sum_r w_r^2 e_r^2 moves by at most
    n R'/(R' - 1) sum_r w_r^2 (2 |e_r| eps + eps^2); eps is taken 0.1% larger to cover the
    float64 arithmetic (errors ~1e-16 max |Y|)."""
    n = film.count.astype(np.float64)[:, None]
    w = film.rep_count / film.count[:, None]
    pooled = np.einsum("pr,prc->pc", w, film.rep_mean)
    e = np.abs(film.rep_mean - pooled[:, None, :])
    eps = 1.001 * 2.0 * 2.0**-24 * np.abs(film.rep_mean).max(axis=1)[:, None, :]
    used = (film.rep_count > 0).sum(axis=1).astype(np.float64)[:, None]
    return n * used / (used - 1) * np.einsum("pr,prc->pc", w * w, 2 * e * eps + eps * eps)


def _rewrite_exr(src, dst, edit) -> None:
    """Copy the EXR ``src`` to ``dst`` through OpenImageIO with every header attribute, after
    ``edit(names, pixels (H, W, C) float32) -> (names, pixels)``."""
    inp = oiio.ImageInput.open(str(src))
    spec = inp.spec()
    pixels = np.array(inp.read_image(0, 0, 0, spec.nchannels, "float"))
    inp.close()
    names, pixels = edit(list(spec.channelnames), pixels)
    out_spec = oiio.ImageSpec(spec.width, spec.height, len(names), "float")
    out_spec.channelnames = tuple(names)
    for attribute in spec.extra_attribs:
        out_spec.attribute(attribute.name, attribute.type, attribute.value)
    out = oiio.ImageOutput.create(str(dst))
    assert out.open(str(dst), out_spec) and out.write_image(np.ascontiguousarray(pixels, dtype=np.float32))
    assert out.close()


def _channel(path, name: str) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    pixels = np.array(inp.read_image(0, 0, 0, spec.nchannels, "float"))
    inp.close()
    return pixels.reshape(-1, spec.nchannels)[:, list(spec.channelnames).index(name)]


@pytest.mark.parametrize("sampler", QMC)
def test_exr_round_trip_keeps_replicates(small_scene, tmp_path, sampler):
    """write_exr / read_exr of a resumed film (two runs: replicates hold 8 + 8 samples): the
    replicate counts come back exact, the replicate and pixel means as their float32 roundings
    (exactly), the record whole; the file's variance channels are the float32 rounding of
    ``Film.variance()``, and the variance the reader recomputes from the float32 replicate
    means is within the propagated rounding bound (``_variance_rounding_bound``) of the
    original. The film read back can be resumed and pooled."""
    film = render_film(small_scene, sampler, 64, 7)
    film = render_film(small_scene, sampler, 64, 7, first_sample=64, film=film)
    path = tmp_path / f"{sampler}.exr"
    write_exr(path, film)
    back = read_exr(path)
    assert back.replicates == R
    # The header keeps the seconds as a 32-bit float.
    assert dataclasses.replace(back.record, seconds=film.record.seconds) == film.record
    assert back.record.seconds == pytest.approx(film.record.seconds, rel=2.0**-23)
    assert np.array_equal(back.count, film.count) and np.array_equal(back.rep_count, film.rep_count)
    assert np.array_equal(back.rep_mean, film.rep_mean.astype(np.float32).astype(np.float64))
    assert np.array_equal(back.mean, film.mean.astype(np.float32).astype(np.float64))
    for c, channel in enumerate("RGB"):
        assert np.array_equal(_channel(path, f"variance.{channel}"), film.variance()[:, c].astype(np.float32))
    assert np.all(np.abs(back.variance() - film.variance()) <= _variance_rounding_bound(film))
    more = render_film(small_scene, sampler, 8, 7, first_sample=128, film=back)
    assert np.all(more.count == 136) and np.all(more.rep_count == 17)


def test_merge_refuses_other_samplers_and_files_without_replicates(small_scene, tmp_path):
    """merge_renders refuses to pool films of different samplers (their replicates are not
    each other's), and a Sobol EXR whose replicate channels were removed (by another tool:
    OpenImageIO, every header attribute kept) reads with its variance but cannot be pooled,
    in either order, with an InputError that names that file as the one at fault; nor can it
    be resumed."""
    sobol = render_film(small_scene, "sobol", 16, 7)
    for other in ("stratified", "independent"):
        with pytest.raises(InputError, match="sampler"):
            merge_renders(sobol, render_film(small_scene, other, 16, 8))
    good, partner, stripped = (tmp_path / n for n in ("good.exr", "partner.exr", "stripped.exr"))
    write_exr(good, sobol)
    write_exr(partner, render_film(small_scene, "sobol", 16, 8))
    keep = ("R", "G", "B", "variance.R", "variance.G", "variance.B")

    def drop_replicates(names, pixels):
        return list(keep), pixels[:, :, [names.index(n) for n in keep]]

    _rewrite_exr(good, stripped, drop_replicates)
    bare = read_exr(stripped)
    assert bare.replicates == 0 and bare.record.sampler == "sobol"
    assert bare.record.samples == sobol.record.samples
    np.testing.assert_allclose(bare.variance(), sobol.variance().astype(np.float32), rtol=1e-12)
    for first, second in ((stripped, partner), (partner, stripped)):
        with pytest.raises(InputError) as caught:
            merge_renders(read_exr(first), read_exr(second), str(first), str(second))
        culprit = str(caught.value).split(": ", 1)[1]
        assert culprit.startswith(f"{stripped} (sobol sampler)") and "replicate" in culprit, str(caught.value)
    with pytest.raises(InputError, match="replicates"):
        render_film(small_scene, "sobol", 8, 7, first_sample=16, film=bare)


def test_read_refuses_replicate_counts_that_do_not_add_up(small_scene, tmp_path):
    """A Sobol EXR in which one pixel's replicate3.samples was raised by 1 (the file otherwise
    intact) no longer adds up to the pixel's count: read_exr raises InputError naming the file
    and the pixel."""
    path, bad = tmp_path / "good.exr", tmp_path / "bad.exr"
    write_exr(path, render_film(small_scene, "sobol", 16, 7))
    x, y = 5, 2

    def bump(names, pixels):
        pixels = pixels.copy()
        pixels[y, x, names.index("replicate3.samples")] += 1.0
        return names, pixels

    _rewrite_exr(path, bad, bump)
    assert read_exr(path).rep_count[y * 16 + x, 3] == 2
    with pytest.raises(InputError, match=r"replicate counts .* pixel \(5, 2\)") as caught:
        read_exr(bad)
    assert str(bad) in str(caught.value)


# The hostile files of an adversarial review: each is self-consistent in what the reader
# checked before (whole counts adding up to the pixel's, finite means) but lies elsewhere.
def _all_in_replicate_0(names, pixels):
    pixels = pixels.copy()
    total = sum(pixels[:, :, names.index(f"replicate{r}.samples")] for r in range(R))
    for r in range(R):
        pixels[:, :, names.index(f"replicate{r}.samples")] = total if r == 0 else 0.0
    return names, pixels


def _shifted_means(names, pixels):
    pixels = pixels.copy()
    for r in range(R):
        pixels[:, :, names.index(f"replicate{r}.R")] += 5.0
    return names, pixels


def _huge_mean(names, pixels):
    pixels = pixels.copy()
    pixels[2, 5, names.index("replicate1.G")] = 3e38
    pixels[2, 5, names.index("replicate2.G")] = -3e38
    return names, pixels


@pytest.mark.parametrize("damage, words", [
    (_all_in_replicate_0, r"replicate counts exceed what the sample ranges"),
    (_shifted_means, r"replicate means do not pool to the pixel mean"),
    (_huge_mean, r"(do not pool|variance beyond what a 32-bit float holds)"),
])
def test_read_refuses_replicate_layers_that_contradict_the_file(small_scene, tmp_path, damage, words):
    """A Sobol EXR whose replicate layers contradict the rest of the file: every count moved
    into replicate 0 (the per-pixel sums still right; it would read with variance 0), every
    replicate mean shifted (the pixel mean left as it was), a pixel whose replicate means are
    huge and opposite. read_exr refuses each with an InputError naming the file, rather than
    let a merge or a resume carry a wrong variance (or fail at write, naming the output)."""
    path, bad = tmp_path / "good.exr", tmp_path / "bad.exr"
    write_exr(path, render_film(small_scene, "sobol", 16, 7))
    _rewrite_exr(path, bad, damage)
    read_exr(path)
    with pytest.raises(InputError, match=words) as caught:
        read_exr(bad)
    assert str(bad) in str(caught.value)


def test_half_float_references_of_both_samplers_read_back(small_scene, tmp_path):
    """References store their means as half floats (tracer reference's default) while the
    replicate means stay float32: the check that the replicate means pool to the pixel mean
    allows half's rounding, also for dark pixels where half floats are subnormal."""
    for sampler in QMC:
        film = render_film(small_scene, sampler, 64, 7)
        film.mean[:5] *= 1e-6  # dark pixels: half's subnormal range
        film.rep_mean[:5] *= 1e-6
        path = tmp_path / f"{sampler}.exr"
        write_exr(path, film, half=True)
        back = read_exr(path)
        assert back.replicates == R and np.array_equal(back.rep_count, film.rep_count)


def test_read_refuses_sobol_indices_beyond_the_sequence(small_scene, tmp_path):
    """A Sobol file whose tracer:samples lists indices past 8 x 2^32 (which the sampler cannot
    draw) is refused on read, naming the file; a render asking for them is refused before it
    starts, as is one that would put more than 2^24 samples in a replicate."""
    path = tmp_path / "far.exr"
    film = render_film(small_scene, "sobol", 8, 7)
    film.record = dataclasses.replace(film.record, samples=((7, 2**35, 2**35 + 8),))
    write_exr(path, film)
    with pytest.raises(InputError, match="beyond") as caught:
        read_exr(path)
    assert str(path) in str(caught.value)
    for settings in (RenderSettings(spp=8, seed=1, first_sample=2**35, sampler="sobol"),
                     RenderSettings(spp=R * 2**24 + R, seed=1, sampler="stratified")):
        with pytest.raises(InputError):
            render(small_scene, Strategy("mis"), settings)


UNEVEN = ((8, 1, 1, 1, 1, 1, 1, 1), (2, 2, 2, 2, 1, 1, 1, 1), (5, 3, 0, 0, 0, 0, 0, 0))


@pytest.mark.parametrize("counts", UNEVEN)
def test_variance_stays_unbiased_with_uneven_replicates(counts):
    """Pools of renders of fewer than 8 spp fill the replicates unevenly (sample s always goes
    to replicate s % 8). With i.i.d. N(0, 1) samples in 20,000 pixels, the film's estimate of
    the variance of the pixel mean, averaged, equals its true value 1 / n: a z-test of the mean
    of (estimate x n - 1) with its pixel-to-pixel standard error, Sidak over the 3 cases (the
    factor R'/(R'-1) used before was 22% low for counts 8, 1, ..., 1)."""
    from tracer.film import Film

    rng = np.random.default_rng(sum(counts))
    pixels, n = 20_000, sum(counts)
    film = Film(pixels, 1, replicates=R)
    for r, k in enumerate(counts):
        if k:
            # k samples of replicate r: sample indices r, r + 8, ..., folded one at a time.
            for j in range(k):
                film.add_block(0, rng.standard_normal((pixels, 1, 3)), r + R * j)
    assert np.array_equal(film.rep_count[0], counts)
    x = film.variance_of_mean()[:, 0] * n - 1.0
    z = x.mean() / (x.std(ddof=1) / math.sqrt(pixels))
    assert abs(z) < z_critical(3), f"mean of n x estimate = {x.mean() + 1:.4f}, z = {z:.2f}"


def test_one_replicate_falls_back_to_the_spread_of_samples(small_scene):
    """Four 1-spp Sobol renders of different seeds pooled hold every sample in replicate 0:
    with nothing to compare across replicates the variance is the per-sample spread (nonzero
    where the samples differ), not 0."""
    pooled = None
    for seed in range(1, 5):
        film = render_film(small_scene, "sobol", 1, seed)
        pooled = film if pooled is None else merge_renders(pooled, film)
    assert np.all(pooled.rep_count[:, 0] == 4) and np.all(pooled.rep_count[:, 1:] == 0)
    spread = pooled.m2 / 3.0
    np.testing.assert_allclose(pooled.variance(), spread, rtol=1e-12)
    assert np.any(pooled.variance() > 0)
