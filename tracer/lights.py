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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import warp
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
        self.alias_prob, self.alias = _alias_table(self.pmf)
        # Selection probability of every scene triangle (0 for non-emitters), for pdf().
        self.pmf_of_triangle = np.zeros(len(scene.faces))
        self.pmf_of_triangle[tri] = self.pmf[: len(tri)]
        # One row per area candidate, so that a sample gathers its triangle in one go:
        # v0 (3), edge1 (3), edge2 (3), normal (3), emission (3), selection pmf / area (1).
        self.area_table = np.concatenate(
            [
                scene.v0[tri],
                scene.edge1[tri],
                scene.edge2[tri],
                scene.normal[tri],
                scene.emission[tri],
                (self.pmf[: len(tri)] / np.where(scene.area[tri] > 0.0, scene.area[tri], 1.0))[:, None],
            ],
            axis=1,
        )

    def pick(self, u_select: np.ndarray) -> np.ndarray:
        """Candidate indices ``(n,)`` distributed by ``pmf``, by Walker's alias method (Vose's
        construction): the integer part of u K picks a column, the fraction decides between the
        column and its alias. O(1) per sample, unlike a binary search of the CDF."""
        scaled = u_select * self.count
        column = np.minimum(scaled.astype(np.int64), self.count - 1)
        return np.where(scaled - column < self.alias_prob[column], column, self.alias[column])

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray) -> LightSample:
        """Sample a light for shading points ``x (n, 3)``; ``u_select (n,)``, ``u_point (n, 2)``."""
        n = len(x)
        if self.count == 0:
            wi = np.zeros((n, 3))
            wi[:, 2] = 1.0
            return LightSample(wi, np.zeros(n), np.zeros((n, 3)), np.zeros(n), np.zeros(n, dtype=bool))
        pick = self.pick(u_select)
        n_tri = len(self.triangles)
        if len(self.points) == 0:  # the common case: area lights only, no index arrays needed
            return self._sample_area(pick, u_point, x)
        if n_tri == 0:
            return self._sample_points(pick, x)
        out = LightSample(
            np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros(n), np.zeros(n, dtype=bool)
        )
        for lanes, part in (
            (np.flatnonzero(pick < n_tri), self._sample_area),
            (np.flatnonzero(pick >= n_tri), None),
        ):
            if not len(lanes):
                continue
            sub = (
                part(pick[lanes], u_point[lanes], x[lanes])
                if part is not None
                else self._sample_points(pick[lanes], x[lanes])
            )
            out.wi[lanes], out.dist[lanes], out.radiance[lanes] = sub.wi, sub.dist, sub.radiance
            out.pdf[lanes], out.delta[lanes] = sub.pdf, sub.delta
        return out

    def _sample_area(self, pick: np.ndarray, u_point: np.ndarray, x: np.ndarray) -> LightSample:
        """Points on the picked emissive triangles (``pick`` < number of triangles)."""
        g = self.area_table[pick]
        b = warp.sample_triangle_barycentric(u_point)
        y = g[:, 0:3] + b[:, 0:1] * g[:, 3:6] + b[:, 1:2] * g[:, 6:9]
        to_light = y - x
        d2 = np.einsum("ij,ij->i", to_light, to_light)
        d = np.sqrt(d2)
        ok = d > 0.0
        wi = to_light / np.where(ok, d, 1.0)[:, None]
        cos_light = -np.einsum("ij,ij->i", g[:, 9:12], wi)
        ok &= cos_light > 0.0  # front side only
        radiance = g[:, 12:15] * ok[:, None]
        pdf = np.where(ok, g[:, 15] * d2 / np.where(ok, cos_light, 1.0), 0.0)
        return LightSample(wi, d, radiance, pdf, np.zeros(len(pick), dtype=bool))

    def _sample_points(self, pick: np.ndarray, x: np.ndarray) -> LightSample:
        """The picked point lights (``pick`` >= number of triangles): delta samples."""
        p = self.points[pick - len(self.triangles)]
        to_light = self.scene.point_position[p] - x
        d2 = np.einsum("ij,ij->i", to_light, to_light)
        d = np.sqrt(d2)
        ok = d > 0.0
        safe_d = np.where(ok, d, 1.0)
        wi = to_light / safe_d[:, None]
        radiance = self.scene.point_intensity[p] / np.where(ok, d2, 1.0)[:, None] * ok[:, None]
        return LightSample(wi, d, radiance, np.where(ok, self.pmf[pick], 0.0), np.ones(len(pick), dtype=bool))

    def pdf(self, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick direction ``wi (n, 3)`` that hits
        triangle ``prim (n,)`` at distance ``dist (n,)``; 0 for non-emitters and back sides."""
        s = self.scene
        pmf = self.pmf_of_triangle[prim]
        cos_light = -np.sum(s.normal[prim] * wi, axis=1)
        ok = (pmf > 0.0) & (cos_light > 0.0)
        return np.where(ok, pmf / np.where(ok, s.area[prim] * cos_light, 1.0) * dist * dist, 0.0)
