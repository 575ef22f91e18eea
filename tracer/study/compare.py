"""Strategy comparisons: equal-spp and equal-time renders, convergence and allocation sweeps.

This module renders and measures; ``report.py`` turns the results into files. Render time
is the wall time of ``render()`` alone: the Embree scene is built once and shared, so every
strategy pays the same setup and none is charged for it. Each run's film carries the render
record that ``render()`` sets (strategy, seed, sample range, seconds), which the report writes
into the run's EXR header.

Errors are measured with the reference's own variance subtracted (``metrics``), so that a
noisy reference does not make every strategy look worse by the same amount and hide their
differences. A Ctrl-C (or SIGTERM) during any render stops the comparison with
``KeyboardInterrupt``: a strategy interrupted mid-way would be compared at fewer samples or
less time than the others, so no partial result is measured.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..embree import RayCaster
from ..errors import InputError
from ..estimators import DirectLighting
from ..film import Film
from ..render_loop import RenderSettings, render_complete
from ..scene import Scene, load_scene
from ..strategy import Strategy
from . import metrics


def scene_for_reference(scene_path: str | Path, reference_path: str | Path, reference: Film,
                        downsample: int = 1, quiet: bool = False) -> Scene:
    """The scene, loaded to render at the reference's resolution / ``downsample``, after
    checking that the reference is of it: the same scene digest (when the reference records
    one; otherwise a note says it cannot be checked), the same aspect ratio as the scene's
    camera, to within one pixel's rounding (a reference of the same frame at another size is
    fine, and a note says so), and at least 2 samples in every pixel (a reference interrupted
    in its first pass has pixels without any, and one sample gives no variance to correct
    with). A reference not made with MIS gets a note: it shares the blind spots of its
    strategy (point lights for bsdf). ``InputError`` naming the reference file otherwise."""
    if reference.spp < 2:
        raise InputError(f"the reference has pixels with {reference.spp} sample(s); it needs at least 2 in "
                         "every pixel (grow it with tracer reference --resume)", str(reference_path))
    scene = load_scene(scene_path)
    digest = reference.record.scene_digest
    if digest is not None and digest != scene.digest:
        raise InputError(f"tracer:scene_digest: the reference is of another scene "
                         f"({reference.record.scene}) than {scene_path}", str(reference_path))
    if digest is None and not quiet:
        print(f"tracer: note: {reference_path} does not record its scene's digest (made by another tool "
              "or an older tracer): it cannot be checked to be of this scene", file=sys.stderr)
    if reference.record.strategy not in (None, "mis") and not quiet:
        print(f"tracer: note: {reference_path} was rendered with {reference.record.strategy}, not mis: it "
              "misses what that strategy cannot see", file=sys.stderr)
    width, height = scene.camera.width, scene.camera.height
    aspect = width / height
    # The same frame: one side of the reference is the other times the aspect ratio, rounded.
    if abs(reference.width - reference.height * aspect) > 0.5 and \
            abs(reference.height - reference.width / aspect) > 0.5:
        raise InputError(f"the reference is {reference.width}x{reference.height}, the scene's camera "
                         f"{width}x{height}: another aspect ratio, so another image", str(reference_path))
    size = (reference.width // downsample, reference.height // downsample)
    if (reference.width, reference.height) != (width, height) and not quiet:
        print(f"tracer: note: rendering at the reference's {reference.width}x{reference.height}, "
              f"not the scene's {width}x{height}", file=sys.stderr)
    scene.camera = dataclasses.replace(scene.camera, width=size[0], height=size[1])
    return scene


def independent_seed(reference: Film, seed: int | None, reference_path: str | Path) -> int:
    """A seed whose samples are independent of the reference's: ``seed`` if the reference holds
    none of it, else InputError; None picks the smallest such seed. A comparison that drew the
    reference's own random numbers would share its noise (the reference's first N samples
    *are* an N-spp MIS render), and subtracting the reference's variance would then favour it.
    A reference that does not say which samples it holds cannot be checked: seed 0 is avoided
    by default (tracer's default seed) and a note says so."""
    held = {s for s, _, _ in reference.record.samples or ()}
    if reference.record.samples is None:
        print(f"tracer: note: {reference_path} does not say which samples it holds: the comparison's "
              "renders cannot be checked to be independent of it", file=sys.stderr)
        held = {0}
    if seed is not None:
        if seed in held:
            raise InputError(f"--seed {seed}: the reference holds samples of seed {seed}, so the "
                             "comparison would share its random numbers; use another seed or leave "
                             "--seed out", str(reference_path))
        return seed
    return next(s for s in range(len(held) + 1) if s not in held)


# (light, bsdf) samples per camera sample for the MIS allocation sweep: ratios 1:0 ... 0:1.
ALLOCATIONS = ((4, 0), (3, 1), (2, 2), (1, 3), (0, 4))


@dataclass
class Run:
    """One strategy's render and its measures against the reference."""

    strategy: Strategy
    film: Film
    seconds: float
    nonfinite: int = 0
    budget: float | None = None
    measures: dict[str, float] = field(default_factory=dict)

    @property
    def spp(self) -> int:
        return self.film.spp

    def measure(self, reference: np.ndarray, reference_variance: np.ndarray) -> dict[str, float]:
        """mse, relmse (the reference's variance ``(P, 3)`` subtracted), variance, efficiency
        against ``reference (P, 3)``, and mse and relmse as measured (``*_uncorrected``)."""
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
    """Renders of one scene with shared Embree state, measured against one reference."""

    def __init__(self, scene: Scene, reference: Film, seed: int = 0, threads: int = 2,
                 progress: bool = False):
        cam = scene.camera
        if (reference.width, reference.height) != (cam.width, cam.height):
            raise ValueError(f"reference is {reference.width}x{reference.height}, scene renders at "
                             f"{cam.width}x{cam.height}")
        self.scene = scene
        self.reference = reference
        self.reference_variance = reference.variance_of_mean()
        self.seed = seed
        self.threads = threads
        self.progress = progress
        self.caster = RayCaster(scene.vertices, scene.faces)

    def _estimator(self, strategy: Strategy) -> DirectLighting:
        return DirectLighting(self.scene, strategy, self.caster)

    def _say(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr)

    def _render(self, strategy: Strategy, settings: RenderSettings, film: Film | None,
                estimator: DirectLighting, progress: bool = False):
        """One render; an interrupted one stops the comparison (module docstring)."""
        return render_complete(self.scene, strategy, settings, film=film, estimator=estimator,
                               progress=progress)

    def _measure(self, run: Run) -> Run:
        run.measure(self.reference.mean, self.reference_variance)
        return run

    @property
    def reference_relmse(self) -> float:
        """The reference's own noise on the relMSE scale (what the measures subtract)."""
        return metrics.reference_relmse(self.reference.mean, self.reference_variance)

    def equal_spp(self, strategy: Strategy, spp: int) -> Run:
        """Render ``spp`` samples per pixel."""
        result = self._render(strategy, RenderSettings(spp=spp, seed=self.seed, threads=self.threads),
                              None, self._estimator(strategy), self.progress)
        run = self._measure(Run(strategy, result.film, result.seconds, result.nonfinite))
        self._say(f"  {strategy.label}: {run.spp} spp, {run.seconds:.2f} s, "
                  f"relMSE {run.measures['relmse']:.4g}")
        return run

    def equal_time(self, strategy: Strategy, budget: float) -> Run:
        """Render as many whole spp as fit in ``budget`` seconds.

        Passes are sized to about half of the time left, from the measured time per spp, and
        the render stops when less than half a pass of 1 spp remains; so the spent time ends
        within about half the time of one spp of the budget.
        """
        estimator = self._estimator(strategy)
        film, spent, spp, nonfinite, per_spp = None, 0.0, 0, 0, None
        while True:
            left = budget - spent
            if per_spp is None:
                chunk = 1
            else:
                if left < 0.5 * per_spp:
                    break
                chunk = max(1, int(0.5 * left / per_spp)) if left > 2 * per_spp else 1
            settings = RenderSettings(spp=chunk, seed=self.seed, threads=self.threads, first_sample=spp)
            result = self._render(strategy, settings, film, estimator)
            film, spp = result.film, spp + chunk
            spent += result.seconds
            nonfinite += result.nonfinite
            per_spp = spent / spp
        run = self._measure(Run(strategy, film, spent, nonfinite, budget=budget))
        self._say(f"  {strategy.label}: {run.spp} spp in {run.seconds:.2f} s of {budget:.2f} s, "
                  f"relMSE {run.measures['relmse']:.4g}")
        return run

    def convergence(self, strategy: Strategy, max_spp: int | None = None,
                    budget: float | None = None) -> list[dict[str, float]]:
        """relMSE and cumulative seconds at spp 1, 2, 4, ... up to ``max_spp`` (or until the
        time ``budget`` is spent). One progressive render: each point adds samples to the last."""
        estimator = self._estimator(strategy)
        points: list[dict[str, float]] = []
        film, spp, spent = None, 0, 0.0
        target = 1
        while (max_spp is None or target <= max_spp):
            settings = RenderSettings(spp=target - spp, seed=self.seed, threads=self.threads,
                                      first_sample=spp)
            result = self._render(strategy, settings, film, estimator)
            film, spp = result.film, target
            spent += result.seconds
            rel = metrics.relmse(film.mean, self.reference.mean, self.reference_variance)
            points.append({"strategy": strategy.name, "heuristic": strategy.recorded_heuristic, "spp": spp,
                           "seconds": spent, "relmse": rel, "efficiency": metrics.efficiency(rel, spent)})
            if budget is not None and spent * 2.0 > budget:  # the next doubling would overshoot
                break
            target *= 2
        self._say(f"  sweep {strategy.label}: {len(points)} points up to {spp} spp, {spent:.2f} s")
        return points


def fit_convergence(points: list[dict[str, float]], x: str) -> tuple[float, float]:
    """Least-squares line through (log x, log relMSE) over the points with spp >= 4 (earlier
    ones carry start-up noise): returns (slope, intercept). Monte Carlo's rate is slope -1."""
    use = [p for p in points if p["spp"] >= 4 and p["relmse"] > 0.0] or [p for p in points if p["relmse"] > 0]
    if len(use) < 2:
        return float("nan"), float("nan")
    lx = np.log([p[x] for p in use])
    ly = np.log([p["relmse"] for p in use])
    slope, intercept = np.polyfit(lx, ly, 1)
    return float(slope), float(intercept)


def time_to_reach(points: list[dict[str, float]], target: float) -> tuple[float, bool]:
    """Seconds to reach relMSE <= target: interpolated (log-log) between measured points, else
    extrapolated along the fitted line. Returns (seconds, extrapolated). Points whose
    (corrected) relMSE is not positive are below the reference's resolution and left out."""
    points = [p for p in points if p["relmse"] > 0.0]
    for before, after in zip(points, points[1:], strict=False):
        if before["relmse"] > target >= after["relmse"]:
            t = np.interp(np.log(target), [np.log(after["relmse"]), np.log(before["relmse"])],
                          [np.log(after["seconds"]), np.log(before["seconds"])])
            return float(np.exp(t)), False
    if points and points[0]["relmse"] <= target:
        return points[0]["seconds"], False
    slope, intercept = fit_convergence(points, "seconds")
    if not np.isfinite(slope) or slope >= 0.0:
        return float("inf"), True
    return float(np.exp((np.log(target) - intercept) / slope)), True


def run_row(run: Run) -> dict[str, object]:
    """The row of ``metrics.json``'s results for one run."""
    row: dict[str, object] = {"strategy": run.strategy.name, "heuristic": run.strategy.recorded_heuristic,
                              "light_samples": run.strategy.light_count,
                              "bsdf_samples": run.strategy.direction_count,
                              "spp": run.spp, "seconds": run.seconds}
    row.update(run.measures)
    if run.budget is not None:
        row["budget"] = run.budget
    if run.nonfinite:
        row["nonfinite"] = run.nonfinite
    return row

