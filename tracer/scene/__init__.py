"""Scenes: the model the renderer reads (``model.py``) and the readers that build it.

Readers: ``toml_reader.py`` for tracer's own TOML format (``docs/SCENE_FORMAT.md``); any file
that is not ``.xml`` is read as TOML. A reader for another format produces the same
:class:`Scene` and is chosen here by file suffix.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Any

from ..errors import InputError
from .model import Scene, Shape
from .toml_reader import check_resolution, read_toml_file, scene_from_document


def default_scene_path() -> Path:
    """The scene ``tracer render`` uses without an argument: ``veach_mis``, shipped in the package."""
    return Path(str(resources.files("tracer") / "scenes" / "veach_mis.toml"))


def load_scene(source: str | os.PathLike[str] | dict[str, Any], width: int | None = None,
               height: int | None = None, base_dir: str | os.PathLike[str] | None = None) -> Scene:
    """Read and validate a scene.

    source : a scene file path, or a scene document as a dict (the TOML file's tables as
        Python values, e.g. ``{"camera": {...}, "shapes": [...]}``).
    width, height : override the camera's resolution.
    base_dir : the folder mesh files are relative to (default: the scene file's folder, or
        the current folder for a dict).
    Raises ``InputError`` naming the file (``<dict>`` for a dict) and the key at fault.
    """
    if isinstance(source, dict):
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        return scene_from_document(source, "<dict>", base, width, height)
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"a scene is a file path or a dict, not {type(source).__name__}")
    path = str(source)
    if Path(path).suffix.lower() == ".xml":
        raise InputError("Mitsuba XML scenes are not supported yet: tracer reads its TOML scene "
                         "format (docs/SCENE_FORMAT.md)", path)
    base = Path(base_dir) if base_dir is not None else Path(path).parent
    return scene_from_document(read_toml_file(path), path, base, width, height)


__all__ = ["Scene", "Shape", "check_resolution", "default_scene_path", "load_scene"]
