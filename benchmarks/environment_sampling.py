"""The environment's light-sampling techniques side by side (issue 33): luminance, uniform,
compensated and product, under the light and mis strategies, and Mitsuba 3's `direct` at equal
time.

    python benchmarks/environment_sampling.py [--scenes environment,environment_studio]
                                              [--width 256] [--height 192] [--spp 16] [--time 3]
                                              [--seeds 3] [--reference-spp 4096] [--threads 2]
                                              [--mitsuba-python PYTHON | --no-mitsuba]
                                              [--out benchmarks/results]

For each shipped scene (tracer/scenes/mitsuba/NAME.xml; `environment`: a sky with a small hot
sun and an area light; `environment_studio`: a studio of bright panels, the only light):

- a reference: tracer's `mis` (luminance) at `--reference-spp`, rendered once into
  OUT/environment_refs/NAME.exr (kept, and reused while it matches the scene and size);
- `light` with uniform, luminance and product sampling, and `mis` with uniform, luminance,
  compensated and product, at equal spp (`--spp`) and at equal wall time (`--time` seconds
  each): relMSE with the reference's noise subtracted, averaged over `--seeds` seeds the
  reference does not hold, and efficiency 1 / (relMSE x seconds); each row's efficiency over its
  strategy's `uniform` row (what issue 33 names) and over luminance; the same over the pixels
  of the glossy objects (`roughconductor`) and of the diffuse ones (`diffuse`) alone, where a
  camera ray through the pixel's centre first meets such an object;
- Mitsuba 3's `direct` (one emitter and one BSDF sample, the power heuristic, its envmap's own
  hierarchical sampling; `llvm_ad_rgb` with all its threads) at about `--time` seconds: its
  relMSE against the same reference and its efficiency, which tracer's `mis` rows are divided
  by. Its first render compiles the LLVM kernels and is not timed. It runs in a child process
  with Mitsuba's interpreter (`--mitsuba-python`), pointed at LLVM 19
  (`efficiency_runs.LIBLLVM19`).

Writes OUT/environment_sampling.json and .md and prints the table. Timing lives in benchmarks,
never in the tests; the machine and its load average are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from efficiency_runs import measure  # noqa: E402  (benchmarks/ is no package)
from efficiency_runs import mitsuba_child as _mitsuba

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENES = ROOT / "tracer" / "scenes" / "mitsuba"
DEFAULT_MITSUBA_PYTHON = "/work/venv-xcheck/bin/python"
# (strategy, environment sampling): every run of a scene, the baseline of each strategy first.
RUNS = [("light", "uniform"), ("light", "luminance"), ("light", "product"), ("mis", "uniform"),
        ("mis", "luminance"), ("mis", "compensated"), ("mis", "product")]
# The objects whose pixels are measured apart: name -> material types.
OBJECTS = {"glossy": ("roughconductor",), "diffuse": ("diffuse",)}


def object_masks(scene) -> dict:
    """Name of ``OBJECTS`` -> (pixels,) bool, the pixels whose centre's camera ray first meets an
    object of those material types."""
    import numpy as np

    from tracer.geometry import SceneRays
    from tracer.plugins import by_code

    camera = scene.camera
    count = camera.width * camera.height
    origins, dirs = camera.rays(np.arange(count), np.full((count, 2), 0.5))
    prim = SceneRays(scene).first_hit(origins.astype(np.float32), dirs.astype(np.float32))
    row = np.full(count, -1)
    triangle = (prim >= 0) & (prim < scene.triangle_count)
    row[triangle] = scene.material[prim[triangle]]
    sphere = prim >= scene.triangle_count
    row[sphere] = scene.sphere_material[prim[sphere] - scene.triangle_count]
    types = by_code("material")
    names = np.array([types[int(k)].name if int(k) in types else "" for k in scene.materials.kind] + [""])
    return {name: np.isin(names[row], kinds) for name, kinds in OBJECTS.items()}


def reference_film(name: str, args):
    """tracer's high-spp MIS reference of scene ``name``, rendered once and kept."""
    from tracer.imagefiles import read_exr
    from tracer.scene import load_scene

    scene = load_scene(SCENES / f"{name}.xml", args.width, args.height)
    path = Path(args.out) / "environment_refs" / f"{name}.exr"
    if path.is_file():
        film = read_exr(path)
        size = (film.width, film.height) == (args.width, args.height)
        if film.record.scene_digest == scene.digest and size and film.spp >= args.reference_spp:
            return scene, film
    path.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "tracer", "reference", str(SCENES / f"{name}.xml"), "--spp",
                    str(args.reference_spp), "--width", str(args.width), "--height", str(args.height),
                    "--seed", "9000", "--threads", str(args.threads), "--float", "--force", "-o", str(path)],
                   check=True)
    return scene, read_exr(path)


