"""Many lights (issue 16): light selection by power, uniformly and by a light BVH, and RIS.

    python benchmarks/many_lights.py [--scenes many_lights,emissive_mesh] [--size 256]
                                     [--time 8] [--seeds 2] [--threads 2]
                                     [--ris 1,2,4,8,16,32,64] [--out benchmarks/results]

For each scene, against its shipped reference (``renders/references/SCENE.exr``, MIS with lights
picked by BVH; made with ``tracer reference --light-selection bvh`` if missing):

- ``light`` and ``mis`` with each light selection, and ``ris`` with M = 4, 16, 32 light
  candidates (lights picked by power and by BVH) and M = 16 light + BSDF candidates, each at
  equal wall time (``--time`` seconds), relMSE with the reference's noise subtracted, averaged
  over ``--seeds`` seeds none of which the reference holds; efficiency 1 / (relMSE x seconds)
  and its ratio to ``mis`` with power selection (the default strategy) and to ``light`` with
  power selection;
- ris's relMSE against its candidate count M at equal time (``--ris``), which shows what M
  buys: candidates cost shading, not rays, until their shading outweighs the rays saved
  (chart ``renders/many_lights_ris.png``);
- the time to build the light tables and the BVH for 100,000 emitting triangles (after the
  compiled code is warm), the issue's target being under a second.

Writes OUT/many_lights.json and OUT/many_lights.md and prints the table. Timing lives in
benchmarks, never in the tests; the machine and its load average are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REFERENCE_SPP = 4096


def reference_path(name: str, args) -> Path:
    """The scene's reference, rendered first if it is missing."""
    path = ROOT / "renders" / "references" / f"{name}.exr"
    if not path.exists():
        print(f"  rendering the {name} reference ({REFERENCE_SPP} spp, BVH MIS)", file=sys.stderr)
        scene = ROOT / "tracer" / "scenes" / f"{name}.toml"
        subprocess.run([sys.executable, "-m", "tracer", "reference", str(scene), "-o", str(path),
                        "--spp", str(REFERENCE_SPP), "--light-selection", "bvh", "--width", str(args.size),
                        "--height", str(args.size), "--threads", str(args.threads)], check=True)
    return path


def methods():
    from tracer.strategy import Strategy

    out = [Strategy(name, light_selection=selection) for name in ("light", "mis")
           for selection in ("uniform", "power", "bvh")]
    out += [Strategy.ris(m, light_selection=selection) for selection in ("power", "bvh") for m in (4, 16, 32)]
    out += [Strategy.ris(16, "light+bsdf", light_selection=selection) for selection in ("power", "bvh")]
    return out


def measure(name: str, args) -> dict:
    from tracer.imagefiles import read_exr
    from tracer.scene import load_scene
    from tracer.strategy import Strategy
    from tracer.study.compare import Comparison, independent_seeds

    ref_path = reference_path(name, args)
    reference = read_exr(ref_path)
    scene = load_scene(ROOT / "tracer" / "scenes" / f"{name}.toml", args.size, args.size)
    seeds = independent_seeds(reference, None, args.seeds, str(ref_path))
    rows = []

    def run(strategy, budget):
        out = []
        for seed in seeds:
            result = Comparison(scene, reference, seed, args.threads).equal_time(strategy, budget)
            out.append({"seed": seed, "spp": result.spp, "seconds": result.seconds,
                        "relmse": result.measures["relmse"]})
        rel = sum(r["relmse"] for r in out) / len(out)
        sec = sum(r["seconds"] for r in out) / len(out)
        return {"label": strategy.label, "strategy": strategy.name,
                "light_selection": strategy.light_selection, "light_samples": strategy.light_samples,
                "bsdf_samples": strategy.bsdf_samples, "runs": out, "relmse": rel, "seconds": sec,
                "spp": sum(r["spp"] for r in out) / len(out), "efficiency": 1.0 / (rel * sec)}

    for strategy in methods():
        row = run(strategy, args.time)
        rows.append(row)
        print(f"  {name} {row['label']}: {row['spp']:.0f} spp, relMSE {row['relmse']:.4g}, "
              f"efficiency {row['efficiency']:.4g}", file=sys.stderr)
    base_mis = next(r for r in rows if r["strategy"] == "mis" and r["light_selection"] == "power")
    base_light = next(r for r in rows if r["strategy"] == "light" and r["light_selection"] == "power")
    for row in rows:
        row["vs_mis_power"] = row["efficiency"] / base_mis["efficiency"]
        row["vs_light_power"] = row["efficiency"] / base_light["efficiency"]
    sweep = []
    for selection in ("power", "bvh"):
        for m in args.ris:
            row = run(Strategy.ris(m, light_selection=selection), args.time)
            sweep.append({"m": m, **row})
            print(f"  {name} ris M={m} ({selection}): relMSE {row['relmse']:.4g}", file=sys.stderr)
    return {"scene": name, "seeds": seeds, "rows": rows, "ris_sweep": sweep}


