"""``--strategy auto`` (``tracer.auto``): which strategies it chooses among, that its render is
exactly a render of the strategy it chose (so it is as unbiased as that strategy, which the
closed-form and furnace tests check), that its choice is reproducible and uses none of the
render's random numbers, and that the choice it records is continued and refused where it must be.
Its bias on every stability case is tested with the suite's other columns (tests/test_stability.py:
``auto`` is one of its columns)."""

from __future__ import annotations

import numpy as np
import pytest

from tracer import auto
from tracer.errors import InputError
from tracer.lights import LightSampler
from tracer.render_loop import RenderSettings, render
from tracer.scene import load_scene
from tracer.scene.shipped import resolve_scene
from tracer.strategy import Strategy
from tracer.study import metrics
from tracer.study.stability import CASE_DIR

from stats import image_mean_and_se, z_critical


def slugs(scene) -> set[str]:
    return {s.slug for s in auto.candidates(scene, Strategy("auto"))}


def test_candidates_are_the_strategies_that_see_all_light():
    """A diffuse box under a rectangle light: bsdf, and light and mis with each light sampling
    (they differ on rectangles); a point light: nothing without light samples; a mirror: nothing
    without direction samples; a street of 1,124 lights: the light BVH as well."""
    cornell = slugs(load_scene(resolve_scene("cornell")))
    assert cornell == {"bsdf", "light", "mis", "light_solid-angle", "mis_solid-angle",
                       "light_solid-angle-cos", "mis_solid-angle-cos"}
    point = slugs(load_scene(resolve_scene("point_light")))
    assert point and all(not s.startswith("bsdf") for s in point)
    mirror = slugs(load_scene(CASE_DIR / "mirror_small_light.toml"))
    assert mirror and all(not s.startswith("light") for s in mirror)
    many = slugs(load_scene(resolve_scene("many_lights")))
    assert "mis_bvh-lights" in many and "mis" in many
    # The BVH from two lights on (its choice weighs distance, which power selection ignores).
    assert "light_bvh-lights" in slugs(load_scene(resolve_scene("veach_mis")))


def test_a_bvh_descent_costs_by_its_depth():
    """The counted cost of the BVH grows with the mean depth of its leaves, plus one level for
    the pick within the leaf: a tree of one leaf (a quad's two triangles) costs one level; the
    street's tree about twelve (the depth its fitted weight was counted with); the other
    strategies' cost does not depend on it."""
    assert auto.bvh_levels(np.array([0, 0])) == 1.0
    assert auto.bvh_levels(np.array([1, 2, 3])) == 3.0
    street = LightSampler(load_scene(resolve_scene("many_lights")), "bvh").tables.selection
    assert 11.0 < auto.bvh_levels(street.trail_depth) < 14.0
    bvh, power = Strategy("mis", light_selection="bvh"), Strategy("mis")
    few, many = (auto.cost_per_sample(bvh, 100, 100, 100, levels) for levels in (1.0, 12.0))
    assert many - few == pytest.approx(11 * auto.COSTS["bvh_level"] * 2)
    assert auto.cost_per_sample(power, 100, 100, 100, 1.0) == auto.cost_per_sample(power, 100, 100, 100, 12.0)


def test_candidates_keep_the_counts_and_heuristic_given():
    scene = load_scene(resolve_scene("cornell"))
    for s in auto.candidates(scene, Strategy("auto", "balance", light_samples=2, bsdf_samples=3)):
        assert (s.light_count, s.direction_count) in ((2, 3), (2, 0), (0, 3))
        assert s.name != "mis" or s.heuristic == "balance"
        # A render that continues one auto chose runs the strategy its record gives back.
        assert Strategy.from_record(s.to_record()) == s


def test_auto_takes_no_option_it_chooses_itself():
    for options in ({"light_sampling": "solid-angle"}, {"light_selection": "bvh"}, {"one_sample": True},
                    {"heuristic": "optimal"}):
        with pytest.raises(ValueError, match="auto"):
            Strategy("auto", **options)


def test_the_pilot_draws_none_of_the_renders_random_numbers():
    """A candidate's pilot seed is a 64-bit mix of the render's seed and the candidate's index:
    never a render seed of the first 4,000 (whose pilots these are), never shared by two
    candidates or two renders (checked over 4,000 seeds x 16 candidates)."""
    seeds = [auto.pilot_seed(s, i) for s in range(4_000) for i in range(16)]
    assert len(set(seeds)) == len(seeds)
    assert not set(seeds) & set(range(4_000))


