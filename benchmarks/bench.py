"""Performance benchmark of tracer: its own speed, its embreex ceiling, and Mitsuba 3 (issue 5).

    python benchmarks/bench.py [--scenes veach_mis,cornell] [--size 512] [--spp 64] [--runs 3]
                               [--threads 2] [--out benchmarks/results]
                               [--mitsuba-python PYTHON | --no-mitsuba]

For each scene, at SIZE x SIZE pixels and SPP samples per pixel, it measures

- every strategy's render wall time with ``--threads`` threads (scene loading and the Embree
  build excluded, a 1-spp warm-up render first), samples per second, and peak memory: each
  configuration runs in its own spawned process, so its peak RSS is its own;
- the embreex ceiling, measured: an untimed render with a recording ray caster stores every
  ray tracer casts (camera, shadow and BSDF rays, float32, batch by batch), then the same
  rays are cast again straight through embreex, with the same batches and threads, and only
  that replay is timed. tracer's time over that is the ratio the targets talk about;
- MIS with 1 thread against ``--threads`` threads, for tracer and for the embreex replay;
- when Mitsuba 3 is available (``--mitsuba-python``, default /work/venv-xcheck/bin/python,
  else this interpreter if it imports mitsuba), its ``direct`` integrator on the same scene,
  resolution and spp, one emitter and one BSDF sample, box filter, in scalar_rgb and
  llvm_ad_rgb, with all of Mitsuba's threads (its default). The first render of each variant
  is a warm-up (it JIT-compiles llvm kernels) and is reported apart.

Every timing is the median of ``--runs`` runs with seed 0, so that the replayed rays are
exactly the timed render's rays. Writes OUT/bench.json (all numbers, all runs, the machine)
and OUT/bench.md, prints the Markdown and the machine, and logs progress on stderr. With the
defaults it takes about 11 minutes on 2 cores. Timing lives here, never in the tests.

Nothing from tracer is imported at module level: the Mitsuba child runs this same file with
Mitsuba's interpreter, which has neither tracer nor embreex.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_MITSUBA_PYTHON = Path("/work/venv-xcheck/bin/python")
MITSUBA_VARIANTS = ("scalar_rgb", "llvm_ad_rgb")
RAY_KINDS = ("camera", "shadow", "bsdf")
SEED = 0

# The targets, checked on this scene with MIS (power heuristic, 1 light + 1 BSDF sample):
# issue 5's, with issue 34's (part 4, "default speed") in place of its ceiling ratio (1.3)
# and Mitsuba llvm speed (0.6).
TARGET_SCENE = "veach_mis"
TARGET_SIZE, TARGET_SPP, TARGET_THREADS = 512, 64, 2
MAX_CEILING_RATIO = 1.6
MIN_SPEEDUP_SCALAR = 1.5
MIN_SPEEDUP_LLVM = 1.2
MIN_THREAD_SCALING = 1.7


def log(message: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def peak_rss_mib() -> float:
    # ru_maxrss is in KiB on Linux.
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def cpu_seconds() -> float:
    """User + system CPU time of this process, all threads: over a wall time, the cores it kept
    busy (on a shared machine, fewer than asked says the cores were not all ours)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def tracer_digest() -> str:
    """A short hash of tracer's sources as this process sees them. tracer is installed editable
    and may be edited while the benchmark runs: differing digests say which numbers are from
    which code."""
    import hashlib

    import tracer

    root = Path(tracer.__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:12]


def run_in_child(fn, *args):
    """``fn(*args)`` in a fresh spawned process: peak RSS and timings of one configuration
    are not polluted by earlier ones (numpy's and Embree's freed memory stays mapped)."""
    with ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


# ---------------------------------------------------------------------------------------------
# tracer, timed (runs in a child)

