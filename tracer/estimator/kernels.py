"""The estimator's kernels: a batch's shading points to rays (``shade``), unblocked rays to
radiance (``gather``).

A batch runs as a wavefront: Embree finds the camera hits; ``shade`` sets up each hit's
shading point and takes its light and direction samples, writing one shadow ray per light
sample and one ray per direction sample with what each would contribute; Embree casts both
sets; ``gather`` adds the unblocked light samples and the direction samples that hit an
emitter, with their MIS weights (ris resamples in between: ``combiners/ris.py``). Samples that
can only contribute 0 cast no ray: a light sample with zero value, and a direction sample
whose ray meets none of the emitters' bounding spheres (``lights.may_reach``) unless there is an
environment, which every escaping ray sees. The sections of
``shade`` follow Mitsuba 3's ``direct.cpp``: the emitter seen directly, emitter sampling,
BSDF (direction) sampling; the delta rule (a delta light's or lobe's sample takes weight 1,
the other technique cannot produce it) lives in the two sampling steps.

These are templates (``tracer.kernels``): each render runs a copy built for its feature set,
in which ``dispatch`` is its plug-ins and the flags below are constants that remove the code
the render does not use. Plain arrays in compiled loops, read out of their tuples once before
each loop (``buffers.py`` says why).
"""

from __future__ import annotations

import math

import numpy as np

from .. import lights, mis, tuning
from ..frame import add_scaled, normalized, scale, sub, to_world
from ..geometry import offset_origin
from ..jit import jit
from ..kernels import UNBOUND, kernel
from ..lights import environment as environment_light
from ..lights import environment_product
from ..materials.base import MAX_MATERIAL_ROWS
from ..samplers import dimensions
from ..textures import FRAME, PERTURB_KIND, lookup, shading_frames
from . import light_samples, shading_point
from .combiners import ris
from .direction_samples import direction_arrays, direction_sample, direction_value, environment_value

# Bound per build (``tracer.kernels.dispatch``): what the render takes and does.
LIGHT_SAMPLES = DIRECTION_SAMPLES = LEARNS = RESAMPLES = TEXTURES = ENVIRONMENT = TRANSMITS = PRODUCT = False


