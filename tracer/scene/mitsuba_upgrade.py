"""Scenes written for Mitsuba 0.x and 1.x, upgraded as Mitsuba 3 upgrades them when it loads them.

Mitsuba 3.9.1 reads every file of a scene with its own ``<scene version>`` (an included file
carries its own) and, after parsing, upgrades the objects of each file whose version is below
2.0.0 (src/core/parser.cpp: ``transform_upgrade``, which applies ``upgrade_from_v1`` to every
object node by the version of the file the object is written in). The rules, as this module
applies them to the element tree of :mod:`tracer.scene.mitsuba_document` (written here, not
copied; checked by loading scenes with Mitsuba 3.9.1):

- **Names in snake_case.** The name of each property of the object (and of each reference or
  nested object, which are properties too there) goes from camelCase to snake_case: where an
  uppercase ASCII letter follows a lowercase one, ``_`` and the run of uppercase letters in
  lowercase (``toWorld`` -> ``to_world``, ``intIOR`` -> ``int_ior``, ``fovAxis`` ->
  ``fov_axis``, and also ``sRGB`` -> ``s_rgb``); other names stay as written (``to_World``).
  Values are not touched: ``<string name="fovAxis" value="y">`` keeps ``y``.
- **diffuse's reflectance.** In a ``diffuse`` object, ``diffuse_reflectance`` (so also
  ``diffuseReflectance``) becomes ``reflectance``.
- **A new name that is taken.** Mitsuba renames a property only if the object has no
  property of the new name yet (``Properties::rename_property``); otherwise it keeps the old
  name, which no Mitsuba 3 plugin reads, and refuses the scene ("unreferenced property"). tracer
  refuses it as it upgrades, naming both lines.
- **uoffset, voffset, uscale, vscale** become a ``to_uv`` transform of the object,
  scale(uscale, vscale) times translate(uoffset, voffset), as in Mitsuba 3.

What Mitsuba 3.9.1 does not upgrade it refuses, and so does tracer: ``<lookAt>`` (Mitsuba
3.0 to 3.6 renamed it ``<lookat>``; 3.9.1 says "unexpected <lookAt> element"), ``<srgb>``,
``<blackbody>``, ``#rrggbb`` colours, Mitsuba 0.6's plugins that Mitsuba 3 does not have
(``ldrfilm``, ...) and the ``intent`` attribute. For the first four the refusal says what
to write instead; for ``<srgb>`` and ``#rrggbb`` with the linear values, as Mitsuba 0.6 read
them (src/librender/scenehandler.cpp and src/libcore/spectrum.cpp in its repository). Values
keep their Mitsuba 3 meaning, as in Mitsuba 3: an emitter's constant ``<spectrum value="c">``
is equal-energy white, c (1.2048, 0.9483, 0.9086) (see :mod:`tracer.scene.spectrum`), where
Mitsuba 0.6's RGB builds made it D65 white, (c, c, c).

An included file without a version is not upgraded (Mitsuba 3.9.1 refuses it: "missing version
attribute"; tracer reads it as a current file).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import InputError, shown
from .mitsuba_document import OBJECT_TAGS, Document, Element, number, numbers

# Files of versions below this are upgraded (parser.cpp: version < util::Version(2, 0, 0)).
FIRST_CURRENT_VERSION = (2, 0, 0)
# Texture coordinate properties that Mitsuba 3 turns into a to_uv transform.
_UV_PROPERTIES = ("uoffset", "voffset", "uscale", "vscale")
# A run of uppercase ASCII letters after a lowercase one: where camelCase starts a word.
_WORD_START = re.compile(r"(?<=[a-z])[A-Z]+")
_HEX_COLOUR = re.compile(r"#([0-9a-fA-F]{2})([0-9a-fA-F]{2})([0-9a-fA-F]{2})")
# How many renames the note names before it counts the rest.
_NAMED_IN_NOTE = 4


def snake_case(name: str) -> str:
    """``name`` as Mitsuba 3 upgrades a property name: ``sampleCount`` -> ``sample_count``,
    ``intIOR`` -> ``int_ior`` (parser.cpp, ``camel_to_underscore_case``)."""
    return _WORD_START.sub(lambda word: "_" + word.group(0).lower(), name)


@dataclass
class Upgrade:
    """What the upgrade did to a scene, for its note.

    versions : the upgraded files' versions as text, by file name, in the order they were read.
    renamed : each distinct (as written, new) name pair, in document order (the keys of a dict
        used as an ordered set).
    """

    versions: dict[str, str]
    renamed: dict[tuple[str, str], None] = field(default_factory=dict)

    def note(self, path: str) -> str:
        """The one line a load tells: from which version(s), and which names changed."""
        if len(self.versions) == 1 and path in self.versions:
            origin = f"version {self.versions[path]}"
        else:
            origin = ", ".join(f"version {version} ({shown(name)})"
                               for name, version in self.versions.items())
        pairs = [f"{shown(old)} -> {shown(new)}" for old, new in list(self.renamed)[:_NAMED_IN_NOTE]]
        if len(self.renamed) > _NAMED_IN_NOTE:
            pairs.append(f"and {len(self.renamed) - _NAMED_IN_NOTE} more")
        renames = (f"property names renamed to Mitsuba 3's: {', '.join(pairs)}" if pairs
                   else "no property name needed renaming")
        return f"{path}: upgraded from {origin} as Mitsuba 3 upgrades older scenes; {renames}"


def upgrade_document(document: Document) -> Upgrade | None:
    """Upgrade, in place, the objects of every file of ``document`` whose version is below
    2.0.0, and refuse what Mitsuba 3.9.1 refuses in them. Returns what was done (None when no
    file is old). Line numbers are kept: elements are renamed, never made anew (but for the
    ``to_uv`` made of uoffset & co., which takes the first one's line)."""
    old = {name: version for name, version in document.versions.items() if version < FIRST_CURRENT_VERSION}
    if not old:
        return None
    upgrade = Upgrade({name: ".".join(map(str, version)) for name, version in old.items()})
    stack = [document.root]
    while stack:
        element = stack.pop()
        stack.extend(reversed(element.children))
        if element.file not in old:
            continue
        _refuse_what_mitsuba_3_refuses(element)
        if element.tag in OBJECT_TAGS or (element.tag == "spectrum" and "type" in element.attrs):
            _upgrade_object(element, old[element.file], upgrade)
    return upgrade


def _upgrade_object(obj: Element, version: tuple[int, int, int], upgrade: Upgrade) -> None:
    """Rename ``obj``'s properties (and named references and objects) as Mitsuba 3 renames
    those of an object written in a file of ``version``."""
    named = [child for child in obj.children if "name" in child.attrs]
    # name -> (the child holding it, the name that child is written with)
    holders: dict[str, tuple[Element, str]] = {}
    for child in named:
        holders.setdefault(child.attrs["name"], (child, child.attrs["name"]))
    for child in named:
        written = child.attrs["name"]
        new = snake_case(written)
        if new != written:
            _rename(obj, child, new, holders, version)
    if obj.attrs.get("type") == "diffuse":
        for child in named:
            if child.attrs["name"] == "diffuse_reflectance":
                _rename(obj, child, "reflectance", holders, version)
    _uv_transform(obj, [child for child in named if child.attrs["name"] in _UV_PROPERTIES], upgrade)
    for child in named:
        if child.attrs["name"] in _UV_PROPERTIES:
            continue
        if child.written_name is not None:
            upgrade.renamed.setdefault((child.written_name, child.attrs["name"]))


def _uv_transform(obj: Element, given: list[Element], upgrade: Upgrade) -> None:
    """``uoffset``, ``voffset``, ``uscale``, ``vscale`` made the one ``to_uv`` transform Mitsuba 3
    makes of them (parser.cpp, ``upgrade_from_v1``): scale(uscale, vscale) times
    translate(uoffset, voffset), so (u, v) -> (uscale (u + uoffset), vscale (v + voffset)). The
    new ``<transform>`` is given the line of the first of them, for messages."""
    if not given:
        return
    values = {"uoffset": 0.0, "voffset": 0.0, "uscale": 1.0, "vscale": 1.0}
    for child in given:
        if child.tag not in ("float", "integer"):
            child.fail(f"'{child.attrs['name']}' is a float, not a {child.tag}", obj)
        values[child.attrs["name"]] = number(child, child.attr("value"), child.attrs["name"])
    if any(child.attrs.get("name") == "to_uv" for child in obj.children):
        given[0].fail("uoffset, voffset, uscale and vscale beside a to_uv (Mitsuba 3 would replace it)", obj)
    su, sv = values["uscale"], values["vscale"]
    matrix = f"{su!r} 0 0 {su * values['uoffset']!r} 0 {sv!r} 0 {sv * values['voffset']!r} 0 0 1 0 0 0 0 1"
    first = given[0]
    transform = Element("transform", {"name": "to_uv"}, first.file, first.line,
                        [Element("matrix", {"value": matrix}, first.file, first.line)])
    obj.children = [c for c in obj.children if c not in given]
    obj.children.insert(0, transform)
    upgrade.renamed.setdefault(("uoffset/voffset/uscale/vscale", "to_uv"))


def _rename(obj: Element, child: Element, new: str, holders: dict[str, tuple[Element, str]],
            version: tuple[int, int, int]) -> None:
    """Give ``child`` the name ``new``, unless another property of ``obj`` holds it (the same
    name written twice is left to the reader, which says "given twice")."""
    old = child.attrs["name"]
    written = child.written_name or old
    holder = holders.get(new)
    if holder is not None and holder[1] != written:
        child.fail(f"'{shown(written)}' becomes '{shown(new)}' in the upgrade of a version "
                   f"{'.'.join(map(str, version))} file, but {holder[0].describe()} (line {holder[0].line}) "
                   f"already holds that name: Mitsuba 3 keeps '{shown(old)}' and refuses it unread", obj)
    holders.setdefault(new, (child, written))
    child.written_name = written
    child.attrs["name"] = new


def _refuse_what_mitsuba_3_refuses(element: Element) -> None:
    """Mitsuba 0.6's elements and colours that Mitsuba 3.9.1 refuses (parser.cpp knows no
    ``<lookAt>``, ``<srgb>`` or ``<blackbody>``, and reads ``<rgb>`` values as numbers only),
    refused with what to write instead, as Mitsuba 0.6 meant them."""
    tag = element.tag
    if tag == "lookAt":
        element.fail("Mitsuba 3.9.1 does not upgrade <lookAt> (Mitsuba 0.6's spelling) and refuses it: "
                     "write <lookat>")
    if tag == "blackbody":
        element.fail("Mitsuba 3.9.1 does not upgrade <blackbody> and refuses it (its spectrum plugin "
                     "<spectrum type=\"blackbody\"> works in spectral variants only, not in the RGB ones "
                     "tracer follows): give the colour as <rgb> or <spectrum value>")
    if tag == "srgb":
        linear = _srgb_decoded(element)
        instead = (f": write <rgb name=\"{shown(element.attrs.get('name', ''))}\" value=\"{linear}\"/>, its "
                   "linear values" if linear else ": give its linear values in <rgb>")
        element.fail("Mitsuba 3.9.1 does not upgrade <srgb> (Mitsuba 0.6's gamma-encoded colour) and "
                     f"refuses it{instead}")
    if tag == "rgb":
        hex_colour = _HEX_COLOUR.fullmatch(element.attrs.get("value", "").strip())
        if hex_colour:
            values = ", ".join(f"{int(byte, 16) / 255:.6g}" for byte in hex_colour.groups())
            element.fail(f"Mitsuba 3.9.1 reads no #rrggbb colours: write value=\"{values}\" (Mitsuba 0.6 "
                         "read each byte / 255, not sRGB-decoded, in <rgb>)")


def _srgb_decoded(element: Element) -> str | None:
    """The linear values, as text, of an ``<srgb value>`` as Mitsuba 0.6 decoded it (one number,
    three, or ``#rrggbb`` as bytes / 255; then the sRGB curve, ``fromSRGBComponent`` in its
    src/libcore/spectrum.cpp); None if the value is none of these."""
    text = element.attrs.get("value", "").strip()
    hex_colour = _HEX_COLOUR.fullmatch(text)
    if hex_colour:
        encoded = [int(byte, 16) / 255 for byte in hex_colour.groups()]
    else:
        try:
            encoded = numbers(element, text, "value")
        except InputError:  # not numbers: the refusal says what to do without them
            return None
        if len(encoded) not in (1, 3):
            return None
    try:
        linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in encoded]
    except OverflowError:  # a number far beyond any colour
        return None
    return ", ".join(f"{c:.6g}" for c in linear)
