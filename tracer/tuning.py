"""What optimal MIS and adaptive allocation learn from the earlier passes of a render.

Both settle, per pixel, something the classic estimator fixes in advance: the weights of MIS
(``--heuristic optimal``) and the split of a camera sample's N = n_l + n_b technique samples
between light and BSDF sampling (``--allocation adaptive``). Both learn it from the passes
already rendered and apply it to the passes that follow, learning again after passes 1, 2, 4,
8, ... (``relearns``). Random numbers are independent across sample indices, so
what a pass uses is independent of its own samples and each pass is unbiased for *any* value
learned; the learning changes the variance only. The first pass (the pilot) has nothing to
learn from: it runs the balance heuristic and the fixed counts. Statistics are gathered only
while a later pass will learn from them (``Tuning.collect``): the last half or more of a
render pays for applying what was learned, not for learning.

**Optimal MIS as a control variate.** Kondapaneni et al. (2019, "Optimal multiple importance
sampling") show that the variance-optimal weights of multi-sample MIS are
w_i = a_i p_i / f + (n_i p_i / q) (1 - sum_k a_k p_k / f), q = sum_k n_k p_k, with a solving
A a = b, A_ik = integral p_i p_k / q, b_i = integral f p_i / q. Summed over a camera sample's
samples x_s (technique t_s), the estimate is

    F = sum_s [ a_{t_s} / n_{t_s} + (f(x_s) - sum_k a_k p_k(x_s)) / q(x_s) ]

which is the balance heuristic's estimate V = sum_s f / q plus terms linear in a. Adding
lambda n to a changes nothing (lambda - lambda per sample), so with two techniques one
coefficient is free; with a_b = 0 and a = a_l:

    F = V + a C,   C = sum_{light samples} (1 / n_l - p_l / q) - sum_{BSDF samples} p_l / q,

and E[C] = 1 - integral p_l = 0: optimal MIS is the balance heuristic plus one zero-mean
control variate, whose best coefficient is the regression one, a = -Cov(V, C) / Var(C), per
pixel and channel. (This a is the A^-1 b of the paper shifted along n; the tests check both
against a 1-D integrand whose optimum is known.) C is bounded (|C| <= N / n_l), so its moments
are well behaved even where V has heavy tails.

Which samples count. The integral runs over the samples both techniques can produce; a sample
that cannot contribute (a blocked shadow ray, a BSDF ray that meets no emitter or an emitter's
back, a zero BSDF value) is, for both techniques alike, a "failed" sample, and a failed sample
of technique t adds a_t / n_t - a_t p_t / (n_t p_t) = 0: it adds nothing, as in the classic
estimator. Only samples that carry light add to C; a delta light's sample adds 1 / n_l - 1 /
n_l = 0 and a delta lobe's 0 (each is the only technique that reaches its point).

Estimating a. Per pixel and channel from the passes so far, a = -S_VC / (S_CC + 4 / n_l^2)
(centred sums of products). The plain regression coefficient -S_VC / S_CC fails on direct
light: most samples add almost nothing to C (a light sample of a small light, where w_bal ~ 1,
adds (1 - w_bal) / n_l ~ 0), and the BSDF samples that hit the light, rare where the light is
small, add about -1 / n_l. Until one of those has been seen, S_CC is tiny, a is huge, and the
first rare sample then adds a * (-1 / n_l): a firefly. (Measured on veach_mis and cornell, the
plain coefficient from 8-64 camera samples made the error 230-1500 times the balance
heuristic's; from 960 samples still 3-9 times.) So S_CC is given 4 pseudo-samples of that
rare value, |C| = 1 / n_l, as if they had been seen (a prior that says: C may vary this much),
which shrinks a toward 0 until the data show more; and where C barely varies (S_CC / m <
1e-12: the techniques' pdfs are proportional, or no sample sees a light, where C is exactly 0;
the near-singular A of the paper) a = 0. A coefficient estimated from m samples costs a factor
of about 1 + 1 / (m - 3) in variance while saving (1 - rho^2) (for normal data; rho =
corr(V, C)), so a is also 0 unless the sample correlation says rho^2 > 1 / (m - 2), where the
gain exceeds that cost; elsewhere the pixel runs the balance heuristic.

One-sample MIS needs none of this: there the balance heuristic minimizes the variance among
all weights that sum to one, negative ones included (Veach 1997, theorem 9.4; a control
variate of the form above cannot lower it further, by Cauchy-Schwarz), so ``optimal`` with
``--one-sample`` is the balance heuristic.

**Adaptive allocation.** A pixel takes n̄_l = c N light and n̄_b = (1 - c) N BSDF samples on
average: a camera sample takes floor(n̄_l) light samples plus one more with probability
frac(n̄_l) (dimension ``TECHNIQUE_CHOICE``) and the rest BSDF samples, and every weight and
division uses the expected counts n̄_l, n̄_b, which keeps each camera sample unbiased
(E[count] / n̄ = 1; one-sample MIS is the case N = 1). c is chosen from the grid ``SHARES``,
whose ends keep every technique alive (c >= 0.05), so that light only one technique reaches (a
mirror's reflection of a lamp) is still found where the pilot saw none of it.

The choice minimizes variance x cost as estimated from earlier passes. For the balance
heuristic over N samples of the mixture c p_l + (1 - c) p_b the variance per camera sample is
about M(c) - F^2 / N with M(c) = integral f^2 / (N (c p_l + (1 - c) p_b)) (Sbert, Havran and
Szirmay-Kalos 2016, "Variance analysis of multi-sample and one-sample multiple importance
sampling"); every sample of share a estimates M(c) for every c at once, as
v^2 (a t + (1 - a)(1 - t)) / (c t + (1 - c)(1 - t)) with v its balance value and t = p_l /
(p_l + p_b), summed over a camera sample's samples. The cost per camera sample is counted in
rays and shadings: 2 for the camera ray and its hit, and per technique sample 1 plus the rays
it was seen to cast (a BSDF sample whose direction can reach no emitter casts none). The
estimates are pooled over the 7 x 7 pixels around each pixel (``NEIGHBOURS``): a pilot of 8
camera samples is too few to rank 11 splits alone.

**Samplers with replicates** (``stratified``, ``sobol``). Their samples are not independent
within a replicate: what was learned from a replicate's earlier points could correlate with
its later ones. So the replicates are split into two groups (even and odd) and each group's
samples use what was learned from the other group only (cross-fitting): different replicates
are independently randomized, so each pass stays exactly unbiased. That holds for optimal
MIS, whose coefficient changes how samples are weighted, not which are drawn. Adaptive
allocation changes which are drawn: once the odd group has been rendered with counts learned
from the even group's pilot, its sums carry information about the even group's own points,
and learning from them again would break the independence. So with replicates the allocation
(and the coefficient with it) is learned once, from the pilot pass, and kept.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .jit import jit

# Candidate shares of light samples c (of a camera sample's N technique samples).
SHARES = np.array([0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95])
NEIGHBOURS = 3  # the allocation pools its estimates over (2 x 3 + 1)^2 pixels
MIN_SAMPLES = 4  # camera samples behind a coefficient or a split before either is used
# Pseudo-samples of C's rare large value (a BSDF sample that hits a light, -1 / n_l) added to
# S_CC before the control variate's coefficient is estimated (module docstring).
PSEUDO_SAMPLES = 4.0
# Cost of a camera sample (its ray and the shading of its hit) and of a technique sample's
# shading, in rays; a technique sample adds the rays it casts.
CAMERA_COST, SHADING_COST = 2.0, 1.0

# Columns of the lane statistics the kernels write (``lane_columns``): the control variate C,
# then sum_s v^2 x ratio for every candidate share, then counts of samples taken and rays cast.
CONTROL = 0
FIRST_SHARE = 1
LIGHT_TAKEN = FIRST_SHARE + len(SHARES)
LIGHT_RAYS, DIRECTION_TAKEN, DIRECTION_RAYS = LIGHT_TAKEN + 1, LIGHT_TAKEN + 2, LIGHT_TAKEN + 3
LANE_COLUMNS = LIGHT_TAKEN + 4

# Columns of the per-pixel sums (``Learner.sums``): the lane statistics plus the camera sample
# count and the moments of V (the balance estimate, RGB) and C.
COUNT = LANE_COLUMNS
SUM_V = COUNT + 1  # 3 columns
SUM_VV = SUM_V + 3  # 3
SUM_VC = SUM_VV + 3  # 3
SUM_CC = SUM_VC + 3
SUM_COLUMNS = SUM_CC + 1


class Tuning(NamedTuple):
    """What one pass applies, as the kernels and the render loop read it.

    light_count : (P, G) expected light samples per camera sample n̄_l at each pixel, for each
        group of replicates (adaptive allocation; (0, 1) otherwise).
    alpha : (P, G, 3) the control variate's coefficient (optimal MIS; (0, 1, 3) otherwise).
    shares : (K,) ``SHARES``, the splits whose variance the kernels estimate.
    groups : G, 1 or 2 (module docstring); a sample of index s is in group (s % R) % G.
    replicates : R of the sampler (1 if it has none).
    collect : the pass's statistics are wanted (a later pass will learn from them).
    """

    light_count: np.ndarray
    alpha: np.ndarray
    shares: np.ndarray
    groups: int
    replicates: int
    collect: bool


def no_tuning() -> Tuning:
    """The tuning of an estimator that learns nothing."""
    return Tuning(np.zeros((0, 1)), np.zeros((0, 1, 3)), SHARES, 1, 1, True)


@jit
def group_of(sample: int, replicates: int, groups: int) -> int:
    """The group of the sample of index ``sample``: its replicate's parity with two groups
    (each group applies what the other's samples taught), 0 with one."""
    return (sample % replicates) % groups


class Learner:
    """Per-pixel sums over the passes merged so far, and the tuning they give the next pass.

    sums : (P, G, ``SUM_COLUMNS``) float64, G groups of replicates (module docstring).
    """

    def __init__(self, pixels: int, width: int, replicates: int, pilot_light: float, total: float,
                 optimal: bool, adaptive: bool):
        """``pilot_light``: the expected light samples of a camera sample before anything is
        learned (n_l, or c_l with one-sample MIS), ``total``: its technique samples N (1 with
        one-sample MIS), as the estimator's plan has them."""
        self.width = width
        self.height = pixels // max(width, 1)
        self.replicates = max(1, replicates)
        self.groups = 2 if replicates > 1 else 1
        self.total = float(total)
        self.pilot_light = float(pilot_light)
        self.optimal, self.adaptive = optimal, adaptive
        self.sums = np.zeros((pixels, self.groups, SUM_COLUMNS))
        self._scratch: tuple[np.ndarray, np.ndarray] | None = None  # for _box_sum
        # Adaptive allocation with replicates learns once, from the pilot (module docstring).
        self.learns_once = adaptive and self.groups == 2
        self._frozen: Tuning | None = None

    def add(self, first_pixel: int, block: np.ndarray) -> None:
        """Add a batch's per-pixel sums ``(npix, G, SUM_COLUMNS)`` (``reduce_lanes``)."""
        self.sums[first_pixel:first_pixel + len(block)] += block

    def tuning(self, collect: bool = True) -> Tuning:
        """What the next passes apply, from everything added so far; ``collect``: whether
        their statistics are wanted."""
        if self._frozen is not None:
            return self._frozen
        swap = self.groups == 2  # each group learns from the other
        light_count = np.zeros((0, 1))
        if not self.sums[:, :, COUNT].any():  # nothing learned yet: the pilot's settings
            return Tuning(light_count, np.zeros((0, 1, 3)), SHARES, self.groups, self.replicates, collect)
        if self.adaptive:
            if self._scratch is None:
                self._scratch = (np.empty_like(self.sums), np.empty_like(self.sums))
            pooled = _box_sum(self.sums, self.height, self.width, NEIGHBOURS, *self._scratch)
            light_count = best_light_count(pooled, SHARES, self.total, self.pilot_light, swap)
        alpha = np.zeros((0, 1, 3))
        if self.optimal:
            alpha = control_coefficient(self.sums, light_count, self.pilot_light, swap)
        if self.learns_once:
            self._frozen = Tuning(light_count, alpha, SHARES, self.groups, self.replicates, False)
            return self._frozen
        return Tuning(light_count, alpha, SHARES, self.groups, self.replicates, collect)

    @property
    def settled(self) -> bool:
        """Whether it has learned all it will (adaptive allocation with replicates)."""
        return self._frozen is not None

    def maps(self) -> dict[str, np.ndarray]:
        """What the render learned, per pixel, as EXR channels ``(P,)`` for a user to look at:
        ``allocation.light`` the share of light samples a next pass would take (adaptive),
        ``alpha.R/G/B`` the control variate's coefficient (optimal); averaged over the groups."""
        tuned = self.tuning()
        pixels = len(self.sums)
        out = {}
        if self.adaptive:
            out["allocation.light"] = tuned.light_count.mean(axis=1) / self.total if len(tuned.light_count) \
                else np.full(pixels, self.pilot_light / self.total)
        if self.optimal:
            for ch, name in enumerate("RGB"):
                out[f"alpha.{name}"] = tuned.alpha[:, :, ch].mean(axis=1) if len(tuned.alpha) \
                    else np.zeros(pixels)
        return out


def relearns(batch, first_sample: int, k: int) -> bool:
    """Whether an estimator that learns learns again before ``batch`` (a ``render_loop.Batch``):
    before the first batch of passes 1, 2, 4, 8, ... of a render whose passes of ``k`` samples
    begin at ``first_sample``."""
    index, offset = divmod(batch.first_sample - first_sample, k)
    return batch.first_pixel == 0 and offset == 0 and index > 0 and index & (index - 1) == 0


class PassHook:
    """The render loop's hook for an estimator that learns between passes (``render_loop``): the
    tuning of the first pass (``first``), whether to learn again before a batch (``relearns``:
    the loop then merges every batch in flight first) and what that gives (``before``), and the
    sums each merged batch adds (``add``).

    learner : the ``Learner`` (a render that continues another passes that one's).
    first_sample, k, spp : the render's first sample index, samples per pass, samples per pixel.
    continues : a later render continues this one, so statistics are collected to the end.
    """

    def __init__(self, learner: Learner, first_sample: int, k: int, spp: int, continues: bool):
        self.learner, self.first_sample, self.k = learner, first_sample, k
        self.passes = -(-spp // k)
        self.continues = continues

    @classmethod
    def of(cls, plan, width: int, height: int, replicates: int, **options) -> "PassHook":
        """A hook with a fresh ``Learner`` for the estimator plan ``plan`` (``estimator.Plan``)."""
        learner = Learner(width * height, width, replicates,
                          plan.c_light if plan.one_sample else plan.n_light, plan.total, plan.optimal,
                          plan.adaptive)
        return cls(learner, **options)

    def first(self) -> Tuning:
        return self._tuning(0)

    def relearns(self, batch) -> bool:
        return not self.learner.settled and relearns(batch, self.first_sample, self.k)

    def before(self, batch) -> Tuning:
        return self._tuning((batch.first_sample - self.first_sample) // self.k)

    def add(self, batch, sums: np.ndarray) -> None:
        self.learner.add(batch.first_pixel, sums)

    def _tuning(self, index: int) -> Tuning:
        # Statistics are collected only while a later pass (or a render that continues this one)
        # will learn from them.
        return self.learner.tuning(collect=self.continues or max(1, 2 * index) < self.passes)


@jit
def control_coefficient(sums, light_count, light_samples: float, swap: bool):
    """(P, G, 3) a = -S_VC / (S_CC + ``PSEUDO_SAMPLES`` / n_l^2) from per-pixel sums ``(P, G,
    SUM_COLUMNS)`` (with ``swap``, group g's a from group 1 - g's sums), n_l the light samples
    the pixel's group takes, ``light_count (P, G)`` (adaptive allocation), else
    ``light_samples``; 0 where there are fewer than ``MIN_SAMPLES`` samples, C barely varies,
    or the sample correlation is too weak to pay for estimating a (module docstring)."""
    pixels, groups, _ = sums.shape
    alpha = np.zeros((pixels, groups, 3))
    for pixel in range(pixels):
        for g in range(groups):
            n_l = light_count[pixel, g] if len(light_count) else light_samples
            prior = PSEUDO_SAMPLES / (n_l * n_l)
            row = sums[pixel, groups - 1 - g] if swap else sums[pixel, g]
            m = row[COUNT]
            if m < MIN_SAMPLES:
                continue
            mean_c = row[CONTROL] / m
            s_cc = row[SUM_CC] - m * mean_c * mean_c
            if not s_cc > 1e-12 * m:
                continue
            for ch in range(3):
                mean_v = row[SUM_V + ch] / m
                s_vc = row[SUM_VC + ch] - m * mean_v * mean_c
                s_vv = row[SUM_VV + ch] - m * mean_v * mean_v
                # Used only where rho^2 > 1 / (m - 2): s_vc^2 (m - 2) > s_vv s_cc.
                if s_vc * s_vc * (m - 2.0) > s_vv * s_cc:
                    alpha[pixel, g, ch] = -s_vc / (s_cc + prior)
    return alpha


@jit
def best_light_count(sums, shares, total: float, pilot_light: float, swap: bool):
    """(P, G) expected light samples n̄_l = c N per camera sample, c the share of ``shares``
    with the least estimated variance x cost (module docstring), from per-pixel sums ``(P, G,
    SUM_COLUMNS)`` (with ``swap``, group g's from group 1 - g's); the pilot's count where they
    hold fewer than ``MIN_SAMPLES`` camera samples or no light."""
    pixels, groups, _ = sums.shape
    out = np.full((pixels, groups), pilot_light)
    for pixel in range(pixels):
        for g in range(groups):
            row = sums[pixel, groups - 1 - g] if swap else sums[pixel, g]
            m = row[COUNT]
            if m < MIN_SAMPLES:
                continue
            squared_mean = 0.0
            for ch in range(3):
                squared_mean += (row[SUM_V + ch] / m) ** 2 / 3.0
            light_rays = row[LIGHT_RAYS] / row[LIGHT_TAKEN] if row[LIGHT_TAKEN] > 0.0 else 1.0
            direction_rays = row[DIRECTION_RAYS] / row[DIRECTION_TAKEN] if row[DIRECTION_TAKEN] > 0.0 else 1.0
            best, best_share = math.inf, -1.0
            for k in range(len(shares)):
                c = shares[k]
                second = row[FIRST_SHARE + k] / m  # M(c) per camera sample
                if not second > 0.0:
                    continue
                variance = max(second - squared_mean / total, 1e-3 * second)
                cost = CAMERA_COST + total * (c * (SHADING_COST + light_rays)
                                              + (1.0 - c) * (SHADING_COST + direction_rays))
                if variance * cost < best:
                    best, best_share = variance * cost, c
            if best_share > 0.0:
                out[pixel, g] = best_share * total
    return out


@jit
def _box_sum(sums, height: int, width: int, radius: int, rows, out):
    """Each pixel's sums ``(P, G, W)`` added over the (2 radius + 1)^2 pixels around it
    (clipped at the image's edges), into ``out`` (same shape; ``rows`` is scratch space of that
    shape: arrays kept between calls, since fresh pages cost more than the sums here): running
    sums along rows, then down columns, in memory order (one add and one subtract per pixel and
    pass, whatever the radius). Returns ``out``."""
    for y in range(height):
        _running_sum(sums[y * width:(y + 1) * width], rows[y * width:(y + 1) * width], width, radius)
    image, boxed = rows.reshape(height, width * sums.shape[1], sums.shape[2]), \
        out.reshape(height, width * sums.shape[1], sums.shape[2])
    _running_sum(image, boxed, height, radius)
    return out


@jit
def _running_sum(source, target, length: int, radius: int) -> None:
    """target[i] = the sum of source[j] for |j - i| <= radius, 0 <= j < length, along the first
    axis of ``source`` (the rest of its axes are added element by element)."""
    running = np.zeros(source.shape[1:])
    for i in range(-radius, length):
        enter, leave = i + radius, i - radius - 1
        if enter < length:
            running += source[enter]
        if leave >= 0:
            running -= source[leave]
        if i >= 0:
            target[i] = running


@jit
def mean_square(raw, w: float) -> float:
    """The mean over channels of (w x raw)^2: a sample's squared balance value, when ``raw``
    is its unweighted value and w its balance weight."""
    return ((raw[0] * w) ** 2 + (raw[1] * w) ** 2 + (raw[2] * w) ** 2) / 3.0


@jit
def learn(lane_stats, lane: int, shares, collect: bool, control: float, v2: float, share_t: float,
          share: float) -> None:
    """Add to a lane's statistics one sample that carries light: its term of the control
    variate C, and if ``collect``, for every candidate share c its estimate of the second
    moment M(c), v^2 (a t + (1 - a)(1 - t)) / (c t + (1 - c)(1 - t)) with a = ``share``, the
    share of light samples it was taken under (module docstring). The estimator's kernels call
    it only in builds that learn (``tracer.estimator.kernels``)."""
    lane_stats[lane, CONTROL] += control
    if not collect:
        return
    used = share * share_t + (1.0 - share) * (1.0 - share_t)
    for k in range(len(shares)):
        c = shares[k]
        lane_stats[lane, FIRST_SHARE + k] += v2 * used / (c * share_t + (1.0 - c) * (1.0 - share_t))


def warm_up() -> None:
    """Compile (or load from numba's cache) the learning's kernels on empty data, so that a
    render's clock does not count it (``render_loop._compile``)."""
    empty = np.zeros((1, 1, SUM_COLUMNS))
    control_coefficient(empty, np.zeros((0, 1)), 1.0, False)
    pooled = _box_sum(empty, 1, 1, NEIGHBOURS, np.empty_like(empty), np.empty_like(empty))
    best_light_count(pooled, SHARES, 2.0, 1.0, False)
    apply_control(np.zeros((0, 3)), np.zeros((0, LANE_COLUMNS)), np.zeros((0, 1, 3)), 0, 1, 0, 1, 1)


@jit
def reduce_lanes(radiance, lane_stats, npix: int, k: int, first_sample: int, replicates: int,
                 groups: int):
    """(npix, G, SUM_COLUMNS) per-pixel sums of a batch's lanes (pixel-major, k samples each):
    ``radiance (n, 3)`` holds the balance estimates V, ``lane_stats (n, LANE_COLUMNS)`` the
    rest. Lanes whose V or statistics are not finite are left out (the film counts the former;
    the latter would turn the neighbourhood sums of the allocation into NaN)."""
    out = np.zeros((npix, groups, SUM_COLUMNS))
    for row in range(npix):
        for j in range(k):
            lane = row * k + j
            c = lane_stats[lane, CONTROL]
            v = radiance[lane]
            if not (np.isfinite(c) and np.isfinite(v[0]) and np.isfinite(v[1]) and np.isfinite(v[2])):
                continue
            finite = True
            for col in range(LANE_COLUMNS):
                finite = finite and np.isfinite(lane_stats[lane, col])
            if not finite:
                continue
            g = group_of(first_sample + j, replicates, groups)
            for col in range(LANE_COLUMNS):
                out[row, g, col] += lane_stats[lane, col]
            out[row, g, COUNT] += 1.0
            for ch in range(3):
                out[row, g, SUM_V + ch] += v[ch]
                out[row, g, SUM_VV + ch] += v[ch] * v[ch]
                out[row, g, SUM_VC + ch] += v[ch] * c
            out[row, g, SUM_CC] += c * c
    return out


@jit
def apply_control(radiance, lane_stats, alpha, first_pixel: int, k: int, first_sample: int,
                  replicates: int, groups: int) -> None:
    """Add a C to each lane's balance estimate (pixel-major lanes, k samples per pixel), with
    a the coefficient of the lane's pixel and group: V -> V + a C."""
    for lane in range(len(radiance)):
        pixel = first_pixel + lane // k
        g = group_of(first_sample + lane % k, replicates, groups)
        c = lane_stats[lane, CONTROL]
        for ch in range(3):
            radiance[lane, ch] += alpha[pixel, g, ch] * c
