"""The ``bvh`` light selection: down a light BVH, each child in proportion to an upper bound of
what its lights can deliver to the shading point (``tracer.lights.bvh``: Conty Estevez and
Kulla 2018, pbrt-v4's ``BVHLightSampler``), so its pmf depends on the point and its shading
normal. A plug-in (``tracer.lights.selections``); it pays with many lights.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...jit import jit
from ...plugins import LightSelection, register
from .. import bvh as tree
from ..selection import alias_tables

NAME = "bvh"
PLUGIN = register(LightSelection(NAME, module=__name__, rank=2, dims=1, per_point=True,
                                 doc="by a light BVH's importance at the shading point"))


class BvhTables(NamedTuple):
    """The tree (``tracer.lights.bvh.LightTree``) and the candidates' pmf by power."""

    nodes: np.ndarray
    child: np.ndarray
    trail: np.ndarray
    trail_depth: np.ndarray
    pmf: np.ndarray


def tables(candidates) -> BvhTables:
    """The tree over the candidates, built top down by the surface area orientation heuristic.
    Triangles and rectangles shine over the front hemisphere of one normal (cone of spread 0),
    spheres and points in every direction (spread pi); theta_e = 90 degrees for all."""
    built = tree.build(candidates.lo, candidates.hi, candidates.axis, candidates.cos_o,
                       np.zeros(len(candidates.flux)), candidates.flux)
    return BvhTables(np.ascontiguousarray(built.nodes), built.child, built.trail, built.trail_depth,
                     alias_tables("power", candidates).pmf)


@jit
def choose(sel, x, n_receiver, u: float):
    if len(sel.nodes) == 0:
        return -1, 0.0
    return tree.choose(sel.nodes, sel.child, x, n_receiver, u)


@jit
def pmf(sel, k: int, x, n_receiver) -> float:
    return tree.pmf_of(sel.nodes, sel.child, sel.trail, sel.trail_depth, k, x, n_receiver)
