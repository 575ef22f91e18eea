"""Orthographic and thin-lens cameras (tracer/camera.py, the XML and TOML readers).

Where Mitsuba decides where a ray goes (the film's extent, the near plane, the lens), the
expected numbers were measured with Mitsuba 3.9.1's ``scalar_rgb`` variant by
benchmarks/mitsuba_reader_facts.py (``lens_cameras``); these tests do not need Mitsuba. The
images themselves are compared with Mitsuba's in tests/test_mitsuba_agreement.py
(tracer/scenes/mitsuba/orthographic.xml and thinlens.xml).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tracer import load_scene
from tracer.errors import InputError
from tracer.warp import sample_concentric_disk

LOOKAT = '<lookat origin="1, 2, 3" target="0.2, 0.5, -1" up="0.1, 1, 0.2"/>'


def _fov(degrees, axis=None):
    axis_property = f'<string name="fov_axis" value="{axis}"/>' if axis else ""
    return f'<float name="fov" value="{degrees}"/>' + axis_property


# As in benchmarks/mitsuba_reader_facts.py: name -> (type, properties, to_world, width, height).
LENS_CAMERAS = {
    "orthographic": ("orthographic", '<float name="near_clip" value="0.7"/>',
                     '<scale x="1.7" y="1.7" z="1.3"/>' + LOOKAT, 200, 100),
    "orthographic_mirrored": ("orthographic", "", '<scale x="-1.7" y="1.7"/>' + LOOKAT, 160, 120),
    "thinlens": ("thinlens", '<float name="aperture_radius" value="0.3"/><float name="focus_distance" '
                 'value="2.5"/><float name="near_clip" value="1e-6"/>' + _fov(40), LOOKAT, 200, 100),
    "thinlens_mirrored": ("thinlens", '<float name="aperture_radius" value="0.3"/><float name="near_clip" '
                          'value="1e-6"/><float name="focus_distance" value="2.5"/>' + _fov(40, "y"),
                          '<scale x="-1"/>' + LOOKAT, 160, 120),
}
FILM_POSITIONS = [(0.5, 0.5), (0.1, 0.2), (0.9, 0.7)]
APERTURE_SAMPLES = [(0.5, 0.5), (0.9, 0.3), (0.2, 0.75)]
# (origin, direction) of Mitsuba's sample_ray(film position, aperture sample), film positions
# outer, aperture samples inner; printed by benchmarks/mitsuba_reader_facts.py.
MITSUBA_LENS_RAYS = {
    "orthographic": [
        ([0.8324996, 1.685937, 2.162499], [-0.1840662, -0.3451241, -0.9203309]),
        ([0.8324996, 1.685937, 2.162499], [-0.1840662, -0.3451241, -0.9203309]),
        ([0.8324996, 1.685937, 2.162499], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.5047299, 2.2502043, 2.2183447], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.5047299, 2.2502043, 2.2183447], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.5047299, 2.2502043, 2.2183447], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.1695731, 1.280856, 2.0469897], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.1695731, 1.280856, 2.0469897], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.1695731, 1.280856, 2.0469897], [-0.1840662, -0.3451241, -0.9203309]),
    ],
    "orthographic_mirrored": [
        ([0.9981596, 1.9965488, 2.9907968], [-0.1840662, -0.3451241, -0.9203309]),
        ([0.9981596, 1.9965488, 2.9907968], [-0.1840662, -0.3451241, -0.9203309]),
        ([0.9981596, 1.9965488, 2.9907968], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.3342202, 2.6261773, 2.487474], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.3342202, 2.6261773, 2.487474], [-0.1840662, -0.3451241, -0.9203309]),
        ([2.3342202, 2.6261773, 2.487474], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.3381349, 1.6056994, 3.4046242], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.3381349, 1.6056994, 3.4046242], [-0.1840662, -0.3451241, -0.9203309]),
        ([-0.3381349, 1.6056994, 3.4046242], [-0.1840662, -0.3451241, -0.9203309]),
    ],
    "thinlens": [
        ([0.9999998, 1.9999996, 2.999999], [-0.1840662, -0.3451241, -0.9203309]),
        ([0.7821416, 1.9281347, 3.0705199], [-0.0964793, -0.3149302, -0.9441984]),
        ([1.1402628, 2.0935016, 2.9368832], [-0.2395514, -0.3815373, -0.8927735]),
        ([0.9999995, 1.9999998, 2.999999], [-0.4491505, -0.2141963, -0.8674006]),
        ([0.7821414, 1.9281348, 3.0705199], [-0.3718178, -0.1897476, -0.9087065]),
        ([1.1402626, 2.0935018, 2.9368832], [-0.4962345, -0.2466836, -0.8324054]),
        ([1.0000001, 1.9999995, 2.999999], [0.0978876, -0.4136235, -0.9051705]),
        ([0.7821419, 1.9281347, 3.0705199], [0.1769037, -0.3766195, -0.9093201]),
        ([1.1402631, 2.0935016, 2.9368832], [0.0445966, -0.4539871, -0.8898916]),
    ],
    "thinlens_mirrored": [
        ([0.9999998, 1.9999996, 2.999999], [-0.1840661, -0.3451241, -0.9203309]),
        ([1.2180264, 1.8998611, 2.9939456], [-0.2700353, -0.3036725, -0.9137089]),
        ([0.8595359, 2.111711, 2.9862001], [-0.1275503, -0.3888022, -0.9124494]),
        ([1.0000002, 1.9999999, 2.999999], [0.1802603, -0.1510757, -0.9719477]),
        ([1.2180268, 1.8998613, 2.9939456], [0.1024773, -0.1166276, -0.9878748]),
        ([0.8595362, 2.1117113, 2.9862001], [0.2287024, -0.1895059, -0.9548731]),
        ([0.9999995, 1.9999995, 2.9999993], [-0.5224073, -0.4218716, -0.7410229]),
        ([1.218026, 1.8998611, 2.9939458], [-0.5863455, -0.3742611, -0.7184201]),
        ([0.8595355, 2.111711, 2.9862003], [-0.4758985, -0.4684565, -0.7443582]),
    ],
}


def sensor_file(tmp_path, kind, props, ops, w, h):
    path = tmp_path / "camera.xml"
    path.write_text(f'<scene version="3.0.0"><sensor type="{kind}">{props}<transform name="to_world">{ops}'
                    f'</transform><film type="hdrfilm"><integer name="width" value="{w}"/><integer '
                    f'name="height" value="{h}"/></film></sensor></scene>')
    return path


def rays_at(camera, positions, lenses):
    """tracer's rays through film positions (u, v) in [0, 1]^2 (v down) and lens samples."""
    w, h = camera.width, camera.height
    pixel, jitter, lens = [], [], []
    for u, v in positions:
        for sample in lenses:
            x, y = u * w, v * h
            pixel.append(int(y) * w + int(x))
            jitter.append((x - int(x), y - int(y)))
            lens.append(sample)
    return camera.rays(np.array(pixel), np.array(jitter), np.array(lens))


