"""Rays against the whole scene: Embree's triangles plus tracer's analytic spheres.

Embree (``tracer.embree``) casts rays against the triangle mesh; the few analytic spheres of a
scene are intersected here, in compiled float64 code, and the nearer hit wins. Primitive ids
number the triangles 0 .. F - 1 and the spheres F .. F + S - 1, as the scene's hit table does.
A scene without analytic spheres takes Embree's fast paths unchanged.

Spheres are tested one by one per ray, which suits the handful of sphere lights and objects a
scene file lists; a scene with hundreds of spheres is better served by ``subdivisions = N``
meshes, which Embree's BVH handles.

Ray-sphere intersection follows Haines, Günther and Akenine-Möller, "Precision Improvements for
Ray/Sphere Intersection" (Ray Tracing Gems, ch. 7, 2019): the discriminant is computed as
r^2 - |f - (f.d) d|^2 (f = o - c, d unit), which does not cancel for small or distant spheres,
and the nearer root as c / q with q = -b - sign(b) sqrt(discriminant), which does not cancel
when b^2 >> discriminant.
"""

from __future__ import annotations

import math

import numpy as np

from .embree import RayCaster
from .frame import add_scaled, cross, dot, scale, sub
from .jit import jit


@jit
def sphere_roots(center, radius: float, o, d):
    """Both distances ``(t0 <= t1)`` at which the ray ``o + t d`` (d unit) meets the sphere, or
    ``(inf, inf)`` if it misses."""
    f = sub(o, center)
    b = dot(f, d)
    g = (f[0] - b * d[0], f[1] - b * d[1], f[2] - b * d[2])
    discriminant = radius * radius - dot(g, g)
    if discriminant < 0.0:
        return math.inf, math.inf
    c = dot(f, f) - radius * radius
    q = -b - math.copysign(math.sqrt(discriminant), b)
    if q == 0.0:  # o on the sphere and the ray tangent: one double root at 0
        return 0.0, 0.0
    t0, t1 = c / q, q
    return (t0, t1) if t0 <= t1 else (t1, t0)


@jit
def sphere_hit(center, radius: float, o, d) -> float:
    """Distance to the first crossing of the sphere at t > 0, inf if none."""
    t0, t1 = sphere_roots(center, radius, o, d)
    if t0 > 0.0:
        return t0
    if t1 > 0.0:
        return t1
    return math.inf


@jit
def surface_point(hit_table, first_sphere: int, p: int, o, d):
    """Where the ray ``o + t d`` (d unit, float64) meets primitive ``p``: ``(x, n, cos_d)`` with
    x the point, n the unit geometric normal of the primitive's front (a triangle's face normal,
    a sphere's outward normal) and cos_d = d . n; cos_d 0 if the ray runs in a triangle's plane.

    A triangle's point is where the ray meets its plane, in float64 (Embree's own distance is
    float32). A sphere's is projected back onto the sphere, which removes the rounding of t
    along the ray (pbrt-v4's re-projection, "Sphere intersection" in Physically Based Rendering,
    4th ed., sec. 6.8.5)."""
    if p < first_sphere:
        n = (hit_table[p, 9], hit_table[p, 10], hit_table[p, 11])
        cos_d = dot(n, d)
        if cos_d == 0.0:
            return o, n, 0.0
        t = ((hit_table[p, 0] - o[0]) * n[0] + (hit_table[p, 1] - o[1]) * n[1]
             + (hit_table[p, 2] - o[2]) * n[2]) / cos_d
        return add_scaled(o, t, d), n, cos_d
    center = (hit_table[p, 0], hit_table[p, 1], hit_table[p, 2])
    radius = hit_table[p, 3]
    t = sphere_hit(center, radius, o, d)
    if not t < math.inf:  # cannot happen for a primitive this ray was found to hit
        t = max(-dot(sub(o, center), d), 0.0)  # the closest approach
    x = add_scaled(o, t, d)
    v = sub(x, center)
    length = math.sqrt(dot(v, v))
    n = scale(1.0 / length, v) if length > 0.0 else (0.0, 0.0, 1.0)
    return add_scaled(center, radius, n), n, dot(n, d)


