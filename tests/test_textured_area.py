"""Textured area emitters sampled by area x texel luminance (``tracer.lights.textured_area``,
the ``triangle_texels`` technique).

- the footprint integrals (each triangle's mean radiance, hence its flux and selection weight)
  against a dense quadrature of the kernels' own lookup (``lookup.emitted``);
- the technique's points against its pdf by chi-square, in the texture's own grid, where the
  density is constant on each cell; the cubature of the pdf over the emitter is 1;
- ``pdf`` of the hit equals the pdf ``sample`` returned, lane by lane;
- the table's share: a large footprint is cut into blocks that still sample exactly.

Configurations: a rectangle (Mitsuba's, two triangles) whose radiance is a bitmap with a bright
spot, a black texel and a dim rest, under a ``to_uv`` that rotates, scales and shifts it (so
the footprint crosses texel cells at a slant and spans more than one period), for each filter
and wrap mode; a checkerboard; an OBJ quad whose coordinates leave [0, 1]^2 with a seam
between its triangles. The unbiasedness of renders is tested in test_textured_emitters.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.estimator import DirectLighting
from tracer.geometry import SceneRays
from tracer.jit import jit
from tracer.lights import LightSampler, technique_names, textured_area
from tracer.textures import LUMINANCE, lookup

import chi2

ASSETS = Path(tracer.__file__).parent / "scenes" / "mitsuba"
CAMERA = """<sensor type="perspective"><transform name="to_world">
    <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>"""
RECTANGLE = """<shape type="rectangle"><transform name="to_world"><scale x="1.2" y="0.7"/>
    <rotate x="1" angle="20"/><translate y="1.0"/></transform>
    <emitter type="area">{texture}</emitter></shape>"""
TO_UV = ('<transform name="to_uv"><rotate z="1" angle="30"/><scale x="1.7" y="1.3"/>'
         '<translate x="0.2" y="-0.1"/></transform>')
BITMAP = ('<texture name="radiance" type="bitmap"><string name="filename" value="{path}"/>'
          '<string name="filter_type" value="{filter}"/><string name="wrap_mode" value="{wrap}"/>'
          + TO_UV + '</texture>')
CHECKER = ('<texture name="radiance" type="checkerboard"><rgb name="color0" value="2.0"/><rgb name="color1" '
           'value="0.1"/><transform name="to_uv"><scale x="3" y="2"/></transform></texture>')
QUAD_OBJ = f"""<shape type="obj"><string name="filename" value="{ASSETS}/meshes/quad_uv.obj"/>
    <transform name="to_world"><scale x="0.9" y="0.6"/><rotate x="1" angle="25"/><translate y="1.0"/>
    </transform>
    <emitter type="area"><texture name="radiance" type="bitmap">
    <string name="filename" value="{ASSETS}/textures/tiles.png"/><string name="filter_type" value="nearest"/>
    </texture></emitter></shape>"""
BITMAPS = [("bilinear", "repeat"), ("bilinear", "mirror"), ("bilinear", "clamp"), ("nearest", "repeat"),
           ("nearest", "clamp")]
# The shading point: below the emitters, facing them.
X, N = np.array([0.1, -0.5, 0.3]), np.array([0.0, 1.0, 0.0])
CHI2_CASES = [f"{f} {w}" for f, w in BITMAPS] + ["checkerboard"]
ALPHA = chi2.sidak(len(CHI2_CASES))
N_SAMPLES = 400_000
# sample()'s pdf against pdf() of the hit: the same float64 formulas on the same float32 table,
# the point rebuilt from x + dist wi. A point within ~1e-15 of a block's edge may be found in the
# next block: where the texture is uniform, the float32 CDFs give neighbours probabilities that
# differ by up to 6e-8 (seen: 6.9e-8 in 1 lane of 50,000).
RTOL = 1e-6
# A block's probability is a difference of float32 CDF values: its relative error is up to
# 6e-8 over the block's share of its row (1e-4 for shares down to 6e-4).
RATIO_RTOL = 1e-4


def _spot(grey: bool) -> np.ndarray:
    """8 x 6 texels: dim 0.05, a bright texel (40), a green one, a black one (grey: their
    luminance in all three channels, so that luminance and the channels' mean agree)."""
    pixels = np.full((6, 8, 3), 0.05)
    pixels[2, 5], pixels[4, 1], pixels[0, 0] = (40.0, 30.0, 20.0), (0.0, 5.0, 0.0), 0.0
    if grey:
        pixels[:] = (pixels @ np.array([0.212671, 0.715160, 0.072169]))[..., None]
    return pixels


def _write(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.FLOAT)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels.astype(np.float32))
    out.close()


