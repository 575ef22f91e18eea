"""The Mitsuba 3 XML reader (tracer/scene/mitsuba_xml.py, mitsuba_document.py, spectrum.py).

Where Mitsuba decides what a scene means (camera rays, transforms, which side a shape emits
from, spectra, defaults), the expected numbers were measured with Mitsuba 3.9.1's
``scalar_rgb`` variant by benchmarks/mitsuba_reader_facts.py (or, for single defaults, by
loading the scene in the comment and reading it back with ``mi.traverse``); these tests do
not need Mitsuba. Everything else checks the reader's own rules: refusals name the file, the
line and the element in one line.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.errors import InputError
from tracer.materials import TYPES
from tracer.scene import load_scene
from tracer.scene import mitsuba_document as document
from tracer.scene.mesh import angle_weighted_normals
from tracer.scene.mitsuba_xml import DISK_SEGMENTS, unit_rows

DATA = Path(__file__).parent / "data" / "xml"
TENT = DATA / "meshes" / "tent.ply"  # two triangles at a ridge, no normals
SENSOR = ('<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm">'
          '<integer name="width" value="8"/><integer name="height" value="6"/></film></sensor>')
EMIT = '<emitter type="area"><rgb name="radiance" value="1"/></emitter>'


def write(tmp_path: Path, body: str, sensor: bool = True, name: str = "scene.xml") -> Path:
    """A scene file: line 1 <scene>, line 2 the sensor (or nothing), ``body`` from line 3."""
    path = tmp_path / name
    path.write_text(f'<scene version="3.0.0">\n{SENSOR if sensor else ""}\n{body}\n</scene>\n')
    return path


def load(tmp_path: Path, body: str, **options):
    return load_scene(write(tmp_path, body), **options)


def refused(tmp_path: Path, body: str, *words: str, line: int | None = None, sensor: bool = True) -> str:
    """Loading ``body`` raises one line of InputError holding ``words`` (and ``scene.xml:LINE:``)."""
    with pytest.raises(InputError) as caught:
        load_scene(write(tmp_path, body, sensor))
    message = str(caught.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message
    if line is not None:
        assert f"scene.xml:{line}:" in message, message
    return message


def material(scene, shape: int = 0) -> tuple[str, dict, bool]:
    """(type name, parameters by name, twosided) of a shape's material, read back from the table."""
    table = scene.materials
    row = scene.shapes[shape].material
    kind = next(t for t in TYPES.values() if t.code == table.kind[row])
    values = {}
    for p in kind.params:
        column = kind.column(p.name)
        v = table.params[row, column: column + p.size]
        values[p.name] = (p.choices[int(v[0])] if p.choices else bool(v[0]) if p.boolean
                          else float(v[0]) if p.size == 1 else v.copy())
    return kind.name, values, bool(table.twosided[row])

# Ray directions of Mitsuba 3.9.1's perspective sensor (scalar_rgb, sensor.sample_ray) at the film
# positions FILM_POSITIONS, for each camera of CAMERA_CASES; printed by
# benchmarks/mitsuba_reader_facts.py.
MITSUBA_RAYS = {
    'fov_x': [
        (-0.1840662, -0.3451241, -0.9203309),
        (-0.5117462, -0.1768287, -0.8407422),
        (0.1705191, -0.4258396, -0.8885853),
    ],
    'fov_x_tall': [
        (-0.1840662, -0.345124, -0.920331),
        (-0.4680956, 0.122643, -0.8751258),
        (0.1636571, -0.6078982, -0.776966),
    ],
    'fov_y': [
        (-0.1840663, -0.345124, -0.9203309),
        (-0.7176869, -0.0278174, -0.6958101),
        (0.4355433, -0.449734, -0.7797701),
    ],
    'fov_diagonal': [
        (-0.1840662, -0.3451241, -0.9203309),
        (-0.4824266, -0.1946942, -0.854025),
        (0.1361444, -0.4203406, -0.8970945),
    ],
    'fov_smaller': [
        (-0.1840662, -0.345124, -0.920331),
        (-0.4680956, 0.122643, -0.8751258),
        (0.1636571, -0.6078982, -0.776966),
    ],
    'fov_larger': [
        (-0.1840662, -0.345124, -0.9203309),
        (-0.3686791, -0.0658474, -0.9272216),
        (0.0215255, -0.5133139, -0.8579309),
    ],
    'focal_35mm': [
        (-0.1840662, -0.3451241, -0.9203309),
        (-0.559643, -0.1461414, -0.8157466),
        (0.2281598, -0.4338952, -0.8715952),
    ],
    'default_50mm': [
        (-0.1840662, -0.3451241, -0.9203309),
        (-0.4349596, -0.1730919, -0.8836568),
        (0.0845826, -0.441127, -0.89345),
    ],
    'rotations': [
        (0.5, 0.2961981, 0.8137977),
        (0.7134073, 0.3796852, 0.588973),
        (0.2366551, 0.2324078, 0.943388),
    ],
    'matrix16': [
        (0.5, 0.0, 0.8660254),
        (0.7134073, 0.1553468, 0.6833136),
        (0.2366551, -0.1042658, 0.9659829),
    ],
    'mirrored_camera': [
        (-0.1840661, -0.3451241, -0.9203309),
        (0.1322369, -0.1791973, -0.9748855),
        (-0.48046, -0.4151263, -0.7725466),
    ],
    'mirrored_world': [
        (-0.1840662, -0.3451241, 0.9203309),
        (-0.4766578, -0.1397015, 0.8679175),
        (0.1336346, -0.4549595, 0.8804281),
    ],
    'lookat_without_up': [
        (0.2822163, 0.1881441, 0.9407209),
        (0.4892969, -0.1330222, 0.8619127),
        (0.1071473, 0.4857396, 0.8675117),
    ],
}

