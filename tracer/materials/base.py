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
from typing import Callable

import numpy as np

from ..jit import jit
from ..plugins import Plugin

# Lobe flags (a bit set): what a sampled lobe, or a material's lobes, are.
DELTA, GLOSSY, DIFFUSE = 1, 2, 4
# The most table rows one material takes (``MaterialType.rows``: a blend and its two parts).
MAX_MATERIAL_ROWS = 3


@dataclass(frozen=True)
class Param:
    """One parameter of a material type: ``size`` columns (1: a number, 3: an RGB or vector),
    the range a scene may give (``lo_open``: lo itself excluded) and the default (None:
    required).

    choices : a parameter a scene gives as one of these names, held as its index (a column of
        0.0, 1.0, ...); the default is then a name.   boolean : given as true or false, held as
        1.0 or 0.0.   late : added to the type after scene digests were first written; a scene
        that leaves it at its default keeps the digest it had (``MaterialTable.digest_params``).
        texture : a scene may give a texture for it (``tracer.textures``): its kernels read it
        per hit, and no derived column depends on it except through its mean.   internal : set
        by the readers, never given by a scene (a blend's part codes): not in the reference.
    """

    name: str
    size: int
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    default: tuple[float, ...] | float | str | bool | None = None
    doc: str = ""
    choices: tuple[str, ...] = ()
    boolean: bool = False
    late: bool = False
    texture: bool = False
    internal: bool = False

    def check(self, value: object) -> None:
        """Raise ValueError unless ``value`` (a number, or ``size`` numbers) is finite and within
        this parameter's range: the range is what every reader must enforce, since a value
        outside it may not render finite (``tests/test_material_bounds.py``)."""
        if self.choices or self.boolean:
            return
        values = np.asarray(value, dtype=np.float64).ravel()
        bad = ~np.isfinite(values)
        if self.lo is not None:
            bad |= (values <= self.lo) if self.lo_open else (values < self.lo)
        if self.hi is not None:
            bad |= values > self.hi
        if bad.any():
            low = "" if self.lo is None else f"{'>' if self.lo_open else '>='} {self.lo:g}"
            high = "" if self.hi is None else f"<= {self.hi:g}"
            raise ValueError(f"{self.name} = {values[np.argmax(bad)]:g} is outside its range "
                             f"({' and '.join(filter(None, (low, high))) or 'finite'})")

    def encode(self, value: object) -> object:
        """``value`` as the column(s) hold it: a choice's index, a boolean's 0 or 1."""
        if self.choices:
            return float(self.choices.index(value)) if isinstance(value, str) else value
        if self.boolean:
            return float(bool(value))
        return value


