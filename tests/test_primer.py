"""The Monte Carlo primer (tracer/study/primer.py): every numbered claim of the exercises, checked
statistically on the numbers that ``tracer primer`` prints.

The exercises run once, through ``run_all`` with seed 0 (the command's default), and each test
reads the numbers of one exercise. Every test function runs at a 1% family false-alarm rate,
Sidak-corrected over its comparisons (tests/stats.py); the seed is fixed, so a pass is
reproducible. Standard errors come from the exact variance (and, for sample variances, the
exact fourth moment) under the claim being tested, not from the measured spread.
"""

from __future__ import annotations

import io
import math
import sys

import numpy as np
import pytest
from scipy import stats as sps

from tracer.errors import InputError
from tracer.study import primer

from stats import sidak, z_critical


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """run_all(out, seed=0) once: (results by name, printed text, out folder)."""
    out = tmp_path_factory.mktemp("primer")
    text = io.StringIO()
    results = primer.run_all(out, seed=0, stream=text)
    return {r.name: r for r in results}, text.getvalue(), out


def sample_variance_se(var: float, mu4: float, n: int) -> float:
    """SE of the unbiased sample variance of n iid values: Var(s^2) = mu4/n - var^2 (n-3)/(n(n-1)).
    Holds for any distribution with a fourth moment; with n >= 1e5 the sample variance is close
    to normal (central limit theorem on the squares), so a z-test on it is sound."""
    return math.sqrt(mu4 / n - var**2 * (n - 3) / (n * (n - 1)))


# ---------------------------------------------------------------------------------------------
# 1. Inversion


def test_inversion_samples_pass_ks(run):
    """KS test of the inversion samples against the exact CDF 1 - exp(-lam x): the p-value must
    be above the 1% level (one comparison; a correct sampler fails with probability 1%).
    Our p-value is also checked against scipy's exact KS distribution, and D against scipy's."""
    result = run[0]["inversion"]
    x, lam = result.numbers["samples"], result.numbers["lam"]
    d, p = result.numbers["ks"][lam]
    assert p > 0.01
    ref = sps.kstest(x, lambda t: 1.0 - np.exp(-lam * t))
    assert d == pytest.approx(ref.statistic, abs=1e-12)
    # The asymptotic Q_KS with Stephens' correction is within a few 1e-3 of the exact law here.
    assert p == pytest.approx(ref.pvalue, abs=5e-3)


def test_ks_rejects_wrong_rate(run):
    """The KS test has power: against Exp(0.9 lam) and Exp(1.1 lam) the same samples are
    rejected at the 1% level. At n = 20000 the largest gap between the true and the wrong CDF
    (0.039 and 0.036) makes sqrt(n) D about 5, against a critical value of 1.63 and a sampling
    spread of sqrt(n) D near 0.5, so a miss would mean a broken test, not bad luck. (A rate
    only 5% off gives sqrt(n) D near 2.5 and was missed by about 1 seed in 100.)"""
    result = run[0]["inversion"]
    lam = result.numbers["lam"]
    wrong = {rate: dp for rate, dp in result.numbers["ks"].items() if rate != lam}
    assert len(wrong) == 2
    for rate, (d, p) in wrong.items():
        assert p < 0.01, (rate, d, p)
    # The tail formula: Q_KS at the tabulated 1% critical value is 1%, and it falls with t.
    assert primer.kolmogorov_sf(primer.KS_CRITICAL_1PCT) == pytest.approx(0.01, abs=1e-4)
    assert primer.kolmogorov_sf(0.5) == pytest.approx(sps.kstwobign.sf(0.5), abs=1e-10)
    assert primer.kolmogorov_sf(2.0) == pytest.approx(sps.kstwobign.sf(2.0), abs=1e-12)