@pytest.mark.parametrize("name", LENS_CAMERAS)
def test_rays_start_and_go_where_mitsubas_do(tmp_path, name):
    """The film's extent from the transform's scale, the near plane an orthographic ray starts
    on (scaled by the transform's z), mirrors, and the lens point of each aperture sample
    (Shirley and Chiu's concentric map, as Mitsuba's): tracer's ray origins and directions are
    Mitsuba's at float32 precision (the thin lenses' near plane, 1e-6 ahead, shifts Mitsuba's
    origins by at most that)."""
    camera = load_scene(sensor_file(tmp_path, *LENS_CAMERAS[name])).camera
    origins, directions = rays_at(camera, FILM_POSITIONS, APERTURE_SAMPLES)
    expected = np.array(MITSUBA_LENS_RAYS[name])
    np.testing.assert_allclose(origins, expected[:, 0], atol=5e-6)
    np.testing.assert_allclose(directions, expected[:, 1], atol=1e-6)


def test_thin_lens_rays_meet_in_the_plane_of_focus(tmp_path):
    """Geometry, independent of Mitsuba: every ray through one film position, whatever its lens
    point, passes through the point where the pinhole ray of that position meets the plane in
    focus (focus_distance ahead along the view), and leaves from within aperture_radius of the
    camera's centre on the lens plane (perpendicular to the view)."""
    camera = load_scene(sensor_file(tmp_path, *LENS_CAMERAS["thinlens"])).camera
    f, _, _ = camera.basis
    rng = np.random.default_rng(3)
    n = 500
    pixel = np.full(n, 37 * camera.width + 151)
    jitter = np.full((n, 2), 0.25)
    origins, directions = camera.rays(pixel, jitter, rng.random((n, 2)))
    pinhole_o, pinhole_d = camera.rays(pixel[:1], jitter[:1])
    focus = pinhole_o[0] + pinhole_d[0] * (camera.focus_distance / (pinhole_d[0] @ f))
    offsets = origins - camera.origin
    np.testing.assert_allclose(offsets @ f, 0.0, atol=1e-12)
    assert np.max(np.linalg.norm(offsets, axis=1)) <= camera.aperture_radius * (1 + 1e-12)
    t = (focus - origins) @ f / (directions @ f)
    np.testing.assert_allclose(origins + directions * t[:, None], np.broadcast_to(focus, (n, 3)), atol=1e-9)


def test_concentric_disk_points_are_uniform():
    """Chi-square of 400,000 points of the concentric map on 12 x 16 cells of equal area (rings
    of equal r^2 width, sectors of equal angle): uniform on the disk, each cell expects N / 192
    (~2,083, so the chi-square approximation is sound); the test's level is 1 %."""
    u = np.random.default_rng(11).random((400_000, 2))
    points = sample_concentric_disk(u)
    r2 = np.sum(points**2, axis=1)
    assert r2.max() <= 1.0
    ring = np.minimum((r2 * 12).astype(int), 11)
    sector = np.minimum(((np.arctan2(points[:, 1], points[:, 0]) + np.pi) / (2 * np.pi) * 16).astype(int), 15)
    counts = np.bincount(ring * 16 + sector, minlength=192)
    assert stats.chisquare(counts).pvalue > 0.01


