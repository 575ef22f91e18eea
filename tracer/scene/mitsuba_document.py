"""Mitsuba 3 XML documents: parsing, ``<include>``, ``<default>``/``$name``, ``<path>``, ids,
``<alias>``, and the values of properties and transforms.

:func:`read_document` turns a scene file into one tree of :class:`Element` (each knowing its
file and line, for messages), with every include spliced in, every ``$name`` substituted and
every id resolved, and each file's version recorded (a file of Mitsuba 0.x is then upgraded
by :mod:`tracer.scene.mitsuba_upgrade`); :mod:`tracer.scene.mitsuba_xml` reads the plugins
from it. The rules are Mitsuba 3.9.1's, checked by loading small scenes with it
(``tests/test_mitsuba_xml.py``):

- ``<default name value>`` defines ``$name`` for the attributes that FOLLOW it in document
  order (a use before it is an error), unless ``name`` is already defined (the first wins); a
  default's own value is substituted when it is read; an undefined ``$name`` is an error.
- relative file names are looked up as Mitsuba's file resolver looks them up (:class:`_Scope`):
  an ``<include filename>`` in the including file's folder, then in the folders searched for
  that file's own names; a mesh file in the main file's ``<path>`` folders, then the main
  scene's folder. The included file's root is a ``<scene>`` whose children take the include's
  place. Cycles and more than MAX_INCLUDE_DEPTH nested includes are refused.
- ``<path value>`` (in a file's ``<scene>``, not inside an object) puts a folder (relative to
  that file's folder, else looked up as an include is) before the others; the latest first. In
  an included file it serves only that file's includes, as in Mitsuba.
- every object (``bsdf``, ``shape``, ...) may have an ``id``, unique in the scene;
  ``<ref id>`` stands for it anywhere an object may appear (its ``name`` is ignored, as
  Mitsuba ignores it); ``<alias id as>`` gives it a second id.
- transforms compose in document order, each operation applied after the ones before it
  (left-multiplied): ``<translate x="1"/><scale value="2"/>`` moves the origin to x = 2.

Parsing uses expat, which reports lines; DOCTYPE and entity declarations are refused outright
(no entity expansion, so no "billion laughs"). ``$name`` substitution, the other way to make a
small file expand (a default that repeats another, doubling at every step), is measured while
it is done: an attribute may not grow past MAX_SUBSTITUTED characters, nor all of them together
past MAX_SUBSTITUTED_TOTAL, and the string past the limit is never built.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn
from xml.parsers import expat

import numpy as np

from ..errors import SHOWN_CHARACTERS, InputError, shown
from ..inputfiles import read_regular_file

MAX_FILE_BYTES = 64 << 20  # far beyond any scene file (meshes live in their own files)
# Includes inside includes: the main file may include a file that includes another, and so on,
# this many times; one more is refused. Mitsuba 3.9.1 allows 14 (parser.cpp, parse_file_impl:
# max_include_depth 15, counted from the main file at depth 0): tracer reads all it reads.
MAX_INCLUDE_DEPTH = 16
MAX_FILES = 1000  # files read through includes, in all
# <path> folders in all files: every include and mesh file is looked for in each, and every
# included file keeps its own copy of the list (scenes have one or two).
MAX_PATHS = 100
MAX_NESTING = 64  # elements inside elements, includes spliced in
MAX_SUBSTITUTED = 1 << 20  # characters of an attribute after $name substitution
# Characters that $name substitution may add in the whole document. A scene's parameters are
# numbers and names a few characters long (an spp, a resolution, a colour), so this is far
# beyond any scene; without it, thousands of attributes each a little under MAX_SUBSTITUTED
# would still make gigabytes (a 1 MB file reached 4 GB). It bounds the text substitution
# makes to 16 Mi characters (at most 64 MB).
MAX_SUBSTITUTED_TOTAL = 16 * MAX_SUBSTITUTED

OBJECT_TAGS = frozenset({"scene", "bsdf", "emitter", "shape", "sensor", "film", "sampler", "integrator",
                         "rfilter", "texture", "medium", "phase", "volume"})
PROPERTY_TAGS = frozenset({"float", "integer", "boolean", "string", "point", "vector", "rgb", "spectrum",
                           "transform"})
TRANSFORM_TAGS = frozenset({"translate", "scale", "rotate", "matrix", "lookat"})
# The attributes each element may have (Mitsuba refuses others too).
_ATTRIBUTES = {
    "scene": {"version", "type", "id"},
    "ref": {"id", "name"},
    "default": {"name", "value"},
    "include": {"filename"},
    "path": {"value"},
    "alias": {"id", "as"},
    "transform": {"name"},
    "point": {"name", "value", "x", "y", "z"},
    "vector": {"name", "value", "x", "y", "z"},
    "spectrum": {"name", "value", "filename", "type", "id"},
    "translate": {"value", "x", "y", "z"},
    "scale": {"value", "x", "y", "z"},
    "rotate": {"value", "x", "y", "z", "angle"},
    "matrix": {"value"},
    "lookat": {"origin", "target", "up"},
}
_NAME_VALUE = {"name", "value"}
_OBJECT_ATTRIBUTES = {"type", "id", "name"}

_SUBSTITUTION = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NOT_FINITE = re.compile(r"[+-]?(?:inf|infinity|nan)", re.IGNORECASE)
_INTEGER = re.compile(r"-?\d+")
_SEPARATORS = re.compile(r"[,\s]+")


@dataclass(eq=False)
class Element:
    """One XML element: its tag, attributes (``$name`` substituted), file and line, children."""

    tag: str
    attrs: dict[str, str]
    file: str
    line: int
    children: list["Element"] = field(default_factory=list)
    # The name as the file writes it, when the upgrade of an old scene renamed it
    # (tracer/scene/mitsuba_upgrade.py); attrs["name"] holds the new one.
    written_name: str | None = None

    def describe(self) -> str:
        """``<tag type="..." id="..." name="...">``, the attributes that name it as the file
        writes them (each cut to ``errors.shown``'s length)."""
        attrs = self.attrs if self.written_name is None else {**self.attrs, "name": self.written_name}
        naming = "".join(f' {k}="{shown(attrs[k])}"' for k in ("type", "id", "name") if k in attrs)
        return f"<{shown(self.tag)}{naming}>"

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    def fail(self, message: str, inside: "Element | None" = None) -> NoReturn:
        """Raise InputError naming this element's file, line and element (and its object)."""
        key = self.describe() + (f" in {inside.describe()}" if inside is not None else "")
        raise InputError(message, self.where, key)

    def attr(self, name: str, default: str | None = None) -> str:
        value = self.attrs.get(name, default)
        if value is None:
            self.fail(f"missing attribute '{name}'")
        return value


@dataclass
class Document:
    """A scene file with its includes spliced in and its ids resolved.

    root : the ``<scene>`` element (``<default>``, ``<include>``, ``<path>`` and ``<alias>``
        removed).   ids : id (and alias) -> object element.   search_folders : the main file's
        ``<path>`` folders, the latest first.   folder : the scene's folder (the main file's,
        unless the reader was given another).   versions : each file's ``<scene version>``
        (major, minor, patch) by the name its elements carry in ``Element.file``, in the order
        the files were read; an included file without a version is not in it.
    """

    path: str
    root: Element
    ids: dict[str, Element]
    search_folders: list[Path]
    folder: Path
    versions: dict[str, tuple[int, int, int]] = field(default_factory=dict)

    def resolve(self, ref: Element) -> Element:
        """The object a ``<ref id>`` stands for."""
        target = self.ids.get(ref.attr("id"))
        if target is None:
            ref.fail(f"no object has id '{shown(ref.attrs['id'])}'")
        return target

    def find_file(self, name: str) -> Path:
        """A file the scene names (a mesh): absolute as is; relative, the first that exists of
        the main file's ``<path>`` folders (the latest first) and the scene's folder, as
        Mitsuba's file resolver finds it when it builds the shapes (``Mesh::Mesh`` in
        src/render/mesh.cpp: ``file_resolver()->resolve(filename)``, after parsing, when only
        the main file's ``<path>`` folders are left in it). Mitsuba also looks in the folder it
        was started from; tracer does not (a scene would then depend on where it is rendered)."""
        try:
            found = _first_found(Path(name), [*self.search_folders, self.folder])
        except (OSError, ValueError):
            found = None
        return found if found is not None else self.folder / name  # missing: the reader says so


def read_document(path: str, base: Path | None = None, parameters: dict[str, str] | None = None) -> Document:
    """Parse the scene file ``path`` (relative file names resolve against ``base``, default its
    folder) into a :class:`Document`; ``parameters`` define ``$name``s as Mitsuba's command-line
    ``-D name=value`` does, before and over the file's ``<default>``s. Raises InputError with
    the file and line at fault."""
    root = _parse_file(path, path)
    if root.tag != "scene":
        root.fail("the root element of a Mitsuba scene is <scene>")
    state = _Expansion()
    state.defaults.update(parameters or {})
    state.versions[path] = _check_version(root)
    main = _Scope(Path(path).parent, [], [os.path.realpath(path)], Path(path).parent)
    root.children = state.expand(root, main, 1)
    ids = _collect_ids(root, state.aliases)
    folder = base if base is not None else Path(path).parent
    return Document(path, root, ids, main.resolver, folder, state.versions)


def _check_version(scene: Element) -> tuple[int, int, int]:
    """The (major, minor, patch) of ``<scene version>``, major 0 to 3 (a file of major 0 or 1 is
    read after the upgrade Mitsuba 3 applies to it: tracer/scene/mitsuba_upgrade.py)."""
    version = scene.attrs.get("version")
    if version is None:
        scene.fail("missing attribute 'version' (Mitsuba 3 scenes say <scene version=\"3.0.0\">)")
    match = re.fullmatch(r"([0-9]{1,6})\.([0-9]{1,6})\.([0-9]{1,6})", version.strip())
    if not match:
        scene.fail(f"version '{shown(version)}' is not of the form major.minor.patch")
    parts = (int(match.group(1)), int(match.group(2)), int(match.group(3)))
    if parts[0] > 3:
        scene.fail(f"version {version.strip()}: tracer reads scenes of Mitsuba versions 0.x to 3.x")
    return parts


def _parse_file(path: str, label: str) -> Element:
    """The element tree of one XML file; ``label`` names it in messages."""
    data = read_regular_file(path, MAX_FILE_BYTES, "scene file", label=label)

    parser = expat.ParserCreate()
    stack: list[Element] = []
    roots: list[Element] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        element = Element(tag, dict(attrs), label, parser.CurrentLineNumber)
        if len(stack) >= MAX_NESTING:
            element.fail(f"elements nested more than {MAX_NESTING} deep")
        (stack[-1].children if stack else roots).append(element)
        stack.append(element)

    def end(tag: str) -> None:
        stack.pop()

    def refuse(what: str):
        def handler(*args) -> None:
            raise InputError(f"{what} are not allowed in a scene file (no entity expansion)",
                             f"{label}:{parser.CurrentLineNumber}")
        return handler

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.StartDoctypeDeclHandler = refuse("DOCTYPE declarations")
    parser.EntityDeclHandler = refuse("entity declarations")
    parser.UnparsedEntityDeclHandler = refuse("entity declarations")
    parser.ExternalEntityRefHandler = refuse("external entities")
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise InputError(f"not well-formed XML: {expat.ErrorString(exc.code)} (column {exc.offset + 1})",
                         f"{label}:{exc.lineno}") from None
    except LookupError as exc:  # an encoding declaration Python does not know
        raise InputError(f"not readable XML: {shown(exc)}", label) from None
    except RecursionError:
        raise InputError("nested too deeply", label) from None
    if not roots:
        raise InputError("no XML element", label)
    return roots[0]


@dataclass
class _Scope:
    """One file as it is expanded, with what Mitsuba's file resolver holds while it is read
    (src/core/parser.cpp, ``parse_xml_node``: an ``<include>`` is looked up in a copy of the
    resolver with the including file's folder put first, and the included file is read with
    that copy; a ``<path>`` puts its folder first in the resolver of the file it is in).

    folder : the file's folder.   resolver : the folders searched after it: its own ``<path>``
        folders, the latest first, then the folders of the file that includes it as they were
        at the include, and so on up to the main file's ``<path>`` folders.   chain : the real
        paths of the files including it and its own, the main file first.   top : the main
        scene's folder, searched last.
    """

    folder: Path
    resolver: list[Path]
    chain: list[str]
    top: Path

    def include_folders(self) -> list[Path]:
        """Where a relative ``<include>`` of this file is looked for, in order."""
        return list(dict.fromkeys([self.folder, *self.resolver, self.top]))

    def included(self, path: Path) -> "_Scope":
        """The scope of the file ``path`` that this file includes."""
        return _Scope(path.parent, [self.folder, *self.resolver], [*self.chain, os.path.realpath(path)],
                      self.top)


class _Expansion:
    """Splices includes in, substitutes ``$name``, collects ``<path>`` folders and aliases."""

    def __init__(self):
        self.defaults: dict[str, str] = {}
        self.aliases: list[Element] = []
        self.versions: dict[str, tuple[int, int, int]] = {}  # Document.versions
        self.files = 1
        self.paths = 0
        self.substituted = 0  # characters $name substitution has added, in all files

    def substitute(self, element: Element) -> None:
        """``$name`` replaced in each attribute of ``element``. The size is counted as the value
        is put together, so that a value past MAX_SUBSTITUTED (a default that repeats another
        doubles at every step: a billion laughs made of $names) or a document past
        MAX_SUBSTITUTED_TOTAL is refused before it is built."""
        for key, text in element.attrs.items():
            if "$" not in text:
                continue
            pieces, length, start = [], 0, 0
            for match in _SUBSTITUTION.finditer(text):
                value = self._value_of(match, element)
                pieces += (text[start:match.start()], value)
                length += match.start() - start + len(value)
                self.substituted += len(value)
                start = match.end()
                self._check_size(element, key, length)
            pieces.append(text[start:])
            self._check_size(element, key, length + len(text) - start)
            element.attrs[key] = "".join(pieces)

    def _check_size(self, element: Element, key: str, length: int) -> None:
        if length > MAX_SUBSTITUTED:
            element.fail(f"attribute '{shown(key)}' is longer than {MAX_SUBSTITUTED} characters after "
                         "substituting $names")
        if self.substituted > MAX_SUBSTITUTED_TOTAL:
            element.fail(f"attribute '{shown(key)}': substituting $names makes more than "
                         f"{MAX_SUBSTITUTED_TOTAL} characters in the whole scene")

    def _value_of(self, match: re.Match, element: Element) -> str:
        name = match.group(1)
        if name not in self.defaults:
            element.fail(f"undefined parameter ${shown(name)} (define it with <default name=... value=...> "
                         "before its first use)")
        return self.defaults[name]

    def expand(self, parent: Element, scope: _Scope, depth: int) -> list[Element]:
        """``parent``'s children with includes spliced in and directives applied; ``scope`` is
        the file they are in."""
        out: list[Element] = []
        for child in parent.children:
            self.substitute(child)
            allowed = _ATTRIBUTES.get(child.tag)
            if allowed is None:
                allowed = (_OBJECT_ATTRIBUTES if child.tag in OBJECT_TAGS
                           else _NAME_VALUE if child.tag in PROPERTY_TAGS else set())
            unexpected = sorted(set(child.attrs) - allowed)
            known = child.tag in OBJECT_TAGS or child.tag in PROPERTY_TAGS or child.tag in _ATTRIBUTES
            if unexpected and known:
                child.fail(f"unexpected attribute '{shown(unexpected[0])}'")
            if child.tag == "default":
                self._no_children(child)
                self.defaults.setdefault(child.attr("name"), child.attr("value"))
            elif child.tag == "path":
                self._no_children(child)
                if parent.tag != "scene":  # Mitsuba: "<path>: path can only be child of root"
                    child.fail("a <path> belongs directly inside <scene>")
                self.paths += 1
                if self.paths > MAX_PATHS:
                    child.fail(f"more than {MAX_PATHS} <path> folders in the scene")
                scope.resolver.insert(0, self._path_folder(child, scope))
            elif child.tag == "alias":
                self._no_children(child)
                child.attr("id")
                child.attr("as")
                self.aliases.append(child)
            elif child.tag == "include":
                self._no_children(child)
                out.extend(self._include(child, scope, depth))
            else:
                if depth + len(scope.chain) > MAX_NESTING:
                    child.fail(f"elements nested more than {MAX_NESTING} deep (includes included)")
                child.children = self.expand(child, scope, depth + 1)
                out.append(child)
        return out

    @staticmethod
    def _no_children(element: Element) -> None:
        if element.children:
            element.children[0].fail(f"<{element.tag}> takes no child elements")

    @staticmethod
    def _path_folder(path: Element, scope: _Scope) -> Path:
        """The folder of a ``<path value>``: relative to its file's folder if it is there, else
        looked up as that file's includes are (parser.cpp, ``TagType::Resource``); Mitsuba
        refuses one that does not exist."""
        value = path.attr("value")
        try:
            found = _first_found(Path(value), scope.include_folders(), Path.is_dir)
        except (OSError, ValueError) as exc:  # a name too long for the file system, a NUL byte
            path.fail(f"cannot look up the folder '{shown(value)}': {getattr(exc, 'strerror', None) or exc}")
        if found is None:
            path.fail(f"folder not found: '{shown(value)}'")
        return found

    def _include(self, include: Element, scope: _Scope, depth: int) -> list[Element]:
        name = include.attr("filename")
        folders = scope.include_folders()
        try:
            path = _first_found(Path(name), folders)
        except (OSError, ValueError) as exc:  # a name too long for the file system, a NUL byte
            include.fail(f"cannot look up the included file '{shown(name)}': "
                         f"{getattr(exc, 'strerror', None) or exc}")
        if path is None:
            looked = shown(", ".join(str(folder) for folder in folders), 4 * SHOWN_CHARACTERS)
            include.fail(f"included file not found (or not a regular file): '{shown(name)}' "
                         f"(looked in {looked})")
        inner = scope.included(path)
        if inner.chain[-1] in scope.chain:
            include.fail(f"include cycle: {shown(str(path))} includes itself (through {len(scope.chain)} "
                         "file(s))")
        if len(scope.chain) > MAX_INCLUDE_DEPTH:  # chain: this file and the files including it
            include.fail(f"more than {MAX_INCLUDE_DEPTH} includes nested in one another")
        self.files += 1
        if self.files > MAX_FILES:
            include.fail(f"more than {MAX_FILES} files included")
        root = _parse_file(str(path), str(path))
        if root.tag != "scene":
            root.fail("an included file's root element is <scene>")
        self.substitute(root)
        if "version" in root.attrs:
            self.versions[str(path)] = _check_version(root)
        return self.expand(root, inner, depth)


def _first_found(name: Path, folders: list[Path], wanted=Path.is_file) -> Path | None:
    """``name`` if absolute, else the first ``folder / name`` that is a file (or what ``wanted``
    accepts), or None: what Mitsuba's ``FileResolver::resolve`` finds (src/core/fresolver.cpp).
    Raises OSError or ValueError when the name cannot be looked up at all (too long for the file
    system, a NUL byte) and is found nowhere."""
    error: OSError | ValueError | None = None
    for candidate in [name] if name.is_absolute() else [folder / name for folder in folders]:
        try:
            if wanted(candidate):
                return candidate
        except (OSError, ValueError) as exc:
            error = error or exc
    if error is not None:
        raise error
    return None


def _collect_ids(root: Element, aliases: list[Element]) -> dict[str, Element]:
    ids: dict[str, Element] = {}
    stack = [root]
    while stack:
        element = stack.pop()
        stack.extend(reversed(element.children))
        plugin = element.tag in OBJECT_TAGS or (element.tag == "spectrum" and "type" in element.attrs)
        if plugin and element is not root:
            ident = element.attrs.get("id")
            if ident is None:
                continue
            if ident in ids:
                element.fail(f"duplicate id '{shown(ident)}' (first at {ids[ident].where})")
            ids[ident] = element
    for alias in aliases:
        source, name = alias.attrs["id"], alias.attrs["as"]
        if source not in ids:
            alias.fail(f"no object has id '{shown(source)}'")
        if name in ids:
            alias.fail(f"id '{shown(name)}' is taken (at {ids[name].where})")
        ids[name] = ids[source]
    return ids


# ---------------------------------------------------------------------------------------------
# Values


def number(element: Element, text: str, what: str) -> float:
    """A finite number written as Mitsuba accepts it (surrounding spaces allowed)."""
    token = text.strip()
    if _NOT_FINITE.fullmatch(token):
        element.fail(f"{what}: expected a finite number, got '{shown(token)}'")
    if not _NUMBER.fullmatch(token):
        element.fail(f"{what}: expected a number, got '{shown(token)}'")
    value = float(token)
    if not math.isfinite(value):
        element.fail(f"{what}: '{shown(token)}' is not a finite number")
    return value


def integer(element: Element, text: str, what: str) -> int:
    token = text.strip()
    if not _INTEGER.fullmatch(token) or len(token) > 30:
        element.fail(f"{what}: expected a whole number, got '{shown(token)}'")
    return int(token)


def numbers(element: Element, text: str, what: str) -> list[float]:
    """Numbers separated by commas and/or spaces ("1, 2, 3", "1 2 3")."""
    return [number(element, token, what) for token in _SEPARATORS.split(text.strip()) if token]


def boolean(element: Element, text: str, what: str) -> bool:
    token = text.strip().lower()
    if token not in ("true", "false"):
        element.fail(f"{what}: expected true or false, got '{shown(text)}'")
    return token == "true"


def xyz(element: Element, default: float | None, what: str = "value") -> np.ndarray:
    """A 3-vector from ``value`` (1 number: all three, or 3) or from ``x``, ``y``, ``z`` (each
    ``default`` when absent; all required when ``default`` is None)."""
    given = [k for k in ("x", "y", "z") if k in element.attrs]
    if "value" in element.attrs:
        if given:
            element.fail("give either value or x, y, z, not both")
        values = numbers(element, element.attrs["value"], what)
        if len(values) not in (1, 3):
            element.fail(f"{what}: expected 1 or 3 numbers, got {len(values)}")
        return np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)
    out = []
    for k in ("x", "y", "z"):
        if k not in element.attrs:
            if default is None:
                element.fail(f"missing attribute '{k}' (or value=\"x, y, z\")")
            out.append(default)
        else:
            out.append(number(element, element.attrs[k], k))
    return np.array(out, dtype=np.float64)


