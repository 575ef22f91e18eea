"""The wavefront render loop: batches of (pixel, sample) lanes, threads, progress, Ctrl-C.

A render is cut into passes, each giving every pixel ``k`` more samples, and each pass into
batches of consecutive pixels. ``k`` depends only on the spp and the strategy's rays per
sample, never on the batch size or the threads, and every random number is a function of
(seed, pixel, sample index, dimension) (``tracer.samplers``); batches are merged into the film
in a fixed order. So the same seed gives the same image bit for bit whatever the batch size
and the number of threads. Threads overlap the batches: Embree and the compiled kernels
release the GIL.

Estimators that learn between passes (optimal MIS, adaptive allocation: ``tracer.tuning``)
learn again after passes 1, 2, 4, 8, ... (``relearns``): what they learn is an estimate whose
error falls as one over the square root of the samples behind it, so it has changed markedly
when those have doubled, and the threads wait only then. Before such a pass starts, every batch
of the passes before it is merged, so the image still depends only on the seed and the
settings.
"""

from __future__ import annotations

import os
import sys
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from . import auto, interrupts, merge_tree, samplers, tuning
from .errors import InputError
from .estimator import DirectLighting
from .film import Film
from .imagefiles import MAX_SPLIT_COUNT
from .jit import jit
from .record import RenderRecord, SampleRange, check_mergeable, merged
from .sampler_choice import MAX_REPLICATE_COUNT
from .scene import Scene
from .strategy import Strategy

DEFAULT_BATCH_LANES = 1 << 15
SAMPLES_PER_PASS = 8
# A pass folds fewer samples per pixel when one sample casts many rays, so that one pixel's
# pass never needs more shading rays than this (``--light-samples 10000``).
MAX_PASS_RAYS = 2 * DEFAULT_BATCH_LANES
MAX_SAMPLE_INDEX = 2**53  # sample counts and indices stay exact in float64 (means, EXR counts)


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
    render draws fresh random numbers; ``batch_lanes`` bounds the lanes of one batch (memory
    only: the image does not depend on it); ``sampler`` names the random-number sampler."""

    spp: int = 64
    seed: int = 0
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    first_sample: int = 0
    batch_lanes: int = DEFAULT_BATCH_LANES
    sampler: str = "independent"


@dataclass
class RenderResult:
    """What a render produced: the film, wall time, and how it ended.

    nonfinite counts samples that came out NaN or infinite (they were set to 0);
    interrupted is true when Ctrl-C stopped the render early (the film keeps every finished
    batch, with its true per-pixel counts); learner holds what an estimator that learns
    (``tracer.tuning``) has learned, for a render that continues this one (else None); drawn
    lists the sample ranges this render added to the film (``tracer.record``: the film's record
    also lists what a film passed in held), which an interrupted render says it kept.
    """

    film: Film
    seconds: float
    samples: int
    nonfinite: int
    interrupted: bool
    learner: tuning.Learner | None = None
    drawn: tuple[SampleRange, ...] = ()


def pass_samples(spp: int, pixels: int, rays_per_sample: int) -> int:
    """Samples per pixel in a pass: at least ``SAMPLES_PER_PASS`` (or spp, if fewer), so that
    the film folds k samples at once per pixel instead of streaming the whole film through
    memory for every sample, and more for small images, so that a pass still has enough lanes
    to amortize the per-call cost of Embree; fewer when a sample casts so many rays that one
    pixel's pass would exceed ``MAX_PASS_RAYS``. It depends on the image and the strategy, never
    on the batch size or the threads."""
    wanted = max(SAMPLES_PER_PASS, DEFAULT_BATCH_LANES // max(pixels, 1))
    return max(1, min(spp, wanted, MAX_PASS_RAYS // max(1, rays_per_sample)))


def plan_batches(width: int, height: int, spp: int, first_sample: int = 0,
                 batch_lanes: int = DEFAULT_BATCH_LANES, k: int = SAMPLES_PER_PASS) -> Iterator[Batch]:
    """Cut ``width * height`` pixels x ``spp`` samples into batches, pass by pass: each pass
    gives every pixel ``k`` samples (the last one what remains), and each batch holds the
    pass's samples of at most ``max(1, batch_lanes // k)`` consecutive pixels. Lazily: memory
    does not grow with spp."""
    pixels = width * height
    k = max(1, min(k, spp))
    chunk = max(1, min(pixels, batch_lanes // k))
    for s0 in range(0, spp, k):
        k_pass = min(k, spp - s0)
        for p0 in range(0, pixels, chunk):
            yield Batch(first_sample + s0, k_pass, p0, min(chunk, pixels - p0))


def lanes_of(batch: Batch) -> tuple[np.ndarray, np.ndarray]:
    """``(pixel, sample)`` (each ``(lanes,)`` int64) of a batch's lanes, pixel by pixel: lane
    i is sample ``first_sample + i % k`` of pixel ``first_pixel + i // k``."""
    pixel = np.repeat(np.arange(batch.first_pixel, batch.first_pixel + batch.npix, dtype=np.int64), batch.k)
    sample = np.tile(np.arange(batch.first_sample, batch.first_sample + batch.k, dtype=np.int64), batch.npix)
    return pixel, sample


