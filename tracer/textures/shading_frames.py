"""Normal and bump maps in the kernels: the shading frame a texture perturbs, and what the
perturbation multiplies a BSDF sample's value by.

Mitsuba 3.9.1's ``normalmap`` and ``bumpmap`` BSDFs (src/bsdfs/normalmap.cpp, bumpmap.cpp,
normalmap_helpers.h) evaluate the BSDF they wrap in a tilted frame; tracer does the same by
replacing a hit's shading frame (``tracer.estimator.shading_point``) before its samples are
taken, so that every light technique, BSDF sampling and MIS weight sees the tilted frame, and
multiplying each sample's value by ``factor``:

- the hit's unperturbed frame is Mitsuba's: z the shading normal, s the part of dp/du
  orthogonal to it (Gram-Schmidt; ``coordinate_system`` where dp/du is 0), t = n x s;
  a hit seen from behind a two-sided material keeps s and t and mirrors z, as Mitsuba's
  ``twosided`` mirrors the directions instead;
- a normal map's texel is the normal 2 rgb - 1 in that frame; its tilted s is the part of the
  frame's x axis orthogonal to it;
- a bump map tilts dp/du and dp/dv by ``scale`` times the height field's gradient along the
  unperturbed normal; the tilted normal is their cross product, turned to the face normal's
  side; its s is the tilted frame's ``basis`` (Mitsuba's is the untilted dp/du made orthogonal
  to the tilted normal in mixed coordinates, so an anisotropic material under a bump map is
  refused by the readers);
- a material whose value depends on the tangent (anisotropic roughness) and has no map is
  shaded in the unperturbed frame itself (kind ``FRAME``);
- with ``flip_invalid`` a tilted normal facing away from the viewer is mirrored about the
  unperturbed normal (its x and y negated);
- a sample counts only in the hemisphere both normals share (wi . n and wi . n' of one sign),
  and with ``shadowing`` is multiplied by Estevez et al.'s shadowing term, 2 / (1 + sqrt(1 +
  a² tan² θ_i)) with a² = min(tan² θ_n' / 8, 1) ("A Microfacet-Based Shadowing Function to
  Solve the Bump Terminator Problem", Ray Tracing Gems, 2019; θ from the unperturbed normal).

dp/du and dp/dv follow Mitsuba's meshes: from the triangle's edges and corner (u, v), the
edges themselves on a mesh without coordinates (whose (u, v) is barycentric), the normal's
``coordinate_system`` where the coordinates are degenerate; on an analytic sphere,
2π r (-y, x, 0) and π r (z cos φ, z sin φ, -sin θ) of the hit in the sphere's frame.
"""

from __future__ import annotations

import math

from ..frame import add_scaled, basis, cross, dot, normalized, scale, sub, to_local, to_world
from ..geometry import shading_normal
from ..jit import jit
from . import (
    BILINEAR,
    BITMAP,
    FILTER,
    FRAME,
    HEIGHT,
    KIND,
    LUMINANCE,
    NORMAL_MAP,
    OFFSET,
    PERTURB_FLIP,
    PERTURB_KIND,
    PERTURB_SCALE,
    PERTURB_SHADOWING,
    PERTURB_TEXTURE,
    TO_UV,
    WIDTH,
    WRAP,
)
from .lookup import _texel, _to_uv, _wrapped, uv_at, value_at

LUMINANCE_R, LUMINANCE_G, LUMINANCE_B = (float(c) for c in LUMINANCE)


