"""The smooth dielectrics (``dielectric``, ``thindielectric``): their delta lobes, the other side
of an interface, and how scenes read them.

The interface contract (lobes declared, pdf 0 for delta samples, weights finite) is checked for
every type in tests/test_sampling.py, and agreement with Mitsuba 3 on a scene of glass in
tests/test_mitsuba_agreement.py (``tracer/scenes/mitsuba/glass.xml``). Here: each sample's
direction and weight against Fresnel's and Snell's laws exactly, and the lobe frequencies
against the Fresnel reflectance with a binomial bound.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tracer import materials, plugins
from tracer.materials import Materials
from tracer.materials.microfacet import fresnel_dielectric_array


def rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([20261202, *key])


def upper(n: int, gen: np.random.Generator) -> np.ndarray:
    """n unit directions with z in (1e-3, 1]: wo as the estimator hands it (toward the viewer)."""
    z = gen.uniform(1e-3, 1.0, n)
    phi = gen.uniform(0.0, 2.0 * np.pi, n)
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def lanes(type_name: str, n: int, gen: np.random.Generator, eta: np.ndarray):
    """n lanes of ``type_name`` with relative index ``eta`` per lane (ext_ior 1) and random
    scales."""
    refl, trans = gen.uniform(0.0, 1.0, (n, 3)), gen.uniform(0.0, 1.0, (n, 3))
    b = Materials.per_lane(type_name, {"specular_reflectance": refl, "specular_transmittance": trans,
                                       "int_ior": eta, "ext_ior": np.ones(n)})
    return b, refl, trans


# eta > 1: light arriving from outside glass; eta < 1: from inside (a row seen from behind),
# where directions beyond the critical angle reflect totally.
@pytest.mark.parametrize("eta_range", [(1.01, 3.0), (1 / 3.0, 1 / 1.01)])
def test_dielectric_samples_follow_fresnel_and_snell(eta_range):
    """With u_lobe uniform, a lane reflects exactly when u_lobe < F(cos_o) (the Fresnel
    reflectance, 1 beyond the critical angle): the mirror direction (a sign flip, exact) with
    weight = specular_reflectance; otherwise the refracted direction, which is a unit vector
    below the surface with its tangential part -wo_xy / eta (Snell) and weight =
    specular_transmittance / eta^2 (radiance across the interface), to rounding. pdf 0, DELTA."""
    n = 40_000
    gen = rng(1, int(eta_range[0] > 1))
    eta = gen.uniform(*eta_range, n)
    b, refl, trans = lanes("dielectric", n, gen, eta)
    wo = upper(n, gen)
    u = gen.random((n, 3))
    s = b.sample(u, wo)
    f = np.array([fresnel_dielectric_array(wo[i:i + 1, 2], eta[i])[0] for i in range(n)])
    reflected = u[:, 0] < f
    assert np.all(s.flags == materials.DELTA) and np.all(s.pdf == 0.0)
    np.testing.assert_array_equal(s.wi[reflected], wo[reflected] * [-1.0, -1.0, 1.0])
    np.testing.assert_array_equal(s.weight[reflected], refl[reflected])
    t = ~reflected
    np.testing.assert_allclose(np.linalg.norm(s.wi[t], axis=1), 1.0, rtol=1e-12)
    assert np.all(s.wi[t, 2] < 0.0)
    np.testing.assert_allclose(s.wi[t, :2], -wo[t, :2] / eta[t, None], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.weight[t], trans[t] / eta[t, None] ** 2, rtol=1e-12)
    if eta_range[1] < 1.0:  # beyond the critical angle, every sample reflects
        total = 1.0 - wo[:, 2] ** 2 > eta ** 2
        assert total.sum() > 1000 and np.all(reflected[total])


def test_thindielectric_samples_reflect_or_pass_straight_through():
    """A pane reflects with probability R' = 2R / (1 + R) (R: one face's Fresnel reflectance):
    the mirror direction with weight = specular_reflectance; else wi = -wo exactly with weight =
    specular_transmittance (the two refractions cancel; no 1 / eta^2)."""
    n = 20_000
    gen = rng(2)
    eta = gen.uniform(1.01, 3.0, n)
    b, refl, trans = lanes("thindielectric", n, gen, eta)
    wo = upper(n, gen)
    u = gen.random((n, 3))
    s = b.sample(u, wo)
    r = np.array([fresnel_dielectric_array(wo[i:i + 1, 2], eta[i])[0] for i in range(n)])
    reflected = u[:, 0] < 2.0 * r / (1.0 + r)
    np.testing.assert_array_equal(s.wi[reflected], wo[reflected] * [-1.0, -1.0, 1.0])
    np.testing.assert_array_equal(s.weight[reflected], refl[reflected])
    np.testing.assert_array_equal(s.wi[~reflected], -wo[~reflected])
    np.testing.assert_array_equal(s.weight[~reflected], trans[~reflected])


@pytest.mark.parametrize("type_name", ["dielectric", "thindielectric"])
def test_lobe_frequencies_match_the_reflectance(type_name):
    """At one wo (60 degrees) and eta 1.5, the share of reflected samples among N = 200,000 is
    binomial with p = the lobe's reflectance (F, or 2F / (1 + F) for the pane): the two-sided
    exact binomial test at alpha = 1e-3 (random u, so this checks the sampler's use of u_lobe,
    not only the threshold)."""
    n = 200_000
    gen = rng(3, ["dielectric", "thindielectric"].index(type_name))
    b = Materials.uniform(type_name, n, int_ior=1.5, ext_ior=1.0)
    wo = np.tile([np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)], (n, 1))
    s = b.sample(gen.random((n, 3)), wo)
    f = fresnel_dielectric_array(np.array([0.5]), 1.5)[0]
    p = f if type_name == "dielectric" else 2.0 * f / (1.0 + f)
    k = int(np.sum(s.wi[:, 2] > 0.0))
    assert stats.binomtest(k, n, p).pvalue > 1e-3, (k / n, p)


def test_a_dielectric_seen_from_behind_shades_with_eta_inverted():
    """MaterialTable.shading: a two-sided dielectric gets a row of its parameters with the
    indices swapped (eta -> 1 / eta), named by ``behind``; a thin pane (the same from both sides)
    and a diffuse material are their own back; a one-sided material is black from behind (-1)."""
    table = materials.table([("glass", "dielectric", {"int_ior": 1.5, "ext_ior": 1.2}),
                             ("pane", "thindielectric", {}), ("wall", "diffuse", {"reflectance": 0.5}),
                             ("one", "dielectric", {})], twosided=[True, True, True, False])
    kind, params, behind = table.shading(plugins.by_code("material"))
    assert len(kind) == 6 and list(behind[:5]) == [0, 5, 2, 3, -1]
    t = materials.TYPES["dielectric"]
    eta = t.column("eta")
    assert params[1, eta] == pytest.approx(1.25) and params[5, eta] == pytest.approx(0.8)
    assert kind[5] == t.code and behind[5] == 5
    np.testing.assert_array_equal(params[:5], table.params)


def test_a_camera_inside_glass_sees_the_light_outside_brighter_by_eta_squared(tmp_path):
    """A camera behind a dielectric quad (behind its normal: inside, eta 1.33) looking at an
    emitter of radiance 1 beyond it, with BSDF sampling: a reflected sample sees nothing, a
    refracted one carries 1.33^2 (radiance in the denser medium) and is taken with probability
    1 - F, so every sample is 0 or 1.33^2 exactly and each pixel's count k of refracted
    samples out of 256 is binomial with p = 1 - F(cos theta), theta the sample's angle to the
    axis: at most the corner of the 4 degree field (tan theta <= tan 2 deg sqrt 2), so p lies in
    [1 - F(cos theta_max), 1 - F(1)] (F from inside, eta 1/1.33). Each of the 16 pixels passes
    an exact two-sided binomial test at the interval's ends (k within the Sidak-corrected
    quantiles of p_lo and p_hi; family rate 1%): no normal approximation, which is poor at
    n p (1 - p) = 5."""
    from tracer import load_scene, render

    scene = tmp_path / "inside.toml"
    scene.write_text("""
