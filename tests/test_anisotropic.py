"""Anisotropic roughness: ``roughconductor`` with ``alpha_v`` (Mitsuba's alpha_u, alpha_v).

What is checked here, and what elsewhere:

- values and pdfs at fixed directions against Mitsuba 3.9.1's ``roughconductor`` (this file);
- the sampler's directions against its pdf (chi-square), and the pdf's and D's normalization
  (cubature) (this file);
- pdf, weight and eval consistency on random anisotropic rows: the interface contract of
  ``tests/test_sampling.py`` draws alpha_v over its range for every run;
- the tangent frame (s along dp/du on meshes with and without coordinates, on a sphere, under
  a normal map, and textured alpha_u / alpha_v): the image of
  ``tracer/scenes/mitsuba/anisotropic.xml`` against Mitsuba's (``tests/test_mitsuba_agreement.py``);
- readers: XML and TOML give the same rows; refusals (this file).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
from test_sampling import check, rng, unit

import tracer
from tracer.errors import InputError
from tracer.materials import Materials, microfacet
from tracer.materials import roughconductor as rc

import chi2

# Mitsuba 3.9.1 (scalar_rgb), roughconductor with material "none" (F = 1), sample_visible on:
# (distribution, alpha_u, alpha_v, wo, wi, f = eval / wi.z, pdf). Mitsuba's wi is tracer's wo.
# Measured with mi.load_dict(...).eval(ctx, si, wi) / wi.z and .pdf, si.wi = wo on a z-up frame
# (directions normalized from the rounded ones written here).
MITSUBA = [
    ("ggx", 0.05, 0.3, (0.48, -0.64, 0.6), (-0.3, 0.5, 0.81), 0.19348685953540792, 0.15837904810905457),
    ("ggx", 0.05, 0.3, (0.1, 0.7, 0.5), (-0.2, -0.75, 0.4), 0.5409860383688198, 0.2661052942276001),
    ("ggx", 0.05, 0.3, (-0.8, 0.2, 0.3), (0.7, -0.1, 0.6), 0.20255011796319902, 0.13124234974384308),
    ("ggx", 0.4, 0.04, (0.48, -0.64, 0.6), (-0.3, 0.5, 0.81), 0.20314860439534616, 0.16579675674438477),
    ("ggx", 0.4, 0.04, (0.1, 0.7, 0.5), (-0.2, -0.75, 0.4), 2.894441354748476, 1.3408366441726685),
    ("ggx", 0.4, 0.04, (-0.8, 0.2, 0.3), (0.7, -0.1, 0.6), 0.17446662646515804, 0.11872364580631256),
    ("beckmann", 0.35, 0.06, (0.48, -0.64, 0.6), (-0.3, 0.5, 0.81), 0.4851208983442306, 0.393716424703598),
    ("beckmann", 0.35, 0.06, (0.1, 0.7, 0.5), (-0.2, -0.75, 0.4), 6.883266623026281, 3.1530776023864746),
    ("beckmann", 0.35, 0.06, (-0.8, 0.2, 0.3), (0.7, -0.1, 0.6), 0.24673012546262582, 0.1596335619688034),
]


def anisotropic(distribution: str, alpha_u: float, alpha_v: float, n: int) -> Materials:
    return Materials.per_lane("roughconductor", {
        "reflectance": np.ones((n, 3)), "alpha": np.full(n, alpha_u), "alpha_v": np.full(n, alpha_v),
        "distribution": np.full(n, float(["ggx", "beckmann"].index(distribution)))})


@pytest.mark.parametrize("case", MITSUBA, ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}")
def test_values_and_pdfs_are_mitsubas(case):
    """f and pdf at fixed direction pairs equal Mitsuba's: GGX to 2e-5 (Mitsuba computes in
    float32: a few roundings of ~6e-8 through a peak's division); Beckmann to 5e-3, because
    Mitsuba's Beckmann G1 is Walter et al.'s rational fit, which differs from tracer's exact
    Smith G1 by up to about 0.3% (``microfacet`` says so), and two G1 enter f."""
    distribution, alpha_u, alpha_v, wo, wi, f_mitsuba, pdf_mitsuba = case
    wo, wi = unit(np.array([wo])), unit(np.array([wi]))
    b = anisotropic(distribution, alpha_u, alpha_v, 1)
    rtol = 2e-5 if distribution == "ggx" else 5e-3
    np.testing.assert_allclose(b.eval(wo, wi)[0], f_mitsuba, rtol=rtol)
    np.testing.assert_allclose(b.pdf(wo, wi)[0], pdf_mitsuba, rtol=rtol)


def test_alpha_v_equal_to_alpha_is_the_isotropic_material():
    """An anisotropic row whose two roughnesses are equal gives the isotropic values (to float
    rounding: different formulas), so the anisotropic D, G1 and warp reduce correctly."""
    gen = rng(31)
    n = 20_000
    wo, wi = unit(gen.normal(size=(n, 3)) * [1, 1, 0] + [0, 0, 1.2]), unit(gen.normal(size=(n, 3)))
    wi[:, 2] = np.abs(wi[:, 2])
    for distribution in ("ggx", "beckmann"):
        iso = anisotropic(distribution, 0.3, 0.0, n)
        same = anisotropic(distribution, 0.3, 0.3, n)
        np.testing.assert_allclose(same.eval(wo, wi), iso.eval(wo, wi), rtol=1e-9)
        np.testing.assert_allclose(same.pdf(wo, wi), iso.pdf(wo, wi), rtol=1e-9)


# (distribution, alpha_u, alpha_v, wo): an azimuth off both axes, so that a swapped or
# mis-stretched axis shows; grazing and steep. Two cases run in the fast suite.
CHI2_CASES = [("ggx", 0.08, 0.5, (0.48, -0.64, 0.6)), ("beckmann", 0.4, 0.07, (-0.9, 0.3, 0.2)),
              pytest.param("ggx", 0.6, 0.05, (-0.9, 0.3, 0.2), marks=pytest.mark.slow),
              pytest.param("beckmann", 0.1, 0.3, (0.48, -0.64, 0.6), marks=pytest.mark.slow)]
ALPHA = chi2.sidak(len(CHI2_CASES))


@pytest.mark.parametrize("distribution, alpha_u, alpha_v, wo", CHI2_CASES)
def test_sampled_directions_follow_the_pdf(distribution, alpha_u, alpha_v, wo):
    """sample() directions vs Materials.pdf on the upper hemisphere, (theta, phi) cells: a
    chi-square goodness of fit with the samples that fall below the surface (pdf 0, weight 0)
    in the rest cell, at a family level of 0.01 over this file's cases (Sidak); the expected
    counts come from adaptive cubature of the pdf, whose error the check bounds."""
    wo = unit(np.array(wo))
    n = 500_000
    b = anisotropic(distribution, alpha_u, alpha_v, n)
    gen = rng(32, int(1000 * alpha_u), int(1000 * alpha_v))
    s = b.sample(gen.random((n, 3)), np.tile(wo, (n, 1)))
    invalid = s.pdf <= 0.0
    assert np.all(s.weight[invalid] == 0.0) and np.all(s.wi[invalid, 2] <= 0.0)

    def pdf(wi):
        return anisotropic(distribution, alpha_u, alpha_v, len(wi)).pdf(np.tile(wo, (len(wi), 1)), wi)

    result = chi2.goodness_of_fit(s.wi, pdf, chi2.spherical_domain((0.0, 0.0, 1.0), np.pi / 2.0),
                                  (40, 80), ALPHA, valid=~invalid,
                                  name=f"{distribution} {alpha_u}/{alpha_v}")
    check(result)


@numba.njit(cache=False)
def _densities(points, wo, alpha_u, alpha_v, distribution, which):
    """(m,) over unit vectors ``points``: which 0, D(h) h.z of h = point; which 1, q(wi) =
    G1(wo) D(h) / (4 wo.z) with h = normalize(wo + wi), the density of reflect(wo, h) for h
    from the visible normals (0 where h.z <= 0), from tracer's own D and G1."""
    out = np.zeros(len(points))
    o = (wo[0], wo[1], wo[2])
    g1_o = microfacet.g1(o[2], microfacet.projected_alpha(o, alpha_u, alpha_v), distribution)
    for i in range(len(points)):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        if which == 1:
            x, y, z = x + o[0], y + o[1], z + o[2]
        length = np.sqrt(x * x + y * y + z * z)
        if not length > 0.0 or z <= 0.0:
            continue
        h = (x / length, y / length, z / length)
        d = microfacet.d_anisotropic(h, alpha_u, alpha_v, distribution)
        out[i] = d * h[2] if which == 0 else g1_o * d / (4.0 * o[2])
    return out


