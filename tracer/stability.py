"""The stability suite: every strategy on every case where some strategy is known to fail.

Each case is a small scene (written to a temporary folder) looked at straight down: a receiver
plate fills the view, lit by the light under test, which the camera never sees directly. For
each strategy the suite measures relMSE against a high-spp MIS render of the same case, the
bias z-score of the image mean per channel (worst channel), the count of NaN/Inf samples and
the time. ``blind`` strategies cannot see the case's light at all (a point light for hemisphere
and BSDF sampling, a mirror for light sampling): they must return exactly zero.

The same module checks Veach's bound for the balance heuristic (thesis, theorem 9.2): among
all estimators that take n_l light and n_b BSDF samples and combine them with weights that sum
to one, the balance heuristic's variance exceeds the best one's by at most
(1 / min(n_l, n_b) - 1 / (n_l + n_b)) mu^2. Using only the light (or only the BSDF) sample is
such an estimator, so with one of each: Var[F_balance] <= Var[F_i, 1 sample] + mu^2 / 2 for
either technique i, at every shading point. It is evaluated on rays through pixel centres (no
jitter), so the per-point variance is exactly what the theorem bounds.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import metrics
from .atomic import save_figure, write_text
from .estimators import DirectLighting, Strategy
from .film import Film
from .render import RenderSettings, render
from .scene import STRATEGIES, Scene, load_scene

SIZE = 32
SPP = 64
REFERENCE_SPP = 1024

CAMERA = """
[camera]
origin = {origin}
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]
fov = 40.0
width = {size}
height = {size}
"""

MATERIALS = """
[materials.matte]
type = "diffuse"
reflectance = [0.6, 0.6, 0.6]
[materials.mirror]
type = "mirror"
reflectance = [0.9, 0.9, 0.9]
[materials.glossy]
type = "roughconductor"
alpha = 0.0001
reflectance = [0.9, 0.9, 0.9]
"""


def _quad(origin, edge1, edge2, material: str | None = None, emission=None) -> str:
    lines = [
        "[[shapes]]",
        'type = "quad"',
        f"origin = {list(map(float, origin))}",
        f"edge1 = {list(map(float, edge1))}",
        f"edge2 = {list(map(float, edge2))}",
    ]
    if material:
        lines.append(f'material = "{material}"')
    if emission is not None:
        lines.append(f"emission = {list(map(float, emission))}")
    return "\n".join(lines) + "\n"


def _receiver(material: str, scale: float = 1.0) -> str:
    """A 2 x 2 plate at y = 0, front side up (edge1 x edge2 = +y)."""
    s = scale
    return _quad([-s, 0, -s], [0, 0, 2 * s], [2 * s, 0, 0], material=material)


def _light_quad(center, size: float, emission: float, facing: str = "down") -> str:
    """A square emitter centred at ``center``; ``down`` faces -y, ``up`` faces +y."""
    c, h = np.asarray(center, dtype=float), size / 2
    if facing == "down":
        return _quad(c + [-h, 0, -h], [size, 0, 0], [0, 0, size], emission=[emission] * 3)
    return _quad(c + [-h, 0, -h], [0, 0, size], [size, 0, 0], emission=[emission] * 3)


@dataclass
class Case:
    """A stability case: its scene text, the strategies blind to its light, the strategies whose
    image mean is reliably normal at the suite's spp (checked for bias), and sample counts."""

    name: str
    description: str
    text: str
    blind: tuple[str, ...] = ()
    testable: tuple[str, ...] = ("light", "mis")
    light_samples: int = 1
    bsdf_samples: int = 1
    files: dict[str, str] = field(default_factory=dict)
    # The technique Veach's bound is checked against: the one that handles this case well, so
    # that its variance is estimated reliably (the other one's is underestimated where it
    # almost never finds the light). None: not checked.
    veach: str | None = None

    def strategy(self, name: str, heuristic: str = "power") -> Strategy:
        return Strategy(name, heuristic, self.light_samples, self.bsdf_samples)


def _degenerate_ply(y: float, half: float, facing_down: bool) -> str:
    """A square at height y (side 2 half) as two real triangles plus two zero-area ones (a
    repeated vertex, three collinear vertices); front side down or up."""
    h = half
    faces = ["3 0 1 2", "3 0 2 3"] if facing_down else ["3 0 2 1", "3 0 3 2"]
    faces += ["3 4 4 5", "3 0 4 2"]  # degenerate: a repeated index; 0, 4, 2 lie on one diagonal
    return "\n".join(
        [
            "ply",
            "format ascii 1.0",
            "element vertex 6",
            "property float x",
            "property float y",
            "property float z",
            "element face 4",
            "property list uchar int vertex_indices",
            "end_header",
            f"{-h} {y} {-h}",
            f"{h} {y} {-h}",
            f"{h} {y} {h}",
            f"{-h} {y} {h}",
            f"0 {y} 0",
            f"{h / 2} {y} {h / 2}",
            *faces,
            "",
        ]
    )


