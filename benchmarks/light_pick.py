"""What one light-selection pick costs: ``power`` (Walker's alias table) against ``bvh`` (the
light BVH's descent, ``tracer.lights.bvh``), in nanoseconds on one core (issue 34, part 3).

    python benchmarks/light_pick.py [SCENE ...] [--points 200000] [--repeats 5] [--out DIR]

For each scene (default: the shipped ``many_lights``, ``emissive_mesh``, ``veach_mis`` and
``cornell``; any scene file may be named), shading points are drawn uniformly by area on the
scene's triangles with their geometric normals (so the descent meets the trees as renders do,
but without a render's coherence between neighbouring lanes: a pessimistic cache), and the
selection's compiled per-lane loop (``LightSampler.choose``) picks a light at each, then
``LightSampler.selection_pmf`` recomputes the pmf of the pick (what MIS asks of a BSDF sample
that meets an emitter). Each figure is the best of ``--repeats`` timed passes over all points
after one warm-up, so compilation is excluded; the tree's mean leaf depth is reported beside it.
Writes OUT/light_pick.json and OUT/light_pick.md. Timing lives in benchmarks, never in the
tests; the machine and its load are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from efficiency_runs import write_results  # noqa: E402

DEFAULT_SCENES = ["many_lights", "emissive_mesh", "veach_mis", "cornell"]


def surface_points(scene, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points uniform by area on the scene's triangles and their unit normals."""
    a, b, c = (scene.vertices[scene.faces[:, j]].astype(np.float64) for j in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    keep = area > 0
    a, b, c, cross, area = a[keep], b[keep], c[keep], cross[keep], area[keep]
    t = rng.choice(len(area), count, p=area / area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    x = a[t] * (1 - s)[:, None] + b[t] * (s * (1 - r2))[:, None] + c[t] * (s * r2)[:, None]
    return np.ascontiguousarray(x), np.ascontiguousarray(cross[t] / area[t][:, None])


def best_of(repeats: int, run) -> float:
    run()  # warm-up: compiled code loaded, caches filled
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def measure(path: str, points: int, repeats: int) -> dict:
    from tracer.lights import LightSampler
    from tracer.lights.selections import bvh as bvh_selection
    from tracer.scene import load_scene

    # The tree's own cost: a render on a scene whose tree is one leaf runs power instead
    # (bvh.runs_as), which this benchmark would otherwise time twice.
    bvh_selection.runs_as = lambda tables: None
    scene = load_scene(path)
    rng = np.random.default_rng(1)
    x, n = surface_points(scene, points, rng)
    u = rng.random(points)
    row: dict = {"scene": Path(path).stem if os.sep in path else path}
    for selection in ("power", "bvh"):
        sampler = LightSampler(scene, selection)
        k, _ = sampler.choose(u, x, n)
        k = np.where(k < 0, 0, k)
        row[f"{selection}_pick_ns"] = best_of(repeats, lambda: sampler.choose(u, x, n)) / points * 1e9
        row[f"{selection}_pmf_ns"] = best_of(repeats, lambda: sampler.selection_pmf(k, x, n)) / points * 1e9
        if selection == "bvh":
            tree = sampler.tables.selection
            row["candidates"] = int(sampler.count)
            row["leaves"] = int(np.sum(tree.child < 0))
            row["mean_depth"] = float(tree.trail_depth.mean()) if len(tree.trail_depth) else 0.0
    return row


def markdown(doc: dict) -> str:
    lines = [f"Light pick cost, ns per pick on one core ({doc['points']:,} surface points per scene, "
             f"best of {doc['repeats']}; {doc['machine']}).", "",
             "| scene | candidates | leaves | mean leaf depth | power pick | power pmf | bvh pick "
             "| bvh pmf |",
             "|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        lines.append(f"| {r['scene']} | {r['candidates']:,} | {r['leaves']:,} | {r['mean_depth']:.1f} | "
                     f"{r['power_pick_ns']:.1f} | {r['power_pmf_ns']:.1f} | {r['bvh_pick_ns']:.0f} | "
                     f"{r['bvh_pmf_ns']:.0f} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES)
    parser.add_argument("--points", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    rows = []
    for path in args.scenes:
        rows.append(measure(path, args.points, args.repeats))
        print(rows[-1], file=sys.stderr)
    doc = {"points": args.points, "repeats": args.repeats,
           "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load "
                      f"{os.getloadavg()[0]:.2f} at the end",
           "command": "python " + " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]), "rows": rows}
    write_results(Path(args.out), "light_pick", doc, markdown(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
