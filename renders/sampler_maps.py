"""Make the README's map of where Sobol points help: per pixel, the variance of the pixel value
with Sobol points over the variance with independent ones, for the shipped scenes.

    python renders/sampler_maps.py [--spp 256] [--block 4] [-o renders/sampler_variance_maps.png]

Both renders use ``mis`` at the same spp; the variances are each sampler's honest variance of
the pixel value (independent: the per-sample variance / spp; Sobol: from its 8 replicates,
``tracer.film``). A single pixel's replicate estimate has 7 degrees of freedom, so the maps
average the variances over ``--block`` x ``--block`` pixels before taking the ratio; a block
holds 16 x 7 degrees of freedom, enough for a ratio good to about 15%.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tracer.render_loop import RenderSettings, render
from tracer.scene import load_scene
from tracer.strategy import Strategy

SCENES = Path(__file__).resolve().parent.parent / "tracer" / "scenes"


def block_mean(values: np.ndarray, block: int) -> np.ndarray:
    """(H, W) -> (H / block, W / block): means of block x block tiles (edges cropped)."""
    h, w = (values.shape[0] // block) * block, (values.shape[1] // block) * block
    return values[:h, :w].reshape(h // block, block, w // block, block).mean(axis=(1, 3))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenes", default="cornell,veach_mis")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--block", type=int, default=4)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("-o", "--output", default="renders/sampler_variance_maps.png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = args.scenes.split(",")
    fig, axes = plt.subplots(1, 2 * len(names), figsize=(5.2 * len(names) * 2, 5.0), squeeze=False)
    for i, name in enumerate(names):
        scene = load_scene(SCENES / f"{name}.toml")
        films = {sampler: render(scene, Strategy("mis"), RenderSettings(spp=args.spp, seed=args.seed,
                                                                         sampler=sampler)).film
                 for sampler in ("independent", "sobol")}
        shape = (scene.camera.height, scene.camera.width)
        variance = {s: block_mean(f.variance_of_mean().mean(axis=1).reshape(shape), args.block)
                    for s, f in films.items()}
        # Blocks without variance under either sampler (unlit, or only emitters) are grey.
        unlit = (variance["independent"] <= 0) | (variance["sobol"] <= 0)
        ratio = np.ma.masked_array(np.log2(np.maximum(variance["sobol"], 1e-300)
                                           / np.maximum(variance["independent"], 1e-300)), mask=unlit)
        image = np.clip(films["independent"].image(), 0, None)
        ax_img, ax_map = axes[0, 2 * i], axes[0, 2 * i + 1]
        ax_img.imshow(np.clip(image / max(np.percentile(image, 99), 1e-9), 0, 1) ** (1 / 2.2))
        ax_img.set_title(f"{name}: mis, {args.spp} spp")
        total = variance["sobol"].sum() / max(variance["independent"].sum(), 1e-300)
        cmap = plt.get_cmap("RdBu_r").copy()
        cmap.set_bad("0.6")
        im = ax_map.imshow(ratio, cmap=cmap, vmin=-5, vmax=5)
        ax_map.set_title(f"variance sobol / independent (image: {total:.2f}x)")
        fig.colorbar(im, ax=ax_map, fraction=0.046, pad=0.04,
                     label=f"log2 ratio ({args.block}x{args.block} blocks; grey: no variance)")
        for ax in (ax_img, ax_map):
            ax.set_xticks([])
            ax.set_yticks([])
        print(f"{name}: variance of the image, sobol / independent = {total:.3f}; share of lit blocks "
              f"where sobol is lower: {(ratio < 0).sum() / max(ratio.count(), 1):.2f}")
    fig.tight_layout()
    fig.savefig(args.output, dpi=110)
    print(f"-> {args.output}")


if __name__ == "__main__":
    main()
