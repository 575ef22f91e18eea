"""Direct lighting estimators: five strategies as settings of one estimator.

    L(x, wo) = Le(x, wo) + integral f(x, wi, wo) Le(y(x, wi), -wi) |cos theta_i| dwi

Two techniques sample ``wi`` at a shading point:

- the *light* technique (light.py): a point on an emitter, pdf converted to solid angle;
- a *direction* technique: ``uniform`` (1/2pi), ``cosine`` (cos/pi) or ``bsdf`` (the
  material's own sampling), followed by a ray that may hit an emitter.

A strategy is a pair of sample counts (Mitsuba's ``emitter_samples``/``bsdf_samples``):

=========  ==============  =================  =========================
strategy   light samples   direction samples  direction sampler
=========  ==============  =================  =========================
uniform    0               M                  uniform hemisphere
cosine     0               M                  cosine hemisphere
bsdf       0               M                  BSDF
light      N               0                  -
mis        N               M                  BSDF, weighted by a heuristic
=========  ==============  =================  =========================

Multi-sample MIS (Veach 1997, section 9.2) weights a light sample by
w_l = h(N p_l, M p_b) and a BSDF sample by w_b = h(M p_b, N p_l), each sample's contribution
divided by its own count. One-sample MIS (section 9.2.4) picks one technique per camera
sample with probability c_l = N / (N + M) and divides by c times its pdf; the weights use
c p. With a single technique the other count is 0 and the weight is 1.

Delta rule: a point light's sample and a mirror's sample get weight 1, because the other
technique produces them with probability 0. Whatever a technique cannot see (a point light
from BSDF or hemisphere sampling, a mirror's reflection from light sampling) contributes 0.

A batch runs as a wavefront of three ray casts and two compiled loops over its lanes
(``tracer.jit``): Embree finds the camera hits; ``_shade`` samples the light and direction
techniques at every shading point and writes one shadow ray per light sample and one ray per
direction sample, with what each would contribute; Embree casts both sets; ``_gather`` adds
the unblocked light samples and the direction samples that hit an emitter, with their MIS
weights. Samples that can only contribute 0 cast no ray: a light sample with zero value, and a
direction sample whose ray meets none of the emitters' bounding spheres (``lights.may_reach``).
Random numbers are ``rand.uniform(key, lane, dimension)``: dimension 0 chooses the
technique in one-sample MIS, light sample j uses 1 + 3j .. 3 + 3j, direction sample j uses
the two after all light samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import bsdf, lights, mis, rand, warp
from .embree import RayCaster
from .frame import add_scaled, basis, dot, normalized, scale, sub, to_local, to_world
from .jit import jit
from .lights import LightSampler, LightTables
from .scene import STRATEGIES, Scene

DIRECTION_SAMPLER = {"uniform": "uniform", "cosine": "cosine", "bsdf": "bsdf", "mis": "bsdf"}
# Codes of the direction samplers for compiled code.
NO_SAMPLER, UNIFORM, COSINE, BSDF = 0, 1, 2, 3
SAMPLER_CODE = {None: NO_SAMPLER, "uniform": UNIFORM, "cosine": COSINE, "bsdf": BSDF}


@dataclass(frozen=True)
class Strategy:
    """How to estimate direct light: a strategy name and its sample counts.

    ``light_samples`` is used by ``light`` and ``mis``; ``bsdf_samples`` by ``uniform``,
    ``cosine``, ``bsdf`` and ``mis`` (it counts the direction samples of each).
    """

    name: str = "mis"
    heuristic: str = "power"
    light_samples: int = 1
    bsdf_samples: int = 1
    one_sample: bool = False
    light_selection: str = "power"

    def __post_init__(self) -> None:
        if self.name not in STRATEGIES:
            raise ValueError(f"unknown strategy {self.name!r}; expected one of {STRATEGIES}")
        mis.code(self.heuristic)  # raises on an unknown name
        if self.light_samples < 0 or self.bsdf_samples < 0:
            raise ValueError("sample counts must be >= 0")
        if self.light_count + self.direction_count == 0:
            raise ValueError(f"strategy {self.name!r} with these counts takes no samples")

    @property
    def label(self) -> str:
        """A short description such as ``mis (power, 1 light + 1 bsdf)``."""
        if self.name == "mis":
            mode = "one-sample, " if self.one_sample else ""
            return f"mis ({mode}{self.heuristic}, {self.light_samples} light + {self.bsdf_samples} bsdf)"
        count = self.light_count or self.direction_count
        return self.name if count == 1 else f"{self.name} (x{count})"

    @property
    def light_count(self) -> int:
        return self.light_samples if self.name in ("light", "mis") else 0

    @property
    def direction_count(self) -> int:
        return self.bsdf_samples if self.name != "light" else 0

    @property
    def direction_sampler(self) -> str | None:
        return DIRECTION_SAMPLER.get(self.name)

    @property
    def one_sample_mis(self) -> bool:
        """Each shading point takes one technique, chosen at random (both counts > 0)."""
        return self.one_sample and self.light_count > 0 and self.direction_count > 0


class Surfaces(NamedTuple):
    """The scene as the kernels read it.

    hit_table : (F, 16) per triangle: v0, edge1, edge2, face normal, emission, material row.
    kind : (K,) int8, reflectance : (K, 3), alpha : (K,): the material table.
    eps : ray offset along the normal (``Scene.ray_epsilon``).
    """

    hit_table: np.ndarray
    kind: np.ndarray
    reflectance: np.ndarray
    alpha: np.ndarray
    eps: float


class Plan(NamedTuple):
    """A strategy as the kernels read it.

    n_light, n_dir : samples per shading point of each technique (0 if unused).
    sampler : direction sampler code.   heuristic : MIS heuristic code.
    one_sample : one-sample MIS.   c_light : probability of the light technique in it.
    """

    n_light: int
    n_dir: int
    sampler: int
    heuristic: int
    one_sample: bool
    c_light: float


class DirectLighting:
    """The estimator for one scene and strategy, shared by all render threads (read-only)."""

    def __init__(self, scene: Scene, strategy: Strategy, caster: RayCaster | None = None):
        self.scene = scene
        self.strategy = strategy
        self.caster = caster if caster is not None else RayCaster(scene.vertices, scene.faces)
        self.lights = LightSampler(scene, strategy.light_selection)
        m = scene.materials
        self.surfaces = Surfaces(np.ascontiguousarray(scene.hit_table), np.ascontiguousarray(m.kind),
                                 np.ascontiguousarray(m.reflectance, dtype=np.float64),
                                 np.ascontiguousarray(m.alpha, dtype=np.float64), float(scene.ray_epsilon))
        n_light, n_dir = strategy.light_count, strategy.direction_count
        self.plan = Plan(n_light, n_dir, SAMPLER_CODE[strategy.direction_sampler],
                         mis.code(strategy.heuristic), strategy.one_sample_mis, n_light / (n_light + n_dir))

    def radiance(self, origins: np.ndarray, dirs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Radiance along camera rays ``(n, 3)`` (dirs unit length): emission seen directly plus
        direct lighting. Returns ``(n, 3)`` float64, one Monte Carlo sample per ray; the
        caller guards against non-finite values. Draws one 64-bit key from ``rng``."""
        key = rand.batch_key(rng)
        n = len(origins)
        plan = self.plan
        shadow = RayBuffer.empty(n if plan.one_sample else n * plan.n_light)
        direction = RayBuffer.empty(n if plan.one_sample else n * plan.n_dir)
        prim = self.caster.first_hit(origins, dirs)
        radiance = np.empty((n, 3))
        tables = self.lights.tables
        n_shadow, n_direction = _shade(prim, origins, dirs, key, self.surfaces, tables, plan,
                                       radiance, shadow, direction)
        s, d = slice(0, n_shadow), slice(0, n_direction)
        blocked = self.caster.occluded(shadow.origin[s], shadow.dir[s], shadow.tmax[s])
        found = self.caster.first_hit(direction.origin[d], direction.dir[d])
        _gather(radiance, self.surfaces, tables, plan, shadow, blocked, direction, found)
        return radiance


