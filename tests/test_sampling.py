"""Every sampler against the density it claims: chi-square tests of the warps, the BSDFs and
light sampling (``chi2.py``), plus the deterministic identities that tie ``sample``, ``pdf``
and ``eval`` together (pdf agreement, weight = f cos / pdf, the mirror, GGX normalization,
energy, reciprocity).

Statistical tests: each chi-square (or binomial) test runs at the Sidak level
ALPHA = 1 - 0.99^(1/N_STAT) over the N_STAT statistical tests of this file, so a correct tracer
fails the file with probability <= 1 %; seeds are fixed, so a pass is reproducible and a
failure is worth reading.
Deterministic identities: each test states its tolerance: 1e-12 to 1e-9 relative for
algebraically equal float64 expressions (round-off is ~1e-15 per operation), exact equality
where the code copies or flips signs, and the cubature's own error estimate for integrals.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from scipy import integrate, stats

from tracer import lights, materials, warp
from tracer.embree import RayCaster
from tracer.geometry import SceneRays
from tracer.lights import LightSampler
from tracer.materials import Materials
from tracer.scene import default_scene_path, load_scene

import chi2

N_SAMPLES = 1_000_000
GRID = (40, 80)  # (polar, phi) cells

ALPHAS = (0.05, 0.2, 0.7)
# wo: normal incidence (the VNDF's degenerate-basis branch), oblique, grazing (wo.z = 0.1).
WO_CASES = {
    "normal": np.array([0.0, 0.0, 1.0]),
    "oblique": np.array([0.48, -0.64, 0.6]),
    "grazing": np.array([np.sqrt(0.99) * np.cos(2.2), np.sqrt(0.99) * np.sin(2.2), 0.1]),
}
# GGX BSDF sampling: the fast suite runs one case per alpha and per wo (a Latin square: the most
# mass lost below the horizon, at 0.7 grazing; normal incidence's degenerate basis; a near-mirror
# lobe); the other six are slow, for the CI budget (11 s each): the VNDF chi-square and the mass
# and energy integrals test every pair in every run.
GGX_CASES = [(a, w) for a in ALPHAS for w in WO_CASES]
GGX_FAST = {(0.7, "grazing"), (0.2, "normal"), (0.05, "oblique")}
GGX_BSDF_CASES = [case if case in GGX_FAST else pytest.param(*case, marks=pytest.mark.slow)
                  for case in GGX_CASES]
DIFFUSE_WO = ("normal", "grazing")
LIGHT_CASES = ("quad", "sphere", "two_power", "two_uniform")

# Statistical tests in this file: chi-square of hemispheres (2), VNDF, GGX BSDF, diffuse BSDF,
# lights, triangle (1); binomial light-selection tests (2 cases; with two lights the two counts
# are complementary, so each case is one test) and the point light's share (1).
N_STAT = 2 + len(GGX_CASES) + len(GGX_CASES) + len(DIFFUSE_WO) + len(LIGHT_CASES) + 1 + 2 + 1
ALPHA = chi2.sidak(N_STAT)

# Relative tolerance for quantities that are algebraically equal but computed along different
# float64 paths (a few divisions, square roots and normalizations: ~1e-15 each); 1e-9 leaves
# room for the conditioning of D near a sharp peak, and is far below any modelling error.
RTOL = 1e-9


def rng(*key: int) -> np.random.Generator:
    """A fixed, independent stream per test (and per case)."""
    return np.random.default_rng([20240611, *key])


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_upper(n: int, gen: np.random.Generator, zmin: float = 1e-3) -> np.ndarray:
    """Directions spread over the upper hemisphere with z >= zmin."""
    w = unit(gen.normal(size=(n, 3)))
    w[:, 2] = np.abs(w[:, 2])
    return unit(np.where(w[:, 2:3] < zmin, w + [0.0, 0.0, zmin], w))


DIFFUSE, ROUGH_CONDUCTOR, MIRROR = "diffuse", "roughconductor", "mirror"


def materials_of(kind, reflectance: np.ndarray, alpha) -> Materials:
    """Lanes of material type(s) ``kind`` with per-lane reflectance (n, 3) and alpha (n,)."""
    n = len(reflectance)
    return Materials.per_lane(kind, {"reflectance": reflectance, "alpha": np.broadcast_to(alpha, (n,))})


def make_bsdf(kind: str, n: int, alpha: float = 1.0, reflectance=(0.9, 0.6, 0.3)) -> Materials:
    refl = np.tile(np.asarray(reflectance, dtype=np.float64), (n, 1))
    return materials_of(kind, refl, float(alpha))


def bsdf_pdf_of(kind: str, wo: np.ndarray, alpha: float = 1.0):
    """wi (m, 3) -> Materials.pdf(wo, wi) for a fixed wo: the density chi2 integrates."""
    def pdf(wi: np.ndarray) -> np.ndarray:
        return make_bsdf(kind, len(wi), alpha).pdf(np.tile(wo, (len(wi), 1)), wi)
    return pdf


def hemisphere() -> chi2.Domain:
    """The upper hemisphere with the horizon on a cell boundary: a pdf that is 0 below it is
    smooth inside every cell, so the cubature converges to round-off."""
    return chi2.spherical_domain((0.0, 0.0, 1.0), np.pi / 2.0, polar="theta")


def check(result: chi2.Chi2Result) -> None:
    print(result.report(3))
    assert result.passed, result.report()
    # The expected counts must be trustworthy for the verdict to mean anything: integration
    # errors may raise X^2 by at most a tenth of its standard deviation sqrt(2 dof).
    assert result.integration_chi2 < 0.1 * np.sqrt(2.0 * result.dof), result.report()


# ---------------------------------------------------------------------------------------------
# Warps


@pytest.mark.parametrize("which", ["uniform", "cosine"])
def test_hemisphere_warps_chi2(which):
    """Uniform / cosine hemisphere samples vs. their pdf on the whole sphere, equal-area
    (cos theta, phi) cells; level ALPHA (Sidak over the file's N_STAT statistical tests)."""
    sample, pdf = {"uniform": (warp.sample_uniform_hemisphere, warp.pdf_uniform_hemisphere),
                   "cosine": (warp.sample_cosine_hemisphere, warp.pdf_cosine_hemisphere)}[which]
    w = sample(rng(1, len(which)).random((N_SAMPLES, 2)))
    result = chi2.goodness_of_fit(w, pdf, chi2.spherical_domain(polar="z"), GRID, ALPHA, name=which)
    # The pdf integrates to 1 over the sphere: Gauss rules are exact on these polynomials.
    assert abs(result.integral - 1.0) < 1e-12
    check(result)


def test_warps_give_unit_upper_directions_and_positive_pdf():
    """Every warp returns finite unit vectors (atol 1e-12: a vector built from sqrt, sin and cos
    is off by a few ulps) with z >= 0, on random u and on the square's corners and diagonals;
    the hemisphere pdfs are > 0 wherever z > 0 (a sample its own pdf calls impossible would
    get an infinite or dropped weight); visible normals face wo; barycentrics stay on the
    triangle."""
    edge = np.array([[0.0, 0.0], [0.5, 0.5], [1 - 1e-16, 1 - 1e-16], [0.0, 1 - 1e-16],
                     [1e-12, 0.3], [0.25, 0.75], [0.75, 0.25], [0.3, 0.3]])
    u = np.concatenate([rng(2).random((10000, 2)), edge])
    for name, sample, pdf in [
            ("uniform", warp.sample_uniform_hemisphere, warp.pdf_uniform_hemisphere),
            ("cosine", warp.sample_cosine_hemisphere, warp.pdf_cosine_hemisphere)]:
        w = sample(u)
        assert np.all(np.isfinite(w)), name
        np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12, err_msg=name)
        assert np.all(w[:, 2] >= 0.0), name
        # Uniform: u0 = 0 gives z = 0 exactly, the rim, where the pdf is 0 by convention.
        inner = u[:, 0] > 0.0 if name == "uniform" else np.ones(len(u), bool)
        assert np.all(pdf(w)[inner & (w[:, 2] > 0)] > 0.0), name
    for alpha in ALPHAS:
        for wo in WO_CASES.values():
            wo_n = np.tile(wo, (len(u), 1))
            h = warp.sample_ggx_visible_normal(u, wo_n, np.full(len(u), alpha))
            assert np.all(np.isfinite(h))
            np.testing.assert_allclose(np.linalg.norm(h, axis=1), 1.0, atol=1e-12)
            assert np.all(h[:, 2] >= 0.0)
            assert np.all(np.sum(h * wo, axis=1) >= -1e-12)  # visible normals face wo
    b = warp.sample_triangle_barycentric(u)
    assert np.all(b >= 0.0) and np.all(b.sum(axis=1) <= 1.0 + 1e-15)


