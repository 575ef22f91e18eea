"""Monte Carlo primer: the course-notes results that tracer grew out of, each one run, shown as
a table and a figure, and checked by a statistical test (``tests/test_primer.py``).

    1. inversion   the inversion method on the exponential distribution, with a KS test
    2. rejection   pi by rejection in a triangle and in a square; the curse of dimensionality
    3. importance  importance sampling, discrete and continuous: measured against exact variance
    4. mis         multiple importance sampling: which weights are unbiased, which win
    5. qmc         plain Monte Carlo against scrambled Sobol points: fitted error rates

Each exercise is one function ``name(rng, out_dir=None, ...) -> Result``. It returns the rows of
its tables and the numbers the tests check, so the tests check the code the command runs; with
``out_dir`` it also writes ``primer_<k>_<name>.png`` there. ``run_all`` runs all five and prints
the tables; ``main`` is what ``tracer primer`` calls.

Conventions: every measured quantity is printed with its standard error (SE) and a z-score
z = (measured - exact) / SE against the exact value; |z| < 3 is agreement within 3 SE. The
exact values are closed forms, or numpy Gauss-Legendre quadrature where there is none.
Randomness comes from the Generator passed in, never from the global ``np.random``; ``run_all``
gives each exercise its own stream spawned from one seed, so one exercise's numbers do not
change when another draws more or fewer samples.

Dependencies: numpy and matplotlib only, except exercise 5, which takes scrambled Sobol points
from ``scipy.stats.qmc`` and is skipped with a one-line message when scipy is missing.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..atomic import save_figure
from ..errors import InputError

SQRT3 = math.sqrt(3.0)
AGREE_SE = 3.0  # the tables call |z| < 3 agreement


# ---------------------------------------------------------------------------------------------
# Results, tables and figures


@dataclass
class Result:
    """One exercise's outcome.

    ``tables`` maps a caption to rows (dicts with the same keys, printed as aligned columns);
    ``numbers`` holds what the tests check (names documented by each exercise); ``figure`` is
    the PNG written, if any; ``skipped`` says why the exercise did not run, if it did not.
    """

    name: str
    title: str
    claim: str
    tables: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    numbers: dict[str, Any] = field(default_factory=dict)
    figure: Path | None = None
    skipped: str | None = None


def _fmt(column: str, value: Any) -> str:
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        value = float(value)
        if column.startswith("z"):
            return f"{value:+.2f}"
        if value == 0.0:
            return "0"
        return f"{value:.5g}"
    return str(value)


def format_table(rows: list[dict[str, Any]], indent: str = "  ") -> str:
    """Rows of dicts as plain aligned text: text columns left-aligned, numbers right-aligned."""
    if not rows:
        return ""
    columns = list(rows[0])
    cells = [[_fmt(c, r.get(c, "")) for c in columns] for r in rows]
    width = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    numeric = [all(isinstance(r.get(c), int | float | np.number) and not isinstance(r.get(c), bool)
                   for r in rows) for c in columns]

    def line(items: list[str]) -> str:
        return indent + "  ".join(s.rjust(w) if num else s.ljust(w)
                                  for s, w, num in zip(items, width, numeric, strict=True)).rstrip()

    out = [line(columns), indent + "  ".join("-" * w for w in width)]
    out += [line(row) for row in cells]
    return "\n".join(out)


def print_result(result: Result, stream: TextIO | None = None) -> None:
    """The title line, the one-sentence claim, then each table under its caption (to stdout
    unless ``stream`` is given; looked up at call time so redirections are honoured)."""
    stream = stream if stream is not None else sys.stdout
    print(f"\n{result.title}", file=stream)
    print(f"  {result.claim}", file=stream)
    if result.skipped:
        print(f"  skipped: {result.skipped}", file=stream)
        return
    for caption, rows in result.tables.items():
        print(f"\n  {caption}", file=stream)
        print(format_table(rows), file=stream)
    if result.figure is not None:
        print(f"\n  figure: {result.figure}", file=stream)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only, no display: works on a headless machine
    import matplotlib.pyplot as plt

    return plt


def _save_figure(fig, path: Path) -> Path:
    """Save atomically (never a torn PNG) and return the path."""
    save_figure(fig, path)
    return path


def _finish_figure(plt, fig, out_dir: Path, stem: str) -> Path:
    fig.tight_layout()
    path = _save_figure(fig, Path(out_dir) / f"{stem}.png")
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------
# Shared statistics


def z_score(measured: float, exact: float, se: float) -> float:
    """(measured - exact) / se; 0 when both agree exactly with se = 0, else +-inf."""
    if se > 0.0:
        return (measured - exact) / se
    return 0.0 if measured == exact else math.copysign(math.inf, measured - exact)


def variance_se(variance: float, mu4: float, n: int) -> float:
    """Standard error of the unbiased sample variance of n iid values with variance ``variance``
    and fourth central moment ``mu4``: Var(s^2) = mu4/n - sigma^4 (n-3)/(n(n-1)) (Casella and
    Berger, Statistical Inference, exercise 5.8). Unlike the chi-square formula 2 sigma^4/(n-1)
    it holds for skewed, heavy-tailed values such as importance weights."""
    return math.sqrt(max(mu4 / n - variance**2 * (n - 3) / (n * (n - 1)), 0.0))


def _mean_row(label: str, samples: np.ndarray, exact: float) -> dict[str, Any]:
    mean = float(samples.mean())
    se = float(samples.std(ddof=1) / math.sqrt(len(samples)))
    return {"quantity": label, "measured": mean, "SE": se, "exact": exact, "z": z_score(mean, exact, se),
            "agrees (3 SE)": abs(z_score(mean, exact, se)) < AGREE_SE}


def gauss_legendre(a: float, b: float, panels: int, order: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss-Legendre rule on [a, b]: ``panels`` equal panels of ``order`` nodes.

    Returns nodes and weights, both ``(panels * order,)`` float64, such that sum(w * g(x))
    approximates the integral of g. Exact for polynomials of degree 2*order - 1 on each panel;
    panels much narrower than the sharpest feature of g make it accurate to about 1e-12.
    """
    t, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(a, b, panels + 1)
    half = 0.5 * np.diff(edges)
    nodes = (edges[:-1, None] + half[:, None] * (t[None, :] + 1.0)).ravel()
    weights = (half[:, None] * w[None, :]).ravel()
    return nodes, weights


def _uniform_open0(rng: np.random.Generator, shape) -> np.ndarray:
    """Uniform on (0, 1]: ``1 - random()``. Used where u = 0 would map to a point with pdf 0
    (sqrt(0) = 0 for the pdf 2x), giving 0/0 in f/p; the half-open end excluded has measure 0."""
    return 1.0 - rng.random(shape)


# ---------------------------------------------------------------------------------------------
# 1. The inversion method


def sample_exponential(u: np.ndarray, lam: float) -> np.ndarray:
    """Inversion of F(x) = 1 - exp(-lam x): X = -log(1 - U) / lam for U uniform on [0, 1).

    ``u (n,)`` in [0, 1) -> ``(n,)`` samples with pdf lam exp(-lam x) (pbrt-v4, section 2.3,
    "Sampling Using the Inversion Method"). log1p keeps precision for small u; 1 - u > 0 since
    u < 1, so the log is finite.
    """
    return -np.log1p(-u) / lam


def exponential_cdf(x: np.ndarray, lam: float) -> np.ndarray:
    """F(x) = 1 - exp(-lam x), written with expm1 for precision near 0."""
    return -np.expm1(-lam * np.asarray(x, dtype=float))


def exponential_pdf(x: np.ndarray, lam: float) -> np.ndarray:
    return lam * np.exp(-lam * np.asarray(x, dtype=float))


def ks_statistic(samples: np.ndarray, cdf: Callable[[np.ndarray], np.ndarray]) -> float:
    """Kolmogorov-Smirnov distance D = sup |F_n(x) - F(x)| between the empirical CDF of
    ``samples (n,)`` and a continuous ``cdf``. The sup is reached at a sample, just before or
    at the jump of F_n, hence the two one-sided maxima."""
    x = np.sort(samples)
    n = len(x)
    f = cdf(x)
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - f), np.max(f - (i - 1) / n)))


