"""Opacity masks (tracer/estimator/cutouts.py, Mitsuba's ``mask``): what passes a cutout.

A cutout changes no random number the strategy's samples draw (its camera decisions have a
stream of their own), so the same lanes with and without a cutout take the same light and
direction samples: what a shadow or direction ray carries through a cutout of opacity a is then
exactly 1 - a times what it carries without it, which these tests check to rounding. The camera's
pass-through is random: each lane passes with probability 1 - a, tested with an exact binomial
test. Agreement with Mitsuba 3 (volpath, max_depth 2) is in tests/test_mitsuba_agreement.py
(scene tracer/scenes/mitsuba/mask.xml). The readers' refusals are checked line by line.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import tracer
from tracer import cli
from tracer.estimator import DirectLighting
from tracer.strategy import Strategy

HEADER = """
[camera]
origin = [0.0, 0.5, 3.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
width = 8
height = 8

[materials.floor]
type = "diffuse"
reflectance = [0.5, 0.6, 0.7]

[materials.black]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
"""

FLOOR = """[[shapes]]
type = "quad"
origin = [-2.0, 0.0, -2.0]
edge1 = [0.0, 0.0, 4.0]
edge2 = [4.0, 0.0, 0.0]
material = "floor"
"""

# A floor at y = 0, a pane at y = 1 spanning it (the cutout under test, or a pane of opacity 0,
# or none), an emitting quad at y = 2 facing down and a point light above: every light sample
# and every direction ray from the floor toward a light crosses the pane once.
LIT_FLOOR = HEADER + """
[materials.pane]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
opacity = {opacity}

""" + FLOOR + """
{pane}

[[shapes]]
type = "quad"
origin = [-0.6, 2.0, -0.6]
edge1 = [1.2, 0.0, 0.0]
edge2 = [0.0, 0.0, 1.2]
emission = [4.0, 3.0, 2.0]

[[lights]]
type = "point"
position = [0.7, 1.8, 0.2]
intensity = [1.0, 2.0, 3.0]
"""

PANE = """[[shapes]]
type = "quad"
origin = [-2.0, 1.0, -2.0]
edge1 = [0.0, 0.0, 4.0]
edge2 = [4.0, 0.0, 0.0]
material = "pane"
"""


def load(tmp_path, text: str, name: str = "scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return tracer.load_scene(str(path))


def floor_rays(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Rays straight down onto the floor from below the pane: the camera side crosses no cutout."""
    rng = np.random.default_rng(seed)
    origins = np.column_stack([rng.uniform(-1.5, 1.5, n), np.full(n, 0.5), rng.uniform(-1.5, 1.5, n)])
    dirs = np.tile([0.0, -1.0, 0.0], (n, 1))
    return origins, dirs


@pytest.mark.parametrize("strategy", ["mis", "light", "bsdf"])
def test_light_through_a_pane_is_one_minus_opacity_of_it(tmp_path, strategy):
    """Per lane, the radiance of floor points lit through a pane of opacity 0.3 is 0.7 times
    that through a pane of opacity 0, which equals that with no pane at all: shadow rays (area
    and point light) and direction rays (bsdf, and mis's both) carry 1 - a through a cutout, and
    a cutout of opacity 0 passes everything. Deterministic: the same samples in all three
    scenes (the floor spans the pane, so the ray offsets are the same); 1e-12 relative allows
    the rounding of one product."""
    origins, dirs = floor_rays(4000)
    strategy = Strategy(strategy)
    images = [DirectLighting(load(tmp_path, LIT_FLOOR.format(opacity=opacity, pane=pane), f"{i}.toml"),
                             strategy).radiance(origins, dirs, seed=11)
              for i, (opacity, pane) in enumerate([(0.3, PANE), (0.0, PANE), (1.0, "")])]
    masked, clear, none = images
    # Lanes that see light: most, but with BSDF sampling alone only those whose ray hits the quad.
    assert np.count_nonzero(none.max(axis=1) > 0) > (100 if strategy.name == "bsdf" else 1000)
    np.testing.assert_allclose(clear, none, rtol=1e-12, atol=0)
    np.testing.assert_allclose(masked, 0.7 * none, rtol=1e-12, atol=0)


def test_opaque_pane_blocks_every_light(tmp_path):
    """A pane of opacity 1 is an ordinary occluder: no light reaches the floor below it."""
    origins, dirs = floor_rays(500)
    scene = load(tmp_path, LIT_FLOOR.format(opacity=1.0, pane=PANE))
    assert not np.any(DirectLighting(scene, Strategy("mis")).radiance(origins, dirs, seed=2))


def test_textured_opacity_is_looked_up_where_the_shadow_ray_crosses(tmp_path):
    """The point light alone (light sampling: one deterministic sample per lane), through a pane
    whose opacity is a checkerboard: each lane's radiance is 1 - a(u, v) times the unmasked one,
    with (u, v) where the segment from the floor point to the light meets the pane, a the
    checkerboard's one-number value there (Mitsuba's swapped colours: color0 where exactly one of
    the scaled coordinates' fractional parts is above 1/2). Lanes whose crossing lies within
    1e-6 of a checker edge are left out (float32 geometry decides their side); 1e-12 relative
    allows the rounding of one product, as above."""
    pane_opacity = ('{ texture = "checkerboard", color0 = 0.25, color1 = 0.9, '
                    'to_uv = [[3.0, 0.0, 0.0], [0.0, 5.0, 0.0]] }')
    text = LIT_FLOOR.replace("""[[shapes]]
type = "quad"
origin = [-0.6, 2.0, -0.6]
edge1 = [1.2, 0.0, 0.0]
edge2 = [0.0, 0.0, 1.2]
emission = [4.0, 3.0, 2.0]
""", "")
    origins, dirs = floor_rays(3000)
    masked = DirectLighting(load(tmp_path, text.format(opacity=pane_opacity, pane=PANE), "a.toml"),
                            Strategy("light")).radiance(origins, dirs, seed=5)
    none = DirectLighting(load(tmp_path, text.format(opacity=1.0, pane=""), "b.toml"),
                          Strategy("light")).radiance(origins, dirs, seed=5)
    floor = origins * [1.0, 0.0, 1.0]
    light = np.array([0.7, 1.8, 0.2])
    crossing = floor + (light - floor) * (1.0 / 1.8)  # where y = 1
    # The pane's quad: o = (-2, 1, -2), edge1 along +z (u), edge2 along +x (v), each 4 long.
    su, sv = 3.0 * (crossing[:, 2] + 2.0) / 4.0, 5.0 * (crossing[:, 0] + 2.0) / 4.0
    fu, fv = su - np.floor(su), sv - np.floor(sv)
    opacity = np.where((fu > 0.5) != (fv > 0.5), 0.25, 0.9)
    clear_of_edges = np.minimum.reduce([np.abs(fu - 0.5), np.abs(fv - 0.5), fu, fv, 1 - fu, 1 - fv]) > 1e-6
    assert clear_of_edges.sum() > 2900 and np.all(none[clear_of_edges].max(axis=1) > 0)
    np.testing.assert_allclose(masked[clear_of_edges], ((1.0 - opacity) * none.T).T[clear_of_edges],
                               rtol=1e-12, atol=0)
    assert {0.25, 0.9} <= set(np.unique(opacity[clear_of_edges]))


# An emitting wall behind two panes of opacity 0.4 and 0.25 (black: a kept hit adds nothing),
# seen by the camera: a lane's radiance is the wall's where it passes both, else 0.
THROUGH = HEADER + """
[materials.near]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
opacity = 0.4

[materials.far]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
opacity = 0.25

[[shapes]]
type = "quad"
origin = [-3.0, -3.0, 0.5]
edge1 = [6.0, 0.0, 0.0]
edge2 = [0.0, 6.0, 0.0]
material = "near"

[[shapes]]
type = "sphere"
center = [0.0, 0.0, -0.2]
radius = 0.6
material = "far"

[[shapes]]
type = "quad"
origin = [-3.0, -3.0, -1.5]
edge1 = [6.0, 0.0, 0.0]
edge2 = [0.0, 6.0, 0.0]
emission = [2.0, 2.0, 2.0]
"""


def test_camera_rays_pass_cutouts_with_probability_one_minus_opacity(tmp_path):
    """Rays from (0, 0, 3) toward the wall: those inside the sphere's silhouette cross the near
    pane and the sphere twice (both of its sides are the cutout), so they reach the wall with
    probability 0.6 x 0.75², the others with 0.6. Each lane's value is 0 or the wall's 2 (any
    other value would be a wrong pass-through), and the counts of lanes that reach it are
    Binomial(n, p): an exact two-sided binomial test per group at 1e-3 (Šidák over the two
    groups: 1 - (1 - 1e-3)^(1/2) each). The lanes' decisions are independent: each lane is its
    own pixel."""
    scene = load(tmp_path, THROUGH)
    n = 40000
    rng = np.random.default_rng(8)
    target = np.column_stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-1.2, 1.2, n), np.full(n, -1.5)])
    origins = np.tile([0.0, 0.0, 3.0], (n, 1))
    dirs = target - origins
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    value = DirectLighting(scene, Strategy("mis")).radiance(origins, dirs, seed=4)
    assert np.all(value[:, 0] == value[:, 1]) and np.all(value[:, 0] == value[:, 2])
    assert set(np.unique(value[:, 0])) <= {0.0, 2.0}
    # Whether a ray meets the sphere (centre c, radius r) at all.
    c = np.array([0.0, 0.0, -0.2])
    along = np.einsum("ij,ij->i", c - origins, dirs)
    miss_distance = np.linalg.norm(origins + along[:, None] * dirs - c, axis=1)
    clear = np.abs(miss_distance - 0.6) > 1e-4  # leave out the rim, where float32 decides
    alpha = 1.0 - (1.0 - 1e-3) ** 0.5
    for group, p in [(miss_distance < 0.6, 0.6 * 0.75**2), (miss_distance > 0.6, 0.6)]:
        lanes = group & clear
        reached = int(np.count_nonzero(value[lanes, 0] == 2.0))
        assert lanes.sum() > 5000
        assert stats.binomtest(reached, int(lanes.sum()), p).pvalue > alpha, (reached, lanes.sum(), p)


