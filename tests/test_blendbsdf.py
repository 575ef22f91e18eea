"""``blendbsdf``: a blend of two materials (Mitsuba's), and how the readers lay it out.

The interface contract (pdf = the sample's pdf, weight = f cos / pdf, lobes, zero below the
surface) is checked on random blends of every reflecting type by
``tests/test_sampling.py::test_every_material_keeps_the_interface_contract``; this file checks
what a blend adds, and the corpus scenes in docs/results/mitsuba-agreement.md check it against
Mitsuba's images.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from test_sampling import check, rng, unit

import tracer
from tracer.errors import InputError
from tracer.materials import Materials, blendbsdf, table

import chi2

DIFFUSE = ("diffuse", {"reflectance": np.array([0.8, 0.5, 0.2])})
ROUGH = ("roughconductor", {"reflectance": np.array([0.9, 0.9, 0.9]), "alpha": 0.15, "eta": np.full(3, 0.2),
                            "k": np.full(3, 3.0)})
MIRROR = ("conductor", {"reflectance": np.ones(3)})


def blend(weight: float, first, second, n: int) -> Materials:
    return Materials(table(blendbsdf.parts("b", weight, first, second)), np.ones(n, dtype=np.int64))


def part(material, n: int) -> Materials:
    return Materials(table([("m", *material)]), np.ones(n, dtype=np.int64))


def test_value_and_pdf_are_the_weighted_sums_of_the_parts():
    """f and pdf of a blend at random direction pairs are (1 - w) and w times its parts' own
    (the parts evaluated alone, through their own rows), to float rounding."""
    gen = rng(41)
    n = 20_000
    wo, wi = unit(gen.normal(size=(n, 3)) + [0, 0, 1.5]), unit(gen.normal(size=(n, 3)))
    wi[:, 2] = np.abs(wi[:, 2])
    for weight in (0.0, 0.3, 1.0):
        b, first, second = blend(weight, DIFFUSE, ROUGH, n), part(DIFFUSE, n), part(ROUGH, n)
        for of in (Materials.eval, Materials.pdf):
            mixed = (1 - weight) * of(first, wo, wi) + weight * of(second, wo, wi)
            np.testing.assert_allclose(of(b, wo, wi), mixed, rtol=1e-12, atol=1e-300)


def test_sampled_directions_follow_the_blended_pdf():
    """Directions of a blend of a diffuse and a rough metal (weight 0.3) against its pdf: a
    chi-square goodness of fit on the upper hemisphere at level 0.01 (one test in this file),
    the samples lost below the surface (the metal's) in the rest cell; the expected counts by
    adaptive cubature (bounded by ``check``)."""
    wo = unit(np.array([0.5, -0.3, 0.6]))
    n = 400_000
    b = blend(0.3, DIFFUSE, ROUGH, n)
    s = b.sample(rng(42).random((n, 3)), np.tile(wo, (n, 1)))
    invalid = s.pdf <= 0.0
    assert np.all(s.weight[invalid] == 0.0)

    def pdf(wi):
        return blend(0.3, DIFFUSE, ROUGH, len(wi)).pdf(np.tile(wo, (len(wi), 1)), wi)

    check(chi2.goodness_of_fit(s.wi, pdf, chi2.spherical_domain((0.0, 0.0, 1.0), np.pi / 2.0), (40, 80), 0.01,
                               valid=~invalid, name="blend diffuse + roughconductor"))


def test_a_delta_part_keeps_its_weight_and_the_mean_weight_is_the_albedo():
    """A blend of a perfect mirror (first) and a diffuse (second), weight w: a sample is the
    mirror's delta reflection (pdf 0, weight 1) with probability 1 - w, and the mean sample
    weight is the blend's albedo, (1 - w) 1 + w reflectance. The mean is compared with a
    z-test at level 0.01 (n = 200,000 bounded weights: the normal approximation is accurate),
    per channel with Sidak over the three channels (they share the samples); the delta share
    with a binomial test."""
    w, n = 0.35, 200_000
    b = blend(w, MIRROR, DIFFUSE, n)
    wo = unit(np.array([0.2, 0.4, 0.8]))
    s = b.sample(rng(43).random((n, 3)), np.tile(wo, (n, 1)))
    delta = s.delta
    np.testing.assert_allclose(s.wi[delta], np.tile(wo * [-1, -1, 1], (int(delta.sum()), 1)), atol=1e-12)
    assert np.all(s.pdf[delta] == 0.0) and np.allclose(s.weight[delta], 1.0)
    assert stats.binomtest(int(delta.sum()), n, 1 - w).pvalue > 0.01
    expected = (1 - w) + w * DIFFUSE[1]["reflectance"]
    z = (s.weight.mean(axis=0) - expected) / (s.weight.std(axis=0, ddof=1) / np.sqrt(n))
    alpha = 1 - (1 - 0.01) ** (1 / 3)
    assert np.all(np.abs(z) < stats.norm.ppf(1 - alpha / 2)), z


def test_the_xml_blend_takes_three_rows_and_its_parts_textures(sphere_with):
    """A blendbsdf becomes its own row and its two parts' rows right after it (the layout the
    kernels read), a textured weight is bound to the blend's row, a part's texture to the
    part's row, and the blend is two-sided where both parts are."""
    scene = sphere_with('<bsdf type="blendbsdf"><texture name="weight" type="checkerboard"/>'
                        '<bsdf type="twosided"><bsdf type="diffuse"><texture name="reflectance" '
                        'type="checkerboard"/></bsdf></bsdf><bsdf type="twosided"><bsdf type="conductor"/>'
                        '</bsdf></bsdf>')
    row = int(scene.sphere_material[0])
    kinds = [tracer.materials.BY_CODE[int(k)].name for k in scene.materials.kind[row:row + 3]]
    assert kinds == ["blendbsdf", "diffuse", "conductor"]
    assert list(scene.materials.twosided[row:row + 3]) == [True, True, True]
    bound = {(b.material, b.param) for b in scene.textures.bindings}
    assert bound == {(row, "weight"), (row + 1, "reflectance")}