class RayBuffer(NamedTuple):
    """Rays from shading points, written by ``_shade``, one row per sample that may contribute.
    Shadow and direction rays share the layout; each leaves the other's fields unwritten.

    origin, dir : (c, 3) float32 for Embree (dir unit length, world).
    tmax : (c,) float32 shadow-ray length (shadow rays only).
    value : (c, 3) what the sample adds if its ray is unblocked (shadow) or hits an emitter
        (direction; then times the emitter's radiance and the MIS weight).
    point : (c, 3) float64 shading point the ray leaves (direction rays only): the light pdf
        of the direction is measured from it, as light sampling measures it.
    pdf : (c,) count-scaled pdf of the direction technique (direction rays only, for MIS).
    lane : (c,) camera lane the sample belongs to.   delta : (c,) a delta sample (weight 1).
    """

    origin: np.ndarray
    dir: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    point: np.ndarray
    pdf: np.ndarray
    lane: np.ndarray
    delta: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "RayBuffer":
        f32 = np.float32
        return cls(np.empty((count, 3), dtype=f32), np.empty((count, 3), dtype=f32),
                   np.empty(count, dtype=f32), np.empty((count, 3)), np.empty((count, 3)), np.empty(count),
                   np.empty(count, dtype=np.int64), np.empty(count, dtype=np.bool_))


