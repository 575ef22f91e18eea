"""The ``power`` light selection: each candidate in proportion to the flux it emits.

pi * area * mean(Le) for an emitting triangle, rectangle or sphere, 4 pi * mean(I) for a point
light, so that bright lights get more samples; drawn with Walker's alias table in O(1)
(``tracer.lights.selection``). A plug-in (``tracer.lights.selections``); the default.
"""

from __future__ import annotations

from ...plugins import LightSelection, register
from ..selection import AliasTables, alias_choose, alias_pmf, alias_tables

NAME = "power"
PLUGIN = register(LightSelection(NAME, module=__name__, rank=0, dims=1, doc="in proportion to flux"))


def tables(candidates) -> AliasTables:
    return alias_tables("power", candidates)


choose = alias_choose
pmf = alias_pmf
