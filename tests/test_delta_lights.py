"""Spot and directional lights (tracer/lights/techniques/point.py, directional.py): what a light
sample carries, against the formulas of Mitsuba 3's ``spot`` and ``directional`` written out
here, and the flux the ``power`` selection gives them. Agreement with Mitsuba 3 itself is in
tests/test_mitsuba_agreement.py (scene tracer/scenes/mitsuba/delta_lights.xml). Delta lights
are deterministic: these tests compare to rounding, nothing statistical.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from scipy import integrate

import tracer
from tracer.errors import InputError
from tracer.lights import LightSampler
from tracer.lights.emitters import spot_solid_angle

SCENE = """
[camera]
origin = [0.0, 0.0, 5.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40.0
width = 8
height = 8

[materials.white]
type = "diffuse"
reflectance = [0.5, 0.5, 0.5]

[[shapes]]
type = "sphere"
center = [0.0, 0.0, -3.0]
radius = 0.5
material = "white"

[[lights]]
type = "spot"
position = [0.0, 2.0, 0.0]
intensity = [4.0, 2.0, 1.0]
direction = [0.0, -1.0, 0.0]
cutoff_angle = 30.0
beam_width = 10.0

[[lights]]
type = "directional"
direction = [0.0, -1.0, -1.0]
irradiance = [0.5, 1.0, 1.5]
"""


def mitsuba_falloff(theta: np.ndarray, cutoff: float, beam: float) -> np.ndarray:
    """Mitsuba 3's spot falloff (src/emitters/spot.cpp), angles in radians: 1 within the beam
    width, (cutoff - theta) / (cutoff - beam) up to the cutoff, 0 beyond."""
    with np.errstate(divide="ignore", invalid="ignore"):  # no ramp where beam == cutoff
        ramp = (cutoff - theta) / (cutoff - beam)
    return np.where(np.cos(theta) > np.cos(cutoff), np.where(np.cos(theta) >= np.cos(beam), 1.0, ramp), 0.0)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("delta") / "scene.toml"
    path.write_text(SCENE)
    return tracer.load_scene(str(path))


def test_spot_samples_carry_intensity_falloff_over_distance_squared(scene):
    """From points on the floor below the spot at angles across its beam, ramp and beyond, the
    light sample toward the spot carries I falloff(theta) / d^2 and the delta flag; beyond the
    cutoff it carries nothing. The light table holds float32 (cos cutoff, cutoff, 1 / ramp
    width): 2e-6 absolute allows the ramp's rounding near the cutoff (values are about 0.1 to
    1), and the angles avoid the two edges themselves, where float32 decides the side."""
    lights = LightSampler(scene, "power")
    spot = int(np.flatnonzero(lights.owner == -1)[0])
    angle = np.radians(np.linspace(0.25, 39.75, 80))
    x = np.stack([2.0 * np.tan(angle), np.zeros_like(angle), np.zeros_like(angle)], axis=1)
    # A u_select that picks the spot (found by trying a grid).
    u = np.linspace(0.0, 1.0, 4097)[:-1]
    picks = lights.choose(u, np.zeros((len(u), 3)))[0]
    u_spot = u[picks == spot][len(u[picks == spot]) // 2]
    s = lights.sample(np.full(len(x), u_spot), np.zeros((len(x), 2)), x)
    d2 = np.sum((x - [0.0, 2.0, 0.0]) ** 2, axis=1)
    falloff = mitsuba_falloff(angle, np.radians(30.0), np.radians(10.0))
    expected = np.array([4.0, 2.0, 1.0]) * (falloff / d2)[:, None]
    assert np.all(s.delta)
    np.testing.assert_allclose(s.radiance, expected, rtol=1e-5, atol=2e-6)
    np.testing.assert_allclose(s.dist, np.sqrt(d2), rtol=1e-12)


def test_directional_samples_point_at_the_light_at_infinity(scene):
    """A directional light's sample is the direction toward the light, -direction, at distance
    inf (its shadow ray runs to infinity), carrying the irradiance, flagged delta."""
    lights = LightSampler(scene, "power")
    u = np.linspace(0.0, 1.0, 4097)[:-1]
    x = np.zeros((len(u), 3))
    picks = lights.choose(u, x)[0]
    directional = int(np.flatnonzero(lights.owner == -2)[0])
    chosen = picks == directional
    assert chosen.any()
    s = lights.sample(u[chosen], np.zeros((int(chosen.sum()), 2)), x[chosen])
    # float32 rows: to float32 rounding
    np.testing.assert_allclose(s.wi, np.tile([0.0, 1.0, 1.0] / np.sqrt(2.0), (len(s.wi), 1)), rtol=1e-7)
    assert np.all(np.isinf(s.dist)) and np.all(s.delta)
    np.testing.assert_allclose(s.radiance, np.tile([0.5, 1.0, 1.5], (len(s.wi), 1)), rtol=1e-7)


@pytest.mark.parametrize("cutoff, beam", [(20.0, 15.0), (60.0, 0.0), (30.0, 30.0), (10.0, 40.0),
                                          (180.0, 180.0)])
def test_spot_flux_is_the_integral_of_its_falloff(cutoff, beam):
    """The ``power`` selection's flux of a spot is I times the solid-angle integral of its
    falloff: checked against adaptive quadrature of Mitsuba's falloff (a beam wider than the
    cutoff is the cutoff's disk; 180 degrees, every way: 4 pi)."""
    c, b = math.radians(cutoff), math.radians(beam)
    if cutoff >= 180.0:
        expected = 4.0 * math.pi
    else:
        def density(t: float) -> float:
            return 2.0 * math.pi * math.sin(t) * float(mitsuba_falloff(np.array(t), c, min(b, c)))

        expected, _ = integrate.quad(density, 0.0, c, points=[min(b, c)], epsabs=1e-12)
    assert spot_solid_angle(c, b) == pytest.approx(expected, rel=1e-6)


