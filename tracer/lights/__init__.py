"""Light techniques behind one interface: choose an emitter, sample it from the shading point.

A light sample is two decisions: which emitter candidate (``selection.py``: by power or
uniformly, Walker's alias table; or by a light BVH, ``bvh.py``, in proportion to an importance
bound at the shading point) and a direction toward it by that candidate's **technique**, which
may depend on the shading point x and its normal n. Every candidate has a technique code
and a row of named columns in one float32 table; the interface, dispatched on the code, is

- :func:`sample` ``(x, n, n_receiver, u) -> (wi, dist, le, pdf, delta)``: the selection
  probability is multiplied into ``pdf`` here, where MIS needs it (pdf in solid angle; for a
  delta light, the selection probability alone);
- :func:`pdf` ``(x, n, n_receiver, hit, wi, dist)``: the pdf with which :func:`sample` would
  produce the direction ``wi`` from ``x`` that hits the emitting primitive ``hit`` at distance
  ``dist``.

``n`` is the geometric normal toward the viewer (the techniques' cosine warp uses it);
``n_receiver`` the shading normal, above which the materials reflect, so that the BVH's
selection may skip lights below it (0: no such bound).

Which technique a candidate gets is the render's **light sampling** (``LIGHT_SAMPLINGS``):

=================  =====================================================================
light sampling     emitting triangle / rectangular quad / analytic sphere
=================  =====================================================================
area               triangle by area (a quad is its two triangles) / sphere by area
solid-angle        spherical triangle / spherical rectangle / cone
solid-angle-cos    the same two warped toward the receiver's cosine / cone
=================  =====================================================================

=========================  ====  ====================================================
technique                  code  module
=========================  ====  ====================================================
triangle_area              0     ``triangle_area.py``: uniform by area, to solid angle
point                      1     ``point.py``: a delta light
sphere_area                2     ``sphere.py``: uniform on the sphere by area
sphere_cone                3     ``sphere.py``: uniform in the subtended cone
spherical_triangle         4     ``triangle_solid_angle.py``: uniform in solid angle
spherical_triangle_cos     5     the same, bilinear warp toward the receiver's cosine
spherical_rectangle        6     ``rectangle.py``: uniform in solid angle
spherical_rectangle_cos    7     the same, bilinear warp toward the receiver's cosine
=========================  ====  ====================================================

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
from ..strategy import LIGHT_SAMPLINGS
from . import bvh, point, rectangle, selection, sphere, triangle_area, triangle_solid_angle
from .bounds import emitter_spheres, may_reach

TECHNIQUES = ("triangle_area", "point", "sphere_area", "sphere_cone", "spherical_triangle",
              "spherical_triangle_cos", "spherical_rectangle", "spherical_rectangle_cos")
(TRIANGLE_AREA, POINT, SPHERE_AREA, SPHERE_CONE, SPHERICAL_TRIANGLE, SPHERICAL_TRIANGLE_COS,
 SPHERICAL_RECTANGLE, SPHERICAL_RECTANGLE_COS) = range(len(TECHNIQUES))
ROW_WIDTH = max(triangle_area.WIDTH, point.WIDTH, sphere.WIDTH, rectangle.WIDTH)
SELECTIONS = ("power", "uniform", "bvh")
# Smallest emitting triangle the light table takes: 1 / area must be finite in float32.
MIN_LIGHT_AREA = float(np.finfo(np.float32).tiny)
# A quad is sampled as a rectangle when its edges are perpendicular to this relative precision
# (|e1 . e2| <= RECTANGLE_TOLERANCE |e1| |e2|); other quads as two triangles.
RECTANGLE_TOLERANCE = 1e-6


class LightTables(NamedTuple):
    """What the per-lane light functions read, for K emitter candidates.

    alias_prob : (K,) float64 and alias : (K,) int64, Walker's table of the selection pmf.
    pmf : (K,) float64 selection probability of each candidate (``bvh``: by power; the BVH's
        own pmf depends on the shading point).
    nodes, child, trail, trail_depth : the light BVH (``bvh.LightTree``); no nodes unless the
        selection is ``bvh``.
    technique : (K,) int8 technique code of each candidate (``TECHNIQUES``).
    rows : (K, ROW_WIDTH) float32, each candidate's parameters in its technique's columns.
        float32 as the scene holds vertices and emission; a row is one 64-byte cache line,
        which light sampling reads at random.
    candidate_of_prim : (F + S,) int32, the candidate that scene primitive p (a triangle, or
        an analytic sphere from F on) belongs to (-1: none), for the pdf of a direction that
        hits it; both triangles of a quad sampled as a rectangle map to its one candidate.
    spheres : (B, 4) float64 bounding spheres (center, radius) of the emitters
        (``bounds.may_reach``).
    """

    alias_prob: np.ndarray
    alias: np.ndarray
    pmf: np.ndarray
    nodes: np.ndarray
    child: np.ndarray
    trail: np.ndarray
    trail_depth: np.ndarray
    technique: np.ndarray
    rows: np.ndarray
    candidate_of_prim: np.ndarray
    spheres: np.ndarray


@jit
def choose(alias_prob, alias, pmf, nodes, child, x, n_receiver, u_select: float):
    """The candidate to sample and its selection probability ``(k, pmf_k)``; ``(-1, 0.0)`` if none
    can light ``x``."""
    if len(nodes) > 0:
        return bvh.choose(nodes, child, x, n_receiver, u_select)
    if len(alias) == 0:
        return -1, 0.0
    k = selection.pick(alias_prob, alias, u_select)
    return k, pmf[k]


@jit
def selection_pmf(pmf, nodes, child, trail, trail_depth, k: int, x, n_receiver) -> float:
    """The probability that :func:`choose` returns candidate ``k`` at ``x``."""
    if len(nodes) > 0:
        return bvh.pmf_of(nodes, child, trail, trail_depth, k, x, n_receiver)
    return pmf[k]


@jit
def sample(alias_prob, alias, pmf, nodes, child, technique, rows, x, n, n_receiver,
           u_select: float, u0: float, u1: float):
    """A light sample for shading point ``x`` with normals ``n`` (geometric) and ``n_receiver``
    (shading; module docstring), from the arrays of ``LightTables`` (kernels pass them one by
    one: reading an array out of a tuple inside a compiled loop costs a reference-count update).
    Returns ``(wi, dist, le, pdf, delta)``:

    wi : world unit direction from x toward the light.   dist : distance to the sampled point.
    le : RGB radiance arriving along wi (area), or I / d^2 (point); the contribution is
        f |cos theta_i| le / pdf. Zero where the sample is invalid.
    pdf : solid-angle pdf including the selection probability; for a delta light, the
        selection probability alone. 0 where invalid.
    delta : a delta light (no other technique can produce this sample).
    """
    k, pmf_k = choose(alias_prob, alias, pmf, nodes, child, x, n_receiver, u_select)
    if k < 0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False
    code = technique[k]
    if code == POINT:
        wi, dist, le = point.sample(rows, k, x)
        return wi, dist, le, (pmf_k if dist > 0.0 else 0.0), True
    if code == TRIANGLE_AREA:
        wi, dist, le, p = triangle_area.sample(rows, k, x, u0, u1)
    elif code == SPHERE_AREA:
        wi, dist, le, p = sphere.sample_area(rows, k, x, u0, u1)
    elif code == SPHERE_CONE:
        wi, dist, le, p = sphere.sample_cone(rows, k, x, u0, u1)
    elif code == SPHERICAL_TRIANGLE or code == SPHERICAL_TRIANGLE_COS:
        wi, dist, le, p = triangle_solid_angle.sample(rows, k, x, n, code == SPHERICAL_TRIANGLE_COS, u0, u1)
    elif code == SPHERICAL_RECTANGLE or code == SPHERICAL_RECTANGLE_COS:
        wi, dist, le, p = rectangle.sample(rows, k, x, n, code == SPHERICAL_RECTANGLE_COS, u0, u1)
    else:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), 0.0, False
    return wi, dist, le, pmf_k * p, False


@jit
def pdf(pmf, nodes, child, trail, trail_depth, technique, rows, candidate_of_prim, x, n, n_receiver,
        prim: int, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks the direction ``wi`` (world) from ``x``
    with normals ``n``, ``n_receiver`` that hits scene primitive ``prim`` at distance ``dist``;
    0 for non-emitters and back sides."""
    k = candidate_of_prim[prim]
    if k < 0:
        return 0.0
    code = technique[k]
    if code == TRIANGLE_AREA:
        p = triangle_area.pdf(rows, k, x, wi, dist)
    elif code == SPHERE_AREA:
        p = sphere.pdf_area(rows, k, x, wi, dist)
    elif code == SPHERE_CONE:
        p = sphere.pdf_cone(rows, k, x, wi, dist)
    elif code == SPHERICAL_TRIANGLE or code == SPHERICAL_TRIANGLE_COS:
        p = triangle_solid_angle.pdf(rows, k, x, n, code == SPHERICAL_TRIANGLE_COS, wi, dist)
    elif code == SPHERICAL_RECTANGLE or code == SPHERICAL_RECTANGLE_COS:
        p = rectangle.pdf(rows, k, x, n, code == SPHERICAL_RECTANGLE_COS, wi, dist)
    else:
        return 0.0
    if not p > 0.0:
        return 0.0
    return selection_pmf(pmf, nodes, child, trail, trail_depth, k, x, n_receiver) * p