@kernel
def shade(hits, sampler, surfaces, light_tables, plan, tuned, out):
    """Camera hits -> emission seen directly into ``out.radiance (n, 3)``, and the shadow and
    direction rays of every shading point into the buffers of ``out``. Returns their counts.
    ris: the light candidates go through ``out.reservoirs`` (the kept one in the lane's shadow
    row) and the direction rays are the BSDF candidates, for ``ris.resample``. An estimator that
    learns zeroes each lane's row of ``out.lane_stats`` and counts the samples and rays in it
    (``tracer.tuning``)."""
    prim, origins, dirs, pixel, sample = hits
    radiance, shadow, direction, reservoirs, lane_stats = out
    hit_table, kinds, params, eps = (surfaces.hit_table, surfaces.material_kind, surfaces.material_params,
                                     surfaces.eps)
    first_sphere, behind, corner_normals = surfaces.first_sphere, surfaces.behind, surfaces.corner_normals
    textures, transmits = surfaces.textures, surfaces.transmits
    # A textured hit's material rows (a blend's parts too), its textured columns set for that hit
    # (``tracer.textures``).
    scratch = np.empty((MAX_MATERIAL_ROWS, params.shape[1]))
    spheres = light_tables.spheres
    weight_sum, u_left = reservoirs.weight, reservoirs.u
    shadow_origin, shadow_dir, shadow_tmax = shadow.origin, shadow.dir, shadow.tmax
    shadow_value, shadow_lane = shadow.value, shadow.lane
    shadow_other, shadow_control, shadow_v2, shadow_t = shadow.other, shadow.control, shadow.v2, shadow.t
    dir_origin, dir_dir, dir_value, dir_lane = (direction.origin, direction.dir, direction.value,
                                                direction.lane)
    dir_point, dir_normal, dir_shading = direction.point, direction.normal, direction.shading
    dir_pdf, dir_delta, dir_other, dir_env_pdf = direction.pdf, direction.delta, direction.other, direction.env_pdf
    # Lane statistics exist only where a pass gathers them (optimal MIS in every pass, adaptive
    # allocation while it still learns): an empty array otherwise, never written.
    learning = LEARNS and len(lane_stats) > 0
    counting = learning and tuned.collect
    n_shadow = 0
    n_direction = 0
    # Read once here, not per light sample: a read through a tuple in the loop costs a
    # reference-count update (``lights.sample_with``).
    selection, technique, light_rows = light_tables.selection, light_tables.technique, light_tables.rows
    environment = light_tables.environment
    emitting = (textures, hit_table, first_sphere, light_tables.prims)
    for lane in range(len(prim)):
        radiance[lane, 0] = radiance[lane, 1] = radiance[lane, 2] = 0.0
        if RESAMPLES:
            weight_sum[lane] = 0.0
        if learning:
            if tuned.collect:
                lane_stats[lane, :] = 0.0
            else:  # only C is read (optimal MIS applies a C)
                lane_stats[lane, tuning.CONTROL] = 0.0
        p = prim[lane]
        d = (float(dirs[lane, 0]), float(dirs[lane, 1]), float(dirs[lane, 2]))
        if p < 0:
            if ENVIRONMENT:  # the environment seen directly, as emitters are (weight 1)
                le = environment_light.radiance(environment, d)
                radiance[lane, 0], radiance[lane, 1], radiance[lane, 2] = le[0], le[1], le[2]
            continue
        o = (float(origins[lane, 0]), float(origins[lane, 1]), float(origins[lane, 2]))
        reflects, cos_view, x, geometric, normal, s, t, wo, material, kind = shading_point.at_hit(
            hit_table, first_sphere, kinds, behind, corner_normals, p, o, d)

        # The emitter seen directly (weight 1 in every strategy): front side only.
        if cos_view > 0.0:
            if TEXTURES:
                le = lookup.emitted(textures, hit_table, first_sphere, p, x)
                radiance[lane, 0], radiance[lane, 1], radiance[lane, 2] = le[0], le[1], le[2]
            else:
                for channel in range(3):
                    radiance[lane, channel] = hit_table[p, 12 + channel]
        if not reflects:
            continue
        point = (x, geometric, normal, s, t, wo)
        # The normal that bounds which lights can reach the surface (the BVH's horizon test):
        # none for a type that transmits, which light from below reaches too. Read from the
        # shading row itself: after a texture lookup ``material`` indexes the scratch table.
        receiver = normal
        through = TRANSMITS and transmits[material]
        if through:
            receiver = (0.0, 0.0, 0.0)
        here = params
        # A normal or bump map tilts the frame every sample is taken in; each sample's value is
        # then multiplied by what the tilt masks and shadows (``tracer.textures.shading_frames``).
        tilted, unperturbed, a2 = False, normal, 0.0
        if TEXTURES:
            own_row = material
            here, material = lookup.textured_row(textures, params, material, hit_table, first_sphere, p, x,
                                                 scratch)
            perturbation = textures.perturb[own_row, PERTURB_KIND]
            if perturbation != 0.0:
                tilted = perturbation != FRAME  # a frame alone masks and shadows nothing
                reflects, normal, s, t, wo, a2 = shading_frames.perturbed(
                    textures, own_row, hit_table, first_sphere, corner_normals, p, x, d, unperturbed)
                if not reflects:
                    continue
                point = (x, geometric, normal, s, t, wo)
        surface = (kind, material, receiver, through)
        state = dispatch.start(sampler, pixel[lane], sample[lane])
        if RESAMPLES:
            u_left[lane] = dispatch.uniform(sampler, state, dimensions.TECHNIQUE_CHOICE)
        lights_here, dirs_here, own_light, own_dir = dispatch.counts(plan, tuned, sampler, state, pixel[lane],
                                                                     sample[lane])
        if counting:
            lane_stats[lane, tuning.LIGHT_TAKEN] = lights_here
            lane_stats[lane, tuning.DIRECTION_TAKEN] = dirs_here
        # Product sampling of the environment: the shading point's lobe proxy in the map's frame,
        # for its light samples and the pdf of its direction samples (``environment_product``).
        lobe = lights.NO_LOBE
        if PRODUCT:
            mirror = to_world(s, t, normal, (-wo[0], -wo[1], wo[2]))
            lobe = environment_product.lobe_in_map(environment.to_map,
                                                   dispatch.material_lobe(kind, here, material, wo), normal, mirror)

        # Emitter sampling: f Le |cos| w_l / (n̄_l p_l), a shadow ray toward the light point.
        if LIGHT_SAMPLES:
            for j in range(lights_here):
                wi_world, dist, value, raw, w_balance, share_t = light_samples.light_sample(
                    j, sampler, state, selection, technique, light_rows, environment, here, plan, point,
                    surface, (own_light, own_dir), emitting, lobe)
                if TEXTURES and tilted:
                    bend = shading_frames.factor(unperturbed, normal, a2, wi_world)
                    value, raw = scale(bend, value), scale(bend, raw)
                # A sample that cannot contribute casts no ray. Learning looks at the unweighted
                # value: whether a sample carries light must not depend on the heuristic (max's
                # weight 0 would hide it from the allocation's statistics).
                carries = raw if learning else value
                if not (carries[0] > 0.0 or carries[1] > 0.0 or carries[2] > 0.0):
                    _flag_nan(radiance, lane, value)
                    continue
                origin, to_target, tmax = _shadow_ray(x, eps, geometric, wi_world, dist)
                if RESAMPLES:
                    ris.offer(shadow_origin, shadow_dir, shadow_tmax, shadow_value, weight_sum, u_left,
                              radiance, lane, origin, to_target, tmax, value)
                    continue
                shadow_tmax[n_shadow] = tmax
                if learning:
                    # Unblocked, this sample adds (1 - w_bal) / n̄_l to C (``tracer.tuning``).
                    shadow_other[n_shadow] = own_light
                    shadow_control[n_shadow] = (1.0 - w_balance) / own_light
                    shadow_v2[n_shadow] = tuning.mean_square(raw, w_balance)
                    shadow_t[n_shadow] = share_t
                    if counting:
                        lane_stats[lane, tuning.LIGHT_RAYS] += 1.0
                n_shadow = _put(shadow_origin, shadow_dir, shadow_value, shadow_lane, n_shadow, origin,
                                to_target, value, lane)

        # Direction sampling: f |cos| / (n̄_d p_d); ``gather`` multiplies in the emitter the ray
        # hits and the MIS weight.
        if DIRECTION_SAMPLES:
            for j in range(dirs_here):
                wi_world, value, pdf_dir, delta = direction_sample(j, sampler, state, here, plan, point,
                                                                   surface, own_dir)
                if TEXTURES and tilted:
                    value = scale(shading_frames.factor(unperturbed, normal, a2, wi_world), value)
                if not (value[0] > 0.0 or value[1] > 0.0 or value[2] > 0.0):
                    _flag_nan(radiance, lane, value)
                    continue
                origin = offset_origin(x, eps, geometric, wi_world)
                if not ENVIRONMENT and not lights.may_reach(spheres, origin, wi_world):
                    continue  # it could only contribute 0: no ray (with an environment, any may)
                dir_pdf[n_direction] = own_dir * pdf_dir
                dir_delta[n_direction] = delta
                dir_other[n_direction] = own_light
                if PRODUCT and own_light > 0.0 and not delta:
                    dir_env_pdf[n_direction] = environment_light.pdf_product(environment, lobe, wi_world)
                if counting:
                    lane_stats[lane, tuning.DIRECTION_RAYS] += 1.0
                for axis in range(3):
                    dir_point[n_direction, axis] = x[axis]
                    dir_normal[n_direction, axis] = geometric[axis]
                    dir_shading[n_direction, axis] = receiver[axis]
                n_direction = _put(dir_origin, dir_dir, dir_value, dir_lane, n_direction, origin, wi_world,
                                   value, lane)
    return n_shadow, n_direction


