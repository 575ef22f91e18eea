"""Command line: argument parsing and calls into the library, no math.

Exit status: 0 done, 1 a check failed, 2 bad input (one line on stderr, no traceback),
130 interrupted by Ctrl-C (after writing what was rendered).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from . import __version__
from .errors import InputError

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def _int_at_least(lo: int):
    """An argparse type: a whole number >= lo, with a message that says what was wrong."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"expected a number >= {lo}, got {value}")
        return value

    return parse


_positive_int = _int_at_least(1)
_count = _int_at_least(0)


def build_parser() -> argparse.ArgumentParser:
    from .lights import SELECTIONS
    from .mis import HEURISTICS
    from .scene import STRATEGIES

    parser = argparse.ArgumentParser(
        prog="tracer", description="Direct-lighting path tracer for comparing sampling strategies.")
    parser.add_argument("--version", action="version", version=f"tracer {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    r = sub.add_parser("render", help="render a scene file to EXR (with variance) and PNG",
                       description="Render a scene to an EXR with per-pixel variance and a PNG preview.")
    r.add_argument("scene", nargs="?", help="scene file (default: the veach_mis scene shipped with tracer)")
    r.add_argument("-o", "--output", help="output EXR path (default: SCENE_STRATEGY.exr here); "
                   "the PNG preview goes beside it")
    r.add_argument("--spp", type=_positive_int, help="samples per pixel (default: the scene's, else 64)")
    r.add_argument("--strategy", choices=STRATEGIES,
                   help="sampling strategy (default: the scene's, else mis)")
    r.add_argument("--heuristic", choices=HEURISTICS, default="power", help="MIS heuristic (default power)")
    r.add_argument("--light-samples", type=_count, default=1, metavar="N",
                   help="light samples per camera sample (light, mis; default 1)")
    r.add_argument("--bsdf-samples", type=_count, default=1, metavar="M",
                   help="direction samples per camera sample (uniform, cosine, bsdf, mis; default 1)")
    r.add_argument("--one-sample", action="store_true",
                   help="one-sample MIS: each camera sample picks light or BSDF with probability N:M")
    r.add_argument("--light-selection", choices=SELECTIONS, default="power",
                   help="how to pick the light to sample (default: in proportion to power)")
    r.add_argument("--seed", type=_count, default=0, help="random seed (default 0)")
    r.add_argument("--threads", type=_positive_int, default=os.cpu_count() or 1,
                   help="worker threads (default: all cores); the image does not depend on it")
    r.add_argument("--width", type=_positive_int, help="override the camera's width in pixels")
    r.add_argument("--height", type=_positive_int, help="override the camera's height in pixels")
    r.add_argument("--exposure", type=float, default=0.0, help="PNG preview exposure in stops (default 0)")
    r.add_argument("--quiet", action="store_true", help="no progress bar and no summary line")
    r.set_defaults(run=cmd_render)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _terminate_like_ctrl_c()
    try:
        return args.run(args)
    except InputError as exc:
        print(f"tracer: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("tracer: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _terminate_like_ctrl_c() -> None:
    """SIGTERM (kill, a batch scheduler's time limit) stops a render as Ctrl-C does: what was
    rendered is written. Only possible from the main thread."""
    import signal
    import threading

    def handler(signum, frame):
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, handler)


def cmd_render(args: argparse.Namespace) -> int:
    from . import scene as scene_mod
    from .estimators import Strategy
    from .render import RenderSettings, render

    scene_path = Path(args.scene) if args.scene else scene_mod.default_scene_path()
    scene = scene_mod.load_scene(scene_path, args.width, args.height)
    defaults = scene.render_defaults
    strategy_name = args.strategy or defaults.get("strategy", "mis")
    spp = args.spp or defaults.get("spp", 64)
    try:
        strategy = Strategy(strategy_name, args.heuristic, args.light_samples, args.bsdf_samples,
                            args.one_sample, args.light_selection)
    except ValueError as exc:
        raise InputError(str(exc), "command line") from None
    output = Path(args.output) if args.output else Path(f"{scene.name}_{strategy_name}.exr")
    if output.suffix.lower() != ".exr":
        raise InputError("output must end in .exr", str(output))
    if not output.parent.is_dir() and str(output.parent):
        raise InputError("output folder does not exist", str(output.parent))

    result = render(scene, strategy, RenderSettings(spp=spp, seed=args.seed, threads=args.threads),
                    progress=not args.quiet)
    film = result.film
    film.attributes.update(render_attributes(scene, strategy, args.seed, result.seconds))
    png = output.with_suffix(".png")
    film.write_exr(output)
    film.write_png(png, args.exposure)

    if result.nonfinite:
        print(f"tracer: warning: {result.nonfinite} samples were NaN or infinite and were set to 0",
              file=sys.stderr)
    if not args.quiet or result.interrupted:
        rate = result.samples / max(result.seconds, 1e-9)
        note = f" (interrupted at {film.spp} spp of {spp})" if result.interrupted else ""
        print(f"{scene.name}: {film.width}x{film.height}, {film.spp} spp, {describe(strategy)}{note}: "
              f"{result.seconds:.2f} s, {rate / 1e6:.2f} M samples/s -> {output}, {png}",
              file=sys.stderr)
    return EXIT_INTERRUPTED if result.interrupted else 0


def describe(strategy) -> str:
    """A short label such as ``mis (power, 1 light + 1 bsdf)``."""
    if strategy.name == "mis":
        mode = "one-sample, " if strategy.one_sample else ""
        return (f"mis ({mode}{strategy.heuristic}, {strategy.light_samples} light + "
                f"{strategy.bsdf_samples} bsdf)")
    count = strategy.light_count or strategy.direction_count
    return strategy.name if count == 1 else f"{strategy.name} (x{count})"


def render_attributes(scene, strategy, seed: int, seconds: float) -> dict[str, object]:
    """EXR header attributes of a render (``DESIGN.md``); tracer:spp is added by the film."""
    return {
        "tracer:strategy": strategy.name,
        "tracer:heuristic": strategy.heuristic if strategy.name == "mis" else "none",
        "tracer:light_samples": int(strategy.light_count),
        "tracer:bsdf_samples": int(strategy.direction_count),
        "tracer:one_sample": int(strategy.one_sample),
        "tracer:light_selection": strategy.light_selection,
        "tracer:seed": int(seed),
        "tracer:seconds": float(seconds),
        "tracer:scene": str(scene.path),
        "tracer:version": __version__,
    }
