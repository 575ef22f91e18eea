"""Renders beyond one process, on Dask's distributed scheduler (the optional ``cluster`` extra).

A render's samples are addressed by (seed, pixel, sample index), so it splits into tasks of
disjoint sample indices: each task renders one node of the render's merge tree
(``tracer.merge_tree``: a power-of-two block of leaves) into a film, with the random numbers the
whole render would draw there, and merge tasks pool sibling nodes along the same tree as they
finish, on the workers, up to the tree's few pieces, which the driver pools. The result is the
same, bit for bit, as the render in one process, whatever the task size, the number of workers
and the order tasks finish in.

Dask does the scheduling: a local cluster of worker processes (``--workers N``) or an existing
cluster (``--scheduler ADDRESS``: SSH, Kubernetes, an HPC job queue). A task is a pure function
of its arguments, so when a worker dies Dask runs its task again elsewhere with the same sample
indices (and a lost finished film is computed again the same way); a sample is pooled only
from a node that finished, once. The scene travels to
the workers by content (the loaded ``Scene``, meshes included, scattered once), never by path.
Tasks render on one thread each: a worker with T threads runs T tasks at once.

Independent whole jobs are tasks too (:func:`map_tasks`): compare's strategies and seeds, check's
entries and seeds.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import signal
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Iterator, Sequence
from typing import Any

from . import interrupts, merge_tree
from .errors import InputError, shown
from .estimator import DirectLighting
from .film import Film
from .record import merged
from .render_loop import (
    RenderResult,
    RenderSettings,
    close_quietly,
    film_to_fill,
    progress_bar,
    render,
    render_complete,
    tree_layout,
)
from .scene import Scene
from .strategy import Strategy

INSTALL_HINT = ("install Dask's distributed scheduler: pip install \".[cluster]\" in tracer's source folder, "
                "or pip install \"dask[distributed]\"")
# Tasks per worker thread a render is cut into by default: enough that a slow or lost worker
# delays the end by a small share, few enough that each task's fixed cost (a film sent back and
# merged, a few milliseconds at 256x256) stays small against its rendering.
TASKS_PER_THREAD = 4
# At most this many shading rays per task by default, so that a task finishes within seconds
# whatever the spp, and Ctrl-C keeps finished work a minute after the start: measured, one
# thread of a loaded 2-core machine renders veach_mis at 256x256 with MIS (2 rays a sample) at
# 1.3 M samples/s, 2.6 M rays/s, so a task of 2^25 rays takes about 13 s; a machine or scene
# four times slower still finishes one in under a minute. Rays, not samples: --light-samples 8
# makes a sample cost 9 rays. (Embree's cost per ray grows slowly with the triangles.)
TASK_RAYS = 1 << 25
# Each chain of segments (tasks smaller than a leaf, ``merge_tree.Segment``) has this many tasks
# submitted at once: the one running and the next, so that a worker goes on without waiting
# for the driver to see the first finish.
CHAIN_TASKS_AHEAD = 2
# Seconds between looks at a cluster's tasks while none finishes: how late an interrupt whose
# KeyboardInterrupt a finalizer dropped is acted on (``tracer.interrupts``).
POLL_SECONDS = 0.1
# Without a terminal for the progress bar, a line at the first finished task, at each tenth of
# them, and at least this often (seconds) in between.
LOG_SECONDS = 60.0
# Seconds to wait for an existing scheduler (--scheduler) to answer, and again for its first
# worker: long enough for a scheduler across a slow network, short enough that a wrong address
# fails while the user still waits for it (``--connect-timeout`` changes it).
CONNECT_SECONDS = 20.0
# The transports a --scheduler address may name. ``inproc`` reaches only a scheduler in this
# process; ``ucx`` is an empty stub in current Dask (its connector cannot be made).
TRANSPORTS = ("tcp", "tls", "ws", "wss")
GATHER_TIMEOUT = 60.0  # seconds to fetch a finished film after Ctrl-C or a failure


class ClusterLost(InputError):
    """The Dask cluster failed (a scheduler gone, a task that keeps killing its workers).
    ``result`` holds what finished before, pooled, for the caller to keep (None if nothing)."""

    def __init__(self, message: str, result: RenderResult | None = None):
        super().__init__(message, "--workers/--scheduler")
        self.result = result


def _distributed():
    """The ``distributed`` module, or an ``InputError`` saying how to install it."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"--workers and --scheduler need Dask: {INSTALL_HINT}",
                         "command line") from None
    return distributed