@jit
def barycentrics(hit_table, p: int, x):
    """``(found, b1, b2)``: the barycentric weights of triangle ``p``'s corners 1 and 2 at point
    ``x`` of its plane (x = v0 + b1 e1 + b2 e2); found is False for a zero-area triangle."""
    e1 = (hit_table[p, 3], hit_table[p, 4], hit_table[p, 5])
    e2 = (hit_table[p, 6], hit_table[p, 7], hit_table[p, 8])
    q = (x[0] - hit_table[p, 0], x[1] - hit_table[p, 1], x[2] - hit_table[p, 2])
    c = cross(e1, e2)
    area2 = dot(c, c)
    if area2 == 0.0:
        return False, 0.0, 0.0
    # x - v0 = b1 e1 + b2 e2: b1 = (q x e2) . c / |c|^2, b2 = (e1 x q) . c / |c|^2.
    return True, dot(cross(q, e2), c) / area2, dot(cross(e1, q), c) / area2


@jit
def shading_normal(corner_normals, hit_table, first_sphere: int, p: int, x, face_normal):
    """The unit shading normal at point ``x`` of primitive ``p``: for a triangle with vertex
    normals (a nonzero row of ``corner_normals``, (F, 9)), their interpolation by x's
    barycentrics, normalized; otherwise (flat triangles, spheres, a degenerate interpolation)
    ``face_normal``."""
    if p >= first_sphere or len(corner_normals) == 0:
        return face_normal
    n0 = (corner_normals[p, 0], corner_normals[p, 1], corner_normals[p, 2])
    n1 = (corner_normals[p, 3], corner_normals[p, 4], corner_normals[p, 5])
    n2 = (corner_normals[p, 6], corner_normals[p, 7], corner_normals[p, 8])
    if dot(n0, n0) == 0.0 or dot(n1, n1) == 0.0 or dot(n2, n2) == 0.0:
        return face_normal
    found, b1, b2 = barycentrics(hit_table, p, x)
    if not found:
        return face_normal
    b0 = 1.0 - b1 - b2
    n = (b0 * n0[0] + b1 * n1[0] + b2 * n2[0], b0 * n0[1] + b1 * n1[1] + b2 * n2[1],
         b0 * n0[2] + b1 * n1[2] + b2 * n2[2])
    length = math.sqrt(dot(n, n))
    if not length > 0.0:
        return face_normal
    return scale(1.0 / length, n)


@jit
def offset_origin(x, eps: float, geometric_normal, direction):
    """Where a ray in ``direction`` leaving surface point ``x`` starts: ``eps`` off the surface
    along the geometric normal, on the side the ray goes to (with shading normals a sampled
    direction may go below the geometric surface, through it)."""
    return add_scaled(x, eps if dot(direction, geometric_normal) >= 0.0 else -eps, geometric_normal)


@jit
def _nearest_spheres(origins, dirs, spheres):
    """``(tmax (n,) float32, sphere (n,) int32)``: for each ray the distance to the first
    sphere it crosses at t > 0 (inf if none), rounded to float32 (Embree's ``tfar``), and that
    sphere's index (-1 if none)."""
    n = len(origins)
    tmax = np.full(n, np.inf, dtype=np.float32)
    which = np.full(n, -1, dtype=np.int32)
    for i in range(n):
        o = (float(origins[i, 0]), float(origins[i, 1]), float(origins[i, 2]))
        d = (float(dirs[i, 0]), float(dirs[i, 1]), float(dirs[i, 2]))
        nearest = math.inf
        for s in range(len(spheres)):
            t = sphere_hit((spheres[s, 0], spheres[s, 1], spheres[s, 2]), spheres[s, 3], o, d)
            if t < nearest:
                nearest = t
                which[i] = s
        tmax[i] = nearest
    return tmax, which


