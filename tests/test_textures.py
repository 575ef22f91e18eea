"""Textures (tracer/textures/): lookups against independent numpy code, the files they read,
the (u, v) of each shape against Mitsuba 3.9.1's, and the Mitsuba reader's textures.

Rendering with textures is compared with Mitsuba 3 itself in tests/test_mitsuba_agreement.py
(scenes tracer/scenes/mitsuba/textures.xml and textured_meshes.xml).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.textures import Binding, Texture, TextureTable, lookup
from tracer.textures.bitmap import read_texels, srgb_to_linear


def arrays_of(*textures: Texture):
    table = TextureTable(list(textures))
    return table.arrays(1, np.zeros((0, 6)), np.zeros((0, 9)))


def test_checkerboard_colours_and_the_one_number_swap():
    # color0 where both fractional parts are above 1/2 or both at most 1/2, after to_uv; a
    # one-number lookup swaps the colours, as Mitsuba's eval_1 does.
    t = Texture("checkerboard", color0=np.array([0.9, 0.8, 0.7]), color1=np.array([0.1, 0.2, 0.3]),
                to_uv=np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]))
    textures = arrays_of(t)
    for u, v, first in [(0.1, 0.1, True), (0.3, 0.1, False), (0.3, 0.3, True), (0.6, 0.1, True),
                        (-0.1, 0.1, False), (0.76, 0.26, True), (0.74, 0.26, False)]:
        rgb = lookup.evaluate(textures, 0, u, v)
        assert np.allclose(rgb, t.color0 if first else t.color1), (u, v)
        one = lookup.evaluate_one(textures, 0, u, v)
        assert one == (t.color1 if first else t.color0)[0], (u, v)


def _numpy_lookup(pixels: np.ndarray, u: np.ndarray, v: np.ndarray, filter_type: str, wrap: str) -> np.ndarray:
    """An independent bitmap lookup, written from Mitsuba's description: texel (i, j) centred at
    ((i + 1/2) / W, (j + 1/2) / H), row 0 at v = 0, indices wrapped per ``wrap``."""
    height, width, _ = pixels.shape

    def wrapped(i, n):
        if wrap == "repeat":
            return np.mod(i, n)
        if wrap == "clamp":
            return np.clip(i, 0, n - 1)
        m = np.mod(i, 2 * n)
        return np.where(m < n, m, 2 * n - 1 - m)

    if filter_type == "nearest":
        return pixels[wrapped(np.floor(v * height).astype(int), height), wrapped(np.floor(u * width).astype(int), width)]
    x, y = u * width - 0.5, v * height - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    wx, wy = (x - x0)[:, None], (y - y0)[:, None]
    i0, i1, j0, j1 = wrapped(x0, width), wrapped(x0 + 1, width), wrapped(y0, height), wrapped(y0 + 1, height)
    return ((1 - wy) * ((1 - wx) * pixels[j0, i0] + wx * pixels[j0, i1])
            + wy * ((1 - wx) * pixels[j1, i0] + wx * pixels[j1, i1]))


@pytest.mark.parametrize("filter_type", ["nearest", "bilinear"])
@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_bitmap_lookups_match_an_independent_implementation(filter_type, wrap):
    rng = np.random.default_rng(7)
    pixels = rng.random((5, 7, 3)).astype(np.float32)
    to_uv = np.array([[1.3, 0.2, -0.4], [-0.1, 0.9, 0.25]])
    t = Texture("bitmap", pixels=pixels, filter=filter_type, wrap=wrap, to_uv=to_uv)
    textures = arrays_of(t)
    u, v = rng.uniform(-1.5, 2.5, 400), rng.uniform(-1.5, 2.5, 400)
    ours = np.array([lookup.evaluate(textures, 0, a, b) for a, b in zip(u, v, strict=True)])
    su, sv = to_uv[0, 0] * u + to_uv[0, 1] * v + to_uv[0, 2], to_uv[1, 0] * u + to_uv[1, 1] * v + to_uv[1, 2]
    expected = _numpy_lookup(pixels.astype(np.float64), su, sv, filter_type, wrap)
    np.testing.assert_allclose(ours, expected, rtol=1e-12, atol=1e-12)
    luminance = np.array([lookup.evaluate_one(textures, 0, a, b) for a, b in zip(u, v, strict=True)])
    np.testing.assert_allclose(luminance, expected @ np.array([0.212671, 0.715160, 0.072169]), rtol=1e-12)


def test_bitmap_texel_centres_and_rows():
    # At a texel's centre a bilinear lookup is the texel; v near 0 is the image's first row.
    pixels = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    textures = arrays_of(Texture("bitmap", pixels=pixels))
    for j in range(2):
        for i in range(3):
            assert lookup.evaluate(textures, 0, (i + 0.5) / 3, (j + 0.5) / 2) == tuple(pixels[j, i])


def _write(path, pixels, fmt):
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close()


def test_image_files_are_decoded_as_mitsuba_decodes_them(tmp_path):
    # 8-bit PNG: sRGB-decoded unless raw; EXR: linear as stored; one grey channel: all three.
    import OpenImageIO as oiio

    encoded = np.array([[[0, 10, 128], [200, 255, 64]]], dtype=np.uint8)
    _write(tmp_path / "a.png", encoded, oiio.UINT8)
    decoded = read_texels(tmp_path / "a.png", raw=False, where="test")
    np.testing.assert_allclose(decoded, srgb_to_linear(encoded / 255.0), rtol=1e-6)
    np.testing.assert_allclose(decoded[0, 0, 2], ((128 / 255 + 0.055) / 1.055) ** 2.4, rtol=1e-6)
    np.testing.assert_allclose(read_texels(tmp_path / "a.png", raw=True, where="test"), encoded / 255.0, rtol=1e-6)
    linear = np.array([[[0.25, 2.5, 0.0]]], dtype=np.float32)
    _write(tmp_path / "b.exr", linear, oiio.FLOAT)
    np.testing.assert_array_equal(read_texels(tmp_path / "b.exr", raw=False, where="test"), linear)
    _write(tmp_path / "g.png", np.array([[[51]]], dtype=np.uint8), oiio.UINT8)
    grey = read_texels(tmp_path / "g.png", raw=True, where="test")
    np.testing.assert_allclose(grey, np.full((1, 1, 3), 0.2), rtol=1e-6)


TILES_PNG = Path(__file__).resolve().parents[1] / "tracer/scenes/mitsuba/textures/tiles.png"


@pytest.mark.parametrize("content, words", [
    (None, "texture image not found"),
    (b"not an image", "cannot read texture image"),
    (TILES_PNG.read_bytes()[:300], "hit end of file"),  # a PNG cut in its pixel data
])
def test_unusable_image_files_are_refused_naming_them(tmp_path, capfd, content, words):
    """One line names the file; libpng's own line on a truncated PNG (written by C to file
    descriptor 2) is not printed beside it."""
    path = tmp_path / "t.png"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(InputError, match=words) as caught:
        read_texels(path, raw=False, where="scene.xml:3")
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)
    assert capfd.readouterr().err == ""


# (u, v) of Mitsuba 3.9.1's shapes at points on them, read from Mitsuba itself
# (scene.ray_intersect(...).uv on the plain shape, no transform).
MITSUBA_UV = {
    "rectangle": [((-0.5, -0.5, 0.0), (0.25, 0.25)), ((0.5, -0.5, 0.0), (0.75, 0.25)),
                  ((-0.5, 0.5, 0.0), (0.25, 0.75))],
    "disk": [((0.5, 0.0, 0.0), (0.5, 0.0)), ((0.0, 0.5, 0.0), (0.5, 0.25)), ((-0.5, 0.0, 0.0), (0.5, 0.5))],
    "sphere": [((0.86602545, 0.0, 0.5), (0.0, 1 / 3)), ((0.0, 0.86602545, 0.5), (0.25, 1 / 3)),
               ((-0.86602545, 0.0, -0.5), (0.5, 2 / 3)), ((0.0, -1.0, 0.0), (0.75, 0.5))],
    "cube": [((0.5, 0.25, 1.0), (0.625, 0.75)), ((1.0, 0.5, 0.25), (0.75, 0.375)),
             ((0.5, 1.0, 0.25), (0.25, 0.375)), ((0.5, 0.25, -1.0), (0.375, 0.75)),
             ((-1.0, 0.5, 0.25), (0.75, 0.625)), ((0.5, -1.0, 0.25), (0.625, 0.75))],
}

SHAPE_SCENE = """<scene version="3.0.0">
  <sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
  <shape type="{shape}">
    <bsdf type="diffuse"><texture name="reflectance" type="checkerboard"/></bsdf>
  </shape>
  <emitter type="point"><point name="position" x="0" y="0" z="3"/></emitter>
