"""What every material declares: its name, code, parameters (named columns) and lobes.

A material type is a module of ``tracer.materials`` with a ``TYPE`` (:class:`MaterialType`)
and three compiled per-lane functions over the scene's parameter table:

- ``eval_pdf(params, row, wo, wi) -> (f, pdf)``: f(wo, wi) as RGB, without the cosine (0
  below the surface and for delta lobes), and the solid-angle pdf with which ``sample``
  picks ``wi`` (0 for delta lobes). Together because MIS needs both and they share work.
- ``sample(params, row, wo, u_lobe, u0, u1) -> (wi, weight, pdf, flags)``: ``u_lobe`` chooses
  the lobe of a material with several (unused by one-lobe materials), ``(u0, u1)`` the
  direction; wi toward the light, weight = f |cos theta_i| / pdf as RGB, pdf, and the lobe
  flags of the sampled lobe (``DELTA``, ``GLOSSY``, ``DIFFUSE``); weight 0 and flags 0 when
  the sample is invalid. For a delta lobe, pdf is 0 and weight is the lobe's contribution
  divided by the probability of choosing it (the mirror's: its reflectance). For a non-delta
  sample of a material that mixes lobes, f and pdf are those of all its non-delta lobes
  (pdf: the choice probabilities times the lobes' pdfs), as ``eval_pdf`` gives them.

``params`` is the ``(K, W)`` float64 table of all materials of a scene and ``row`` the
material's row: a material reads its own columns by name (``column``), never by a bare number.
Directions are local to the shading frame (z = the normal, flipped toward the viewer, so
``wo.z > 0``: materials are two-sided); ``wo`` points toward the viewer, ``wi`` toward the
light (pbrt's convention).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..jit import jit

# Lobe flags (a bit set): what a sampled lobe, or a material's lobes, are.
DELTA, GLOSSY, DIFFUSE = 1, 2, 4


@dataclass(frozen=True)
class Param:
    """One parameter of a material type: ``size`` columns (1: a number, 3: an RGB or vector),
    the range a scene may give (``lo_open``: lo itself excluded) and the default (None:
    required)."""

    name: str
    size: int
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    default: tuple[float, ...] | float | None = None
    doc: str = ""


@dataclass(frozen=True)
class MaterialType:
    """A material type: ``name`` as scene files spell it, ``code`` as kernels dispatch on it,
    ``params`` laid out in columns in this order, ``lobes`` the flags of every lobe it has."""

    name: str
    code: int
    params: tuple[Param, ...]
    lobes: int
    doc: str = ""

    def column(self, name: str) -> int:
        """First column of parameter ``name`` in this type's rows."""
        offset = 0
        for p in self.params:
            if p.name == name:
                return offset
            offset += p.size
        raise KeyError(f"material {self.name!r} has no parameter {name!r}")

    @property
    def width(self) -> int:
        """Columns a row of this type uses."""
        return sum(p.size for p in self.params)

    def row(self, values: dict[str, object]) -> np.ndarray:
        """This type's parameters as a row, from ``values`` by name (defaults where absent)."""
        out = np.zeros(self.width)
        for p in self.params:
            value = values.get(p.name, p.default)
            if value is None:
                raise ValueError(f"material {self.name!r} needs {p.name!r}")
            out[self.column(p.name): self.column(p.name) + p.size] = np.broadcast_to(
                np.asarray(value, dtype=np.float64), (p.size,))
        return out


@jit
def rgb(params, row: int, column: int):
    """The three columns ``column .. column + 2`` of material ``row`` as an RGB tuple."""
    return params[row, column], params[row, column + 1], params[row, column + 2]


@dataclass
class MaterialTable:
    """The materials of a scene, one row each; row 0 is the black material (``NONE``) of
    shapes that name none.

    kind : (K,) int8 material code.   params : (K, W) float64, each row laid out by its type.
    names : (K,) material names as the scene gives them.
    """

    kind: np.ndarray
    params: np.ndarray
    names: list[str]
