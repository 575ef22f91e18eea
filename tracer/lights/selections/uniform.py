"""The ``uniform`` light selection: each light (an emissive shape or a point light) equally
likely, then a candidate of that shape (a triangle of a mesh) in proportion to its area (a
textured emitter's: its flux, ``tracer.lights.emitters.Emitters.share``); drawn
with Walker's alias table (``tracer.lights.selection``). A plug-in (``tracer.lights.selections``).
"""

from __future__ import annotations

from ...plugins import LightSelection, register
from ..selection import AliasTables, alias_choose, alias_pmf, alias_tables

NAME = "uniform"
PLUGIN = register(LightSelection(NAME, module=__name__, rank=1, dims=1, doc="each light alike, then by area"))


def tables(candidates) -> AliasTables:
    return alias_tables("uniform", candidates)


choose = alias_choose
pmf = alias_pmf
