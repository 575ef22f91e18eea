"""Render a `tracer` scene file with Mitsuba 3 as an independent reference.

    python benchmarks/mitsuba_render.py SCENE.toml --spp N --runs K -o OUT.exr \
        [--variant scalar_rgb] [--width W --height H] [--seed S] \
        [--emitter-samples E --bsdf-samples B] [--threads T]

Renders K independent runs (seeds S, S+1, ..., S+K-1) of N samples per pixel each with
Mitsuba's `direct` integrator and writes one EXR in the project's convention:

- channels R, G, B: the mean over the K runs (float32, zip compression);
- channels variance.R/G/B: the per-pixel variance of a *single sample's* estimate, estimated
  as (unbiased sample variance of the K run images) * N.  A run image is the mean of N
  independent samples, so its variance is var_1 / N; multiplying by N recovers var_1, and the
  variance of the pixel mean written here is variance / (N * K), as for `tracer`'s films.
  (The estimate has only K - 1 degrees of freedom per pixel: use many runs when the variance
  matters, not just the mean.)
- header: tracer:spp = N*K, tracer:strategy = "mitsuba-direct", tracer:heuristic = "power"
  (what Mitsuba's `direct` uses), tracer:seed, tracer:seconds (render wall time summed over
  runs, scene loading excluded), tracer:scene.

The file is written to a temporary name beside OUT and renamed, so an interrupted run never
leaves a torn file.  Needs mitsuba, numpy, trimesh and OpenImageIO (see mitsuba_scene.py).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

import numpy as np

# Run as a script from anywhere: the sibling module is found next to this file.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import mitsuba_scene  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="scene file (TOML, SCENE_FORMAT.md)")
    p.add_argument("--spp", type=int, required=True, help="samples per pixel of each run (N)")
    p.add_argument("--runs", type=int, default=4,
                   help="independent runs (K >= 2: the variance is estimated across runs)")
    p.add_argument("-o", "--output", required=True, help="output EXR")
    p.add_argument("--variant", default="scalar_rgb",
                   help="Mitsuba variant; an RGB one (scalar_rgb, llvm_ad_rgb)")
    p.add_argument("--width", type=int, help="override the camera's width")
    p.add_argument("--height", type=int, help="override the camera's height")
    p.add_argument("--seed", type=int, default=0, help="seed of the first run")
    p.add_argument("--emitter-samples", type=int, default=1)
    p.add_argument("--bsdf-samples", type=int, default=1)
    p.add_argument("--threads", type=int, help="worker threads (default: all cores)")
    args = p.parse_args(argv)
    if args.spp < 1:
        p.error("--spp must be at least 1")
    if args.runs < 2:
        p.error("--runs must be at least 2 (the variance channels are estimated across runs)")
    if "spectral" in args.variant or "mono" in args.variant:
        p.error("--variant must be an RGB variant: scene colours are RGB triples")
    if args.emitter_samples < 0 or args.bsdf_samples < 0 or \
            args.emitter_samples + args.bsdf_samples == 0:
        p.error("--emitter-samples and --bsdf-samples must be >= 0 and not both 0")
    return args


def write_exr(path: str, mean: np.ndarray, variance: np.ndarray, attributes: dict) -> None:
    """Write mean (H, W, 3) and single-sample variance (H, W, 3) as a 6-channel float32 EXR.

    Row 0 is the top of the image (Mitsuba's and OpenImageIO's order alike).  `attributes`
    maps header names to int / float / str values.  Atomic: temporary file, then rename.
    """
    import OpenImageIO as oiio

    height, width, _ = mean.shape
    pixels = np.concatenate([mean, variance], axis=2).astype(np.float32)
    spec = oiio.ImageSpec(width, height, 6, "float")
    spec.channelnames = ("R", "G", "B", "variance.R", "variance.G", "variance.B")
    spec.attribute("compression", "zip")
    for key, value in attributes.items():
        spec.attribute(key, value)

    path = os.path.abspath(path)
    tmp = f"{path}.tmp-{os.getpid()}.exr"  # keep the .exr suffix: OIIO picks the format by it
    out = oiio.ImageOutput.create(tmp)
    if out is None:
        raise RuntimeError(f"OpenImageIO cannot create {tmp}: {oiio.geterror()}")
    try:
        if not out.open(tmp, spec) or not out.write_image(pixels):
            raise RuntimeError(f"OpenImageIO failed writing {tmp}: {out.geterror()}")
        out.close()
        os.replace(tmp, path)
    except BaseException:
        out.close()
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def main(argv=None) -> int:
    args = parse_args(argv)

    import drjit as dr
    import mitsuba as mi

    mi.set_variant(args.variant)
    if args.threads:
        # Mitsuba's scalar renderer and the LLVM backend both run on Dr.Jit's thread pool.
        dr.set_thread_count(args.threads)

    scene_dict = mitsuba_scene.load_mitsuba_scene(
        args.scene, spp=args.spp, seed=args.seed, width=args.width, height=args.height,
        emitter_samples=args.emitter_samples, bsdf_samples=args.bsdf_samples)
    scene = mi.load_dict(scene_dict)

    images = []
    seconds = 0.0
    for k in range(args.runs):
        seed = args.seed + k
        start = time.perf_counter()
        image = np.array(mi.render(scene, seed=seed, spp=args.spp), dtype=np.float64)
        elapsed = time.perf_counter() - start
        seconds += elapsed
        images.append(image[..., :3])
        print(f"run {k + 1}/{args.runs} (seed {seed}, {args.spp} spp): {elapsed:.3f} s",
              flush=True)

    stack = np.stack(images)  # (K, H, W, 3)
    mean = stack.mean(axis=0)
    variance = stack.var(axis=0, ddof=1) * args.spp
    write_exr(args.output, mean, variance, {
        "tracer:spp": int(args.spp * args.runs),
        "tracer:strategy": "mitsuba-direct",
        "tracer:heuristic": "power",
        "tracer:seed": int(args.seed),
        "tracer:seconds": float(seconds),
        "tracer:scene": str(args.scene),
    })
    print(f"total {seconds:.3f} s render time, {args.spp * args.runs} spp -> {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