def _scene(tmp_path: Path, case: str, grey: bool = False):
    """The scene of ``case``: ``filter wrap`` (the bitmap rectangle), ``checkerboard`` or
    ``obj``."""
    path = tmp_path / f"spot{'_grey' if grey else ''}.exr"
    if not path.exists():
        _write(path, _spot(grey))
    if case == "obj":
        shape = QUAD_OBJ
    elif case == "checkerboard":
        shape = RECTANGLE.format(texture=CHECKER)
    else:
        filt, wrap = case.split()
        shape = RECTANGLE.format(texture=BITMAP.format(path=path, filter=filt, wrap=wrap))
    file = tmp_path / f"{case.replace(' ', '_')}{'_grey' if grey else ''}.xml"
    file.write_text(f'<scene version="3.0.0">{CAMERA}{shape}</scene>')
    return tracer.load_scene(file)


@jit
def _mean_of_lookups(textures, hit_table, first_sphere, p, v0, e1, e2, n):
    """The midpoint rule over an n x n grid of the square folded onto triangle p (the
    parallelogram v0 + a e1 + b e2, a + b <= 1 kept, cells on the diagonal halved): the mean
    of ``lookup.emitted`` over the triangle, RGB."""
    total = np.zeros(3)
    weight = 0.0
    for i in range(n):
        for j in range(n - i):
            a, b = (i + 0.5) / n, (j + 0.5) / n
            w = 0.5 if i + j == n - 1 else 1.0
            x = (v0[0] + a * e1[0] + b * e2[0], v0[1] + a * e1[1] + b * e2[1], v0[2] + a * e1[2] + b * e2[2])
            r, g, bb = lookup.emitted(textures, hit_table, first_sphere, p, x)
            total[0] += w * r
            total[1] += w * g
            total[2] += w * bb
            weight += w
    return total / weight


@pytest.mark.parametrize("case", CHI2_CASES + ["obj"])
def test_footprint_means_are_the_lookup_integrated(tmp_path, case):
    """``textured_area.mean_radiance`` of each emitting triangle (exact moments of the clipped
    cells) against the midpoint rule over 1500 x 1500 points of the triangle of the kernels'
    lookup itself: a check of the grid, wraps, offsets and moments against code that shares
    none of them. The midpoint rule is exact to O(h^2) where the lookup is smooth and to O(h)
    along its jumps (nearest texels, the checkerboard, clamped edges): with h = 1/1500 of the
    triangle and the spot's jump of 40 over one texel's edges, 1e-3 relative bounds it (the
    largest seen is 2.3e-4); bilinear lookups, continuous, agree to 1e-5."""
    scene = _scene(tmp_path, case)
    surfaces = DirectLighting(scene, tracer.Strategy("light")).surfaces
    triangles = np.arange(scene.triangle_count)
    exact = textured_area.mean_radiance(scene, triangles)
    assert np.all(textured_area.sampled_by_texels(scene, triangles))
    for p in triangles:
        dense = _mean_of_lookups(surfaces.textures, surfaces.hit_table, surfaces.first_sphere, int(p),
                                 tuple(scene.v0[p]), tuple(scene.edge1[p]), tuple(scene.edge2[p]), 1500)
        tolerance = 1e-5 if case.startswith("bilinear") else 1e-3
        np.testing.assert_allclose(exact[p], dense, rtol=tolerance, atol=1e-9, err_msg=f"triangle {p}")


