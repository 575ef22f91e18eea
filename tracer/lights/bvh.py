"""Light selection by a light BVH: choose the emitter candidate by its importance at the shading point.

Power selection picks a light independently of the point being lit, so in a room of a thousand
lights most samples go to lights that are far away, facing elsewhere or below the horizon. A
light BVH (Conty Estevez and Kulla, "Importance Sampling of Many Lights with Adaptive Tree
Splitting", HPG 2018; pbrt-v4's ``BVHLightSampler``, Pharr, Jakob and Humphreys, *Physically
Based Rendering*, 4th ed., sec. 12.6.3) groups the candidates in a binary tree whose nodes
bound their members' power, positions (a box) and emission directions (a cone). A light is
chosen by descending from the root, taking each child with probability proportional to an
upper bound of what its lights could deliver to the shading point x with normal n:

    importance = power * cos(theta') / d^2 * cos(theta_i')

with d the distance to the box's centre (clamped below by the box's half diagonal, so that a
point inside or next to a big node does not blow up), theta' the smallest angle any emitter of
the node could have between its normal cone and a direction toward x, and theta_i' the
smallest angle between n and any direction from x into the box. Both bounds come from the
angle theta_b the box subtends from x (its bounding sphere's): angles shrink by theta_b, and
by theta_o, the cone's spread. A node that cannot reach x (theta' >= theta_e: every emitter
faces away; theta_i' >= 90 deg: the box lies below the horizon) has importance 0 and is never
taken.

**Unbiasedness.** The selection pmf of candidate k at (x, n) is the product of the branch
probabilities along its path, and :func:`pmf_of` recomputes exactly that product (the same
expressions in the same order, so it equals what :func:`choose` returned bit for bit). It is
zero only where the bounds prove the light contributes nothing: the emitters shine from their
front (theta_e = 90 deg) and the materials reflect only above the shading normal n (no
transmission), so a light with importance 0 has f |cos| Le = 0 at x. A material that
transmits would need the receiver bound switched off (n = 0 turns it off).

**Build.** Top down by pbrt-v4's surface area orientation heuristic (SAOH; Conty Estevez and
Kulla, sec. 4.3): a node's members are split where the cost Kr (phi_L M_Omega(L) M_A(L) +
phi_R M_Omega(R) M_A(R)) is least, over up to 12 bins of their centres along each axis, with
M_A a box's surface area, M_Omega the solid angle its normal cone and emission spread sweep,
and Kr the node's longest extent over its extent along the split axis (which keeps thin boxes
from being cut lengthwise). The cost sees each group's normal cone as an estimate (its mean
axis and spread, from a sum of axes: no trigonometry per light); the nodes' bounds themselves
are exact unions, made bottom up once the tree stands. Nodes of up to four lights split at the
median. Compiled; no loop over lights runs in the interpreter: 100,000 emitters build in
0.4-0.7 s on the 2-core test machine (``benchmarks/many_lights.py`` measured 0.67 s). Leaves
hold one candidate, or a *cluster*: a few consecutive candidates of one emitter with one normal
whose boxes together are hardly bigger than the largest (``clusters``: the two triangles of a
quad light under area sampling), chosen among themselves by power. Splitting a quad's halves
buys the descent almost nothing (both are as near, as bright and facing the same way) and
costs a level everywhere: on Mitsuba's Cornell box a level was the whole tree, and 28% of the
render's time. Each node's children are stored side by side (``child[i]``, ``child[i] + 1``),
and a leaf's path from the root is its *trail*, one bit per level (1: the second child), as in
pbrt-v4, which the pmf walk follows; a cluster's members share it.

What the tree buys, measured at three shading points of the ``many_lights`` street as the sum
over lights of share^2 / pmf (share: the light's part of the point's unshadowed light; 1 is a
pmf proportional to it): power selection 32-88, this tree 1.5-4.0, the flat importance of
every light (no tree; O(K) per sample) 1.05-3.6. A first version, a balanced tree over the
lights' Morton order (Lin and Yuksel 2020), built faster but scored 7.9-11.3.

Node layout, one float64 row of ``NODE_WIDTH``: box min (3), box max (3), cone axis (3), cos
theta_o, cos theta_e, power, and what the importance reads of the box, precomputed: its bounding
sphere's centre (3), squared radius and radius, and sin theta_o; then theta_o and theta_e
themselves, which the build's cone unions and costs work with (no arccos per merge).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import jit
from ..samplers import reuse

NODE_WIDTH = 20
LO, HI, AXIS, COS_O, COS_E, POWER, CENTRE, RADIUS2, RADIUS, SIN_O, THETA_O, THETA_E = (
    0, 3, 6, 9, 10, 11, 12, 15, 16, 17, 18, 19)
# Boxes grow by this relative amount (of their size and position), so that points sampled on an
# emitter in float64 never fall outside its node's box by a rounding error.
BOX_PAD = 1e-9
# Cone unions widen by this angle (radians) against rounding in the axis rotation.
CONE_PAD = 1e-7
# Importance is capped here, so that a point on top of a point light does not make inf / inf.
MAX_IMPORTANCE = 1e300


class LightTree(NamedTuple):
    """A light BVH over K candidates in C leaves (clusters of consecutive candidates).

    nodes : (2 C - 1, NODE_WIDTH) float64 node bounds; node 0 is the root.
    child : (2 C - 1,) int64, the first of node i's two children (the second is child[i] + 1),
        or -1 - k for a leaf whose first candidate is k.
    span : (2 C - 1,) int64, a leaf's number of candidates (k .. k + span - 1); 0 for the others.
    share : (K,) float64, candidate k's probability within its leaf (its power over the leaf's).
    trail : (K,) int64, the path from the root to candidate k's leaf: bit l says which child it
        takes at level l (1: the second).   trail_depth : (K,) int64, the length of that path.
    """

    nodes: np.ndarray
    child: np.ndarray
    span: np.ndarray
    share: np.ndarray
    trail: np.ndarray
    trail_depth: np.ndarray


def empty() -> LightTree:
    """The tree of a render that does not select by BVH (no nodes)."""
    none = np.zeros(0, dtype=np.int64)
    return LightTree(np.zeros((0, NODE_WIDTH)), none, none, np.zeros(0), none, none)


# A cluster holds at most this many candidates, and its box's diagonal is at most CLUSTER_SPREAD
# times its largest member's (a quad's two triangles: 1 for an axis-aligned quad, 1.26 for one
# turned 45 degrees in its plane; two neighbouring quads of a grid: 2 and more).
CLUSTER_MAX = 4
CLUSTER_SPREAD = 1.5
# Normals this close (cosine; about 1.4e-4 rad) count as one way: the two triangles of a quad of
# float32 vertices have normals up to ~2e-5 rad apart. (The leaf's cone is their exact union.)
SAME_WAY = 1.0 - 1e-8


def build(lo: np.ndarray, hi: np.ndarray, axis: np.ndarray, cos_o: np.ndarray, cos_e: np.ndarray,
          power: np.ndarray, owner: np.ndarray | None = None) -> LightTree:
    """The tree over K candidates with boxes ``lo, hi (K, 3)``, unit cone axes ``axis (K, 3)``,
    cone spreads ``cos_o (K,)`` (1: one direction, -1: all), emission spreads ``cos_e (K,)``
    (0 for emitters that shine over their front hemisphere) and powers ``power (K,)`` (> 0).
    With ``owner (K,)`` (the emitter each candidate belongs to), consecutive candidates of one
    emitter and one normal that lie close together share a leaf (:func:`clusters`); without
    it, every leaf holds one candidate."""
    count = len(power)
    if count == 0:
        return empty()
    size = np.abs(hi - lo) + np.abs(lo) + np.abs(hi)
    rows = np.zeros((count, NODE_WIDTH))
    rows[:, LO:LO + 3] = lo - BOX_PAD * size
    rows[:, HI:HI + 3] = hi + BOX_PAD * size
    rows[:, AXIS:AXIS + 3] = axis
    rows[:, COS_O] = cos_o
    rows[:, COS_E] = cos_e
    rows[:, THETA_O] = np.arccos(np.clip(cos_o, -1.0, 1.0))
    rows[:, THETA_E] = np.arccos(np.clip(cos_e, -1.0, 1.0))
    rows[:, POWER] = power
    first = (clusters(lo, hi, axis, cos_o, np.asarray(owner, dtype=np.int64)) if owner is not None
             else np.arange(count + 1))
    leaves = _cluster_rows(rows, first)
    nodes, child, trail_c, depth_c = _build(leaves)
    # Leaves name their first candidate and how many follow; members inherit their leaf's trail.
    leaf = child < 0
    cluster = -1 - child[leaf]
    span = np.zeros(len(child), dtype=np.int64)
    span[leaf] = first[cluster + 1] - first[cluster]
    child[leaf] = -1 - first[cluster]
    members = np.diff(first)
    trail = np.repeat(trail_c, members)
    trail_depth = np.repeat(depth_c, members)
    cluster_power = np.repeat(leaves[:, POWER], members)
    share = np.where(members.repeat(members) == 1, 1.0, power / cluster_power)
    # The cone cosines of internal nodes and clusters from their angles, unions made by
    # _cone_union (a leaf of one candidate keeps the cosine it was given).
    united = (child >= 0) | (span > 1)
    nodes[united, COS_O] = np.cos(nodes[united, THETA_O])
    half = 0.5 * (nodes[:, HI:HI + 3] - nodes[:, LO:LO + 3])
    nodes[:, CENTRE:CENTRE + 3] = nodes[:, LO:LO + 3] + half
    nodes[:, RADIUS2] = np.sum(half * half, axis=1)
    nodes[:, RADIUS] = np.sqrt(nodes[:, RADIUS2])
    nodes[:, SIN_O] = np.sqrt(np.maximum(1.0 - nodes[:, COS_O] ** 2, 0.0))
    return LightTree(nodes, child, span, share, trail, trail_depth)


@jit
def clusters(lo, hi, axis, cos_o, owner):
    """``first (C + 1,)``: the candidates split into C runs of consecutive ones, run c being
    ``first[c] .. first[c + 1] - 1``. A candidate joins the run before it when both belong to
    one emitter (``owner``), face one way (single-direction cones, ``cos_o`` 1, with axes within
    SAME_WAY) and the run's box stays within CLUSTER_SPREAD times the diagonal of its largest
    member, up to CLUSTER_MAX members. Any grouping keeps the selection unbiased (a leaf's members
    are chosen by power, the pmf says so); this one only decides which splits are not worth a
    level of descent."""
    count = len(owner)
    first = np.zeros(count + 1, dtype=np.int64)
    runs = 0
    box = np.zeros(6)
    largest = 0.0
    for k in range(count):
        ex, ey, ez = hi[k, 0] - lo[k, 0], hi[k, 1] - lo[k, 1], hi[k, 2] - lo[k, 2]
        diagonal = math.sqrt(ex * ex + ey * ey + ez * ez)
        joins = False
        if k > 0 and k - first[runs - 1] < CLUSTER_MAX and owner[k] == owner[k - 1] and cos_o[k] >= 1.0 \
                and cos_o[k - 1] >= 1.0:
            same_way = axis[k, 0] * axis[k - 1, 0] + axis[k, 1] * axis[k - 1, 1] + axis[k, 2] * axis[k - 1, 2]
            spread = 0.0
            for a in range(3):
                spread += (max(box[3 + a], hi[k, a]) - min(box[a], lo[k, a])) ** 2
            joins = same_way >= SAME_WAY and math.sqrt(spread) <= CLUSTER_SPREAD * max(largest, diagonal)
        if not joins:
            first[runs] = k
            runs += 1
            largest = 0.0
            for a in range(3):
                box[a], box[3 + a] = lo[k, a], hi[k, a]
        for a in range(3):
            box[a], box[3 + a] = min(box[a], lo[k, a]), max(box[3 + a], hi[k, a])
        largest = max(largest, diagonal)
    first[runs] = count
    return first[:runs + 1]


@jit
def _cluster_rows(rows, first):
    """One node row per run of ``first`` (:func:`clusters`): the union of its members' rows."""
    out = np.zeros((len(first) - 1, NODE_WIDTH))
    for c in range(len(first) - 1):
        out[c, :] = rows[first[c]]
        for k in range(first[c] + 1, first[c + 1]):
            _merge(out[c], rows[k])
    return out


