"""Mitsuba's ``mesh_attribute`` texture: PLY properties as material parameters.

What is compared: Mitsuba's grouping of PLY properties into attributes (its documented rules,
src/shapes/ply.cpp), the corner values of a fan-triangulated PLY as written in the file, and the
radiance of a diffuse square textured by a vertex and a face attribute under a directional
light, ray by ray, against the closed form rho E cos / pi with rho interpolated by barycentrics
written out here for the square's two fan triangles. The light is a delta light and the
strategy samples only it, so each ray's radiance is exact (no Monte Carlo noise): the bound is
float32 storage of the attribute (relative 2^-24 per value, a few of them summed).
Refusals (a shape without the attribute, faces of mixed sizes, four channels) are one line.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

import tracer
from tracer import cli
from tracer.estimator import DirectLighting
from tracer.scene.mesh import _ply_groups, read_mesh_file
from tracer.strategy import Strategy

SQUARE = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
VERTEX_RGB = np.array([[0.9, 0.1, 0.2], [0.2, 0.8, 0.1], [0.1, 0.3, 0.7], [0.6, 0.6, 0.05]])
FACE_WEIGHT = 0.35
IRRADIANCE = 2.0


def ply(path, faces=((0, 1, 2, 3),), face_props=("weight_0",), face_values=None):
    """An ASCII PLY of the unit square in z = 0 with float vertex colours r, g, b and one face
    property per name in ``face_props``."""
    header = ["ply", "format ascii 1.0", f"element vertex {len(SQUARE)}"]
    header += [f"property float {name}" for name in ("x", "y", "z", "r", "g", "b")]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    header += [f"property float {name}" for name in face_props]
    header.append("end_header")
    lines = [" ".join(str(v) for v in (x, y, 0.0, *VERTEX_RGB[i])) for i, (x, y) in enumerate(SQUARE)]
    for k, face in enumerate(faces):
        values = face_values[k] if face_values is not None else [FACE_WEIGHT] * len(face_props)
        lines.append(" ".join(str(v) for v in (len(face), *face, *values)))
    path.write_text("\n".join(header + lines) + "\n")
    return path


def scene_xml(tmp_path, attribute: str, shape: str = '<string name="filename" value="square.ply"/>',
              shape_type: str = "ply") -> str:
    ply(tmp_path / "square.ply")
    path = tmp_path / "scene.xml"
    path.write_text(textwrap.dedent(f"""\
        <scene version="3.0.0">
            <sensor type="perspective">
                <float name="fov" value="40"/>
                <transform name="to_world">
                    <lookat origin="0.5, 0.5, 3" target="0.5, 0.5, 0" up="0, 1, 0"/>
                </transform>
                <film type="hdrfilm">
                    <integer name="width" value="8"/><integer name="height" value="8"/>
                </film>
            </sensor>
            <emitter type="directional">
                <vector name="direction" value="0, 0, -1"/>
                <rgb name="irradiance" value="{IRRADIANCE}"/>
            </emitter>
            <shape type="{shape_type}">
                {shape}
                <bsdf type="twosided"><bsdf type="diffuse">
                    <texture type="mesh_attribute" name="reflectance">
                        <string name="name" value="{attribute}"/>
                    </texture>
                </bsdf></bsdf>
            </shape>
        </scene>"""))
    return str(path)


def test_ply_properties_group_as_mitsuba_groups_them():
    """Mitsuba's rules: r, g, b (or red, green, blue) make ``color``; consecutive
    {prefix}_{x|y|z}, _{r|g|b}, _{0|1|2}, _{1|2|3} fields make {prefix} ({prefix}_color for
    r, g, b), with 1 or 3 fields; fields without a one-letter postfix, a broken sequence (s_x,
    s_z: the whole attribute, and s_y after it) and two-field groups are left out."""
    names = ["red", "green", "blue", "n_x", "n_y", "n_z", "w_0", "c_r", "c_g", "c_b", "bad", "k_1", "k_2",
             "q_1", "long_xy", "s_x", "s_z", "s_y"]
    assert _ply_groups(names) == [("color", ["red", "green", "blue"]), ("n", ["n_x", "n_y", "n_z"]),
                                  ("w", ["w_0"]), ("c_color", ["c_r", "c_g", "c_b"]), ("q", ["q_1"])]


def test_a_quad_face_and_its_vertices_give_each_fan_triangle_its_corners(tmp_path):
    """The square's one quad face becomes triangles (0, 1, 2) and (0, 2, 3), Mitsuba's fan: the
    vertex colour at each triangle's corners is the file's colour of those vertices, the face's
    weight is on all six corners. Exact: the file's float32 values, read as float64."""
    mesh = read_mesh_file(ply(tmp_path / "square.ply"))
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    expected = VERTEX_RGB.astype(np.float32).astype(np.float64)[mesh.faces]
    np.testing.assert_array_equal(mesh.attributes["vertex_color"], expected)
    np.testing.assert_array_equal(mesh.attributes["face_weight"],
                                  np.full((2, 3, 1), np.float32(FACE_WEIGHT), dtype=np.float64))