def test_a_render_through_cutouts_is_the_same_in_any_batch(tmp_path):
    """A lane's pass-through decisions depend on its pixel and sample alone: rendering the lanes
    in two halves gives each lane the value it has in one batch."""
    scene = load(tmp_path, THROUGH)
    n = 2000
    rng = np.random.default_rng(1)
    dirs = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n), -np.ones(n)])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    origins = np.tile([0.0, 0.0, 3.0], (n, 1))
    estimator = DirectLighting(scene, Strategy("mis"))
    pixel = np.arange(n)
    whole = estimator.radiance(origins, dirs, seed=9, pixel=pixel)
    halves = np.concatenate([estimator.radiance(origins[:1000], dirs[:1000], seed=9, pixel=pixel[:1000]),
                             estimator.radiance(origins[1000:], dirs[1000:], seed=9, pixel=pixel[1000:])])
    np.testing.assert_array_equal(whole, halves)


MASKED_XML = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="rectangle">
{inside}
    </shape>
    <emitter type="point"><point name="position" x="0" y="0" z="2"/></emitter>
</scene>
"""


@pytest.mark.parametrize("inside, where, message", [
    ('<bsdf type="mask"><float name="opacity" value="0.3"/>'
     '<bsdf type="diffuse"/></bsdf><emitter type="area"/>', 8,
     '<bsdf type="mask"> in <shape type="rectangle">: a mask on an emitting shape is not supported '
     '(tracer\'s emitters are opaque)'),
    ('<bsdf type="mask"><float name="opacity" value="0.3"/></bsdf>', 8,
     '<bsdf type="mask">: mask needs one nested bsdf, not 0'),
    ('<bsdf type="mask"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>', 8,
     '<bsdf type="mask"> in <bsdf type="mask">: a mask inside a mask is not supported (give one mask '
     'the product of the opacities)'),
])
def test_mitsuba_masks_that_are_refused(tmp_path, capsys, inside, where, message):
    """What tracer does not render of Mitsuba's mask is refused in one line naming the element."""
    path = tmp_path / "scene.xml"
    path.write_text(MASKED_XML.format(inside=inside))
    assert cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0] == f"tracer: error: {path}:{where}: {message}"


