"""tracer against Mitsuba 3's `direct` integrator on scenes of the public corpus
(benchmarks/scene_coverage_sources.toml), which nobody wrote for tracer.

    /work/venv-xcheck/bin/python benchmarks/corpus_agreement.py --mitsuba CORPUS SCENE ... --out DIR
    python benchmarks/corpus_agreement.py --compare DIR

Each scene's repository is mirrored into DIR/NAME/ (other files linked, XML files rewritten)
so that both renderers see the same scene with: Mitsuba's `direct` integrator, a
box pixel filter (tracer's; Mitsuba's default Gaussian blurs every edge), and the film scaled
so that its longer side is `--size` pixels. `--mitsuba` (with Mitsuba 3's Python) renders K
independent runs and stores DIR/NAME.npz as benchmarks/mitsuba_xml.py does, with the rewritten
scene tree kept; `--compare` (with tracer's Python) renders each stored scene with
`mis` and prints the statistics of benchmarks/mitsuba_xml.py (`compare`): the image mean per
channel (z, Šidák over the channels), the worst pixel (t, Šidák over all pixel-channels), the
sum of squared pixel scores (χ²), and 8 x 8 blocks (z of each block's mean, Šidák over blocks
and channels).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mitsuba_xml  # noqa: E402  (the statistics: one copy)

# An integrator's tags: self-closing, opening, closing (integrators nest: stokes wraps path).
INTEGRATOR_TAG = re.compile(r"<integrator\b[^>]*?/>|<integrator\b[^>]*>|</integrator\s*>")
RFILTER = re.compile(r"<rfilter\b[^>]*?/>|<rfilter\b[^>]*?>.*?</rfilter>", re.S)
FILM = re.compile(r"(<film\b[^>]*?>)(.*?)(</film>)", re.S)
SIDE = re.compile(r'(<integer\s+name="(width|height)"\s+value=")(\d+)(")')
# A film side given as a scene parameter ($res), and that parameter's default.
SIDE_PARAMETER = re.compile(r'<integer\s+name="(?:width|height)"\s+value="\$(\w+)"')


def without_integrators(text: str) -> str:
    """``text`` less every integrator element, nested ones with the one that holds them."""
    kept, start, depth = [], 0, 0
    for tag in INTEGRATOR_TAG.finditer(text):
        closing, alone = tag.group(0).startswith("</"), tag.group(0).endswith("/>")
        if depth == 0 and not closing:
            kept.append(text[start:tag.start()])
        depth += 0 if alone else (-1 if closing else 1)
        if depth == 0:
            start = tag.end()
    return "".join(kept) + text[start:]


# What Mitsuba renders tracer's direct light with: `direct`, or for scenes with masks `volpath`
# at max_depth 2 (Mitsuba's `direct` stops shadow rays at a mask; volpath passes masks without
# counting a bounce and weighs shadow rays by their transmittance: docs/MITSUBA_XML.md, mask).
INTEGRATORS = {"direct": '<integrator type="direct"/>',
               "volpath": '<integrator type="volpath"><integer name="max_depth" value="2"/></integrator>'}
INTEGRATOR = INTEGRATORS["direct"]


def rewrite(text: str, size: int) -> str:
    """A scene file's text with the integrator ``INTEGRATOR``, a box filter and a film of longer
    side ``size`` (films with numeric sizes; others are left as they are)."""
    text = without_integrators(text)
    # Film sides that are parameters ($res): their numeric defaults scaled by one factor, so
    # that the longer side is ``size`` and the aspect ratio stays.
    defaults = {}
    for name in set(SIDE_PARAMETER.findall(text)):
        pattern = re.compile(rf'(<default\s+name="{name}"\s+value=")(\d+)(")')
        found = pattern.search(text)
        if found is not None:
            defaults[name] = (pattern, int(found.group(2)))
    if defaults and max(v for _, v in defaults.values()) > size:
        scale = size / max(v for _, v in defaults.values())
        for pattern, value in defaults.values():
            text = pattern.sub(lambda m, v=value: f"{m.group(1)}{max(1, round(v * scale))}{m.group(3)}",
                               text, count=1)
    if "<sensor" in text:
        text = re.sub(r"(<scene\b[^>]*>)", lambda m: f"{m.group(1)}\n{INTEGRATOR}", text, count=1)

    def film(match: re.Match) -> str:
        body = RFILTER.sub("", match.group(2))
        sides = {m.group(2): int(m.group(3)) for m in SIDE.finditer(body)}
        if len(sides) == 2:
            scale = size / max(sides.values())
            body = SIDE.sub(lambda m: f"{m.group(1)}{max(1, round(sides[m.group(2)] * scale))}{m.group(4)}",
                            body)
        return match.group(1) + body + '<rfilter type="box"/>' + match.group(3)

    return FILM.sub(film, text)


def mirror_tree(source: Path, target: Path, size: int) -> None:
    """``source``'s folder tree under ``target``: XML files rewritten, other files linked."""
    for path in source.rglob("*"):
        out = target / path.relative_to(source)
        if path.is_dir():
            out.mkdir(parents=True, exist_ok=True)
        elif path.suffix == ".xml":
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(rewrite(path.read_text(errors="replace"), size))
        else:
            out.parent.mkdir(parents=True, exist_ok=True)
            out.symlink_to(path.resolve())