@pytest.mark.parametrize("alpha,wo_name", GGX_CASES)
def test_ggx_visible_normals_chi2(alpha, wo_name):
    """Half vectors from sample_ggx_visible_normal vs. pdf_ggx_visible_normal, (theta, phi)
    cells on a cap around the normal that holds the lobe (the tail goes to the rest cell);
    level ALPHA."""
    wo = WO_CASES[wo_name]
    n = N_SAMPLES // 2
    gen = rng(3, int(alpha * 100), list(WO_CASES).index(wo_name))
    h = warp.sample_ggx_visible_normal(gen.random((n, 2)), np.tile(wo, (n, 1)), np.full(n, alpha))

    def pdf(hh):
        return warp.pdf_ggx_visible_normal(hh, np.tile(wo, (len(hh), 1)), np.full(len(hh), alpha))

    domain = chi2.spherical_domain((0.0, 0.0, 1.0), min(np.pi / 2, np.arctan(10 * alpha)))
    check(chi2.goodness_of_fit(h, pdf, domain, GRID, ALPHA, name=f"vndf a={alpha} wo={wo_name}"))


def test_triangle_barycentric_chi2():
    """Points v0 + b1 e1 + b2 e2 from sample_triangle_barycentric on a skewed 3-D triangle vs.
    the area pdf 1/area, on a (s = b1 + b2, t = b2 / s) grid where the density is linear, so the
    expected counts are exact; level ALPHA. Points off the triangle land in the rest cell."""
    v0, v1, v2 = np.array([0.3, -0.2, 1.0]), np.array([2.0, 0.1, 0.5]), np.array([0.1, 1.5, -0.4])
    area = 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0))
    b = warp.sample_triangle_barycentric(rng(4).random((N_SAMPLES, 2)))
    x = v0 + b[:, 0:1] * (v1 - v0) + b[:, 1:2] * (v2 - v0)
    result = chi2.goodness_of_fit(x, lambda p: np.full(len(p), 1.0 / area),
                                  chi2.triangle_domain(v0, v1, v2), (32, 32), ALPHA,
                                  name="triangle")
    assert abs(result.integral - 1.0) < 1e-12
    check(result)


# ---------------------------------------------------------------------------------------------
# BSDF sampling: density of wi, and the identities between sample, pdf and eval


def sample_bsdf(kind: int, wo: np.ndarray, alpha: float, n: int, gen: np.random.Generator):
    b = make_bsdf(kind, n, alpha)
    wo_n = np.tile(wo, (n, 1))
    return b, wo_n, b.sample(gen.random((n, 2)), wo_n)


