"""Mitsuba 3 references of the XML verification scenes, and tracer's agreement with them.

    /work/venv-xcheck/bin/python benchmarks/mitsuba_xml.py [SCENE ...] [--preview DIR]
    python benchmarks/mitsuba_xml.py --compare [SCENE ...] [--spp N] [--seed S]

Without `--compare` (run with a Python that has Mitsuba 3, variant `scalar_rgb`): renders each
scene `tracer/scenes/mitsuba/NAME.xml` (files in `parts/` are included pieces, not scenes) at
the small resolution of `REFERENCES` (same aspect ratio as the file's film, passed as the
file's `$width`/`$height` defaults), as K independent renders (seeds far enough apart that no
pixel's random stream is reused, see `run_seed`) of s spp each, and writes
`tests/data/mitsuba_refs/NAME.npz`:

- `mean` (H, W, 3) float32: the mean of the K renders, i.e. of K s samples per pixel;
- `var_of_mean` (H, W, 3) float32: the variance of that mean, estimated as the unbiased sample
  variance of the K render images divided by K (K - 1 degrees of freedom per pixel);
- `runs` (K), `spp_per_run` (s), `width`, `height`, `mitsuba_version`, `variant`,
  `scene_sha256` (of the XML file), `inputs_sha256` (of the file and everything it includes
  or loads, recursively: the reference is stale when this changes), `seconds` (render time).

With `--compare` (run with tracer's Python): renders each reference's scene with
`tracer.render(tracer.load_scene(path, width=W, height=H), "mis", ...)` at the reference's
resolution and prints, per scene, the image-mean relative difference per channel with its
standard error and z, and the per-pixel tests of tests/test_mitsuba_agreement.py (which
imports its statistics from here: one copy), as a Markdown table for the README.

The statistics (`compare`) need numpy and scipy only; neither Mitsuba nor tracer.
"""

from __future__ import annotations

import argparse
import hashlib
import pathlib
import re
import sys
import time
from dataclasses import dataclass

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENES = ROOT / "tracer" / "scenes" / "mitsuba"
REFS = ROOT / "tests" / "data" / "mitsuba_refs"
VARIANT = "scalar_rgb"

# name -> (width, height, runs K, spp per run s). The resolution keeps the file's aspect ratio.
REFERENCES = {
    "cornell_box": (64, 64, 32, 256),
    "veach_mis": (96, 72, 32, 256),
    "smooth_mesh": (96, 72, 32, 256),
    "transforms": (128, 64, 32, 256),
    "transforms_focal": (96, 64, 32, 256),
    "textures": (96, 72, 32, 256),
    "textured_meshes": (96, 72, 32, 256),
    "glass": (96, 72, 32, 256),
    "environment": (96, 72, 32, 256),
    "delta_lights": (96, 72, 32, 256),
    "rough_glass": (96, 72, 32, 256),
    "mask": (96, 72, 32, 256),
    "pplastic": (96, 72, 32, 256),
    "normal_maps": (96, 72, 32, 256),
    "orthographic": (96, 64, 32, 256),
    "thinlens": (96, 64, 32, 256),
    "projected_lights": (96, 64, 32, 256),
    "anisotropic": (96, 72, 32, 256),
    "textured_emitters": (96, 72, 32, 256),
    "principled": (96, 72, 32, 256),
    "environment_studio": (96, 72, 32, 256),
}

# tracer's side of the comparison (--compare and tests/test_mitsuba_agreement.py).
TRACER_SPP = 1024
TRACER_SEED = 15

# Family-wise false-alarm rate of each statistical test (the suite's, tests/stats.py).
FAMILY_ALPHA = 0.01
# Pixels where both renderers report zero variance must agree to float32 rounding: Mitsuba
# sums s float32 samples per run (relative error up to about s * 2^-24 = 1.5e-5 at s = 256).
EXACT_RTOL = 1e-4
EXACT_ATOL = 1e-7
# A floor on the standard error of a pixel difference, relative to the pixel value plus an
# absolute part, so that float rounding noise (a "variance" of 1e-14 relative) and values
# that are 0 to float32 precision (Mitsuba 0 where tracer has 1e-27) never yield a huge z.
ROUNDING_RTOL = 2e-6
ROUNDING_ATOL = 1e-7


def scene_names() -> list[str]:
    return sorted(p.stem for p in SCENES.glob("*.xml"))


def scene_path(name: str) -> pathlib.Path:
    return SCENES / f"{name}.xml"


