"""Normal and bump maps (tracer/textures/shading_frames.py, Mitsuba's ``normalmap`` and
``bumpmap``): the pieces of the tilted frame checked one by one against what they must be, and
the readers' refusals line by line.

The kernels' functions are called directly (numba dispatchers run from Python): these checks are
deterministic, so their bounds are rounding, each derived where it is used. Agreement of whole
renders with Mitsuba 3 is in tests/test_mitsuba_agreement.py (scene
tracer/scenes/mitsuba/normal_maps.xml: both maps, a mesh with coordinates and normals, an
analytic sphere, a two-sided floor, both of Mitsuba's switches).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_masks import MASKED_XML  # a rectangle holding the BSDF under test, and a light

import tracer
from tracer import cli
from tracer.estimator import DirectLighting
from tracer.strategy import Strategy
from tracer.textures import Texture, TextureTable
from tracer.textures.lookup import evaluate_one, uv_at
from tracer.textures.shading_frames import factor, height_gradient, perturbed, uv_partials

MITSUBA = tracer.__path__[0] + "/scenes/mitsuba"


def _arrays(texture: Texture):
    table = TextureTable()
    table.add(texture)
    return table.arrays(1, np.zeros((0, 6)), np.zeros((0, 9)))


def test_the_height_gradient_is_the_derivative_of_the_lookup():
    """Inside one cell of texel centres a bilinear lookup is bilinear in (su, sv), so a central
    difference of step h there equals its derivative up to rounding: values of order 1 looked
    up in float64 differ by about 1e-16, divided by 2h = 2e-6 that is 1e-10, and the gradient is
    of order 10-100 (a texel is 1/12 wide). The to_uv map has a rotation and a shear on a
    texture that is not square, so a gradient taken before it, with its transpose missing, or
    scaled by the resolution after it (Mitsuba 3.9.1's order, which is not the derivative here:
    shading_frames.height_gradient), is off by far more than 1e-7."""
    rng = np.random.default_rng(5)
    texture = Texture("bitmap", pixels=rng.random((7, 12, 3)).astype(np.float32), wrap="repeat")
    texture.to_uv = np.array([[1.3, 0.4, 0.1], [-0.5, 0.9, 0.3]])
    arrays = _arrays(texture)
    h = 1e-6
    checked = 0
    for u, v in rng.random((200, 2)):
        su, sv = texture.to_uv @ [u, v, 1.0]
        pu, pv = su * 12 - 0.5, sv * 7 - 0.5
        if min(pu % 1, 1 - pu % 1, pv % 1, 1 - pv % 1) < 1e-4:
            continue  # the steps would cross a cell's edge, where the lookup has a kink
        du = (evaluate_one(arrays, 0, u + h, v) - evaluate_one(arrays, 0, u - h, v)) / (2 * h)
        dv = (evaluate_one(arrays, 0, u, v + h) - evaluate_one(arrays, 0, u, v - h)) / (2 * h)
        g_u, g_v = height_gradient(arrays, 0, u, v)
        assert g_u == pytest.approx(du, abs=1e-7) and g_v == pytest.approx(dv, abs=1e-7)
        checked += 1
    assert checked > 150


def test_a_nearest_lookup_or_a_checkerboard_has_no_gradient():
    """Mitsuba's eval_1_grad is 0 for a nearest lookup (piecewise constant) and tracer refuses a
    checkerboard height field; the kernel returns 0 for both rather than garbage."""
    texture = Texture("bitmap", pixels=np.random.default_rng(1).random((4, 4, 3)).astype(np.float32),
                      filter="nearest")
    assert height_gradient(_arrays(texture), 0, 0.3, 0.6) == (0.0, 0.0)
    assert height_gradient(_arrays(Texture("checkerboard")), 0, 0.3, 0.6) == (0.0, 0.0)


def _scene_with(tmp_path, shape: str, bsdf: str):
    path = tmp_path / "scene.xml"
    path.write_text(f"""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    {shape.format(bsdf=bsdf)}
    <emitter type="point"><point name="position" x="0" y="0" z="3"/></emitter>
