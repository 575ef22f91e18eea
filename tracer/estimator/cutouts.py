"""Cutouts: surfaces that stop only a fraction of the light that meets them (Mitsuba's ``mask``).

A material row's opacity a in [0, 1] (``MaterialTable.opacity``, a constant or a texture
looked up at the hit) is the fraction of light its surface stops. The estimator sees it in
three places, each an unbiased estimate of light passing a fraction 1 - a:

- **camera rays**: a hit is kept with probability a and passed through otherwise, the ray
  cast on from just beyond it (pbrt-v4's stochastic alpha test, "Intersection tests" in
  Physically Based Rendering, 4th ed., sec. 7.1.1), until a kept hit or a miss. The uniform of
  layer k is dimension k of a stream of its own per lane (the independent sampler's hash keyed
  by the seed with ``SALT``), so that the decisions do not draw on the dimensions the strategy's
  samples use (``tracer.samplers.dimensions``) and a lane's decisions are the same in any batch;
- **shadow rays**: a ray that Embree finds blocked is followed through each cutout it crosses
  to the end of its segment, its value multiplied by that cutout's 1 - a; an opaque surface or a = 1 blocks it
  (deterministic transmittance, as Mitsuba's ``volpath`` weighs a ``mask`` on a shadow ray:
  lower variance than a stochastic test and no random numbers);
- **direction rays**: likewise, through each cutout to the first surface that is not one, which
  is what the ray's MIS weight and emitter are read from.

Rays are re-cast in rounds (a wavefront per layer) from Python, as the camera, shadow and
direction rays are cast (``tracer.estimator``); after ``MAX_LAYERS`` cutouts a ray is taken as
stopped (kept, or blocked), which no scene of fewer stacked cutouts meets. A scene without
cutouts runs none of this. An emitter cannot be a cutout (the readers refuse one).
"""

from __future__ import annotations

import math

import numpy as np

from ..frame import dot, normalized, sub
from ..geometry import offset_origin, surface_point
from ..jit import jit
from ..samplers.independent import lane_key, stream_uniform
from ..textures.lookup import uv_at, value_at

# Cutouts one ray may pass before it counts as stopped (see the module's docstring).
MAX_LAYERS = 256
# Xor'ed into the sampler's seed key: the pass-through decisions' stream of a lane.
SALT = np.uint64(0x6A09E667F3BCC909)


def present(opacity: np.ndarray, opacity_texture: np.ndarray) -> bool:
    """Whether a scene has any cutout: a material row with opacity below 1 or a textured one."""
    return bool(np.any(opacity < 1.0) or np.any(opacity_texture >= 0))


@jit
def opacity_at(hit_table, first_sphere: int, opacity, textures, p: int, x) -> float:
    """The opacity of primitive ``p`` at its point ``x``: its material row's constant, or its
    texture's one-number value there clamped into [0, 1] (Mitsuba's ``eval_opacity``)."""
    row = int(hit_table[p, 15])
    texture = textures.opacity[row]
    if texture < 0:
        return opacity[row]
    u, v = uv_at(textures, hit_table, first_sphere, p, x)
    return min(max(value_at(textures, texture, True, hit_table, p, x, u, v)[0], 0.0), 1.0)


@jit
def _is_cutout(hit_table, opacity, textures, p: int) -> bool:
    row = int(hit_table[p, 15])
    return opacity[row] < 1.0 or textures.opacity[row] >= 0


@jit
def _crossing(origins, dirs, i: int, hit_table, first_sphere: int, eps: float, opacity, textures, p: int):
    """Where ray ``i`` (``origins[i], dirs[i]``) goes on beyond its hit of cutout ``p``: the
    offset point past the hit, and the opacity there."""
    o = (float(origins[i, 0]), float(origins[i, 1]), float(origins[i, 2]))
    d = (float(dirs[i, 0]), float(dirs[i, 1]), float(dirs[i, 2]))
    x, face_normal, _ = surface_point(hit_table, first_sphere, p, o, d)
    return offset_origin(x, eps, face_normal, d), opacity_at(hit_table, first_sphere, opacity, textures, p, x)


