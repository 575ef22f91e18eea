"""Every technique and ``auto`` against the default strategy at equal time, on scenes nobody tuned
them for (issue 34).

    python benchmarks/equal_time.py [--time 2] [--seeds 3] [--width 160] [--scene-seed SEED]
                                    [--corpus /tmp/corpus] [--only cbox,city]
                                    [--strategies mis_bvh,auto] [--out DIR]

Scenes:

- public corpus (held out; fetch mitsuba-renderer/mitsuba-data and mitsuba-tutorials and
  extract the files below under ``--corpus``; a missing one is skipped with a note):
  ``cbox`` (mitsuba-data ``scenes/cbox/cbox-rgb.xml``: a small ceiling light),
  ``sphere_light`` (mitsuba-data ``docs/scenes/shape_sphere_light_analytic.xml``: a sphere
  light over a rough plastic floor under a dim constant sky), ``matpreview`` (mitsuba-data
  ``scenes/matpreview/matpreview.xml``: an environment map, plastic and diffuse), ``simple``
  (mitsuba-tutorials ``scenes/simple.xml``: two point lights);
- shipped: ``cornell``, ``veach_mis``, ``many_lights``;
- generated from ``--scene-seed`` (default: drawn from the clock at the start of the run and
  printed, so that no one has looked at the scene before it is measured): ``room`` (quads and
  triangles of random size and power over diffuse and rough metal, ``far_light.generated_scene``)
  and ``city`` (:func:`city`: a grid of blocks with about 1,000 small lights, windows, street
  lamps and bright floodlights inside walled courtyards, over a rough wet street).

Strategies: ``mis`` (power heuristic, area sampling, power selection, 1 + 1: the default and the
baseline), ``light``, ``bsdf``, ``mis`` with the balance heuristic, with each solid-angle light
sampling and with the light BVH, ``light`` by solid angle, ``ris`` (16 candidates), ``mis`` with
optimal weights and adaptive allocation, ``mis`` with the Sobol sampler, and ``auto``. A
strategy that cannot see all of a scene's light (``light`` where a material has a delta lobe,
``bsdf`` under point lights) is left out there.

Each strategy renders ``--time`` seconds (wall clock, 2 threads) for each seed, strategies
interleaved within a seed, against a 1024-spp ``mis`` reference of each scene (its noise
subtracted, ``study.metrics.relmse``). Efficiency is 1 / (relMSE x seconds) per seed; the ratio
to the baseline's is reported as the geometric mean over seeds with a 95% t-interval of the
log-ratios (n - 1 degrees of freedom: wide with 3 seeds). Writes OUT/equal_time.json and
OUT/equal_time.md.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from efficiency_runs import write_results  # noqa: E402  (benchmarks/ is no package)

CORPUS = {
    "cbox": "cbox/scenes/cbox/cbox-rgb.xml",
    "sphere_light": "md/docs/scenes/shape_sphere_light_analytic.xml",
    "matpreview": "md/scenes/matpreview/matpreview.xml",
    "simple": "mt/scenes/simple.xml",
}
SHIPPED = ("cornell", "veach_mis", "many_lights")
REFERENCE_SPP = 1024


def strategies():
    from tracer.strategy import Strategy

    return [
        ("mis", Strategy("mis"), "independent"),
        ("light", Strategy("light"), "independent"),
        ("bsdf", Strategy("bsdf"), "independent"),
        ("mis_balance", Strategy("mis", "balance"), "independent"),
        ("mis_solid-angle", Strategy("mis", light_sampling="solid-angle"), "independent"),
        ("mis_solid-angle-cos", Strategy("mis", light_sampling="solid-angle-cos"), "independent"),
        ("light_solid-angle", Strategy("light", light_sampling="solid-angle"), "independent"),
        ("mis_bvh", Strategy("mis", light_selection="bvh"), "independent"),
        ("ris_16", Strategy.ris(16), "independent"),
        ("mis_optimal_adaptive", Strategy("mis", "optimal", allocation="adaptive"), "independent"),
        ("mis_sobol", Strategy("mis"), "sobol"),
        ("auto", Strategy("auto"), "independent"),
        ("auto_sobol", Strategy("auto"), "sobol"),
    ]


# Strategies of the independent sampler that auto chooses among ("best fixed"); samplers are
# compared with samplers (auto_sobol against mis_sobol).
NOT_FIXED = ("auto", "auto_sobol", "mis_sobol")


def city(seed: int, folder: Path) -> Path:
    """A city seen from above at an angle, written to ``folder/city.toml`` (with its meshes): a 6 x
    6 grid of blocks of random height, lit windows on every facade (radiance log-uniform over
    two decades), a street lamp facing down at each crossing, and on a third of the blocks a
    bright floodlight inside a walled rooftop courtyard, facing up (much of the scene's power,
    none of it reaching the street). Streets are a rough conductor (wet asphalt), buildings
    diffuse."""
    import trimesh

    rng = np.random.default_rng(seed)
    boxes, walls, lights = [], [], []

    def box(lo, hi):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix(
            (lo + hi) / 2))

    def quad(origin, e1, e2, emission):
        lights.append({"origin": list(map(float, origin)), "edge1": list(map(float, e1)),
                       "edge2": list(map(float, e2)), "emission": list(map(float, emission))})

    pitch, size = 10.0, 7.0
    for i in range(6):
        for j in range(6):
            x0, z0 = (i - 3) * pitch, (j - 3) * pitch
            height = float(rng.uniform(6.0, 30.0))
            boxes.append(box([x0, 0.0, z0], [x0 + size, height, z0 + size]))
            # Windows on the four facades, 0.5 x 0.8, lit with probability 0.35.
            for face in range(4):
                for u in np.arange(0.5, size - 0.5, 1.2):
                    for y in np.arange(1.0, height - 1.0, 2.0):
                        if rng.random() > 0.35:
                            continue
                        emission = rng.uniform(0.5, 1.0, 3) * math.exp(rng.uniform(math.log(0.2), math.log(20.0)))
                        eps = 0.01
                        if face == 0:    # -z facade, facing -z: e1 x e2 = -z
                            quad([x0 + u, y, z0 - eps], [0, 0.8, 0], [0.5, 0, 0], emission)
                        elif face == 1:  # +z facade, facing +z
                            quad([x0 + u, y, z0 + size + eps], [0.5, 0, 0], [0, 0.8, 0], emission)
                        elif face == 2:  # -x facade, facing -x
                            quad([x0 - eps, y, z0 + u], [0, 0, 0.5], [0, 0.8, 0], emission)
                        else:            # +x facade, facing +x
                            quad([x0 + size + eps, y, z0 + u], [0, 0.8, 0], [0, 0, 0.5], emission)
            # A street lamp at the block's corner crossing, facing down.
            quad([x0 - 1.65, 6.0, z0 - 1.65], [0.3, 0, 0], [0, 0, 0.3], [60.0, 40.0, 15.0])
            if rng.random() < 1 / 3:
                # A rooftop courtyard: walls 2 m high around a floodlight facing up.
                top = height
                walls += [box([x0, top, z0], [x0 + size, top + 2.0, z0 + 0.2]),
                          box([x0, top, z0 + size - 0.2], [x0 + size, top + 2.0, z0 + size]),
                          box([x0, top, z0], [x0 + 0.2, top + 2.0, z0 + size]),
                          box([x0 + size - 0.2, top, z0], [x0 + size, top + 2.0, z0 + size])]
                quad([x0 + 3.0, top + 0.05, z0 + 3.0], [0, 0, 1.0], [1.0, 0, 0], [400.0, 380.0, 350.0])
    trimesh.util.concatenate(boxes).export(folder / "city_blocks.ply")
    if walls:
        trimesh.util.concatenate(walls).export(folder / "city_walls.ply")

    def vec(v):
        return "[" + ", ".join(f"{c:.5g}" for c in v) + "]"

    text = ["[camera]", "origin = [-38.0, 45.0, -52.0]", "target = [2.0, 0.0, 4.0]", "fov = 50.0",
            "width = 200", "height = 150", "", "[materials.facade]", 'type = "diffuse"',
            "reflectance = [0.45, 0.42, 0.4]", "", "[materials.street]", 'type = "roughconductor"',
            "reflectance = [0.3, 0.3, 0.32]", "alpha = 0.25", "",
            "[[shapes]]", 'type = "quad"', "origin = [-40.0, 0.0, -40.0]", "edge1 = [0.0, 0.0, 80.0]",
            "edge2 = [80.0, 0.0, 0.0]", 'material = "street"', "",
            "[[shapes]]", 'type = "mesh"', 'file = "city_blocks.ply"', 'material = "facade"', ""]
    if walls:
        text += ["[[shapes]]", 'type = "mesh"', 'file = "city_walls.ply"', 'material = "facade"', ""]
    for light in lights:
        text += ["[[shapes]]", 'type = "quad"'] + [f"{k} = {vec(v)}" for k, v in light.items()] + [""]
    path = folder / "city.toml"
    path.write_text("\n".join(text))
    return path


def scene_files(args, folder: Path) -> dict[str, Path]:
    """Every scene of the run by name (module docstring); corpus files that are missing are
    left out with a note."""
    from far_light import scene_files as room_files

    files: dict[str, Path] = {}
    for name, relative in CORPUS.items():
        path = Path(args.corpus) / relative
        if path.exists():
            files[name] = path
        else:
            print(f"equal_time: {path} is missing: {name} left out", file=sys.stderr)
    for name in SHIPPED:
        files[name] = ROOT / "tracer" / "scenes" / f"{name}.toml"
    files["room"] = room_files(argparse.Namespace(scene_seed=args.scene_seed, cbox=None), folder)["generated"]
    files["city"] = city(args.scene_seed, folder)
    if args.only:
        files = {k: v for k, v in files.items() if k in args.only.split(",")}
    return files


def ratio_interval(ours: list[float], base: list[float]) -> tuple[float, float, float]:
    """Geometric mean of ours / base over seeds and its 95% t-interval (log scale)."""
    from scipy import stats

    logs = np.log(np.asarray(ours) / np.asarray(base))
    mean = float(logs.mean())
    if len(logs) < 2:
        return math.exp(mean), math.nan, math.nan
    half = float(stats.t.ppf(0.975, len(logs) - 1) * logs.std(ddof=1) / math.sqrt(len(logs)))
    return math.exp(mean), math.exp(mean - half), math.exp(mean + half)


def markdown(doc: dict) -> str:
    lines = [f"Equal-time efficiency against `mis` (power, area, power selection, 1 + 1), {doc['time']} s "
             f"per run, {doc['seeds']} seeds, 2 threads, width {doc['width']}; scene seed {doc['scene_seed']}. "
             f"{doc['machine']}. Command: `{doc['command']}`", "",
             "Each cell: geometric mean of the per-seed efficiency ratio, 95% interval in brackets; "
             "**bold** where the interval is above 1, *italic* where below; - where the strategy "
             "cannot see all of the scene's light.", ""]
    names = [n for n, *_ in doc["strategies"]]
    lines.append("| scene | " + " | ".join(names[1:]) + " |")
    lines.append("|---|" + "---:|" * (len(names) - 1))
    for scene, rows in doc["results"].items():
        cells = []
        for name in names[1:]:
            r = rows.get(name)
            if r is None:
                cells.append("-")
                continue
            text = f"{r['ratio']:.2f} [{r['lo']:.2f}, {r['hi']:.2f}]"
            if r["lo"] > 1:
                text = f"**{text}**"
            elif r["hi"] < 1:
                text = f"*{text}*"
            cells.append(text)
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    auto_rows = {scene: rows for scene, rows in doc["results"].items() if "auto" in rows}
    lines += [] if not auto_rows else [
              "", "`auto` against the best fixed strategy of each scene (independent sampler; efficiency "
              "over the best's, geometric mean over seeds), what it chose, and `auto` with the Sobol "
              "sampler against `mis` with it. The last column is the reference's own relMSE over the "
              "least relMSE of the scene's runs: above about 1 the reference's noise, which is "
              "subtracted, is larger than the error it measures, and the ratios of the best "
              "strategies are less certain than their intervals say. The best fixed strategy is the "
              "one of highest mean ratio in this same run, which favours it: the largest of a dozen "
              "noisy ratios is biased upward.", "",
              "| scene | best fixed | auto / best | auto / mis | auto chose | auto_sobol / mis_sobol | "
              "reference / best relMSE |", "|---|---|---:|---:|---|---:|---:|"]
    for scene, rows in auto_rows.items():
        fixed = {k: v for k, v in rows.items() if k not in NOT_FIXED}
        best = max(fixed, key=lambda k: fixed[k]["ratio"])
        a = rows["auto"]
        least = min(min(r["relmse"]) for r in rows.values())
        ratio, lo, hi = ratio_interval(a["efficiency"], fixed[best]["efficiency"])
        sobol = (f"{rows['auto_sobol']['ratio'] / rows['mis_sobol']['ratio']:.2f}"
                 if "auto_sobol" in rows and "mis_sobol" in rows else "-")
        reference = doc["reference_relmse"].get(scene)
        lines.append(f"| {scene} | {best} | {ratio:.2f} [{lo:.2f}, {hi:.2f}] | {a['ratio']:.2f} | "
                     f"{', '.join(sorted(set(a['chose'])))} | {sobol} | "
                     f"{'-' if reference is None else f'{reference / least:.1f}'} |")
    lines += ["", "Where each strategy loses to `mis` at equal time (its interval below 1) and where it wins "
              "(above 1):", "", "| strategy | loses on | wins on |", "|---|---|---|"]
    for name in names[1:]:
        by = {scene: rows[name] for scene, rows in doc["results"].items() if name in rows}
        loses = [f"{scene} ({r['ratio']:.2f})" for scene, r in by.items() if r["hi"] < 1]
        wins = [f"{scene} ({r['ratio']:.2f})" for scene, r in by.items() if r["lo"] > 1]
        lines.append(f"| {name} | {', '.join(loses) or '-'} | {', '.join(wins) or '-'} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time", type=float, default=2.0)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--scene-seed", type=int, default=None)
    parser.add_argument("--corpus", default="/tmp/corpus")
    parser.add_argument("--only", default="")
    parser.add_argument("--strategies", default="", help="labels to run (comma-separated; mis, the "
                        "baseline, always runs)")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    if args.scene_seed is None:
        args.scene_seed = int(time.time() * 1000) % 2**31
    print(f"equal_time: scene seed {args.scene_seed}", file=sys.stderr)

    from tracer import auto
    from tracer.render_loop import RenderSettings, render_complete
    from tracer.scene import load_scene
    from tracer.strategy import Strategy
    from tracer.study import metrics
    from tracer.study.compare import Comparison

    wanted = {"mis", *filter(None, args.strategies.split(","))}
    selected = [entry for entry in strategies() if not args.strategies or entry[0] in wanted]
    unknown = wanted - {label for label, _, _ in strategies()}
    if unknown:
        parser.error(f"--strategies: no strategy labelled {', '.join(sorted(unknown))}")
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        files = scene_files(args, Path(tmp))
        scenes, reference_relmse = {}, {}
        for name, path in files.items():
            full = load_scene(path)
            height = max(1, round(args.width * full.camera.height / full.camera.width))
            scene = load_scene(path, width=args.width, height=height)
            start = time.perf_counter()
            reference = render_complete(scene, Strategy("mis"),
                                        RenderSettings(spp=REFERENCE_SPP, seed=10**6, threads=2)).film
            print(f"  {name}: reference {REFERENCE_SPP} spp in {time.perf_counter() - start:.1f} s", file=sys.stderr)
            scenes[name] = (scene, reference)
            reference_relmse[name] = metrics.reference_relmse(reference.mean, reference.variance_of_mean())
        runs: dict = {name: {} for name in scenes}
        for seed in range(args.seeds):
            for name, (scene, reference) in scenes.items():
                comparison = Comparison(scene, reference, seed, 2)
                for label, strategy, sampler in selected:
                    if not auto.sees_all_light(scene, strategy):
                        continue
                    run = comparison.equal_time(strategy, args.time, sampler)
                    rel = metrics.relmse(run.film.mean, reference.mean, reference.variance_of_mean())
                    entry = runs[name].setdefault(label, {"efficiency": [], "relmse": [], "seconds": [],
                                                          "spp": [], "chose": []})
                    entry["efficiency"].append(1.0 / (max(rel, 1e-300) * run.seconds))
                    entry["relmse"].append(rel)
                    entry["seconds"].append(run.seconds)
                    entry["spp"].append(run.spp)
                    chosen = label.startswith("auto")
                    entry["chose"].append(Strategy.from_record(run.film.record).slug if chosen else label)
                    print(f"  seed {seed} {name} {label}: relMSE {rel:.4g}, {run.spp} spp in {run.seconds:.2f} s"
                          + (f" (chose {entry['chose'][-1]})" if chosen else ""), file=sys.stderr)
        for name, by in runs.items():
            base = by["mis"]["efficiency"]
            results[name] = {}
            for label, entry in by.items():
                ratio, lo, hi = ratio_interval(entry["efficiency"], base)
                results[name][label] = {**entry, "ratio": ratio, "lo": lo, "hi": hi}
    import os

    doc = {"time": args.time, "seeds": args.seeds, "width": args.width, "scene_seed": args.scene_seed,
           "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load "
                      f"{os.getloadavg()[0]:.2f} at the end",
           "command": "python " + " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
           "strategies": [(label, s.slug, sampler) for label, s, sampler in selected],
           "reference_relmse": reference_relmse,
           "results": results}
    write_results(Path(args.out), "equal_time", doc, markdown)  # the JSON first: the runs are kept
    return 0


if __name__ == "__main__":
    sys.exit(main())