@jit
def _sphere_where_missed(prim, which, first_sphere: int) -> None:
    """Where Embree found no triangle before the nearest sphere (``prim[i]`` -1), the sphere."""
    for i in range(len(prim)):
        if prim[i] < 0 and which[i] >= 0:
            prim[i] = first_sphere + which[i]


@jit
def _spheres_block(blocked, origins, dirs, tmax, spheres) -> None:
    """Set ``blocked[i]`` where a sphere crosses the segment ``0 < t < tmax[i]`` of ray i."""
    for i in range(len(blocked)):
        if blocked[i]:
            continue
        o = (float(origins[i, 0]), float(origins[i, 1]), float(origins[i, 2]))
        d = (float(dirs[i, 0]), float(dirs[i, 1]), float(dirs[i, 2]))
        for s in range(len(spheres)):
            t0, t1 = sphere_roots((spheres[s, 0], spheres[s, 1], spheres[s, 2]), spheres[s, 3], o, d)
            if (0.0 < t0 < tmax[i]) or (0.0 < t1 < tmax[i]):
                blocked[i] = True
                break


class SceneRays:
    """Closest hits and occlusion against a scene's triangles and analytic spheres, or with
    ``emitters_only`` against its emitting ones alone (the occluders left out: where a direction
    meets the first emitter, as ris's BSDF candidates need, ``tracer.estimator``).

    caster : the Embree scene of the triangles (built here unless given).
    spheres : (S, 4) float64 centre and radius.   first_sphere : the local id of sphere 0.
    ids : None, or (local triangles + spheres,) int32 the scene primitive id of each local one.
    Thread-safe after construction, as ``RayCaster`` is.
    """

    def __init__(self, scene, caster: RayCaster | None = None, emitters_only: bool = False):
        self.ids = None
        if emitters_only:
            # The same float32 vertices, so that Embree finds the same hits as in the full scene.
            tri = np.flatnonzero(scene.emission.max(axis=1, initial=0.0) > 0.0)
            sph = np.flatnonzero(scene.sphere_emission.max(axis=1, initial=0.0) > 0.0)
            used, local = np.unique(scene.faces[tri], return_inverse=True)
            caster = RayCaster(scene.vertices[used], local.reshape(-1, 3))
            self.spheres = np.ascontiguousarray(scene.spheres[sph], dtype=np.float64).reshape(-1, 4)
            self.first_sphere = len(tri)
            self.ids = np.concatenate([tri, scene.triangle_count + sph]).astype(np.int32)
        else:
            self.spheres = np.ascontiguousarray(scene.spheres, dtype=np.float64).reshape(-1, 4)
            self.first_sphere = int(scene.triangle_count)
        self.caster = caster if caster is not None else RayCaster(scene.vertices, scene.faces)

    def first_hit(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(n,) int32 id of the primitive each ray ``origins, dirs (n, 3)`` float32 hits first,
        -1 on a miss."""
        if not len(self.spheres):
            prim = self.caster.first_hit(origins, dirs)
        else:
            # The spheres first: Embree then looks for triangles only up to the nearest one,
            # returning ids alone (its full hit record, to compare distances after, made the
            # camera rays of veach_mis 25% slower to cast; the whole render x0.97: CHANGELOG).
            tmax, which = _nearest_spheres(origins, dirs, self.spheres)
            prim = np.array(self.caster.first_hit(origins, dirs, tmax), dtype=np.int32)
            _sphere_where_missed(prim, which, self.first_sphere)
        if self.ids is None:
            return prim
        if not len(self.ids):
            return np.full(len(prim), -1, dtype=np.int32)
        return np.where(prim >= 0, self.ids[np.maximum(prim, 0)], -1).astype(np.int32)

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """(n,) bool: a triangle or a sphere lies on the segment origin + t dir, 0 < t < tmax."""
        blocked = np.array(self.caster.occluded(origins, dirs, tmax), dtype=np.bool_)
        if len(self.spheres) and len(blocked):
            _spheres_block(blocked, origins, dirs, np.asarray(tmax, dtype=np.float64), self.spheres)
        return blocked
