"""The scenes shipped inside the package, reachable by name from any folder.

Every command and function that takes a scene (``tracer render``, ``reference``, ``compare``,
``convert``, ``check --create``, a baseline entry, ``tracer.load_scene``) resolves it here, with
:func:`resolve_scene`, so they all accept the same names:

- an existing file (relative to the current folder, or absolute) is always that file, so a
  scene of your own called ``cornell`` is never shadowed by the shipped one;
- else a shipped name: the stem of a TOML scene in ``tracer/scenes/`` (``cornell``), or
  ``mitsuba/`` and the stem of a Mitsuba 3 scene in ``tracer/scenes/mitsuba/``
  (``mitsuba/veach_mis``; the prefix keeps it apart from the TOML ``veach_mis``); either may
  be written with its suffix (``cornell.toml``, ``mitsuba/veach_mis.xml``);
- else an ``InputError`` that lists the shipped names.

``tracer scenes`` lists them with :func:`shipped_scenes`, each with its description: the first
sentence of the file's leading comment (``#`` lines of a TOML file, the first ``<!-- -->`` of an
XML one) without its parenthetical asides. Comments are not part of a scene's digest, so a
TOML scene's description can be edited without touching the references and baselines made of
it; a Mitsuba scene's file is hashed whole by its Mitsuba reference (tests/data/mitsuba_refs),
so editing its comment means regenerating that reference.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from ..errors import InputError

# Where a Mitsuba scene's name starts: its folder under tracer/scenes/.
MITSUBA_PREFIX = "mitsuba/"
# A description longer than this is cut (with an ellipsis) so that each scene is one line.
DESCRIPTION_CHARACTERS = 100


@dataclass(frozen=True)
class ShippedScene:
    """A scene file shipped in the package: the name it is reached by, its file and its
    one-line description ("" when its file has no leading comment)."""

    name: str
    path: Path
    description: str


def shipped_folder() -> Path:
    """``tracer/scenes`` of the installed package (a source checkout's own folder when editable)."""
    return Path(str(resources.files("tracer") / "scenes"))


def shipped_scenes() -> list[ShippedScene]:
    """Every shipped scene: the TOML ones by name, then the Mitsuba ones."""
    folder = shipped_folder()
    files = [(path.stem, path) for path in sorted(folder.glob("*.toml"))]
    files += [(MITSUBA_PREFIX + path.stem, path) for path in sorted((folder / "mitsuba").glob("*.xml"))]
    return [ShippedScene(name, path, describe(path)) for name, path in files]


def shipped_names() -> list[str]:
    return [scene.name for scene in shipped_scenes()]


def resolve_scene(source: str | os.PathLike[str]) -> Path:
    """The scene file ``source`` names: an existing file, else a shipped scene's name (with or
    without its suffix), else InputError listing the shipped names. A folder given as a scene
    is passed on as it is (unless a shipped name matches it), so the reader says what it is."""
    text = os.fspath(source)
    # lexists and not a folder: a FIFO or a dangling link is the user's file too, and the
    # reader refuses it with its own message rather than this one hiding it behind a name.
    if os.path.lexists(text) and not os.path.isdir(text):
        return Path(text)
    shipped = shipped_scene_named(text)
    if shipped is not None:
        return shipped
    if os.path.isdir(text):
        return Path(text)
    names = ", ".join(shipped_names())
    raise InputError(f"no such scene file, nor a shipped scene's name (shipped: {names}; tracer scenes "
                     "describes them)", text)


def shipped_scene_named(text: str) -> Path | None:
    """The file of the shipped scene named ``text`` (with or without its suffix), or None."""
    for scene in shipped_scenes():
        if text in (scene.name, scene.name + scene.path.suffix):
            return scene.path
    return None


def describe(path: Path) -> str:
    """The first sentence of the leading comment of the scene file ``path`` on one line, or ""."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return ""
    if path.suffix.lower() == ".xml":
        match = re.match(r"\s*(?:<\?xml[^>]*\?>\s*)?<!--(.*?)-->", text, re.S)
        comment = match.group(1) if match else ""
    else:
        lines = []
        for line in text.splitlines():
            if not line.startswith("#"):
                break
            lines.append(line[1:])
        comment = " ".join(lines)
    # Parenthetical asides (a citation, a test's issue number) are left out of the one line.
    words = re.sub(r"\s*\([^()]*\)", "", " ".join(comment.split()))
    # A sentence ends at a full stop followed by a space and a capital letter or by the end:
    # "figure 9.2" and "0.005" do not end one.
    end = re.search(r"\.(?=\s+[A-Z(]|$)", words)
    sentence = words[: end.end()] if end else words
    if len(sentence) > DESCRIPTION_CHARACTERS:
        sentence = sentence[: DESCRIPTION_CHARACTERS - 1].rstrip() + "…"
    return sentence
