"""Optimal MIS and adaptive allocation (``tracer.tuning``): unbiased for whatever they learn,
reproducible bit for bit, and usable from the command line.

The estimator of a pass is unbiased for *any* control-variate coefficient a and any expected
light count n̄_l in (0, N): what is learned only moves the variance. So the tests here force
tunings, including absurd ones (a = 40, a pilot that called one technique useless), and test
the means against closed forms; that a learned tuning is good is the benchmark's business
(``benchmarks/optimal_mis.py``), and the 1-D optimum is tested in ``test_primer``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_estimators import ANALYTIC_SCENE, POINTS, expected_radiance, shoot_at

from tracer import samplers, tuning
from tracer.cli import main
from tracer.estimator import DirectLighting
from tracer.imagefiles import read_exr
from tracer.render_loop import Batch, RenderSettings, render
from tracer.scene import load_scene
from tracer.strategy import Strategy
from tracer.tuning import relearns

from stats import sidak, t_test_mean

# Strategies that learn: optimal MIS at two sample counts, adaptive allocation with each kind
# of heuristic, and one-sample MIS with a per-pixel technique probability.
LEARNING = [
    Strategy("mis", "optimal"),
    Strategy("mis", "optimal", light_samples=2, bsdf_samples=3),
    Strategy("mis", "balance", allocation="adaptive"),
    Strategy("mis", "optimal", light_samples=2, bsdf_samples=1, allocation="adaptive"),
    Strategy("mis", "power", light_samples=3, bsdf_samples=1, one_sample=True, allocation="adaptive"),
]
# (share of light samples, a per channel): the pilot's split, extremes that call one technique
# useless, a split that makes the counts random, and coefficients far from any optimum.
TUNINGS = [(None, (0.0, 0.0, 0.0)), (0.05, (5.0, -2.0, 40.0)), (0.95, (-30.0, 1.0, 0.5)),
           (0.3, (0.7, 0.7, 0.7))]


def forced(strategy: Strategy, share: float | None, alpha) -> tuning.Tuning:
    """A tuning for lanes of pixel 0: light share ``share`` of the strategy's N (None: the
    pilot's counts) and coefficient ``alpha`` (RGB)."""
    total = 1.0 if strategy.one_sample_mis else strategy.light_count + strategy.direction_count
    light_count = np.zeros((0, 1)) if share is None or not strategy.adaptive else np.array([[share * total]])
    return tuning.Tuning(light_count, np.array([[alpha]], dtype=np.float64), tuning.SHARES, 1, 1, True)


def shade(estimator: DirectLighting, origins, dirs, tuned: tuning.Tuning, seed: int) -> np.ndarray:
    """Radiance of rays as independent samples of pixel 0 under ``tuned``: V + a C."""
    n = len(origins)
    sample = np.arange(n, dtype=np.int64)
    radiance, lane_stats = estimator.shade_lanes(
        np.ascontiguousarray(origins, dtype=np.float32), np.ascontiguousarray(dirs, dtype=np.float32),
        samplers.make("independent", seed, 0, n), np.zeros(n, dtype=np.int64), sample, tuned)
    if estimator.plan.optimal:
        radiance = radiance + tuned.alpha[0, 0] * lane_stats[:, tuning.CONTROL, None]
    return radiance


def test_any_tuning_is_unbiased_on_the_closed_form_scene(write_scene):
    """Each learning strategy under each forced tuning (shares of light samples from 0.05 to
    0.95, with random counts in between; coefficients a up to 40): the mean radiance at four
    points of the closed-form scene against rho/pi E, one-sample t-tests of 20,000 samples per
    strategy x tuning x point x channel, Sidak over all (1% family false-alarm rate). A control
    variate C whose mean is not exactly 0 (a sample counted by one technique and not the other)
    would be multiplied by a = 40 into a bias of many standard errors; weights that used the
    drawn counts instead of the expected ones would bias every random-count split."""
    scene = load_scene(write_scene(ANALYTIC_SCENE))
    expected = np.array([expected_radiance(x) for x in POINTS])
    origins, dirs, which = shoot_at(POINTS, 20_000)
    level = sidak(len(LEARNING) * len(TUNINGS) * len(POINTS) * 3)
    failures = []
    for i, strategy in enumerate(LEARNING):
        estimator = DirectLighting(scene, strategy)
        for j, (share, alpha) in enumerate(TUNINGS):
            radiance = shade(estimator, origins, dirs, forced(strategy, share, alpha), seed=500 + 10 * i + j)
            assert np.all(np.isfinite(radiance))
            for p in range(len(POINTS)):
                pvalues = t_test_mean(radiance[which == p], expected[p])
                if np.any(pvalues < level):
                    failures.append(f"{strategy.label} share {share} a {alpha}: point {POINTS[p]} "
                                    f"mean {radiance[which == p].mean(axis=0)} expected {expected[p]}")
    assert not failures, "\n".join(failures)


