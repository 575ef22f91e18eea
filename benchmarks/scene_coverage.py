"""How many public Mitsuba scenes tracer renders, and why it refuses the others.

(Not ``coverage.py``: scripts here are run with this folder on ``sys.path``, and a module of
that name would hide the ``coverage`` package, which numba imports when it is installed.)

    python benchmarks/scene_coverage.py CORPUS [--jobs 2] [--timeout 600] [--out benchmarks/results]

CORPUS is a folder holding the sources of `benchmarks/scene_coverage_sources.toml`, each extracted
into a subfolder named by its `folder` (see that file for how to fetch them; the scenes
themselves are not committed). Every ``.xml`` file under a source's `scenes` folders whose root
element is ``<scene>`` is a scene, except files that another file of the corpus includes
(``<include filename>``): those are fragments.

Each scene is rendered as a user would render it, in its own process:

    tracer render SCENE --width 64 --height 64 --spp 16 -D spp=16 --quiet -o TMP/out.exr

(``-D spp=16`` defines ``$spp``, which Mitsuba's documentation scenes leave to the command line,
``mitsuba -D spp=...``.)

with ``TRACER_KERNELS=shared`` so that one kernel build serves every scene. The outcome is

- **renders**: exit status 0 and an EXR written;
- **refused**: exit status 2 and a last line ``tracer: error: ...`` with no traceback; the
  reason is grouped by the feature it names (`feature_of`);
- **crashed**: any other exit, or a traceback on stderr;
- **hung**: still running after `--timeout` seconds (default 600 s; kernels compile in the
  first renders, so this is not a render-time limit).

Writes ``scene_coverage.json`` (every scene, its outcome and its line) and ``scene_coverage.md`` (the table
for docs/results/scene-coverage.md) to `--out`.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCES = HERE / "scene_coverage_sources.toml"
INCLUDE = re.compile(rb'<include\b[^>]*\bfilename\s*=\s*"([^"]+)"')
ROOT_SCENE = re.compile(rb"^\s*(<\?xml[^>]*\?>\s*)?(<!--.*?-->\s*)*<scene\b", re.S)


def scenes_of(corpus: Path, sources: list[dict]) -> list[tuple[str, Path]]:
    """(source folder, path) of every scene of the corpus, fragments left out, sorted."""
    candidates: list[tuple[str, Path]] = []
    included: set[Path] = set()
    for source in sources:
        root = corpus / source["folder"]
        if not root.is_dir():
            sys.exit(f"scene_coverage: {root}: missing (fetch {source['repo']} there: see {SOURCES.name})")
        for folder in source.get("scenes", ["."]):
            for path in sorted((root / folder).rglob("*.xml")):
                text = path.read_bytes()
                for name in INCLUDE.findall(text):
                    included.add((path.parent / name.decode("utf-8", "replace")).resolve())
                if ROOT_SCENE.match(text):
                    candidates.append((source["folder"], path))
    return [(folder, path) for folder, path in candidates if path.resolve() not in included]


# A refusal names what it refuses; these patterns turn the line into the feature's name, the
# first that matches winning (the element's tag and type where the line shows one).
FEATURES = [
    (re.compile(r"is a Mitsuba 0\.|version \"?0\.|scene version"), "Mitsuba 0.x scene"),
    (re.compile(r'<(texture|bsdf|emitter|shape|sensor|medium|film|rfilter|sampler|phase|volume|spectrum)'
                r' type="([^"]+)"'), None),
    (re.compile(r"<(\w+)[ >]"), None),
    (re.compile(r"holds no triangles"), "mesh without triangles"),
]


def feature_of(line: str) -> str:
    """The feature a refusal line names, e.g. ``emitter envmap``, for grouping."""
    message = re.sub(r"^tracer: error: ", "", line)
    for pattern, name in FEATURES:
        match = pattern.search(message)
        if match:
            if name is not None:
                return name
            groups = [g for g in match.groups() if g]
            return " ".join(groups)
    return message[:60]


PLUGIN = re.compile(rb'<(shape|bsdf|emitter|texture|sensor|medium|phase|volume|spectrum|integrator)\b'
                    rb'[^>]*?\btype\s*=\s*"([^"$]+)"')
VERSION = re.compile(rb'<scene\b[^>]*\bversion\s*=\s*"(\d+)\.')
# The plugins tracer reads today (kept by hand: the static count below is a planning aid, the
# outcome of each render is the measurement). Integrators are all read (told, not obeyed).
READS = {
    "shape": {"obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk", "cylinder", "instance",
              "shapegroup"},
    "bsdf": {"diffuse", "conductor", "roughconductor", "plastic", "roughplastic", "pplastic", "twosided",
             "dielectric", "roughdielectric", "thindielectric", "mask", "normalmap", "bumpmap", "blendbsdf",
             "principled", "principledthin"},
    "emitter": {"area", "point", "spot", "projector", "directional", "envmap", "constant"},
    "sensor": {"perspective", "thinlens", "orthographic"},
    "texture": {"bitmap", "checkerboard", "mesh_attribute", "rawconstant"},
}

def needs(scene: Path) -> set[str]:
    """What a scene's files (the scene and, transitively, what it includes, found beside the
    including file or the scene) use that tracer does not read: ``emitter envmap``, ``Mitsuba
    0.x scene``, ... A static estimate from the text: a plugin declared but unused counts."""
    found: set[str] = set()
    seen: set[Path] = set()
    todo = [scene]
    while todo:
        path = todo.pop()
        if path in seen or not path.is_file():
            continue
        seen.add(path)
        text = path.read_bytes()
        version = VERSION.search(text)
        if version and int(version.group(1)) < 2:
            found.add("Mitsuba 0.x scene")
        for tag, kind in PLUGIN.findall(text):
            tag, kind = tag.decode(), kind.decode()
            if tag == "integrator":
                continue
            if kind not in READS.get(tag, set()):
                found.add(f"{tag} {kind}")
        for name in INCLUDE.findall(text):
            name = name.decode("utf-8", "replace")
            todo += [path.parent / name, scene.parent / name]
    return found


def render(scene: Path, timeout: float, spp: int, size: int) -> dict:
    """Render one scene in its own process; returns its outcome record."""
    env = dict(os.environ, TRACER_KERNELS="shared")
    with tempfile.TemporaryDirectory(prefix="coverage-") as folder:
        out = Path(folder) / "out.exr"
        # -D spp=N: Mitsuba's documentation scenes leave $spp for the command line (mitsuba -D).
        command = [sys.executable, "-m", "tracer", "render", str(scene), "--width", str(size),
                   "--height", str(size), "--spp", str(spp), "-D", f"spp={spp}", "--quiet", "-o", str(out)]
        start = time.monotonic()
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                  env=env, cwd=folder, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return {"outcome": "hung", "line": f"still running after {timeout:g} s",
                    "seconds": time.monotonic() - start}
        seconds = time.monotonic() - start
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        last = lines[-1] if lines else ""
        notes = [line for line in lines if line.startswith("tracer: note:")]
        if "Traceback" in done.stderr:
            outcome = "crashed"
        elif done.returncode == 0 and out.is_file():
            outcome = "renders"
        elif done.returncode == 2 and last.startswith("tracer: error:"):
            outcome = "refused"
        else:
            outcome = "crashed"
        record = {"outcome": outcome, "line": last, "seconds": seconds, "notes": notes,
                  "status": done.returncode, "needs": sorted(needs(scene))}
        if outcome == "refused":
            record["feature"] = feature_of(last)
        if outcome == "crashed":
            record["stderr_tail"] = done.stderr[-2000:]
        return record


def table(records: dict[str, dict], corpus_name: str, command: str) -> str:
    """The Markdown summary: outcomes, then refusals grouped by feature."""
    outcomes = Counter(r["outcome"] for r in records.values())
    features = Counter(r["feature"] for r in records.values() if r["outcome"] == "refused")
    lines = [f"Scenes: {len(records)} ({corpus_name}). Command: `{command}`", "",
             "| outcome | scenes |", "|---|---:|"]
    for outcome in ("renders", "refused", "crashed", "hung"):
        lines.append(f"| {outcome} | {outcomes.get(outcome, 0)} |")
    lines += ["", "| refused for (the first feature each scene's line names) | scenes |", "|---|---:|"]
    for feature, count in features.most_common():
        lines.append(f"| {feature.replace('|', '/')} | {count} |")
    # Every feature a refused scene needs, so that a scene counts once for each (static).
    needed = Counter(f for r in records.values() if r["outcome"] != "renders" for f in r.get("needs", []))
    lines += ["", "| feature the scenes that do not render use (each scene counted for each; from the "
              "files' text) | scenes |", "|---|---:|"]
    for feature, count in needed.most_common():
        lines.append(f"| {feature.replace('|', '/')} | {count} |")
    bad = [(name, r) for name, r in sorted(records.items()) if r["outcome"] in ("crashed", "hung")]
    if bad:
        lines += ["", "Crashed or hung:", ""]
        lines += [f"- `{name}`: {r['outcome']}: {r['line'][:160]}" for name, r in bad]
    return "\n".join(lines) + "\n"


def _relative(record: dict, corpus: str) -> dict:
    """The record with the corpus folder written CORPUS, so that the table reads the same
    wherever the corpus was extracted."""
    for key in ("line", "stderr_tail"):
        if key in record:
            record[key] = record[key].replace(corpus, "CORPUS")
    record["notes"] = [note.replace(corpus, "CORPUS") for note in record.get("notes", [])]
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corpus", type=Path)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--only", help="render only scenes whose path contains this")
    parser.add_argument("--out", type=Path, default=HERE / "results")
    args = parser.parse_args()
    sources = tomllib.loads(SOURCES.read_text())["source"]
    scenes = scenes_of(args.corpus, sources)
    if args.only:
        scenes = [(f, p) for f, p in scenes if args.only in str(p)]
    names = [str(path.relative_to(args.corpus)) for _, path in scenes]
    print(f"scene_coverage: {len(scenes)} scenes, {args.jobs} at a time", file=sys.stderr)
    records: dict[str, dict] = {}
    with ThreadPoolExecutor(args.jobs) as pool:
        futures = {name: pool.submit(render, path, args.timeout, args.spp, args.size)
                   for name, (_, path) in zip(names, scenes, strict=True)}
        for done_count, (name, future) in enumerate(futures.items(), 1):
            records[name] = r = _relative(future.result(), str(args.corpus.resolve()))
            print(f"[{done_count}/{len(scenes)}] {r['outcome']:8} {name}: {r['line'][:150]}",
                  file=sys.stderr, flush=True)
    command = (f"python benchmarks/scene_coverage.py CORPUS --spp {args.spp} --size {args.size}")
    corpus_name = ", ".join(s["repo"] + "@" + s["commit"][:8] for s in sources)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "scene_coverage.json").write_text(json.dumps(records, indent=1, sort_keys=True) + "\n")
    (args.out / "scene_coverage.md").write_text(table(records, corpus_name, command))
    print(table(records, corpus_name, command))


if __name__ == "__main__":
    main()