BINS = 12
# Nodes of at most this many members are split at their median (module docstring).
SMALL_NODE = 4
# Below this many levels left in a 64-bit trail, nodes are split at their median, which ends
# within log2(members) levels.
TRAIL_BITS = 62


@jit
def _build(leaves):
    """The compiled top-down build: ``(nodes, child, trail, trail_depth)`` over the candidate
    rows ``leaves (K, NODE_WIDTH)`` (box, cone, spread, power filled in)."""
    count = len(leaves)
    nodes = np.zeros((2 * count - 1, NODE_WIDTH))
    child = np.full(2 * count - 1, -1, dtype=np.int64)
    trail = np.zeros(count, dtype=np.int64)
    trail_depth = np.zeros(count, dtype=np.int64)
    order = np.arange(count)
    centre = 0.5 * (leaves[:, LO:LO + 3] + leaves[:, HI:HI + 3])
    # Work stack of (node, first member, end, depth, trail so far); members are order[first:end].
    stack = np.zeros((2 * count, 5), dtype=np.int64)
    stack[0, 2] = count
    top, used = 1, 1
    bins = np.zeros((3, BINS, SUMMARY_WIDTH))
    scratch = np.zeros((BINS + 2, SUMMARY_WIDTH))  # _split's suffix rows and left row
    bounds = np.zeros((4, 3))  # _split's centre and box extremes
    while top > 0:
        top -= 1
        node, first, end = stack[top, 0], stack[top, 1], stack[top, 2]
        depth, path = stack[top, 3], stack[top, 4]
        if end - first == 1:
            k = order[first]
            nodes[node, :] = leaves[k]
            child[node] = -1 - k
            trail[k] = path
            trail_depth[k] = depth
            continue
        # Two members: nothing to choose. Up to SMALL_NODE: the median, which is all that three
        # or four lights need (and most nodes are that small, so the SAOH would cost most there).
        median = end - first <= SMALL_NODE or depth + math.ceil(math.log2(end - first)) >= TRAIL_BITS
        middle = first + 1 if end - first == 2 else _split(leaves, centre, order, first, end, bins, scratch,
                                                               bounds, median)
        child[node] = used
        for side in range(2):
            stack[top + side, 0] = used + side
            stack[top + side, 1] = first if side == 0 else middle
            stack[top + side, 2] = middle if side == 0 else end
            stack[top + side, 3] = depth + 1
            stack[top + side, 4] = path | (side << depth)
        top += 2
        used += 2
    # Bounds bottom up: children come after their parent, so in reverse order every child is
    # done before its parent (one union per node; each node's bounds hold its children's).
    for node in range(len(nodes) - 1, -1, -1):
        if child[node] >= 0:
            nodes[node, :] = nodes[child[node]]
            _merge(nodes[node], nodes[child[node] + 1])
    return nodes, child, trail, trail_depth