def test_delta_lights_convert_to_toml_and_back(scene, tmp_path):
    """``tracer convert`` writes spot and directional lights, and the TOML reads back as the same
    scene (same digest, so the same cone, axis and irradiance bits)."""
    from tracer.scene.toml_writer import write_scene

    xml = tracer.load_scene("mitsuba/delta_lights")
    write_scene(xml, tmp_path / "back.toml", "delta_lights.xml")
    assert tracer.load_scene(str(tmp_path / "back.toml")).digest == xml.digest
    write_scene(scene, tmp_path / "again.toml", "scene.toml")
    assert tracer.load_scene(str(tmp_path / "again.toml")).digest == scene.digest


@pytest.mark.parametrize("light, message", [
    ('<emitter type="spot"><texture type="checkerboard" name="texture"/></emitter>', "projects a bitmap texture"),
    ('<emitter type="spot"><transform name="to_world"><scale x="2"/></transform></emitter>',
     "distort the cone"),
    ('<emitter type="spot"><float name="cutoff_angle" value="0"/></emitter>', "cutoff_angle"),
    ('<emitter type="directional"><vector name="direction" x="0" y="0" z="0"/></emitter>',
     "direction is zero"),
    ('<emitter type="directional"><vector name="direction" x="0" y="0" z="1"/>'
     '<transform name="to_world"><rotate x="1" angle="10"/></transform></emitter>', "not both"),
])
def test_bad_delta_lights_are_refused(tmp_path, light, message):
    """A broken spot or directional light is refused in one line naming the file."""
    path = tmp_path / "scene.xml"
    path.write_text(textwrap.dedent(f"""
        <scene version="3.0.0">
            <sensor type="perspective"/>
            {light}
        </scene>"""))
    with pytest.raises(InputError, match=message) as caught:
        tracer.load_scene(str(path))
    assert "scene.xml" in str(caught.value) and "\n" not in str(caught.value)