</scene>
"""


@pytest.mark.parametrize("shape", sorted(MITSUBA_UV))
def test_texture_coordinates_of_each_shape_are_mitsubas(tmp_path, shape):
    # The primitive holding each point is found by brute force; its (u, v) there must be
    # Mitsuba's. tracer's disk is a fan of 288 triangles whose linear (u, v) come within 6e-5 of
    # Mitsuba's exact radius and within half a triangle's angle, 1/576, of its angle.
    path = tmp_path / "s.xml"
    path.write_text(SHAPE_SCENE.format(shape=shape))
    scene = tracer.load_scene(path)
    textures = scene.textures.arrays(len(scene.materials.kind), scene.corner_uv, scene.sphere_frame)
    for point, expected in MITSUBA_UV[shape]:
        x = np.array(point, dtype=np.float64)
        p = _primitive_at(scene, x)
        u, v = lookup.uv_at(textures, scene.hit_table, scene.triangle_count, p, (x[0], x[1], x[2]))
        u_tolerance, v_tolerance = (6e-5, 1 / 576 + 1e-12) if shape == "disk" else (1e-6, 1e-6)
        assert abs(u - expected[0]) < u_tolerance and abs(v - expected[1]) < v_tolerance, (point, (u, v), expected)


def _primitive_at(scene, x: np.ndarray) -> int:
    if len(scene.spheres):
        return scene.triangle_count
    for p in range(scene.triangle_count):
        v0, e1, e2, n = scene.v0[p], scene.edge1[p], scene.edge2[p], scene.normal[p]
        if abs(np.dot(x - v0, n)) > 1e-9:
            continue
        m = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
        b1, b2 = np.linalg.solve(m, [(x - v0) @ e1, (x - v0) @ e2])
        if b1 >= -1e-9 and b2 >= -1e-9 and b1 + b2 <= 1 + 1e-9:
            return p
    raise AssertionError(f"no triangle holds {x}")


@pytest.mark.parametrize("flip", ["false", "true"])
def test_a_mesh_without_coordinates_keeps_its_files_corner_order_when_turned(tmp_path, flip):
    # Without texture coordinates Mitsuba's (u, v) is (b1, b2) of the file's corners, whichever
    # side flip_normals makes the front; tracer turns the winding of a flipped mesh, so its
    # turned corners must carry the file order's coordinates (they had the turned order's).
    # The point v0 + 0.3 (v1 - v0) + 0.2 (v2 - v0) of the file's triangle has (0.3, 0.2), to
    # float64 rounding of a plane intersection and barycentrics (1e-12).
    (tmp_path / "tri.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                      "property float y\nproperty float z\nelement face 1\n"
                                      "property list uchar int vertex_indices\nend_header\n"
                                      "-1 -1 0\n1 -1 0\n-1 1 0\n3 0 1 2\n")
    path = tmp_path / "s.xml"
    path.write_text(SHAPE_SCENE.format(shape="ply").replace(
        '<shape type="ply">', f'<shape type="ply"><string name="filename" value="tri.ply"/>'
        f'<boolean name="flip_normals" value="{flip}"/>'))
    scene = tracer.load_scene(path)
    textures = scene.textures.arrays(len(scene.materials.kind), scene.corner_uv, scene.sphere_frame)
    v0, v1, v2 = np.array([-1.0, -1, 0]), np.array([1.0, -1, 0]), np.array([-1.0, 1, 0])
    x = v0 + 0.3 * (v1 - v0) + 0.2 * (v2 - v0)
    u, v = lookup.uv_at(textures, scene.hit_table, scene.triangle_count, 0, tuple(x))
    assert abs(u - 0.3) < 1e-12 and abs(v - 0.2) < 1e-12, (u, v)


def test_a_rotated_sphere_takes_its_coordinates_in_its_own_frame(tmp_path):
    # Rotated 90 degrees about z, the sphere's local x axis is the world's y: the world point
    # (0, 1, 0) has Mitsuba's (u, v) of the local point (1, 0, 0), (0, 1/2).
    path = tmp_path / "s.xml"
    path.write_text(SHAPE_SCENE.format(shape="sphere").replace(
        '<shape type="sphere">', '<shape type="sphere"><transform name="to_world"><rotate z="1" angle="90"/>'
        '</transform>'))
    scene = tracer.load_scene(path)
    textures = scene.textures.arrays(len(scene.materials.kind), scene.corner_uv, scene.sphere_frame)
    u, v = lookup.uv_at(textures, scene.hit_table, scene.triangle_count, scene.triangle_count, (0.0, 1.0, 0.0))
    assert abs(u) < 1e-12 or abs(u - 1.0) < 1e-12
    assert math.isclose(v, 0.5, abs_tol=1e-12)


def test_a_textured_material_row_holds_the_lookup_and_the_mean(tmp_path):
    # The table holds the texture's mean (what derived constants use); the row a hit shades
    # with holds the lookup at its (u, v), clamped into the parameter's range.
    t = Texture("checkerboard", color0=np.array([1.5, 0.5, 0.5]), color1=np.array([0.1, 0.2, 0.3]))
    table = TextureTable([t], [Binding(1, "reflectance", 0, 3, 0, 0.0, 1.0)])
    params = np.array([[0.0, 0.0, 0.0], [0.8, 0.35, 0.4]])
    hit_table = np.zeros((1, 16))
    hit_table[0, 3:6] = [1.0, 0.0, 0.0]
    hit_table[0, 6:9] = [0.0, 1.0, 0.0]
    textures = table.arrays(2, np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]]), np.zeros((0, 9)))
    scratch = np.empty((1, 3))
    row_table, row = lookup.textured_row(textures, params, 1, hit_table, 1, 0, (0.1, 0.1, 0.0), scratch)
    assert row == 0 and tuple(row_table[0]) == (1.0, 0.5, 0.5)  # color0, its red clamped to 1
    row_table, row = lookup.textured_row(textures, params, 1, hit_table, 1, 0, (0.7, 0.1, 0.0), scratch)
    assert tuple(row_table[0]) == (0.1, 0.2, 0.3)
    same, row = lookup.textured_row(textures, params, 0, hit_table, 1, 0, (0.7, 0.1, 0.0), scratch)
    assert row == 0 and same is params


XML = """<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
    <integer name="height" value="4"/></film></sensor>
  {body}
  <emitter type="point"><point name="position" x="0" y="0" z="3"/></emitter>
