"""Regenerate `tests/data/mitsuba_bsdf_values.npz`: Mitsuba 3.9.1's own f and pdf of a BSDF at
random direction pairs, for tracer's tests to compare against.

    /work/venv-xcheck/bin/python benchmarks/mitsuba_bsdf_values.py [-o tests/data/mitsuba_bsdf_values.npz]

For each BSDF type here (`principled`, `principledthin`), `SETS` random parameter sets (every
parameter Mitsuba reads, drawn in its documented range, plus the all-default set), and for each
set `PAIRS` direction pairs: wo (Mitsuba's si.wi, toward the viewer) on either side of the
surface, wi (Mitsuba's wo, toward the light) on either side, both from a fixed seed. Mitsuba, in
the `scalar_rgb` variant on a z-up frame, gives eval(ctx, si, wi) / |wi.z| (tracer's f has no
cosine) and pdf(ctx, si, wi). The file holds, per type, the parameter sets (as tracer names
them: Mitsuba's `specular` becomes `eta`), the set index, wo, wi, f (RGB) and pdf of every pair.
Directions within 0.02 of the horizon are left out: there Mitsuba's float32 cosines differ from
tracer's float64 ones by more than the comparison's tolerance.
"""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np

SETS, PAIRS = 12, 400

PRINCIPLED_UNIT = ("roughness", "anisotropic", "metallic", "spec_tint", "sheen", "sheen_tint", "clearcoat",
                   "clearcoat_gloss", "spec_trans", "flatness")
THIN_UNIT = ("roughness", "anisotropic", "spec_trans", "spec_tint", "sheen", "sheen_tint", "flatness")


def eta_of_specular(specular: float) -> float:
    return 2.0 / (1.0 - np.sqrt(0.08 * specular)) - 1.0


def parameter_sets(kind: str, gen: np.random.Generator) -> list[dict[str, object]]:
    """The all-default set, then SETS - 1 random ones (each number in [0, 1] or 0 with
    probability 1/4, so lobes are switched off as often as on)."""
    sets: list[dict[str, object]] = [{}]
    for _ in range(SETS - 1):
        values: dict[str, object] = {"base_color": [float(x) for x in gen.uniform(0.0, 1.0, 3)]}
        for name in (PRINCIPLED_UNIT if kind == "principled" else THIN_UNIT):
            values[name] = 0.0 if gen.random() < 0.25 else float(gen.uniform(0.0, 1.0))
        if kind == "principled":
            values["specular"] = float(gen.uniform(0.05, 1.0))
        else:
            values["eta"] = float(gen.uniform(1.05, 2.0))
            values["diff_trans"] = 0.0 if gen.random() < 0.25 else float(gen.uniform(0.0, 2.0))
        sets.append(values)
    return sets


def directions(gen: np.random.Generator, n: int) -> np.ndarray:
    v = gen.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", default="tests/data/mitsuba_bsdf_values.npz")
    args = parser.parse_args()

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    gen = np.random.default_rng(20261204)
    out: dict[str, np.ndarray] = {}
    for kind in ("principled", "principledthin"):
        sets = parameter_sets(kind, gen)
        rows = []
        for index, values in enumerate(sets):
            spec = {"type": kind}
            for name, value in values.items():
                spec[name] = {"type": "rgb", "value": value} if name == "base_color" else value
            bsdf = mi.load_dict(spec)
            ctx = mi.BSDFContext()
            wo_all, wi_all = directions(gen, 4 * PAIRS), directions(gen, 4 * PAIRS)
            keep = (np.abs(wo_all[:, 2]) > 0.02) & (np.abs(wi_all[:, 2]) > 0.02)
            for wo, wi in list(zip(wo_all[keep], wi_all[keep], strict=True))[:PAIRS]:
                si = mi.SurfaceInteraction3f()
                si.p = mi.Point3f(0, 0, 0)
                si.n = mi.Normal3f(0, 0, 1)
                si.sh_frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
                si.uv = mi.Point2f(0.5, 0.5)
                si.wi = mi.Vector3f(*wo)
                f = np.array(bsdf.eval(ctx, si, mi.Vector3f(*wi))) / abs(wi[2])
                pdf = float(bsdf.pdf(ctx, si, mi.Vector3f(*wi)))
                rows.append((index, *wo, *wi, *f, pdf))
        table = np.array(rows, dtype=np.float64)
        out[f"{kind}_sets"] = np.array(json.dumps(sets))
        out[f"{kind}_set"] = table[:, 0].astype(np.int64)
        out[f"{kind}_wo"], out[f"{kind}_wi"] = table[:, 1:4], table[:, 4:7]
        out[f"{kind}_f"], out[f"{kind}_pdf"] = table[:, 7:10], table[:, 10]
    pathlib.Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, mitsuba=np.array(mi.__version__), **out)
    counts = ", ".join(f"{k}: {len(out[k + '_pdf'])} pairs" for k in ("principled", "principledthin"))
    print(f"{args.out}: {counts}")


if __name__ == "__main__":
    main()
