"""The scene format's declared keys (tracer/scene/keys.py) and the reader agree: every declared
key of every table is accepted, and a typo names the key the file has and the one it meant.
The reader raising for keys it reads but which are not declared is exercised by every scene
the suite loads. Not statistical."""

import pytest

from tracer import load_scene
from tracer.errors import InputError
from tracer.scene import keys

CAMERA = {"origin": [0, 1, 4], "target": [0, 1, 0], "up": [0, 1, 0], "fov": 40, "width": 8, "height": 6,
          "mirrored": False, "projection": "perspective", "aperture_radius": 0.1, "focus_distance": 4.0}
# The orthographic camera's own key (its projection excludes fov and the lens).
ORTHOGRAPHIC = {"origin": [0, 1, 4], "target": [0, 1, 0], "projection": "orthographic", "view_width": 3.0}


def every_key_scene(tmp_path):
    """A scene that gives every declared key of every table (a mesh file for the mesh keys)."""
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    import OpenImageIO as oiio

    image = oiio.ImageBuf(oiio.ImageSpec(2, 2, 3, oiio.UINT8))
    assert image.write(str(tmp_path / "t.png"))
    common = {"material": "m", "emission": [0, 0, 0]}
    return {
        "render": {"spp": 4, "strategy": "mis", "light_sampling": "area", "sampler": "independent"},
        "camera": CAMERA,
        "materials": {
            "m": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5], "twosided": True, "opacity": 0.75},
            "checks": {"type": "diffuse", "reflectance": {"texture": "checkerboard", "color0": 0.9,
                                                          "color1": [0.1, 0.2, 0.3], "to_uv": [[2, 0, 0], [0, 2, 0]]}},
            "image": {"type": "diffuse", "reflectance": {"texture": "bitmap", "file": "t.png", "raw": True,
                                                         "filter": "nearest", "wrap": "clamp"}},
            "tilted": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5],
                       "normal_map": {"texture": "bitmap", "file": "t.png", "raw": True}},
            "bumpy": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5],
                      "bump_map": {"texture": "bitmap", "file": "t.png"}, "bump_scale": 0.1,
                      "flip_invalid_normals": False, "use_shadowing_function": False}},
        "shapes": [
            {"type": "quad", "origin": [0, 0, 0], "edge1": [1, 0, 0], "edge2": [0, 0, -1],
             "uv": [[0, 0], [2, 0], [2, 2], [0, 2]], **common},
            {"type": "sphere", "center": [0, 1, 0], "radius": 0.5, "subdivisions": 1, **common},
            {"type": "sphere", "center": [0, 3, 0], "radius": 0.5, "uv_frame": [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
             **common},
            {"type": "mesh", "file": mesh.name, "normals": "vertex", "flip_v": True, **common},
        ],
        "lights": [{"type": "point", "position": [0, 2, 0], "intensity": [1, 1, 1]},
                   {"type": "spot", "position": [0, 2, 0], "intensity": [1, 1, 1], "direction": [0, -1, 0],
                    "cutoff_angle": 30.0, "beam_width": 10.0},
                   {"type": "directional", "direction": [0, -1, 0], "irradiance": [1, 1, 1]}],
        # radiance (a constant environment) excludes map: tests/test_environment.py reads it
        "environment": {"map": "t.png", "scale": 2.0, "to_world": [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]},
    }


def test_every_declared_key_is_read(tmp_path):
    doc = every_key_scene(tmp_path)
    given = {"top level": set(doc), "[render]": set(doc["render"]), "[camera]": set(CAMERA) | set(ORTHOGRAPHIC),
             "[materials.NAME]": {"type", "twosided", "opacity", "normal_map", "bump_map", "bump_scale",
                                  "flip_invalid_normals", "use_shadowing_function"},
             "a material parameter's texture": {key for m in doc["materials"].values()
                                                for value in m.values() if isinstance(value, dict) for key in value}}
    for shape in doc["shapes"]:
        given.setdefault(f'[[shapes]] type = "{shape["type"]}"', set()).update(shape)
    for light in doc["lights"]:
        given[f'[[lights]] type = "{light["type"]}"'] = set(light)
    given["[environment]"] = set(doc["environment"]) | {"radiance"}
    for section in keys.SECTIONS:  # the scene above really gives every declared key
        assert set(section.names()) == given[section.header], section.header
    load_scene(doc, base_dir=tmp_path)
    assert load_scene({**doc, "camera": ORTHOGRAPHIC}, base_dir=tmp_path).camera.view_width == 3.0


@pytest.mark.parametrize("table, typo, meant, message", [
    ("camera", "fov_y", "fov", "camera.fov: missing required key (the table has 'fov_y', which is not a key"),
    ("camera", "widht", "width", "camera.widht: unknown key 'widht' (did you mean 'width'?)"),
    ("material", "reflectanse", "reflectance",
     "materials.m.reflectance: missing required key (the table has 'reflectanse'"),
    ("material", "twosidded", "twosided",
     "materials.m.twosidded: unknown key 'twosidded' (did you mean 'twosided'?)"),
    ("shape", "radious", "radius", "shapes[0].radius: missing required key (the table has 'radious'"),
])
def test_a_typo_names_the_key_given_and_the_key_meant(table, typo, meant, message):
    doc = {"camera": dict(CAMERA), "materials": {"m": {"type": "diffuse", "reflectance": [1, 1, 1]}},
           "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0}]}
    where = {"camera": doc["camera"], "material": doc["materials"]["m"], "shape": doc["shapes"][0]}[table]
    where[typo] = where.pop(meant, True)
    with pytest.raises(InputError) as caught:
        load_scene(doc)
    assert message in str(caught.value)