def test_mitsuba_mask_reads_its_opacity_into_a_row_of_its_own(tmp_path):
    """The mask's nested BSDF gets a row of its own with the mask's opacity (a colour's
    luminance); the nested BSDF used unmasked elsewhere keeps opacity 1."""
    path = tmp_path / "scene.xml"
    path.write_text("""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <bsdf type="diffuse" id="green"><rgb name="reflectance" value="0.1, 0.8, 0.1"/></bsdf>
    <shape type="rectangle">
        <bsdf type="mask"><rgb name="opacity" value="0.2, 0.4, 0.6"/><ref id="green"/></bsdf>
    </shape>
    <shape type="sphere"><ref id="green"/></shape>
    <emitter type="point"><point name="position" x="0" y="0" z="2"/></emitter>
</scene>
""")
    table = tracer.load_scene(str(path)).materials
    luminance = 0.212671 * 0.2 + 0.715160 * 0.4 + 0.072169 * 0.6
    assert sorted(table.opacity.tolist()) == pytest.approx([luminance, 1.0, 1.0])
    masked = int(np.argmin(table.opacity))
    green = table.names.index("green")
    np.testing.assert_array_equal(table.params[masked], table.params[green])


@pytest.mark.parametrize("opacity, message", [
    ("1.5", "materials.pane.opacity"),
    ('"half"', "materials.pane.opacity"),
])
def test_toml_opacity_out_of_range_is_refused(tmp_path, capsys, opacity, message):
    path = tmp_path / "scene.toml"
    path.write_text(LIT_FLOOR.format(opacity=opacity, pane=PANE))
    assert cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and str(path) in err[0], err


