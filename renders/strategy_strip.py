"""Make the README's strategy strip: one scene, every strategy at equal spp, labelled.

    python renders/strategy_strip.py [SCENE] [--spp 16] [-o renders/veach_mis_strategies.png]

(The full comparison with references and error maps is ``tracer compare``'s job.)
"""

from __future__ import annotations

import argparse

import numpy as np
import OpenImageIO as oiio

from tracer.imagefiles import write_png
from tracer.render_loop import RenderSettings, render
from tracer.scene import default_scene_path, load_scene
from tracer.strategy import STRATEGIES, Strategy


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("scene", nargs="?", default=str(default_scene_path()))
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("-o", "--output", default="renders/veach_mis_strategies.png")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    tiles = []
    for name in STRATEGIES:
        image = render(scene, Strategy(name), RenderSettings(spp=args.spp, seed=1)).film.image()
        buf = oiio.ImageBuf(np.ascontiguousarray(image.astype(np.float32)))
        oiio.ImageBufAlgo.render_text(buf, 6, 18, f"{name} {args.spp} spp", 16, "", (1.0, 1.0, 0.3))
        tiles.append(buf.get_pixels(oiio.FLOAT))
    write_png(args.output, np.concatenate(tiles, axis=1))


if __name__ == "__main__":
    main()