@jit
def uv_partials(textures, hit_table, first_sphere: int, p: int, x, face_normal):
    """(dp/du, dp/dv) at point ``x`` of primitive ``p`` (world vectors, not unit)."""
    if p >= first_sphere:
        s = p - first_sphere
        radius = hit_table[p, 3]
        d = ((x[0] - hit_table[p, 0]) / radius, (x[1] - hit_table[p, 1]) / radius,
             (x[2] - hit_table[p, 2]) / radius)
        frame = textures.sphere_frame
        r0, r1, r2 = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
        if s < len(frame):  # rows of the world-to-local rotation
            r0 = (frame[s, 0], frame[s, 1], frame[s, 2])
            r1 = (frame[s, 3], frame[s, 4], frame[s, 5])
            r2 = (frame[s, 6], frame[s, 7], frame[s, 8])
        lx, ly, lz = dot(r0, d), dot(r1, d), dot(r2, d)
        rd = math.sqrt(lx * lx + ly * ly)
        du_local = (-ly, lx, 0.0)
        dv_local = (lz * lx / rd, lz * ly / rd, -rd) if rd > 0.0 else (1.0, 0.0, 0.0)
        # local -> world: the transpose of the rotation (its rows are the local axes)
        du = scale(2.0 * math.pi * radius, to_world(r0, r1, r2, du_local))
        dv = scale(math.pi * radius, to_world(r0, r1, r2, dv_local))
        return du, dv
    e1 = (hit_table[p, 3], hit_table[p, 4], hit_table[p, 5])
    e2 = (hit_table[p, 6], hit_table[p, 7], hit_table[p, 8])
    corner_uv = textures.corner_uv
    if len(corner_uv) == 0:
        return e1, e2
    du0, dv0 = corner_uv[p, 2] - corner_uv[p, 0], corner_uv[p, 3] - corner_uv[p, 1]
    du1, dv1 = corner_uv[p, 4] - corner_uv[p, 0], corner_uv[p, 5] - corner_uv[p, 1]
    det = du0 * dv1 - dv0 * du1
    if det == 0.0:
        return basis(face_normal)
    inv = 1.0 / det
    dp_du = scale(inv, add_scaled(scale(dv1, e1), -dv0, e2))
    dp_dv = scale(inv, add_scaled(scale(-du1, e1), du0, e2))
    return dp_du, dp_dv


@jit
def height_gradient(textures, t: int, u: float, v: float):
    """(df/du, df/dv) of texture ``t``'s one-number value at (u, v): the derivative of the
    bilinear blend of the four texels' luminances, by the chain rule through the resolution and
    ``to_uv``'s linear part A; 0 for a nearest lookup or a checkerboard. Mitsuba 3.9.1's bitmap
    ``eval_1_grad`` multiplies by the resolution after A's transpose instead of before, which is
    the same where A is diagonal or the texture square, and otherwise not the derivative (a
    rotated ``to_uv`` on a 2:1 texture gives a gradient off by up to 2x): tracer keeps the
    derivative, so a bump map under such a ``to_uv`` renders unlike Mitsuba's."""
    info = textures.info
    if int(info[t, KIND]) != BITMAP or int(info[t, FILTER]) != BILINEAR:
        return 0.0, 0.0
    su, sv = _to_uv(info, t, u, v)
    pixels = textures.pixels
    width, height, offset = int(info[t, WIDTH]), int(info[t, HEIGHT]), int(info[t, OFFSET])
    wrap = int(info[t, WRAP])
    pu, pv = su * width - 0.5, sv * height - 0.5
    fu, fv = math.floor(pu), math.floor(pv)
    wu, wv = pu - fu, pv - fv
    i0, j0 = _wrapped(int(fu), width, wrap), _wrapped(int(fv), height, wrap)
    i1, j1 = _wrapped(int(fu) + 1, width, wrap), _wrapped(int(fv) + 1, height, wrap)
    f00 = _luminance(pixels, offset, width, i0, j0)
    f10 = _luminance(pixels, offset, width, i1, j0)
    f01 = _luminance(pixels, offset, width, i0, j1)
    f11 = _luminance(pixels, offset, width, i1, j1)
    d_su = width * ((1.0 - wv) * (f10 - f00) + wv * (f11 - f01))
    d_sv = height * ((1.0 - wu) * (f01 - f00) + wu * (f11 - f10))
    m = TO_UV  # (su, sv) = A (u, v) + b: the gradient in (u, v) is A^T times it
    return (info[t, m] * d_su + info[t, m + 3] * d_sv, info[t, m + 1] * d_su + info[t, m + 4] * d_sv)


@jit
def _luminance(pixels, offset: int, width: int, i: int, j: int) -> float:
    return (LUMINANCE_R * _texel(pixels, offset, width, i, j, 0)
            + LUMINANCE_G * _texel(pixels, offset, width, i, j, 1)
            + LUMINANCE_B * _texel(pixels, offset, width, i, j, 2))


