"""The ``ris`` combiner: resampled importance sampling (Talbot, Cline and Egbert, "Importance
Resampling for Global Illumination", EGSR 2005). A plug-in (``tracer.estimator.combiners``).

A shading point draws N light and M BSDF candidates y_j, exactly the samples MIS with N + M
samples would take, and computes for each the value v_j that MIS would add if its ray were
unblocked: f Le |cos| m_j / p_j (RGB), m_j the heuristic's weight over the count-scaled pdfs
divided by the candidate's count (1 / N for a light-only ris). It keeps one candidate J with
probability w_J / sum w, w_j = mean(v_j) (so the target is p̂ = mean(f Le |cos|), unshadowed),
casts one shadow ray for it, and adds

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

from ... import mis, samplers
from ...frame import add_scaled, normalized, sub
from ...jit import jit
from ...kernels import kernel, template
from ...plugins import Combiner, register
from .. import counts as taken
from ..direction_samples import direction_arrays, direction_value, environment_value

NAME = "ris"
PLUGIN = register(Combiner(NAME, module=__name__, rank=3, resamples=True,
                           doc="resampled importance sampling"))
ENVIRONMENT = False  # bound per build (``tracer.kernels``)


@template
def counts(plan, tuned, sampler, state, pixel: int, sample: int):
    return taken.fixed(plan)


weight = mis.weight_of


@jit
def offer(origins, dirs, tmaxs, values, weight_sum, u_left, radiance, lane: int, origin, direction,
          tmax: float, value) -> None:
    """Offer a candidate whose unblocked contribution would be ``value`` (RGB, as MIS would add
    it) and whose shadow ray is ``origin, direction, tmax`` to ``lane``'s reservoir; kept, it
    replaces the lane's shadow row. Weight w = mean(value); a non-finite one marks the lane NaN
    (the render loop counts and zeroes it)."""
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


@kernel(ignores=("sampler",))  # takes no sampler (each lane's number was drawn in shade)
def resample(radiance, surfaces, light_tables, plan, direction, prim, shadow, reservoirs) -> int:
    """Offer the BSDF candidates (direction rows, whose rays met the emitters ``prim``) to their
    lanes' reservoirs; then turn each lane's kept candidate into its shadow ray carrying
    v_J / mean(v_J) * sum w, packed into rows 0 .. count - 1. Returns the count."""
    eps, hit_table, first_sphere = surfaces.eps, surfaces.hit_table, surfaces.first_sphere
    textures = surfaces.textures  # read once: a read through a tuple in the loop costs a reference count
    shadow_origin, shadow_dir, shadow_tmax = shadow.origin, shadow.dir, shadow.tmax
    shadow_value, shadow_lane = shadow.value, shadow.lane
    weight_sum, u_left = reservoirs.weight, reservoirs.u
    rays = direction_arrays(direction)
    dirs, points, origins, lanes = direction.dir, direction.point, direction.origin, direction.lane
    for row in range(len(prim)):
        wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
        origin = (float(origins[row, 0]), float(origins[row, 1]), float(origins[row, 2]))
        if prim[row] < 0:
            if not ENVIRONMENT:
                continue
            # It met no emitter: it escapes to the environment (an occlusion ray to infinity).
            value, _, _ = environment_value(light_tables, plan.heuristic, rays, row)
            offer(shadow_origin, shadow_dir, shadow_tmax, shadow_value, weight_sum, u_left, radiance,
                  lanes[row], origin, wi, math.inf, value)
            continue
        hit, dist, value, _, _ = direction_value(hit_table, first_sphere, textures, light_tables,
                                                 plan.heuristic, rays, row, prim[row])
        if not hit:
            continue
        x = (points[row, 0], points[row, 1], points[row, 2])
        to_target, length = normalized(sub(add_scaled(x, dist, wi), origin))
        offer(shadow_origin, shadow_dir, shadow_tmax, shadow_value, weight_sum, u_left, radiance,
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
