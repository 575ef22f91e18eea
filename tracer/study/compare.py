"""Strategy comparisons: equal-spp and equal-time renders, convergence and allocation sweeps.

This module renders and measures; ``report.py`` turns the results into files. Render time
is the time of ``render()`` alone, on one of two clocks (``CLOCKS``): ``wall``, the elapsed
time ``render()`` measures (the default: what a user waits), or ``cpu``, the process CPU time
of the call (``time.process_time``), summed over all the render's threads, which other
processes on a shared machine inflate far less. The Embree scene is built once and shared, so
every strategy pays the same setup and none is charged for it. Each run's film carries the
render record that ``render()`` sets (strategy, seed, sample range, wall seconds), which the
report writes into the run's EXR header.

Convergence sweeps render each strategy progressively (1, 2, 4, ... spp) once per seed, with
several independent seeds, and are summarized by the mean over seeds at each spp: the expected
relMSE of an unbiased estimator falls exactly as 1/spp, but a single run of a heavy-tailed
estimator does not show it until its rare large samples have been drawn. Fitted slopes and
times to a target relMSE carry confidence intervals from the jackknife over seeds (the seeds
are the independent units; points of one seed share their samples).

Errors are measured with the reference's own variance subtracted (``metrics``), so that a
noisy reference does not make every strategy look worse by the same amount and hide their
differences; where that variance is not known (another renderer's image without variance
channels or a sample count: ``reference.Reference``), nothing is subtracted and the measures
are as measured. A Ctrl-C (or SIGTERM) during any render stops the comparison with
``KeyboardInterrupt``: a strategy interrupted mid-way would be compared at fewer samples or
less time than the others, so no partial result is measured.
"""

from __future__ import annotations

import copy
import dataclasses
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..embree import RayCaster
from ..estimator import DirectLighting
from ..film import Film
from ..record import MAX_SAMPLE_INDEX
from ..render_loop import RenderResult, RenderSettings, render_complete
from ..sampler_choice import DEFAULT_SAMPLER
from ..scene import Scene
from ..strategy import Strategy
from . import metrics
from .reference import (  # noqa: F401 (independent_seed, independent_seeds, scene_for_reference: compare's API)
    Reference,
    as_reference,
    independent_seed,
    independent_seeds,
    scene_for_reference,
)

# (light, bsdf) samples per camera sample for the MIS allocation sweep: ratios 1:0 ... 0:1.
ALLOCATIONS = ((4, 0), (3, 1), (2, 2), (1, 3), (0, 4))

# What render time is measured on (module docstring).
CLOCKS = ("wall", "cpu")

# Convergence sweeps: the first spp used in fits (1 and 2 spp carry start-up costs in time and
# are the most heavily skewed in error); the confidence of the intervals given for slopes and
# times; and how far beyond the sweep's longest (mean) time a time to target may be
# extrapolated along the fitted line.
FIT_MIN_SPP = 4
CONFIDENCE = 0.95
EXTRAPOLATION_LIMIT = 4.0