</scene>
""")
    return tracer.load_scene(str(path))


FLAT = ('<bsdf type="normalmap"><rgb name="normalmap" value="0.5, 0.5, 1"/>'
        '<bsdf type="diffuse"/></bsdf>')
QUAD = f"""<shape type="ply"><string name="filename" value="{MITSUBA}/meshes/quad_uv.ply"/>
    <transform name="to_world"><rotate z="1" angle="25"/><scale x="1.5" y="0.7"/></transform>
    {{bsdf}}</shape>"""
SPHERE = """<shape type="sphere"><float name="radius" value="0.8"/>
    <transform name="to_world"><rotate x="1" angle="50"/><translate x="0.2"/></transform>{bsdf}</shape>"""


def _surfaces(scene):
    return DirectLighting(scene, Strategy("mis")).surfaces


def test_a_triangles_uv_partials_carry_texture_steps_to_surface_steps(tmp_path):
    """On a triangle the point is affine in (u, v), so from corner 0 to corner k it moves by
    exactly dp/du (u_k - u_0) + dp/dv (v_k - v_0): checked for both other corners of every
    triangle of a rotated, unevenly scaled quad whose coordinates run over [0, 2] x [0, 1.5],
    to 1e-12 (coordinates of order 1, a few float64 operations)."""
    scene = _scene_with(tmp_path, QUAD, FLAT)
    surfaces = _surfaces(scene)
    corners = scene.vertices[scene.faces]
    uv = surfaces.textures.corner_uv.reshape(-1, 3, 2)
    for p in range(len(scene.faces)):
        face = tuple(surfaces.hit_table[p, 9:12])
        partials = uv_partials(surfaces.textures, surfaces.hit_table, surfaces.first_sphere, p,
                               tuple(corners[p, 0]), face)
        dp_du, dp_dv = (np.array(a) for a in partials)
        for k in (1, 2):
            step = dp_du * (uv[p, k, 0] - uv[p, 0, 0]) + dp_dv * (uv[p, k, 1] - uv[p, 0, 1])
            np.testing.assert_allclose(step, corners[p, k] - corners[p, 0], atol=1e-12)


def test_a_spheres_uv_partials_are_the_derivatives_of_its_coordinates(tmp_path):
    """Mitsuba's sphere maps (u, v) to the local direction (sin θ cos φ, sin θ sin φ, cos θ),
    φ = 2π u, θ = π v: a central difference of that map (turned to world, times the radius)
    with step h = 1e-6 matches dp/du and dp/dv to 1e-7. The difference errs by h²/6 times the
    third derivative, (2π)³ r h² / 6 ~ 3e-11, plus rounding of about 1e-16 / h = 1e-10; a wrong
    factor or axis would be off by the entries themselves (of order 1 to 5)."""
    scene = _scene_with(tmp_path, SPHERE, FLAT)
    surfaces = _surfaces(scene)
    p = surfaces.first_sphere
    center, radius = surfaces.hit_table[p, 0:3], surfaces.hit_table[p, 3]
    rows = surfaces.textures.sphere_frame[0].reshape(3, 3)  # world -> local

    def point(u, v):
        phi, theta = 2 * math.pi * u, math.pi * v
        local = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
        return center + radius * rows.T @ local

    h = 1e-6
    for u, v in [(0.1, 0.3), (0.6, 0.55), (0.93, 0.8)]:
        x = point(u, v)
        # the parameterization differenced here is the one lookups use (to float64 rounding)
        looked_up = uv_at(surfaces.textures, surfaces.hit_table, p, p, tuple(x))
        assert looked_up == pytest.approx((u, v), abs=1e-12)
        face = tuple((x - center) / radius)
        dp_du, dp_dv = uv_partials(surfaces.textures, surfaces.hit_table, p, p, tuple(x), face)
        np.testing.assert_allclose(dp_du, (point(u + h, v) - point(u - h, v)) / (2 * h), atol=1e-7)
        np.testing.assert_allclose(dp_dv, (point(u, v + h) - point(u, v - h)) / (2 * h), atol=1e-7)


@pytest.mark.parametrize("shape", [QUAD, SPHERE])
def test_a_flat_normal_map_leaves_the_frame_as_it_is(tmp_path, shape):
    """The texel (0.5, 0.5, 1) is the normal (0, 0, 1) of the unperturbed frame: the tilted normal
    is the shading normal and the direction to the viewer keeps its angle to it (to 1e-12), the
    shadowing term's a² is 0, and a sample above the surface counts fully (one below both
    normals passes the mask too, as Mitsuba's: the material's own cosine then gives 0)."""
    scene = _scene_with(tmp_path, shape, FLAT)
    surfaces = _surfaces(scene)
    p = surfaces.first_sphere if shape is SPHERE else 0
    row = int(surfaces.hit_table[p, 15])
    if p < surfaces.first_sphere:
        x = tuple(scene.vertices[scene.faces[p]].mean(axis=0))
        normal = tuple(surfaces.hit_table[p, 9:12])
    else:
        center, radius = surfaces.hit_table[p, 0:3], surfaces.hit_table[p, 3]
        n = np.array([0.3, 0.2, 0.93])
        n /= np.linalg.norm(n)
        x, normal = tuple(center + radius * n), tuple(n)
    d = np.array([0.1, -0.2, -1.0])
    d /= np.linalg.norm(d)
    if np.dot(d, normal) > 0:
        d = -d
    reflects, tilted, s, t, wo, a2 = perturbed(surfaces.textures, row, surfaces.hit_table,
                                               surfaces.first_sphere, surfaces.corner_normals, p, x,
                                               tuple(d), normal)
    assert reflects and a2 == 0.0
    np.testing.assert_allclose(tilted, normal, atol=1e-12)
    assert wo[2] == pytest.approx(-float(np.dot(d, normal)), abs=1e-12)
    frame = np.array([s, t, tilted])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    up = np.array(normal) + 0.3 * np.array(s)
    up /= np.linalg.norm(up)
    assert factor(normal, tilted, a2, tuple(up)) == 1.0


def test_the_shadowing_term_and_the_shared_hemisphere():
    """Estevez et al.'s term 2 / (1 + sqrt(1 + a² tan² θ)) at a² = 0.5, θ = 60° (tan² = 3):
    2 / (1 + sqrt(2.5)); a direction above the unperturbed normal but below the tilted one
    counts 0."""
    normal, tilted = (0.0, 0.0, 1.0), (math.sin(0.4), 0.0, math.cos(0.4))
    wi = (math.sin(math.pi / 3), 0.0, math.cos(math.pi / 3))
    assert factor(normal, tilted, 0.5, wi) == pytest.approx(2.0 / (1.0 + math.sqrt(2.5)), rel=1e-14)
    below_tilted = (-math.cos(0.3), 0.0, math.sin(0.3))  # 17° above the plane, 6° below the tilt
    assert np.dot(below_tilted, normal) > 0 > np.dot(below_tilted, tilted)
    assert factor(normal, tilted, 0.5, below_tilted) == 0.0


def test_flip_invalid_normals_mirrors_a_normal_facing_away(tmp_path):
    """A constant normal map tilted 60° away from a viewer who looks at 70° from the other
    side: with Mitsuba's default the texel's normal is mirrored about the shading normal (x and y
    negated), so the viewer sees the surface; switched off, the viewer is below the tilted
    frame and the hit reflects nothing (Mitsuba's nested BSDF evaluates to 0 there)."""
    n = (math.sin(math.radians(60)), 0.0, math.cos(math.radians(60)))
    rgb = ", ".join(f"{0.5 + 0.5 * c:.9f}" for c in n)
    results = {}
    for flip in ("true", "false"):
        bsdf = (f'<bsdf type="normalmap"><boolean name="flip_invalid_normals" value="{flip}"/>'
                f'<rgb name="normalmap" value="{rgb}"/><bsdf type="diffuse"/></bsdf>')
        scene = _scene_with(tmp_path, QUAD.replace('<rotate z="1" angle="25"/>', ''), bsdf)
        surfaces = _surfaces(scene)
        x = tuple(scene.vertices[scene.faces[0]].mean(axis=0))
        normal = tuple(surfaces.hit_table[0, 9:12])
        # the quad's dp/du is +x (u runs along x): the texel leans toward +x, the viewer is at -x
        d = (math.sin(math.radians(70)), 0.0, -math.cos(math.radians(70)))
        results[flip] = perturbed(surfaces.textures, int(surfaces.hit_table[0, 15]), surfaces.hit_table,
                                  surfaces.first_sphere, surfaces.corner_normals, 0, x, d, normal)
    reflects, tilted, _, _, _, a2 = results["true"]
    assert reflects
    # The texel is an rgb constant, stored in float32: its components are off by up to 3e-8
    # (half a float32 ulp at 0.5 .. 1, doubled by 2 rgb - 1), hence 1e-7.
    np.testing.assert_allclose(tilted, (-n[0], 0.0, n[2]), rtol=0, atol=1e-7)
    # The shadowing term's a² = min(tan²(60°) / 8, 1) = 3/8, from the tilted normal's angle.
    assert a2 == pytest.approx(3 / 8, rel=1e-6)
    assert not results["false"][0]


BUMPS = f'<texture type="bitmap"><string name="filename" value="{MITSUBA}/textures/bumps.png"/></texture>'


@pytest.mark.parametrize("inside, message", [
    ('<bsdf type="normalmap"><bsdf type="diffuse"/></bsdf>',
     "<bsdf type=\"normalmap\">: missing property 'normalmap' (a texture or an rgb)"),
    ('<bsdf type="bumpmap"><bsdf type="diffuse"/></bsdf>',
     '<bsdf type="bumpmap">: bumpmap needs one nested texture (the height field), not 0'),
    (f'<bsdf type="bumpmap">{BUMPS}{BUMPS}<bsdf type="diffuse"/></bsdf>',
     '<bsdf type="bumpmap">: bumpmap needs one nested texture (the height field), not 2'),
    ('<bsdf type="bumpmap"><texture type="checkerboard"/><bsdf type="diffuse"/></bsdf>',
     '<texture type="checkerboard"> in <bsdf type="bumpmap">: a bumpmap\'s height field is a bitmap here, '
     'not a checkerboard (Mitsuba takes the gradient of bitmaps only)'),
    (f'<bsdf type="bumpmap">{BUMPS}<bsdf type="dielectric"/></bsdf>',
     '<bsdf type="dielectric"> in <bsdf type="bumpmap">: a bumpmap around dielectric is not supported '
     '(tracer tilts the frame of materials that only reflect)'),
    (f'<bsdf type="normalmap"><rgb name="normalmap" value="0.5, 0.5, 1"/><bsdf type="bumpmap">{BUMPS}'
     '<bsdf type="diffuse"/></bsdf></bsdf>',
     '<bsdf type="bumpmap"> in <bsdf type="normalmap">: a bumpmap inside a normalmap is not supported '
     '(give one map)'),
    ('<bsdf type="normalmap"><rgb name="normalmap" value="0.5, 0.5, 1"/><bsdf type="mask">'
     '<bsdf type="diffuse"/></bsdf></bsdf>',
     '<bsdf type="mask"> in <bsdf type="normalmap">: a mask inside a normalmap is not supported '
     '(put the mask outside the normalmap)'),
    (f'<bsdf type="bumpmap">{BUMPS}<bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>',
     '<bsdf type="twosided"> in <bsdf type="bumpmap">: a twosided inside a bumpmap is not supported '
     '(put the twosided outside the bumpmap)'),
    ('<bsdf type="normalmap"><rgb name="normalmap" value="0.5, 0.5, 2"/><bsdf type="diffuse"/></bsdf>',
     '<rgb name="normalmap"> in <bsdf type="normalmap">: normalmap: expected a number <= 1, got 2'),
    (f'<bsdf type="bumpmap"><float name="scale" value="1e9"/>{BUMPS}<bsdf type="diffuse"/></bsdf>',
     '<float name="scale"> in <bsdf type="bumpmap">: scale: expected a number <= 1e+06, got 1e+09'),
])
def test_normal_and_bump_maps_that_are_refused(tmp_path, capsys, inside, message):
    """What tracer does not render of Mitsuba's two maps is refused in one line naming the
    element (exit status 2, no traceback)."""
    path = tmp_path / "scene.xml"
    path.write_text(MASKED_XML.format(inside=inside))
    assert cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"tracer: error: {path}:") and err[0].endswith(message), err[0]