def _grid_domain(scene, sampler: LightSampler):
    """The rectangle parametrized by the grid coordinates of its texture (``Grid.corners``),
    whose cells are the lookup's: ``(domain, grid shape, pdf over area, the rectangle's
    triangle of a point)``. Points of the plane outside the rectangle map to NaN."""
    first = scene.shapes[0].first
    grid = textured_area.Grid.of(scene.textures.textures[0])
    uv = textured_area.corner_uv(scene, np.array([first]))[0]
    corners = grid.corners(uv)  # triangle (o, o + e1, o + e1 + e2)
    o, e1 = scene.v0[first], scene.edge1[first]
    e12 = scene.edge2[first]
    to_grid = np.stack([corners[1] - corners[0], corners[2] - corners[1]], axis=1)  # per (s, t)
    e2 = e12 - e1
    to_st = np.linalg.inv(to_grid)
    quad = np.array([corners[0], corners[1], corners[2], corners[0] + to_grid[:, 1]])
    lo, hi = np.floor(quad.min(axis=0)), np.ceil(quad.max(axis=0))
    area = float(np.linalg.norm(np.cross(e1, e2)))
    normal = np.cross(e1, e2) / area
    jacobian = area / abs(np.linalg.det(to_grid))  # surface area per unit grid area

    def st_of(g):
        return (g - corners[0]) @ to_st.T

    def forward(g):
        st = st_of(g)
        return o + st[:, :1] * e1 + st[:, 1:] * e2

    def inverse(y):
        st = np.linalg.lstsq(np.stack([e1, e2], axis=1), (y - o).T, rcond=None)[0].T
        outside = np.any((st < -1e-7) | (st > 1.0 + 1e-7), axis=1)
        g = corners[0] + st @ to_grid.T
        return np.where(outside[:, None], np.nan, g)

    def triangle_of(y):
        st = np.linalg.lstsq(np.stack([e1, e2], axis=1), (y - o).T, rcond=None)[0].T
        return np.where(st[:, 0] >= st[:, 1], first, first + 1), st

    def pdf(y):
        prim, st = triangle_of(y)
        inside = np.all((st >= 0.0) & (st <= 1.0), axis=1)
        v = y - X
        d = np.linalg.norm(v, axis=1)
        wi = v / d[:, None]
        p = sampler.pdf(np.tile(X, (len(y), 1)), prim, wi, d, np.tile(N, (len(y), 1)))
        return np.where(inside, p * np.maximum(-(wi @ normal), 0.0) / d**2, 0.0)

    domain = chi2.Domain("texture grid", ((lo[0], hi[0]), (lo[1], hi[1])), forward, inverse,
                         lambda g: np.full(len(g), jacobian), ("gx", "gy"))
    return domain, (int(hi[0] - lo[0]), int(hi[1] - lo[1])), pdf, triangle_of


@pytest.mark.parametrize("case", CHI2_CASES)
def test_texel_sampling_chi2(tmp_path, case):
    """Points of ``LightSampler.sample`` (both triangles, chosen by the selection) against the
    density ``LightSampler.pdf`` gives them, over the rectangle in its texture's grid: the
    chi-square cells are the lookup's cells, on which the density is constant (the texture is
    grey, so that the two triangles' densities agree along the diagonal), so the cubature is
    exact but along the rectangle's slanted outline. The cubature of the pdf over the rectangle
    is 1 (the pdf is normalized: every sample is valid, x sees the front). At ALPHA, Sidak over
    this file's chi-square tests; the seed is fixed."""
    scene = _scene(tmp_path, case, grey=True)
    sampler = LightSampler(scene, "power", "area")
    assert set(sampler.tables.technique.tolist()) == {9}  # triangle_texels
    domain, shape, pdf, _ = _grid_domain(scene, sampler)
    gen = np.random.default_rng([20261205, CHI2_CASES.index(case)])
    s = sampler.sample(gen.random(N_SAMPLES), gen.random((N_SAMPLES, 2)), np.tile(X, (N_SAMPLES, 1)),
                       np.tile(N, (N_SAMPLES, 1)))
    valid = s.pdf > 0.0
    assert valid.all()
    points = X + s.dist[:, None] * s.wi
    result = chi2.goodness_of_fit(points, pdf, domain, shape, ALPHA, valid=valid, mass=1.0, name=case)
    print(result.report())
    assert abs(result.integral - 1.0) < max(result.integration_error, 1e-5), result.report()
    assert result.passed, result.report()
    assert result.integration_chi2 < 0.1 * np.sqrt(2.0 * result.dof), result.report()