@jit
def pass_camera(lanes, prim, origins, dirs, pixel, sample, seed_key, layer: int, hit_table, first_sphere: int,
                eps: float, opacity, textures, passing) -> int:
    """Decide layer ``layer`` of the camera lanes ``lanes`` (indices into the batch), whose rays
    ``origins, dirs (n, 3)`` float32 hit ``prim``: a lane whose hit is a cutout of opacity a
    passes with probability 1 - a, its origin moved to just beyond the hit (in place). Writes
    the passing lanes into ``passing`` and returns their count."""
    key_of_seed = seed_key ^ SALT
    count = 0
    for k in range(len(lanes)):
        lane = lanes[k]
        p = prim[lane]
        if p < 0 or not _is_cutout(hit_table, opacity, textures, p):
            continue
        beyond, a = _crossing(origins, dirs, lane, hit_table, first_sphere, eps, opacity, textures, p)
        if stream_uniform(lane_key(key_of_seed, pixel[lane], sample[lane]), layer) < a:
            continue  # kept: the camera sees this surface
        for c in range(3):
            origins[lane, c] = beyond[c]
        passing[count] = lane
        count += 1
    return count


@jit
def through_shadow(rows, prim, origins, dirs, ends, value, v2, blocked, hit_table, first_sphere: int,
                   eps: float, opacity, textures, passing) -> int:
    """One layer of the shadow rays ``rows`` that something blocks: ``prim[k]`` is what row
    ``rows[k]``'s ray ``origins[k], dirs[k]`` hits first, and ``ends[k]`` is where its segment
    ends (the original ray's end, just short of the light point; not finite for a light at
    infinity, whose ray has no end). A hit beyond the end, or none, unblocks the row; an opaque
    hit, or a cutout of opacity 1, blocks it; a cutout of opacity a < 1 multiplies the row's
    ``value`` by 1 - a (and the mean square of its value ``v2``, which adaptive allocation
    learns from, by (1 - a)²; the terms of optimal MIS's C stay: a sample that carries any light
    is in C's support, ``tracer.tuning``) and starts the rest of the segment just beyond it:
    ``origins[k]`` and ``dirs[k]`` are set to the segment from there to the same end (re-aimed,
    since the offset moves the start off the line: kept on it, the end would move by the offset
    over the cosine and could reach the light; a ray to infinity keeps its direction). Writes
    the positions k of the rows still to follow into ``passing`` and returns their count."""
    count = 0
    for k in range(len(rows)):
        row = rows[k]
        p = prim[k]
        blocked[row] = False
        if p < 0:
            continue
        o = (float(origins[k, 0]), float(origins[k, 1]), float(origins[k, 2]))
        d = (float(dirs[k, 0]), float(dirs[k, 1]), float(dirs[k, 2]))
        end = (ends[k, 0], ends[k, 1], ends[k, 2])
        bounded = math.isfinite(end[0] + end[1] + end[2])
        x, face_normal, _ = surface_point(hit_table, first_sphere, p, o, d)
        if bounded and dot(sub(x, o), d) >= dot(sub(end, o), d):
            continue  # the first thing on the line lies beyond the segment's end
        a = opacity_at(hit_table, first_sphere, opacity, textures, p, x) \
            if _is_cutout(hit_table, opacity, textures, p) else 1.0
        if a >= 1.0:
            blocked[row] = True
            continue
        for c in range(3):
            value[row, c] *= 1.0 - a
        v2[row] *= (1.0 - a) * (1.0 - a)
        beyond = offset_origin(x, eps, face_normal, d)
        rest = d
        if bounded:
            if dot(sub(end, beyond), d) <= 0.0:
                continue  # the cutout lies at the end itself: nothing more between
            rest, _ = normalized(sub(end, beyond))
        for c in range(3):
            origins[k, c] = beyond[c]
            dirs[k, c] = rest[c]
        blocked[row] = True  # until a later layer finds the rest of the segment clear
        passing[count] = k
        count += 1
    return count


@jit
def through_direction(rows, prim, origins, dirs, value, hit_table, first_sphere: int, eps: float, opacity,
                      textures, passing) -> int:
    """One layer of the direction rays ``rows`` whose hits ``prim`` (indexed by row) may be
    cutouts: a cutout of opacity a < 1 multiplies the row's ``value`` by 1 - a and moves its
    origin (``origins``, indexed by row, in place) past the hit. Writes the rows to cast again
    into ``passing`` and returns their count; a row whose hit is not a cutout (or has opacity 1)
    keeps it: that is the surface the ray ends on."""
    count = 0
    for k in range(len(rows)):
        row = rows[k]
        p = prim[row]
        if p < 0 or not _is_cutout(hit_table, opacity, textures, p):
            continue
        beyond, a = _crossing(origins, dirs, row, hit_table, first_sphere, eps, opacity, textures, p)
        if a >= 1.0:
            continue
        for c in range(3):
            value[row, c] *= 1.0 - a
            origins[row, c] = beyond[c]
        passing[count] = row
        count += 1
    return count


