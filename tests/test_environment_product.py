"""Product sampling of the environment (``environment_sampling = "product"``;
tracer/lights/environment_product.py): the sampler against its own pdf for receivers of every
kind of lobe, the pdf's normalization and positivity, its reduction to luminance sampling for a
lobe it does not know, and that light sampling, MIS and RIS with it estimate the image that MIS
with luminance sampling does.

Seeds are fixed; every statistical test is at the suite's 1% family-wise rate (tests/stats.py),
Šidák-corrected over what it compares.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from test_environment import SKY_SCENE, _map

import tracer
from tracer.jit import jit
from tracer.lights import environment as light
from tracer.lights import environment_product as product
from tracer.scene import shipped_folder
from tracer.scene.environment import Environment
from tracer.strategy import Strategy

import chi2
from stats import z_critical

# (name, material lobe (kd, ks, ku, alpha), shading normal, wo reflected about it): a diffuse
# receiver facing sideways, glossy lobes sharp and broad at a grazing mirror direction, a
# mixture, and the uniform lobe of a material the proxy does not know.
_N = np.array([0.3, 0.8, -0.52]) / np.linalg.norm([0.3, 0.8, -0.52])
_M = np.array([0.9, 0.1, 0.42]) / np.linalg.norm([0.9, 0.1, 0.42])
LOBES = [("diffuse", (0.8, 0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
         ("sharp glossy", (0.0, 1.0, 0.0, 0.05), tuple(_N), tuple(_M)),
         ("broad glossy", (0.0, 0.9, 0.0, 0.4), tuple(_N), tuple(_M)),
         ("plastic", (0.6, 0.4, 0.0, 0.2), (0.0, 1.0, 0.0), (0.6, 0.8, 0.0)),
         ("uniform", (0.0, 0.0, 1.0, 1.0), (0.0, 0.0, 1.0), (0.0, 0.0, 1.0))]


@jit
def _sample(env, material_lobe, normal, mirror, u):
    lobe = product.lobe_in_map(env.to_map, material_lobe, normal, mirror)
    wi, le, p = np.empty((len(u), 3)), np.empty((len(u), 3)), np.empty(len(u))
    for i in range(len(u)):
        w, radiance, p[i] = light.sample_product(env, lobe, u[i, 0], u[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, le, p


@jit
def _pdf(env, material_lobe, normal, mirror, wi):
    lobe = product.lobe_in_map(env.to_map, material_lobe, normal, mirror)
    out = np.empty(len(wi))
    for i in range(len(wi)):
        out[i] = light.pdf_product(env, lobe, (wi[i, 0], wi[i, 1], wi[i, 2]))
    return out


@jit
def _luminance_pdf(env, wi):
    out = np.empty(len(wi))
    for i in range(len(wi)):
        out[i] = light.pdf(env, (wi[i, 0], wi[i, 1], wi[i, 2]))
    return out


@jit
def _tree_sum(env, material_lobe, normal, mirror):
    lobe = product.lobe_in_map(env.to_map, material_lobe, normal, mirror)
    blocks = env.product
    rows, columns = len(blocks.row_edge) - 1, len(blocks.column_edge) - 1
    total = 0.0
    for i in range(rows):
        for j in range(columns):
            total += product.tree_probability(blocks, lobe, i, j)
    return total


def _maps():
    """The small test map (8 x 16 cells: blocks of one cell at the finest level) and a larger
    one (40 x 100 cells: blocks of uneven sizes, some 1 and some 2 cells wide at level 5)."""
    rng = np.random.default_rng(8)
    texels = rng.uniform(0.0, 0.3, (41, 100, 3)).astype(np.float32)
    texels[9:15, 66:76] = 20.0  # a sun
    texels[25:, :] *= 0.1  # a dim ground
    turned = Environment(texels, np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]))
    return {"small": _map(), "large": turned}


CASES = [(m, lobe) for m in ("small", "large") for lobe in LOBES]
# CI budget: the large map's cases (7-11 s each) run with -m slow but for its broad glossy lobe,
# the one whose blocks the walk weighs least evenly; the small map's run every time.
FAST_LARGE = ("broad glossy",)


@pytest.mark.parametrize("map_name, case", [
    pytest.param(m, c, marks=pytest.mark.slow) if m == "large" and c[0] not in FAST_LARGE else (m, c)
    for m, c in CASES], ids=[f"{m}-{c[0]}" for m, c in CASES])
def test_samples_follow_the_pdf(map_name, case):
    """χ² of 300,000 samples on the whole sphere, in equal-area bins that do not align with the
    map's cells or blocks, against ``pdf_product`` integrated per bin by cubature (mass 1: the
    pdf is normalized, which ``test_the_pdf_is_positive...`` checks exactly); each sample's pdf is
    the pdf function's at its direction (but where rounding puts it across a cell edge). Ten
    tests, Šidák at the suite's rate."""
    _, material_lobe, normal, mirror = case
    table = light.table(_maps()[map_name], 0, "product")
    u = np.random.default_rng([52, CASES.index((map_name, case))]).random((300_000, 2))
    wi, _, p = _sample(table, material_lobe, normal, mirror, u)
    assert np.all(p > 0.0)
    assert np.isclose(_pdf(table, material_lobe, normal, mirror, wi), p, rtol=1e-12).mean() > 0.999
    domain = chi2.spherical_domain((0.0, 1.0, 0.0), np.pi, polar="z")
    result = chi2.goodness_of_fit(
        wi, lambda w: _pdf(table, material_lobe, normal, mirror, np.ascontiguousarray(w)), domain, (24, 48),
        chi2.sidak(len(CASES)), mass=1.0, name=f"product sampler, {case[0]}, {map_name} map")
    assert result.passed, result.report()


