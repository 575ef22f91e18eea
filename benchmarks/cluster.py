"""The overhead of rendering a reference on Dask against rendering it in one process.

    python benchmarks/cluster.py [--scene veach_mis] [--size 256] [--spp 1024] [--workers 2]
                                 [--task-spp 32,128,512] [--rounds 3]

Times ``render_loop.render`` on ``--workers`` threads and ``cluster.render_distributed`` on a
local cluster of as many single-threaded worker processes, for each task size (and the default
one), interleaved round by round (each round starting one run further along) so that a drift
of this shared machine's speed hits all sides alike. The cluster is started, and every worker
has loaded the compiled kernels and built the scene, before the clock starts: the times
compare rendering, not start-up, which is reported apart (it is paid once per command).
Checks that every distributed image is the local one bit for bit. Prints a table of medians
and ratios (Dask / local). Timing lives here, never in the tests.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from tracer import cluster
from tracer import scene as scene_mod
from tracer.render_loop import RenderSettings, render
from tracer.strategy import Strategy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="veach_mis")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--task-spp", default="32,128,512")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    path = scene_mod.default_scene_path().with_name(f"{args.scene}.toml")
    scene = scene_mod.load_scene(path, args.size, args.size)
    strategy = Strategy("mis")
    settings = RenderSettings(spp=args.spp, seed=1, threads=args.workers)
    sizes: list[int | None] = [None] + [int(t) for t in args.task_spp.split(",") if t]

    started = time.perf_counter()
    with cluster.connect(workers=args.workers) as client:
        startup = time.perf_counter() - started
        # Every worker loads the kernels and builds the scene once, off the clock.
        warm = RenderSettings(spp=2 * args.workers * 8, seed=1)
        cluster.render_distributed(client, scene, strategy, warm, task_spp=8)
        warmed = time.perf_counter() - started
        render(scene, strategy, RenderSettings(spp=1, threads=args.workers))
        local_times, dask_times = [], {size: [] for size in sizes}
        expected = None
        got = []
        runs: list[int | str | None] = ["local", *sizes]
        for round_index in range(args.rounds):
            # Each round starts one further along the list: no run is always first or last.
            shift = round_index % len(runs)
            for size in runs[shift:] + runs[:shift]:
                t = time.perf_counter()
                if size == "local":
                    film = render(scene, strategy, settings).film
                    local_times.append(time.perf_counter() - t)
                    expected = film if expected is None else expected
                    continue
                film = cluster.render_distributed(client, scene, strategy, settings, task_spp=size).film
                dask_times[size].append(time.perf_counter() - t)
                got.append((size, film))
        for size, film in got:
            if not (np.array_equal(film.mean, expected.mean) and np.array_equal(film.m2, expected.m2)):
                sys.exit(f"task size {size}: the Dask image differs from the local one")
    local = statistics.median(local_times)
    print(f"{args.scene} {args.size}x{args.size}, {args.spp} spp, mis; {args.workers} threads locally, "
          f"{args.workers} single-threaded Dask workers; medians of {args.rounds} interleaved rounds")
    print(f"local cluster start {startup:.1f} s, workers warmed (kernels loaded, scene built) "
          f"after {warmed:.1f} s")
    print(f"{'run':>18} {'seconds':>8} {'vs local':>9}")
    print(f"{'local':>18} {local:8.2f} {1.0:9.3f}")
    for size in sizes:
        median = statistics.median(dask_times[size])
        label = "dask default" if size is None else f"dask {size} spp"
        print(f"{label:>18} {median:8.2f} {median / local:9.3f}")
    print("every Dask image was the local one bit for bit")


if __name__ == "__main__":
    main()