@jit
def _merge(into, row) -> None:
    """``into`` := the node row bounding ``into`` and ``row`` (box, power, spread, cone)."""
    for a in range(3):
        into[LO + a] = min(into[LO + a], row[LO + a])
        into[HI + a] = max(into[HI + a], row[HI + a])
    into[POWER] += row[POWER]
    into[COS_E] = min(into[COS_E], row[COS_E])  # exact, for the importance
    into[THETA_E] = max(into[THETA_E], row[THETA_E])  # the same spread, for the costs
    _cone_union(into, row)


@jit
def _cone_union(into, row) -> None:
    """``into``'s normal cone := the smallest cone holding it and ``row``'s, as pbrt-v4's
    ``Union(DirectionCone, DirectionCone)`` constructs it: if one holds the other, that one; else
    the cone spanning both, its axis turned from a's toward b's in their plane; widened by
    CONE_PAD against rounding. Works on the THETA_O column (COS_O is set after the build)."""
    wa = (into[AXIS], into[AXIS + 1], into[AXIS + 2])
    wb = (row[AXIS], row[AXIS + 1], row[AXIS + 2])
    theta_a, theta_b = into[THETA_O], row[THETA_O]
    # The angle between the axes, accurate for nearly equal ones too.
    dx, dy, dz = wa[0] - wb[0], wa[1] - wb[1], wa[2] - wb[2]
    sx, sy, sz = wa[0] + wb[0], wa[1] + wb[1], wa[2] + wb[2]
    theta_d = 2.0 * math.atan2(math.sqrt(dx * dx + dy * dy + dz * dz), math.sqrt(sx * sx + sy * sy + sz * sz))
    if min(theta_d + theta_b, math.pi) <= theta_a:
        return  # a holds b
    if min(theta_d + theta_a, math.pi) <= theta_b:
        for a in range(3):
            into[AXIS + a] = wb[a]
        into[THETA_O] = theta_b
        return
    theta_o = 0.5 * (theta_a + theta_d + theta_b)
    kx, ky, kz = wa[1] * wb[2] - wa[2] * wb[1], wa[2] * wb[0] - wa[0] * wb[2], wa[0] * wb[1] - wa[1] * wb[0]
    length = math.sqrt(kx * kx + ky * ky + kz * kz)
    if theta_o >= math.pi or length == 0.0:
        into[THETA_O] = math.pi  # every direction
        return
    # Rodrigues' rotation of wa by theta_o - theta_a about k = (wa x wb) / |wa x wb| (k is
    # perpendicular to wa, so wa cos + (k x wa) sin).
    kx, ky, kz = kx / length, ky / length, kz / length
    angle = theta_o - theta_a
    c, s = math.cos(angle), math.sin(angle)
    rx = wa[0] * c + (ky * wa[2] - kz * wa[1]) * s
    ry = wa[1] * c + (kz * wa[0] - kx * wa[2]) * s
    rz = wa[2] * c + (kx * wa[1] - ky * wa[0]) * s
    norm = math.sqrt(rx * rx + ry * ry + rz * rz)
    into[AXIS], into[AXIS + 1], into[AXIS + 2] = rx / norm, ry / norm, rz / norm
    into[THETA_O] = min(theta_o + CONE_PAD, math.pi)