def product_of_options(names: list[str], *, heuristics: list[str], allocations: list[str],
                       light_samplings: list[str | None], light_selections: list[str | None],
                       ris_settings: list[tuple[int, str]], light_samples: int | None = None,
                       bsdf_samples: int | None = None, one_sample: bool | None = None,
                       environment_samplings: list[str | None] | None = None) -> tuple[list[Strategy], str]:
    """Every strategy a comparison of the strategy ``names`` runs, with lists of options: mis with
    every heuristic and allocation, ris with every ``(candidates, sources)`` of ``ris_settings``,
    each strategy that takes light samples with every light sampling, selection and environment
    sampling (those that take none once; None is the default), in that order; a strategy that
    cannot take an environment sampling (``compensated`` without BSDF samples) runs the others
    asked for, and is refused if it can take none of them. Returns them with the heuristic ris
    weights its candidates with: the first classic one given (optimal weights may be negative).
    Raises ``ValueError`` naming the option that cannot be."""
    from ..strategy import CLASSIC_HEURISTICS

    classic = [h for h in heuristics if h in CLASSIC_HEURISTICS]
    if not classic and "ris" in names and any(sources == "light+bsdf" for _, sources in ris_settings):
        raise ValueError("--heuristic: ris weights its light and BSDF candidates with balance, power or max "
                         "(optimal weights may be negative); add one of them to the list")
    ris_heuristic = (classic or ["power"])[0]

    environments = environment_samplings or [None]

    def make(name, ris=None, heuristic=None, allocation=None, sampling=None, selection=None,
             environment=None) -> Strategy:
        candidates, sources = ris or (None, None)
        return Strategy.from_options(name, heuristic=heuristic, light_samples=light_samples,
                                     bsdf_samples=bsdf_samples, one_sample=one_sample,
                                     light_selection=selection, light_sampling=sampling,
                                     allocation=allocation, ris_candidates=candidates,
                                     ris_sources=sources, environment_sampling=environment)

    def takes(name, ris, environment) -> bool:
        """Whether strategy ``name`` can take environment sampling ``environment``."""
        try:
            make(name, ris, environment=environment)
        except ValueError:
            return False
        return True

    def weightings(name):
        if name == "mis":
            return [(h, a) for h in heuristics for a in allocations]
        return [(ris_heuristic if name == "ris" else "power", "fixed")]

    strategies = []
    for name in names:
        for ris in ris_settings if name == "ris" else [None]:
            takes_lights = make(name, ris).light_count > 0
            # None it can take: the first, which make() refuses with the reason.
            offered = ([e for e in environments if takes(name, ris, e)] if takes_lights else []) \
                or environments[:1]
            strategies += [make(name, ris, heuristic, allocation, sampling, selection, environment)
                           for heuristic, allocation in weightings(name)
                           for sampling in (light_samplings if takes_lights else light_samplings[:1])
                           for selection in (light_selections if takes_lights else light_selections[:1])
                           for environment in offered]
    return strategies, ris_heuristic


def method_name(strategy: Strategy, sampler: str = DEFAULT_SAMPLER) -> str:
    """A strategy's slug (``Strategy.slug``) with its sampler where that is not the default:
    ``mis``, ``mis_l3_b1``, ``ris_m16``, ``mis_sobol`` ..."""
    return strategy.slug if sampler == DEFAULT_SAMPLER else f"{strategy.slug}_{sampler}"


@dataclass
class Run:
    """One strategy's render (with one sampler) and its measures against the reference."""

    strategy: Strategy
    film: Film
    seconds: float  # on the comparison's clock
    nonfinite: int = 0
    budget: float | None = None
    measures: dict[str, float] = field(default_factory=dict)
    clock: str = "wall"
    wall_seconds: float | None = None  # both clocks, whichever the comparison uses
    cpu_seconds: float | None = None
    sampler: str = DEFAULT_SAMPLER

    @property
    def name(self) -> str:
        return method_name(self.strategy, self.sampler)

    @property
    def spp(self) -> int:
        return self.film.spp

    def measure(self, reference: np.ndarray, reference_variance: np.ndarray | None) -> dict[str, float]:
        """mse, relmse (the reference's variance ``(P, 3)`` subtracted; None: not known, nothing
        subtracted), variance, efficiency against ``reference (P, 3)``, and mse and relmse as
        measured (``*_uncorrected``)."""
        rel = metrics.relmse(self.film.mean, reference, reference_variance)
        self.measures = {
            "mse": metrics.mse(self.film.mean, reference, reference_variance),
            "relmse": rel,
            "variance": metrics.variance(self.film),
            "efficiency": metrics.efficiency(rel, self.seconds),
            "mse_uncorrected": metrics.mse(self.film.mean, reference),
            "relmse_uncorrected": metrics.relmse(self.film.mean, reference),
        }
        return self.measures


