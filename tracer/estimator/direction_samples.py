"""Direction (BSDF) sampling: one direction sample at a shading point, and what it adds when its
ray meets an emitter.

A direction sample draws w_i by the direction technique (``tracer.directions``), which gives
f |cos theta_i| / p_d; divided by its expected count n̄_d it is the ray's ``value``. When the
ray hits the front of an emitter of radiance Le at distance r, it adds

    value Le w_d,   w_d = h(n̄_d p_d, n̄_l p_l(x, w_i, r))

with p_l the pdf with which the light technique would have produced the same direction, the
selection probability included (``tracer.lights.pdf``); a delta lobe's sample, or one without
light samples, has w_d = 1. A ray that escapes the scene meets the environment, if there is one
(``environment_value``), weighted the same way against the environment's light pdf.
"""

from __future__ import annotations

import math

from .. import lights
from ..frame import add_scaled, dot, sub, to_world
from ..geometry import surface_point
from ..jit import jit
from ..kernels import UNBOUND, template
from ..lights import environment as environment_light
from ..samplers import dimensions
from ..textures import lookup

TEXTURES = False  # bound per build (``tracer.kernels``)


@template
def direction_sample(j: int, sampler, state, params, plan, point, surface, own_dir: float):
    """Direction sample ``j`` of the shading point ``point = (x, geometric, normal, s, t, wo)``
    of material ``surface = (kind, row, ...)`` with expected count ``own_dir``:
    ``(wi_world, value, pdf_dir, delta)``, value = f |cos| / (n̄_d p_d) as RGB (0: nothing to
    trace), pdf_dir the technique's own pdf of the direction."""
    x, geometric, normal, s, t, wo = point
    kind, material = surface[0], surface[1]
    u = dispatch.uniform_pair(sampler, state, dimensions.direction(plan.light_slots, j))
    wi, weight, pdf_dir, delta = dispatch.direction_sample(
        kind, params, material, wo,
        dispatch.uniform(sampler, state, dimensions.lobe_choice(plan.light_slots, j)),
        u[0], u[1])
    value = (weight[0] / own_dir, weight[1] / own_dir, weight[2] / own_dir)
    return to_world(s, t, normal, wi), value, pdf_dir, delta


@jit
def _plane_distance(hit_table, p, o, cos_normal) -> float:
    """Distance from ``o`` along a unit direction d to the plane of triangle ``p``, given
    cos_normal = d . face normal (nonzero): (v0 - o) . n / (d . n)."""
    return ((hit_table[p, 0] - o[0]) * hit_table[p, 9] + (hit_table[p, 1] - o[1]) * hit_table[p, 10]
            + (hit_table[p, 2] - o[2]) * hit_table[p, 11]) / cos_normal


@template
def direction_value(hit_table, first_sphere: int, textures, light_tables, heuristic: int, rays, row: int,
                    p: int):
    """What direction sample ``row``, whose ray hits primitive ``p``, adds: ``(hit, dist,
    value, raw, pdf_light)``, value = raw x its MIS weight against the light technique (whose
    count is the row's ``other``), raw = its weight x the emitter's radiance (RGB), dist the
    emitter's distance from the shading point, pdf_light the light technique's pdf of the
    direction (0 for a delta sample or without light samples), hit False if it adds nothing
    (the emitter's back side). ``textures`` give a textured emitter's radiance at the point
    hit (``lookup.emitted``). ``rays`` is a tuple of the direction buffer's arrays, unpacked
    by the caller before its loop."""
    dirs, values, points, normals, shadings, origins, pdfs, deltas, others, _ = rays
    wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
    x = (points[row, 0], points[row, 1], points[row, 2])
    y = x  # the emitter's point (a sphere's is found here; a triangle's only if textured)
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
        pdf_light = lights.pdf(light_tables, x, n, receiver, p, wi, dist)
        w = dispatch.weight(heuristic, pdfs[row], other * pdf_light)
    if TEXTURES:
        if p < first_sphere:
            y = add_scaled(x, dist, wi)
        le = lookup.emitted(textures, hit_table, first_sphere, p, y)
    else:
        le = (hit_table[p, 12], hit_table[p, 13], hit_table[p, 14])
    value, raw = _carried(values, row, le, w)
    return True, dist, value, raw, pdf_light


@jit
def _carried(values, row: int, le, w: float):
    """``(value, raw)`` of direction row ``row`` meeting radiance ``le``: raw = its weight x le,
    value = raw x the MIS weight ``w``."""
    raw = (values[row, 0] * le[0], values[row, 1] * le[1], values[row, 2] * le[2])
    return (raw[0] * w, raw[1] * w, raw[2] * w), raw


@template
def environment_value(light_tables, heuristic: int, rays, row: int):
    """What direction sample ``row``, whose ray escapes the scene, adds from the environment:
    ``(value, raw, pdf_light)`` as :func:`direction_value` (the environment is never seen from
    behind; its pdf is ``lights.pdf_environment``, from the row's ``env_pdf`` under product
    sampling)."""
    dirs, values, points, normals, shadings, origins, pdfs, deltas, others, env_pdfs = rays
    wi = (float(dirs[row, 0]), float(dirs[row, 1]), float(dirs[row, 2]))
    le = environment_light.radiance(light_tables.environment, wi)
    w = 1.0
    pdf_light = 0.0
    other = others[row]
    if other > 0.0 and not deltas[row]:
        x = (points[row, 0], points[row, 1], points[row, 2])
        receiver = (shadings[row, 0], shadings[row, 1], shadings[row, 2])
        pdf_light = lights.pdf_environment(light_tables, x, receiver, wi, env_pdfs[row])
        w = dispatch.weight(heuristic, pdfs[row], other * pdf_light)
    value, raw = _carried(values, row, le, w)
    return value, raw, pdf_light


@jit
def direction_arrays(direction):
    """The direction buffer's arrays that :func:`direction_value` reads, as one plain tuple."""
    return (direction.dir, direction.value, direction.point, direction.normal, direction.shading,
            direction.origin, direction.pdf, direction.delta, direction.other, direction.env_pdf)


dispatch = UNBOUND  # bound per build (``tracer.kernels``)
