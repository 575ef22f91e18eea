"""Light techniques behind one interface: choose an emitter, sample it from the shading point.

A light sample is two decisions: which emitter candidate (``selection.py``: by power or
uniformly, Walker's alias table) and a direction toward it by that candidate's **technique**,
which may depend on the shading point x and its normal n (cone sampling of spheres and
spherical triangles will). Every candidate has a technique code and a row of named columns in
one float32 table; the interface, dispatched on the code, is

- :func:`sample` ``(x, n, u) -> (wi, dist, le, pdf, delta)``: the selection probability is
  multiplied into ``pdf`` here, where MIS needs it (pdf in solid angle; for a delta light,
  the selection probability alone);
- :func:`pdf` ``(x, hit, wi)``: the pdf with which :func:`sample` would produce the direction
  ``wi`` from ``x`` that hits the emitting triangle ``hit`` at distance ``dist``.

=================  ====  ===================================================
technique          code  module
=================  ====  ===================================================
triangle_area      0     ``triangle_area.py``: uniform by area, converted to solid angle
point              1     ``point.py``: a delta light
=================  ====  ===================================================

Adding a technique: a module with ``NAME``, its column layout, ``sample`` (and ``pdf`` if it
can be hit by a ray); a code in ``TECHNIQUES``; a branch in :func:`sample` and :func:`pdf`;
and the choice of which emitters use it in :func:`build_tables`.

:class:`LightSampler` builds the tables once per scene and runs the same compiled code over
batches of lanes (tests, tools).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..jit import jit
from . import point, selection, triangle_area
from .bounds import emitter_spheres, may_reach

TECHNIQUES = (triangle_area.NAME, point.NAME)  # the code of a technique is its index here
TRIANGLE_AREA, POINT = 0, 1
ROW_WIDTH = max(triangle_area.WIDTH, point.WIDTH)
SELECTIONS = ("power", "uniform")
# Smallest emitting triangle the light table takes: 1 / area must be finite in float32.
MIN_LIGHT_AREA = float(np.finfo(np.float32).tiny)


class LightTables(NamedTuple):
    """What the per-lane light functions read, for K emitter candidates.

    alias_prob : (K,) float64 and alias : (K,) int64, Walker's table of the selection pmf.
    pmf : (K,) float64 selection probability of each candidate.
    technique : (K,) int8 technique code of each candidate (``TECHNIQUES``).
    rows : (K, ROW_WIDTH) float32, each candidate's parameters in its technique's columns.
        float32 as the scene holds vertices and emission; a row is one 64-byte cache line,
        which light sampling reads at random.
    candidate_of_triangle : (F,) int32, the candidate that is scene triangle f (-1: none),
        for the pdf of a direction that hits it.
    spheres : (S, 4) float64 bounding spheres (center, radius) of the emitting triangles
        (``bounds.may_reach``).
    """

    alias_prob: np.ndarray
    alias: np.ndarray
    pmf: np.ndarray
    technique: np.ndarray
    rows: np.ndarray
    candidate_of_triangle: np.ndarray
    spheres: np.ndarray


@jit
def sample(alias_prob, alias, pmf, technique, rows, x, n, u_select: float, u0: float, u1: float):
    """A light sample for shading point ``x`` with normal ``n`` (world), from the arrays of
    ``LightTables`` (kernels pass them one by one: reading an array out of a tuple inside a
    compiled loop costs a reference-count update). Returns ``(wi, dist, le, pdf, delta)``:

    wi : world unit direction from x toward the light.   dist : distance to the sampled point.
    le : RGB radiance arriving along wi (area), or I / d^2 (point); the contribution is
        f |cos theta_i| le / pdf. Zero where the sample is invalid.
    pdf : solid-angle pdf including the selection probability; for a delta light, the
        selection probability alone. 0 where invalid.
    delta : a delta light (no other technique can produce this sample).
    """
    if len(alias) == 0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False
    k = selection.pick(alias_prob, alias, u_select)
    code = technique[k]
    if code == TRIANGLE_AREA:
        wi, dist, le, p = triangle_area.sample(rows, k, x, u0, u1)
        return wi, dist, le, pmf[k] * p, False
    if code == POINT:
        wi, dist, le = point.sample(rows, k, x)
        return wi, dist, le, (pmf[k] if dist > 0.0 else 0.0), True
    return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False


@jit
def pdf(pmf, technique, rows, candidate_of_triangle, x, prim: int, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks the direction ``wi`` (world) from ``x``
    that hits scene triangle ``prim`` at distance ``dist``; 0 for non-emitters and back sides."""
    k = candidate_of_triangle[prim]
    if k < 0:
        return 0.0
    if technique[k] == TRIANGLE_AREA:
        return pmf[k] * triangle_area.pdf(rows, k, x, wi, dist)
    return 0.0