class Comparison:
    """Renders of one scene with shared Embree state, measured against one reference (a
    tracer render's film, or a :class:`Reference`, which may be another renderer's image)."""

    def __init__(self, scene: Scene, reference: Film | Reference, seed: int = 0, threads: int = 2,
                 progress: bool = False, clock: str = "wall"):
        reference = as_reference(reference)
        cam = scene.camera
        if (reference.width, reference.height) != (cam.width, cam.height):
            raise ValueError(f"reference is {reference.width}x{reference.height}, scene renders at "
                             f"{cam.width}x{cam.height}")
        if clock not in CLOCKS:
            raise ValueError(f"clock {clock!r}: expected one of {', '.join(CLOCKS)}")
        self.scene = scene
        self.reference = reference
        self.reference_variance = reference.pixel_variance  # (P, 3), or None: not known
        self.seed = seed
        self.threads = threads
        self.progress = progress
        self.clock = clock
        self.caster = RayCaster(scene.vertices, scene.faces)
        self._warm: set[Strategy] = set()
        self.token = uuid.uuid4().hex  # names this comparison to the workers that keep a copy of it

    def _estimator(self, strategy: Strategy) -> DirectLighting | None:
        """The estimator of ``strategy``; None for ``auto``, which ``render()`` resolves by its
        pilot (on the clock) and later passes continue (:meth:`_continued`)."""
        return None if strategy.name == "auto" else DirectLighting(self.scene, strategy, self.caster)

    def _continued(self, estimator: DirectLighting | None, result: RenderResult) -> DirectLighting | None:
        """The estimator for the passes after ``result``: for ``auto``, the strategy its pilot
        chose (its film's record), built once instead of at every pass."""
        if estimator is None and result.film.record.auto:
            return self._estimator(Strategy.from_record(result.film.record))
        return estimator

    def _say(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr)

    def _warm_up(self, strategy: Strategy) -> None:
        """Before the first CPU-timed render of a strategy: one sample of a 1x1 copy of the
        scene, so that loading the compiled kernels (which ``render()`` keeps off its wall
        clock, but which process CPU time would count) is not charged to the first run."""
        if strategy in self._warm:
            return
        tiny = copy.copy(self.scene)
        tiny.camera = dataclasses.replace(self.scene.camera, width=1, height=1)
        render_complete(tiny, strategy, RenderSettings(spp=1, seed=self.seed, threads=1),
                        estimator=None if strategy.name == "auto" else DirectLighting(tiny, strategy, self.caster))
        self._warm.add(strategy)

    def _render(self, strategy: Strategy, settings: RenderSettings, film: Film | None,
                estimator: DirectLighting, progress: bool = False,
                continues: RenderResult | None = None) -> tuple[RenderResult, float, float]:
        """One render, continuing the render ``continues`` (its film is ``film``; an estimator
        that learns goes on from what it learned); an interrupted one stops the comparison
        (module docstring). Returns the result, its seconds on the comparison's clock and its
        process CPU seconds (all threads)."""
        if self.clock == "cpu":
            self._warm_up(strategy)
        # On one thread the render runs in this one: its own CPU time, not that of the process's
        # other threads (a Dask worker's event loop and its other tasks).
        cpu_clock = time.thread_time if self.threads == 1 else time.process_time
        start = cpu_clock()
        result = render_complete(self.scene, strategy, settings, film=film, estimator=estimator,
                                 progress=progress, learner=continues.learner if continues else None)
        cpu = cpu_clock() - start
        return result, (cpu if self.clock == "cpu" else result.seconds), cpu

    def _measure(self, run: Run) -> Run:
        run.measure(self.reference.mean, self.reference_variance)
        return run

    @property
    def reference_relmse(self) -> float | None:
        """The reference's own noise on the relMSE scale (what the measures subtract); None
        where its variance is not known (nothing is subtracted)."""
        if self.reference_variance is None:
            return None
        return metrics.reference_relmse(self.reference.mean, self.reference_variance)

    def equal_spp(self, strategy: Strategy, spp: int, sampler: str = DEFAULT_SAMPLER) -> Run:
        """Render ``spp`` samples per pixel with ``sampler``."""
        settings = RenderSettings(spp=spp, seed=self.seed, threads=self.threads, sampler=sampler)
        result, seconds, cpu = self._render(strategy, settings, None, self._estimator(strategy),
                                            self.progress)
        run = self._measure(Run(strategy, result.film, seconds, result.nonfinite, clock=self.clock,
                                wall_seconds=result.seconds, cpu_seconds=cpu, sampler=sampler))
        self._say(f"  {_described(strategy, sampler)}: {run.spp} spp, {run.seconds:.2f} {self.unit}, "
                  f"relMSE {run.measures['relmse']:.4g}")
        return run

    @property
    def unit(self) -> str:
        """How seconds on this comparison's clock are shown: ``s`` or ``CPU s``."""
        return "CPU s" if self.clock == "cpu" else "s"

    def equal_time(self, strategy: Strategy, budget: float, sampler: str = DEFAULT_SAMPLER) -> Run:
        """Render as many whole spp as fit in ``budget`` seconds of the comparison's clock.

        Passes are sized to about half of the time left, from the measured time per spp, and
        the render stops when less than half a pass of 1 spp remains; so the spent time ends
        within about half the time of one spp of the budget. Each pass draws the next sample
        indices: a Sobol replicate continues its sequence, a stratified one adds a set
        stratified on its own (``tracer.samplers``).
        """
        estimator = self._estimator(strategy)
        film, spent, spp, nonfinite, per_spp = None, 0.0, 0, 0, None
        wall, cpu = 0.0, 0.0
        result = None
        while True:
            left = budget - spent
            if per_spp is None:
                chunk = 1
            else:
                if left < 0.5 * per_spp:
                    break
                chunk = max(1, int(0.5 * left / per_spp)) if left > 2 * per_spp else 1
            settings = RenderSettings(spp=chunk, seed=self.seed, threads=self.threads, first_sample=spp,
                                      sampler=sampler)
            result, seconds, chunk_cpu = self._render(strategy, settings, film, estimator, continues=result)
            estimator = self._continued(estimator, result)
            film, spp = result.film, spp + chunk
            spent += seconds
            wall += result.seconds
            cpu += chunk_cpu
            nonfinite += result.nonfinite
            per_spp = spent / spp
        run = self._measure(Run(strategy, film, spent, nonfinite, budget=budget, clock=self.clock,
                                wall_seconds=wall, cpu_seconds=cpu, sampler=sampler))
        self._say(f"  {_described(strategy, sampler)}: {run.spp} spp in {run.seconds:.2f} {self.unit} of "
                  f"{budget:.2f}, relMSE {run.measures['relmse']:.4g}")
        return run

    def convergence(self, strategy: Strategy, max_spp: int | None = None,
                    budget: float | None = None, seed: int | None = None,
                    sampler: str = DEFAULT_SAMPLER) -> list[dict[str, Any]]:
        """relMSE and cumulative seconds (on the comparison's clock) at spp 1, 2, 4, ... up to
        ``max_spp`` (or until the time ``budget`` is spent), for one ``seed`` (default: the
        comparison's). One progressive render: each point adds samples to the last (so each
        Sobol replicate holds 2^k points of its sequence at every point from 8 spp on, and a
        stratified replicate a stratified set per doubling). Points are named by
        :func:`method_name`."""
        seed = self.seed if seed is None else seed
        estimator = self._estimator(strategy)
        points: list[dict[str, Any]] = []
        film, spp, spent = None, 0, 0.0
        target = 1
        result = None
        while (max_spp is None or target <= max_spp):
            settings = RenderSettings(spp=target - spp, seed=seed, threads=self.threads, first_sample=spp,
                                      sampler=sampler)
            result, seconds, _ = self._render(strategy, settings, film, estimator, continues=result)
            estimator = self._continued(estimator, result)
            film, spp = result.film, target
            spent += seconds
            rel = metrics.relmse(film.mean, self.reference.mean, self.reference_variance)
            points.append({"name": method_name(strategy, sampler), "strategy": strategy.name,
                           "heuristic": strategy.recorded_heuristic, "sampler": sampler, "seed": seed,
                           "spp": spp, "seconds": spent, "relmse": rel,
                           "efficiency": metrics.efficiency(rel, spent)})
            if budget is not None and spent * 2.0 > budget:  # the next doubling would overshoot
                break
            target *= 2
        return points

    def perform(self, calls: list[tuple[str, tuple]], client=None) -> list:
        """The results of method calls ``(name, args)`` of this comparison (``equal_spp``,
        ``equal_time``, ``convergence``): here one after the other, or with a Dask ``client`` all
        at once, each a task on one thread of a worker (``tracer.cluster``), timed there."""
        if client is None:
            return [getattr(self, name)(*args) for name, args in calls]
        from ..cluster import map_tasks

        return map_tasks(client, comparison_call,
                         [(self.token, self.scene, self.reference, self.seed, self.clock, name, args)
                          for name, args in calls], progress=self.progress)

    def sweeps(self, items: list[tuple[Strategy, str]], seeds: list[int], max_spp: int | None = None,
               budget: float | None = None, client=None) -> list[dict[str, Any]]:
        """:meth:`convergence` for every ``(strategy, sampler)`` of ``items`` and every seed, each
        strategy's seeds up to the same spp: its first seed's sweep decides it (``max_spp``, or as
        far as the ``budget`` goes), so that each point has every seed and the mean over seeds is
        taken at the same spp. With a ``client`` the first seeds run first, as tasks, then the
        others (its progress bar shows them); here each strategy's seeds run in turn and its
        line is said as it is done, so that a sweep of many seconds is not silent."""
        methods = f"{len(items)} method{'s' if len(items) != 1 else ''}"
        self._say(f"  sweep: relMSE at spp 1, 2, 4, ... of {methods} x {len(seeds)} seeds")
        if client is None:
            out: list[dict[str, Any]] = []
            for strategy, sampler in items:
                points = self.convergence(strategy, max_spp, budget, seeds[0], sampler)
                for seed in seeds[1:]:
                    points += self.convergence(strategy, points[-1]["spp"], None, seed, sampler)
                out += self._swept(strategy, sampler, points, len(seeds))
            return out
        first = self.perform([("convergence", (strategy, max_spp, budget, seeds[0], sampler))
                              for strategy, sampler in items], client)
        rest = self.perform([("convergence", (strategy, points[-1]["spp"], None, seed, sampler))
                             for (strategy, sampler), points in zip(items, first, strict=True)
                             for seed in seeds[1:]], client)
        out = []
        others = len(seeds) - 1
        for i, ((strategy, sampler), points) in enumerate(zip(items, first, strict=True)):
            points = points + [p for seed_points in rest[i * others:(i + 1) * others] for p in seed_points]
            out += self._swept(strategy, sampler, points, len(seeds))
        return out

    def _swept(self, strategy: Strategy, sampler: str, points: list[dict[str, Any]],
               seeds: int) -> list[dict[str, Any]]:
        """Say one strategy's sweep line (its seeds, points, last spp and time there); return its points."""
        last = points[-1]["spp"]
        spent = sum(p["seconds"] for p in points if p["spp"] == last)
        self._say(f"  sweep {_described(strategy, sampler)}: {seeds} seeds x "
                  f"{len(points) // seeds} points up to {last} spp, {spent:.2f} {self.unit}")
        return points

    def sweep(self, strategy: Strategy, seeds: list[int], max_spp: int | None = None,
              budget: float | None = None, sampler: str = DEFAULT_SAMPLER) -> list[dict[str, Any]]:
        """:meth:`sweeps` of one strategy and sampler, here."""
        return self.sweeps([(strategy, sampler)], seeds, max_spp, budget)


