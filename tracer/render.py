"""The wavefront render loop: batches of (pixel, sample) lanes, threads, progress, Ctrl-C.

A render is cut into batches fixed by the resolution, the spp, the batch size and the
strategy's sample counts (not by the threads): ``k`` samples for each of a run of consecutive
pixels, ``batch_lanes`` lanes at most. Each batch draws its random
numbers from keys that its own generator gives, keyed by (seed, first sample index, first
pixel); see ``tracer.rand``. Batches
are merged into the film in a fixed order. So the same seed gives the same image bit for bit
whatever the number of threads (``DESIGN.md``). Threads overlap the batches: Embree and the
compiled kernels release the GIL.
"""

from __future__ import annotations

import os
import sys
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import rand
from .estimators import DirectLighting, Strategy
from .film import Film
from .jit import jit
from .scene import Scene

DEFAULT_BATCH_LANES = 1 << 15
SAMPLES_PER_PASS = 8


@dataclass(frozen=True)
class Batch:
    """k samples (indices first_sample, ...) for each of npix pixels (first_pixel, ...)."""

    first_sample: int
    k: int
    first_pixel: int
    npix: int

    @property
    def lanes(self) -> int:
        return self.k * self.npix


@dataclass
class RenderSettings:
    """spp to add, seed, threads; ``first_sample`` offsets sample indices so that a resumed
    render draws fresh random numbers; ``batch_lanes`` bounds the lanes of one batch."""

    spp: int = 64
    seed: int = 0
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    first_sample: int = 0
    batch_lanes: int = DEFAULT_BATCH_LANES


@dataclass
class RenderResult:
    """What a render produced: the film, wall time, and how it ended.

    nonfinite counts samples that came out NaN or infinite (they were set to 0);
    interrupted is true when Ctrl-C stopped the render early (the film keeps every finished
    batch, with its true per-pixel counts).
    """

    film: Film
    seconds: float
    samples: int
    nonfinite: int
    interrupted: bool


def render_attributes(scene: Scene, strategy: Strategy, settings: RenderSettings,
                      result: RenderResult) -> dict[str, object]:
    """EXR header attributes of a render (``DESIGN.md``); ``tracer:spp`` is the film's own.

    ``first_sample``/``next_sample`` bound the sample indices drawn with ``seed``, so that
    a resumed render or a merge can make sure no random numbers are used twice.
    """
    from . import __version__

    return {
        "tracer:strategy": strategy.name,
        "tracer:heuristic": strategy.heuristic if strategy.name == "mis" else "none",
        "tracer:light_samples": int(strategy.light_count),
        "tracer:bsdf_samples": int(strategy.direction_count),
        "tracer:one_sample": int(strategy.one_sample),
        "tracer:light_selection": strategy.light_selection,
        "tracer:seed": int(settings.seed),
        "tracer:first_sample": int(settings.first_sample),
        "tracer:next_sample": int(settings.first_sample + settings.spp),
        "tracer:seconds": float(result.seconds),
        "tracer:scene": str(scene.path),
        "tracer:version": __version__,
    }