# -------------------------------------------------------------------------------------------------
# Compiled kernels
#
# The kernels unpack their named tuples once, before the loop over lanes: reading an array out
# of a tuple inside the loop costs a reference-count update (~25 ns) each time.


@jit
def _shade(prim, origins, dirs, key, surfaces: Surfaces, light_tables: LightTables, plan: Plan,
           radiance, shadow: RayBuffer, direction: RayBuffer):
    """Camera hits -> emission seen directly into ``radiance (n, 3)``, and the shadow and
    direction rays of every shading point into the buffers. Returns their counts."""
    hit_table, kinds, reflectances, alphas, eps = surfaces
    alias_prob, alias, pmf, area, point_lights, _, spheres = light_tables
    shadow_origin, shadow_dir, shadow_tmax, shadow_value, _, _, shadow_lane, _ = shadow
    dir_origin, dir_dir, _, dir_value, dir_point, dir_pdf, dir_lane, dir_delta = direction
    n_light, n_dir = float(plan.n_light), float(plan.n_dir)
    n_shadow = 0
    n_direction = 0
    for lane in range(len(prim)):
        radiance[lane, 0] = radiance[lane, 1] = radiance[lane, 2] = 0.0
        p = prim[lane]
        if p < 0:
            continue
        d = (float(dirs[lane, 0]), float(dirs[lane, 1]), float(dirs[lane, 2]))
        face_normal = (hit_table[p, 9], hit_table[p, 10], hit_table[p, 11])
        cos_view = -dot(face_normal, d)
        # Emitters seen directly (weight 1 in every strategy): front side only.
        if cos_view > 0.0:
            for channel in range(3):
                radiance[lane, channel] = hit_table[p, 12 + channel]
        material = int(hit_table[p, 15])
        kind = kinds[material]
        if kind == bsdf.NONE or cos_view == 0.0:
            continue
        # The shading point, where the ray meets the triangle's plane (float64; Embree's own
        # distance is float32), and a frame around the face normal flipped toward the viewer.
        o = (float(origins[lane, 0]), float(origins[lane, 1]), float(origins[lane, 2]))
        x = add_scaled(o, _plane_distance(hit_table, p, o, -cos_view), d)
        normal = scale(1.0 if cos_view > 0.0 else -1.0, face_normal)
        s, t = basis(normal)
        wo = to_local(s, t, normal, scale(-1.0, d))
        origin = add_scaled(x, eps, normal)
        reflectance = (reflectances[material, 0], reflectances[material, 1], reflectances[material, 2])
        alpha = alphas[material]
        stream = rand.lane_stream(key, lane)

        # Which samples this point takes: (light samples, direction samples, their counts).
        if plan.one_sample:
            take_light = rand.uniform(stream, 0) < plan.c_light
            lights_here, dirs_here = (1, 0) if take_light else (0, 1)
            own_light, own_dir = plan.c_light, 1.0 - plan.c_light
        else:
            lights_here, dirs_here = plan.n_light, plan.n_dir
            own_light, own_dir = n_light, n_dir

        for j in range(lights_here):
            dim = 1 + 3 * j
            wi_world, dist, le, pdf_light, delta = lights.sample(
                alias_prob, alias, pmf, area, point_lights, rand.uniform(stream, dim),
                rand.uniform(stream, dim + 1), rand.uniform(stream, dim + 2), x)
            if not pdf_light > 0.0:
                continue
            wi = to_local(s, t, normal, wi_world)
            # f Le |cos| w_l / (own p_l); other = 0 (no direction technique) gives weight 1.
            f, pdf_bsdf = bsdf.shape_and_pdf(kind, alpha, wo, wi)
            c = f * max(wi[2], 0.0) / (own_light * pdf_light)
            if own_dir > 0.0 and plan.sampler != NO_SAMPLER and not delta:
                pdf_dir = pdf_bsdf if plan.sampler == BSDF else _hemisphere_pdf(plan.sampler, wi[2])
                c *= mis.weight_of(plan.heuristic, own_light * pdf_light, own_dir * pdf_dir)
            value = (reflectance[0] * le[0] * c, reflectance[1] * le[1] * c, reflectance[2] * le[2] * c)
            if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
                _flag_nan(radiance, lane, value)
                continue
            # The shadow ray runs from the offset origin to the sampled point, stopping short of it.
            to_target, length = normalized(sub(add_scaled(x, dist, wi_world), origin))
            shadow_tmax[n_shadow] = max(length - eps, 0.0)
            n_shadow = _put(shadow_origin, shadow_dir, shadow_value, shadow_lane, n_shadow,
                            origin, to_target, value, lane)

        for j in range(dirs_here):
            dim = 1 + 3 * plan.n_light + 2 * j
            u0, u1 = rand.uniform(stream, dim), rand.uniform(stream, dim + 1)
            wi, weight, pdf_dir, delta = _direction_sample(plan.sampler, kind, alpha, wo, u0, u1)
            # f |cos| / (own p_d); _gather multiplies in the emitter it hits and the MIS weight.
            c = weight / own_dir
            value = (reflectance[0] * c, reflectance[1] * c, reflectance[2] * c)
            if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
                _flag_nan(radiance, lane, value)
                continue
            wi_world = to_world(s, t, normal, wi)
            if not lights.may_reach(spheres, origin, wi_world):
                continue  # it could only contribute 0: no ray
            dir_pdf[n_direction] = own_dir * pdf_dir
            dir_delta[n_direction] = delta
            for axis in range(3):
                dir_point[n_direction, axis] = x[axis]
            n_direction = _put(dir_origin, dir_dir, dir_value, dir_lane, n_direction,
                               origin, wi_world, value, lane)
    return n_shadow, n_direction