@pytest.mark.parametrize("case", CHI2_CASES + ["obj"])
def test_sample_pdf_equals_pdf_of_the_hit(tmp_path, case):
    """For every sample, ``pdf`` of the primitive a ray along it hits, at the sampled distance,
    equals the pdf ``sample`` returned (RTOL), so BSDF samples get the weight light sampling
    has. Left out:
    samples within 1e-6 (in barycentrics) of the edge the two triangles share, where the ray may
    find the other triangle, whose density differs (a coloured texture: its selection weight
    follows the channels' mean, its points the luminance)."""
    scene = _scene(tmp_path, case)
    _pdf_of_hits_agree(scene, LightSampler(scene, "power", "area"), 50_000,
                       [20261205, 100 + (CHI2_CASES + ["obj"]).index(case)])


def _pdf_of_hits_agree(scene, sampler: LightSampler, m: int, seed) -> None:
    """``test_sample_pdf_equals_pdf_of_the_hit`` for ``m`` samples of ``sampler``."""
    gen = np.random.default_rng(seed)
    s = sampler.sample(gen.random(m), gen.random((m, 2)), np.tile(X, (m, 1)), np.tile(N, (m, 1)))
    assert np.all(s.pdf > 0.0)
    prim = SceneRays(scene).first_hit(np.tile(X, (m, 1)).astype(np.float32), s.wi.astype(np.float32))
    y = X + s.dist[:, None] * s.wi
    shared = np.zeros(m, dtype=bool)
    for p in (0, 1):  # near the diagonal: a barycentric of either triangle near 0
        c = np.cross(scene.edge1[p], scene.edge2[p])
        b1 = np.cross(y - scene.v0[p], scene.edge2[p]) @ c / (c @ c)
        b2 = np.cross(scene.edge1[p], y - scene.v0[p]) @ c / (c @ c)
        shared |= np.minimum(np.abs(b1), np.abs(b2)) < 1e-6
    keep = (prim >= 0) & ~shared
    assert keep.mean() > 0.999
    again = sampler.pdf(np.tile(X, (keep.sum(), 1)), prim[keep], s.wi[keep], s.dist[keep],
                        np.tile(N, (keep.sum(), 1)))
    np.testing.assert_allclose(again, s.pdf[keep], rtol=RTOL)


def test_large_footprints_are_sampled_by_blocks(tmp_path, monkeypatch):
    """With the table's share cut to 12 blocks a triangle, the rectangle's footprints (about 70
    bilinear cells each) are sampled by blocks of cells: still an exact, normalized density (the
    probabilities the CDFs give sum to 1 over the blocks; ``pdf`` of the hit equals the sampled
    pdf), every block where the texture is positive keeps positive probability, and the mean
    radiance does not change (it is integrated at the texels' resolution)."""
    scene = _scene(tmp_path, "bilinear repeat")
    triangles = np.arange(scene.triangle_count)
    fine, mean = textured_area.texel_tables(scene, triangles)
    monkeypatch.setattr(textured_area, "TABLE_FLOATS", 3 * 2 * 12)
    coarse, coarse_mean = textured_area.texel_tables(scene, triangles)
    np.testing.assert_allclose(coarse_mean, mean, rtol=1e-12)
    for t in triangles:
        assert coarse.shape[t].prod() <= 12 < fine.shape[t].prod()
        np.testing.assert_allclose(coarse.probability(t).sum(), 1.0, rtol=1e-6)
        # Every block the triangle touches (found by points of the triangle mapped by the
        # table's own barycentric map) can be drawn: the dim rest of the texture is positive.
        a, b = np.meshgrid(np.linspace(0.0, 1.0, 201), np.linspace(0.0, 1.0, 201))
        inside = a + b <= 1.0
        g = coarse.origin[t] + np.stack([a[inside], b[inside]], axis=1) @ coarse.to_grid[t].T
        rows, columns = coarse.shape[t]
        touched = np.zeros((rows, columns), dtype=bool)
        touched[np.clip(g[:, 1].astype(int), 0, rows - 1),
                np.clip(g[:, 0].astype(int), 0, columns - 1)] = True
        assert np.all(coarse.probability(t)[touched] > 0.0)
    _pdf_of_hits_agree(scene, LightSampler(scene, "power", "area"), 20_000, 20261206)


