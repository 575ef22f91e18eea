"""``roughdielectric`` (tracer/materials/roughdielectric.py): its sampling against its pdf on
the whole sphere, the pdf's mass, energy, the reciprocity of the refraction lobe, and how
Mitsuba scenes read it.

The interface contract (sample weight = f |cos| / pdf, sample pdf = pdf) is checked for every
type in tests/test_sampling.py, and agreement with Mitsuba 3 in
tests/test_mitsuba_agreement.py (``tracer/scenes/mitsuba/rough_glass.xml``). Seeds are fixed;
each statistical test is at 1% / N_STAT (Šidák), so the file fails a correct tracer with
probability at most 1%.
"""

from __future__ import annotations

import numpy as np
import pytest

from tracer.materials import Materials

import chi2

# (alpha, eta, cos_o, distribution): sharp and wide lobes, from outside and from inside glass
# (eta < 1; at cos_o 0.3 beyond the critical angle part of the lobe reflects totally).
CASES = [(0.1, 1.5, 0.9, "ggx"), (0.5, 1.5, 0.3, "beckmann"), (0.3, 1 / 1.5, 0.9, "ggx"),
         (0.5, 1 / 1.5, 0.3, "beckmann")]
N_STAT = len(CASES)
ALPHA = chi2.sidak(N_STAT)


def rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([20261203, *key])


def lanes(n: int, alpha: float, eta: float, distribution: str) -> Materials:
    """n lanes of one roughdielectric (one table row shared by all: its derived eta is computed
    once, not per lane)."""
    one = Materials.per_lane("roughdielectric", {
        "specular_reflectance": np.ones((1, 3)), "specular_transmittance": np.ones((1, 3)),
        "int_ior": np.full(1, eta), "ext_ior": np.ones(1), "alpha": np.full(1, alpha),
        "distribution": np.full(1, ["ggx", "beckmann"].index(distribution))})
    return Materials(one.table, np.full(n, one.row[0], dtype=np.int64))


def wo_of(cos_o: float) -> np.ndarray:
    return np.array([np.sqrt(1.0 - cos_o * cos_o), 0.0, cos_o])


def pdf_of(alpha: float, eta: float, distribution: str, wo: np.ndarray):
    def pdf(wi: np.ndarray) -> np.ndarray:
        return lanes(len(wi), alpha, eta, distribution).pdf(np.tile(wo, (len(wi), 1)), wi)
    return pdf


@pytest.mark.parametrize("alpha, eta, cos_o, distribution", CASES)
def test_samples_follow_the_pdf_on_the_sphere(alpha, eta, cos_o, distribution):
    """χ² of 100,000 samples (reflection and refraction together) on the whole sphere of
    directions, in equal-area cells (cos theta, phi), against pdf(wo, wi) integrated per cell by
    cubature; samples that fail (a microfacet direction leaving on the wrong side) go to the
    rest cell, which expects N (1 - the pdf's integral): the pdf must be the density with which
    sample() produces directions, not renormalized. eta < 1 is glass seen from inside, where
    part of the sphere reflects totally."""
    n = 100_000
    gen = rng(1, CASES.index((alpha, eta, cos_o, distribution)))
    wo = wo_of(cos_o)
    b = lanes(n, alpha, eta, distribution)
    s = b.sample(gen.random((n, 3)), np.tile(wo, (n, 1)))
    valid = s.pdf > 0.0
    assert np.all(s.weight[~valid] == 0.0)
    assert (s.wi[valid, 2] > 0.0).any() and (s.wi[valid, 2] < 0.0).any()  # both lobes are sampled
    domain = chi2.spherical_domain((0.0, 0.0, 1.0), np.pi, polar="z")
    result = chi2.goodness_of_fit(s.wi, pdf_of(alpha, eta, distribution, wo), domain, (24, 24), ALPHA,
                                  valid=valid, name=f"roughdielectric a={alpha} eta={eta:.3f} cos={cos_o}")
    assert result.passed, result.report()