def render_batch(estimator: DirectLighting, batch: Batch, sampler: samplers.SamplerParams,
                 tuned: tuning.Tuning | None = None) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Render one batch with what the pass applies (``tuned``; None: nothing learned):
    returns samples ``(npix, k, 3)``, the count of non-finite ones, and for an estimator that
    learns the batch's per-pixel sums if the tuning collects them (``tracer.tuning.reduce_lanes``;
    else None)."""
    pixel, sample = lanes_of(batch)
    origins, dirs = estimator.camera_rays(sampler, pixel, sample)
    radiance, lane_stats = estimator.shade_lanes(origins, dirs, sampler, pixel, sample, tuned)
    sums = None
    if estimator.learns:
        tuned = tuned if tuned is not None else tuning.no_tuning()
        if tuned.collect:
            sums = tuning.reduce_lanes(radiance, lane_stats, batch.npix, batch.k, batch.first_sample,
                                       tuned.replicates, tuned.groups)
        if len(tuned.alpha):
            tuning.apply_control(radiance, lane_stats, tuned.alpha, batch.first_pixel, batch.k,
                                 batch.first_sample, tuned.replicates, tuned.groups)
    nonfinite = _zero_nonfinite(radiance)
    return radiance.reshape(batch.npix, batch.k, 3), nonfinite, sums


def _compile(estimator: DirectLighting, film: Film, sampler: samplers.SamplerParams,
             progress: bool = False) -> None:
    """Compile the render's kernels (or load them from the cache) before the clock starts, with
    a progress line while they compile (``DirectLighting.compile``), then run a batch once on
    zero lanes for whatever else it calls: the first render after an install would otherwise
    count seconds of compilation as rendering, unfair in an equal-time comparison."""
    estimator.compile(sampler, progress)
    sums = render_batch(estimator, Batch(0, 1, 0, 0), sampler, tuning.no_tuning())[2]
    film.add_block(0, np.zeros((0, 1, 3)))
    if sums is not None:  # the learning's own kernels
        tuning.warm_up()


@jit
def _zero_nonfinite(radiance: np.ndarray) -> int:
    """Set the rows of ``radiance (n, 3)`` that hold a NaN or an infinity to 0; returns how many."""
    count = 0
    for i in range(len(radiance)):
        if not (np.isfinite(radiance[i, 0]) and np.isfinite(radiance[i, 1]) and np.isfinite(radiance[i, 2])):
            radiance[i, 0] = radiance[i, 1] = radiance[i, 2] = 0.0
            count += 1
    return count


def film_to_fill(scene: Scene, strategy: Strategy, settings: RenderSettings,
                 film: Film | None) -> tuple[Film, RenderRecord | None]:
    """Check a render's settings, and that ``film`` (a new one if None) may take its samples:
    raises ``InputError`` otherwise. Returns the film and the record of what it already held
    (None if nothing)."""
    last = settings.first_sample + settings.spp
    if settings.sampler not in samplers.SAMPLERS:
        raise InputError(f"unknown sampler {settings.sampler!r}; expected one of "
                         f"{', '.join(samplers.SAMPLERS)}")
    if settings.spp < 1 or settings.first_sample < 0 or last > MAX_SAMPLE_INDEX:
        raise InputError(f"spp {settings.spp} from sample index {settings.first_sample}: sample indices must "
                         f"lie in 0 .. {MAX_SAMPLE_INDEX} (2^53, where counts stay exact in float64)")
    if last > samplers.max_samples(settings.sampler):
        raise InputError(f"spp {settings.spp} from sample index {settings.first_sample}: the "
                         f"{settings.sampler} sampler draws at most {samplers.max_samples(settings.sampler)} "
                         "samples per pixel")
    cam = scene.camera
    replicates = samplers.replicates_of(settings.sampler)
    film = film if film is not None else Film(cam.width, cam.height, replicates=replicates)
    earlier = film.record if bool(film.count.any()) else None
    if earlier is not None:
        _check_continues(earlier, scene, strategy, settings)
    if film.replicates != replicates:
        raise InputError(f"cannot add {settings.sampler} samples to a film of {film.replicates} replicates "
                         f"(the {settings.sampler} sampler keeps {replicates})")
    if not film.uniform and int(film.count.max()) + settings.spp >= MAX_SPLIT_COUNT:
        # Checked now rather than when the file is written, after all the work.
        raise InputError(f"{settings.spp} spp more would put {int(film.count.max()) + settings.spp} samples "
                         f"in a pixel of a film whose pixels hold unequal counts, which its render file "
                         f"stores exactly only below {MAX_SPLIT_COUNT} (2^48)")
    held = int(film.rep_count.max()) if replicates and film.rep_count.size else 0
    if replicates and held + -(-settings.spp // replicates) > MAX_REPLICATE_COUNT:
        # Checked now rather than when the file is written, after all the work.
        raise InputError(f"{settings.spp} spp more would put over {MAX_REPLICATE_COUNT} samples in a "
                         f"replicate of the {settings.sampler} sampler, more than its render file counts "
                         "exactly")
    return film, earlier


def render(scene: Scene, strategy: Strategy, settings: RenderSettings, film: Film | None = None,
           progress: bool = False, estimator: DirectLighting | None = None,
           learner: tuning.Learner | None = None, part: merge_tree.Task | None = None,
           continued: Film | None = None) -> RenderResult:
    """Render ``settings.spp`` samples per pixel into ``film`` (a new one if None).

    The film's record (``tracer.record``) is set to describe all it holds: the strategy and
    sampler, the scene's digest, the sample ranges a film passed in held plus the one drawn now,
    and the seconds of both. A film that already holds samples must have been made by the same
    estimator and sampler on the same scene, and must not hold any of the samples to be drawn
    (``InputError`` otherwise: its record could not say what the film holds). Ctrl-C stops the
    render, also during the first compilation: batches already running
    finish and are kept, the rest are dropped, and the result says ``interrupted``.

    An estimator that learns between passes starts from ``learner`` (the ``learner`` of the
    result of a render this one continues, as ``compare`` continues renders to fill a time
    budget), else from nothing, with a pilot pass.

    The new samples are pooled along the render's merge tree (``tracer.merge_tree``) and the
    pool is then merged into ``film``. ``part``, a node of that tree, renders only its leaves
    (a task of a distributed render, ``tracer.cluster``): with the same random numbers and the
    same bits as the whole render has there. A part that is a segment of a leaf
    (``merge_tree.Segment``) after its first pass continues ``continued``, the film of the
    leaf's passes before it (not changed: a copy is continued), and the film returned holds the
    leaf's passes up to the segment's end. Estimators that learn cannot render a part: what they
    apply depends on every earlier sample.

    Ctrl-C is never lost to a finalizer that drops its ``KeyboardInterrupt``: the loop calls
    ``interrupts.check`` between batches (``tracer.interrupts``).
    """
    cam = scene.camera
    choice, pilot_seconds = None, 0.0
    if estimator is None and strategy.name == "auto":
        strategy, estimator, choice, pilot_seconds = _resolve_auto(scene, strategy, settings, film, progress)
    runs = estimator.strategy if estimator is not None else strategy
    fresh = film is None  # then the pool of the new samples becomes the film
    film, earlier = film_to_fill(scene, runs, settings, film)
    replicates = film.replicates
    sampler = samplers.make(settings.sampler, settings.seed, settings.first_sample, settings.spp)
    bar = None
    nonfinite = 0
    samples = 0
    interrupted = False
    start = time.perf_counter()
    seconds = 0.0

    continues = learner is not None
    hook: tuning.PassHook | None = None  # set once the estimator is known to learn
    tree = tree_layout(scene, runs, settings)
    k = tree.k
    first, stop = tree.samples(part) if part is not None else (0, settings.spp)
    if part is not None:
        if runs.learns:
            raise InputError(f"cannot render a part of a render with {runs.label}, which learns from "
                             "every earlier sample")
        _check_part(tree, settings, part, continued, fresh)
    leaf = LeafFilm(tree, cam.width, cam.height, replicates, merge_tree.Pool(tree.leaves, pooled_into))
    if continued is not None:
        leaf.continue_leaf(part.leaf, continued)
        earlier = continued.record

    def merge(batch: Batch, result: tuple[np.ndarray, int, np.ndarray | None]) -> None:
        nonlocal nonfinite, samples
        block, bad, sums = result
        leaf.add_block(batch, block, settings.first_sample)
        if sums is not None:
            hook.add(batch, sums)
        nonfinite += bad
        samples += batch.lanes
        if bar is not None:
            bar.update(batch.lanes)

    try:
        estimator = estimator if estimator is not None else DirectLighting(scene, strategy)
        # The strategy the estimator was built for is the one that runs. A batch casts at most
        # 2 x batch_lanes rays from its shading points (or one pixel's pass, if that is more),
        # so that --light-samples 10000 shrinks the batches instead of exhausting memory.
        lanes = max(1, settings.batch_lanes * 2 // max(2, runs.samples_per_lane))
        batches = plan_batches(cam.width, cam.height, stop - first, settings.first_sample + first, lanes, k)
        # numba's compiler cannot take a KeyboardInterrupt (one that lands in LLVM's callbacks
        # leaves it broken): a signal during the compilation stops the render right after it.
        with interrupts.deferred("tracer: interrupted; stopping as soon as the kernels are compiled"
                                 if progress else None) as arrived:
            _compile(estimator, leaf.film, sampler, progress)
        if arrived:
            raise KeyboardInterrupt
        interrupts.check()
        bar = progress_bar(cam.width * cam.height * (stop - first), progress)
        start = time.perf_counter()
        if estimator.learns:
            options = dict(first_sample=settings.first_sample, k=k, spp=settings.spp, continues=continues)
            hook = tuning.PassHook(learner, **options) if learner is not None else \
                tuning.PassHook.of(estimator.plan, cam.width, cam.height, replicates, **options)
        threads = max(1, settings.threads)
        # One executor whatever the thread count: one thread is a pool of one.
        with ThreadPoolExecutor(max_workers=threads) as pool:
            interrupted = _run_pipelined(pool, threads, batches, estimator, sampler, merge, hook)
        seconds = time.perf_counter() - start + pilot_seconds
    except KeyboardInterrupt:
        interrupted = True
        seconds = time.perf_counter() - start + pilot_seconds
    finally:
        close_quietly(bar)
    if interrupted:
        interrupts.clear()  # acted on: the finished batches are kept below
    pooled = leaf.finish(complete=not interrupted)
    # Each pixel holds a prefix of its new indices (batches start in plan order and every
    # started one is merged), so an interrupted render drew first .. first + (most added) - 1.
    drawn = stop - first
    if interrupted:
        drawn = int(pooled.count.max()) if pooled is not None and len(pooled.count) else 0
    if pooled is not None and fresh:
        film = pooled
    elif pooled is not None:
        film.merge(pooled)
    ran = estimator.lights.selection if estimator is not None else None
    film.record = _record(scene, runs, settings, first, drawn, seconds, earlier,
                          ran if estimator is not None and ran != estimator.lights.requested else None)
    if choice is not None or (earlier is not None and earlier.auto):
        film.record = replace(film.record, auto=choice.summary() if choice else earlier.auto)
    learner = hook.learner if hook is not None else (learner if runs.learns else None)
    if learner is not None:
        film.learned = learner.maps()
    new_first = settings.first_sample + first
    added = ((settings.seed, new_first, new_first + drawn),) if drawn else ()
    return RenderResult(film, seconds, samples, nonfinite, interrupted, learner, added)


def _resolve_auto(scene: Scene, auto_strategy: Strategy, settings: RenderSettings, film: Film | None,
                  progress: bool) -> tuple[Strategy, DirectLighting, "auto.Choice | None", float]:
    """The strategy a render of ``--strategy auto`` runs (``tracer.auto``), its estimator, the
    pilot's choice (None when ``film`` holds an earlier ``auto`` render, whose strategy the new
    samples continue) and the pilot's seconds. Candidates compile before the pilot starts, as
    every render's kernels compile off its clock."""
    if film is not None and bool(film.count.any()) and film.record.auto:
        try:
            chosen = Strategy.from_record(film.record)
        except ValueError as exc:
            raise InputError(f"the film's record names no strategy to continue: {exc}") from None
        return chosen, DirectLighting(scene, chosen), None, 0.0
    try:
        candidates = auto.candidates(scene, auto_strategy)
    except ValueError as exc:
        raise InputError(f"{scene.path}: {exc}") from None
    pilots = {s: DirectLighting(scene, auto.pilot_strategy(s)) for s in candidates}
    pilot = samplers.make("independent", 0)

    def compiled(estimators):
        with interrupts.deferred("tracer: interrupted; stopping as soon as the kernels are compiled"
                                 if progress else None) as arrived:
            for estimator in estimators:
                estimator.compile(pilot, progress)
        if arrived:
            raise KeyboardInterrupt

    compiled(pilots.values())
    say = (lambda text: print(f"tracer: {text}", file=sys.stderr)) if progress else None
    choice = auto.choose(scene, auto_strategy, settings.seed, pilots, say, max(1, settings.threads))
    estimator = pilots[choice.strategy]
    if auto.pilot_strategy(choice.strategy) != choice.strategy:
        # A mis candidate's pilot ran its learning build; the render runs the plain one (compiled
        # off the clock, as every render's kernels are).
        estimator = DirectLighting(scene, choice.strategy)
        compiled([estimator])
    return choice.strategy, estimator, choice, choice.seconds