def _rho_vertex(x: float, y: float) -> np.ndarray:
    """The vertex colour at (x, y) of the square: triangle (0, 1, 2) holds y <= x, where
    (x, y) = b1 v1 + b2 v2 gives b1 = x - y, b2 = y; triangle (0, 2, 3) the rest, b1 = x,
    b2 = y - x (each with b0 = 1 - b1 - b2)."""
    c = VERTEX_RGB.astype(np.float32).astype(np.float64)
    if y <= x:
        b1, b2, corners = x - y, y, (0, 1, 2)
    else:
        b1, b2, corners = x, y - x, (0, 2, 3)
    return (1.0 - b1 - b2) * c[corners[0]] + b1 * c[corners[1]] + b2 * c[corners[2]]


@pytest.mark.parametrize("attribute", ["vertex_color", "face_weight"])
def test_radiance_is_the_interpolated_attribute_times_the_closed_form(tmp_path, attribute):
    """Rays at 50 points of the square (off its diagonal by more than rounding) under a
    directional light of irradiance E along -z: L = rho E / pi (cos = 1), rho the vertex colour
    interpolated as :func:`_rho_vertex` says, or the face weight as grey. Both sides use the
    same float32 values; what differs is the rounding of the hit point and of the barycentrics
    computed from it (a few float32 ulps of the unit square's coordinates, ~1e-7): relative
    1e-6."""
    scene = tracer.load_scene(scene_xml(tmp_path, attribute))
    gen = np.random.default_rng(11)
    points = np.column_stack([gen.uniform(0.02, 0.98, (200, 2)), np.zeros(200)])
    points = points[np.abs(points[:, 0] - points[:, 1]) > 1e-3][:50]
    origins = points + np.array([0.1, -0.2, 1.0])
    dirs = (points - origins) / np.linalg.norm(points - origins, axis=1, keepdims=True)
    radiance = DirectLighting(scene, Strategy("light")).radiance(origins, dirs, seed=3)
    if attribute == "vertex_color":
        rho = np.array([_rho_vertex(x, y) for x, y, _ in points])
    else:
        rho = np.full((len(points), 3), float(np.float32(FACE_WEIGHT)))
    np.testing.assert_allclose(radiance, rho * IRRADIANCE / math.pi, rtol=1e-6)


def _refusal(capsys, path: str) -> str:
    assert cli.main(["render", path, "-o", path + ".exr"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracer: error: "), lines
    return lines[0]


def test_a_shape_without_the_attribute_is_refused_in_one_line(tmp_path, capsys):
    """A mesh without the named attribute, and an analytic sphere (which has none), are refused
    naming the shape, the attribute and what the shape has."""
    line = _refusal(capsys, scene_xml(tmp_path, "vertex_albedo"))
    assert "no mesh attribute 'vertex_albedo'" in line and "face_weight, vertex_color" in line
    line = _refusal(capsys, scene_xml(tmp_path, "vertex_color", shape="", shape_type="sphere"))
    assert "shape 1 (sphere) has no mesh attribute 'vertex_color'" in line


def test_faces_of_mixed_sizes_with_a_face_attribute_are_refused(tmp_path, capsys):
    """trimesh groups faces of different sizes, which would mix up a face attribute's faces:
    such a file is refused with a face attribute, in one line naming it."""
    path = scene_xml(tmp_path, "face_weight")  # its square.ply replaced by one of mixed faces:
    ply(tmp_path / "square.ply", faces=((0, 1, 2), (0, 2, 3, 1)), face_values=[[0.1], [0.2]])
    line = _refusal(capsys, path)
    assert "square.ply" in line and "faces of one size" in line


def test_a_one_number_lookup_of_a_colour_attribute_is_zero_as_in_mitsuba():
    """Mitsuba's ``eval_1`` of an attribute without exactly one channel is 0: the texture's
    one-number mean is then 0, its three-number mean the corners' mean."""
    from tracer.textures import Texture

    texture = Texture("mesh_attribute", attribute="vertex_color")
    texture.resolve(np.tile(VERTEX_RGB[:3], (2, 1, 1)), np.array([True, True]), 3)
    assert texture.mean(1).tolist() == [0.0]
    np.testing.assert_allclose(texture.mean(3), VERTEX_RGB[:3].astype(np.float32).mean(axis=0), rtol=1e-7)


def test_a_colour_attribute_as_an_opacity_is_told(tmp_path, capsys):
    """A mask's opacity is one number: fed the three-channel vertex colour it reads 0 (fully
    cut out), as Mitsuba does, and the reader says so in its note line; the render succeeds."""
    path = tmp_path / "mask.xml"
    text = open(scene_xml(tmp_path, "vertex_color")).read()
    start, end = text.index('<bsdf type="twosided">'), text.index("</bsdf></bsdf>") + len("</bsdf></bsdf>")
    path.write_text(text[:start] + '<bsdf type="mask"><texture type="mesh_attribute" name="opacity">'
                    '<string name="name" value="vertex_color"/></texture><bsdf type="diffuse"/></bsdf>'
                    + text[end:])
    assert cli.main(["render", str(path), "-o", str(tmp_path / "m.exr"), "--spp", "1"]) == 0
    err = capsys.readouterr().err
    assert "reads the 3-channel mesh attribute 'vertex_color' as 0, as Mitsuba's eval_1 does" in err, err
