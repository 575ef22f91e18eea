"""Area emitters whose radiance is a texture (Mitsuba's ``area`` emitter with a ``radiance``
texture): ``tracer.textures.lookup.emitted`` and ``sampled_emission``.

What is checked here, and what elsewhere:

- the emission seen directly is the texture's value at the hit's (u, v), on a rectangle, a
  mesh with its own coordinates and an analytic sphere (exact, against numpy lookups);
- light samples and BSDF samples see the same texture: renders that reach the emitters only by
  light sampling (area and solid-angle techniques) or only by BSDF sampling agree, on emitters
  whose coordinates Mitsuba cannot light-sample without bias (a to_uv, coordinates beyond
  [0, 1]^2 and a seam; docs/MITSUBA_XML.md);
- sampling by area x texel luminance (``triangle_texels``) and uniformly by area give the same
  image, region by region, for light sampling alone and for MIS (this file); the technique's
  density itself is tested in test_textured_area.py;
- refusals of radiance textures that cannot be light (this file);
- agreement with Mitsuba 3.9.1 where its own sampling is exact:
  ``tracer/scenes/mitsuba/textured_emitters.xml`` in ``tests/test_mitsuba_agreement.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.estimator import DirectLighting
from tracer.lights import emitters, technique_names
from tracer.study.statistics import image_mean_and_se
from tracer.textures import lookup
from tracer.textures.bitmap import read_texels

from stats import z_critical

ASSETS = Path(tracer.__file__).parent / "scenes" / "mitsuba"

SCENE = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="55"/>
        <transform name="to_world"><lookat origin="0, 2.2, 5.5" target="0, 0.4, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world">
            <scale x="4" y="3"/><rotate x="1" angle="-90"/><translate y="-0.5"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <scale x="1.1" y="0.8"/><rotate x="1" angle="35"/><rotate y="1" angle="20"/>
            <translate x="-1.6" y="1.2" z="0.2"/>
        </transform>
        <emitter type="area">
            <texture name="radiance" type="bitmap">
                <string name="filename" value="{assets}/textures/tiles.png"/>
                <string name="filter_type" value="nearest"/>
                <transform name="to_uv"><scale x="2" y="1.5"/><translate x="0.3"/></transform>
            </texture>
        </emitter>
    </shape>
    <shape type="obj">
        <string name="filename" value="{assets}/meshes/quad_uv.obj"/>
        <transform name="to_world">
            <scale x="0.9" y="0.6"/><rotate x="1" angle="25"/><translate y="1.5" z="-1"/>
        </transform>
        <emitter type="area">
            <texture name="radiance" type="bitmap">
                <string name="filename" value="{assets}/textures/ramp.exr"/>
                <string name="filter_type" value="nearest"/>
            </texture>
        </emitter>
    </shape>
    <shape type="sphere">
        <float name="radius" value="0.4"/>
        <transform name="to_world">
            <rotate x="1" angle="-50"/><translate x="1.6" y="1.1" z="-0.2"/>
        </transform>
        <emitter type="area">
            <texture name="radiance" type="checkerboard">
                <rgb name="color0" value="0.95, 0.3, 0.1"/>
                <rgb name="color1" value="0.1, 0.25, 0.9"/>
                <transform name="to_uv"><scale x="6" y="3"/></transform>
            </texture>
        </emitter>
    </shape>
</scene>
"""


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("textured_emitters") / "scene.xml"
    path.write_text(SCENE.replace("{assets}", str(ASSETS)))
    return path


def _nearest(pixels: np.ndarray, u: float, v: float) -> np.ndarray:
    """Mitsuba's nearest lookup with repeat: texel (floor(u W), floor(v H)), row 0 at v = 0."""
    height, width, _ = pixels.shape
    return pixels[int(np.floor(v * height)) % height, int(np.floor(u * width)) % width]