def test_inversion_moments(run):
    """Mean and variance of the samples against 1/lam and 1/lam^2: z-tests with the exact SEs
    (mean: sqrt(var/n); variance: from mu4 = 9/lam^4), Sidak over 2."""
    nums = run[0]["inversion"].numbers
    lam, n = nums["lam"], nums["n"]
    crit = z_critical(2)
    assert abs(nums["mean"] - 1.0 / lam) / math.sqrt(1.0 / (lam * lam * n)) < crit
    assert abs(nums["var"] - 1.0 / lam**2) / sample_variance_se(1.0 / lam**2, 9.0 / lam**4, n) < crit
    # The sampler itself: exactly the inverse of the CDF.
    u = np.linspace(0.0, 0.999, 7)
    assert np.allclose(primer.exponential_cdf(primer.sample_exponential(u, lam), lam), u, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# 2. Rejection sampling and pi


def test_pi_estimators_unbiased(run):
    """Mean of T trials of each estimator against pi: z-test with the exact SE
    sqrt(c^2 p(1-p)/(n T)), Sidak over the 2 estimators."""
    nums = run[0]["rejection"].numbers
    crit = z_critical(2)
    for key in ("triangle", "square"):
        est = nums["estimates"][key]
        se = math.sqrt(nums["exact_var"][key] / len(est))
        assert abs(est.mean() - math.pi) / se < crit, key
    # The geometry behind p: exact area ratios of the inscribed circles.
    assert primer.TRIANGLE_P == pytest.approx((math.pi / 12) / (math.sqrt(3) / 4))
    assert primer.SQUARE_P == pytest.approx(math.pi / 4)


def test_pi_variances_match_exact(run):
    """Sample variance of the T estimates against the exact c^2 p(1-p)/n. The estimates are
    c k/n with k ~ Binomial(1000, p), very nearly normal, so (T-1) s^2 / sigma^2 ~ chi^2_(T-1)
    (checked: the exact excess kurtosis (1 - 6pq)/(npq) is below 0.01, so the variance of s^2
    differs from the normal-theory 2 sigma^4/(T-1) by under 1%). Two-sided, Sidak over 2."""
    nums = run[0]["rejection"].numbers
    a = sidak(2)
    for key in ("triangle", "square"):
        est = nums["estimates"][key]
        t = len(est)
        var, mu4 = nums["exact_var"][key], nums["exact_mu4"][key]
        p = primer.TRIANGLE_P if key == "triangle" else primer.SQUARE_P
        assert mu4 / var**2 - 3.0 == pytest.approx(float(sps.binom.stats(nums["n"], p, moments="k")))
        assert abs(mu4 / var**2 - 3.0) < 0.01, key
        stat = (t - 1) * est.var(ddof=1) / var
        assert sps.chi2.ppf(a / 2, t - 1) < stat < sps.chi2.isf(a / 2, t - 1), (key, stat)


def test_square_beats_triangle(run):
    """(b) has the lower variance: exactly (2.70e-3 against 6.45e-3 at n = 1000), and measured,
    by a one-sided F-test of s_a^2 / s_b^2 > 1 (independent, nearly normal samples of equal
    size T: the ratio is F(T-1, T-1) under equal variances) at the 1% level."""
    nums = run[0]["rejection"].numbers
    assert nums["exact_var"]["square"] < nums["exact_var"]["triangle"]
    a, b = nums["estimates"]["triangle"], nums["estimates"]["square"]
    ratio = a.var(ddof=1) / b.var(ddof=1)
    assert ratio > sps.f.isf(0.01, len(a) - 1, len(b) - 1)


def test_ball_acceptance_matches_volume_and_falls(run):
    """Acceptance rate of the unit d-ball in [-1, 1]^d against pi^(d/2)/(Gamma(d/2+1) 2^d):
    z-test with the binomial SE sqrt(p(1-p)/N) per d; and it falls with d: for each d, a
    one-sided z-test that rate_d - rate_(d+1) > 0 (independent draws: SEs add in quadrature).
    Sidak over all 2D - 1 comparisons."""
    nums = run[0]["rejection"].numbers
    dims, accepted, n = nums["dims"], nums["accepted"], nums["points"]
    m = 2 * len(dims) - 1
    rates = [k / n for k in accepted]
    for d, rate, exact in zip(dims, rates, nums["exact_rate"], strict=True):
        assert exact == pytest.approx(math.pi ** (d / 2) / (math.gamma(d / 2 + 1) * 2**d), rel=1e-13)
        se = math.sqrt(exact * (1 - exact) / n)
        if se == 0.0:  # d = 1: the segment fills its cube, every point is accepted
            assert rate == exact == 1.0
        else:
            assert abs(rate - exact) / se < z_critical(m), d
    se = [math.sqrt(p * (1 - p) / n) for p in nums["exact_rate"]]
    for i in range(len(dims) - 1):
        assert (rates[i] - rates[i + 1]) / math.hypot(se[i], se[i + 1]) > z_critical(m, sides=1), dims[i]


# ---------------------------------------------------------------------------------------------
# 3. Importance sampling


def _check_is_cases(cases: dict, n: int) -> int:
    """z-tests of mean and sample variance for every case with nonzero exact variance."""
    live = {k: c for k, c in cases.items() if c["var"] > 0.0}
    crit = z_critical(2 * len(live))
    for case, c in live.items():
        est = c["estimates"]
        assert abs(est.mean() - c["mean"]) / math.sqrt(c["var"] / n) < crit, case
        assert abs(est.var(ddof=1) - c["var"]) / sample_variance_se(c["var"], c["mu4"], n) < crit, case
    return len(live)


def test_discrete_is_unbiased_with_exact_variance(run):
    """For each discrete f and pmf p with nonzero variance: the mean of n estimates f(X)/p(X)
    against I = sum f, and their sample variance against sum f^2/p - I^2, both z-tests with
    exact SEs (the variance's from the exact fourth moment sum p (f/p - I)^4, as the weights are
    far from normal). Sidak over all of them."""
    nums = run[0]["importance"].numbers
    assert _check_is_cases(nums["discrete"], nums["n"]) == 4
    for c in nums["discrete"].values():
        assert c["mean"] == pytest.approx(c["f"].sum())
        assert c["var"] == pytest.approx((c["f"] ** 2 / c["pmf"]).sum() - c["f"].sum() ** 2, abs=1e-9)


def test_pmf_proportional_to_f_is_optimal(run):
    """The Lagrange-multiplier result: minimizing sum f^2/p subject to sum p = 1 gives
    p = |f| / sum |f|, with sum f^2/p = (sum |f|)^2. For f >= 0 that is I^2: zero variance, so
    every estimate equals I to float precision. For signed f the minimum (sum |f|)^2 - I^2 > 0
    is reached and no pmf does better (checked on 2000 random pmfs: Cauchy-Schwarz, no noise)."""
    nums = run[0]["importance"].numbers
    best = nums["discrete"]["f >= 0, p proportional to f"]
    total = nums["discrete_f"].sum()
    assert np.max(np.abs(best["estimates"] - total)) <= 1e-12 * total
    assert abs(best["var"]) <= 1e-12 * total**2
    signed = nums["signed_f"]
    optimum = nums["discrete"]["signed f, p proportional to |f|"]["var"]
    assert optimum == pytest.approx(np.abs(signed).sum() ** 2 - signed.sum() ** 2)
    assert optimum > 0.0
    pmfs = np.random.default_rng(3).dirichlet(np.ones(len(signed)), size=2000)
    variances = (signed**2 / pmfs).sum(axis=1) - signed.sum() ** 2
    assert variances.min() >= optimum


def test_continuous_is_unbiased_with_exact_variance(run):
    """Integral of 4x^3 over [0, 1] with pdfs sampled by inversion: mean and variance z-tests
    against I = 1 and int f^2/p - 1 (exact SEs, Sidak over all). The quadrature behind the
    exact values is checked against closed forms: 9/7 (uniform), 1/3 (2x), 0 (4x^3), and for
    p = 1.5 - x, 16 int x^6/(a - x) = 16 (a^6 log(a/(a-1)) - sum_k a^k/(6-k)) - 1 with a = 1.5.
    p proportional to f gives every estimate exactly 1."""
    nums = run[0]["importance"].numbers
    assert _check_is_cases(nums["continuous"], nums["n"]) == 3
    a = 1.5
    poor = 16.0 * (a**6 * math.log(a / (a - 1.0)) - sum(a**k / (6 - k) for k in range(6))) - 1.0
    closed = {"uniform, p = 1": 9 / 7, "linear, p = 2x": 1 / 3, "p = 4x^3, proportional to f": 0.0,
              "poor, p = 1.5 - x": poor}
    for case, (pdf, _, _) in primer.CONTINUOUS_PDFS.items():
        mean, var, _ = primer.continuous_is_moments(primer.continuous_f, pdf)
        assert mean == pytest.approx(1.0, abs=1e-12)
        assert var == pytest.approx(closed[case], abs=1e-10), case
        assert nums["continuous"][case]["var"] == pytest.approx(closed[case], abs=1e-10), case
    ideal = nums["continuous"]["p = 4x^3, proportional to f"]["estimates"]
    assert np.all(ideal == 1.0)


# ---------------------------------------------------------------------------------------------
# 4. Multiple importance sampling


def test_mis_exact_values_by_quadrature():
    """The quadrature is accurate: the integral matches its closed form, and the exact
    variances do not move when the quadrature panels are doubled."""
    x, w = primer.gauss_legendre(0.0, 1.0, 4000)
    assert (w * primer.mis_f(x)).sum() == pytest.approx(primer.MIS_I, rel=1e-12)
    assert (w * primer.mis_p2(x)).sum() == pytest.approx(1.0, rel=1e-12)
    u = np.linspace(0.0, 1.0, 11)
    # Inversion: the sampled point's CDF is u (CDF by quadrature on [0, x]).
    for ui, xi in zip(u[1:-1], primer.mis_sample2(u[1:-1]), strict=True):
        t, tw = primer.gauss_legendre(0.0, float(xi), 4000)
        assert (tw * primer.mis_p2(t)).sum() == pytest.approx(ui, abs=1e-10)
    for est in primer.MIS_ESTIMATORS:
        coarse, fine = primer.mis_exact(est, 4000), primer.mis_exact(est, 8000)
        assert coarse["var"] == pytest.approx(fine["var"], rel=1e-6), est.name


def test_mis_unit_sum_weights_unbiased(run):
    """Every estimator whose weights sum to one (each pdf alone, constants 1/2 + 1/2, balance,
    power, optimal with exact and with learned a): mean of T trials against I, z-test with the
    exact SE sqrt(var/T), Sidak over 7."""
    nums = run[0]["mis"].numbers
    rows = {k: r for k, r in nums["rows"].items() if r["weight_sum_is_one"]}
    assert len(rows) == 7
    for name, r in rows.items():
        est = r["estimates"]
        assert abs(est.mean() - nums["I"]) / math.sqrt(r["var"] / len(est)) < z_critical(7), name


def test_optimal_mis_is_the_analytic_optimum():
    """Optimal MIS in 1-D, exactly (quadrature): the a = A^-1 b of Kondapaneni et al. gives a
    variance no other estimator of the family reaches (a 1-D scan of a_1 - a_2 around it, the
    only coefficient that matters, finds nothing lower; a shift of a along n = (1, 1) changes
    no weight), below the balance and power heuristics' and equal to int f^2 / q - a . b."""
    alpha = primer.optimal_alpha()
    best = primer.mis_exact(primer.MisEstimator("opt", (1, 1), (primer._optimal(0, alpha),
                                                                   primer._optimal(1, alpha))))
    x, w = primer.gauss_legendre(0.0, 1.0, 4000)
    p1, p2, f = primer.mis_p1(x), primer.mis_p2(x), primer.mis_f(x)
    b = np.array([(w * f * p1 / (p1 + p2)).sum(), (w * f * p2 / (p1 + p2)).sum()])
    assert best["var"] == pytest.approx((w * f * f / (p1 + p2)).sum() - alpha @ b, rel=1e-9)
    shifted = alpha + 0.7
    same = primer.mis_exact(primer.MisEstimator("shift", (1, 1), (primer._optimal(0, shifted),
                                                                     primer._optimal(1, shifted))))
    assert same["var"] == pytest.approx(best["var"], rel=1e-9)
    for delta in (-0.2, -0.05, -0.01, 0.01, 0.05, 0.2):
        other = alpha + np.array([delta, 0.0])
        moved = primer.mis_exact(primer.MisEstimator("moved", (1, 1), (primer._optimal(0, other),
                                                                          primer._optimal(1, other))))
        assert moved["var"] > best["var"], delta
    for name in ("balance heuristic", f"power heuristic, beta = {primer.POWER_BETA:g}"):
        heuristic = next(e for e in primer.MIS_ESTIMATORS if e.name == name)
        assert primer.mis_exact(heuristic)["var"] > best["var"], name


def test_learned_alpha_matches_the_analytic_optimum():
    """The renderer's way of learning a (``tracer.tuning.control_coefficient``: the regression
    of the balance estimate V on the control variate C, shrunk by 4 pseudo-samples) applied to
    the 1-D integrand: from 200,000 independent draws it matches the coefficient a_1 - a_2 of
    the analytic optimum A^-1 b. z-test with the regression slope's standard error (the
    shrinkage moves a by ~4 / (n Var C) of itself, 1e-4 SE here, negligible)."""
    alpha, se = primer.learned_alpha(np.random.default_rng(11), 200_000)
    exact = primer.control_variate_alpha(primer.optimal_alpha())
    assert abs(alpha - exact) / se < z_critical(1)


def test_mis_other_weights_biased_by_predicted_amount(run):
    """Weights that do not sum to one are biased by int (w1 + w2 - 1) f: for the constants
    3/4 + 1/2 that is exactly I/4 (checked), for p_i/max(p1, p2) quadrature gives it. For each,
    a two-sided z-test of the measured mean against I + predicted bias, and a one-sided z-test
    that the mean is above I (the bias is really there). Sidak over 4."""
    nums = run[0]["mis"].numbers
    rows = {k: r for k, r in nums["rows"].items() if not r["weight_sum_is_one"]}
    assert len(rows) == 2
    assert rows["constant 3/4 + 1/2 (sum 1.25)"]["bias"] == pytest.approx(0.25 * nums["I"], rel=1e-12)
    for name, r in rows.items():
        est = r["estimates"]
        se = math.sqrt(r["var"] / len(est))
        assert abs(est.mean() - (nums["I"] + r["bias"])) / se < z_critical(4), name
        assert (est.mean() - nums["I"]) / se > z_critical(4, sides=1), name


def test_mis_variances_match_quadrature(run):
    """Sample variance of the T estimates of each of the 9 estimators against its exact variance
    by quadrature (sum over techniques of the variance of w_i f/(n_i p_i)); z-test with the SE
    from the exact fourth moment, Sidak over 9."""
    nums = run[0]["mis"].numbers
    assert len(nums["rows"]) == 9
    for name, r in nums["rows"].items():
        est = r["estimates"]
        z = (est.var(ddof=1) - r["var"]) / sample_variance_se(r["var"], r["mu4"], len(est))
        assert abs(z) < z_critical(9), (name, z)


def test_mis_heuristics_beat_each_pdf_alone(run):
    """At the same 2 samples, the balance and power heuristics have lower variance than either
    pdf alone: exactly (quadrature), and measured, by a one-sided z-test on the difference of
    the two sample variances (independent; SEs from exact fourth moments), Sidak over 4."""
    rows = run[0]["mis"].numbers["rows"]
    singles = ["p1 only (uniform)", "p2 only (peak)"]
    combined = ["balance heuristic", f"power heuristic, beta = {primer.POWER_BETA:g}"]
    for s in singles:
        for c in combined:
            assert rows[c]["var"] < rows[s]["var"]
            a, b = rows[s], rows[c]
            se = math.hypot(sample_variance_se(a["var"], a["mu4"], len(a["estimates"])),
                            sample_variance_se(b["var"], b["mu4"], len(b["estimates"])))
            diff = a["estimates"].var(ddof=1) - b["estimates"].var(ddof=1)
            assert diff / se > z_critical(4, sides=1), (s, c)


# ---------------------------------------------------------------------------------------------
# 5. Quasi-Monte Carlo


def test_qmc_exact_integral():
    """The series values of int exp(xy) and of the variance of f(U) against 2-D quadrature."""
    x, w = primer.gauss_legendre(0.0, 1.0, 8)
    xx, yy = np.meshgrid(x, x)
    ww = np.outer(w, w)
    values = primer.qmc_f(np.stack([xx.ravel(), yy.ravel()], axis=1)).reshape(xx.shape)
    assert (ww * values).sum() == pytest.approx(primer.QMC_I, rel=1e-13)
    assert (ww * values**2).sum() - primer.QMC_I**2 == pytest.approx(primer.QMC_VAR, rel=1e-10)


def test_qmc_sobol_rate_steeper_than_mc(run):
    """Fitted log-log slopes of the RMSE over 256 runs, with jackknife SEs over the runs (which
    match the seed-to-seed spread of the slopes: about 0.01 for MC, 0.06-0.08 for Sobol when
    this was written). Plain MC: two-sided z-test of the slope against -1/2, its exact rate.
    Sobol: one-sided z-test that its slope is steeper than MC's by more than 0.5, i.e. faster
    than n^-1 (theory for scrambled nets and smooth f: n^-1.5). Sidak over 2."""
    nums = run[0]["qmc"].numbers
    assert abs(nums["mc_rate"] + 0.5) / nums["mc_rate_se"] < z_critical(2)
    gap = nums["mc_rate"] - nums["sobol_rate"] - 0.5
    assert gap / math.hypot(nums["mc_rate_se"], nums["sobol_rate_se"]) > z_critical(2, sides=1)


def test_qmc_skipped_without_scipy(monkeypatch):
    """Without scipy, exercise 5 is skipped with a one-line message naming the fix, and the
    other exercises are unaffected (nothing else imports scipy)."""
    monkeypatch.setitem(sys.modules, "scipy.stats", None)  # makes `from scipy.stats import` fail
    result = primer.qmc(np.random.default_rng(0), None)
    assert result.skipped and "pip install scipy" in result.skipped and "\n" not in result.skipped
    text = io.StringIO()
    primer.print_result(result, text)
    assert "skipped" in text.getvalue() and "pip install scipy" in text.getvalue()


# ---------------------------------------------------------------------------------------------
# The command


def test_run_all_writes_a_figure_and_a_table_per_exercise(run):
    """One PNG per exercise in the output folder (no temporary files left), and a title line
    and at least one table header per exercise in the printed text."""
    results, text, out = run
    assert list(results) == ["inversion", "rejection", "importance", "mis", "qmc"]
    names = sorted(p.name for p in out.iterdir())
    assert names == ["primer_1_inversion.png", "primer_2_rejection.png", "primer_3_importance.png",
                     "primer_4_mis.png", "primer_5_qmc.png"]
    for k, result in enumerate(results.values(), start=1):
        assert result.figure == out / names[k - 1]
        assert result.figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert result.title.startswith(f"{k}. ") and result.title in text
        assert result.tables and all(rows for rows in result.tables.values())
        for caption in result.tables:
            assert caption in text
    assert text.count("\n  ---") >= 5  # the rule under each table header


def test_numbers_depend_on_the_seed_alone(tmp_path):
    """Same seed, same numbers, with or without a figure (the figure draws its own points after
    the table's); a different seed, different numbers."""
    def small(seed, out=None):
        return primer.rejection(np.random.default_rng(seed), out, n=100, trials=20, dims=(2, 3), points=500)

    a, b, c = small(1), small(1, tmp_path), small(2)
    assert b.figure is not None and b.figure.is_file()
    assert np.array_equal(a.numbers["estimates"]["square"], b.numbers["estimates"]["square"])
    assert a.numbers["accepted"] == b.numbers["accepted"]
    assert not np.array_equal(a.numbers["estimates"]["square"], c.numbers["estimates"]["square"])


def test_main_rejects_a_file_as_output_folder(tmp_path):
    """--out naming an existing file is bad input (InputError: one line, exit status 2)."""
    path = tmp_path / "file.txt"
    path.write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        primer.main(path, 0)


def test_rejection_figure_draws_its_circles_round():
    """The rejection figure's circles (the incircles of the triangle and the square) are as wide
    as they are tall on the page: both panels have equal aspect, one unit as long in x as in y.
    Fails if a panel lets its axes box set the scale instead, which draws the circle as an oval
    (the triangle's panel spans 1 unit across and 0.87 up)."""
    from matplotlib.patches import Circle

    result = primer.rejection(np.random.default_rng(0), None, n=100, trials=20, dims=(2, 3), points=500)
    fig = primer.rejection_figure(np.random.default_rng(1), result)
    fig.canvas.draw()
    circles = [patch for ax in fig.axes for patch in ax.patches if isinstance(patch, Circle)]
    assert len(circles) == 2
    for circle in circles:
        box = circle.get_window_extent()
        assert box.width == pytest.approx(box.height)
    primer._pyplot().close(fig)