W = '<float name="weight" value="0.5"/>'
D = '<bsdf type="diffuse"/>'


@pytest.mark.parametrize("bsdf, words", [
    (f'<bsdf type="blendbsdf">{W}{D}</bsdf>', "two nested BSDFs"),
    (f'<bsdf type="blendbsdf">{D}{D}</bsdf>', "missing property 'weight'"),
    (f'<bsdf type="blendbsdf"><float name="weight" value="1.5"/>{D}{D}</bsdf>', "expected a number <= 1"),
    (f'<bsdf type="blendbsdf">{W}{D}<bsdf type="dielectric"/></bsdf>', "blendbsdf of dielectric"),
    (f'<bsdf type="blendbsdf">{W}{D}<bsdf type="blendbsdf">{W}{D}{D}</bsdf></bsdf>', "blendbsdf inside a"),
    (f'<bsdf type="blendbsdf">{W}{D}<bsdf type="twosided">{D}</bsdf></bsdf>', "one-sided and a two-sided"),
    (f'<bsdf type="blendbsdf">{W}{D}<bsdf type="mask">{D}</bsdf></bsdf>', "mask, normalmap or bumpmap"),
])
def test_refusals_name_the_line(sphere_with, bsdf, words):
    with pytest.raises(InputError) as caught:
        sphere_with(bsdf)
    message = str(caught.value)
    assert words in message and "a.xml:" in message and "\n" not in message, message


@pytest.mark.parametrize("bsdfs", [
    f'<bsdf type="blendbsdf" id="B">{W}{D}<ref id="B"/></bsdf>',
    f'<bsdf type="blendbsdf" id="A">{W}{D}<ref id="B"/></bsdf>'
    f'<bsdf type="blendbsdf" id="B">{W}{D}<ref id="A"/></bsdf>',
    f'<bsdf type="twosided" id="T"><bsdf type="blendbsdf">{W}{D}<ref id="T"/></bsdf></bsdf>',
])
def test_a_blend_nested_in_itself_is_refused(tmp_path, bsdfs):
    """A reference cycle through a blend (itself, another blend, a twosided around it), used by
    no shape, is refused in one line, as Mitsuba refuses a reference cycle (it used to recurse
    until Python's stack ran out)."""
    path = tmp_path / "cycle.xml"
    path.write_text(f'<scene version="3.0.0">{bsdfs}<shape type="sphere"/>'
                    '<emitter type="point"><point name="position" value="0, 0, 5"/></emitter></scene>')
    with pytest.raises(InputError) as caught:
        tracer.load_scene(path)
    message = str(caught.value)
    assert "circular reference" in message and "cycle.xml:" in message and "\n" not in message, message


def test_toml_refuses_a_blend_by_name():
    with pytest.raises(InputError, match="blendbsdf is read from Mitsuba XML only") as caught:
        tracer.load_scene({
            "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
            "materials": {"m": {"type": "blendbsdf", "weight": 0.5}},
            "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "m"}],
            "lights": [{"type": "point", "position": [0, 0, 5], "intensity": [1, 1, 1]}]})
    assert "materials.m.type" in str(caught.value)