def _check_part(tree: merge_tree.Layout, settings: RenderSettings, part: merge_tree.Task,
                continued: Film | None, fresh: bool) -> None:
    """``InputError`` unless ``part`` is a node or a segment of the render's tree and
    ``continued`` is what a segment after a leaf's first pass needs: the film of exactly the
    leaf's passes before it (its record says which samples it holds), into a new film
    (``fresh``)."""
    try:
        if isinstance(part, merge_tree.Segment):
            tree.check_segment(part)
        else:
            merge_tree.check_node(tree.leaves, part)
    except ValueError as exc:
        raise InputError(f"cannot render part {part}: {exc}") from None
    needs = isinstance(part, merge_tree.Segment) and part.first_pass > 0
    if continued is None and not needs:
        return
    if not needs or not fresh:
        raise InputError(f"only a segment after a leaf's first pass continues a film, into a new one, "
                         f"not part {part}")
    first, stop = tree.samples(merge_tree.Segment(part.leaf, 0, part.first_pass))
    before = ((settings.seed, settings.first_sample + first, settings.first_sample + stop),)
    if continued is None or continued.record.samples != before:
        held = continued.record.samples if continued is not None else "nothing"
        raise InputError(f"part {part} continues the film of samples {before} of its leaf, not {held}")


def close_quietly(bar) -> None:
    """Close a progress bar (None: nothing) with Ctrl-C held back: raised there, after the loop
    that it counted, the interrupt would escape the code that keeps the finished work. One that
    arrives is left pending, for the command to end as interrupted (``tracer.interrupts``)."""
    if bar is None:
        return
    with interrupts.deferred() as arrived:
        bar.close()
    interrupts.leave_pending(arrived)