def _known_points(scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points of the three emitters where the texture's value is known independently:
    ``(prim (n,), point (n, 3), front normal (n, 3), radiance (n, 3))``. The rectangle at local
    (x, y) (Mitsuba's (u, v) = ((x + 1) / 2, (y + 1) / 2), mapped by to_uv); quad_uv.obj's two
    triangles, whose coordinates reach beyond [0, 1] (repeat wraps them) and jump at the seam
    between them (their corners' coordinates as read: ``Scene.corner_uv``, whose reading
    test_textures.py checks); the sphere's checkerboard at points of its own frame (Mitsuba's
    (u, v) = (phi / 2 pi, theta / pi) there, through to_uv (6, 3)), away from the squares' edges."""
    tiles = read_texels(ASSETS / "textures" / "tiles.png", False, "tiles")
    ramp = read_texels(ASSETS / "textures" / "ramp.exr", False, "ramp")
    rect, quad = scene.shapes[1], scene.shapes[2]
    prims, points, normals, expected = [], [], [], []
    corner, e1, e2 = (scene.vertices[scene.faces[rect.first][i]] for i in (0, 1, 2))
    e2 = e2 - e1
    e1 = e1 - corner
    for s, t in [(0.13, 0.2), (0.37, 0.81), (0.9, 0.55), (0.62, 0.05), (0.3, 0.7)]:
        prims.append(rect.first if s >= t else rect.first + 1)  # triangles (o, o+e1, o+e1+e2), (o, .., o+e2)
        points.append(corner + s * e1 + t * e2)
        normals.append(scene.normal[rect.first])
        expected.append(_nearest(tiles, 2.0 * s + 0.3, 1.5 * t))
    for p, (b1, b2) in [(quad.first, (0.2, 0.1)), (quad.first, (0.5, 0.3)), (quad.first, (0.7, 0.25)),
                        (quad.first + 1, (0.2, 0.6)), (quad.first + 1, (0.4, 0.4))]:
        tri = scene.vertices[scene.faces[p]]
        prims.append(p)
        points.append(tri[0] + b1 * (tri[1] - tri[0]) + b2 * (tri[2] - tri[0]))
        normals.append(scene.normal[p])
        uv = scene.corner_uv[p].reshape(3, 2)
        u, v = (1.0 - b1 - b2) * uv[0] + b1 * uv[1] + b2 * uv[2]
        expected.append(_nearest(ramp, u, v))
    angle = np.radians(-50.0)
    cos, sin = np.cos(angle), np.sin(angle)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, cos, -sin], [0.0, sin, cos]])
    centre, radius = scene.spheres[0, :3], scene.spheres[0, 3]
    color0, color1 = np.array([0.95, 0.3, 0.1]), np.array([0.1, 0.25, 0.9])
    for theta, phi in [(0.4, 0.3), (1.2, 2.0), (2.0, 4.1), (1.6, 5.5)]:
        local = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        outward = rotation @ local
        prims.append(scene.triangle_count)
        points.append(centre + radius * outward)
        normals.append(outward)
        su, sv = 6.0 * phi / (2.0 * np.pi), 3.0 * theta / np.pi
        assert min(abs(su * 2 - round(su * 2)), abs(sv * 2 - round(sv * 2))) > 0.04  # off the edges
        expected.append(color0 if (su % 1.0 > 0.5) == (sv % 1.0 > 0.5) else color1)
    return np.array(prims), np.array(points), np.array(normals), np.array(expected, dtype=np.float64)


def test_emission_seen_directly_is_the_texture_at_the_hit(scene_file):
    """Rays from outside each emitter toward points of known value (``_known_points``) return
    the texture's value there exactly (the emitters have no material: nothing else adds
    light)."""
    scene = tracer.load_scene(scene_file)
    _, points, normals, expected = _known_points(scene)
    got = DirectLighting(scene, tracer.Strategy("mis")).radiance(points + 0.5 * normals, -normals)
    np.testing.assert_allclose(got, expected, rtol=1e-6)


@pytest.mark.parametrize("light_sampling", ["area", "solid-angle"])
def test_a_light_sample_takes_the_texture_at_its_point(scene_file, light_sampling):
    """``lookup.sampled_emission`` of a light sample that a technique returned toward a point of
    known value (``_known_points``; from a shading point off the emitter's front, a little to
    the side) is the texture's value there, whichever candidate holds the point: one triangle,
    a sphere, or under ``solid-angle`` the rectangle's one candidate over two triangles (Mitsuba's
    rectangle coordinates are affine, so either triangle's give the same (u, v) here; a TOML
    quad's need not be). Exact to float rounding: the point is rebuilt as x + dist wi; a point
    taken a fifth of the way short of it fails."""
    scene = tracer.load_scene(scene_file)
    est = DirectLighting(scene, tracer.Strategy("light", light_sampling=light_sampling))
    tables, surfaces = est.lights.tables, est.surfaces
    prims, points, normals, expected = _known_points(scene)
    constant = (7.0, 7.0, 7.0)
    for p, y, n, value in zip(prims, points, normals, expected, strict=True):
        k = int(tables.candidate_of_prim[p])
        assert k >= 0
        x = y + 0.6 * n + 0.2 * np.cross(n, [0.3, 0.5, 0.8])
        dist = float(np.linalg.norm(y - x))
        wi = tuple((y - x) / dist)
        got = lookup.sampled_emission(surfaces.textures, surfaces.hit_table, surfaces.first_sphere,
                                      tables.prims, k, tuple(x), wi, dist, constant)
        np.testing.assert_allclose(got, value, rtol=1e-6, err_msg=f"prim {p}")
    # No candidate (no light reaches the point): the technique's value passes through.
    none = lookup.sampled_emission(surfaces.textures, surfaces.hit_table, surfaces.first_sphere, tables.prims,
                                   -1, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, constant)
    assert none == constant