# Each worker keeps the comparison of the last task it ran (its Embree scene, the reference's
# variance), so that the tasks after the first one of a comparison do not rebuild them.
_WORKER_COMPARISON: dict[str, Comparison] = {}
_WORKER_LOCK = threading.Lock()  # a worker runs one task per thread


def comparison_call(token: str, scene: Scene, reference: Reference, seed: int, clock: str, name: str,
                    args: tuple) -> Any:
    """A task (``Comparison.perform``): method ``name`` of the comparison ``token`` on one thread."""
    with _WORKER_LOCK:
        if token not in _WORKER_COMPARISON:
            _WORKER_COMPARISON.clear()
            _WORKER_COMPARISON[token] = Comparison(scene, reference, seed, threads=1, clock=clock)
        comparison = _WORKER_COMPARISON[token]
    return getattr(comparison, name)(*args)


def _described(strategy: Strategy, sampler: str) -> str:
    """The strategy's label, and the sampler unless it is the default."""
    return strategy.label + ("" if sampler == DEFAULT_SAMPLER else f", {sampler} sampler")


def fit_convergence(points: list[dict[str, float]], x: str) -> tuple[float, float]:
    """Least-squares line through (log x, log relMSE) over the points with spp >= FIT_MIN_SPP
    (earlier ones carry start-up noise; all points if fewer than two are left): returns
    (slope, intercept). Monte Carlo's rate is slope -1. Points whose (corrected) relMSE is not
    positive are below the reference's resolution and left out."""
    use = [p for p in points if p["spp"] >= FIT_MIN_SPP and p["relmse"] > 0.0]
    if len(use) < 2:
        use = [p for p in points if p["relmse"] > 0.0]
    if len(use) < 2:
        return float("nan"), float("nan")
    lx = np.log([p[x] for p in use])
    ly = np.log([p["relmse"] for p in use])
    slope, intercept = np.polyfit(lx, ly, 1)
    return float(slope), float(intercept)