def tree_layout(scene: Scene, strategy: Strategy, settings: RenderSettings) -> merge_tree.Layout:
    """The merge tree of a render (``tracer.merge_tree``): fixed by the scene's resolution, the
    strategy's rays per sample, the spp and the sampler's replicates; the same for every way of
    cutting the render up."""
    pixels = scene.camera.width * scene.camera.height
    k = pass_samples(settings.spp, pixels, strategy.samples_per_lane)
    # What each pending film costs: per pixel a count, mean and M2 (8 + 24 + 24 bytes), and per
    # replicate a count and mean (8 + 24).
    film_bytes = pixels * (56 + 32 * samplers.replicates_of(settings.sampler))
    return merge_tree.layout(settings.spp, k, film_bytes)


def pooled_into(a: Film, b: Film) -> Film:
    """``a`` with ``b`` merged into it: the merge of the merge tree (``tracer.merge_tree``)."""
    a.merge(b)
    return a


class LeafFilm:
    """The leaf of the merge tree that batches are being folded into, and the pool it goes to.

    Batches come in plan order; the first batch of a new leaf hands the finished one to the
    pool (``merge_tree.Pool``) and starts a fresh film.
    """

    def __init__(self, tree: merge_tree.Layout, width: int, height: int, replicates: int,
                 pool: merge_tree.Pool):
        self.tree, self.pool = tree, pool
        self.shape = (width, height, replicates)
        self.index: int | None = None
        self.film = self._fresh()

    def _fresh(self) -> Film:
        width, height, replicates = self.shape
        return Film(width, height, replicates=replicates)

    def add_block(self, batch: Batch, block: np.ndarray, first_sample: int) -> None:
        """Fold a batch's samples ``(npix, k, 3)``; ``first_sample`` is the render's first index."""
        index = self.tree.leaf_of(batch.first_sample - first_sample)
        if index != self.index:
            self._close()
            self.index = index
        self.film.add_block(batch.first_pixel, block, batch.first_sample)

    def continue_leaf(self, index: int, film: Film) -> None:
        """Fold the next batches into a copy of ``film``, which holds leaf ``index``'s passes
        before them (a segment task): the leaf is then folded as if rendered whole."""
        self.index, self.film = index, film.copy()

    def _close(self) -> None:
        if self.index is not None:
            self.pool.add((self.index, 1), self.film)
            self.film = self._fresh()
        self.index = None

    def finish(self, complete: bool) -> Film | None:
        """The samples folded, pooled (None if none): along the tree if ``complete``, else (a
        render cut short) with the leaf being filled merged last, as it holds a prefix of pixels."""
        partial = None
        if complete:
            self._close()
        elif self.index is not None:
            partial, self.index = self.film, None
        pooled = self.pool.result()
        if partial is not None:
            pooled = partial if pooled is None else pooled_into(pooled, partial)
        return pooled