def _rectangles(scene, tri: np.ndarray) -> tuple[list[int], np.ndarray]:
    """The emitting quads among ``scene.shapes`` that are rectangles with both triangles in
    ``tri``: their shape indices and ``(Q, 3, 3)`` corner, edge u, edge v, taken from the quad's
    float32 vertices (o, o + e1, o + e1 + e2, o + e2), so that the rectangle sampled is the one
    Embree intersects (float32(o) + float32(e1) can differ from float32(o + e1): a light
    0.00013 wide at x = 1000 was 6% wider that way)."""
    in_table = set(tri.tolist())
    found, frames = [], []
    for index, shape in enumerate(scene.shapes):
        if shape.type != "quad" or shape.count != 2 or not shape.emissive:
            continue
        if shape.first not in in_table or shape.first + 1 not in in_table:
            continue
        first, second = scene.faces[shape.first], scene.faces[shape.first + 1]  # (0, 1, 2), (0, 2, 3)
        corner = scene.vertices[first[0]]
        e1 = scene.vertices[first[1]] - corner
        e2 = scene.vertices[second[2]] - corner
        if abs(np.dot(e1, e2)) <= RECTANGLE_TOLERANCE * np.linalg.norm(e1) * np.linalg.norm(e2):
            found.append(index)
            frames.append([corner, e1, e2])
    return found, np.array(frames, dtype=np.float64).reshape(-1, 3, 3)


