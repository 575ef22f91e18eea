"""The stability suite: every strategy on every case where some strategy is known to fail.

Each case is a small scene file in ``cases/`` (its header says what failure it shows), looked
at straight down: a receiver plate fills the view, lit by the light under test, which the
camera never sees directly. For each strategy the suite measures relMSE against a high-spp MIS
render of the same case, the bias z-score of the image mean per channel (worst channel), the
count of NaN/Inf samples and the time. ``blind`` strategies cannot see the case's light at all
(a point light for hemisphere and BSDF sampling, a mirror for light sampling): they must return
exactly zero.

The same module checks Veach's bound for the balance heuristic (thesis, theorem 9.2): among
all estimators that take n_l light and n_b BSDF samples and combine them with weights that sum
to one, the balance heuristic's variance exceeds the best one's by at most
(1 / min(n_l, n_b) - 1 / (n_l + n_b)) mu^2. Using only the light (or only the BSDF) sample is
such an estimator, so with one of each: Var[F_balance] <= Var[F_i, 1 sample] + mu^2 / 2 for
either technique i, at every shading point. It is evaluated on rays through pixel centres (no
jitter), so the per-point variance is exactly what the theorem bounds.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import save_figure, write_text
from ..estimator import DirectLighting
from ..film import Film
from ..render_loop import RenderSettings, render_complete
from ..sampler_choice import DEFAULT_SAMPLER
from ..scene import Scene, load_scene
from ..strategy import STRATEGIES, Strategy
from . import metrics, statistics

# The suite's columns: every strategy, then light and MIS with each solid-angle light sampling
# (``tracer.lights``), then light, MIS and ris with lights picked by a light BVH, then (on the
# cases with an environment only: ``Case.environment``) light and MIS with the environment
# sampled uniformly, MIS with it compensated, and light and MIS with it sampled by product with
# the BSDF, as (column, strategy, light sampling, light selection, environment sampling).
COLUMNS = tuple((name, name, "area", "power", "luminance") for name in STRATEGIES) + tuple(
    (f"{name}_{sampling}", name, sampling, "power", "luminance") for name in ("light", "mis")
    for sampling in ("solid-angle", "solid-angle-cos")) + tuple(
    (f"{name}_bvh", name, "area", "bvh", "luminance") for name in ("light", "mis", "ris")) + (
    ("light_uniform-env", "light", "area", "power", "uniform"),
    ("mis_uniform-env", "mis", "area", "power", "uniform"),
    ("mis_compensated-env", "mis", "area", "power", "compensated"),
    ("light_product-env", "light", "area", "power", "product"),
    ("mis_product-env", "mis", "area", "power", "product"))
COLUMN_NAMES = tuple(column for column, *_ in COLUMNS)
# The columns that differ from another only in how the environment is sampled.
ENVIRONMENT_COLUMNS = tuple(column for column, *_, environment in COLUMNS if environment != "luminance")
# ris takes this many times the case's light and BSDF samples as candidates (4 + 4 by default).
RIS_CANDIDATE_FACTOR = 4
SIZE = 32
SPP = 64
REFERENCE_SPP = 1024
CASE_DIR = Path(str(resources.files(__package__) / "cases"))  # the cases' scene files, shipped


@dataclass
class Case:
    """A stability case: its scene file, the strategies blind to its light, the strategies whose
    image mean is reliably normal at the suite's spp (checked for bias), and sample counts.

    scene : the scene file's name in ``cases/`` without ``.toml`` (None: the case's name);
        cases that differ only in their sample counts share one.
    size : the image's width and height in pixels (the file's own size is replaced).
    veach : the technique Veach's bound is checked against: the one that handles this case
        well, so that its variance is estimated reliably (the other one's is underestimated
        where it almost never finds the light). None: not checked.
    environment : the scene has an environment: the ``ENVIRONMENT_COLUMNS`` run on it too.
    untestable : columns left out of the bias test although their strategy is ``testable``
        (heavy-tailed there at the suite's spp: a normal bound on the image mean does not hold).
    """

    name: str
    description: str
    scene: str | None = None
    blind: tuple[str, ...] = ()
    testable: tuple[str, ...] = ("light", "mis")
    light_samples: int = 1
    bsdf_samples: int = 1
    veach: str | None = None
    size: int = SIZE
    environment: bool = False
    untestable: tuple[str, ...] = ()

    @property
    def path(self) -> Path:
        return CASE_DIR / f"{self.scene or self.name}.toml"

    @property
    def columns(self) -> tuple[tuple[str, str, str, str, str], ...]:
        """The suite's columns this case runs (``COLUMNS``)."""
        return tuple(c for c in COLUMNS if self.environment or c[0] not in ENVIRONMENT_COLUMNS)

    def strategy(self, name: str, heuristic: str = "power", light_sampling: str = "area",
                 light_selection: str = "power", environment_sampling: str = "luminance") -> Strategy:
        factor = RIS_CANDIDATE_FACTOR if name == "ris" else 1
        return Strategy(name, heuristic, factor * self.light_samples, factor * self.bsdf_samples,
                        light_sampling=light_sampling, light_selection=light_selection,
                        environment_sampling=environment_sampling)


def cases(size: int = SIZE) -> list[Case]:
    """The suite's cases, rendered at ``size`` x ``size`` pixels."""
    hemisphere = ("uniform", "cosine", "bsdf")  # the strategies that cannot hit a point light
    out = [
        Case("tiny_light", "sphere light of radius 1e-3", veach="light"),
        Case("tiny_sphere_light", "true sphere light of radius 1e-3 (a cone of 1e-6 sr)", veach="light"),
        Case("inside_sphere_light", "shading points inside a sphere light (it gives 0 there)"),
        Case("big_light", "an emitter filling most of the hemisphere",
             testable=STRATEGIES, veach="bsdf"),
        Case("grazing_light", "light arriving at grazing angles",
             testable=("light", "mis", "bsdf", "cosine"), veach="light"),
        Case("light_behind", "light behind the receiver (expected: black)",
             testable=STRATEGIES),
        Case("point_light", "a point light", blind=hemisphere),
        Case("mirror_small_light", "ideal mirror under a small light",
             blind=("uniform", "cosine", "light"), testable=("bsdf", "mis")),
        Case("mirror_large_light", "ideal mirror under a large light",
             blind=("uniform", "cosine", "light"), testable=("bsdf", "mis")),
        Case("ggx_1e-4_small_light", "GGX alpha 1e-4 under a small light",
             testable=("bsdf", "mis")),
        Case("ggx_1e-4_large_light", "GGX alpha 1e-4 under a large light",
             testable=("bsdf", "mis"), veach="bsdf"),
        Case("zero_area_triangles", "emissive and receiving meshes with zero-area triangles",
             testable=("light", "mis", "bsdf", "cosine"), veach="light"),
        Case("conductor_small_light", "smooth gold (conductor Fresnel) under a small light",
             blind=("uniform", "cosine", "light"), testable=("bsdf", "mis")),
        Case("beckmann_1e-3_small_light", "Beckmann alpha 1e-3 under a small light",
             testable=("bsdf", "mis")),
        Case("plastic_small_light", "smooth plastic: light sampling cannot see the coating",
             testable=("mis",)),
        Case("roughplastic_small_light", "rough plastic (Beckmann 0.02): BSDF sampling misses the light",
             testable=("mis",)),
        Case("bright_light_behind_wall", "power selection wastes its samples on a light facing away",
             testable=("bsdf", "mis", "ris")),
        Case("dim_light_near", "power selection rarely picks the near, dim light", testable=("mis", "ris")),
        Case("occluded_bright_light", "RIS's unshadowed target ranks a hidden light first",
             testable=("bsdf", "cosine", "mis")),
        Case("tiny_sun_environment", "a tiny hot sun in a dim sky (environment map)", environment=True,
             testable=("light", "mis"), untestable=("light_uniform-env", "mis_uniform-env")),
        Case("mirror_environment", "ideal mirror under a sky (environment map)", environment=True,
             blind=("uniform", "cosine", "light"), testable=("bsdf", "mis")),
        Case("near_uniform_environment", "a near-uniform sky (environment map): importance gains nothing",
             environment=True, testable=STRATEGIES),
    ]
    for scale in ("0.001", "1000"):
        out.append(Case(f"scaled_{scale}", f"a small quad light, every length x {scale}"))
    for n_light, n_bsdf in ((4, 1), (1, 4), (4, 4)):
        out.append(Case(f"point_light_{n_light}l_{n_bsdf}b",
                        f"point light, {n_light} light + {n_bsdf} BSDF samples (must not brighten)",
                        scene="point_light", blind=hemisphere, light_samples=n_light, bsdf_samples=n_bsdf))
    return [dataclasses.replace(c, size=size) for c in out]


def load_case(case: Case) -> Scene:
    """The case's scene at ``case.size`` x ``case.size`` pixels."""
    return load_scene(case.path, width=case.size, height=case.size)


@dataclass
class Cell:
    """One strategy on one case."""

    case: str
    strategy: str
    relmse: float
    z: float
    nonfinite: int
    seconds: float
    mean: list[float]
    reference_mean: list[float]
    blind: bool
    testable: bool
    zero: bool
    chose: str = ""  # the auto column: the strategy its pilot chose (``Strategy.slug``)


def _image_mean_z(film: Film, reference: Film) -> float:
    """Worst-channel z of the image mean against the reference's."""
    z = statistics.image_mean_z(film.mean, film.variance_of_mean(), reference.mean,
                                reference.variance_of_mean())
    return statistics.worst_channel(z)


def run_case(
    case: Case,
    scene: Scene,
    spp: int = SPP,
    seed: int = 0,
    threads: int = 2,
    reference_spp: int = REFERENCE_SPP,
    sampler: str = DEFAULT_SAMPLER,
) -> list[Cell]:
    """Every strategy on one case, rendered with ``sampler``, against a ``reference_spp`` MIS
    render of it (independent samples). The image-mean z-test reads the variance channel,
    which every sampler keeps honest (``tracer.film``)."""
    # The reference always takes 1 light + 1 BSDF sample, so that a sample count that changes
    # the expected value (an image that brightens with the count) shows as bias.
    reference = render_complete(
        scene, Strategy("mis"), RenderSettings(spp=reference_spp, seed=seed + 1_000_000, threads=threads)
    ).film
    cells = []
    for column, name, sampling, selection, environment in case.columns:
        settings = RenderSettings(spp=spp, seed=seed, threads=threads, sampler=sampler)
        strategy = case.strategy(name, light_sampling=sampling, light_selection=selection,
                                 environment_sampling=environment)
        result = render_complete(scene, strategy, settings)
        film = result.film
        chose = Strategy.from_record(film.record) if name == "auto" else None
        # auto is as testable as the strategy it chose (its image is that strategy's render).
        tested = chose.name if chose is not None else name
        cells.append(
            Cell(
                case=case.name,
                strategy=column,
                relmse=metrics.relmse(film.mean, reference.mean),
                z=_image_mean_z(film, reference),
                nonfinite=result.nonfinite,
                seconds=result.seconds,
                mean=film.mean.mean(axis=0).tolist(),
                reference_mean=reference.mean.mean(axis=0).tolist(),
                blind=name in case.blind,
                testable=tested in case.testable and tested not in case.blind and column not in case.untestable,
                zero=bool(np.all(film.mean == 0.0)),
                chose=chose.slug if chose is not None else "",
            )
        )
    return cells


def veach_bound(
    case: Case, scene: Scene, samples: int = 1024, size: int = 12, seed: int = 0
) -> dict[str, Any]:
    """Per-point variances of balance MIS (1 + 1 samples) and of each technique alone (1 sample),
    on rays through the centres of a size x size grid of pixels, ``samples`` each.

    Returns the summed variances, their standard errors (from fourth moments) and the theorem's
    slack sum(mu^2)/2; the bound holds when var_mis <= min(var_light, var_bsdf) + slack, up to
    the estimates' own error.
    """
    cam = scene.camera
    pixel = np.arange(cam.width * cam.height, dtype=np.int64)
    step = max(1, len(pixel) // (size * size))
    pixel = np.repeat(pixel[::step][: size * size], samples)
    sample = np.tile(np.arange(samples, dtype=np.int64), len(pixel) // samples)
    origins, dirs = cam.rays(pixel, np.full((len(pixel), 2), 0.5))
    out: dict[str, Any] = {}
    mu2 = None
    for label, strategy in (
        ("mis_balance", Strategy("mis", "balance", 1, 1)),
        ("light", Strategy("light")),
        ("bsdf", Strategy("bsdf")),
    ):
        # Sample index k of each pixel (the pixel's k-th copy): independent samples per point.
        # The estimators share the light dimensions, not the direction ones (those follow the
        # light samples in the dimension map).
        radiance = DirectLighting(scene, strategy).radiance(origins, dirs, seed=seed, pixel=pixel,
                                                            sample=sample)
        values = radiance.reshape(-1, samples, 3)
        var = values.var(axis=1, ddof=1)  # (points, 3)
        # Standard error of a sample variance: sqrt((m4 - s^4 (n-3)/(n-1)) / n).
        m4 = ((values - values.mean(axis=1, keepdims=True)) ** 4).mean(axis=1)
        se2 = np.maximum(m4 - var**2 * (samples - 3) / (samples - 1), 0.0) / samples
        out[label] = float(var.sum())
        out[f"{label}_se"] = float(np.sqrt(se2.sum()))
        if label == "mis_balance":
            mu2 = (values.mean(axis=1) ** 2).sum()
    out["slack"] = float(mu2) / 2.0
    out["technique"] = case.veach
    return out


def run_suite(
    out: Path | None,
    spp: int = SPP,
    size: int = SIZE,
    seed: int = 0,
    threads: int = 2,
    stream=None,
    reference_spp: int = REFERENCE_SPP,
    sampler: str = DEFAULT_SAMPLER,
) -> dict[str, Any]:
    """Run every case with ``sampler``; write stability.json and stability.png into ``out`` if
    given."""
    stream = stream if stream is not None else sys.stderr
    cells: list[Cell] = []
    veach: dict[str, dict[str, Any]] = {}
    for case in cases(size):
        start = time.perf_counter()
        scene = load_case(case)
        cells += run_case(case, scene, spp, seed, threads, reference_spp, sampler)
        if case.veach:
            veach[case.name] = veach_bound(case, scene, seed=seed)
        print(f"  {case.name}: {time.perf_counter() - start:.1f} s", file=stream)
    doc = {
        "spp": spp,
        "size": size,
        "reference_spp": reference_spp,
        "sampler": sampler,
        "cases": {c.name: c.description for c in cases(size)},
        "cells": [c.__dict__ for c in cells],
        "veach_bound": veach,
    }
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        write_text(out / "stability.json", json.dumps(doc, indent=2) + "\n")
        heat_map(cells, out / "stability.png")
    return doc


def expectations(doc: dict[str, Any], alpha: float = 0.01) -> list[str]:
    """What must hold, as a list of violations (empty: all hold).

    - every cell is finite and no sample was NaN or infinite;
    - a blind strategy returns exactly zero;
    - a testable strategy's image mean is within the two-sided normal bound of the reference's
      (Sidak-corrected over all testable cells, 1% family false-alarm rate);
    - Veach's bound holds, up to a one-sided normal bound on the variance estimates' error
      (Sidak over the cases checked).
    """
    cells = [Cell(**c) if isinstance(c, dict) else c for c in doc["cells"]]
    problems = []
    for c in cells:
        if not (np.isfinite(c.relmse) and np.all(np.isfinite(c.mean))) or c.nonfinite:
            problems.append(f"{c.case}/{c.strategy}: not finite ({c.nonfinite} NaN/Inf samples)")
        if c.blind and not c.zero:
            problems.append(f"{c.case}/{c.strategy}: blind to the light but not zero")
    testable = [c for c in cells if c.testable]
    z_crit = statistics.z_critical(alpha, len(testable))
    for c in testable:
        if not abs(c.z) <= z_crit:
            problems.append(f"{c.case}/{c.strategy}: biased, image mean z = {c.z:+.2f} (bound {z_crit:.2f})")
    bounds = doc.get("veach_bound", {})
    z_veach = statistics.z_critical(alpha, len(bounds), sides=1)
    for name, b in bounds.items():
        best = b["technique"]
        excess = b["mis_balance"] - (b[best] + b["slack"])
        se = np.hypot(b["mis_balance_se"], b[f"{best}_se"])
        if excess > z_veach * se + 1e-12:
            problems.append(
                f"{name}: balance MIS variance {b['mis_balance']:.4g} exceeds Veach's bound "
                f"{b[best] + b['slack']:.4g} by {excess / max(se, 1e-300):.1f} standard errors"
            )
    return problems


def format_table(cells: list[Cell]) -> str:
    """Strategy x case table: relMSE / bias z / NaN+Inf count / seconds per cell."""
    names = list(dict.fromkeys(c.case for c in cells))
    width = max(len(n) for n in names)
    head = f"{'case':<{width}}  " + "  ".join(f"{s:>27}" for s in COLUMN_NAMES)
    lines = [head, f"{'':<{width}}  " + "  ".join(f"{'relMSE     z  bad      s':>27}" for _ in COLUMN_NAMES)]
    for name in names:
        row = {c.strategy: c for c in cells if c.case == name}
        parts = []
        for s in COLUMN_NAMES:
            c = row.get(s)
            if c is None:  # an environment column on a case without one
                parts.append(f"{'-':>27}")
            elif c.blind:
                parts.append(f"{'blind (' + ('zero' if c.zero else 'NOT ZERO') + ')':>27}")
            else:
                parts.append(f"{c.relmse:>9.3g} {c.z:>+6.2f} {c.nonfinite:>4d} {c.seconds:>6.2f}")
        lines.append(f"{name:<{width}}  " + "  ".join(parts))
    return "\n".join(lines)


def heat_map(cells: list[Cell], path: Path) -> None:
    """log10 relMSE per strategy x case, annotated; blind cells hatched grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(c.case for c in cells))
    grid = np.full((len(names), len(COLUMN_NAMES)), np.nan)
    fig, ax = plt.subplots(figsize=(17, 0.5 * len(names) + 2.4))
    for c in cells:
        i, j = names.index(c.case), COLUMN_NAMES.index(c.strategy)
        if not c.blind:
            grid[i, j] = np.log10(max(c.relmse, 1e-12))
    im = ax.imshow(grid, cmap="magma_r", vmin=-6, vmax=2, aspect="auto")
    for c in cells:
        i, j = names.index(c.case), COLUMN_NAMES.index(c.strategy)
        if c.blind:
            # facecolor and edgecolor apart: ``color`` set both, and the hatch (drawn in the edge
            # colour) vanished into the face.
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, facecolor="#eeeeee", edgecolor="#888888",
                                       hatch="///", linewidth=0.0))
            ax.text(j, i, "blind: 0", ha="center", va="center", fontsize=7, color="#444444")
        else:
            bad = f"\n{c.nonfinite} NaN/Inf" if c.nonfinite else ""
            color = "white" if grid[i, j] > -2 else "black"
            ax.text(
                j, i, f"{c.relmse:.2g}\nz {c.z:+.1f}{bad}", ha="center", va="center", fontsize=7, color=color
            )
    # One word a line ("mis", "compensated", "env"): the environment columns' names are too
    # wide for a cell on one line.
    ax.set_xticks(range(len(COLUMN_NAMES)),
                  [n.replace("_", "\n").replace("-env", "\nenv") for n in COLUMN_NAMES], fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_title("relMSE per strategy and case (z: bias of the image mean, in standard errors)", fontsize=10)
    fig.colorbar(im, ax=ax, label="log10 relMSE", fraction=0.04)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