def render_complete(scene: Scene, strategy: Strategy, settings: RenderSettings, **options) -> RenderResult:
    """:func:`render` for callers that can use only a whole render (comparisons, checks,
    baselines: a render cut short would be measured as if it had its full spp): raises
    ``KeyboardInterrupt`` if Ctrl-C or SIGTERM stopped it."""
    result = render(scene, strategy, settings, **options)
    if result.interrupted:
        raise KeyboardInterrupt
    return result


def _check_continues(earlier: RenderRecord, scene: Scene, strategy: Strategy,
                     settings: RenderSettings) -> None:
    """Refuse to add samples to a film whose record says it was made otherwise: another
    estimator, sampler or scene, or sample indices of this seed that it already holds
    (``record.check_mergeable``); its record could not then say what it holds."""
    new = RenderRecord.of_render(strategy, settings.sampler, settings.seed, settings.first_sample,
                                 settings.spp, 0.0, scene)
    check_mergeable(earlier, new, "the film", "the samples to add")


def _record(scene: Scene, strategy: Strategy, settings: RenderSettings, offset: int, drawn: int,
            seconds: float, earlier: RenderRecord | None, selection_ran: str | None = None) -> RenderRecord:
    """The record of a film after a render that drew ``drawn`` sample indices from
    ``settings.first_sample + offset`` into it (its kernels running ``selection_ran``, where
    that differs from the strategy's selection): the new range joined to the ``earlier``
    record's, as ``record.merged`` joins them."""
    record = replace(RenderRecord.of_render(strategy, settings.sampler, settings.seed,
                                            settings.first_sample + offset, drawn, seconds, scene),
                     light_selection_ran=selection_ran)
    return merged(record, earlier) if earlier is not None else record


