"""Mitsuba 0.x and 1.x scenes, read after the upgrade Mitsuba 3 applies (tracer/scene/mitsuba_upgrade.py).

The rules are Mitsuba 3.9.1's (src/core/parser.cpp, ``upgrade_from_v1``): each file whose
``<scene version>`` is below 2.0.0 has its property names turned from camelCase to snake_case,
and a diffuse BSDF's ``diffuse_reflectance`` becomes ``reflectance``. OLD_SCENE and NEW_SCENE
below were both loaded with Mitsuba 3.9.1 (``scalar_rgb``) and gave the same parameters
(``mi.traverse``); what Mitsuba 3.9.1 refuses in an old file (``<lookAt>``, ``<srgb>``,
``<blackbody>``, ``#rrggbb``, ``ldrfilm``, a renamed property whose new name is taken) it
refused there too. These tests do not need Mitsuba.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tracer.errors import InputError, shown
from tracer.scene import load_scene
from tracer.scene.mitsuba_upgrade import snake_case

MESH = Path(__file__).parent / "data" / "xml" / "meshes" / "tri_normals.obj"

# A Mitsuba 0.6 scene, with 0.6's names, and below it the same scene as written for Mitsuba 3.
OLD_SCENE = """<?xml version="1.0" encoding="utf-8"?>
<scene version="0.6.0">
    <integrator type="direct">
        <integer name="emitterSamples" value="2"/>
        <integer name="bsdfSamples" value="2"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="35"/>
        <string name="fovAxis" value="y"/>
        <float name="shutterClose" value="0.5"/>
        <transform name="toWorld">
            <lookat origin="0, 1, 6" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sampleCount" value="32"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="40"/>
            <integer name="height" value="30"/>
            <boolean name="banner" value="false"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="wall">
        <rgb name="diffuseReflectance" value="0.6, 0.5, 0.4"/>
    </bsdf>
    <bsdf type="plastic" id="shiny">
        <rgb name="diffuseReflectance" value="0.2, 0.3, 0.7"/>
        <float name="intIOR" value="1.6"/>
        <string name="extIOR" value="air"/>
        <boolean name="nonlinear" value="true"/>
    </bsdf>
    <bsdf type="roughconductor" id="metal">
        <string name="material" value="Au"/>
        <string name="distribution" value="ggx"/>
        <float name="alphaU" value="0.2"/>
        <float name="alphaV" value="0.2"/>
        <rgb name="specularReflectance" value="0.9"/>
    </bsdf>
    <shape type="rectangle">
        <transform name="toWorld">
            <scale value="3"/><rotate x="1" angle="-90"/><translate y="-1"/>
        </transform>
        <ref id="wall"/>
    </shape>
    <shape type="sphere">
        <point name="center" x="-1" y="0" z="0"/>
        <float name="radius" value="0.5"/>
        <ref id="shiny"/>
    </shape>
    <shape type="obj">
        <string name="filename" value="tri_normals.obj"/>
        <boolean name="faceNormals" value="true"/>
        <boolean name="flipNormals" value="true"/>
        <transform name="toWorld"><translate x="1"/></transform>
        <ref id="metal"/>
    </shape>
    <shape type="cube">
        <transform name="toWorld"><scale value="0.3"/><translate y="2"/></transform>
        <emitter type="area">
            <rgb name="radiance" value="5"/>
            <float name="samplingWeight" value="2"/>
        </emitter>
    </shape>
    <emitter type="point">
        <spectrum name="intensity" value="400:2, 700:4"/>
        <point name="position" x="2" y="3" z="2"/>
    </emitter>