# The split search summarizes a group of members in one row of SUMMARY_WIDTH: box min (3), box
# max (3), the sum of their cone axes (3), their count, power, largest theta_o and theta_e.
# Its normal cone is estimated, not bounded: axis along the sum, spread acos(|sum| / count)
# (exact for two equal halves of a symmetric pair) plus the largest member spread. The cost
# only steers where nodes split; the nodes' own bounds are exact unions (bottom up in _build).
SUMMARY_WIDTH = 13
S_LO, S_HI, S_AXES, S_COUNT, S_POWER, S_THETA_O, S_THETA_E = 0, 3, 6, 9, 10, 11, 12


@jit
def _summarize(into, leaf) -> None:
    """Add a candidate row ``leaf`` to the summary row ``into`` (empty: count 0)."""
    if into[S_COUNT] == 0.0:
        for a in range(3):
            into[S_LO + a] = leaf[LO + a]
            into[S_HI + a] = leaf[HI + a]
            into[S_AXES + a] = leaf[AXIS + a]
        into[S_COUNT], into[S_POWER] = 1.0, leaf[POWER]
        into[S_THETA_O], into[S_THETA_E] = leaf[THETA_O], leaf[THETA_E]
        return
    for a in range(3):
        into[S_LO + a] = min(into[S_LO + a], leaf[LO + a])
        into[S_HI + a] = max(into[S_HI + a], leaf[HI + a])
        into[S_AXES + a] += leaf[AXIS + a]
    into[S_COUNT] += 1.0
    into[S_POWER] += leaf[POWER]
    into[S_THETA_O] = max(into[S_THETA_O], leaf[THETA_O])
    into[S_THETA_E] = max(into[S_THETA_E], leaf[THETA_E])