def _run_pipelined(pool: ThreadPoolExecutor, threads: int, batches: Iterator[Batch],
                   estimator: DirectLighting, sampler: samplers.SamplerParams, merge,
                   hook: tuning.PassHook | None = None) -> bool:
    """Keep 2 x threads batches in flight and merge them in submission order; for an estimator
    that learns (``hook``), before each batch the hook relearns before, merge every batch in
    flight, then take the tuning the hook gives the next batches.

    Returns True if Ctrl-C stopped it; then the batches already started are awaited and kept.
    """
    in_flight: deque[tuple[Batch, Future]] = deque()
    tuned = hook.first() if hook is not None else None

    def merge_oldest() -> None:
        # The wait is interruptible; taking the batch off the queue and merging it are not, so
        # that a Ctrl-C landing in between neither drops a finished batch nor merges it twice.
        batch, future = in_flight[0]
        result = future.result()
        with interrupts.deferred() as arrived:
            in_flight.popleft()
            merge(batch, result)
        if arrived:
            raise KeyboardInterrupt
        interrupts.check()

    try:
        for batch in batches:
            if hook is not None and hook.relearns(batch):
                while in_flight:
                    merge_oldest()
                tuned = hook.before(batch)
            in_flight.append((batch, pool.submit(render_batch, estimator, batch, sampler, tuned)))
            if len(in_flight) >= 2 * threads:
                merge_oldest()
        while in_flight:
            merge_oldest()
        return False
    except KeyboardInterrupt:
        with interrupts.deferred():
            # Newest first: a thread that finds batch i cancelled takes the next one, which must
            # then be cancelled already, or a pixel could hold a pass without the one before it.
            cancelled = {id(future) for _, future in reversed(in_flight) if future.cancel()}
            for batch, future in in_flight:
                if id(future) not in cancelled:
                    merge(batch, future.result())
        return True


def progress_bar(total: int, enabled: bool, unit: str = "sample"):
    """A tqdm bar on stderr counting ``unit``, or None when disabled or stderr is not a terminal."""
    if not enabled or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, unit_scale=unit == "sample", file=sys.stderr, leave=False,
                dynamic_ncols=True, smoothing=0.1)