MIRROR_SCENE = """
[camera]
origin = [0.0, 1.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 30.0
width = 4
height = 4

[materials.mirror]
type = "mirror"
reflectance = [0.9, 0.6, 0.3]

[[shapes]]
type = "quad"
origin = [-2.0, 0.0, -2.0]
edge1 = [0.0, 0.0, 4.0]
edge2 = [4.0, 0.0, 0.0]
material = "mirror"

[[shapes]]                      # a wide panel facing the mirror, where its reflections go
type = "quad"
origin = [-3.0, 3.0, -6.0]
edge1 = [0.0, -3.0, -3.0]
edge2 = [6.0, 0.0, 0.0]
emission = [2.0, 3.0, 4.0]
"""


def test_light_only_a_starved_technique_reaches_is_still_counted(write_scene):
    """A pixel where the pilot says BSDF sampling is useless, while only it can see the light:
    a mirror (delta lobe) reflecting a panel, with 95% of the samples given to light sampling,
    which never reaches the reflection. Each camera sample then takes a BSDF sample with
    probability 0.1 (N = 2) and divides by the expected count, so the mean is still the exact
    reflectance x Le (t-test of 40,000 samples per channel, Sidak over 3 x 2 strategies);
    and where the pilot saw nothing at all the pilot's split stays."""
    scene = load_scene(write_scene(MIRROR_SCENE))
    origins = np.tile([0.0, 1.0, 3.0], (40_000, 1))
    dirs = np.tile(-origins[0] / np.linalg.norm(origins[0]), (40_000, 1))
    expected = np.array([0.9, 0.6, 0.3]) * np.array([2.0, 3.0, 4.0])
    level = sidak(6)
    for strategy in (Strategy("mis", "balance", allocation="adaptive"),
                     Strategy("mis", "optimal", allocation="adaptive")):
        tuned = forced(strategy, 0.95, (3.0, 3.0, 3.0))
        radiance = shade(DirectLighting(scene, strategy), origins, dirs, tuned, seed=77)
        assert 0.05 < np.mean(radiance[:, 0] > 0.0) < 0.15  # a BSDF sample in ~10% of camera samples
        assert np.all(t_test_mean(radiance, expected) > level), (strategy.label, radiance.mean(axis=0))
    empty = np.zeros((1, 1, tuning.SUM_COLUMNS))
    assert tuning.best_light_count(empty, tuning.SHARES, 2.0, 1.0, False)[0, 0] == 1.0


def test_learning_is_scheduled_at_doubling_passes():
    """Passes 1, 2, 4, 8, ... learn again, before their first batch only."""
    k = 8
    learned = [p for p in range(40) if relearns(Batch(100 + p * k, k, 0, 16), 100, k)]
    assert learned == [1, 2, 4, 8, 16, 32]
    assert not relearns(Batch(100 + 4 * k, k, 16, 16), 100, k)


@pytest.mark.parametrize("sampler", ["independent", "sobol"])
def test_learning_renders_are_reproducible(sampler):
    """Optimal MIS with adaptive allocation learns between passes, yet the image depends only
    on the seed: 1 or 2 threads and batches of 4,096 or 512 lanes give the same bits (each pass
    learns from the passes before it only, merged in a fixed order), and the EXR-bound maps of
    what was learned are the same. With replicates (sobol), each half learns from the other."""
    from conftest import SCENES

    scene = load_scene(SCENES / "veach_mis.toml", 24, 18)
    strategy = Strategy("mis", "optimal", allocation="adaptive")
    # 24 x 18 pixels take passes of 75 spp (small images take more per pass): 6 passes.
    films = [render(scene, strategy, RenderSettings(spp=450, seed=3, threads=threads, batch_lanes=lanes,
                                                    sampler=sampler)).film
             for threads, lanes in ((1, 4096), (2, 512))]
    assert np.array_equal(films[0].mean, films[1].mean) and np.array_equal(films[0].m2, films[1].m2)
    assert sorted(films[0].learned) == ["allocation.light", "alpha.B", "alpha.G", "alpha.R"]
    for name, plane in films[0].learned.items():
        assert np.array_equal(plane, films[1].learned[name]), name
    share = films[0].learned["allocation.light"]
    assert np.all((share >= tuning.SHARES[0]) & (share <= tuning.SHARES[-1]))
    assert len(np.unique(share)) > 1  # the split differs between pixels


def test_command_line_writes_what_was_learned(tmp_path, capsys):
    """``tracer render --heuristic optimal --allocation adaptive`` names its output by both,
    records the allocation in the header and writes the maps as channels beside the image."""
    from conftest import SCENES

    out = tmp_path / "v.exr"
    assert main(["render", str(SCENES / "veach_mis.toml"), "--width", "32", "--height", "24", "--spp", "24",
                 "--heuristic", "optimal", "--allocation", "adaptive", "-o", str(out), "--quiet"]) == 0
    film = read_exr(out)
    assert film.record.heuristic == "optimal" and film.record.allocation == "adaptive"
    import OpenImageIO as oiio

    names = set(oiio.ImageInput.open(str(out)).spec().channelnames)
    assert {"allocation.light", "alpha.R", "alpha.G", "alpha.B"} <= names