def time_tracer(scene_path: str, size: int, spp: int, strategy: str, threads: int, runs: int) -> dict:
    """Median wall time of ``runs`` renders of one strategy; also setup time and peak RSS."""
    digest = tracer_digest()
    from tracer.estimator import DirectLighting
    from tracer.render_loop import RenderSettings, render
    from tracer.scene import load_scene
    from tracer.strategy import Strategy

    start = time.perf_counter()
    scene = load_scene(scene_path, size, size)
    estimator = DirectLighting(scene, Strategy(strategy))
    setup = time.perf_counter() - start
    # A cheap first render takes the one-time costs (lazy imports, first page faults) out of
    # the timed ones, as Mitsuba's warm-up does for its JIT.
    render(scene, estimator.strategy, RenderSettings(spp=1, seed=SEED, threads=threads), estimator=estimator)
    times, cores = [], []
    for run in range(runs):
        start, cpu = time.perf_counter(), cpu_seconds()
        result = render(scene, estimator.strategy, RenderSettings(spp=spp, seed=SEED, threads=threads),
                        estimator=estimator)
        times.append(time.perf_counter() - start)
        cores.append((cpu_seconds() - cpu) / times[-1])
        if result.interrupted or result.samples != size * size * spp:
            raise RuntimeError(f"{strategy}: render incomplete ({result.samples} samples)")
        log(f"  tracer {scene.name} {strategy} {threads}T run {run + 1}/{runs}: {times[-1]:.2f} s")
    return {"seconds": statistics.median(times), "runs": times, "cores_busy": statistics.median(cores),
            "setup_seconds": setup, "triangles": int(len(scene.faces)), "peak_rss_mib": peak_rss_mib(),
            "tracer_digest": digest}


# ---------------------------------------------------------------------------------------------
# The embreex ceiling: record tracer's rays, replay them through embreex alone (in a child)

@dataclass
class Call:
    """One embreex query as tracer made it: float32 arrays; tmax for shadow rays, and for
    closest hits in scenes with analytic spheres (up to the nearest one)."""

    kind: str
    origins: object
    dirs: object
    tmax: object = None


def _recording_classes():
    """The recording caster and estimator, defined lazily because they subclass tracer's."""
    import numpy as np

    from tracer.embree import RayCaster
    from tracer.estimator import DirectLighting

    class RecordingCaster(RayCaster):
        """Casts like RayCaster and keeps a float32 copy of every query, batch by batch.

        Each render thread fills its own batch (thread-local, in call order); a finished batch
        joins the shared list under a lock. In a batch, the first closest-hit call is the
        camera rays, later ones are BSDF (direction) rays, occluded calls are shadow rays.
        """

        def __init__(self, vertices, faces):
            super().__init__(vertices, faces)
            self._local = threading.local()
            self._lock = threading.Lock()
            self.batches: list[list[Call]] = []

        def begin_batch(self) -> None:
            self._local.calls = []

        def end_batch(self) -> None:
            with self._lock:
                self.batches.append(self._local.calls)
            self._local.calls = None

        def _record(self, kind: str, origins, dirs, tmax=None) -> None:
            calls = getattr(self._local, "calls", None)
            if calls is None:
                raise RuntimeError("a ray query outside DirectLighting.shade_lanes: tracer's render loop "
                                   "changed, update benchmarks/bench.py")
            if len(origins) == 0:  # RayCaster does not call Embree for an empty query
                return
            if kind == "closest":
                kind = "bsdf" if any(c.kind in ("camera", "bsdf") for c in calls) else "camera"
            # The same float32 conversion RayCaster makes, so Embree sees identical rays.
            calls.append(Call(kind, np.array(origins, dtype=np.float32), np.array(dirs, dtype=np.float32),
                              None if tmax is None else np.array(tmax, dtype=np.float32)))

        def first_hit(self, origins, dirs, tmax=None):
            self._record("closest", origins, dirs, tmax)
            return super().first_hit(origins, dirs, tmax)

        def intersect(self, origins, dirs):
            raise RuntimeError("DirectLighting called RayCaster.intersect: tracer's render loop "
                               "changed, update benchmarks/bench.py")

        def occluded(self, origins, dirs, tmax):
            self._record("shadow", origins, dirs, tmax)
            return super().occluded(origins, dirs, tmax)

    class RecordingEstimator(DirectLighting):
        """DirectLighting whose shade_lanes() (one call per render batch) brackets a batch."""

        def shade_lanes(self, *args, **kwargs):
            self.caster.begin_batch()
            try:
                return super().shade_lanes(*args, **kwargs)
            finally:
                self.caster.end_batch()

    return RecordingCaster, RecordingEstimator


