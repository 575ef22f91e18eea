"""Shared fixtures: small scenes written to a temporary folder."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "tracer" / "scenes"


@pytest.fixture
def write_scene(tmp_path):
    """write_scene(text, name='scene.toml') -> Path: a scene file in a fresh folder."""

    def write(text: str, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return path

    return write
