"""Measure, with Mitsuba 3, the facts tests/test_mitsuba_xml.py checks tracer's XML reader against.

Run with a Python that has Mitsuba 3.9.1 (``pip install mitsuba==3.9.1``)::

    python benchmarks/mitsuba_reader_facts.py > facts.json

It loads small scenes in the ``scalar_rgb`` variant and prints, as JSON: the ray directions
of perspective sensors at film positions (every ``fov_axis``, ``focal_length``, look-at,
matrix and mirrored transforms, a 2:1 and a 9:16 film), the origins and directions of
orthographic and thin-lens sensors' rays at film positions and lens samples, the ``to_world`` matrices of
transform snippets, the linear sRGB Mitsuba makes of spectra (reflectance, eta, emitter) and
the side each shape emits from after mirroring and flipping. The test file holds the numbers
this printed (tracer's tests do not need Mitsuba).
"""

from __future__ import annotations

import json
import os
import tempfile

import mitsuba as mi

mi.set_variant("scalar_rgb")
mi.set_log_level(mi.LogLevel.Error)  # its out-of-gamut warnings go to stdout, into the JSON

LOOKAT = '<lookat origin="1, 2, 3" target="0.2, 0.5, -1" up="0.1, 1, 0.2"/>'
def _fov(degrees: float, axis: str | None = None) -> str:
    axis_property = f'<string name="fov_axis" value="{axis}"/>' if axis else ""
    return f'<float name="fov" value="{degrees}"/>{axis_property}'