@pytest.mark.parametrize("wo_name", DIFFUSE_WO)
def test_diffuse_bsdf_chi2(wo_name):
    """Diffuse sample() directions vs. Materials.pdf over the whole sphere (cos theta, phi); every
    sample is valid and pdf integrates to 1; level ALPHA."""
    wo = WO_CASES[wo_name]
    _, _, s = sample_bsdf(DIFFUSE, wo, 1.0, N_SAMPLES, rng(5, DIFFUSE_WO.index(wo_name)))
    result = chi2.goodness_of_fit(s.wi, bsdf_pdf_of(DIFFUSE, wo),
                                  chi2.spherical_domain(polar="z"), GRID, ALPHA,
                                  valid=s.pdf > 0.0, name=f"diffuse wo={wo_name}")
    assert abs(result.integral - 1.0) < 1e-12
    check(result)


@pytest.mark.parametrize("alpha,wo_name", GGX_BSDF_CASES)
def test_rough_conductor_bsdf_chi2(alpha, wo_name):
    """GGX sample() directions vs. Materials.pdf, (theta, phi) cells on a cap around the mirror
    direction; level ALPHA.

    What is right below the horizon: wi = reflect(wo, h) with h from the visible normals falls
    below the surface with a probability that grows with alpha and with grazing wo. Those
    samples must carry pdf 0 and weight 0 (they estimate 0, so the estimator stays unbiased),
    and pdf() must stay the *unnormalized* density D_wo(h) / (4 wo.h) of the samples that
    remain, integrating to 1 - P(below): MIS needs the density with which sample() actually
    produces wi. So the invalid samples go to the rest cell, which expects N (1 - integral of
    pdf over the cap): a pdf renormalized by P(above) fails whenever the lost mass is more than
    about half a percent (all cases but alpha = 0.05 at normal and oblique wo, which lose 0.25
    and 0.36 %; the deterministic mass test below covers those)."""
    wo = WO_CASES[wo_name]
    n = N_SAMPLES // 2
    gen = rng(6, int(alpha * 100), list(WO_CASES).index(wo_name))
    _, _, s = sample_bsdf(ROUGH_CONDUCTOR, wo, alpha, n, gen)
    invalid = s.pdf <= 0.0
    assert np.all(s.weight[invalid] == 0.0)
    assert np.all(s.wi[invalid, 2] <= 0.0), "only directions below the surface may be invalid"
    assert not np.any(s.delta)
    mirror_dir = wo * [-1.0, -1.0, 1.0]
    domain = chi2.spherical_domain(mirror_dir, min(np.pi, 2.0 * np.arctan(5.0 * alpha)))
    result = chi2.goodness_of_fit(s.wi, bsdf_pdf_of(ROUGH_CONDUCTOR, wo, alpha), domain, GRID,
                                  ALPHA, valid=~invalid, name=f"ggx bsdf a={alpha} wo={wo_name}")
    check(result)


@pytest.mark.parametrize("kind", [DIFFUSE, ROUGH_CONDUCTOR])
def test_bsdf_sample_pdf_weight_agree_with_pdf_and_eval(kind):
    """On valid samples (pdf > 0), sample().pdf and pdf(wo, wi) both equal the density written
    here independently (diffuse: cos / pi; GGX: the visible-normal density D_wo(h) / (4 wo.h)
    of ``warp.pdf_ggx_visible_normal``, a different formula from the material's
    D / (2 (cos_o + sigma_o))), and sample().weight == eval(wo, wi) cos(theta_i) / pdf, to RTOL
    (algebraically equal, different float paths); invalid samples have weight 0. Many wo (down
    to wo.z = 0.01) and alphas in one batch."""
    n = 200_000
    gen = rng(7, ["diffuse", "roughconductor"].index(kind))
    wo = random_upper(n, gen, zmin=0.01)
    alpha = gen.choice(np.array([0.01, 0.05, 0.2, 0.7, 1.5]), n)
    refl = gen.random((n, 3))
    b = materials_of(kind, refl, alpha)
    s = b.sample(gen.random((n, 2)), wo)
    ok = s.pdf > 0.0
    assert ok.mean() > 0.5
    assert np.all(s.weight[~ok] == 0.0)
    np.testing.assert_allclose(np.linalg.norm(s.wi, axis=1), 1.0, atol=1e-12)
    wi = s.wi[ok]
    if kind == DIFFUSE:
        expected_pdf = wi[:, 2] / np.pi
    else:
        h = unit(wo[ok] + wi)
        expected_pdf = warp.pdf_ggx_visible_normal(h, wo[ok], alpha[ok]) / (4.0 * np.sum(wo[ok] * h, axis=1))
    np.testing.assert_allclose(s.pdf[ok], expected_pdf, rtol=1e-9, atol=0)
    np.testing.assert_allclose(b.take(ok).pdf(wo[ok], wi), expected_pdf, rtol=1e-9, atol=0)
    f = b.take(ok).eval(wo[ok], s.wi[ok])
    expected_weight = f * s.wi[ok, 2:3] / s.pdf[ok, None]
    np.testing.assert_allclose(s.weight[ok], expected_weight, rtol=RTOL, atol=1e-300)


def _random_parameters(kind, n: int, gen: np.random.Generator) -> dict[str, np.ndarray]:
    """Per-lane parameters of material type ``kind`` drawn inside each parameter's declared
    range (the lower 15% of a wide range such as GGX alpha's (0, 10], where materials live; an
    unbounded one from lo to lo + 4), every choice and both booleans. A type with derived columns
    (tables built per material) gets 6 distinct parameter sets spread over the lanes."""
    sets = 6 if kind.derived else n
    values = {}
    for p in kind.params:
        if p.choices or p.boolean:
            values[p.name] = gen.integers(0, len(p.choices) or 2, sets).astype(np.float64)
            continue
        lo = 0.0 if p.lo is None else p.lo
        hi = lo + 4.0 if p.hi is None else p.hi
        top = hi if hi - lo <= 4.0 else lo + 0.15 * (hi - lo)
        values[p.name] = gen.uniform(lo + 0.01 * (top - lo), top, (sets, p.size)).squeeze(axis=1) \
            if p.size == 1 else gen.uniform(lo, top, (sets, p.size))
    if sets < n:
        which = gen.integers(0, sets, n)
        values = {name: v[which] for name, v in values.items()}
    return values