def time_to_reach(points: list[dict[str, float]], target: float) -> tuple[float, bool]:
    """Seconds to reach relMSE <= target on one curve: the first point's seconds if it is
    already there, else interpolated (log-log) at the first crossing, else extrapolated: the
    spp at which the line fitted against spp reaches the target, costed at the last doubling's
    seconds per spp (render time grows linearly in spp; the early points also carry fixed costs
    per render, which would steepen a line fitted against seconds), inf if the line does not
    fall. Returns (seconds, extrapolated). A relMSE that is not positive (below what the
    reference resolves) has reached any target, but cannot be interpolated or fitted in logs."""
    if points and points[0]["relmse"] <= target:
        return points[0]["seconds"], False
    for before, after in zip(points, points[1:], strict=False):
        if before["relmse"] > target >= after["relmse"]:
            if after["relmse"] <= 0.0:
                return after["seconds"], False
            t = np.interp(np.log(target), [np.log(after["relmse"]), np.log(before["relmse"])],
                          [np.log(after["seconds"]), np.log(before["seconds"])])
            return float(np.exp(t)), False
    points = [p for p in points if p["relmse"] > 0.0]
    if len(points) < 2:
        return float("inf"), True
    slope, intercept = fit_convergence(points, "spp")
    if not np.isfinite(slope) or slope >= 0.0:
        return float("inf"), True
    log_spp = (np.log(target) - intercept) / slope
    if log_spp > np.log(MAX_SAMPLE_INDEX):  # more samples than a film can count
        return float("inf"), True
    spp = np.exp(log_spp)
    last, before = points[-1], points[-2]
    per_spp = (last["seconds"] - before["seconds"]) / (last["spp"] - before["spp"])
    return float(last["seconds"] + (spp - last["spp"]) * per_spp), True


