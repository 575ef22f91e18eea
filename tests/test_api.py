"""The Python API: the README's example runs as written, help(tracer) shows the API, scenes
load from dicts, and the command line answers --help without loading numba."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.scene import default_scene_path

ROOT = Path(__file__).resolve().parent.parent
# The Python examples a newcomer meets first: the README's and the guide's API page, each the
# first python block after its heading.
EXAMPLES = {"README.md": "## Python", "docs/guide/python-api.md": "# Python API"}


def _example(document: str) -> str:
    text = (ROOT / document).read_text()
    section = text[text.index(EXAMPLES[document] + "\n"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.mark.parametrize("document", list(EXAMPLES))
def test_documented_example_runs_from_any_folder(document, tmp_path, monkeypatch, capsys):
    """The example, verbatim, in an empty folder of its own: it names its scene by the shipped
    name (``load_scene("cornell")``), which works from any folder, renders, compares and writes
    the EXR and PNG it says it writes."""
    example = _example(document)
    monkeypatch.chdir(tmp_path)
    exec(compile(example, document, "exec"), {})
    out = capsys.readouterr().out
    assert "(64, 64, 3) (64, 64, 3) 16" in out and "relmse" in out
    assert (tmp_path / "cornell_mis.exr").is_file() and (tmp_path / "cornell_mis.png").is_file()
    back = tracer.read_image(tmp_path / "cornell_mis.exr")
    assert back.spp == 16 and back.film.record.heuristic == "balance"


def test_help_shows_the_api():
    """pydoc documents the API functions and classes themselves (loaded on first use), not only
    the package docstring that names them: their own docstrings' first lines must appear."""
    import pydoc

    text = pydoc.render_doc(tracer, renderer=pydoc.plaintext)
    for name in ("load_scene", "render", "read_image", "compare", "Strategy", "Image"):
        first_line = getattr(tracer, name).__doc__.strip().splitlines()[0]
        assert first_line in text, name
        assert first_line not in tracer.__doc__, name


def test_scene_from_dict_equals_scene_from_file():
    """A scene given as a dict of the TOML file's tables renders the same bits as the file."""
    import tomllib

    path = default_scene_path().parent / "cornell.toml"
    doc = tomllib.loads(path.read_text())
    from_dict = tracer.load_scene(doc, width=8, height=8, base_dir=path.parent)
    from_file = tracer.load_scene(path, width=8, height=8)
    a = tracer.render(from_dict, spp=2, seed=3, threads=1)
    b = tracer.render(from_file, spp=2, seed=3, threads=1)
    assert np.array_equal(a.mean, b.mean)


def test_bad_options_say_what_is_wrong():
    scene = tracer.load_scene(default_scene_path(), width=4, height=4)
    with pytest.raises(ValueError, match="unknown strategy"):
        tracer.render(scene, strategy="nope")
    with pytest.raises(ValueError, match="spp"):
        tracer.render(scene, spp=0)
    with pytest.raises(tracer.InputError, match="camera"):
        tracer.load_scene({"shapes": []})


def test_command_line_help_does_not_load_numba():
    """``tracer --help`` and argument errors must come back fast: the CLI, the package and the
    strategy names import neither numba nor embreex (those take about a second)."""
    code = ("import sys\nfrom tracer.cli import build_parser\nbuild_parser()\n"
            "print(sorted(m for m in ('numba', 'embreex', 'matplotlib', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_moving_the_camera_between_renders_moves_the_image():
    """The camera's rays follow its current fields: a notebook that moves the camera and renders
    again gets the new view, not a cached one."""
    scene = tracer.load_scene(default_scene_path().parent / "cornell.toml", width=8, height=8)
    a = tracer.render(scene, spp=1, seed=0, threads=1)
    scene.camera.origin = scene.camera.origin + np.array([0.3, 0.0, 0.0])
    b = tracer.render(scene, spp=1, seed=0, threads=1)
    assert not np.array_equal(a.mean, b.mean)


def test_reader_checks_every_element_of_a_parameter():
    """A vector parameter is checked element by element against its declared range, open lower
    bounds included (what a material type with such a parameter relies on)."""
    from tracer.errors import InputError
    from tracer.scene.toml_reader import _Reader

    r = _Reader("x.toml", "materials.m", {"eta": [1.0, 0.0, 2.0], "k": [0.1, 0.2]})
    with pytest.raises(InputError, match=r"materials.m.eta: expected numbers > 0,"):
        r.vector("eta", 3, lo=0.0, lo_open=True)
    with pytest.raises(InputError, match="expected a list of 3 numbers"):
        r.vector("k", 3)
    assert r.vector("k", 2, lo=0.0).tolist() == [0.1, 0.2]


def test_tiny_sphere_has_finite_vertices():
    """A sphere of radius 1e-20 at the origin (trimesh's own scaling gives NaN vertices there)
    loads with finite vertices on the sphere."""
    doc = {"camera": {"origin": [0.0, 0.0, 1.0], "target": [0.0, 0.0, 0.0], "fov": 40.0, "width": 4,
                      "height": 4},
           "shapes": [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1e-20, "subdivisions": 1}]}
    scene = tracer.load_scene(doc)
    assert np.all(np.isfinite(scene.vertices))
    np.testing.assert_allclose(np.linalg.norm(scene.vertices, axis=1), 1e-20, rtol=1e-6)


def test_a_signal_during_the_trimesh_import_is_not_swallowed(monkeypatch):
    """trimesh's first import catches BaseException around optional imports, which swallowed a
    Ctrl-C arriving then. Simulated: an import that signals the process and swallows what it
    raises, as trimesh's does; the signal must still end in KeyboardInterrupt after it."""
    import builtins
    import os
    import signal

    from tracer.scene import mesh

    real_import = builtins.__import__

    def swallowing_import(name, *args, **kwargs):
        if name == "trimesh":
            try:
                os.kill(os.getpid(), signal.SIGINT)
                sum(range(1000))  # let the handler run here, inside the import
            except BaseException:
                pass
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", swallowing_import)
    with pytest.raises(KeyboardInterrupt):
        mesh.import_trimesh()


def test_render_refuses_a_light_sampling_that_is_not_a_name():
    """light_sampling="" or False is a mistake, not a request for the default: ValueError
    naming the option (None, the default, takes the scene's or tracer's default)."""
    scene = tracer.load_scene(default_scene_path(), width=4, height=4)
    for bad in ("", False, 0, "AREA"):
        with pytest.raises(ValueError, match="light sampling"):
            tracer.render(scene, "mis", spp=1, light_sampling=bad)
    assert tracer.render(scene, "light", spp=1).film.record.light_sampling == "area"
