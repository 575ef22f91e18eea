"""Materials behind one interface (``base.py`` says what a material type declares).

One module per material type, each a plug-in (``tracer.plugins``) that registers its
``MaterialType``; the kernels' dispatch over the types a scene uses is generated
(``tracer.kernels.dispatch``), in the manner of pbrt-v4's BxDFs:

================  ====  ==============================================================
type              code  module
================  ====  ==============================================================
(none)            0     black: shapes without a material reflect nothing
diffuse           1     ``diffuse.py``: Lambertian
roughconductor    2     ``roughconductor.py``: GGX or Beckmann metal, conductor Fresnel
mirror            3     ``mirror.py``: ideal specular reflection (delta)
conductor         4     ``conductor.py``: smooth metal, conductor Fresnel (delta)
plastic           5     ``plastic.py``: diffuse base under a smooth coating (delta + diffuse)
roughplastic      6     ``roughplastic.py``: diffuse base under a rough coating
dielectric        7     ``dielectric.py``: smooth glass, delta reflection and refraction
thindielectric    8     ``thindielectric.py``: a thin pane, delta reflection and transmission
roughdielectric   9     ``roughdielectric.py``: rough glass, microfacet reflection and refraction
pplastic          10    ``pplastic.py``: rough specular plus Fresnel-attenuated diffuse (Mitsuba's)
blendbsdf         11    ``blendbsdf.py``: a blend of two materials (composite: its parts are rows)
principled        12    ``principled.py``: Burley's principled BSDF (Mitsuba's), an interface
principledthin    13    ``principledthin.py``: Burley's thin sheet (Mitsuba's), both sides alike
================  ====  ==============================================================

``microfacet.py`` holds what the rough types share (distributions, visible-normal sampling,
Fresnel terms), ``principled_lobes.py`` what the two principled types share; ``presets.py``
the named metals of Mitsuba scenes. A material is two-sided (TOML) or one-sided, black from
behind its shading normal (Mitsuba's rule): ``MaterialTable.twosided``, applied by the
estimator, not by the types; a type whose sides differ (a dielectric's inside) declares
``behind``, and the estimator shades a hit from behind with a row of those parameters
(``MaterialTable.shading``).

Adding a material: one module here with ``CODE``, ``TYPE = register(MaterialType(...))``,
``eval_pdf`` and ``sample`` (found by ``plugins.discover``: nothing else to edit). The scene
reader reads its parameters from ``TYPE.params``; ``tests/test_sampling.py`` checks the
interface's contract (sample weight = f cos / pdf, sample pdf = pdf) on every registered type,
and a new type adds its own chi-square test there.

The batch API (:class:`Materials`) runs the same compiled code over arrays of lanes, for tests
and tools, built for the types of its table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import plugins
from ..kernels import UNBOUND, kernel
from .base import DELTA, DIFFUSE, GLOSSY, MaterialTable, MaterialType, Param

NONE = 0  # the code of the black material
# Every registered material type by name and by code, a live view (a user's type registered
# later is there too).
TYPES = plugins.Live("material")
BY_CODE = plugins.Live("material", by="code")


def table(materials: list[tuple[str, str, dict[str, object]]], twosided: list[bool] | None = None,
          opacity: list[float] | None = None) -> MaterialTable:
    """A material table from ``(name, type name, parameters by name)`` triples; row 0 is the
    black material, so the i-th triple is row i + 1. ``twosided``: per triple, whether the
    material reflects on both sides (default: all do, as tracer's TOML materials); ``opacity``:
    per triple, the fraction of light it stops (default: 1, opaque)."""
    rows = [np.zeros(0)]
    kinds = [NONE]
    for name, type_name, values in materials:
        kind = TYPES[type_name]
        try:
            rows.append(kind.row(values))
        except ValueError as exc:  # a value outside its parameter's range (Param.check)
            raise ValueError(f"material '{name}' ({type_name}): {exc}") from None
        kinds.append(kind.code)
    width = max(len(r) for r in rows)
    params = np.zeros((len(rows), max(width, 1)))
    for i, r in enumerate(rows):
        params[i, : len(r)] = r
    sides = [True] + (list(twosided) if twosided is not None else [True] * len(materials))
    stops = [1.0] + (list(opacity) if opacity is not None else [1.0] * len(materials))
    return MaterialTable(np.asarray(kinds, dtype=np.int8), params, ["(none)"] + [m[0] for m in materials],
                         np.asarray(sides, dtype=np.bool_), np.asarray(stops, dtype=np.float64))


def lobes(kind: int) -> int:
    """The lobe flags of material code ``kind`` (0 for the black material)."""
    return BY_CODE[kind].lobes if kind in BY_CODE else 0


@dataclass
class MaterialSample:
    """Result of :meth:`Materials.sample`; every field has one row per lane.

    wi : (n, 3) local unit direction toward the light.
    weight : (n, 3) f |cos theta_i| / pdf, or the lobe's reflectance for a delta sample; 0 if invalid.
    pdf : (n,) solid-angle pdf of ``wi``; 0 for delta samples and invalid ones.
    flags : (n,) int lobe flags of the sampled lobe (0 if invalid).
    """

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    flags: np.ndarray

    @property
    def delta(self) -> np.ndarray:
        return (self.flags & DELTA) != 0


@dataclass
class Materials:
    """Per-lane materials for batch evaluation: lane i has material row ``row[i]`` of ``table``.
    All directions are local ``(n, 3)`` arrays."""

    table: MaterialTable
    row: np.ndarray

    @classmethod
    def uniform(cls, type_name: str, n: int, **values) -> "Materials":
        """n lanes of one material of type ``type_name`` with parameters ``values``."""
        return cls(table([("m", type_name, values)]), np.ones(n, dtype=np.int64))

    @classmethod
    def per_lane(cls, type_names, values: dict[str, np.ndarray]) -> "Materials":
        """Lane i: a material of type ``type_names[i]`` (a sequence, or one name for all lanes)
        with parameters ``values[name][i]`` (``(n,)`` or ``(n, 3)`` arrays; a parameter that a
        lane's type does not have is ignored, one it has and ``values`` lacks takes its default;
        derived columns are computed once per distinct parameter set)."""
        n = len(next(iter(values.values())))
        names = np.broadcast_to(np.asarray(type_names, dtype=object), (n,))
        params = np.zeros((n + 1, max([t.width for t in TYPES.values()])))
        kind = np.zeros(n + 1, dtype=np.int8)
        for type_name in set(names.tolist()):
            t = TYPES[type_name]
            lanes = 1 + np.flatnonzero(names == type_name)
            kind[lanes] = t.code
            if t.derived:  # tables computed from the parameters, once per distinct set
                rows: dict[bytes, np.ndarray] = {}
                for lane in lanes:
                    given = {p.name: np.asarray(values[p.name], dtype=np.float64)[lane - 1]
                             for p in t.params if p.name in values}
                    key = b"".join(np.ascontiguousarray(v).tobytes() for v in given.values())
                    if key not in rows:
                        rows[key] = t.row(given)
                    params[lane, :t.width] = rows[key]
                continue
            for p in t.params:
                column = t.column(p.name)
                given = (np.asarray(values[p.name], dtype=np.float64)[lanes - 1] if p.name in values
                         else np.broadcast_to(np.asarray(p.encode(p.default), dtype=np.float64),
                                              (len(lanes), p.size)))
                params[lanes, column:column + p.size] = given.reshape(len(lanes), p.size)
        return cls(MaterialTable(kind, params, ["(none)"] + [f"lane{i}" for i in range(n)]),
                   np.arange(1, n + 1, dtype=np.int64))

    def take(self, idx: np.ndarray) -> "Materials":
        """The lanes ``idx`` (indices or a boolean mask)."""
        return Materials(self.table, self.row[idx])

    @property
    def delta(self) -> np.ndarray:
        """(n,) bool: every lobe of the lane's material is a delta lobe."""
        lobe = np.array([lobes(int(k)) for k in self.table.kind])[self.row]
        return lobe == DELTA

    def _kernel(self, template):
        """``template`` built for the material types of this table (``tracer.kernels``)."""
        from ..kernels import FeatureSet, build

        names = tuple(BY_CODE[int(k)].name for k in sorted(set(self.table.kind.tolist()))
                      if int(k) in BY_CODE)
        features = FeatureSet(names, (), "power", "independent", None, "sum", False, False, False)
        return build(features).function(template)

    def eval(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """f(wo, wi) without the cosine, ``(n, 3)``; zero below the surface and for delta lobes."""
        return self._kernel(_eval_pdf_lanes)(self.table.kind, self.table.params, self.row, wo, wi)[0]

    def pdf(self, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` picks ``wi``, ``(n,)``; 0 for delta lobes."""
        return self._kernel(_eval_pdf_lanes)(self.table.kind, self.table.params, self.row, wo, wi)[1]

    def sample(self, u: np.ndarray, wo: np.ndarray) -> MaterialSample:
        """Importance-sample ``wi`` given ``wo (n, 3)``, with ``u (n, 3)`` in [0, 1)^3: the lobe
        choice, then the direction. ``u (n, 2)`` (the direction only) is allowed when every
        lane's material has a single lobe."""
        u = np.asarray(u, dtype=np.float64)
        if u.shape[1] == 2:
            lobe_bits = np.array([bin(lobes(int(k))).count("1") for k in self.table.kind])[self.row]
            if np.any(lobe_bits > 1):
                raise ValueError("materials with several lobes need u (n, 3): a lobe choice and a direction")
            u = np.concatenate([np.zeros((len(u), 1)), u], axis=1)
        return MaterialSample(*self._kernel(_sample_lanes)(self.table.kind, self.table.params, self.row,
                                                           wo, u))


@kernel
def _eval_pdf_lanes(kind, params, row, wo, wi):
    n = len(row)
    f, p = np.empty((n, 3)), np.empty(n)
    for i in range(n):
        value, p[i] = dispatch.material_eval_pdf(kind[row[i]], params, row[i], (wo[i, 0], wo[i, 1], wo[i, 2]),
                               (wi[i, 0], wi[i, 1], wi[i, 2]))
        f[i, 0], f[i, 1], f[i, 2] = value
    return f, p


@kernel
def _sample_lanes(kind, params, row, wo, u):
    n = len(row)
    wi, weight, p = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    flags = np.empty(n, dtype=np.int64)
    for i in range(n):
        w, value, p[i], flags[i] = dispatch.material_sample(kind[row[i]], params, row[i],
                                                            (wo[i, 0], wo[i, 1], wo[i, 2]),
                                                            u[i, 0], u[i, 1], u[i, 2])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        weight[i, 0], weight[i, 1], weight[i, 2] = value
    return wi, weight, p, flags


dispatch = UNBOUND  # bound per build (``tracer.kernels``)

__all__ = ["DELTA", "DIFFUSE", "GLOSSY", "NONE", "TYPES", "MaterialSample", "MaterialTable", "MaterialType",
           "Materials", "Param", "lobes", "table"]