def tracer_runs(name: str, scene, reference, args) -> list[dict]:
    from tracer.strategy import Strategy
    from tracer.study.compare import independent_seeds

    seeds = independent_seeds(reference, None, args.seeds, str(Path(args.out) / "environment_refs"))
    rows = []
    masks = object_masks(scene)
    for strategy_name, sampling in RUNS:
        row = measure(scene, reference, Strategy(strategy_name, environment_sampling=sampling), seeds,
                      args.spp, args.time, args.threads,
                      {"scene": name, "strategy": strategy_name, "environment_sampling": sampling}, masks)
        print(f"  {name} {strategy_name} {sampling}: equal spp relMSE {row['equal_spp_relmse']:.4g}, "
              f"equal time relMSE {row['equal_time_relmse']:.4g} ({row['equal_time_seconds']:.2f} s)",
              file=sys.stderr)
        rows.append(row)
    by_run = {(r["strategy"], r["environment_sampling"]): r for r in rows}
    for row in rows:
        for kind in ("equal_spp", "equal_time"):
            for base in ("uniform", "luminance"):
                row[f"{kind}_vs_{base}"] = (row[f"{kind}_efficiency"]
                                            / by_run[row["strategy"], base][f"{kind}_efficiency"])
                for part in masks:
                    row[f"{kind}_{part}_vs_{base}"] = (row[f"{kind}_{part}_efficiency"]
                                                       / by_run[row["strategy"], base][f"{kind}_{part}_efficiency"])
    return rows


def mitsuba_child(spec: dict) -> dict:
    """Run in Mitsuba's interpreter: a warm-up render, then one timed render; writes the image to
    spec['out'] (.npy) and returns the timing."""
    import mitsuba as mi
    import numpy as np

    mi.set_variant(spec["variant"])
    scene = mi.load_file(spec["scene"], width=spec["width"], height=spec["height"], spp=spec["spp"])
    np.array(mi.render(scene, seed=10_000, spp=min(spec["spp"], 4)))  # compiles the kernels: untimed
    start = time.perf_counter()
    image = np.array(mi.render(scene, seed=spec["seed"], spp=spec["spp"]), dtype=np.float64)[..., :3]
    seconds = time.perf_counter() - start
    np.save(spec["out"], image)
    return {"seconds": seconds, "spp": spec["spp"], "variant": spec["variant"],
            "mitsuba_version": mi.__version__}


def _child(python: str, spec: dict) -> dict:
    return _mitsuba(python, Path(__file__).resolve(), spec)


def mitsuba_run(python: str, name: str, args, reference) -> dict:
    import numpy as np

    from tracer.study import metrics

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        spec = {"scene": str(SCENES / f"{name}.xml"), "width": args.width, "height": args.height,
                "variant": "llvm_ad_rgb", "seed": 0}
        probe = _child(python, {**spec, "spp": 8, "out": os.path.join(tmp, "probe.npy")})
        spp = max(1, int(round(args.time / (probe["seconds"] / 8))))
        for run in range(args.seeds):
            path = os.path.join(tmp, f"run{run}.npy")
            result = _child(python, {**spec, "spp": spp, "seed": 1 + run, "out": path})
            image = np.load(path).reshape(-1, 3)
            rel = metrics.relmse(image, reference.mean, reference.variance_of_mean())
            out.append({"spp": result["spp"], "seconds": result["seconds"], "relmse": rel,
                        "mitsuba_version": result["mitsuba_version"]})
    rel = sum(r["relmse"] for r in out) / len(out)
    sec = sum(r["seconds"] for r in out) / len(out)
    return {"runs": out, "relmse": rel, "seconds": sec, "efficiency": 1.0 / (rel * sec),
            "variant": "llvm_ad_rgb", "mitsuba_version": out[0]["mitsuba_version"]}