@jit
def _combine(into, other) -> None:
    """Summary ``into`` := ``into`` and ``other`` together."""
    if other[S_COUNT] == 0.0:
        return
    if into[S_COUNT] == 0.0:
        into[:] = other
        return
    for a in range(3):
        into[S_LO + a] = min(into[S_LO + a], other[S_LO + a])
        into[S_HI + a] = max(into[S_HI + a], other[S_HI + a])
        into[S_AXES + a] += other[S_AXES + a]
    into[S_COUNT] += other[S_COUNT]
    into[S_POWER] += other[S_POWER]
    into[S_THETA_O] = max(into[S_THETA_O], other[S_THETA_O])
    into[S_THETA_E] = max(into[S_THETA_E], other[S_THETA_E])


@jit
def _orientation_measure(theta_o: float, theta_e: float) -> float:
    """M_Omega: the solid angle (times pi) that a normal cone of spread theta_o emitting over
    theta_e around each normal sweeps (Conty Estevez and Kulla, eq. 1; pbrt-v4's
    ``EvaluateCost``)."""
    theta_w = min(theta_o + theta_e, math.pi)
    cos_o, sin_o = math.cos(theta_o), math.sin(theta_o)
    return 2.0 * math.pi * (1.0 - cos_o) + 0.5 * math.pi * (
        2.0 * theta_w * sin_o - math.cos(theta_o - 2.0 * theta_w) - 2.0 * theta_o * sin_o + cos_o)