def kolmogorov_sf(t: float) -> float:
    """Q_KS(t) = P(sup |Brownian bridge| > t), the limiting tail of sqrt(n) D.

    The alternating series 2 sum (-1)^(k-1) exp(-2 k^2 t^2) converges fast for large t; for
    small t its Jacobi-theta dual 1 - sqrt(2 pi)/t sum exp(-(2k-1)^2 pi^2 / (8 t^2)) does
    (Numerical Recipes, 3rd ed., section 6.14, the KSdist routine, which switches at t = 1.18).
    """
    if t <= 0.0:
        return 1.0
    k = np.arange(1, 101)
    if t < 1.18:
        y = np.exp(-((2 * k - 1) ** 2) * math.pi**2 / (8.0 * t * t))
        return float(min(max(1.0 - math.sqrt(2.0 * math.pi) / t * y.sum(), 0.0), 1.0))
    terms = 2.0 * (-1.0) ** (k - 1) * np.exp(-2.0 * k**2 * t * t)
    return float(min(max(terms.sum(), 0.0), 1.0))


def ks_test(samples: np.ndarray, cdf: Callable[[np.ndarray], np.ndarray]) -> tuple[float, float]:
    """One-sample KS test: (D, p-value). The p-value is Q_KS((sqrt(n) + 0.12 + 0.11/sqrt(n)) D)
    with Stephens' finite-n correction (Numerical Recipes, section 14.3, "Are Two Distributions
    Different?"); the tests find it within 5e-3 of scipy's exact p-value at n = 20000."""
    n = len(samples)
    d = ks_statistic(samples, cdf)
    root = math.sqrt(n)
    return d, kolmogorov_sf((root + 0.12 + 0.11 / root) * d)


KS_CRITICAL_1PCT = 1.6276  # Q_KS(t) = 0.01: the 1% critical value of sqrt(n) D


def inversion(rng: np.random.Generator, out_dir: Path | None = None, n: int = 20_000,
              lam: float = 2.0, wrong: tuple[float, ...] = (0.9, 1.1)) -> Result:
    """Exercise 1: sample Exp(lam) by inversion; KS-test the samples against the exact CDF,
    and against CDFs with a wrong rate (lam times each of ``wrong``) to show the test's power.

    numbers: ``n``, ``lam``, ``samples (n,)``, ``ks`` {rate tested: (D, p)}, ``mean``,
    ``mean_se``, ``var``, ``var_se`` (exact mean 1/lam, variance 1/lam^2, mu4 9/lam^4).
    """
    x = sample_exponential(rng.random(n), lam)
    ks = {}
    ks_rows = []
    for factor in (1.0, *wrong):
        rate = lam * factor
        d, p = ks_test(x, lambda t, r=rate: exponential_cdf(t, r))
        ks[rate] = (d, p)
        ks_rows.append({"tested against": f"Exp({rate:g})" + (" (true)" if factor == 1.0 else " (wrong)"),
                        "D": d, "sqrt(n) D": math.sqrt(n) * d, "p-value": p,
                        "rejected at 1%": p < 0.01})
    var = float(x.var(ddof=1))
    var_exact = 1.0 / lam**2
    var_se = variance_se(var_exact, 9.0 / lam**4, n)  # Exp(lam): mu4 = 9 / lam^4
    moment_rows = [_mean_row("mean", x, 1.0 / lam),
                   {"quantity": "variance", "measured": var, "SE": var_se, "exact": var_exact,
                    "z": z_score(var, var_exact, var_se),
                    "agrees (3 SE)": abs(z_score(var, var_exact, var_se)) < AGREE_SE}]
    result = Result(
        "inversion", f"1. Inversion method: X = -log(1 - U)/lam is Exp(lam), lam = {lam:g}, n = {n}",
        "The KS test accepts the samples against the exact CDF 1 - exp(-lam x) and rejects CDFs "
        "with a rate 10% off either way; mean and variance agree with 1/lam and 1/lam^2.",
        {"Kolmogorov-Smirnov tests (reject when p < 0.01)": ks_rows,
         "moments against the exact values": moment_rows},
        {"n": n, "lam": lam, "samples": x, "ks": ks, "mean": moment_rows[0]["measured"],
         "mean_se": moment_rows[0]["SE"], "var": var, "var_se": var_se})
    if out_dir is not None:
        result.figure = _inversion_figure(x, lam, wrong, ks, Path(out_dir))
    return result


def _inversion_figure(x, lam, wrong, ks, out_dir: Path) -> Path:
    plt = _pyplot()
    fig, (ax_h, ax_d) = plt.subplots(1, 2, figsize=(11, 4.2))
    top = float(np.quantile(x, 0.999))
    ax_h.hist(x, bins=80, range=(0.0, top), density=True, color="#9ecae1", edgecolor="#6baed6",
              lw=0.3, label=f"histogram of {len(x)} samples")
    grid = np.linspace(0.0, top, 400)
    ax_h.plot(grid, exponential_pdf(grid, lam), color="#d62728", lw=1.8,
              label=f"density {lam:g} exp(−{lam:g} x)")
    ax_h.set_xlabel("x")
    ax_h.set_ylabel("density")
    ax_h.set_title("inversion samples against the exact density", fontsize=10)
    ax_h.legend(fontsize=8)

    # KS: the whole empirical CDF minus the tested CDF; the test rejects when it leaves the band.
    xs = np.sort(x)
    ecdf = np.arange(1, len(xs) + 1) / len(xs)
    band = KS_CRITICAL_1PCT / math.sqrt(len(xs))
    colors = ["#2ca02c", "#ff7f0e", "#d62728", "#9467bd"]
    for factor, color in zip((1.0, *wrong), colors, strict=False):
        rate = lam * factor
        d, p = ks[rate]
        ax_d.plot(xs, ecdf - exponential_cdf(xs, rate), color=color, lw=1.0,
                  label=f"tested against Exp({rate:g}): D = {d:.4f}, p = {p:.2g}")
    ax_d.axhspan(-band, band, color="0.85", zorder=0, label=f"1% acceptance band ±{band:.4f}")
    ax_d.axhline(0.0, color="k", lw=0.6)
    ax_d.set_xlim(0.0, top)
    ax_d.set_xlabel("x")
    ax_d.set_ylabel("empirical CDF − tested CDF")
    ax_d.set_title("Kolmogorov-Smirnov: accepts the true rate, rejects wrong ones", fontsize=10)
    ax_d.legend(fontsize=8, loc="lower right")
    return _finish_figure(plt, fig, out_dir, "primer_1_inversion")


# ---------------------------------------------------------------------------------------------
# 2. Rejection sampling and pi

# Equilateral triangle with vertices (0, 0), (1, 0), (1/2, sqrt(3)/2): its inscribed circle has
# centre (1/2, sqrt(3)/6) and radius 1/(2 sqrt(3)), so area ratio p = (pi/12) / (sqrt(3)/4).
TRIANGLE_P = math.pi / (3.0 * SQRT3)
TRIANGLE_C = 3.0 * SQRT3  # pi = c p
SQUARE_P = math.pi / 4.0
SQUARE_C = 4.0


def sample_triangle(u: np.ndarray) -> np.ndarray:
    """``u (..., 2)`` uniform on the unit square -> ``(..., 2)`` uniform in the equilateral
    triangle (0, 0), (1, 0), (1/2, sqrt(3)/2).

    a e1 + b e2 with (a, b) uniform covers the parallelogram on the edges e1, e2 uniformly; the
    half with a + b > 1 is the triangle turned by 180 degrees, so folding it back with
    (a, b) -> (1 - a, 1 - b) keeps the density uniform and wastes no sample.
    """
    a, b = u[..., 0], u[..., 1]
    fold = a + b > 1.0
    a = np.where(fold, 1.0 - a, a)
    b = np.where(fold, 1.0 - b, b)
    return np.stack([a + 0.5 * b, (SQRT3 / 2.0) * b], axis=-1)


def inside_triangle_incircle(p: np.ndarray) -> np.ndarray:
    """``p (..., 2)`` -> ``(...,)`` bool: inside the inscribed circle of that triangle."""
    return (p[..., 0] - 0.5) ** 2 + (p[..., 1] - SQRT3 / 6.0) ** 2 < 1.0 / 12.0