def _composite_lanes(kind, n: int, gen: np.random.Generator) -> Materials:
    """Lanes of a composite type (a blend): 60 blends of random weight (0 and 1 among them) whose
    parts are random materials that only reflect, with random parameters, laid out as the
    readers lay them out (``blendbsdf.parts``); lane i is a random one of them."""
    from tracer.materials import blendbsdf
    from tracer.textures import tiltable

    leaves = sorted(t.name for t in materials.TYPES.values() if not t.composite and tiltable(t))
    triples = []
    for b in range(60):
        parts = []
        for _ in range(2):
            leaf = materials.TYPES[leaves[gen.integers(len(leaves))]]
            values = {name: v[0] for name, v in _random_parameters(leaf, 1, gen).items()}
            parts.append((leaf.name, values))
        weight = [0.0, 1.0][b] if b < 2 else float(gen.random())
        triples += blendbsdf.parts(f"blend{b}", weight, *parts)
    rows = 1 + 3 * gen.integers(0, 60, n)
    return Materials(materials.table(triples), rows.astype(np.int64))


@pytest.mark.parametrize("type_name", sorted(materials.TYPES))
def test_every_material_keeps_the_interface_contract(type_name):
    """For every registered material type (a new one is tested here without a line of test
    code): sampled lobes are among the type's declared lobes; a delta sample has pdf 0, and
    eval and pdf give 0 for its direction when the type has only delta lobes (no other technique
    may claim it; a mixed type's other lobes may); a valid non-delta
    sample's pdf equals pdf(wo, wi) and its weight equals eval |cos| / pdf, to RTOL; an invalid
    sample has weight 0 and no flags; eval and pdf vanish below the surface unless the type
    ``transmits``; weights are finite and non-negative. Deterministic checks on 50,000 lanes."""
    kind = materials.TYPES[type_name]
    n = 50_000
    gen = rng(22, sorted(materials.TYPES).index(type_name))
    b = _composite_lanes(kind, n, gen) if kind.composite else Materials.per_lane(
        type_name, _random_parameters(kind, n, gen))
    wo = random_upper(n, gen, zmin=0.01)
    s = b.sample(gen.random((n, 3)), wo)
    assert np.all(np.isfinite(s.weight)) and np.all(s.weight >= 0.0)
    assert np.all((s.flags & ~kind.lobes) == 0)
    delta = (s.flags & materials.DELTA) != 0
    valid = (s.flags != 0) & ~delta
    invalid = s.flags == 0
    assert valid.mean() + delta.mean() > 0.5
    assert np.all(s.weight[invalid] == 0.0)
    assert np.all(s.pdf[delta] == 0.0)
    if delta.any() and kind.lobes == materials.DELTA:  # a mixed material's other lobes may see it
        assert np.all(b.take(delta).eval(wo[delta], s.wi[delta]) == 0.0)
        assert np.all(b.take(delta).pdf(wo[delta], s.wi[delta]) == 0.0)
    if valid.any():
        bv, wov, wiv = b.take(valid), wo[valid], s.wi[valid]
        assert np.all(s.pdf[valid] > 0.0)
        np.testing.assert_allclose(bv.pdf(wov, wiv), s.pdf[valid], rtol=RTOL, atol=0)
        expected = bv.eval(wov, wiv) * np.abs(wiv[:, 2:3]) / s.pdf[valid, None]
        np.testing.assert_allclose(s.weight[valid], expected, rtol=RTOL, atol=1e-300)
        if not kind.transmits:  # only a transmitting type samples below the surface
            assert np.all(wiv[:, 2] > 0.0)
    if not kind.transmits:
        below = unit(gen.normal(size=(n, 3)) * [1.0, 1.0, 0.0] - [0.0, 0.0, 0.1])
        assert np.all(b.eval(wo, below) == 0.0) and np.all(b.pdf(wo, below) == 0.0)


def test_mixed_batch_matches_homogeneous_batches():
    """A batch that mixes diffuse, GGX and mirror lanes gives bit-identical sample/eval/pdf to
    the same lanes evaluated kind by kind (lane splitting must not mix up rows)."""
    n = 3000
    gen = rng(8)
    kind = gen.choice(np.array([DIFFUSE, ROUGH_CONDUCTOR, MIRROR]), n)
    b = materials_of(kind, gen.random((n, 3)), gen.uniform(0.05, 1.0, n))
    wo, wi, u = random_upper(n, gen), unit(gen.normal(size=(n, 3))), gen.random((n, 2))
    s, f, p = b.sample(u, wo), b.eval(wo, wi), b.pdf(wo, wi)
    for k in (DIFFUSE, ROUGH_CONDUCTOR, MIRROR):
        idx = np.flatnonzero(kind == k)
        bk = b.take(idx)
        sk = bk.sample(u[idx], wo[idx])
        for name in ("wi", "weight", "pdf", "flags"):
            np.testing.assert_array_equal(getattr(s, name)[idx], getattr(sk, name),
                                          err_msg=f"{k} {name}")
        np.testing.assert_array_equal(f[idx], bk.eval(wo[idx], wi[idx]))
        np.testing.assert_array_equal(p[idx], bk.pdf(wo[idx], wi[idx]))


