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
weights. Random numbers are ``rand.uniform(key, lane, dimension)``: dimension 0 chooses the
technique in one-sample MIS, light sample j uses 1 + 3j .. 3 + 3j, direction sample j uses
the two after all light samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import bsdf, lights, mis, rand, warp
from .embree import RayCaster
from .frame import add_scaled, basis, normalized, scale, sub, to_local, to_world
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
        hits = self.caster.intersect(origins, dirs)
        radiance = np.empty((n, 3))
        tables = self.lights.tables
        n_shadow, n_direction = _shade(hits.prim, hits.u, hits.v, dirs, key, self.surfaces, tables, plan,
                                       radiance, shadow, direction)
        s, d = slice(0, n_shadow), slice(0, n_direction)
        blocked = self.caster.occluded(shadow.origin[s], shadow.dir[s], shadow.tmax[s])
        found = self.caster.intersect(direction.origin[d], direction.dir[d])
        _gather(radiance, self.surfaces, tables, plan, shadow, blocked, direction, found.prim, found.t)
        return radiance


class RayBuffer(NamedTuple):
    """Rays from shading points, written by ``_shade``, one row per sample that may contribute.

    origin, dir : (c, 3) float32 for Embree (dir unit length, world).
    tmax : (c,) float32 shadow-ray length (shadow rays only).
    value : (c, 3) what the sample adds if its ray is unblocked (shadow) or hits an emitter
        (direction; then times the emitter's radiance and the MIS weight).
    pdf : (c,) count-scaled pdf of the direction technique (direction rays only, for MIS).
    lane : (c,) camera lane the sample belongs to.   delta : (c,) a delta sample (weight 1).
    """

    origin: np.ndarray
    dir: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    pdf: np.ndarray
    lane: np.ndarray
    delta: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "RayBuffer":
        return cls(np.empty((count, 3), dtype=np.float32), np.empty((count, 3), dtype=np.float32),
                   np.empty(count, dtype=np.float32), np.empty((count, 3)), np.empty(count),
                   np.empty(count, dtype=np.int64), np.empty(count, dtype=np.bool_))


# -------------------------------------------------------------------------------------------------
# Compiled kernels


@jit
def _shade(prim, hit_u, hit_v, dirs, key, surfaces: Surfaces, light_tables: LightTables, plan: Plan,
           radiance, shadow: RayBuffer, direction: RayBuffer):
    """Camera hits -> emission seen directly into ``radiance (n, 3)``, and the shadow and
    direction rays of every shading point into the buffers. Returns their counts."""
    n_shadow = 0
    n_direction = 0
    for lane in range(len(prim)):
        radiance[lane, 0] = radiance[lane, 1] = radiance[lane, 2] = 0.0
        p = prim[lane]
        if p < 0:
            continue
        g = surfaces.hit_table[p]
        d = (float(dirs[lane, 0]), float(dirs[lane, 1]), float(dirs[lane, 2]))
        cos_view = -(g[9] * d[0] + g[10] * d[1] + g[11] * d[2])
        # Emitters seen directly (weight 1 in every strategy): front side only.
        if cos_view > 0.0:
            radiance[lane, 0], radiance[lane, 1], radiance[lane, 2] = g[12], g[13], g[14]
        material = int(g[15])
        kind = surfaces.kind[material]
        if kind == bsdf.NONE or cos_view == 0.0:
            continue
        # The shading point: frame around the face normal flipped toward the viewer.
        u, v = float(hit_u[lane]), float(hit_v[lane])
        x = (g[0] + u * g[3] + v * g[6], g[1] + u * g[4] + v * g[7], g[2] + u * g[5] + v * g[8])
        sign = 1.0 if cos_view > 0.0 else -1.0
        normal = (sign * g[9], sign * g[10], sign * g[11])
        s, t = basis(normal)
        wo = to_local(s, t, normal, scale(-1.0, d))
        origin = add_scaled(x, surfaces.eps, normal)
        point = (x, origin, s, t, normal, wo, kind, surfaces.reflectance[material], surfaces.alpha[material],
                 surfaces.eps)
        stream = rand.lane_stream(key, lane)
        n_light, n_dir = float(plan.n_light), float(plan.n_dir)
        if plan.one_sample:
            if rand.uniform(stream, 0) < plan.c_light:
                n_shadow = _light_sample(point, lane, stream, 1, plan.c_light, 1.0 - plan.c_light,
                                         light_tables, plan, shadow, n_shadow)
            else:
                n_direction = _direction_sample(point, lane, stream, 1 + 3 * plan.n_light, 1.0 - plan.c_light,
                                                plan, direction, n_direction)
            continue
        for j in range(plan.n_light):
            n_shadow = _light_sample(point, lane, stream, 1 + 3 * j, n_light, n_dir, light_tables, plan,
                                     shadow, n_shadow)
        for j in range(plan.n_dir):
            n_direction = _direction_sample(point, lane, stream, 1 + 3 * plan.n_light + 2 * j, n_dir,
                                            plan, direction, n_direction)
    return n_shadow, n_direction