def build_tables(scene, light_selection: str = "power") -> tuple[LightTables, np.ndarray]:
    """The light tables of ``scene`` (a ``tracer.scene.Scene``), and ``(K,)`` the shape index of
    each candidate (-1 - i for point light i). Every emitting triangle of positive area is a
    ``triangle_area`` candidate, every point light of positive intensity a ``point`` one."""
    if light_selection not in SELECTIONS:
        raise ValueError(f"light selection must be one of {SELECTIONS}, got {light_selection!r}")
    # Emission is >= 0, so a triangle with area and some positive channel has positive flux.
    # The table holds 1 / area in float32: a triangle smaller than float32's smallest normal
    # number (a sphere of radius 1e-20) would put inf there, so it is left out like a zero-area
    # one (never light-sampled; a BSDF sample that hits it gets weight 1, consistently).
    tri = np.flatnonzero((scene.area >= MIN_LIGHT_AREA) & (scene.emission.max(axis=1, initial=0.0) > 0.0))
    tri_flux = np.pi * scene.area[tri] * scene.emission[tri].mean(axis=1)
    point_flux = 4.0 * np.pi * scene.point_intensity.mean(axis=1)
    points = np.flatnonzero(point_flux > 0.0)
    owner = np.concatenate([scene.shape_of_triangle[tri], -1 - points]).astype(np.int64)
    weight = selection.weights(light_selection, np.concatenate([tri_flux, point_flux[points]]), owner,
                               np.concatenate([scene.area[tri], np.ones(len(points))]))
    count = len(weight)
    pmf = weight / weight.sum() if count else weight
    alias_prob, alias = selection.alias_table(pmf)
    rows = np.zeros((count, ROW_WIDTH), dtype=np.float32)
    corners = scene.vertices[scene.faces[tri]]
    rows[: len(tri), : triangle_area.WIDTH] = triangle_area.rows(corners, scene.normal[tri],
                                                                 scene.emission[tri], scene.area[tri])
    rows[len(tri):, : point.WIDTH] = point.rows(scene.point_position[points], scene.point_intensity[points])
    technique = np.array([TRIANGLE_AREA] * len(tri) + [POINT] * len(points), dtype=np.int8)
    candidate_of_triangle = np.full(len(scene.faces), -1, dtype=np.int32)
    candidate_of_triangle[tri] = np.arange(len(tri), dtype=np.int32)
    spheres = emitter_spheres(corners, scene.shape_of_triangle[tri], scene.ray_epsilon)
    tables = LightTables(alias_prob, alias, pmf, technique, np.ascontiguousarray(rows),
                         candidate_of_triangle, spheres)
    return tables, owner


@dataclass
class LightSample:
    """One light sample per lane.

    wi : (n, 3) world unit direction from the shading point toward the light.
    dist : (n,) distance to the sampled point.
    radiance : (n, 3) Le arriving along ``wi`` (area), or I / d^2 (point): the estimator's
        contribution is f |cos theta_i| radiance / pdf. 0 where the sample is invalid.
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
    candidate (-1 - i for point light i).   pmf : (K,) selection probabilities.
    """

    def __init__(self, scene, selection: str = "power"):
        self.scene = scene
        self.selection = selection
        self.tables, self.owner = build_tables(scene, selection)
        self.pmf = self.tables.pmf
        self.count = len(self.pmf)

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray,
               n: np.ndarray | None = None) -> LightSample:
        """Sample a light for shading points ``x (n, 3)`` with normals ``n (n, 3)`` (unused by
        today's techniques; default +z); ``u_select (n,)``, ``u_point (n, 2)``."""
        normal = np.broadcast_to([0.0, 0.0, 1.0], x.shape) if n is None else n
        return LightSample(*_sample_lanes(self.tables, u_select, u_point, x, normal))

    def pdf(self, x: np.ndarray, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick, from ``x (n, 3)``, the direction
        ``wi (n, 3)`` that hits triangle ``prim (n,)`` at distance ``dist (n,)``; 0 for
        non-emitters and back sides."""
        return _pdf_lanes(self.tables, x, prim, wi, dist)


@jit
def _sample_lanes(tables, u_select, u_point, x, normal):
    alias_prob, alias, pmf = tables.alias_prob, tables.alias, tables.pmf
    technique, rows = tables.technique, tables.rows
    n = len(u_select)
    wi, dist, le = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    p, delta = np.empty(n), np.empty(n, dtype=np.bool_)
    for i in range(n):
        xi = (x[i, 0], x[i, 1], x[i, 2])
        ni = (normal[i, 0], normal[i, 1], normal[i, 2])
        w, dist[i], radiance, p[i], delta[i] = sample(alias_prob, alias, pmf, technique, rows, xi, ni,
                                                      u_select[i], u_point[i, 0], u_point[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, dist, le, p, delta


@jit
def _pdf_lanes(tables, x, prim, wi, dist):
    pmf, technique, rows, candidate_of_triangle = tables.pmf, tables.technique, tables.rows, \
        tables.candidate_of_triangle
    out = np.empty(len(prim))
    for i in range(len(prim)):
        out[i] = pdf(pmf, technique, rows, candidate_of_triangle, (x[i, 0], x[i, 1], x[i, 2]), prim[i],
                     (wi[i, 0], wi[i, 1], wi[i, 2]), dist[i])
    return out


__all__ = ["POINT", "SELECTIONS", "TECHNIQUES", "TRIANGLE_AREA", "LightSample", "LightSampler", "LightTables",
           "build_tables", "may_reach", "pdf", "sample"]