# gather takes no sampler, so it cannot depend on one: its copy serves every sampler.
@kernel(ignores=("sampler",))
def gather(radiance, surfaces, light_tables, plan, tuned, shadow, blocked, direction, prim, lane_stats):
    """Add to ``radiance`` the light samples whose shadow rays are unblocked, and the direction
    samples whose rays hit the front of an emitter, weighted against the light technique; an
    estimator that learns adds what these samples tell to ``lane_stats`` (``tracer.tuning``)."""
    shadow_value, shadow_lane = shadow.value, shadow.lane
    shadow_other, shadow_control, shadow_v2, shadow_t = shadow.other, shadow.control, shadow.v2, shadow.t
    # The second moments per share are what the allocation learns from: not for optimal MIS alone.
    collect = tuned.collect and plan.adaptive
    shares = tuned.shares
    learning = LEARNS and len(lane_stats) > 0
    for row in range(len(blocked)):
        if not blocked[row]:
            lane = shadow_lane[row]
            for c in range(3):
                radiance[lane, c] += shadow_value[row, c]
            if learning:
                tuning.learn(lane_stats, lane, shares, collect, shadow_control[row], shadow_v2[row],
                             shadow_t[row], shadow_other[row] / plan.total)
    hit_table, first_sphere, textures = surfaces.hit_table, surfaces.first_sphere, surfaces.textures
    rays = direction_arrays(direction)
    lanes, others, pdfs, deltas = direction.lane, direction.other, direction.pdf, direction.delta
    for row in range(len(prim)):
        if prim[row] < 0:
            if not ENVIRONMENT:
                continue
            value, raw, pdf_light = environment_value(light_tables, plan.heuristic, rays, row)
        else:
            hit, _, value, raw, pdf_light = direction_value(hit_table, first_sphere, textures, light_tables,
                                                            plan.heuristic, rays, row, prim[row])
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
            tuning.learn(lane_stats, lane, shares, collect, -(1.0 - w_balance) / other,
                         tuning.mean_square(raw, w_balance), share_t, other / plan.total)


@jit
def _shadow_ray(x, eps: float, geometric, wi, dist: float):
    """``(origin, direction, tmax)`` of the shadow ray of a light sample at distance ``dist``
    along ``wi`` from ``x``: from the offset origin to the sampled point, stopping short of it;
    to infinity for the environment (dist inf)."""
    origin = offset_origin(x, eps, geometric, wi)
    if dist == math.inf:
        return origin, wi, math.inf
    to_target, length = normalized(sub(add_scaled(x, dist, wi), origin))
    return origin, to_target, max(length - eps, 0.0)


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


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