@contextlib.contextmanager
def connect(workers: int | None = None, scheduler: str | None = None,
            timeout: float = CONNECT_SECONDS) -> Iterator[Any]:
    """A Dask ``Client``: of a new local cluster of ``workers`` single-threaded worker processes,
    or of the existing scheduler at ``scheduler`` (``tcp://host:8786``), which must answer as a
    Dask scheduler within ``timeout`` seconds and have a worker within as many again (else an
    ``InputError`` naming the address and what went wrong). The local cluster is shut down on
    leaving."""
    distributed = _distributed()
    if scheduler is not None:
        security = _security_for(distributed, scheduler)
        _probe_scheduler(distributed, scheduler, timeout, security)
        try:
            client = distributed.Client(scheduler, timeout=timeout, security=security)
        except Exception as exc:  # the probe passed: whatever fails now is the scheduler's side
            raise InputError(f"cannot connect to the Dask scheduler at {shown(scheduler)}: "
                             f"{_described(exc)}", "--scheduler") from None
        with client:
            try:
                client.wait_for_workers(1, timeout=timeout)
            except TimeoutError:
                raise InputError(f"the Dask scheduler at {shown(scheduler)} has no workers (waited "
                                 f"{timeout:g} s)", "--scheduler") from None
            _check_workers(client)
            yield client
        return
    # The worker processes ignore SIGINT (they inherit SIG_IGN, which survives exec): a Ctrl-C at
    # the terminal reaches the whole process group, and the driver alone must handle it, taking
    # the finished films from the workers before it shuts them down.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if _main_thread() else None
    try:
        # Worker processes log to stderr; only their errors are worth a user's attention.
        # Dask's workers sample their threads' stacks every 10 ms for the dashboard's profile:
        # measured, renders took 10-15% longer with it (benchmarks/cluster.py). The dashboard on
        # a free port: a second local cluster would warn that 8787 is taken.
        import dask.config  # installed with distributed

        with dask.config.set({"distributed.worker.profile.enabled": False}):
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                               dashboard_address=":0", silence_logs=logging.ERROR)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    with cluster, distributed.Client(cluster) as client:
        # A worker that the nanny starts again (after it died, or was killed) is spawned now,
        # under the driver's own handler, which exec does not pass on: it would die of the next
        # Ctrl-C, with a traceback, and take its finished films with it. Every worker, those to
        # come included, runs this on joining.
        client.register_worker_callbacks(setup=_ignore_ctrl_c)
        yield client


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _ignore_ctrl_c() -> None:
    """On a local cluster's worker: SIGINT ignored (the driver alone handles Ctrl-C)."""
    if _main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _described(exc: BaseException) -> str:
    """An exception as a short phrase for an error line: the type and first line, cut, of the
    error at the root of its chain (Dask wraps a refused connection in its own error, whose
    text is the connector object's repr)."""
    while exc.__cause__ is not None:
        exc = exc.__cause__
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {shown(text[0])}" if text else type(exc).__name__


def _security_for(distributed, address: str):
    """Dask's ``Security`` (from Dask's configuration) for connecting to ``address``, after
    checking that its transport is one tracer can use: ``InputError`` otherwise (before
    any connection, which Dask would answer with a ``TypeError``)."""
    from distributed.comm.addressing import parse_address

    scheme, location = parse_address(address)
    if scheme not in TRANSPORTS or not location:
        raise InputError(f"{shown(address)} is not an address of a Dask scheduler tracer can reach: "
                         f"expected {', '.join(s + '://HOST:PORT' for s in TRANSPORTS)} (or HOST:PORT "
                         "for tcp)", "--scheduler")
    security = distributed.Security()
    if scheme in ("tls", "wss") and security.get_connection_args("client")["ssl_context"] is None:
        raise InputError(f"{shown(address)}: {scheme}:// needs Dask's TLS settings (the client's "
                         "certificate, key and CA file: distributed.comm.tls.client.cert, .client.key "
                         "and distributed.comm.tls.ca-file in Dask's configuration, or the "
                         "DASK_DISTRIBUTED__COMM__TLS__... environment variables), and none are set",
                         "--scheduler")
    return security