# name: (sensor properties, to_world operations, width, height)
CAMERAS = {
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

# Sensors with a lens or parallel rays: name -> (type, properties, to_world operations, width,
# height); their rays' origins and directions at FILM_POSITIONS x APERTURE_SAMPLES. The thin
# lenses' near_clip is tiny: Mitsuba starts their rays on the near plane, tracer at the lens.
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
APERTURE_SAMPLES = [(0.5, 0.5), (0.9, 0.3), (0.2, 0.75)]

TRANSFORMS = [
    '<translate x="1"/><scale value="2"/>',
    '<scale value="2"/><translate x="1"/>',
    '<rotate z="1" angle="90"/>',
    '<rotate x="1" angle="90"/><translate y="3"/>',
    '<rotate x="1" y="1" angle="30"/>',
    '<matrix value="1 2 3 4 5 6 7 8 9 10 11 12 0 0 0 1"/>',
    '<matrix value="1 2 3 4 5 6 7 8 9"/>',
    '<scale x="2" y="3"/>',
    '<translate value="1 2 3"/>',
    '<translate value="2"/>',
    '<lookat origin="0, 0, 0" target="1, 0, 0" up="0, 0, 1"/>',
    '<lookat origin="0, 0, 0" target="0, 0, 1"/>',
    '<lookat origin="1, 2, 3" target="1, 2.5, 3.2"/>',
]

SPECTRA = ["0.5", "2", "400:0.5, 700:0.5", "360:1, 830:1", "450:0.2, 550:0.8, 650:0.3", "500:1, 600:0",
           "400:2, 700:2", "400:2, 500:6, 600:9, 700:4", "400:0.1, 500:0.5, 600:0.8, 700:0.3",
           "380:0.9, 480:0.05, 780:0.6"]


def load(body: str):
    return mi.load_string(f'<scene version="3.0.0">{body}</scene>')


def cameras() -> dict:
    out = {}
    for name, (props, ops, w, h) in CAMERAS.items():
        scene = load(f'<sensor type="perspective">{props}<transform name="to_world">{ops}</transform>'
                     f'<film type="hdrfilm"><integer name="width" value="{w}"/>'
                     f'<integer name="height" value="{h}"/></film></sensor>')
        sensor = scene.sensors()[0]
        rays = [sensor.sample_ray(0.0, 0.5, mi.Point2f(*uv), mi.Point2f(0.5, 0.5))[0]
                for uv in FILM_POSITIONS]
        out[name] = [[round(float(c), 7) for c in ray.d] for ray in rays]
    return out


def lens_cameras() -> dict:
    out = {}
    for name, (kind, props, ops, w, h) in LENS_CAMERAS.items():
        scene = load(f'<sensor type="{kind}">{props}<transform name="to_world">{ops}</transform>'
                     f'<film type="hdrfilm"><integer name="width" value="{w}"/>'
                     f'<integer name="height" value="{h}"/></film></sensor>')
        sensor = scene.sensors()[0]
        rays = [sensor.sample_ray(0.0, 0.5, mi.Point2f(*uv), mi.Point2f(*lens))[0]
                for uv in FILM_POSITIONS for lens in APERTURE_SAMPLES]
        out[name] = [[[round(float(c), 7) for c in ray.o], [round(float(c), 7) for c in ray.d]]
                     for ray in rays]
    return out


def transforms() -> dict:
    out = {}
    for ops in TRANSFORMS:
        scene = load(f'<shape type="rectangle" id="r"><transform name="to_world">{ops}</transform></shape>')
        matrix = mi.traverse(scene)["r.to_world"].matrix
        out[ops] = [[round(float(matrix[i][j]), 6) for j in range(4)] for i in range(3)]
    return out


def spectra() -> dict:
    out = {}
    for value in SPECTRA:
        scene = load(f'<bsdf type="diffuse" id="d"><spectrum name="reflectance" value="{value}"/></bsdf>'
                     f'<bsdf type="conductor" id="c"><spectrum name="eta" value="{value}"/></bsdf>'
                     f'<emitter type="point" id="p"><spectrum name="intensity" value="{value}"/></emitter>')
        params = mi.traverse(scene)

        def rgb(key, params=params):
            v = params[key]
            return [round(float(c), 6) for c in v] if hasattr(v, "__len__") else [round(float(v), 6)] * 3

        out[value] = {"reflectance": rgb("d.reflectance.value"), "eta": rgb("c.eta.value"),
                      "emitter": rgb("p.intensity.value")}
    return out


def fronts(folder: str) -> dict:
    """The side (+1: +z, -1: -z) from which each shape emits, seen along z at (-0.2, 0.2)
    (x mirrored shapes) or (0.3, 0.2) (the others); for the cube, whether its top face emits
    outward (+1, seen from z = 5) or inward (-1, seen from its centre)."""
    with open(os.path.join(folder, "normals.obj"), "w") as fh:
        fh.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n")
    with open(os.path.join(folder, "plain.obj"), "w") as fh:
        fh.write("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    mirror = '<transform name="to_world"><scale x="-1"/></transform>'
    flip = '<boolean name="flip_normals" value="true"/>'
    face = '<boolean name="face_normals" value="true"/>'
    cases = {
        "rectangle": ("rectangle", ""), "rectangle mirrored": ("rectangle", mirror),
        "rectangle flipped": ("rectangle", flip), "rectangle mirrored flipped": ("rectangle", mirror + flip),
        "disk mirrored": ("disk", mirror), "cube mirrored": ("cube", mirror),
        "cube mirrored flipped": ("cube", mirror + flip),
        "obj with normals, mirrored": ("obj normals.obj", mirror),
        "obj with normals, mirrored, flipped": ("obj normals.obj", mirror + flip),
        "obj with normals, mirrored, face_normals": ("obj normals.obj", mirror + face),
        "obj without normals, mirrored": ("obj plain.obj", mirror),
    }
    out = {}
    for name, (kind, extra) in cases.items():
        kind, _, filename = kind.partition(" ")
        file_prop = f'<string name="filename" value="{os.path.join(folder, filename)}"/>' if filename else ""
        scene = load(f'<shape type="{kind}">{file_prop}{extra}'
                     '<emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>')
        x = -0.2 if "mirrored" in name else 0.3
        lit = []
        for z in (5.0, 0.0 if kind == "cube" else -5.0):
            si = scene.ray_intersect(mi.Ray3f(mi.Point3f(x, 0.2, z), mi.Vector3f(0, 0, -1 if z > 0 else 1)))
            lit.append(float(si.emitter(scene).eval(si)[0]) > 0.0)
        out[name] = 1 if lit[0] and not lit[1] else -1 if lit[1] and not lit[0] else 0
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        facts = {"version": mi.__version__, "cameras": cameras(), "lens_cameras": lens_cameras(),
                 "transforms": transforms(),
                 "spectra": spectra(), "fronts": fronts(folder)}
    print(json.dumps(facts, indent=1))


if __name__ == "__main__":
    main()