[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 4.0
width = 4
height = 4
[materials.glass]
type = "dielectric"
int_ior = 1.33
ext_ior = 1.0
[[shapes]]
type = "quad"
origin = [-2.0, -2.0, 0.0]
edge1 = [0.0, 4.0, 0.0]
edge2 = [4.0, 0.0, 0.0]
material = "glass"
[[shapes]]
type = "quad"
origin = [-5.0, -5.0, -3.0]
edge1 = [10.0, 0.0, 0.0]
edge2 = [0.0, 10.0, 0.0]
emission = [1.0, 1.0, 1.0]
""")
    n = 256
    image = render(load_scene(str(scene)), "bsdf", spp=n, seed=4)
    theta_max = np.arctan(np.tan(np.radians(2.0)) * np.sqrt(2.0))
    f = fresnel_dielectric_array(np.array([1.0, np.cos(theta_max)]), 1.0 / 1.33)
    p_hi, p_lo = 1.0 - f[0], 1.0 - f[1]
    k = image.mean[..., 0].astype(np.float64) * n / 1.33 ** 2  # refracted samples per pixel
    np.testing.assert_allclose(k, np.round(k), atol=1e-3)  # whole counts: samples are 0 or eta^2
    alpha = 1.0 - 0.99 ** (1.0 / k.size)
    lo, hi = stats.binom.ppf(alpha / 2.0, n, p_lo), stats.binom.isf(alpha / 2.0, n, p_hi)
    assert np.all((np.round(k) >= lo) & (np.round(k) <= hi)), (np.round(k), lo, hi)