@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("eta", [1.33, 1 / 1.33])
def test_energy_is_at_most_one_and_sampling_sees_all_of_it(alpha, eta):
    """The directional albedo, the integral of f |cos| over the sphere, is at most max(1,
    1 / eta^2) (a microfacet interface loses the energy of rays that would scatter again, never
    gains; radiance leaving glass into air is brighter by 1 / eta^2 > 1, as the smooth
    dielectric's refraction weight is), and
    the mean sample weight estimates the same integral: two estimates of one number, by
    midpoint cubature on a 400 x 800 equal-area grid (deterministic; its error bounded by its
    difference from a 200 x 400 grid) and by 400,000 samples (standard error from the samples;
    z below 4.5 with 6 cases, Šidák at 1%)."""
    wo = wo_of(0.7)
    albedo, coarse = albedo_by_cubature(wo, alpha, eta, 400), albedo_by_cubature(wo, alpha, eta, 200)
    # The midpoint rule's error falls as h^2, so the fine grid's is a third of the two grids'
    # difference; that difference bounds it (with room for the rule not yet being asymptotic).
    cubature_error = abs(albedo - coarse)
    n = 400_000
    s = lanes(n, alpha, eta, "ggx").sample(rng(2, int(alpha * 100), int(eta > 1)).random((n, 3)),
                                            np.tile(wo, (n, 1)))
    mean, error = s.weight[:, 0].mean(), s.weight[:, 0].std(ddof=1) / np.sqrt(n)
    bound = max(1.0, 1.0 / eta**2)
    assert albedo <= bound + cubature_error and mean <= bound + 4.5 * error
    assert abs(mean - albedo) < 4.5 * error + cubature_error, (mean, error, albedo, cubature_error)


def albedo_by_cubature(wo: np.ndarray, alpha: float, eta: float, rows: int) -> float:
    """The integral of f |cos| over the sphere by the midpoint rule on a rows x 2 rows grid,
    equal-area in (cos theta, phi)."""
    cols = 2 * rows
    z = -1.0 + (np.arange(rows) + 0.5) * 2.0 / rows
    phi = (np.arange(cols) + 0.5) * 2.0 * np.pi / cols
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1.0 - zz * zz)
    wi = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    f = lanes(len(wi), alpha, eta, "ggx").eval(np.tile(wo, (len(wi), 1)), wi)[:, 0]
    return float(np.sum(f * np.abs(wi[:, 2])) * (2.0 / rows) * (2.0 * np.pi / cols))


def test_refraction_obeys_generalized_reciprocity():
    """Walter et al.'s refraction lobe with Mitsuba's radiance scaling (1 / eta^2) satisfies
    f(wo, wi; eta) = f(-wi', -wo'; 1/eta) / eta^2 for the reversed path seen from the other side:
    written in tracer's frames (wo always up), f_out(wo, wi) eta^2 = f_in(wi_up, wo_down), with
    wi_up = -wi and wo_down = -wo. Deterministic to 1e-9 relative."""
    gen = rng(3)
    n = 20_000
    eta = 1.45
    wo = gen.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.05
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi = gen.normal(size=(n, 3))
    wi[:, 2] = -np.abs(wi[:, 2]) - 0.05
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    outside = lanes(n, 0.3, eta, "beckmann").eval(wo, wi)[:, 0]
    inside = lanes(n, 0.3, 1.0 / eta, "beckmann").eval(-wi, -wo)[:, 0]
    nonzero = outside > 1e-12
    assert nonzero.mean() > 0.05  # most random pairs have no microfacet between them (sides disagree)
    np.testing.assert_allclose(outside[nonzero] * eta * eta, inside[nonzero], rtol=1e-9)


def test_a_textured_roughness_is_read_from_both_sides(tmp_path):
    """A roughdielectric's textured alpha feeds its outside row and its inside row (the row a
    hit from behind shades with, ``MaterialTable.shading``): both read the same texture, as
    Mitsuba's one BSDF does, so a refraction out of the glass sees the roughness there."""
    import tracer
    from tracer.estimator import DirectLighting
    from tracer.materials import roughdielectric
    from tracer.strategy import Strategy

    path = tmp_path / "glass.xml"
    path.write_text('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm"><integer '
                    'name="width" value="4"/><integer name="height" value="4"/></film></sensor>'
                    '<shape type="sphere"><bsdf type="roughdielectric"><texture name="alpha" '
                    'type="checkerboard"><float name="color0" value="0.05"/><float name="color1" '
                    'value="0.5"/></texture></bsdf></shape><emitter type="point"/></scene>')
    scene = tracer.load_scene(path)
    surfaces = DirectLighting(scene, Strategy.from_options("mis")).surfaces
    row = int(scene.sphere_material[0])
    inside = int(surfaces.behind[row])
    assert inside >= len(scene.materials.kind)
    textures = surfaces.textures
    for r in (row, inside):
        first, last = textures.first_binding[r], textures.first_binding[r + 1]
        assert last - first == 1 and textures.bindings[first, 0] == roughdielectric.ALPHA