# to_world matrices (top three rows) Mitsuba 3.9.1 builds from these operations (mi.traverse).
MITSUBA_TRANSFORMS = {
    '<translate x="1"/><scale value="2"/>':
        [[2.0, 0.0, 0.0, 2.0], [0.0, 2.0, 0.0, 0.0], [0.0, 0.0, 2.0, 0.0]],
    '<scale value="2"/><translate x="1"/>':
        [[2.0, 0.0, 0.0, 1.0], [0.0, 2.0, 0.0, 0.0], [0.0, 0.0, 2.0, 0.0]],
    '<rotate z="1" angle="90"/>':
        [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
    '<rotate x="1" angle="90"/><translate y="3"/>':
        [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 3.0], [0.0, 1.0, 0.0, 0.0]],
    '<rotate x="1" y="1" angle="30"/>':
        [[1.0, 0.133975, 0.5, 0.0], [0.133975, 1.0, -0.5, 0.0], [-0.5, 0.5, 0.866025, 0.0]],
    '<matrix value="1 2 3 4 5 6 7 8 9 10 11 12 0 0 0 1"/>':
        [[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0], [9.0, 10.0, 11.0, 12.0]],
    '<matrix value="1 2 3 4 5 6 7 8 9"/>':
        [[1.0, 2.0, 3.0, 0.0], [4.0, 5.0, 6.0, 0.0], [7.0, 8.0, 9.0, 0.0]],
    '<scale x="2" y="3"/>':
        [[2.0, 0.0, 0.0, 0.0], [0.0, 3.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
    '<translate value="1 2 3"/>':
        [[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 2.0], [0.0, 0.0, 1.0, 3.0]],
    '<translate value="2"/>':
        [[1.0, 0.0, 0.0, 2.0], [0.0, 1.0, 0.0, 2.0], [0.0, 0.0, 1.0, 2.0]],
    '<lookat origin="0, 0, 0" target="1, 0, 0" up="0, 0, 1"/>':
        [[0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]],
    '<lookat origin="0, 0, 0" target="0, 0, 1"/>':
        [[0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
    '<lookat origin="1, 2, 3" target="1, 2.5, 3.2"/>':
        [[0.0, 1.0, 0.0, 1.0], [-0.371391, 0.0, 0.928477, 2.0], [0.928477, 0.0, 0.371391, 3.0]],
}

# Linear sRGB Mitsuba 3.9.1 makes of <spectrum value=...> as a diffuse reflectance, a conductor's
# eta and a point emitter's intensity (mi.traverse; out-of-gamut channels clamped as it clamps them),
# rounded to 6 decimals: measured with Mitsuba by benchmarks/mitsuba_reader_facts.py's spectra(), the
# last three entries too (that function run with them added to its SPECTRA).
MITSUBA_SPECTRA = {
    '0.5': {
        'reflectance': (0.5, 0.5, 0.5),
        'eta': (0.5, 0.5, 0.5),
        'emitter': (0.602397, 0.474146, 0.454458),
    },
    '2': {
        'reflectance': (2.0, 2.0, 2.0),
        'eta': (2.0, 2.0, 2.0),
        'emitter': (2.409588, 1.896582, 1.817832),
    },
    '400:0.5, 700:0.5': {
        'reflectance': (0.497671, 0.499878, 0.497455),
        'eta': (0.497671, 0.499878, 0.497455),
        'emitter': (0.599847, 0.47476, 0.451722),
    },
    '360:1, 830:1': {
        'reflectance': (0.998985, 0.998874, 0.998802),
        'eta': (0.998985, 0.998874, 0.998802),
        'emitter': (1.204884, 0.948228, 0.909267),
    },
    '450:0.2, 550:0.8, 650:0.3': {
        'reflectance': (0.417042, 0.726045, 0.113149),
        'eta': (0.417042, 0.726045, 0.113149),
        'emitter': (0.506507, 0.696452, 0.087186),
    },
    '500:1, 600:0': {
        'reflectance': (0.0, 0.579277, 0.0),
        'eta': (0.0, 0.579277, 0.0),
        'emitter': (0.0, 0.548331, 0.0),
    },
    '400:2, 700:2': {
        'reflectance': (1.0, 1.0, 1.0),
        'eta': (1.990684, 1.999513, 1.989818),
        'emitter': (2.399387, 1.899041, 1.806887),
    },
    '400:2, 500:6, 600:9, 700:4': {
        'reflectance': (1.0, 1.0, 1.0),
        'eta': (8.517208, 7.45245, 3.711974),
        'emitter': (10.038166, 7.132708, 3.266685),
    },
    '400:0.1, 500:0.5, 600:0.8, 700:0.3': {
        'reflectance': (0.752187, 0.645269, 0.271706),
        'eta': (0.752187, 0.645269, 0.271706),
        'emitter': (0.883847, 0.618319, 0.236324),
    },
    '380:0.9, 480:0.05, 780:0.6': {
        'reflectance': (0.378091, 0.131942, 0.296347),
        'eta': (0.378091, 0.131942, 0.296347),
        'emitter': (0.43477, 0.124662, 0.283906),
    },
}

# The side each shape emits from in Mitsuba 3.9.1 (+1: +z, -1: -z; the cube: +1 outward, -1 inward).
MITSUBA_FRONTS = {
    'rectangle': 1,
    'rectangle mirrored': 1,
    'rectangle flipped': -1,
    'rectangle mirrored flipped': -1,
    'disk mirrored': 1,
    'cube mirrored': 1,
    'cube mirrored flipped': -1,
    'obj with normals, mirrored': 1,
    'obj with normals, mirrored, flipped': -1,
    'obj with normals, mirrored, face_normals': -1,
    'obj without normals, mirrored': -1,
}


# ---------------------------------------------------------------------------------------------
# The camera


LOOKAT = '<lookat origin="1, 2, 3" target="0.2, 0.5, -1" up="0.1, 1, 0.2"/>'
def _fov(degrees: float, axis: str | None = None) -> str:
    axis_property = f'<string name="fov_axis" value="{axis}"/>' if axis else ""
    return f'<float name="fov" value="{degrees}"/>{axis_property}'

# name: (sensor properties, to_world operations, film width, height), as in
# benchmarks/mitsuba_reader_facts.py
CAMERA_CASES = {
    "fov_x": (_fov(50), LOOKAT, 200, 100),
    "fov_x_tall": (_fov(50, "x"), LOOKAT, 90, 160),
    "fov_y": (_fov(50, "y"), LOOKAT, 200, 100),
    "fov_diagonal": (_fov(50, "diagonal"), LOOKAT, 200, 100),
    "fov_smaller": (_fov(50, "smaller"), LOOKAT, 90, 160),
    "fov_larger": (_fov(50, "larger"), LOOKAT, 90, 160),
    "focal_35mm": ('<string name="focal_length" value="35mm"/>', LOOKAT, 200, 100),
    "default_50mm": ("", LOOKAT, 120, 90),
    "rotations": (_fov(40), '<rotate y="1" angle="30"/><rotate x="1" angle="-20"/>'
                            '<translate x="0.5" y="1" z="4"/>', 160, 120),
    "matrix16": (_fov(40), '<matrix value="0.8660254 0 0.5 1  0 1 0 2  -0.5 0 0.8660254 3  0 0 0 1"/>',
                 160, 120),
    "mirrored_camera": (_fov(45), '<scale x="-1"/>' + LOOKAT, 160, 120),
    "mirrored_world": (_fov(45), LOOKAT + '<scale z="-1"/>', 160, 120),
    "lookat_without_up": (_fov(45), '<lookat origin="0, 0, 0" target="0.3, 0.2, 1"/>', 100, 100),
}
FILM_POSITIONS = [(0.5, 0.5), (0.1, 0.2), (0.9, 0.7)]


def camera_file(tmp_path: Path, name: str) -> Path:
    props, ops, w, h = CAMERA_CASES[name]
    return write(tmp_path, f'<sensor type="perspective">{props}<transform name="to_world">{ops}</transform>'
                           f'<film type="hdrfilm"><integer name="width" value="{w}"/>'
                           f'<integer name="height" value="{h}"/></film></sensor>', sensor=False)


def rays_at(camera, positions) -> np.ndarray:
    """tracer's camera ray directions through film positions (u, v) in [0, 1]^2 (v down)."""
    w, h = camera.width, camera.height
    pixel, jitter = [], []
    for u, v in positions:
        x, y = u * w, v * h
        pixel.append(int(y) * w + int(x))
        jitter.append((x - int(x), y - int(y)))
    return camera.rays(np.array(pixel), np.array(jitter))[1]


@pytest.mark.parametrize("name", CAMERA_CASES)
def test_camera_rays_are_mitsubas(tmp_path, name):
    """Every fov_axis on a wide and a tall film, focal_length, Mitsuba's default (50 mm), look-at
    with and without up, rotations, a 4x4 matrix, and mirrors (det < 0: the camera's own x
    axis, or the world's z): tracer's rays go where Mitsuba's do (float32 precision)."""
    camera = load_scene(camera_file(tmp_path, name)).camera
    np.testing.assert_allclose(rays_at(camera, FILM_POSITIONS), MITSUBA_RAYS[name], atol=1e-6)
    assert camera.mirrored == name.startswith("mirrored")


def test_resolution_overrides_keep_mitsubas_field_of_view(tmp_path):
    """width/height overrides: one side keeps the film's aspect ratio (as for TOML); both give
    the film Mitsuba would render at that size, fov still along fov_axis (x: 50 degrees)."""
    path = camera_file(tmp_path, "fov_x")  # 200 x 100, 50 degrees along x
    one = load_scene(path, width=100).camera
    assert (one.width, one.height) == (100, 50) and one.fov == pytest.approx(load_scene(path).camera.fov)
    both = load_scene(path, width=64, height=64).camera
    assert (both.width, both.height) == (64, 64) and both.fov == pytest.approx(50.0)
    assert load_scene(path, height=10).camera.width == 20
    assert tracer.load_scene(str(path), 30, 20).camera.fov == pytest.approx(
        math.degrees(2 * math.atan(math.tan(math.radians(25)) * 20 / 30)))


def test_film_and_sampler_defaults_and_spp(tmp_path):
    """Mitsuba's film is 768 x 576 unless given (mi.load_string of a bare perspective sensor:
    film().size() = [768, 576]); the sampler's sample_count is the scene's spp (none given:
    tracer's own default, not Mitsuba's 4)."""
    scene = load_scene(write(tmp_path, '<sensor type="perspective"/>', sensor=False))
    assert (scene.camera.width, scene.camera.height) == (768, 576) and scene.render_defaults == {}
    path = write(tmp_path, '<sensor type="perspective"><sampler type="independent">'
                           '<integer name="sample_count" value="12"/></sampler></sensor>', sensor=False)
    assert load_scene(path).render_defaults == {"spp": 12}


@pytest.mark.parametrize("sensor, words", [
    ('<sensor type="radiancemeter"/>', ["sensor 'radiancemeter' is not supported", "thinlens and orthographic"]),
    ('<sensor type="perspective"><float name="fov" value="40"/><string name="focal_length" value="20mm"/>'
     '</sensor>', ["fov or focal_length"]),
    # Mitsuba: "Found 1 unreferenced property ... string fov_axis" with a focal length
    ('<sensor type="perspective"><string name="focal_length" value="20mm"/><string name="fov_axis" '
     'value="y"/></sensor>', ["no property 'fov_axis'"]),
    ('<sensor type="perspective"><float name="fov" value="40"/><string name="fov_axis" value="z"/></sensor>',
     ["fov_axis"]),
    ('<sensor type="perspective"><float name="fov" value="180"/></sensor>', ["fov"]),
    ('<sensor type="perspective"><float name="fov" value="175"/><string name="fov_axis" value="x"/>'
     '<film type="hdrfilm"><integer name="width" value="10"/><integer name="height" value="100"/></film>'
     '</sensor>', ["179"]),
    ('<sensor type="perspective"><transform name="to_world"><scale value="2"/></transform></sensor>',
     ["scales or shears"]),
    ('<sensor type="perspective"><float name="principal_point_offset_x" value="0.1"/></sensor>',
     ["principal point"]),
    ('<sensor type="perspective"><film type="hdrfilm"><integer name="crop_width" value="4"/></film></sensor>',
     ["crop window"]),
    ('<sensor type="perspective"><film type="specfilm"/></sensor>', ["film 'specfilm'"]),
    ('<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="100000"/></film></sensor>',
     ["width"]),
    ('<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="30000"/>'
     '<integer name="height" value="30000"/></film></sensor>', ["resolution 30000x30000"]),
])
def test_sensor_refusals(tmp_path, sensor, words):
    refused(tmp_path, sensor, *words, line=3, sensor=False)


def test_focus_distance_and_banner_are_read_and_ignored(tmp_path):
    """Mitsuba 3.9.1 reads a perspective sensor's focus_distance (every projective camera has
    one; a pinhole's image does not depend on it) and an hdrfilm's banner (of any type: it marks
    it read and writes none), so both load without a note; aperture_radius is the thin lens's,
    which Mitsuba's perspective sensor leaves unread, and refuses."""
    notes = []
    path = write(tmp_path, '<sensor type="perspective"><float name="focus_distance" value="1000"/>'
                           '<film type="hdrfilm"><boolean name="banner" value="false"/>'
                           '<integer name="width" value="8"/><integer name="height" value="6"/></film>'
                           '</sensor>', sensor=False)
    scene = load_scene(path, notify=notes.append)
    assert (scene.camera.width, scene.camera.height) == (8, 6) and notes == []
    refused(tmp_path, '<sensor type="perspective"><float name="aperture_radius" value="0.1"/></sensor>',
            "no property 'aperture_radius'", line=3, sensor=False)


def test_camera_matrices_rigid_to_printed_precision_are_mitsubas(tmp_path):
    """A look-at written as a 16-number matrix to 6 or 5 significant digits (an entry of
    M M^T - I about 1e-6 or 1.3e-5; the survey of public scenes found such cameras refused)
    loads, and its rays are Mitsuba's (M times the camera-space direction) to within that; a
    scale is refused where Mitsuba refuses it (an entry of M M^T - I beyond 1e-3:
    Transform::has_scale, in the perspective sensor's constructor), and not before."""
    origin, target = np.array([278.0, 273.0, -800.0]), np.array([268.0, 263.0, -799.0])
    forward = (target - origin) / np.linalg.norm(target - origin)
    left = np.cross([0.0, 1.0, 0.0], forward)
    left /= np.linalg.norm(left)
    exact = np.eye(4)
    exact[:3, :3] = np.stack([left, np.cross(forward, left), forward], axis=1)
    exact[:3, 3] = origin

    def sensor(matrix: np.ndarray, digits: int) -> str:
        value = " ".join(f"{v:.{digits}g}" for v in matrix.ravel())
        return (f'<sensor type="perspective"><float name="fov" value="40"/><transform name="to_world">'
                f'<matrix value="{value}"/></transform></sensor>')

    for digits, deviation in [(6, 1e-6), (5, 1e-5)]:
        written = np.array([float(f"{v:.{digits}g}") for v in exact.ravel()]).reshape(4, 4)
        assert np.max(np.abs(written[:3, :3] @ written[:3, :3].T - np.eye(3))) > deviation
        camera = load_scene(write(tmp_path, sensor(written, digits), sensor=False)).camera
        f, r, u = camera.basis
        tan_half, aspect = math.tan(math.radians(camera.fov) / 2), camera.width / camera.height
        for sx, sy in [(0.0, 0.0), (1.0, 1.0), (-1.0, 0.5)]:  # film positions, -1 to 1 across
            local = np.array([-sx * tan_half * aspect, sy * tan_half, 1.0])  # Mitsuba's +x: the left
            mitsuba = written[:3, :3] @ (local / np.linalg.norm(local))
            ours = f + sx * tan_half * aspect * r + sy * tan_half * u
            np.testing.assert_allclose(ours / np.linalg.norm(ours), mitsuba / np.linalg.norm(mitsuba),
                                       atol=3 * deviation)
    for scale, kept in [(1.0004, True), (1.0006, False)]:  # M M^T - I: 8e-4 and 1.2e-3 on the diagonal
        scaled = exact.copy()
        scaled[:3, :3] *= scale
        if kept:
            load_scene(write(tmp_path, sensor(scaled, 9), sensor=False))
        else:
            refused(tmp_path, sensor(scaled, 9), "scales or shears", line=3, sensor=False)


def test_no_sensor_is_refused(tmp_path):
    refused(tmp_path, '<shape type="cube"/>', "no <sensor>", sensor=False)


def test_what_tracer_does_not_obey_is_one_line_per_load(tmp_path):
    """The integrator, a non-box filter, the film's pixel format, clipping planes and the
    sampler type are read and told once per load, in one line, to notify; API users without
    notify hear nothing."""
    path = write(tmp_path, '<integrator type="path"><integer name="max_depth" value="3"/></integrator>\n'
                           '<sensor type="perspective"><float name="near_clip" value="0.1"/>'
                           '<float name="far_clip" value="100"/><sampler type="stratified">'
                           '<integer name="sample_count" value="4"/></sampler><film type="hdrfilm">'
                           '<string name="pixel_format" value="rgba"/><rfilter type="gaussian">'
                           '<float name="stddev" value="0.3"/></rfilter></film></sensor>', sensor=False)
    lines: list[str] = []
    load_scene(path, notify=lines.append)
    assert len(lines) == 1 and "\n" not in lines[0]
    for word in ('<integrator type="path">', '<rfilter type="gaussian">', 'pixel_format "rgba"',
                 "near_clip 0.1", "far_clip 100", '<sampler type="stratified">', "box filter"):
        assert word in lines[0], lines[0]
    plain = write(tmp_path, '<shape type="cube"/>', name="plain.xml")
    load_scene(plain, notify=lines.append)
    assert len(lines) == 1  # nothing to tell: no line
    load_scene(path)  # no notify: nothing printed, nothing raised


def test_the_command_line_prints_the_note_once(tmp_path):
    path = write(tmp_path, '<integrator type="path"/>\n<shape type="rectangle">' + EMIT + "</shape>")
    argv = [sys.executable, "-m", "tracer", "convert", str(path), "-o", str(tmp_path / "s.toml")]
    run = subprocess.run(argv, capture_output=True, text=True)
    notes = [line for line in run.stderr.splitlines() if line.startswith("tracer: note:")]
    assert run.returncode == 0 and len(notes) == 1 and '<integrator type="path">' in notes[0], run.stderr


# ---------------------------------------------------------------------------------------------
# Transforms


def matrix_of(tmp_path: Path, ops: str) -> np.ndarray:
    path = write(tmp_path, f'<shape type="rectangle"><transform name="to_world">{ops}</transform></shape>')
    doc = document.read_document(str(path))
    shape = next(e for e in doc.root.children if e.tag == "shape")
    return document.transform_matrix(shape.children[0])


@pytest.mark.parametrize("ops", MITSUBA_TRANSFORMS)
def test_transforms_are_mitsubas(tmp_path, ops):
    """Composition in document order (each operation left-multiplied), Rodrigues rotations with
    the axis as given (Mitsuba does not normalize it), 9- and 16-number matrices (row major), a
    one-number translate, look-at with and without up (Duff et al.'s basis)."""
    np.testing.assert_allclose(matrix_of(tmp_path, ops)[:3], MITSUBA_TRANSFORMS[ops], atol=2e-6)


@pytest.mark.parametrize("ops, words", [
    ('<rotate angle="30"/>', ["rotation axis is zero"]),
    ('<rotate x="1"/>', ["missing attribute 'angle'"]),
    ('<translate x="1" value="1, 2, 3"/>', ["either value or x, y, z"]),
    ('<scale value="2, 3"/>', ["1 or 3 numbers"]),
    ('<matrix value="1 0 0 0 1 0 0 0 1 0 0 0"/>', ["9 or 16 numbers"]),
    ('<matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 2"/>', ["projective"]),
    ('<lookat origin="0, 0, 0" target="0, 1, 0" up="0, 1, 0"/>', ["parallel"]),
    ('<lookat origin="1, 1, 1" target="1, 1, 1"/>', ["target equals origin"]),
    ('<translate x="1" foo="2"/>', ["unexpected attribute 'foo'"]),
    ('<shear x="1"/>', ["unknown element"]),
    ('<scale value="0"/>', ["singular"]),
    ('<scale value="1e300"/><scale value="1e300"/>', ["not finite"]),
])
def test_transform_refusals(tmp_path, ops, words):
    refused(tmp_path, f'<shape type="rectangle">\n<transform name="to_world">{ops}</transform></shape>',
            *words)


# ---------------------------------------------------------------------------------------------
# Shapes


def front_z(scene, shape: int = 0) -> int:
    """+1 / -1: the z sign of the face normal (tracer's front side) of every triangle of a shape."""
    s = scene.shapes[shape]
    signs = np.sign(scene.normal[s.first: s.first + s.count, 2])
    assert np.all(signs == signs[0])
    return int(signs[0])


MIRROR = '<transform name="to_world"><scale x="-1"/></transform>'
FLIP = '<boolean name="flip_normals" value="true"/>'


@pytest.mark.parametrize("name, extra", [("rectangle", ""), ("rectangle mirrored", MIRROR),
                                         ("rectangle flipped", FLIP),
                                         ("rectangle mirrored flipped", MIRROR + FLIP)])
def test_rectangle_faces_where_mitsubas_emits(tmp_path, name, extra):
    """A rectangle is tracer's quad [-1, 1]^2 at z = 0, its e1 x e2 along Mitsuba's normal (the
    to_world normal transform of +z, flipped by flip_normals): against the edges' cross product
    when the transform mirrors, so the edges are swapped then."""
    scene = load(tmp_path, f'<shape type="rectangle">{extra}{EMIT}</shape>')
    shape = scene.shapes[0]
    assert shape.type == "quad" and shape.count == 2
    assert front_z(scene) == MITSUBA_FRONTS[name]
    corners = {tuple(v) for v in scene.vertices[scene.faces[:2].ravel()]}
    assert corners == {(x, y, 0.0) for x in (-1.0, 1.0) for y in (-1.0, 1.0)}
    r = shape.record
    assert np.dot(np.cross(r["edge1"], r["edge2"]), [0, 0, 1]) == 4.0 * MITSUBA_FRONTS[name]


def test_rectangle_placed_by_a_transform(tmp_path):
    scene = load(tmp_path, '<shape type="rectangle"><transform name="to_world"><scale x="2" y="0.5"/>'
                           '<rotate x="1" angle="-90"/><translate y="1"/></transform></shape>')
    r = scene.shapes[0].record
    np.testing.assert_allclose(r["origin"], [-2, 1, 0.5], atol=1e-15)
    np.testing.assert_allclose(np.cross(r["edge1"], r["edge2"]) / 4.0, [0, 1, 0], atol=1e-15)
    assert scene.area.sum() == pytest.approx(4.0)


@pytest.mark.parametrize("name, extra", [("cube mirrored", MIRROR), ("cube mirrored flipped", MIRROR + FLIP)])
def test_cube_faces_outward_unless_flipped(tmp_path, name, extra):
    """[-1, 1]^3 as 12 flat triangles facing out (Mitsuba keeps them out through a mirror, turns
    them in with flip_normals)."""
    scene = load(tmp_path, f'<shape type="cube">{extra}{EMIT}</shape>')
    assert scene.shapes[0].type == "mesh" and len(scene.faces) == 12 and len(scene.corner_normals) == 0
    centroids = scene.vertices[scene.faces].mean(axis=1)
    outward = np.einsum("ij,ij->i", scene.normal, centroids)
    assert np.all(np.sign(outward) == MITSUBA_FRONTS[name])
    assert scene.area.sum() == pytest.approx(24.0)


def test_disk_is_a_fan_within_a_ten_thousandth_of_its_area(tmp_path):
    scene = load(tmp_path, '<shape type="disk"><transform name="to_world"><scale x="-2" y="0.5"/>'
                           f'<translate z="1"/></transform>{EMIT}</shape>')
    assert len(scene.faces) == DISK_SEGMENTS and front_z(scene) == MITSUBA_FRONTS["disk mirrored"]
    assert abs(scene.area.sum() / (math.pi * 2 * 0.5) - 1.0) < 1e-4
    assert np.allclose(scene.vertices[:, 2], 1.0)


@pytest.mark.parametrize("flip", [False, True])
def test_cylinder_is_a_tube_of_quads_facing_out_with_radial_normals(tmp_path, flip):
    """Mitsuba's cylinder: radius 0.5 from p0 to p1 (here along x, then moved by to_world) as
    CYLINDER_SEGMENTS quads whose corners lie on the tube, whose faces and vertex normals point
    away from the axis (toward it with flip_normals); its area within 1e-4 of 2π r L; its
    corners' (u, v) are (φ / 2π, z) in the tube's frame, Mitsuba's to_frame of the axis (s, t,
    n = x here), the seam's corners at u = 1 on the quads that end there."""
    from tracer.scene.mitsuba_xml import CYLINDER_SEGMENTS, _axis_frame

    extra = '<boolean name="flip_normals" value="true"/>' if flip else ""
    scene = load(tmp_path, '<shape type="cylinder"><float name="radius" value="0.5"/>'
                           '<point name="p0" value="0, 0, 0"/><point name="p1" value="2, 0, 0"/>'
                           f'<transform name="to_world"><translate y="1"/></transform>{extra}'
                           '<bsdf type="diffuse"><texture name="reflectance" type="checkerboard"/></bsdf>'
                           '</shape>')
    assert len(scene.faces) == 2 * CYLINDER_SEGMENTS
    corners = scene.vertices[scene.faces].reshape(-1, 3) - [0.0, 1.0, 0.0]
    uv = scene.corner_uv.reshape(-1, 2)
    s_axis, t_axis, _ = _axis_frame(np.array([1.0, 0.0, 0.0])).T
    phi = np.arctan2(corners @ t_axis, corners @ s_axis) % (2 * math.pi)
    np.testing.assert_allclose(uv[:, 1], corners[:, 0] / 2.0, atol=1e-6)
    seam = np.isclose(uv[:, 0], 1.0)
    np.testing.assert_allclose(uv[~seam, 0], phi[~seam] / (2 * math.pi), atol=1e-6)
    assert np.all(phi[seam] < 1e-6) or np.all(phi[seam] > 2 * math.pi - 1e-6)
    radial = scene.vertices - [0.0, 1.0, 0.0]
    radial[:, 0] = 0.0
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), 0.5, rtol=1e-6)
    assert np.allclose(scene.vertices[:, 0].min(), 0.0) and np.allclose(scene.vertices[:, 0].max(), 2.0)
    centre = scene.v0 + (scene.edge1 + scene.edge2) / 3.0
    outward = centre - [0.0, 1.0, 0.0]
    outward[:, 0] = 0.0
    sign = -1.0 if flip else 1.0
    assert np.all(sign * np.einsum("ij,ij->i", scene.normal, outward) > 0.0)
    corner_normals = scene.corner_normals.reshape(-1, 3, 3)
    corner_radial = (scene.vertices[scene.faces] - [0.0, 1.0, 0.0]) * [0.0, 2.0, 2.0]
    np.testing.assert_allclose(corner_normals, sign * corner_radial, atol=1e-6)
    assert abs(scene.area.sum() / (2 * math.pi * 0.5 * 2.0) - 1.0) < 1e-4


def test_instances_copy_their_group_under_their_transform(tmp_path):
    """Each instance adds its shapegroup's shapes under the instance's to_world after each
    shape's own (Mitsuba's instance): a cube and a sphere, twice; the group alone adds nothing."""
    group = ('<shape type="shapegroup" id="g"><shape type="cube"><transform name="to_world">'
             '<translate x="1"/></transform></shape><shape type="sphere"><float name="radius" value="0.5"/>'
             '</shape></shape>')
    alone = load(tmp_path, group + f'<shape type="rectangle">{EMIT}</shape>')
    assert len(alone.shapes) == 1
    scene = load(tmp_path, group + '<shape type="instance"><ref id="g"/></shape>'
                 '<shape type="instance"><ref id="g"/><transform name="to_world"><scale value="2"/>'
                 f'<translate z="5"/></transform></shape><shape type="rectangle">{EMIT}</shape>')
    assert [s.type for s in scene.shapes] == ["mesh", "sphere", "mesh", "sphere", "quad"]
    first, second = (scene.vertices[scene.faces[s.first:s.first + s.count]].reshape(-1, 3)
                     for s in (scene.shapes[0], scene.shapes[2]))
    np.testing.assert_allclose(second, 2.0 * first + [0.0, 0.0, 5.0], atol=1e-5)
    np.testing.assert_allclose(scene.spheres, [[0, 0, 0, 0.5], [0, 0, 5, 1.0]])
    assert scene.material[scene.shapes[0].first] == scene.material[scene.shapes[2].first]


def test_sphere_center_radius_and_to_world(tmp_path):
    """Mitsuba's sphere is to_world x translate(center) x scale(radius): center (1, 0, 0),
    radius 2 under scale 3 is centre (3, 0, 0), radius 6 (mi.traverse: to_world [[6, 0, 0, 3],
    ...]); an analytic sphere in tracer."""
    scene = load(tmp_path, '<shape type="sphere"><point name="center" value="1, 0, 0"/>'
                           '<float name="radius" value="2"/><transform name="to_world">'
                           f'<rotate y="1" angle="90"/><scale value="3"/></transform>{EMIT}</shape>')
    assert scene.shapes[0].type == "sphere" and len(scene.faces) == 0
    np.testing.assert_allclose(scene.spheres[0], [0, 0, -3, 6], atol=1e-6)
    assert load(tmp_path, "<shape type=\"sphere\"/>").spheres.tolist() == [[0, 0, 0, 1]]


@pytest.mark.parametrize("extra, words", [
    ('<transform name="to_world"><scale x="1" y="2" z="1"/></transform>', ["scales unevenly"]),
    (FLIP, ["inward-facing sphere"]),
    # Mitsuba 3.9.1 turns a sphere under <scale x="-1"/> inside out (its normals point inward)
    (MIRROR, ["inward-facing sphere"]),
    ('<float name="radius" value="0"/>', ["radius"]),
    ('<point name="center" value="1e16, 0, 0"/>', ["coordinate range"]),
])
def test_sphere_refusals(tmp_path, extra, words):
    refused(tmp_path, f'<shape type="sphere">\n{extra}</shape>', *words)


def obj_scene(tmp_path: Path, extra: str, file: str = "tri_normals.obj"):
    return load(tmp_path, f'<shape type="obj"><string name="filename" value="{DATA / "meshes" / file}"/>'
                          f'{extra}{EMIT}</shape>')


@pytest.mark.parametrize("name, extra, smooth", [
    ("obj with normals, mirrored", MIRROR, True),
    ("obj with normals, mirrored, flipped", MIRROR + FLIP, True),
    ("obj with normals, mirrored, face_normals", MIRROR + '<boolean name="face_normals" value="true"/>',
     False),
])
def test_mesh_front_is_mitsubas_shading_side(tmp_path, name, extra, smooth):
    """Mitsuba emits (and reflects, one-sidedly) on the side of the shading normal: with the
    file's normals under a mirror that is against the transformed winding, which tracer then
    turns; with face_normals it is the geometric side."""
    scene = obj_scene(tmp_path, extra)
    assert front_z(scene) == MITSUBA_FRONTS[name]
    assert bool(len(scene.corner_normals)) == smooth
    if smooth:  # the shading normals are on the front side too
        assert np.all(np.sign(scene.corner_normals[0].reshape(3, 3)[:, 2]) == MITSUBA_FRONTS[name])


def test_mesh_without_normals_under_a_mirror(tmp_path):
    tri = tmp_path / "plain.obj"
    tri.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = load(tmp_path, f'<shape type="obj"><string name="filename" value="{tri}"/>{MIRROR}{EMIT}</shape>')
    assert front_z(scene) == MITSUBA_FRONTS["obj without normals, mirrored"]


def test_file_normals_transform_by_the_inverse_transpose(tmp_path):
    """Vertex normals n become L^-T n, normalized (and negated by flip_normals)."""
    scale = np.array([2.0, 1.0, 0.5])
    scene = obj_scene(tmp_path, f'<transform name="to_world"><scale value="{scale[0]}, {scale[1]}, '
                                f'{scale[2]}"/></transform>')
    file_normals = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8]])
    expected = file_normals / scale
    expected /= np.linalg.norm(expected, axis=1)[:, None]
    np.testing.assert_allclose(scene.corner_normals[0].reshape(3, 3), expected, atol=1e-15)
    flipped = obj_scene(tmp_path, FLIP)
    np.testing.assert_allclose(flipped.corner_normals[0].reshape(3, 3), -file_normals[[2, 1, 0]], atol=1e-15)
    assert flipped.faces.tolist() == [[2, 1, 0]]