def test_light_and_bsdf_samples_see_the_same_texture(scene_file):
    """The floor's light reaches it only from the three textured emitters. Renders by light
    sampling alone (area, and solid-angle: the rectangle then is one candidate over two
    triangles), by BSDF sampling alone, and by MIS are unbiased estimates of the same image, so
    their image means agree: each pair's difference over its standard error (pixels are
    independent, so the image mean's variance is the sum of the pixel means' variances over
    the pixel count squared, per channel; thousands of pixels make it normal) is within the
    Sidak bound over 3 pairs x 3 channels. Channels are correlated within a pair, which Sidak
    allows (its bound holds under positive dependence). What it sees, measured: light samples
    that take the emitter's mean instead of the texture at their point move the light-only
    green mean by 1.8% (z = -5.8); a point displaced by 3% of its distance it does not see (the
    exact test above catches such errors)."""
    scene = tracer.load_scene(scene_file)
    films = {}
    for name, strategy in [("bsdf", tracer.Strategy("bsdf")), ("light", tracer.Strategy("light")),
                           ("light solid-angle", tracer.Strategy("light", light_sampling="solid-angle")),
                           ("mis", tracer.Strategy("mis"))]:
        films[name] = tracer.render(scene, strategy, spp=512, seed=7, sampler="independent")
    bsdf_mean, bsdf_se = _image_mean(films["bsdf"])
    bound = z_critical(9)
    for name in ("light", "light solid-angle", "mis"):
        mean, se = _image_mean(films[name])
        z = (mean - bsdf_mean) / np.hypot(se, bsdf_se)
        assert np.all(np.abs(z) < bound), (name, mean, bsdf_mean, z)


TILES = (3, 4)  # rows x columns of the regions compared


def test_texel_sampling_agrees_with_area_sampling(scene_file, monkeypatch):
    """Renders of the same scene whose textured triangles are light-sampled by area x texel
    luminance (``triangle_texels``, the default under ``area``) and uniformly by area
    (``triangle_area``, as before it: the textured triangles' table turned off), each for
    ``light`` alone (the new density must be positive wherever the texture is: a region the
    new technique cannot reach would be dark in it only) and for ``mis`` (its pdf must be the
    one it samples by, or the weights would not sum to 1), are unbiased estimates of one image.
    So the means of each of 3 x 4 regions of the image agree per channel: each difference over
    its standard error (independent seeds; a region's mean over its 64 pixels and 256 samples
    each, normal) is within the Sidak bound over 2 strategies x 12 regions x 3 channels (the
    channels are correlated, which Sidak allows). Regions rather than the whole image: a
    density wrong in one part of an emitter moves the light on one part of the floor."""
    scene = tracer.load_scene(scene_file)
    films = {}
    for technique in ("texels", "area"):
        if technique == "area":
            monkeypatch.setattr(emitters, "texel_sampled", lambda scene, tri: np.zeros(len(tri), dtype=bool))
        for seed, name in enumerate(("light", "mis")):
            estimator = DirectLighting(scene, tracer.Strategy(name))
            used = set(technique_names(estimator.lights.tables))
            assert ("triangle_texels" in used) == (technique == "texels"), used
            films[technique, name] = tracer.render(scene, tracer.Strategy(name), spp=256, seed=11 + seed
                                                   + 2 * (technique == "area"), sampler="independent")
    bound = z_critical(2 * TILES[0] * TILES[1] * 3)
    for name in ("light", "mis"):
        (new_mean, new_se), (old_mean, old_se) = (_region_means(films[t, name]) for t in ("texels", "area"))
        z = (new_mean - old_mean) / np.hypot(new_se, old_se)
        assert np.all(np.abs(z) < bound), (name, np.abs(z).max(), bound)


def _region_means(image) -> tuple[np.ndarray, np.ndarray]:
    """The mean of each region of ``TILES`` per channel and its standard error, (R, C, 3) each."""
    mean, var = image.mean, image.variance_of_mean  # (H, W, 3)
    height, width = mean.shape[:2]
    rows, columns = TILES
    shape = (rows, height // rows, columns, width // columns, 3)
    count = (height // rows) * (width // columns)
    return (mean.reshape(shape).mean(axis=(1, 3)), np.sqrt(var.reshape(shape).sum(axis=(1, 3))) / count)


def _image_mean(image) -> tuple[np.ndarray, np.ndarray]:
    """An image's mean per channel and its standard error, (3,) each."""
    return image_mean_and_se(image.mean.reshape(-1, 3), image.variance_of_mean.reshape(-1, 3))


@pytest.mark.parametrize("texture, message", [
    ('<texture name="radiance" type="checkerboard"><rgb name="color0" value="-0.5"/></texture>',
     "color0"),
    ('<texture name="radiance" type="mesh_attribute"><string name="name" value="vertex_color"/></texture>',
     "mesh_attribute radiance is not supported"),
    ('<texture name="radiance" type="rawconstant"><float name="value" value="-1"/></texture>',
     "negative values"),
])
def test_radiance_textures_that_are_not_light_are_refused(tmp_path, texture, message):
    """A radiance texture with negative values, or one tracer cannot light-sample, is refused in
    one line that names the file and the line."""
    path = tmp_path / "bad.xml"
    path.write_text(f"""<scene version="3.0.0">
    <shape type="rectangle">
        <emitter type="area">
            {texture}
        </emitter>
    </shape>
</scene>
""")
    with pytest.raises(InputError) as error:
        tracer.load_scene(path)
    text = str(error.value)
    assert message in text and "bad.xml:" in text and "\n" not in text