@jit
def _light_sample(point, lane, stream, dim, own, other, light_tables, plan, out, row):
    """One light sample at ``point``: f Le |cos| w_l / (own p_l) into ``out[row]`` with its shadow
    ray, if it can contribute. ``own`` scales this technique's pdf (its sample count, or its
    selection probability in one-sample MIS), ``other`` the direction technique's; other = 0
    gives weight 1. Returns the next free row."""
    x, origin, s, t, normal, wo, kind, reflectance, alpha, eps = point
    u_select, u0, u1 = rand.uniform(stream, dim), rand.uniform(stream, dim + 1), rand.uniform(stream, dim + 2)
    wi_world, dist, le, pdf_light, delta = lights.sample(light_tables, u_select, u0, u1, x)
    if not pdf_light > 0.0:
        return row
    wi = to_local(s, t, normal, wi_world)
    c = bsdf.shape(kind, alpha, wo, wi) * max(wi[2], 0.0) / (own * pdf_light)
    if other > 0.0 and plan.sampler != NO_SAMPLER and not delta:
        pdf_dir = _direction_pdf(plan.sampler, kind, alpha, wo, wi)
        c *= mis.weight_of(plan.heuristic, own * pdf_light, other * pdf_dir)
    value = (reflectance[0] * le[0] * c, reflectance[1] * le[1] * c, reflectance[2] * le[2] * c)
    if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
        return row
    # The shadow ray runs from the offset origin to the sampled point and stops short of it.
    to_target, length = normalized(sub(add_scaled(x, dist, wi_world), origin))
    out.tmax[row] = max(length - eps, 0.0)
    _write_ray(out, row, origin, to_target, value, lane)
    return row + 1


@jit
def _direction_sample(point, lane, stream, dim, own, plan, out, row):
    """One direction sample at ``point``: f |cos| / (own p_d) into ``out[row]`` with its ray and
    count-scaled pdf; ``_gather`` multiplies in the emitter it hits and the MIS weight.
    Returns the next free row."""
    x, origin, s, t, normal, wo, kind, reflectance, alpha, eps = point
    u0, u1 = rand.uniform(stream, dim), rand.uniform(stream, dim + 1)
    delta = False
    if plan.sampler == BSDF:
        wi, weight, pdf_dir, delta = bsdf.sample(kind, alpha, wo, u0, u1)
    else:
        if plan.sampler == UNIFORM:
            wi = warp.uniform_hemisphere(u0, u1)
            pdf_dir = warp.uniform_hemisphere_pdf(wi[2])
        else:
            wi = warp.cosine_hemisphere(u0, u1)
            pdf_dir = warp.cosine_hemisphere_pdf(wi[2])
        weight = bsdf.shape(kind, alpha, wo, wi) * max(wi[2], 0.0) / pdf_dir if pdf_dir > 0.0 else 0.0
    c = weight / own
    value = (reflectance[0] * c, reflectance[1] * c, reflectance[2] * c)
    if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
        return row
    out.pdf[row] = own * pdf_dir
    out.delta[row] = delta
    _write_ray(out, row, origin, to_world(s, t, normal, wi), value, lane)
    return row + 1


@jit
def _write_ray(out, row, origin, direction, value, lane):
    for k in range(3):
        out.origin[row, k] = origin[k]
        out.dir[row, k] = direction[k]
        out.value[row, k] = value[k]
    out.lane[row] = lane


@jit
def _direction_pdf(sampler, kind, alpha, wo, wi):
    """pdf of the direction technique for a light-sampled ``wi`` (for MIS weights)."""
    if sampler == UNIFORM:
        return warp.uniform_hemisphere_pdf(wi[2])
    if sampler == COSINE:
        return warp.cosine_hemisphere_pdf(wi[2])
    return bsdf.pdf(kind, alpha, wo, wi)


@jit
def _gather(radiance, surfaces: Surfaces, light_tables: LightTables, plan: Plan, shadow: RayBuffer, blocked,
            direction: RayBuffer, prim, dist):
    """Add to ``radiance`` the light samples whose shadow rays are unblocked, and the direction
    samples whose rays hit the front of an emitter, weighted against the light technique."""
    for row in range(len(blocked)):
        if not blocked[row]:
            lane = shadow.lane[row]
            for k in range(3):
                radiance[lane, k] += shadow.value[row, k]
    other = plan.c_light if plan.one_sample else float(plan.n_light)
    for row in range(len(prim)):
        p = prim[row]
        if p < 0:
            continue
        g = surfaces.hit_table[p]
        wi = (float(direction.dir[row, 0]), float(direction.dir[row, 1]), float(direction.dir[row, 2]))
        if not g[9] * wi[0] + g[10] * wi[1] + g[11] * wi[2] < 0.0:  # emitters shine from the front
            continue
        w = 1.0
        if other > 0.0 and not direction.delta[row]:
            w = mis.weight_of(plan.heuristic, direction.pdf[row],
                              other * lights.pdf(light_tables, p, wi, float(dist[row])))
        lane = direction.lane[row]
        for k in range(3):
            radiance[lane, k] += direction.value[row, k] * g[12 + k] * w