def build_tables(scene, light_selection: str = "power",
                 light_sampling: str = "area") -> tuple[LightTables, np.ndarray]:
    """The light tables of ``scene`` (a ``tracer.scene.Scene``), and ``(K,)`` the shape index of
    each candidate (-1 - i for point light i).

    Candidates: every emitting triangle of positive area (under ``solid-angle`` sampling a
    rectangular quad is one candidate instead of two triangles), every emitting analytic
    sphere and every point light of positive intensity; their techniques follow
    ``light_sampling`` (module docstring)."""
    if light_selection not in SELECTIONS:
        raise ValueError(f"light selection must be one of {SELECTIONS}, got {light_selection!r}")
    if light_sampling not in LIGHT_SAMPLINGS:
        raise ValueError(f"light sampling must be one of {LIGHT_SAMPLINGS}, got {light_sampling!r}")
    solid, cos_warp = light_sampling != "area", light_sampling == "solid-angle-cos"
    # Emission is >= 0, so a triangle with area and some positive channel has positive flux.
    # The table holds 1 / area in float32: a triangle smaller than float32's smallest normal
    # number (a sphere of radius 1e-20) would put inf there, so it is left out like a zero-area
    # one (never light-sampled; a BSDF sample that hits it gets weight 1, consistently).
    tri = np.flatnonzero((scene.area >= MIN_LIGHT_AREA) & (scene.emission.max(axis=1, initial=0.0) > 0.0))
    quads, frames = _rectangles(scene, tri) if solid else ([], np.zeros((0, 3, 3)))
    in_quad = np.isin(tri, [scene.shapes[q].first + i for q in quads for i in (0, 1)])
    tri_alone = tri[~in_quad]
    quad_area = np.linalg.norm(np.cross(frames[:, 1], frames[:, 2]), axis=1)
    quad_emission = np.array([scene.shapes[q].emission for q in quads]).reshape(-1, 3)
    sph = np.flatnonzero((scene.sphere_emission.max(axis=1, initial=0.0) > 0.0)
                         & (4.0 * np.pi * scene.spheres[:, 3] ** 2 >= MIN_LIGHT_AREA))
    sphere_area = 4.0 * np.pi * scene.spheres[sph, 3] ** 2
    point_flux = 4.0 * np.pi * scene.point_intensity.mean(axis=1)
    points = np.flatnonzero(point_flux > 0.0)

    flux = np.concatenate([np.pi * scene.area[tri_alone] * scene.emission[tri_alone].mean(axis=1),
                           np.pi * quad_area * quad_emission.mean(axis=1),
                           np.pi * sphere_area * scene.sphere_emission[sph].mean(axis=1), point_flux[points]])
    owner = np.concatenate([scene.shape_of_triangle[tri_alone], np.array(quads, dtype=np.int64),
                            scene.shape_of_sphere[sph], -1 - points]).astype(np.int64)
    weight = selection.weights("power" if light_selection == "bvh" else light_selection, flux, owner,
                               np.concatenate([scene.area[tri_alone], quad_area, sphere_area,
                                               np.ones(len(points))]))
    count = len(weight)
    pmf = weight / weight.sum() if count else weight
    alias_prob, alias = selection.alias_table(pmf)

    rows = np.zeros((count, ROW_WIDTH), dtype=np.float32)
    technique = np.zeros(count, dtype=np.int8)
    first_quad = len(tri_alone)
    first_sphere = first_quad + len(quads)
    first_point = first_sphere + len(sph)
    corners = scene.vertices[scene.faces[tri_alone]]
    rows[:first_quad, :triangle_area.WIDTH] = triangle_area.rows(
        corners, scene.normal[tri_alone], scene.emission[tri_alone], scene.area[tri_alone])
    technique[:first_quad] = (SPHERICAL_TRIANGLE_COS if cos_warp else SPHERICAL_TRIANGLE) if solid \
        else TRIANGLE_AREA
    rows[first_quad:first_sphere, :rectangle.WIDTH] = rectangle.rows(frames, quad_emission)
    technique[first_quad:first_sphere] = SPHERICAL_RECTANGLE_COS if cos_warp else SPHERICAL_RECTANGLE
    rows[first_sphere:first_point, :sphere.WIDTH] = sphere.rows(scene.spheres[sph],
                                                                scene.sphere_emission[sph])
    technique[first_sphere:first_point] = SPHERE_CONE if solid else SPHERE_AREA
    rows[first_point:, :point.WIDTH] = point.rows(scene.point_position[points], scene.point_intensity[points])
    technique[first_point:] = POINT

    first_prim_sphere = len(scene.faces)
    candidate_of_prim = np.full(first_prim_sphere + len(scene.spheres), -1, dtype=np.int32)
    candidate_of_prim[tri_alone] = np.arange(first_quad, dtype=np.int32)
    for i, q in enumerate(quads):
        candidate_of_prim[scene.shapes[q].first:scene.shapes[q].first + 2] = first_quad + i
    candidate_of_prim[first_prim_sphere + sph] = np.arange(first_sphere, first_point, dtype=np.int32)

    # Bounding spheres for the culling of direction rays: one per emissive shape (a rectangle's
    # two triangles bound it exactly).
    spheres = emitter_spheres(scene.vertices[scene.faces[tri]], scene.shape_of_triangle[tri],
                              scene.ray_epsilon, scene.spheres[sph], scene.shape_of_sphere[sph])
    tree = bvh.empty()
    if light_selection == "bvh":
        quad_corners = frames[:, :1] + np.array([0.0, 1.0, 1.0, 0.0])[:, None] * frames[:, 1:2] \
            + np.array([0.0, 0.0, 1.0, 1.0])[:, None] * frames[:, 2:3]
        lo = np.concatenate([corners.min(axis=1), quad_corners.min(axis=1),
                             scene.spheres[sph, :3] - scene.spheres[sph, 3:], scene.point_position[points]])
        hi = np.concatenate([corners.max(axis=1), quad_corners.max(axis=1),
                             scene.spheres[sph, :3] + scene.spheres[sph, 3:], scene.point_position[points]])
        # Triangles and rectangles shine over the front hemisphere of one normal (cone of
        # spread 0); spheres and points in every direction (spread pi). theta_e = 90 deg for all.
        axis = np.zeros((count, 3))
        axis[:, 2] = 1.0
        axis[:first_quad] = scene.normal[tri_alone]
        axis[first_quad:first_sphere] = scene.normal[[scene.shapes[q].first for q in quads]].reshape(-1, 3)
        cos_o = np.where(np.arange(count) < first_sphere, 1.0, -1.0)
        tree = bvh.build(lo, hi, axis, cos_o, np.zeros(count), flux)
    tables = LightTables(alias_prob, alias, pmf, np.ascontiguousarray(tree.nodes), tree.child, tree.trail,
                         tree.trail_depth, technique, np.ascontiguousarray(rows),
                         candidate_of_prim, spheres)
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

    def __init__(self, scene, selection: str = "power", sampling: str = "area"):
        self.scene = scene
        self.selection = selection
        self.sampling = sampling
        self.tables, self.owner = build_tables(scene, selection, sampling)
        self.pmf = self.tables.pmf
        self.count = len(self.pmf)

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray,
               n: np.ndarray | None = None, n_receiver: np.ndarray | None = None) -> LightSample:
        """Sample a light for shading points ``x (n, 3)`` with unit normals ``n (n, 3)`` (used by
        ``solid-angle-cos``; default +z) and ``n_receiver`` (used by ``bvh``; default ``n``);
        ``u_select (n,)``, ``u_point (n, 2)``."""
        normal, receiver = self._normals(x, n, n_receiver)
        return LightSample(*_sample_lanes(self.tables, u_select, u_point, x, normal, receiver))

    def pdf(self, x: np.ndarray, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray,
            n: np.ndarray | None = None, n_receiver: np.ndarray | None = None) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick, from ``x (n, 3)`` with normals
        ``n`` and ``n_receiver`` (as there), the direction ``wi (n, 3)`` that hits primitive
        ``prim (n,)`` at distance ``dist (n,)``; 0 for non-emitters and back sides."""
        normal, receiver = self._normals(x, n, n_receiver)
        return _pdf_lanes(self.tables, x, normal, receiver, prim, wi, dist)

    def choose(self, u_select: np.ndarray, x: np.ndarray, n_receiver: np.ndarray | None = None):
        """The selection alone: ``(candidate (n,) int64, pmf (n,))`` for ``u_select (n,)`` at
        points ``x (n, 3)`` with shading normals ``n_receiver`` (default +z); candidate -1 and
        pmf 0 where no light can reach the point."""
        _, receiver = self._normals(x, None, n_receiver)
        return _choose_lanes(self.tables, u_select, x, receiver)

    def selection_pmf(self, k: np.ndarray, x: np.ndarray, n_receiver: np.ndarray | None = None) -> np.ndarray:
        """``(n,)`` the probability that :meth:`choose` picks candidate ``k[i]`` at ``x[i]``."""
        _, receiver = self._normals(x, None, n_receiver)
        return _selection_pmf_lanes(self.tables, np.asarray(k, dtype=np.int64), x, receiver)

    @staticmethod
    def _normals(x, n, n_receiver):
        normal = np.broadcast_to([0.0, 0.0, 1.0], x.shape) if n is None else n
        return normal, normal if n_receiver is None else n_receiver


@jit
def _sample_lanes(tables, u_select, u_point, x, normal, receiver):
    alias_prob, alias, pmf = tables.alias_prob, tables.alias, tables.pmf
    nodes, child = tables.nodes, tables.child
    technique, rows = tables.technique, tables.rows
    n = len(u_select)
    wi, dist, le = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    p, delta = np.empty(n), np.empty(n, dtype=np.bool_)
    for i in range(n):
        w, dist[i], radiance, p[i], delta[i] = sample(
            alias_prob, alias, pmf, nodes, child, technique, rows,
            (x[i, 0], x[i, 1], x[i, 2]), (normal[i, 0], normal[i, 1], normal[i, 2]),
            (receiver[i, 0], receiver[i, 1], receiver[i, 2]), u_select[i], u_point[i, 0], u_point[i, 1])
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, dist, le, p, delta


@jit
def _pdf_lanes(tables, x, normal, receiver, prim, wi, dist):
    pmf, nodes, child, trail, trail_depth = (tables.pmf, tables.nodes, tables.child, tables.trail,
                                             tables.trail_depth)
    technique, rows, candidate_of_prim = tables.technique, tables.rows, tables.candidate_of_prim
    out = np.empty(len(prim))
    for i in range(len(prim)):
        out[i] = pdf(pmf, nodes, child, trail, trail_depth, technique, rows, candidate_of_prim,
                     (x[i, 0], x[i, 1], x[i, 2]), (normal[i, 0], normal[i, 1], normal[i, 2]),
                     (receiver[i, 0], receiver[i, 1], receiver[i, 2]), prim[i],
                     (wi[i, 0], wi[i, 1], wi[i, 2]), dist[i])
    return out


@jit
def _choose_lanes(tables, u_select, x, receiver):
    alias_prob, alias, pmf = tables.alias_prob, tables.alias, tables.pmf
    nodes, child = tables.nodes, tables.child
    k, p = np.empty(len(u_select), dtype=np.int64), np.empty(len(u_select))
    for i in range(len(u_select)):
        k[i], p[i] = choose(alias_prob, alias, pmf, nodes, child, (x[i, 0], x[i, 1], x[i, 2]),
                            (receiver[i, 0], receiver[i, 1], receiver[i, 2]), u_select[i])
    return k, p


@jit
def _selection_pmf_lanes(tables, k, x, receiver):
    pmf, nodes, child, trail, trail_depth = (tables.pmf, tables.nodes, tables.child, tables.trail,
                                             tables.trail_depth)
    out = np.empty(len(k))
    for i in range(len(k)):
        out[i] = selection_pmf(pmf, nodes, child, trail, trail_depth, k[i], (x[i, 0], x[i, 1], x[i, 2]),
                               (receiver[i, 0], receiver[i, 1], receiver[i, 2]))
    return out


__all__ = ["LIGHT_SAMPLINGS", "POINT", "SELECTIONS", "TECHNIQUES", "TRIANGLE_AREA", "LightSample",
           "LightSampler", "LightTables",
           "build_tables", "may_reach", "pdf", "sample"]
