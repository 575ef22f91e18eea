"""Optimal MIS and adaptive allocation (issue 17) against the classic heuristics.

    python benchmarks/optimal_mis.py [--scenes veach_mis,cornell] [--size 256] [--spp 64]
                                     [--time 6] [--seeds 2] [--threads 2] [--out benchmarks/results]

For each scene, against its shipped reference (``renders/references/SCENE.exr``):

- ``mis`` with the balance, power, maximum and optimal heuristics, each with fixed (1 light + 1
  BSDF sample) and adaptive allocation, at equal spp (``--spp``) and at equal wall time
  (``--time`` seconds): relMSE with the reference's noise subtracted, averaged over ``--seeds``
  seeds none of which the reference holds; seconds per spp (what the learning costs), and
  efficiency 1 / (relMSE x seconds) with its ratio to the power heuristic with fixed counts
  (the default strategy, and the issue's baseline);
- a figure (``renders/optimal_mis.png``) of the first scene: the image, the allocation map
  (share of light samples), the control variate's coefficient and the per-pixel efficiency of
  optimal MIS with adaptive allocation against the power heuristic, at equal time.

Writes OUT/optimal_mis.json and OUT/optimal_mis.md and prints the table. Timing lives in
benchmarks, never in the tests; the machine and its load average are recorded with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
HEURISTICS = ("power", "balance", "max", "optimal")
ALLOCATIONS = ("fixed", "adaptive")


def measure(name: str, args) -> dict:
    from tracer.imagefiles import read_exr
    from tracer.scene import load_scene
    from tracer.strategy import Strategy
    from tracer.study.compare import Comparison, independent_seeds

    ref_path = ROOT / "renders" / "references" / f"{name}.exr"
    reference = read_exr(ref_path)
    scene = load_scene(ROOT / "tracer" / "scenes" / f"{name}.toml", args.size, args.size)
    seeds = independent_seeds(reference, None, args.seeds, str(ref_path))
    rows, films = [], {}
    for heuristic in HEURISTICS:
        for allocation in ALLOCATIONS:
            strategy = Strategy("mis", heuristic, allocation=allocation)
            row = {"label": strategy.label, "heuristic": heuristic, "allocation": allocation}
            for mode in ("spp", "time"):
                runs = []
                for seed in seeds:
                    comparison = Comparison(scene, reference, seed, args.threads)
                    run = comparison.equal_spp(strategy, args.spp) if mode == "spp" else \
                        comparison.equal_time(strategy, args.time)
                    runs.append({"seed": seed, "spp": run.spp, "seconds": run.seconds,
                                 "relmse": run.measures["relmse"]})
                    if mode == "time" and seed == seeds[0]:
                        films[(heuristic, allocation)] = run
                rel = sum(r["relmse"] for r in runs) / len(runs)
                sec = sum(r["seconds"] for r in runs) / len(runs)
                row[mode] = {"runs": runs, "relmse": rel, "seconds": sec,
                             "spp": sum(r["spp"] for r in runs) / len(runs),
                             "seconds_per_spp": sum(r["seconds"] / r["spp"] for r in runs) / len(runs),
                             "efficiency": 1.0 / (rel * sec)}
            rows.append(row)
            print(f"  {name} {row['label']}: equal spp relMSE {row['spp']['relmse']:.4g} "
                  f"({row['spp']['seconds']:.2f} s); equal time {row['time']['spp']:.0f} spp, relMSE "
                  f"{row['time']['relmse']:.4g}", file=sys.stderr)
    base = next(r for r in rows if r["heuristic"] == "power" and r["allocation"] == "fixed")
    for row in rows:
        for mode in ("spp", "time"):
            row[mode]["vs_power"] = row[mode]["efficiency"] / base[mode]["efficiency"]
            row[mode]["relmse_vs_power"] = base[mode]["relmse"] / row[mode]["relmse"]
        row["cost_vs_power"] = row["spp"]["seconds_per_spp"] / base["spp"]["seconds_per_spp"]
    return {"scene": name, "seeds": seeds, "rows": rows, "films": films, "reference": reference}


def figure(result: dict, path: Path) -> None:
    """Image, allocation map, control-variate coefficient and efficiency ratio map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tracer.imagefiles import to_srgb8
    from tracer.study import metrics

    learned = result["films"][("optimal", "adaptive")]
    power = result["films"][("power", "fixed")]
    reference = result["reference"]
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.4))
    axes[0].imshow(to_srgb8(learned.film.image()))
    axes[0].set_title(f"{result['scene']}: optimal MIS, adaptive allocation", fontsize=9)
    shape = (learned.film.height, learned.film.width)
    share = learned.film.learned["allocation.light"].reshape(shape)
    im = axes[1].imshow(share, vmin=0.0, vmax=1.0, cmap="coolwarm", interpolation="nearest")
    axes[1].set_title("allocation: share of light samples (blue: BSDF)", fontsize=9)
    fig.colorbar(im, ax=axes[1], fraction=0.046, pad=0.04)
    alpha = np.mean([learned.film.learned[f"alpha.{c}"] for c in "RGB"], axis=0).reshape(shape)
    limit = float(np.quantile(np.abs(alpha), 0.99)) or 1.0
    im = axes[2].imshow(alpha, vmin=-limit, vmax=limit, cmap="PuOr", interpolation="nearest")
    axes[2].set_title("optimal MIS: control-variate coefficient a (mean RGB)", fontsize=9)
    fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    err = [metrics.relative_squared_error(r.film.image(), reference.image()) for r in (learned, power)]
    ratio = metrics.efficiency_ratio_map(err[0], learned.seconds, err[1], power.seconds)
    im = axes[3].imshow(ratio, vmin=-4, vmax=4, cmap="RdBu", interpolation="nearest")
    axes[3].set_title("log2 efficiency: optimal + adaptive (blue) vs power (red), equal time", fontsize=9)
    fig.colorbar(im, ax=axes[3], fraction=0.046, pad=0.04)
    for ax in axes:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(doc: dict) -> str:
    lines = [f"# Optimal MIS and adaptive allocation ({doc['machine']}, load {doc['load']}, "
             f"{doc['size']}x{doc['size']}, {doc['spp']} spp / {doc['time']} s, {doc['seeds']} seeds)", ""]
    for result in doc["results"]:
        lines += [f"## {result['scene']}", "",
                  "| heuristic | allocation | relMSE at equal spp | vs power | time per spp | "
                  "relMSE at equal time | efficiency | vs power |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in result["rows"]:
            s, t = r["spp"], r["time"]
            lines.append(f"| {r['heuristic']} | {r['allocation']} | {s['relmse']:.4g} | "
                         f"{s['relmse_vs_power']:.2f}x | {r['cost_vs_power']:.2f}x | {t['relmse']:.4g} | "
                         f"{t['efficiency']:.4g} | {t['vs_power']:.2f}x |")
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", default="veach_mis,cornell")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--time", type=float, default=6.0)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    results = [measure(name, args) for name in args.scenes.split(",")]
    figure(results[0], ROOT / "renders" / "optimal_mis.png")
    doc = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "load": " ".join(f"{x:.2f}" for x in os.getloadavg()), "time": args.time, "spp": args.spp,
           "seeds": args.seeds, "size": args.size,
           "results": [{k: v for k, v in r.items() if k not in ("films", "reference")} for r in results]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "optimal_mis.json").write_text(json.dumps(doc, indent=2) + "\n")
    (out / "optimal_mis.md").write_text(markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    main()