@jit
def _cost(summary) -> float:
    """phi M_Omega M_A of a summary row (0 when empty)."""
    if summary[S_COUNT] == 0.0:
        return 0.0
    ex, ey, ez = (summary[S_HI] - summary[S_LO], summary[S_HI + 1] - summary[S_LO + 1],
                  summary[S_HI + 2] - summary[S_LO + 2])
    area = 2.0 * (ex * ey + ey * ez + ez * ex)
    length = math.sqrt(summary[S_AXES] ** 2 + summary[S_AXES + 1] ** 2 + summary[S_AXES + 2] ** 2)
    spread = min(math.acos(min(length / summary[S_COUNT], 1.0)) + summary[S_THETA_O], math.pi)
    return summary[S_POWER] * _orientation_measure(spread, summary[S_THETA_E]) * area


@jit
def _split(leaves, centre, order, first: int, end: int, bins, scratch, bounds, median: bool) -> int:
    """Reorder ``order[first:end]`` into two groups and return where the second starts: by the
    cheapest SAOH split over up to BINS bins of the members' centres along each axis, or at the
    median along the widest axis of the centres (``median``, or when no split separates them).
    ``bins`` (3, BINS, SUMMARY_WIDTH), ``scratch`` (BINS + 2, SUMMARY_WIDTH) and ``bounds``
    (4, 3) are work space, allocated once per build."""
    lo_c, hi_c, lo_b, hi_b = bounds[0], bounds[1], bounds[2], bounds[3]  # centres' and boxes' extremes
    lo_c[:] = np.inf
    lo_b[:] = np.inf
    hi_c[:] = -np.inf
    hi_b[:] = -np.inf
    for m in range(first, end):
        k = order[m]
        for a in range(3):
            lo_c[a] = min(lo_c[a], centre[k, a])
            hi_c[a] = max(hi_c[a], centre[k, a])
            lo_b[a] = min(lo_b[a], leaves[k, LO + a])
            hi_b[a] = max(hi_b[a], leaves[k, HI + a])
    extent = max(hi_b[0] - lo_b[0], hi_b[1] - lo_b[1], hi_b[2] - lo_b[2])
    best, best_axis, best_bin = np.inf, -1, -1
    count = min(BINS, end - first)  # bins: as many as members, up to BINS (more gain a small node nothing)
    if not median:
        bins[:, :count, S_COUNT] = 0.0
        for m in range(first, end):  # each member into its bin along each axis
            k = order[m]
            for a in range(3):
                span = hi_c[a] - lo_c[a]
                if span > 0.0:
                    b = min(int(count * (centre[k, a] - lo_c[a]) / span), count - 1)
                    _summarize(bins[a, b], leaves[k])
        suffix, left = scratch[:count + 1], scratch[BINS + 1]  # suffix[c]: bins c .. count - 1 together
        for a in range(3):
            if not hi_c[a] - lo_c[a] > 0.0:
                continue
            suffix[count, S_COUNT] = 0.0
            for c in range(count - 1, -1, -1):
                suffix[c, :] = suffix[c + 1]
                _combine(suffix[c], bins[a, c])
            regularize = extent / max(hi_b[a] - lo_b[a], 1e-300)
            left[S_COUNT] = 0.0
            for cut in range(1, count):
                _combine(left, bins[a, cut - 1])
                if left[S_COUNT] == 0.0 or suffix[cut, S_COUNT] == 0.0:
                    continue
                cost = regularize * (_cost(left) + _cost(suffix[cut]))
                if cost < best:
                    best, best_axis, best_bin = cost, a, cut
    if best_axis < 0:  # the median along the widest axis of the centres
        a = int(np.argmax(hi_c - lo_c))
        keys = np.empty(end - first)
        for m in range(first, end):
            keys[m - first] = centre[order[m], a]
        order[first:end] = order[first:end][np.argsort(keys, kind="mergesort")]
        return first + (end - first) // 2
    span = hi_c[best_axis] - lo_c[best_axis]
    i, j = first, end - 1
    while i <= j:  # partition: the members of the bins below the cut first
        b = min(int(count * (centre[order[i], best_axis] - lo_c[best_axis]) / span), count - 1)
        if b < best_bin:
            i += 1
        else:
            order[i], order[j] = order[j], order[i]
            j -= 1
    return i


# -------------------------------------------------------------------------------------------------
# Compiled: the importance of a node, the descent, and the pmf of a given candidate.


