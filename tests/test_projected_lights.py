"""Lights that project images: Mitsuba's textured ``spot`` and ``projector``
(tracer/lights/projected_images.py, the point light technique, the XML reader).

The values a light gives at points (its intensity in the direction of the point over the
squared distance) were measured with Mitsuba 3.9.1's ``scalar_rgb`` variant, its emitters'
``sample_direction``, for the cases of tests/projected_light_cases.py; the images themselves are
compared with Mitsuba's in tests/test_mitsuba_agreement.py (projected_lights.xml). Not
statistical, except where a test says so.
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
from conftest import ROOT
from projected_light_cases import CASES, POINTS

from tracer import load_scene
from tracer.errors import InputError
from tracer.lights import LightSampler
from tracer.lights import emitters as light_emitters
from tracer.scene.toml_writer import write_scene

ASSETS = ROOT / "tracer" / "scenes" / "mitsuba"
SENSOR = ('<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm">'
          '<integer name="width" value="8"/><integer name="height" value="6"/></film></sensor>')
# Mitsuba's sample_direction values at POINTS (benchmarks/mitsuba_reader_facts.py's way: printed
# by a script that loads each case and calls it; RGB, float32).
MITSUBA = {
    "spot_bilinear": [[0.234715, 0.2109967, 0.0788314], [0.2822413, 0.3345271, 0.0894454],
                      [0.1884506, 0.0996981, 0.0650618]] + [[0.0, 0.0, 0.0]] * 7,
    "spot_nearest_png": [[0.0419331, 0.3149719, 0.0252954], [0.0487523, 0.0094897, 0.0146387],
                         [0.2736898, 0.265077, 0.0159391]] + [[0.0, 0.0, 0.0]] * 7,
    "projector_scaled": [[0.0, 0.0, 0.0]] * 3 + [[0.0481492, 0.2583979, 0.0549267],
                                                  [0.2275213, 0.1905155, 0.1258624],
                                                  [0.0233384, 0.1058913, 0.2256457]] + [[0.0, 0.0, 0.0]] * 4,
    "projector_constant_fov_y": [[0.0, 0.0, 0.0]] * 6 + [[0.0586118, 0.1172236, 0.1758354],
                                                         [0.0598319, 0.1196638, 0.1794957]]
    + [[0.0, 0.0, 0.0]] * 2,
    "projector_focal_length": [[0.0, 0.0, 0.0]] * 9 + [[0.1911521, 0.0917697, 0.0690692]],
}


def scene_of(tmp_path, emitter: str):
    path = tmp_path / "lights.xml"
    path.write_text(f'<scene version="3.0.0"><path value="{ASSETS}"/>{SENSOR}{emitter}</scene>')
    return load_scene(path)


@pytest.mark.parametrize("name", CASES)
def test_light_values_are_mitsubas(tmp_path, name):
    """A textured spot (bilinear EXR, nearest sRGB PNG), projectors (a bitmap under a rotation
    with a uniform scale, a constant with fov along y, a focal length): at points in and out of
    each light's image, tracer's light sample carries the value Mitsuba's sample_direction
    returns (float32 rounding; 0 outside the cone or the frustum, and behind a projector). No
    point lies on a texel edge of a nearest lookup, where float32 rounding picks the texel."""
    scene = scene_of(tmp_path, CASES[name])
    x = np.array(POINTS, dtype=np.float64)
    got = LightSampler(scene).sample(np.full(len(x), 0.5), np.full((len(x), 2), 0.5), x).radiance
    np.testing.assert_allclose(got, MITSUBA[name], rtol=2e-5, atol=1e-7)


@pytest.mark.parametrize("name", ["spot_bilinear", "projector_scaled", "projector_constant_fov_y"])
def test_power_is_the_integral_of_the_intensity(tmp_path, name):
    """The power the selection weighs a light by (``emitters.points``) against the integral of
    its intensity over the sphere, by the midpoint rule on 1,000 x 2,000 cells of (cos theta,
    phi) around its axis: a projector's is exact (mean(I) mean(image) times the image's area at
    distance 1), to the quadrature's error (0.5% here, the image's texel edges); a textured
    spot's uses the image's mean over the whole square of which the cone sees the disk, so it
    is only close (within 15%)."""
    scene = scene_of(tmp_path, CASES[name])
    image = scene.point_images[0]
    frame = image.to_local  # rows: the light's axes in world
    n_theta, n_phi = 1000, 2000
    cos_theta = 1.0 - (np.arange(n_theta) + 0.5) / n_theta  # the front hemisphere holds all light
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    c, p = np.meshgrid(cos_theta, phi, indexing="ij")
    s = np.sqrt(1 - c * c)
    local = np.stack([s * np.cos(p), s * np.sin(p), c], axis=-1).reshape(-1, 3)
    x = scene.point_position[0] + local @ frame  # points at distance 1 in each direction
    le = LightSampler(scene).sample(np.full(len(x), 0.5), np.full((len(x), 2), 0.5), x).radiance
    integral = le.mean(axis=1).sum() * (1.0 / n_theta) * (2 * np.pi / n_phi)
    flux = light_emitters.points(scene).flux[0]
    assert flux == pytest.approx(integral, rel=0.005 if image.kind == "projector" else 0.15)


def test_convert_refuses_projected_images(tmp_path):
    """tracer's TOML format has no projected images: convert refuses, naming them, rather than
    writing a plain spot (another image under the same name)."""
    scene = scene_of(tmp_path, CASES["projector_constant_fov_y"])
    with pytest.raises(InputError, match="project images \\(projector\\).*does not hold yet"):
        write_scene(scene, tmp_path / "out.toml", "lights.xml")


@pytest.mark.parametrize("emitter, words", [
    (CASES["spot_bilinear"].replace('value="28"', 'value="95"'), "cutoff_angle must be below 90"),
    (CASES["spot_bilinear"].replace('name="texture"', 'name="irradiance"'), "must be named 'texture'"),
    (CASES["spot_bilinear"].replace('type="bitmap" name="texture"><string name="filename" '
                                    'value="textures/ramp.exr"/>', 'type="checkerboard" name="texture">'),
     "projects a bitmap texture"),
    (CASES["projector_scaled"].replace('<scale value="1.5"/>', '<scale x="1.5"/>'),
     "to_world of a projector"),
    (CASES["projector_scaled"].replace(
        '</texture>', '<transform name="to_uv"><scale value="2"/></transform></texture>'), "to_uv"),
    (CASES["projector_scaled"].replace('value="40"', 'value="190"'), "fov"),
    # Numbers whose light overflows: the scale, to_world's scale, the frustum.
    (CASES["projector_scaled"].replace('value="2.5"', 'value="1e18"'), "exceed 1e+18"),
    (CASES["projector_scaled"].replace('<scale value="1.5"/>', '<scale value="1e200"/>'),
     "to_world of a projector"),
    (CASES["projector_focal_length"].replace('"35mm"', '"1e-300"'), "horizontal field of view"),
    (CASES["spot_bilinear"].replace('value="28"', 'value="1e-300"'), "at least 0.0001 degrees"),
])
def test_refusals_name_the_element(tmp_path, emitter, words):
    with pytest.raises(InputError) as caught:
        scene_of(tmp_path, emitter)
    assert words in str(caught.value) and "\n" not in str(caught.value), str(caught.value)


@pytest.mark.parametrize("texel, words", [(3e38, "intensity x texels exceed 1e+18"),
                                          (-1.0, "negative texels")])
def test_hot_or_negative_images_are_refused(tmp_path, texel, words):
    """An EXR a spot projects with a texel near float32's limit would make an infinite light
    power (and a NaN light choice): refused, as an environment map's is; so is a negative one."""
    path = tmp_path / "hot.exr"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(2, 2, 3, "float"))
    out.write_image(np.full((2, 2, 3), [texel, 0.5, 0.5], dtype=np.float32))
    out.close()
    emitter = CASES["spot_bilinear"].replace("textures/ramp.exr", str(path))
    with pytest.raises(InputError) as caught:
        scene_of(tmp_path, emitter)
    assert words in str(caught.value) and "\n" not in str(caught.value), str(caught.value)
