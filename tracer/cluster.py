"""Renders beyond one process, on Dask's distributed scheduler (the optional ``cluster`` extra).

A render's samples are addressed by (seed, pixel, sample index), so it splits into tasks of
disjoint sample indices: each task renders one node of the render's merge tree
(``tracer.merge_tree``: a power-of-two block of leaves) into a film, with the random numbers the
whole render would draw there, and the driver pools the task films along the same tree as they
arrive. The result is the same, bit for bit, as the render in one process, whatever the task
size, the number of workers and the order tasks finish in.

Dask does the scheduling: a local cluster of worker processes (``--workers N``) or an existing
cluster (``--scheduler ADDRESS``: SSH, Kubernetes, an HPC job queue). A task is a pure function
of its arguments, so when a worker dies Dask runs its task again elsewhere with the same sample
indices; a sample is pooled only from a task whose result arrived, once. The scene travels to
the workers by content (the loaded ``Scene``, meshes included, scattered once), never by path.
Tasks render on one thread each: a worker with T threads runs T tasks at once.

Independent whole jobs are tasks too (:func:`map_tasks`): compare's strategies and seeds, check's
entries and seeds.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import sys
import time
import uuid
from collections.abc import Iterator, Sequence
from typing import Any

from . import interrupts, merge_tree
from .errors import InputError
from .estimators import DirectLighting
from .film import Film
from .record import merged
from .render_loop import (
    RenderResult,
    RenderSettings,
    _progress_bar,
    film_to_fill,
    pass_samples,
    pooled_into,
    render,
    render_complete,
)
from .scene import Scene
from .strategy import Strategy

INSTALL_HINT = "pip install 'tracer[cluster]' (Dask's distributed scheduler)"
# Tasks per worker thread a render is cut into by default: enough that a slow or lost worker
# delays the end by a small share, few enough that each task's fixed cost (a film sent back and
# merged, a few milliseconds at 256x256) stays small against its rendering.
TASKS_PER_THREAD = 4
CONNECT_TIMEOUT = "20s"


def _distributed():
    """The ``distributed`` module, or an ``InputError`` saying how to install it."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"--workers and --scheduler need Dask: {INSTALL_HINT}",
                         "command line") from None
    return distributed


