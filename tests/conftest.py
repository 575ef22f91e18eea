"""Shared fixtures: small scenes written to a temporary folder; the PYTHONPATH of child processes."""

from __future__ import annotations

import fcntl
import os
import pickle
import textwrap
from pathlib import Path

import pytest

# Before tracer is imported, which reads it: the suite's kernels are compiled with numba's
# inlining off (``tracer.jit.INLINE``): the same bits in a third less compile time, over the
# dozens of builds the suite compiles; tests/test_jit_cache.py checks the bits against a child
# process that compiles with the default.
os.environ.setdefault("TRACER_INLINE", "never")

import tracer  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "tracer" / "scenes"

# Child processes (``python -m tracer ...`` in another folder, a notebook's kernel) import the
# same copy of tracer as the tests: ``python -m pytest`` in a checkout imports the checkout's,
# while a child elsewhere would import the installed one and compile every kernel a second time
# for it (about 100 s of CI). tests/test_packaging.py checks the installed copy holds every file.
# The suite renders hundreds of small scenes: they share one build of the kernels per strategy and
# sampler (``tracer.kernels.shared_builds``) instead of compiling one per scene, which took the
# suite past 40 minutes. tests/test_kernels.py checks that a scene's own build gives the same
# bits, and renders that way where the build itself is what it tests.
os.environ["TRACER_KERNELS"] = "shared"
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(Path(tracer.__file__).resolve().parent.parent), *filter(None, [os.environ.get("PYTHONPATH")])])


@pytest.fixture(scope="session")
def computed_once(tmp_path_factory):
    """computed_once(name, compute) -> compute(folder)'s value, computed once in a whole run.

    Under ``-n 2`` each process runs a module's fixture for the tests it was given, so an
    expensive study (the stability suite: about two minutes) ran twice. The processes share the
    parent of their base temporary folders: the first to take ``name``'s lock computes in a folder
    there and pickles the value; the other waits on the lock (not on a clock) and reads it. A
    failed computation leaves no value, so the next process computes again and fails the same way.
    """
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent

    def once(name: str, compute):
        folder = root / f"once-{name}"
        folder.mkdir(exist_ok=True)
        stored = folder / "value.pickle"
        with open(folder / ".lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if stored.exists():
                return pickle.loads(stored.read_bytes())
            value = compute(folder)
            partial = folder / "value.pickle.partial"
            partial.write_bytes(pickle.dumps(value))
            partial.replace(stored)
            return value

    return once


@pytest.fixture
def write_scene(tmp_path):
    """write_scene(text, name='scene.toml') -> Path: a scene file in a fresh folder."""

    def write(text: str, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return path

    return write


SPHERE_XML = """<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
    <integer name="height" value="4"/></film></sensor>
  <shape type="sphere">{bsdf}</shape>
  <emitter type="point"><point name="position" value="0, 0, 5"/></emitter>
</scene>"""


@pytest.fixture
def sphere_with(tmp_path):
    """sphere_with(bsdf) -> Scene: a Mitsuba scene file ``a.xml`` of one sphere whose BSDF is
    the XML ``bsdf``, a point light and a 4x4 film, loaded."""
    import tracer

    def load(bsdf: str):
        path = tmp_path / "a.xml"
        path.write_text(SPHERE_XML.format(bsdf=bsdf))
        return tracer.load_scene(path)

    return load