def test_a_candidate_that_never_saw_the_light_is_not_taken_for_noiseless():
    """Four candidates on 100 pixels of 8 samples: three see each pixel's value 1 with sample
    variance 0.5, one saw nothing (mean 0, variance 0). Its own variance says relMSE 0; its
    disagreement with the other three says 8 x 1 per sample (less their noise, 1.5 / 9), in
    units of 1 / (m^2 + 0.01) with m the pooled mean 0.75. The three are charged the same for
    the missing one's pull on their comparison, so their order among themselves is kept."""
    spp = 8
    means = np.stack([np.ones((100, 3))] * 3 + [np.zeros((100, 3))])
    variances = np.stack([np.full((100, 3), 0.5)] * 3 + [np.zeros((100, 3))])
    relmse = auto.relmse_estimates(means, variances, spp)
    assert auto.RELMSE_EPSILON == metrics.RELMSE_EPSILON  # the pilot measures what compare reports
    scale = 1.0 / (0.75 ** 2 + auto.RELMSE_EPSILON)
    assert relmse[3] == pytest.approx((spp - 1.5 / 9) * scale, rel=1e-12)
    good = (spp * (1 / 3) ** 2 - 1.0 / 9) * scale  # others' mean 2/3; their noise (0.5 + 0.5) / 9
    np.testing.assert_allclose(relmse[:3], good, rtol=1e-12)
    assert relmse[3] > 8 * relmse[0]


def test_pilot_pixels_cover_the_image():
    assert len(auto.pilot_pixels(32, 32)) == 1024
    lattice = auto.pilot_pixels(512, 384)
    assert 3000 <= len(lattice) <= auto.PILOT_PIXELS and lattice.max() < 512 * 384
    rows, columns = np.divmod(lattice, 512)
    assert rows.min() < 8 and rows.max() > 384 - 8 and columns.min() < 8 and columns.max() > 512 - 8


@pytest.fixture(scope="module")
def small_cornell():
    return load_scene(resolve_scene("cornell"), 24, 24)


def test_auto_renders_exactly_the_strategy_it_chose(small_cornell):
    """auto's image is bit for bit the render of the strategy its record names, with the same
    seed: it adds no estimator of its own, so it is unbiased wherever its candidates are; its
    seconds include the pilot's; the record keeps what the pilot measured."""
    settings = RenderSettings(spp=8, seed=3, threads=2)
    chosen = render(small_cornell, Strategy("auto"), settings)
    record = chosen.film.record
    assert record.auto and record.strategy != "auto"
    strategy = Strategy.from_record(record)
    assert strategy in auto.candidates(small_cornell, Strategy("auto"))
    assert record.auto.startswith(strategy.slug + " 1;")
    fixed = render(small_cornell, strategy, settings)
    np.testing.assert_array_equal(chosen.film.mean, fixed.film.mean)
    again = render(small_cornell, Strategy("auto"), settings)
    assert again.film.record.auto == record.auto  # deterministic: the same choice and measures
    np.testing.assert_array_equal(again.film.mean, chosen.film.mean)


def test_auto_continues_the_strategy_it_chose(small_cornell):
    """More samples added to an auto render run the strategy it chose, without a new pilot (which
    could choose another, and the film could then not say what it holds)."""
    first = render(small_cornell, Strategy("auto"), RenderSettings(spp=4, seed=5, threads=1))
    more = render(small_cornell, Strategy("auto"), RenderSettings(spp=4, seed=5, threads=1, first_sample=4),
                  film=first.film)
    assert more.film.record.strategy == first.film.record.strategy
    assert more.film.record.auto == first.film.record.auto
    assert int(more.film.count.min()) == 8


def test_auto_never_chooses_the_technique_that_cannot_find_a_tiny_light():
    """On a sphere light of radius 1e-3 BSDF sampling almost never hits the light: its relMSE per
    sample is orders of magnitude above light sampling's, so a pilot that measures efficiency at
    all must not choose bsdf."""
    scene = load_scene(CASE_DIR / "tiny_light.toml", 32, 32)
    choice = auto.choose(scene, Strategy("auto"), seed=0)
    assert choice.strategy.name != "bsdf"


def test_auto_under_the_white_furnace_is_one(write_scene, tmp_path):
    """A closed sphere emitting radiance 1 inward around a white diffuse plate (the furnace of
    tests/test_estimators.py): every pixel's expected value is 1, whatever the pixel sees (the
    plate reflects exactly 1, the sphere emits 1). The image mean of auto's render (16 pixels x
    256 samples) is z-tested against 1 per channel at the Sidak level over the 3 channels (the
    channels share samples; Sidak's inequality holds for two-sided tests of jointly normal
    statistics of any correlation)."""
    from test_estimators import _furnace_scene

    scene = _furnace_scene(write_scene, tmp_path, 'type = "diffuse"\nreflectance = [1.0, 1.0, 1.0]')
    film = render(scene, Strategy("auto"), RenderSettings(spp=256, seed=11, threads=2)).film
    mean, se = image_mean_and_se(film)
    # A zero-variance choice (bsdf: exactly 1 here) must then be 1 to rounding.
    assert np.all(np.abs(mean - 1.0) <= z_critical(3) * se + 1e-9), (film.record.strategy, mean, se)


