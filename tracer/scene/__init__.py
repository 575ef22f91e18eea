"""Scenes: the model the renderer reads (``model.py``) and the readers that build it.

Readers: ``toml_reader.py`` for tracer's own TOML format (``docs/SCENE_FORMAT.md``) and
``mitsuba_xml.py`` for Mitsuba 3 XML scenes (``docs/MITSUBA_XML.md``), chosen by file suffix:
``.xml`` is Mitsuba's, anything else TOML. Both produce the same :class:`Scene`;
``toml_writer.py`` writes any scene back as TOML (``tracer convert``). A scene is a file path
or the name of a scene shipped in the package (``shipped.py``: ``cornell``, ``mitsuba/veach_mis``).

Notes: what a scene asks for that tracer does not do (a Mitsuba scene's integrator, pixel
filter, ...) is told in one line per load to ``notify``, or, without one, to the handler of
``tracer.notices`` (the command line prints it on stderr; by default, for API users, it is
dropped).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import notices
from ..errors import InputError
from .model import Scene, Shape
from .shipped import ShippedScene, resolve_scene, shipped_folder, shipped_scenes
from .toml_reader import check_resolution, read_toml_file, scene_from_document


def default_scene_path() -> Path:
    """The scene ``tracer render`` uses without an argument: ``veach_mis``, shipped in the package."""
    return shipped_folder() / "veach_mis.toml"


def load_scene(source: str | os.PathLike[str] | dict[str, Any], width: int | None = None,
               height: int | None = None, base_dir: str | os.PathLike[str] | None = None,
               notify: Callable[[str], None] | None = None,
               parameters: dict[str, str] | None = None) -> Scene:
    """Read and validate a scene.

    source : a scene file path (``.xml``: a Mitsuba 3 scene, anything else TOML), the name of
        a scene shipped with tracer (``"cornell"``, ``"mitsuba/veach_mis"``: ``tracer scenes``
        lists them; an existing file of that name wins), or a scene document as a dict (the
        TOML file's tables as Python values, e.g. ``{"camera": {...}, "shapes": [...]}``).
    width, height : override the camera's resolution.
    base_dir : the folder mesh files are relative to (default: the scene file's folder, or
        the current folder for a dict).
    notify : receives, as one line, what the scene asks for and tracer does not do (a
        Mitsuba scene's integrator, filter, ...); default: ``tracer.notices.note``, which
        drops it unless a handler was installed (the command line installs one).
    parameters : a Mitsuba scene's ``$name`` values by name, as Mitsuba's ``-D name=value``
        gives them (over the file's ``<default>``s); refused for a TOML scene, which has none.
    Raises ``InputError`` naming the file (``<dict>`` for a dict) and the key (for XML: the
        line and element) at fault.
    """
    if parameters and isinstance(source, dict):
        raise InputError("scene parameters (-D) are for Mitsuba XML scenes; a TOML scene has no $names",
                         "<dict>")
    if isinstance(source, dict):
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        return scene_from_document(source, "<dict>", base, width, height)
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"a scene is a file path or a dict, not {type(source).__name__}")
    path = str(resolve_scene(source))
    base = Path(base_dir) if base_dir is not None else Path(path).parent
    if parameters and Path(path).suffix.lower() != ".xml":
        raise InputError("scene parameters (-D) are for Mitsuba XML scenes; a TOML scene has no $names", path)
    if Path(path).suffix.lower() == ".xml":
        from .mitsuba_xml import read_mitsuba_scene

        return read_mitsuba_scene(path, width, height, base, notify or notices.note, parameters)
    return scene_from_document(read_toml_file(path), path, base, width, height)


__all__ = ["Scene", "Shape", "ShippedScene", "check_resolution", "default_scene_path", "load_scene",
           "resolve_scene", "shipped_scenes"]