def plan_batches(width: int, height: int, spp: int, first_sample: int = 0,
                 batch_lanes: int = DEFAULT_BATCH_LANES) -> list[Batch]:
    """Cut ``width * height`` pixels x ``spp`` samples into batches, pass by pass.

    A pass gives every pixel k more samples. k is at least ``SAMPLES_PER_PASS`` (or spp, if
    fewer), so that the film folds k samples at once per pixel instead of streaming the whole
    film through memory for every sample, and larger for small images so that a batch still
    has enough lanes to amortize the per-call cost of Embree.
    """
    pixels = width * height
    k = max(1, min(spp, batch_lanes, max(SAMPLES_PER_PASS, batch_lanes // max(pixels, 1))))
    chunk = max(1, min(pixels, batch_lanes // k))
    batches = []
    for s0 in range(0, spp, k):
        k_pass = min(k, spp - s0)
        for p0 in range(0, pixels, chunk):
            batches.append(Batch(first_sample + s0, k_pass, p0, min(chunk, pixels - p0)))
    return batches


def render_batch(estimator: DirectLighting, batch: Batch, seed: int) -> tuple[np.ndarray, int]:
    """Render one batch: returns samples ``(npix, k, 3)`` and the count of non-finite ones."""
    rng = np.random.Generator(np.random.Philox(np.random.SeedSequence(
        [seed, batch.first_sample, batch.first_pixel])))
    camera = estimator.scene.camera
    origins, dirs = camera.batch_rays(rand.batch_key(rng), batch.first_pixel, batch.npix, batch.k)
    radiance = estimator.radiance(origins, dirs, rng)
    nonfinite = _zero_nonfinite(radiance)
    return radiance.reshape(batch.npix, batch.k, 3), nonfinite


def _compile(estimator: DirectLighting, film: Film) -> None:
    """Run a batch's kernels once on zero lanes before the clock starts, so that numba compiles
    them (or loads them from its cache) then: the first render after an install would otherwise
    count seconds of compilation as rendering, unfair in an equal-time comparison."""
    origins, dirs = estimator.scene.camera.batch_rays(np.uint64(0), 0, 0, 1)
    radiance = estimator.radiance(origins, dirs, np.random.default_rng(0))
    _zero_nonfinite(radiance)
    film.add_block(0, radiance.reshape(0, 1, 3))


@jit
def _zero_nonfinite(radiance: np.ndarray) -> int:
    """Set the rows of ``radiance (n, 3)`` that hold a NaN or an infinity to 0; returns how many."""
    count = 0
    for i in range(len(radiance)):
        if not (np.isfinite(radiance[i, 0]) and np.isfinite(radiance[i, 1]) and np.isfinite(radiance[i, 2])):
            radiance[i, 0] = radiance[i, 1] = radiance[i, 2] = 0.0
            count += 1
    return count


def render(scene: Scene, strategy: Strategy, settings: RenderSettings, film: Film | None = None,
           progress: bool = False, estimator: DirectLighting | None = None) -> RenderResult:
    """Render ``settings.spp`` samples per pixel into ``film`` (a new one if None).

    Ctrl-C stops the render: batches already running finish and are kept, the rest are
    dropped, and the result says ``interrupted``.
    """
    cam = scene.camera
    film = film if film is not None else Film(cam.width, cam.height)
    estimator = estimator if estimator is not None else DirectLighting(scene, strategy)
    # A batch casts at most 2 x batch_lanes rays from its shading points (or one lane's, if
    # that is more), so that --light-samples 10000 shrinks the batches instead of exhausting
    # memory.
    runs = estimator.strategy  # the strategy the estimator was built for is the one that runs
    per_lane = 1 if runs.one_sample_mis else runs.light_count + runs.direction_count
    lanes = max(1, settings.batch_lanes * 2 // max(2, per_lane))
    batches = plan_batches(cam.width, cam.height, settings.spp, settings.first_sample, lanes)
    bar = _progress_bar(cam.width * cam.height * settings.spp, progress)
    nonfinite = 0
    samples = 0
    interrupted = False
    start = time.perf_counter()
    _compile(estimator, film)
    if progress and time.perf_counter() - start > 1.0:
        print(f"tracer: compiled the shading kernels in {time.perf_counter() - start:.1f} s "
              "(once after an install or an edit; later runs load them from the cache)", file=sys.stderr)
    start = time.perf_counter()

    def merge(batch: Batch, result: tuple[np.ndarray, int]) -> None:
        nonlocal nonfinite, samples
        block, bad = result
        film.add_block(batch.first_pixel, block)
        nonfinite += bad
        samples += batch.lanes
        if bar is not None:
            bar.update(batch.lanes)

    threads = max(1, settings.threads)
    try:
        if threads == 1:
            for batch in batches:
                merge(batch, render_batch(estimator, batch, settings.seed))
        else:
            with ThreadPoolExecutor(max_workers=threads) as pool:
                interrupted = _run_pipelined(pool, threads, batches, estimator, settings.seed, merge)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    return RenderResult(film, time.perf_counter() - start, samples, nonfinite, interrupted)


def _run_pipelined(pool: ThreadPoolExecutor, threads: int, batches: list[Batch],
                   estimator: DirectLighting, seed: int, merge) -> bool:
    """Keep 2 x threads batches in flight and merge them in submission order.

    Returns True if Ctrl-C stopped it; then the batches already started are awaited and kept.
    """
    in_flight: deque[tuple[Batch, Future]] = deque()
    todo = iter(batches)
    try:
        for batch in todo:
            in_flight.append((batch, pool.submit(render_batch, estimator, batch, seed)))
            if len(in_flight) >= 2 * threads:
                done_batch, future = in_flight.popleft()
                merge(done_batch, future.result())
        while in_flight:
            done_batch, future = in_flight.popleft()
            merge(done_batch, future.result())
        return False
    except KeyboardInterrupt:
        for batch, future in in_flight:
            if not future.cancel():
                merge(batch, future.result())
        return True


def _progress_bar(total: int, enabled: bool):
    """A tqdm bar on stderr, or None when disabled or stderr is not a terminal."""
    if not enabled or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="sample", unit_scale=True, file=sys.stderr, leave=False,
                dynamic_ncols=True, smoothing=0.1)