# How long the probe's thread may outlive its own deadline (asyncio's cancellation, closing
# the socket) before the driver stops waiting for it.
_PROBE_GRACE_SECONDS = 5.0


def _probe_scheduler(distributed, address: str, seconds: float, security) -> None:
    """``InputError`` unless a Dask scheduler answers at ``address`` within ``seconds``.

    Dask's ``Client`` alone cannot be trusted with a wrong address: its handshake waits without
    a deadline for a server that accepts the connection and never answers, and it reads the
    first 8 bytes of any other server's answer as a frame length (an HTTP server's "HTTP/1.1"
    asks numpy for exabytes). So before the ``Client``, this connects once itself, in steps
    under one deadline: the connection, Dask's handshake, and the ``identity`` request, whose
    answer names the kind of server (a worker answers too, as a ``Worker``)."""
    import asyncio

    from distributed.comm.addressing import parse_address
    from distributed.comm.registry import get_backend

    scheme, location = parse_address(address)
    step = ["connecting"]

    async def identity() -> Any:
        try:
            connector = get_backend(scheme).get_connector()
        except Exception as exc:  # a transport Dask lists but cannot make
            raise InputError(f"Dask's {scheme}:// transport does not work in this install "
                             f"({_described(exc)})", "--scheduler") from None
        comm = await connector.connect(location, deserialize=True, **security.get_connection_args("client"))
        try:
            step[0] = "waiting for Dask's handshake"
            await comm.write(comm.handshake_info())
            await comm.read()
            step[0] = "waiting for the answer to Dask's identity request"
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    outcome: dict[str, Any] = {}

    def run() -> None:  # on a thread of its own: the caller may already run an event loop
        try:
            outcome["reply"] = asyncio.run(asyncio.wait_for(identity(), seconds))
        except BaseException as exc:  # handed to the caller, who decides
            outcome["error"] = exc

    thread = threading.Thread(target=run, name="tracer-scheduler-probe", daemon=True)
    thread.start()
    thread.join(seconds + _PROBE_GRACE_SECONDS)
    error = outcome.get("error")
    where = f"the Dask scheduler at {shown(address)}"
    if isinstance(error, InputError):
        raise error
    if thread.is_alive() or isinstance(error, TimeoutError):
        if step[0] == "connecting":
            raise InputError(f"cannot reach {where}: no connection within {seconds:g} s", "--scheduler")
        raise InputError(f"{shown(address)} accepted the connection but gave no answer in Dask's protocol "
                         f"within {seconds:g} s ({step[0]}): is a Dask scheduler listening there?",
                         "--scheduler")
    if error is not None and step[0] == "connecting":  # refused, no such host, no port, ...
        raise InputError(f"cannot reach {where}: {_described(error)}", "--scheduler")
    if error is not None:  # a closed connection, garbage read as a frame length, ...
        raise InputError(f"{shown(address)} does not answer in Dask's protocol ({step[0]}: "
                         f"{_described(error)}): is a Dask scheduler listening there?", "--scheduler")
    reply = outcome["reply"]
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        found = (f"a Dask {shown(kind).lower()}" if isinstance(kind, str)
                 else "a server that speaks Dask's protocol")
        raise InputError(f"{shown(address)} is {found}, not a Dask scheduler: give the address of the "
                         "cluster's scheduler", "--scheduler")


def _worker_identity() -> tuple[str, str]:
    """tracer's version and source digest on a worker (``connect`` compares them)."""
    from . import __version__, jit

    return __version__, jit.source_digest().hex()


def _check_workers(client) -> None:
    """Refuse a cluster whose workers run another tracer than this one: their samples would be
    mixed with ours silently."""
    here = _worker_identity()
    try:
        there = client.run(_worker_identity)
    except Exception as exc:  # a worker without tracer cannot even unpickle the function
        raise InputError(f"cannot run tracer on the Dask workers ({type(exc).__name__}: {exc}); install "
                         f"tracer {here[0]} on every worker", "--scheduler") from None
    other = {address: identity for address, identity in there.items() if tuple(identity) != here}
    if other:
        address, (version, digest) = next(iter(other.items()))
        raise InputError(f"{len(other)} Dask worker(s) run another tracer ({address}: version {version}, "
                         f"sources {digest[:12]}; here {here[0]}, {here[1][:12]}): install this one on "
                         "every worker", "--scheduler")


def worker_threads(client) -> int:
    """Threads across the cluster's workers (tasks that run at once)."""
    return max(1, sum(client.nthreads().values()))