@pytest.mark.parametrize("case", ["nearest repeat", "nearest clamp", "checkerboard", "obj"])
def test_density_follows_the_texture(tmp_path, case):
    """With a nearest lookup the density is the texture's luminance at the point times one
    constant per triangle (area x texel luminance): at sampled points, pdf_A / luminance(y)
    (luminance by the kernels' own lookup, ``lookup.emitted``) is the same within each triangle
    to RATIO_RTOL (no texel here is below the CDF's floor, 2^-22 of a row's light). The OBJ
    quad's triangles map (u, v) one with and one against the orientation of their corners."""
    scene = _scene(tmp_path, case)
    sampler = LightSampler(scene, "power", "area")
    surfaces = DirectLighting(scene, tracer.Strategy("light")).surfaces
    m = 4000
    gen = np.random.default_rng(20261207)
    s = sampler.sample(gen.random(m), gen.random((m, 2)), np.tile(X, (m, 1)), np.tile(N, (m, 1)))
    y = X + s.dist[:, None] * s.wi
    prim = SceneRays(scene).first_hit(np.tile(X, (m, 1)).astype(np.float32), s.wi.astype(np.float32))
    luminance = np.array([np.array(lookup.emitted(surfaces.textures, surfaces.hit_table, surfaces.first_sphere,
                                                  int(p), tuple(point))) @ LUMINANCE
                          for p, point in zip(prim, y, strict=True)])
    cos_light = -np.sum(s.wi * scene.normal[prim], axis=1)
    ratio = s.pdf * cos_light / s.dist**2 / luminance
    for p in np.unique(prim):
        mine = ratio[prim == p]
        np.testing.assert_allclose(mine, np.median(mine), rtol=RATIO_RTOL, err_msg=f"triangle {p}")


def test_selections_weigh_textured_triangles_by_their_light(tmp_path):
    """Part 1 as the selections see it, on a textured rectangle beside an untextured one:
    ``power`` gives each candidate pi area x the channels' mean of its mean radiance (the
    textured triangles' from ``mean_radiance``, not the texture's mean), and ``uniform`` gives
    each shape 1/2 and splits the textured one between its triangles in proportion to that
    flux (the untextured one by area, as before)."""
    plain = ('<shape type="rectangle"><transform name="to_world"><translate x="3"/></transform>'
             '<emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>')
    path = tmp_path / "spot.exr"
    _write(path, _spot(False))
    file = tmp_path / "two.xml"
    file.write_text(f'<scene version="3.0.0">{CAMERA}'
                    f'{RECTANGLE.format(texture=BITMAP.format(path=path, filter="nearest", wrap="repeat"))}'
                    f'{plain}</scene>')
    scene = tracer.load_scene(file)
    triangles = np.arange(4)
    flux = np.pi * scene.area[triangles] * textured_area.mean_radiance(scene, triangles).mean(axis=1)
    assert abs(flux[0] / flux[1] - 1.0) > 0.1  # the spot lies in one half
    power, uniform = (LightSampler(scene, selection, "area") for selection in ("power", "uniform"))
    # Candidates by triangle (the untextured triangles come first in the table).
    np.testing.assert_allclose(power.pmf[power.tables.candidate_of_prim[triangles]], flux / flux.sum(),
                               rtol=1e-12)
    np.testing.assert_allclose(uniform.pmf[uniform.tables.candidate_of_prim[triangles]], [0.5 * flux[0] / flux[:2].sum(), 0.5 * flux[1] / flux[:2].sum(),
                                         0.25, 0.25], rtol=1e-12)


def _obj_scene(tmp_path: Path, name: str, uv: np.ndarray, pixels: np.ndarray, extra: str = ""):
    """One emitting triangle (0,0,0), (1,0,0), (0,1,0) facing +z, its corners' (u, v) ``uv (3, 2)``,
    its radiance the bitmap ``pixels`` (nearest), and ``extra`` XML (another light)."""
    vertices = "".join(f"v {x} {y} 0\nvt {float(u)!r} {float(v)!r}\n" for (x, y), (u, v) in zip([(0, 0), (1, 0), (0, 1)], uv,
                                                                                   strict=True))
    (tmp_path / f"{name}.obj").write_text(vertices + "f 1/1 2/2 3/3\n")
    _write(tmp_path / f"{name}.exr", pixels)
    (tmp_path / f"{name}.xml").write_text(
        f'<scene version="3.0.0">{CAMERA}<shape type="obj"><string name="filename" value="{tmp_path / name}.obj"/>'
        '<boolean name="face_normals" value="true"/><emitter type="area"><texture name="radiance" type="bitmap">'
        f'<string name="filename" value="{tmp_path / name}.exr"/><string name="filter_type" value="nearest"/>'
        f'</texture></emitter></shape>{extra}</scene>')
    return tracer.load_scene(tmp_path / f"{name}.xml")


