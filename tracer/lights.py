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
        self.cdf = np.cumsum(self.pmf)
        if self.count:
            self.cdf[-1] = 1.0
        # Selection probability of every scene triangle (0 for non-emitters), for pdf().
        self.pmf_of_triangle = np.zeros(len(scene.faces))
        self.pmf_of_triangle[tri] = self.pmf[: len(tri)]

    def sample(self, u_select: np.ndarray, u_point: np.ndarray, x: np.ndarray) -> LightSample:
        """Sample a light for shading points ``x (n, 3)``; ``u_select (n,)``, ``u_point (n, 2)``."""
        n = len(x)
        wi = np.zeros((n, 3))
        wi[:, 2] = 1.0
        dist = np.zeros(n)
        radiance = np.zeros((n, 3))
        pdf = np.zeros(n)
        delta = np.zeros(n, dtype=bool)
        if self.count == 0:
            return LightSample(wi, dist, radiance, pdf, delta)

        pick = np.minimum(np.searchsorted(self.cdf, u_select, side="right"), self.count - 1)
        pmf = self.pmf[pick]
        n_tri = len(self.triangles)

        area_lanes = np.flatnonzero(pick < n_tri)
        if len(area_lanes):
            s = self.scene
            t = self.triangles[pick[area_lanes]]
            b = warp.sample_triangle_barycentric(u_point[area_lanes])
            y = s.v0[t] + b[:, 0:1] * s.edge1[t] + b[:, 1:2] * s.edge2[t]
            to_light = y - x[area_lanes]
            d = np.linalg.norm(to_light, axis=1)
            ok = d > 0.0
            w = to_light / np.where(ok, d, 1.0)[:, None]
            cos_light = -np.sum(s.normal[t] * w, axis=1)
            ok &= cos_light > 0.0  # front side only
            wi[area_lanes] = np.where(ok[:, None], w, wi[area_lanes])
            dist[area_lanes] = d
            radiance[area_lanes] = np.where(ok[:, None], s.emission[t], 0.0)
            safe_cos = np.where(ok, cos_light, 1.0)
            pdf[area_lanes] = np.where(ok, pmf[area_lanes] / s.area[t] * d * d / safe_cos, 0.0)

        point_lanes = np.flatnonzero(pick >= n_tri)
        if len(point_lanes):
            p = self.points[pick[point_lanes] - n_tri]
            to_light = self.scene.point_position[p] - x[point_lanes]
            d = np.linalg.norm(to_light, axis=1)
            ok = d > 0.0
            safe_d = np.where(ok, d, 1.0)
            wi[point_lanes] = np.where(ok[:, None], to_light / safe_d[:, None], wi[point_lanes])
            dist[point_lanes] = d
            radiance[point_lanes] = np.where(ok[:, None],
                                             self.scene.point_intensity[p] / (safe_d * safe_d)[:, None], 0.0)
            pdf[point_lanes] = np.where(ok, pmf[point_lanes], 0.0)
            delta[point_lanes] = True
        return LightSample(wi, dist, radiance, pdf, delta)

    def pdf(self, prim: np.ndarray, wi: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would pick direction ``wi (n, 3)`` that hits
        triangle ``prim (n,)`` at distance ``dist (n,)``; 0 for non-emitters and back sides."""
        s = self.scene
        pmf = self.pmf_of_triangle[prim]
        cos_light = -np.sum(s.normal[prim] * wi, axis=1)
        ok = (pmf > 0.0) & (cos_light > 0.0)
        return np.where(ok, pmf / np.where(ok, s.area[prim] * cos_light, 1.0) * dist * dist, 0.0)