</scene>
"""

NEW_SCENE = """<?xml version="1.0" encoding="utf-8"?>
<scene version="3.0.0">
    <integrator type="direct">
        <integer name="emitter_samples" value="2"/>
        <integer name="bsdf_samples" value="2"/>
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="35"/>
        <string name="fov_axis" value="y"/>
        <float name="shutter_close" value="0.5"/>
        <transform name="to_world">
            <lookat origin="0, 1, 6" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="32"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="40"/>
            <integer name="height" value="30"/>
            <boolean name="banner" value="false"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="wall">
        <rgb name="reflectance" value="0.6, 0.5, 0.4"/>
    </bsdf>
    <bsdf type="plastic" id="shiny">
        <rgb name="diffuse_reflectance" value="0.2, 0.3, 0.7"/>
        <float name="int_ior" value="1.6"/>
        <string name="ext_ior" value="air"/>
        <boolean name="nonlinear" value="true"/>
    </bsdf>
    <bsdf type="roughconductor" id="metal">
        <string name="material" value="Au"/>
        <string name="distribution" value="ggx"/>
        <float name="alpha_u" value="0.2"/>
        <float name="alpha_v" value="0.2"/>
        <rgb name="specular_reflectance" value="0.9"/>
    </bsdf>
    <shape type="rectangle">
        <transform name="to_world">
            <scale value="3"/><rotate x="1" angle="-90"/><translate y="-1"/>
        </transform>
        <ref id="wall"/>
    </shape>
    <shape type="sphere">
        <point name="center" x="-1" y="0" z="0"/>
        <float name="radius" value="0.5"/>
        <ref id="shiny"/>
    </shape>
    <shape type="obj">
        <string name="filename" value="tri_normals.obj"/>
        <boolean name="face_normals" value="true"/>
        <boolean name="flip_normals" value="true"/>
        <transform name="to_world"><translate x="1"/></transform>
        <ref id="metal"/>
    </shape>
    <shape type="cube">
        <transform name="to_world"><scale value="0.3"/><translate y="2"/></transform>
        <emitter type="area">
            <rgb name="radiance" value="5"/>
            <float name="sampling_weight" value="2"/>
        </emitter>
    </shape>
    <emitter type="point">
        <spectrum name="intensity" value="400:2, 700:4"/>
        <point name="position" x="2" y="3" z="2"/>
    </emitter>
</scene>
"""

SENSOR = ('<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm">'
          '<integer name="width" value="8"/><integer name="height" value="6"/></film></sensor>')


def scene_file(folder: Path, text: str, name: str = "scene.xml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(MESH, folder / MESH.name)
    path = folder / name
    path.write_text(text)
    return path


def old_scene(tmp_path: Path, body: str, version: str = "0.6.0", name: str = "scene.xml") -> Path:
    """A scene file of ``version``: line 1 <scene>, line 2 a sensor (nothing if ``body`` has
    its own), ``body`` from line 3."""
    sensor = "" if "<sensor" in body else SENSOR
    text = f'<scene version="{version}">\n{sensor}\n{body}\n</scene>\n'
    return scene_file(tmp_path, text, name)


def refusal(path: Path) -> str:
    with pytest.raises(InputError) as caught:
        load_scene(path)
    message = str(caught.value)
    assert "\n" not in message and "Traceback" not in message
    return message


def test_a_mitsuba_06_scene_is_its_mitsuba_3_equivalent(tmp_path):
    """camelCase names (toWorld, fovAxis, sampleCount, intIOR, alphaU, faceNormals, ...) and a
    diffuse's diffuseReflectance read as Mitsuba 3 upgrades them: the same scene digest,
    film size and spp as the scene written with Mitsuba 3's names, and one note more."""
    old_notes: list[str] = []
    new_notes: list[str] = []
    old = load_scene(scene_file(tmp_path / "old", OLD_SCENE), notify=old_notes.append)
    new = load_scene(scene_file(tmp_path / "new", NEW_SCENE), notify=new_notes.append)
    assert old.digest == new.digest
    assert (old.camera.width, old.camera.height) == (new.camera.width, new.camera.height) == (40, 30)
    assert old.render_defaults == new.render_defaults == {"spp": 32}
    assert new_notes == []
    assert len(old_notes) == 1 and "\n" not in old_notes[0], old_notes
    note = old_notes[0]
    for words in ("scene.xml: upgraded from version 0.6.0", "as Mitsuba 3 upgrades",
                  "emitterSamples -> emitter_samples", "and 12 more"):
        assert words in note, note


def test_the_upgrade_is_told_once_per_load_and_once_on_the_command_line(tmp_path):
    """Every load tells the upgrade in one line (beside the line of what is not obeyed); the
    command line prints it once, however often the command loads the scene."""
    path = old_scene(tmp_path, '<integrator type="path"><integer name="maxDepth" value="3"/></integrator>\n'
                               '<shape type="rectangle"><emitter type="area"/></shape>')
    lines: list[str] = []
    load_scene(path, notify=lines.append)
    assert len(lines) == 2 and "upgraded from version 0.6.0" in lines[0], lines
    assert "maxDepth -> max_depth" in lines[0] and '<integrator type="path">' in lines[1], lines
    load_scene(path, notify=lines.append)
    assert lines[2:] == lines[:2]
    argv = [sys.executable, "-m", "tracer", "convert", str(path), "-o", str(tmp_path / "s.toml")]
    run = subprocess.run(argv, capture_output=True, text=True)
    notes = [line for line in run.stderr.splitlines() if line.startswith("tracer: note:")]
    assert run.returncode == 0 and len(notes) == 2, run.stderr
    assert sum("upgraded from version 0.6.0" in line for line in notes) == 1, notes


