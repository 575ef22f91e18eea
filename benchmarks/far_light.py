"""Where solid-angle light sampling should step aside for area sampling (issue 34, part 2).

    python benchmarks/far_light.py [--far 0,0.003,0.01,0.03,0.1] [--cbox PATH] [--size 128]
                                   [--spp 16] [--time 2] [--seeds 3] [--scene-seed SEED]

``tracer.lights.far_light.FAR``: a solid-angle technique samples a light by area where
(radius / distance)^2 < FAR (0: never, tracer before this change). For each value, in a child
process of its own (FAR is compiled into the kernels; each child has its own numba cache,
``NUMBA_CACHE_DIR``, so no value reads another's kernels), ``light`` and ``mis`` with
``solid-angle`` and ``solid-angle-cos`` are measured at equal spp and equal time
(``efficiency_runs.measure``) on

- ``cornell``: tracer's shipped Cornell box (a small ceiling quad), the scene the loss was
  reported on;
- ``cbox``: Mitsuba's own Cornell box (mitsuba-data ``scenes/cbox/cbox-rgb.xml``, ``--cbox``;
  a held-out scene: fetch mitsuba-renderer/mitsuba-data and extract ``scenes/cbox``);
- ``generated``: a room of quads and emitting triangles of random size, height and power over
  diffuse and rough-conductor surfaces, from ``--scene-seed`` (held out: the default is the
  date of the run, not a seed looked at before);

and ``area`` (which FAR does not touch) once, as the baseline. Efficiency is
1 / (relMSE x seconds) against a 1024-spp MIS ``area`` reference of each scene (its noise
subtracted), averaged over the seeds. Writes OUT/far_light.json and OUT/far_light.md.
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
from efficiency_runs import measure, write_results  # noqa: E402  (benchmarks/ is no package)

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SAMPLINGS = ("solid-angle", "solid-angle-cos")


def generated_scene(seed: int) -> tuple[list[dict], list]:
    """A 10 x 10 room: floor (half diffuse, half GGX 0.2 gold-like), a back wall, 12 quad lights
    of side 0.05-1.5 m at heights 0.3-3.5 m tilted up to 60 degrees (``[[shapes]]`` tables),
    and 6 emitting triangles of sides up to about 1 m (their corners, (3, 3) each)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    shapes = [
        {"type": "quad", "origin": [-5.0, 0.0, -5.0], "edge1": [0.0, 0.0, 10.0], "edge2": [5.0, 0.0, 0.0],
         "material": "matte"},
        {"type": "quad", "origin": [0.0, 0.0, -5.0], "edge1": [0.0, 0.0, 10.0], "edge2": [5.0, 0.0, 0.0],
         "material": "metal"},
        {"type": "quad", "origin": [-5.0, 0.0, -5.0], "edge1": [10.0, 0.0, 0.0], "edge2": [0.0, 5.0, 0.0],
         "material": "matte"}]
    for _ in range(12):
        size = float(rng.uniform(0.05, 1.5))
        tilt = float(rng.uniform(0.0, np.pi / 3))
        spin = float(rng.uniform(0.0, 2 * np.pi))
        normal = np.array([np.sin(tilt) * np.cos(spin), -np.cos(tilt), np.sin(tilt) * np.sin(spin)])
        e1 = np.cross(normal, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)  # e1 x e2 = normal: facing down
        centre = np.array([rng.uniform(-4, 4), rng.uniform(0.3, 3.5), rng.uniform(-4, 4)])
        shapes.append({"type": "quad", "origin": (centre - 0.5 * size * (e1 + e2)).tolist(),
                       "edge1": (size * e1).tolist(), "edge2": (size * e2).tolist(),
                       "emission": (rng.uniform(0.3, 1.0, 3) * 4.0 / size ** 2 * rng.uniform(0.2, 1.0)).tolist()})
    triangles = []
    for _ in range(6):
        a = np.array([rng.uniform(-4, 4), rng.uniform(0.5, 3.0), rng.uniform(-4, 4)])
        triangles.append([a, a + rng.uniform(-0.6, 0.6, 3), a + rng.uniform(-0.6, 0.6, 3)])
    return shapes, triangles


def _vec(v) -> str:
    return "[" + ", ".join(f"{float(c):.6g}" for c in v) + "]"


def scene_files(args, folder: Path) -> dict[str, Path]:
    """The scenes by name: the shipped Cornell box, Mitsuba's (``--cbox``), the generated room
    (written to ``folder`` as TOML with an OBJ of its emitting triangles)."""
    quads, triangles = generated_scene(args.scene_seed)
    obj = [f"v {_vec(p)[1:-1].replace(',', '')}" for tri in triangles for p in tri]
    obj += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(triangles))]
    (folder / "triangles.obj").write_text("\n".join(obj) + "\n")
    text = ["[camera]", "origin = [0.0, 4.0, 9.0]", "target = [0.0, 0.5, 0.0]", "fov = 55.0",
            "width = 128", "height = 128", "", "[materials.matte]", 'type = "diffuse"',
            "reflectance = [0.6, 0.6, 0.6]", "", "[materials.metal]", 'type = "roughconductor"',
            "reflectance = [0.9, 0.7, 0.4]", "alpha = 0.2", ""]
    for quad in quads:
        text += ["[[shapes]]", 'type = "quad"'] + [
            f'{key} = "{value}"' if key == "material" else f"{key} = {_vec(value)}"
            for key, value in quad.items() if key != "type"] + [""]
    text += ["[[shapes]]", 'type = "mesh"', 'file = "triangles.obj"', "emission = [3.0, 3.0, 3.0]", ""]
    generated = folder / "generated.toml"
    generated.write_text("\n".join(text))
    files = {"cornell": ROOT / "scenes" / "cornell.toml", "generated": generated}
    if args.cbox:
        files["cbox"] = Path(args.cbox)
    return files