def test_smooth_normals_are_computed_after_the_transform(tmp_path):
    """A mesh without normals is smooth unless face_normals: Mitsuba's angle-weighted normals
    of the transformed mesh (a shear changes the angles, so before would differ)."""
    ops = '<transform name="to_world"><matrix value="1 0.8 0  0 1 0  0 0 1"/></transform>'
    scene = load(tmp_path, f'<shape type="ply"><string name="filename" value="{TENT}"/>{ops}</shape>')
    vertices = scene.vertices[: 4]
    expected = angle_weighted_normals(np.array([[0, 0, 0], [1, 0, 0.5], [1.8, 1, 0.5], [0.8, 1, 0]]),
                                      scene.faces)
    np.testing.assert_allclose(scene.corner_normals.reshape(-1, 3), expected[scene.faces.ravel()], atol=1e-7)
    assert np.allclose(vertices, [[0, 0, 0], [1, 0, 0.5], [1.8, 1, 0.5], [0.8, 1, 0]])
    flat = load(tmp_path, f'<shape type="ply"><string name="filename" value="{TENT}"/>'
                          '<boolean name="face_normals" value="true"/></shape>')
    assert len(flat.corner_normals) == 0


def test_unit_normals_come_back_from_a_mesh_file_bit_for_bit(tmp_path):
    """unit_rows' rows written as float64 PLY normals read back unchanged (the mesh reader keeps
    rows that are unit to 1e-12, so a converted scene keeps its digest); rows that are not unit
    are normalized; zero rows stay zero."""
    from tracer.scene.mesh import read_mesh_file
    rows = np.random.default_rng(3).normal(size=(3000, 3))
    rows[5] = 0.0
    unit = unit_rows(rows)
    assert not np.any(unit[5])
    np.testing.assert_allclose(unit[6], rows[6] / np.linalg.norm(rows[6]), atol=1e-15)
    unit[5] = [0.0, 0.0, 1.0]  # a zero normal in a mesh file is refused
    vertices = np.random.default_rng(4).random((3000, 3))
    faces = np.arange(3000).reshape(-1, 3)
    for normals, expected in ((unit, unit), (2.5 * unit, unit)):
        header = ("ply\nformat binary_little_endian 1.0\nelement vertex 3000\nproperty double x\n"
                  "property double y\nproperty double z\nproperty double nx\nproperty double ny\n"
                  "property double nz\nelement face 1000\nproperty list uchar int vertex_indices\n"
                  "end_header\n")
        body = np.concatenate([vertices, normals], axis=1).astype("<f8").tobytes()
        face_rows = np.zeros(1000, dtype=[("n", "u1"), ("i", "<i4", (3,))])
        face_rows["n"], face_rows["i"] = 3, faces
        (tmp_path / "m.ply").write_bytes(header.encode() + body + face_rows.tobytes())
        normals_read = read_mesh_file(tmp_path / "m.ply").normals
        if normals is unit:
            assert np.array_equal(normals_read, expected)
        else:
            np.testing.assert_allclose(normals_read, expected, rtol=0, atol=4e-16)