def test_a_bump_map_on_a_disk_is_refused(tmp_path, capsys):
    """tracer's disk is a fan of triangles whose dp/dv is the rim's everywhere (Mitsuba's
    analytic disk has 2π r): a bump map's tilt would be wrong toward the centre, so it is
    refused in one line; a normal map (which needs only dp/du's direction) is not."""
    path = tmp_path / "scene.xml"
    path.write_text(MASKED_XML.replace('"rectangle"', '"disk"').format(
        inside=f'<bsdf type="bumpmap">{BUMPS}<bsdf type="diffuse"/></bsdf>'))
    assert cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("a bumpmap on a disk is not supported (tracer's disk is a fan "
                                              "of triangles, whose dp/dv is not the disk's)"), err
    path.write_text(MASKED_XML.replace('"rectangle"', '"disk"').format(inside=FLAT))
    assert tracer.load_scene(str(path)).textures.perturbations


def test_an_obj_with_a_vertex_no_face_uses_keeps_its_normals(tmp_path):
    """trimesh's OBJ reader drops a file's normals when a vertex is referenced by no face (a
    valid OBJ: the last vertex of meshes/uv_sphere.obj is one), which made tracer compute its
    own and shade the sphere's poles unlike Mitsuba (found by normal_maps.xml, 0.6% darker).
    The normals are then read from the file's text, one vertex per face corner."""
    from tracer.scene.mesh import read_mesh_file

    path = tmp_path / "m.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvn 0 0 1\nvn 0.6 0 0.8\nvn 0 0.6 0.8\n"
                    "f 1//1 2//2 3//3\n")
    mesh = read_mesh_file(path)
    assert mesh.normals is not None
    np.testing.assert_allclose(mesh.normals[mesh.faces[0]], [[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]])
    np.testing.assert_array_equal(mesh.vertices[mesh.faces[0]], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


GREY = [0.5, 0.5, 0.5]
TOML_SCENE = {"camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 8, "height": 8},
              "shapes": [{"type": "quad", "origin": [-1, -1, 0], "edge1": [2, 0, 0], "edge2": [0, 2, 0],
                          "material": "m"}],
              "lights": [{"type": "point", "position": [0, 0, 2], "intensity": [1, 1, 1]}]}


def test_toml_maps_are_mitsubas(tmp_path):
    """A TOML quad's normal_map and bump_map (with bump_scale and both switches) give the same
    perturbation rows and texels as the Mitsuba rectangle's normalmap and bumpmap (the quad is
    Mitsuba's rectangle, tests/test_textures.py)."""
    normals = f"{MITSUBA}/textures/normals.png"
    cases = [({"normal_map": {"texture": "bitmap", "file": normals, "raw": True}},
              f'<bsdf type="normalmap"><texture name="normalmap" type="bitmap">'
              f'<boolean name="raw" value="true"/><string name="filename" value="{normals}"/></texture>'
              '<bsdf type="diffuse"/></bsdf>'),
             ({"bump_map": {"texture": "bitmap", "file": normals}, "bump_scale": 0.3,
               "flip_invalid_normals": False, "use_shadowing_function": False},
              f'<bsdf type="bumpmap"><float name="scale" value="0.3"/><boolean name="flip_invalid_normals" '
              f'value="false"/><boolean name="use_shadowing_function" value="false"/><texture type="bitmap">'
              f'<string name="filename" value="{normals}"/></texture><bsdf type="diffuse"/></bsdf>')]
    for keys_given, bsdf in cases:
        material = {"type": "diffuse", "reflectance": GREY, "twosided": False, **keys_given}
        toml = tracer.load_scene(dict(TOML_SCENE, materials={"m": material}))
        xml = _scene_with(tmp_path, '<shape type="rectangle">{bsdf}</shape>', bsdf)
        assert list(toml.textures.perturbations.values()) == list(xml.textures.perturbations.values())
        np.testing.assert_array_equal(toml.textures.textures[0].pixels, xml.textures.textures[0].pixels)


@pytest.mark.parametrize("given, words", [
    ({"normal_map": {"texture": "checkerboard"}, "bump_map": {"texture": "checkerboard"}},
     "materials.m.bump_map: give a normal_map or a bump_map, not both"),
    ({"bump_scale": 2.0}, "materials.m.bump_scale: needs a normal_map or a bump_map"),
    ({"bump_map": {"texture": "checkerboard"}},
     "materials.m.bump_map: a bump map is a bilinear bitmap (its gradient is that of the bilinear lookup)"),
    ({"normal_map": {"texture": "checkerboard"}, "bump_scale": 2.0},
     "materials.m.bump_scale: bump_scale belongs to a bump_map"),
    ({"normal_map": 0.5}, "materials.m.normal_map: expected a texture table, got a number"),
])
def test_toml_maps_that_are_refused(given, words):
    """A TOML material's maps are checked naming the key."""
    with pytest.raises(tracer.errors.InputError) as caught:
        tracer.load_scene(dict(TOML_SCENE, materials={"m": dict(type="diffuse", reflectance=GREY, **given)}))
    assert words in str(caught.value)


def test_a_toml_map_on_glass_is_refused():
    with pytest.raises(tracer.errors.InputError) as caught:
        tracer.load_scene(dict(TOML_SCENE, materials={"m": {"type": "dielectric",
                                                             "normal_map": {"texture": "checkerboard"}}}))
    assert ("materials.m.normal_map: a normal_map on dielectric is not supported (tracer tilts the frame of "
            "materials that only reflect)") in str(caught.value)