def test_sliver_footprints_are_sampled_by_area(tmp_path):
    """A triangle whose (u, v) footprint is a sliver (twice its area over its longest edge squared
    below ``MIN_CONDITION``) would have its map from barycentrics held in float32 too poorly for
    an exact pdf (a reviewer measured a pdf 0 everywhere at a width of 1e-8, and 2% of bias at
    1e-6): it is sampled uniformly by area. A thin one above the bound (width 1e-3, 9 cells) is
    texel-sampled with an exact pdf: ``sample``'s pdf equals ``pdf`` of the same point, lane by
    lane (RTOL: the same float64 formulas on the same float32 table)."""
    pixels = 0.5 + np.random.default_rng(3).random((100, 100, 3))
    x, n = np.array([0.3, 0.3, 0.7]), np.array([0.0, 0.0, -1.0])
    for width, texels in ((1e-8, False), (1e-6, False), (1e-3, True)):
        uv = np.array([[0.003, 0.001], [0.9, 0.95], [0.9 + width, 0.95 - width]])
        scene = _obj_scene(tmp_path, f"sliver{width:g}", uv, pixels)
        assert textured_area.sampled_by_texels(scene, np.arange(1))[0] == texels
        sampler = LightSampler(scene, "power", "area")
        assert technique_names(sampler.tables) == (("triangle_texels",) if texels else ("triangle_area",))
        m = 20_000
        gen = np.random.default_rng(5)
        s = sampler.sample(gen.random(m), gen.random((m, 2)), np.tile(x, (m, 1)), np.tile(n, (m, 1)))
        assert np.all(s.pdf > 0.0)
        again = sampler.pdf(np.tile(x, (m, 1)), np.zeros(m, dtype=np.int64), s.wi, s.dist, np.tile(n, (m, 1)))
        np.testing.assert_allclose(again, s.pdf, rtol=RTOL)


def test_black_footprint_is_no_light(tmp_path):
    """A textured triangle whose footprint covers only black texels (a 4 x 4 bitmap lit in one
    texel the footprint misses) sends no light: it is no candidate, so the ``uniform``
    selection does not divide by its flux of 0 (it made every pmf NaN and the image black),
    and the point light beside it is chosen with probability 1 by every selection."""
    pixels = np.zeros((4, 4, 3))
    pixels[0, 3] = 5.0  # the top right texel; the footprint is the lower left quarter
    uv = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]])
    point = '<emitter type="point"><point name="position" x="0.2" y="0.2" z="1"/></emitter>'
    scene = _obj_scene(tmp_path, "black", uv, pixels, point)
    for selection in ("power", "uniform", "bvh"):
        sampler = LightSampler(scene, selection, "area")
        assert sampler.count == 1
        k, pmf = sampler.choose(np.array([0.3, 0.9]), np.zeros((2, 3)), np.tile([0.0, 0.0, 1.0], (2, 1)))
        assert np.all(pmf == 1.0), (selection, pmf)


def test_distributions_too_large_for_the_table_fall_back_to_area(tmp_path, monkeypatch):
    """When the textured triangles' distributions would take more of the light table than
    ``TEXEL_TABLE_FLOATS`` (here cut to 64 floats, as a mesh of 200,000 textured triangles
    would need), they are sampled by area with a note, not refused (an InputError before)."""
    from tracer import lights, notices

    notes = []
    previous = notices.set_handler(notes.append)
    try:
        monkeypatch.setattr(lights, "TEXEL_TABLE_FLOATS", 64)
        scene = _scene(tmp_path, "bilinear repeat")
        sampler = LightSampler(scene, "power", "area")
    finally:
        notices.set_handler(previous)
    assert "triangle_texels" not in technique_names(sampler.tables)
    assert any("sampled by area" in line for line in notes), notes