def pi_by_triangle(rng: np.random.Generator, n: int, trials: int) -> np.ndarray:
    """``(trials,)`` independent estimates 3 sqrt(3) k / n, k of n triangle points in the circle."""
    k = inside_triangle_incircle(sample_triangle(rng.random((trials, n, 2)))).sum(axis=1)
    return TRIANGLE_C * k / n


def pi_by_square(rng: np.random.Generator, n: int, trials: int) -> np.ndarray:
    """``(trials,)`` independent estimates 4 k / n, k of n points of [-1, 1]^2 in the unit disc."""
    p = rng.uniform(-1.0, 1.0, (trials, n, 2))
    k = (np.einsum("tnd,tnd->tn", p, p) < 1.0).sum(axis=1)
    return SQUARE_C * k / n


def binomial_estimator_moments(c: float, p: float, n: int) -> tuple[float, float]:
    """Variance and fourth central moment of c k / n for k ~ Binomial(n, p): variance
    c^2 p(1-p)/n, and the binomial's fourth central moment n p q (1 + 3 (n - 2) p q) scaled by
    (c/n)^4 (equivalently, excess kurtosis (1 - 6 p q) / (n p q); the tests check it)."""
    q = 1.0 - p
    return c * c * p * q / n, (c / n) ** 4 * n * p * q * (1.0 + 3.0 * (n - 2) * p * q)


def ball_volume_ratio(d: int) -> float:
    """Volume of the unit d-ball over its bounding cube [-1, 1]^d, pi^(d/2) / (Gamma(d/2 + 1) 2^d)
    (DLMF section 5.19(iii)). Computed by the recurrence V_d = (2 pi / d) V_(d-2) (the same
    formula, one Gamma step at a time) from V_1 / 2 = 1 and V_2 / 4 = pi/4, so that d = 1 gives
    exactly 1 where pi^(1/2) / Gamma(3/2) / 2 rounds to 1 - 1e-16."""
    ratio = 1.0 if d % 2 else math.pi / 4.0
    for k in range(4 - d % 2, d + 1, 2):
        ratio *= math.pi / (2.0 * k)  # (2 pi / k) for the volume, 1/4 for the cube's two more sides
    return ratio


def ball_acceptance(rng: np.random.Generator, d: int, points: int) -> int:
    """Number of ``points`` uniform points of [-1, 1]^d inside the unit ball."""
    x = rng.uniform(-1.0, 1.0, (points, d))
    return int((np.einsum("nd,nd->n", x, x) < 1.0).sum())


def rejection(rng: np.random.Generator, out_dir: Path | None = None, n: int = 1000, trials: int = 2000,
              dims: Iterable[int] = range(1, 13), points: int = 200_000) -> Result:
    """Exercise 2: two rejection estimators of pi at equal n, over ``trials`` independent trials,
    against their exact mean and variance; then the acceptance rate of the d-ball in its cube.

    numbers: ``n``, ``trials``, ``estimates`` {"triangle", "square": (trials,)},
    ``exact_var`` and ``exact_mu4`` {same keys}, ``dims`` (list), ``accepted`` (list, of
    ``points`` each), ``points``, ``exact_rate`` (list).
    """
    estimates = {"triangle": pi_by_triangle(rng, n, trials), "square": pi_by_square(rng, n, trials)}
    setup = {"triangle": (TRIANGLE_C, TRIANGLE_P), "square": (SQUARE_C, SQUARE_P)}
    exact_var, exact_mu4, pi_rows = {}, {}, []
    for key, est in estimates.items():
        c, p = setup[key]
        exact_var[key], exact_mu4[key] = binomial_estimator_moments(c, p, n)
        mean, se = float(est.mean()), math.sqrt(exact_var[key] / trials)
        var = float(est.var(ddof=1))
        vse = variance_se(exact_var[key], exact_mu4[key], trials)
        pi_rows.append({"estimator": f"({'a' if key == 'triangle' else 'b'}) {key}: {c:.4g} k/n",
                        "p = P(inside)": p, "mean": mean, "SE": se,
                        "z(mean - pi)": z_score(mean, math.pi, se),
                        "variance": var, "SE(var)": vse, "exact c^2 p(1-p)/n": exact_var[key],
                        "z(var)": z_score(var, exact_var[key], vse)})
    ratio = float(estimates["triangle"].var(ddof=1) / estimates["square"].var(ddof=1))
    exact_ratio = exact_var["triangle"] / exact_var["square"]
    # Delta method: the relative SEs of two independent sample variances add in quadrature.
    rel = [variance_se(exact_var[k], exact_mu4[k], trials) / exact_var[k] for k in estimates]
    ratio_se = exact_ratio * math.hypot(*rel)
    ratio_rows = [{"quantity": "variance (a) / variance (b)", "measured": ratio, "SE": ratio_se,
                   "exact": exact_ratio, "z": z_score(ratio, exact_ratio, ratio_se),
                   "agrees (3 SE)": abs(z_score(ratio, exact_ratio, ratio_se)) < AGREE_SE}]

    dims = list(dims)
    accepted = [ball_acceptance(rng, d, points) for d in dims]
    exact_rate = [ball_volume_ratio(d) for d in dims]
    dim_rows = []
    for d, k, p in zip(dims, accepted, exact_rate, strict=True):
        rate = k / points
        se = math.sqrt(p * (1.0 - p) / points)  # binomial SE under the exact rate
        dim_rows.append({"d": d, "accepted": k, "rate": rate, "SE": se, "exact ratio": p,
                         "z": z_score(rate, p, se), "draws per accepted point": 1.0 / p})
    result = Result(
        "rejection", f"2. Rejection sampling: pi from points in a circle, n = {n} points, {trials} trials",
        "Both estimators are unbiased with the exact variance c^2 p(1-p)/n; the square wins "
        "because its circle fills more of it (p = 0.785 against 0.605) and c is smaller; in d "
        "dimensions the ball fills a vanishing part of its cube.",
        {"pi estimators (z: measured - exact in SEs)": pi_rows, "variance ratio": ratio_rows,
         f"acceptance of the unit d-ball in [-1, 1]^d, {points} points per d": dim_rows},
        {"n": n, "trials": trials, "estimates": estimates, "exact_var": exact_var, "exact_mu4": exact_mu4,
         "dims": dims, "accepted": accepted, "points": points, "exact_rate": exact_rate})
    if out_dir is not None:
        result.figure = _rejection_figure(rng, result, Path(out_dir))
    return result


def _rejection_figure(rng: np.random.Generator, result: Result, out_dir: Path) -> Path:
    return _finish_figure(_pyplot(), rejection_figure(rng, result), out_dir, "primer_2_rejection")


