"""Make the README's strips: one scene, every strategy (or every light-sampling technique) at
equal spp, labelled.

    python renders/strategy_strip.py [SCENE] [--spp 16] [-o renders/veach_mis_strategies.png]
    python renders/strategy_strip.py SCENE --light-sampling [--strategy light] [--spp 4] -o OUT.png

With ``--light-sampling`` the tiles are ``--strategy`` with each of area, solid-angle and
solid-angle-cos, each labelled with its relMSE against ``--reference`` when one is given.
(The full comparison with references and error maps is ``tracer compare``'s job.)
"""

from __future__ import annotations

import argparse

import numpy as np
import OpenImageIO as oiio

from tracer.imagefiles import read_exr, write_png
from tracer.render_loop import RenderSettings, render
from tracer.scene import default_scene_path, load_scene
from tracer.strategy import LIGHT_SAMPLINGS, STRATEGIES, Strategy
from tracer.study import metrics


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("scene", nargs="?", default=str(default_scene_path()))
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--light-sampling", action="store_true",
                        help="tiles: --strategy with each light-sampling technique")
    parser.add_argument("--strategy", default="light")
    parser.add_argument("--reference", help="reference EXR: label each tile with its relMSE")
    parser.add_argument("-o", "--output", default="renders/veach_mis_strategies.png")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    reference = read_exr(args.reference) if args.reference else None
    strategies = ([Strategy(args.strategy, light_sampling=s) for s in LIGHT_SAMPLINGS] if args.light_sampling
                  else [Strategy(name) for name in STRATEGIES])
    tiles = []
    for strategy in strategies:
        film = render(scene, strategy, RenderSettings(spp=args.spp, seed=1)).film
        label = strategy.light_sampling if args.light_sampling else strategy.name
        buf = oiio.ImageBuf(np.ascontiguousarray(film.image().astype(np.float32)))
        oiio.ImageBufAlgo.render_text(buf, 6, 18, f"{label} {args.spp} spp", 16, "", (1.0, 1.0, 0.3))
        if reference is not None:
            rel = metrics.relmse(film.mean, reference.mean, reference.variance_of_mean())
            oiio.ImageBufAlgo.render_text(buf, 6, 38, f"relMSE {rel:.3g}", 16, "", (1.0, 1.0, 0.3))
        tiles.append(buf.get_pixels(oiio.FLOAT))
    write_png(args.output, np.concatenate(tiles, axis=1))


if __name__ == "__main__":
    main()