def cases(size: int = SIZE) -> list[Case]:
    """The suite's cases (scene texts at ``size`` x ``size`` pixels)."""
    cam = CAMERA.format(origin=[0.0, 1.0, 0.0], size=size)
    base = cam + MATERIALS
    matte = _receiver("matte")
    out = [
        Case(
            "tiny_light",
            "sphere light of radius 1e-3",
            base
            + matte
            + """
[[shapes]]
type = "sphere"
center = [0.3, 1.2, 0.1]
radius = 0.001
subdivisions = 1
emission = [400000.0, 400000.0, 400000.0]
""",
            testable=("light", "mis"),
            veach="light",
        ),
        Case(
            "big_light",
            "an emitter filling most of the hemisphere",
            base + matte + _light_quad([0, 1.05, 0], 30.0, 1.0),
            testable=STRATEGIES,
            veach="bsdf",
        ),
        Case(
            "grazing_light",
            "light arriving at grazing angles",
            base + matte + _quad([1.5, 0.0, -1.0], [0, 0, 2.0], [0, 0.08, 0], emission=[40.0] * 3),
            testable=("light", "mis", "bsdf", "cosine"),
            veach="light",
        ),
        Case(
            "light_behind",
            "light behind the receiver (expected: black)",
            base + matte + _light_quad([0, -0.5, 0], 1.0, 5.0, facing="up"),
            testable=STRATEGIES,
        ),
        Case(
            "point_light",
            "a point light",
            base
            + matte
            + """
[[lights]]
type = "point"
position = [0.2, 0.8, 0.1]
intensity = [1.0, 1.0, 1.0]
""",
            blind=("uniform", "cosine", "bsdf"),
        ),
        Case(
            "mirror_small_light",
            "ideal mirror under a small light",
            base + _receiver("mirror") + _light_quad([0, 2.0, 0], 0.2, 50.0),
            blind=("uniform", "cosine", "light"),
            testable=("bsdf", "mis"),
        ),
        Case(
            "mirror_large_light",
            "ideal mirror under a large light",
            base + _receiver("mirror") + _light_quad([0, 2.0, 0], 4.0, 1.0),
            blind=("uniform", "cosine", "light"),
            testable=("bsdf", "mis"),
        ),
        Case(
            "ggx_1e-4_small_light",
            "GGX alpha 1e-4 under a small light",
            base + _receiver("glossy") + _light_quad([0, 2.0, 0], 0.2, 50.0),
            testable=("bsdf", "mis"),
        ),
        Case(
            "ggx_1e-4_large_light",
            "GGX alpha 1e-4 under a large light",
            base + _receiver("glossy") + _light_quad([0, 2.0, 0], 4.0, 1.0),
            testable=("bsdf", "mis"),
            veach="bsdf",
        ),
        Case(
            "zero_area_triangles",
            "emissive and receiving meshes with zero-area triangles",
            base
            + '[[shapes]]\ntype = "mesh"\nfile = "light.ply"\nemission = [20.0, 20.0, 20.0]\n'
            + '[[shapes]]\ntype = "mesh"\nfile = "receiver.ply"\nmaterial = "matte"\n',
            files={
                "light.ply": _degenerate_ply(1.5, 0.2, True),
                "receiver.ply": _degenerate_ply(0.0, 1.0, False),
            },
            testable=("light", "mis", "bsdf", "cosine"),
            veach="light",
        ),
    ]
    for scale in (1e-3, 1e3):
        text = CAMERA.format(origin=[0.0, scale, 0.0], size=size) + MATERIALS + _receiver("matte", scale)
        text += _light_quad([0, 1.5 * scale, 0], 0.4 * scale, 20.0)
        out.append(
            Case(
                f"scaled_{scale:g}",
                f"a small quad light, every length x {scale:g}",
                text,
                testable=("light", "mis"),
            )
        )
    point = (
        base + matte + '[[lights]]\ntype = "point"\nposition = [0.2, 0.8, 0.1]\nintensity = [1.0, 1.0, 1.0]\n'
    )
    for n_light, n_bsdf in ((4, 1), (1, 4), (4, 4)):
        out.append(
            Case(
                f"point_light_{n_light}l_{n_bsdf}b",
                f"point light, {n_light} light + {n_bsdf} BSDF samples (must not brighten)",
                point,
                blind=("uniform", "cosine", "bsdf"),
                light_samples=n_light,
                bsdf_samples=n_bsdf,
            )
        )
    return out


def load_case(case: Case, folder: Path) -> Scene:
    path = folder / f"{case.name}.toml"
    path.write_text(case.text)
    for name, content in case.files.items():
        (folder / name).write_text(content)
    return load_scene(path)


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


def _image_mean_z(film: Film, reference: Film) -> float:
    """Worst-channel z of the image mean against the reference's."""
    z = metrics.image_mean_z(film.mean, film.variance_of_mean(), reference.mean, reference.variance_of_mean())
    return float(z[np.argmax(np.abs(z))])


