"""Texture lookups in the kernels: a hit's (u, v), a texture's value there, and the material
row a textured hit shades with.

(u, v) at a hit follows Mitsuba 3: on a triangle, its corners' coordinates interpolated by the
hit's barycentrics (a mesh without coordinates gets (b1, b2), the barycentrics themselves, as
Mitsuba's meshes do: its corners are given (0, 0), (1, 0), (0, 1)); on an analytic sphere,
(φ / 2π, θ / π) of the hit in the sphere's own frame (φ from its local x axis toward y, in
[0, 2π); θ from its local z axis).
"""

from __future__ import annotations

import math

from ..geometry import barycentrics
from ..jit import jit
from . import (
    BILINEAR,
    CHECKERBOARD,
    COLOR0,
    COLOR1,
    FILTER,
    HEIGHT,
    KIND,
    LUMINANCE,
    MESH_ATTRIBUTE,
    MIRROR,
    OFFSET,
    REPEAT,
    TO_UV,
    WIDTH,
    WRAP,
)

LUMINANCE_R, LUMINANCE_G, LUMINANCE_B = (float(c) for c in LUMINANCE)


@jit
def uv_at(textures, hit_table, first_sphere: int, p: int, x):
    """(u, v) at point ``x`` of primitive ``p``."""
    if p >= first_sphere:
        s = p - first_sphere
        radius = hit_table[p, 3]
        d0 = (x[0] - hit_table[p, 0]) / radius
        d1 = (x[1] - hit_table[p, 1]) / radius
        d2 = (x[2] - hit_table[p, 2]) / radius
        frame = textures.sphere_frame
        if s < len(frame):
            local0 = frame[s, 0] * d0 + frame[s, 1] * d1 + frame[s, 2] * d2
            local1 = frame[s, 3] * d0 + frame[s, 4] * d1 + frame[s, 5] * d2
            local2 = frame[s, 6] * d0 + frame[s, 7] * d1 + frame[s, 8] * d2
        else:
            local0, local1, local2 = d0, d1, d2
        phi = math.atan2(local1, local0)
        if phi < 0.0:
            phi += 2.0 * math.pi
        return phi / (2.0 * math.pi), math.acos(min(max(local2, -1.0), 1.0)) / math.pi
    _, b1, b2 = barycentrics(hit_table, p, x)
    corner_uv = textures.corner_uv
    if len(corner_uv) == 0:
        return b1, b2
    b0 = 1.0 - b1 - b2
    u = b0 * corner_uv[p, 0] + b1 * corner_uv[p, 2] + b2 * corner_uv[p, 4]
    v = b0 * corner_uv[p, 1] + b1 * corner_uv[p, 3] + b2 * corner_uv[p, 5]
    return u, v


@jit
def _wrapped(i: int, size: int, wrap: int) -> int:
    """Texel index ``i`` of a row or column of ``size`` texels, wrapped as ``wrap`` says."""
    if wrap == REPEAT:
        return i % size  # Python's modulo: in 0 .. size - 1 for negative i too
    if wrap == MIRROR:
        period = i % (2 * size)
        return period if period < size else 2 * size - 1 - period
    return min(max(i, 0), size - 1)  # clamp


@jit
def _texel(pixels, offset: int, width: int, i: int, j: int, c: int) -> float:
    return float(pixels[offset + (j * width + i) * 3 + c])


@jit
def _to_uv(info, t: int, u: float, v: float):
    """(u, v) mapped by texture ``t``'s ``to_uv``."""
    m = TO_UV
    return (info[t, m] * u + info[t, m + 1] * v + info[t, m + 2],
            info[t, m + 3] * u + info[t, m + 4] * v + info[t, m + 5])


