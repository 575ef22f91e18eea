"""Bounding spheres of the emitters, to skip direction samples that cannot reach one.

A direction sample contributes only if its ray hits an emitter; a ray that meets none of the
spheres around the emitters cannot, so the estimator does not cast it (``may_reach``).
"""

from __future__ import annotations

import numpy as np

from ..jit import jit

MAX_SPHERES = 16  # more emitters than this share one bounding sphere (the test is per sphere)


def emitter_spheres(corners: np.ndarray, group: np.ndarray, ray_epsilon: float,
                    spheres: np.ndarray | None = None, sphere_group: np.ndarray | None = None) -> np.ndarray:
    """``(B, 4)`` spheres (center, radius) around emitting triangles ``corners (T, 3, 3)`` and
    analytic sphere emitters ``spheres (S, 4)``, one per ``group`` / ``sphere_group`` id (an
    emissive shape), or one around them all when there are more than ``MAX_SPHERES`` groups.
    Radii are padded by the scene's ray offset and 1e-6 relative, so that float32 rays that hit
    an emitter for Embree (or for the sphere test) always meet its bounding sphere."""
    spheres = np.zeros((0, 4)) if spheres is None else spheres
    sphere_group = np.zeros(0, dtype=np.int64) if sphere_group is None else sphere_group
    n_tri = len(corners)
    owner = np.concatenate([group, sphere_group]).astype(np.int64)
    groups = [np.flatnonzero(owner == g) for g in np.unique(owner)]
    if len(groups) > MAX_SPHERES:
        groups = [np.arange(len(owner))]
    out = np.zeros((len(groups), 4))
    for row, members in enumerate(groups):
        points = corners[members[members < n_tri]].reshape(-1, 3)
        balls = spheres[members[members >= n_tri] - n_tri]
        lo = np.min(np.concatenate([points, balls[:, :3] - balls[:, 3:]]), axis=0)
        hi = np.max(np.concatenate([points, balls[:, :3] + balls[:, 3:]]), axis=0)
        center = 0.5 * (lo + hi)
        radius = max(np.sqrt(np.max(np.sum((points - center) ** 2, axis=1), initial=0.0)),
                     np.max(np.linalg.norm(balls[:, :3] - center, axis=1) + balls[:, 3], initial=0.0))
        out[row, :3] = center
        out[row, 3] = radius * (1.0 + 1e-6) + ray_epsilon + 1e-6 * np.max(np.abs(center))
    return out


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