def render_mitsuba(scene: Path, root: Path, out: Path, size: int, runs: int, spp: int) -> None:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    name = scene.stem
    tree = out / name
    shutil.rmtree(tree, ignore_errors=True)
    mirror_tree(root, tree, size)
    copy = tree / scene.relative_to(root)
    loaded = mi.load_file(str(copy))
    film = loaded.sensors()[0].film()
    width, height = (int(v) for v in film.size())
    total, total_sq = np.zeros((height, width, 3)), np.zeros((height, width, 3))
    start = time.perf_counter()
    for k in range(runs):
        image = np.array(mi.render(loaded, seed=mitsuba_xml.run_seed(k, width, height), spp=spp),
                         dtype=np.float64)[..., :3]
        total += image
        total_sq += image * image
    mean = total / runs
    var_of_mean = np.maximum(total_sq - runs * mean * mean, 0.0) / (runs - 1) / runs
    np.savez_compressed(out / f"{name}.npz", mean=mean.astype(np.float32),
                        var_of_mean=var_of_mean.astype(np.float32),
                        runs=np.int64(runs), spp_per_run=np.int64(spp), width=np.int64(width),
                        height=np.int64(height), mitsuba_version=np.str_(mi.__version__),
                        scene=np.str_(str(copy.relative_to(out))))
    print(f"{name}: {width}x{height}, {runs} x {spp} spp, {time.perf_counter() - start:.1f} s", flush=True)


def compare_all(out: Path, spp: int, seed: int, light_selection: str = "power") -> int:
    import tracer

    failed = 0
    rows = []
    for record in sorted(out.glob("*.npz")):
        with np.load(record) as data:
            ref = mitsuba_xml.Reference(record.stem, data["mean"].astype(np.float64),
                                        data["var_of_mean"].astype(np.float64), int(data["runs"]),
                                        int(data["spp_per_run"]), int(data["width"]), int(data["height"]),
                                        str(data["mitsuba_version"]), "", "")
            scene_file = out / str(data["scene"])
        scene = tracer.load_scene(scene_file, width=ref.width, height=ref.height)
        strategy = tracer.Strategy("mis", light_selection=light_selection)
        image = tracer.render(scene, strategy, spp=spp, seed=seed, sampler="independent")
        c = mitsuba_xml.compare(image.mean, image.variance, image.count, ref)
        var_mean = image.variance / np.maximum(image.count, 1)[..., None]
        block_p, worst = mitsuba_xml.block_test(image.mean, var_mean, ref)
        relative = c.mean_tracer / np.where(c.mean_mitsuba > 0, c.mean_mitsuba, np.nan) - 1.0
        passed = min(c.mean_p, c.sidak_p, c.chi2_p, block_p) >= mitsuba_xml.FAMILY_ALPHA
        ok = bool(passed and not c.exact_bad.any())
        failed += not ok
        rows.append({"scene": record.stem, "size": f"{ref.width}x{ref.height}",
                     "mean": " / ".join(f"{100 * r:+.2f}%" for r in relative),
                     "mean_p": c.mean_p, "pixel_p": c.sidak_p, "chi2_p": c.chi2_p, "block_p": block_p,
                     "ok": ok})
        print(json.dumps(rows[-1]), flush=True)
    print("| scene | size | image mean R / G / B: tracer/Mitsuba − 1 | image-mean p | worst pixel p | χ² p | "
          "worst 8x8 block p | |\n|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['size']} | {r['mean']} | {r['mean_p']:.3f} | {r['pixel_p']:.3f} | "
              f"{r['chi2_p']:.3f} | {r['block_p']:.3f} | {'ok' if r['ok'] else 'FAIL'} |")
    return 1 if failed else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mitsuba", type=Path, metavar="CORPUS",
                   help="render references of SCENE ... (paths in CORPUS)")
    p.add_argument("scenes", nargs="*", type=Path)
    p.add_argument("--compare", action="store_true")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--size", type=int, default=96)
    p.add_argument("--integrator", choices=sorted(INTEGRATORS), default="direct",
                   help="Mitsuba's integrator: direct, or volpath (max_depth 2) for scenes with masks")
    p.add_argument("--runs", type=int, default=16)
    p.add_argument("--mitsuba-spp", type=int, default=256)
    p.add_argument("--spp", type=int, default=1024)
    p.add_argument("--seed", type=int, default=15)
    # A scene whose power estimates starve a light (a spot beside an environment, whose power is
    # estimated over the scene's bounding sphere) renders heavy-tailed noise under "power" at
    # 1024 spp, which the tests' normal bounds do not cover: "uniform" shows whether the
    # estimator agrees there.
    p.add_argument("--light-selection", default="power")
    args = p.parse_args()
    global INTEGRATOR
    INTEGRATOR = INTEGRATORS[args.integrator]
    args.out.mkdir(parents=True, exist_ok=True)
    if args.mitsuba:
        corpus = args.mitsuba.resolve()
        for scene in args.scenes:
            scene = scene.resolve()
            # The scene's whole repository is mirrored: its <path> folders may reach anywhere in it.
            root = corpus / scene.relative_to(corpus).parts[0]
            render_mitsuba(scene, root, args.out, args.size, args.runs, args.mitsuba_spp)
        return 0
    return compare_all(args.out, args.spp, args.seed, args.light_selection)


if __name__ == "__main__":
    sys.exit(main())