@pytest.mark.parametrize("args, words", [
    (["--strategy", "light", "--allocation", "adaptive"], "needs the mis strategy"),
    (["--strategy", "mis", "--bsdf-samples", "0", "--allocation", "adaptive"], "needs the mis strategy"),
    (["--strategy", "ris", "--ris-sources", "light+bsdf", "--heuristic", "optimal"], "ris cannot use"),
])
def test_settings_that_cannot_learn_are_refused(args, words, tmp_path, capsys):
    """Adaptive allocation splits two techniques, so it needs mis with both; ris resamples in
    proportion to its weights, which optimal MIS may make negative: one line, exit 2."""
    from conftest import SCENES

    status = main(["render", str(SCENES / "cornell.toml"), "--spp", "1", "-o", str(tmp_path / "x.exr"),
                   *args])
    err = capsys.readouterr().err
    assert status == 2 and words in err and len(err.strip().splitlines()) == 1, err


# A claim of efficiency, not of correctness (unbiasedness on these cases is test_stability's),
# and 15 s of the 15-minute CI budget: run with -m slow.
@pytest.mark.slow
def test_learning_is_not_worse_than_balance_beyond_its_noise_on_the_stability_cases():
    """On every stability case (the failure cases of each technique: tiny, huge, grazing and
    occluded lights, mirrors, near-specular lobes, point lights, degenerate meshes), optimal MIS
    and adaptive allocation against the balance heuristic at the same 64 spp: per pixel, d =
    relative squared error of the learning render minus that of the balance render, both against
    one 1024-spp reference (whose own noise cancels in d). The bound: the mean of d must not be
    above 0 by more than its sampling noise, i.e. the one-sided bootstrap interval of mean d
    over the case's pixels (2,000 resamples; no normality assumed, the errors are heavy-tailed)
    must reach down to 0, at a Sidak level over cases x 2 (1% family false-alarm rate). Optimal
    MIS uses the balance render's seed, so d isolates what its control variate adds; adaptive
    allocation draws other counts, so its d also carries the two renders' independent noise."""
    from tracer.study import metrics, stability

    cases = stability.cases(size=16)
    level = sidak(2 * len(cases))
    rng = np.random.default_rng(17)
    failures = []
    for i, case in enumerate(cases):
        scene = stability.load_case(case)
        counts = (case.light_samples, case.bsdf_samples)

        def image(heuristic, spp, seed, allocation="fixed", scene=scene, counts=counts):
            strategy = Strategy("mis", heuristic, *counts, allocation=allocation)
            return render(scene, strategy, RenderSettings(spp=spp, seed=seed, threads=2)).film.mean

        reference = image("balance", 1024, 10_000 + i)
        balance = image("balance", 64, i)
        error_balance = metrics.relative_squared_error(balance, reference).mean(axis=1)
        for name, learned in (("optimal", image("optimal", 64, i)),
                              ("adaptive", image("balance", 64, i, "adaptive"))):
            d = metrics.relative_squared_error(learned, reference).mean(axis=1) - error_balance
            means = d[rng.integers(0, len(d), size=(2000, len(d)))].mean(axis=1)
            if np.quantile(means, level) > 0.0:
                failures.append(f"{case.name} {name}: relMSE {error_balance.mean() + d.mean():.4g} "
                                f"against balance {error_balance.mean():.4g}")
    assert not failures, "\n".join(failures)


def test_allocation_pools_each_pixel_with_its_neighbours():
    """The allocation's statistics of a pixel are the sums over the 7 x 7 pixels around it,
    clipped at the image's edges (checked against slicing, on an image that is not square)."""
    rng = np.random.default_rng(0)
    height, width = 9, 13
    sums = rng.random((height * width, 2, 5))
    boxed = tuning._box_sum(sums, height, width, tuning.NEIGHBOURS, np.empty_like(sums),
                            np.empty_like(sums)).reshape(height, width, 2, 5)
    image = sums.reshape(height, width, 2, 5)
    r = tuning.NEIGHBOURS
    for y in range(height):
        for x in range(width):
            window = image[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1].sum(axis=(0, 1))
            assert np.allclose(boxed[y, x], window), (y, x)


def test_allocation_with_replicates_is_learned_once_from_the_pilot():
    """With a replicate sampler, adaptive allocation learns from the pilot only and keeps it:
    once a group has been rendered with counts learned from the other group's pilot, its sums
    carry information about the other group's own points (tracer.tuning, Samplers with
    replicates). Adding more sums changes nothing, and the renders stop collecting them."""
    learner = tuning.Learner(16, 4, 8, 1.0, 2.0, True, True)
    rng = np.random.default_rng(5)
    learner.add(0, rng.random((16, 2, tuning.SUM_COLUMNS)) * 10)
    first = learner.tuning()
    assert learner.settled and not first.collect
    learner.add(0, rng.random((16, 2, tuning.SUM_COLUMNS)) * 10)
    assert learner.tuning() is first
    independent = tuning.Learner(16, 4, 0, 1.0, 2.0, True, True)
    independent.add(0, rng.random((16, 1, tuning.SUM_COLUMNS)) * 10)
    assert not independent.settled and independent.tuning().collect
