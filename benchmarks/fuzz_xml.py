"""The fuzzer's Mitsuba XML family (``benchmarks/fuzz.py`` holds the runner and the others).

Each case is a small valid Mitsuba 3 scene (a camera, a floor, a light, a shape with a BSDF)
with one to three hostile changes, chosen from the classes the adversarial run of issue 38 used:

- ``$name`` substitution that grows (defaults nested ``depth`` deep, each ``k`` uses of the one
  below), used once in a big attribute or once in each of many elements, in the main file or in
  an include: refused quickly, never built;
- include graphs: chains around the depth limit (16 allowed), diamonds (2^d reads, stopped by
  the file limit), cycles, includes of folders, FIFOs, devices and missing files, files found
  through ``<path>`` folders, many ``<path>`` entries;
- huge and odd strings in every slot (ids, types, names, values, file names: megabytes,
  newlines, terminal escapes, bidi marks): one short line;
- mesh files with polygons of every size, bad indices, no faces, CRLF and tabs;
- camera matrices near and beyond Mitsuba's rigidity tolerance, singular, NaN, huge;
- BSDF reference graphs (``ref``, ``twosided`` chains, self references, cycles), used or not;
- material values at and beyond the ends of tracer's ranges (plastic IORs, conductor eta and
  k, roughness).

Checks: ``tracer.load_scene`` in the probe worker and ``tracer render`` of 8 x 8 pixels at 2 spp
in a subprocess; both under the runner's memory limit, so a substitution that is built instead
of refused is a crash or a traceback, and one that takes minutes is a hang.
"""

from __future__ import annotations

import math
import os
import random
from pathlib import Path
from typing import Callable

SENSOR = ('<sensor type="perspective"><float name="fov" value="40"/>'
          '<transform name="to_world"><lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/></transform>'
          '<film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>'
          '</sensor>')
FLOOR = ('<shape type="rectangle" id="floor"><transform name="to_world"><scale value="3"/>'
         '<rotate x="1" angle="-90"/></transform><bsdf type="diffuse"/></shape>')
LIGHT = ('<shape type="sphere"><point name="center" x="0" y="2" z="0"/><float name="radius" value="0.3"/>'
         '<emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>')
THING = '<shape type="cube" id="thing"><transform name="to_world"><scale value="0.4"/></transform>{bsdf}</shape>'
DIFFUSE = '<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>'

# Odd strings for names and values: long, control characters, escapes, bidi marks, non-ASCII.
ODD_TEXT = ("a\nb", "tab\there", "\x1b[31mred\x1b[0m", "\u202ereversed", "émoji 🎨", "\ufeffbom",
            "../../etc/passwd", "%s%n", "$", "$$", "${x}", "")


def _scene(body: str, version: str = "3.0.0") -> str:
    return f'<scene version="{version}">\n{body}\n</scene>\n'


def _base(bsdf: str = DIFFUSE) -> list[str]:
    return [SENSOR, FLOOR, LIGHT, THING.format(bsdf=bsdf)]