def replay(embree_scene, batches: list[list[Call]], threads: int) -> tuple[float, dict[str, float]]:
    """Cast the recorded batches through embreex with ``threads`` threads, as render() would.

    Returns the wall time and, per ray kind, the thread-seconds spent inside embreex's run().
    The queries are exactly RayCaster's: closest hit returning the triangle ids only
    (``first_hit``), occlusion with a fresh ``dists`` array (embreex overwrites it).
    """
    import numpy as np

    # Fresh tmax copies are made before the clock starts: the copy is tracer's cost, not Embree's.
    dists = [[None if c.tmax is None else np.array(c.tmax) for c in batch] for batch in batches]

    def cast(index: int) -> dict[str, float]:
        spent = dict.fromkeys(RAY_KINDS, 0.0)
        for call, tmax in zip(batches[index], dists[index], strict=True):
            start = time.perf_counter()
            if call.kind == "shadow":
                embree_scene.run(call.origins, call.dirs, dists=tmax, query="OCCLUDED")
            elif tmax is None:
                embree_scene.run(call.origins, call.dirs)
            else:  # a closest hit up to the nearest analytic sphere (SceneRays.first_hit)
                embree_scene.run(call.origins, call.dirs, dists=tmax)
            spent[call.kind] += time.perf_counter() - start
        return spent

    start = time.perf_counter()
    if threads == 1:  # render() runs batches in the calling thread too
        parts = [cast(i) for i in range(len(batches))]
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            parts = list(pool.map(cast, range(len(batches))))
    seconds = time.perf_counter() - start
    return seconds, {k: sum(p[k] for p in parts) for k in RAY_KINDS}


def measure_ceiling(scene_path: str, size: int, spp: int, strategy: str, thread_counts: list[int],
                    runs: int) -> dict:
    """Record one render's rays (untimed), then time ``runs`` replays for each thread count."""
    digest = tracer_digest()
    from tracer.embree import RayCaster
    from tracer.render_loop import RenderSettings, render
    from tracer.scene import load_scene
    from tracer.strategy import Strategy

    recording_caster, recording_estimator = _recording_classes()
    scene = load_scene(scene_path, size, size)
    caster = recording_caster(scene.vertices, scene.faces)
    estimator = recording_estimator(scene, Strategy(strategy), caster=caster)
    start = time.perf_counter()
    render(scene, estimator.strategy, RenderSettings(spp=spp, seed=SEED, threads=thread_counts[0]),
           estimator=estimator)
    record_seconds = time.perf_counter() - start
    batches = caster.batches
    rays = dict.fromkeys(RAY_KINDS, 0)
    calls = dict.fromkeys(RAY_KINDS, 0)
    recorded_bytes = 0
    for call in (c for batch in batches for c in batch):
        rays[call.kind] += len(call.origins)
        calls[call.kind] += 1
        recorded_bytes += sum(a.nbytes for a in (call.origins, call.dirs, call.tmax) if a is not None)
    if rays["camera"] != size * size * spp:  # one camera call per batch, or the batching changed
        raise RuntimeError(f"recorded {rays['camera']} camera rays, expected {size * size * spp}: "
                           "tracer's render loop changed, update benchmarks/bench.py")
    log(f"  recorded {scene.name} {strategy}: {sum(rays.values()) / 1e6:.1f} M rays in {len(batches)} "
        f"batches, {recorded_bytes / 2**20:.0f} MiB, {record_seconds:.1f} s")
    del caster, estimator  # only the recorded arrays are needed now

    # A fresh caster over the same scene, built (first query) before any thread starts.
    fresh = RayCaster(scene.vertices, scene.faces)
    embree_scene = fresh._scene  # the embreex scene itself: the replay bypasses tracer's wrapper
    by_threads = {}
    for threads in thread_counts:
        times, kind_seconds, cores = [], [], []
        for run in range(runs):
            cpu = cpu_seconds()
            seconds, spent = replay(embree_scene, batches, threads)
            times.append(seconds)
            cores.append((cpu_seconds() - cpu) / seconds)
            kind_seconds.append(spent)
            log(f"  embreex replay {scene.name} {strategy} {threads}T run {run + 1}/{runs}: {seconds:.2f} s")
        median = statistics.median(times)
        # The per-kind split of the run closest to the median (thread-seconds inside run()).
        split = kind_seconds[min(range(runs), key=lambda i: abs(times[i] - median))]
        by_threads[str(threads)] = {"seconds": median, "runs": times, "cores_busy": statistics.median(cores),
                                    "thread_seconds_by_kind": split,
                                    "rays_per_second": sum(rays.values()) / median}
    return {"rays": rays, "calls": calls, "batches": len(batches), "recorded_mib": recorded_bytes / 2**20,
            "record_seconds": record_seconds, "threads": by_threads, "peak_rss_mib": peak_rss_mib(),
            "tracer_digest": digest}


