"""Why the samplers converge as they do: two measurements behind the README's "Where QMC helps".

    python benchmarks/samplers_structure.py [--out benchmarks/results]

1. **One shading point.** The closed-form scene of ``tests/test_estimators.py`` (a diffuse plane
   under three polygonal lights), rays shot straight at one plane point (no camera jitter), each
   of 256 "pixels" taking N samples (8 replicates of N / 8 points): the variance of the pixel
   means against N, and its fitted slope, per sampler and strategy. Without the camera pair
   the estimate depends on few decisions (light choice, light point, BSDF direction).
2. **Two decisions in different pairs.** f(x, y) = [x < 0.37] [y < 0.61] with x and y from two
   different pairs of dimensions, over 2,048 pixels: spp x the variance of the pixel mean, for
   the samplers and for a reference construction, 8 replicates each of N / 8 points whose x and
   y are stratified in 1-D and paired by independent uniform random permutations (Latin
   hypercube pairing, what a padded sampler shuffling with a uniform permutation gives). Plain
   Monte Carlo gives ab(1 - ab) = 0.175.

Writes ``samplers_structure.json`` and ``.md`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

SAMPLERS = ("independent", "stratified", "sobol")
POINT_SPP = (16, 64, 256, 1024)
CROSS_SPP = (64, 256, 1024)


def one_point() -> list[dict]:
    from test_estimators import ANALYTIC_SCENE, POINTS, shoot_at

    from tracer.estimator import DirectLighting
    from tracer.scene import load_scene
    from tracer.strategy import Strategy

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "closed_form.toml")
        Path(path).write_text(ANALYTIC_SCENE)
        scene = load_scene(path)
    rows = []
    pixels = 256
    for strategy in ("light", "mis"):
        estimator = DirectLighting(scene, Strategy(strategy))
        for sampler in SAMPLERS:
            variances = []
            for n in POINT_SPP:
                origins, dirs, _ = shoot_at(POINTS[:1], pixels * n)
                lanes = np.arange(len(origins))
                radiance = estimator.radiance(origins, dirs, seed=5, pixel=lanes // n, sample=lanes % n,
                                              sampler=sampler)
                variances.append(float(radiance.reshape(pixels, n, 3).mean(axis=1)[:, 0].var(ddof=1)))
            slope = float(np.polyfit(np.log(POINT_SPP), np.log(variances), 1)[0])
            rows.append({"strategy": strategy, "sampler": sampler, "spp": list(POINT_SPP),
                         "variance_of_pixel_mean": variances, "slope": slope})
            print(f"one point: {strategy} {sampler}: slope {slope:.2f}", file=sys.stderr)
    return rows


def cross_pairs() -> list[dict]:
    from tracer import samplers

    rng = np.random.default_rng(1)
    pixels, a, b = 2048, 0.37, 0.61

    def f(x, y):
        return (x < a) * (y < b)

    rows = []
    for spp in CROSS_SPP:
        n = spp // samplers.REPLICATES
        estimates = []
        for _ in range(pixels):
            total = 0.0
            for _ in range(samplers.REPLICATES):
                x = (rng.permutation(n) + rng.random(n)) / n
                y = (rng.permutation(n) + rng.random(n)) / n
                total += f(x, y).sum()
            estimates.append(total / spp)
        row = {"spp": spp, "latin_hypercube_pairing": float(np.var(estimates) * spp)}
        pixel, sample = np.repeat(np.arange(pixels), spp), np.tile(np.arange(spp), pixels)
        for name in SAMPLERS:
            params = samplers.make(name, 11, 0, spp)
            values = []
            for dims in ([0, 4], [0, 5], [1, 4], [4, 8]):
                u = samplers.uniforms(params, pixel, sample, dims)
                values.append(float(np.var(f(u[:, 0], u[:, 1]).reshape(pixels, spp).mean(axis=1)) * spp))
            row[name] = float(np.mean(values))
        rows.append(row)
        print(f"cross pairs at {spp} spp: {row}", file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = parser.parse_args()
    doc = {"one_point": one_point(), "cross_pairs": cross_pairs(), "load_at_end": os.getloadavg()}
    out = Path(args.out)
    (out / "samplers_structure.json").write_text(json.dumps(doc, indent=2) + "\n")
    lines = ["# Why the samplers converge as they do", "",
             "`python benchmarks/samplers_structure.py` (see its docstring for the set-up).", "",
             "## 1. One shading point (closed-form scene, 256 pixels of N samples)", "",
             "| strategy | sampler | " + " | ".join(f"Var(pixel mean), N = {n}" for n in POINT_SPP)
             + " | slope |", "|---|---|" + "---|" * (len(POINT_SPP) + 1)]
    for r in doc["one_point"]:
        lines.append(f"| {r['strategy']} | {r['sampler']} | "
                     + " | ".join(f"{v:.3g}" for v in r["variance_of_pixel_mean"]) + f" | {r['slope']:.2f} |")
    lines += ["", "## 2. Steps in two different pairs: spp x Var(pixel mean) (Monte Carlo: 0.175)", "",
              "| spp | Latin hypercube pairing | " + " | ".join(SAMPLERS) + " |", "|---|---|" + "---|" * 3]
    for r in doc["cross_pairs"]:
        lines.append(f"| {r['spp']} | {r['latin_hypercube_pairing']:.4f} | "
                     + " | ".join(f"{r[s]:.4f}" for s in SAMPLERS) + " |")
    (out / "samplers_structure.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
