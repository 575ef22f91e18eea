"""Samples per second of each strategy on one scene (median of several runs, one process).

    python benchmarks/strategy_speed.py [SCENE] [--width 256 --height 256 --spp 64 --runs 3]

Prints a Markdown table and the machine it ran on. Timing lives here, never in the tests.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

from tracer.render_loop import RenderSettings, render
from tracer.scene import default_scene_path, load_scene
from tracer.strategy import STRATEGIES, Strategy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default=str(default_scene_path()))
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()

    scene = load_scene(args.scene, args.width, args.height)
    samples = args.width * args.height * args.spp
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, {args.threads} threads")
    print(f"scene: {scene.name} {args.width}x{args.height}, {args.spp} spp, median of {args.runs} runs\n")
    print("| strategy | seconds | M samples/s |")
    print("|---|---:|---:|")
    for name in STRATEGIES:
        # Untimed: the first render of a process compiles (or loads) the kernels.
        render(scene, Strategy(name), RenderSettings(spp=1, seed=0, threads=args.threads))
        times = []
        for run in range(args.runs):
            start = time.perf_counter()
            render(scene, Strategy(name), RenderSettings(spp=args.spp, seed=run, threads=args.threads))
            times.append(time.perf_counter() - start)
        seconds = statistics.median(times)
        print(f"| {name} | {seconds:.2f} | {samples / seconds / 1e6:.2f} |")


if __name__ == "__main__":
    main()