def transform_matrix(element: Element) -> np.ndarray:
    """The 4 x 4 matrix of a ``<transform>``: its operations in order, each left-multiplied."""
    matrix = np.eye(4)
    for op in element.children:
        if op.tag not in TRANSFORM_TAGS:
            op.fail(f"not a transform operation (expected {', '.join(sorted(TRANSFORM_TAGS))})", element)
        if op.children:
            op.children[0].fail(f"<{op.tag}> takes no child elements")
        with np.errstate(over="ignore", invalid="ignore"):  # refused below when it overflows
            matrix = _operation(op) @ matrix
    if not np.all(np.isfinite(matrix)):
        element.fail("the transform is not finite (its numbers overflow)")
    return matrix


def _operation(op: Element) -> np.ndarray:
    m = np.eye(4)
    if op.tag == "translate":
        m[:3, 3] = xyz(op, 0.0)
    elif op.tag == "scale":
        m[:3, :3] = np.diag(xyz(op, 1.0))
    elif op.tag == "rotate":
        angle = number(op, op.attr("angle"), "angle")
        axis = xyz(op, 0.0, "axis")
        if not np.any(axis):
            op.fail("the rotation axis is zero")
        m[:3, :3] = rotation(axis, angle)
    elif op.tag == "matrix":
        values = numbers(op, op.attr("value"), "value")
        if len(values) == 16:
            m = np.array(values, dtype=np.float64).reshape(4, 4)
            if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
                op.fail(f"the last row is {m[3].tolist()}, not 0 0 0 1: projective matrices are not "
                        "supported")
        elif len(values) == 9:
            m[:3, :3] = np.array(values, dtype=np.float64).reshape(3, 3)
        else:
            op.fail(f"a matrix has 9 or 16 numbers, not {len(values)}")
    else:
        m = lookat(op)
    return m