def test_quads_and_polygons_are_fans_as_mitsubas_obj_loader_makes_them(tmp_path):
    """Mitsuba's OBJ loader (src/shapes/obj.cpp) makes a face of k corners the k - 2 triangles
    (c0, c1, c2), (c0, c2, c3), ...: mitsuba-data's Cornell box luminaire, one quad, was refused
    ("holds no triangles"). An all-quad OBJ keeps its normals (trimesh would drop them), a mixed
    one its order; PLY quads and pentagons are the same fans (Mitsuba 3.9.1 refuses PLY faces
    that are not triangles: tracer reads them as its OBJ loader would). No faces: refused."""
    from tracer.scene.mesh import MeshError, read_mesh_file

    def mesh_of(name: str, text: str):
        (tmp_path / name).write_text(text)
        return read_mesh_file(tmp_path / name)

    luminaire = ("v 343.0 548.8 227.0\nv 343.0 548.8 332.0\nv 213.0 548.8 332.0\nv 213.0 548.8 227.0\n"
                 "f 1 2 3 4\n")
    assert mesh_of("luminaire.obj", luminaire).faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    scene = load(tmp_path, f'<shape type="obj"><string name="filename" value="luminaire.obj"/>{EMIT}</shape>')
    assert len(scene.faces) == 2 and np.allclose(scene.vertices[scene.faces[1, 2]], [213.0, 548.8, 227.0])
    corners = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0.5 0\n"
    normals = np.array([[0, 0, 1], [0, 0.6, 0.8], [0.6, 0, 0.8], [0.8, 0, 0.6]])
    quad = mesh_of("normals.obj", corners + "".join(f"vn {a} {b} {c}\n" for a, b, c in normals)
                   + "f 1//1 2//2 3//3 4//4\n")
    assert quad.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and quad.normals.tolist() == normals.tolist()
    mixed = mesh_of("mixed.obj", corners + "f 1 2 4\n  f 2 3 4 5 1\n")
    assert mixed.faces.tolist() == [[0, 1, 3], [1, 2, 3], [1, 3, 4], [1, 4, 0]]
    header = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
              "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face {}\n"
              "property list uchar int vertex_indices\nend_header\n")
    vertices = "".join(f"{line[2:]} 0 0 1\n" for line in corners.splitlines())
    quads = mesh_of("quads.ply", header.format(2) + vertices + "4 0 1 2 3\n4 4 3 2 1\n")
    assert quads.faces.tolist() == [[0, 1, 2], [0, 2, 3], [4, 3, 2], [4, 2, 1]]
    assert quads.normals.tolist() == [[0, 0, 1]] * 5
    assert mesh_of("pentagon.ply", header.format(1) + vertices + "5 0 1 2 3 4\n").faces.tolist() == \
        [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    for name, text in [("empty.obj", corners), ("empty.ply", header.format(0) + vertices)]:
        with pytest.raises(MeshError, match="holds no faces"):
            mesh_of(name, text)


@pytest.mark.parametrize("shape, words", [
    ('<shape type="serialized"/>', ["serialized", "missing property 'filename'"]),
    ('<shape type="instance"/>', ["instance", "needs one reference to a shapegroup"]),
    ('<shape type="shapegroup"><shape type="instance"/></shape>', ["nested instancing"]),
    (f'<shape type="shapegroup" id="g"><shape type="cube">{EMIT}</shape></shape>'
     '<shape type="instance"><ref id="g"/></shape>', ["an emitter in a shapegroup"]),
    ('<shape type="linearcurve"/>', ["linearcurve"]),
    ('<shape type="obj"/>', ["filename"]),
    ('<shape type="obj"><string name="filename" value="missing.obj"/></shape>', ["mesh file not found"]),
    (f'<shape type="ply"><string name="filename" value="{TENT}"/><float name="maximum" value="1"/></shape>',
     ["no property 'maximum'"]),
    ('<shape type="rectangle"><bsdf type="diffuse"/><bsdf type="diffuse"/></shape>', ["one bsdf"]),
    ('<shape type="rectangle"><emitter type="point"/></shape>', ["shape's emitter is 'area'"]),
    ('<shape type="rectangle"><sensor type="perspective"/></shape>', ["not expected inside"]),
    ('<shape type="rectangle"><transform name="to_world"><translate x="1e16"/></transform></shape>',
     ["beyond"]),
])
def test_shape_refusals(tmp_path, shape, words):
    refused(tmp_path, shape, *words, line=3)


# ---------------------------------------------------------------------------------------------
# Materials


def test_mitsubas_default_bsdfs(tmp_path):
    """A shape without a bsdf: Mitsuba's one-sided diffuse of reflectance 0.5 (mi.traverse of a
    bare cube: bsdf.reflectance.value 0.5), shared; an emitting shape without one: black
    (bsdf.reflectance.value 0.0), tracer's material row 0."""
    scene = load(tmp_path, f'<shape type="cube"/><shape type="disk"/><shape type="rectangle">{EMIT}</shape>')
    assert material(scene, 0) == ("diffuse", {"reflectance": pytest.approx([0.5] * 3)}, False)
    assert scene.shapes[0].material == scene.shapes[1].material == 1
    assert scene.shapes[2].material == 0 and len(scene.materials.names) == 2


def test_bsdf_defaults_are_mitsubas(tmp_path):
    """Mitsuba 3.9.1's defaults (print(mi.load_dict({'type': T}))): roughconductor beckmann,
    alpha 0.1, eta 0, k 1 (material "none"), specular_reflectance 1; conductor the same mirror;
    plastic and roughplastic diffuse_reflectance 0.5, int_ior polypropylene 1.49, ext_ior air
    1.000277 (eta traversed 1.48959), nonlinear false, roughplastic beckmann, alpha 0.1.
    Every BSDF outside twosided is one-sided."""
    scene = load(tmp_path, "\n".join(f'<shape type="cube"><bsdf type="{t}"/></shape>' for t in
                                     ("roughconductor", "conductor", "plastic", "roughplastic", "diffuse")))
    rc = material(scene, 0)
    assert rc[0] == "roughconductor" and not rc[2]
    assert rc[1]["distribution"] == "beckmann" and rc[1]["alpha"] == 0.1
    assert list(rc[1]["eta"]) == [0.0] * 3 and list(rc[1]["k"]) == [1.0] * 3
    assert list(rc[1]["reflectance"]) == [1.0] * 3
    c = material(scene, 1)
    assert c[0] == "conductor" and list(c[1]["eta"]) == [0] * 3 and list(c[1]["k"]) == [1] * 3
    for shape, kind in ((2, "plastic"), (3, "roughplastic")):
        name, values, twosided = material(scene, shape)
        assert name == kind and not twosided
        assert values["int_ior"] == 1.49 and values["ext_ior"] == 1.000277 and values["nonlinear"] is False
        assert list(values["diffuse_reflectance"]) == [0.5] * 3
        assert list(values["specular_reflectance"]) == [1.0] * 3
    assert material(scene, 3)[1]["distribution"] == "beckmann" and material(scene, 3)[1]["alpha"] == 0.1
    assert material(scene, 4) == ("diffuse", {"reflectance": pytest.approx([0.5] * 3)}, False)


def test_twosided_and_references(tmp_path):
    """twosided wraps one BSDF (nested or referenced): that material on both sides. One BSDF
    declared at the top, used directly and through twosided, gives two rows; a BSDF used by
    two shapes, one row."""
    scene = load(tmp_path, '<bsdf type="diffuse" id="d"><rgb name="reflectance" value="0.2, 0.3, 0.4"/>'
                           '</bsdf>\n<bsdf type="twosided" id="both"><ref id="d"/></bsdf>\n'
                           '<shape type="cube"><ref id="d"/></shape><shape type="cube">'
                           '<ref name="bsdf" id="d"/></shape><shape type="cube"><ref id="both"/></shape>')
    assert scene.shapes[0].material == scene.shapes[1].material != scene.shapes[2].material
    assert material(scene, 0)[2] is False and material(scene, 2)[2] is True
    assert list(material(scene, 2)[1]["reflectance"]) == [0.2, 0.3, 0.4]
    assert scene.materials.names[1:] == ["d", "both"]


def test_conductor_presets_and_iors(tmp_path):
    """material="Au" takes tracer.materials.presets' eta and k; IOR names are Mitsuba's table
    (case-insensitive: "BK7" is 1.5046, read back as a plastic's eta with ext_ior 1); alpha_u =
    alpha_v is isotropic; distribution names in any case; alpha 0 is clamped to Mitsuba's 1e-4
    (print(mi.load_dict({'type': 'roughplastic', 'alpha': 0})): alpha = 0.0001)."""
    from tracer.materials.presets import CONDUCTORS

    scene = load(tmp_path, '<shape type="cube"><bsdf type="roughconductor">'
                           '<string name="material" value="Au"/>'
                           '<string name="distribution" value="GGX"/><float name="alpha_u" value="0.3"/>'
                           '<float name="alpha_v" value="0.3"/></bsdf></shape>\n'
                           '<shape type="cube"><bsdf type="roughplastic"><string name="int_ior" value="BK7"/>'
                           '<string name="ext_ior" value="water"/><float name="alpha" value="0"/>'
                           '<boolean name="nonlinear" value="true"/></bsdf></shape>')
    name, values, _ = material(scene, 0)
    assert values["distribution"] == "ggx" and values["alpha"] == 0.3
    np.testing.assert_array_equal(values["eta"], CONDUCTORS["Au"][0])
    np.testing.assert_array_equal(values["k"], CONDUCTORS["Au"][1])
    name, values, _ = material(scene, 1)
    assert (values["int_ior"], values["ext_ior"], values["alpha"]) == (1.5046, 1.333, 1e-4)
    assert values["nonlinear"] is True


# Mitsuba 3.9.1's IOR names, read back with ext_ior 1 as a plastic's eta (mi.traverse 'p.eta').
MITSUBA_IORS = {"vacuum": 1.0, "air": 1.00028, "water": 1.333, "acetone": 1.36, "ethanol": 1.361,
                "glycerol": 1.4729, "bk7": 1.5046, "polypropylene": 1.49, "diamond": 2.419, "water ice": 1.31,
                "fused quartz": 1.458, "pyrex": 1.47, "acrylic glass": 1.49, "sodium chloride": 1.544,
                "amber": 1.55, "pet": 1.575, "silicone oil": 1.52045, "bromine": 1.661, "benzene": 1.501,
                "carbon tetrachloride": 1.461, "helium": 1.00004, "hydrogen": 1.00013,
                "carbon dioxide": 1.00045}


def test_ior_names_are_mitsubas():
    from tracer.materials.presets import IORS

    assert set(IORS) == set(MITSUBA_IORS)
    for name, value in MITSUBA_IORS.items():
        assert IORS[name] == pytest.approx(value, abs=6e-6), name


@pytest.mark.parametrize("bsdf, words", [
    ('<bsdf type="roughdielectric" id="glass"><texture type="checkerboard" name="specular_transmittance"/>'
     '</bsdf>', ["specular_transmittance", "is not expected inside"]),
    ('<bsdf type="dielectric"><float name="int_ior" value="0"/></bsdf>', ["int_ior", ">= 0.01, got 0"]),
    ('<bsdf type="thindielectric"><string name="ext_ior" value="glas"/></bsdf>', ["unknown IOR name 'glas'"]),
    ('<bsdf type="hair"/>', ["bsdf 'hair' is not supported"]),
    ('<bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="plastic"/></bsdf>', ["two different BSDFs"]),
    ('<bsdf type="twosided"/>', ["one nested bsdf"]),
    ('<bsdf type="twosided"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>', ["twosided inside"]),
    ('<bsdf type="roughplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.2"/>'
     '</bsdf>', ["anisotropic roughness", "on roughplastic"]),
    ('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/></bsdf>', ["go together"]),
    ('<bsdf type="roughconductor"><float name="alpha" value="0.1"/><float name="alpha_u" value="0.1"/>'
     '<float name="alpha_v" value="0.1"/></bsdf>', ["alpha or alpha_u"]),
    ('<bsdf type="roughconductor"><rgb name="alpha" value="0.1, 0.2, 0.1"/></bsdf>', ["per colour channel"]),
    ('<bsdf type="roughconductor"><string name="distribution" value="phong"/></bsdf>', ["beckmann or ggx"]),
    # Mitsuba: "Should specify either (eta, k) or material, not both."
    ('<bsdf type="conductor"><string name="material" value="Au"/><rgb name="eta" value="1"/></bsdf>',
     ["material or eta"]),
    ('<bsdf type="conductor"><string name="material" value="au"/></bsdf>', ["case-sensitive: 'Au'"]),
    ('<bsdf type="conductor"><float name="ext_ior" value="1.2"/></bsdf>', ["no property 'ext_ior'"]),
    ('<bsdf type="plastic"><string name="int_ior" value="glass"/></bsdf>', ["unknown IOR name 'glass'"]),
    ('<bsdf type="plastic"><rgb name="int_ior" value="1.5"/></bsdf>', ["'int_ior' is a float"]),
    ('<bsdf type="plastic"><float name="int_ior" value="-1"/></bsdf>', [">= 0.01"]),
    # Mitsuba: "Invalid RGB reflectance value [2, 2, 2], must be in the range [0, 1]!"
    ('<bsdf type="diffuse"><rgb name="reflectance" value="2, 2, 2"/></bsdf>', ["<= 1"]),
    ('<bsdf type="diffuse"><float name="reflectance" value="-0.1"/></bsdf>', [">= 0"]),
    ('<bsdf type="diffuse"><string name="reflectance" value="0.5"/></bsdf>', ["is a rgb or float"]),
    ('<bsdf type="diffuse"><texture name="reflectance" type="bitmap"/></bsdf>',
     ["missing property 'filename'"]),
])
def test_bsdf_refusals(tmp_path, bsdf, words):
    refused(tmp_path, f'<shape type="cube">\n{bsdf}</shape>', *words, line=4)


def test_unused_declarations_are_checked_as_mitsuba_checks_them(tmp_path):
    """A declaration no shape uses changes no image: it is refused only where Mitsuba refuses
    it. A twosided (one BSDF, or two: Mitsuba's twosided takes two), a dielectric or another of
    Mitsuba's BSDFs that tracer does not render load; values out of range, an unknown type, a
    dielectric inside a twosided (Mitsuba nests only BSDFs without transmission), a twosided
    without a BSDF, a twosided that refers to itself (Mitsuba: "circular reference detected")
    and an area emitter's negative radiance are refused. A chain of 3000 twosided BSDFs, each
    referring to the next, is checked without recursion. (Textures are refused wherever they
    are.)"""
    for body in ('<bsdf type="twosided" id="both"><bsdf type="diffuse"/></bsdf>',
                 '<bsdf type="twosided" id="two"><bsdf type="diffuse"/><bsdf type="conductor"/></bsdf>',
                 '<bsdf type="dielectric" id="glass"/>', '<bsdf type="principled" id="p"/>',
                 '<bsdf type="diffuse" id="d"/><bsdf type="twosided" id="t"><ref id="d"/></bsdf>'):
        assert len(load(tmp_path, body).materials.names) == 1, body  # the black row only
    for body, words in [
            ('<bsdf type="twosided" id="t">\n<bsdf type="diffuse"><float name="reflectance" value="2"/>'
             '</bsdf></bsdf>', ["<= 1"]),
            ('<bsdf type="difuse" id="typo"/>', ["bsdf 'difuse' is not supported"]),
            ('<bsdf type="twosided" id="t">\n<bsdf type="dielectric"/></bsdf>',
             ["dielectric inside a twosided"]),
            ('<bsdf type="twosided" id="t"/>', ["twosided needs one or two nested BSDFs"]),
            ('<bsdf type="twosided" id="a"><ref id="b"/></bsdf>\n<bsdf type="twosided" id="b"><ref id="a"/>'
             '</bsdf>', ['<ref id="a">: a circular reference']),
            ('<texture type="noise" id="t"/>', ["texture 'noise' is not supported"]),
            ('<emitter type="area" id="e"><rgb name="radiance" value="-1"/></emitter>', [">= 0"])]:
        refused(tmp_path, body, *words)
    chain = "".join(f'<bsdf type="twosided" id="t{i}"><ref id="t{i + 1}"/></bsdf>' for i in range(3000))
    assert len(load(tmp_path, chain + '<bsdf type="diffuse" id="t3000"/>').materials.names) == 1


def test_sample_visible_false_is_told(tmp_path):
    lines: list[str] = []
    load_scene(write(tmp_path, '<shape type="cube"><bsdf type="roughconductor">'
                               '<boolean name="sample_visible" value="false"/></bsdf></shape>'),
               notify=lines.append)
    assert len(lines) == 1 and "sample_visible false" in lines[0]


# ---------------------------------------------------------------------------------------------
# Emitters and spectra


def test_emitter_defaults_and_forms(tmp_path):
    """An area emitter's radiance defaults to 1 (white), a point emitter's intensity to 1 at
    the origin (mi.traverse: radiance.value 1.0, p.position [0, 0, 0]); a point may be placed by
    to_world's translation; an area emitter may be declared at the top and referenced."""
    scene = load(tmp_path, '<shape type="rectangle"><emitter type="area"/></shape>\n'
                           '<emitter type="point"/>\n<emitter type="point"><transform name="to_world">'
                           '<rotate x="1" angle="30"/><translate x="1" y="2" z="3"/></transform>'
                           '<float name="intensity" value="5"/></emitter>\n'
                           '<emitter type="area" id="lamp"><rgb name="radiance" value="1, 2, 3"/></emitter>\n'
                           '<shape type="disk"><ref id="lamp"/></shape>')
    assert scene.shapes[0].emission.tolist() == [1, 1, 1]
    assert scene.point_position.tolist() == [[0, 0, 0], [1, 2, 3]]
    assert scene.point_intensity.tolist() == [[1, 1, 1], [5, 5, 5]]
    assert scene.shapes[1].emission.tolist() == [1, 2, 3] and scene.shapes[1].material == 0


@pytest.mark.parametrize("body, words", [
    ('<emitter type="envmap"/>', ["missing property 'filename'"]),
    ('<emitter type="constant"/><emitter type="constant"/>', ["a second environment emitter"]),
    ('<emitter type="radiancemeter"/>', ["emitter 'radiancemeter' is not supported", "projector"]),
    # Mitsuba: "Only one of the parameters 'position' and 'to_world' can be specified"
    ('<emitter type="point"><point name="position" value="1, 1, 1"/><transform name="to_world">'
     '<translate x="1"/></transform></emitter>', ["position or to_world"]),
    ('<emitter type="point"><point name="position" x="1"/></emitter>', ["missing attribute 'y'"]),
    # Mitsuba: "An endpoint can be only be attached to a single shape."
    ('<emitter type="area" id="e"/><shape type="cube"><ref id="e"/></shape><shape type="cube"><ref id="e"/>'
     '</shape>', ["already belongs to the shape at"]),
    ('<shape type="cube"><emitter type="area"><rgb name="radiance" value="1e19"/></emitter></shape>',
     ["<= 1e+18"]),
])
def test_emitter_refusals(tmp_path, body, words):
    refused(tmp_path, body, *words, line=3)


@pytest.mark.parametrize("value", MITSUBA_SPECTRA)
def test_spectra_are_close_to_mitsubas(tmp_path, value):
    """A constant stays itself (an emitter's is equal-energy white, Mitsuba's c (1.20479,
    0.948292, 0.908916)); tabulated spectra are summed against the CIE 1931 tables as Mitsuba
    sums them, under D65 for non-emitters, and clamped as Mitsuba clamps them. Measured: every
    channel within 5.9e-6 of Mitsuba's (6-decimal) numbers, and within 0.16 of the bound
    2e-6 + 4e-6 |expected| checked here (a margin of 6). A reflectance above 1 is refused by
    tracer (Mitsuba renders it)."""
    expected = MITSUBA_SPECTRA[value]
    body = (f'<shape type="cube"><bsdf type="conductor"><spectrum name="eta" value="{value}"/></bsdf>'
            f'<emitter type="area"><spectrum name="radiance" value="{value}"/></emitter></shape>\n')
    reflectance_ok = max(expected["reflectance"]) <= 1.0 and value != "2"
    if reflectance_ok:
        body += (f'<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" value="{value}"/>'
                 '</bsdf></shape>')
    scene = load(tmp_path, body)
    close = {"atol": 2e-6, "rtol": 4e-6}  # the numbers are rounded to 5e-7 and float32 in Mitsuba
    np.testing.assert_allclose(material(scene, 0)[1]["eta"], expected["eta"], **close)
    np.testing.assert_allclose(scene.shapes[0].emission, expected["emitter"], **close)
    if reflectance_ok:
        np.testing.assert_allclose(material(scene, 1)[1]["reflectance"], expected["reflectance"], **close)
    if ":" not in value:
        assert list(material(scene, 0)[1]["eta"]) == [float(value)] * 3


def test_spectrum_clamping_is_told_and_rgb_forms(tmp_path):
    lines: list[str] = []
    scene = load_scene(write(tmp_path, '<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" '
                                       'value="400:2 700:2"/></bsdf></shape>\n<shape type="cube"><bsdf '
                                       'type="diffuse"><rgb name="reflectance" value="0.1,,0.2  0.3"/></bsdf>'
                                       '</shape>'), notify=lines.append)
    assert list(material(scene, 0)[1]["reflectance"]) == [1.0, 1.0, 1.0]
    assert list(material(scene, 1)[1]["reflectance"]) == [0.1, 0.2, 0.3]
    assert len(lines) == 1 and "scene.xml:3" in lines[0] and "clamped" in lines[0]


@pytest.mark.parametrize("value, words", [
    ("550:1", ["at least two"]),
    ("400:0.1, 300:0.2", ["increasing"]),
    ("400:0.1, 400:0.2", ["increasing"]),
    # Mitsuba: 'Invalid spectrum value "0.1" (expected wavelength:value pairs)'
    ("0.1, 0.2", ["expected a number"]),
    ("400:0.1:3, 500:1", ["wavelength:value pairs"]),
    ("400:nan, 500:1", ["finite"]),
])
def test_spectrum_refusals(tmp_path, value, words):
    refused(tmp_path, '<shape type="cube">\n<bsdf type="diffuse">'
                      f'<spectrum name="reflectance" value="{value}"/></bsdf></shape>', *words, line=4)


def test_spectrum_files_and_plugins_are_refused(tmp_path):
    refused(tmp_path, '<shape type="cube">\n<bsdf type="diffuse">'
                      '<spectrum name="reflectance" filename="a.spd"/></bsdf></shape>', "from files", line=4)
    refused(tmp_path, '<shape type="cube">\n<emitter type="area"><spectrum type="blackbody"/></emitter>'
                      '</shape>', "spectrum plugins", line=4)


# ---------------------------------------------------------------------------------------------
# The document: defaults, includes, paths, ids


def test_defaults_and_substitution(tmp_path):
    """$name is replaced in any attribute after its <default> (the first default of a name
    wins; a default inside an object counts from there on); several in one value; the longest
    name ($rr, not $r then r)."""
    scene = load(tmp_path, '<default name="r" value="0.2"/><default name="rr" value="0.4"/>'
                           '<default name="r" value="0.9"/><default name="t" value="diffuse"/>\n'
                           '<shape type="cube"><bsdf type="$t">'
                           '<rgb name="reflectance" value="$r, $rr, $r"/></bsdf>'
                           '</shape>\n<shape type="cube"><bsdf type="diffuse"><default name="q" value="0.3"/>'
                           '<float name="reflectance" value="$q"/></bsdf></shape>')
    assert list(material(scene, 0)[1]["reflectance"]) == [0.2, 0.4, 0.2]
    assert list(material(scene, 1)[1]["reflectance"]) == [0.3] * 3


@pytest.mark.parametrize("body, words, line", [
    # Mitsuba: "undefined parameter: $r" (a use before its default)
    ('<shape type="cube">\n<bsdf type="diffuse"><float name="reflectance" value="$r"/></bsdf></shape>\n'
     '<default name="r" value="0.2"/>', ["undefined parameter $r"], 4),
    ('<default name="a" value="$b"/>', ["undefined parameter $b"], 3),
])
def test_undefined_parameters(tmp_path, body, words, line):
    refused(tmp_path, body, *words, line=line)


def test_the_feature_scene(tmp_path):
    """tests/data/xml/features.xml: includes relative to the including file (two levels), a
    <path> folder for a mesh, an alias, refs to top-level BSDFs and an area emitter declared in
    an included file, $name in an included file, every shape type, a point light."""
    scene = load_scene(DATA / "features.xml")
    assert [s.type for s in scene.shapes] == ["quad", "quad", "mesh", "sphere"] + ["mesh"] * 4
    assert scene.render_defaults == {"spp": 8} and (scene.camera.width, scene.camera.height) == (48, 32)
    names = scene.materials.names
    assert names[scene.shapes[0].material] == "grey" and scene.materials.twosided[scene.shapes[0].material]
    assert names[scene.shapes[2].material] == "gold" and names[scene.shapes[3].material] == "coat"
    white = np.array([1.204794, 0.948291, 0.908916])  # equal-energy white in sRGB, as Mitsuba makes it
    np.testing.assert_allclose(scene.shapes[1].emission, 48 * white, rtol=1e-6)
    assert scene.shapes[1].material == 0  # an emitter without a bsdf: black
    assert scene.shapes[6].record["file"].endswith("parts/deeper/tent_in_path.ply")
    assert len(scene.corner_normals) == len(scene.faces)
    assert not np.any(scene.corner_normals[scene.shapes[7].first:])  # face_normals: flat
    assert scene.point_intensity.tolist() == [[2, 2, 1.5]]


def test_include_cycles_depth_and_roots(tmp_path):
    with pytest.raises(InputError, match="include cycle"):
        load_scene(DATA / "cycle_a.xml")
    (tmp_path / "part.xml").write_text('<bsdf type="diffuse"/>')
    refused(tmp_path, '<include filename="part.xml"/>', "root element is <scene>")


@pytest.mark.parametrize("nested", [document.MAX_INCLUDE_DEPTH, document.MAX_INCLUDE_DEPTH + 1])
def test_include_depth_limit_says_what_it_does(tmp_path, nested):
    """MAX_INCLUDE_DEPTH (16) includes nested in one another load (the main file includes d1,
    which includes d2, ... d16); one more is refused, naming the limit."""
    for i in range(nested):
        include = f'<include filename="d{i + 1}.xml"/>'
        (tmp_path / f"d{i}.xml").write_text(f'<scene version="3.0.0">{include}</scene>')
    (tmp_path / f"d{nested}.xml").write_text(f'<scene version="3.0.0">{SENSOR}</scene>')
    if nested <= document.MAX_INCLUDE_DEPTH:
        assert load_scene(tmp_path / "d0.xml").camera.width == 8
    else:
        with pytest.raises(InputError) as caught:
            load_scene(tmp_path / "d0.xml")
        message = str(caught.value)
        assert f"d{nested - 1}.xml:1: <include>: more than 16 includes nested in one another" in message


def test_files_are_found_as_mitsubas_file_resolver_finds_them(tmp_path):
    """Mitsuba 3.9.1 (src/core/parser.cpp, src/core/fresolver.cpp): an include is looked for
    beside the including file, then where that file's own names are looked for (its <path>
    folders, the including file's folder, ..., the main file's <path> folders, the main
    scene's folder); a mesh in the main file's <path> folders and then the main scene's folder,
    not beside the file that names it. A <path> of an included file serves its includes only.
    As mitsuba-data's scenes/cbox/cbox-rgb.xml does: fragments name meshes and each other
    relative to the main scene."""
    (tmp_path / "fragments" / "parts").mkdir(parents=True)
    (tmp_path / "lib").mkdir()
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "fragments" / "parts" / "tri_in_parts.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")

    def scene_file(path: Path, body: str) -> None:
        path.write_text(f'<scene version="3.0.0">{body}</scene>')

    scene_file(tmp_path / "main.xml", f'{SENSOR}<path value="lib"/><include filename="fragments/a.xml"/>'
                                      '<include filename="from_lib.xml"/>')
    scene_file(tmp_path / "lib" / "from_lib.xml", '<bsdf type="diffuse" id="lib"/>')
    # a.xml: b.xml is the main scene's fragments/b.xml, c.xml is beside a.xml, e.xml in its <path>
    scene_file(tmp_path / "fragments" / "a.xml",
               '<include filename="fragments/b.xml"/><include filename="c.xml"/><path value="parts"/>'
               '<include filename="e.xml"/><shape type="obj"><string name="filename" value="meshes/tri.obj"/>'
               '<ref id="lib"/></shape>')
    scene_file(tmp_path / "fragments" / "b.xml", '<bsdf type="diffuse" id="b"/>')
    scene_file(tmp_path / "fragments" / "c.xml", '<bsdf type="diffuse" id="c"/>')
    scene_file(tmp_path / "c.xml", '<bsdf type="conductor" id="not_this_c"/>')  # beside a.xml comes first
    scene_file(tmp_path / "fragments" / "parts" / "e.xml", '<bsdf type="diffuse" id="e"/>')
    assert set(document.read_document(str(tmp_path / "main.xml")).ids) == {"lib", "b", "c", "e"}
    scene = load_scene(tmp_path / "main.xml")
    assert scene.shapes[0].record["file"] == str(tmp_path / "meshes" / "tri.obj")
    assert scene.materials.names[scene.shapes[0].material] == "lib"
    # a <path> in an included file does not reach the meshes (Mitsuba builds them after parsing)
    scene_file(tmp_path / "fragments" / "e.xml", '<shape type="obj"><string name="filename" '
                                                 'value="tri_in_parts.obj"/></shape>')
    scene_file(tmp_path / "fragments" / "parts" / "e.xml", '<include filename="../e.xml"/>')
    with pytest.raises(InputError, match="mesh file not found"):
        load_scene(tmp_path / "main.xml")
    refused(tmp_path, '<path value="nowhere"/>', "folder not found: 'nowhere'", line=3)
    refused(tmp_path, '<shape type="cube"><path value="."/></shape>', "directly inside <scene>", line=3)
    refused(tmp_path, '<path value="."/>' * document.MAX_PATHS + '\n<path value="."/>',
            "more than 100 <path>", line=4)
    message = refused(tmp_path, '<include filename="nothere.xml"/>', "included file not found", line=3)
    assert f"looked in {tmp_path}" in message


