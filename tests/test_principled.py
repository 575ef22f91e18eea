"""``principled`` and ``principledthin`` (tracer/materials/principled.py, principledthin.py):
their values and pdfs against Mitsuba 3.9.1's, their sampling against their pdfs on the whole
sphere, and how Mitsuba scenes read them.

The interface contract (sample weight = f |cos| / pdf, sample pdf = pdf, on random rows inside
and outside) is checked for every type in tests/test_sampling.py. Mitsuba's numbers come from
``benchmarks/mitsuba_bsdf_values.py`` (tests/data/mitsuba_bsdf_values.npz: 12 parameter sets of
each type, the defaults among them, 400 direction pairs each, on both sides). Seeds are fixed;
the χ² tests are at 1% / N_STAT (Šidák), so they fail a correct tracer with probability at most
1%.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.materials import Materials, principled, principledthin

import chi2

VALUES = Path(__file__).parent / "data" / "mitsuba_bsdf_values.npz"
TYPES = {"principled": principled.TYPE, "principledthin": principledthin.TYPE}


def rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([20261204, *key])


def lanes_of(kind, sets: list[dict[str, object]]) -> Materials:
    """One lane per parameter set (Mitsuba's names: ``specular`` becomes eta; missing ones
    take tracer's defaults, which are Mitsuba's)."""
    columns = {p.name: np.zeros((len(sets), p.size)) if p.size > 1 else np.zeros(len(sets))
               for p in kind.params}
    for i, given in enumerate(sets):
        values = {p.name: p.default for p in kind.params}
        values.update({k: v for k, v in given.items() if k != "specular"})
        if "specular" in given:
            values["eta"] = principled.eta_of_specular(given["specular"])
        elif kind is principled.TYPE and "eta" not in given:
            values["eta"] = principled.eta_of_specular(0.5)  # Mitsuba's default specular
        for p in kind.params:
            columns[p.name][i] = p.encode(values[p.name])
    return Materials.per_lane(kind.name, columns)


@pytest.mark.parametrize("type_name", sorted(TYPES))
def test_values_and_pdfs_are_mitsubas(type_name):
    """f and pdf at 4,800 direction pairs (wo on either side, wi on either side) equal
    Mitsuba's to 1e-5 relative plus 2e-3 of the pair's own magnitude where that is larger:
    Mitsuba computes in float32 and in the tails of the rough refraction the half vector's
    denominator (wo . h + eta wi . h)^2 cancels digits (measured worst: 1.2e-3 relative, on
    values of 1e-7). A lane seen from behind is shaded as the kernels shade it: principled with
    the row of its inside (``behind``) and the directions mirrored (z negated); the thin sheet
    with its own row. Where Mitsuba's value is 0 from inside (spec_trans 0: the inside of an
    interface that transmits nothing), tracer's pdf is 0 too, where Mitsuba's is not: no
    estimate reads a pdf whose f is 0, and tracer then draws no sample (Mitsuba draws none
    either)."""
    data = np.load(VALUES)
    kind = TYPES[type_name]
    sets = json.loads(str(data[f"{type_name}_sets"]))
    index, wo, wi = data[f"{type_name}_set"], data[f"{type_name}_wo"], data[f"{type_name}_wi"]
    f_mitsuba, pdf_mitsuba = data[f"{type_name}_f"], data[f"{type_name}_pdf"]
    behind = wo[:, 2] < 0.0
    flip = np.where(behind, -1.0, 1.0)
    wo_t, wi_t = wo.copy(), wi.copy()
    wo_t[:, 2] *= flip
    wi_t[:, 2] *= flip
    given = [dict(sets[i]) for i in index]
    if kind is principled.TYPE:
        for values, inside in zip(given, behind, strict=True):
            values["inside"] = bool(inside)
    b = lanes_of(kind, given)
    f, pdf = b.eval(wo_t, wi_t), b.pdf(wo_t, wi_t)
    lit = f_mitsuba.max(axis=1) > 0.0
    assert lit.mean() > 0.5 and (behind & lit).sum() > 500
    np.testing.assert_allclose(f, f_mitsuba, rtol=2e-3, atol=1e-5 * np.abs(f_mitsuba).max())
    seen = f_mitsuba.max(axis=1) > 0.0
    if kind is principled.TYPE:
        dark_inside = behind & ~seen
        assert np.all(pdf[dark_inside] == 0.0)
        seen = ~dark_inside
    np.testing.assert_allclose(pdf[seen], pdf_mitsuba[seen], rtol=2e-3, atol=1e-5 * pdf_mitsuba.max())


# (type, parameters, cos_o): every lobe at once, from outside and inside; the thin sheet with
# and without its diffuse transmission.
CASES = [
    ("principled", {"roughness": 0.5, "anisotropic": 0.6, "metallic": 0.3, "spec_trans": 0.5, "sheen": 0.5,
                    "clearcoat": 0.8, "clearcoat_gloss": 0.5, "eta": 1.5,
                    "base_color": (0.8, 0.4, 0.2)}, 0.7),
    ("principled", {"roughness": 0.6, "spec_trans": 0.7, "eta": 1.4, "inside": True}, 0.4),
    ("principled", {"roughness": 0.7, "metallic": 0.9, "clearcoat": 1.0, "clearcoat_gloss": 0.2}, 0.25),
    ("principledthin", {"roughness": 0.5, "anisotropic": 0.5, "spec_trans": 0.5, "diff_trans": 0.8,
                        "eta": 1.3}, 0.6),
    ("principledthin", {"roughness": 0.6, "spec_trans": 0.9, "eta": 1.8, "sheen": 1.0}, 0.3),
]
N_STAT = len(CASES)
ALPHA = chi2.sidak(N_STAT)


@pytest.mark.parametrize("case", range(len(CASES)))
def test_samples_follow_the_pdf_on_the_sphere(case):
    """χ² of 200,000 samples (all lobes, reflection and transmission) on the whole sphere in
    equal-area cells, against pdf(wo, wi) integrated per cell by cubature; failed samples (a
    microfacet direction leaving on the wrong side) go to the rest cell, which expects N (1 -
    the pdf's integral), so the pdf must be the density of sample(), not a renormalized one.
    Roughness here is at least 0.5: a sharper lobe needs finer cells than the cubature of a
    24 x 24 grid resolves (the interface contract covers sharp lobes at fixed directions)."""
    type_name, values, cos_o = CASES[case]
    kind = TYPES[type_name]
    n = 200_000
    gen = rng(1, case)
    one = lanes_of(kind, [values])
    wo = np.array([np.sqrt(1.0 - cos_o * cos_o), 0.0, cos_o])
    b = Materials(one.table, np.full(n, one.row[0], dtype=np.int64))
    s = b.sample(gen.random((n, 3)), np.tile(wo, (n, 1)))
    valid = s.pdf > 0.0
    assert np.all(s.weight[~valid] == 0.0) and valid.mean() > 0.5

    def pdf(wi: np.ndarray) -> np.ndarray:
        same = Materials(one.table, np.full(len(wi), one.row[0], dtype=np.int64))
        return same.pdf(np.tile(wo, (len(wi), 1)), wi)

    domain = chi2.spherical_domain((0.0, 0.0, 1.0), np.pi, polar="z")
    result = chi2.goodness_of_fit(s.wi, pdf, domain, (24, 24), ALPHA, valid=valid,
                                  name=f"{type_name} case {case}")
    assert result.passed, result.report()


@pytest.mark.parametrize("type_name", sorted(TYPES))
def test_the_pdf_covers_every_direction_with_a_value(type_name):
    """Wherever f > 0 (any lobe, either side) the pdf is > 0 at the default sampling rates, so
    BSDF sampling alone converges to the image: 20,000 random pairs of random parameter sets."""
    kind = TYPES[type_name]
    gen = rng(2, sorted(TYPES).index(type_name))
    n = 20_000
    sets = []
    for _ in range(n):
        values = {p.name: float(gen.uniform(p.lo, p.hi)) for p in kind.params
                  if p.size == 1 and p.texture and p.name != "eta"}
        values["base_color"] = tuple(gen.uniform(0.0, 1.0, 3))
        values["eta"] = float(gen.uniform(1.05, 2.0))
        if kind is principled.TYPE:
            values["inside"] = bool(gen.random() < 0.3)
        sets.append(values)
    b = lanes_of(kind, sets)
    wo = gen.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.05
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi = gen.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    f, pdf = b.eval(wo, wi), b.pdf(wo, wi)
    lit = f.max(axis=1) > 0.0
    assert lit.mean() > 0.3 and (lit & (wi[:, 2] < 0.0)).any()
    assert np.all(pdf[lit] > 0.0)


def row_values(scene, row: int) -> dict[str, object]:
    kind = tracer.materials.BY_CODE[int(scene.materials.kind[row])]
    return kind.values(scene.materials.params[row])


def test_xml_reads_mitsubas_parameters(sphere_with):
    """Mitsuba's names and defaults: specular 0.5 is eta 1.5; a given specular maps to eta by
    2 / (1 - sqrt(0.08 s)) - 1; a float texture binds to its parameter; the BSDF shades both
    sides (an interface), and a twosided around it mirrors the front instead."""
    scene = sphere_with('<bsdf type="principled"><float name="specular" value="0.8"/>'
                 '<texture name="metallic" type="checkerboard"><float name="color0" value="0.2"/>'
                 '<float name="color1" value="0.6"/></texture></bsdf>')
    values = row_values(scene, 1)
    assert values["eta"] == pytest.approx(2.0 / (1.0 - np.sqrt(0.064)) - 1.0)
    assert values["roughness"] == 0.5 and values["mirrored"] == 0.0
    assert {(b.material, b.param) for b in scene.textures.bindings} == {(1, "metallic")}
    assert bool(scene.materials.twosided[1])
    assert principled.eta_of_specular(0.5) == pytest.approx(1.5)
    wrapped = sphere_with('<bsdf type="twosided"><bsdf type="principled"/></bsdf>')
    assert row_values(wrapped, 1)["mirrored"] == 1.0
    thin = sphere_with('<bsdf type="principledthin"><float name="diff_trans" value="1.5"/>'
                '<float name="eta" value="1.2"/></bsdf>')
    values = row_values(thin, 1)
    assert values["diff_trans"] == 1.5 and values["eta"] == 1.2 and bool(thin.materials.twosided[1])


@pytest.mark.parametrize("bsdf, words", [
    ('<bsdf type="principled"><float name="eta" value="1.4"/><float name="specular" value="0.3"/></bsdf>',
     "give eta or specular, not both"),
    ('<bsdf type="principled"><float name="roughness" value="1.5"/></bsdf>', "roughness"),
    ('<bsdf type="principled"><float name="eta" value="0.7"/></bsdf>', "eta"),
    ('<bsdf type="principled"><float name="main_specular_sampling_rate" value="0"/></bsdf>',
     "main_specular_sampling_rate"),
    ('<bsdf type="twosided"><bsdf type="principled"><float name="spec_trans" value="0.5"/></bsdf></bsdf>',
     "principled with spec_trans inside a twosided"),
    ('<bsdf type="twosided"><bsdf type="principledthin"/></bsdf>', "principledthin inside a twosided"),
    ('<bsdf type="principledthin"><float name="diff_trans" value="2.5"/></bsdf>', "diff_trans"),
    ('<bsdf type="principled"><float name="spec_trans" value="0.5"/><float name="clearcoat_glos" value="1"/>'
     '</bsdf>', "clearcoat_glos"),
])
def test_refusals_name_the_file_and_key(sphere_with, bsdf, words):
    with pytest.raises(InputError) as caught:
        sphere_with(bsdf)
    message = str(caught.value)
    assert words in message and "a.xml:" in message and "\n" not in message, message


def test_a_twosided_principled_without_transmission_is_its_front_from_both_sides(sphere_with):
    """Mitsuba's twosided mirrors the front to the back: the row that shades a hit from behind
    has the front's parameters (not the inside of an interface)."""
    scene = sphere_with('<bsdf type="twosided"><bsdf type="principled"><float name="sheen" value="0.5"/>'
                 '</bsdf></bsdf>')
    kinds, params, behind = scene.materials.shading(tracer.materials.BY_CODE)
    back = int(behind[1])
    assert back != 1 and np.array_equal(params[back], params[1])