class XmlCase:
    """The files of one case as it is built: the main scene's parts and other files."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.parts = _base()
        self.files: dict[str, str | bytes] = {}
        self.inputs: set[str] = {"scene.xml"}
        self.fifo_scene = False  # the main scene file is a FIFO (written by include_graph)

    def add_file(self, name: str, content: str | bytes) -> None:
        self.files[name] = content
        self.inputs.add(name)

    def write(self) -> None:
        for name, content in self.files.items():
            path = self.folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(content, bytes):
                path.write_bytes(content)
            else:
                path.write_text(content, encoding="utf-8", errors="surrogatepass")
        if not self.fifo_scene:
            (self.folder / "scene.xml").write_text(_scene("\n".join(self.parts)), encoding="utf-8",
                                                   errors="surrogatepass")


def substitution_bomb(rng: random.Random, case: XmlCase) -> str:
    """Defaults nested ``depth`` deep, each ``k`` uses of the one below."""
    depth, k = rng.randint(2, 40), rng.randint(2, 10)
    defaults = ['<default name="d0" value="x"/>'] + [
        f'<default name="d{i + 1}" value="{("$d" + str(i)) * k}"/>' for i in range(depth)]
    uses = rng.choice(("one big attribute", "many elements", "in an include", "an undefined name"))
    top = f"$d{depth}"
    if uses == "one big attribute":
        case.parts.append(f'<shape type="sphere" id="{top}"/>')
    elif uses == "many elements":
        case.parts += [f'<shape type="sphere" id="s{i}"><float name="radius" value="$d{min(depth, 3)}"/></shape>'
                       for i in range(rng.choice((10, 100, 1000)))]
    elif uses == "in an include":
        case.add_file("defaults.xml", _scene("\n".join(defaults)))
        case.parts.insert(0, '<include filename="defaults.xml"/>')
        case.parts.append(f'<shape type="sphere" id="{top}"/>')
        return f"$name bomb: depth {depth}, {k} uses each, defined in an include"
    else:
        case.parts.append('<shape type="sphere" id="$nowhere"/>')
    case.parts[:0] = defaults
    return f"$name bomb: depth {depth}, {k} uses each, {uses}"


def include_graph(rng: random.Random, case: XmlCase) -> str:
    """Chains, diamonds, cycles and includes of things that are not XML files."""
    how = rng.choice(("chain", "diamond", "cycle", "folder", "fifo", "device", "missing", "through path",
                      "many paths", "not xml", "absolute"))
    if how == "chain":
        depth = rng.randint(14, 18)
        for i in range(depth):
            inner = f'<include filename="c{i + 1}.xml"/>' if i + 1 < depth else DIFFUSE.replace(
                "<bsdf", '<bsdf id="deep"')
            case.add_file(f"c{i}.xml", _scene(inner))
        case.parts.insert(0, '<include filename="c0.xml"/>')
        return f"include chain {depth} deep"
    if how == "diamond":
        depth = rng.randint(5, 14)
        for i in range(depth):
            inner = (f'<include filename="d{i + 1}.xml"/><include filename="d{i + 1}.xml"/>'
                     if i + 1 < depth else "")
            case.add_file(f"d{i}.xml", _scene(inner))
        case.parts.insert(0, '<include filename="d0.xml"/>')
        return f"include diamond {depth} deep ({2 ** depth} reads)"
    if how == "cycle":
        length = rng.randint(1, 5)
        for i in range(length):
            case.add_file(f"y{i}.xml", _scene(f'<include filename="y{(i + 1) % length}.xml"/>'))
        case.parts.insert(0, '<include filename="y0.xml"/>')
        return f"include cycle of {length}"
    if how == "folder":
        (case.folder / "sub").mkdir(exist_ok=True)
        case.parts.insert(0, '<include filename="sub"/>')
        return "include of a folder"
    if how == "fifo":
        if not (case.folder / "pipe.xml").exists():
            os.mkfifo(case.folder / "pipe.xml")
        case.inputs.add("pipe.xml")
        if rng.random() < 0.5 and not case.fifo_scene:
            os.replace(case.folder / "pipe.xml", case.folder / "scene.xml")
            case.fifo_scene = True
            return "the scene file is a FIFO"
        case.parts.insert(0, '<include filename="pipe.xml"/>')
        return "include of a FIFO"
    if how == "device":
        if not (case.folder / "zero.xml").is_symlink():
            os.symlink("/dev/zero", case.folder / "zero.xml")
        case.inputs.add("zero.xml")
        case.parts.insert(0, '<include filename="zero.xml"/>')
        return "include of /dev/zero"
    if how == "missing":
        case.parts.insert(0, f'<include filename="{rng.choice(("nope.xml", "a/b/c.xml", "", "."))}"/>')
        return "include of a missing file"
    if how == "through path":
        case.add_file("parts/found.xml", _scene(DIFFUSE.replace("<bsdf", '<bsdf id="found"')))
        case.parts.insert(0, '<path value="parts"/><include filename="found.xml"/>')
        return "include found through <path>"
    if how == "many paths":
        count = rng.choice((50, 100, 101, 150))
        for i in range(count):
            (case.folder / f"p{i}").mkdir(exist_ok=True)
        case.parts.insert(0, "".join(f'<path value="p{i}"/>' for i in range(count)))
        return f"{count} <path> folders"
    if how == "not xml":
        case.add_file("junk.xml", bytes(rng.randrange(256) for _ in range(200)))
        case.parts.insert(0, '<include filename="junk.xml"/>')
        return "include of random bytes"
    case.parts.insert(0, '<include filename="/etc/hostname"/>')
    return "include of an absolute path outside the scene"


def huge_string(rng: random.Random, case: XmlCase) -> str:
    """A huge or odd string in one slot."""
    size = rng.choice((300, 100_000, 8_000_000))
    text = rng.choice(("x" * size, ("é" * size)[:size], "\n" * min(size, 10000), rng.choice(ODD_TEXT) * 3))
    slot = rng.choice(("id", "type", "property name", "value", "filename", "tag", "attribute name"))
    if slot == "id":
        case.parts.append(f'<bsdf type="diffuse" id="{_attr(text)}"/>')
    elif slot == "type":
        case.parts.append(f'<bsdf type="{_attr(text)}"/>')
    elif slot == "property name":
        case.parts.append(f'<shape type="sphere"><float name="{_attr(text)}" value="1"/></shape>')
    elif slot == "value":
        case.parts.append(f'<shape type="sphere"><float name="radius" value="{_attr(text)}"/></shape>')
    elif slot == "filename":
        case.parts.append(f'<shape type="obj"><string name="filename" value="{_attr(text)}"/></shape>')
    elif slot == "tag":
        case.parts.append(f"<{'t' * min(size, 100000)}/>")
    else:
        case.parts.append(f'<shape type="sphere" {"a" * min(size, 100000)}="1"/>')
    return f"a {len(text)}-character string as a{'n' if slot[0] in 'aeiou' else ''} {slot}"


def _attr(text: str) -> str:
    return text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")


def polygon_mesh(rng: random.Random, case: XmlCase) -> str:
    """An OBJ or PLY with faces of 0 .. many corners, bad indices or odd whitespace."""
    corners = rng.choice((1, 2, 3, 4, 5, 8, 255))
    ring = [(round(0.5 * math.cos(2 * math.pi * i / corners), 6), round(0.5 * math.sin(2 * math.pi * i / corners), 6))
            for i in range(corners)]
    how = rng.choice(("obj", "obj", "obj crlf tabs", "obj bad index", "obj no faces", "ply", "ply mixed"))
    if how.startswith("obj"):
        lines = [f"v {x} {y} 0" for x, y in ring]
        face = "f " + " ".join(str(i + 1) for i in range(corners))
        if how == "obj bad index":
            face = "f " + " ".join(str(i + 1 + rng.choice((0, 0, 100, -1000))) for i in range(corners))
        if how != "obj no faces":
            lines.append(face)
        text = "\n".join(lines) + "\n"
        if how == "obj crlf tabs":
            text = text.replace(" ", "\t").replace("\n", "\r\n")
        case.add_file("poly.obj", text.encode())
        case.parts.append('<shape type="obj"><string name="filename" value="poly.obj"/>'
                          '<bsdf type="diffuse"/></shape>')
        return f"{how} with a {corners}-corner face"
    header = ["ply", "format ascii 1.0", f"element vertex {corners}", "property float x", "property float y",
              "property float z", "element face 2" if how == "ply mixed" else "element face 1",
              "property list uchar int vertex_indices", "end_header"]
    rows = [f"{x} {y} 0" for x, y in ring] + [f"{corners} " + " ".join(str(i) for i in range(corners))]
    if how == "ply mixed":
        rows.append("3 0 1 2" if corners >= 3 else "1 0")
    case.add_file("poly.ply", ("\n".join(header + rows) + "\n").encode())
    case.parts.append('<shape type="ply"><string name="filename" value="poly.ply"/><bsdf type="diffuse"/></shape>')
    return f"{how} with a {corners}-corner face"


def camera_matrix(rng: random.Random, case: XmlCase) -> str:
    """A sensor whose to_world is nearly rigid, scaled, sheared, mirrored, singular or not finite."""
    scale = rng.choice((1.0, 1.0 + 5e-4, 1.0 - 5e-4, 1.0 + 2e-3, 0.0, -1.0, 1e308, float("nan"), float("inf")))
    shear = rng.choice((0.0, 1e-6, 1e-4, 9e-4, 2e-3, 0.5))
    digits = rng.choice((4, 5, 6, 17))
    m = [[scale, shear, 0.0, 0.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 4.0], [0.0, 0.0, 0.0, 1.0]]
    text = " ".join(f"{v:.{digits}g}" for row in m for v in row)
    case.parts[0] = SENSOR.replace('<lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/>',
                                   f'<matrix value="{text}"/>')
    return f"camera matrix with scale {scale}, shear {shear}, {digits} digits"


def bsdf_graph(rng: random.Random, case: XmlCase) -> str:
    """References among BSDFs: chains of twosided, self references, cycles, used or unused."""
    how = rng.choice(("self twosided", "cycle", "long chain", "alias loop", "unused dielectric"))
    if how == "self twosided":
        case.parts.append('<bsdf type="twosided" id="t"><ref id="t"/></bsdf>')
    elif how == "cycle":
        case.parts.append('<bsdf type="twosided" id="a"><ref id="b"/></bsdf>'
                          '<bsdf type="twosided" id="b"><ref id="a"/></bsdf>')
    elif how == "long chain":
        length = rng.choice((10, 1000, 10000))
        case.parts.append('<bsdf type="diffuse" id="c0"/>' + "".join(
            f'<bsdf type="twosided" id="c{i + 1}"><ref id="c{i}"/></bsdf>' for i in range(length)))
    elif how == "alias loop":
        case.parts.append('<alias id="p" as="q"/><alias id="q" as="p"/>')
    else:
        case.parts.append('<bsdf type="dielectric" id="glass"/>')
    if rng.random() < 0.5:
        target = {"self twosided": "t", "cycle": "a", "long chain": "c1", "alias loop": "p",
                  "unused dielectric": "glass"}[how]
        case.parts[3] = THING.format(bsdf=f'<ref id="{target}"/>')
        return f"BSDF graph: {how}, used"
    return f"BSDF graph: {how}, unused"


def material_extreme(rng: random.Random, case: XmlCase) -> str:
    """A BSDF value at or beyond an end of tracer's range (the ranges: docs/SCENE_FORMAT.md)."""
    bsdf, what = rng.choice((
        ('<bsdf type="plastic"><float name="int_ior" value="{v}"/></bsdf>', "plastic int_ior"),
        ('<bsdf type="roughplastic"><float name="ext_ior" value="{v}"/></bsdf>', "roughplastic ext_ior"),
        ('<bsdf type="conductor"><rgb name="eta" value="{v}"/><rgb name="k" value="{v}"/></bsdf>',
         "conductor eta and k"),
        ('<bsdf type="roughconductor"><float name="alpha" value="{v}"/></bsdf>', "roughconductor alpha"),
    ))
    value = rng.choice(("0", "1e-300", "1e-160", "5e-324", "0.01", "0.0099", "100", "100.01", "1000",
                        "1001", "1e300", "-1", "nan", "inf"))
    case.parts[3] = THING.format(bsdf=bsdf.format(v=value))
    return f"{what} = {value}"


MUTATIONS: tuple[tuple[Callable[[random.Random, XmlCase], str], int], ...] = (
    (substitution_bomb, 3), (include_graph, 4), (huge_string, 3), (polygon_mesh, 3), (camera_matrix, 2),
    (bsdf_graph, 2), (material_extreme, 3))


def build(rng: random.Random, folder: Path) -> tuple[list[str], tuple[str, ...]]:
    """Write a case into ``folder`` (its main file ``scene.xml``): (mutations, input names)."""
    case = XmlCase(folder)
    functions = [f for f, _ in MUTATIONS]
    weights = [w for _, w in MUTATIONS]
    mutations = [rng.choices(functions, weights)[0](rng, case)
                 for _ in range(rng.choices((1, 2, 3), (6, 3, 1))[0])]
    case.write()
    return mutations, tuple(sorted(case.inputs))