</scene>
"""


def _load(tmp_path, body: str):
    path = tmp_path / "scene.xml"
    path.write_text(XML.format(body=body))
    return tracer.load_scene(path)


def test_plastic_lobe_weights_use_the_textures_mean(tmp_path):
    # Mitsuba computes a plastic's specular sampling weight from its textures' means: the
    # derived column is computed from the checkerboard's mean, and the digest knows the texture.
    textured = _load(tmp_path, '<shape type="rectangle"><bsdf type="plastic"><texture name="diffuse_reflectance" '
                     'type="checkerboard"><rgb name="color0" value="0.9"/><rgb name="color1" value="0.1"/>'
                     '</texture></bsdf></shape>')
    constant = _load(tmp_path, '<shape type="rectangle"><bsdf type="plastic"><rgb name="diffuse_reflectance" '
                     'value="0.5"/></bsdf></shape>')
    np.testing.assert_array_equal(textured.materials.params, constant.materials.params)
    assert textured.digest != constant.digest
    assert len(textured.textures.bindings) == 1


@pytest.mark.parametrize("body, words", [
    ('<shape type="rectangle"><bsdf type="roughplastic"><texture name="alpha" type="checkerboard"/></bsdf></shape>',
     "roughplastic's alpha cannot be a texture"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="noise"/></bsdf></shape>',
     "texture 'noise' is not supported"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="bitmap"><string '
     'name="filename" value="missing.png"/></texture></bsdf></shape>', "missing.png"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="bitmap"/></bsdf></shape>',
     "missing property 'filename'"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="checkerboard"/><rgb '
     'name="reflectance" value="0.5"/></bsdf></shape>', "given twice"),
    ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="checkerboard">'
     '<texture name="color0" type="checkerboard"/></texture></bsdf></shape>', "not expected inside"),
    ('<shape type="rectangle"><bsdf type="roughdielectric"><texture name="alpha_u" type="checkerboard"/>'
     '<float name="alpha_v" value="0.2"/></bsdf></shape>', "anisotropic roughness .* on roughdielectric"),
])
def test_textures_tracer_cannot_use_are_refused_in_one_line(tmp_path, body, words):
    with pytest.raises(InputError, match=words) as caught:
        _load(tmp_path, body)
    assert "\n" not in str(caught.value)


def test_a_bad_filter_or_wrap_mode_names_the_line(tmp_path, ):
    (tmp_path / "t.png").write_bytes(b"")
    for key, value in (("filter_type", "cubic"), ("wrap_mode", "tile")):
        body = (f'<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="bitmap"><string '
                f'name="filename" value="t.png"/><string name="{key}" value="{value}"/></texture></bsdf></shape>')
        with pytest.raises(InputError, match=f"{key}: expected") as caught:
            _load(tmp_path, body)
        assert "scene.xml:4" in str(caught.value)


TOML_CAMERA = {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4}


def test_a_toml_quad_is_textured_as_mitsubas_rectangle(tmp_path):
    # The same parallelogram and checkerboard in both formats: the same corner coordinates
    # (Mitsuba's rectangle: (0, 0) at o, (1, 0) at o + edge1) and the same texture rows.
    xml = _load(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" '
                'type="checkerboard"><rgb name="color0" value="0.9"/><transform name="to_uv"><scale x="3" y="2"/>'
                '</transform></texture></bsdf></shape>')
    toml = tracer.load_scene({"camera": TOML_CAMERA, "materials": {"m": {"type": "diffuse", "reflectance": {
        "texture": "checkerboard", "color0": 0.9, "to_uv": [[3, 0, 0], [0, 2, 0]]}}},
        "shapes": [{"type": "quad", "origin": [-1, -1, 0], "edge1": [2, 0, 0], "edge2": [0, 2, 0], "material": "m"}],
        "lights": [{"type": "point", "position": [0, 0, 3], "intensity": [1, 1, 1]}]})
    np.testing.assert_array_equal(toml.corner_uv, xml.corner_uv)
    a = toml.textures.arrays(2, toml.corner_uv, toml.sphere_frame)
    b = xml.textures.arrays(2, xml.corner_uv, xml.sphere_frame)
    np.testing.assert_array_equal(a.info, b.info)
    np.testing.assert_array_equal(a.bindings, b.bindings)


def _toml(tmp_path, material: dict, shape: dict | None = None):
    return tracer.load_scene({"camera": TOML_CAMERA, "materials": {"m": material},
                              "shapes": [shape or {"type": "quad", "origin": [-1, -1, 0], "edge1": [2, 0, 0],
                                                   "edge2": [0, 2, 0], "material": "m"}]}, base_dir=tmp_path)


@pytest.mark.parametrize("material, shape, words", [
    ({"type": "diffuse", "reflectance": {"texture": "bitmap", "file": "nope.png"}}, None,
     "materials.m.reflectance.file: texture image not found"),
    ({"type": "diffuse", "reflectance": {"texture": "bitmap", "file": "t.png", "filtr": "nearest"}}, None,
     "unknown key 'filtr' (did you mean 'filter'?)"),
    ({"type": "diffuse", "reflectance": {"texture": "noise"}}, None, "expected one of checkerboard, bitmap"),
    ({"type": "plastic", "int_ior": {"texture": "checkerboard"}}, None, "materials.m.int_ior: expected a number"),
    ({"type": "diffuse", "reflectance": {"texture": "checkerboard", "to_uv": [[1, 0], [0, 1]]}}, None,
     "expected 2 lists of 3 numbers"),
    ({"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]},
     {"type": "sphere", "center": [0, 0, 0], "radius": 1, "uv_frame": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]},
     "uv_frame: expected the rows of a rotation"),
    ({"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]},
     {"type": "sphere", "center": [0, 0, 0], "radius": 1, "subdivisions": 1, "uv_frame": [[1, 0, 0]] * 3},
     "uv_frame is a true sphere's"),
])
def test_toml_textures_are_checked_naming_the_key(tmp_path, material, shape, words):
    import OpenImageIO as oiio

    _write(tmp_path / "t.png", np.zeros((2, 2, 3), dtype=np.uint8), oiio.UINT8)
    with pytest.raises(InputError, match=re.escape(words)) as caught:
        _toml(tmp_path, material, shape)
    assert "\n" not in str(caught.value)


def test_flip_v_turns_a_mesh_files_coordinates(tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0.25\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    material = {"type": "diffuse", "reflectance": {"texture": "checkerboard"}}
    for flip, expected in ((False, [0, 0.25, 1, 0, 0, 1]), (True, [0, 0.75, 1, 1, 0, 0])):
        scene = _toml(tmp_path, material, {"type": "mesh", "file": "tri.obj", "material": "m", "flip_v": flip})
        np.testing.assert_allclose(scene.corner_uv, [expected])


def test_rawconstant_is_its_value_everywhere(tmp_path):
    """Mitsuba's ``rawconstant``: a vector (or one number for all three channels) used as it is,
    with no sRGB decoding: the bound texture is one texel of that value; to_uv and a missing
    value are refused in one line."""
    scene = _load(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" '
                  'type="rawconstant"><vector name="value" value="0.2, 0.5, 0.8"/></texture></bsdf></shape>')
    (texture,) = scene.textures.textures
    np.testing.assert_array_equal(texture.pixels.reshape(3), np.float32([0.2, 0.5, 0.8]))
    grey = _load(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" '
                 'type="rawconstant"><float name="value" value="0.25"/></texture></bsdf></shape>')
    np.testing.assert_array_equal(grey.textures.textures[0].pixels.reshape(3), np.float32([0.25] * 3))
    for body, words in (('<float name="value" value="0.2"/><transform name="to_uv"><scale value="2"/>'
                         '</transform>', "no to_uv"), ("", "missing property 'value'")):
        with pytest.raises(InputError, match=words) as caught:
            _load(tmp_path, '<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" '
                  f'type="rawconstant">{body}</texture></bsdf></shape>')
        assert "\n" not in str(caught.value)