def rotation(axis: np.ndarray, degrees: float) -> np.ndarray:
    """Rodrigues' rotation by ``degrees`` about ``axis``, counter-clockwise looking down the axis.
    The axis is used as given, not normalized, as Mitsuba 3.9.1 does (a non-unit axis also
    scales: ``<rotate x="1" y="1" angle="30"/>`` is not a rotation there either)."""
    theta = math.radians(degrees)
    c, s = math.cos(theta), math.sin(theta)
    x, y, z = axis
    cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return c * np.eye(3) + (1.0 - c) * np.outer(axis, axis) + s * cross


def lookat(op: Element) -> np.ndarray:
    """Mitsuba's look-at matrix: columns left = up x dir, up' = dir x left, dir, origin (a
    camera looks along its local +z, its local +x to the image's left). Without ``up``, the
    first vector of Duff et al.'s orthonormal basis of dir (JCGT 6(1), 2017), as Mitsuba."""
    origin = _vector_attr(op, "origin")
    target = _vector_attr(op, "target")
    direction = target - origin
    length = float(np.linalg.norm(direction))
    if not length > 0.0 or not math.isfinite(length):
        op.fail("target equals origin: no viewing direction")
    direction = direction / length
    if "up" in op.attrs:
        up = _vector_attr(op, "up")
    else:
        up = _basis_vector(direction)
    left = np.cross(up, direction)
    norm = float(np.linalg.norm(left))
    if not norm > 1e-12 * max(float(np.linalg.norm(up)), 1e-300):
        op.fail("up is zero or parallel to the viewing direction")
    left = left / norm
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(direction, left), direction, origin
    return m


def _basis_vector(n: np.ndarray) -> np.ndarray:
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])


def _vector_attr(op: Element, name: str) -> np.ndarray:
    values = numbers(op, op.attr(name), name)
    if len(values) != 3:
        op.fail(f"{name}: expected 3 numbers, got {len(values)}")
    return np.array(values, dtype=np.float64)

