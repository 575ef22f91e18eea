"""A/B timing of two versions of tracer on this machine: is a change slower?

    python benchmarks/ab.py --base REV [--pairs 6] [--scene veach_mis] [--size 512] [--spp 64]
                            [--strategy mis] [--threads 2]

Checks out REV into a temporary git worktree and times one render of the same scene, size,
spp and strategy with REV's sources and with the working tree's, alternating the two in fresh
processes (B, A, B, A, ...), each process rendering twice after a 1-spp warm-up. On a shared
machine whose speed drifts by several percent within minutes (these 2-core machines do), only
interleaved runs compare fairly: a drift then hits both sides alike. Prints every time, the
medians and their ratio (working tree / REV). Timing lives here, never in the tests.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# Runs in the child, against whichever tracer PYTHONPATH puts first. It imports only names that
# both old and new trees have (the estimator module re-exports Strategy), or tries both names.
CHILD = """
import sys, time
try:
    from tracer.estimator import DirectLighting, Strategy  # the package of the feature-set kernels
except ImportError:
    from tracer.estimators import DirectLighting, Strategy
from tracer.scene import load_scene
# tracer.render first: an editable install would serve the working tree's render_loop to an
# older tree that lacks it.
try:
    from tracer.render import RenderSettings, render  # the module's name before the open core
except ImportError:
    from tracer.render_loop import RenderSettings, render
import tracer
assert tracer.__file__.startswith(sys.argv[6]), (tracer.__file__, sys.argv[6])
scene_path, strategy = sys.argv[1], sys.argv[4]
size, spp, threads = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[5])
scene = load_scene(scene_path, size, size)
est = DirectLighting(scene, Strategy(strategy))
render(scene, est.strategy, RenderSettings(spp=1, seed=0, threads=threads), estimator=est)
for _ in range(2):
    start = time.perf_counter()
    render(scene, est.strategy, RenderSettings(spp=spp, seed=0, threads=threads), estimator=est)
    print(time.perf_counter() - start)
"""


def times(tree: Path, args: argparse.Namespace) -> list[float]:
    """Two render times with the sources of ``tree`` (a checkout's root)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    scene = str(ROOT / "scenes" / f"{args.scene}.toml")
    out = subprocess.run([sys.executable, "-c", CHILD, scene, str(args.size), str(args.spp), args.strategy,
                          str(args.threads), str(tree.resolve())], cwd=tree, env=env, capture_output=True,
                         text=True, check=True)
    return [float(line) for line in out.stdout.split()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the git revision to compare against (A)")
    parser.add_argument("--pairs", type=int, default=6, help="alternations of A and B (default 6)")
    parser.add_argument("--scene", default="veach_mis")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--strategy", default="mis")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="tracer-ab-") as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(base), args.base], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            runs: dict[str, list[float]] = {"A": [], "B": []}
            for pair in range(args.pairs):
                for side, tree in (("B", ROOT), ("A", base)) if pair % 2 else (("A", base), ("B", ROOT)):
                    runs[side] += times(tree, args)
                    print(f"{side} ({'base ' + args.base if side == 'A' else 'working tree'}): "
                          f"{' '.join(f'{t:.3f}' for t in runs[side][-2:])} s", flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, check=False)
    a, b = statistics.median(runs["A"]), statistics.median(runs["B"])
    print(f"\n{args.scene} {args.size}x{args.size}, {args.spp} spp, {args.strategy}, {args.threads} threads, "
          f"{len(runs['A'])} renders each")
    print(f"median A (base {args.base}) {a:.3f} s, B (working tree) {b:.3f} s, B / A = {b / a:.4f}")


if __name__ == "__main__":
    main()
