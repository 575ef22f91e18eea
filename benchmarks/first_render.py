#!/usr/bin/env python3
"""How long a new user waits for the first image, and for each feature's first use.

Each case is one ``tracer render`` command run as a whole process (wall time, the machine's load
average printed beside it), in this order against one kernel cache that starts empty (a fresh
``NUMBA_CACHE_DIR``): so the first case is a first render on a fresh install, and each later one
the first use of a feature after the ones before it. Then the first case again, warm: the
start-up of every later run. ``--runs N`` repeats the warm one N times (median).

    python benchmarks/first_render.py [--runs 5] [--only default,cornell]

Cases: the default scene; ``cornell``; a scene with every material type and every emitter kind
(``every_feature``, written to a temporary folder) under each light sampling; and, on the
default scene, each other light selection, sampler, strategy and MIS setting (ris, bvh, sobol,
stratified, optimal MIS, adaptive allocation, one-sample MIS, light and bsdf alone).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# Every material type tracer has (by its scene-file name) on a row of spheres, lit by a quad, a
# triangle of a mesh file, an emitting sphere and a point light.
EVERY_FEATURE = """
[camera]
origin = [0.0, 2.0, 9.0]
target = [0.0, 0.6, 0.0]
fov = 45.0
width = 64
height = 48

[materials.floor]
type = "diffuse"
reflectance = [0.6, 0.6, 0.6]

{materials}

[[shapes]]
type = "quad"
origin = [-6.0, 0.0, -6.0]
edge1 = [0.0, 0.0, 12.0]
edge2 = [12.0, 0.0, 0.0]
material = "floor"

{spheres}

[[shapes]]
type = "quad"
origin = [-1.0, 4.0, -1.0]
edge1 = [2.0, 0.0, 0.0]
edge2 = [0.0, 0.0, 2.0]
emission = [6.0, 6.0, 6.0]

[[shapes]]
type = "sphere"
center = [3.5, 3.0, 1.0]
radius = 0.3
emission = [4.0, 3.0, 2.0]

[[shapes]]
type = "mesh"
file = "triangle.obj"
emission = [2.0, 3.0, 5.0]

[[lights]]
type = "point"
position = [0.0, 5.0, 4.0]
intensity = [3.0, 3.0, 3.0]
"""


def every_feature_scene(folder: Path) -> Path:
    """The scene above with one sphere of each registered material type, in its default
    parameters (``MaterialType.params``' defaults, or the midpoint of the range)."""
    from tracer import materials

    blocks, spheres = [], []
    for i, (name, kind) in enumerate(sorted(materials.TYPES.items())):
        lines = [f"[materials.m{i}]", f'type = "{name}"']
        for param in kind.params:
            if getattr(param, "default", None) is not None:
                continue
            lo = param.lo if param.lo is not None else 0.0
            hi = param.hi if param.hi is not None and param.hi < 10 else lo + 1.0
            value = round(lo + 0.5 * (hi - lo), 3)
            lines.append(f"{param.name} = "
                         + (f"[{value}, {value}, {value}]" if param.size == 3 else f"{value}"))
        blocks.append("\n".join(lines))
        spheres.append(f'[[shapes]]\ntype = "sphere"\ncenter = [{-4.5 + 1.1 * i:.2f}, 0.5, 0.0]\n'
                       f'radius = 0.5\nmaterial = "m{i}"')
    (folder / "triangle.obj").write_text("v -4 3 -2\nv -3.5 3.5 -1\nv -3 3 -2\nf 1 2 3\n")
    path = folder / "every_feature.toml"
    path.write_text(EVERY_FEATURE.format(materials="\n\n".join(blocks), spheres="\n\n".join(spheres)))
    return path


def cases(every: Path) -> list[tuple[str, list[str]]]:
    small = ["--width", "32", "--height", "32", "--spp", "2"]
    out = [("default", small), ("cornell", ["scenes/cornell.toml", *small])]
    for sampling in ("area", "solid-angle", "solid-angle-cos"):
        out.append((f"every_feature {sampling}", [str(every), "--light-sampling", sampling, "--spp", "2"]))
    for name, options in (("ris", ["--strategy", "ris"]), ("bvh", ["--light-selection", "bvh"]),
                          ("uniform selection", ["--light-selection", "uniform"]),
                          ("sobol", ["--sampler", "sobol"]), ("stratified", ["--sampler", "stratified"]),
                          ("optimal", ["--heuristic", "optimal", "--light-samples", "2",
                                       "--bsdf-samples", "2"]),
                          ("adaptive", ["--allocation", "adaptive"]), ("one-sample", ["--one-sample"]),
                          ("light", ["--strategy", "light"]), ("bsdf", ["--strategy", "bsdf"])):
        out.append((name, [*small, *options]))
    return out


def run(arguments: list[str], cache: Path, out: Path) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # a user's Python keeps its bytecode
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "tracer", "render", *arguments, "--out", str(out),
                           "--quiet", "--force"],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{arguments}: exit {done.returncode}\n{done.stderr[-2000:]}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="warm runs of the first case (median)")
    parser.add_argument("--only", default="", help="comma-separated case names (default: all)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        every = every_feature_scene(folder)
        chosen = cases(every)
        if args.only:
            wanted = {n.strip() for n in args.only.split(",")}
            chosen = [c for c in chosen if c[0] in wanted or c[0].split()[0] in wanted]
        cache = folder / "cache"
        cache.mkdir()
        print(f"# {os.cpu_count()} cores; cache {cache} (empty at the start)")
        for name, arguments in chosen:
            load = os.getloadavg()[0]
            seconds = run(arguments, cache, folder / "out.exr")
            print(f"{name:<28} cold {seconds:7.1f} s   (load {load:.2f})", flush=True)
        warm = []
        for _ in range(args.runs):
            warm.append(run(chosen[0][1], cache, folder / "out.exr"))
        print(f"{chosen[0][0]:<28} warm {statistics.median(warm):7.2f} s   (median of {args.runs}: "
              f"{', '.join(f'{s:.2f}' for s in warm)}; load {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
