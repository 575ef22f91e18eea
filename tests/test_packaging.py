"""The installed package holds every file of the source tree that tracer reads at run time."""

from __future__ import annotations

import sysconfig
from importlib import metadata
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "tracer"


def test_installed_package_holds_every_file_of_the_tree():
    """Every file under tracer/ in the checkout (sources, scenes, meshes, the stability cases,
    the viewer's script) is in the installed distribution's file list. The tests and their child
    processes import the checkout (conftest.py), so without this a file left out of
    ``package-data`` would only fail for users. Skipped for an editable install, which lists no
    package files (it points at the checkout)."""
    # The distribution installed in this environment's site-packages, not a tracer.egg-info
    # that a build left in the checkout (on sys.path first when pytest runs from there).
    installed = list(metadata.distributions(name="tracer", path=[sysconfig.get_paths()["purelib"]]))
    if not installed:
        pytest.skip("tracer is not installed in this environment")
    listed = {path.as_posix() for path in installed[0].files or []}
    if not any(name.startswith("tracer/") for name in listed):
        pytest.skip("tracer is installed in editable mode (its files are the checkout's)")
    tree = {path.relative_to(PACKAGE.parent).as_posix() for path in PACKAGE.rglob("*")
            if path.is_file() and "__pycache__" not in path.parts}
    assert tree - listed == set()