@jit
def perturbed(textures, row: int, hit_table, first_sphere: int, corner_normals, p: int, x, d, normal):
    """The tilted frame of a hit of primitive ``p`` at ``x`` (ray direction ``d``) whose
    material row ``row`` has a normal or bump map (or ``FRAME``: the unperturbed frame) and whose
    shading normal (toward the viewer) is ``normal``: ``(reflects, normal', s', t', wo', a2)``,
    with wo' the direction toward the viewer in the tilted frame and a2 the shadowing term's a²
    (0 without shadowing). reflects is False where the viewer is below the tilted frame
    (tracer's materials, one-sided there, reflect nothing; Mitsuba's evaluate to 0) or the map
    gives no direction."""
    perturb = textures.perturb
    kind = int(perturb[row, PERTURB_KIND])
    t_index = int(perturb[row, PERTURB_TEXTURE])
    if p < first_sphere:
        face = (hit_table[p, 9], hit_table[p, 10], hit_table[p, 11])
    else:  # a sphere's outward normal
        face, _ = normalized(sub(x, (hit_table[p, 0], hit_table[p, 1], hit_table[p, 2])))
    # The unperturbed normal on the front side: ``normal`` or, from behind a two-sided
    # material (``shading_point.at_hit`` turned it to the viewer), its opposite.
    unperturbed = shading_normal(corner_normals, hit_table, first_sphere, p, x, face)
    side = 1.0 if dot(unperturbed, normal) >= 0.0 else -1.0
    front = scale(side, normal)
    dp_du, dp_dv = uv_partials(textures, hit_table, first_sphere, p, x, face)
    s, length = normalized(add_scaled(dp_du, -dot(front, dp_du), front))
    if not length > 0.0:
        s, _ = basis(front)
    t = cross(front, s)
    # The frame (s, t, normal): mirrored (left-handed) from behind, as Mitsuba's twosided.
    wo = to_local(s, t, normal, scale(-1.0, d))
    if kind == FRAME:  # no map: the frame itself, for a material whose value depends on s
        return wo[2] > 0.0, normal, s, t, wo, 0.0
    u, v = uv_at(textures, hit_table, first_sphere, p, x)
    if kind == NORMAL_MAP:
        r, g, b = value_at(textures, t_index, False, hit_table, p, x, u, v)
        n_local = (2.0 * r - 1.0, 2.0 * g - 1.0, 2.0 * b - 1.0)
    else:  # a bump map
        g_u, g_v = height_gradient(textures, t_index, u, v)
        bump = perturb[row, PERTURB_SCALE]
        du = add_scaled(dp_du, bump * g_u - dot(front, dp_du), front)
        dv = add_scaled(dp_dv, bump * g_v - dot(front, dp_dv), front)
        n_world, length = normalized(cross(du, dv))
        if not length > 0.0:
            return False, normal, s, t, wo, 0.0
        if dot(face, n_world) < 0.0:
            n_world = scale(-1.0, n_world)
        n_local = to_local(s, t, front, n_world)
    if perturb[row, PERTURB_FLIP] != 0.0 and wo[2] * dot(wo, n_local) <= 0.0:
        n_local = (-n_local[0], -n_local[1], n_local[2])
    n_local, length = normalized(n_local)
    if not length > 0.0:
        return False, normal, s, t, wo, 0.0
    a2 = 0.0
    if perturb[row, PERTURB_SHADOWING] != 0.0:
        z2 = n_local[2] * n_local[2]
        a2 = min(0.125 * max(1.0 - z2, 0.0) / z2, 1.0) if z2 > 0.0 else 1.0
    n_tilted = to_world(s, t, normal, n_local)
    if kind == NORMAL_MAP:  # Mitsuba's tilted s: the frame's x axis made orthogonal to n'
        s_local, _ = normalized(add_scaled((1.0, 0.0, 0.0), -n_local[0], n_local))
        s_tilted = to_world(s, t, normal, s_local)
        t_tilted = to_world(s, t, normal, cross(n_local, s_local))
    else:
        s_tilted, t_tilted = basis(n_tilted)
    wo_tilted = to_local(s_tilted, t_tilted, n_tilted, scale(-1.0, d))
    return wo_tilted[2] > 0.0, n_tilted, s_tilted, t_tilted, wo_tilted, a2


@jit
def factor(normal, tilted, a2: float, wi) -> float:
    """What a sample toward ``wi`` (world, unit) is multiplied by at a hit whose unperturbed
    normal is ``normal`` and tilted one ``tilted``: 0 unless both normals see it on one side,
    else the shadowing term (1 with a2 = 0)."""
    cos_i = dot(wi, normal)
    if not cos_i * dot(wi, tilted) > 0.0:
        return 0.0
    if a2 == 0.0:
        return 1.0
    cos2 = cos_i * cos_i
    tan2 = max(1.0 - cos2, 0.0) / cos2
    return 2.0 / (1.0 + math.sqrt(1.0 + a2 * tan2))