def child(spec: dict) -> list[dict]:
    """In a child process: set FAR, then measure every (scene, strategy, sampling)."""
    from tracer import Strategy
    from tracer.imagefiles import read_exr
    from tracer.lights import far_light
    from tracer.scene import load_scene

    far_light.FAR = spec["far"]
    rows = []
    for name, path in spec["scenes"].items():
        scene = load_scene(path, width=spec["size"], height=spec["size"])
        reference = read_exr(spec["references"][name])
        for strategy in ("light", "mis"):
            for sampling in spec["samplings"]:
                row = measure(scene, reference, Strategy(strategy, light_sampling=sampling), spec["seeds"],
                              spec["spp"], spec["time"], 2,
                              {"scene": name, "strategy": strategy, "light_sampling": sampling,
                               "far": spec["far"]})
                print(f"  FAR {spec['far']}: {name} {strategy} {sampling}: relMSE {row['equal_spp_relmse']:.4g} "
                      f"at {spec['spp']} spp, {row['equal_time_relmse']:.4g} in {spec['time']} s", file=sys.stderr)
                rows.append(row)
    return rows


def run_child(spec: dict, cache: Path) -> list[dict]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)], env=env,
                          stdout=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"far_light: the child for FAR {spec['far']} failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def markdown(results: dict) -> str:
    lines = [f"Machine: {results['machine']}; load average before/after {results['load_before']} / "
             f"{results['load_after']}.", "",
             f"{results['size']}x{results['size']}, equal spp = {results['spp']}, equal time = {results['time']} s, "
             f"{len(results['seeds'])} seeds; generated scene seed {results['scene_seed']}. Efficiency over "
             "`area`'s, the same strategy on the same scene.", "",
             "| scene | strategy | light sampling | FAR | relMSE (equal spp) | relMSE (equal time) | "
             "vs area (equal spp) | vs area (equal time) |", "|---|---|---|---|---|---|---|---|"]
    rows = results["rows"]
    for r in rows:
        base = next(b for b in rows if b["scene"] == r["scene"] and b["strategy"] == r["strategy"]
                    and b["light_sampling"] == "area")
        lines.append(f"| {r['scene']} | {r['strategy']} | {r['light_sampling']} | "
                     f"{'' if r['light_sampling'] == 'area' else r['far']} | {r['equal_spp_relmse']:.4g} | "
                     f"{r['equal_time_relmse']:.4g} | "
                     f"{r['equal_spp_efficiency'] / base['equal_spp_efficiency']:.2f} | "
                     f"{r['equal_time_efficiency'] / base['equal_time_efficiency']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print(json.dumps(child(json.loads(sys.argv[2]))))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--far", default="0,0.003,0.01,0.03,0.1")
    parser.add_argument("--cbox", default="", help="Mitsuba's cbox-rgb.xml (mitsuba-data scenes/cbox)")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--time", type=float, default=2.0)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--scene-seed", type=int, default=int(time.strftime("%Y%m%d")))
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()

    import tracer
    from tracer.imagefiles import write_exr
    from tracer.scene import load_scene

    results = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_before": list(os.getloadavg()),
               "size": args.size, "spp": args.spp, "time": args.time, "seeds": list(range(1, args.seeds + 1)),
               "scene_seed": args.scene_seed, "rows": []}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        files = scene_files(args, folder)
        references = {}
        for name, path in files.items():
            scene = load_scene(path, width=args.size, height=args.size)
            film = tracer.render(scene, tracer.Strategy("mis"), spp=args.reference_spp, seed=99_999)
            references[name] = str(folder / f"{name}.exr")
            write_exr(references[name], film.film)
            print(f"reference {name}: {args.reference_spp} spp", file=sys.stderr)
        spec = {"scenes": {k: str(v) for k, v in files.items()}, "references": references, "size": args.size,
                "spp": args.spp, "time": args.time, "seeds": results["seeds"]}
        base = {**spec, "samplings": ["area"], "far": 0.0}
        results["rows"] += run_child(base, folder / "cache-area")
        for far in (float(v) for v in args.far.split(",")):
            results["rows"] += run_child({**spec, "samplings": list(SAMPLINGS), "far": far},
                                         folder / f"cache-{far}")
    results["load_after"] = list(os.getloadavg())
    write_results(Path(args.out), "far_light", results, markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
