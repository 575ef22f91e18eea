"""The direct-lighting estimator: five strategies as settings of one estimator.

    L(x, wo) = Le(x, wo) + integral f(x, wi, wo) Le(y(x, wi), -wi) |cos theta_i| dwi

Two techniques sample ``wi`` at a shading point:

- the *light* technique (``tracer.lights``): choose an emitter, sample a direction toward it;
- a *direction* technique: ``uniform`` (1/2pi), ``cosine`` (cos/pi) or ``bsdf`` (the
  material's own sampling, ``tracer.materials``), followed by a ray that may hit an emitter.

A strategy (``tracer.strategy``) is a pair of sample counts and a direction technique.
Multi-sample MIS (Veach 1997, section 9.2) weights a light sample by w_l = h(N p_l, M p_b) and
a BSDF sample by w_b = h(M p_b, N p_l), each sample's contribution divided by its own count.
One-sample MIS (section 9.2.4) picks one technique per camera sample with probability
c_l = N / (N + M) and divides by c times its pdf; the weights use c p. With a single technique
the other count is 0 and the weight is 1.

Delta rule: a delta light's sample and a delta lobe's sample get weight 1, because the other
technique produces them with probability 0. Whatever a technique cannot see (a point light
from BSDF or hemisphere sampling, a mirror's reflection from light sampling) contributes 0.

A batch runs as a wavefront of three ray casts and two compiled loops over its lanes
(``tracer.jit``): Embree finds the camera hits; ``_shade`` samples the light and direction
techniques at every shading point and writes one shadow ray per light sample and one ray per
direction sample, with what each would contribute; Embree casts both sets; ``_gather`` adds
the unblocked light samples and the direction samples that hit an emitter, with their MIS
weights. Samples that can only contribute 0 cast no ray: a light sample with zero value, and a
direction sample whose ray meets none of the emitters' bounding spheres (``lights.may_reach``).
Every random number is ``u(seed, pixel, sample index, dimension)`` from the render's sampler,
with the dimensions of ``tracer.samplers.dimensions``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import lights, materials, mis, samplers, warp
from .embree import RayCaster
from .frame import add_scaled, basis, dot, normalized, scale, sub, to_local, to_world
from .geometry import SceneRays, offset_origin, shading_normal, surface_point
from .jit import jit
from .lights import LightSampler
from .samplers import dimensions
from .scene import Scene
from .strategy import Strategy

# Codes of the direction techniques for compiled code.
NO_DIRECTIONS, UNIFORM, COSINE, BSDF = 0, 1, 2, 3
DIRECTION_CODE = {None: NO_DIRECTIONS, "uniform": UNIFORM, "cosine": COSINE, "bsdf": BSDF}


class Surfaces(NamedTuple):
    """The scene as the kernels read it.

    hit_table : (F + S, 16) per primitive (``Scene.hit_table``): geometry, emission, material row.
    material_kind : (K,) int8 material codes.   material_params : (K, W) their parameters.
    twosided : (K,) bool, the material reflects on both sides (else black from behind).
    eps : ray offset along the normal (``Scene.ray_epsilon``).
    first_sphere : F, the primitive id of the first analytic sphere.
    corner_normals : (F, 9) vertex normals of smooth triangles, or (0, 9) (``Scene.corner_normals``).
    """

    hit_table: np.ndarray
    material_kind: np.ndarray
    material_params: np.ndarray
    twosided: np.ndarray
    eps: float
    first_sphere: int
    corner_normals: np.ndarray


class Plan(NamedTuple):
    """A strategy as the kernels read it.

    n_light, n_dir : samples per shading point of each technique (0 if unused).
    direction : direction technique code.   heuristic : MIS heuristic code.
    one_sample : one-sample MIS.   c_light : probability of the light technique in it.
    """

    n_light: int
    n_dir: int
    direction: int
    heuristic: int
    one_sample: bool
    c_light: float


class DirectLighting:
    """The estimator for one scene and strategy, shared by all render threads (read-only)."""

    def __init__(self, scene: Scene, strategy: Strategy, caster: RayCaster | None = None):
        self.scene = scene
        self.strategy = strategy
        self.rays = SceneRays(scene, caster)
        self.caster = self.rays.caster
        self.lights = LightSampler(scene, strategy.light_selection, strategy.light_sampling)
        m = scene.materials
        self.surfaces = Surfaces(np.ascontiguousarray(scene.hit_table), np.ascontiguousarray(m.kind),
                                 np.ascontiguousarray(m.params, dtype=np.float64),
                                 np.ascontiguousarray(m.twosided, dtype=np.bool_), float(scene.ray_epsilon),
                                 int(scene.triangle_count), np.ascontiguousarray(scene.corner_normals))
        n_light, n_dir = strategy.light_count, strategy.direction_count
        self.plan = Plan(n_light, n_dir, DIRECTION_CODE[strategy.direction_technique],
                         mis.code(strategy.heuristic), strategy.one_sample_mis, n_light / (n_light + n_dir))

    def radiance(self, origins: np.ndarray, dirs: np.ndarray, seed: int = 0, pixel: np.ndarray | None = None,
                 sample: np.ndarray | None = None, sampler: str = "independent") -> np.ndarray:
        """Radiance along rays ``origins, dirs (n, 3)`` (dirs unit length): emission seen
        directly plus direct lighting, one Monte Carlo sample per ray, ``(n, 3)`` float64.

        Lane i draws its random numbers as sample ``sample[i]`` of pixel ``pixel[i]`` (``(n,)``
        int64; defaults: pixel = 0 .. n - 1, sample = 0, so every lane is independent) from
        ``sampler`` seeded with ``seed``, as a render of samples 0 .. max(sample) would (which
        sizes ``stratified``'s grid). Non-finite values are returned as they are.
        """
        n = len(origins)
        pixel = np.arange(n, dtype=np.int64) if pixel is None else np.asarray(pixel, dtype=np.int64)
        sample = np.broadcast_to(np.asarray(0 if sample is None else sample, dtype=np.int64), (n,))
        spp = int(sample.max()) + 1 if n else 1
        return self.shade_lanes(np.ascontiguousarray(origins, dtype=np.float32),
                                np.ascontiguousarray(dirs, dtype=np.float32),
                                samplers.make(sampler, seed, 0, spp), pixel, np.ascontiguousarray(sample))

    def shade_lanes(self, origins: np.ndarray, dirs: np.ndarray, sampler: samplers.SamplerParams,
                    pixel: np.ndarray, sample: np.ndarray) -> np.ndarray:
        """:meth:`radiance` for the render loop: float32 rays, a built sampler, int64 lanes."""
        n = len(origins)
        plan = self.plan
        shadow = RayBuffer.empty(n if plan.one_sample else n * plan.n_light)
        direction = RayBuffer.empty(n if plan.one_sample else n * plan.n_dir)
        prim = self.rays.first_hit(origins, dirs)
        radiance = np.empty((n, 3))
        tables = self.lights.tables
        n_shadow, n_direction = _shade(prim, origins, dirs, sampler, pixel, sample, self.surfaces, tables,
                                       plan, radiance, shadow, direction)
        s, d = slice(0, n_shadow), slice(0, n_direction)
        blocked = self.rays.occluded(shadow.origin[s], shadow.dir[s], shadow.tmax[s])
        found = self.rays.first_hit(direction.origin[d], direction.dir[d])
        _gather(radiance, self.surfaces, tables, plan, shadow, blocked, direction, found)
        return radiance


class RayBuffer(NamedTuple):
    """Rays from shading points, written by ``_shade``, one row per sample that may contribute.
    Shadow and direction rays share the layout; each leaves the other's fields unwritten.

    origin, dir : (c, 3) float32 for Embree (dir unit length, world).
    tmax : (c,) float32 shadow-ray length (shadow rays only).
    value : (c, 3) what the sample adds if its ray is unblocked (shadow) or hits an emitter
        (direction; then times the emitter's radiance and the MIS weight).
    point, normal : (c, 3) float64 shading point the ray leaves and its normal (direction rays
        only): the light pdf of the direction is measured from them, as light sampling does.
    pdf : (c,) count-scaled pdf of the direction technique (direction rays only, for MIS).
    lane : (c,) camera lane the sample belongs to.   delta : (c,) a delta sample (weight 1).
    """

    origin: np.ndarray
    dir: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    pdf: np.ndarray
    lane: np.ndarray
    delta: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "RayBuffer":
        f32 = np.float32
        return cls(np.empty((count, 3), dtype=f32), np.empty((count, 3), dtype=f32),
                   np.empty(count, dtype=f32), np.empty((count, 3)), np.empty((count, 3)),
                   np.empty((count, 3)), np.empty(count),
                   np.empty(count, dtype=np.int64), np.empty(count, dtype=np.bool_))


# -------------------------------------------------------------------------------------------------
# Compiled kernels
#
# The kernels read the fields of their named tuples once, before the loop over lanes: reading
# an array out of a tuple inside the loop costs a reference-count update (~25 ns) each time.


@jit
def _shade(prim, origins, dirs, sampler, pixel, sample, surfaces: Surfaces, light_tables, plan: Plan,
           radiance, shadow: RayBuffer, direction: RayBuffer):
    """Camera hits -> emission seen directly into ``radiance (n, 3)``, and the shadow and
    direction rays of every shading point into the buffers. Returns their counts."""
    hit_table, kinds, params, eps = (surfaces.hit_table, surfaces.material_kind, surfaces.material_params,
                                     surfaces.eps)
    first_sphere, twosided, corner_normals = surfaces.first_sphere, surfaces.twosided, surfaces.corner_normals
    alias_prob, alias, pmf = light_tables.alias_prob, light_tables.alias, light_tables.pmf
    technique, rows, spheres = light_tables.technique, light_tables.rows, light_tables.spheres
    shadow_origin, shadow_dir, shadow_tmax = shadow.origin, shadow.dir, shadow.tmax
    shadow_value, shadow_lane = shadow.value, shadow.lane
    dir_origin, dir_dir = direction.origin, direction.dir
    dir_value, dir_point, dir_normal = direction.value, direction.point, direction.normal
    dir_pdf, dir_lane, dir_delta = direction.pdf, direction.lane, direction.delta
    n_light, n_dir = float(plan.n_light), float(plan.n_dir)
    n_shadow = 0
    n_direction = 0
    for lane in range(len(prim)):
        radiance[lane, 0] = radiance[lane, 1] = radiance[lane, 2] = 0.0
        p = prim[lane]
        if p < 0:
            continue
        d = (float(dirs[lane, 0]), float(dirs[lane, 1]), float(dirs[lane, 2]))
        o = (float(origins[lane, 0]), float(origins[lane, 1]), float(origins[lane, 2]))
        # The shading point, where the ray meets the triangle's plane or the sphere (float64;
        # Embree's own distance is float32), and the geometric normal of the primitive's front.
        x, face_normal, cos_d = surface_point(hit_table, first_sphere, p, o, d)
        cos_view = -cos_d
        # Emitters seen directly (weight 1 in every strategy): front side only.
        if cos_view > 0.0:
            for channel in range(3):
                radiance[lane, channel] = hit_table[p, 12 + channel]
        material = int(hit_table[p, 15])
        kind = kinds[material]
        if kind == materials.NONE or cos_view == 0.0:
            continue
        # The geometric normal toward the viewer: ray offsets and the light techniques use it.
        geometric = scale(1.0 if cos_view > 0.0 else -1.0, face_normal)
        # The shading frame: around the (interpolated) shading normal, flipped toward the viewer
        # for a two-sided material; a one-sided material seen from behind reflects nothing.
        normal = shading_normal(corner_normals, hit_table, first_sphere, p, x, face_normal)
        cos_shading = -dot(d, normal)
        if cos_shading < 0.0 and twosided[material]:
            normal = scale(-1.0, normal)
        elif not cos_shading > 0.0:
            continue
        s, t = basis(normal)
        wo = to_local(s, t, normal, scale(-1.0, d))
        state = samplers.start(sampler, pixel[lane], sample[lane])

        # Which samples this point takes: (light samples, direction samples, their counts).
        if plan.one_sample:
            take_light = samplers.uniform(sampler, state, dimensions.TECHNIQUE_CHOICE) < plan.c_light
            lights_here, dirs_here = (1, 0) if take_light else (0, 1)
            own_light, own_dir = plan.c_light, 1.0 - plan.c_light
        else:
            lights_here, dirs_here = plan.n_light, plan.n_dir
            own_light, own_dir = n_light, n_dir

        # Light samples: f Le |cos| w_l / (own p_l); other = 0 (no direction technique) gives weight 1.
        for j in range(lights_here):
            u = samplers.uniform_pair(sampler, state, dimensions.light_point(j))
            wi_world, dist, le, pdf_light, delta = lights.sample(
                alias_prob, alias, pmf, technique, rows, x, geometric,
                samplers.uniform(sampler, state, dimensions.light_choice(j)), u[0], u[1])
            if not pdf_light > 0.0:
                continue
            wi = to_local(s, t, normal, wi_world)
            f, pdf_bsdf = materials.eval_pdf(kind, params, material, wo, wi)
            c = max(wi[2], 0.0) / (own_light * pdf_light)
            if own_dir > 0.0 and plan.direction != NO_DIRECTIONS and not delta:
                pdf_dir = pdf_bsdf if plan.direction == BSDF else _hemisphere_pdf(plan.direction, wi[2])
                c *= mis.weight_of(plan.heuristic, own_light * pdf_light, own_dir * pdf_dir)
            value = (f[0] * le[0] * c, f[1] * le[1] * c, f[2] * le[2] * c)
            if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
                _flag_nan(radiance, lane, value)
                continue
            # The shadow ray runs from the offset origin to the sampled point, stopping short of it.
            origin = offset_origin(x, eps, geometric, wi_world)
            to_target, length = normalized(sub(add_scaled(x, dist, wi_world), origin))
            shadow_tmax[n_shadow] = max(length - eps, 0.0)
            n_shadow = _put(shadow_origin, shadow_dir, shadow_value, shadow_lane, n_shadow,
                            origin, to_target, value, lane)

        # Direction samples: f |cos| / (own p_d); _gather multiplies in the emitter it hits and
        # the MIS weight.
        for j in range(dirs_here):
            u = samplers.uniform_pair(sampler, state, dimensions.direction(plan.n_light, j))
            wi, weight, pdf_dir, delta = _direction_sample(
                plan.direction, kind, params, material, wo,
                samplers.uniform(sampler, state, dimensions.lobe_choice(plan.n_light, j)), u[0], u[1])
            value = (weight[0] / own_dir, weight[1] / own_dir, weight[2] / own_dir)
            if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
                _flag_nan(radiance, lane, value)
                continue
            wi_world = to_world(s, t, normal, wi)
            origin = offset_origin(x, eps, geometric, wi_world)
            if not lights.may_reach(spheres, origin, wi_world):
                continue  # it could only contribute 0: no ray
            dir_pdf[n_direction] = own_dir * pdf_dir
            dir_delta[n_direction] = delta
            for axis in range(3):
                dir_point[n_direction, axis] = x[axis]
                dir_normal[n_direction, axis] = geometric[axis]
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
    and zeroes it (``render_loop._zero_nonfinite``) instead of the sample vanishing unnoticed."""
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
def _direction_sample(technique, kind, params, material, wo, u_lobe, u0, u1):
    """One direction from the strategy's direction technique: ``(wi, weight, pdf, delta)`` with
    weight = f |cos| / pdf as RGB (a delta lobe's: its contribution over its choice probability)."""
    if technique == BSDF:
        wi, weight, pdf_dir, flags = materials.sample(kind, params, material, wo, u_lobe, u0, u1)
        return wi, weight, pdf_dir, (flags & materials.DELTA) != 0
    wi = warp.uniform_hemisphere(u0, u1) if technique == UNIFORM else warp.cosine_hemisphere(u0, u1)
    pdf_dir = _hemisphere_pdf(technique, wi[2])
    if not pdf_dir > 0.0:
        return wi, (0.0, 0.0, 0.0), pdf_dir, False
    f = materials.eval_pdf(kind, params, material, wo, wi)[0]
    c = max(wi[2], 0.0) / pdf_dir
    return wi, (f[0] * c, f[1] * c, f[2] * c), pdf_dir, False


@jit
def _hemisphere_pdf(technique, cos_i):
    """pdf of the uniform or cosine hemisphere technique at a direction with cos(theta) = cos_i."""
    if technique == UNIFORM:
        return warp.uniform_hemisphere_pdf(cos_i)
    return warp.cosine_hemisphere_pdf(cos_i)


@jit
def _gather(radiance, surfaces: Surfaces, light_tables, plan: Plan, shadow: RayBuffer, blocked,
            direction: RayBuffer, prim):
    """Add to ``radiance`` the light samples whose shadow rays are unblocked, and the direction
    samples whose rays hit the front of an emitter, weighted against the light technique."""
    hit_table, first_sphere = surfaces.hit_table, surfaces.first_sphere
    pmf, technique, rows = light_tables.pmf, light_tables.technique, light_tables.rows
    candidate_of_prim = light_tables.candidate_of_prim
    shadow_value, shadow_lane = shadow.value, shadow.lane
    for row in range(len(blocked)):
        if not blocked[row]:
            lane = shadow_lane[row]
            for c in range(3):
                radiance[lane, c] += shadow_value[row, c]
    other = plan.c_light if plan.one_sample else float(plan.n_light)
    dirs, values, points, pdfs = direction.dir, direction.value, direction.point, direction.pdf
    normals, origins, lanes, deltas = direction.normal, direction.origin, direction.lane, direction.delta
    for row in range(len(prim)):
        p = prim[row]
        if p < 0:
            continue
        wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
        x = (points[row, 0], points[row, 1], points[row, 2])
        if p < first_sphere:
            cos_normal = hit_table[p, 9] * wi[0] + hit_table[p, 10] * wi[1] + hit_table[p, 11] * wi[2]
            dist = _plane_distance(hit_table, p, x, cos_normal) if cos_normal < 0.0 else 0.0
        else:  # the sphere point the ray found, and its distance from the shading point
            o = (float(origins[row, 0]), float(origins[row, 1]), float(origins[row, 2]))
            y, _, cos_normal = surface_point(hit_table, first_sphere, p, o, wi)
            v = sub(y, x)
            dist = math.sqrt(dot(v, v))
        if not cos_normal < 0.0:
            continue  # emitters shine from the front only
        w = 1.0
        if other > 0.0 and not deltas[row]:
            n = (normals[row, 0], normals[row, 1], normals[row, 2])
            pdf_light = lights.pdf(pmf, technique, rows, candidate_of_prim, x, n, p, wi, dist)
            w = mis.weight_of(plan.heuristic, pdfs[row], other * pdf_light)
        lane = lanes[row]
        for c in range(3):
            radiance[lane, c] += values[row, c] * hit_table[p, 12 + c] * w