# ---------------------------------------------------------------------------------------------
# Mitsuba 3 (runs in a child process with Mitsuba's interpreter: this file with --mitsuba-child)

def mitsuba_child(spec: dict) -> dict:
    """Time Mitsuba's ``direct`` integrator on one scene in one variant: a warm-up render,
    then ``runs`` timed renders, each converted to numpy so that the LLVM kernel has run."""
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    sys.path.insert(0, str(HERE))
    import mitsuba_scene

    mi.set_variant(spec["variant"])
    start = time.perf_counter()
    scene = mi.load_dict(mitsuba_scene.load_mitsuba_scene(
        spec["scene"], spp=spec["spp"], seed=SEED, width=spec["size"], height=spec["size"],
        emitter_samples=1, bsdf_samples=1))
    setup = time.perf_counter() - start

    def one_render(seed: int) -> tuple[float, float]:
        start, cpu = time.perf_counter(), cpu_seconds()
        image = np.array(mi.render(scene, seed=seed, spp=spec["spp"]))
        seconds = time.perf_counter() - start
        if image.shape[:2] != (spec["size"], spec["size"]) or not np.all(np.isfinite(image)):
            raise RuntimeError(f"unexpected Mitsuba image {image.shape}")
        return seconds, (cpu_seconds() - cpu) / seconds

    warmup, _ = one_render(SEED)
    # Seeds differ between runs so no cache could serve a repeated render (the LLVM kernel is
    # reused all the same: the seed is not baked into it).
    times, cores = [], []
    for run in range(spec["runs"]):
        seconds, busy = one_render(SEED + 1 + run)
        times.append(seconds)
        cores.append(busy)
        log(f"  mitsuba {spec['variant']} run {run + 1}/{spec['runs']}: {times[-1]:.2f} s")
    return {"variant": spec["variant"], "seconds": statistics.median(times), "runs": times,
            "cores_busy": statistics.median(cores),
            "warmup_seconds": warmup, "setup_seconds": setup, "threads": int(dr.thread_count()),
            "peak_rss_mib": peak_rss_mib(), "mitsuba_version": mi.__version__,
            "drjit_version": dr.__version__}


def find_mitsuba_python(requested: str | None) -> tuple[str | None, str]:
    """An interpreter that imports mitsuba, and a note saying which (or why none)."""
    candidates = [requested] if requested else [str(DEFAULT_MITSUBA_PYTHON), sys.executable]
    for python in candidates:
        if not python or not Path(python).exists():
            continue
        probe = subprocess.run([python, "-c", "import mitsuba, drjit"], capture_output=True, text=True)
        if probe.returncode == 0:
            return python, f"run with {python}"
    return None, f"Mitsuba skipped: none of {candidates} imports mitsuba"