# ---------------------------------------------------------------------------------------------
# Sweeps over several seeds: mean curves, slopes and times with confidence intervals


@dataclass
class SweepCurve:
    """One strategy's sweep over seeds as arrays: ``relmse (S, K)`` and cumulative ``seconds
    (S, K)`` of S seeds at the K spp of ``spp (K,)`` that every seed reached."""

    strategy: str
    seeds: list[int]
    spp: np.ndarray
    seconds: np.ndarray
    relmse: np.ndarray

    def mean_points(self, keep: np.ndarray | None = None) -> list[dict[str, float]]:
        """The curve of the means over the seeds (those of ``keep (S,) bool``, default all):
        dicts with spp, seconds and relmse, as :func:`fit_convergence` takes them."""
        rows = np.ones(len(self.seeds), dtype=bool) if keep is None else keep
        seconds, relmse = self.seconds[rows].mean(axis=0), self.relmse[rows].mean(axis=0)
        return [{"spp": int(n), "seconds": float(t), "relmse": float(r)}
                for n, t, r in zip(self.spp, seconds, relmse, strict=True)]

    def summary(self) -> list[dict[str, float]]:
        """Per spp: the mean seconds and relMSE over the seeds, the standard error of the mean
        relMSE (NaN for one seed), and the smallest and largest single-seed relMSE."""
        count = len(self.seeds)
        rel = self.relmse
        se = rel.std(axis=0, ddof=1) / np.sqrt(count) if count > 1 else np.full(len(self.spp), np.nan)
        columns = zip(self.spp, self.seconds.mean(axis=0), rel.mean(axis=0), se, rel.min(axis=0),
                      rel.max(axis=0), strict=True)
        return [{"strategy": self.strategy, "spp": int(n), "seeds": count, "seconds": float(t),
                 "relmse": float(r), "relmse_se": float(e), "relmse_min": float(lo), "relmse_max": float(hi)}
                for n, t, r, e, lo, hi in columns]