def test_ids_refs_and_aliases(tmp_path):
    refused(tmp_path, '<bsdf type="diffuse" id="d"/>\n<bsdf type="diffuse" id="d"/>',
            "duplicate id 'd' (first at", line=4)
    refused(tmp_path, '<shape type="cube"><ref id="nothere"/></shape>', "no object has id 'nothere'", line=3)
    refused(tmp_path, '<alias id="nothere" as="x"/>', "no object has id 'nothere'", line=3)
    refused(tmp_path, '<bsdf type="diffuse" id="a"/><bsdf type="diffuse" id="b"/>\n<alias id="a" as="b"/>',
            "id 'b' is taken", line=4)
    scene = load(tmp_path, '<bsdf type="diffuse" id="a"/><alias id="a" as="b"/>'
                           '<shape type="cube"><ref id="b"/></shape>')
    assert scene.materials.names[1:] == ["a"]


@pytest.mark.parametrize("text, words", [
    ('<scene version="3.0.0"><shape type="cube"></scene>', ["not well-formed XML", "mismatched tag", ":1:"]),
    ('<?xml version="1.0"?>\n<!DOCTYPE scene [<!ENTITY a "aaaa">]>\n<scene version="3.0.0"/>',
     ["DOCTYPE declarations are not allowed", ":2:"]),
    ('<scene version="3.0.0">&undefined;</scene>', ["undefined entity"]),
    ('<bsdf version="3.0.0"/>', ["root element of a Mitsuba scene is <scene>"]),
    ('<scene/>', ["missing attribute 'version'"]),
    ('<scene version="4.0.0"/>', ["versions 0.x to 3.x"]),
    ('<scene version="three"/>', ["major.minor.patch"]),
    ("", ["not well-formed XML"]),
    ("\xff\xfe<", ["not well-formed XML"]),
])
def test_malformed_documents(tmp_path, text, words):
    path = tmp_path / "scene.xml"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(InputError) as caught:
        load_scene(path)
    assert "\n" not in str(caught.value)
    for word in words:
        assert word in str(caught.value), str(caught.value)


