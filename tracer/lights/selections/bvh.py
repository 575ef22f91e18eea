"""The ``bvh`` light selection: down a light BVH, each child in proportion to an upper bound of
what its lights can deliver to the shading point (``tracer.lights.bvh``: Conty Estevez and
Kulla 2018, pbrt-v4's ``BVHLightSampler``), so its pmf depends on the point and its shading
normal. A plug-in (``tracer.lights.selections``); it pays with many lights.

**Lights at infinity.** Directional lights and the environment (``Emitters.AT_INFINITY``, the
last candidates) have no position, and a leaf bounding one by the scene's box, emitting every
way, tells the descent little. So, as pbrt-v4's ``BVHLightSampler`` does (``Sample`` and
``PMF`` in src/pbrt/lightsamplers.h; *Physically Based Rendering*, 4th ed., sec. 12.6.3: the
lights whose ``Bounds()`` is unset, its infinite lights and ``DistantLight``), they stay out of
the tree, which holds the other candidates, and a selection first decides between the tree
and each light at infinity: light j with probability p_j = w_j / W, the tree with
p_tree = w_tree / W (W the sum of the weights), in which case u is rescaled to [0, 1)
(``tracer.samplers.reuse``) and the descent goes on as before; a candidate of the tree has
pmf p_tree x its path's product. Candidate indices are unchanged (the tree's leaves are the
candidates before the lights at infinity). The weights are in the tree's units, pi x the
irradiance a light gives the point (a small light's importance, power cos theta' cos theta_i'
/ d^2, is that):

- the tree: its root's importance at (x, n) (0 where no light of the tree can reach x);
- a directional light: pi E max(cos theta_i, 0), exactly its irradiance (pi E without a
  receiver normal); 0 below the horizon, where it cannot contribute;
- the environment: pi times its irradiance averaged over receiver normals, pi/4 x the integral
  of its radiance over the sphere (for any map: the mean over normals of max(cos, 0) is 1/4),
  i.e. its flux / (4 r^2), the flux being measured over the scene's bounding sphere of radius r
  (``tracer.lights.environment.flux``). Positive everywhere, as the map may light any point.

So the pmf is a pure function of (k, x, n), sums to 1 over the candidates wherever some light
can reach x, and :func:`pmf` computes each factor by the same expressions :func:`choose` does.

**Why these weights.** pbrt-v4 gives each light at infinity and the tree equal shares
(p_inf = 1/2 for one with a tree); the ``power`` selection's shares are by flux. mis with
``bvh``, relMSE at 16 spp against a 4,096-spp reference (mis, ``power``), 128 x 96, mean of
seeds 1-3 (the seeds' spread was under 10%):

===========================================  ========  =========  ====================
rule                                         environ-  many_env   delta_lights
                                             ment                 (directional)
===========================================  ========  =========  ====================
before: a leaf of the tree (scene box)       0.0223    0.0760     0.0328
pbrt-v4: equal shares                        0.0249    0.0652     0.0281
by flux (as ``power`` selects)               0.0329    0.1192     0.0363
pi x irradiance against the root (this)      0.0187    0.0649     0.0288
``power`` selection, for comparison          0.0332    0.2034     0.0446
===========================================  ========  =========  ====================

(environment: ``scenes/mitsuba/environment.xml``, a sky with a sun and one small area light;
many_env: 36 small area lights of random size, tilt and power over a floor, two spheres and a
wall under the same sky, generated with seed 7; delta_lights: two spots, a point and a
directional light, no environment.) The irradiance rule is best or level everywhere; equal
shares lose a third on the environment scene, where the sky outshines the lamp at most points,
and flux shares overrate a light at infinity badly (its flux counts what the whole scene's
disk catches). Scaling the environment's weight by 1/2 or 2 measured 0.0204 and 0.0195
(environment), 0.0767 and 0.0642 (many_env): the unscaled mean irradiance sits at the optimum.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...jit import jit
from ...plugins import LightSelection, register
from ...samplers import reuse
from .. import bvh as tree
from ..emitters import scene_radius
from ..selection import alias_tables

NAME = "bvh"
PLUGIN = register(LightSelection(NAME, module=__name__, rank=2, dims=1, per_point=True,
                                 doc="by a light BVH's importance at the shading point"))
# Columns of a light at infinity's row: its weight (pi x irradiance), the unit direction toward
# it (0: every direction, no receiver cosine).
WEIGHT, TOWARD = 0, 1


class BvhTables(NamedTuple):
    """The tree (``tracer.lights.bvh.LightTree``) over the candidates before the lights at
    infinity, the candidates' pmf by power, and ``infinite (m, 4)`` the rows of the m lights
    at infinity (candidates K - m .. K - 1; columns ``WEIGHT``, ``TOWARD``)."""

    nodes: np.ndarray
    child: np.ndarray
    span: np.ndarray
    share: np.ndarray
    trail: np.ndarray
    trail_depth: np.ndarray
    pmf: np.ndarray
    infinite: np.ndarray


def tables(candidates) -> BvhTables:
    """The tree over the bounded candidates, built top down by the surface area orientation
    heuristic, and the rows of the lights at infinity (module docstring). Triangles and
    rectangles shine over the front hemisphere of one normal (cone of spread 0), spheres and
    points in every direction (spread pi); theta_e = 90 degrees for all."""
    infinite = np.asarray(candidates.infinite, dtype=bool)
    bounded = len(infinite) - int(infinite.sum())
    if infinite[:bounded].any():
        raise ValueError("the lights at infinity must be the last candidates")
    built = tree.build(candidates.lo[:bounded], candidates.hi[:bounded], candidates.axis[:bounded],
                       candidates.cos_o[:bounded], np.zeros(bounded), candidates.flux[:bounded],
                       candidates.owner[:bounded])
    rows = np.zeros((len(infinite) - bounded, 4))
    for j, k in enumerate(range(bounded, len(infinite))):
        irradiance = candidates.flux[k] / (np.pi * scene_radius(candidates.lo[k], candidates.hi[k]) ** 2)
        if candidates.cos_o[k] >= 1.0:  # one direction (a directional light): exact, with its cosine
            rows[j, WEIGHT] = np.pi * irradiance
            rows[j, TOWARD:TOWARD + 3] = -candidates.axis[k]
        else:  # every direction (the environment): the mean over receiver normals
            rows[j, WEIGHT] = 0.25 * np.pi * irradiance
    return BvhTables(np.ascontiguousarray(built.nodes), built.child, built.span, built.share, built.trail,
                     built.trail_depth, alias_tables("power", candidates).pmf, rows)


def runs_as(tables: BvhTables) -> str | None:
    """``power`` for a tree of one leaf and no lights at infinity, else None (module
    ``tracer.lights.selections``). Such a tree picks among its leaf's members by their power
    shares, with no bound to test (``tracer.lights.bvh.choose``), and the leaf holds every
    candidate: its pmf is the power pmf at every point. Measured (benchmarks/light_pick.py):
    its pick cost 39 ns against 2 for the alias table on tracer's Cornell box; power's kernels
    are also the ones a ``mis`` render has already compiled."""
    return "power" if len(tables.nodes) == 1 and len(tables.infinite) == 0 else None


@jit
def _infinite_weight(rows, j: int, n) -> float:
    """The weight of light at infinity ``j`` at a receiver of normal ``n`` (0: none)."""
    tx, ty, tz = rows[j, TOWARD], rows[j, TOWARD + 1], rows[j, TOWARD + 2]
    if (tx == 0.0 and ty == 0.0 and tz == 0.0) or (n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0):
        return rows[j, WEIGHT]
    return rows[j, WEIGHT] * max(n[0] * tx + n[1] * ty + n[2] * tz, 0.0)


@jit
def _tree_share(nodes, infinite, x, n):
    """``(p_tree, total)``: the probability of descending the tree at ``(x, n)`` and the sum
    of the weights (0: no light can reach x), with lights at infinity (rows ``infinite``)."""
    w_tree = tree.importance(nodes, 0, x, n) if len(nodes) > 0 else 0.0
    total = w_tree
    for j in range(len(infinite)):
        total += _infinite_weight(infinite, j, n)
    if not total > 0.0:
        return 0.0, 0.0
    return w_tree / total, total


# Both functions go straight to the tree where there are no lights at infinity (most scenes), and
# read the tables' arrays once: each array passed on inside the per-lane code costs numba
# reference counts, and the general path cost the descent of a one-leaf tree 80 ns against 20.
@jit
def choose(sel, x, n_receiver, u: float):
    nodes, infinite = sel.nodes, sel.infinite
    if len(infinite) == 0:  # the descent alone
        if len(nodes) == 0:
            return -1, 0.0
        return tree.choose(nodes, sel.child, sel.span, sel.share, x, n_receiver, u)
    p_tree, total = _tree_share(nodes, infinite, x, n_receiver)
    if not total > 0.0:
        return -1, 0.0
    if u < p_tree:
        k, p = tree.choose(nodes, sel.child, sel.span, sel.share, x, n_receiver, reuse(u, p_tree, True))
        return k, p * p_tree
    # A light at infinity, by the running sum of their probabilities from p_tree (the last
    # one of positive weight takes what rounding leaves above the sum).
    first, running, last, p_last = len(sel.trail), p_tree, -1, 0.0
    for j in range(len(infinite)):
        p = _infinite_weight(infinite, j, n_receiver) / total
        if p > 0.0:
            running += p
            last, p_last = j, p
            if u < running:
                break
    return (first + last, p_last) if last >= 0 else (-1, 0.0)


@jit
def pmf(sel, k: int, x, n_receiver) -> float:
    nodes, infinite = sel.nodes, sel.infinite
    if len(infinite) == 0:
        if len(nodes) == 0:
            return 0.0
        return tree.pmf_of(nodes, sel.child, sel.span, sel.share, sel.trail, sel.trail_depth, k, x,
                           n_receiver)
    p_tree, total = _tree_share(nodes, infinite, x, n_receiver)
    if not total > 0.0:
        return 0.0
    first = len(sel.trail)
    if k >= first:
        return _infinite_weight(infinite, k - first, n_receiver) / total
    if not p_tree > 0.0:
        return 0.0
    return tree.pmf_of(nodes, sel.child, sel.span, sel.share, sel.trail, sel.trail_depth, k, x,
                       n_receiver) * p_tree