def rejection_figure(rng: np.random.Generator, result: Result):
    """The rejection exercise's figure (a matplotlib Figure, laid out, not saved): the point
    sets with their circles on equal-aspect axes (one unit is as long in x as in y, so the
    circles are drawn round), the spread of the estimates, and the acceptance rate against d."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 9))
    shown = 1500
    # A fresh draw only for the picture: the figure never changes the numbers in the table.
    tri = sample_triangle(rng.random((shown, 2)))
    sq = rng.uniform(-1.0, 1.0, (shown, 2))
    for ax, pts, inside, circle, outline, label, c in (
            (axes[0, 0], tri, inside_triangle_incircle(tri), ((0.5, SQRT3 / 6.0), 1.0 / (2.0 * SQRT3)),
             np.array([[0, 0], [1, 0], [0.5, SQRT3 / 2.0], [0, 0]]), "(a) triangle: π ≈ 3√3 k/n", TRIANGLE_C),
            (axes[0, 1], sq, np.einsum("nd,nd->n", sq, sq) < 1.0, ((0.0, 0.0), 1.0),
             np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]]), "(b) square: π ≈ 4 k/n", SQUARE_C)):
        ax.scatter(*pts[inside].T, s=3, color="#1f77b4", label="inside the circle: accepted (k)")
        ax.scatter(*pts[~inside].T, s=3, color="#ff7f0e", label="outside: rejected")
        ax.add_patch(plt.Circle(circle[0], circle[1], fill=False, color="k", lw=1.2))
        ax.plot(*outline.T, color="k", lw=1.2)
        ax.set_aspect("equal", adjustable="box")  # the axes box takes the data's shape
        ax.set_title(f"{label}: here {c:.4g} × {inside.sum()}/{shown} = {c * inside.mean():.4f}", fontsize=10)
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    axes[0, 0].legend(fontsize=8, loc="upper right", markerscale=3)  # the triangle leaves that corner free

    ax = axes[1, 0]
    nums = result.numbers
    lo = min(e.min() for e in nums["estimates"].values())
    hi = max(e.max() for e in nums["estimates"].values())
    grid = np.linspace(lo, hi, 400)
    for key, color, tag in (("triangle", "#d62728", "(a) triangle"), ("square", "#1f77b4", "(b) square")):
        est, var = nums["estimates"][key], nums["exact_var"][key]
        # The estimates lie on a lattice c k / n: bins of a whole number of lattice steps, edges
        # between lattice points, or the histogram shows aliasing stripes instead of the shape.
        step = (TRIANGLE_C if key == "triangle" else SQUARE_C) / nums["n"]
        width = step * max(1, round((hi - lo) / 45 / step))
        bins = np.arange(est.min() - step / 2, est.max() + width, width)
        ax.hist(est, bins=bins, density=True, alpha=0.45, color=color,
                label=f"{tag}: variance {est.var(ddof=1):.2e} (exact {var:.2e})")
        normal = np.exp(-((grid - math.pi) ** 2) / (2 * var)) / math.sqrt(2 * math.pi * var)
        ax.plot(grid, normal, color=color, lw=1.5)
    ax.axvline(math.pi, color="k", lw=0.8, ls="--", label="π")
    ax.set_xlabel(f"estimate of π from n = {nums['n']} points")
    ax.set_ylabel("density over trials")
    ax.set_title(f"{nums['trials']} trials each; curves: normal with the exact variance", fontsize=10)
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    dims = np.array(nums["dims"])
    rate = np.array(nums["accepted"]) / nums["points"]
    se = np.sqrt(np.array(nums["exact_rate"]) * (1 - np.array(nums["exact_rate"])) / nums["points"])
    fine = np.arange(1, max(dims.max(), 20) + 1)
    ax.semilogy(fine, [ball_volume_ratio(int(d)) for d in fine], color="k", lw=1.0,
                label="exact π^(d/2) / (Γ(d/2+1) 2^d)")
    ax.errorbar(dims, rate, yerr=2 * se, fmt="o", ms=4, color="#d62728", capsize=2,
                label=f"measured, {nums['points']} points per d (±2 SE)")
    ax.set_xlabel("dimension d")
    ax.set_ylabel("acceptance rate (ball volume / cube volume)")
    ax.set_title("curse of dimensionality: rejection from the bounding cube", fontsize=10)
    ax.set_xticks(fine[::2] if len(fine) > 12 else fine)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------------
# 3. Importance sampling

# A positive discrete integrand with one bump, and a signed one (p proportional to |f| is then
# the best pmf but cannot reach zero variance).
DISCRETE_F = np.array([1.0, 3.0, 7.0, 12.0, 9.0, 4.0, 2.0, 1.0])
SIGNED_F = np.array([3.0, -1.0, 4.0, -1.0, 5.0, -9.0, 2.0, 6.0])


def sample_pmf(u: np.ndarray, pmf: np.ndarray) -> np.ndarray:
    """Discrete inversion: ``u (n,)`` in [0, 1) -> ``(n,)`` int indices i with P(i) = pmf[i],
    the smallest i with u < cdf[i]. Clipped so that rounding in the last cdf value (1 - eps)
    cannot produce an index past the end."""
    cdf = np.cumsum(pmf) / pmf.sum()
    return np.minimum(np.searchsorted(cdf, u, side="right"), len(pmf) - 1)


def discrete_is_moments(f: np.ndarray, pmf: np.ndarray) -> tuple[float, float, float]:
    """Exact mean, variance and fourth central moment of f(X)/p(X), X ~ pmf, for ``f (K,)`` and
    ``pmf (K,)`` > 0: mean sum f = I, variance sum f^2/p - I^2 (Owen, Monte Carlo theory,
    methods and examples, 2013, section 9.1)."""
    ratio = f / pmf
    mean = float(f.sum())
    return mean, float((f * ratio).sum() - mean**2), float((pmf * (ratio - mean) ** 4).sum())


def discrete_is(rng: np.random.Generator, f: np.ndarray, pmf: np.ndarray, n: int) -> np.ndarray:
    """``(n,)`` one-sample estimates f(X)/p(X) of sum f, X drawn from ``pmf``."""
    i = sample_pmf(rng.random(n), pmf)
    return f[i] / pmf[i]


# A continuous 1-D integral: I = int_0^1 4 x^3 dx = 1, with pdfs sampled by inversion.
def continuous_f(x: np.ndarray) -> np.ndarray:
    return 4.0 * x**3


CONTINUOUS_I = 1.0
# name -> (pdf, inverse CDF on u in (0, 1], exact variance in closed form where simple)
CONTINUOUS_PDFS: dict[str, tuple[Callable, Callable, float | None]] = {
    "uniform, p = 1": (np.ones_like, lambda u: u, 16.0 / 7.0 - 1.0),
    "linear, p = 2x": (lambda x: 2.0 * x, np.sqrt, 8.0 / 6.0 - 1.0),
    "p = 4x^3, proportional to f": (lambda x: 4.0 * x**3, lambda u: u**0.25, 0.0),
    # Decreasing where f increases: F(x) = 1.5 x - x^2/2 = u solved for x.
    "poor, p = 1.5 - x": (lambda x: 1.5 - x, lambda u: 1.5 - np.sqrt(2.25 - 2.0 * u), None),
}


def continuous_is_moments(f: Callable, pdf: Callable, panels: int = 400) -> tuple[float, float, float]:
    """Mean, variance and fourth central moment of f(X)/p(X), X ~ pdf on [0, 1], by quadrature:
    variance = int f^2/p dx - I^2 (Owen 2013, section 9.1)."""
    x, w = gauss_legendre(0.0, 1.0, panels)
    p = pdf(x)
    ratio = f(x) / p
    mean = float((w * f(x)).sum())
    return mean, float((w * p * (ratio - mean) ** 2).sum()), float((w * p * (ratio - mean) ** 4).sum())


def _is_row(case: str, est: np.ndarray, mean_x: float, var_x: float, mu4_x: float) -> dict[str, Any]:
    n = len(est)
    mean, var = float(est.mean()), float(est.var(ddof=1))
    se = math.sqrt(var_x / n)
    vse = variance_se(var_x, mu4_x, n)
    return {"case": case, "mean": mean, "SE": se, "exact I": mean_x, "z(mean)": z_score(mean, mean_x, se),
            "variance": var, "SE(var)": vse, "exact variance": var_x, "z(var)": z_score(var, var_x, vse)}


def importance(rng: np.random.Generator, out_dir: Path | None = None, n: int = 100_000) -> Result:
    """Exercise 3: importance sampling with several pmfs (discrete) and pdfs (continuous),
    ``n`` one-sample estimates each, measured against the exact mean and variance.

    numbers: ``n``; ``discrete`` and ``continuous``: {case: {"estimates": (n,), "mean", "var",
    "mu4" (exact), "pmf" or "pdf"}}; ``discrete_f``, ``signed_f``.
    """
    positive = DISCRETE_F
    pmfs = {
        "f >= 0, uniform p": (positive, np.full(len(positive), 1.0 / len(positive))),
        "f >= 0, p proportional to f": (positive, positive / positive.sum()),
        "f >= 0, poor p proportional to 1/f": (positive, (1.0 / positive) / (1.0 / positive).sum()),
        "signed f, uniform p": (SIGNED_F, np.full(len(SIGNED_F), 1.0 / len(SIGNED_F))),
        "signed f, p proportional to |f|": (SIGNED_F, np.abs(SIGNED_F) / np.abs(SIGNED_F).sum()),
    }
    discrete, d_rows = {}, []
    for case, (f, pmf) in pmfs.items():
        est = discrete_is(rng, f, pmf, n)
        mean_x, var_x, mu4_x = discrete_is_moments(f, pmf)
        discrete[case] = {"estimates": est, "f": f, "pmf": pmf, "mean": mean_x, "var": var_x, "mu4": mu4_x}
        d_rows.append(_is_row(case, est, mean_x, var_x, mu4_x))
    continuous, c_rows = {}, []
    for case, (pdf, invert, closed) in CONTINUOUS_PDFS.items():
        x = invert(_uniform_open0(rng, n))
        est = continuous_f(x) / pdf(x)
        mean_x, var_x, mu4_x = continuous_is_moments(continuous_f, pdf)
        if closed is not None:
            var_x = closed  # the closed form where there is one; the tests check quadrature against it
        continuous[case] = {"estimates": est, "pdf": pdf, "mean": mean_x, "var": var_x, "mu4": mu4_x}
        c_rows.append(_is_row(case, est, mean_x, var_x, mu4_x))
    result = Result(
        "importance", f"3. Importance sampling: f(X)/p(X), n = {n} one-sample estimates per case",
        "Every pmf/pdf gives an unbiased estimate whose variance is sum f^2/p - I^2 (integral "
        "f^2/p - I^2); p proportional to f >= 0 gives zero variance, p proportional to |f| the "
        "least for signed f, a p that is small where f is large the most.",
        {f"discrete: f = {DISCRETE_F.astype(int).tolist()} (I = {DISCRETE_F.sum():g}) or signed "
         f"f = {SIGNED_F.astype(int).tolist()} (I = {SIGNED_F.sum():g})": d_rows,
         "continuous: I = integral of 4x^3 over [0, 1] = 1, X sampled by inversion": c_rows},
        {"n": n, "discrete": discrete, "continuous": continuous, "discrete_f": DISCRETE_F,
         "signed_f": SIGNED_F})
    if out_dir is not None:
        result.figure = _importance_figure(result, Path(out_dir))
    return result


def _importance_figure(result: Result, out_dir: Path) -> Path:
    plt = _pyplot()
    fig, (ax_d, ax_c, ax_h) = plt.subplots(1, 3, figsize=(15, 4.4))
    disc = result.numbers["discrete"]
    k = np.arange(len(DISCRETE_F))
    ax_d.bar(k - 0.3, DISCRETE_F / DISCRETE_F.sum(), width=0.2, color="k", label="f / I (the ideal p)")
    labels = (("f >= 0, uniform p", "uniform p", "#7f7f7f"),
              ("f >= 0, p proportional to f", "p ∝ f", "#2ca02c"),
              ("f >= 0, poor p proportional to 1/f", "poor p ∝ 1/f", "#d62728"))
    for j, (case, tag, color) in enumerate(labels):
        ax_d.bar(k - 0.1 + 0.2 * j, disc[case]["pmf"], width=0.2, color=color,
                 label=f"{tag}: variance {disc[case]['var']:.4g}")
    ax_d.set_xlabel("i")
    ax_d.set_ylabel("probability")
    ax_d.set_title(f"discrete: f = {DISCRETE_F.astype(int).tolist()}", fontsize=10)
    ax_d.legend(fontsize=8)

    cont = result.numbers["continuous"]
    colors = ["#7f7f7f", "#1f77b4", "#2ca02c", "#d62728"]
    x = np.linspace(0.0, 1.0, 300)
    ax_c.plot(x, continuous_f(x), color="k", lw=2.2, label="f(x) = 4x³ (also the ideal pdf)")
    for (case, data), color in zip(cont.items(), colors, strict=True):
        ax_c.plot(x, data["pdf"](x), color=color, lw=1.3, ls="--",
                  label=f"{case.replace('^3', '³')}: variance {data['var']:.4g}")
    ax_c.set_xlabel("x")
    ax_c.set_ylabel("f(x), p(x)")
    ax_c.set_title("continuous: integral of 4x³ over [0, 1] = 1", fontsize=10)
    ax_c.legend(fontsize=8, loc="upper left")

    top = max(float(d["estimates"].max()) for d in cont.values())
    bins = np.linspace(0.0, top, 81)
    for (case, data), color in zip(cont.items(), colors, strict=True):
        est = data["estimates"]
        name = case.replace("^3", "³")
        if data["var"] == 0.0:
            ax_h.axvline(CONTINUOUS_I, color=color, lw=2.0, label=f"{name}: all exactly 1")
            continue
        ax_h.hist(est, bins=bins, density=True, histtype="step", lw=1.4, color=color,
                  label=f"{name}: sd {est.std():.3g}")
    ax_h.set_yscale("log")
    ax_h.set_xlabel("one-sample estimate f(X)/p(X)")
    ax_h.set_ylabel("density")
    ax_h.set_title("distribution of the one-sample estimates (mean 1)", fontsize=10)
    ax_h.legend(fontsize=8)
    return _finish_figure(plt, fig, out_dir, "primer_3_importance")


# ---------------------------------------------------------------------------------------------
# 4. Multiple importance sampling

# f(x) = 3x^2 + a Cauchy peak of width G at C on [0, 1]: a broad part that rises towards 1 and a
# narrow peak. p1 is uniform (poor on the peak); p2 is a wider truncated Cauchy around the peak
# (matched to that part of f, poor near x = 1 where its tail is thin and f is largest).
MIS_C, MIS_G, MIS_G2 = 0.3, 0.01, 0.02
MIS_A = 1.0 / (math.pi * MIS_G)  # peak height: the untruncated peak has area 1
MIS_Z2 = MIS_G2 * (math.atan((1.0 - MIS_C) / MIS_G2) + math.atan(MIS_C / MIS_G2))  # p2's normalisation
# The integral: 1 from 3x^2, plus the peak's A g (atan((1 - c)/g) + atan(c/g)) on [0, 1].
MIS_I = 1.0 + MIS_A * MIS_G * (math.atan((1.0 - MIS_C) / MIS_G) + math.atan(MIS_C / MIS_G))
POWER_BETA = 2.0


def mis_f(x: np.ndarray) -> np.ndarray:
    """The integrand 3x^2 + A / (1 + ((x - c)/g)^2) on [0, 1]; its integral is MIS_I."""
    return 3.0 * x**2 + MIS_A / (1.0 + ((x - MIS_C) / MIS_G) ** 2)


def mis_p1(x: np.ndarray) -> np.ndarray:
    return np.ones_like(x)


def mis_p2(x: np.ndarray) -> np.ndarray:
    """Truncated Cauchy on [0, 1], centre c, width g2."""
    return 1.0 / (MIS_Z2 * (1.0 + ((x - MIS_C) / MIS_G2) ** 2))


def mis_sample1(u: np.ndarray) -> np.ndarray:
    return u


def mis_sample2(u: np.ndarray) -> np.ndarray:
    """Inversion of the truncated Cauchy: its CDF is linear in atan((x - c)/g2)."""
    lo, hi = math.atan(-MIS_C / MIS_G2), math.atan((1.0 - MIS_C) / MIS_G2)
    return MIS_C + MIS_G2 * np.tan(lo + u * (hi - lo))


def _constant(value: float) -> Callable[..., np.ndarray]:
    return lambda p1, p2, f=None: np.full_like(p1, value)


def _heuristic(beta: float, mine: int) -> Callable[..., np.ndarray]:
    """w_i = p_i^beta / (p1^beta + p2^beta): beta = 1 balance, 2 power (Veach 1997, section
    9.2). Equal sample counts here, so the count scaling of the multi-sample model cancels."""
    return lambda p1, p2, f=None: (p1, p2)[mine] ** beta / (p1**beta + p2**beta)


def _max_normalised(mine: int) -> Callable[..., np.ndarray]:
    """A plausible mistake: w_i = p_i / max(p1, p2). Each weight is in [0, 1] but they sum to
    1 + min/max > 1, so the estimator counts the overlap twice."""
    return lambda p1, p2, f=None: (p1, p2)[mine] / np.maximum(p1, p2)


def optimal_alpha(counts: tuple[int, int] = (1, 1), panels: int = 4000) -> np.ndarray:
    """The variance-optimal a = A^-1 b of Kondapaneni et al. 2019 for f and (p1, p2) with
    ``counts`` samples, by quadrature: A_ik = int p_i p_k / q, b_i = int f p_i / q, q = sum_j
    n_j p_j."""
    x, w = gauss_legendre(0.0, 1.0, panels)
    p = np.stack([mis_p1(x), mis_p2(x)])
    q = counts[0] * p[0] + counts[1] * p[1]
    a = np.einsum("ix,kx,x->ik", p, p, w / q)
    b = np.einsum("ix,x->i", p, w * mis_f(x) / q)
    return np.linalg.solve(a, b)


def _optimal(mine: int, alpha: np.ndarray, counts: tuple[int, int] = (1, 1)) -> Callable[..., np.ndarray]:
    """Kondapaneni et al.'s weights w_i = a_i p_i / f + (n_i p_i / q)(1 - (a . p) / f): they
    sum to one for any a (so the estimator is unbiased for any a), and the a of
    :func:`optimal_alpha` minimizes the variance. A weight may be negative or above 1."""
    def weight(p1, p2, f):
        p = (p1, p2)
        q = counts[0] * p1 + counts[1] * p2
        share = alpha[0] * p1 + alpha[1] * p2
        return alpha[mine] * p[mine] / f + counts[mine] * p[mine] / q * (1.0 - share / f)
    return weight


def control_variate_alpha(alpha: np.ndarray, counts: tuple[int, int] = (1, 1)) -> float:
    """The one coefficient a_1 - (n_1 / n_2) a_2 that matters: adding lambda n to a changes no
    weight, so optimal MIS is the balance heuristic's V plus (a_1 - n_1 a_2 / n_2) C, with the
    zero-mean control variate C of ``tracer.tuning``."""
    return float(alpha[0] - counts[0] * alpha[1] / counts[1])


def learned_alpha(rng: np.random.Generator, pilot: int) -> tuple[float, float]:
    """a learned as the renderer learns it (``tracer.tuning.control_coefficient``) from
    ``pilot`` independent draws of one sample per technique: the balance estimate V and the
    control variate C = (1 - p1/q)(X1) - (p1/q)(X2), q = p1 + p2, per draw. Returns a and the
    standard error of a regression slope, sqrt(Var(V + a C) / (pilot Var(C)))."""
    from .. import tuning

    x1, x2 = mis_sample1(rng.random(pilot)), mis_sample2(rng.random(pilot))
    share1 = mis_p1(x1) / (mis_p1(x1) + mis_p2(x1))
    share2 = mis_p1(x2) / (mis_p1(x2) + mis_p2(x2))
    v = mis_f(x1) / (mis_p1(x1) + mis_p2(x1)) + mis_f(x2) / (mis_p1(x2) + mis_p2(x2))
    c = (1.0 - share1) - share2
    sums = np.zeros((1, 1, tuning.SUM_COLUMNS))
    row = sums[0, 0]
    row[tuning.COUNT], row[tuning.CONTROL], row[tuning.SUM_CC] = pilot, c.sum(), (c * c).sum()
    row[tuning.SUM_V:tuning.SUM_V + 3] = v.sum()
    row[tuning.SUM_VV:tuning.SUM_VV + 3] = (v * v).sum()
    row[tuning.SUM_VC:tuning.SUM_VC + 3] = (v * c).sum()
    alpha = float(tuning.control_coefficient(sums, np.zeros((0, 1)), 1.0, False)[0, 0, 0])
    return alpha, math.sqrt(np.var(v + alpha * c) / (pilot * np.var(c)))


@dataclass(frozen=True)
class MisEstimator:
    """F = sum_i (1/n_i) sum_j w_i(X_ij) f(X_ij) / p_i(X_ij), X_ij ~ p_i (Veach 1997, eq. 9.4),
    with n = (n1, n2) samples; weights take (p1(x), p2(x), f(x)) arrays and return w_i(x)."""

    name: str
    counts: tuple[int, int]
    weights: tuple[Callable, Callable]


ONE = _constant(1.0)
MIS_ESTIMATORS = (
    MisEstimator("p1 only (uniform)", (2, 0), (ONE, ONE)),
    MisEstimator("p2 only (peak)", (0, 2), (ONE, ONE)),
    MisEstimator("constant 1/2 + 1/2", (1, 1), (_constant(0.5), _constant(0.5))),
    MisEstimator("constant 3/4 + 1/2 (sum 1.25)", (1, 1), (_constant(0.75), _constant(0.5))),
    MisEstimator("p_i / max(p1, p2) (sum > 1)", (1, 1), (_max_normalised(0), _max_normalised(1))),
    MisEstimator("balance heuristic", (1, 1), (_heuristic(1.0, 0), _heuristic(1.0, 1))),
    MisEstimator(f"power heuristic, beta = {POWER_BETA:g}", (1, 1),
                 (_heuristic(POWER_BETA, 0), _heuristic(POWER_BETA, 1))),
)
OPTIMAL_NAME = "optimal (a = A^-1 b by quadrature)"
LEARNED_NAME = "optimal, a learned from a pilot"
MIS_PILOT = 2000  # pilot draws behind the learned a


def mis_estimates(rng: np.random.Generator, est: MisEstimator, trials: int) -> np.ndarray:
    """``(trials,)`` independent values of the estimator F."""
    total = np.zeros(trials)
    for i, (count, sample) in enumerate(zip(est.counts, (mis_sample1, mis_sample2), strict=True)):
        for _ in range(count):
            x = sample(rng.random(trials))
            p1, p2 = mis_p1(x), mis_p2(x)
            f = mis_f(x)
            total += est.weights[i](p1, p2, f) * f / (count * (p1, p2)[i])
    return total


def mis_exact(est: MisEstimator, panels: int = 4000) -> dict[str, float]:
    """Exact mean, bias, variance and fourth central moment of F by quadrature.

    Each sample j of technique i contributes h_i(X) = w_i f / (n_i p_i); the contributions are
    independent, so means and variances add, and the fourth central moment of the sum is
    sum mu4_j + 3 ((sum var_j)^2 - sum var_j^2). Bias = integral of (w1 + w2 - 1) f over the
    techniques used: zero exactly when the weights sum to one wherever f != 0.
    """
    x, w = gauss_legendre(0.0, 1.0, panels)
    p = (mis_p1(x), mis_p2(x))
    f = mis_f(x)
    means, variances, mu4s = [], [], []
    for i, count in enumerate(est.counts):
        if count == 0:
            continue
        h = est.weights[i](*p, f) * f / (count * p[i])
        m = float((w * p[i] * h).sum())
        means += [m] * count
        variances += [float((w * p[i] * (h - m) ** 2).sum())] * count
        mu4s += [float((w * p[i] * (h - m) ** 4).sum())] * count
    var = sum(variances)
    mean = sum(means)
    return {"mean": mean, "bias": mean - float((w * f).sum()), "var": var,
            "mu4": sum(mu4s) + 3.0 * (var**2 - sum(v * v for v in variances))}


def mis_estimators(rng: np.random.Generator) -> tuple[tuple[MisEstimator, ...], dict[str, float]]:
    """``MIS_ESTIMATORS`` plus optimal MIS twice: with the a of :func:`optimal_alpha`, and
    with a learned from a pilot of ``MIS_PILOT`` draws (independent of the trials, so
    the estimator stays unbiased); and the numbers behind them: the optimal a (2,), its
    control-variate coefficient, and the learned one with its standard error."""
    alpha = optimal_alpha()
    learned, learned_se = learned_alpha(rng, MIS_PILOT)
    as_pair = np.array([learned, 0.0])  # a_2 = 0: the same estimator (control_variate_alpha)
    extra = (MisEstimator(OPTIMAL_NAME, (1, 1), (_optimal(0, alpha), _optimal(1, alpha))),
             MisEstimator(LEARNED_NAME, (1, 1), (_optimal(0, as_pair), _optimal(1, as_pair))))
    return MIS_ESTIMATORS + extra, {"alpha": alpha, "cv_alpha": control_variate_alpha(alpha),
                                    "learned_alpha": learned, "learned_alpha_se": learned_se}


def mis(rng: np.random.Generator, out_dir: Path | None = None, trials: int = 200_000) -> Result:
    """Exercise 4: nine ways to combine two samples (one per pdf, or two from one pdf) into an
    estimate of int_0^1 f, each run ``trials`` times: mean, bias and variance against exact.
    The last two are optimal MIS (Kondapaneni et al. 2019), with its a from quadrature and
    learned from a pilot as the renderer learns it.

    numbers: ``trials``, ``I``, ``rows`` {name: {"estimates": (trials,), "mean", "bias",
    "var", "mu4" (exact), "weight_sum_is_one" (bool)}}, ``optimal`` (``mis_estimators``).
    """
    rows, table = {}, []
    estimators, optimal = mis_estimators(rng)
    for est in estimators:
        values = mis_estimates(rng, est, trials)
        exact = mis_exact(est)
        unit = abs(exact["bias"]) < 1e-9 * MIS_I
        mean, var = float(values.mean()), float(values.var(ddof=1))
        se = math.sqrt(exact["var"] / trials)
        vse = variance_se(exact["var"], exact["mu4"], trials)
        rows[est.name] = {"estimates": values, **exact, "weight_sum_is_one": unit}
        if unit:
            exact["bias"] = 0.0  # what quadrature gives is rounding, ~1e-16
        table.append({"weights": est.name, "samples p1+p2": f"{est.counts[0]}+{est.counts[1]}",
                      "mean": mean, "SE": se, "bias": mean - MIS_I, "exact bias": exact["bias"],
                      "z(bias)": z_score(mean - MIS_I, exact["bias"], se), "variance": var,
                      "SE(var)": vse, "exact variance": exact["var"],
                      "z(var)": z_score(var, exact["var"], vse)})
    result = Result(
        "mis", f"4. Multiple importance sampling: I = integral of 3x^2 + peak = {MIS_I:.6f}, "
        f"{trials} trials of 2 samples",
        "Weights summing to one (constants or functions) are unbiased, other sums are biased "
        "by integral (w1 + w2 - 1) f; balance and power heuristics have a fraction of the "
        "variance of either pdf alone, which each fail where the other is good. Optimal MIS "
        "(weights that may be negative: the balance heuristic plus a control variate) has the "
        "least variance of all, also with its coefficient learned from a pilot.",
        {"estimators of the same integral, 2 samples each (z: measured - exact in SEs)": table,
         "optimal MIS's coefficient a_1 - a_2 (the control variate's; z: learned - exact)": [
             {"a": "A^-1 b by quadrature", "value": optimal["cv_alpha"], "SE": "", "z": ""},
             {"a": f"learned from {MIS_PILOT} pilot draws", "value": optimal["learned_alpha"],
              "SE": optimal["learned_alpha_se"],
              "z": z_score(optimal["learned_alpha"], optimal["cv_alpha"], optimal["learned_alpha_se"])}]},
        {"trials": trials, "I": MIS_I, "rows": rows, "optimal": optimal})
    if out_dir is not None:
        result.figure = _mis_figure(result, Path(out_dir))
    return result


def _mis_figure(result: Result, out_dir: Path) -> Path:
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    x = np.linspace(0.0, 1.0, 2001)
    p1, p2 = mis_p1(x), mis_p2(x)

    ax = axes[0, 0]
    ax.plot(x, mis_f(x), color="k", lw=2.0, label="f(x) = 3x² + peak")
    ax.plot(x, p1, color="#1f77b4", lw=1.3, ls="--", label="p1: uniform (poor on the peak)")
    ax.plot(x, p2, color="#d62728", lw=1.3, ls="--", label="p2: Cauchy around the peak (poor near x = 1)")
    ax.set_yscale("log")
    ax.set_ylim(1e-3, 100.0)  # room below the curves for the legend
    ax.set_xlabel("x")
    ax.set_ylabel("f(x), p(x)  (log scale)")
    ax.set_title("integrand and the two sampling pdfs", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")

    ax = axes[0, 1]
    for (name, w1, color) in (("balance w1", _heuristic(1.0, 0), "#2ca02c"),
                              ("power w1", _heuristic(POWER_BETA, 0), "#9467bd"),
                              ("optimal w1", _optimal(0, result.numbers["optimal"]["alpha"]), "#8c564b")):
        ax.plot(x, w1(p1, p2, mis_f(x)), color=color, lw=1.5, label=f"{name} (w2 = 1 − w1)")
    ax.plot(x, _max_normalised(0)(p1, p2) + _max_normalised(1)(p1, p2), color="#ff7f0e", lw=1.5,
            label="p_i / max: w1 + w2 (should be 1)")
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xlabel("x")
    ax.set_ylabel("weight")
    ax.set_title("weights of the uniform technique; the broken sum", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")

    table = next(iter(result.tables.values()))
    names = [r["weights"] for r in table]
    pos = np.arange(len(names))[::-1]
    colors = ["#2ca02c" if result.numbers["rows"][n]["weight_sum_is_one"] else "#d62728" for n in names]
    ax = axes[1, 0]
    for r, y, color in zip(table, pos, colors, strict=True):
        ax.errorbar(r["mean"], y, xerr=3 * r["SE"], fmt="o", ms=4, color=color, capsize=3)
    ax.scatter([MIS_I + r["exact bias"] for r in table], pos, marker="o", s=90, facecolors="none",
               edgecolors="k", zorder=3, label="I + predicted bias (quadrature)")
    ax.axvline(MIS_I, color="k", lw=0.8, ls="--", label=f"I = {MIS_I:.4f}")
    ax.set_yticks(pos, names, fontsize=8)
    ax.set_xlabel("mean of the estimates (±3 SE); red: weights do not sum to 1")
    ax.set_title("bias", fontsize=10)
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    ax.barh(pos, [r["variance"] for r in table], color=colors, alpha=0.8, label="measured")
    ax.scatter([r["exact variance"] for r in table], pos, marker="|", s=200, color="k", zorder=3,
               label="exact (quadrature)")
    ax.set_xscale("log")
    ax.set_yticks(pos, names, fontsize=8)
    ax.set_xlabel("variance of one estimate (2 samples)")
    ax.set_title("variance", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    return _finish_figure(plt, fig, out_dir, "primer_4_mis")


# ---------------------------------------------------------------------------------------------
# 5. Quasi-Monte Carlo


def qmc_f(xy: np.ndarray) -> np.ndarray:
    """``xy (n, 2)`` -> ``(n,)``: the smooth integrand exp(x y) on the unit square."""
    return np.exp(xy[:, 0] * xy[:, 1])


def _series(scale: float) -> float:
    # int int exp(s x y) dx dy = sum_k s^k / ((k + 1)^2 k!) from the power series of exp,
    # since int int (x y)^k = 1/(k + 1)^2. The terms fall faster than 2^k / k!: 40 are plenty.
    return sum(scale**k / ((k + 1) ** 2 * math.factorial(k)) for k in range(40))


QMC_I = _series(1.0)
QMC_VAR = _series(2.0) - QMC_I**2  # variance of f(U) for U uniform on the square


def fit_rate(n: np.ndarray, error: np.ndarray) -> float:
    """Least-squares slope of log error against log n: error ~ n^slope."""
    return float(np.polyfit(np.log(n), np.log(error), 1)[0])


def _rate_with_se(n: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, float, float]:
    """RMSE over replicates ``errors (R, len(n))`` -> (rmse (len(n),), fitted slope, jackknife SE
    of the slope over the replicates (Efron and Tibshirani, An Introduction to the Bootstrap,
    chapter 11): how much the fitted rate moves from one set of runs to another)."""
    sq = errors**2
    rmse = np.sqrt(sq.mean(axis=0))
    slope = fit_rate(n, rmse)
    r = len(errors)
    loo = np.array([fit_rate(n, np.sqrt((sq.sum(axis=0) - sq[i]) / (r - 1))) for i in range(r)])
    return rmse, slope, float(math.sqrt((r - 1) / r * ((loo - loo.mean()) ** 2).sum()))


def _sobol_engine(scipy_qmc, rng: np.random.Generator):
    """A 2-D Sobol engine, scrambled (linear matrix scramble + digital shift) from ``rng``."""
    try:
        return scipy_qmc.Sobol(d=2, scramble=True, rng=rng)
    except TypeError:  # scipy < 1.15 calls the argument seed
        return scipy_qmc.Sobol(d=2, scramble=True, seed=rng)


def qmc(rng: np.random.Generator, out_dir: Path | None = None, m_max: int = 14, m_min: int = 4,
        replicates: int = 256) -> Result:
    """Exercise 5: RMSE of plain Monte Carlo and of scrambled Sobol points for int exp(xy) over
    the unit square, at n = 2^m_min ... 2^m_max, over ``replicates`` independent runs (seeds
    for MC, scramblings for Sobol); fitted rates with their jackknife SE.

    Each run draws 2^m_max points and reads the estimate at every power of two from its
    prefix: a prefix of length 2^m of a Sobol sequence is itself a (0, m, 2)-net in base 2.
    Scrambled-net errors are heavy-tailed across scramblings (a few runs dominate the RMSE), so
    the rates need a few hundred runs to be stable to about +-0.07. n stops at 2^14: scipy's
    Sobol points are multiples of 2^-30, a bias floor near 1e-9 that larger n would reach.
    numbers: ``n (M,)``, ``mc_errors`` and ``sobol_errors`` (replicates, M), ``mc_rmse``,
    ``sobol_rmse``, ``mc_rate``, ``mc_rate_se``, ``sobol_rate``, ``sobol_rate_se``, ``I``,
    ``var``. Skipped (``Result.skipped``) when scipy is not installed.
    """
    title = "5. Quasi-Monte Carlo: plain MC against scrambled Sobol on the integral of exp(xy) over [0,1]^2"
    claim = ("Plain MC error falls as n^-1/2 (the line sigma/sqrt(n)); scrambled Sobol points, "
             "evenly spread, fall much faster for this smooth integrand.")
    try:
        from scipy.stats import qmc as scipy_qmc
    except ImportError:
        return Result("qmc", title, claim,
                      skipped="exercise 5 needs scipy for its Sobol points: pip install scipy")
    n = 2 ** np.arange(m_min, m_max + 1)
    total = 2**m_max
    mc_errors = np.zeros((replicates, len(n)))
    sobol_errors = np.zeros((replicates, len(n)))
    streams = rng.spawn(2 * replicates)
    for r in range(replicates):
        sobol = _sobol_engine(scipy_qmc, streams[2 * r + 1])
        for errors, points in ((mc_errors, streams[2 * r].random((total, 2))),
                               (sobol_errors, sobol.random_base2(m_max))):
            running = np.cumsum(qmc_f(points))
            errors[r] = running[n - 1] / n - QMC_I
    mc_rmse, mc_rate, mc_se = _rate_with_se(n, mc_errors)
    sobol_rmse, sobol_rate, sobol_se = _rate_with_se(n, sobol_errors)
    rows = [{"n": int(k), "MC RMSE": float(a), "exact MC sigma/sqrt(n)": math.sqrt(QMC_VAR / k),
             "Sobol RMSE": float(b), "MC / Sobol": float(a / b)}
            for k, a, b in zip(n, mc_rmse, sobol_rmse, strict=True)]
    rates = [{"method": "plain Monte Carlo", "fitted rate": mc_rate, "SE": mc_se, "theory": "-0.5 exactly"},
             {"method": "scrambled Sobol", "fitted rate": sobol_rate, "SE": sobol_se,
              "theory": "-1.5 (smooth f, Owen 1997); -1 worst case"}]
    result = Result(
        "qmc", title, claim,
        {f"root mean square error over {replicates} runs (I = {QMC_I:.10f})": rows,
         "fitted rates: RMSE ~ n^rate (SE: jackknife over runs)": rates},
        {"n": n, "mc_errors": mc_errors, "sobol_errors": sobol_errors, "mc_rmse": mc_rmse,
         "sobol_rmse": sobol_rmse, "mc_rate": mc_rate, "mc_rate_se": mc_se, "sobol_rate": sobol_rate,
         "sobol_rate_se": sobol_se, "I": QMC_I, "var": QMC_VAR, "replicates": replicates})
    if out_dir is not None:
        sobol_points = _sobol_engine(scipy_qmc, streams[1]).random_base2(8)
        result.figure = _qmc_figure(result, streams[0].random((256, 2)), sobol_points, Path(out_dir))
    return result


def _qmc_figure(result: Result, mc_points: np.ndarray, sobol_points: np.ndarray, out_dir: Path) -> Path:
    plt = _pyplot()
    fig, (ax_mc, ax_sb, ax_e) = plt.subplots(1, 3, figsize=(15, 4.6),
                                             gridspec_kw={"width_ratios": [1, 1, 1.5]})
    for ax, pts, name in ((ax_mc, mc_points, "256 uniform random points"),
                          (ax_sb, sobol_points, "256 scrambled Sobol points")):
        ax.scatter(*pts.T, s=6, color="#1f77b4")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_aspect("equal")
        ax.set_xticks(np.linspace(0, 1, 5))
        ax.set_yticks(np.linspace(0, 1, 5))
        # 16 x 16 cells: a 256-point Sobol net puts exactly one point in each, random points do not.
        ax.set_xticks(np.linspace(0, 1, 17), minor=True)
        ax.set_yticks(np.linspace(0, 1, 17), minor=True)
        ax.grid(True, which="both", lw=0.4, alpha=0.5)
        ax.set_title(f"{name} (grid: 16 × 16 cells)", fontsize=10)
        ax.set_xlabel("x")
        ax.set_ylabel("y")

    nums = result.numbers
    n = nums["n"]
    ax_e.loglog(n, nums["mc_rmse"], "o-", ms=4, color="#d62728",
                label=f"plain MC: fitted n^{nums['mc_rate']:.2f} ± {nums['mc_rate_se']:.2f}")
    ax_e.loglog(n, np.sqrt(nums["var"] / n), color="#d62728", lw=0.8, ls=":", label="exact σ/√n")
    ax_e.loglog(n, nums["sobol_rmse"], "s-", ms=4, color="#1f77b4",
                label=f"scrambled Sobol: fitted n^{nums['sobol_rate']:.2f} ± {nums['sobol_rate_se']:.2f}")
    anchor = nums["sobol_rmse"][0]
    ax_e.loglog(n, anchor * (n / n[0]) ** -1.0, color="0.5", lw=0.8, ls="--", label="slope −1")
    ax_e.loglog(n, anchor * (n / n[0]) ** -1.5, color="0.5", lw=0.8, ls="-.", label="slope −1.5")
    ax_e.set_xlabel("number of points n")
    ax_e.set_ylabel(f"RMSE over {nums['replicates']} runs")
    ax_e.set_title("error of the estimate of ∫∫ exp(xy) dx dy", fontsize=10)
    ax_e.grid(True, which="both", lw=0.3, alpha=0.5)
    ax_e.legend(fontsize=8)
    return _finish_figure(plt, fig, out_dir, "primer_5_qmc")


# ---------------------------------------------------------------------------------------------
# All of them

EXERCISES: tuple[Callable[..., Result], ...] = (inversion, rejection, importance, mis, qmc)


def run_all(out_dir: Path | None, seed: int = 0, stream: TextIO | None = None) -> list[Result]:
    """Run the five exercises, print each one's tables to ``stream`` and, with ``out_dir``,
    write one PNG each there (the folder is created). Each exercise draws from its own
    Generator, spawned from ``seed``: the numbers depend on the seed alone."""
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
    streams = np.random.SeedSequence(seed).spawn(len(EXERCISES))
    stream = stream if stream is not None else sys.stdout
    results = []
    for exercise, child in zip(EXERCISES, streams, strict=True):
        result = exercise(np.random.default_rng(child), out_dir)
        print_result(result, stream)
        stream.flush()
        results.append(result)
    return results


def main(out_dir: str | os.PathLike[str] | None = None, seed: int = 0) -> int:
    """``tracer primer [--out DIR] [--seed N]``: run everything, print the tables, write the
    figures to DIR if given. Returns the exit status (0); a DIR that exists and is not a folder
    raises InputError, which the CLI prints as one line."""
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise InputError("exists and is not a folder", str(out))
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create the folder: {exc.strerror}", str(out)) from None
    run_all(out, seed)
    return 0
