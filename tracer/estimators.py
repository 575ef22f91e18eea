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

**Resampled importance sampling** (``ris``; Talbot, Cline and Egbert, "Importance Resampling
for Global Illumination", EGSR 2005). A shading point draws N light and M BSDF candidates y_j,
exactly the samples MIS with N + M samples would take, and computes for each the value v_j that
MIS would add if its ray were unblocked: f Le |cos| m_j / p_j (RGB), m_j the heuristic's weight
over the count-scaled pdfs divided by the candidate's count (1 / N for a light-only ris). It
keeps one candidate J with probability w_J / sum w, w_j = mean(v_j) (so the target is
p̂ = mean(f Le |cos|), unshadowed), casts one shadow ray for it, and adds

    v_J / mean(v_J) * sum_j w_j = f Le |cos| / p̂ (y_J) * sum_j m_j p̂(y_j) / p_j(y_j)

if it is unblocked. E[...] = sum_j E[m_j f V / p_j] = integral of f V times sum_j m_j, so the
estimate is unbiased when (1) the weights m_j sum to 1 wherever f V > 0 (they are MIS weights
over the techniques that can produce the point; a delta light or lobe has one technique and
m = 1 / its count), (2) p̂ > 0 wherever f V > 0 (p̂ is f Le |cos| itself, unshadowed, and every
channel is >= 0, so their mean is 0 only where all are) and (3) a candidate with p̂ > 0 has a
pdf > 0 under its own technique (it was drawn from it). Visibility is the one factor p̂ leaves
out, which is where RIS fails: a target that ranks occluded lights highly wastes its one
shadow ray (``test_stability``'s heavy-occlusion row).

Candidates cost shading, not rays: a light candidate needs no ray at all, and a BSDF candidate
finds the emitter its direction meets with a ray against the emitters alone (a second Embree
scene of the emitting triangles and spheres, ``SceneRays(emitters_only=True)``); the first
emitter along a direction is the only one whose light could arrive from it, so its (unshadowed)
value is that emitter's, and condition (1) holds since MIS weights the pair (direction, first
emitter). The kept candidate is chosen by weighted reservoir sampling in one pass: candidate j
replaces the kept one with probability w_j / (w_1 + ... + w_j), decided by one uniform number
that is rescaled after every decision (dimension ``TECHNIQUE_CHOICE``), so the choice is the
same at any batch size.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import lights, materials, mis, samplers, tuning, warp
from .embree import RayCaster
from .frame import add_scaled, basis, dot, normalized, scale, sub, to_local, to_world
from .geometry import SceneRays, offset_origin, shading_normal, surface_point
from .jit import jit
from .lights import LightSampler
from .samplers import dimensions
from .scene import Scene
from .strategy import Strategy
from .tuning import Tuning

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

    n_light, n_dir : samples per shading point of each technique (0 if unused); ris: candidates.
    direction : direction technique code.   heuristic : MIS heuristic code.
    one_sample : one-sample MIS.   c_light : probability of the light technique in it.
    ris : resample one candidate per shading point (module docstring).
    optimal : add up optimal MIS's control variate C per lane (``tracer.tuning``).
    adaptive : each pixel's expected light count comes from the tuning (``tracer.tuning``).
    total : technique samples per camera sample N (1 with one-sample MIS).
    light_slots : light samples a camera sample may take at most (where direction samples'
        dimensions begin).
    """

    n_light: int
    n_dir: int
    direction: int
    heuristic: int
    one_sample: bool
    c_light: float
    ris: bool
    optimal: bool
    adaptive: bool
    total: float
    light_slots: int


class Reservoirs(NamedTuple):
    """Per camera lane, the candidates ris has seen (the kept one's ray is the lane's row of the
    shadow buffer): weight (n,) their sum of w_j; u (n,) the rescaled resampling uniform."""

    weight: np.ndarray
    u: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "Reservoirs":
        return cls(np.empty(count), np.empty(count))


class DirectLighting:
    """The estimator for one scene and strategy, shared by all render threads (read-only)."""

    def __init__(self, scene: Scene, strategy: Strategy, caster: RayCaster | None = None):
        self.scene = scene
        self.strategy = strategy
        self.rays = SceneRays(scene, caster)
        self.caster = self.rays.caster
        self.lights = LightSampler(scene, strategy.light_selection, strategy.light_sampling)
        ris = strategy.name == "ris"
        # ris's BSDF candidates find their emitter without the occluders.
        self.emitter_rays = SceneRays(scene, emitters_only=True) if ris and strategy.direction_count else None
        m = scene.materials
        self.surfaces = Surfaces(np.ascontiguousarray(scene.hit_table), np.ascontiguousarray(m.kind),
                                 np.ascontiguousarray(m.params, dtype=np.float64),
                                 np.ascontiguousarray(m.twosided, dtype=np.bool_), float(scene.ray_epsilon),
                                 int(scene.triangle_count), np.ascontiguousarray(scene.corner_normals))
        n_light, n_dir = strategy.light_count, strategy.direction_count
        one_sample = strategy.one_sample_mis
        total = 1.0 if one_sample else float(n_light + n_dir)
        self.plan = Plan(n_light, n_dir, DIRECTION_CODE[strategy.direction_technique],
                         mis.code(strategy.heuristic), one_sample, n_light / (n_light + n_dir),
                         ris, strategy.learns_control_variate, strategy.adaptive, total,
                         n_light + n_dir if strategy.adaptive else n_light)

    @property
    def learns(self) -> bool:
        """Whether the render loop must learn between passes (``tracer.tuning``)."""
        return self.strategy.learns

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
                                samplers.make(sampler, seed, 0, spp), pixel, np.ascontiguousarray(sample))[0]

    def shade_lanes(self, origins: np.ndarray, dirs: np.ndarray, sampler: samplers.SamplerParams,
                    pixel: np.ndarray, sample: np.ndarray,
                    tuned: Tuning | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`radiance` for the render loop: float32 rays, a built sampler, int64 lanes,
        and what the pass applies (``tracer.tuning``; None: the pilot's settings). Returns the
        radiance ``(n, 3)`` (for optimal MIS, the balance estimate V, to which the render loop
        adds a C) and the lane statistics ``(n, tuning.LANE_COLUMNS)`` ((0, ...) unless the
        estimator learns)."""
        n = len(origins)
        plan = self.plan
        tuned = tuned if tuned is not None else tuning.no_tuning()
        slots = plan.light_slots
        shadow = RayBuffer.empty(n if plan.one_sample or plan.ris else n * slots)
        direction = RayBuffer.empty(n if plan.one_sample else n * (slots if plan.adaptive else plan.n_dir))
        reservoirs = Reservoirs.empty(n if plan.ris else 0)
        # Optimal MIS needs each lane's C in every pass; the rest only while it is collected.
        wanted = plan.optimal or (plan.adaptive and tuned.collect)
        lane_stats = np.empty((n if wanted else 0, tuning.LANE_COLUMNS))
        prim = self.rays.first_hit(origins, dirs)
        radiance = np.empty((n, 3))
        tables = self.lights.tables
        n_shadow, n_direction = _shade(prim, origins, dirs, sampler, pixel, sample, self.surfaces, tables,
                                       plan, tuned, radiance, shadow, direction, reservoirs, lane_stats)
        d = slice(0, n_direction)
        if plan.ris:
            # The BSDF candidates meet their emitters; one shadow ray per lane for the kept one.
            found = self.emitter_rays.first_hit(direction.origin[d], direction.dir[d]) if n_direction \
                else np.zeros(0, dtype=np.int32)
            n_shadow = _resample(radiance, self.surfaces, tables, plan, direction, found, shadow, reservoirs)
            d, found = slice(0, 0), found[:0]
        s = slice(0, n_shadow)
        blocked = self.rays.occluded(shadow.origin[s], shadow.dir[s], shadow.tmax[s])
        if not plan.ris:
            found = self.rays.first_hit(direction.origin[d], direction.dir[d])
        _gather(radiance, self.surfaces, tables, plan, tuned, shadow, blocked, direction, found, lane_stats)
        return radiance, lane_stats


class RayBuffer(NamedTuple):
    """Rays from shading points, written by ``_shade``, one row per sample that may contribute.
    Shadow and direction rays share the layout; each leaves the other's fields unwritten.

    origin, dir : (c, 3) float32 for Embree (dir unit length, world).
    tmax : (c,) float32 shadow-ray length (shadow rays only).
    value : (c, 3) what the sample adds if its ray is unblocked (shadow) or hits an emitter
        (direction; then times the emitter's radiance and the MIS weight).
    point, normal, shading : (c, 3) float64 shading point the ray leaves, its geometric and
        its shading normal (direction rays only): the light pdf of the direction is measured
        from them, as light sampling does.
    pdf : (c,) count-scaled pdf of the direction technique (direction rays only, for MIS).
    lane : (c,) camera lane the sample belongs to.   delta : (c,) a delta sample (weight 1).
    other : (c,) the (expected) light sample count of the shading point: the MIS weights of
        direction samples scale the light pdf by it.
    control, v2, t : (c,) what an unblocked light sample adds to ``tracer.tuning``'s statistics
        (its term of C, the mean square of its balance value over channels, p_l / (p_l + p_b));
        written only when the estimator learns.
    """

    origin: np.ndarray
    dir: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    shading: np.ndarray
    pdf: np.ndarray
    lane: np.ndarray
    delta: np.ndarray
    other: np.ndarray
    control: np.ndarray
    v2: np.ndarray
    t: np.ndarray

    @classmethod
    def empty(cls, count: int) -> "RayBuffer":
        f32 = np.float32
        return cls(np.empty((count, 3), dtype=f32), np.empty((count, 3), dtype=f32),
                   np.empty(count, dtype=f32), np.empty((count, 3)), np.empty((count, 3)),
                   np.empty((count, 3)), np.empty((count, 3)), np.empty(count),
                   np.empty(count, dtype=np.int64), np.empty(count, dtype=np.bool_),
                   np.empty(count), np.empty(count), np.empty(count), np.empty(count))


# -------------------------------------------------------------------------------------------------
# Compiled kernels
#
# The kernels read the fields of their named tuples once, before the loop over lanes: reading
# an array out of a tuple inside the loop costs a reference-count update (~25 ns) each time.


@jit
def _shade(prim, origins, dirs, sampler, pixel, sample, surfaces: Surfaces, light_tables, plan: Plan,
           tuned: Tuning, radiance, shadow: RayBuffer, direction: RayBuffer, reservoirs: Reservoirs,
           lane_stats):
    """Camera hits -> emission seen directly into ``radiance (n, 3)``, and the shadow and
    direction rays of every shading point into the buffers. Returns their counts. ris: the
    light candidates go through ``reservoirs`` (the kept one in the lane's shadow row) and the
    direction rays are the BSDF candidates, for ``_resample``. An estimator that learns zeroes
    each lane's row of ``lane_stats`` and counts the samples and rays in it (``tracer.tuning``)."""
    hit_table, kinds, params, eps = (surfaces.hit_table, surfaces.material_kind, surfaces.material_params,
                                     surfaces.eps)
    first_sphere, twosided, corner_normals = surfaces.first_sphere, surfaces.twosided, surfaces.corner_normals
    alias_prob, alias, pmf = light_tables.alias_prob, light_tables.alias, light_tables.pmf
    nodes, child = light_tables.nodes, light_tables.child
    technique, rows, spheres = light_tables.technique, light_tables.rows, light_tables.spheres
    weight_sum, u_left = reservoirs.weight, reservoirs.u
    shadow_origin, shadow_dir, shadow_tmax = shadow.origin, shadow.dir, shadow.tmax
    shadow_value, shadow_lane = shadow.value, shadow.lane
    dir_origin, dir_dir = direction.origin, direction.dir
    dir_value, dir_point, dir_normal, dir_shading = direction.value, direction.point, direction.normal, \
        direction.shading
    dir_pdf, dir_lane, dir_delta, dir_other = direction.pdf, direction.lane, direction.delta, direction.other
    shadow_other, shadow_control, shadow_v2, shadow_t = shadow.other, shadow.control, shadow.v2, shadow.t
    light_count, replicates, groups = tuned.light_count, tuned.replicates, tuned.groups
    learning = len(lane_stats) > 0
    counting = learning and tuned.collect
    n_light, n_dir = float(plan.n_light), float(plan.n_dir)
    n_shadow = 0
    n_direction = 0
    for lane in range(len(prim)):
        radiance[lane, 0] = radiance[lane, 1] = radiance[lane, 2] = 0.0
        if plan.ris:
            weight_sum[lane] = 0.0
        if learning:
            if tuned.collect:
                lane_stats[lane, :] = 0.0
            else:  # only C is read (optimal MIS applies a C)
                lane_stats[lane, tuning.CONTROL] = 0.0
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
        if plan.ris:
            u_left[lane] = samplers.uniform(sampler, state, dimensions.TECHNIQUE_CHOICE)

        # Which samples this point takes: (light samples, direction samples, their expected
        # counts). One-sample MIS and adaptive allocation draw the counts: floor(n̄_l) light
        # samples and one more with probability frac(n̄_l), the rest direction samples.
        if plan.one_sample or plan.adaptive:
            own_light = plan.c_light if plan.one_sample else n_light
            if plan.adaptive and len(light_count):
                own_light = light_count[pixel[lane], tuning.group_of(sample[lane], replicates, groups)]
            own_dir = plan.total - own_light
            whole = math.floor(own_light)
            extra = samplers.uniform(sampler, state, dimensions.TECHNIQUE_CHOICE) < own_light - whole
            lights_here = int(whole) + (1 if extra else 0)
            dirs_here = int(plan.total) - lights_here
        else:
            lights_here, dirs_here = plan.n_light, plan.n_dir
            own_light, own_dir = n_light, n_dir
        if counting:
            lane_stats[lane, tuning.LIGHT_TAKEN] = lights_here
            lane_stats[lane, tuning.DIRECTION_TAKEN] = dirs_here

        # Light samples: f Le |cos| w_l / (own p_l); other = 0 (no direction technique) gives weight 1.
        for j in range(lights_here):
            u = samplers.uniform_pair(sampler, state, dimensions.light_point(j))
            wi_world, dist, le, pdf_light, delta = lights.sample(
                alias_prob, alias, pmf, nodes, child, technique, rows, x, geometric, normal,
                samplers.uniform(sampler, state, dimensions.light_choice(j)), u[0], u[1])
            if not pdf_light > 0.0:
                continue
            wi = to_local(s, t, normal, wi_world)
            f, pdf_bsdf = materials.eval_pdf(kind, params, material, wo, wi)
            c = max(wi[2], 0.0) / (own_light * pdf_light)
            w, w_balance, share_t = 1.0, 1.0, 1.0
            if own_dir > 0.0 and plan.direction != NO_DIRECTIONS and not delta:
                pdf_dir = pdf_bsdf if plan.direction == BSDF else _hemisphere_pdf(plan.direction, wi[2])
                w = mis.weight_of(plan.heuristic, own_light * pdf_light, own_dir * pdf_dir)
                if learning:
                    w_balance = mis.weight_of(mis.BALANCE, own_light * pdf_light, own_dir * pdf_dir)
                    share_t = mis.weight_of(mis.BALANCE, pdf_light, pdf_dir)
            raw = (f[0] * le[0] * c, f[1] * le[1] * c, f[2] * le[2] * c)
            cw = c * w
            value = (f[0] * le[0] * cw, f[1] * le[1] * cw, f[2] * le[2] * cw)
            # A sample that cannot contribute casts no ray. Learning looks at the unweighted
            # value: whether a sample carries light must not depend on the heuristic (max's
            # weight 0 would hide it from the allocation's statistics).
            carries = raw if learning else value
            if not (carries[0] > 0.0 or carries[1] > 0.0 or carries[2] > 0.0):
                _flag_nan(radiance, lane, value)
                continue
            # The shadow ray runs from the offset origin to the sampled point, stopping short of it.
            origin = offset_origin(x, eps, geometric, wi_world)
            to_target, length = normalized(sub(add_scaled(x, dist, wi_world), origin))
            if plan.ris:
                _offer(shadow_origin, shadow_dir, shadow_tmax, shadow_value, weight_sum, u_left, radiance,
                       lane, origin, to_target, max(length - eps, 0.0), value)
                continue
            shadow_tmax[n_shadow] = max(length - eps, 0.0)
            if learning:
                # Unblocked, this sample adds (1 - w_bal) / n̄_l to C (``tracer.tuning``).
                shadow_other[n_shadow] = own_light
                shadow_control[n_shadow] = (1.0 - w_balance) / own_light
                shadow_v2[n_shadow] = _mean_square(raw, w_balance)
                shadow_t[n_shadow] = share_t
                if counting:
                    lane_stats[lane, tuning.LIGHT_RAYS] += 1.0
            n_shadow = _put(shadow_origin, shadow_dir, shadow_value, shadow_lane, n_shadow,
                            origin, to_target, value, lane)

        # Direction samples: f |cos| / (own p_d); _gather multiplies in the emitter it hits and
        # the MIS weight.
        for j in range(dirs_here):
            u = samplers.uniform_pair(sampler, state, dimensions.direction(plan.light_slots, j))
            wi, weight, pdf_dir, delta = _direction_sample(
                plan.direction, kind, params, material, wo,
                samplers.uniform(sampler, state, dimensions.lobe_choice(plan.light_slots, j)), u[0], u[1])
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
            dir_other[n_direction] = own_light
            if counting:
                lane_stats[lane, tuning.DIRECTION_RAYS] += 1.0
            for axis in range(3):
                dir_point[n_direction, axis] = x[axis]
                dir_normal[n_direction, axis] = geometric[axis]
                dir_shading[n_direction, axis] = normal[axis]
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
def _gather(radiance, surfaces: Surfaces, light_tables, plan: Plan, tuned: Tuning, shadow: RayBuffer, blocked,
            direction: RayBuffer, prim, lane_stats):
    """Add to ``radiance`` the light samples whose shadow rays are unblocked, and the direction
    samples whose rays hit the front of an emitter, weighted against the light technique; an
    estimator that learns adds what these samples tell to ``lane_stats`` (``tracer.tuning``)."""
    shadow_value, shadow_lane = shadow.value, shadow.lane
    shadow_other, shadow_control, shadow_v2, shadow_t = shadow.other, shadow.control, shadow.v2, shadow.t
    # The second moments per share are what the allocation learns from: not for optimal MIS alone.
    learning, collect = len(lane_stats) > 0, tuned.collect and plan.adaptive
    shares = tuned.shares
    for row in range(len(blocked)):
        if not blocked[row]:
            lane = shadow_lane[row]
            for c in range(3):
                radiance[lane, c] += shadow_value[row, c]
            if learning:
                _learn(lane_stats, lane, shares, collect, shadow_control[row], shadow_v2[row], shadow_t[row],
                       shadow_other[row] / plan.total)
    hit_table, first_sphere = surfaces.hit_table, surfaces.first_sphere
    tables, rays = _pdf_arrays(light_tables), _direction_arrays(direction)
    lanes, others, pdfs, deltas = direction.lane, direction.other, direction.pdf, direction.delta
    for row in range(len(prim)):
        if prim[row] < 0:
            continue
        hit, _, value, raw, pdf_light = _direction_value(hit_table, first_sphere, tables, plan.heuristic,
                                                         rays, row, prim[row])
        if not hit:
            continue
        lane = lanes[row]
        for c in range(3):
            radiance[lane, c] += value[c]
        if learning and (raw[0] > 0.0 or raw[1] > 0.0 or raw[2] > 0.0):
            # Unblocked, a direction sample adds -p_l / q = -(1 - w_bal) / n̄_l to C; a delta
            # lobe's sample (whose pdf is not a density) is the only technique's: w_bal = 1.
            other = others[row]
            w_balance, share_t = 1.0, 0.0
            if not deltas[row]:
                w_balance = mis.weight_of(mis.BALANCE, pdfs[row], other * pdf_light)
                share_t = mis.weight_of(mis.BALANCE, pdf_light, pdfs[row] / (plan.total - other))
            _learn(lane_stats, lane, shares, collect, -(1.0 - w_balance) / other,
                   _mean_square(raw, w_balance), share_t, other / plan.total)


@jit
def _mean_square(raw, w: float) -> float:
    """The mean over channels of (w x raw)^2: a sample's squared balance value, when ``raw``
    is its unweighted value and w its balance weight."""
    return ((raw[0] * w) ** 2 + (raw[1] * w) ** 2 + (raw[2] * w) ** 2) / 3.0


@jit
def _learn(lane_stats, lane: int, shares, collect: bool, control: float, v2: float, share_t: float,
           share: float) -> None:
    """Add to a lane's statistics one sample that carries light: its term of the control
    variate C, and if ``collect``, for every candidate share c its estimate of the second
    moment M(c), v^2 (a t + (1 - a)(1 - t)) / (c t + (1 - c)(1 - t)) with a = ``share``, the
    share of light samples it was taken under (``tracer.tuning``)."""
    lane_stats[lane, tuning.CONTROL] += control
    if not collect:
        return
    used = share * share_t + (1.0 - share) * (1.0 - share_t)
    for k in range(len(shares)):
        c = shares[k]
        lane_stats[lane, tuning.FIRST_SHARE + k] += v2 * used / (c * share_t + (1.0 - c) * (1.0 - share_t))


@jit
def _pdf_arrays(light_tables):
    """The light tables' arrays that the light pdf of a direction reads, as one plain tuple."""
    t = light_tables
    return t.pmf, t.nodes, t.child, t.trail, t.trail_depth, t.technique, t.rows, t.candidate_of_prim


@jit
def _direction_arrays(direction: RayBuffer):
    """The direction buffer's arrays that ``_direction_value`` reads, as one plain tuple."""
    return (direction.dir, direction.value, direction.point, direction.normal, direction.shading,
            direction.origin, direction.pdf, direction.delta, direction.other)


@jit
def _direction_value(hit_table, first_sphere: int, tables, heuristic: int, rays, row: int, p: int):
    """What direction sample ``row``, whose ray hits primitive ``p``, adds: ``(hit, dist,
    value, raw, pdf_light)``, value = raw x its MIS weight against the light technique (whose
    count is the row's ``other``), raw = its weight x the emitter's radiance (RGB), dist the
    emitter's distance from the shading point, pdf_light the light technique's pdf of the
    direction (0 for a delta sample or without light samples), hit False if it adds nothing
    (the emitter's back side). ``tables`` and ``rays`` are tuples of the light tables' and the
    direction buffer's arrays, unpacked by the caller before its loop (a named tuple's field
    read in the loop costs a reference-count update)."""
    pmf, nodes, child, trail, trail_depth, technique, light_rows, candidate_of_prim = tables
    dirs, values, points, normals, shadings, origins, pdfs, deltas, others = rays
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
        return False, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0  # emitters shine from the front only
    w = 1.0
    pdf_light = 0.0
    other = others[row]
    if other > 0.0 and not deltas[row]:
        n = (normals[row, 0], normals[row, 1], normals[row, 2])
        receiver = (shadings[row, 0], shadings[row, 1], shadings[row, 2])
        pdf_light = lights.pdf(pmf, nodes, child, trail, trail_depth, technique, light_rows,
                               candidate_of_prim, x, n, receiver, p, wi, dist)
        w = mis.weight_of(heuristic, pdfs[row], other * pdf_light)
    raw = (values[row, 0] * hit_table[p, 12], values[row, 1] * hit_table[p, 13],
           values[row, 2] * hit_table[p, 14])
    return True, dist, (raw[0] * w, raw[1] * w, raw[2] * w), raw, pdf_light


@jit
def _offer(origins, dirs, tmaxs, values, weight_sum, u_left, radiance, lane: int, origin, direction,
           tmax: float, value) -> None:
    """ris: offer a candidate whose unblocked contribution would be ``value`` (RGB, as MIS
    would add it) and whose shadow ray is ``origin, direction, tmax`` to ``lane``'s reservoir;
    kept, it replaces the lane's shadow row. Weight w = mean(value); a non-finite one marks the
    lane NaN (the render loop counts and zeroes it)."""
    w = (value[0] + value[1] + value[2]) / 3.0
    if not w < math.inf:
        radiance[lane, 0] = math.nan
        return
    if not w > 0.0:
        return
    total = weight_sum[lane] + w
    weight_sum[lane] = total
    keep = w / total
    took = u_left[lane] < keep
    u_left[lane] = samplers.reuse(u_left[lane], keep, took)
    if took:
        for c in range(3):
            origins[lane, c] = origin[c]
            dirs[lane, c] = direction[c]
            values[lane, c] = value[c]
        tmaxs[lane] = tmax


@jit
def _resample(radiance, surfaces: Surfaces, light_tables, plan: Plan, direction: RayBuffer, prim,
              shadow: RayBuffer, reservoirs: Reservoirs) -> int:
    """ris: offer the BSDF candidates (direction rows, whose rays met the emitters ``prim``) to
    their lanes' reservoirs; then turn each lane's kept candidate into its shadow ray carrying
    v_J / mean(v_J) * sum w, packed into rows 0 .. count - 1. Returns the count."""
    eps, hit_table, first_sphere = surfaces.eps, surfaces.hit_table, surfaces.first_sphere
    shadow_origin, shadow_dir, shadow_tmax = shadow.origin, shadow.dir, shadow.tmax
    shadow_value, shadow_lane = shadow.value, shadow.lane
    weight_sum, u_left = reservoirs.weight, reservoirs.u
    tables, rays = _pdf_arrays(light_tables), _direction_arrays(direction)
    dirs, points, origins, lanes = direction.dir, direction.point, direction.origin, direction.lane
    for row in range(len(prim)):
        if prim[row] < 0:
            continue
        hit, dist, value, _, _ = _direction_value(hit_table, first_sphere, tables, plan.heuristic, rays, row,
                                                  prim[row])
        if not hit:
            continue
        x = (points[row, 0], points[row, 1], points[row, 2])
        wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
        origin = (float(origins[row, 0]), float(origins[row, 1]), float(origins[row, 2]))
        to_target, length = normalized(sub(add_scaled(x, dist, wi), origin))
        _offer(shadow_origin, shadow_dir, shadow_tmax, shadow_value, weight_sum, u_left, radiance,
               lanes[row], origin, to_target, max(length - eps, 0.0), value)
    count = 0
    for lane in range(len(weight_sum)):
        if not weight_sum[lane] > 0.0:
            continue
        kept_weight = (shadow_value[lane, 0] + shadow_value[lane, 1] + shadow_value[lane, 2]) / 3.0
        scale_by = weight_sum[lane] / kept_weight
        for c in range(3):  # count <= lane: rows move down only
            shadow_origin[count, c] = shadow_origin[lane, c]
            shadow_dir[count, c] = shadow_dir[lane, c]
            shadow_value[count, c] = shadow_value[lane, c] * scale_by
        shadow_tmax[count] = shadow_tmax[lane]
        shadow_lane[count] = lane
        count += 1
    return count
