"""The figure of the environment's sampling (issue 33): a map, each technique's density over it,
and samples drawn by each.

    python benchmarks/environment_figure.py [--map tracer/scenes/mitsuba/textures/sky.exr]
                                            [--samples 2000] [-o renders/environment_sampling.png]

Row 1: the map (tone-mapped, latitude-longitude as stored: u across, t = theta / pi down). Rows
2-4: the solid-angle pdf of ``luminance``, ``compensated`` and ``uniform`` sampling
(``tracer.lights.environment``) on the map's cells (log scale, in 1 / sr), with ``--samples``
directions drawn by that technique, placed at their (u, t) in the map. Rows 5-6: ``product``
sampling (``tracer.lights.environment_product``), whose pdf depends on the receiver: for a
diffuse surface facing the horizon (its normal marked) and for a glossy one (a rough conductor's
lobe proxy, alpha 0.15; its mirror direction marked). Everything is computed by tracer's own
tables and sampler; nothing is drawn from formulas of this script.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=str(ROOT / "tracer/scenes/mitsuba/textures/sky.exr"))
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("-o", "--out", default=str(ROOT / "renders/environment_sampling.png"))
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tracer.atomic import save_figure
    from tracer.jit import jit
    from tracer.lights import environment as light
    from tracer.scene.environment import Environment
    from tracer.textures.bitmap import read_texels

    from tracer.lights import environment_product as product

    @jit
    def draw(table, u, material_lobe, normal, mirror):
        lobe = product.lobe_in_map(table.to_map, material_lobe, normal, mirror)
        out = np.empty((len(u), 3))
        for i in range(len(u)):
            if material_lobe[3] > 0.0:
                w, _, _ = light.sample_product(table, lobe, u[i, 0], u[i, 1])
            else:
                w, _, _ = light.sample(table, u[i, 0], u[i, 1])
            out[i, 0], out[i, 1], out[i, 2] = w
        return out

    @jit
    def cell_pdfs(table, material_lobe, normal, mirror):
        """Each cell's product pdf (constant on a cell), at its centre."""
        lobe = product.lobe_in_map(table.to_map, material_lobe, normal, mirror)
        rows, columns = table.cell_pdf.shape
        out = np.empty((rows, columns))
        for r in range(rows):
            for c in range(columns):
                out[r, c] = light.pdf_product(table, lobe, light.direction_in_cell(table, r, c, 0.5, 0.5))
        return out

    def map_coordinates(w):
        return np.mod(np.arctan2(w[..., 0], -w[..., 2]) / (2 * np.pi), 1.0), np.arccos(np.clip(w[..., 1], -1, 1)) / np.pi

    texels = read_texels(Path(args.map), False, args.map)
    environment = Environment(texels, np.eye(3), source=args.map)
    u = np.random.default_rng(7).random((args.samples, 2))
    # (title, sampling, material lobe (kd, ks, ku, alpha; alpha 0: not product), normal, mirror)
    facing = np.array([0.8, 0.35, 0.0]) / np.hypot(0.8, 0.35)
    mirror = np.array([-0.5, 0.6, -0.62]) / np.linalg.norm([-0.5, 0.6, -0.62])
    glossy_normal = (mirror + np.array([0.0, 0.0, 1.0])) / np.linalg.norm(mirror + np.array([0.0, 0.0, 1.0]))
    none = ((0.0, 0.0, 1.0), (0.0, 0.0, 1.0))
    rows = [("luminance", "luminance", (0.0, 0.0, 1.0, 0.0), *none),
            ("compensated", "compensated", (0.0, 0.0, 1.0, 0.0), *none),
            ("uniform", "uniform", (0.0, 0.0, 1.0, 0.0), *none),
            ("product, a diffuse receiver (normal: +)", "product", (0.8, 0.0, 0.0, 1.0), tuple(facing), tuple(facing)),
            ("product, a glossy receiver (alpha 0.15; mirror direction: +)", "product", (0.0, 0.9, 0.0, 0.15),
             tuple(glossy_normal), tuple(mirror))]
    fig, axes = plt.subplots(len(rows) + 1, 1, figsize=(8, 3.25 * (len(rows) + 1)))
    luminance = environment.texels.astype(np.float64) @ light.LUMINANCE
    image = axes[0].imshow(np.log10(np.maximum(luminance, 1e-6)), extent=(0, 1, 1, 0), aspect="auto",
                           interpolation="nearest", cmap="magma")
    fig.colorbar(image, ax=axes[0], label="log10 luminance")
    axes[0].set_title(f"{Path(args.map).name}: the map's luminance (u across, t = theta / pi down)")
    for ax, (title, sampling, material_lobe, normal, mirror_dir) in zip(axes[1:], rows, strict=True):
        table = light.table(environment, 0, sampling)
        cells = table.cell_pdf if sampling != "product" else cell_pdfs(table, material_lobe, normal, mirror_dir)
        pdf = np.where(cells > 0.0, cells, np.nan)
        width = table.cell_pdf.shape[1]
        # Cell columns start half a texel in (cell c spans u in [c + 1/2, c + 3/2] / W): roll so
        # that the image's columns line up with u, and repeat the first after the last (wrapping).
        shown = np.roll(np.log10(pdf), 1, axis=1)
        shown = np.concatenate([shown, shown[:, :1]], axis=1)
        image = ax.imshow(shown, extent=(-0.5 / width, 1 + 0.5 / width, 1, 0), aspect="auto",
                          interpolation="nearest", cmap="viridis")
        fig.colorbar(image, ax=ax, label="log10 pdf (1/sr)")
        wi = draw(table, u, material_lobe, normal, mirror_dir)
        su, st = map_coordinates(wi)
        ax.scatter(su, st, s=1.0, c="red", edgecolors="none", alpha=0.5)
        if sampling == "product":
            mark = mirror_dir if material_lobe[1] > 0.0 else normal
            mu, mt = map_coordinates(np.asarray(mark))
            ax.scatter([mu], [mt], s=80, marker="+", c="white", linewidths=1.5)
        never = int(np.isnan(pdf).sum())
        ax.set_title(f"{title}: pdf and {args.samples} samples"
                     + (f"; {never} / {pdf.size} cells (white) left to BSDF samples" if never else ""))
        ax.set_xlim(0, 1)
        ax.set_ylim(1, 0)
    for ax in axes:
        ax.set_xlabel("u")
        ax.set_ylabel("t")
    fig.tight_layout()
    save_figure(fig, Path(args.out), dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
