"""``auto``: the strategy a pilot measures most efficient on the scene at hand.

A user who asks for ``--strategy auto`` gets one of the fixed strategies tracer has, chosen for
the scene by estimated efficiency 1 / (relMSE per sample x cost per sample), as Grittmann et al.
(2022, "Efficiency-aware multiple importance sampling for bidirectional rendering algorithms")
choose among technique combinations by variance and cost measured together.

**Candidates** (:func:`candidates`). From the strategy the user gave as a template (its counts
N, M, heuristic and environment sampling): ``mis`` (N light + M BSDF samples) and ``light`` (N)
for every light sampling whose techniques differ on this scene (``area``, ``solid-angle``,
``solid-angle-cos``: on a scene of triangles only, the last two are the same technique) and
every light selection worth trying (``power``; ``bvh`` too from ``BVH_MIN_LIGHTS`` (2) lights,
counted where they are fewest: a quad is one light to solid-angle sampling, and where its tree
has more than one leaf: one leaf runs as ``power``, ``lights.build_tables``), and
``bsdf`` (M). Only strategies that see all of the scene's light are candidates, so that
whatever the pilot chooses estimates the same image: without light samples a point, spot or
directional light is never reached, and without direction samples a delta lobe (a mirror, glass,
a smooth coating) never reflects an emitter (``light`` is dropped where a material has one).

**Pilot** (:func:`choose`). Each candidate renders ``PILOT_SPP`` samples of up to
``PILOT_PIXELS`` pixels (a regular lattice over the image) with a seed of its own, derived from
the render's, so that no random number of the render decides the choice: the render that
follows is a fixed strategy whose samples are independent of the choice, and so unbiased
whatever was chosen. The pilot's samples are not kept. Its relMSE per sample is the mean over
those pixels and the channels of s^2 / (m^2 + 0.01), with s^2 the candidate's sample variance
and m the pixel's mean over all candidates (each is unbiased; their mean is the steadiest value
to normalize by), the measure ``tracer compare`` reports (``study.metrics.relmse``); or, where
the candidate disagrees with the others by more than its own spread explains (it never sampled
what carries the light), the relMSE that disagreement implies (:func:`relmse_estimates`); and
for ``light`` and ``bsdf``, at least the relMSE that the second moments measured by a ``mis``
pilot imply for them (:func:`single_technique_bounds`: a pilot of one technique misses its rare
large samples, which MIS's samples of the other technique find). ``mis`` candidates run their
pilot through the learning build of adaptive allocation (:func:`pilot_strategy`), which writes
those moments; the render runs the plain build.

**Cost**, deterministic (a seed gives the same choice on any machine and under any load), in
units of one shadow ray (``COSTS``): a camera sample's ray and the shading of its hit, one
shading per light or direction sample, the shadow and direction rays the pilot actually cast
(a light sample below the horizon casts none, nor does a direction that can reach no emitter),
and what a light technique or the light BVH adds per sample. The weights were measured on this
project's machine (``benchmarks/auto_costs.py``: seconds per lane of each candidate on seven
scenes, fitted by least squares with one time per ray for each scene; it reports how well the
model fits). What the model cannot know is how much dearer a ray is in one scene's geometry
than another's: that scales every candidate of a scene alike, except that shadow rays (any hit
ends them) and direction rays (the closest hit) differ by a factor that varies by scene.

The choice is made once per render, for the whole image: MIS already adapts per pixel between
its techniques, and a choice per tile would need the film to fold tiles of different
strategies (left for later; the render record would have to say which tile took which).
Compilation stays off the clock as for every strategy (``render_loop._compile``); the pilot is
on it: a render's seconds include its pilot.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from . import samplers, tuning
from .scene import Scene
from .strategy import Strategy, light_samplings

PILOT_PIXELS = 4096  # pixels of the pilot lattice (all of them in a smaller image)
PILOT_SPP = 8  # samples per pilot pixel and candidate
# The relMSE's epsilon, as ``study.metrics.RELMSE_EPSILON`` (which the core may not import;
# tests/test_auto.py checks they agree): the relative error of dark pixels.
RELMSE_EPSILON = 0.01
# From this many light candidates the light BVH is tried as well as power selection: from two,
# because its choice depends on distance and orientation, which power selection ignores (two
# point lights at different distances are enough for it to win).
BVH_MIN_LIGHTS = 2
# A pilot's seed: the render's, mixed with this (splitmix-style) so that the pilot's random
# numbers are none of the render's.
PILOT_SALT = 0x9E3779B97F4A7C15

# Weight of each kind of work in the cost of a camera sample, in units of one shadow ray, fitted
# by benchmarks/auto_costs.py to the seconds per lane of every candidate on 7 scenes (69 pairs;
# the model's median error 6.5%, largest 43%: results/auto_costs.json).
COSTS = {
    "camera": 1.76,           # a camera sample: its ray (a closest hit) and the shading of its hit
    "shading": 0.84,          # evaluating a light or direction sample (BSDF, pdfs, MIS weight)
    "shadow_ray": 1.0,        # an occlusion ray (the unit: 67-144 ns on the 7 scenes)
    "direction_ray": 3.62,    # a direction sample's closest-hit ray, the emitter it meets, its MIS pdf
    "solid-angle": 0.75,      # a solid-angle light sample (spherical rectangle / triangle, cone)
    "solid-angle-cos": 0.95,  # its cosine-warped variant
    # A level of a light BVH descent (per light sample, and per MIS direction ray): the fit gave
    # 4.77 a descent on many_lights, the only fitted scene with BVH candidates, whose tree of 2,248
    # lights was then counted as 12 levels (bvh_levels gives 12.4 for its tree today); a
    # descent's work grows with its depth (two child importances a level), so a tree of a few
    # lights costs a fraction of that.
    "bvh_level": 4.77 / 12,
}


def bvh_levels(trail_depth: np.ndarray) -> float:
    """The work of a light BVH descent, in levels: the mean depth of its candidates' leaves
    (``trail_depth (K,)``; where a descent ends depends on the point, so no candidate is
    weighted above another), plus one for the pick within the leaf and the entry to the tree
    (``benchmarks/light_pick.py`` measured about as much for a tree of one leaf as for a level)."""
    return 1.0 + (float(np.mean(trail_depth)) if len(trail_depth) else 0.0)


@dataclass(frozen=True)
class Measured:
    """One candidate's pilot: relMSE of one sample per pixel, cost of one camera sample
    (``COSTS``'s units) and efficiency 1 / (relmse x cost) (inf where the pilot saw no error)."""

    strategy: Strategy
    relmse: float
    cost: float

    @property
    def efficiency(self) -> float:
        return math.inf if self.relmse <= 0.0 else 1.0 / (self.relmse * self.cost)


@dataclass(frozen=True)
class Choice:
    """What the pilot chose and what it measured (best first), and its wall seconds."""

    strategy: Strategy
    measured: tuple[Measured, ...]
    seconds: float

    def summary(self) -> str:
        """One line for the render record and the command line: each candidate's slug and its
        efficiency relative to the chosen one's, ``mis_solid-angle 1; mis 0.81; light 0.4``."""
        best = self.measured[0].efficiency
        parts = []
        for m in self.measured:
            ratio = 1.0 if math.isinf(best) and math.isinf(m.efficiency) else m.efficiency / best
            parts.append(f"{m.strategy.slug} {ratio:.3g}")
        return "; ".join(parts)


def template(strategy: Strategy) -> dict[str, object]:
    """What of an ``auto`` strategy its candidates keep: counts, heuristic, environment sampling."""
    return {"heuristic": strategy.heuristic, "environment_sampling": strategy.environment_sampling}


def _has_delta_lights(scene: Scene) -> bool:
    from .lights import emitters

    return len(emitters.points(scene)) + len(emitters.directionals(scene)) > 0


def _has_delta_lobes(scene: Scene) -> bool:
    from . import plugins
    from .materials.base import DELTA

    types = plugins.by_code("material")
    return any(types[int(k)].lobes & DELTA for k in set(scene.materials.kind.tolist()) if int(k) in types)


def sees_all_light(scene: Scene, strategy: Strategy) -> bool:
    """Whether ``strategy`` reaches all of ``scene``'s light: light samples where there are point,
    spot or directional lights, direction samples where a material has a delta lobe."""
    if not strategy.light_count and _has_delta_lights(scene):
        return False
    return bool(strategy.direction_count) or not _has_delta_lobes(scene)


def candidates(scene: Scene, auto: Strategy) -> list[Strategy]:
    """The fixed strategies ``auto`` chooses among on ``scene`` (module docstring), each seeing
    all of the scene's light. Raises ``ValueError`` if none does (a scene of point lights seen
    only in a mirror needs a light path of two bounces, which no direct-lighting strategy has)."""
    from .lights import LightSampler, technique_names

    kept = template(auto)
    n_light, n_dir = max(1, auto.light_samples), max(1, auto.bsdf_samples)
    # Each candidate as its render record gives it back (``Strategy.from_record``): what a
    # strategy does not use left at its default, so that a continued render is the same one.
    out = [Strategy("bsdf", light_samples=0, bsdf_samples=n_dir)]
    tables = {sampling: LightSampler(scene, "power", sampling, auto.environment_sampling).tables
              for sampling in light_samplings()}
    # The BVH is worth a pilot where there are lights to choose between: counted where they are
    # fewest (a quad light is two triangles to area sampling but one rectangle to solid-angle).
    emitters = min(len(t.technique) for t in tables.values())
    seen: set[tuple[str, ...]] = set()
    for sampling, light_tables in tables.items():
        techniques = technique_names(light_tables)
        if techniques in seen:
            continue
        seen.add(techniques)
        # Not where the BVH would run as power (a tree of one leaf: ``lights.build_tables``),
        # which would be the power candidate's pilot twice.
        tree = emitters >= BVH_MIN_LIGHTS and \
            LightSampler(scene, "bvh", sampling, auto.environment_sampling).selection == "bvh"
        for selection in ["power"] + (["bvh"] if tree else []):
            chosen = dict(light_sampling=sampling, light_selection=selection, **kept)
            out.append(Strategy("mis", light_samples=n_light, bsdf_samples=n_dir, **chosen))
            out.append(Strategy("light", light_samples=n_light, bsdf_samples=0, light_sampling=sampling,
                                light_selection=selection, environment_sampling=auto.environment_sampling))
    out = [s for s in out if sees_all_light(scene, s)]
    if not out:
        raise ValueError("auto has no strategy that sees all of this scene's light")
    return out


def pilot_pixels(width: int, height: int, count: int = PILOT_PIXELS) -> np.ndarray:
    """The pilot's pixels ``(n,)`` int64: all of them, or a regular lattice of about ``count``
    (every ``stride``-th pixel of every ``stride``-th row, centred in its cell)."""
    if width * height <= count:
        return np.arange(width * height, dtype=np.int64)
    stride = math.ceil(math.sqrt(width * height / count))
    xs = np.arange(stride // 2, width, stride, dtype=np.int64)
    ys = np.arange(stride // 2, height, stride, dtype=np.int64)
    return (ys[:, None] * width + xs[None, :]).ravel()


def pilot_seed(seed: int, candidate: int = 0) -> int:
    """The seed of candidate ``candidate``'s pilot in a render of ``seed``: a 64-bit mix
    (SplitMix64's finalizer) of the two, so that the pilots' random numbers are none of the
    render's and the candidates' pilots are independent of each other (:func:`relmse_estimates`
    compares them)."""
    z = (int(seed) + PILOT_SALT * (int(candidate) + 1)) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return z ^ (z >> 31)


def relmse_estimates(means: np.ndarray, variances: np.ndarray, spp: int) -> np.ndarray:
    """Each candidate's relMSE per sample ``(K,)`` from its pilot's per-pixel ``means`` and
    unbiased ``variances`` ``(K, n, 3)`` of ``spp`` independent samples each.

    A candidate's own sample variance misses what its pilot never sampled: BSDF sampling of a
    tiny light sees no light in 8 samples of every pixel, and its variance is 0. So each
    candidate is also checked against the others: all are unbiased for the same pixels, so
    spp x the mean over pixels of (its mean - the others' mean)^2 / (m^2 + 0.01), less what the
    others' own noise adds to it, also estimates its relMSE per sample, without relying on its
    having seen its rare samples (a candidate that missed the light is off by the whole light).
    Each candidate gets the larger of the two estimates. (The candidates' pilots draw
    independent random numbers, ``pilot_seed``, so their errors are independent.)
    """
    means, variances = np.asarray(means), np.asarray(variances)
    count = len(means)
    pooled = means.mean(axis=0)
    scale = 1.0 / (pooled * pooled + RELMSE_EPSILON)
    spread = (variances * scale).mean(axis=(1, 2))
    if count < 2:
        return spread
    total = means.sum(axis=0)
    out = np.empty(count)
    for c in range(count):
        others = (total - means[c]) / (count - 1)
        deviation = spp * float(((means[c] - others) ** 2 * scale).mean())
        # Var(others' mean) x spp = sum of their relMSEs / (count - 1)^2.
        noise = (spread.sum() - spread[c]) / (count - 1) ** 2
        out[c] = max(spread[c], deviation - noise)
    return out


def cost_per_sample(strategy: Strategy, lanes: int, shadow_rays: int, direction_rays: int,
                    levels: float = 1.0) -> float:
    """Cost of one camera sample of ``strategy`` (``COSTS``'s units) from a pilot of ``lanes``
    camera samples that cast ``shadow_rays`` and ``direction_rays``; ``levels``: the work of
    its light BVH's descent (:func:`bvh_levels`), if it selects by one."""
    lanes = max(lanes, 1)
    cost = (COSTS["camera"] + COSTS["shading"] * (strategy.light_count + strategy.direction_count)
            + COSTS["shadow_ray"] * shadow_rays / lanes + COSTS["direction_ray"] * direction_rays / lanes)
    if strategy.light_count:
        cost += strategy.light_count * COSTS.get(strategy.light_sampling, 0.0)
        if strategy.light_selection == "bvh":
            # A light sample descends the tree; an MIS direction ray asks it for the pmf of the
            # light it meets (counted per direction ray: a bound).
            cost += COSTS["bvh_level"] * levels * (strategy.light_count + direction_rays / lanes)
    return cost


class Pilot(NamedTuple):
    """One candidate's pilot over the pilot pixels: per-pixel ``mean`` and unbiased ``variance``
    ``(n, 3)``, the ``cost`` of a camera sample (:func:`cost_per_sample`), and for a ``mis``
    candidate the per-pixel ``moments (n, 3)``: the mean over its camera samples of tuning's
    second moments M(c) (channel mean) at c = 1 (light samples only), at its own split and at
    c = 0 (BSDF samples only); None for the others."""

    mean: np.ndarray
    variance: np.ndarray
    cost: float
    moments: np.ndarray | None


def pilot_strategy(strategy: Strategy) -> Strategy:
    """The strategy whose pilot measures ``strategy``: for ``mis``, its learning build (adaptive
    allocation), which in its first pass, all a pilot renders, is the same estimator with the
    same fixed counts and also writes the second moments of the other splits (``tracer.tuning``);
    any other strategy itself."""
    if strategy.name == "mis" and strategy.light_count and strategy.direction_count and not strategy.adaptive:
        return replace(strategy, allocation="adaptive")
    return strategy


def moment_shares(strategy: Strategy) -> np.ndarray:
    """The shares c at which a pilot of ``strategy`` estimates M(c) (``tracer.tuning``'s
    ``Tuning.shares``, whose length the kernels fix): 1, its own split, 0, then its own again."""
    own = strategy.light_count / (strategy.light_count + strategy.direction_count)
    shares = np.full(len(tuning.SHARES), own)
    shares[0], shares[2] = 1.0, 0.0
    return shares


def measure(scene: Scene, strategy: Strategy, pixel_set: np.ndarray, seed: int, estimator=None,
            spp: int = PILOT_SPP) -> Pilot:
    """Render ``spp`` samples of each pixel of ``pixel_set`` with ``strategy`` (independent
    sampler, ``seed``) through the estimator of its pilot (``estimator``, else one of
    :func:`pilot_strategy`)."""
    from .estimator import DirectLighting

    estimator = estimator if estimator is not None else DirectLighting(scene, pilot_strategy(strategy))
    sampler = samplers.make("independent", seed, 0, spp)
    pixel = np.repeat(pixel_set, spp)
    sample = np.tile(np.arange(spp, dtype=np.int64), len(pixel_set))
    learns = estimator.plan.adaptive
    tuned = tuning.Tuning(np.zeros((0, 1)), np.zeros((0, 1, 3)), moment_shares(strategy), 1, 1, True) \
        if learns else None
    rays: list[tuple[int, int]] = []
    origins, dirs = estimator.camera_rays(sampler, pixel, sample)
    radiance, lane_stats = estimator.shade_lanes(origins, dirs, sampler, pixel, sample, tuned=tuned,
                                                 rays=rays)
    radiance = np.where(np.isfinite(radiance), radiance, 0.0).reshape(len(pixel_set), spp, 3)
    moments = None
    if learns:
        first = tuning.FIRST_SHARE
        # A lane's NaN (0 / 0: a sample of no value where one technique cannot go) counts as 0,
        # which can only lower the bound; inf (light one technique cannot produce) stays.
        moments = np.nan_to_num(lane_stats[:, first:first + 3], nan=0.0, posinf=np.inf)
        moments = moments.reshape(len(pixel_set), spp, 3).mean(axis=1)
    shadow = sum(r[0] for r in rays)
    direction = sum(r[1] for r in rays)
    selection = estimator.lights.tables.selection
    # A bvh selection that runs as power (one leaf, tracer.lights.build_tables) descends nothing.
    levels = bvh_levels(selection.trail_depth) if estimator.lights.selection == "bvh" else 0.0
    cost = cost_per_sample(strategy, len(pixel), shadow, direction, levels)
    return Pilot(radiance.mean(axis=1), radiance.var(axis=1, ddof=1), cost, moments)


def single_technique_bounds(strategies: list[Strategy], pilots: list[Pilot]) -> np.ndarray:
    """(K,) lower bounds on the relMSE per sample of each ``light`` and ``bsdf`` candidate,
    from the second moments the pilot of a ``mis`` candidate measured (0 where none applies).

    A pilot of light samples alone misses what makes them bad: the rare light sample of a
    glossy lobe (the light's pdf far below the BSDF's) is worth f / p_l, huge, and 8 samples
    of a pixel seldom draw one, so its sample variance is far too small (on a city of small
    lights over a wet street, by 5 times; BSDF sampling's, of small bright windows, by 20).
    MIS samples both techniques: each of its samples estimates the second moment
    S(c) = N M(c) = integral f^2 / (c p_l + (1 - c) p_b) of every split c at once
    (``tracer.tuning``; f and the pdfs are those of one camera sample's shading point), the
    light-only one (c = 1) included, and those values are not rare. Light alone with n samples
    has variance (S(1) - F^2) / n given the camera sample (F the shading's expected value there),
    and two bounds follow, per pixel, whichever is larger:

    - F^2 <= S(c) for every c, so Var(light) >= (S(1) - min_c S(c)) / n, the variance of F
      over the pixel's footprint left out (it only adds);
    - with one light sample, light's camera sample Y = Le + f / p_l (Le the emission seen
      directly, >= 0, as F is) has E[Y^2] >= E[S(1)], so Var(Y) >= E[S(1)] - m^2 with m the
      pixel's mean (the pooled pilots'); with n samples the variance is at least 1 / n of
      that. This one keeps the F^2 the first drops where F is most of S(1).

    The same with S(0) for ``bsdf``. Per pixel the bound is divided by the largest channel's
    pooled mean squared plus the epsilon: S is a mean over channels (so m^2 above is too), and
    mean_c Var_c / (m_c^2 + eps) >= mean_c Var_c / (max_c m_c^2 + eps). Up to the pilot's noise
    (means over 4,096 pixels of means over 8 samples of values that are not heavy-tailed) the
    result is below the technique's relMSE; the heuristic the mis pilot renders with plays no
    part."""
    out = np.zeros(len(strategies))
    pooled = np.mean([p.mean for p in pilots], axis=0)
    pooled_squared = pooled * pooled
    squared = pooled_squared.mean(axis=1)
    scale = 1.0 / (pooled_squared.max(axis=1) + RELMSE_EPSILON)
    for k, strategy in enumerate(strategies):
        if strategy.light_count and strategy.direction_count:
            continue
        source = next((j for j, s in enumerate(strategies) if pilots[j].moments is not None and (
            not strategy.light_count or (s.light_sampling, s.light_selection)
            == (strategy.light_sampling, strategy.light_selection))), None)
        if source is None:
            continue
        mis = strategies[source]
        moments = pilots[source].moments * (mis.light_count + mis.direction_count)  # S(1), S(a), S(0)
        own, count = (moments[:, 0], strategy.light_count) if strategy.light_count \
            else (moments[:, 2], strategy.direction_count)
        # own is inf where the technique cannot produce light the other found: so is the bound.
        excess = np.maximum(own - moments.min(axis=1), own - squared)
        out[k] = float(np.mean(excess * scale)) / count
    return out


def choose(scene: Scene, auto: Strategy, seed: int, estimators: dict | None = None,
           say=None, threads: int = 1) -> Choice:
    """Run the pilot of every candidate (module docstring), ``threads`` at once, and return the
    most efficient. ``estimators`` (each of :func:`candidates` -> the ``DirectLighting`` of its
    :func:`pilot_strategy`, built and compiled by the caller), if given, are the candidates;
    ``say(text)`` reports what was chosen."""
    from concurrent.futures import ThreadPoolExecutor

    start = time.perf_counter()
    strategies = list(estimators) if estimators else candidates(scene, auto)
    pixel_set = pilot_pixels(scene.camera.width, scene.camera.height)
    spp = PILOT_SPP
    with ThreadPoolExecutor(max_workers=max(1, threads)) as pool:
        # Each candidate's pilot is one batch; Embree and the kernels release the GIL.
        pilots = list(pool.map(lambda i: measure(scene, strategies[i], pixel_set, pilot_seed(seed, i),
                                                 (estimators or {}).get(strategies[i]), spp),
                               range(len(strategies))))
    relmse = relmse_estimates(np.array([p.mean for p in pilots]), np.array([p.variance for p in pilots]), spp)
    relmse = np.maximum(relmse, single_technique_bounds(strategies, pilots))
    measured = [Measured(s, float(r), p.cost) for s, r, p in zip(strategies, relmse, pilots)]
    # Ties (a scene every candidate renders without noise) go to the candidate listed first.
    order = sorted(range(len(measured)), key=lambda i: (-measured[i].efficiency, i))
    ranked = tuple(measured[i] for i in order)
    choice = Choice(ranked[0].strategy, ranked, time.perf_counter() - start)
    if say is not None:
        say(f"auto: {choice.strategy.label} (pilot of {len(strategies)} strategies x {len(pixel_set)} pixels "
            f"x {spp} spp, {choice.seconds:.2f} s; efficiency relative to it: {choice.summary()})")
    return choice