@contextlib.contextmanager
def connect(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask ``Client``: of a new local cluster of ``workers`` single-threaded worker processes,
    or of the existing scheduler at ``scheduler`` (``tcp://host:8786``). The local cluster is
    shut down on leaving."""
    distributed = _distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}",
                             "--scheduler") from None
        with client:
            yield client
        return
    # Worker processes log to stderr; only their errors are worth a user's attention.
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def worker_threads(client) -> int:
    """Threads across the cluster's workers (tasks that run at once)."""
    return max(1, sum(client.nthreads().values()))


def task_leaves(tree: merge_tree.Layout, threads: int, task_spp: int | None = None) -> int:
    """Leaves per task: the largest power of two that is at most ``task_spp`` samples, or by
    default that cuts the render into at least ``TASKS_PER_THREAD`` tasks per thread."""
    if task_spp is not None:
        wanted = max(1, task_spp // tree.leaf_spp)
    else:
        wanted = max(1, tree.leaves // (TASKS_PER_THREAD * threads))
    return 1 << (wanted.bit_length() - 1)


# Each worker keeps the estimator (its Embree scene and light tables) of the last render it
# worked on, so that the tasks after the first one do not build it again. The key holds the
# resolution, which the scene's digest leaves out (the estimator casts its camera's rays).
_ESTIMATOR: dict[tuple[str, int, int, Strategy], DirectLighting] = {}


def _estimator(scene: Scene, strategy: Strategy) -> DirectLighting:
    key = (scene.digest, scene.camera.width, scene.camera.height, strategy)
    if key not in _ESTIMATOR:
        _ESTIMATOR.clear()
        _ESTIMATOR[key] = DirectLighting(scene, strategy)
    return _ESTIMATOR[key]


def render_part(scene: Scene, strategy: Strategy, settings: RenderSettings,
                part: merge_tree.Node) -> tuple[Film, int, int]:
    """A task: node ``part`` of the render ``settings`` on one thread. Returns its film, the count
    of samples that were not finite, and the samples rendered."""
    settings = dataclasses.replace(settings, threads=1)
    result = render(scene, strategy, settings, estimator=_estimator(scene, strategy), part=part)
    return result.film, result.nonfinite, result.samples


def render_distributed(client, scene: Scene, strategy: Strategy, settings: RenderSettings,
                       film: Film | None = None, progress: bool = False,
                       task_spp: int | None = None) -> RenderResult:
    """:func:`tracer.render_loop.render` on a Dask cluster: the same film, bit for bit.

    Ctrl-C (or SIGTERM) cancels the tasks not finished; the film then holds exactly the tasks
    whose results arrived, and its record lists their sample ranges. Strategies that learn
    between passes (optimal MIS, adaptive allocation) are refused: each pass depends on all the
    samples before it.
    """
    if strategy.learns:
        raise InputError(f"{strategy.label} learns between passes from every earlier sample, so its "
                         "passes are not independent tasks: render it without --workers or --scheduler",
                         "command line")
    fresh = film is None
    film, earlier = film_to_fill(scene, strategy, settings, film)
    cam = scene.camera
    k = pass_samples(settings.spp, cam.width * cam.height, strategy.samples_per_lane)
    tree = merge_tree.layout(settings.spp, k)
    threads = worker_threads(client)
    nodes = merge_tree.task_nodes(tree.leaves, task_leaves(tree, threads, task_spp))
    first, stop = tree.samples(nodes[0])
    if progress:
        print(f"tracer: {len(nodes)} tasks of up to {stop - first} spp on {threads} worker threads "
              f"(Dask scheduler {client.scheduler.address})", file=sys.stderr)
    pool: merge_tree.Pool[Film] = merge_tree.Pool(tree.leaves, pooled_into)
    records = []
    nonfinite = samples = 0
    interrupted = False
    start = time.perf_counter()
    bar = _progress_bar(cam.width * cam.height * settings.spp, progress)
    futures = []
    try:
        shared_scene = client.scatter(scene, broadcast=True, hash=False)
        prefix = f"tracer-render-{uuid.uuid4().hex}"
        futures = [client.submit(render_part, shared_scene, strategy, settings, node,
                                 key=f"{prefix}-{node[0]}") for node in nodes]
        node_of = {future.key: node for future, node in zip(futures, nodes, strict=True)}
        for future, result in _completed(futures):
            part, bad, count = result
            with interrupts.deferred() as arrived:  # a task's film is pooled whole or not at all
                pool.add(node_of[future.key], part)
                records.append(part.record)
                nonfinite += bad
                samples += count
            if arrived:
                raise KeyboardInterrupt
            if bar is not None:
                bar.update(count)
            elif progress:
                _log_progress(len(records), len(nodes))
    except KeyboardInterrupt:
        interrupted = True
        with contextlib.suppress(Exception):
            client.cancel(futures)
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - start
    pooled = pool.result()
    if pooled is not None:
        record = records[0]
        for other in records[1:]:
            record = merged(record, other)
        pooled.record = dataclasses.replace(record, seconds=seconds)
        if fresh:
            film = pooled
        else:
            film.merge(pooled)
            film.record = merged(earlier, pooled.record) if earlier is not None else pooled.record
    return RenderResult(film, seconds, samples, nonfinite, interrupted)


def _log_progress(done: int, total: int) -> None:
    """Without a terminal for the bar (a batch job's log), a line at each tenth of the tasks."""
    if done * 10 // total > (done - 1) * 10 // total:
        print(f"tracer: {done} of {total} tasks done", file=sys.stderr, flush=True)


def _completed(futures) -> Iterator[tuple[Any, Any]]:
    """``(future, result)`` as tasks finish; a task that failed or was cancelled raises its error."""
    distributed = _distributed()
    for future, result in distributed.as_completed(futures, with_results=True, raise_errors=False):
        if future.status != "finished":
            try:
                future.result()  # raises the task's exception (a worker's InputError stays one)
            except (distributed.KilledWorker, distributed.comm.CommClosedError, OSError) as exc:
                # The cluster failed, not the render: one line, as for a failing disk.
                raise InputError(f"the Dask cluster lost task {future.key}: {type(exc).__name__}: {exc}",
                                 "--workers/--scheduler") from None
            raise InputError(f"Dask task {future.key} ended as {future.status}", "--workers/--scheduler")
        yield future, result


def map_tasks(client, function, calls: Sequence[tuple], progress: bool = False) -> list:
    """``function(*call)`` for each of ``calls`` as Dask tasks: the results in the order of
    ``calls``. Scenes and films among the arguments are sent to the workers once each, by content,
    however many tasks take them. Raises ``KeyboardInterrupt`` on Ctrl-C, after cancelling the
    tasks; a task's exception is raised here (an ``InputError`` stays one)."""
    prefix = f"tracer-{getattr(function, '__name__', 'task')}-{uuid.uuid4().hex}"
    futures = []
    sent: dict[int, Any] = {}

    def shared(value):
        if not isinstance(value, (Scene, Film)):
            return value
        if id(value) not in sent:
            sent[id(value)] = client.scatter(value, broadcast=True, hash=False)
        return sent[id(value)]

    bar = _progress_bar(len(calls), progress)
    try:
        futures = [client.submit(function, *map(shared, call), key=f"{prefix}-{index}")
                   for index, call in enumerate(calls)]
        results: dict[str, Any] = {}
        for future, result in _completed(futures):
            results[future.key] = result
            if bar is not None:
                bar.update(1)
        return [results[future.key] for future in futures]
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise
    finally:
        if bar is not None:
            bar.close()


def render_whole(scene: Scene, strategy: Strategy, settings: RenderSettings) -> RenderResult:
    """A task: one whole render on one thread (``render_complete``)."""
    settings = dataclasses.replace(settings, threads=1)
    return render_complete(scene, strategy, settings, estimator=_estimator(scene, strategy))