def sweep_curves(points: list[dict[str, Any]]) -> dict[str, SweepCurve]:
    """The sweep's points (``Comparison.sweep``'s dicts, any strategies and seeds) as one
    :class:`SweepCurve` per method (``name``: strategy, light sampling and sampler; the
    strategy for points without one), in order of first appearance. Points without a seed
    count as one seed."""
    curves = {}
    named = [{**p, "name": p.get("name", p["strategy"])} for p in points]
    for name in dict.fromkeys(p["name"] for p in named):
        mine = [p for p in named if p["name"] == name]
        seeds = list(dict.fromkeys(p.get("seed") for p in mine))
        by_seed = [{p["spp"]: p for p in mine if p.get("seed") == seed} for seed in seeds]
        spp = sorted(set.intersection(*(set(b) for b in by_seed)))

        def table(key: str, by_seed=by_seed, spp=spp) -> np.ndarray:
            values = [[b[n][key] for n in spp] for b in by_seed]
            return np.array(values, dtype=np.float64).reshape(len(by_seed), -1)

        curves[name] = SweepCurve(name, seeds, np.array(spp, dtype=np.int64), table("seconds"),
                                  table("relmse"))
    return curves


def t_quantile(confidence: float, dof: int) -> float:
    """The two-sided Student t critical value for ``confidence`` and ``dof`` degrees of freedom."""
    from scipy import stats

    return float(stats.t.ppf(0.5 + confidence / 2.0, dof))


def jackknife(curve: SweepCurve, statistic: Callable[[list[dict[str, float]]], float]) -> tuple[float, float]:
    """``statistic`` of the mean curve over all seeds, and its jackknife standard error over the
    seeds: sqrt((S-1)/S sum_i (theta_(i) - mean theta_(.))^2), theta_(i) the statistic with seed i
    left out. The seeds are the independent units (a seed's points share samples). NaN for
    fewer than 2 seeds; inf if a leave-one-out value is not finite."""
    value = statistic(curve.mean_points())
    count = len(curve.seeds)
    if count < 2:
        return value, float("nan")
    left_out = []
    for i in range(count):
        keep = np.ones(count, dtype=bool)
        keep[i] = False
        left_out.append(statistic(curve.mean_points(keep)))
    replicates = np.array(left_out)
    if not np.all(np.isfinite(replicates)):
        return value, float("inf")
    return value, float(np.sqrt((count - 1) / count * np.sum((replicates - replicates.mean()) ** 2)))


@dataclass
class SlopeFit:
    """A fitted convergence slope with its confidence interval (NaN bounds for one seed)."""

    slope: float
    intercept: float
    low: float
    high: float
    seeds: int

    def excludes(self, value: float) -> bool:
        """Whether the interval is defined and ``value`` lies outside it."""
        return bool(np.isfinite(self.low) and np.isfinite(self.high) and not self.low <= value <= self.high)


def fit_sweep(curve: SweepCurve, x: str, confidence: float = CONFIDENCE) -> SlopeFit:
    """The slope of log mean relMSE against log ``x`` (``spp`` or ``seconds``) by
    :func:`fit_convergence`, with a ``confidence`` interval slope +- t se from the jackknife
    over the seeds and Student's t with S - 1 degrees of freedom."""
    slope, intercept = fit_convergence(curve.mean_points(), x)
    _, se = jackknife(curve, lambda points: fit_convergence(points, x)[0])
    count = len(curve.seeds)
    if count < 2 or not np.isfinite(slope):
        return SlopeFit(slope, intercept, float("nan"), float("nan"), count)
    half = t_quantile(confidence, count - 1) * se
    return SlopeFit(slope, intercept, slope - half, slope + half, count)


