"""Chi-square goodness-of-fit tests for samplers, in the spirit of Mitsuba 3's ``chi2.py``.

A sampler draws N points (directions on the sphere, or points on a triangle); its claimed
density ``pdf`` is a pure function of the point. We

1. lay a grid of cells over a rectangle of parameters (a, b) that a :class:`Domain` maps onto
   the sample space (a spherical cap in (theta, phi) or (cos theta, phi), a triangle in
   (s, t)), and count the samples in each cell. Samples that fall outside the domain, or that
   the caller marks invalid (pdf 0, weight 0), go to one extra "rest" cell;
2. integrate ``pdf`` over every cell with an adaptive Gauss-Legendre cubature
   (:func:`integrate_cells`), so the expected count is E_i = N * integral; the rest cell
   expects N * (1 - integral over the domain): the mass a sampler loses (GGX directions
   below the horizon, the back of a one-sided light) is therefore tested too;
3. pool the cells with E_i < 5 into one (merged with the smallest other cells until it
   expects >= 5), compute X^2 = sum (O_i - E_i)^2 / E_i and its p-value from the chi-square
   distribution with (cells - 1) degrees of freedom (``scipy.stats.chi2.sf``);
4. separately, for every cell that expects < 5 samples, compute the Poisson tail
   P(X >= O_i | E_i): a handful of samples where the pdf says (almost) none can occur is
   invisible inside a pooled cell but is caught here;
5. reject when either part is significant. The test's level ``alpha`` is split evenly
   between the two parts (Bonferroni), and the low-cell tails are Sidak-corrected over the
   number of low cells, so a correct sampler fails a call with probability <= alpha.
   Choose alpha with :func:`sidak` so that a whole suite of n_tests calls raises a false
   alarm with probability <= 1 %.

Accuracy of the expected counts. Each cell is integrated with a sub x sub Gauss-Legendre
product rule, then split in 2 x 2 children with the same rule, recursively, until the coarse
and the refined estimates of a box agree to ``tol_box = tol_cell * 2^-level`` or ``max_level``
is reached. A discontinuity line (the horizon, a light's silhouette) crosses ~2^level boxes
at a level, so this allocation bounds the cell's total error by ~tol_cell. For a chi-square
test ``tol_cell = TOL_SIGMA * sqrt(max(E_i, 1)) / N`` with TOL_SIGMA = 0.02: an error d_i in
E_i raises the expected X^2 by d_i^2 / E_i <= TOL_SIGMA^2 = 4e-4 per cell, so over C cells by
<= 4e-4 C = 2.9e-4 sqrt(C) standard deviations of X^2 (sqrt(2 C)): 1.6 % for a 40 x 80 grid.
Cells that reach ``max_level`` first (steep jumps, integrable singularities at a tessellated
sphere's silhouette) are counted in ``unconverged_cells``; the achieved error estimate per
cell (the sum of |refined - coarse| over its boxes, an overestimate of the error of the
refined value) gives ``integration_error`` (on the total), ``worst_integration_sigma`` (the
largest in units of sqrt(E_i)) and ``integration_chi2`` = sum d_i^2 / E_i, the bound on the
bias of X^2 that a caller should compare with sqrt(2 dof).

Blind spots. Cubature only sees the integrand at its nodes: a support smaller than the node
spacing (a light smaller than a cell, a sliver of hemisphere in a cell that the horizon cuts
near a corner) reads as 0 at every node, and coarse and refined then agree on 0. Make the
domain fit the distribution (a cap around a light) so that no feature is smaller than a
cell, and let :func:`goodness_of_fit` guide the refinement with the samples: boxes holding
a sample in a cell that expects < 5 are refined down to ``guide_level`` whatever the
tolerance says (the expected counts still depend on the pdf alone; a region where the pdf
is 0 stays 0 however deep it is refined). Without this, a 40 x 80 cap around a GGX lobe
cut by the horizon had cells whose true expectation was 0.6 samples computed as exactly 0,
and a single valid sample there failed the Poisson part.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from tracer.study.statistics import sidak_family

# Re-exported: callers pick a call's alpha as chi2.sidak(n_tests), the level of a suite of n_tests.
from stats import sidak as sidak

MIN_EXPECTED = 5.0  # cells expecting fewer samples are pooled (Cochran's rule)
TOL_SIGMA = 0.02  # integration tolerance per cell, in units of the cell's Poisson sigma
_GAUSS = {k: np.polynomial.legendre.leggauss(k) for k in (2, 3, 4, 5, 6, 8)}


# ---------------------------------------------------------------------------------------------
# Domains: a parameter rectangle mapped onto the sample space


@dataclass(frozen=True)
class Domain:
    """A rectangle of parameters ``bounds = ((a0, a1), (b0, b1))`` mapped onto sample space.

    forward : params (m, 2) -> points (m, k).
    inverse : points (m, k) -> params (m, 2); NaN, or values outside ``bounds``, mean
        "not in the domain" (the sample goes to the rest cell).
    jacobian : params (m, 2) -> (m,) measure of the sample space per unit parameter area
        (solid angle for directions, area for points), so that the integral of a density p
        over a cell is the integral of p(forward(a, b)) * jacobian(a, b) da db.
    """

    name: str
    bounds: tuple[tuple[float, float], tuple[float, float]]
    forward: Callable[[np.ndarray], np.ndarray]
    inverse: Callable[[np.ndarray], np.ndarray]
    jacobian: Callable[[np.ndarray], np.ndarray]
    labels: tuple[str, str] = ("a", "b")


def _basis(axis: np.ndarray) -> np.ndarray:
    """Rows (s, t, n): an orthonormal right-handed basis with n = axis (test-side, independent
    of tracer.frame)."""
    n = np.asarray(axis, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    s = np.cross(helper, n)
    s /= np.linalg.norm(s)
    return np.stack([s, np.cross(n, s), n])


def spherical_domain(axis=(0.0, 0.0, 1.0), theta_max: float = np.pi,
                     polar: str = "theta") -> Domain:
    """Unit directions within ``theta_max`` of ``axis``, parametrized by (polar, phi) in the
    frame whose z axis is ``axis``; phi in [-pi, pi].

    polar = "theta": a = theta in [0, theta_max], jacobian sin(theta) (resolves peaks at the
        axis and keeps the integrand smooth there);
    polar = "z": a = cos(theta) in [cos(theta_max), 1], jacobian 1 (equal-area cells).
    """
    basis = _basis(np.asarray(axis))
    theta_max = float(theta_max)
    if polar == "theta":
        bounds = ((0.0, theta_max), (-np.pi, np.pi))

        def to_z(a):
            return np.cos(a), np.sin(a)

        def jac(p):
            return np.sin(p[:, 0])

        def polar_of(local):
            return np.arccos(np.clip(local[:, 2], -1.0, 1.0))
    elif polar == "z":
        bounds = ((float(np.cos(theta_max)), 1.0), (-np.pi, np.pi))

        def to_z(a):
            return a, np.sqrt(np.maximum(0.0, 1.0 - a * a))

        def jac(p):
            return np.ones(len(p))

        def polar_of(local):
            return np.clip(local[:, 2], -1.0, 1.0)
    else:
        raise ValueError(f"polar must be 'theta' or 'z', got {polar!r}")

    s_axis, t_axis, n_axis = basis

    def forward(p):
        z, r = to_z(p[:, 0])
        # Written out: numpy's (m, 3) @ (3, 3) is several times slower than three axpys.
        x, y = r * np.cos(p[:, 1]), r * np.sin(p[:, 1])
        return x[:, None] * s_axis + y[:, None] * t_axis + z[:, None] * n_axis

    def inverse(w):
        local = np.stack([w[:, 0] * b[0] + w[:, 1] * b[1] + w[:, 2] * b[2] for b in basis], axis=1)
        return np.stack([polar_of(local), np.arctan2(local[:, 1], local[:, 0])], axis=1)

    label = "theta" if polar == "theta" else "cos theta"
    return Domain(f"cap(axis={np.round(basis[2], 3).tolist()}, theta<={theta_max:.3f})",
                  bounds, forward, inverse, jac, (label, "phi"))


def triangle_domain(v0, v1, v2) -> Domain:
    """Points of the triangle (v0, v1, v2) in 3-D, parametrized by (s, t) in [0, 1]^2 with
    barycentrics b1 = s (1 - t), b2 = s t (point v0 + b1 (v1 - v0) + b2 (v2 - v0)); the
    jacobian is s * |(v1 - v0) x (v2 - v0)|. A uniform density is smooth (linear in s) here,
    so the Gauss rule integrates it exactly; points off the triangle map outside [0, 1]^2."""
    v0, e1, e2 = (np.asarray(v0, float), np.asarray(v1, float) - v0, np.asarray(v2, float) - v0)
    twice_area = float(np.linalg.norm(np.cross(e1, e2)))
    edges = np.stack([e1, e2], axis=1)  # (3, 2)
    pinv = np.linalg.pinv(edges)  # (2, 3) least-squares barycentrics (b1, b2)

    def forward(p):
        b1 = p[:, 0] * (1.0 - p[:, 1])
        b2 = p[:, 0] * p[:, 1]
        return v0 + b1[:, None] * e1 + b2[:, None] * e2

    def inverse(x):
        b = (x - v0) @ pinv.T
        s = b[:, 0] + b[:, 1]
        off_plane = np.linalg.norm(v0 + b @ edges.T - x, axis=1) > 1e-9 * max(twice_area, 1.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(s > 0.0, b[:, 1] / np.where(s > 0.0, s, 1.0), 0.0)
        # A negative barycentric gives t outside [0, 1] or s outside [0, 1]: not in the domain.
        t = np.where((b[:, 0] < 0.0) | (b[:, 1] < 0.0) | off_plane, np.nan, t)
        return np.stack([s, t], axis=1)

    def jac(p):
        return p[:, 0] * twice_area

    return Domain("triangle", ((0.0, 1.0), (0.0, 1.0)), forward, inverse, jac,
                  ("s=b1+b2", "t=b2/s"))


# ---------------------------------------------------------------------------------------------
# Histogram and adaptive cubature


def histogram(points: np.ndarray, domain: Domain, shape: tuple[int, int],
              valid: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Counts ``(na, nb)`` of ``points (n, k)`` per cell, and the number of the rest (invalid
    or outside the domain)."""
    n = len(points)
    valid = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    p = np.full((n, 2), np.nan)
    if valid.any():
        with np.errstate(invalid="ignore"):
            p[valid] = domain.inverse(points[valid])
    (a0, a1), (b0, b1) = domain.bounds
    na, nb = shape
    with np.errstate(invalid="ignore"):
        ia = np.floor((p[:, 0] - a0) / (a1 - a0) * na)
        ib = np.floor((p[:, 1] - b0) / (b1 - b0) * nb)
        # Parameters exactly on the upper bound (theta = theta_max, phi = pi) belong to the
        # last cell: the map is onto the closed rectangle.
        ia = np.where(p[:, 0] == a1, na - 1, ia)
        ib = np.where(p[:, 1] == b1, nb - 1, ib)
        inside = (ia >= 0) & (ia < na) & (ib >= 0) & (ib < nb)
    counts = np.bincount((ia[inside] * nb + ib[inside]).astype(np.int64), minlength=na * nb)
    return counts.reshape(na, nb).astype(np.float64), int(n - inside.sum())


