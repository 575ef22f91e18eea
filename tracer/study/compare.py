"""Strategy comparisons: equal-spp and equal-time renders, convergence and allocation sweeps.

This module renders and measures; ``report.py`` turns the results into files. Render time
is the wall time of ``render()`` alone: the Embree scene is built once and shared, so every
strategy pays the same setup and none is charged for it. Each run's film carries the render
record that ``render()`` sets (strategy, seed, sample range, seconds), which the report writes
into the run's EXR header.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

from ..embree import RayCaster
from ..estimators import DirectLighting
from ..film import Film
from ..render_loop import RenderSettings, render
from ..scene import Scene
from ..strategy import Strategy
from . import metrics

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

    def measure(self, reference: np.ndarray) -> dict[str, float]:
        """mse, relmse, variance, efficiency against ``reference (P, 3)``."""
        rel = metrics.relmse(self.film.mean, reference)
        self.measures = {
            "mse": metrics.mse(self.film.mean, reference),
            "relmse": rel,
            "variance": metrics.variance(self.film),
            "efficiency": metrics.efficiency(rel, self.seconds),
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
        self.seed = seed
        self.threads = threads
        self.progress = progress
        self.caster = RayCaster(scene.vertices, scene.faces)

    def _estimator(self, strategy: Strategy) -> DirectLighting:
        return DirectLighting(self.scene, strategy, self.caster)

    def _say(self, text: str) -> None:
        if self.progress:
            print(text, file=sys.stderr)

    def equal_spp(self, strategy: Strategy, spp: int) -> Run:
        """Render ``spp`` samples per pixel."""
        result = render(self.scene, strategy, RenderSettings(spp=spp, seed=self.seed, threads=self.threads),
                        estimator=self._estimator(strategy), progress=self.progress)
        run = Run(strategy, result.film, result.seconds, result.nonfinite)
        run.measure(self.reference.mean)
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
            result = render(self.scene, strategy, settings, film=film, estimator=estimator)
            film, spp = result.film, spp + chunk
            spent += result.seconds
            nonfinite += result.nonfinite
            per_spp = spent / spp
        run = Run(strategy, film, spent, nonfinite, budget=budget)
        run.measure(self.reference.mean)
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
            result = render(self.scene, strategy, settings, film=film, estimator=estimator)
            film, spp = result.film, target
            spent += result.seconds
            rel = metrics.relmse(film.mean, self.reference.mean)
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
    extrapolated along the fitted line. Returns (seconds, extrapolated)."""
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