def test_the_pdf_is_positive_wherever_luminance_sampling_is_and_sums_to_one():
    """The floor keeps every cell that luminance sampling can pick pickable by product sampling
    (so light sampling alone stays unbiased with it), for every lobe, on directions drawn
    uniformly; and the block probabilities of the descent sum to 1 over the finest blocks.
    Deterministic up to rounding."""
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(20_000, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    for env in _maps().values():
        table = light.table(env, 0, "product")
        seen = _luminance_pdf(table, wi) > 0.0
        for _, material_lobe, normal, mirror in LOBES:
            p = _pdf(table, material_lobe, normal, mirror, wi)
            np.testing.assert_array_equal(p > 0.0, seen)
            assert _tree_sum(table, material_lobe, normal, mirror) == pytest.approx(1.0, rel=1e-12)


def test_a_lobe_it_does_not_know_gives_luminance_sampling():
    """A material without a lobe proxy (ku only) weighs every block by its luminance share alone,
    so the product pdf is the luminance pdf, to rounding."""
    rng = np.random.default_rng(6)
    wi = rng.normal(size=(5_000, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    for env in _maps().values():
        table = light.table(env, 0, "product")
        _, material_lobe, normal, mirror = LOBES[-1]
        np.testing.assert_allclose(_pdf(table, material_lobe, normal, mirror, wi), _luminance_pdf(table, wi),
                                   rtol=1e-10)


def test_blocks_partition_the_cells():
    """Every finest block's cell range is where ``row_block`` and ``column_block`` send its cells,
    and the levels' luminance shares sum to 1 each (each level partitions the map)."""
    for env in _maps().values():
        blocks = light.table(env, 0, "product").product
        for edge, of_cell in ((blocks.row_edge, blocks.row_block), (blocks.column_edge, blocks.column_block)):
            for b in range(len(edge) - 1):
                assert np.all(of_cell[edge[b]:edge[b + 1]] == b)
        starts = blocks.level_start
        for level in range(len(starts) - 1):
            share = blocks.block[starts[level]:starts[level + 1], product.ENERGY].sum()
            assert share == pytest.approx(1.0, rel=1e-12)


def test_strategies_that_take_product_sampling():
    """Product sampling is valid without BSDF samples (its pdf is positive wherever the map's is):
    light, mis and ris take it, and their names and records say so."""
    for strategy in (Strategy("light", environment_sampling="product"),
                     Strategy("mis", environment_sampling="product"),
                     Strategy.ris(8, "light+bsdf", environment_sampling="product")):
        assert strategy.to_record()["environment_sampling"] == "product"
        assert "product-environment" in strategy.slug and "product environment" in strategy.label


# CI budget (41 s, mostly compiling four feature sets): runs with -m slow; in every run the
# stability suite's product columns test light and MIS with product sampling for bias on its
# three environment cases.
@pytest.mark.slow
def test_product_sampling_estimates_the_same_image(tmp_path):
    """Under the shipped sky map (a hot sun, turned and scaled) with an area light, over diffuse,
    rough-conductor and plastic surfaces, light sampling, MIS and RIS (light and BSDF candidates)
    with product environment sampling estimate the image that MIS with luminance sampling does:
    the image means per channel differ by less than z standard errors of their difference (Šidák
    over 3 strategies x 3 channels; the standard error from per-pixel variances summed over
    independent pixels; channels tested apart, never summed). A pdf that disagreed with the
    sampler, or MIS weights from another pdf than the one sampled, would bias these means."""
    shutil.copy(shipped_folder() / "mitsuba" / "textures" / "sky.exr", tmp_path / "sky.exr")
    (tmp_path / "sky.toml").write_text(SKY_SCENE)
    scene = tracer.load_scene(str(tmp_path / "sky.toml"))

    def estimate(strategy, seed):
        image = tracer.render(scene, strategy, spp=128, seed=seed)
        pixels = image.mean.reshape(-1, 3).astype(np.float64)
        var_of_mean = (image.variance.reshape(-1, 3) / image.count.reshape(-1, 1)).astype(np.float64)
        return pixels.mean(axis=0), np.sqrt(var_of_mean.sum(axis=0)) / len(pixels)

    mean0, error0 = estimate(Strategy("mis"), 30)
    candidates = (Strategy("light", environment_sampling="product"),
                  Strategy("mis", environment_sampling="product"),
                  Strategy.ris(8, "light+bsdf", environment_sampling="product"))
    for seed, strategy in enumerate(candidates):
        mean, error = estimate(strategy, 31 + seed)
        z = (mean - mean0) / np.hypot(error, error0)
        assert np.all(np.abs(z) < z_critical(3 * 3)), (strategy.name, z)