@jit
def importance(nodes, i: int, x, n) -> float:
    """Upper-bound estimate of the light node ``i`` delivers to point ``x`` with unit normal
    ``n`` (n = 0: no receiver bound), as in the module docstring; 0 if it cannot reach x."""
    power = nodes[i, POWER]
    if not power > 0.0:
        return 0.0
    vx, vy, vz = x[0] - nodes[i, CENTRE], x[1] - nodes[i, CENTRE + 1], x[2] - nodes[i, CENTRE + 2]
    r2 = nodes[i, RADIUS2]
    d2 = vx * vx + vy * vy + vz * vz  # squared distance from the bounding sphere's centre to x
    if d2 <= r2:  # x inside the box's bounding sphere: every direction is possible
        return min(power / max(r2, 1e-300), MAX_IMPORTANCE)
    inv_d = 1.0 / math.sqrt(d2)
    # theta_b: the half-angle of the cone of directions from x into the bounding sphere.
    sin_b = nodes[i, RADIUS] * inv_d
    cos_b = math.sqrt(max(1.0 - sin_b * sin_b, 0.0))
    # theta' = max(theta_w - theta_o - theta_b, 0), theta_w the angle between the cone axis and
    # w = (x - c) / d, the direction from the node toward x.
    cos_w = (nodes[i, AXIS] * vx + nodes[i, AXIS + 1] * vy + nodes[i, AXIS + 2] * vz) * inv_d
    cos_o = nodes[i, COS_O]
    if cos_w > cos_o:
        cos_x, sin_x = 1.0, 0.0
    else:
        sin_w = math.sqrt(max(1.0 - cos_w * cos_w, 0.0))
        sin_o = nodes[i, SIN_O]
        cos_x, sin_x = cos_w * cos_o + sin_w * sin_o, sin_w * cos_o - cos_w * sin_o
    cos_p = 1.0 if cos_x > cos_b else cos_x * cos_b + sin_x * sin_b
    if cos_p <= nodes[i, COS_E]:
        return 0.0
    value = power * cos_p * (inv_d * inv_d)
    if n[0] != 0.0 or n[1] != 0.0 or n[2] != 0.0:
        # theta_i' = max(theta_i - theta_b, 0), theta_i the angle between n and -w (x to the node).
        cos_i = -(n[0] * vx + n[1] * vy + n[2] * vz) * inv_d
        if cos_i <= cos_b:
            sin_i = math.sqrt(max(1.0 - cos_i * cos_i, 0.0))
            cos_ip = cos_i * cos_b + sin_i * sin_b
            if cos_ip <= 0.0:
                return 0.0
            value *= cos_ip
    return min(value, MAX_IMPORTANCE)


@jit
def choose(nodes, child, span, share, x, n, u: float):
    """Descend from the root, each child in proportion to its importance at ``(x, n)``, using
    ``u`` in [0, 1) (rescaled at every level), then a member of the leaf by its ``share``.
    Returns ``(candidate, pmf)``, or ``(-1, 0.0)`` when no light can reach x (both children of
    a node have importance 0; only lights that cannot contribute lose that probability)."""
    node = 0
    prob = 1.0
    while child[node] >= 0:
        first = child[node]
        i0 = importance(nodes, first, x, n)
        i1 = importance(nodes, first + 1, x, n)
        total = i0 + i1
        if not total > 0.0:
            return -1, 0.0
        p_first = i0 / total
        took = u < p_first
        u = reuse(u, p_first, took)
        if took:
            node = first
            prob *= p_first
        else:
            node = first + 1
            prob *= i1 / total
    k = -1 - child[node]
    if span[node] == 1:
        return k, prob
    last = k + span[node] - 1
    while k < last and not u < share[k]:  # the member by the running sum of shares
        u -= share[k]
        k += 1
    return k, prob * share[k]


@jit
def pmf_of(nodes, child, span, share, trail, trail_depth, k: int, x, n) -> float:
    """The probability that :func:`choose` at ``(x, n)`` returns candidate ``k``: the same
    branch probabilities along k's trail, multiplied in the same order, times k's share of
    its leaf."""
    node = 0
    prob = 1.0
    path = trail[k]
    for level in range(trail_depth[k]):
        first = child[node]
        i0 = importance(nodes, first, x, n)
        i1 = importance(nodes, first + 1, x, n)
        total = i0 + i1
        if not total > 0.0:
            return 0.0
        if (path >> level) & 1:
            node = first + 1
            prob *= i1 / total
        else:
            node = first
            prob *= i0 / total
    return prob if span[node] == 1 else prob * share[k]