def _rule(func: Callable[[np.ndarray], np.ndarray], domain: Domain, lo: np.ndarray, hi: np.ndarray,
          sub: int, chunk: int = 1 << 20) -> np.ndarray:
    """Gauss-Legendre sub x sub estimate of the integral of func(forward) * jacobian over
    each parameter box [lo, hi] (``(m, 2)`` each)."""
    x, w = _GAUSS[sub]
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    ua, ub = np.meshgrid(x, x, indexing="ij")
    wab = np.outer(w, w).ravel()
    ua, ub = ua.ravel(), ub.ravel()
    out = np.empty(len(lo))
    per = max(1, chunk // (sub * sub))
    for start in range(0, len(lo), per):
        box_lo, box_hi = lo[start:start + per], hi[start:start + per]
        size = box_hi - box_lo
        pa = box_lo[:, 0:1] + size[:, 0:1] * ua
        pb = box_lo[:, 1:2] + size[:, 1:2] * ub
        params = np.stack([pa.ravel(), pb.ravel()], axis=1)
        values = np.asarray(func(domain.forward(params)), dtype=np.float64)
        values = (values * domain.jacobian(params)).reshape(len(box_lo), sub * sub)
        out[start:start + per] = (values @ wab) * size[:, 0] * size[:, 1]
    return out


@dataclass
class Cubature:
    """Integrals of a density over the cells of a grid.

    integral : (na, nb) integral per cell (a probability if func is a pdf).
    error : (na, nb) error estimate per cell (sum over boxes of |refined - coarse|).
    unconverged : (na, nb) bool, cells that hit ``max_level`` before meeting the tolerance.
    evaluations : how many times func was evaluated.
    """

    integral: np.ndarray
    error: np.ndarray
    unconverged: np.ndarray
    evaluations: int

    @property
    def total(self) -> float:
        return float(self.integral.sum())

    @property
    def total_error(self) -> float:
        return float(self.error.sum())


def integrate_cells(func: Callable[[np.ndarray], np.ndarray], domain: Domain,
                    shape: tuple[int, int],
                    tol: float | Callable[[np.ndarray], np.ndarray], sub: int = 4,
                    max_level: int = 7,
                    guide: Callable[[np.ndarray], np.ndarray] | None = None,
                    guide_level: int = 10) -> Cubature:
    """Adaptive cubature of ``func`` (points (m, k) -> (m,)) over every cell of a
    ``shape = (na, nb)`` grid on ``domain``.

    ``tol`` is the absolute tolerance per cell, or a function of the coarse per-cell integrals
    ``(na, nb) -> (na, nb)`` returning it. A box at refinement level L is accepted when its
    sub x sub Gauss estimate and the sum of its four children's estimates differ by at most
    tol_cell * 2^-L; the refined value is kept. See the module docstring for the accuracy.

    ``guide`` maps the coarse per-cell integrals to parameters ``(m, 2)`` of points whose
    boxes are refined regardless of the tolerance, down to ``guide_level``. Blind cubature
    cannot see a support smaller than its node spacing (a sliver of hemisphere in a cell that
    the horizon cuts near a corner): all nodes read 0, so coarse and refined agree on 0. The
    samples themselves show where the support is, so :func:`goodness_of_fit` guides the
    refinement with the samples that fell in cells expecting few: the expected counts still
    depend on the pdf alone, only the effort spent on them depends on the samples. A region
    where the pdf really is 0 stays 0 however deep it is refined.
    """
    (a0, a1), (b0, b1) = domain.bounds
    na, nb = shape
    ea, eb = np.linspace(a0, a1, na + 1), np.linspace(b0, b1, nb + 1)
    ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
    lo = np.stack([ea[ia.ravel()], eb[ib.ravel()]], axis=1)
    hi = np.stack([ea[ia.ravel() + 1], eb[ib.ravel() + 1]], axis=1)
    cell = np.arange(na * nb)
    estimate = _rule(func, domain, lo, hi, sub)
    evaluations = len(lo) * sub * sub
    tol_cell = (tol(estimate.reshape(shape)).ravel() if callable(tol)
                else np.full(na * nb, float(tol)))
    cell_lo = lo.copy()
    cell_size = hi - lo
    guide_keys = None
    if guide is not None:
        g = np.asarray(guide(estimate.reshape(shape)), dtype=np.float64).reshape(-1, 2)
        ga = np.clip(np.floor((g[:, 0] - a0) / (a1 - a0) * na), 0, na - 1).astype(np.int64)
        gb = np.clip(np.floor((g[:, 1] - b0) / (b1 - b0) * nb), 0, nb - 1).astype(np.int64)
        g_cell = ga * nb + gb
        g_frac = (g - cell_lo[g_cell]) / cell_size[g_cell]  # position inside its cell, [0, 1]^2
        guide_level = min(int(guide_level), 20)

        def guide_keys(level: int) -> np.ndarray:
            k = 1 << level
            fa = np.clip(np.floor(g_frac[:, 0] * k), 0, k - 1).astype(np.int64)
            fb = np.clip(np.floor(g_frac[:, 1] * k), 0, k - 1).astype(np.int64)
            return np.unique((g_cell << 40) | (fa << 20) | fb)

    integral = np.zeros(na * nb)
    error = np.zeros(na * nb)
    unconverged = np.zeros(na * nb, dtype=bool)
    last = max(max_level, guide_level if guide is not None else 0)
    for level in range(last + 1):
        if len(lo) == 0:
            break
        mid = 0.5 * (lo + hi)
        # Children in the order (lo, lo), (lo, hi), (hi, lo), (hi, hi) halves.
        c_lo = np.stack([lo, np.stack([lo[:, 0], mid[:, 1]], 1),
                         np.stack([mid[:, 0], lo[:, 1]], 1), mid], axis=1)
        c_hi = np.stack([mid, np.stack([mid[:, 0], hi[:, 1]], 1),
                         np.stack([hi[:, 0], mid[:, 1]], 1), hi], axis=1)
        child = _rule(func, domain, c_lo.reshape(-1, 2), c_hi.reshape(-1, 2), sub).reshape(-1, 4)
        evaluations += c_lo.shape[0] * 4 * sub * sub
        fine = child.sum(axis=1)
        diff = np.abs(fine - estimate)
        converged = diff <= tol_cell[cell] * 2.0 ** -level
        forced = np.zeros(len(lo), dtype=bool)
        if guide_keys is not None and level < guide_level:
            k = 1 << level
            frac = (lo - cell_lo[cell]) / cell_size[cell]
            fa = np.clip(np.rint(frac[:, 0] * k), 0, k - 1).astype(np.int64)
            fb = np.clip(np.rint(frac[:, 1] * k), 0, k - 1).astype(np.int64)
            forced = np.isin((cell.astype(np.int64) << 40) | (fa << 20) | fb, guide_keys(level))
        if level >= max_level:
            # Out of tolerance budget: keep the refined value and flag the cell (guided boxes
            # still go deeper, up to guide_level).
            unconverged[cell[~converged & ~forced]] = True
            converged[:] = True
        accept = (converged & ~forced) | (level == last)
        np.add.at(integral, cell[accept], fine[accept])
        np.add.at(error, cell[accept], diff[accept])
        more = ~accept
        lo = c_lo[more].reshape(-1, 2)
        hi = c_hi[more].reshape(-1, 2)
        estimate = child[more].ravel()
        cell = np.repeat(cell[more], 4)
    return Cubature(integral.reshape(shape), error.reshape(shape), unconverged.reshape(shape),
                    evaluations)


# ---------------------------------------------------------------------------------------------
# The statistic


def pooled_chi2(observed: np.ndarray, expected: np.ndarray,
                min_expected: float = MIN_EXPECTED) -> tuple[float, int, np.ndarray]:
    """Pearson's X^2 after pooling: cells expecting < ``min_expected`` are summed into one,
    which absorbs the smallest other cells until it expects >= ``min_expected``.

    Returns (statistic, degrees of freedom = kept cells - 1, mask of the pooled cells).
    """
    observed = np.asarray(observed, dtype=np.float64).ravel()
    expected = np.asarray(expected, dtype=np.float64).ravel()
    pooled = expected < min_expected
    order = np.argsort(expected)
    k = int(pooled.sum())
    pool_e = float(expected[pooled].sum())
    while k < len(order) and pool_e < min_expected and pooled.any():
        pooled[order[k]] = True
        pool_e += expected[order[k]]
        k += 1
    keep = ~pooled
    stat = float(np.sum((observed[keep] - expected[keep]) ** 2 / expected[keep]))
    cells = int(keep.sum())
    if pooled.any() and pool_e > 0.0:
        pool_o = float(observed[pooled].sum())
        stat += (pool_o - pool_e) ** 2 / pool_e
        cells += 1
    return stat, max(cells - 1, 1), pooled


@dataclass
class Chi2Result:
    """Outcome of :func:`goodness_of_fit`; ``passed`` is the verdict, :meth:`report` explains."""

    name: str
    domain: Domain
    shape: tuple[int, int]
    n: int
    alpha: float
    observed: np.ndarray  # (na, nb) counts
    expected: np.ndarray  # (na, nb) expected counts
    rest_observed: int
    rest_expected: float
    integral: float  # integral of the pdf over the domain
    integration_error: float  # estimated absolute error of ``integral``
    worst_integration_sigma: float  # max over cells of |error| * N / sqrt(max(E, 1))
    integration_chi2: float  # sum over cells of (N error)^2 / max(E, 1): bound on the X^2 bias
    unconverged_cells: int
    statistic: float
    dof: int
    p_chi2: float
    p_low: float  # Sidak-adjusted smallest Poisson tail over the low cells (1 if none)
    low_cells: int
    p_value: float = field(init=False)
    passed: bool = field(init=False)

    def __post_init__(self) -> None:
        # Bonferroni over the two parts: the test fails with probability <= alpha under H0.
        self.p_value = min(1.0, 2.0 * min(self.p_chi2, self.p_low))
        self.passed = bool(self.p_value >= self.alpha)

    def worst_cells(self, k: int = 6) -> list[tuple[int, int, float, float, float]]:
        """The k cells with the largest |O - E| / sqrt(max(E, 1)): (i, j, O, E, z)."""
        e, o = self.expected.ravel(), self.observed.ravel()
        z = (o - e) / np.sqrt(np.maximum(e, 1.0))
        order = np.argsort(-np.abs(z))[:k]
        nb = self.shape[1]
        return [(int(i // nb), int(i % nb), float(o[i]), float(e[i]), float(z[i])) for i in order]

    def report(self, k: int = 6) -> str:
        """A few lines: the verdict, the numbers behind it and the worst cells."""
        (a0, a1), (b0, b1) = self.domain.bounds
        na, nb = self.shape
        la, lb = self.domain.labels
        verdict = "PASS" if self.passed else "FAIL"
        lines = [
            f"chi2 {verdict} {self.name} on {self.domain.name}, grid {na}x{nb}, N={self.n}",
            f"  X^2={self.statistic:.1f} dof={self.dof} p_chi2={self.p_chi2:.3g}; "
            f"low cells={self.low_cells} p_low={self.p_low:.3g}; p={self.p_value:.3g} "
            f"vs alpha={self.alpha:.3g}",
            f"  integral of pdf over domain={self.integral:.6f} (+-{self.integration_error:.1e}, "
            f"worst cell {self.worst_integration_sigma:.3f} sigma, X^2 bias <= "
            f"{self.integration_chi2:.2g}, {self.unconverged_cells} unconverged); "
            f"rest cell O={self.rest_observed} E={self.rest_expected:.1f}",
            "  worst cells (z = (O-E)/sqrt(E)):",
        ]
        for i, j, o, e, z in self.worst_cells(k):
            ra = (a0 + (a1 - a0) * i / na, a0 + (a1 - a0) * (i + 1) / na)
            rb = (b0 + (b1 - b0) * j / nb, b0 + (b1 - b0) * (j + 1) / nb)
            lines.append(f"    {la} in [{ra[0]:.4f}, {ra[1]:.4f}], "
                         f"{lb} in [{rb[0]:.4f}, {rb[1]:.4f}]:"
                         f" O={o:.0f} E={e:.1f} z={z:+.1f}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()


def goodness_of_fit(points: np.ndarray, pdf: Callable[[np.ndarray], np.ndarray], domain: Domain,
                    shape: tuple[int, int], alpha: float, valid: np.ndarray | None = None,
                    name: str = "", mass: float | None = None, sub: int = 4, max_level: int = 7,
                    guide_level: int = 12, tol_sigma: float = TOL_SIGMA) -> Chi2Result:
    """Chi-square test that ``points (n, k)`` (those with ``valid``) follow density ``pdf``.

    ``pdf`` maps points (m, k) -> (m,) in the domain's measure (solid angle, area); it may
    integrate to less than 1 over the domain: the remainder is what the rest cell (invalid
    samples, samples outside the domain) expects. ``alpha`` is this test's significance level
    (use :func:`sidak` over the suite's number of tests).

    ``mass``: the integral of ``pdf`` over the domain when it is known in closed form (1 for a
    full-sphere domain, the selection mass of the lights that face x, ...). The rest cell then
    expects N (1 - mass) exactly, instead of N (1 - cubature), which would gather every cell's
    integration error into one cell (for a quad light, 1e6 samples and the default tolerance,
    ~10 spurious expected samples in a rest cell that truly expects none). Compare
    ``Chi2Result.integral`` with ``mass`` to check the pdf's normalization.
    """
    n = len(points)
    observed, rest_o = histogram(points, domain, shape, valid)

    def tol(coarse: np.ndarray) -> np.ndarray:
        return tol_sigma * np.sqrt(np.maximum(n * np.abs(coarse), 1.0)) / n

    valid_mask = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    with np.errstate(invalid="ignore"):
        params = domain.inverse(points[valid_mask]) if valid_mask.any() else np.zeros((0, 2))
    (a0, a1), (b0, b1) = domain.bounds
    params = params[(params[:, 0] >= a0) & (params[:, 0] <= a1)
                    & (params[:, 1] >= b0) & (params[:, 1] <= b1)]

    def guide(coarse: np.ndarray) -> np.ndarray:
        # The samples that fell in cells which the coarse rule says expect few: resolve them.
        na, nb = shape
        ia = np.clip(((params[:, 0] - a0) / (a1 - a0) * na).astype(np.int64), 0, na - 1)
        ib = np.clip(((params[:, 1] - b0) / (b1 - b0) * nb).astype(np.int64), 0, nb - 1)
        return params[n * coarse[ia, ib] < MIN_EXPECTED]

    cub = integrate_cells(pdf, domain, shape, tol, sub=sub, max_level=max_level, guide=guide,
                          guide_level=guide_level)
    expected = n * cub.integral
    rest_mass = 1.0 - (cub.total if mass is None else float(mass))
    rest_e = max(n * rest_mass, 0.0)

    obs_all = np.append(observed.ravel(), rest_o)
    exp_all = np.append(expected.ravel(), rest_e)
    stat, dof, _ = pooled_chi2(obs_all, exp_all)
    p_chi2 = float(stats.chi2.sf(stat, dof))

    # Cells that expect few samples: Poisson upper tails, Sidak-corrected over those cells.
    # The integration error is added to E so that it cannot make a correct pdf fail.
    low = exp_all < MIN_EXPECTED
    err_all = np.append(n * cub.error.ravel(), n * cub.total_error if mass is None else 0.0)
    e_low = np.maximum(exp_all[low] + err_all[low], 0.0)
    o_low = obs_all[low]
    if low.any():
        tails = np.where(o_low > 0, stats.poisson.sf(o_low - 1, e_low), 1.0)
        p_low = sidak_family(float(tails.min()), int(low.sum()))
    else:
        p_low = 1.0

    sigma_err = err_all / np.sqrt(np.maximum(exp_all, 1.0))
    worst = float(np.max(sigma_err))
    return Chi2Result(name=name, domain=domain, shape=tuple(shape), n=n, alpha=alpha,
                      observed=observed, expected=expected, rest_observed=rest_o,
                      rest_expected=rest_e, integral=cub.total, integration_error=cub.total_error,
                      worst_integration_sigma=worst, integration_chi2=float(np.sum(sigma_err ** 2)),
                      unconverged_cells=int(cub.unconverged.sum()),
                      statistic=stat, dof=dof, p_chi2=p_chi2, p_low=p_low, low_cells=int(low.sum()))