def test_billion_laughs_is_refused_quickly(tmp_path):
    entities = '<!ENTITY l0 "lol">' + "".join(f'<!ENTITY l{i} "{f"&l{i - 1};" * 10}">' for i in range(1, 10))
    path = tmp_path / "laughs.xml"
    path.write_text(f'<?xml version="1.0"?><!DOCTYPE scene [{entities}]><scene version="3.0.0">&l9;</scene>')
    with pytest.raises(InputError, match="DOCTYPE"):
        load_scene(path)


@pytest.mark.parametrize("body, words", [
    ('<shape type="cube"><bsdf type="diffuse"><float name="reflectance" value="0.3x"/></bsdf></shape>',
     ["expected a number, got '0.3x'"]),
    ('<shape type="cube"><bsdf type="diffuse"><float name="reflectance" value="nan"/></bsdf></shape>',
     ["finite"]),
    ('<shape type="cube"><bsdf type="diffuse"><float name="reflectance" value="inf"/></bsdf></shape>',
     ["finite"]),
    ('<shape type="cube"><bsdf type="diffuse"><float name="reflectance" value="1e999"/></bsdf></shape>',
     ["not a finite number"]),
    # Mitsuba: 'could not parse integer value "1.0"'
    ('<sensor type="perspective"><sampler type="independent"><integer name="sample_count" value="1.0"/>'
     '</sampler></sensor>', ["expected a whole number"]),
    ('<sensor type="perspective"><sampler type="independent"><integer name="sample_count" value="0"/>'
     '</sampler></sensor>', [">= 1"]),
    # Mitsuba: 'could not parse boolean value "1" -- must be "true" or "false"'
    ('<shape type="cube"><boolean name="flip_normals" value="1"/></shape>', ["expected true or false"]),
    ('<shape type="cube"><float name="flip_normals" value="1"/></shape>', ["'flip_normals' is a boolean"]),
    ('<shape type="cube"><boolean name="flip_normals" value="true"/>'
     '<boolean name="flip_normals" value="true"/></shape>', ["given twice"]),
    ('<shape type="cube"><boolean value="true"/></shape>', ["missing attribute 'name'"]),
    ('<shape type="cube"><foo/></shape>', ["unknown element"]),
    ('<shape type="cube" colour="red"/>', ["unexpected attribute 'colour'"]),
    ('<float name="x" value="1"/>', ["properties belong inside an object"]),
    ('<medium type="homogeneous"/>', ["participating media"]),
    ('<shape type="cube"><ref id="m"/></shape><medium type="homogeneous" id="m"/>', ["participating media"]),
])
def test_value_and_element_refusals(tmp_path, body, words):
    refused(tmp_path, body, *words, line=3, sensor="sensor" not in body)