def test_zero_aperture_is_the_pinhole(tmp_path):
    """A thinlens of aperture 0 is the perspective camera: the same rays for any lens sample and
    the same scene digest (so its renders and merges are the pinhole's)."""
    props = '<float name="aperture_radius" value="0"/><float name="focus_distance" value="2"/>' + _fov(40)
    lens = load_scene(sensor_file(tmp_path, "thinlens", props, LOOKAT, 64, 48))
    pinhole = load_scene(sensor_file(tmp_path, "perspective", '<float name="focus_distance" value="2"/>'
                                     + _fov(40), LOOKAT, 64, 48))
    pixel = np.arange(64 * 48)
    jitter = np.random.default_rng(2).random((len(pixel), 2))
    got = lens.camera.rays(pixel, jitter, np.random.default_rng(4).random((len(pixel), 2)))
    want = pinhole.camera.rays(pixel, jitter)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert lens.digest == pinhole.digest


def toml_camera(tmp_path, **camera):
    lines = [f"{key} = {value!r}".replace("'", '"') for key, value in camera.items()]
    path = tmp_path / "scene.toml"
    path.write_text("[camera]\n" + "\n".join(lines)
                    + '\n[materials.m]\ntype = "diffuse"\nreflectance = [0.5, 0.5, 0.5]\n'
                    "[[shapes]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"m\"\n"
                    "emission = [1, 1, 1]\n")
    return path


BASE = {"origin": [0, 0, 5], "target": [0, 0, 0]}


def test_toml_cameras_read_as_the_xml_ones(tmp_path):
    """The TOML keys make the same cameras as Mitsuba's sensors: an orthographic film of
    view_width across, a thin lens of aperture_radius focused at focus_distance."""
    ortho = load_scene(toml_camera(tmp_path, **BASE, projection="orthographic", view_width=2.5)).camera
    o, d = ortho.rays(np.array([0, 255 * 256 + 255]), np.array([[0.0, 0.0], [1.0, 1.0]]))
    np.testing.assert_allclose(o, [[-1.25, 1.25, 5], [1.25, -1.25, 5]], atol=1e-12)
    np.testing.assert_allclose(d, [[0, 0, -1], [0, 0, -1]], atol=1e-12)
    lens = load_scene(toml_camera(tmp_path, **BASE, fov=30, aperture_radius=0.5, focus_distance=4)).camera
    assert lens.thin_lens and lens.focus_distance == 4.0 and lens.aperture_radius == 0.5


@pytest.mark.parametrize("camera, words", [
    ({"projection": "orthographic", "view_width": 2, "fov": 30},
     "camera.fov: an orthographic camera has no fov"),
    ({"projection": "orthographic"}, "camera.view_width: missing required key"),
    ({"projection": "orthographic", "view_width": 0}, "camera.view_width"),
    ({"fov": 30, "view_width": 2}, "camera.view_width: view_width is the orthographic camera's"),
    ({"fov": 30, "aperture_radius": 0.1}, "camera.focus_distance: missing required key"),
    ({"fov": 30, "aperture_radius": -0.1, "focus_distance": 1}, "camera.aperture_radius"),
    ({"projection": "fisheye", "fov": 30}, "camera.projection"),
])
def test_toml_camera_refusals_name_the_key(tmp_path, camera, words):
    with pytest.raises(InputError) as caught:
        load_scene(toml_camera(tmp_path, **BASE, **camera))
    assert words in str(caught.value) and "\n" not in str(caught.value), str(caught.value)


@pytest.mark.parametrize("kind, props, ops, words", [
    ("thinlens", _fov(40), LOOKAT, "needs aperture_radius"),
    ("thinlens", _fov(40) + '<float name="aperture_radius" value="1e300"/>', LOOKAT, "aperture_radius"),
    ("thinlens", _fov(40) + '<float name="aperture_radius" value="0.1"/><float name="focus_distance" '
     'value="1e300"/>', LOOKAT, "focus_distance"),
    ("orthographic", "", '<scale x="2" y="1"/>' + LOOKAT, "scales x and y differently"),
    ("orthographic", "", '<matrix value="1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1"/>', "shears"),
    ("orthographic", "", '<scale x="0"/>', "scales one axis to zero"),
    ("orthographic", _fov(40), LOOKAT, "fov"),
])
def test_xml_sensor_refusals(tmp_path, kind, props, ops, words):
    with pytest.raises(InputError) as caught:
        load_scene(sensor_file(tmp_path, kind, props, ops, 8, 6))
    assert words in str(caught.value) and "\n" not in str(caught.value), str(caught.value)
