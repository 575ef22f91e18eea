"""Renders on Dask's local cluster of 2 worker processes (``tracer.cluster``).

Bit-identity is the contract here (``tracer.merge_tree``, tested without Dask in
test_merge_tree.py): a render pooled from tasks of any size, finished in any order, on workers
that may die, must equal the render in one process bit for bit. Films are compared with
``np.array_equal``, never a tolerance.

The Dask tests skip when ``distributed`` is not installed, unless ``TRACER_CLUSTER_TESTS=required``
(as ``.ci/run`` sets, installing the ``cluster`` extra), where they fail instead.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from test_interrupts import InterruptedFinalizer

from tracer import merge_tree
from tracer import scene as scene_mod
from tracer.imagefiles import read_exr
from tracer.record import format_ranges
from tracer.render_loop import RenderSettings, pass_samples, pooled_into, render
from tracer.strategy import Strategy

from test_merge_tree import same_film, small_scene

REQUIRED = os.environ.get("TRACER_CLUSTER_TESTS") == "required"
ROOT = Path(__file__).resolve().parent.parent


def _distributed():
    try:
        import distributed
    except ImportError:
        if REQUIRED:
            raise
        pytest.skip("Dask's distributed is not installed (pip install '.[cluster]')")
    return distributed


@pytest.fixture(scope="module")
def client():
    _distributed()
    from tracer.cluster import connect

    with connect(workers=2) as dask_client:
        yield dask_client


def test_distributed_reference_is_the_local_one_bit_for_bit(client):
    """render_distributed on 2 worker processes, for two task sizes and the default, equals the
    single-process render of the same seed bit for bit (mean, M2, counts), and its record lists
    the whole sample range once."""
    from tracer.cluster import render_distributed

    scene = small_scene()
    strategy = Strategy("mis")
    k = pass_samples(10**6, 32 * 24, strategy.samples_per_lane)
    settings = RenderSettings(spp=20 * k + 3, seed=3, threads=2)
    local = render(scene, strategy, settings).film
    for task_spp in (k, 4 * k, None):
        result = render_distributed(client, scene, strategy, settings, task_spp=task_spp)
        assert not result.interrupted
        assert same_film(result.film, local), task_spp
        assert result.film.record.samples == ((3, 0, settings.spp),)


def test_distributed_stratified_reference_with_replicates(client):
    """The stratified sampler's replicate means pool along the same tree: bit for bit too."""
    from tracer.cluster import render_distributed

    scene = small_scene()
    settings = RenderSettings(spp=600, seed=2, threads=2, sampler="stratified")
    local = render(scene, Strategy("mis"), settings).film
    got = render_distributed(client, scene, Strategy("mis"), settings, task_spp=128).film
    assert same_film(got, local)


def test_a_worker_killed_mid_render_has_its_tasks_rerun(client):
    """SIGKILL of a worker process while it holds tasks: Dask runs them again on another worker
    with the same sample indices (and computes again any finished film the dead worker held),
    and the image is still the single-process render bit for bit: a sample counted twice or lost
    would change the counts and the means. Dask's task stream shows that every task the victim
    held at the kill was completed by another worker, so the rerun did happen."""
    distributed = _distributed()
    from tracer.cluster import render_distributed

    scene = small_scene(64, 48)
    strategy = Strategy("mis")
    settings = RenderSettings(spp=3000, seed=11, threads=2)
    local = render(scene, strategy, settings).film
    pids = client.run(os.getpid)
    out = {}

    def run():
        out["result"] = render_distributed(client, scene, strategy, settings, task_spp=100)

    with distributed.get_task_stream(client) as stream:
        thread = threading.Thread(target=run)
        thread.start()
        victim, held = None, []
        deadline = time.monotonic() + 60
        while victim is None and time.monotonic() < deadline and thread.is_alive():
            busy = {address: keys for address, keys in client.processing().items()
                    if any("-part-" in str(key) for key in keys)}
            if busy:
                victim, held = next(iter(busy.items()))
                os.kill(pids[victim], signal.SIGKILL)
            else:
                time.sleep(0.01)
        thread.join(180)
    assert victim is not None, "no worker was ever seen rendering"
    assert not thread.is_alive()
    assert same_film(out["result"].film, local)
    assert out["result"].film.record.samples == ((11, 0, 3000),)
    finished_by = {}
    for record in stream.data:
        finished_by.setdefault(str(record["key"]), set()).add(record["worker"])
    for key in map(str, held):
        assert finished_by.get(key, set()) - {victim}, f"{key} was not run again elsewhere"
    client.wait_for_workers(2, timeout=60)
    assert pids[victim] not in client.run(os.getpid).values()