@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
def test_d_and_the_visible_normal_density_are_normalized(distribution):
    """Adaptive cubature (every discontinuity on a cell boundary; 1e-6 is > 10x its reported
    error, and a wrong stretch or normalization is O(alpha_u / alpha_v - 1)): the integral of
    D(h) cos(theta_h) over the hemisphere is 1; q(wi), the density of reflect(wo, h) before
    any direction is lost below the surface, integrates to 1 over the sphere, which holds only
    if G1 (through the projected roughness) is the projected-area normalization of this D
    (Heitz 2014); and Materials.pdf is q above the surface (pointwise, 1e-9)."""
    wo = unit(np.array([0.3, -0.5, 0.5]))
    alpha_u, alpha_v = 0.45, 0.12
    code = ["ggx", "beckmann"].index(distribution)

    def d_cos(h):
        return _densities(h, wo, alpha_u, alpha_v, code, 0)

    def q(wi):
        return _densities(wi, wo, alpha_u, alpha_v, code, 1)

    c_d = chi2.integrate_cells(d_cos, chi2.spherical_domain((0.0, 0.0, 1.0), np.pi / 2.0), (16, 32), 1e-9,
                               sub=6, max_level=12)
    c_q = chi2.integrate_cells(q, chi2.spherical_domain((0.0, 0.0, 1.0), np.pi - np.arccos(wo[2])),
                               (16, 32), 1e-9, sub=6, max_level=12)
    for c in (c_d, c_q):
        assert c.total_error < 1e-7, c.total_error
        assert abs(c.total - 1.0) < 1e-6, c.total
    wi = unit(rng(33).normal(size=(50_000, 3)))
    pdf = anisotropic(distribution, alpha_u, alpha_v, len(wi)).pdf(np.tile(wo, (len(wi), 1)), wi)
    np.testing.assert_allclose(pdf, np.where(wi[:, 2] > 0.0, q(wi), 0.0), rtol=1e-9, atol=0)


