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


def test_first_hit_without_triangles_with_emitters_only_and_with_no_rays():
    """The edge cases of the same query: a scene of spheres alone (Embree holds no triangle, and
    every hit is a sphere's), the emitters-only rays ris uses (local ids mapped back to the
    scene's: an emitting sphere behind an emitting quad is found through the occluder that the
    emitters-only scene leaves out), and an empty batch (an int32 array of length 0)."""
    spheres_only = load_scene({"camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40.0, "width": 4,
                                          "height": 4},
                               "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
                                          {"type": "sphere", "center": [0, 0, -3], "radius": 1.0}]})
    rays = SceneRays(spheres_only)
    origins = np.array([[0, 0, 5], [0, 0, 5], [5, 0, 0]], dtype=np.float32)
    dirs = np.array([[0, 0, -1], [0, 1, 0], [-1, 0, 0]], dtype=np.float32)
    assert rays.first_hit(origins, dirs).tolist() == [rays.first_sphere, -1, rays.first_sphere]
    empty = rays.first_hit(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))
    assert empty.dtype == np.int32 and empty.shape == (0,)

    mixed = load_scene({"camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40.0, "width": 4, "height": 4},
                        "shapes": [{"type": "quad", "origin": [-2, -2, 2], "edge1": [4, 0, 0], "edge2": [0, 4, 0]},
                                   {"type": "quad", "origin": [-2, -2, -1], "edge1": [4, 0, 0], "edge2": [0, 4, 0],
                                    "emission": [1, 1, 1]},
                                   {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5,
                                    "emission": [2, 2, 2]}]})
    full, emitters = SceneRays(mixed), SceneRays(mixed, emitters_only=True)
    origins = np.array([[0, 0, 5], [1.5, 1.5, 5]], dtype=np.float32)
    dirs = np.array([[0, 0, -1], [0, 0, -1]], dtype=np.float32)
    occluder = full.first_hit(origins, dirs)
    assert np.all((occluder >= 0) & (occluder < 2))  # the plain quad's two triangles, in front
    found = emitters.first_hit(origins, dirs)
    sphere = mixed.triangle_count  # the scene's id of its first sphere
    assert found[0] == sphere and 2 <= found[1] < 4  # the sphere; beside it, the emitting quad