def test_booleans_numbers_and_vectors_as_mitsuba_writes_them(tmp_path):
    """Booleans in any case ("TRUE"), numbers with spaces and exponents, vectors from value
    (one number: all three) or x, y, z."""
    scene = load(tmp_path, '<shape type="rectangle"><boolean name="flip_normals" value="TRUE"/></shape>\n'
                           '<shape type="sphere"><point name="center" value="2"/>'
                           '<float name="radius" value=" 5e-1 "/></shape>\n'
                           '<emitter type="point"><vector name="position" x="1" y="2" z="3"/></emitter>')
    assert front_z(scene) == -1
    assert scene.spheres.tolist() == [[2, 2, 2, 0.5]] and scene.point_position.tolist() == [[1, 2, 3]]


# ---------------------------------------------------------------------------------------------
# The commands that take a scene


LIT = ('<sensor type="perspective"><float name="fov" value="45"/><transform name="to_world">'
       '<lookat origin="0, 1, 4" target="0, 0.5, 0" up="0, 1, 0"/></transform><sampler type="independent">'
       '<integer name="sample_count" value="2"/></sampler><film type="hdrfilm">'
       '<integer name="width" value="8"/><integer name="height" value="6"/></film></sensor>\n'
       '<integrator type="path"/>\n'
       '<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>'
       '</transform><bsdf type="diffuse"/></shape>\n<shape type="cube"><transform name="to_world">'
       '<scale value="0.4"/><translate y="0.4"/></transform><bsdf type="roughplastic"/></shape>\n'
       '<shape type="rectangle"><transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/>'
       '<translate y="2"/></transform><emitter type="area"><rgb name="radiance" value="10"/></emitter>'
       '</shape>')