def test_convert_writes_a_constant_opacity(tmp_path):
    """tracer convert writes a material's constant opacity: the TOML it writes loads as the same
    scene (the digest holds the opacities)."""
    from tracer.scene.toml_writer import write_scene

    scene = load(tmp_path, LIT_FLOOR.format(opacity=0.3, pane=PANE))
    write_scene(scene, tmp_path / "again.toml", str(scene.path))
    again = tracer.load_scene(str(tmp_path / "again.toml"))
    assert again.digest == scene.digest
    assert sorted(again.materials.opacity.tolist()) == [0.3, 1.0, 1.0, 1.0]


def test_toml_emitter_with_opacity_is_refused(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(LIT_FLOOR.format(opacity=0.5, pane=PANE).replace(
        'emission = [4.0, 3.0, 2.0]', 'emission = [4.0, 3.0, 2.0]\nmaterial = "pane"'))
    assert cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"tracer: error: {path}: shape 3 emits, and its material 'pane' has an opacity (a mask): "
                   "tracer's emitters are opaque"], err


# A sun (directional light) above a leaf plane of opacity 0.5, above the floor; optionally an
# opaque roof between the leaves and the floor.
SUN = HEADER + """
[materials.leaves]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
opacity = 0.5

""" + FLOOR + """
[[shapes]]
type = "quad"
origin = [-9.0, 2.0, -9.0]
edge1 = [0.0, 0.0, 18.0]
edge2 = [18.0, 0.0, 0.0]
material = "leaves"

{roof}

[[lights]]
type = "directional"
direction = [0.0, -1.0, 0.0]
irradiance = [1.0, 2.0, 3.0]
"""

ROOF = """[[shapes]]
type = "quad"
origin = [-9.0, 1.0, -9.0]
edge1 = [0.0, 0.0, 18.0]
edge2 = [18.0, 0.0, 0.0]
material = "black"
"""


def test_light_from_infinity_through_a_cutout_and_an_occluder(tmp_path):
    """A directional light's shadow rays run to infinity: through the leaves (opacity 0.5) they
    carry half the light, exactly, and an opaque roof below the leaves still blocks all of it
    (a ray to infinity has no end to re-aim at: it keeps its direction past each cutout)."""
    origins, dirs = floor_rays(400)
    light = Strategy("light")
    leaves = DirectLighting(load(tmp_path, SUN.format(roof=""), "a.toml"), light).radiance(origins, dirs)
    roofed = DirectLighting(load(tmp_path, SUN.format(roof=ROOF), "b.toml"), light).radiance(origins, dirs)
    clear = DirectLighting(load(tmp_path, SUN.format(roof="").replace("opacity = 0.5", "opacity = 0.0"),
                                "c.toml"), light).radiance(origins, dirs)
    assert np.all(clear > 0)
    np.testing.assert_allclose(leaves, 0.5 * clear, rtol=1e-12, atol=0)
    assert not np.any(roofed)


@pytest.mark.parametrize("bsdf", [
    '<bsdf type="twosided"><bsdf type="mask"><float name="opacity" value="0.3"/>'
    '<bsdf type="diffuse"/></bsdf></bsdf>',
    '<bsdf type="mask"><float name="opacity" value="0.3"/>'
    '<bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>',
])
def test_a_mask_and_a_twosided_nest_either_way(tmp_path, bsdf):
    """A twosided around a mask and a mask around a twosided (both of which Mitsuba takes) give one
    two-sided row with the mask's opacity, and no row for the BSDFs inside."""
    path = tmp_path / "scene.xml"
    path.write_text(MASKED_XML.format(inside=bsdf))
    table = tracer.load_scene(str(path)).materials
    assert len(table.kind) == 2  # the black material, and the mask's row
    assert table.opacity[1] == pytest.approx(0.3) and table.twosided[1]
