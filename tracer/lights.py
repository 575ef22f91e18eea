"""Light sampling: pick an emitter, pick a point on it, express the pdf in solid angle.

Emitters are the emissive triangles of area lights (front side only) and point lights
(delta). One discrete distribution covers them all:

- ``power`` (default): each candidate in proportion to the flux it emits, pi * area * mean(Le)
  for a triangle and 4 pi * mean(I) for a point light, so bright lights get more samples;
- ``uniform``: each light (an emissive shape or a point light) equally likely, then a triangle
  of that shape in proportion to its area.

For an area light the solid-angle pdf of the direction toward point y on triangle t is
p_w = P(t) / area(t) * d^2 / |cos theta_light| (pbrt-v4 section 12.2). The selection
probability is multiplied in here, where it belongs, so MIS sees the full light pdf.

The per-lane functions ``sample`` and ``pdf`` are compiled (``tracer.jit``) for the
estimator's kernels and read the flat tables of ``LightTables``; ``LightSampler`` builds those
tables once per scene and runs the same code over batches (tests, tools).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import warp
from .jit import jit
from .scene import Scene

SELECTIONS = ("power", "uniform")


@dataclass
class LightSample:
    """One light sample per lane.

    wi : (n, 3) world unit direction from the shading point toward the light.
    dist : (n,) distance to the sampled point.
    radiance : (n, 3) Le arriving along ``wi`` (area), or I / d^2 (point): the estimator's
        contribution is f |cos theta_i| radiance / pdf. 0 where the sample is invalid.
    pdf : (n,) solid-angle pdf including the selection probability; for a point light, its
        selection probability alone. 0 where invalid.
    delta : (n,) bool, a point light (no other technique can produce this sample).
    """

    wi: np.ndarray
    dist: np.ndarray
    radiance: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray


def _alias_table(pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Walker's alias table for ``pmf (K,)`` by Vose's stable construction (Vose 1991): column k
    keeps itself with probability prob[k] and otherwise gives its alias."""
    k = len(pmf)
    prob = np.ones(k)
    alias = np.arange(k)
    if k == 0:
        return prob, alias
    scaled = pmf * k
    small = [i for i in range(k) if scaled[i] < 1.0]
    large = [i for i in range(k) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        prob[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    # What remains is 1 up to rounding: keep those columns whole.
    for i in small + large:
        prob[i] = 1.0
    return prob, alias


class LightTables(NamedTuple):
    """What the per-lane light functions read. K candidates: T emissive triangles first, then
    P point lights.

    alias_prob : (K,) float64 and alias : (K,) int64, Walker's table over the candidates.
    pmf : (K,) selection probabilities.
    area : (T, 16) float32 per triangle candidate: v0 (3), v1 (3), v2 (3), normal (3),
        emission (3), selection pmf / area (1).
    point : (P, 6) per point candidate: position (3), intensity (3).
    by_triangle : (F, 4) float32 per scene triangle: normal (3), selection pmf / area (1; 0 for
        non-emitters), for the pdf of a direction that hits it.
    spheres : (S, 4) bounding spheres, center (3) and radius (1), that hold every emitting
        triangle: a ray that meets none of them cannot reach an emitter (``may_reach``).
    """

    alias_prob: np.ndarray
    alias: np.ndarray
    pmf: np.ndarray
    area: np.ndarray
    point: np.ndarray
    by_triangle: np.ndarray
    spheres: np.ndarray


MAX_SPHERES = 16  # more emitters than this share one bounding sphere (the test is per sphere)


def emitter_spheres(scene: Scene) -> np.ndarray:
    """``(S, 4)`` spheres (center, radius) around the emitting triangles, one per emissive shape,
    or one around them all when there are more than ``MAX_SPHERES``. Radii are padded by the
    scene's ray offset and 1e-6 relative, so that float32 rays that hit an emitter for Embree
    always meet its sphere."""
    emitting = np.flatnonzero((scene.emission.max(axis=1) > 0.0) & (scene.area > 0.0))
    groups = [emitting[scene.light_of_triangle[emitting] == light]
              for light in np.unique(scene.light_of_triangle[emitting])]
    if len(groups) > MAX_SPHERES:
        groups = [emitting]
    spheres = np.zeros((len(groups), 4))
    for row, tri in enumerate(groups):
        corners = scene.vertices[scene.faces[tri]].reshape(-1, 3)
        center = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
        radius = np.sqrt(np.max(np.sum((corners - center) ** 2, axis=1)))
        spheres[row, :3] = center
        spheres[row, 3] = radius * (1.0 + 1e-6) + scene.ray_epsilon + 1e-6 * np.max(np.abs(center))
    return spheres


@jit
def may_reach(spheres, o, w) -> bool:
    """Whether the ray from ``o`` along unit ``w`` meets one of the emitter ``spheres`` (or starts
    inside one): if not, it cannot hit an emitter, and a direction sample need not be cast."""
    for i in range(len(spheres)):
        cx, cy, cz, r = spheres[i, 0] - o[0], spheres[i, 1] - o[1], spheres[i, 2] - o[2], spheres[i, 3]
        along = cx * w[0] + cy * w[1] + cz * w[2]
        dist2 = cx * cx + cy * cy + cz * cz
        if dist2 <= r * r or (along >= 0.0 and dist2 - along * along <= r * r):
            return True
    return False


# The per-lane functions take the table arrays one by one: in compiled code, reading an array
# out of a tuple inside a loop costs a reference-count update (~25 ns), so kernels unpack
# ``LightTables`` once, before their loops.


@jit
def pick(alias_prob, alias, u_select: float) -> int:
    """A candidate index distributed by ``pmf``, by Walker's alias method: the integer part of
    u K picks a column, the fraction decides between the column and its alias. O(1) per
    sample, unlike a binary search of the CDF."""
    count = len(alias)
    scaled = u_select * count
    column = min(int(scaled), count - 1)
    return column if scaled - column < alias_prob[column] else alias[column]


@jit
def sample(alias_prob, alias, pmf, area, point, u_select: float, u0: float, u1: float, x):
    """Sample a light for shading point ``x`` (world), from the arrays of ``LightTables``.
    Returns ``(wi, dist, le, pdf, delta)``:

    wi : world unit direction from x toward the light.   dist : distance to the sampled point.
    le : RGB radiance arriving along wi (area), or I / d^2 (point); the contribution is
        f |cos theta_i| le / pdf. Zero where the sample is invalid.
    pdf : solid-angle pdf including the selection probability; for a point light, its selection
        probability alone. 0 where invalid.
    delta : a point light (no other technique can produce this sample).
    """
    zero = (0.0, 0.0, 0.0)
    if len(alias) == 0:
        return (0.0, 0.0, 1.0), 0.0, zero, 0.0, False
    k = pick(alias_prob, alias, u_select)
    n_tri = len(area)
    if k < n_tri:
        b1, b2 = warp.triangle_barycentric(u0, u1)
        v0 = (float(area[k, 0]), float(area[k, 1]), float(area[k, 2]))
        lx = v0[0] + b1 * (area[k, 3] - v0[0]) + b2 * (area[k, 6] - v0[0]) - x[0]
        ly = v0[1] + b1 * (area[k, 4] - v0[1]) + b2 * (area[k, 7] - v0[1]) - x[1]
        lz = v0[2] + b1 * (area[k, 5] - v0[2]) + b2 * (area[k, 8] - v0[2]) - x[2]
        d2 = lx * lx + ly * ly + lz * lz
        d = math.sqrt(d2)
        if d <= 0.0:
            return (0.0, 0.0, 1.0), 0.0, zero, 0.0, False
        inv_d = 1.0 / d
        wi = (lx * inv_d, ly * inv_d, lz * inv_d)
        cos_light = -(area[k, 9] * wi[0] + area[k, 10] * wi[1] + area[k, 11] * wi[2])
        if cos_light <= 0.0:  # front side only
            return wi, d, zero, 0.0, False
        return wi, d, (area[k, 12], area[k, 13], area[k, 14]), area[k, 15] * d2 / cos_light, False
    q = k - n_tri
    lx, ly, lz = point[q, 0] - x[0], point[q, 1] - x[1], point[q, 2] - x[2]
    d2 = lx * lx + ly * ly + lz * lz
    d = math.sqrt(d2)
    if d <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, zero, 0.0, True
    inv_d = 1.0 / d
    falloff = inv_d * inv_d
    intensity = (point[q, 3] * falloff, point[q, 4] * falloff, point[q, 5] * falloff)
    return (lx * inv_d, ly * inv_d, lz * inv_d), d, intensity, pmf[k], True


@jit
def pdf(by_triangle, prim: int, wi, dist: float) -> float:
    """Solid-angle pdf with which :func:`sample` picks direction ``wi`` (world) that hits
    triangle ``prim`` at distance ``dist``; 0 for non-emitters and back sides."""
    cos_light = -(by_triangle[prim, 0] * wi[0] + by_triangle[prim, 1] * wi[1] + by_triangle[prim, 2] * wi[2])
    pmf_over_area = by_triangle[prim, 3]
    if pmf_over_area <= 0.0 or cos_light <= 0.0:
        return 0.0
    return pmf_over_area * dist * dist / cos_light


class LightSampler:
    """The emitters of a scene with their selection distribution."""

    def __init__(self, scene: Scene, selection: str = "power"):
        if selection not in SELECTIONS:
            raise ValueError(f"light selection must be one of {SELECTIONS}, got {selection!r}")
        self.scene = scene
        self.selection = selection
        tri = np.flatnonzero((scene.light_of_triangle >= 0) & (scene.area > 0.0))
        tri_flux = np.pi * scene.area[tri] * scene.emission[tri].mean(axis=1)
        keep = tri_flux > 0.0
        tri, tri_flux = tri[keep], tri_flux[keep]
        point_flux = 4.0 * np.pi * scene.point_intensity.mean(axis=1)
        points = np.flatnonzero(point_flux > 0.0)

        if selection == "power":
            weight = np.concatenate([tri_flux, point_flux[points]])
        else:
            light = scene.light_of_triangle[tri]
            light_area = np.bincount(light, weights=scene.area[tri], minlength=light.max(initial=-1) + 1)
            n_lights = len(np.unique(light)) + len(points)
            tri_weight = scene.area[tri] / light_area[light] / max(n_lights, 1)
            weight = np.concatenate([tri_weight, np.full(len(points), 1.0 / max(n_lights, 1))])

        self.triangles = tri  # (T,) triangle index of each area candidate
        self.points = points  # (P,) point-light index of each point candidate
        total = weight.sum()
        self.count = len(weight)
        self.pmf = weight / total if self.count else weight
        alias_prob, alias = _alias_table(self.pmf)
        pmf_over_area = self.pmf[: len(tri)] / scene.area[tri]  # area > 0 by the choice of tri
        by_triangle = np.zeros((len(scene.faces), 4), dtype=np.float32)  # rounded as ``area`` is
        by_triangle[:, 0:3] = scene.normal
        by_triangle[tri, 3] = pmf_over_area
        self.tables = LightTables(
            alias_prob=alias_prob,
            alias=alias,
            pmf=self.pmf,
            # float32, exactly as the scene holds vertices and emission (scene.py rounds both;
            # edges are formed in float64, exactly, so sampled points lie on Embree's triangles).
            # A row is one 64-byte cache line, which light sampling reads at random (11% faster
            # shading on veach_mis than float64).
            area=np.ascontiguousarray(np.concatenate(
                [scene.vertices[scene.faces[tri]].reshape(len(tri), 9), scene.normal[tri],
                 scene.emission[tri], pmf_over_area[:, None]], axis=1).reshape(len(tri), 16),
                dtype=np.float32),
            point=np.ascontiguousarray(np.concatenate(
                [scene.point_position[points], scene.point_intensity[points]], axis=1).reshape(-1, 6)),
            by_triangle=by_triangle,
            spheres=emitter_spheres(scene),
        )

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray) -> LightSample:
        """Sample a light for shading points ``x (n, 3)``; ``u_select (n,)``, ``u_point (n, 2)``."""
        return LightSample(*_sample_lanes(self.tables, u_select, u_point, x))

    def pdf(self, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick direction ``wi (n, 3)`` that hits
        triangle ``prim (n,)`` at distance ``dist (n,)``; 0 for non-emitters and back sides."""
        return _pdf_lanes(self.tables, prim, wi, dist)


@jit
def _sample_lanes(tables, u_select, u_point, x):
    alias_prob, alias, pmf, area, point, _, _ = tables
    n = len(u_select)
    wi, dist, le = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    p, delta = np.empty(n), np.empty(n, dtype=np.bool_)
    for i in range(n):
        xi = (x[i, 0], x[i, 1], x[i, 2])
        w, dist[i], radiance, p[i], delta[i] = sample(alias_prob, alias, pmf, area, point, u_select[i],
                                                      u_point[i, 0], u_point[i, 1], xi)
        wi[i, 0], wi[i, 1], wi[i, 2] = w
        le[i, 0], le[i, 1], le[i, 2] = radiance
    return wi, dist, le, p, delta


@jit
def _pdf_lanes(tables, prim, wi, dist):
    by_triangle = tables.by_triangle
    out = np.empty(len(prim))
    for i in range(len(prim)):
        out[i] = pdf(by_triangle, prim[i], (wi[i, 0], wi[i, 1], wi[i, 2]), dist[i])
    return out