def test_xml_and_toml_give_the_same_row_and_frame(sphere_with):
    """alpha_u and alpha_v in XML are alpha and alpha_v in TOML; the row is shaded in Mitsuba's
    frame (``TextureTable.frames``) either way, and an isotropic row is not."""
    xml = sphere_with('<bsdf type="roughconductor"><float name="alpha_u" value="0.05"/>'
                   '<float name="alpha_v" value="0.3"/><string name="distribution" value="ggx"/></bsdf>')
    toml = tracer.load_scene({
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
        "materials": {"m": {"type": "roughconductor", "reflectance": [1, 1, 1], "alpha": 0.05,
                            "alpha_v": 0.3}},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "m"}],
        "lights": [{"type": "point", "position": [0, 0, 5], "intensity": [1, 1, 1]}]})
    for scene in (xml, toml):
        row = int(scene.sphere_material[0])
        assert scene.materials.params[row, rc.ALPHA] == 0.05
        assert scene.materials.params[row, rc.ALPHA_V] == 0.3
        assert scene.textures.frames == {row}
    iso = sphere_with('<bsdf type="roughconductor"><float name="alpha_u" value="0.2"/>'
                   '<float name="alpha_v" value="0.2"/></bsdf>')
    assert not iso.textures.frames and iso.materials.params[int(iso.sphere_material[0]), rc.ALPHA_V] == 0.0


@pytest.mark.parametrize("bsdf, words", [
    ('<bsdf type="roughplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>'
     '</bsdf>',
     "anisotropic roughness (alpha_u and alpha_v) on roughplastic is not supported"),
    ('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/></bsdf>', "go together"),
    ('<bsdf type="bumpmap"><texture type="bitmap"><string name="filename" value="{bumps}"/></texture>'
     '<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>'
     '</bsdf></bsdf>', "bumpmap around anisotropic roughness"),
])
def test_refusals_name_the_line(sphere_with, bsdf, words):
    from conftest import ROOT

    bumps = ROOT / "tracer/scenes/mitsuba/textures/bumps.png"
    with pytest.raises(InputError) as caught:
        sphere_with(bsdf.replace("{bumps}", str(bumps)))
    message = str(caught.value)
    assert words in message and "a.xml:" in message and "\n" not in message, message