def time_to_target(curve: SweepCurve, target: float, confidence: float = CONFIDENCE,
                   limit: float = EXTRAPOLATION_LIMIT) -> dict[str, Any]:
    """Seconds for the mean curve to reach relMSE ``target`` (:func:`time_to_reach`), with a
    ``confidence`` interval from the jackknife over seeds of its logarithm; reported only where
    the data support it. ``how`` says which: ``at most`` (reached at the first point),
    ``interpolated`` (between two measured points) or ``extrapolated`` along the line fitted
    against spp, which needs at least 2 seeds, a slope whose interval lies below 0 and a time
    at most ``limit`` times the sweep's longest. Otherwise ``seconds`` is None and ``note``
    says why."""
    points = curve.mean_points()
    row: dict[str, Any] = {"strategy": curve.strategy, "target_relmse": target, "seeds": len(curve.seeds),
                           "seconds": None, "low": None, "high": None, "how": None, "note": "",
                           "confidence": confidence}
    seconds, extrapolated = time_to_reach(points, target)
    longest = points[-1]["seconds"]
    if extrapolated:
        fit = fit_sweep(curve, "spp", confidence)
        if len(curve.seeds) < 2:
            row["note"] = "not reached, and one seed gives no interval to extrapolate with"
            return row
        if not np.isfinite(fit.slope):
            row["note"] = "not reached, and too few points to fit a slope"
            return row
        if not fit.high < 0.0:
            row["note"] = (f"not reached, and the slope ({fit.slope:.2f}, interval "
                           f"{fit.low:.2f} .. {fit.high:.2f}) does not exclude 0")
            return row
        if not seconds <= limit * longest:
            row["note"] = (f"not reached; the fitted line reaches it beyond {limit:g}x the sweep's "
                           f"longest time ({longest:.3g} s)")
            return row
        row["how"] = "extrapolated"
    else:
        row["how"] = "at most" if points[0]["relmse"] <= target else "interpolated"
    log_t, se = jackknife(curve, lambda pts: float(np.log(time_to_reach(pts, target)[0])))
    row["seconds"] = seconds
    if np.isfinite(se):
        half = t_quantile(confidence, len(curve.seeds) - 1) * se
        row["low"], row["high"] = float(np.exp(log_t - half)), float(np.exp(log_t + half))
    elif se == float("inf"):
        row["low"], row["high"] = 0.0, float("inf")
    return row


def convergence_rows(points: list[dict[str, Any]], target: float,
                     confidence: float = CONFIDENCE) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """For ``metrics.json`` and the tables: one row of fitted slopes per strategy (against spp
    and seconds, each with its interval, and whether the spp interval holds Monte Carlo's -1)
    and one row of time to ``target`` (:func:`time_to_target`)."""
    slopes, times = [], []
    for name, curve in sweep_curves(points).items():
        row: dict[str, Any] = {"strategy": name, "seeds": len(curve.seeds), "confidence": confidence,
                               "first_spp_fitted": FIT_MIN_SPP}
        for x in ("spp", "seconds"):
            fit = fit_sweep(curve, x, confidence)
            row.update({f"slope_{x}": fit.slope, f"slope_{x}_low": fit.low, f"slope_{x}_high": fit.high})
        low, high = row["slope_spp_low"], row["slope_spp_high"]
        row["holds_minus_one"] = bool(low <= -1.0 <= high) if np.isfinite(low) and np.isfinite(high) else None
        slopes.append(row)
        times.append(time_to_target(curve, target, confidence))
    return slopes, times


def run_row(run: Run) -> dict[str, object]:
    """The row of ``metrics.json``'s results for one run."""
    row: dict[str, object] = {"strategy": run.strategy.name, "heuristic": run.strategy.recorded_heuristic,
                              "allocation": run.strategy.allocation,
                              "light_samples": run.strategy.light_count,
                              "bsdf_samples": run.strategy.direction_count,
                              "light_sampling": run.strategy.recorded_light_sampling,
                              "environment_sampling": run.strategy.recorded_environment_sampling,
                              "light_selection": run.strategy.light_selection if run.strategy.light_count
                              else "none", "sampler": run.sampler,
                              "spp": run.spp, "seconds": run.seconds, "clock": run.clock,
                              "wall_seconds": run.wall_seconds, "cpu_seconds": run.cpu_seconds}
    row.update(run.measures)
    if run.budget is not None:
        row["budget"] = run.budget
    if run.nonfinite:
        row["nonfinite"] = run.nonfinite
    return row