def run_mitsuba(python: str, scene_path: str, size: int, spp: int, runs: int, variant: str) -> dict:
    """One variant in its own process (own peak RSS); errors are reported, not raised."""
    spec = {"scene": scene_path, "size": size, "spp": spp, "runs": runs, "variant": variant}
    proc = subprocess.run([python, str(Path(__file__).resolve()), "--mitsuba-child", json.dumps(spec)],
                          stdout=subprocess.PIPE, stderr=None, text=True)
    if proc.returncode != 0:
        return {"variant": variant, "error": f"exit status {proc.returncode} (see stderr above)"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------------------------
# Machine, files, report

def machine_info() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    def meminfo_gib() -> float | None:
        try:
            with open("/proc/meminfo") as f:
                for line in f:
                    if line.startswith("MemTotal:"):
                        return int(line.split()[1]) / 2**20
        except OSError:
            pass
        return None

    def cpu_model() -> str:
        try:
            with open("/proc/cpuinfo") as f:
                for line in f:
                    if line.startswith("model name"):
                        return line.split(":", 1)[1].strip()
        except OSError:
            pass
        return platform.processor() or platform.machine()

    def package(name: str) -> str | None:
        try:
            return version(name)
        except PackageNotFoundError:
            return None

    def git(*args: str) -> str | None:
        proc = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True)
        return proc.stdout.strip() if proc.returncode == 0 else None

    status = git("status", "--porcelain", "--", "tracer")
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "usable_cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "memory_gib": meminfo_gib(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": package("numpy"),
        "embreex": package("embreex"),
        "tracer": package("tracer"),
        # The tracer code measured: the commit, and whether tracer/ had uncommitted changes.
        "git_commit": git("rev-parse", "--short", "HEAD"),
        "tracer_digest": tracer_digest(),
        "tracer_dirty": bool(status) if status is not None else None,
        "load_average_at_start": os.getloadavg(),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def resolve_scene(name: str) -> Path:
    """A scene name (``scenes/NAME.toml``, or tracer's packaged copy) or a path to a .toml."""
    if name.endswith(".toml"):
        return Path(name).resolve()
    path = REPO / "scenes" / f"{name}.toml"
    if path.exists():
        return path
    from tracer.scene import default_scene_path

    return default_scene_path().parent / f"{name}.toml"


def targets(results: dict, settings: dict) -> list[dict]:
    """The targets, each with its measured value and whether it is met (None: not measured)."""
    scene = results["scenes"].get(TARGET_SCENE)
    if scene is None:
        return []
    mis = scene["strategies"]["mis"]
    rows = [{"target": f"MIS total time / embreex ceiling for the same rays ({settings['threads']} threads)",
             "required": f"<= {MAX_CEILING_RATIO}", "measured": mis["ratio"],
             "met": mis["ratio"] <= MAX_CEILING_RATIO}]
    for variant, bound in (("scalar_rgb", MIN_SPEEDUP_SCALAR), ("llvm_ad_rgb", MIN_SPEEDUP_LLVM)):
        m = scene.get("mitsuba", {}).get(variant, {})
        speed = m.get("tracer_speedup")
        rows.append({"target": f"speed relative to Mitsuba 3 {variant} (its time / tracer MIS time)",
                     "required": f">= {bound}", "measured": speed,
                     "met": None if speed is None else speed >= bound})
    scaling = scene["thread_scaling"]["tracer_speedup"]
    rows.append({"target": f"MIS speed-up from 1 to {settings['threads']} threads",
                 "required": f">= {MIN_THREAD_SCALING}", "measured": scaling,
                 "met": scaling >= MIN_THREAD_SCALING})
    worst = max((name for name in scene["strategies"] if name != "mis"),
                key=lambda name: scene["strategies"][name]["seconds"], default=None)
    if worst is not None:
        relative = scene["strategies"][worst]["seconds"] / mis["seconds"]
        rows.append({"target": f"other strategies' time per sample / MIS's (worst: {worst})",
                     "required": "<= 1", "measured": relative, "met": relative <= 1.0})
    at_spec = (settings["size"], settings["spp"], settings["threads"]) == (TARGET_SIZE, TARGET_SPP,
                                                                             TARGET_THREADS)
    for row in rows:
        row["at_spec_settings"] = at_spec
    return rows


def _digests(tree) -> list[str]:
    """Every tracer source digest recorded anywhere in the results."""
    if isinstance(tree, dict):
        return [v for k, v in tree.items() if k == "tracer_digest"] + \
            [d for k, v in tree.items() if k != "tracer_digest" for d in _digests(v)]
    return []


