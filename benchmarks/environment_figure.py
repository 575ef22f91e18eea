"""The figure of the environment's sampling (issue 33): a map, each technique's density over it,
and samples drawn by each.

    python benchmarks/environment_figure.py [--map tracer/scenes/mitsuba/textures/sky.exr]
                                            [--samples 2000] [-o renders/environment_sampling.png]

Row 1: the map (tone-mapped, latitude-longitude as stored: u across, t = theta / pi down). Rows
2-4: the solid-angle pdf of ``luminance``, ``compensated`` and ``uniform`` sampling
(``tracer.lights.environment``) on the map's cells (log scale, in 1 / sr), with ``--samples``
directions drawn by that technique, placed at their (u, t) in the map. Everything is computed by
tracer's own tables and sampler; nothing is drawn from formulas of this script.
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

    @jit
    def draw(table, u):
        out = np.empty((len(u), 3))
        for i in range(len(u)):
            w, _, _ = light.sample(table, u[i, 0], u[i, 1])
            out[i, 0], out[i, 1], out[i, 2] = w
        return out

    texels = read_texels(Path(args.map), False, args.map)
    environment = Environment(texels, np.eye(3), source=args.map)
    u = np.random.default_rng(7).random((args.samples, 2))
    fig, axes = plt.subplots(4, 1, figsize=(8, 13))
    luminance = environment.texels.astype(np.float64) @ light.LUMINANCE
    image = axes[0].imshow(np.log10(np.maximum(luminance, 1e-6)), extent=(0, 1, 1, 0), aspect="auto",
                           interpolation="nearest", cmap="magma")
    fig.colorbar(image, ax=axes[0], label="log10 luminance")
    axes[0].set_title(f"{Path(args.map).name}: the map's luminance (u across, t = theta / pi down)")
    for ax, sampling in zip(axes[1:], ("luminance", "compensated", "uniform"), strict=True):
        table = light.table(environment, 0, sampling)
        pdf = np.where(table.cell_pdf > 0.0, table.cell_pdf, np.nan)
        width = table.cell_pdf.shape[1]
        # Cell columns start half a texel in (cell c spans u in [c + 1/2, c + 3/2] / W): roll so
        # that the image's columns line up with u, and repeat the first after the last (wrapping).
        shown = np.roll(np.log10(pdf), 1, axis=1)
        shown = np.concatenate([shown, shown[:, :1]], axis=1)
        image = ax.imshow(shown, extent=(-0.5 / width, 1 + 0.5 / width, 1, 0), aspect="auto",
                          interpolation="nearest", cmap="viridis")
        fig.colorbar(image, ax=ax, label="log10 pdf (1/sr)")
        wi = draw(table, u)
        su = np.mod(np.arctan2(wi[:, 0], -wi[:, 2]) / (2 * np.pi), 1.0)
        st = np.arccos(np.clip(wi[:, 1], -1, 1)) / np.pi
        ax.scatter(su, st, s=1.0, c="red", edgecolors="none", alpha=0.5)
        never = int(np.isnan(pdf).sum())
        ax.set_title(f"{sampling}: pdf and {args.samples} samples"
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