def test_mirror_is_exact_delta_reflection():
    """Mirror: sample() gives exactly (-wo.x, -wo.y, wo.z) (a sign flip: exact in float), weight
    == reflectance exactly, delta True, pdf 0; eval and pdf are 0 for every direction,
    including the reflection itself (no other technique may claim the delta lobe)."""
    n = 5000
    gen = rng(9)
    wo = random_upper(n, gen)
    refl = gen.random((n, 3))
    b = materials_of(MIRROR, refl, 1.0)
    s = b.sample(gen.random((n, 2)), wo)
    np.testing.assert_array_equal(s.wi, wo * [-1.0, -1.0, 1.0])
    np.testing.assert_allclose(s.wi, wo * np.array([-1.0, -1.0, 1.0]), atol=1e-15)  # reflected about z
    np.testing.assert_array_equal(s.weight, refl)
    assert np.all(s.delta) and np.all(s.pdf == 0.0) and np.all(b.delta)
    for wi in (s.wi, unit(gen.normal(size=(n, 3)))):
        assert np.all(b.eval(wo, wi) == 0.0)
        assert np.all(b.pdf(wo, wi) == 0.0)


def test_bsdfs_vanish_below_the_surface():
    """eval and pdf are exactly 0 for wi.z <= 0 (diffuse and GGX): the pdf integrals below are
    then taken over the upper hemisphere only, with the horizon on a cell boundary."""
    n = 20000
    gen = rng(10)
    wo = random_upper(n, gen)
    wi = unit(gen.normal(size=(n, 3)))
    wi[:, 2] = -np.abs(wi[:, 2])
    wi[:10, 2] = 0.0
    wi = unit(wi)
    for kind in (DIFFUSE, ROUGH_CONDUCTOR):
        b = materials_of(kind, np.ones((n, 3)), gen.uniform(0.05, 1.0, n))
        assert np.all(b.eval(wo, wi) == 0.0) and np.all(b.pdf(wo, wi) == 0.0)


def test_bsdf_eval_is_reciprocal():
    """f(wo, wi) == f(wi, wo) for diffuse and GGX (D(h), G1 G1 and 4 cos cos are symmetric; the
    products are rounded in another order): rtol 1e-12, i.e. a few ulps."""
    n = 50000
    gen = rng(11)
    wo, wi = random_upper(n, gen), random_upper(n, gen)
    for kind in (DIFFUSE, ROUGH_CONDUCTOR):
        b = materials_of(kind, gen.random((n, 3)), gen.uniform(0.02, 1.5, n))
        f1, f2 = b.eval(wo, wi), b.eval(wi, wo)
        assert np.all(f1 >= 0.0) and np.all(np.isfinite(f1))
        np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=0)


# ---------------------------------------------------------------------------------------------
# GGX normalization and energy (numerical integration)


@pytest.mark.parametrize("alpha", [0.01, 0.05, 0.2, 0.7, 1.0, 2.0])
def test_ggx_d_is_normalized(alpha):
    """The integral of D(h) cos(theta_h) over the hemisphere is 1 (D is isotropic: one 1-D
    adaptive quadrature in theta, with the peak at theta ~ alpha as a break point); quad's
    own error estimate is < 1e-11, so 1e-9 is tight yet safe."""
    def integrand(theta):
        return 2.0 * np.pi * warp.ggx_d(np.cos(theta), alpha) * np.cos(theta) * np.sin(theta)

    value, err = integrate.quad(integrand, 0.0, np.pi / 2, points=[np.arctan(alpha)], limit=200,
                                epsabs=1e-13, epsrel=1e-12)
    assert err < 1e-11
    assert abs(value - 1.0) < 1e-9, value


def cubature(func, domain=None, shape=(16, 32), tol=1e-9, max_level=12):
    return chi2.integrate_cells(func, domain or hemisphere(), shape, tol, sub=6,
                                max_level=max_level)


@pytest.mark.parametrize("alpha,wo_name", GGX_CASES)
def test_ggx_pdf_mass_and_energy(alpha, wo_name):
    """Numerical integrals (adaptive cubature with every discontinuity on a cell boundary;
    1e-6 is > 10x its reported error, and a wrong Jacobian or a missing factor is O(1)):

    - the visible-normal pdf integrates to 1 over h (Heitz 2018: Smith's G1 is exactly the
      projected-area normalization of D);
    - q(wi) = D_wo(h) / (4 wo.h), h = normalize(wo + wi), the density of reflect(wo, h) on the
      whole sphere, integrates to 1 over wi (this checks the 1/(4 wo.h) Jacobian); it is 0 for
      wi.z < -wo.z, where h.z < 0, so that cone is the domain's boundary;
    - Materials.pdf equals q where wi.z > 0 and 0 elsewhere (pointwise, RTOL): its integral over wi
      is P(reflect(wo, h).z > 0) <= 1, the mass the sampler keeps (the chi-square test checks
      the same mass statistically through its rest cell);
    - the white furnace: the integral of f cos over wi (reflectance 1) is <= 1 and equals the
      integral of pdf(wi) G1(wi) (the mean sample weight), which is <= that mass."""
    wo = WO_CASES[wo_name]

    def tile(x, m):
        return np.tile(x, (m, 1))

    def vndf(h):
        return warp.pdf_ggx_visible_normal(h, tile(wo, len(h)), np.full(len(h), alpha))

    def q(wi):
        h = unit(wo + wi)
        return vndf(h) / (4.0 * np.sum(wo * h, axis=1))

    pdf = bsdf_pdf_of(ROUGH_CONDUCTOR, wo, alpha)

    def f_cos(wi):
        b = make_bsdf(ROUGH_CONDUCTOR, len(wi), alpha, (1.0, 1.0, 1.0))
        return b.eval(tile(wo, len(wi)), wi)[:, 0] * wi[:, 2]

    def pdf_g1(wi):
        return pdf(wi) * warp.ggx_g1_array(wi, np.full(len(wi), alpha))

    wi = unit(rng(14).normal(size=(100000, 3)))
    np.testing.assert_allclose(pdf(wi), np.where(wi[:, 2] > 0.0, q(wi), 0.0), rtol=RTOL, atol=0)

    c_vndf = cubature(vndf)
    c_q = cubature(q, chi2.spherical_domain((0.0, 0.0, 1.0), np.pi - np.arccos(wo[2])))
    c_pdf, c_f, c_g1 = cubature(pdf), cubature(f_cos), cubature(pdf_g1)
    for c in (c_vndf, c_q, c_pdf, c_f, c_g1):
        assert c.total_error < 1e-7, c.total_error
    assert abs(c_vndf.total - 1.0) < 1e-6, c_vndf.total
    assert abs(c_q.total - 1.0) < 1e-6, c_q.total
    assert c_pdf.total <= 1.0 + 1e-6, c_pdf.total
    assert c_f.total <= 1.0 + 1e-6, c_f.total
    assert abs(c_f.total - c_g1.total) < 1e-6, (c_f.total, c_g1.total)
    assert c_g1.total <= c_pdf.total + 1e-6
    print(f"alpha={alpha} wo={wo_name}: P(up)={c_pdf.total:.6f} albedo={c_f.total:.6f}")