@jit
def _plane_distance(hit_table, p, o, cos_normal) -> float:
    """Distance from ``o`` along a unit direction d to the plane of triangle ``p``, given
    cos_normal = d . face normal (nonzero): (v0 - o) . n / (d . n)."""
    return ((hit_table[p, 0] - o[0]) * hit_table[p, 9] + (hit_table[p, 1] - o[1]) * hit_table[p, 10]
            + (hit_table[p, 2] - o[2]) * hit_table[p, 11]) / cos_normal


@jit
def _flag_nan(radiance, lane, value) -> None:
    """A sample value that is NaN marks its lane's radiance NaN, so that the render loop counts
    and zeroes it (``render._zero_nonfinite``) instead of the sample vanishing unnoticed."""
    if math.isnan(value[0] + value[1] + value[2]):
        radiance[lane, 0] = math.nan


@jit
def _put(origins, dirs, values, lanes, row, origin, direction, value, lane) -> int:
    """Write one ray and what it carries into row ``row``; returns the next free row."""
    for c in range(3):
        origins[row, c] = origin[c]
        dirs[row, c] = direction[c]
        values[row, c] = value[c]
    lanes[row] = lane
    return row + 1


@jit
def _direction_sample(sampler, kind, alpha, wo, u0, u1):
    """One direction from the strategy's sampler: ``(wi, weight, pdf, delta)`` with weight =
    f |cos| / pdf (the reflectance left out), as ``bsdf.sample`` returns it."""
    if sampler == BSDF:
        return bsdf.sample(kind, alpha, wo, u0, u1)
    wi = warp.uniform_hemisphere(u0, u1) if sampler == UNIFORM else warp.cosine_hemisphere(u0, u1)
    pdf_dir = _hemisphere_pdf(sampler, wi[2])
    weight = bsdf.shape(kind, alpha, wo, wi) * max(wi[2], 0.0) / pdf_dir if pdf_dir > 0.0 else 0.0
    return wi, weight, pdf_dir, False


@jit
def _hemisphere_pdf(sampler, cos_i):
    """pdf of the uniform or cosine hemisphere sampler at a direction with cos(theta) = cos_i."""
    if sampler == UNIFORM:
        return warp.uniform_hemisphere_pdf(cos_i)
    return warp.cosine_hemisphere_pdf(cos_i)


@jit
def _gather(radiance, surfaces: Surfaces, light_tables: LightTables, plan: Plan, shadow: RayBuffer, blocked,
            direction: RayBuffer, prim):
    """Add to ``radiance`` the light samples whose shadow rays are unblocked, and the direction
    samples whose rays hit the front of an emitter, weighted against the light technique."""
    hit_table = surfaces.hit_table
    by_triangle = light_tables.by_triangle
    shadow_value, shadow_lane = shadow.value, shadow.lane
    for row in range(len(blocked)):
        if not blocked[row]:
            lane = shadow_lane[row]
            for c in range(3):
                radiance[lane, c] += shadow_value[row, c]
    other = plan.c_light if plan.one_sample else float(plan.n_light)
    _, dirs, _, values, points, pdfs, lanes, deltas = direction
    for row in range(len(prim)):
        p = prim[row]
        if p < 0:
            continue
        wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
        cos_normal = hit_table[p, 9] * wi[0] + hit_table[p, 10] * wi[1] + hit_table[p, 11] * wi[2]
        if not cos_normal < 0.0:
            continue  # emitters shine from the front only
        w = 1.0
        if other > 0.0 and not deltas[row]:
            x = (points[row, 0], points[row, 1], points[row, 2])
            pdf_light = lights.pdf(by_triangle, p, wi, _plane_distance(hit_table, p, x, cos_normal))
            w = mis.weight_of(plan.heuristic, pdfs[row], other * pdf_light)
        lane = lanes[row]
        for c in range(3):
            radiance[lane, c] += values[row, c] * hit_table[p, 12 + c] * w