def task_passes(tree: merge_tree.Layout, threads: int, pixels: int, rays_per_sample: int,
                task_spp: int | None = None) -> int:
    """Passes per task: ``task_spp`` samples in whole passes (at least one), or by default a
    share of the render that cuts it into at least ``TASKS_PER_THREAD`` tasks per thread, in
    whole leaves, but at most ``TASK_RAYS`` shading rays (a task smaller than a leaf is a
    segment of it: ``merge_tree.tasks``)."""
    if task_spp is not None:
        return max(1, task_spp // tree.k)
    share = tree.leaf_passes * max(1, tree.leaves // (TASKS_PER_THREAD * threads))
    budget = TASK_RAYS // max(1, pixels * rays_per_sample * tree.k)
    return max(1, min(share, budget))


# Each worker keeps the estimators (Embree scene, light tables) of the last few renders it worked
# on, so that the tasks after the first one do not build them again. The key holds the
# resolution, which the scene's digest leaves out (the estimator casts its camera's rays).
_ESTIMATORS: dict[tuple[str, int, int, Strategy], DirectLighting] = {}
_ESTIMATORS_KEPT = 4
_CACHE_LOCK = threading.Lock()  # a worker runs one task per thread


def _estimator(scene: Scene, strategy: Strategy) -> DirectLighting:
    key = (scene.digest, scene.camera.width, scene.camera.height, strategy)
    with _CACHE_LOCK:
        if key not in _ESTIMATORS:
            while len(_ESTIMATORS) >= _ESTIMATORS_KEPT:
                del _ESTIMATORS[next(iter(_ESTIMATORS))]
            _ESTIMATORS[key] = DirectLighting(scene, strategy)
        return _ESTIMATORS[key]


def refuse_undistributable(strategy: Strategy, where: str | None = None) -> None:
    """``InputError`` for a strategy whose passes are not independent tasks: one that learns
    between passes (its sample ranges depend on all the samples before them) or ``auto`` (its
    pilot decides, on this machine, what every task would render)."""
    if strategy.learns:
        raise InputError(f"{strategy.label} learns between passes from every earlier sample, so its passes "
                         "are not independent tasks: render it without --workers or --scheduler", where)
    if strategy.name == "auto":
        raise InputError("auto's pilot chooses its strategy on this machine before any sample is drawn: render "
                         "it without --workers or --scheduler, or distribute the strategy it chose (the render "
                         "record's tracer:strategy and tracer:auto say which)", where)


# What a task of a distributed render gives back: its film, the count of samples that were not
# finite, and the samples rendered.
Part = tuple[Film, int, int]


def render_part(scene: Scene, strategy: Strategy, settings: RenderSettings, part: merge_tree.Task,
                before: Part | None = None) -> Part:
    """A task: node or segment ``part`` of the render ``settings`` on one thread; a segment after
    its leaf's first pass continues ``before``, the part of the segment before it, and the part
    returned holds both (counts included)."""
    settings = dataclasses.replace(settings, threads=1)
    result = render(scene, strategy, settings, estimator=_estimator(scene, strategy), part=part,
                    continued=before[0] if before is not None else None)
    earlier_nonfinite, earlier_samples = (before[1], before[2]) if before is not None else (0, 0)
    return result.film, result.nonfinite + earlier_nonfinite, result.samples + earlier_samples


def merge_parts(left: Part, right: Part) -> Part:
    """A task: two sibling nodes of the merge tree pooled as the tree says (``left`` with ``right``
    merged in, as ``render_loop.pooled_into`` does locally), into a copy: Dask may still hold
    ``left`` for a Ctrl-C."""
    film = left[0].copy()
    film.merge(right[0])
    film.record = merged(left[0].record, right[0].record)
    return film, left[1] + right[1], left[2] + right[2]


def _pool_in_order(parts: list[Part]) -> Part:
    """Disjoint nodes (in leaf order) pooled one after the other: the pieces of a whole render, as
    the tree says, or the finished nodes of one cut short."""
    pooled = parts[0]
    for part in parts[1:]:
        pooled = merge_parts(pooled, part)
    return pooled


@dataclasses.dataclass
class _Chain:
    """The tasks that render one node of the tree, run one after the other (one task, or the
    segments of a leaf), as the driver submits them."""

    node: merge_tree.Node
    tasks: Iterator[merge_tree.Task]  # not yet submitted
    submitted: deque = dataclasses.field(default_factory=deque)  # futures, unfinished, oldest first
    latest: Any = None  # the last finished task's future: its film holds the chain's samples so far
    ended: bool = False  # every task submitted


def render_distributed(client, scene: Scene, strategy: Strategy, settings: RenderSettings,
                       film: Film | None = None, progress: bool = False,
                       task_spp: int | None = None) -> RenderResult:
    """:func:`tracer.render_loop.render` on a Dask cluster: the same film, bit for bit.

    Tasks render nodes of the render's merge tree, or segments of its leaves (``task_passes``,
    ``merge_tree.tasks``); merge tasks pool sibling nodes on the workers as they finish, up to
    the tree's pieces, so that the driver receives a few films, not one per task, and Dask frees
    a node's film once its parent holds it. Whole nodes are submitted at once (at most
    ``MAX_LEAVES``); the chains of segments, which may number billions, ``threads`` at a time.
    Ctrl-C (or SIGTERM) cancels what has not finished; the film then pools the largest finished
    nodes and the latest finished segment of each leaf under way, exactly the tasks that finished,
    and its record lists their sample ranges. Strategies that learn between passes (optimal MIS,
    adaptive allocation) are refused: each pass depends on all the samples before it.
    """
    refuse_undistributable(strategy)
    fresh = film is None
    film, earlier = film_to_fill(scene, strategy, settings, film)
    pixels = scene.camera.width * scene.camera.height
    tree = tree_layout(scene, strategy, settings)
    threads = worker_threads(client)
    passes = task_passes(tree, threads, pixels, strategy.samples_per_lane, task_spp)
    whole_nodes = merge_tree.task_leaves(tree, passes) > 0
    total = merge_tree.task_count(tree, passes)
    largest = min(settings.spp, (merge_tree.task_leaves(tree, passes) * tree.leaf_passes or passes) * tree.k)
    if progress:
        print(f"tracer: {total} tasks of up to {largest} spp on {threads} worker threads "
              f"(Dask scheduler {client.scheduler.address})", file=sys.stderr)
    interrupted = False
    start = time.perf_counter()
    bar = progress_bar(pixels * settings.spp, progress)
    log = _ProgressLog(total, progress and bar is None)
    # A node's future: the last task of its chain, or the merge of its children.
    futures: dict[merge_tree.Node, Any] = {}
    children: dict[merge_tree.Node, tuple[merge_tree.Node, merge_tree.Node]] = {}
    node_of: dict[str, merge_tree.Node] = {}  # key of a node's future -> the node
    chain_of: dict[str, tuple[_Chain, merge_tree.Task]] = {}  # unfinished render task's key -> ...
    active: dict[merge_tree.Node, _Chain] = {}  # the chains under way, by node
    parts: list[Part] = []
    lost: ClusterLost | None = None
    tracker = _distributed().as_completed([], with_results=False, raise_errors=False)
    prefix = f"tracer-render-{uuid.uuid4().hex}"

    def merge_submitted(left, right):
        # The pool's merge: it calls this exactly as the tree says, left node first.
        left_node, right_node = node_of[left.key], node_of[right.key]
        parent = (left_node[0], 2 * left_node[1])
        future = client.submit(merge_parts, left, right, key=f"{prefix}-merge-{parent[0]}-{parent[1]}")
        futures[parent], children[parent], node_of[future.key] = future, (left_node, right_node), parent
        tracker.add(future)
        return future

    pool = merge_tree.Pool(tree.leaves, merge_submitted)
    chains = merge_tree.tasks(tree, passes)

    def top_up(chain: _Chain) -> None:
        while not chain.ended and len(chain.submitted) < CHAIN_TASKS_AHEAD:
            task = next(chain.tasks, None)
            if task is None:
                chain.ended = True
                node_of[futures[chain.node].key] = chain.node
                pool.add(chain.node, futures[chain.node])  # submits the merges it completes
                break
            before = chain.submitted[-1] if chain.submitted else chain.latest
            name = (f"{task[0]}-{task[1]}" if not isinstance(task, merge_tree.Segment)
                    else f"{task.leaf}-passes-{task.first_pass}-{task.stop_pass}")
            future = client.submit(render_part, shared_scene, strategy, settings, task, before,
                                   key=f"{prefix}-part-{name}")
            chain.submitted.append(future)
            chain_of[future.key] = chain, task
            futures[chain.node] = future  # until the chain's last task replaces it
            tracker.add(future)

    def start_chains() -> None:
        while whole_nodes or len(active) < threads:
            node, tasks = next(chains, (None, None))
            if node is None:
                return
            active[node] = _Chain(node, tasks)
            top_up(active[node])

    try:
        shared_scene = _sent(client, scene, f"{prefix}-scene")
        start_chains()
        for future, _ in _completed(tracker):
            chain, task = chain_of.pop(future.key, (None, None))
            if chain is not None:  # a render task
                chain.submitted = deque(f for f in chain.submitted if f.key != future.key)
                chain.latest = future  # the one before it may go: this film holds its samples
                first, stop = tree.samples(task)
                if bar is not None:
                    bar.update(pixels * (stop - first))
                log.finished(stop - first)
                if chain.ended and not chain.submitted:
                    del active[chain.node]
                    start_chains()
                else:
                    top_up(chain)
            for child in children.get(node_of.get(future.key), ()):
                del futures[child]  # its parent holds its samples now: Dask may free it
        parts = client.gather([futures[piece] for piece in merge_tree.pieces(tree.leaves)])
    except (KeyboardInterrupt, ClusterLost) as exc:
        interrupted = True
        lost = exc if isinstance(exc, ClusterLost) else None
        parts = _gather_finished(client, tree, futures, children, list(active.values()))
        interrupts.clear()  # acted on: the finished tasks are kept below
    finally:
        close_quietly(bar)
    seconds = time.perf_counter() - start
    samples = nonfinite = 0
    drawn: tuple = ()
    if parts:
        pooled, nonfinite, samples = _pool_in_order(parts)
        pooled.record = dataclasses.replace(pooled.record, seconds=seconds)
        drawn = pooled.record.samples or ()
        if fresh:
            film = pooled
        else:
            film.merge(pooled)
            film.record = merged(pooled.record, earlier) if earlier is not None else pooled.record
    result = RenderResult(film, seconds, samples, nonfinite, interrupted, drawn=drawn)
    if lost is not None:
        raise ClusterLost(str(lost), result if parts else None)
    return result


def _gather_finished(client, tree: merge_tree.Layout, futures: dict, children: dict,
                     chains: list[_Chain]) -> list[Part]:
    """After Ctrl-C or a lost cluster: cancel what has not finished and fetch the largest finished
    nodes and the latest finished segment of each leaf under way (``chains``), in leaf order
    (every finished task lies in exactly one). A film the cluster can no longer give is left
    out, with the samples it held."""
    with interrupts.deferred():
        finished = {node: futures[node] for piece in merge_tree.pieces(tree.leaves)
                    for node in _finished_under(piece, futures, children)}
        finished.update({chain.node: chain.latest for chain in chains
                         if chain.latest is not None and chain.node not in finished})
        kept = {future.key for future in finished.values()}
        waiting = [f for f in futures.values() if f.key not in kept]
        waiting += [f for chain in chains for f in chain.submitted if f.key not in kept]
        with contextlib.suppress(Exception):
            client.cancel(waiting)
        parts = []
        for node in sorted(finished):
            with contextlib.suppress(Exception):
                parts.append(finished[node].result(timeout=GATHER_TIMEOUT))
        return parts


def _finished_under(node: merge_tree.Node, futures: dict, children: dict) -> list[merge_tree.Node]:
    """The largest finished nodes of the subtree under ``node``, in leaf order."""
    future = futures.get(node)
    if future is not None and future.status == "finished":
        return [node]
    if node not in children:
        return []
    left, right = children[node]
    return _finished_under(left, futures, children) + _finished_under(right, futures, children)


class _ProgressLog:
    """Without a terminal for the bar (a batch job's log), lines that say how far a render is:
    at the first finished task (the first work Ctrl-C keeps), at each tenth of the tasks, and
    every ``LOG_SECONDS`` in between."""

    def __init__(self, total: int, enabled: bool):
        self.total, self.enabled = total, enabled
        self.done = self.spp = 0
        self.last = time.perf_counter()

    def finished(self, spp: int) -> None:
        """One more task done, of ``spp`` samples per pixel."""
        self.done += 1
        self.spp += spp
        now = time.perf_counter()
        tenth = self.done * 10 // self.total > (self.done - 1) * 10 // self.total
        if self.enabled and (self.done == 1 or tenth or now - self.last >= LOG_SECONDS):
            self.last = now
            print(f"tracer: {self.done} of {self.total} tasks done ({self.spp} spp finished)",
                  file=sys.stderr, flush=True)


def _completed(tracker) -> Iterator[tuple[Any, Any]]:
    """``(future, result)`` as the tasks of ``tracker`` (a ``distributed.as_completed``, which may
    be added to meanwhile) finish (result None unless it has results: else the data stay on the
    workers). A task that raised raises its error here (a worker's ``InputError`` stays one);
    one the cluster lost (a worker killed too often, the scheduler gone, its inputs lost) raises
    ``ClusterLost``. Waits in polls of ``POLL_SECONDS``, each ending with ``interrupts.check``:
    an interrupt dropped by a finalizer (a Dask future's, for one) stops the wait all the same."""
    distributed = _distributed()
    while True:
        interrupts.check()
        if not tracker.has_ready():
            if tracker.is_empty():
                return
            with tracker.thread_condition:
                tracker.thread_condition.wait(timeout=POLL_SECONDS)
            continue
        item = next(tracker)
        future, result = item if tracker.with_results else (item, None)
        if future.status != "finished":
            # Not finished when as_completed handed it over: it failed, or the worker holding its
            # result died after finishing it and Dask is computing it again (``lost``, then
            # ``pending``). result() waits for the rerun: a task finished again is a finished task.
            try:
                value = future.result()
            except (distributed.KilledWorker, distributed.CancelledError, distributed.comm.CommClosedError,
                    OSError) as exc:
                raise ClusterLost(f"the Dask cluster lost task {future.key}: {type(exc).__name__}: "
                                  f"{exc}") from None
            if future.status != "finished":
                raise ClusterLost(f"Dask task {future.key} ended as {future.status}")
            if tracker.with_results:
                result = value
        yield future, result


def _sent(client, value, key: str):
    """``value`` as a Dask future that any worker can compute again (a task returning it, so the
    value is in the graph: a scattered value is lost with the last worker holding it), copied to
    every worker at once: else the scheduler, preferring the worker that holds a task's inputs,
    piles the first tasks onto the one that computed it (measured: 20-40% longer renders)."""
    future = client.submit(_identity, value, key=key, pure=False)
    client.replicate([future])
    return future


def _identity(value):
    return value


def map_tasks(client, function, calls: Sequence[tuple], progress: bool = False) -> list:
    """``function(*call)`` for each of ``calls`` as Dask tasks: the results in the order of
    ``calls``. Scenes and films among the arguments are sent to the workers once each, by content,
    however many tasks take them. Raises ``KeyboardInterrupt`` on Ctrl-C, after cancelling the
    tasks; a task's exception is raised here (an ``InputError`` stays one, a lost cluster is
    ``ClusterLost``)."""
    prefix = f"tracer-{getattr(function, '__name__', 'task')}-{uuid.uuid4().hex}"
    pending: dict[str, Any] = {}
    sent: dict[int, Any] = {}

    def shared(value):
        if not isinstance(value, (Scene, Film)):
            return value
        if id(value) not in sent:
            sent[id(value)] = _sent(client, value, f"{prefix}-input-{len(sent)}")
        return sent[id(value)]

    bar = progress_bar(len(calls), progress, unit="task")
    keys = [f"{prefix}-{index}" for index in range(len(calls))]
    try:
        for key, call in zip(keys, calls, strict=True):
            pending[key] = client.submit(function, *map(shared, call), key=key)
        results: dict[str, Any] = {}
        tracker = _distributed().as_completed(list(pending.values()), with_results=True, raise_errors=False)
        for future, result in _completed(tracker):
            results[future.key] = result
            del pending[future.key]  # its result is here: the workers may let it go
            if bar is not None:
                bar.update(1)
        return [results[key] for key in keys]
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            client.cancel(list(pending.values()))
        raise
    finally:
        close_quietly(bar)


def render_whole(scene: Scene, strategy: Strategy, settings: RenderSettings) -> RenderResult:
    """A task: one whole render on one thread (``render_complete``)."""
    settings = dataclasses.replace(settings, threads=1)
    return render_complete(scene, strategy, settings, estimator=_estimator(scene, strategy))