@pytest.mark.parametrize("version, upgraded", [("0.5.0", True), ("0.6.0", True), ("1.9.9", True),
                                               ("2.0.0", False), ("3.0.0", False)])
def test_versions_below_2_are_upgraded(tmp_path, version, upgraded):
    """Mitsuba upgrades a file whose version is below 2.0.0; in a 2.x or 3.x file a camelCase
    name stays as written, and no plugin reads it (Mitsuba: "unreferenced property")."""
    path = old_scene(tmp_path, '<shape type="sphere"><float name="radius" value="2"/>\n'
                               '<transform name="toWorld"><translate x="1"/></transform></shape>', version)
    if upgraded:
        lines: list[str] = []
        scene = load_scene(path, notify=lines.append)
        assert scene.spheres[0].tolist() == [1.0, 0.0, 0.0, 2.0]
        assert lines == [f"{path}: upgraded from version {version} as Mitsuba 3 upgrades older scenes; "
                         "property names renamed to Mitsuba 3's: toWorld -> to_world"]
    else:
        message = refusal(path)
        assert message.startswith(f'{path}:4: <transform name="toWorld"> in <shape type="sphere">: sphere '
                                  "has no property 'toWorld'"), message


@pytest.mark.parametrize("written, upgraded", [
    ("toWorld", "to_world"), ("sampleCount", "sample_count"), ("fovAxis", "fov_axis"),
    ("intIOR", "int_ior"), ("specularReflectance", "specular_reflectance"), ("alphaU", "alpha_u"),
    ("cropOffsetX", "crop_offset_x"), ("sRGB", "s_rgb"), ("to_World", "to_World"), ("fov", "fov"),
    ("already_snake", "already_snake"), ("aB1C", "a_b1C"), ("ABC", "ABC"), ("éA", "éA"),
])
def test_snake_case_is_mitsubas(written, upgraded):
    """Mitsuba's camel_to_underscore_case: an uppercase ASCII letter after a lowercase one
    starts a word, written as _ and the run of uppercase letters lowered."""
    assert snake_case(written) == upgraded


def test_uv_offsets_and_scales_become_mitsubas_to_uv(tmp_path):
    # Mitsuba 3 makes uoffset & co. the transform scale(uscale, vscale) translate(uoffset,
    # voffset): the 0.6 texture is the 3.0 one with that matrix, digest for digest.
    texture = ('<shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="checkerboard">'
               '{uv}</texture></bsdf></shape><emitter type="point"><point name="position" x="0" y="0" z="2"/>'
               '</emitter>')
    old = old_scene(tmp_path / "old", texture.format(
        uv='<float name="uoffset" value="0.25"/><float name="uscale" value="4"/><float name="vscale" value="2"/>'))
    new = old_scene(tmp_path / "new", texture.format(
        uv='<transform name="to_uv"><matrix value="4 0 0 1  0 2 0 0  0 0 1 0  0 0 0 1"/></transform>'),
        version="3.0.0")
    assert load_scene(old).digest == load_scene(new).digest
    assert load_scene(old).textures.textures[0].to_uv.tolist() == [[4.0, 0.0, 1.0], [0.0, 2.0, 0.0]]


def test_an_included_file_is_upgraded_by_its_own_version(tmp_path):
    """Mitsuba reads each file with its own version: a 0.6 file included by a 3.0 scene is
    upgraded, a 3.0 file included by a 0.6 scene is not."""
    (tmp_path / "old_part.xml").write_text('<scene version="0.6.0">\n<shape type="sphere">\n'
                                           '<transform name="toWorld"><translate x="1"/></transform>'
                                           '</shape></scene>')
    (tmp_path / "new_part.xml").write_text('<scene version="3.0.0">\n<shape type="sphere">\n'
                                           '<transform name="toWorld"><translate x="1"/></transform>'
                                           '</shape></scene>')
    lines: list[str] = []
    main = old_scene(tmp_path, '<include filename="old_part.xml"/>', "3.0.0")
    scene = load_scene(main, notify=lines.append)
    assert scene.spheres[0].tolist() == [1.0, 0.0, 0.0, 1.0]
    # The note names the included file as error lines name paths (``shown``: cut when long, as
    # pytest's temporary folders can be).
    named = shown(str(tmp_path / "old_part.xml"))
    assert len(lines) == 1 and f"upgraded from version 0.6.0 ({named})" in lines[0], lines
    message = refusal(old_scene(tmp_path, '<include filename="new_part.xml"/>', name="old.xml"))
    assert message.startswith(f'{tmp_path / "new_part.xml"}:3: <transform name="toWorld">'), message


