#!/usr/bin/env python3
"""Where a short render's start-up time goes: imports, scene loading, kernel loading, writing.

Runs ``tracer render SCENE --width 32 --height 32 --spp 1`` a few times in fresh interpreters
(after one warm-up run that fills the kernel cache) and reports, as medians over the runs:

- the whole command's wall and CPU time;
- ``python -X importtime``'s cumulative import time of the heavy packages (numba, trimesh with
  the scipy it pulls in, OpenImageIO, embreex) and of tracer's own modules;
- the phases inside one render: loading the scene, building the estimator (Embree scene, light
  tables), loading the compiled kernels from the cache (``render_loop._compile``), rendering and
  writing the files. Loading the kernels includes numba's first-use set-up of its typing and
  lowering registries, during which numba checks for a BLAS by importing ``scipy.linalg``
  (about 0.35 s, found with cProfile); a scene with mesh files has already paid for much of
  scipy through trimesh, so its kernel loading looks shorter.

The machine's load average is printed with the numbers: on a shared machine wall time grows
with the load, CPU time much less. Usage: ``python benchmarks/startup.py [SCENE ...] [--runs 5]``
(default: veach_mis, which has no mesh files and so never imports trimesh, and cornell, which
has two).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("numba", "trimesh", "scipy", "OpenImageIO", "embreex", "tqdm")

# One render in-process, timing its phases; prints one line "phase seconds" per phase.
PHASES = r"""
import sys, time
t0 = time.perf_counter()
import tracer.cli  # noqa: F401  (what the command imports first)
from tracer.scene import load_scene
from tracer.estimator import DirectLighting
from tracer.film import Film
from tracer.imagefiles import write_exr, write_png
from tracer import render_loop, samplers
from tracer.strategy import Strategy
t1 = time.perf_counter()
scene = load_scene(sys.argv[1], 32, 32)
t2 = time.perf_counter()
estimator = DirectLighting(scene, Strategy("mis"))
t3 = time.perf_counter()
film = Film(32, 32)
render_loop._compile(estimator, film, samplers.make("independent", 0))
t4 = time.perf_counter()
result = render_loop.render(scene, Strategy("mis"), render_loop.RenderSettings(spp=1, threads=2),
                            estimator=estimator)
t5 = time.perf_counter()
write_exr(sys.argv[2], result.film)
write_png(sys.argv[2][:-4] + ".png", result.film.image())
t6 = time.perf_counter()
for name, a, b in (("imports", t0, t1), ("load scene", t1, t2), ("build estimator", t2, t3),
                   ("load kernels", t3, t4), ("render", t4, t5), ("write files", t5, t6)):
    print(f"{name}\t{b - a:.4f}")
"""


def run_command(scene: str, out: str) -> tuple[float, float]:
    """(wall, cpu) seconds of one ``tracer render`` in a fresh interpreter."""
    import resource
    import time

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tracer", "render", scene, "--width", "32", "--height", "32",
                    "--spp", "1", "--quiet", "-o", out, "--force"], check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def import_times(scene: str, out: str) -> dict[str, float]:
    """Cumulative import seconds of the heavy top-level packages and of tracer's own modules
    (tracer's figures exclude the heavy packages they import)."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "tracer", "render", scene, "--width",
                           "32", "--height", "32", "--spp", "1", "--quiet", "-o", out, "--force"],
                          capture_output=True, text=True, check=True)
    totals: dict[str, float] = {}
    for line in done.stderr.splitlines():
        match = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)", line)
        if not match:
            continue
        self_us, cumulative_us, indent, name = int(match[1]), int(match[2]), len(match[3]), match[4]
        top = name.split(".")[0]
        if top in HEAVY and indent <= 12 and name == top:
            totals[top] = totals.get(top, 0.0) + cumulative_us / 1e6
        if top == "tracer":
            totals["tracer (own code)"] = totals.get("tracer (own code)", 0.0) + self_us / 1e6
    return totals


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=[str(ROOT / "scenes" / "veach_mis.toml"),
                                                      str(ROOT / "scenes" / "cornell.toml")],
                        help="scene files (default: veach_mis, no mesh files, and cornell, two PLY meshes)")
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    for scene in args.scenes:
        report(scene, args.runs)
    return 0


def report(scene: str, runs: int) -> None:
    """Measure one scene and print its figures."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "startup.exr")
        run_command(scene, out)  # warm-up: fills the kernel cache if it is empty
        commands = [run_command(scene, out) for _ in range(runs)]
        imports = [import_times(scene, out) for _ in range(runs)]
        phases: dict[str, list[float]] = {}
        for _ in range(runs):
            done = subprocess.run([sys.executable, "-c", PHASES, scene, out], capture_output=True,
                                  text=True, check=True)
            for line in done.stdout.splitlines():
                name, seconds = line.split("\t")
                phases.setdefault(name, []).append(float(seconds))
    load = os.getloadavg()
    print(f"tracer render {Path(scene).name} --width 32 --height 32 --spp 1, median of {runs} "
          f"runs; {os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"  whole command: wall {statistics.median(w for w, _ in commands):.2f} s, "
          f"CPU {statistics.median(c for _, c in commands):.2f} s")
    print("  imports (cumulative, -X importtime):")
    for name in sorted({k for d in imports for k in d}, key=lambda k: -statistics.median(d.get(k, 0.0)
                                                                                          for d in imports)):
        print(f"    {name:<20} {statistics.median(d.get(name, 0.0) for d in imports):6.2f} s")
    print("  phases of one render (in-process):")
    for name, values in phases.items():
        print(f"    {name:<20} {statistics.median(values):6.2f} s")


if __name__ == "__main__":
    sys.exit(main())