def test_ctrl_c_during_a_distributed_reference_writes_exactly_the_finished_tasks(tmp_path):
    """SIGINT to ``tracer reference --workers 2`` once some tasks are done: exit 130, the EXR
    is written, and it holds exactly the tasks that finished: every pixel holds the samples its
    record lists (no task half in), fewer than asked, and the film is those tasks' nodes rendered
    here and pooled."""
    _distributed()
    scene_path = scene_mod.default_scene_path()
    out = tmp_path / "ref.exr"
    k = pass_samples(10**6, 32 * 24, Strategy("mis").samples_per_lane)
    spp, task_spp = 400 * k, 4 * k
    argv = ["reference", str(scene_path), "--width", "32", "--height", "24", "--spp", str(spp),
            "--workers", "2", "--task-spp", str(task_spp), "--float", "-o", str(out)]
    # A session of its own, and SIGINT to the whole process group, as Ctrl-C at a terminal does:
    # the local cluster's worker processes get it too and must leave it to the driver.
    # SIGINT at its default in the child: a non-interactive shell may start us with it ignored,
    # and Python then keeps it ignored.
    proc = subprocess.Popen([sys.executable, "-m", "tracer", *argv], cwd=tmp_path, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if "tasks done" in line:
            os.killpg(proc.pid, signal.SIGINT)
            break
    rest = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130, "".join(lines) + rest
    film = read_exr(out)
    ranges = film.record.samples
    held = sum(stop - first for _, first, stop in ranges)
    assert 0 < held < spp
    assert np.all(film.count == held)
    # The same nodes, rendered here and pooled along the tree, give the same bits.
    tree = merge_tree.layout(spp, pass_samples(spp, 32 * 24, Strategy("mis").samples_per_lane))

    def held_whole(node):
        first, stop = tree.samples(node)
        return any(a <= first and stop <= b for _, a, b in ranges)

    nodes = [node for node in merge_tree.task_nodes(tree.leaves, task_spp // tree.leaf_spp)
             if held_whole(node)]
    assert sum(b - a for a, b in map(tree.samples, nodes)) == held
    scene = small_scene()
    pool = merge_tree.Pool(tree.leaves, pooled_into)
    settings = RenderSettings(spp=spp, seed=0, threads=2)
    for node in nodes:
        pool.add(node, render(scene, Strategy("mis"), settings, part=node).film)
    # Exactly these samples: the counts agree exactly. The means are the same sums, but a render
    # cut short pools its largest finished nodes in leaf order, which may group them otherwise
    # than the local pool (a merge task not yet run): float64 rounding only (~1e-16 relative), so
    # the 32-bit floats of the file (--float) can differ by at most one unit in the last place,
    # which is at most 2^-23 of the value.
    pooled = pool.result()
    assert np.array_equal(pooled.count, film.count)
    assert np.allclose(pooled.mean.astype(np.float32), film.mean, rtol=2.0**-23, atol=0.0)


def test_cluster_options_without_dask_say_how_to_install(tmp_path, monkeypatch, capsys):
    """Without distributed, --workers is one line naming the extra to install, exit 2."""
    from tracer import cli

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed raises ImportError
    code = cli.main(["reference", str(scene_mod.default_scene_path()), "--workers", "2", "--spp", "8",
                     "-o", str(tmp_path / "r.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and 'pip install "dask[distributed]"' in err[0], err
    assert not (tmp_path / "r.exr").exists()


def test_compare_tasks_give_the_local_comparison(client):
    """Comparison.perform with a client (each strategy, and each seed of a sweep, a task on one
    worker thread) gives the same images, counts and relMSE as the calls run here, in the same
    order: timing differs, numbers of samples do not."""
    from tracer.study.compare import Comparison

    scene = small_scene()
    reference = render(scene, Strategy("mis"), RenderSettings(spp=64, seed=0, threads=2)).film
    comparison = Comparison(scene, reference, seed=1, threads=2)
    calls = [("equal_spp", (Strategy("light"), 16, "independent")),
             ("equal_spp", (Strategy("bsdf"), 16, "stratified"))]
    local, remote = comparison.perform(calls), comparison.perform(calls, client)
    for a, b in zip(local, remote, strict=True):
        assert a.strategy == b.strategy and same_film(a.film, b.film)
        assert a.measures["relmse"] == b.measures["relmse"]
    items = [(Strategy("mis"), "independent")]
    here = comparison.sweeps(items, [1, 2, 3], max_spp=8)
    there = comparison.sweeps(items, [1, 2, 3], max_spp=8, client=client)
    strip = [{k: v for k, v in p.items() if k not in ("seconds", "efficiency")} for p in here]
    assert strip == [{k: v for k, v in p.items() if k not in ("seconds", "efficiency")} for p in there]


def test_check_tasks_measure_what_the_local_check_measures(client):
    """run_check with a client (each entry's seeds as tasks) measures the shipped baseline's
    entry exactly as without: the same per-seed relMSE and variance, the same pooled film."""
    from tracer.study.check import load_baseline, run_check

    baseline = ROOT / "renders" / "noise_baseline.json"
    entries = [e for e in load_baseline(baseline) if e.name == "cornell/light"]
    here = run_check(baseline, stream=None, entries=entries).measurements["cornell/light"]
    there = run_check(baseline, stream=None, entries=entries, client=client).measurements["cornell/light"]
    assert np.array_equal(here.relmse, there.relmse) and np.array_equal(here.variance, there.variance)
    assert same_film(here.pooled, there.pooled)


def test_resume_on_the_cluster_is_the_local_resume(client, tmp_path):
    """``reference --resume --workers``: the grown file is the one a local resume writes, bit for
    bit (pixels and record); a learning strategy is refused with one line before any cluster."""
    from tracer import cli

    scene = str(scene_mod.default_scene_path())
    size = ["--width", "24", "--height", "16", "--float", "--quiet"]
    for name in ("local", "dask"):
        assert cli.main(["reference", scene, "--spp", "64", "-o", str(tmp_path / f"{name}.exr"), *size]) == 0
    resume = ["reference", scene, "--spp", "300", "--resume", *size]
    assert cli.main([*resume, "-o", str(tmp_path / "local.exr")]) == 0
    assert cli.main([*resume, "-o", str(tmp_path / "dask.exr"), "--scheduler", client.scheduler.address]) == 0
    local, dask = read_exr(tmp_path / "local.exr"), read_exr(tmp_path / "dask.exr")
    assert np.array_equal(local.mean, dask.mean) and np.array_equal(local.variance(), dask.variance())
    assert local.record.samples == dask.record.samples == ((0, 0, 364),)
    assert local.record.version == dask.record.version
    assert cli.main(["reference", scene, "--heuristic", "optimal", "--workers", "2", *size,
                     "-o", str(tmp_path / "optimal.exr")]) == 2


# The wait --connect-timeout gives a scheduler in the tests below; a run that fails must end
# within it (plus the seconds Python takes to start), far below the test's own timeout.
CONNECT_SECONDS = 5
HTTP_ANSWER = b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


@pytest.fixture
def tiny_server():
    """tiny_server(answer) -> port of a TCP server on 127.0.0.1 that, for each connection, reads
    once and sends ``answer`` and closes (an HTTP server's refusal), or for None accepts and
    never answers (a silent server). It stops with the test."""
    listeners, held = [], []

    def start(answer: bytes | None) -> int:
        listener = socket.create_server(("127.0.0.1", 0))
        listeners.append(listener)

        def serve():
            while True:
                try:
                    conn, _ = listener.accept()
                except OSError:  # closed by the test's end
                    return
                held.append(conn)
                if answer is not None:
                    with conn:
                        conn.recv(65536)
                        conn.sendall(answer)

        threading.Thread(target=serve, daemon=True).start()
        return listener.getsockname()[1]

    yield start
    for sock in listeners + held:
        sock.close()


def _run_tracer(argv, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tracer", *argv], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize("server, scheme, words", [
    ("http", "tcp", "does not answer in Dask's protocol"),
    ("silent", "tcp", "gave no answer in Dask's protocol within 5 s"),
    ("http", "tls", "needs Dask's TLS settings"),
    ("http", "ucx", "not an address of a Dask scheduler tracer can reach"),
])
def test_a_scheduler_address_that_is_no_dask_scheduler_is_one_line(tmp_path, tiny_server, server, scheme,
                                                                   words):
    """``--scheduler`` at an HTTP server (whose answer Dask read as a frame of 3 EiB: a numpy
    MemoryError), a server that accepts and never answers (Dask's handshake waited past 100 s),
    and tls:// without TLS settings and ucx:// (Dask raised TypeError): one line naming the
    address and what is wrong, exit 2, within the connect timeout, and no file."""
    _distributed()
    port = tiny_server(HTTP_ANSWER if server == "http" else None)
    address = f"{scheme}://127.0.0.1:{port}"
    out = tmp_path / "ref.exr"
    started = time.monotonic()
    proc = _run_tracer(["reference", str(scene_mod.default_scene_path()), "--scheduler", address,
                        "--connect-timeout", str(CONNECT_SECONDS), "--spp", "4", "--width", "8",
                        "--height", "8", "-o", str(out)], timeout=CONNECT_SECONDS + 60)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("tracer: error: --scheduler: ") and address in lines[0], lines
    assert words in lines[0] and "Traceback" not in proc.stderr, lines
    assert time.monotonic() - started < CONNECT_SECONDS + 30, "it did not end within the connect timeout"
    assert not out.exists()


def test_a_workers_address_is_refused_as_not_the_scheduler(client, tmp_path, capsys):
    """A worker answers Dask's handshake too: its address is refused in one line saying so."""
    from tracer import cli

    worker = next(iter(client.scheduler_info()["workers"]))
    code = cli.main(["reference", str(scene_mod.default_scene_path()), "--scheduler", worker,
                     "--connect-timeout", str(CONNECT_SECONDS), "--spp", "4", "-o", str(tmp_path / "r.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "is a Dask worker, not a Dask scheduler" in err[0], err


def test_tasks_smaller_than_a_leaf_give_the_local_render_bit_for_bit(client, monkeypatch):
    """With leaves of 4 passes (MAX_LEAVES lowered to 4, here and on the workers, as a render of
    2^40 spp has leaves of 2^25 passes), tasks of 1 and 3 passes are segments of a leaf, each
    continuing the film of the one before: the render equals the local one bit for bit, and its
    record lists the whole range once."""
    from tracer.cluster import render_distributed

    scene = small_scene()
    strategy = Strategy("mis")
    k = pass_samples(10**6, 32 * 24, strategy.samples_per_lane)
    settings = RenderSettings(spp=12 * k + 5, seed=4, threads=2)  # 13 passes: leaves of 4, 4, 4, 1
    monkeypatch.setattr(merge_tree, "MAX_LEAVES", 4)
    client.run(setattr, merge_tree, "MAX_LEAVES", 4)
    try:
        local = render(scene, strategy, settings).film
        for task_spp in (k, 3 * k):
            result = render_distributed(client, scene, strategy, settings, task_spp=task_spp)
            assert not result.interrupted
            assert same_film(result.film, local), task_spp
            assert result.film.record.samples == ((4, 0, settings.spp),)
    finally:
        client.run(setattr, merge_tree, "MAX_LEAVES", 4096)


def test_an_interrupt_dropped_while_the_driver_waits_still_stops_the_render(client, monkeypatch):
    """SIGINT landing in a finalizer while the driver waits for tasks (a Dask future's finalizer
    runs there when the driver lets a film go): Python drops the KeyboardInterrupt, but the
    driver's next poll sees the recorded signal, cancels the rest and keeps the finished tasks."""
    from tracer import cluster, interrupts

    scene = small_scene()
    strategy = Strategy("mis")
    k = pass_samples(10**6, 32 * 24, strategy.samples_per_lane)
    settings = RenderSettings(spp=400 * k, seed=5, threads=2)
    logged = cluster._ProgressLog.finished

    def finished_then_finalize(self, spp):
        logged(self, spp)
        if self.done == 1:
            InterruptedFinalizer()

    monkeypatch.setattr(cluster._ProgressLog, "finished", finished_then_finalize)
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", lambda report: dropped.append(report.exc_type))
    with interrupts.watching():
        result = cluster.render_distributed(client, scene, strategy, settings, task_spp=4 * k)
    assert KeyboardInterrupt in dropped
    assert result.interrupted and 0 < result.film.spp < settings.spp


# CI budget: 120 s by design (default-size tasks take about 13 s each); the smaller interrupt
# tests of this module keep the finished-task rule in every run.
@pytest.mark.slow
def test_ctrl_c_of_a_huge_distributed_reference_keeps_finished_tasks(tmp_path):
    """``reference --spp 2^40 --workers 2`` with the default task size: leaves of 2^21 passes, so
    tasks are segments of them of at most cluster.TASK_RAYS rays (seconds each), and SIGINT once
    the program says a task is done keeps them: exit 130, the EXR is written, and its header's
    sample ranges are those the message says were kept, each from the start of a leaf. Before,
    a default task was 512 leaves (2^30 spp here) and an interrupt kept nothing."""
    _distributed()
    out = tmp_path / "ref.exr"
    spp = 2**40
    argv = ["reference", str(scene_mod.default_scene_path()), "--width", "16", "--height", "16",
            "--spp", str(spp), "--workers", "2", "--float", "-o", str(out)]
    proc = subprocess.Popen([sys.executable, "-m", "tracer", *argv], cwd=tmp_path, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr] + [lines.put(None)],
                     daemon=True).start()
    said = []
    try:
        # Generous for a loaded machine (and workers that load the kernels from the cache): a
        # task takes about 13 s on one idle thread.
        deadline = time.monotonic() + 300
        while not any("tasks done" in line for line in said):
            line = lines.get(timeout=max(1.0, deadline - time.monotonic()))
            assert line is not None, "".join(said)
            said.append(line)
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=120)
        while (line := lines.get(timeout=30)) is not None:
            said.append(line)
    finally:
        if proc.poll() is None:  # the test failed: leave no render running
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = "".join(said)
    assert proc.returncode == 130, err
    kept = re.search(r"kept samples (\S+) as seed:first-last", err)
    assert kept, err
    film = read_exr(out)
    assert format_ranges(film.record.samples) == kept.group(1)
    held = sum(stop - first for _, first, stop in film.record.samples)
    assert 0 < held < spp and np.all(film.count == held)
    assert f"every pixel holds {held} spp" in err, err
    tree = merge_tree.layout(spp, pass_samples(spp, 16 * 16, Strategy("mis").samples_per_lane))
    assert all(first % tree.leaf_spp == 0 for _, first, _ in film.record.samples), film.record.samples


def test_a_worker_started_again_still_leaves_ctrl_c_to_the_driver(client):
    """A local cluster's worker killed and started again by its nanny ignores SIGINT, as the
    first workers do: before, it was spawned under the driver's handler, and the next Ctrl-C at
    the terminal (sent to the whole process group) killed it with a traceback ("Process Dask
    Worker process (from Nanny)") and lost the finished films it held ("nothing written")."""
    pids = client.run(os.getpid)
    victim, pid = next(iter(pids.items()))
    os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + 120
    while True:
        # The nanny starts the worker again, which runs its callbacks right after joining: a
        # poll, skipping a worker that is not there (yet, or any more).
        now = client.run(os.getpid, on_error="ignore")
        # A bool: a handler itself may not pickle (asyncio's runner installs a partial).
        ignored = client.run(lambda: signal.getsignal(signal.SIGINT) == signal.SIG_IGN, on_error="ignore")
        if len(now) == 2 and pid not in now.values() and all(ignored.values()):
            break
        assert time.monotonic() < deadline, f"workers {now}, SIGINT ignored {ignored}"
        time.sleep(0.05)
    client.wait_for_workers(2, timeout=60)