def markdown(results: dict) -> str:
    lines = [f"Machine: {results['machine']}; load average before/after "
             f"{results['load_before']} / {results['load_after']}.", "",
             f"{results['width']}x{results['height']}, equal spp = {results['spp']}, equal time = "
             f"{results['time']} s per render, relMSE against tracer's {results['reference_spp']}-spp MIS "
             f"reference (its noise subtracted), averaged over {results['seeds']} seeds.", "",
             "| scene | strategy | environment sampling | relMSE (equal spp) | relMSE (equal time) "
             "| spp in time "
             "| efficiency vs uniform (equal spp) | (equal time) | vs luminance (equal time) "
             "| glossy objects vs luminance (equal spp) | (equal time) "
             "| diffuse objects vs luminance (equal spp) | (equal time) "
             "| vs Mitsuba 3 (equal time) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["rows"]:
        spp_in_time = sum(x["spp"] for x in r["equal_time"]) / len(r["equal_time"])
        mitsuba = results.get("mitsuba", {}).get(r["scene"], {})
        versus = (f"{r['equal_time_efficiency'] / mitsuba['efficiency']:.2f}"
                  if r["strategy"] == "mis" and "efficiency" in mitsuba else "")
        lines.append(f"| {r['scene']} | {r['strategy']} | {r['environment_sampling']} | "
                     f"{r['equal_spp_relmse']:.4g} | {r['equal_time_relmse']:.4g} | {spp_in_time:.0f} | "
                     f"{r['equal_spp_vs_uniform']:.2f} | {r['equal_time_vs_uniform']:.2f} | "
                     f"{r['equal_time_vs_luminance']:.2f} | "
                     + "".join(f"{r.get(f'{kind}_{part}_vs_luminance', float('nan')):.2f} | "
                               for part in OBJECTS for kind in ("equal_spp", "equal_time"))
                     + f"{versus} |")
    for name, m in results.get("mitsuba", {}).items():
        if "error" in m:
            lines += ["", f"Mitsuba on {name}: {m['error']}"]
        else:
            spp = sum(r["spp"] for r in m["runs"]) / len(m["runs"])
            lines += ["", f"Mitsuba 3 {m['mitsuba_version']} `direct` ({m['variant']}) on {name}: relMSE "
                      f"{m['relmse']:.4g} in {m['seconds']:.2f} s ({spp:.0f} spp)."]
    return "\n".join(lines) + "\n"


def main() -> int:
    if len(sys.argv) == 3 and sys.argv[1] == "--mitsuba-child":
        print(json.dumps(mitsuba_child(json.loads(sys.argv[2]))))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="environment,environment_studio")
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--height", type=int, default=192)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--time", type=float, default=3.0)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--mitsuba-python", default=DEFAULT_MITSUBA_PYTHON)
    parser.add_argument("--no-mitsuba", action="store_true")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    results = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
               "load_before": [round(v, 2) for v in os.getloadavg()], "width": args.width,
               "height": args.height, "spp": args.spp, "time": args.time, "seeds": args.seeds,
               "reference_spp": args.reference_spp, "rows": [], "mitsuba": {}}
    for name in args.scenes.split(","):
        scene, reference = reference_film(name, args)  # read once: both renderers' runs use it
        results["rows"] += tracer_runs(name, scene, reference, args)
        if not args.no_mitsuba:
            try:
                results["mitsuba"][name] = mitsuba_run(args.mitsuba_python, name, args, reference)
            except (OSError, RuntimeError) as exc:
                results["mitsuba"][name] = {"error": str(exc)}
    results["load_after"] = [round(v, 2) for v in os.getloadavg()]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "environment_sampling.json").write_text(json.dumps(results, indent=2) + "\n")
    text = markdown(results)
    (out / "environment_sampling.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