@dataclass(frozen=True)
class MaterialType(Plugin):
    """A material type, a plug-in (``tracer.plugins``): ``name`` as scene files spell it,
    ``code`` as kernels dispatch on it (stable: scene digests hold it), ``module`` the module of
    its ``eval_pdf`` and ``sample``, ``params`` laid out in columns in this order, ``lobes`` the
    flags of every lobe it has; a direction sample of it draws 3 numbers (lobe, direction).

    derived : columns computed from the parameters once per material (tables, constants that
        kernels would otherwise recompute per sample), after the parameters in each row;
        ``derive(values) -> {name: value}`` fills them from the parameters by name.
    behind : for a type whose two sides differ (an interface with an inside, ``dielectric``):
        ``behind(values) -> values``, its parameters as seen from behind the shading normal. The
        estimator shades a hit from behind with a row of those (``MaterialTable.shading``), so
        that the type itself always sees ``wo.z > 0``.
    rows : the table rows a material of the type takes: 1, or for a composite type (a blend of
        other materials, ``blendbsdf``) its own row and its parts' rows after it, which its
        functions (templates) evaluate through ``dispatch.part_eval_pdf`` and ``part_sample``.
    oriented : ``oriented(values) -> bool``, for a type whose value can depend on the direction
        of the surface's tangent (anisotropic roughness): where it is True for a row, the
        kernels shade that row in Mitsuba's frame, s along dp/du (``tracer.textures.FRAME``);
        other rows are isotropic about the normal and take any tangent.
    transmits : the type has a transmission lobe with a density (``roughdielectric``): its
        ``eval_pdf`` may be nonzero for wi.z < 0, light sampling takes |cos theta_i| and no
        light selection may skip the lights below its shading normal's horizon. (A delta
        transmission needs none of this: light samples never see it.)
    """

    params: tuple[Param, ...] = ()
    lobes: int = 0
    derived: tuple[Param, ...] = ()
    derive: Callable[[dict[str, object]], dict[str, object]] | None = None
    behind: Callable[[dict[str, object]], dict[str, object]] | None = None
    transmits: bool = False
    oriented: Callable[[dict[str, object]], bool] | None = None
    rows: int = 1
    dims: int = 3
    kind: str = "material"

    @property
    def composite(self) -> bool:
        """Whether the type is made of other materials' rows (``rows``)."""
        return self.rows > 1

    def column(self, name: str) -> int:
        """First column of parameter (or derived column) ``name`` in this type's rows."""
        offset = 0
        for p in self.params + self.derived:
            if p.name == name:
                return offset
            offset += p.size
        raise KeyError(f"material {self.name!r} has no parameter {name!r}")

    @property
    def width(self) -> int:
        """Columns a row of this type uses."""
        return sum(p.size for p in self.params + self.derived)

    def row(self, values: dict[str, object]) -> np.ndarray:
        """This type's parameters as a row, from ``values`` by name (defaults where absent;
        choices by name or index, booleans as bool or number), then its derived columns."""
        out = np.zeros(self.width)
        given: dict[str, object] = {}
        for p in self.params:
            value = values.get(p.name, p.default)
            if value is None:
                raise ValueError(f"material {self.name!r} needs {p.name!r}")
            p.check(value)
            column = self.column(p.name)
            out[column: column + p.size] = np.broadcast_to(np.asarray(p.encode(value), dtype=np.float64),
                                                           (p.size,))
            given[p.name] = out[column] if p.size == 1 else out[column: column + p.size].copy()
        if self.derive is not None:
            for name, value in self.derive(given).items():
                column = self.column(name)
                size = next(p.size for p in self.derived if p.name == name)
                out[column: column + size] = np.broadcast_to(np.asarray(value, dtype=np.float64), (size,))
        return out

    def values(self, row: np.ndarray) -> dict[str, object]:
        """The parameters of ``row`` by name, as :meth:`row` takes them (choices as indices)."""
        out: dict[str, object] = {}
        for p in self.params:
            column = self.column(p.name)
            out[p.name] = float(row[column]) if p.size == 1 else row[column: column + p.size].copy()
        return out

    def digest_width(self, row: np.ndarray) -> int:
        """How many leading columns of ``row`` a scene digest holds: all but the trailing
        ``late`` parameters that hold their defaults (and the derived columns, which follow
        from the parameters)."""
        width = sum(p.size for p in self.params)
        for p in reversed(self.params):
            if not p.late:
                break
            column = self.column(p.name)
            default = np.broadcast_to(np.asarray(p.encode(p.default), dtype=np.float64), (p.size,))
            if not np.array_equal(row[column: column + p.size], default):
                break
            width -= p.size
        return width


@jit
def no_density(params, row, wo, wi):
    """``eval_pdf`` of a type with delta lobes only: 0 and 0 for any given direction (no other
    technique can hit a delta lobe)."""
    return (0.0, 0.0, 0.0), 0.0


@jit
def rgb(params, row: int, column: int):
    """The three columns ``column .. column + 2`` of material ``row`` as an RGB tuple."""
    return params[row, column], params[row, column + 1], params[row, column + 2]


@jit
def mean3(params, row: int, column: int) -> float:
    """The mean of the three columns ``column .. column + 2`` of material ``row`` (a colour's
    weight in a lobe proxy: ``lobe``)."""
    return (params[row, column] + params[row, column + 1] + params[row, column + 2]) / 3.0


