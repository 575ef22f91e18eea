"""The materials Mitsuba scenes need: Fresnel terms, the Beckmann distribution, the conductor,
plastic and rough plastic models, one-sided materials and shading normals.

Deterministic identities (closed forms, algebraic identities between two code paths) state
their tolerance next to them. Statistical tests (chi-square of samplers, t- and z-tests of
means) run at Sidak levels over the tests of this file (``N_STAT``) or of one test function,
with fixed seeds; each says what it compares and why its bound holds.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, special
from scipy import stats as sps

from tracer.estimator import DirectLighting
from tracer.materials import Materials, microfacet
from tracer.scene import load_scene
from tracer.strategy import Strategy

import chi2
from stats import sidak, t_test_mean

N_SAMPLES = 300_000
GRID = (30, 60)
WO = {
    "normal": np.array([0.0, 0.0, 1.0]),
    "oblique": np.array([0.48, -0.64, 0.6]),
    "grazing": np.array([np.sqrt(0.99) * np.cos(2.2), np.sqrt(0.99) * np.sin(2.2), 0.1]),
}
BECKMANN_CASES = [(a, w) for a in (0.1, 0.5) for w in WO]
BSDF_CASES = [("roughconductor", "beckmann", 0.3, "oblique"), ("roughconductor", "beckmann", 0.08, "grazing"),
              ("plastic", None, None, "normal"), ("plastic", None, None, "grazing"),
              ("roughplastic", "beckmann", 0.2, "oblique"), ("roughplastic", "ggx", 0.4, "grazing"),
              ("pplastic", "beckmann", 0.1, "oblique"), ("pplastic", "ggx", 0.3, "grazing")]
N_STAT = len(BECKMANN_CASES) + len(BSDF_CASES)
ALPHA = chi2.sidak(N_STAT)


def rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([20261130, *key])


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def check(result: chi2.Chi2Result) -> None:
    print(result.report(3))
    assert result.passed, result.report()
    assert result.integration_chi2 < 0.1 * np.sqrt(2.0 * result.dof), result.report()


# ---------------------------------------------------------------------------------------------
# Fresnel terms


def test_conductor_fresnel_closed_forms():
    """At normal incidence F = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2); F -> 1 at grazing;
    eta = 0, k = 1 (Mitsuba's "none") is exactly 1 at every angle; with k = 0 and no total
    internal reflection the conductor formula is the dielectric one (two code paths, complex
    and real). Tolerance 1e-12: a handful of float64 operations."""
    for eta, k in ((0.2, 3.9), (1.1, 2.0), (2.9, 0.3), (1.5, 0.0)):
        expected = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
        assert abs(microfacet.fresnel_conductor_array(np.array([1.0]), eta, k)[0] - expected) < 1e-12
        assert microfacet.fresnel_conductor_array(np.array([1e-9]), eta, k)[0] > 1.0 - 1e-7
    cos = np.linspace(0.0, 1.0, 1001)
    assert np.all(microfacet.fresnel_conductor_array(cos, 0.0, 1.0) == 1.0)
    for eta in (1.33, 1.5, 2.4):
        np.testing.assert_allclose(microfacet.fresnel_conductor_array(cos[1:], eta, 0.0),
                                   microfacet.fresnel_dielectric_array(cos[1:], eta), rtol=1e-12, atol=1e-15)


def test_dielectric_fresnel_total_internal_reflection_and_symmetry():
    """From the dense side (eta < 1) F = 1 beyond the critical angle; F(cos_i, eta) from the
    outside equals F at the refracted angle from the inside (the Stokes relation, exact in
    the Fresnel equations). Tolerance 1e-12."""
    eta = 1.0 / 1.5
    critical = np.sqrt(1.0 - eta ** 2)
    assert np.all(microfacet.fresnel_dielectric_array(np.linspace(0.0, critical - 1e-9, 50), eta) == 1.0)
    assert np.all(microfacet.fresnel_dielectric_array(np.linspace(critical + 1e-6, 1.0, 50), eta) < 1.0)
    cos_i = np.linspace(0.01, 1.0, 100)
    cos_t = np.sqrt(1.0 - (1.0 - cos_i ** 2) / 1.5 ** 2)
    np.testing.assert_allclose(microfacet.fresnel_dielectric_array(cos_i, 1.5),
                               microfacet.fresnel_dielectric_array(cos_t, 1.0 / 1.5), rtol=1e-12)


@pytest.mark.parametrize("eta", [1.2, 1.49, 2.4])
def test_diffuse_fresnel_reflectance_identity(eta):
    """eta^2 (1 - Fdr(1/eta)) = 1 - Fdr(eta) (the hemispherical transmittances of the two sides
    balance; it makes the plastic's linear albedo exact): the quadrature must hold it to 1e-10,
    and Fdr(eta) must match scipy's adaptive quadrature of 2 int F mu dmu to 1e-10."""
    inside = microfacet.diffuse_fresnel_reflectance(1.0 / eta)
    outside = microfacet.diffuse_fresnel_reflectance(eta)
    assert abs(eta ** 2 * (1.0 - inside) - (1.0 - outside)) < 1e-10
    fresnel = microfacet.fresnel_dielectric_array
    reference = integrate.quad(lambda mu: 2.0 * mu * fresnel(np.array([mu]), eta)[0],
                               0.0, 1.0, epsabs=1e-13, epsrel=1e-13)[0]
    assert abs(outside - reference) < 1e-10


def test_erfinv_inverts_erf():
    """erf(erfinv(y)) = y to 4 ulp of 1 absolute, down to 1 - |y| = 1e-15, and scipy's erfinv
    agrees to 1e-13 relative: the Beckmann sampler's slopes are only as exact as this."""
    y = np.concatenate([np.linspace(-0.999999, 0.999999, 4001), 1.0 - np.logspace(-15, -1, 50),
                        -1.0 + np.logspace(-15, -1, 50)])
    x = np.array([microfacet.erfinv(v) for v in y])
    assert np.max(np.abs(special.erf(x) - y)) < 2e-16 * 4
    np.testing.assert_allclose(x, special.erfinv(y), rtol=1e-13, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# Beckmann


@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_beckmann_is_normalized(alpha):
    """Projected-area normalization: int D(h) cos(theta_h) dh = 1 over the hemisphere, by
    adaptive quadrature: within 1e-7 of 1, with quadpack's error estimate below that."""
    def integrand(theta):
        c = np.cos(theta)
        return 2.0 * np.pi * microfacet.beckmann_d_cos2(c * c, alpha) * c * np.sin(theta)
    value, error = integrate.quad(integrand, 0.0, np.pi / 2 - 1e-12, limit=200, epsabs=1e-12)
    assert error < 1e-7 and abs(value - 1.0) < 1e-7


@pytest.mark.parametrize("alpha,wo_name", BECKMANN_CASES)
def test_beckmann_visible_normals_chi2(alpha, wo_name):
    """Half vectors from the Beckmann visible-normal sampler vs. the density G1(wo) max(0, wo.h)
    D(h) / wo.z in solid angle, which integrates to 1 exactly when G1 is Smith's for D (so the
    integral also checks Lambda): (theta, phi) cells over the hemisphere; level ALPHA."""
    wo = WO[wo_name]
    gen = rng(1, int(alpha * 100), list(WO).index(wo_name))
    n = N_SAMPLES
    h = microfacet.sample_visible_normals(gen.random((n, 2)), np.tile(wo, (n, 1)), np.full(n, alpha),
                                          microfacet.BECKMANN)
    np.testing.assert_allclose(np.linalg.norm(h, axis=1), 1.0, atol=1e-12)

    def pdf(hh):
        return microfacet.visible_normal_pdf(hh, np.tile(wo, (len(hh), 1)), np.full(len(hh), alpha),
                                             microfacet.BECKMANN)
    # A cap around the normal holding all but ~1e-8 of the mass (slopes beyond 4.5 alpha); the
    # rest cell expects what lies outside.
    domain = chi2.spherical_domain((0.0, 0.0, 1.0), min(np.pi / 2, np.arctan(4.5 * alpha)), polar="theta")
    result = chi2.goodness_of_fit(h, pdf, domain, GRID, ALPHA, name=f"beckmann vndf a={alpha} wo={wo_name}")
    check(result)


# ---------------------------------------------------------------------------------------------
# BSDFs


def bsdf(type_name: str, n: int, distribution=None, alpha=None, **values) -> Materials:
    """n lanes of one material; parameters not given take their defaults."""
    params = {k: np.tile(np.asarray(v, dtype=np.float64), (n, 1)) if np.ndim(v) else np.full(n, float(v))
              for k, v in values.items()}
    if alpha is not None:
        params["alpha"] = np.full(n, alpha)
    if distribution is not None:
        params["distribution"] = np.full(n, float(microfacet.DISTRIBUTIONS.index(distribution)))
    return Materials.per_lane(type_name, params)


SMALL = 8  # lanes of a material built for its parameters (derived tables are per lane)


def lanes(material: Materials, n: int) -> Materials:
    """n lanes of the material in row 1 (its tables computed once)."""
    return Materials(material.table, np.ones(n, dtype=np.int64))


@pytest.mark.parametrize("type_name,distribution,alpha,wo_name", BSDF_CASES)
def test_bsdf_sampling_chi2(type_name, distribution, alpha, wo_name):
    """sample() directions vs. Materials.pdf over the whole sphere in (cos theta, phi): valid
    non-delta samples in the cells, delta samples (the plastic's coating) and invalid ones
    (rough reflections below the horizon) in the rest cell, which expects N (1 - integral of
    pdf): so the test also checks that pdf is the density sample() really produces, including
    the lobe-selection probabilities. Level ALPHA."""
    wo = WO[wo_name]
    values = ({"reflectance": [0.9, 0.6, 0.3], "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2]}
              if type_name == "roughconductor" else {"diffuse_reflectance": [0.7, 0.5, 0.3]})
    one = bsdf(type_name, 1, distribution, alpha, **values)
    n = N_SAMPLES
    m = lanes(one, n)
    gen = rng(2, BSDF_CASES.index((type_name, distribution, alpha, wo_name)))
    s = m.sample(gen.random((n, 3)), np.tile(wo, (n, 1)))
    valid = (s.pdf > 0.0) & ~s.delta
    assert np.all(s.weight[s.flags == 0] == 0.0)

    def pdf(wi):
        return lanes(one, len(wi)).pdf(np.tile(wo, (len(wi), 1)), wi)
    if type_name == "roughconductor":  # a cap around the lobe
        domain = chi2.spherical_domain(wo * [-1.0, -1.0, 1.0], min(np.pi, 2.0 * np.arctan(5.0 * alpha)))
    else:  # lobes with a diffuse part: the whole sphere
        domain = chi2.spherical_domain(polar="z")
    result = chi2.goodness_of_fit(s.wi, pdf, domain, GRID, ALPHA, valid=valid,
                                  name=f"{type_name} {distribution} a={alpha} wo={wo_name}")
    check(result)


@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
def test_pplastic_is_a_dielectric_reflector_plus_an_attenuated_diffuse(distribution):
    """pplastic's two terms through two other code paths: with a black diffuse_reflectance its
    f is roughconductor's with k = 0 (whose Fresnel term is then the dielectric one: tested
    above) and the same eta and alpha; with a black specular_reflectance it is the closed form
    diffuse (1 - F(cos_o)) (1 - F(cos_i)) / pi. The whole f is their sum, and f is 0 whenever
    either direction is below the surface. Tolerance 1e-12 relative: a few float64 operations
    in a different order."""
    gen = rng(9, microfacet.DISTRIBUTIONS.index(distribution))
    n = 2000
    wo, wi = unit(gen.normal(size=(n, 3))), unit(gen.normal(size=(n, 3)))
    eta, alpha = 1.7, 0.25
    specular, diffuse = np.array([0.9, 0.5, 0.7]), np.array([0.2, 0.6, 0.4])
    common = dict(int_ior=eta, ext_ior=1.0)
    only_specular = lanes(bsdf("pplastic", 1, distribution, alpha, diffuse_reflectance=[0.0] * 3,
                               specular_reflectance=specular, **common), n).eval(wo, wi)
    metal = lanes(bsdf("roughconductor", 1, distribution, alpha, reflectance=specular, eta=[eta] * 3,
                       k=[0.0] * 3), n).eval(wo, wi)
    np.testing.assert_allclose(only_specular, metal, rtol=1e-12, atol=1e-300)
    only_diffuse = lanes(bsdf("pplastic", 1, distribution, alpha, diffuse_reflectance=diffuse,
                              specular_reflectance=[0.0] * 3, **common), n).eval(wo, wi)
    above = (wo[:, 2] > 0) & (wi[:, 2] > 0)
    fresnel = microfacet.fresnel_dielectric_array
    attenuation = np.zeros(n)
    attenuation[above] = ((1 - fresnel(wo[above, 2], eta)) * (1 - fresnel(wi[above, 2], eta)) / np.pi)
    np.testing.assert_allclose(only_diffuse, attenuation[:, None] * diffuse, rtol=1e-12, atol=1e-300)
    both = lanes(bsdf("pplastic", 1, distribution, alpha, diffuse_reflectance=diffuse,
                      specular_reflectance=specular, **common), n).eval(wo, wi)
    np.testing.assert_allclose(both, only_specular + only_diffuse, rtol=1e-12, atol=1e-300)
    assert np.all(both[~above] == 0.0) and np.all(both[above].sum(axis=1) > 0.0)


def test_conductor_reflects_by_fresnel():
    """The smooth conductor's one sample is the mirror direction with weight reflectance x
    F(cos_o; eta + i k) per channel, exactly the Fresnel function's value (same code path:
    tolerance 0), and pdf 0 with the DELTA flag."""
    n = 100
    gen = rng(3)
    wo = unit(gen.random((n, 3)) + [0.0, 0.0, 0.05])
    one = bsdf("conductor", 1, reflectance=[0.9, 0.8, 0.7], eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 2.2])
    s = lanes(one, n).sample(gen.random((n, 3)), wo)
    assert np.all(s.delta) and np.all(s.pdf == 0.0)
    np.testing.assert_array_equal(s.wi, wo * [-1.0, -1.0, 1.0])
    for c, (r, eta, k) in enumerate(zip([0.9, 0.8, 0.7], [0.2, 0.9, 1.1], [3.9, 2.4, 2.2], strict=True)):
        fresnel = microfacet.fresnel_conductor_array(wo[:, 2], eta, k)
        np.testing.assert_array_equal(s.weight[:, c], r * fresnel)


def _mean_weight(material: Materials, wo: np.ndarray, n: int, gen) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of sample weights (delta ones included) at one wo: the
    directional albedo, unbiased whatever the lobes."""
    s = lanes(material, n).sample(gen.random((n, 3)), np.tile(wo, (n, 1)))
    return s.weight.mean(axis=0), s.weight.std(axis=0, ddof=1) / np.sqrt(n)


@pytest.mark.parametrize("nonlinear", [False, True])
def test_plastic_albedo_is_its_closed_form(nonlinear):
    """The plastic's directional albedo (the mean sample weight, coating and base) is
    spec F(cos_o) + (1 - F(cos_o)) R (1 - Fdr_int) / (1 - Fdr_int) in the linear model, i.e.
    spec F + R (1 - F), and spec F + (1 - F) R (1 - Fdr_int) / (1 - R Fdr_int) with
    ``nonlinear`` (both from eta^2 (1 - Fdr_int) = 1 - Fdr_ext). z-test of 200,000 weights per
    wo, Sidak over 3 wo x 3 channels x 2 modes (the weights are bounded: the normal
    approximation of the mean holds)."""
    diffuse, specular = np.array([0.8, 0.5, 0.2]), np.array([1.0, 0.7, 0.9])
    one = bsdf("plastic", 1, diffuse_reflectance=diffuse, specular_reflectance=specular, int_ior=1.6,
               ext_ior=1.05, nonlinear=float(nonlinear))
    eta = 1.6 / 1.05
    fdr_int = microfacet.diffuse_fresnel_reflectance(1.0 / eta)
    gen = rng(4, int(nonlinear))
    for wo in WO.values():
        f = microfacet.fresnel_dielectric_array(np.array([wo[2]]), eta)[0]
        base = diffuse * (1 - fdr_int) / (1 - diffuse * fdr_int) if nonlinear else diffuse
        expected = specular * f + (1 - f) * base
        mean, se = _mean_weight(one, wo, 200_000, gen)
        z = (mean - expected) / se
        assert np.all(2 * sps.norm.sf(np.abs(z)) > sidak(3 * 3 * 2)), (wo, mean, expected)


@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
def test_roughplastic_transmittance_table_and_energy(distribution):
    """T(mu) = E[(1 - F(wo.h)) G1(wt)] over the visible normals, wt the refraction of wo about h
    (Mitsuba 3's definition): the material's interpolated table against a Monte Carlo estimate
    written here with numpy, with random points, at four angles (z-test; the table's own error,
    from the 64 x 64 midpoint rule and the interpolation, measured against a 256 x 256 rule at
    mu 0.05 .. 1, is at most 7e-4 (GGX) and 5e-4 (Beckmann) at this alpha; 1e-3 is added to the
    standard error as a third of the bound's width); and the whole material's albedo with white
    reflectances is at most 1 (one-sided test on the mean of bounded weights: Mitsuba's model
    is not energy-exact, but loses energy, never creates it). Sidak over 4 angles x 2 checks."""
    alpha = 0.3
    one = bsdf("roughplastic", 1, distribution, alpha, diffuse_reflectance=[1.0, 1.0, 1.0])
    eta = 1.49 / 1.000277
    gen = rng(5, microfacet.DISTRIBUTIONS.index(distribution))
    level = sidak(8)
    code = microfacet.DISTRIBUTIONS.index(distribution)
    n = 100_000
    from tracer.materials import roughplastic
    for mu in (0.05, 0.3, 0.7, 1.0):
        wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
        u = gen.random((n, 2))
        h = microfacet.sample_visible_normals(u, np.tile(wo, (n, 1)), np.full(n, alpha), code)
        cos_i = h @ wo
        cos2_t = 1.0 - (1.0 - cos_i ** 2) / eta ** 2
        k = cos_i / eta - np.sqrt(np.maximum(cos2_t, 0.0))
        wt = -wo / eta + k[:, None] * h
        ok = (cos_i > 0) & (cos2_t > 0) & (wt[:, 2] < 0) & (np.sum(wt * h, axis=1) < 0)
        g1 = np.array([microfacet.g1(z, alpha, code) for z in np.where(ok, -wt[:, 2], 0.0)])
        fresnel = microfacet.fresnel_dielectric_array(np.maximum(cos_i, 0.0), eta)
        value = np.where(ok, (1.0 - fresnel) * g1, 0.0)
        table = roughplastic.transmittance(one.table.params, 1, mu)
        z = (table - value.mean()) / (value.std(ddof=1) / np.sqrt(n) + 1e-3 / 3)
        assert 2 * sps.norm.sf(abs(z)) > level, (mu, table, value.mean())
        mean, se = _mean_weight(one, wo, n, gen)
        assert np.all(mean - 1.0 < sps.norm.isf(level) * se), (mu, mean)


# ---------------------------------------------------------------------------------------------
# The estimator: furnace, one-sided materials, shading normals


def _furnace(write_scene, tmp_path, material: str):
    from test_estimators import _furnace_scene
    return _furnace_scene(write_scene, tmp_path, material)


def test_furnace_plastic_is_its_closed_form(write_scene, tmp_path):
    """A plastic plate in a closed sphere of radiance 1 reflects its directional albedo
    spec F(cos_o) + R (1 - F(cos_o)) (linear model) toward the camera: BSDF sampling (which
    sees the delta coating) and MIS (whose BSDF half does) are t-tested against it, Sidak over
    2 strategies x 3 channels; light sampling alone cannot see the coating's delta lobe and
    must give exactly the base's part R (1 - F), in the mean (same test)."""
    scene = _furnace(write_scene, tmp_path, 'type = "plastic"\ndiffuse_reflectance = [0.8, 0.5, 0.2]\n'
                                            'int_ior = 1.5\next_ior = 1.0')
    from test_estimators import shoot_at
    origins, dirs, _ = shoot_at(np.array([[0.0, 0.0, 0.0]]), 60_000)
    cos_o = float(-dirs[0] @ np.array([0.0, 1.0, 0.0]))
    f = microfacet.fresnel_dielectric_array(np.array([cos_o]), 1.5)[0]
    base = np.array([0.8, 0.5, 0.2]) * (1 - f)
    level = sidak(3 * 3)
    for i, (name, expected) in enumerate((("bsdf", f + base), ("mis", f + base), ("light", base))):
        radiance = DirectLighting(scene, Strategy(name)).radiance(origins, dirs, seed=30 + i)
        assert np.all(t_test_mean(radiance, expected) > level), (name, radiance.mean(axis=0), expected)


@pytest.mark.parametrize("material", [
    'type = "roughplastic"\ndistribution = "beckmann"\nalpha = 0.2\ndiffuse_reflectance = [0.6, 0.4, 0.2]',
    'type = "roughconductor"\ndistribution = "beckmann"\nalpha = 0.3\nreflectance = [1.0, 1.0, 1.0]\n'
    'eta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.2]',
    'type = "pplastic"\ndistribution = "ggx"\nalpha = 0.15\ndiffuse_reflectance = [0.6, 0.4, 0.2]'])
def test_furnace_new_materials_agree_across_strategies(write_scene, tmp_path, material):
    """Under uniform radiance 1 every strategy estimates the same directional albedo: uniform,
    cosine, light and MIS against BSDF sampling, two-sample z-tests Sidak over 3 materials x
    4 strategies x 3 channels (60,000 samples each; the weights are bounded by a few units)."""
    scene = _furnace(write_scene, tmp_path, material)
    from test_estimators import shoot_at
    origins, dirs, _ = shoot_at(np.array([[0.0, 0.0, 0.0]]), 60_000)
    ref = DirectLighting(scene, Strategy("bsdf")).radiance(origins, dirs, seed=1)
    ref_mean, ref_var = ref.mean(axis=0), ref.var(axis=0, ddof=1) / len(ref)
    level = sidak(3 * 4 * 3)
    for i, name in enumerate(["uniform", "cosine", "light", "mis"]):
        radiance = DirectLighting(scene, Strategy(name)).radiance(origins, dirs, seed=40 + i)
        se = np.sqrt(radiance.var(axis=0, ddof=1) / len(radiance) + ref_var)
        z = (radiance.mean(axis=0) - ref_mean) / se
        assert np.all(2 * sps.norm.sf(np.abs(z)) > level), (name, radiance.mean(axis=0), ref_mean)


PLANE_AND_LIGHT = """
[camera]
origin = [0.0, 3.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 8

[materials.plane]
type = "diffuse"
reflectance = [0.5, 0.5, 0.5]
{sides}

[[shapes]]
type = "{plane_type}"
{plane}
material = "plane"

[[shapes]]
type = "quad"
origin = [-0.4, 1.0, -0.3]
edge1 = [0.8, 0.0, 0.0]
edge2 = [0.0, 0.0, 0.6]
emission = [4.0, 2.0, 1.0]
"""
QUAD_UP = 'origin = [-5.0, 0.0, -5.0]\nedge1 = [0.0, 0.0, 10.0]\nedge2 = [10.0, 0.0, 0.0]'
QUAD_DOWN = 'origin = [-5.0, 0.0, -5.0]\nedge1 = [10.0, 0.0, 0.0]\nedge2 = [0.0, 0.0, 10.0]'


def test_one_sided_material_is_black_from_behind(write_scene):
    """A one-sided (``twosided = false``) diffuse plane whose normal points away from the
    camera and the light reflects exactly nothing; flipped to face them it reflects exactly
    what the two-sided material does (same seed, same samples: bit for bit)."""
    from test_estimators import shoot_at
    origins, dirs, _ = shoot_at(np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.2]]), 2000)

    def render(plane: str, sides: str) -> np.ndarray:
        scene = load_scene(write_scene(PLANE_AND_LIGHT.format(plane_type="quad", plane=plane, sides=sides)))
        return DirectLighting(scene, Strategy("mis")).radiance(origins, dirs, seed=3)
    assert np.all(render(QUAD_DOWN, "twosided = false") == 0.0)
    front = render(QUAD_UP, "twosided = false")
    assert front.mean() > 0.01
    np.testing.assert_array_equal(front, render(QUAD_UP, ""))
    np.testing.assert_array_equal(front, render(QUAD_DOWN, "twosided = true"))


def _tilted_plane(tmp_path, tilt: np.ndarray) -> str:
    """A 10 x 10 plane of two triangles at y = 0 facing +y whose three vertex normals all equal
    ``tilt``: interpolation gives that normal everywhere."""
    vertices = np.array([[-5.0, 0.0, -5.0], [-5.0, 0.0, 5.0], [5.0, 0.0, 5.0], [5.0, 0.0, -5.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    header = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
              "property double z\nproperty double nx\nproperty double ny\nproperty double nz\n"
              "element face 2\nproperty list uchar int vertex_indices\nend_header\n")
    body = "".join(" ".join(repr(float(c)) for c in (*v, *tilt)) + "\n" for v in vertices)
    body += "".join("3 " + " ".join(str(i) for i in f) + "\n" for f in faces)
    (tmp_path / "tilted.ply").write_text(header + body)
    return 'file = "tilted.ply"\nnormals = "vertex"'


def test_shading_normal_gives_the_closed_form_of_the_tilted_surface(write_scene, tmp_path):
    """A flat plane whose vertex normals are all tilted to n' shades as a diffuse surface with
    normal n' would: the radiance at x is rho / pi * Le * (Lambert's polygon irradiance about
    n'), for a light wholly above both planes. Every strategy is t-tested against it (Sidak
    over 5 strategies x 2 points x 3 channels): this checks that f, cos and the sampling
    frame all use the shading normal, and that the light pdf and ray offsets (geometric)
    still make the techniques agree."""
    from test_estimators import polygon_irradiance, quad_corners, shoot_at
    tilt = unit([0.25, 1.0, 0.1])
    plane = _tilted_plane(tmp_path, tilt)
    scene = load_scene(write_scene(PLANE_AND_LIGHT.format(plane_type="mesh", plane=plane, sides="")))
    points = np.array([[0.0, 0.0, 0.0], [0.6, 0.0, 0.4]])
    corners = quad_corners([-0.4, 1.0, -0.3], [0.8, 0.0, 0.0], [0.0, 0.0, 0.6])
    origins, dirs, which = shoot_at(points, 40_000)
    level = sidak(5 * 2 * 3)
    for i, name in enumerate(["light", "bsdf", "cosine", "mis", "mis-one"]):
        strategy = Strategy("mis", one_sample=True) if name == "mis-one" else Strategy(name)
        radiance = DirectLighting(scene, strategy).radiance(origins, dirs, seed=50 + i)
        for p, x in enumerate(points):
            expected = 0.5 / np.pi * np.array([4.0, 2.0, 1.0]) * polygon_irradiance(x, tilt, corners)
            assert np.all(t_test_mean(radiance[which == p], expected) > level), (name, x, expected)


def test_smooth_sphere_strategies_agree(write_scene, tmp_path):
    """On a smooth (vertex-normal) icosphere of rough plastic under a quad light, where sampled
    directions do fall below the geometric surface near the silhouette, light, BSDF, MIS and
    one-sample MIS estimate the same radiance at each of 3 points: two-sample z-tests against
    MIS (balance), Sidak over 3 strategies x 3 points x 3 channels."""
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    sphere.export(tmp_path / "ball.ply")
    scene = load_scene(write_scene("""
        [camera]
        origin = [0.0, 0.5, 4.0]
        target = [0.0, 0.0, 0.0]
        fov = 40.0
        width = 8
        height = 8

        [materials.coat]
        type = "roughplastic"
        alpha = 0.3
        diffuse_reflectance = [0.6, 0.4, 0.2]

        [[shapes]]
        type = "mesh"
        file = "ball.ply"
        normals = "vertex"
        material = "coat"

        [[shapes]]
        type = "quad"
        origin = [-1.0, 2.0, -1.0]
        edge1 = [2.0, 0.0, 0.0]
        edge2 = [0.0, 0.0, 2.0]
        emission = [3.0, 3.0, 3.0]
        """))
    targets = np.array([[0.0, 0.5, 0.8], [0.6, 0.7, 0.2], [-0.9, 0.3, 0.1]])
    origins = np.tile([0.0, 0.5, 4.0], (3, 1)).astype(np.float64)
    which = np.repeat(np.arange(3), 40_000)
    dirs = unit(targets - origins)[which]
    origins = origins[which]
    ref = DirectLighting(scene, Strategy("mis", "balance")).radiance(origins, dirs, seed=60)
    level = sidak(3 * 3 * 3)
    for i, strategy in enumerate([Strategy("light"), Strategy("bsdf"), Strategy("mis", one_sample=True)]):
        radiance = DirectLighting(scene, strategy).radiance(origins, dirs, seed=61 + i)
        for p in range(3):
            a, b = radiance[which == p], ref[which == p]
            z = (a.mean(axis=0) - b.mean(axis=0)) / np.sqrt(a.var(axis=0, ddof=1) / len(a)
                                                            + b.var(axis=0, ddof=1) / len(b) + 1e-300)
            assert np.all(2 * sps.norm.sf(np.abs(z)) > level), (strategy, p, a.mean(axis=0), b.mean(axis=0))