def run_case(
    case: Case,
    scene: Scene,
    spp: int = SPP,
    seed: int = 0,
    threads: int = 2,
    reference_spp: int = REFERENCE_SPP,
) -> list[Cell]:
    """Every strategy on one case, against a ``reference_spp`` MIS render of it."""
    # The reference always takes 1 light + 1 BSDF sample, so that a sample count that changes
    # the expected value (an image that brightens with the count) shows as bias.
    reference = render(
        scene, Strategy("mis"), RenderSettings(spp=reference_spp, seed=seed + 1_000_000, threads=threads)
    ).film
    cells = []
    for name in STRATEGIES:
        result = render(scene, case.strategy(name), RenderSettings(spp=spp, seed=seed, threads=threads))
        film = result.film
        cells.append(
            Cell(
                case=case.name,
                strategy=name,
                relmse=metrics.relmse(film.mean, reference.mean),
                z=_image_mean_z(film, reference),
                nonfinite=result.nonfinite,
                seconds=result.seconds,
                mean=film.mean.mean(axis=0).tolist(),
                reference_mean=reference.mean.mean(axis=0).tolist(),
                blind=name in case.blind,
                testable=name in case.testable and name not in case.blind,
                zero=bool(np.all(film.mean == 0.0)),
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
    pixel = np.arange(cam.width * cam.height)
    step = max(1, len(pixel) // (size * size))
    pixel = np.repeat(pixel[::step][: size * size], samples)
    origins, dirs = cam.rays(pixel, np.full((len(pixel), 2), 0.5))
    out: dict[str, Any] = {}
    mu2 = None
    for label, strategy in (
        ("mis_balance", Strategy("mis", "balance", 1, 1)),
        ("light", Strategy("light")),
        ("bsdf", Strategy("bsdf")),
    ):
        radiance = DirectLighting(scene, strategy).radiance(origins, dirs, np.random.default_rng(seed))
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
) -> dict[str, Any]:
    """Run every case; write stability.json and stability.png into ``out`` if given."""
    stream = stream if stream is not None else sys.stderr
    cells: list[Cell] = []
    veach: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases(size):
            start = time.perf_counter()
            scene = load_case(case, Path(tmp))
            cells += run_case(case, scene, spp, seed, threads, reference_spp)
            if case.veach:
                veach[case.name] = veach_bound(case, scene, seed=seed)
            print(f"  {case.name}: {time.perf_counter() - start:.1f} s", file=stream)
    doc = {
        "spp": spp,
        "size": size,
        "reference_spp": reference_spp,
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
    from scipy import stats

    cells = [Cell(**c) if isinstance(c, dict) else c for c in doc["cells"]]
    problems = []
    for c in cells:
        if not (np.isfinite(c.relmse) and np.all(np.isfinite(c.mean))) or c.nonfinite:
            problems.append(f"{c.case}/{c.strategy}: not finite ({c.nonfinite} NaN/Inf samples)")
        if c.blind and not c.zero:
            problems.append(f"{c.case}/{c.strategy}: blind to the light but not zero")
    testable = [c for c in cells if c.testable]
    z_crit = stats.norm.isf(metrics.sidak(alpha, len(testable)) / 2.0)
    for c in testable:
        if not abs(c.z) <= z_crit:
            problems.append(f"{c.case}/{c.strategy}: biased, image mean z = {c.z:+.2f} (bound {z_crit:.2f})")
    bounds = doc.get("veach_bound", {})
    z_veach = stats.norm.isf(metrics.sidak(alpha, len(bounds)))
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
    head = f"{'case':<{width}}  " + "  ".join(f"{s:>27}" for s in STRATEGIES)
    lines = [head, f"{'':<{width}}  " + "  ".join(f"{'relMSE     z  bad      s':>27}" for _ in STRATEGIES)]
    for name in names:
        row = {c.strategy: c for c in cells if c.case == name}
        parts = []
        for s in STRATEGIES:
            c = row[s]
            if c.blind:
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
    grid = np.full((len(names), len(STRATEGIES)), np.nan)
    fig, ax = plt.subplots(figsize=(9, 0.5 * len(names) + 2))
    for c in cells:
        i, j = names.index(c.case), STRATEGIES.index(c.strategy)
        if not c.blind:
            grid[i, j] = np.log10(max(c.relmse, 1e-12))
    im = ax.imshow(grid, cmap="magma_r", vmin=-6, vmax=2, aspect="auto")
    for c in cells:
        i, j = names.index(c.case), STRATEGIES.index(c.strategy)
        if c.blind:
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, color="#dddddd", hatch="//", ec="#999999"))
            ax.text(j, i, "blind: 0", ha="center", va="center", fontsize=7, color="#444444")
        else:
            bad = f"\n{c.nonfinite} NaN/Inf" if c.nonfinite else ""
            color = "white" if grid[i, j] > -2 else "black"
            ax.text(
                j, i, f"{c.relmse:.2g}\nz {c.z:+.1f}{bad}", ha="center", va="center", fontsize=7, color=color
            )
    ax.set_xticks(range(len(STRATEGIES)), STRATEGIES)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_title("relMSE per strategy and case (z: bias of the image mean, in standard errors)", fontsize=10)
    fig.colorbar(im, ax=ax, label="log10 relMSE", fraction=0.04)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