def test_diffuse_energy_and_mass():
    """Lambertian: the integral of f cos over wi is the reflectance and pdf integrates to 1
    (smooth integrands, exact Gauss rules: 1e-9)."""
    wo = WO_CASES["oblique"]
    refl = (0.9, 0.6, 0.3)

    def f_cos(wi):
        b = make_bsdf(DIFFUSE, len(wi), 1.0, refl)
        return b.eval(np.tile(wo, (len(wi), 1)), wi)[:, 1] * wi[:, 2]

    assert abs(cubature(f_cos).total - 0.6) < 1e-9
    assert abs(cubature(bsdf_pdf_of(DIFFUSE, wo)).total - 1.0) < 1e-9


# ---------------------------------------------------------------------------------------------
# Light sampling


CAMERA = """
[camera]
origin = [0.0, 0.5, 4.0]
target = [0.0, 0.5, 0.0]
fov = 40.0
width = 4
height = 4
"""

LIGHT_SCENES = {
    # One tilted quad facing down and toward +z: cos(theta_light) and d vary across it.
    "quad": ("""
[[shapes]]
type = "quad"
origin = [-0.4, 1.0, -0.3]
edge1 = [0.8, 0.0, 0.0]
edge2 = [0.0, 0.3, 0.6]
emission = [3.0, 2.0, 1.0]
""", np.array([0.1, 0.0, 0.5]), "power"),
    # A tessellated sphere: about half its facets face away from x (invalid samples), and the
    # facets near the silhouette are seen at grazing angles (large pdf).
    "sphere": ("""
[[shapes]]
type = "sphere"
center = [0.2, 1.5, -0.1]
radius = 0.4
subdivisions = 2
emission = [5.0, 5.0, 5.0]
""", np.array([0.0, 0.0, 0.0]), "power"),
    # Two quads of different power (flux ratio 2.4 : 1.44), disjoint as seen from x.
    "two_power": ("""
[[shapes]]
type = "quad"
origin = [-0.8, 1.2, -0.2]
edge1 = [0.3, 0.0, 0.0]
edge2 = [0.0, 0.0, 0.4]
emission = [20.0, 20.0, 20.0]

[[shapes]]
type = "quad"
origin = [0.2, 1.0, -0.5]
edge1 = [0.6, 0.0, 0.0]
edge2 = [0.0, 0.0, 0.8]
emission = [2.0, 3.0, 4.0]
""", np.array([0.0, 0.0, 0.0]), "power"),
}
LIGHT_SCENES["two_uniform"] = (*LIGHT_SCENES["two_power"][:2], "uniform")


def light_setup(case: str, tmp_path):
    text, x, selection = LIGHT_SCENES[case]
    path = tmp_path / f"{case}.toml"
    path.write_text(textwrap.dedent(CAMERA + text))
    scene = load_scene(path)
    return scene, LightSampler(scene, selection), RayCaster(scene.vertices, scene.faces), x


def light_pdf_on_sphere(sampler: LightSampler, caster: RayCaster, x: np.ndarray,
                        light: int | None = None):
    """w (m, 3) world unit -> LightSampler.pdf for the triangle the ray x + t w hits first, 0 on
    a miss (or, with ``light``, on triangles of other lights). With convex, mutually disjoint
    emitters and no occluders, the first hit is the only emitter point in direction w, so
    this is the full solid-angle density of light samples."""
    scene = sampler.scene

    def pdf(w: np.ndarray) -> np.ndarray:
        hits = caster.intersect(np.tile(x, (len(w), 1)), w)
        found = hits.prim >= 0
        if light is not None:
            found &= scene.light_of_triangle[np.maximum(hits.prim, 0)] == light
        p = np.zeros(len(w))
        p[found] = sampler.pdf(np.tile(x, (int(found.sum()), 1)), hits.prim[found], w[found], hits.t[found])
        return p
    return pdf


def light_cap(scene, x: np.ndarray) -> chi2.Domain:
    """The cone from x around all emissive vertices (a convex cone holding their hull)."""
    emissive = np.unique(scene.faces[scene.light_of_triangle >= 0])
    d = unit(scene.vertices[emissive] - x)
    axis = unit(d.mean(axis=0))
    theta = np.arccos(np.clip(d @ axis, -1.0, 1.0)).max()
    return chi2.spherical_domain(axis, min(np.pi, 1.02 * theta + 1e-3))