@jit
def weighted(wi, f, pdf: float, lobe: int):
    """A ``sample`` result ``(wi, weight, pdf, lobe)`` for a direction drawn with density
    ``pdf`` whose f is ``f``: weight = f |cos(theta_i)| / pdf (wi below the surface: a
    transmission); all zero where ``lobe`` is 0 (no direction was drawn) or the pdf is not
    positive."""
    if lobe == 0 or not pdf > 0.0:
        return wi, (0.0, 0.0, 0.0), 0.0, 0
    c = abs(wi[2]) / pdf
    return wi, (f[0] * c, f[1] * c, f[2] * c), pdf, lobe


@dataclass
class MaterialTable:
    """The materials of a scene, one row each; row 0 is the black material (``NONE``) of
    shapes that name none.

    kind : (K,) int8 material code.   params : (K, W) float64, each row laid out by its type.
    names : (K,) material names as the scene gives them.
    twosided : (K,) bool: the material reflects on both sides of a surface (tracer's TOML
        materials); False: on the side the shading normal points to only, black from behind
        (Mitsuba's BSDFs unless wrapped in ``twosided``). Default: all True.
    opacity : (K,) float64 in [0, 1]: the fraction of light a surface of the material stops
        (Mitsuba's ``mask``; 1: opaque, the default). A hit is passed through with probability
        1 - opacity, and a shadow ray crossing the surface carries that fraction on
        (``tracer.estimator.cutouts``). A textured opacity is bound in the scene's texture table
        (``TextureTable.cutouts``); this column then holds the texture's mean.
    """

    kind: np.ndarray
    params: np.ndarray
    names: list[str]
    twosided: np.ndarray | None = None
    opacity: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.twosided is None:
            self.twosided = np.ones(len(self.kind), dtype=np.bool_)
        self.twosided = np.asarray(self.twosided, dtype=np.bool_)
        if self.opacity is None:
            self.opacity = np.ones(len(self.kind))
        self.opacity = np.asarray(self.opacity, dtype=np.float64)

    def shading(self, types: dict[int, MaterialType]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The table as the kernels shade with it (``types`` by code): ``kind (K',)``, ``params
        (K', W)`` and ``behind (K',)`` int64, the row a hit seen from behind a material's shading
        normal shades with: the material's own (two-sided), -1 (one-sided: black from behind),
        or, for a two-sided material whose type has ``behind``, a row appended after the K rows
        of this table holding the parameters seen from that side."""
        kind, params = list(self.kind), [row for row in self.params]
        behind = np.where(self.twosided, np.arange(len(self.kind)), -1).astype(np.int64)
        for m, code in enumerate(self.kind):
            t = types.get(int(code))
            if t is None or t.behind is None or not self.twosided[m]:
                continue
            back = np.zeros(self.params.shape[1])
            back[:t.width] = t.row(t.behind(t.values(self.params[m])))
            behind[m] = len(kind)
            kind.append(code)
            params.append(back)
        behind = np.concatenate([behind, np.arange(len(self.kind), len(kind), dtype=np.int64)])
        return (np.asarray(kind, dtype=np.int8), np.ascontiguousarray(np.array(params, dtype=np.float64)
                                                                      .reshape(len(kind), -1)), behind)

    def digest_params(self, types: dict[int, MaterialType]) -> np.ndarray:
        """The parameter table as a scene digest holds it: each row up to its type's
        ``digest_width`` (``types`` by code), zero-padded to the widest, so that scenes written
        before a type gained ``late`` parameters keep their digests."""
        widths = [types[int(k)].digest_width(row) if int(k) in types else 0
                  for k, row in zip(self.kind, self.params, strict=True)]
        out = np.zeros((len(self.kind), max(max(widths, default=0), 1)))
        for i, w in enumerate(widths):
            out[i, :w] = self.params[i, :w]
        return out