def build_times() -> dict:
    """Light-table and BVH build times for 100,000 emitting triangles, compiled code warm."""
    import numpy as np

    from tracer.lights import build_tables, bvh
    from tracer.scene import load_scene

    rng = np.random.default_rng(0)
    count = 100_000
    corners = rng.uniform(-50.0, 50.0, (count, 1, 3)) + rng.normal(0.0, 0.2, (count, 3, 3))
    import trimesh

    mesh = trimesh.Trimesh(corners.reshape(-1, 3), np.arange(3 * count).reshape(-1, 3), process=False)
    folder = Path(os.environ.get("TMPDIR", "/tmp")) / "tracer_many_lights_bench"
    folder.mkdir(exist_ok=True)
    mesh.export(folder / "emitters.ply")
    doc = {"camera": {"origin": [0.0, 0.0, 100.0], "target": [0.0, 0.0, 0.0], "fov": 40.0},
           "shapes": [{"type": "mesh", "file": str(folder / "emitters.ply"), "emission": [1.0, 1.0, 1.0]}]}
    scene = load_scene(doc)
    build_tables(load_scene({**doc, "shapes": [{"type": "quad", "origin": [0, 0, 0], "edge1": [1, 0, 0],
                                                 "edge2": [0, 1, 0], "emission": [1, 1, 1]}]}), "bvh")
    out = {"emitters": int(count)}
    for selection in ("power", "bvh"):
        start = time.perf_counter()
        tables, _, _ = build_tables(scene, selection)
        out[f"tables_{selection}_seconds"] = time.perf_counter() - start
    lo = scene.vertices[scene.faces].min(axis=1)
    hi = scene.vertices[scene.faces].max(axis=1)
    start = time.perf_counter()
    bvh.build(lo, hi, scene.normal, np.ones(count), np.zeros(count), scene.area)
    out["bvh_build_seconds"] = time.perf_counter() - start
    out["bvh_depth"] = int(tables.selection.trail_depth.max())
    return out


def ris_chart(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5.2 * len(results), 3.8), squeeze=False)
    for ax, result in zip(axes[0], results, strict=True):
        for selection, style in (("power", "o-"), ("bvh", "s-")):
            points = [r for r in result["ris_sweep"] if r["light_selection"] == selection]
            ax.plot([p["m"] for p in points], [p["relmse"] for p in points], style,
                    label=f"ris, lights picked by {selection}")
        for selection, style in (("power", ":"), ("bvh", "--")):
            row = next(r for r in result["rows"]
                       if r["strategy"] == "mis" and r["light_selection"] == selection)
            ax.axhline(row["relmse"], color="grey", linestyle=style, label=f"mis, {row['light_selection']}")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("candidates M per camera sample")
        ax.set_ylabel("relMSE at equal time")
        ax.set_title(f"{result['scene']}: {result['rows'][0]['seconds']:.0f} s each")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def markdown(doc: dict) -> str:
    lines = [f"# Many lights ({doc['machine']}, load {doc['load']}, {doc['time']} s each, "
             f"{doc['seeds']} seeds, {doc['size']}x{doc['size']})", ""]
    for result in doc["results"]:
        lines += [f"## {result['scene']}", "",
                  "| method | spp | relMSE | efficiency | vs mis power | vs light power |",
                  "|---|---|---|---|---|---|"]
        for r in result["rows"]:
            lines.append(f"| {r['label']} | {r['spp']:.0f} | {r['relmse']:.4g} | {r['efficiency']:.4g} | "
                         f"{r['vs_mis_power']:.2f}x | {r['vs_light_power']:.2f}x |")
        lines += ["", "ris against M at equal time:", "",
                  "| M | relMSE (power) | relMSE (bvh) |", "|---|---|---|"]
        by = {(r["light_selection"], r["m"]): r for r in result["ris_sweep"]}
        for m in sorted({r["m"] for r in result["ris_sweep"]}):
            lines.append(f"| {m} | {by[('power', m)]['relmse']:.4g} | {by[('bvh', m)]['relmse']:.4g} |")
        lines.append("")
    b = doc["build"]
    lines += [f"Build for {b['emitters']:,} emitting triangles: light tables "
              f"{b['tables_power_seconds']:.3f} s (power), {b['tables_bvh_seconds']:.3f} s (bvh, of which "
              f"the tree {b['bvh_build_seconds']:.3f} s; depth {b['bvh_depth']}).", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", default="many_lights,emissive_mesh")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--time", type=float, default=8.0)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--ris", default="1,2,4,8,16,32,64")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    args.ris = [int(m) for m in args.ris.split(",")]
    build = build_times()
    print(f"  build: {build}", file=sys.stderr)
    results = [measure(name, args) for name in args.scenes.split(",")]
    doc = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "load": " ".join(f"{x:.2f}" for x in os.getloadavg()), "time": args.time, "seeds": args.seeds,
           "size": args.size, "build": build, "results": results}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "many_lights.json").write_text(json.dumps(doc, indent=2) + "\n")
    (out / "many_lights.md").write_text(markdown(doc))
    ris_chart(results, ROOT / "renders" / "many_lights_ris.png")
    print(markdown(doc))


if __name__ == "__main__":
    main()