def expected_pmf(scene, selection: str) -> np.ndarray:
    """Selection probability of every triangle, from the documented rule (written here
    independently of lights.py): 'power' in proportion to area * mean(Le) (pi cancels);
    'uniform' 1 / (number of lights) times the triangle's share of its light's area."""
    light = scene.light_of_triangle
    emissive = light >= 0
    if selection == "power":
        w = np.where(emissive, scene.area * scene.emission.mean(axis=1), 0.0)
        return w / w.sum()
    lights = np.unique(light[emissive])
    p = np.zeros(len(light))
    for k in lights:
        mine = light == k
        p[mine] = scene.area[mine] / scene.area[mine].sum() / len(lights)
    return p


def front_mass(scene, selection: str, x: np.ndarray) -> float:
    """Selection probability of the triangles that face x: a planar triangle faces x entirely
    or not at all, so this is exactly the probability that a light sample is valid."""
    front = np.sum(scene.normal * (scene.v0 - x), axis=1) < 0.0
    return float(expected_pmf(scene, selection)[front].sum())


# The quad case takes 37 s (its chi-square grid is the finest): slow since tracer 0.7, for the
# CI budget; the closed-form tests of test_estimators sample quad lights in every run.
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c == "quad" else c
                                  for c in LIGHT_CASES])
def test_light_sampling_chi2(case, tmp_path):
    """Directions of valid light samples vs. LightSampler.pdf of the first hit in that direction
    (selection probability included), on a cap around the lights; invalid samples (back-facing
    facets) go to the rest cell, which expects N (1 - mass); level ALPHA. The integral of the
    pdf over the cap must equal that mass, the selection probability of the front-facing
    triangles (1 for quads), within the cubature's reported error (an overestimate: the
    actual differences are 4-10x smaller), which must itself be < 1e-3."""
    scene, sampler, caster, x = light_setup(case, tmp_path)
    gen = rng(12, LIGHT_CASES.index(case))
    s = sampler.sample(gen.random(N_SAMPLES), gen.random((N_SAMPLES, 2)),
                       np.tile(x, (N_SAMPLES, 1)))
    valid = (s.pdf > 0.0) & ~s.delta
    assert np.all(s.radiance[~valid] == 0.0)
    mass = front_mass(scene, sampler.selection, x)
    if case != "sphere":
        assert mass == pytest.approx(1.0, abs=1e-12)
    result = chi2.goodness_of_fit(s.wi, light_pdf_on_sphere(sampler, caster, x),
                                  light_cap(scene, x),
                                  GRID, ALPHA, valid=valid, mass=mass, name=f"light {case}")
    print(f"integral - mass = {result.integral - mass:.2e}, "
          f"estimated error {result.integration_error:.1e}")
    assert abs(result.integral - mass) < max(result.integration_error, 1e-6), result.report()
    assert result.integration_error < 1e-3
    check(result)


@pytest.mark.parametrize("case", LIGHT_CASES)
def test_light_sample_pdf_agrees_with_pdf(case, tmp_path):
    """For valid light samples, LightSampler.pdf(x, prim, wi, dist) equals the sample's pdf to
    RTOL, with prim found by casting the ray (Embree is float32, so lanes whose hit lies within
    1e-4 of a triangle edge, where the neighbour may be reported, are left out: the pdf is
    discontinuous across sphere facets). The cast distance matches dist to float32 accuracy."""
    scene, sampler, caster, x = light_setup(case, tmp_path)
    n = 100_000
    gen = rng(13, LIGHT_CASES.index(case))
    s = sampler.sample(gen.random(n), gen.random((n, 2)), np.tile(x, (n, 1)))
    valid = (s.pdf > 0.0) & ~s.delta
    assert valid.mean() > (0.3 if case == "sphere" else 0.999)
    wi, dist, pdf = s.wi[valid], s.dist[valid], s.pdf[valid]
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    hits = caster.intersect(np.tile(x, (len(wi), 1)), wi)
    assert np.all(hits.prim >= 0)
    np.testing.assert_allclose(hits.t, dist, rtol=1e-5)
    inner = np.minimum(np.minimum(hits.u, hits.v), 1.0 - hits.u - hits.v) > 1e-4
    assert inner.mean() > 0.95
    xs = np.tile(x, (len(wi), 1))
    np.testing.assert_allclose(sampler.pdf(xs[inner], hits.prim[inner], wi[inner], dist[inner]), pdf[inner],
                               rtol=RTOL, atol=0)
    # Seen from the back (the same triangle, the direction reversed), a one-sided emitter has pdf 0.
    assert np.all(sampler.pdf(xs, hits.prim, -wi, dist) == 0.0)
    # The radiance is the emission of the triangle the direction hits (exact copy).
    np.testing.assert_array_equal(s.radiance[valid][inner], scene.emission[hits.prim[inner]])


SHIPPED_SCENES = ("veach_mis", "cornell", "tiny_light", "point_light", "big_light", "near_mirror")