def _num(value, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def markdown(results: dict) -> str:
    s, m = results["settings"], results["machine"]
    threads = s["threads"]
    samples = s["size"] * s["size"] * s["spp"]
    lines = [
        "# tracer benchmark",
        "",
        f"{m['date']}. Machine: {m['cpu']}, {m['cores']} cores, {_num(m['memory_gib'], 1)} GiB; "
        f"Python {m['python']}, numpy {m['numpy']}, embreex {m['embreex']}; tracer at {m['git_commit']}"
        f"{' (tracer/ modified)' if m['tracer_dirty'] else ''} (sources {m['tracer_digest']}); "
        f"1-minute load average {m['load_average_at_start'][0]:.2f} at start, "
        f"{results['load_average_at_end'][0]:.2f} at end.",
        "",
        f"{s['size']}x{s['size']}, {s['spp']} spp ({samples / 1e6:.1f} M samples), seed {SEED}, median of "
        f"{s['runs']} runs; tracer with {threads} threads, render() wall time after a 1-spp warm-up "
        "(scene loading and Embree build excluded). The embreex ceiling replays the very rays of the "
        "render through embreex alone, same batches and threads; ratio = tracer / ceiling. Peak MiB: "
        "peak RSS of a process that only ran that configuration. Cores busy: CPU time / wall time "
        "of the timed runs (below the thread count when the cores are shared or threads wait).",
    ]
    changed = [d for d in results["tracer_digests"] if d != m["tracer_digest"]]
    if changed:
        lines += ["", f"**tracer/ changed while the benchmark ran**: some configurations ran other sources "
                  f"({', '.join(changed)}); each result's `tracer_digest` in bench.json says which."]
    for name, scene in results["scenes"].items():
        mis_seconds = scene["strategies"]["mis"]["seconds"] if "mis" in scene["strategies"] else None
        lines += ["", f"## {name} ({scene['triangles']} triangles)", "",
                  "| strategy | seconds | M samples/s | embreex ceiling s | ratio | peak MiB | cores busy |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for strategy, r in scene["strategies"].items():
            lines.append(f"| {strategy} | {r['seconds']:.2f} | {samples / r['seconds'] / 1e6:.2f} | "
                         f"{r['ceiling_seconds']:.2f} | {r['ratio']:.2f} | {r['peak_rss_mib']:.0f} | "
                         f"{r['cores_busy']:.2f} |")
        lines += ["", "Rays cast (millions), embreex alone on them, thread-seconds inside embreex by kind:",
                  "", "| strategy | camera | shadow | BSDF | embreex M rays/s | camera s | shadow s "
                  "| BSDF s |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for strategy, r in scene["strategies"].items():
            c = r["ceiling"]
            rays, ceil = c["rays"], c["threads"][str(threads)]
            split = ceil["thread_seconds_by_kind"]
            lines.append(f"| {strategy} | " + " | ".join(f"{rays[k] / 1e6:.2f}" for k in RAY_KINDS)
                         + f" | {ceil['rays_per_second'] / 1e6:.1f} | "
                         + " | ".join(f"{split[k]:.2f}" for k in RAY_KINDS) + " |")
        ts = scene["thread_scaling"]
        lines += ["", "Thread scaling (MIS):", "",
                  f"| | 1 thread s | {threads} threads s | speed-up | cores busy ({threads} threads) |",
                  "|---|---:|---:|---:|---:|",
                  f"| tracer | {ts['tracer_1']:.2f} | {ts['tracer_n']:.2f} | {ts['tracer_speedup']:.2f} | "
                  f"{ts['tracer_n_cores_busy']:.2f} |",
                  f"| embreex alone, same rays | {ts['embreex_1']:.2f} | {ts['embreex_n']:.2f} | "
                  f"{ts['embreex_speedup']:.2f} | {ts['embreex_n_cores_busy']:.2f} |"]
        if scene.get("mitsuba"):
            lines += ["", f"Mitsuba 3 `direct` (1 emitter + 1 BSDF sample, power heuristic, box filter), "
                      f"all its threads; speed-up = Mitsuba seconds / tracer MIS seconds "
                      f"({_num(mis_seconds)} s):", "",
                      "| variant | threads | warm-up s | seconds | M samples/s | peak MiB | cores busy "
                      "| tracer speed-up |",
                      "|---|---:|---:|---:|---:|---:|---:|---:|"]
            for variant, r in scene["mitsuba"].items():
                if "error" in r:
                    lines.append(f"| {variant} | failed: {r['error']} | | | | | | |")
                    continue
                lines.append(f"| {variant} | {r['threads']} | {r['warmup_seconds']:.2f} | "
                             f"{r['seconds']:.2f} | {samples / r['seconds'] / 1e6:.2f} | "
                             f"{r['peak_rss_mib']:.0f} | {r['cores_busy']:.2f} | "
                             f"{_num(r['tracer_speedup'])} |")
    versions = f" {m['mitsuba']} (Dr.Jit {m['drjit']})" if "mitsuba" in m else ""
    lines += ["", f"Mitsuba 3{versions}: {results['mitsuba_note']}."]
    if results["targets"]:
        at_spec = results["targets"][0]["at_spec_settings"]
        lines += ["", f"## Targets ({TARGET_SCENE}, MIS"
                  + ("" if at_spec else f"; measured at {s['size']}x{s['size']}, {s['spp']} spp, {threads} "
                     f"threads, not the spec's {TARGET_SIZE}x{TARGET_SIZE}, {TARGET_SPP} spp, "
                     f"{TARGET_THREADS} threads") + ")", "",
                  "| target | required | measured | met |", "|---|---:|---:|---|"]
        for t in results["targets"]:
            met = "not measured" if t["met"] is None else ("met" if t["met"] else "**not met**")
            lines.append(f"| {t['target']} | {t['required']} | {_num(t['measured'])} | {met} |")
    lines += ["", f"Whole benchmark: {results['total_seconds'] / 60:.1f} min.", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------

def bench_scene(name: str, args, strategies: tuple[str, ...], mitsuba_python: str | None) -> dict:
    scene_path = str(resolve_scene(name))
    size, spp, runs, threads = args.size, args.spp, args.runs, args.threads
    out: dict = {"path": scene_path, "strategies": {}}
    for strategy in strategies:
        log(f"{name}: {strategy}, tracer with {threads} threads")
        timed = run_in_child(time_tracer, scene_path, size, spp, strategy, threads, runs)
        log(f"{name}: {strategy}, recording the rays and replaying them through embreex")
        # MIS's replay is also timed with 1 thread, for embreex's own thread scaling.
        counts = [threads, 1] if strategy == "mis" and threads != 1 else [threads]
        ceiling = run_in_child(measure_ceiling, scene_path, size, spp, strategy, counts, runs)
        ceiling_seconds = ceiling["threads"][str(threads)]["seconds"]
        out["triangles"] = timed["triangles"]
        out["strategies"][strategy] = {
            "seconds": timed["seconds"], "runs": timed["runs"], "cores_busy": timed["cores_busy"],
            "setup_seconds": timed["setup_seconds"], "tracer_digest": timed["tracer_digest"],
            "samples_per_second": size * size * spp / timed["seconds"], "peak_rss_mib": timed["peak_rss_mib"],
            "ceiling_seconds": ceiling_seconds, "ratio": timed["seconds"] / ceiling_seconds,
            "ceiling": ceiling}
        log(f"{name}: {strategy}: {timed['seconds']:.2f} s, ceiling {ceiling_seconds:.2f} s, "
            f"ratio {timed['seconds'] / ceiling_seconds:.2f}, peak {timed['peak_rss_mib']:.0f} MiB")

    if "mis" in out["strategies"]:
        mis = out["strategies"]["mis"]
        if threads == 1:
            one = mis
        else:
            log(f"{name}: mis, tracer with 1 thread")
            one = run_in_child(time_tracer, scene_path, size, spp, "mis", 1, runs)
        embreex = mis["ceiling"]["threads"]
        out["thread_scaling"] = {
            "tracer_1": one["seconds"], "tracer_n": mis["seconds"], "tracer_1_runs": one["runs"],
            "tracer_1_cores_busy": one["cores_busy"], "tracer_digest": one["tracer_digest"],
            "tracer_speedup": one["seconds"] / mis["seconds"], "tracer_n_cores_busy": mis["cores_busy"],
            "embreex_n_cores_busy": embreex[str(threads)]["cores_busy"],
            "embreex_1": embreex["1"]["seconds"], "embreex_n": embreex[str(threads)]["seconds"],
            "embreex_speedup": embreex["1"]["seconds"] / embreex[str(threads)]["seconds"]}

    if mitsuba_python:
        out["mitsuba"] = {}
        for variant in MITSUBA_VARIANTS:
            log(f"{name}: Mitsuba 3 {variant}")
            r = run_mitsuba(mitsuba_python, scene_path, size, spp, runs, variant)
            if "error" not in r and "mis" in out["strategies"]:
                r["tracer_speedup"] = r["seconds"] / out["strategies"]["mis"]["seconds"]
            out["mitsuba"][variant] = r
            if "error" not in r:
                log(f"{name}: Mitsuba {variant}: {r['seconds']:.2f} s (warm-up {r['warmup_seconds']:.2f} s)")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="veach_mis,cornell",
                        help="comma-separated scene names (scenes/NAME.toml) or .toml paths")
    parser.add_argument("--size", type=int, default=TARGET_SIZE, help="width and height in pixels")
    parser.add_argument("--spp", type=int, default=TARGET_SPP, help="samples per pixel")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per configuration (median)")
    parser.add_argument("--threads", type=int, default=TARGET_THREADS, help="tracer's threads")
    parser.add_argument("--strategies", default=None,
                        help="comma-separated subset of tracer's strategies (default: all but auto)")
    parser.add_argument("--out", default=str(HERE / "results"), help="directory for bench.json/bench.md")
    parser.add_argument("--mitsuba-python", default=None,
                        help=f"interpreter with mitsuba (default: {DEFAULT_MITSUBA_PYTHON} if it "
                             "exists, else this one if it imports mitsuba)")
    parser.add_argument("--no-mitsuba", action="store_true", help="skip Mitsuba")
    parser.add_argument("--mitsuba-child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.mitsuba_child:
        # Only the JSON line goes to stdout; the parent reads it.
        print(json.dumps(mitsuba_child(json.loads(args.mitsuba_child))), flush=True)
        return 0
    if min(args.size, args.spp, args.runs, args.threads) < 1:
        parser.error("--size, --spp, --runs and --threads must be at least 1")

    from tracer.strategy import STRATEGIES

    # auto is a choice among these (its pilot and then one of them), not a strategy to time.
    fixed = tuple(name for name in STRATEGIES if name != "auto")
    strategies = tuple(args.strategies.split(",")) if args.strategies else fixed
    unknown = set(strategies) - set(fixed)
    if unknown:
        parser.error(f"unknown strategies {sorted(unknown)}; expected some of {fixed}")
    if "mis" not in strategies:  # the ratios, thread scaling and targets are all about MIS
        strategies = (*strategies, "mis")
    if args.no_mitsuba:
        mitsuba_python, mitsuba_note = None, "skipped (--no-mitsuba)"
    else:
        mitsuba_python, mitsuba_note = find_mitsuba_python(args.mitsuba_python)

    start = time.perf_counter()
    machine = machine_info()
    log(f"machine: {machine['cpu']}, {machine['cores']} cores, {_num(machine['memory_gib'], 1)} GiB, "
        f"Python {machine['python']}, numpy {machine['numpy']}, embreex {machine['embreex']}; {mitsuba_note}")
    settings = {"size": args.size, "spp": args.spp, "runs": args.runs, "threads": args.threads,
                "seed": SEED, "strategies": list(strategies)}
    results = {"settings": settings, "machine": machine, "mitsuba_note": mitsuba_note, "scenes": {}}
    out = Path(args.out)
    for name in args.scenes.split(","):
        results["scenes"][Path(name).stem] = bench_scene(name, args, strategies, mitsuba_python)
    results["targets"] = targets(results, settings)
    results["total_seconds"] = time.perf_counter() - start
    results["load_average_at_end"] = os.getloadavg()
    results["tracer_digests"] = sorted(set(_digests(results["scenes"])))
    if mitsuba_python:
        versions = next((r for sc in results["scenes"].values() for r in sc.get("mitsuba", {}).values()
                         if "mitsuba_version" in r), None)
        if versions:
            machine["mitsuba"] = versions["mitsuba_version"]
            machine["drjit"] = versions["drjit_version"]
    text = markdown(results)
    write_atomic(out / "bench.json", json.dumps(results, indent=2) + "\n")
    write_atomic(out / "bench.md", text)
    print(text)
    log(f"wrote {out / 'bench.json'} and {out / 'bench.md'} in {results['total_seconds'] / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
