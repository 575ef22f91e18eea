"""The environment light (tracer/lights/environment.py, tracer/scene/environment.py): its lookup
in Mitsuba 3's convention, its sampler against its pdf, and renders under it.

Agreement with Mitsuba 3 itself is in tests/test_mitsuba_agreement.py (scene
tracer/scenes/mitsuba/environment.xml, whose background pixels the two renderers look up alike
to float32 rounding). Seeds are fixed; every statistical test is at the suite's 1% family-wise
rate (tests/stats.py), Šidák-corrected over what it compares.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.jit import jit
from tracer.lights import LightSampler
from tracer.lights import environment as light
from tracer.scene import shipped_folder
from tracer.scene.environment import Environment

import chi2
from stats import FAMILY_ALPHA, z_critical


def _rotation_y(degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])


def _map(seed: int = 3, height: int = 9, width: int = 16) -> Environment:
    """A map with a hot texel, a black region and random texels elsewhere, turned about y."""
    rng = np.random.default_rng(seed)
    texels = rng.uniform(0.0, 1.0, (height, width, 3)).astype(np.float32)
    texels[2:5, 3:8] = 0.0  # a black patch: its cells must never be sampled
    texels[6, 11] = (80.0, 60.0, 40.0)  # a hot spot
    return Environment(texels, _rotation_y(25.0))


@jit
def _lookup(env, wi):
    out = np.empty((len(wi), 3))
    for i in range(len(wi)):
        out[i, 0], out[i, 1], out[i, 2] = light.radiance(env, (wi[i, 0], wi[i, 1], wi[i, 2]))
    return out


@jit
def _pdf(env, wi):
    out = np.empty(len(wi))
    for i in range(len(wi)):
        out[i] = light.pdf(env, (wi[i, 0], wi[i, 1], wi[i, 2]))
    return out


@jit
def _sample(env, u):
    wi, le, p = np.empty((len(u), 3)), np.empty((len(u), 3)), np.empty(len(u))
    for i in range(len(u)):
        w, radiance, p[i] = light.sample(env, u[i, 0], u[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, le, p


@jit
def _cell_round_trip(env, r, c, a, b):
    out = np.empty((len(r), 2), dtype=np.int64)
    for i in range(len(r)):
        out[i, 0], out[i, 1] = light.cell_of(env, light.direction_in_cell(env, r[i], c[i], a[i], b[i]))
    return out


def _texel_direction(env: Environment, row: float, column: float) -> np.ndarray:
    """The world direction at which texel (row, column) is centred, written from Mitsuba's
    envmap.cpp (uv_to_direction with u = (column + 1/2) / W, t = row / (H - 1)), apart from
    the code under test."""
    height, width = env.texels.shape[:2]
    phi, theta = 2.0 * np.pi * (column + 0.5) / width, np.pi * row / (height - 1)
    local = np.array([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)])
    return env.to_world @ local


def test_lookup_is_each_texel_at_its_centre_and_bilinear_between():
    """At a texel's centre direction the lookup is that texel (to float rounding); halfway
    between two columns (across the periodic seam too) and two rows it is their mean: the
    convention of Mitsuba 3's envmap, with to_world applied. Deterministic."""
    env = _map()
    table = light.table(env, -1)
    height, width = env.texels.shape[:2]
    rows, columns = np.meshgrid(np.arange(1, height - 1), np.arange(width), indexing="ij")
    centres = np.array([_texel_direction(env, r, c)
                        for r, c in zip(rows.ravel(), columns.ravel(), strict=True)])
    np.testing.assert_allclose(_lookup(table, centres), env.texels[rows.ravel(), columns.ravel()],
                               rtol=1e-5, atol=1e-6)
    seam = np.array([_texel_direction(env, 4, width - 0.5)])  # between the last column and the first
    np.testing.assert_allclose(_lookup(table, seam)[0], 0.5 * (env.texels[4, -1] + env.texels[4, 0]),
                               rtol=1e-5)
    between_rows = np.array([_texel_direction(env, 5.5, 2)])
    np.testing.assert_allclose(_lookup(table, between_rows)[0], 0.5 * (env.texels[5, 2] + env.texels[6, 2]),
                               rtol=1e-5)
    poles = _lookup(table, np.array([env.to_world @ [0.0, 1.0, 0.0], env.to_world @ [0.0, -1.0, 0.0]]))
    for value, row in zip(poles, (env.texels[0], env.texels[-1]), strict=True):  # within its row's texels
        assert np.all(value >= row.min(axis=0) - 1e-6) and np.all(value <= row.max(axis=0) + 1e-6)


