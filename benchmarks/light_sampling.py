"""Light-sampling techniques side by side (issue 13): area, solid-angle and solid-angle-cos.

    python benchmarks/light_sampling.py [--scenes veach_mis,cornell] [--size 256] [--spp 16]
                                        [--time 4] [--seeds 3] [--threads 2]
                                        [--mitsuba-python PYTHON | --no-mitsuba]
                                        [--out benchmarks/results]

For each scene, against its shipped reference (``renders/references/SCENE.exr``, 1024-spp MIS):

- ``light`` and ``mis`` with each technique at equal spp (``--spp``) and at equal wall time
  (``--time`` seconds each), relMSE with the reference's noise subtracted, averaged over
  ``--seeds`` seeds (none of which the reference holds), and efficiency 1 / (relMSE x seconds);
  the ratio of each technique's efficiency to ``area``'s is what the issue's targets name;
- the share of light samples that come back 0, at the shading points the camera sees (pixel
  centres): before any ray is cast (the sampled point is on the light's far side or back, or
  below the receiver's horizon) and in all (those, plus the ones whose shadow ray is blocked);
- on ``cornell``, Mitsuba 3's ``direct`` integrator (one emitter and one BSDF sample, the power
  heuristic, ``llvm_ad_rgb`` with all its threads) at about the same time as tracer's ``mis``:
  its relMSE against the same reference and its efficiency. Its first render compiles the LLVM
  kernels and is not timed. It runs in a child process with Mitsuba's interpreter
  (``--mitsuba-python``, default /work/venv-xcheck/bin/python).

Writes OUT/light_sampling.json and OUT/light_sampling.md and prints the table. Timing lives in
benchmarks, never in the tests; the machine and its load average are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from efficiency_runs import measure  # noqa: E402  (benchmarks/ is no package)
from efficiency_runs import mitsuba_child as _mitsuba

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SAMPLINGS = ("area", "solid-angle", "solid-angle-cos")
DEFAULT_MITSUBA_PYTHON = "/work/venv-xcheck/bin/python"


def zero_shares(scene, sampling: str, samples_per_point: int = 16) -> dict[str, float]:
    """Shares of light samples that contribute 0 at the pixel-centre shading points."""
    import numpy as np

    from tracer.geometry import SceneRays, surface_point
    from tracer.lights import LightSampler

    cam = scene.camera
    pixel = np.arange(cam.width * cam.height, dtype=np.int64)
    origins, dirs = cam.rays(pixel, np.full((len(pixel), 2), 0.5))
    rays = SceneRays(scene)
    prim = rays.first_hit(origins.astype(np.float32), dirs.astype(np.float32))
    points, normals = [], []
    for i in np.flatnonzero(prim >= 0):
        if scene.hit_table[prim[i], 15] == 0:  # no material: nothing to light
            continue
        x, n, cos_d = surface_point(scene.hit_table, scene.triangle_count, int(prim[i]),
                                    tuple(float(v) for v in origins[i]), tuple(float(v) for v in dirs[i]))
        if cos_d == 0.0:
            continue
        points.append(x)
        normals.append(n if cos_d < 0.0 else tuple(-c for c in n))
    x = np.repeat(np.array(points), samples_per_point, axis=0)
    n = np.repeat(np.array(normals), samples_per_point, axis=0)
    gen = np.random.default_rng(13)
    s = LightSampler(scene, "power", sampling).sample(gen.random(len(x)), gen.random((len(x), 2)), x, n)
    above = np.sum(s.wi * n, axis=1) > 0.0
    live = (s.pdf > 0.0) & (s.radiance.max(axis=1) > 0.0) & above
    eps = scene.ray_epsilon
    origin = x + eps * n
    target = x + s.dist[:, None] * s.wi
    to_target = target - origin
    length = np.linalg.norm(to_target, axis=1)
    blocked = np.zeros(len(x), dtype=bool)
    idx = np.flatnonzero(live & (length > 0))
    blocked[idx] = rays.occluded(origin[idx].astype(np.float32),
                                 (to_target[idx] / length[idx, None]).astype(np.float32),
                                 np.maximum(length[idx] - eps, 0.0).astype(np.float32))
    return {"zero_before_rays": float(1.0 - live.mean()),
            "zero_in_all": float(1.0 - (live & ~blocked).mean())}


def tracer_runs(name: str, args) -> list[dict]:
    from tracer.imagefiles import read_exr
    from tracer.scene import load_scene
    from tracer.strategy import Strategy
    from tracer.study.compare import independent_seeds

    reference = read_exr(ROOT / "renders" / "references" / f"{name}.exr")
    scene = load_scene(ROOT / "scenes" / f"{name}.toml", args.size, args.size)
    seeds = independent_seeds(reference, None, args.seeds, str(ROOT / "renders" / "references"))
    rows = []
    for strategy_name in ("light", "mis"):
        for sampling in SAMPLINGS:
            row = measure(scene, reference, Strategy(strategy_name, light_sampling=sampling), seeds,
                          args.spp, args.time, args.threads,
                          {"scene": name, "strategy": strategy_name, "light_sampling": sampling})
            row.update(zero_shares(scene, sampling))
            print(f"  {name} {strategy_name} {sampling}: equal spp relMSE {row['equal_spp_relmse']:.4g}, "
                  f"equal time relMSE {row['equal_time_relmse']:.4g} "
                  f"({row['equal_time_seconds']:.2f} s), zero {row['zero_in_all']:.1%}", file=sys.stderr)
            rows.append(row)
    for row in rows:
        base = next(r for r in rows if r["strategy"] == row["strategy"] and r["light_sampling"] == "area")
        for kind in ("equal_spp", "equal_time"):
            row[f"{kind}_efficiency_vs_area"] = row[f"{kind}_efficiency"] / base[f"{kind}_efficiency"]
    return rows


def mitsuba_child(spec: dict) -> dict:
    """Run in Mitsuba's interpreter: a warm-up render, then ``runs`` timed renders; writes the
    mean image to spec['out'] (.npy) and returns the timings."""
    import mitsuba as mi
    import numpy as np

    sys.path.insert(0, str(HERE))
    import mitsuba_scene

    mi.set_variant(spec["variant"])
    scene = mi.load_dict(mitsuba_scene.load_mitsuba_scene(
        spec["scene"], spp=spec["spp"], seed=0, width=spec["size"], height=spec["size"],
        emitter_samples=1, bsdf_samples=1))
    np.array(mi.render(scene, seed=10_000, spp=spec["spp"]))  # compiles the kernels: untimed
    images, seconds = [], 0.0
    for run in range(spec["runs"]):
        start = time.perf_counter()
        seed = 1000 * spec.get("seed_offset", 0) + run
        images.append(np.array(mi.render(scene, seed=seed, spp=spec["spp"]), dtype=np.float64)[..., :3])
        seconds += time.perf_counter() - start
    np.save(spec["out"], np.mean(images, axis=0))
    return {"seconds": seconds, "spp": spec["spp"] * spec["runs"], "variant": spec["variant"],
            "mitsuba_version": mi.__version__}


def mitsuba_run(python: str, name: str, args, seconds_target: float) -> dict:
    import numpy as np

    from tracer.imagefiles import read_exr
    from tracer.study import metrics

    reference = read_exr(ROOT / "renders" / "references" / f"{name}.exr")
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        # A first child measures the time per spp; the second renders about the target time.
        probe = _child(python, {"scene": str(ROOT / "scenes" / f"{name}.toml"), "size": args.size, "spp": 4,
                                "runs": 1, "variant": "llvm_ad_rgb", "out": os.path.join(tmp, "probe.npy")})
        per_spp = probe["seconds"] / 4
        spp = max(1, int(round(seconds_target / per_spp)))
        for seed_run in range(args.seeds):
            path = os.path.join(tmp, f"run{seed_run}.npy")
            result = _child(python, {"scene": str(ROOT / "scenes" / f"{name}.toml"), "size": args.size,
                                     "spp": spp, "runs": 1, "variant": "llvm_ad_rgb", "out": path,
                                     "seed_offset": seed_run})
            image = np.load(path).reshape(-1, 3)
            rel = metrics.relmse(image, reference.mean, reference.variance_of_mean())
            out.append({"spp": result["spp"], "seconds": result["seconds"], "relmse": rel,
                        "mitsuba_version": result["mitsuba_version"]})
    rel = sum(r["relmse"] for r in out) / len(out)
    sec = sum(r["seconds"] for r in out) / len(out)
    return {"runs": out, "relmse": rel, "seconds": sec, "efficiency": 1.0 / (rel * sec),
            "variant": "llvm_ad_rgb", "mitsuba_version": out[0]["mitsuba_version"]}


def _child(python: str, spec: dict) -> dict:
    return _mitsuba(python, Path(__file__).resolve(), spec)


def markdown(results: dict) -> str:
    lines = [f"Machine: {results['machine']}; load average before/after "
             f"{results['load_before']} / {results['load_after']}.", "",
             f"{results['size']}x{results['size']}, equal spp = {results['spp']}, equal time = "
             f"{results['time']} s per render, relMSE averaged over {results['seeds']} seeds.", "",
             "| scene | strategy | light sampling | relMSE (equal spp) | relMSE (equal time) | spp in time "
             "| efficiency vs area (equal spp) | efficiency vs area (equal time) | zero before rays "
             "| zero in all |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["rows"]:
        spp_in_time = sum(x["spp"] for x in r["equal_time"]) / len(r["equal_time"])
        lines.append(f"| {r['scene']} | {r['strategy']} | {r['light_sampling']} | "
                     f"{r['equal_spp_relmse']:.4g} | {r['equal_time_relmse']:.4g} | {spp_in_time:.0f} | "
                     f"{r['equal_spp_efficiency_vs_area']:.2f} | {r['equal_time_efficiency_vs_area']:.2f} | "
                     f"{r['zero_before_rays']:.1%} | {r['zero_in_all']:.1%} |")
    for name, m in results.get("mitsuba", {}).items():
        if "error" in m:
            lines += ["", f"Mitsuba on {name}: {m['error']}"]
            continue
        lines += ["", f"Mitsuba 3 {m['mitsuba_version']} `direct` ({m['variant']}) on {name}: relMSE "
                  f"{m['relmse']:.4g} in {m['seconds']:.2f} s; tracer `mis` with each technique, "
                  "efficiency over Mitsuba's:"]
        for r in results["rows"]:
            if r["scene"] == name and r["strategy"] == "mis":
                lines.append(f"- {r['light_sampling']}: {r['equal_time_efficiency'] / m['efficiency']:.2f}x")
    return "\n".join(lines) + "\n"


def main() -> int:
    if len(sys.argv) == 3 and sys.argv[1] == "--mitsuba-child":
        spec = json.loads(sys.argv[2])
        print(json.dumps(mitsuba_child(spec)))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="veach_mis,cornell")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--time", type=float, default=4.0)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--mitsuba-python", default=DEFAULT_MITSUBA_PYTHON)
    parser.add_argument("--no-mitsuba", action="store_true")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    results = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
               "load_before": [round(v, 2) for v in os.getloadavg()], "size": args.size, "spp": args.spp,
               "time": args.time, "seeds": args.seeds, "rows": [], "mitsuba": {}}
    for name in args.scenes.split(","):
        results["rows"] += tracer_runs(name, args)
        if name == "cornell" and not args.no_mitsuba:
            try:
                results["mitsuba"][name] = mitsuba_run(args.mitsuba_python, name, args, args.time)
            except (OSError, RuntimeError) as exc:
                results["mitsuba"][name] = {"error": str(exc)}
    results["load_after"] = [round(v, 2) for v in os.getloadavg()]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "light_sampling.json").write_text(json.dumps(results, indent=2) + "\n")
    text = markdown(results)
    (out / "light_sampling.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
