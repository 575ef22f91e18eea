"""Closest hits against triangles and analytic spheres together (``tracer.geometry.SceneRays``).

SceneRays finds the nearest sphere first and asks Embree for a triangle only up to it; here
that is compared with the brute-force answer: Embree's nearest triangle with its distance, and
every sphere's distance, whichever is nearer. Deterministic: no statistics.
"""

from __future__ import annotations

import numpy as np

from tracer.geometry import SceneRays, sphere_hit
from tracer.scene import load_scene


def test_first_hit_is_the_nearest_of_triangles_and_spheres():
    """20,000 rays from random points in random directions through a box of quads (walls and
    two tilted panels; open above and on two sides) holding five spheres, two of which cut through a panel and the floor.
    Each ray's answer must be the nearer of Embree's closest triangle (its float32 distance)
    and the nearest sphere (float64), except where the two distances agree to 1e-5 relative,
    where float32 rounding may decide either way; those rays must be under 0.1%."""
    quad = lambda o, e1, e2: {"type": "quad", "origin": o, "edge1": e1, "edge2": e2}  # noqa: E731
    shapes = [quad([-2, 0, -2], [0, 0, 4], [4, 0, 0]), quad([-2, 0, -2], [4, 0, 0], [0, 3, 0]),
              quad([-2, 0, -2], [0, 3, 0], [0, 0, 4]), quad([-0.5, 0.5, -1], [1.5, 0.3, 0.2], [0.1, 0.2, 1.7]),
              quad([0.2, 1.8, 0.0], [1.0, 0.0, 0.4], [0.0, 0.6, 1.0])]
    rng = np.random.default_rng(4)
    spheres = [([0.3, 0.6, -0.2], 0.35), ([-1.0, 0.1, 1.0], 0.4), ([1.2, 2.2, 1.0], 0.3),
               ([0.0, 1.5, 1.2], 0.2), ([-1.5, 2.5, -1.5], 0.25)]
    shapes += [{"type": "sphere", "center": c, "radius": r} for c, r in spheres]
    scene = load_scene({"camera": {"origin": [0, 1.5, 5], "target": [0, 1, 0], "fov": 50.0, "width": 4,
                                   "height": 4}, "shapes": shapes})
    rays = SceneRays(scene)
    assert len(rays.spheres) == 5
    n = 20_000
    origins = rng.uniform([-1.9, 0.05, -1.9], [1.9, 2.9, 1.9], (n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    prim = rays.first_hit(origins, dirs)

    hits = rays.caster.intersect(origins, dirs)
    t_triangle = np.where(hits.prim >= 0, hits.t.astype(np.float64), np.inf)
    t_sphere = np.array([[sphere_hit(np.array(c, float), r, o.astype(float), d.astype(float)) for c, r in spheres]
                         for o, d in zip(origins, dirs, strict=True)])
    nearest_sphere = t_sphere.argmin(axis=1)
    t_nearest = t_sphere.min(axis=1)
    expected = np.where(t_nearest < t_triangle, rays.first_sphere + nearest_sphere, hits.prim)
    both = np.isfinite(t_nearest) & np.isfinite(t_triangle)
    gap = np.abs(np.where(both, t_nearest, 0.0) - np.where(both, t_triangle, 0.0))
    tie = both & (gap <= 1e-5 * t_nearest)
    assert tie.mean() < 1e-3
    assert np.array_equal(prim[~tie], expected[~tie])
    # Every kind of answer occurs: spheres, triangles (some behind a sphere), misses (the box is open).
    assert (expected >= rays.first_sphere).sum() > 500 and (both & (t_nearest > t_triangle)).sum() > 100
    assert 0 < (expected < 0).sum()
