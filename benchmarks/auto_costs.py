"""Measure the cost constants of ``tracer.auto`` (``COSTS``): seconds per camera sample of every
candidate strategy on several scenes, fitted by least squares to counts of work.

    python benchmarks/auto_costs.py [--lanes 65536] [--repeats 5] [SCENE ...]

Each candidate renders the same lanes (one thread, the pilot's lattice) ``--repeats`` times,
candidates interleaved within each repeat, and the median seconds per lane is kept. The model
(:func:`fit`): seconds per lane = t_scene x the sum of each kind of work counted (a camera
sample, shadings, shadow rays, direction rays, solid-angle and cosine-warped light samples,
BVH descents) times its weight, the weights shared by all scenes and in units of one shadow ray.
It writes the fit and each candidate's measured and modelled time to
``results/auto_costs.json``, so that a reader sees how well the model holds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_SCENES = ["cornell", "veach_mis", "many_lights", "big_light", "tiny_light", "emissive_mesh",
                  str(HERE.parent / "tracer/scenes/mitsuba/cornell_box.xml")]


def work_counts(strategy, lanes: int, shadow: int, direction: int, levels: float) -> dict[str, float]:
    """What a camera sample of ``strategy`` did in the pilot, per lane, by the terms of
    ``tracer.auto.cost_per_sample`` (``COSTS``'s keys); ``levels``: the light BVH's descent
    (``auto.bvh_levels``), 0 where none runs (a ``bvh`` that runs as ``power``)."""
    light = strategy.light_count
    bvh = strategy.light_selection == "bvh" and light > 0 and levels > 0.0
    return {"camera": 1.0, "shading": float(light + strategy.direction_count),
            "shadow_ray": shadow / lanes, "direction_ray": direction / lanes,
            "solid-angle": light if strategy.light_sampling == "solid-angle" else 0.0,
            "solid-angle-cos": light if strategy.light_sampling == "solid-angle-cos" else 0.0,
            "bvh_level": levels * (light + direction / lanes) if bvh else 0.0}


TERMS = ("camera", "shading", "shadow_ray", "direction_ray", "solid-angle", "solid-angle-cos", "bvh_level")


def fit(rows: list[dict]) -> dict[str, float]:
    """Least squares of log time: seconds per lane = t_scene x sum_k w_k x count_k, with one
    t_scene per scene (its rays cost what its geometry makes them cost) and the weights w_k
    shared, in units of the shadow ray (w = 1); relative errors, so cheap and dear strategies
    count alike. Returns the weights and the fit's median and largest relative errors."""
    from scipy.optimize import least_squares

    scenes = sorted({r["scene"] for r in rows})
    free = [k for k in TERMS if k != "shadow_ray"]
    x = np.array([[r[k] for k in TERMS] for r in rows])
    y = np.array([r["seconds_per_lane"] for r in rows])
    which = np.array([scenes.index(r["scene"]) for r in rows])

    def model(params):
        weights = dict(zip(free, np.exp(params[:len(free)])))
        weights["shadow_ray"] = 1.0
        w = np.array([weights[k] for k in TERMS])
        return np.exp(params[len(free):])[which] * (x @ w)

    start = np.concatenate([np.zeros(len(free)), np.log([np.median(y[which == i]) / 4 for i in
                                                          range(len(scenes))])])
    result = least_squares(lambda p: np.log(model(p)) - np.log(y), start)
    weights = dict(zip(free, np.exp(result.x[:len(free)]).tolist()))
    modelled = model(result.x)
    for r, m in zip(rows, modelled):
        r["modelled_seconds_per_lane"] = float(m)
    error = np.abs(modelled / y - 1.0)
    return {"weights": weights, "median_relative_error": float(np.median(error)),
            "max_relative_error": float(np.max(error)),
            "ns_per_shadow_ray": dict(zip(scenes, (np.exp(result.x[len(free):]) * 1e9).tolist()))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES)
    parser.add_argument("--lanes", type=int, default=1 << 16)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(HERE / "results" / "auto_costs.json"))
    args = parser.parse_args()

    from tracer import auto, samplers
    from tracer.scene import load_scene
    from tracer.scene.shipped import resolve_scene
    from tracer.estimator import DirectLighting
    from tracer.strategy import Strategy

    rows = []
    for name in args.scenes:
        scene = load_scene(resolve_scene(name))
        pixel_set = auto.pilot_pixels(scene.camera.width, scene.camera.height)
        spp = max(1, args.lanes // len(pixel_set))
        sampler = samplers.make("independent", 1, 0, spp)
        pixel = np.repeat(pixel_set, spp)
        sample = np.tile(np.arange(spp, dtype=np.int64), len(pixel_set))
        strategies = auto.candidates(scene, Strategy("auto"))
        estimators = {s: DirectLighting(scene, s) for s in strategies}
        for est in estimators.values():
            est.compile(sampler, progress=True)
        times: dict = {s: [] for s in strategies}
        counts = {}
        for _ in range(args.repeats):
            for s in strategies:
                est = estimators[s]
                rays: list = []
                t0 = time.perf_counter()
                origins, dirs = est.camera_rays(sampler, pixel, sample)
                est.shade_lanes(origins, dirs, sampler, pixel, sample, rays=rays)
                times[s].append(time.perf_counter() - t0)
                counts[s] = work_counts(s, len(pixel), sum(r[0] for r in rays), sum(r[1] for r in rays),
                                        auto.bvh_levels(est.lights.tables.selection.trail_depth)
                                        if est.lights.selection == "bvh" else 0.0)
        for s in strategies:
            rows.append({"scene": Path(name).stem, "strategy": s.slug, "seconds_per_lane":
                         statistics.median(times[s]) / len(pixel), **counts[s]})
            print(f"{Path(name).stem:14s} {s.slug:28s} {rows[-1]['seconds_per_lane'] * 1e9:8.1f} ns/lane "
                  f"rays {counts[s]['shadow_ray']:.2f} + {counts[s]['direction_ray']:.2f}", file=sys.stderr)

    result = fit(rows)
    print(json.dumps(result, indent=1))
    Path(args.out).write_text(json.dumps({"fit": result, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
