"""The only module that talks to Embree (through ``embreex``).

Embree takes float32 rays; everything else in tracer is float64, so the conversion happens
here and nowhere else. ``tnear`` is fixed at 0 in embreex, so callers offset ray origins
(see ``Scene.ray_epsilon``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh


@dataclass
class Hits:
    """Closest hits of a batch of rays, in Embree's own arrays (not converted).

    prim : (n,) int32 triangle index, -1 on a miss.
    t : (n,) float32 distance along the (unit) ray direction; inf on a miss.
    u, v : (n,) float32 barycentrics of the hit: p = v0 + u (v1 - v0) + v (v2 - v0).
    """

    prim: np.ndarray
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray


class RayCaster:
    """An Embree scene over one triangle mesh.

    The acceleration structure is built by a first query in the constructor, because embreex
    builds it lazily and without a lock: after construction, queries are thread-safe (and
    release the GIL).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self._scene = rtcore_scene.EmbreeScene()
        self.empty = len(faces) == 0
        if not self.empty:
            self._mesh = TriangleMesh(self._scene, np.ascontiguousarray(vertices, dtype=np.float32),
                                      np.ascontiguousarray(faces, dtype=np.int32))
            one = np.zeros((1, 3), dtype=np.float32)
            self._scene.run(one, one + np.float32(1.0))

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> Hits:
        """Closest hit along each ray. ``origins, dirs: (n, 3)``, dirs unit length."""
        n = len(origins)
        if self.empty or n == 0:
            zero = np.zeros(n, dtype=np.float32)
            return Hits(np.full(n, -1, dtype=np.int32), np.full(n, np.inf, dtype=np.float32), zero, zero)
        out = self._scene.run(_f32(origins), _f32(dirs), output=1)
        prim, t = out["primID"], out["tfar"]
        t[prim < 0] = np.inf
        return Hits(prim, t, out["u"], out["v"])

    def first_hit(self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray | None = None) -> np.ndarray:
        """(n,) int32 index of the triangle each ray hits first, -1 on a miss; with ``tmax
        (n,)``, among the hits at t <= tmax only. Faster than :meth:`intersect`, whose full
        output also builds t, u, v and the normal; the estimator recomputes the hit distance
        from the triangle's plane in float64."""
        n = len(origins)
        if self.empty or n == 0:
            return np.full(n, -1, dtype=np.int32)
        if tmax is None:
            return self._scene.run(_f32(origins), _f32(dirs))
        # embreex overwrites ``dists`` in place, so it always gets a fresh array.
        return self._scene.run(_f32(origins), _f32(dirs), dists=np.array(tmax, dtype=np.float32))

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """(n,) bool: something lies on the segment origin + t dir, 0 <= t < tmax."""
        n = len(origins)
        if self.empty or n == 0:
            return np.zeros(n, dtype=bool)
        # embreex overwrites ``dists`` in place, so it always gets a fresh array.
        dists = np.array(tmax, dtype=np.float32)
        return self._scene.run(_f32(origins), _f32(dirs), dists=dists, query="OCCLUDED") == 0


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)