def test_a_small_map_is_padded_as_mitsuba_pads_it():
    """Mitsuba pads a map to 2 x 3 texels by repeating its last column and row
    (Bitmap::pad_to): a 1 x 1 map is a constant environment."""
    env = Environment(np.full((1, 1, 3), 2.5, dtype=np.float32), np.eye(3))
    assert env.texels.shape == (3, 2, 3)
    directions = np.random.default_rng(1).normal(size=(50, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    np.testing.assert_allclose(_lookup(light.table(env, -1), directions), 2.5, rtol=1e-6)


def test_pdf_integrates_to_one_and_is_zero_where_the_map_is_black():
    """The cells' pdf times their solid angles sums to 1 (the distribution is normalized), and
    a cell whose four texels are black has pdf 0 while every other has pdf > 0, so light
    sampling can reach every direction that sends light. Deterministic up to rounding."""
    env = _map()
    table = light.table(env, 0)
    _, solid_angle = light.cell_weights(np.ones(env.texels.shape[:2]))
    assert solid_angle.sum() == pytest.approx(4.0 * np.pi, rel=1e-12)
    assert float((table.cell_pdf * solid_angle).sum()) == pytest.approx(1.0, rel=1e-12)
    lum = env.texels.astype(np.float64) @ light.LUMINANCE
    corners = lum[:-1] + lum[1:]
    corners = corners + np.roll(corners, -1, axis=1)
    np.testing.assert_array_equal(table.cell_pdf > 0.0, corners > 0.0)


def test_cells_round_trip():
    """``direction_in_cell`` and ``cell_of`` are inverse: a direction placed inside cell (r, c)
    is found in (r, c) (fractions kept off the edges, where rounding may cross). Deterministic."""
    env = _map()
    table = light.table(env, 0)
    rows, width = table.cell_pdf.shape
    rng = np.random.default_rng(5)
    r, c = rng.integers(0, rows, 2000), rng.integers(0, width, 2000)
    a, b = rng.uniform(1e-6, 1 - 1e-6, 2000), rng.uniform(1e-6, 1 - 1e-6, 2000)
    np.testing.assert_array_equal(_cell_round_trip(table, r, c, a, b), np.stack([r, c], axis=1))


def test_samples_follow_the_pdf_and_carry_the_lookup():
    """χ² of 400,000 samples on the whole sphere, binned in equal-area cells that do not align
    with the map's, against the pdf (integrated per bin by cubature; tests/chi2.py pools bins
    expecting few samples). Each sample's pdf is the pdf function's at its direction and its
    radiance the lookup's there (exactly, away from cell edges). One χ² test at the suite's
    rate."""
    env = _map()
    table = light.table(env, 0)
    u = np.random.default_rng(11).random((400_000, 2))
    wi, le, p = _sample(table, u)
    assert np.all(p > 0.0)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, rtol=1e-12)
    agree = np.isclose(_pdf(table, wi), p, rtol=1e-12)
    assert agree.mean() > 0.999  # differs only where rounding puts a sample across a cell edge
    np.testing.assert_allclose(le, _lookup(table, wi), rtol=1e-12)
    domain = chi2.spherical_domain((0.0, 1.0, 0.0), np.pi, polar="z")
    result = chi2.goodness_of_fit(wi, lambda w: _pdf(table, np.ascontiguousarray(w)), domain, (24, 48),
                                  FAMILY_ALPHA, mass=1.0, name="environment sampler")
    assert result.passed, result.report()


def _furnace(tmp_path, strategy: str, spp: int, seed: int):
    """A diffuse sphere (albedo 0.6) alone under a constant environment of radiance
    (0.5, 1, 2): every pixel on it sees 0.6 x that radiance (nothing occludes a convex object's
    view of its own hemisphere), every other pixel the environment itself."""
    path = tmp_path / "furnace.toml"
    path.write_text(textwrap.dedent("""
        [camera]
        origin = [0.0, 0.0, 4.0]
        target = [0.0, 0.0, 0.0]
        up = [0.0, 1.0, 0.0]
        fov = 40.0
        width = 16
        height = 16

        [environment]
        radiance = [0.5, 1.0, 2.0]

        [materials.white]
        type = "diffuse"
        reflectance = [0.6, 0.6, 0.6]

        [[shapes]]
        type = "sphere"
        center = [0.0, 0.0, 0.0]
        radius = 1.0
        material = "white"
    """))
    scene = tracer.load_scene(str(path))
    return scene, tracer.render(scene, strategy, spp=spp, seed=seed)


@pytest.mark.parametrize("strategy", ["mis", "light"])
def test_white_furnace(tmp_path, strategy):
    """Under a constant environment a diffuse sphere's pixels have expectation albedo x
    radiance: each wholly covered pixel's mean over 256 samples is z-tested against it with its
    own standard error (pixels independent, samples i.i.d.; 256 samples of a bounded value make
    the mean close to normal), Šidák over the pixels. The three channels of one pixel share
    every sample, so only G is tested and the channels' ratio checked exactly. Background pixels
    see the radiance exactly. ``bsdf`` (cosine sampling) is exact here, checked apart."""
    scene, image = _furnace(tmp_path, strategy, 256, 21)
    inside, outside = _pixels_inside_and_outside(16)
    np.testing.assert_array_equal(image.mean[outside],
                                  np.tile(np.float32([0.5, 1.0, 2.0]), (int(outside.sum()), 1)))
    mean, variance = image.mean[inside][:, 1].astype(np.float64), image.variance[inside][:, 1]
    z = (mean - 0.6) / np.sqrt(variance / image.count[inside])
    bound = z_critical(int(inside.sum()))
    assert np.max(np.abs(z)) < bound, (np.max(np.abs(z)), bound)
    np.testing.assert_allclose(image.mean[inside][:, 2], 2.0 * image.mean[inside][:, 1], rtol=1e-5)


def _pixels_inside_and_outside(side: int) -> tuple[np.ndarray, np.ndarray]:
    """Masks (side, side) of the furnace's pixels wholly inside the sphere's silhouette and
    wholly outside it (every corner of the pixel within, or beyond, the sphere's angular radius
    asin(1/4) seen from the camera at distance 4 with a 40 degree field of view; a 1% margin
    keeps rounding off the edge). Pixels across the edge mix both and are left out."""
    edges = np.linspace(-1.0, 1.0, side + 1) * math.tan(math.radians(20.0))
    corner_angle = np.arctan(np.hypot(edges[:, None], edges[None, :]))  # (side + 1, side + 1)
    corners = np.stack([corner_angle[:-1, :-1], corner_angle[1:, :-1], corner_angle[:-1, 1:],
                        corner_angle[1:, 1:]])
    edge = math.asin(0.25)
    near = np.min(np.stack([corner_angle[:-1, :-1], corner_angle[1:, 1:], corner_angle[:-1, 1:],
                            corner_angle[1:, :-1]]), axis=0)
    # The pixel nearest the axis along a row or column may dip inside between its corners: its
    # nearest point is checked too (the axis distance clipped to the pixel).
    lo, hi = edges[:-1], edges[1:]
    nearest = np.where(lo * hi < 0.0, 0.0, np.minimum(np.abs(lo), np.abs(hi)))
    near = np.minimum(near, np.arctan(np.hypot(nearest[:, None], nearest[None, :])))
    return corners.max(axis=0) < 0.99 * edge, near > 1.01 * edge


def test_white_furnace_bsdf_sampling_is_exact(tmp_path):
    """Cosine-weighted BSDF samples of a diffuse sphere under a constant sky carry
    albedo x radiance each: every sphere pixel is 0.6 x radiance to float rounding."""
    scene, image = _furnace(tmp_path, "bsdf", 4, 2)
    inside, _ = _pixels_inside_and_outside(16)
    assert inside.sum() > 40
    np.testing.assert_allclose(image.mean[inside], np.tile([0.3, 0.6, 1.2], (int(inside.sum()), 1)),
                               rtol=1e-5)


SKY_SCENE = """
[camera]
origin = [0.5, 1.2, 5.0]
target = [0.0, 0.2, 0.0]
up = [0.0, 1.0, 0.0]
fov = 55.0
width = 32
height = 24

[environment]
map = "sky.exr"
scale = 0.8
to_world = [[0.766044443, 0.0, -0.642787610], [0.0, 1.0, 0.0], [0.642787610, 0.0, 0.766044443]]

[materials.white]
type = "diffuse"
reflectance = [0.7, 0.7, 0.7]

[materials.gold]
type = "roughconductor"
alpha = 0.15
reflectance = [0.9, 0.7, 0.3]

[[shapes]]
type = "sphere"
center = [-1.1, 0.0, 0.0]
radius = 0.9
material = "white"

[[shapes]]
type = "sphere"
center = [1.0, 0.0, 0.2]
radius = 0.9
material = "gold"

[[shapes]]
type = "quad"
origin = [-4.0, -0.9, 4.0]
edge1 = [8.0, 0.0, 0.0]
edge2 = [0.0, 0.0, -8.0]
material = "white"

[[shapes]]
type = "quad"
origin = [-0.3, 2.5, 0.7]
edge1 = [0.6, 0.0, 0.0]
edge2 = [0.0, 0.0, 0.6]
emission = [20.0, 18.0, 15.0]
"""


def test_strategies_agree_under_a_map_with_an_area_light(tmp_path):
    """Under the shipped sky map (turned by to_world, scaled) with an area light, over diffuse
    and rough-conductor surfaces (no delta lobes, which light sampling alone cannot see), light
    sampling alone and MIS estimate the same image: the image means per channel differ by less
    than z (Šidák over 3 channels) standard errors of their difference. The standard error comes
    from per-pixel variances summed over pixels (independent); the channels are tested
    separately and corrected for, never summed."""
    import shutil

    shutil.copy(shipped_folder() / "mitsuba" / "textures" / "sky.exr", tmp_path / "sky.exr")
    (tmp_path / "sky.toml").write_text(SKY_SCENE)
    scene = tracer.load_scene(str(tmp_path / "sky.toml"))
    means, errors = [], []
    for strategy, seed in (("mis", 4), ("light", 5)):
        image = tracer.render(scene, strategy, spp=128, seed=seed)
        pixels = image.mean.reshape(-1, 3).astype(np.float64)
        var_of_mean = (image.variance.reshape(-1, 3) / image.count.reshape(-1, 1)).astype(np.float64)
        means.append(pixels.mean(axis=0))
        errors.append(np.sqrt(var_of_mean.sum(axis=0)) / len(pixels))
    z = (means[0] - means[1]) / np.hypot(errors[0], errors[1])
    assert np.all(np.abs(z) < z_critical(3)), z


def test_light_selection_counts_the_environment():
    """The environment is one light candidate, the last: by power its share is its flux
    (pi r^2 times its integrated mean radiance) against the emitters', and by ``uniform`` it is
    one light among the lights."""
    scene = tracer.load_scene(str(shipped_folder() / "mitsuba" / "environment.xml"))
    power = LightSampler(scene, "power")
    assert power.owner[-1] == -1 - len(scene.point_position)
    assert power.tables.environment.candidate == power.count - 1
    assert 0.0 < power.pmf[-1] < 1.0 and power.pmf.sum() == pytest.approx(1.0)
    uniform = LightSampler(scene, "uniform")
    assert uniform.pmf[-1] == pytest.approx(0.5)  # the sky and one area light


def _write_scene(tmp_path, environment: str) -> str:
    (tmp_path / "scene.xml").write_text(textwrap.dedent(f"""
        <scene version="3.0.0">
            <sensor type="perspective"><float name="fov" value="40"/>
                <film type="hdrfilm">
                    <integer name="width" value="8"/><integer name="height" value="8"/></film>
            </sensor>
            {environment}
            <shape type="sphere"><float name="radius" value="0.5"/>
                <transform name="to_world"><translate z="3"/></transform></shape>
        </scene>"""))
    return str(tmp_path / "scene.xml")


@pytest.mark.parametrize("environment, message", [
    ('<emitter type="constant"/><emitter type="constant"/>', "a second environment emitter"),
    ('<emitter type="envmap"><string name="filename" value="none.exr"/></emitter>', "not found"),
    ('<emitter type="envmap"/>', "missing property 'filename'"),
    ('<emitter type="envmap"><string name="filename" value="sky.exr"/>'
     '<transform name="to_world"><scale value="2"/></transform></emitter>', "must be a rotation"),
    ('<emitter type="envmap"><string name="filename" value="sky.exr"/>'
     '<float name="scale" value="-1"/></emitter>', "scale"),
    ('<emitter type="constant"><texture type="checkerboard" name="radiance"/></emitter>',
     "textured constant"),
])
def test_bad_environments_are_refused_with_the_reason(tmp_path, environment, message):
    """A broken environment is refused in one line naming the file and what is wrong."""
    import shutil

    shutil.copy(shipped_folder() / "mitsuba" / "textures" / "sky.exr", tmp_path / "sky.exr")
    with pytest.raises(InputError, match=message) as caught:
        tracer.load_scene(_write_scene(tmp_path, environment))
    assert "scene.xml" in str(caught.value) and "\n" not in str(caught.value)


def test_negative_texels_are_refused(tmp_path):
    """A map with a negative texel (radiance is >= 0) is refused, naming the file."""
    import OpenImageIO as oiio

    texels = np.ones((4, 8, 3), dtype=np.float32)
    texels[1, 2, 0] = -0.5
    out = oiio.ImageOutput.create(str(tmp_path / "bad.exr"))
    out.open(str(tmp_path / "bad.exr"), oiio.ImageSpec(8, 4, 3, oiio.FLOAT))
    out.write_image(texels)
    out.close()
    with pytest.raises(InputError, match="negative texels"):
        tracer.load_scene(_write_scene(tmp_path, '<emitter type="envmap"><string name="filename" '
                                                 'value="bad.exr"/></emitter>'))


def test_digest_tells_environments_apart(tmp_path):
    """Two scenes that differ only in their environment have different digests (merges and
    comparisons refuse a mixture); the same file read twice has one."""
    a = tracer.load_scene(_write_scene(tmp_path, '<emitter type="constant"/>'))
    b = tracer.load_scene(_write_scene(tmp_path, '<emitter type="constant"><rgb name="radiance" value="2"/>'
                                                 '</emitter>'))
    c = tracer.load_scene(_write_scene(tmp_path, '<emitter type="constant"><rgb name="radiance" value="2"/>'
                                                 '</emitter>'))
    assert a.digest != b.digest and b.digest == c.digest


def test_an_environment_map_converts_to_a_reference_to_its_file(tmp_path):
    """``tracer convert`` writes a map as ``[environment] map`` (the image file, relative to the
    TOML), ``scale`` and ``to_world``: the TOML reads back as the same scene (same digest), from
    another folder too. A map whose file is gone is refused in one line, nothing written."""
    import shutil

    from tracer.scene.toml_writer import write_scene

    shutil.copy(shipped_folder() / "mitsuba" / "textures" / "sky.exr", tmp_path / "sky.exr")
    scene = tracer.load_scene(_write_scene(tmp_path, '<emitter type="envmap"><string name="filename" '
                                                     'value="sky.exr"/><float name="scale" value="0.3"/>'
                                                     '<transform name="to_world"><rotate y="1" angle="-40"/>'
                                                     '</transform></emitter>'))
    (tmp_path / "out").mkdir()
    write_scene(scene, tmp_path / "out" / "back.toml", "scene.xml")
    assert 'map = "../sky.exr"' in (tmp_path / "out" / "back.toml").read_text()
    assert tracer.load_scene(str(tmp_path / "out" / "back.toml")).digest == scene.digest
    (tmp_path / "sky.exr").unlink()
    with pytest.raises(InputError, match="environment map whose image file is not known or not there"):
        write_scene(scene, tmp_path / "gone.toml", "scene.xml")
    assert not (tmp_path / "gone.toml").exists()


def test_a_constant_environment_converts_to_toml_and_back(tmp_path):
    """``tracer convert`` writes a constant environment as ``[environment] radiance``, and the
    TOML reads back as the same scene (same digest)."""
    from tracer.scene.toml_writer import write_scene

    scene = tracer.load_scene(_write_scene(tmp_path, '<emitter type="constant"><rgb name="radiance" '
                                                     'value="0.25, 0.5, 3"/></emitter>'))
    write_scene(scene, tmp_path / "back.toml", "scene.xml")
    assert tracer.load_scene(str(tmp_path / "back.toml")).digest == scene.digest
