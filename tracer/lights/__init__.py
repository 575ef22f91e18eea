"""Light sampling: choose an emitter candidate, then sample a direction toward it.

A light sample is two decisions, each a plug-in (``tracer.plugins``): which emitter candidate
(the render's **light selection**, ``tracer.lights.selections``: ``power``, ``uniform``,
``bvh``) and a direction toward it by that candidate's **light technique**
(``tracer.lights.techniques``), which may depend on the shading point x and its normal n.
Which technique a candidate gets follows its emitter kind (``tracer.lights.emitters``) and the
render's **light sampling** (``--light-sampling``): each technique lists the samplings and
emitter kinds it serves (``area``: triangles and spheres by area; ``solid-angle``: spherical
triangles, spherical rectangles, cones; ``solid-angle-cos``: the first two warped toward the
receiver's cosine). A quad is a rectangle candidate only where the light sampling has a
technique for rectangles; else its two triangles are candidates. A triangle of an emitter whose
radiance is a texture is a ``textured_triangle`` candidate where the light sampling has a
technique for those (``area``: ``triangle_texels``, a point by area x the texture's luminance,
``tracer.lights.textured_area``); else a triangle like the others.

Compiled, per lane (templates, built per feature set by ``tracer.kernels``; ``dispatch`` holds
the render's selection and a generated chain over its techniques):

- :func:`sample` ``(lights, x, n, n_receiver, u_select, u0, u1) -> (wi, dist, le, pdf, delta)``:
  the selection probability is multiplied into ``pdf`` here, where MIS needs it (pdf in solid
  angle; for a delta light, the selection probability alone);
- :func:`pdf` ``(lights, x, n, n_receiver, prim, wi, dist)``: the pdf with which :func:`sample`
  would produce the direction ``wi`` from ``x`` that hits the emitting primitive ``prim`` at
  distance ``dist``; :func:`pdf_environment` that of a direction that escapes the scene.

The environment (``tracer.lights.environment``) is the last candidate when the scene has one;
it has no technique plug-in (code -1): ``sample_with`` samples it by its own table, and its
samples have ``dist`` = inf (shadow rays to infinity).

``n`` is the geometric normal toward the viewer (the techniques' cosine warp uses it);
``n_receiver`` the shading normal, above which the materials reflect, so that the BVH's
selection may skip lights below it (0: no such bound).

:func:`build_tables` builds a scene's :class:`LightTables` for a selection and a sampling;
:class:`LightSampler` runs the compiled code over batches of lanes (tests, tools).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from .. import notices, plugins
from ..kernels import UNBOUND, kernel, template
from . import emitters
from . import environment as environment_light
from .bounds import emitter_spheres, may_reach

# The widest row any technique writes: one 64-byte cache line of float32.
ROW_WIDTH = plugins.LIGHT_ROW_WIDTH
# The share of the light table (``projected_images.MAX_TABLE_FLOATS``, 2^24 floats) textured
# emitters' distributions may take; beyond, they are sampled by area (``build_tables``).
TEXEL_TABLE_FLOATS = 3 * 2**22
# Bound per build (``tracer.kernels``): the scene has an environment; it is light-sampled by
# product with the shading point's lobe (``environment_product``).
ENVIRONMENT = PRODUCT = False
# The lobe argument of a light sample that has none (no product sampling), of the same types.
NO_LOBE = ((0.0, 0.0, 1.0), (0.0, 0.0, 1.0), 0.0, 0.0, 1.0, 1.0, 0.0)


def light_samplings() -> tuple[str, ...]:
    """The light samplings a render may ask for: every name a registered technique lists (point
    lights' "*" serves them all), a user's plug-ins included."""
    return tuple(dict.fromkeys(s for t in plugins.registry("light_technique").values()
                               for s in t.light_samplings if s != "*"))


def __getattr__(name: str):
    # PEP 562: ``LIGHT_SAMPLINGS`` and ``SELECTIONS`` follow the registries, so a plug-in
    # registered after this module was imported is offered too.
    if name == "LIGHT_SAMPLINGS":
        return light_samplings()
    if name == "SELECTIONS":
        return plugins.names("light_selection")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class LightTables(NamedTuple):
    """What the per-lane light functions read, for K emitter candidates.

    selection : the selection's tables (``tracer.lights.selections``), with ``pmf (K,)``.
    technique : (K,) int8 technique code of each candidate (``tracer.lights.techniques``).
    rows : (K + A, ROW_WIDTH) float32, each candidate's parameters in its technique's columns,
        then A rows that candidates link to (a point light's image: ``point.appendix``; a textured
        triangle's distribution: ``triangle_texels.appendix``).
        float32 as the scene holds vertices and emission; a row is one 64-byte cache line,
        which light sampling reads at random.
    candidate_of_prim : (F + S,) int32, the candidate that scene primitive p (a triangle, or
        an analytic sphere from F on) belongs to (-1: none), for the pdf of a direction that
        hits it; both triangles of a quad sampled as a rectangle map to its one candidate.
    spheres : (B, 4) float64 bounding spheres (center, radius) of the emitters
        (``bounds.may_reach``).
    environment : the environment's table (``environment.EnvironmentTable``; its
        ``candidate`` -1 without one).
    prims : (K, 2) int32, the scene primitives each candidate covers (a rectangle: its two
        triangles; a triangle or a sphere: one, then -1; the others: -1, -1), for the value of
        a textured emitter at a sampled point (``tracer.textures.lookup.sampled_emission``).
    """

    selection: Any
    technique: np.ndarray
    rows: np.ndarray
    candidate_of_prim: np.ndarray
    spheres: np.ndarray
    environment: Any
    prims: np.ndarray


@template
def sample(lights, x, n, n_receiver, u_select: float, u0: float, u1: float):
    """A light sample for shading point ``x`` with normals ``n`` (geometric) and ``n_receiver``
    (shading; module docstring): ``(wi, dist, le, pdf, delta)``.

    wi : world unit direction from x toward the light.   dist : distance to the sampled point.
    le : RGB radiance arriving along wi (area), or I / d^2 (point); the contribution is
        f |cos theta_i| le / pdf. Zero where the sample is invalid.
    pdf : solid-angle pdf including the selection probability; for a delta light, the
        selection probability alone. 0 where invalid.
    delta : a delta light (no other technique can produce this sample).
    """
    wi, dist, le, p, delta, _ = sample_with(lights.selection, lights.technique, lights.rows,
                                            lights.environment, x, n, n_receiver, u_select, u0, u1, NO_LOBE)
    return wi, dist, le, p, delta


@template
def sample_with(selection, technique, rows, environment, x, n, n_receiver, u_select: float, u0: float,
                u1: float, lobe):
    """:func:`sample` with the tables' parts read beforehand, and the candidate sampled last
    (-1 if none): ``(wi, dist, le, pdf, delta, k)``. ``lobe`` is the shading point's lobe
    proxy in the map's frame where the environment is sampled by product
    (``environment_product.lobe_in_map``; else ``NO_LOBE``, unread). A per-lane loop reads the parts once,
    before it starts. Each read of an array through a tuple costs a reference-count update
    (numba), and reading ``lights.selection``, ``.technique`` and ``.rows`` per light sample cost
    ``shade`` 30% on ``veach_mis`` (1.13 s against 0.80 s for 512 x 512 x 16 lanes, one thread)."""
    k, pmf_k = dispatch.choose(selection, x, n_receiver, u_select)
    if k < 0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False, k
    if ENVIRONMENT and k == environment.candidate:
        if PRODUCT:
            wi, le, p = environment_light.sample_product(environment, lobe, u0, u1)
        else:
            wi, le, p = environment_light.sample(environment, u0, u1)
        return wi, math.inf, le, pmf_k * p, False, k
    wi, dist, le, p, delta = dispatch.technique_sample(technique[k], rows, k, x, n, u0, u1)
    return wi, dist, le, pmf_k * p, delta, k


@template
def pdf(lights, x, n, n_receiver, prim: int, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks the direction ``wi`` (world) from ``x``
    with normals ``n``, ``n_receiver`` that hits scene primitive ``prim`` at distance ``dist``;
    0 for non-emitters and back sides."""
    k = lights.candidate_of_prim[prim]
    if k < 0:
        return 0.0
    p = dispatch.technique_pdf(lights.technique[k], lights.rows, k, x, n, wi, dist)
    if not p > 0.0:
        return 0.0
    return dispatch.selection_pmf(lights.selection, k, x, n_receiver) * p


@template
def pdf_environment(lights, x, n_receiver, wi, p_product: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks the direction ``wi`` (world) from ``x``
    when the ray along it escapes to the environment; 0 without a sampled environment. Under
    product sampling, ``p_product`` is the environment's own pdf of ``wi`` at that shading point
    (``environment.pdf_product``, which needs its lobe), else unread."""
    k = lights.environment.candidate
    if k < 0:
        return 0.0
    p = p_product if PRODUCT else environment_light.pdf(lights.environment, wi)
    if not p > 0.0:
        return 0.0
    return dispatch.selection_pmf(lights.selection, k, x, n_receiver) * p


def techniques_for(light_sampling: str) -> dict[str, plugins.LightTechnique]:
    """Emitter kind -> the technique that samples it under ``light_sampling`` (kinds without one,
    rectangles under ``area``, are absent: their emitters are candidates of another kind)."""
    offered = light_samplings()
    if light_sampling not in offered:
        raise ValueError(f"light sampling must be one of {offered}, got {light_sampling!r}")
    chosen: dict[str, plugins.LightTechnique] = {}
    for technique in plugins.registry("light_technique").values():
        if light_sampling in technique.light_samplings or "*" in technique.light_samplings:
            for kind in technique.emitters:
                chosen.setdefault(kind, technique)
    return chosen


def _triangle_records(scene, tri: np.ndarray, texels: np.ndarray, chosen: dict) -> dict:
    """The ``triangle``, ``textured_triangle`` and ``rectangle`` records of the emitting
    triangles ``tri``: those where ``texels`` go to the technique for textured triangles, then
    quads to one for rectangles where the light sampling has one, the rest as triangles."""
    rest = tri[~texels]
    rectangles = (emitters.rectangles(scene, rest) if "rectangle" in chosen
                  else emitters.rectangles(scene, rest[:0]))
    in_rectangle = (np.isin(rest, np.concatenate(rectangles.prims)) if len(rectangles)
                    else np.zeros(len(rest), bool))
    return {"triangle": emitters.triangles(scene, rest[~in_rectangle]),
            "textured_triangle": emitters.textured_triangles(scene, tri[texels]), "rectangle": rectangles}


def build_tables(scene, light_selection: str = "power", light_sampling: str = "area",
                 environment_sampling: str = "luminance") -> tuple[LightTables, np.ndarray, str]:
    """The light tables of ``scene`` (a ``tracer.scene.Scene``), ``(K,)`` the shape index of
    each candidate (-1 - i for point light i), and the selection the tables are for:
    ``light_selection``, or the cheaper one it runs as on these candidates (its ``runs_as``,
    ``tracer.lights.selections``).

    Candidates (``tracer.lights.emitters``): every emitting triangle of positive area (a
    textured one is a ``textured_triangle`` where the light sampling has a technique for those;
    a rectangular quad is one candidate instead of two triangles where it has one for
    rectangles), every emitting analytic sphere and every point light of positive intensity,
    in that order; their techniques follow ``light_sampling``, the environment's
    ``environment_sampling`` (``tracer.strategy.ENVIRONMENT_SAMPLINGS``)."""
    selection = plugins.get("light_selection", light_selection)
    chosen = techniques_for(light_sampling)
    tri = emitters.emitting_triangles(scene)
    texels = (emitters.texel_sampled(scene, tri) if "textured_triangle" in chosen
              else np.zeros(len(tri), bool))
    records = _triangle_records(scene, tri, texels, chosen)
    textured = records["textured_triangle"]
    if len(textured) and hasattr(chosen["textured_triangle"].functions(), "table_floats") and \
            chosen["textured_triangle"].functions().table_floats(textured) > TEXEL_TABLE_FLOATS:
        notices.note(f"the textured emitters' {len(textured):,} triangles would take more of the light table "
                     "than it holds for them: sampled by area, not by their textures")
        records = _triangle_records(scene, tri, np.zeros(len(tri), bool), chosen)
    records.update(sphere=emitters.spheres(scene), point=emitters.points(scene),
                   directional=emitters.directionals(scene), environment=emitters.environment(scene))
    ordered = [records[kind] for kind in emitters.KINDS]
    count = sum(len(r) for r in ordered)
    rows = np.zeros((count, ROW_WIDTH), dtype=np.float32)
    technique = np.zeros(count, dtype=np.int8)
    candidate_of_prim = np.full(len(scene.faces) + len(scene.spheres), -1, dtype=np.int32)
    prims = np.full((count, 2), -1, dtype=np.int32)
    first = 0
    appended: list[np.ndarray] = []
    environment_candidate = -1
    for kind, record in zip(emitters.KINDS, ordered, strict=True):
        if not len(record):
            continue
        if kind == "environment":  # sampled by its own table: no technique, no primitives
            technique[first] = -1
            environment_candidate = first
            first += 1
            continue
        plugin = chosen.get(kind)
        if plugin is None:
            raise ValueError(f"light sampling {light_sampling!r} has no technique for the scene's "
                             f"{kind} emitters "
                             f"(it serves {', '.join(sorted(chosen)) or 'none'})")
        functions = plugin.functions()
        block = functions.rows(record)
        rows[first:first + len(record), :block.shape[1]] = block
        if hasattr(functions, "appendix"):  # rows after the candidates' (a light's image)
            link, extra, column = functions.appendix(record, count + sum(len(a) for a in appended))
            rows[first:first + len(record), column] = link
            appended.append(extra)
        technique[first:first + len(record)] = plugin.code
        for column, covered in enumerate(record.prims):
            candidate_of_prim[covered] = np.arange(first, first + len(record), dtype=np.int32)
            prims[first:first + len(record), column] = covered
        first += len(record)
    candidates = emitters.Candidates.of(ordered)
    tables = selection.functions().tables(candidates)
    ran = getattr(selection.functions(), "runs_as", lambda _: None)(tables) or light_selection
    if ran != light_selection:
        tables = plugins.get("light_selection", ran).functions().tables(candidates)
    # Bounding spheres for the culling of direction rays: one per emissive shape (a rectangle's
    # two triangles bound it exactly).
    spheres = emitter_spheres(scene.vertices[scene.faces[tri]], scene.shape_of_triangle[tri],
                              scene.ray_epsilon, records["sphere"].spheres, records["sphere"].owner)
    environment = environment_light.table(scene.environment, environment_candidate, environment_sampling)
    rows = np.concatenate([rows, *appended]) if appended else rows
    return LightTables(tables, technique, np.ascontiguousarray(rows), candidate_of_prim, spheres,
                       environment, prims), candidates.owner, ran


def technique_names(tables: LightTables) -> tuple[str, ...]:
    """The names of the techniques the candidates of ``tables`` use, by code (the environment,
    code -1, has none)."""
    by_code = plugins.by_code("light_technique")
    return tuple(by_code[c].name for c in sorted(set(tables.technique.tolist())) if c >= 0)


@dataclass
class LightSample:
    """One light sample per lane.

    wi : (n, 3) world unit direction from the shading point toward the light.
    dist : (n,) distance to the sampled point.
    radiance : (n, 3) Le arriving along ``wi`` (area), or I / d^2 (point): the estimator's
        contribution is f |cos theta_i| radiance / pdf. 0 where the sample is invalid. For a
        textured emitter, the technique's constant (its texture's mean over the candidate's
        footprint, ``tracer.lights.textured_area``): the estimator looks the texture up at
        the sampled point (``tracer.textures.lookup.sampled_emission``).
    pdf : (n,) solid-angle pdf including the selection probability; for a point light, its
        selection probability alone. 0 where invalid.
    delta : (n,) bool, a delta light (no other technique can produce this sample).
    """

    wi: np.ndarray
    dist: np.ndarray
    radiance: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray


class LightSampler:
    """The emitters of a scene with their selection distribution, for batches of lanes.

    tables : the ``LightTables`` the kernels read.   owner : (K,) shape index of each
    candidate (-1 - i for point light i).   pmf : (K,) selection probabilities by power (the
    ``bvh`` selection's depend on the point).   requested : the selection asked for.
    selection : the one the tables are for and the kernels run (``build_tables``).
    """

    def __init__(self, scene, selection: str = "power", sampling: str = "area",
                 environment_sampling: str = "luminance"):
        self.scene = scene
        self.requested = selection
        self.sampling = sampling
        self.tables, self.owner, self.selection = build_tables(scene, selection, sampling, environment_sampling)
        self.pmf = self.tables.selection.pmf
        self.count = len(self.pmf)

    def kernel(self, t):
        """Template ``t`` built for this sampler's selection and techniques (``tracer.kernels``)."""
        from ..kernels import FeatureSet, build

        features = FeatureSet((), technique_names(self.tables), self.selection, "independent", None, "sum",
                              True, False, False, environment=self.tables.environment.candidate >= 0)
        return build(features).function(t)

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray,
               n: np.ndarray | None = None, n_receiver: np.ndarray | None = None) -> LightSample:
        """Sample a light for shading points ``x (n, 3)`` with unit normals ``n (n, 3)`` (used by
        ``solid-angle-cos``; default +z) and ``n_receiver`` (used by ``bvh``; default ``n``);
        ``u_select (n,)``, ``u_point (n, 2)``."""
        normal, receiver = self._normals(x, n, n_receiver)
        return LightSample(*self.kernel(_sample_lanes)(self.tables, u_select, u_point, x, normal, receiver))

    def pdf(self, x: np.ndarray, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray,
            n: np.ndarray | None = None, n_receiver: np.ndarray | None = None) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick, from ``x (n, 3)`` with normals
        ``n`` and ``n_receiver`` (as there), the direction ``wi (n, 3)`` that hits primitive
        ``prim (n,)`` at distance ``dist (n,)``; 0 for non-emitters and back sides."""
        normal, receiver = self._normals(x, n, n_receiver)
        return self.kernel(_pdf_lanes)(self.tables, x, normal, receiver, prim, wi, dist)

    def choose(self, u_select: np.ndarray, x: np.ndarray, n_receiver: np.ndarray | None = None):
        """The selection alone: ``(candidate (n,) int64, pmf (n,))`` for ``u_select (n,)`` at
        points ``x (n, 3)`` with shading normals ``n_receiver`` (default +z); candidate -1 and
        pmf 0 where no light can reach the point."""
        _, receiver = self._normals(x, None, n_receiver)
        return self.kernel(_choose_lanes)(self.tables, u_select, x, receiver)

    def selection_pmf(self, k: np.ndarray, x: np.ndarray, n_receiver: np.ndarray | None = None) -> np.ndarray:
        """``(n,)`` the probability that :meth:`choose` picks candidate ``k[i]`` at ``x[i]``."""
        _, receiver = self._normals(x, None, n_receiver)
        return self.kernel(_selection_pmf_lanes)(self.tables, np.asarray(k, dtype=np.int64), x, receiver)

    @staticmethod
    def _normals(x, n, n_receiver):
        normal = np.broadcast_to([0.0, 0.0, 1.0], x.shape) if n is None else n
        return normal, normal if n_receiver is None else n_receiver


@kernel
def _sample_lanes(tables, u_select, u_point, x, normal, receiver):
    n = len(u_select)
    wi, dist, le = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    p, delta = np.empty(n), np.empty(n, dtype=np.bool_)
    for i in range(n):
        w, dist[i], radiance, p[i], delta[i] = sample(
            tables, (x[i, 0], x[i, 1], x[i, 2]), (normal[i, 0], normal[i, 1], normal[i, 2]),
            (receiver[i, 0], receiver[i, 1], receiver[i, 2]), u_select[i], u_point[i, 0], u_point[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, dist, le, p, delta


@kernel
def _pdf_lanes(tables, x, normal, receiver, prim, wi, dist):
    out = np.empty(len(prim))
    for i in range(len(prim)):
        out[i] = pdf(tables, (x[i, 0], x[i, 1], x[i, 2]), (normal[i, 0], normal[i, 1], normal[i, 2]),
                     (receiver[i, 0], receiver[i, 1], receiver[i, 2]), prim[i],
                     (wi[i, 0], wi[i, 1], wi[i, 2]), dist[i])
    return out


@kernel
def _choose_lanes(tables, u_select, x, receiver):
    k, p = np.empty(len(u_select), dtype=np.int64), np.empty(len(u_select))
    for i in range(len(u_select)):
        k[i], p[i] = dispatch.choose(tables.selection, (x[i, 0], x[i, 1], x[i, 2]),
                                     (receiver[i, 0], receiver[i, 1], receiver[i, 2]), u_select[i])
    return k, p


@kernel
def _selection_pmf_lanes(tables, k, x, receiver):
    out = np.empty(len(k))
    for i in range(len(k)):
        out[i] = dispatch.selection_pmf(tables.selection, k[i], (x[i, 0], x[i, 1], x[i, 2]),
                                        (receiver[i, 0], receiver[i, 1], receiver[i, 2]))
    return out


dispatch = UNBOUND  # bound per build (``tracer.kernels``)

__all__ = ["LIGHT_SAMPLINGS", "ROW_WIDTH", "SELECTIONS", "LightSample", "LightSampler", "LightTables",
           "build_tables", "may_reach", "pdf", "pdf_environment", "sample", "technique_names"]