def sha256_file(path: pathlib.Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def scene_inputs(path: pathlib.Path) -> list[pathlib.Path]:
    """The XML file and every file it names in a `filename` attribute or property (`include`,
    meshes), recursively, relative to the top file's folder (Mitsuba's resolver)."""
    base = path.parent
    seen: list[pathlib.Path] = []
    todo = [path]
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen.append(current)
        if current.suffix.lower() != ".xml":
            continue
        text = current.read_text()
        names = re.findall(r'<include\s+filename="([^"]+)"', text)
        names += re.findall(r'<string\s+name="filename"\s+value="([^"]+)"', text)
        todo += [base / n for n in names]
    return seen


def inputs_sha256(path: pathlib.Path) -> str:
    """SHA-256 over the names (relative to the scene folder) and contents of scene_inputs."""
    digest = hashlib.sha256()
    for p in sorted(scene_inputs(path)):
        digest.update(str(p.relative_to(path.parent)).encode() + b"\0")
        digest.update(hashlib.sha256(p.read_bytes()).digest())
    return digest.hexdigest()


# --------------------------------------------------------------------------------------------
# Mitsuba references


def run_seed(k: int, width: int, height: int) -> int:
    """Seed of render k. Mitsuba's scalar renderer seeds pixel i of block b (blocks of B x B
    pixels, B = 32 here, padded past the film's edge) with seed * W * H + b * B^2 + i, which
    runs up to seed * W * H + (padded film area): consecutive seeds would hand one random
    stream to two pixels of two renders. Seeds `stride` apart, stride W * H >= the padded
    area, never do."""
    padded = -(-width // 32) * 32 * -(-height // 32) * 32
    stride = -(-padded // (width * height))
    return stride * k + 1


def render_reference(name: str, preview: pathlib.Path | None = None) -> dict:
    import mitsuba as mi

    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    width, height, runs, spp = REFERENCES[name]
    path = scene_path(name)
    scene = mi.load_file(str(path), width=width, height=height, spp=spp)
    total = np.zeros((height, width, 3))
    total_sq = np.zeros((height, width, 3))
    start = time.perf_counter()
    for k in range(runs):
        image = mi.render(scene, seed=run_seed(k, width, height), spp=spp)
        image = np.array(image, dtype=np.float64)[..., :3]
        if image.shape != (height, width, 3) or not np.all(np.isfinite(image)):
            raise RuntimeError(f"{name}: render {k} has shape {image.shape} or non-finite pixels")
        total += image
        total_sq += image * image
    seconds = time.perf_counter() - start
    mean = total / runs
    # Unbiased variance across the K renders (two-pass form from the sums: fine in float64 at
    # these magnitudes), then divided by K: the variance of the mean.
    var_runs = np.maximum(total_sq - runs * mean * mean, 0.0) / (runs - 1)
    var_of_mean = var_runs / runs
    record = {
        "mean": mean.astype(np.float32),
        "var_of_mean": var_of_mean.astype(np.float32),
        "runs": np.int64(runs),
        "spp_per_run": np.int64(spp),
        "width": np.int64(width),
        "height": np.int64(height),
        "mitsuba_version": np.str_(mi.__version__),
        "variant": np.str_(VARIANT),
        "scene_sha256": np.str_(sha256_file(path)),
        "inputs_sha256": np.str_(inputs_sha256(path)),
        "seconds": np.float64(seconds),
    }
    REFS.mkdir(parents=True, exist_ok=True)
    out = REFS / f"{name}.npz"
    tmp = out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, **record)
    tmp.replace(out)
    if preview is not None:
        preview.mkdir(parents=True, exist_ok=True)
        mi.util.write_bitmap(str(preview / f"{name}_mitsuba.png"), np.clip(mean, 0, None).astype(np.float32))
    rel = np.sqrt(var_of_mean.sum()) / max(mean.sum(), 1e-30)
    print(f"{name}: {width}x{height}, {runs} x {spp} spp, {seconds:.1f} s, "
          f"{out.stat().st_size / 1024:.0f} kB, image mean {mean.mean(axis=(0, 1)).round(5)}, "
          f"relative SE of the image sum {rel:.2e}", flush=True)
    return record


# --------------------------------------------------------------------------------------------
# Statistics (shared with tests/test_mitsuba_agreement.py)


@dataclass
class Reference:
    name: str
    mean: np.ndarray          # (H, W, 3) float64
    var_of_mean: np.ndarray   # (H, W, 3) float64
    runs: int
    spp_per_run: int
    width: int
    height: int
    mitsuba_version: str
    scene_sha256: str
    inputs_sha256: str

    @property
    def samples(self) -> int:
        return self.runs * self.spp_per_run


def load_reference(name: str) -> Reference:
    with np.load(REFS / f"{name}.npz") as data:
        return Reference(name, data["mean"].astype(np.float64), data["var_of_mean"].astype(np.float64),
                         int(data["runs"]), int(data["spp_per_run"]), int(data["width"]),
                         int(data["height"]), str(data["mitsuba_version"]), str(data["scene_sha256"]),
                         str(data["inputs_sha256"]))


@dataclass
class Comparison:
    """Every number the agreement tests look at, for one scene.

    Pixel statistics use a robust standard error (see `compare`): z (H, W, 3), p (H, W, 3),
    `tested` (H, W, 3) bool (pixel-channels with a positive standard error), `exact` (H, W, 3)
    bool (both variances 0) and `exact_bad` (exact ones that differ beyond rounding).
    """

    z: np.ndarray
    p: np.ndarray
    tested: np.ndarray
    exact: np.ndarray
    exact_bad: np.ndarray
    sidak_p: float          # family p-value of the smallest per-pixel p (Sidak over m)
    worst: tuple            # (row, col, channel) of the smallest p
    chi2: float             # sum of the per-pixel normal scores squared
    chi2_m: int             # its degrees of freedom (tested pixel-channels)
    chi2_p: float           # upper tail p-value of chi2 under chi-square(m)
    mean_tracer: np.ndarray  # (3,) image means
    mean_mitsuba: np.ndarray
    mean_se: np.ndarray      # (3,) standard error of their difference
    mean_z: np.ndarray       # (3,)
    mean_p: float            # two-sided p of the worst channel, Sidak over the 3 channels


def compare(t_mean, t_var, t_count, ref: Reference) -> Comparison:
    """Compare tracer's image (mean (H, W, 3), per-sample variance (H, W, 3), samples per pixel
    (H, W)) with a Mitsuba reference.

    Per pixel and channel, d = tracer - Mitsuba. Each side's per-sample variance is estimated
    (tracer: its Welford variance, n_t - 1 degrees of freedom; Mitsuba: K s var_of_mean, K - 1),
    and both sides use the larger of the two estimates: se^2 = max(s_t^2, s_m^2) (1/n_t + 1/n_m).
    Both renderers estimate the same integral with similar MIS estimators, so where the true
    variances are equal this is the pooled standard error, and where they differ it is larger
    than the true one (conservative). The max guards against the heavy-tail failure of a
    per-pixel z-test: a rare bright event (a reflected light's edge, a small light hit by a
    BSDF sample) that one side's n samples happened not to see leaves that side with a variance
    estimate near 0 and a mean near 0, while the other side, having seen it, has both; with
    each side's own variance, z would reach 5-6 for a pixel where tracer is right. The
    degrees of freedom are those of the estimate used (n_t - 1 or K - 1), and p comes from
    Student's t (the variance is estimated, with as few as K - 1 = 31 degrees of freedom).
    A rounding floor (ROUNDING_RTOL of the pixel value plus ROUNDING_ATOL, float32's resolution
    at 1) keeps float noise, and values that are 0 to float32 precision on one side and 1e-27
    on the other, from producing a huge z. Pixel-channels where both variances are exactly 0
    (background, a light seen directly, shadowed or unlit points) are tested separately: they
    must agree to float32 rounding (EXACT_RTOL, EXACT_ATOL).

    The image mean per channel is compared with the plain (not floored) standard error,
    sqrt(sum over pixels of (s_t^2/n_t + var_of_mean_m)) / number of pixels: over thousands
    of pixels the summed variance estimates are accurate whatever their individual tails.
    """
    from scipy import stats

    t_mean = np.asarray(t_mean, dtype=np.float64)
    t_var = np.asarray(t_var, dtype=np.float64)
    n_t = np.asarray(t_count, dtype=np.float64)[..., None] * np.ones(3)
    if t_mean.shape != ref.mean.shape:
        raise ValueError(f"{ref.name}: tracer image {t_mean.shape} vs reference {ref.mean.shape}")
    n_m = float(ref.samples)
    s2_t = t_var
    s2_m = ref.var_of_mean * n_m
    d = t_mean - ref.mean

    exact = (s2_t == 0) & (s2_m == 0)
    exact_bad = exact & (np.abs(d) > EXACT_RTOL * np.maximum(np.abs(t_mean), np.abs(ref.mean)) + EXACT_ATOL)

    s2 = np.maximum(s2_t, s2_m)
    dof = np.where(s2_t >= s2_m, n_t - 1, ref.runs - 1)
    scale = np.maximum(np.abs(t_mean), np.abs(ref.mean))
    se = np.sqrt(s2 * (1 / n_t + 1 / n_m) + (ROUNDING_RTOL * scale + ROUNDING_ATOL) ** 2)
    tested = ~exact & (se > 0)
    z = np.zeros_like(d)
    z[tested] = d[tested] / se[tested]
    p = np.ones_like(d)
    p[tested] = 2 * stats.t.sf(np.abs(z[tested]), np.maximum(dof[tested], 1))
    m = int(tested.sum())
    if m:
        flat = int(np.argmin(np.where(tested, p, np.inf)))
        worst = tuple(int(i) for i in np.unravel_index(flat, p.shape))
        p_min = float(p[worst])
        sidak_p = float(-np.expm1(m * np.log1p(-p_min))) if p_min < 1 else 1.0
        # Normal scores of the t p-values: chi-square(1) each under agreement.
        scores = stats.norm.isf(p[tested] / 2)
        chi2 = float(np.sum(scores ** 2))
        chi2_p = float(stats.chi2.sf(chi2, m))
    else:
        worst, sidak_p, chi2, chi2_p = (0, 0, 0), 1.0, 0.0, 1.0

    pixels = d.shape[0] * d.shape[1]
    mean_t = t_mean.mean(axis=(0, 1))
    mean_m = ref.mean.mean(axis=(0, 1))
    mean_se = np.sqrt((s2_t / n_t + ref.var_of_mean).sum(axis=(0, 1))) / pixels
    with np.errstate(divide="ignore", invalid="ignore"):
        mean_z = np.where(mean_se > 0, (mean_t - mean_m) / mean_se,
                          np.where(mean_t == mean_m, 0.0, np.inf))
    p_worst = float(2 * stats.norm.sf(np.max(np.abs(mean_z))))
    mean_p = float(-np.expm1(3 * np.log1p(-p_worst))) if p_worst < 1 else 1.0
    return Comparison(z, p, tested, exact, exact_bad, sidak_p, worst, chi2, m, chi2_p,
                      mean_t, mean_m, mean_se, mean_z, mean_p)


def block_test(t_mean, t_var_of_mean, ref: Reference, block: int = 8) -> tuple[float, tuple]:
    """The worst 8 x 8 block: each block's mean difference per channel over its standard error
    (the pixels of a block are independent, so the variances of their means add; each channel
    is tested on its own, never summed with the others, since a pixel's channels are not
    independent), two-sided normal p (a block's mean of 64 independent pixels is close to
    normal), Šidák over blocks x channels, with the per-pixel test's rounding floor on the
    standard error. ``t_var_of_mean`` (H, W, 3): the variance of each of
    tracer's pixel means. Returns (family p, worst (row, column, channel, z))."""
    from scipy import stats

    height, width, _ = ref.mean.shape
    var_tracer = t_var_of_mean
    best_p, worst, m = 1.0, None, 0
    for y in range(0, height - block + 1, block):
        for x in range(0, width - block + 1, block):
            window = (slice(y, y + block), slice(x, x + block))
            d = t_mean[window].mean(axis=(0, 1)) - ref.mean[window].mean(axis=(0, 1))
            summed = var_tracer[window].sum(axis=(0, 1)) + ref.var_of_mean[window].sum(axis=(0, 1))
            # The per-pixel test's rounding floor (``compare``), on the block's mean: blocks of
            # pixels without noise in either renderer (a delta light on a diffuse plane) differ
            # by float32 rounding alone, which a variance of 1e-31 would make a huge z.
            level = np.abs(ref.mean[window].mean(axis=(0, 1)))
            se = np.sqrt(summed / block**4 + (ROUNDING_RTOL * level + ROUNDING_ATOL) ** 2)
            for c in range(3):
                if se[c] <= 0.0:
                    continue
                m += 1
                p = 2.0 * stats.norm.sf(abs(d[c]) / se[c])
                if p < best_p:
                    best_p, worst = p, (y, x, c, d[c] / se[c])
    family = 1.0 - (1.0 - best_p) ** max(m, 1) if best_p > 1e-12 else m * best_p
    return family, worst


def render_tracer(name: str, ref: Reference, spp: int = TRACER_SPP, seed: int = TRACER_SEED):
    """tracer's render of scene `name` at the reference's resolution: the `tracer.Image`."""
    import tracer

    scene = tracer.load_scene(scene_path(name), width=ref.width, height=ref.height)
    return tracer.render(scene, "mis", spp=spp, seed=seed, sampler="independent")


def compare_table(names: list[str], spp: int, seed: int, preview: pathlib.Path | None) -> int:
    rows = []
    failures = 0
    for name in names:
        ref = load_reference(name)
        stale = ref.inputs_sha256 != inputs_sha256(scene_path(name))
        start = time.perf_counter()
        image = render_tracer(name, ref, spp, seed)
        seconds = time.perf_counter() - start
        c = compare(image.mean, image.variance, image.count, ref)
        rel = (c.mean_tracer - c.mean_mitsuba) / c.mean_mitsuba
        rel_se = c.mean_se / c.mean_mitsuba
        ok = (c.mean_p >= FAMILY_ALPHA and c.sidak_p >= FAMILY_ALPHA and c.chi2_p >= FAMILY_ALPHA
              and not c.exact_bad.any() and image.nonfinite == 0 and not stale)
        failures += not ok
        rows.append(
            f"| {name} | {ref.width}x{ref.height} | {ref.samples} / {spp} | "
            + " | ".join(f"{100 * r:+.2f}% ± {100 * s:.2f}%" for r, s in zip(rel, rel_se, strict=True))
            + f" | {c.mean_p:.3f} | {c.chi2 / max(c.chi2_m, 1):.3f} | {c.chi2_p:.3f} | {c.sidak_p:.3f}"
            f" | {int(c.exact.sum())} / {int(c.exact_bad.sum())} | {seconds:.1f} s"
            f" | {'ok' if ok else 'FAIL'}{' (stale reference)' if stale else ''} |")
        print(f"{name}: worst pixel (row, col, channel) {c.worst}: tracer {image.mean[c.worst]:.5g}, "
              f"Mitsuba {ref.mean[c.worst]:.5g}, z {c.z[c.worst]:+.2f}; image-mean z {c.mean_z.round(2)}",
              file=sys.stderr, flush=True)
        if preview is not None:
            write_preview(preview, name, image.mean, ref, c)
    print("| scene | resolution | spp Mitsuba / tracer | image mean R: tracer/Mitsuba − 1 ± SE | G | B "
          "| image-mean p (Šidák, 3) | χ²/m per pixel | χ² p | per-pixel Šidák p "
          "| exact pixels / differing | tracer time | |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(row)
    return 1 if failures else 0


def write_preview(folder: pathlib.Path, name: str, mean: np.ndarray, ref: Reference, c: Comparison) -> None:
    """tracer | Mitsuba | z map (red: tracer brighter, blue: darker; full at |z| = 4), as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    gamma = lambda x: np.clip(x, 0, 1) ** (1 / 2.2)  # noqa: E731
    axes[0].imshow(gamma(mean))
    axes[0].set_title("tracer")
    axes[1].imshow(gamma(ref.mean))
    axes[1].set_title(f"Mitsuba {ref.mitsuba_version}")
    zl = np.where(c.tested, c.z, 0).mean(axis=2)
    im = axes[2].imshow(zl, cmap="RdBu_r", vmin=-4, vmax=4)
    axes[2].set_title("z (mean over channels)")
    fig.colorbar(im, ax=axes[2])
    for ax in axes:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(folder / f"{name}_compare.png", dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenes", nargs="*", help=f"scene names (default: all of {SCENES})")
    p.add_argument("--compare", action="store_true",
                   help="render with tracer and compare with the stored references")
    p.add_argument("--spp", type=int, default=TRACER_SPP, help="tracer's spp (--compare)")
    p.add_argument("--seed", type=int, default=TRACER_SEED, help="tracer's seed (--compare)")
    p.add_argument("--preview", type=pathlib.Path, help="write PNG previews into this folder")
    args = p.parse_args(argv)
    names = args.scenes or scene_names()
    unknown = [n for n in names if n not in REFERENCES or not scene_path(n).is_file()]
    if unknown:
        p.error(f"unknown scenes {unknown} (known: {sorted(REFERENCES)})")
    missing = sorted(set(scene_names()) - set(REFERENCES))
    if missing:
        p.error(f"scenes without a REFERENCES entry: {missing}")
    if args.compare:
        return compare_table(names, args.spp, args.seed, args.preview)
    start = time.perf_counter()
    for name in names:
        render_reference(name, args.preview)
    print(f"total {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