@pytest.mark.parametrize("name", SHIPPED_SCENES)
def test_culled_rays_cannot_reach_an_emitter(name):
    """The estimator does not cast a direction sample whose ray meets none of the emitter
    bounding spheres (lights.may_reach). Deterministic check on 20000 random rays from random
    points in the scene's box and on its surfaces: every ray whose first hit (Embree's triangles
    and the analytic spheres, ``geometry.SceneRays``) is an emitter meets a bounding sphere.
    The test is not vacuous: rays hit each scene's
    emitter (over a hundred rays; tiny_light's sphere is too small for that), and where lights
    are small (veach_mis, cornell, tiny_light) over 30% of these rays are culled (94% of the
    BSDF rays in a veach_mis render)."""
    scene = load_scene(str(default_scene_path().parent / f"{name}.toml"), 16, 16)
    tables = LightSampler(scene).tables
    rays = SceneRays(scene)
    gen = rng(21, SHIPPED_SCENES.index(name))
    n = 20000
    corners = np.concatenate([scene.vertices, scene.spheres[:, :3] - scene.spheres[:, 3:],
                              scene.spheres[:, :3] + scene.spheres[:, 3:]])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    origins = lo + (hi - lo) * gen.random((n, 3))
    on_surface = gen.random(n) < 0.5  # half the origins on random triangles, just off them
    tri = gen.integers(0, len(scene.faces), n)
    b = warp.sample_triangle_barycentric(gen.random((n, 2)))
    points = scene.v0[tri] + b[:, :1] * scene.edge1[tri] + b[:, 1:] * scene.edge2[tri]
    origins[on_surface] = (points + scene.ray_epsilon * scene.normal[tri])[on_surface]
    dirs = gen.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hit = rays.first_hit(origins.astype(np.float32), dirs.astype(np.float32))
    emitter = (hit >= 0) & (scene.hit_table[np.maximum(hit, 0), 12:15].max(axis=1) > 0.0)
    reach = np.array([lights.may_reach(tables.spheres, tuple(o), tuple(w))
                      for o, w in zip(origins, dirs, strict=True)])
    assert np.all(reach[emitter]), np.flatnonzero(emitter & ~reach)[:5]
    if len(tables.spheres) == 0:
        assert not reach.any()
    elif name != "tiny_light":
        assert emitter.sum() > 100, emitter.sum()
    if name in ("veach_mis", "cornell", "tiny_light"):
        assert (~reach).mean() > 0.3, (~reach).mean()


def test_point_light_is_a_delta_sample(tmp_path):
    """A point light beside a quad light: with 'power' selection it gets the share
    4 pi mean(I) / (4 pi mean(I) + pi area mean(Le)) of the samples (two-sided binomial test at
    level ALPHA), and its samples are delta with wi = unit(p - x), dist = |p - x|,
    radiance = I / d^2 and pdf = its selection probability (float64 formulas: RTOL)."""
    text = CAMERA + LIGHT_SCENES["quad"][0] + """
[[lights]]
type = "point"
position = [0.6, 0.9, -0.2]
intensity = [1.0, 2.0, 3.0]
"""
    path = tmp_path / "point.toml"
    path.write_text(textwrap.dedent(text))
    scene = load_scene(path)
    sampler = LightSampler(scene, "power")
    x = np.array([0.1, 0.0, 0.5])
    flux_point = 4.0 * np.pi * 2.0
    flux_quad = np.pi * scene.area.sum() * 2.0
    share = flux_point / (flux_point + flux_quad)
    gen = rng(16)
    s = sampler.sample(gen.random(N_SAMPLES), gen.random((N_SAMPLES, 2)),
                       np.tile(x, (N_SAMPLES, 1)))
    p = stats.binomtest(int(s.delta.sum()), N_SAMPLES, share).pvalue
    print(f"point light share {share:.4f}, observed {s.delta.mean():.4f}, p={p:.3g}")
    assert p >= ALPHA
    # The scene holds light positions and intensities at float32 precision, as its light table
    # does; the formulas below start from those values.
    d = scene.point_position[0] - x
    dist = np.linalg.norm(d)
    m = int(s.delta.sum())
    np.testing.assert_allclose(s.wi[s.delta], np.tile(d / dist, (m, 1)), rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose(s.dist[s.delta], dist, rtol=RTOL)
    np.testing.assert_allclose(s.radiance[s.delta], np.tile(scene.point_intensity[0], (m, 1)) / dist**2,
                               rtol=RTOL)
    np.testing.assert_allclose(s.pdf[s.delta], share, rtol=RTOL)
    assert np.all(s.pdf[~s.delta] > 0.0)


@pytest.mark.parametrize("case", ["two_power", "two_uniform"])
def test_light_selection_probabilities(case, tmp_path):
    """Each light receives its documented share of the samples: 'power' selects in proportion
    to area * mean(Le) (here 2.4 : 1.44), 'uniform' 1/2 each. Deterministic: the integral of
    LightSampler.pdf over the directions of light k equals that share, within the cubature's
    reported error. Statistical: the number of samples hitting light k is Binomial(N, share),
    two-sided exact test at level ALPHA (it shares the file's Sidak budget). The chi-square
    test alone would pass a sampler whose sample() and pdf() agreed on a wrong share."""
    scene, sampler, caster, x = light_setup(case, tmp_path)
    emissive = scene.light_of_triangle >= 0
    share = np.bincount(scene.light_of_triangle[emissive],
                        weights=expected_pmf(scene, sampler.selection)[emissive])
    gen = rng(15, LIGHT_CASES.index(case))
    s = sampler.sample(gen.random(N_SAMPLES), gen.random((N_SAMPLES, 2)),
                       np.tile(x, (N_SAMPLES, 1)))
    hits = caster.intersect(np.tile(x, (N_SAMPLES, 1)), s.wi)
    assert np.all(hits.prim >= 0)
    count = np.bincount(scene.light_of_triangle[hits.prim], minlength=len(share))
    for k in range(len(share)):
        # Absolute tolerance 1e-7 per cell: the 3200 cells' total stays < 1e-4.
        cub = chi2.integrate_cells(light_pdf_on_sphere(sampler, caster, x, light=k),
                                   light_cap(scene, x), GRID, 1e-7, max_level=8)
        assert cub.total_error < 1e-4
        assert abs(cub.total - share[k]) < cub.total_error + 1e-6, (k, cub.total, share[k])
        p = stats.binomtest(int(count[k]), N_SAMPLES, share[k]).pvalue
        print(f"light {k}: share {share[k]:.4f}, integral {cub.total:.6f}, "
              f"samples {count[k]}, p={p:.3g}")
        assert p >= ALPHA, (k, count[k], share[k], p)
