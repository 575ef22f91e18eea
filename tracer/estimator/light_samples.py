"""Emitter sampling: one light sample at a shading point, and what it adds if unblocked.

For a shading point with light samples counted n̄_l and direction samples n̄_d (the expected
counts, ``tracer.estimator.counts``), a light sample toward the light point y along w_i adds

    f(w_o, w_i) Le |cos theta_i| w_l / (n̄_l p_l),   w_l = h(n̄_l p_l, n̄_d p_d)

if its shadow ray reaches y, where p_l is the light technique's pdf (the selection probability
included, ``tracer.lights``) and p_d the direction technique's pdf of the same direction
(``tracer.directions``); a delta light's sample, or one without a direction technique, has
w_l = 1 (the other technique cannot produce it). The combiner's ``weight`` is h
(``tracer.estimator.combiners``).
"""

from __future__ import annotations

from .. import lights, mis
from ..frame import to_local
from ..kernels import UNBOUND, template
from ..samplers import dimensions
from ..textures import lookup

LEARNS = DIRECTION_SAMPLES = TRANSMITS = TEXTURES = False  # bound per build (``tracer.kernels``)


@template
def light_sample(j: int, sampler, state, selection, technique, rows, environment, params, plan, point,
                 surface, own, emitting, lobe):
    """Light sample ``j`` of the shading point ``point = (x, geometric, normal, s, t, wo)`` of
    material ``surface = (kind, row, receiver, through)`` (receiver: the normal bounding which
    lights reach it, 0 for a type that transmits, ``through``), taken with expected counts
    ``own = (n̄_l, n̄_d)``, from
    the light tables' ``selection``, ``technique``, ``rows`` and ``environment``, read before
    the kernel's loop and passed apart (``lights.sample_with``; 13 parameters for that reason),
    and ``emitting = (textures, hit_table, first_sphere, prims)``, what a textured emitter's
    value at the sampled point is looked up in (``lookup.sampled_emission``):
    ``(wi_world, dist, value, raw, w_balance, share_t)``.

    value : RGB it adds if unblocked (weighted).   raw : the same before the MIS weight (what
    the learning looks at).   w_balance, share_t : its balance weight and p_l / (p_l + p_d), for
    the learning (``tracer.tuning``; 1 unless the build learns).   dist : to the light point
    (inf for the environment); 0 with a zero value where the sample is invalid. ``lobe``: the
    shading point's lobe proxy for product sampling of the environment (``lights.sample_with``)."""
    x, geometric, normal, s, t, wo = point
    kind, material, receiver, through = surface
    own_light, own_dir = own
    zero = (0.0, 0.0, 0.0)
    u = dispatch.uniform_pair(sampler, state, dimensions.light_point(j))
    wi_world, dist, le, pdf_light, delta, k = lights.sample_with(
        selection, technique, rows, environment, x, geometric, receiver,
        dispatch.uniform(sampler, state, dimensions.light_choice(j)),
        u[0], u[1], lobe)
    if not pdf_light > 0.0:
        return wi_world, 0.0, zero, zero, 1.0, 1.0
    if TEXTURES:
        textures, hit_table, first_sphere, prims = emitting
        le = lookup.sampled_emission(textures, hit_table, first_sphere, prims, k, x, wi_world, dist, le)
    wi = to_local(s, t, normal, wi_world)
    f, pdf_bsdf = dispatch.material_eval_pdf(kind, params, material, wo, wi)
    # A type that transmits takes light from below too: |cos theta_i| (``MaterialType.transmits``).
    c = (abs(wi[2]) if TRANSMITS and through else max(wi[2], 0.0)) / (own_light * pdf_light)
    w, w_balance, share_t = 1.0, 1.0, 1.0
    if DIRECTION_SAMPLES:
        if own_dir > 0.0 and not delta:
            pdf_dir = dispatch.direction_pdf(wi, pdf_bsdf)
            w = dispatch.weight(plan.heuristic, own_light * pdf_light, own_dir * pdf_dir)
            if LEARNS:
                w_balance = mis.weight_of(mis.BALANCE, own_light * pdf_light, own_dir * pdf_dir)
                share_t = mis.weight_of(mis.BALANCE, pdf_light, pdf_dir)
    raw = (f[0] * le[0] * c, f[1] * le[1] * c, f[2] * le[2] * c)
    cw = c * w
    value = (f[0] * le[0] * cw, f[1] * le[1] * cw, f[2] * le[2] * cw)
    return wi_world, dist, value, raw, w_balance, share_t


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