@jit
def evaluate(textures, t: int, u: float, v: float):
    """Texture ``t``'s RGB value at (u, v), before any one-number reduction."""
    info = textures.info
    su, sv = _to_uv(info, t, u, v)
    if int(info[t, KIND]) == CHECKERBOARD:
        first = (su - math.floor(su) > 0.5) == (sv - math.floor(sv) > 0.5)
        column = COLOR0 if first else COLOR1
        return info[t, column], info[t, column + 1], info[t, column + 2]
    return bitmap_value(textures.pixels, int(info[t, OFFSET]), int(info[t, WIDTH]), int(info[t, HEIGHT]),
                        int(info[t, WRAP]), int(info[t, FILTER]) == BILINEAR, su, sv)


@jit
def bitmap_value(pixels, offset: int, width: int, height: int, wrap: int, bilinear: bool, su: float,
                 sv: float):
    """The RGB value at (su, sv) of the ``width`` x ``height`` bitmap whose texels start at
    ``pixels[offset]`` (RGB, row by row, row 0 at v = 0), looked up as Mitsuba's ``bitmap``:
    the texel holding (su, sv), or bilinear between the four texel centres around it."""
    if not bilinear:
        i = _wrapped(int(math.floor(su * width)), width, wrap)
        j = _wrapped(int(math.floor(sv * height)), height, wrap)
        return (_texel(pixels, offset, width, i, j, 0), _texel(pixels, offset, width, i, j, 1),
                _texel(pixels, offset, width, i, j, 2))
    # Texel centres at (i + 1/2) / width: the four around (su, sv) and their weights.
    pu, pv = su * width - 0.5, sv * height - 0.5
    fu, fv = math.floor(pu), math.floor(pv)
    wu, wv = pu - fu, pv - fv
    i0, j0 = _wrapped(int(fu), width, wrap), _wrapped(int(fv), height, wrap)
    i1, j1 = _wrapped(int(fu) + 1, width, wrap), _wrapped(int(fv) + 1, height, wrap)
    r = g = b = 0.0
    for c in range(3):
        value = ((1.0 - wv) * ((1.0 - wu) * _texel(pixels, offset, width, i0, j0, c)
                               + wu * _texel(pixels, offset, width, i1, j0, c))
                 + wv * ((1.0 - wu) * _texel(pixels, offset, width, i0, j1, c)
                         + wu * _texel(pixels, offset, width, i1, j1, c)))
        if c == 0:
            r = value
        elif c == 1:
            g = value
        else:
            b = value
    return r, g, b


@jit
def evaluate_one(textures, t: int, u: float, v: float) -> float:
    """Texture ``t``'s one-number value at (u, v), as Mitsuba's ``eval_1``: a checkerboard's
    colours swapped (color0 where exactly one of the fractional parts is above 1/2), a bitmap's
    luminance."""
    info = textures.info
    if int(info[t, KIND]) == CHECKERBOARD:
        su, sv = _to_uv(info, t, u, v)
        first = (su - math.floor(su) > 0.5) != (sv - math.floor(sv) > 0.5)
        return info[t, COLOR0 if first else COLOR1]
    r, g, b = evaluate(textures, t, u, v)
    return LUMINANCE_R * r + LUMINANCE_G * g + LUMINANCE_B * b


@jit
def _attribute(textures, t: int, one: bool, hit_table, p: int, x):
    """Mesh attribute ``t`` at point ``x`` of triangle ``p``: its corner values blended by the
    barycentrics (a face attribute's corners are equal), RGB; ``one``: the one-number value,
    0 unless the attribute has one channel (Mitsuba's ``eval_1``), in all three."""
    info = textures.info
    if one and int(info[t, WIDTH]) != 1:
        return 0.0, 0.0, 0.0
    _, b1, b2 = barycentrics(hit_table, p, x)
    b0 = 1.0 - b1 - b2
    pixels = textures.pixels
    base = int(info[t, OFFSET]) + 9 * p
    r = b0 * pixels[base] + b1 * pixels[base + 3] + b2 * pixels[base + 6]
    if one:
        return r, r, r
    g = b0 * pixels[base + 1] + b1 * pixels[base + 4] + b2 * pixels[base + 7]
    b = b0 * pixels[base + 2] + b1 * pixels[base + 5] + b2 * pixels[base + 8]
    return r, g, b