def test_render_reference_compare_and_check_take_xml_scenes(tmp_path, capsys):
    """render (with the sampler's spp and a --width override), reference, compare's scene
    loading and check --create / check all read an .xml scene; the note is printed once per
    command however often it loads the scene."""
    from tracer import cli
    from tracer.imagefiles import read_exr
    from tracer.study.compare import scene_for_reference

    scene = write(tmp_path, LIT, sensor=False, name="lit.xml")
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "r.exr"), "--width", "12", "--quiet"]) == 0
    film = read_exr(tmp_path / "r.exr")
    assert (film.width, film.height, film.spp) == (12, 9, 2)
    assert cli.main(["reference", str(scene), "-o", str(tmp_path / "ref.exr"), "--spp", "8", "--quiet"]) == 0
    reference = read_exr(tmp_path / "ref.exr")
    assert scene_for_reference(scene, tmp_path / "ref.exr", reference, quiet=True).digest == \
        load_scene(scene).digest == reference.record.scene_digest
    baseline = tmp_path / "b.json"
    assert cli.main(["check", "--create", str(baseline), "--scenes", str(scene), "--strategies", "mis",
                     "--spp", "2", "--reference-spp", "32", "--size", "8", "--threads", "2"]) == 0
    assert cli.main(["check", "--baseline", str(baseline), "--threads", "2", "--out", str(tmp_path / "f")]) \
        == 0
    err = capsys.readouterr().err
    assert err.count("tracer: note:") == 4, err  # one per command
    bad = write(tmp_path, '<shape type="cube">\n<bsdf type="hair" id="glass"/></shape>',
                name="bad.xml")
    assert cli.main(["render", str(bad), "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'tracer: error: {bad}:4: <bsdf type="hair" id="glass">: bsdf \'hair\' is not supported; '
                   "tracer reads diffuse, conductor, roughconductor, plastic, roughplastic, pplastic, dielectric, "
                   "roughdielectric, thindielectric, twosided, mask, normalmap, bumpmap, blendbsdf, principled and "
                   "principledthin"]


def test_substitution_is_bounded_while_it_is_done(tmp_path):
    """$name defaults that double at every step, used many times: one attribute made of 256 uses
    of a default just under the attribute limit (128 Mi characters) is refused before it is
    built, and 100 attributes of one use each (50 Mi characters in all) when the whole scene's
    substitutions pass MAX_SUBSTITUTED_TOTAL, each in one line naming the file, line, element
    and attribute, with little memory (a 1 MB file of such attributes took 4 GB and 48 s)."""
    import tracemalloc

    doubled = ('<default name="a0" value="x"/>'
               + "".join(f'<default name="a{i + 1}" value="$a{i}$a{i}"/>' for i in range(19)))  # $a19: 2^19
    cases = {
        "one": (f'<shape type="cube" id="{"$a19" * 256}"/>', '<shape type="cube" id="$a19$a19',
                "attribute 'id' is longer than 1048576 characters", 4 * document.MAX_SUBSTITUTED),
        "many": ("".join(f'<bsdf type="diffuse" id="$a19-{i}"/>' for i in range(100)),
                 '<bsdf type="diffuse" id="$a19-30">', "attribute 'id': substituting $names makes more than",
                 24 * document.MAX_SUBSTITUTED),  # MAX_SUBSTITUTED_TOTAL is 16 of them
    }
    for name, (body, element, words, most_bytes) in cases.items():
        path = tmp_path / f"{name}.xml"
        path.write_text(f'<scene version="3.0.0">{doubled}\n{body}</scene>')
        tracemalloc.start()
        try:
            with pytest.raises(InputError) as caught:
                document.read_document(str(path))
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        message = str(caught.value)
        assert message.startswith(f"{path}:2: {element}") and words in message, message
        assert len(message) < 400 and peak < most_bytes, (name, len(message), peak)


def test_huge_names_give_short_lines_quickly(tmp_path):
    """An echoed user string (an id, a type, a property or attribute name, a $name, a conductor
    or IOR name, an include's file name, a tag) of 8 MB is cut in the error line (errors.shown),
    and the refusal takes about as long as parsing the file (a 60 MB material name gave a 60 MB
    line after 78 s; folding its case once per conductor name took seconds)."""
    import time

    big = "m" * (8 << 20)
    cases = {
        "id": f'<shape type="cube"><bsdf type="hair" id="{big}"/></shape>',
        "type": f'<shape type="cube"><bsdf type="{big}"/></shape>',
        "property": f'<shape type="cube"><float name="{big}" value="1"/></shape>',
        "ref": f'<shape type="cube"><ref id="{big}"/></shape>',
        "duplicate": f'<bsdf type="diffuse" id="{big}"/><bsdf type="diffuse" id="{big}"/>',
        "parameter": f'<shape type="cube" id="${big}"/>',
        "attribute": f'<shape type="cube" {big}="1"/>',
        "conductor": f'<shape type="cube"><bsdf type="conductor"><string name="material" value="{big}"/>'
                     '</bsdf></shape>',
        "ior": f'<shape type="cube"><bsdf type="plastic"><string name="int_ior" value="{big}"/></bsdf>'
               '</shape>',
        "number": f'<shape type="sphere"><float name="radius" value="{big}"/></shape>',
        "include": f'<include filename="{big}"/>',
        "mesh": f'<shape type="obj"><string name="filename" value="{big}"/></shape>',
        "tag": f"<{big}/>",
        "version": None,
    }
    for name, body in cases.items():
        path = tmp_path / f"{name}.xml"
        path.write_text(f'<scene version="3.{big}.0"/>' if body is None else
                        f'<scene version="3.0.0">{SENSOR}{body}</scene>')
        start = time.perf_counter()
        with pytest.raises(InputError) as caught:
            load_scene(path)
        seconds = time.perf_counter() - start
        message = str(caught.value)
        # (at most the path, the element, 80 characters of the name and a list of Mitsuba's names)
        assert "\n" not in message and len(message) < 1000 and "mmmm" in message, (name, message[:1100])
        assert seconds < 10, (name, seconds)  # parsing 8 MB with expat takes about 0.3 s


def test_hostile_documents_are_refused_in_one_line(tmp_path):
    """Found by an adversarial run: an unknown encoding (expat raised LookupError), $name
    defaults that double at every step (a billion laughs without entities: memory ran away),
    an include name too long for the file system (OSError) and a version of 5000 digits
    (Python's integer-digit limit) each give InputError in one line, quickly."""
    cases = {
        "encoding": ('<?xml version="1.0" encoding="klingon"?><scene version="3.0.0"/>', ["klingon"]),
        "laughs": ('<scene version="3.0.0"><default name="a0" value="xxxxxxxxxx"/>'
                   + "".join(f'<default name="a{i + 1}" value="$a{i}$a{i}"/>' for i in range(40))
                   + "</scene>", ["longer than", "$names"]),
        "long include": (f'<scene version="3.0.0"><include filename="{"a" * 5000}.xml"/></scene>',
                         ["cannot look up the included file"]),
        "long version": (f'<scene version="3{"0" * 5000}.0.0"/>', ["not of the form major.minor.patch"]),
    }
    for name, (text, words) in cases.items():
        path = tmp_path / f"{name.replace(' ', '_')}.xml"
        path.write_text(text)
        with pytest.raises(InputError) as caught:
            load_scene(path)
        message = str(caught.value)
        assert "\n" not in message and len(message) < 400, message
        for word in words:
            assert word in message, (name, message)


def test_the_direct_integrator_is_not_reported_as_not_obeyed(tmp_path):
    """`<integrator type="direct">` is what tracer renders: a scene that asks for it gets no note
    (it used to say "not obeyed" for it); any other integrator still does (test above)."""
    path = write(tmp_path, '<integrator type="direct"/>\n<shape type="rectangle">' + EMIT + "</shape>")
    notes: list[str] = []
    load_scene(path, notify=notes.append)
    assert notes == []


def test_parameters_define_names_as_mitsubas_dash_d(tmp_path):
    """``parameters`` (the command line's ``-D NAME=VALUE``) define a scene's ``$names`` over
    its ``<default>``s, as Mitsuba's -D does; a scene that uses an undefined one is refused
    without them and reads with them; a TOML scene refuses them."""
    load_scene = tracer.load_scene
    path = tmp_path / "scene.xml"
    path.write_text('<scene version="3.0.0"><default name="fov" value="30"/>'
                    '<sensor type="perspective"><float name="fov" value="$fov"/>'
                    '<sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>'
                    '</sensor></scene>')
    with pytest.raises(InputError, match=r"undefined parameter \$spp"):
        load_scene(str(path))
    scene = load_scene(str(path), parameters={"spp": "7", "fov": "50"})
    assert scene.render_defaults["spp"] == 7
    assert load_scene(str(path), parameters={"spp": "7"}).camera.fov != scene.camera.fov
    toml = tmp_path / "scene.toml"
    toml.write_text('[camera]\norigin = [0, 0, 1]\ntarget = [0, 0, 0]\nup = [0, 1, 0]\nfov = 40\n')
    with pytest.raises(InputError, match="for Mitsuba XML scenes"):
        load_scene(str(toml), parameters={"spp": "7"})