class Cutouts:
    """The cutouts of one scene and the rounds that carry rays through them (read-only after
    construction; its methods write only the arrays they are given)."""

    def __init__(self, rays, hit_table: np.ndarray, first_sphere: int, eps: float, opacity: np.ndarray,
                 textures):
        self.rays = rays  # SceneRays of the whole scene
        self.hit_table, self.first_sphere, self.eps = hit_table, first_sphere, eps
        self.opacity, self.textures = np.ascontiguousarray(opacity, dtype=np.float64), textures

    def calls(self, sampler) -> list:
        """The compiled functions of the rounds, with arguments of their types, for
        ``DirectLighting.compile`` (``tracer.kernels.compiling.Call``)."""
        from ..kernels.compiling import Call

        common = self._common()
        rows = np.zeros(0, dtype=np.int64)
        rays = np.zeros((0, 3), dtype=np.float32)
        prim = np.zeros(0, dtype=np.int32)
        value = np.zeros((0, 3))
        scalars = np.zeros(0)
        blocked = np.zeros(0, dtype=np.bool_)
        return [Call((rows, prim, rays, rays, rows, rows, sampler.seed_key, 0, *common, rows),
                     function=pass_camera),
                Call((rows, prim, rays, rays, value, value, scalars, blocked, *common, rows),
                     function=through_shadow),
                Call((rows, prim, rays, rays, value, *common, rows), function=through_direction)]

    def _common(self) -> tuple:
        return self.hit_table, self.first_sphere, self.eps, self.opacity, self.textures

    def camera(self, prim: np.ndarray, origins: np.ndarray, dirs: np.ndarray, pixel: np.ndarray,
               sample: np.ndarray, seed_key) -> None:
        """Carry camera rays through the cutouts they hit: ``prim`` (n,) and ``origins`` (n, 3)
        float32 are updated in place to the hit each lane keeps."""
        hit_table, first_sphere, eps, opacity, textures = self._common()
        lanes = np.arange(len(prim), dtype=np.int64)
        passing = np.empty(len(prim), dtype=np.int64)
        for layer in range(MAX_LAYERS):
            count = pass_camera(lanes, prim, origins, dirs, pixel, sample, seed_key, layer, hit_table,
                                first_sphere, eps, opacity, textures, passing)
            if count == 0:
                return
            lanes = passing[:count].copy()
            prim[lanes] = self.rays.first_hit(origins[lanes], dirs[lanes])

    def shadow(self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray, value: np.ndarray,
               v2: np.ndarray, blocked: np.ndarray) -> None:
        """Follow the blocked shadow rays through the cutouts on their segments: ``blocked`` (n,),
        ``value`` (n, 3) and ``v2`` (n,) are updated in place (the rays themselves are not
        changed)."""
        hit_table, first_sphere, eps, opacity, textures = self._common()
        rows = np.flatnonzero(blocked).astype(np.int64)
        here = np.ascontiguousarray(origins[rows], dtype=np.float32)
        toward = np.ascontiguousarray(dirs[rows], dtype=np.float32)
        # Where each segment ends; a light at infinity's (tmax inf) has no end: inf, or NaN
        # where a component of its direction is 0, both read as "not finite" by the kernel.
        with np.errstate(invalid="ignore"):
            ends = here + np.asarray(tmax[rows], dtype=np.float64)[:, None] * toward
        passing = np.empty(len(rows), dtype=np.int64)
        for _ in range(MAX_LAYERS):
            if not len(rows):
                return
            prim = self.rays.first_hit(here, toward)
            count = through_shadow(rows, prim, here, toward, ends, value, v2, blocked, hit_table,
                                   first_sphere, eps, opacity, textures, passing)
            keep = passing[:count]
            rows, here, toward, ends = rows[keep], here[keep], toward[keep], ends[keep]

    def direction(self, prim: np.ndarray, origins: np.ndarray, dirs: np.ndarray, value: np.ndarray) -> None:
        """Carry direction rays through the cutouts they hit: ``prim`` (n,), ``origins`` (n, 3)
        float32 and ``value`` (n, 3) are updated in place."""
        hit_table, first_sphere, eps, opacity, textures = self._common()
        rows = np.arange(len(prim), dtype=np.int64)
        passing = np.empty(len(prim), dtype=np.int64)
        for _ in range(MAX_LAYERS):
            count = through_direction(rows, prim, origins, dirs, value, hit_table, first_sphere, eps, opacity,
                                      textures, passing)
            if count == 0:
                return
            rows = passing[:count].copy()
            prim[rows] = self.rays.first_hit(origins[rows], dirs[rows])