def test_messages_name_the_line_and_the_name_as_written(tmp_path):
    """Renamed elements keep their lines; a message names the element as the file writes it
    and the property by its Mitsuba 3 name."""
    path = old_scene(tmp_path, '<shape type="cube"/>\n\n'
                               '<sensor type="perspective"><film type="hdrfilm">\n'
                               '<boolean name="highQualityEdges" value="true"/></film></sensor>')
    assert refusal(path) == (f'{path}:6: <boolean name="highQualityEdges"> in <film type="hdrfilm">: hdrfilm '
                             "has no property 'high_quality_edges' that tracer reads")
    twice = old_scene(tmp_path, '<shape type="sphere">\n<float name="radius" value="1"/>\n'
                                '<transform name="toWorld"/>\n<transform name="toWorld"/></shape>')
    assert "property 'to_world' is given twice (first at line 5)" in refusal(twice)


@pytest.mark.parametrize("body, words", [
    ('<shape type="sphere"><transform name="toWorld">\n<lookAt origin="0,0,1" target="0,0,0"/>'
     '</transform></shape>', ["scene.xml:4: <lookAt>:", "does not upgrade <lookAt>", "write <lookat>"]),
    ('<shape type="sphere"><bsdf type="diffuse">\n<srgb name="diffuseReflectance" value="0.2, 0.4, 0.6"/>'
     '</bsdf></shape>',
     ['scene.xml:4: <srgb name="diffuseReflectance">', "does not upgrade <srgb>",
      'write <rgb name="reflectance" value="0.0331048, 0.132868, 0.318547"/>']),
    ('<shape type="sphere"><bsdf type="diffuse">\n<srgb name="reflectance" value="#336699"/>'
     '</bsdf></shape>', ['value="0.0331048, 0.132868, 0.318547"']),
    ('<shape type="sphere"><bsdf type="diffuse">\n<srgb name="reflectance" value="pink"/></bsdf></shape>',
     ["scene.xml:4:", "give its linear values in <rgb>"]),
    ('<shape type="sphere"><bsdf type="diffuse">\n<rgb name="reflectance" value="#336699"/></bsdf></shape>',
     ["scene.xml:4:", "no #rrggbb colours", 'write value="0.2, 0.4, 0.6"']),
    ('<emitter type="point">\n<blackbody name="intensity" temperature="5000K"/></emitter>',
     ["scene.xml:4: <blackbody", "does not upgrade <blackbody>", "spectral variants only"]),
    ('<sensor type="perspective">\n<film type="ldrfilm"/></sensor>',
     ["scene.xml:4:", "film 'ldrfilm' is not supported", "Mitsuba 3 has none"]),
    ('<shape type="sphere"><bsdf type="diffuse">\n<rgb name="reflectance" intent="illuminant" value="1"/>'
     '</bsdf></shape>', ["scene.xml:4:", "unexpected attribute 'intent'"]),
    ('<shape type="sphere"><bsdf type="plastic">\n<float name="uoffset" value="0.5"/></bsdf></shape>',
     ["scene.xml:4:", "plastic has no property 'to_uv'"]),
    ('<shape type="sphere">\n<float name="radius" value="1"/><transform name="to_world"/>\n'
     '<transform name="toWorld"/></shape>',
     ['scene.xml:5: <transform name="toWorld">', "'toWorld' becomes 'to_world' in the upgrade of a version "
      '0.6.0 file, but <transform name="to_world"> (line 4) already holds that name',
      "Mitsuba 3 keeps 'toWorld' and refuses it unread"]),
    ('<shape type="sphere"><bsdf type="diffuse">\n<rgb name="reflectance" value="1"/>\n'
     '<rgb name="diffuseReflectance" value="1"/></bsdf></shape>',
     ["scene.xml:5:", "'diffuseReflectance' becomes 'reflectance'", "keeps 'diffuse_reflectance'"]),
])
def test_what_mitsuba_3_does_not_upgrade_is_refused_in_one_line(tmp_path, body, words):
    """What Mitsuba 3.9.1 refuses in an old file tracer refuses too, naming the file and the
    line, and for Mitsuba 0.6's colours and look-at, what to write instead."""
    message = refusal(old_scene(tmp_path, body))
    for word in words:
        assert word in message, message