def test_a_distributed_render_refuses_auto():
    from tracer.cluster import refuse_undistributable

    with pytest.raises(InputError, match="auto"):
        refuse_undistributable(Strategy("auto"))


def test_single_technique_bounds_follow_the_second_moments():
    """The bound of :func:`auto.single_technique_bounds` on made-up pilots (exact arithmetic, no
    sampling): where every split has the same second moment S (the integrand is what each
    technique samples in proportion: zero variance), light and bsdf alone are bounded by 0;
    with S(1) = 9, S(a) = 1, S(0) = 3 (N = 2; mean 1 in every channel, so the scale is 1 /
    (1 + 0.01)) light alone (n = 1) has variance at least 9 - 1 = 8 and bsdf alone 3 - 1 = 2; a
    technique that cannot produce the light the other found (S = inf) is bounded by inf; light
    with solid-angle sampling takes its moments from mis with solid-angle sampling, not area;
    where the pixel's mean squared is below min S, the bound from E[Y^2] is the larger."""
    mis, light, bsdf = Strategy("mis"), Strategy("light"), Strategy("bsdf", light_samples=0)
    mean, variance = np.ones((4, 3)), np.zeros((4, 3))

    def pilot(moments):
        return auto.Pilot(mean, variance, 1.0, None if moments is None else np.tile(moments, (4, 1)))

    flat = auto.single_technique_bounds([mis, light, bsdf], [pilot([0.5, 0.5, 0.5]), pilot(None), pilot(None)])
    assert list(flat) == [0.0, 0.0, 0.0]
    tailed = auto.single_technique_bounds([mis, light, bsdf], [pilot([4.5, 0.5, 1.5]), pilot(None), pilot(None)])
    assert tailed[1] == pytest.approx(8.0 / 1.01) and tailed[2] == pytest.approx(2.0 / 1.01)
    blind = auto.single_technique_bounds([mis, light], [pilot([np.inf, 0.5, 0.5]), pilot(None)])
    assert blind[1] == np.inf
    solid = Strategy("mis", light_sampling="solid-angle")
    light_solid = Strategy("light", light_sampling="solid-angle")
    by_sampling = auto.single_technique_bounds([mis, solid, light_solid],
                                               [pilot([4.5, 0.5, 0.5]), pilot([1.0, 0.5, 0.5]), pilot(None)])
    assert by_sampling[2] == pytest.approx(1.0 / 1.01)
    # A pixel mean of 0.5 (m^2 = 0.25 below min S = 1): light's camera sample has E[Y^2] >= S(1)
    # = 9, so its variance is at least 9 - 0.25, more than 9 - min S; scale 1 / (0.25 + 0.01).
    mean[:] = 0.5
    dim = auto.single_technique_bounds([mis, light], [pilot([4.5, 0.5, 0.5]), pilot(None)])
    assert dim[1] == pytest.approx(8.75 / 0.26)


@pytest.mark.slow  # compiles veach_mis's learning build (about 35 s cold): CI's run took 15 min 15 s with it
def test_a_pilot_of_mis_sees_the_glossy_tail_of_light_sampling():
    """veach_mis's sharp plates reflect the big lights in a narrow lobe, which light samples
    reach rarely and at a great value: a pilot of light samples alone underestimates their
    variance. The bound from the mis pilot's second moments (which are not rare) is above what
    light's own pilot measured, as the equal-time runs say it must be (light is 0.06x mis at
    equal time there: benchmarks/results/equal_time.md)."""
    scene = load_scene(resolve_scene("veach_mis"), 48, 36)
    strategies = [Strategy("mis"), Strategy("light")]
    pixels = auto.pilot_pixels(48, 36)
    pilots = [auto.measure(scene, s, pixels, auto.pilot_seed(0, i)) for i, s in enumerate(strategies)]
    own = auto.relmse_estimates(np.array([p.mean for p in pilots]), np.array([p.variance for p in pilots]),
                                auto.PILOT_SPP)
    bound = auto.single_technique_bounds(strategies, pilots)
    assert pilots[0].moments is not None and pilots[1].moments is None
    assert bound[1] > 2.0 * own[1], (bound, own)