@jit
def value_at(textures, t: int, one: bool, hit_table, p: int, x, u: float, v: float):
    """Texture ``t``'s value at point ``x`` of primitive ``p``, whose (u, v) there is given: RGB,
    or with ``one`` the one-number value (``evaluate_one``) in all three."""
    if int(textures.info[t, KIND]) == MESH_ATTRIBUTE:
        return _attribute(textures, t, one, hit_table, p, x)
    if one:
        value = evaluate_one(textures, t, u, v)
        return value, value, value
    return evaluate(textures, t, u, v)


@jit
def textured_row(textures, params, material: int, hit_table, first_sphere: int, p: int, x, scratch):
    """``(table, row)`` a hit of primitive ``p`` at ``x`` shades with: ``(params, material)``
    for a material without textures; otherwise ``(scratch, 0)``, the material's rows (its own
    and, for a blend, its parts': ``Textures.span``) copied into ``scratch`` (>= span, W) with
    each textured parameter's columns set to its texture's value here, clamped into the
    parameter's range (what the material's kernels are written for)."""
    span = textures.span[material]
    first, last = textures.first_binding[material], textures.first_binding[material + span]
    if first == last:
        return params, material
    for r in range(span):
        for column in range(params.shape[1]):
            scratch[r, column] = params[material + r, column]
    u, v = uv_at(textures, hit_table, first_sphere, p, x)
    bindings = textures.bindings
    for r in range(span):
        for k in range(textures.first_binding[material + r], textures.first_binding[material + r + 1]):
            column, size, t = int(bindings[k, 0]), int(bindings[k, 1]), int(bindings[k, 2])
            lo, hi = bindings[k, 3], bindings[k, 4]
            red, green, blue = value_at(textures, t, size == 1, hit_table, p, x, u, v)
            scratch[r, column] = min(max(red, lo), hi)
            if size != 1:
                scratch[r, column + 1] = min(max(green, lo), hi)
                scratch[r, column + 2] = min(max(blue, lo), hi)
    return scratch, 0



@jit
def emitted(textures, hit_table, first_sphere: int, p: int, x):
    """The radiance primitive ``p`` emits from its front at its point ``x``: its emission
    texture's RGB at x's (u, v) (``Textures.emission``), else the hit table's constant."""
    emission = textures.emission
    if len(emission) > 0 and emission[p] >= 0:
        u, v = uv_at(textures, hit_table, first_sphere, p, x)
        red, green, blue = value_at(textures, emission[p], False, hit_table, p, x, u, v)
        return max(red, 0.0), max(green, 0.0), max(blue, 0.0)
    return hit_table[p, 12], hit_table[p, 13], hit_table[p, 14]


@jit
def sampled_emission(textures, hit_table, first_sphere: int, prims, k: int, x, wi, dist: float, le):
    """The radiance that arrives at ``x`` along ``wi`` from the point at ``dist`` on light
    candidate ``k``, whose light technique gave ``le`` (its row's constant): the emission there
    if the candidate's primitives (``LightTables.prims``) are textured, else ``le``. A
    rectangle's point lies on one of its two triangles: the first if its barycentrics there are
    in the triangle (the second's (u, v) may differ on a quad from a mesh file)."""
    emission = textures.emission
    if k < 0 or len(emission) == 0:
        return le
    p = prims[k, 0]
    if p < 0 or emission[p] < 0:
        return le
    y = (x[0] + dist * wi[0], x[1] + dist * wi[1], x[2] + dist * wi[2])
    if prims[k, 1] >= 0:
        _, b1, b2 = barycentrics(hit_table, p, y)
        if not (b1 >= 0.0 and b2 >= 0.0 and b1 + b2 <= 1.0):
            p = prims[k, 1]
    return emitted(textures, hit_table, first_sphere, p, y)
